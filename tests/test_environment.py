"""The environment map: chi-square test of its importance sampling against its pdf (a map
with one bright pixel, and the real sun HDRI at full strength), the mapping and rotation
of the scene format, and furnace tests (uniform environment, diffuse albedo 1 -> 1)."""
import math
import os

import numpy as np
import pytest
from numba import njit

from pathtracer.kernels.envmap import (env_cell, env_eval, env_lookup, env_pdf, env_sample,
                                      env_sample_lit, env_uv, radiance_in_cell)
from pathtracer.kernels.rng import path_key, sample_1d
from pathtracer.scene import load_scene
from pathtracer.kernels.constants import LUM_B, LUM_G, LUM_R
from pathtracer.kernels import layout as L
from pathtracer.kernels.layout import ENV_DENSITY, ENV_TEXEL_WIDTH
from pathtracer.kernels.envmap import environment_tables, guide_size, guide_table
from pathtracer.scene.images import read_image
from pathtracer.film import write_image
from tests.conftest import BACKENDS, SHARED, needs_shared
from tests.helpers import sphere_mesh, write_scene
from tests.helpers import mean_and_se, run
from tests.helpers import chi2_test


def info(rotation_deg=0.0, world_from_map=None):
    """env_info of a map turned by rotation_deg about +Y, or oriented by world_from_map."""
    from pathtracer.scene.loader import EnvironmentMap
    inf = np.zeros(L.ENV_INFO_SIZE, np.float32)
    inf[L.ENV_P_SELECT] = 1.0
    w = world_from_map if world_from_map is not None else EnvironmentMap(
        None, rotation=rotation_deg).world_from_map()
    inf[L.ENV_ROT:L.ENV_ROT + 9] = np.asarray(w).T.reshape(-1)
    return inf


@njit(cache=True)
def _hist(marg, cond, guide, texels, inf, n, n_t, n_p):
    h = np.zeros((n_t, n_p))
    bad = 0
    for i in range(n):
        k = path_key(i, 3, 77)
        d, p = env_sample(marg, cond, guide, texels, inf, sample_1d(k, 0), sample_1d(k, 1),
                          True)
        if p <= 0:
            continue
        p2 = env_pdf(texels, inf, d)
        if abs(p2 - p) > 1e-3 * p:
            bad += 1
        t = math.acos(min(max(d[1], -1.0), 1.0))
        ph = math.atan2(d[0], -d[2]) + math.pi
        h[min(int(t / math.pi * n_t), n_t - 1), min(int(ph / (2 * math.pi) * n_p), n_p - 1)] += 1
    return h, bad


@njit(cache=True)
def _integral(texels, inf, n_t, n_p, sub):
    """Integral of the solid-angle pdf over (theta, phi) cells, in theta (smooth: the
    sin theta of the measure cancels the pdf's 1 / sin theta)."""
    out = np.zeros((n_t, n_p))
    dt = math.pi / n_t
    dp = 2 * math.pi / n_p
    for i in range(n_t):
        for j in range(n_p):
            acc = 0.0
            for a in range(sub):
                t = (i + (a + 0.5) / sub) * dt
                for b in range(sub):
                    ph = (j + (b + 0.5) / sub) * dp - math.pi
                    d = (np.float32(math.sin(t) * math.sin(ph)), np.float32(math.cos(t)),
                         np.float32(-math.sin(t) * math.cos(ph)))
                    acc += env_pdf(texels, inf, d) * math.sin(t)
            out[i, j] = acc * dt * dp / (sub * sub)
    return out


def _check_sampling(img, rotation, n=400_000, n_t=32, n_p=64, sub=6, compensate=True,
                    world_from_map=None):
    texels, marg, cond, guide = environment_tables(img, compensate)
    inf = info(rotation, world_from_map)
    h, bad = _hist(marg, cond, guide, texels, inf, n, n_t, n_p)
    # the direction -> (u, v) round trip may land in the neighbouring cell by rounding
    assert bad <= n * 1e-4, "env_pdf disagrees with env_sample's pdf"
    integ = _integral(texels, inf, n_t, n_p, sub)
    assert integ.sum() == pytest.approx(1.0, abs=5e-3)
    chi2_test(h, integ * n)


