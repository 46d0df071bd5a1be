"""The principled BSDF: chi-square tests of its sampling against its pdf over a grid of
parameters (Mitsuba's chi2.py method: directions histogrammed over (cos theta, phi) cells,
the pdf integrated over each cell on a sub-grid), weight == eval / pdf, reciprocity of the
reflection lobes, and energy bounds."""
import math

import numpy as np
import pytest
from numba import njit

from pathtracer.kernels.layout import P_FIELDS
from pathtracer.kernels.principled import (ALL_LOBES, Lobes, make_principled, principled_eval,
                                           principled_sample, reuse_sample)
from pathtracer.kernels.rng import path_key, sample_1d
from tests.helpers import chi2_test, principled_params as params

F = np.float32


def direction(cos_theta, phi=0.3):
    s = math.sqrt(max(0.0, 1 - cos_theta * cos_theta))
    return (F(s * math.cos(phi)), F(s * math.sin(phi)), F(cos_theta))


@njit(cache=True)
def _sample_hist(p, wo, n, seed, n_cos, n_phi):
    h = np.zeros((n_cos, n_phi))
    bad = 0
    for i in range(n):
        k = path_key(i, 7, seed)
        wi, w, pdf = principled_sample(p, wo, sample_1d(k, 0), sample_1d(k, 1),
                                       sample_1d(k, 2))
        if pdf <= 0:
            continue
        # the pdf of a returned direction must be what eval says, and weight = eval / pdf
        f, pdf2 = principled_eval(p, wo, wi)
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
        pj = min(int(phi / (2 * math.pi) * n_phi), n_phi - 1)
        h[ci, pj] += 1
    return h, bad


@njit(cache=True)
def _pdf_integral(p, wo, n_cos, n_phi, sub):
    """Integral of the pdf over each (cos theta, phi) cell: midpoint rule on sub x sub,
    refined near the horizon, where refraction near the critical angle has an integrable
    singularity (the half-vector Jacobian grows like 1 / cos theta)."""
    out = np.zeros((n_cos, n_phi))
    dc = 2.0 / n_cos
    dp = 2 * math.pi / n_phi
    sub0 = sub
    for i in range(n_cos):
        z_mid = -1.0 + (i + 0.5) * dc
        sub = sub0 * 6 if abs(z_mid) < 0.1 else sub0
        for j in range(n_phi):
            acc = 0.0
            for a in range(sub):
                z = -1.0 + (i + (a + 0.5) / sub) * dc
                s = math.sqrt(max(0.0, 1 - z * z))
                for b in range(sub):
                    phi = (j + (b + 0.5) / sub) * dp
                    wi = (np.float32(s * math.cos(phi)), np.float32(s * math.sin(phi)),
                          np.float32(z))
                    acc += principled_eval(p, wo, wi)[1]
            out[i, j] = acc * dc * dp / (sub * sub)
    return out


CASES = [
    ("default", params(), 0.7),
    ("rough1", params(roughness=1.0), 0.3),
    ("metal_smoothish", params(metallic=1.0, roughness=0.1), 0.7),
    ("metal_grazing", params(metallic=1.0, roughness=0.3), 0.1),
    ("anisotropic", params(metallic=1.0, roughness=0.4, anisotropic=0.9), 0.6),
    ("sheen_clearcoat", params(roughness=0.8, sheen=1.0, sheen_tint=0.5, clearcoat=1.0,
                               clearcoat_gloss=0.7), 0.5),
    ("subsurface_tint", params(flatness=1.0, spec_tint=1.0), 0.4),
    ("glass_front", params(transmission=1.0, roughness=0.3), 0.8),
    ("glass_inside", params(transmission=1.0, roughness=0.3), -0.8),
    ("glass_inside_tir", params(transmission=1.0, roughness=0.4), -0.3),
    ("eta_below_1", params(transmission=1.0, roughness=0.35, eta=0.7), 0.6),
    ("eta_3", params(transmission=1.0, roughness=0.5, eta=3.0), 0.5),
    ("mix", params(transmission=0.5, roughness=0.6, metallic=0.2, clearcoat=0.5,
                   anisotropic=0.5, sheen=0.5), 0.7),
    ("mix_inside", params(transmission=0.7, roughness=0.5, anisotropic=0.3), -0.6),
    ("rough_glass", params(transmission=1.0, roughness=1.0), 0.5),
]


@pytest.mark.parametrize("name,p,cos_o", CASES, ids=[c[0] for c in CASES])
def test_principled_chi2(name, p, cos_o):
    wo = direction(cos_o)
    n_cos, n_phi, n = 48, 96, 400_000
    h, bad = _sample_hist(p, wo, n, 11, n_cos, n_phi)
    assert bad == 0, "sample disagrees with eval/pdf"
    integ = _pdf_integral(p, wo, n_cos, n_phi, 12)
    total = integ.sum()
    # The pdf integrates to the probability of producing a sample (< 1 where samples
    # are absorbed, e.g. microfacet reflections that leave below the horizon).
    assert total <= 1.0 + 2e-3
    assert h.sum() / n == pytest.approx(total, abs=5e-3)
    chi2_test(h, integ * n)


