"""Agreement with Mitsuba 3: the principled BSDF lobe by lobe and mixed, smooth glass
against Mitsuba's `dielectric`, and a diffuse sphere, all lit by the studio HDRI (which
also checks the environment mapping: the background is the map seen directly).

References: tests/references/*.npy, rendered by `python -m tests.mitsuba_refs` (settings in
references.json). Our image (the default sampler, sobol) is averaged over K independent
seeds; per pixel and for the image mean, the difference to the reference is judged against
the spread of those seeds plus the reference's own noise, on a tone-mapped scale x / (1 + x)
so that the few pixels that see a small bright lamp through a sharp lobe do not decide the
verdict alone. Each case renders with the independent sampler against Mitsuba's reference;
three of them (SOBOL_CASES) also with the default sampler, sobol, against the independent one.
"""
import json
import os

import numpy as np
import pytest

from pathtracer.backends import make_backend
from pathtracer.progressive import render
from pathtracer.scene import load_scene
from tests.conftest import BACKENDS, SHARED, needs_shared
from tests.mitsuba_refs import CASES, REF_DIR, env_for, our_scene

META = json.load(open(os.path.join(REF_DIR, "references.json")))
K = 8
# The cases also rendered with the sobol sampler: the plain diffuse path, every principled
# lobe at once, and a delta BSDF. The sampler and the BSDF are separate code (a sampler
# hands the BSDF uniform numbers by a dimension layout that no lobe changes), and the BSDF
# specialised to fewer lobes equals the full one bit for bit
# (tests/test_principled.py::test_lobes_compiled_out_change_nothing), so each further case
# would test the same code again at the price of a kernel compile (~15-20 s of CI's CPU).
SOBOL_CASES = ("diffuse_only", "principled_mixed", "glass_smooth_vs_dielectric")


def tone(x):
    return x / (1.0 + x)


def _render_seeds(tmp_path, backend, spp, scene_of_seed, tag=""):
    """The K images (float64) of the scene files scene_of_seed(0 .. K - 1) at spp."""
    imgs = []
    for seed in range(K):
        path = tmp_path / f"s{seed}{tag}.json"
        path.write_text(json.dumps(scene_of_seed(seed)))
        scene = load_scene(str(path))
        result = render(scene, make_backend(backend, scene), spp=spp)
        assert result.film.nonfinite == 0
        imgs.append(result.film.image().astype(np.float64))
    return np.array(imgs)


def _renders(tmp_path, case, backend, spp, sampler):
    env = env_for(case, SHARED)

    def scene_of_seed(seed):
        desc = our_scene(CASES[case], env, spp=spp, seed=seed)
        desc["render"]["sampler"] = sampler
        return desc
    return _render_seeds(tmp_path, backend, spp, scene_of_seed, "-" + sampler)


@needs_shared
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", list(CASES))
def test_agrees_with_mitsuba(tmp_path, case, backend):
    """Our independent sampler against Mitsuba's reference (the same estimator: the
    reference's noise is ours scaled by the sample counts), then (SOBOL_CASES) the default
    sampler, sobol, against our independent one: together, sobol agrees with Mitsuba to the
    independent renders' precision. (Compared with the reference directly, sobol's 4-7x
    smaller spread at 1024 spp shows the known envmap texel-placement difference of the
    near-mirror case: pooled ratio 3.7 there, against 2.0 for the independent sampler; H100,
    2026-11-23.)"""
    spp = 64 if backend == "cpu" else 1024
    ref = np.load(os.path.join(REF_DIR, case + ".npy")).astype(np.float64)
    ind = _renders(tmp_path, case, backend, spp, "independent")
    _check_agreement(f"{case} independent vs Mitsuba", ind, ref, None, (K * spp) / META["spp"])
    if case not in SOBOL_CASES:
        return
    sobol = _renders(tmp_path, case, backend, spp, "sobol")
    _check_agreement(f"{case} sobol vs independent", sobol, ind.mean(0), ind, 0.0)


def _check_agreement(label, imgs, ref, ref_imgs, ref_share):
    """``imgs`` (K seeds) against ``ref``, whose noise is either that of the K renders
    ``ref_imgs`` averaged, or (ref_imgs None) ``ref_share`` times that of imgs' mean."""
    def se2(x):
        return x.var(0, ddof=1) / K

    # 1. image mean per channel: within 4 standard errors (seed spread, both sides)
    m = imgs.mean(axis=(1, 2))                    # (K, 3)
    var = se2(m) * (1 + ref_share)
    if ref_imgs is not None:
        var = var + se2(ref_imgs.mean(axis=(1, 2)))
    diff = imgs.mean(0).mean((0, 1)) - ref.mean((0, 1))
    se = np.sqrt(var)
    assert np.all(np.abs(diff) <= 4 * se + 2e-3 * ref.mean((0, 1))), (label, diff, se)

    # 2. per pixel, tone-mapped: squared z-scores. Their median is robust to the
    # heavy-tailed pixels that see small bright lamps; for a t statistic with K - 1 = 7
    # degrees of freedom it is about 0.5 when both sides agree. The pooled ratio
    # (sum of squared differences over sum of variances) is about 1.
    t = tone(imgs)
    t_se2 = se2(t) * (1 + ref_share) + 1e-10
    if ref_imgs is not None:
        t_se2 = t_se2 + se2(tone(ref_imgs))
    d2 = (t.mean(0) - tone(ref)) ** 2
    z2 = d2 / t_se2
    print(f"{label}: median z^2 {np.median(z2):.3f}, pooled {d2.sum() / t_se2.sum():.3f}")
    assert np.median(z2) < 0.9, (label, np.median(z2))
    assert d2.sum() / t_se2.sum() < 2.5, (label, d2.sum() / t_se2.sum())


@needs_shared
@pytest.mark.parametrize("backend", BACKENDS)
def test_textures_agree_with_mitsuba(tmp_path, backend):
    """A sphere with a textured base colour (sRGB, mirrored) and roughness (linear), tiles
    and offsets that are not whole numbers (tests/mitsuba_texture_ref.py), against Mitsuba
    3's render of the benchmark's translation of the same scene file
    (pathtracer.mitsuba): the textures' orientation, tiling, wrapping, decoding and
    bilinear lookups agree, and so does the translation the benchmark relies on."""
    from tests.mitsuba_refs import smooth_sky
    from tests.mitsuba_texture_ref import NAME, SPHERE_RES, our_scene, roughness_map
    from tests.test_normal_map import write_sphere_obj
    smooth_sky()
    meta = json.load(open(os.path.join(REF_DIR, NAME + ".json")))
    ref = np.load(os.path.join(REF_DIR, NAME + ".npy")).astype(np.float64)
    obj = str(tmp_path / "sphere.obj")
    write_sphere_obj(obj, *SPHERE_RES)
    rough = roughness_map(str(tmp_path / "roughness.png"))
    spp = 64 if backend == "cpu" else 1024
    imgs = _render_seeds(tmp_path, backend, spp,
                         lambda seed: our_scene(obj, rough, spp=spp, seed=seed))
    _check_agreement("textured sphere vs Mitsuba", imgs, ref, None, (K * spp) / meta["spp"])