def test_one_bright_pixel_map():
    img = np.full((16, 32, 3), 1e-3)
    img[5, 20] = 5e4
    _check_sampling(img, 30.0)


def test_rows_lit_on_alternate_sides():
    """Neighbouring texel rows lit on opposite sides: at a height t between two texel rows
    the column density is (1 - t) f0(u) + t f1(u) of the two rows' densities, and a
    column search that weighs the rows otherwise moves mass between the sides (with the
    rows' CDFs blended at 1/2 instead of t, chi-square fails). Without compensation (its
    zero-density regions make the pdf's round trip through a direction too steep here),
    and dim near the poles (where the round trip through acos loses digits)."""
    img = np.full((16, 16, 3), 0.05)
    img[4:12:2, :5] = 3.0
    img[5:12:2, 9:14] = 2.0
    _check_sampling(img, 0.0, compensate=False)


def test_tilted_map_sampling():
    """A map in any orientation (Mitsuba's Z-up scenes turn it about X): the samples'
    directions still follow the pdf the lookups report (chi-square over world cells)."""
    img = np.full((16, 32, 3), 1e-2)
    img[3, 7] = 2e3
    img[10:12, 20:26] = 50.0
    a, b = math.radians(-90), math.radians(35)
    about_x = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    about_z = np.array([[math.cos(b), -math.sin(b), 0], [math.sin(b), math.cos(b), 0], [0, 0, 1]])
    # (uncompensated: compensation zeroes the dim texels' density, whose small islands
    # across the tilted grid the cells' sub-sampled integral could miss)
    _check_sampling(img, 0.0, world_from_map=about_z @ about_x, compensate=False, sub=12)


@needs_shared
def test_sun_hdri_sampling():
    img, _ = read_image(os.path.join(SHARED, "assets", "hdri", "rooitou_park_1k.hdr"))
    assert img.max() > 6e4          # the sun, at full strength
    _check_sampling(img, -75.0, sub=32)


def test_mapping_and_rotation():
    """u = 0.5 + atan2(x, -z) / 2pi, v = acos(y) / pi; rotation turns the map
    counter-clockwise seen from above."""
    f = np.float32
    u, v, _ = env_uv(info(0), (f(0), f(0), f(-1)))
    assert (u, v) == pytest.approx((0.5, 0.5))
    u, v, _ = env_uv(info(0), (f(1), f(0), f(0)))
    assert (u, v) == pytest.approx((0.75, 0.5))
    u, v, _ = env_uv(info(0), (f(0), f(1), f(0)))
    assert v == pytest.approx(0.0)
    # the map's -z feature (u = 0.5) turned by +90 degrees appears towards -x
    u, _, _ = env_uv(info(90), (f(-1), f(0), f(0)))
    assert u == pytest.approx(0.5, abs=1e-6)
    # a single bright texel is seen where the mapping says
    img = np.zeros((8, 16, ENV_TEXEL_WIDTH), np.float32)    # texels: rgb and density
    img[2, 12, 0] = 1.0     # u = 12.5 / 16, v = 2.5 / 8
    u0, v0 = 12.5 / 16, 2.5 / 8
    t, ph = v0 * math.pi, (u0 - 0.5) * 2 * math.pi
    d = (f(math.sin(t) * math.sin(ph)), f(math.cos(t)), f(-math.sin(t) * math.cos(ph)))
    assert env_eval(img, info(0), d) == pytest.approx((1, 0, 0), abs=1e-5)


def _furnace(tmp_path, env, backend, material):
    v, f = sphere_mesh(16, 32)
    scene = {
        "camera": {"resolution": [24, 24], "position": [0, 0, 4], "lookAt": [0, 0, 0],
                   "fov": 40},
        "render": {"spp": 64, "maxBounces": 200, "rrDepth": 200},
        "materials": [dict(material, name="m")],
        "objects": [{"name": "s", "vertices": v, "faces": f, "material": "m",
                     "smooth": True}],
        "environment": env,
    }
    s = load_scene(write_scene(tmp_path, scene))
    return run(s, backend, spp=64).film.image()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", ["color", "file"])