def test_reflection_is_reciprocal():
    """f(wo, wi)/|cos_i| == f(wi, wo)/|cos_o| for the reflection lobes."""
    rng = np.random.default_rng(3)
    p = params(roughness=0.4, metallic=0.3, clearcoat=0.7, sheen=0.6, anisotropic=0.4)
    for _ in range(200):
        a = rng.normal(size=3)
        b = rng.normal(size=3)
        a[2] = abs(a[2])
        b[2] = abs(b[2])
        wo = tuple(F(x) for x in a / np.linalg.norm(a))
        wi = tuple(F(x) for x in b / np.linalg.norm(b))
        f1 = np.array(principled_eval(p, wo, wi)[0]) / wi[2]
        f2 = np.array(principled_eval(p, wi, wo)[0]) / wo[2]
        assert np.allclose(f1, f2, rtol=2e-3, atol=1e-6)


@njit(cache=True)
def _flux_albedo(p, wo, n, seed):
    """Directional albedo (mean weight), with transmitted weights converted from radiance to
    flux (times (eta_i / eta_t)^2), and its standard error."""
    eta = p[5]
    s = np.zeros(3)
    s2 = np.zeros(3)
    for i in range(n):
        k = path_key(i, 5, seed)
        wi, w, pdf = principled_sample(p, wo, sample_1d(k, 0), sample_1d(k, 1),
                                       sample_1d(k, 2))
        if pdf <= 0:
            continue
        c = 1.0
        if wi[2] * wo[2] < 0:
            c = eta * eta if wo[2] > 0 else 1.0 / (eta * eta)
        for j in range(3):
            x = w[j] * c
            s[j] += x
            s2[j] += x * x
    m = s / n
    return m, np.sqrt(np.maximum(s2 / n - m * m, 0.0) / n)


CONSERVING = [
    params(r=1, g=1, b=1, metallic=1.0, roughness=r, anisotropic=a)
    for r in (0.0, 0.3, 1.0) for a in (0.0, 0.9)] + [
    params(r=1, g=1, b=1, transmission=1.0, roughness=r, eta=e)
    for r in (0.0, 0.4, 1.0) for e in (1.0001, 1.5, 3.0, 0.7)] + [
    # Burley's diffuse without retro-reflection (roughness 0) and no specular
    params(r=1, g=1, b=1, roughness=0.0, eta=1.0)]


@pytest.mark.parametrize("p", CONSERVING)
def test_energy_conserving_corners(p):
    """Over parameter corners whose lobes are energy conserving (white metals of any
    roughness and anisotropy; clear glass of any roughness and index, from both sides;
    Burley's diffuse without retro-reflection), the BSDF never returns more than it
    receives: directional albedo <= 1 within noise at every angle, grazing included.
    (Burley's retro-reflective diffuse, the Hanrahan-Krueger subsurface flattening, sheen
    and clearcoat are not energy conserving, in Mitsuba as here; see docs/scene-format.md.)"""
    for cz in (1.0, 0.7, 0.3, 0.05, -0.3, -0.9):
        if cz < 0 and p[13] == 0:
            continue
        wo = direction(cz)
        m, se = _flux_albedo(p, wo, 100_000, 3)
        assert np.all(m <= 1.0 + 4 * se + 1e-4), (p, cz, m, se)


def _variant_kernel(lobes):
    """eval and sample of the BSDF compiled with ``lobes`` over arrays of parameters
    (n, 14), directions wo and wi (n, 3) and uniforms (n, 3): (n, 4) eval rows (f, pdf)
    and (n, 7) sample rows (wi, weight, pdf)."""
    eval_l, sample_l = make_principled(lobes)

    @njit(error_model="numpy")
    def run(P, WO, WI, U):
        n = P.shape[0]
        ev = np.zeros((n, 4), np.float32)
        sm = np.zeros((n, 7), np.float32)
        for i in range(n):
            q = P[i]
            p = (q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7], q[8], q[9], q[10], q[11],
                 q[12], q[13])
            wo = (WO[i, 0], WO[i, 1], WO[i, 2])
            wi = (WI[i, 0], WI[i, 1], WI[i, 2])
            f, pdf = eval_l(p, wo, wi)
            ev[i, 0], ev[i, 1], ev[i, 2], ev[i, 3] = f[0], f[1], f[2], pdf
            d, w, pdf = sample_l(p, wo, U[i, 0], U[i, 1], U[i, 2])
            sm[i, 0], sm[i, 1], sm[i, 2] = d[0], d[1], d[2]
            sm[i, 3], sm[i, 4], sm[i, 5], sm[i, 6] = w[0], w[1], w[2], pdf
        return ev, sm
    return run


# Lobes field: the parameter values of materials without it
LOBE_OFF = {"dielectric": {"metallic": 1.0},
            "clearcoat": {"clearcoat": 0.0, "clearcoat_gloss": 0.0},
            "sheen": {"sheen": 0.0, "sheen_tint": 0.0}, "transmission": {"transmission": 0.0},
            "flatness": {"flatness": 0.0}, "spec_tint": {"spec_tint": 0.0},
            "anisotropic": {"anisotropic": 0.0}}
