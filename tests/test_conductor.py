"""The conductor BSDF (Mitsuba's conductor / roughconductor): its values and pdf against
Mitsuba 3's own plugin, its Fresnel term against the Fresnel equations in complex
arithmetic, chi-square tests of its sampling, a white furnace, and scenes using it."""
import math
import os

import numpy as np
import pytest
from numba import njit

from pathtracer.kernels.conductor import conductor_eval, conductor_sample, fresnel_conductor
from pathtracer.kernels.layout import (P_COND_ALPHA_U, P_COND_ALPHA_V, P_COND_DISTRIBUTION,
                                       P_COND_ETA, P_COND_K, P_SIZE)
from pathtracer.kernels.rng import path_key, sample_1d
from pathtracer.scene.mitsuba_xml import conductor_table
from tests.helpers import chi2_test, run, sphere_mesh, write_scene

F = np.float32
HERE = os.path.dirname(os.path.abspath(__file__))
TABLE = os.path.join(HERE, "references", "conductor_mitsuba.npz")


def cparams(tint=(1.0, 1.0, 1.0), alpha_u=0.1, alpha_v=None, eta=(0.0, 0.0, 0.0),
            k=(1.0, 1.0, 1.0), beckmann=False):
    p = [0.0] * P_SIZE
    p[0:3] = tint
    p[P_COND_ALPHA_U] = alpha_u
    p[P_COND_ALPHA_V] = alpha_u if alpha_v is None else alpha_v
    p[P_COND_ETA:P_COND_ETA + 3] = eta
    p[P_COND_K:P_COND_K + 3] = k
    p[P_COND_DISTRIBUTION] = 1.0 if beckmann else 0.0
    return tuple(F(x) for x in p)


def test_matches_mitsuba_roughconductor():
    """eval (f |cos|) equal to Mitsuba 3.9.1's roughconductor at 64 direction pairs of 8
    cases (GGX and Beckmann, isotropic and anisotropic both ways, gold, aluminium and a
    mirror's index), and the pdf (both sample the visible normals).
    The table is Mitsuba's own output (tests/mitsuba_conductor_ref.py)."""
    t = np.load(TABLE)
    for c in range(len(t["values"])):
        p = cparams(tuple(t["tint"]), *t["alpha"][c], tuple(t["eta"][c]), tuple(t["k"][c]),
                    bool(t["distribution"][c]))
        for j in range(len(t["wo"])):
            f, pdf = conductor_eval(p, tuple(F(x) for x in t["wo"][j]),
                                    tuple(F(x) for x in t["wi"][j]))
            ref = t["values"][c, j]
            assert np.allclose(f, ref, rtol=2e-4, atol=1e-6), (c, j, f, ref)
            # GGX: the same pdf; Beckmann: ours takes the exact Smith G1 (its sampler's
            # density), Mitsuba's its rational fit of G1 (within 0.35 %)
            rel = 2e-4 if not t["distribution"][c] else 4e-3
            assert pdf == pytest.approx(t["pdfs"][c, j], rel=rel, abs=1e-6), (c, j)