def test_white_furnace_diffuse(tmp_path, backend, kind):
    """A diffuse albedo-1 object under a uniform environment of 1 renders 1 everywhere
    it is seen; with the file the estimate mixes environment sampling and BSDF sampling
    by MIS, so any error in either pdf shows."""
    if kind == "file":
        write_image(str(tmp_path / "white.hdr"), np.ones((32, 64, 3), np.float32))
        env = {"file": "white.hdr", "rotation": 33}
    else:
        env = {"color": 1.0}
    img = _furnace(tmp_path, env, backend, {"type": "diffuse", "albedo": 1.0})
    if kind == "color":
        # BSDF sampling alone: every sample is exactly 1
        assert np.abs(img - 1).max() < 1e-4, np.abs(img - 1).max()
    else:
        # MIS of two strategies: unbiased, not noise-free. Image mean within 4 standard
        # errors of 1, and no pixel beyond 6 of its own.
        m, se = mean_and_se(img)
        assert np.all(np.abs(m - 1) < 4 * se + 1e-4), (m, se)
        assert np.abs(img - 1).max() < 0.25


@pytest.mark.parametrize("backend", BACKENDS)
def test_white_furnace_glass_and_metal(tmp_path, backend):
    """Energy-conserving principled configurations (white metal; clear glass: what enters
    leaves) render 1 under a uniform environment, within noise: never more."""
    write_image(str(tmp_path / "white.hdr"), np.ones((32, 64, 3), np.float32))
    for mat in ({"albedo": 1.0, "metallic": 1.0, "roughness": 0.0},
                {"albedo": 1.0, "metallic": 1.0, "roughness": 0.5},
                {"albedo": 1.0, "transmission": 1.0, "roughness": 0.0, "eta": 1.5},
                {"albedo": 1.0, "transmission": 1.0, "roughness": 0.4, "eta": 1.33}):
        img = _furnace(tmp_path, {"file": "white.hdr"}, backend, mat)
        m, se = mean_and_se(img)
        # rough microfacet models lose the energy of multiple scattering between facets
        # (a few %): the mean may fall below 1, never rise above it.
        assert np.all(m < 1 + 4 * se + 1e-4), (mat, m, se)
        assert np.all(m > 0.9), (mat, m)


@njit(cache=True)
def _radiance_over_pdf(texels, inf, n):
    """luminance / solid-angle pdf at n directions spread over the sphere (|y| < 0.9:
    where a row of texels spans little change of sin(theta))."""
    out = np.zeros(n)
    k = 0
    for i in range(n):
        y = -0.9 + 1.8 * (i + 0.5) / n
        phi = 2.399963 * i                     # golden-angle spiral
        r = math.sqrt(1.0 - y * y)
        d = (np.float32(r * math.cos(phi)), np.float32(y), np.float32(r * math.sin(phi)))
        c = env_eval(texels, inf, d)
        p = env_pdf(texels, inf, d)
        lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
        if p > 0 and lum > 0:
            out[k] = lum / p
            k += 1
    return out[:k]


@needs_shared
def test_sampling_density_follows_the_bilinear_radiance():
    """Without MIS compensation: on the sunlit HDRI, luminance / pdf is the same in every
    direction to 3 % (the density is the bilinear lookup's luminance x sin(theta), sin
    taken at texel centres): so direct light from the environment has no fireflies from the
    density. A piecewise-constant density over texels (the one used before) gave 73x here,
    at the sun's bilinear skirt. With compensation the density follows the excess over the
    sky's mean instead (test_compensated_density_is_the_excess_over_the_mean)."""
    img, _ = read_image(os.path.join(SHARED, "assets", "hdri", "rooitou_park_1k.hdr"))
    texels, _, _, _ = environment_tables(img, compensate=False)
    q = _radiance_over_pdf(texels, info(-75.0), 2_000_000)
    assert len(q) > 1_000_000
    assert q.max() / q.min() < 1.03, q.max() / q.min()