# the cases: the lobes compiled in (every lobe off but the dielectric part; that and one
# more; all but the dielectric part: metals)
LOBE_CASES = ([("dielectric",)] + [("dielectric", f) for f in list(LOBE_OFF)[1:]] +
              [tuple(list(LOBE_OFF)[1:])])


def test_lobe_flags_reach_the_bsdf_in_order():
    """Features' lobe flags, the Specialisation's lobes tuple and kernels.principled.Lobes
    name the same parts in the same order (make_scatter passes them on by position)."""
    from pathtracer.kernels.layout import Features, specialise
    assert Features._fields[-len(Lobes._fields):] == Lobes._fields
    for k, name in enumerate(Lobes._fields):
        f = Features(False, False, False, False, principled=True,
                     **{n: n == name for n in Lobes._fields})
        assert Lobes(*specialise(f).lobes) == Lobes(*(i == k for i in range(len(Lobes._fields))))


@pytest.mark.parametrize("on", LOBE_CASES, ids=["-".join(c) for c in LOBE_CASES])
def test_lobes_compiled_out_change_nothing(on):
    """The BSDF specialised for materials without some lobes (kernels compile only the
    lobes a scene uses) gives bit for bit the full BSDF's values and samples for such
    materials."""
    rng = np.random.default_rng(7)
    n = 4000
    P = rng.uniform(0, 1, (n, len(P_FIELDS))).astype(np.float32)
    P[:, P_FIELDS.index("eta")] = rng.choice([1.0, 1.33, 1.5, 2.4], n)
    for k in ("metallic", "transmission", "roughness"):   # the corners too
        P[rng.uniform(size=n) < 0.2, P_FIELDS.index(k)] = rng.choice([0.0, 1.0])
    lobes = Lobes(*(field in on for field in Lobes._fields))
    for field, values in LOBE_OFF.items():
        if field not in on:
            for name, value in values.items():
                P[:, P_FIELDS.index(name)] = value
    # (as the kernel's materials: a transmissive one never has eta 1, see surface.principled_at)
    eta = P[:, P_FIELDS.index("eta")]
    eta[(eta == 1.0) & (P[:, P_FIELDS.index("transmission")] > 0)] = 1.5
    WO = rng.normal(size=(n, 3))
    WI = rng.normal(size=(n, 3))
    WO = (WO / np.linalg.norm(WO, axis=1)[:, None]).astype(np.float32)
    WI = (WI / np.linalg.norm(WI, axis=1)[:, None]).astype(np.float32)
    WO[:n // 2, 2] = np.abs(WO[:n // 2, 2])     # mostly from outside, where all lobes live
    U = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    ev_full, sm_full = _variant_kernel(ALL_LOBES)(P, WO, WI, U)
    ev, sm = _variant_kernel(lobes)(P, WO, WI, U)
    assert np.array_equal(ev, ev_full, equal_nan=True)
    assert np.array_equal(sm, sm_full, equal_nan=True)
    assert (ev_full[:, 3] > 0).sum() > n // 4 and (sm_full[:, 6] > 0).sum() > n // 4


def test_lobe_choice_keeps_each_lobes_numbers_stratified():
    """The lobe is chosen by the direction's first number and that number stretched back
    (reuse_sample): numbers stratified one per 1/64 give each lobe numbers stratified one per
    1/(its count), which a separate lobe number would not."""
    rng = np.random.default_rng(3)
    u = (np.arange(64) + rng.random(64)) / 64
    shares = [(0.0, 0.5), (0.5, 0.25), (0.75, 0.25)]     # (start, width) of total 1
    for start, width in shares:
        mine = u[(u >= start) & (u < start + width)]
        got = np.array([reuse_sample(np.float32(x), np.float32(start), np.float32(width))
                        for x in mine])
        assert len(got) == round(64 * width)
        assert ((got >= 0) & (got < 1)).all()
        assert sorted(np.floor(got * len(got)).astype(int)) == list(range(len(got)))
    # a lobe number drawn apart: the diffuse lobe's direction numbers are not so spread
    pick = rng.random(64) < 0.5
    assert len(np.unique(np.floor(u[pick] * pick.sum()))) < pick.sum()
    assert reuse_sample(np.float32(1.0), np.float32(0.0), np.float32(1.0)) < 1.0
    # and principled_sample picks its lobe so: without transmission the third number
    # changes nothing (with a separate lobe number it chose between diffuse and specular)
    p = params(clearcoat=0.5, sheen=0.3)
    wo = direction(0.6)
    for u1, u2 in rng.random((32, 2)).astype(np.float32):
        a = principled_sample(p, wo, np.float32(0.05), u1, u2)
        b = principled_sample(p, wo, np.float32(0.95), u1, u2)
        assert np.array_equal(np.array(a[0] + a[1] + (a[2],)), np.array(b[0] + b[1] + (b[2],)))