def test_matches_mitsuba_live():
    """The same against Mitsuba itself where it is installed (the `bench` extra), at
    other directions: the table cannot go stale."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(5)
    for dist in ("ggx", "beckmann"):
        bsdf = mi.load_dict({"type": "roughconductor", "distribution": dist, "alpha_u": 0.2,
                             "alpha_v": 0.07, "material": "Cu"})
        eta, k = conductor_table()["Cu"]
        p = cparams((1, 1, 1), 0.2, 0.07, tuple(eta), tuple(k), dist == "beckmann")
        for _ in range(100):
            a, b = rng.normal(size=(2, 3))
            a[2], b[2] = abs(a[2]), abs(b[2])
            a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*a)
            si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            ref = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*b)))
            f, _ = conductor_eval(p, tuple(F(x) for x in a), tuple(F(x) for x in b))
            assert np.allclose(f, ref, rtol=2e-4, atol=1e-6)


def _fresnel_reference(c, n):
    """The Fresnel equations for a complex index n (s and p amplitudes squared)."""
    t = np.sqrt(n * n - (1 - c * c) + 0j)
    rs = abs((c - t) / (c + t)) ** 2
    rp = abs((n * n * c - t) / (n * n * c + t)) ** 2
    return 0.5 * (rs + rp)


@pytest.mark.parametrize("n", [0.1431 + 3.9831j, 1.5 + 0j, 0.05 + 1j, 0 + 1j, 2.5 + 8j,
                               1.6574 + 9.2238j])
def test_fresnel_conductor(n):
    for c in np.linspace(0.001, 1.0, 200):
        got = fresnel_conductor(F(c), F(n.real), F(n.imag))
        assert got == pytest.approx(_fresnel_reference(c, n), abs=2e-6)
    # eta 0, k 1 (Mitsuba's material 'none'): a perfect mirror at every angle
    assert fresnel_conductor(F(0.3), F(0.0), F(1.0)) == pytest.approx(1.0, abs=1e-6)


@njit(cache=True)
def _sample_hist(p, wo, n, seed, n_cos, n_phi):
    h = np.zeros((n_cos, n_phi))
    bad = 0
    for i in range(n):
        k = path_key(i, 7, seed)
        wi, w, pdf = conductor_sample(p, wo, sample_1d(k, 0), sample_1d(k, 1))
        if pdf <= 0:
            continue
        f, pdf2 = conductor_eval(p, wo, wi)
        if abs(pdf2 - pdf) > 1e-4 * pdf or not np.isfinite(w[0] + w[1] + w[2]):
            bad += 1
        for c in range(3):
            if abs(f[c] / pdf2 - w[c]) > 1e-3 * max(abs(w[c]), 1e-3):
                bad += 1
        z = min(max(wi[2], -1.0), 1.0)
        ci = min(int((z + 1.0) * 0.5 * n_cos), n_cos - 1)
        phi = math.atan2(wi[1], wi[0])
        if phi < 0:
            phi += 2 * math.pi
        h[ci, min(int(phi / (2 * math.pi) * n_phi), n_phi - 1)] += 1
    return h, bad


@njit(cache=True)
def _pdf_integral(p, wo, n_cos, n_phi, sub):
    out = np.zeros((n_cos, n_phi))
    dc = 2.0 / n_cos
    dp = 2 * math.pi / n_phi
    for i in range(n_cos):
        for j in range(n_phi):
            acc = 0.0
            for a in range(sub):
                z = -1.0 + (i + (a + 0.5) / sub) * dc
                s = math.sqrt(max(0.0, 1 - z * z))
                for b in range(sub):
                    phi = (j + (b + 0.5) / sub) * dp
                    wi = (np.float32(s * math.cos(phi)), np.float32(s * math.sin(phi)),
                          np.float32(z))
                    acc += conductor_eval(p, wo, wi)[1]
            out[i, j] = acc * dc * dp / (sub * sub)
    return out


def direction(cos_theta, phi=0.3):
    s = math.sqrt(max(0.0, 1 - cos_theta * cos_theta))
    return (F(s * math.cos(phi)), F(s * math.sin(phi)), F(cos_theta))


CHI2_CASES = [
    ("ggx", cparams(alpha_u=0.3), 0.7),
    ("ggx_grazing", cparams(alpha_u=0.5), 0.1),
    ("ggx_aniso", cparams(alpha_u=0.4, alpha_v=0.1), 0.6),
    ("beckmann", cparams(alpha_u=0.3, beckmann=True), 0.7),
    ("beckmann_grazing", cparams(alpha_u=0.6, beckmann=True), 0.15),
    ("beckmann_aniso", cparams(alpha_u=0.1, alpha_v=0.5, beckmann=True), 0.5),
    ("beckmann_head_on", cparams(alpha_u=0.4, alpha_v=0.2, beckmann=True), 1.0),
]


@pytest.mark.parametrize("name,p,cos_o", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_conductor_chi2(name, p, cos_o):
    wo = direction(cos_o)
    n_cos, n_phi, n = 48, 96, 300_000
    h, bad = _sample_hist(p, wo, n, 11, n_cos, n_phi)
    assert bad == 0, "sample disagrees with eval/pdf"
    integ = _pdf_integral(p, wo, n_cos, n_phi, 10)
    assert integ.sum() <= 1.0 + 2e-3
    assert h.sum() / n == pytest.approx(integ.sum(), abs=5e-3)
    chi2_test(h, integ * n)


@njit(cache=True)
def _albedo(p, wo, n, seed):
    s = np.zeros(3)
    s2 = np.zeros(3)
    for i in range(n):
        k = path_key(i, 5, seed)
        wi, w, pdf = conductor_sample(p, wo, sample_1d(k, 0), sample_1d(k, 1))
        if pdf <= 0:
            continue
        for j in range(3):
            s[j] += w[j]
            s2[j] += w[j] * w[j]
    m = s / n
    return m, np.sqrt(np.maximum(s2 / n - m * m, 0.0) / n)


@pytest.mark.parametrize("beckmann", [False, True])
def test_white_furnace(beckmann):
    """A perfect mirror's index (reflectance 1): the smooth conductor reflects everything
    at every angle; rough ones never more than they receive (single scattering loses the
    light that meets a second facet, as in Mitsuba: 0.72 at alpha 0.6 x 0.3 head-on, where
    Mitsuba's sampler measures 0.72 too), and a slightly rough one little."""
    for cz in (1.0, 0.7, 0.3, 0.05):
        m, se = _albedo(cparams(alpha_u=0.0, beckmann=beckmann), direction(cz), 20_000, 3)
        assert np.allclose(m, 1.0, atol=5e-4), (cz, m)   # (alpha 0.001 at grazing)
        for a in (0.2, 0.6, 1.0):
            m, se = _albedo(cparams(alpha_u=a, alpha_v=a * 0.5, beckmann=beckmann),
                            direction(cz), 50_000, 3)
            assert np.all(m <= 1.0 + 4 * se + 1e-4), (a, cz, m, se)
            if cz == 1.0 and a == 0.2:
                assert np.all(m > 0.95), (a, m)


def _sphere_scene(material):
    v, f = sphere_mesh()
    return {"camera": {"position": [0, 0, 4], "lookAt": [0, 0, 0], "fov": 30,
                       "resolution": [24, 24]},
            "render": {"spp": 16, "maxBounces": 4},
            "environment": {"color": [1.0, 1.0, 1.0]},
            "materials": [material],
            "objects": [{"name": "ball", "vertices": v, "faces": f,
                         "material": material["name"]}]}


def test_mirror_sphere_in_white_furnace(tmp_path):
    """A smooth conductor of reflectance 1 under a white sky renders white everywhere
    (the image equals the sky), through the whole bounce on the CPU."""
    path = write_scene(tmp_path, _sphere_scene({"name": "m", "type": "conductor"}))
    from pathtracer import load_scene
    scene = load_scene(path)
    assert scene.compiled.features.conductor and not scene.compiled.features.principled
    img = run(scene.compiled).film.image()
    assert np.allclose(img, 1.0, atol=2e-3), (img.min(), img.max())


def test_conductor_keys_are_checked(tmp_path):
    from pathtracer import SceneError, load_scene
    bad = {"name": "m", "type": "conductor", "alphaU": 1.5}
    with pytest.raises(SceneError, match="alphaU"):
        load_scene(write_scene(tmp_path, _sphere_scene(bad)))
    bad = {"name": "m", "type": "conductor", "metallic": 1.0}
    with pytest.raises(SceneError, match="metallic"):
        load_scene(write_scene(tmp_path, _sphere_scene(bad)))


def _pane_scene(angle_deg, eta):
    """A camera looking through a thin pane (turned by angle_deg about y) at an emissive
    wall of radiance 1, small enough that the pane's reflections miss it; a black sky."""
    quad = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
    a = math.radians(angle_deg)
    rot = [[math.cos(a), 0, math.sin(a), 0], [0, 1, 0, 0], [-math.sin(a), 0, math.cos(a), 0],
           [0, 0, 0, 1]]
    return {"camera": {"position": [0, 0, 4], "lookAt": [0, 0, 0], "fov": 4,
                       "resolution": [8, 8]},
            "render": {"spp": 256, "maxBounces": 4, "seed": 3},
            "materials": [{"name": "pane", "type": "thindielectric", "eta": eta},
                          {"name": "wall", "type": "diffuse", "albedo": 0, "emission": 1}],
            "objects": [{"name": "pane", "vertices": quad, "faces": [[0, 1, 2], [0, 2, 3]],
                         "material": "pane", "transform": {"matrix": rot}},
                        {"name": "wall", "vertices": [[x * 0.8, y * 0.8, -2] for x, y, _ in quad],
                         "faces": [[0, 1, 2], [0, 2, 3]], "material": "wall"}]}


@pytest.mark.parametrize("angle,eta", [(0, 1.5), (60, 1.5), (75, 2.4)])
def test_thin_dielectric_pane_transmits_one_minus_its_reflectance(tmp_path, angle, eta):
    """Through a thin pane (Mitsuba's thindielectric) a wall of radiance 1 shows 1 - R',
    R' = 2R / (1 + R), R the Fresnel reflectance at the view angle: the stochastic choice
    between passing and the mirror is unbiased (a Bernoulli mean within 4 standard
    errors). Checked against Mitsuba 3.9.1's thindielectric on a lit scene with
    `bench.mitsuba_compare` (channel means 1.001-1.002, docs/benchmarks.md)."""
    from pathtracer import load_scene
    from pathtracer.kernels.principled import fresnel_dielectric
    scene = load_scene(write_scene(tmp_path, _pane_scene(angle, eta)))
    assert scene.compiled.features.alpha and scene.compiled.features.conductor
    img = run(scene.compiled).film.image()
    r = fresnel_dielectric(F(math.cos(math.radians(angle))), F(eta))[0]
    t = 1 - 2 * r / (1 + r)
    se = math.sqrt(t * (1 - t) / (256 * 64))
    assert abs(img.mean() - t) < 4 * se + 1e-4, (img.mean(), t, se)


def test_thin_dielectric_keys_are_checked(tmp_path):
    from pathtracer import SceneError, load_scene
    s = _pane_scene(0, 1.5)
    s["materials"][0]["alphaMode"] = "blend"
    with pytest.raises(SceneError, match="alphaMode"):
        load_scene(write_scene(tmp_path, s))