@njit(cache=True)
def _lookups(texels, marg, cond, guide, inf, n):
    """For n sampled directions: |the radiance env_sample_lit gives - env_eval(d)| over
    the radiance, and whether env_lookup gave env_eval's and env_pdf's numbers exactly
    (with and without the pdf)."""
    rel = np.zeros(n)
    same = 0
    for i in range(n):
        k = path_key(i, 5, 91)
        d, p, b, u, v = env_sample_lit(marg, cond, guide, texels, inf, sample_1d(k, 0),
                                       sample_1d(k, 1), True)
        a = env_eval(texels, inf, d)
        rel[i] = max(abs(a[0] - b[0]), abs(a[1] - b[1]), abs(a[2] - b[2])) / max(
            a[0], a[1], a[2], 1e-30)
        le, p1 = env_lookup(texels, inf, d, True)
        le0, p0 = env_lookup(texels, inf, d, False)
        if le == a and le0 == a and p1 == env_pdf(texels, inf, d) and p0 == 0.0:
            same += 1
    return rel, same


@needs_shared
def test_lookups_at_the_sampled_coordinates():
    """Next-event estimation takes the sky's radiance from the texels its sample's density
    came from, blended at the sampled point (env_sample_lit), escaped rays take radiance
    and density from one mapping (env_lookup): the former agrees with env_eval of the
    sampled direction up to the direction's round trip's rounding, the latter gives
    env_eval's and env_pdf's numbers exactly."""
    img, _ = read_image(os.path.join(SHARED, "assets", "hdri", "rooitou_park_1k.hdr"))
    texels, marg, cond, guide = environment_tables(img)
    n = 200_000
    rel, same = _lookups(texels, marg, cond, guide, info(100.0), n)
    assert same == n
    # (the direction's round trip through float32 sines and arctangents moves (u, v) by a
    # few 1e-5 of a texel: median 1.7e-5 here)
    assert np.median(rel) < 1e-4 and np.quantile(rel, 0.999) < 1e-3, (
        np.median(rel), np.quantile(rel, 0.999), rel.max())


def test_sampled_radiance_is_the_blend_at_the_sampled_point():
    """env_sample_lit's radiance is the bilinear blend of the map at the sample's own map
    coordinates (env_cell and radiance_in_cell at its (u, v)), on a map of random texels:
    the cell's texels and fractions in the right order (a swapped axis or texel would be off
    by the texels' differences, ~1)."""
    rng = np.random.default_rng(0)
    h, w = 16, 32
    texels, marg, cond, guide = environment_tables(
        rng.random((h, w, 3)).astype(np.float32) * 10)
    worst = 0.0
    for i in range(2000):
        k = path_key(i, 5, 91)
        _, p, le, u, v = env_sample_lit(marg, cond, guide, texels, info(30.0),
                                        sample_1d(k, 0), sample_1d(k, 1), True)
        assert p > 0
        ref = radiance_in_cell(texels, *env_cell(w, h, u, v))
        worst = max(worst, max(abs(a - b) for a, b in zip(le, ref)) / max(ref))
    assert worst < 1e-5, worst


def _sky_with_sun(h=32, w=64):
    """A synthetic sky: a smooth gradient (0.2 to 1.2, warmer towards the horizon) and a
    small sun of ~5000 over 2 x 2 texels."""
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    img = np.zeros((h, w, 3), np.float32)
    img[..., 0] = 0.2 + v[:, None] * (1.0 + 0.3 * np.cos(2 * np.pi * u[None, :]))
    img[..., 1] = 0.3 + 0.6 * v[:, None]
    img[..., 2] = 1.2 - 0.5 * v[:, None]
    img[9:11, 40:42] = 5000.0
    return img


def test_compensated_density_is_the_excess_over_the_mean():
    """MIS compensation (Karlik et al. 2019): at texel centres the density x sin(theta) is
    proportional to max(luminance - mean, 0), the mean taken over the sphere; 0 where the
    sky is at or below its mean. A constant map keeps the plain (uniform) density."""
    img = _sky_with_sun()
    h, w = img.shape[:2]
    pdf = environment_tables(img)[0][..., ENV_DENSITY]
    plain = environment_tables(img, compensate=False)[0][..., ENV_DENSITY]
    lum = img.astype(np.float64) @ np.array([LUM_R, LUM_G, LUM_B], np.float64)
    sin_t = np.sin(np.pi * (np.arange(h) + 0.5) / h)[:, None]
    mean = (lum * sin_t).sum() / (sin_t.sum() * w)
    excess = np.maximum(lum - mean, 0) * sin_t
    assert np.count_nonzero(excess) == 4             # the sun only: the gradient is below
    assert np.all(pdf[excess == 0] == 0)
    ratio = pdf[excess > 0] / excess[excess > 0]
    assert ratio.max() / ratio.min() == pytest.approx(1.0, abs=1e-5)
    # the plain density follows the luminance everywhere
    q = plain / (lum * sin_t)
    assert q.max() / q.min() == pytest.approx(1.0, abs=1e-5)
    # a constant map: the plain density
    flat = np.full((8, 16, 3), 2.0, np.float32)
    assert np.array_equal(environment_tables(flat)[0],
                          environment_tables(flat, compensate=False)[0])
    assert np.count_nonzero(environment_tables(flat)[0][..., ENV_DENSITY]) == 8 * 16


@njit(cache=True)
def _samples(marg, cond, guide, texels, inf, n, guided):
    """env_sample_lit's (u, v) and pdf for n random sample pairs."""
    out = np.zeros((n, 3), np.float32)
    for i in range(n):
        k = path_key(i, 7, 13)
        _, p, _, u, v = env_sample_lit(marg, cond, guide, texels, inf, sample_1d(k, 0),
                                       sample_1d(k, 1), guided)
        out[i, 0] = u
        out[i, 1] = v
        out[i, 2] = p
    return out


@pytest.mark.parametrize("compensate", [True, False])
def test_guided_search_finds_the_bisections_cells(compensate):
    """The guide tables only shorten the searches: with them (the CPU) env_sample_lit
    gives the samples it gives searching every cell (the GPU) and with one-interval guides,
    on a sky with a sun (rows and runs of columns without mass when compensated) and on
    random texels of an odd-sized map; and every guide entry is the last cell at or below
    its quantile (guide_table)."""
    rng = np.random.default_rng(5)
    for img in (_sky_with_sun(), rng.random((13, 37, 3)).astype(np.float32) ** 4):
        texels, marg, cond, guide = environment_tables(img, compensate)
        h, w = img.shape[:2]
        n_guide = guide.shape[1] - 1
        assert n_guide == guide_size(w, h) > 1
        for row, cum in [(j, cond[j]) for j in range(h)] + [(h, marg)]:
            q = np.arange(n_guide + 1) / n_guide * np.float64(cum[-1])
            for b, i in enumerate(guide[row]):
                assert 0 <= i < len(cum) - 1
                assert i == len(cum) - 2 or cum[i + 1] > q[b]
                assert cum[i] <= q[b] or i == 0
        plain = np.empty((h + 1, 2), np.int32)
        for j in range(h):
            plain[j] = guide_table(cond[j], 1)
        plain[h] = guide_table(marg, 1)
        inf = info(20.0)
        n = 100_000
        a = _samples(marg, cond, guide, texels, inf, n, True)
        assert np.array_equal(a, _samples(marg, cond, guide, texels, inf, n, False))
        assert np.array_equal(a, _samples(marg, cond, plain, texels, inf, n, True))


def test_compensated_sampling_chi_square():
    """The sampler draws the compensated density (a sky whose gradient is partly above
    its mean, with a sun): chi-square against env_pdf's integral over cells."""
    img = _sky_with_sun()
    img[..., :] += np.linspace(0.0, 3.0, img.shape[1])[None, :, None]
    _check_sampling(img, 60.0, sub=8)


def _spheres_under_the_sky(tmp_path):
    """A diffuse and a rough metal sphere on a diffuse floor under _sky_with_sun (written
    to tmp_path/sky.hdr), 8x8 pixels: a scene dictionary."""
    write_image(str(tmp_path / "sky.hdr"), _sky_with_sun())
    v, f = sphere_mesh(12, 24, radius=0.5)
    floor_v = [[-3, -0.5, -3], [3, -0.5, -3], [3, -0.5, 3], [-3, -0.5, 3]]
    return {
        "camera": {"resolution": [8, 8], "position": [0, 1.2, 3.2], "lookAt": [0, -0.1, 0],
                   "fov": 45},
        "render": {"spp": 64, "maxBounces": 4, "sampler": "independent"},
        "materials": [{"name": "d", "type": "diffuse", "albedo": [0.7, 0.6, 0.5]},
                      {"name": "m", "albedo": 0.9, "metallic": 1.0, "roughness": 0.3},
                      {"name": "g", "type": "diffuse", "albedo": 0.5}],
        "objects": [
            {"name": "a", "vertices": (np.array(v) + [-0.55, 0, 0]).tolist(), "faces": f,
             "material": "d", "smooth": True},
            {"name": "b", "vertices": (np.array(v) + [0.55, 0, 0]).tolist(), "faces": f,
             "material": "m", "smooth": True},
            {"name": "floor", "vertices": floor_v, "faces": [[0, 2, 1], [0, 3, 2]],
             "material": "g"}],
        "environment": {"file": "sky.hdr", "rotation": 20},
    }


@pytest.mark.parametrize("backend", BACKENDS)
def test_compensation_keeps_the_image(tmp_path, backend):
    """Unbiasedness: a diffuse sphere and a rough metal sphere on a diffuse floor under the
    synthetic sky with its sun, rendered with the compensated density and with the plain
    one ("misCompensation": false; the same estimator otherwise): per pixel, the means of
    24 renders of each agree within their standard errors (z-test). Where the compensated
    density is 0, only BSDF sampling reaches the sky, with MIS weight 1: a wrong weight
    there would lose or double the sky's light in the shadows."""
    scene = _spheres_under_the_sky(tmp_path)
    stats = []
    for seed0, compensate in ((0, True), (1000, False)):
        scene["environment"]["misCompensation"] = compensate
        s = load_scene(write_scene(tmp_path, scene, f"s{int(compensate)}.json"))
        # the key reaches the tables: the compensated density is 0 below the sky's mean
        assert np.any(s.arrays.env_img[..., ENV_DENSITY] == 0) == compensate
        imgs = np.array([run(s, backend, spp=64, seed=seed0 + k).film.image()
                         for k in range(24)], np.float64)
        stats.append((imgs.mean(0), imgs.std(0, ddof=1) / np.sqrt(len(imgs))))
    (m1, se1), (m0, se0) = stats
    # the compensated density changes the estimator: its noise differs
    assert not np.allclose(se1, se0, rtol=0.05)
    z = (m1 - m0) / np.sqrt(se1 ** 2 + se0 ** 2 + 1e-12)
    assert np.abs(z).max() < 6.0, np.abs(z).max()      # 192 values, ~46 dof each
    assert np.abs(z).mean() < 1.1, np.abs(z).mean()    # E|z| ~ 0.8


def test_cpu_ring_skips_finished_pixels(tmp_path):
    """The CPU's pass for scenes with an environment map finishes each path a few paths
    later from a ring per image row (drivers.deferred); pixels that
    adaptive sampling has finished are skipped in between. The other pixels' sums and
    counts are those of the pass over every pixel, bit for bit, and the finished pixels
    are zero (each row holds 8 pixels x 5 paths, more than the ring's records)."""
    from pathtracer.backends import make_backend
    from pathtracer.kernels import layout as L
    scene = load_scene(write_scene(tmp_path, _spheres_under_the_sky(tmp_path)))
    assert scene.features.env_map and scene.width * 5 > L.ESCAPE_RING
    backend = make_backend("cpu", scene)
    full, full_stats = [x.copy() for x in backend.render_pass(0, 5, 3, 4, 3)]
    active = np.ones((scene.height, scene.width), np.uint8)
    active[::2, 1::3] = 0
    active[3] = 0
    active[5, :4] = 0
    out, stats = backend.render_pass(0, 5, 3, 4, 3, active=active)
    on = active.astype(bool)
    np.testing.assert_array_equal(out[on], full[on])
    np.testing.assert_array_equal(stats[on], full_stats[on])
    assert not out[~on].any() and not stats[~on].any()
    assert full[on].all() and full_stats[..., L.STAT_BOUNCE_RAYS].sum() > 0
