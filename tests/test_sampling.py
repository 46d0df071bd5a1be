"""Chi-square tests of every sampling routine against its density (Mitsuba chi2.py style:
histogram of samples vs the pdf integrated over each cell, low-expectation cells pooled)."""
import numpy as np
import pytest
from numba import njit

from pathtracer.kernels.lights import sample_discrete, sample_triangle_point
from pathtracer.kernels.search import last_at_most
from pathtracer.kernels.materials import diffuse_eval_local, diffuse_sample_local
from pathtracer.kernels.vec import frame, to_world
from pathtracer.kernels.rng import path_key, sample_1d
from pathtracer.kernels.warps import (power_heuristic, square_to_cosine_hemisphere,
                                      square_to_disk_concentric)
from tests.helpers import chi2_test

N = 200_000


@njit(cache=True)
def _uniforms(n, seed):
    out = np.empty((n, 2), np.float32)
    for i in range(n):
        k = path_key(i, 0, seed)
        out[i, 0] = sample_1d(k, 0)
        out[i, 1] = sample_1d(k, 1)
    return out


@njit(cache=True)
def _cosine_dirs(u, n):
    out = np.empty((u.shape[0], 3), np.float32)
    pdf = np.empty(u.shape[0], np.float32)
    ng = (n[0], n[1], n[2])
    t, s = frame(ng)
    albedo = (np.float32(1), np.float32(1), np.float32(1))
    up = (np.float32(0), np.float32(0), np.float32(1))
    for i in range(u.shape[0]):
        local, w, p = diffuse_sample_local(albedo, up, u[i, 0], u[i, 1])
        wi = to_world(local, t, s, ng)
        out[i, 0] = wi[0]
        out[i, 1] = wi[1]
        out[i, 2] = wi[2]
        pdf[i] = p
    return out, pdf


@pytest.mark.parametrize("normal", [(0, 0, 1), (0, 1, 0), (0, -1, 0), (0, 0, -1),
                                    (0.6, 0.0, -0.8), (0.267, -0.535, 0.802)])
def test_cosine_hemisphere_chi2(normal):
    """Cosine sampling around any normal, including +-Y where the thesis frame collapsed."""
    n = np.array(normal, np.float32)
    n /= np.linalg.norm(n)
    u = _uniforms(N, 3)
    d, pdf = _cosine_dirs(u, n)
    assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-5)
    cos = d @ n
    assert (cos > 0).all() and np.allclose(pdf, cos / np.pi, rtol=1e-4, atol=1e-7)
    # Histogram in (cos theta, phi) about the normal; expected mass per cell analytic.
    t = np.cross(n, [1, 0, 0] if abs(n[0]) < 0.9 else [0, 1, 0])
    t /= np.linalg.norm(t)
    s = np.cross(n, t)
    phi = np.arctan2(d @ s, d @ t) % (2 * np.pi)
    nc, nphi = 10, 20
    h, _, _ = np.histogram2d(cos, phi, bins=[nc, nphi], range=[[0, 1], [0, 2 * np.pi]])
    edges = np.linspace(0, 1, nc + 1)
    mass_c = np.diff(edges ** 2)           # P(cos < c) = c^2 for cosine-weighted
    expected = np.outer(mass_c, np.full(nphi, 1 / nphi)) * N
    chi2_test(h, expected)


def test_diffuse_weight_is_eval_over_pdf():
    albedo = (np.float32(0.3), np.float32(0.6), np.float32(0.9))
    n = (np.float32(0), np.float32(0), np.float32(1))
    u = _uniforms(1000, 9)
    for u1, u2 in u:
        wi, weight, pdf = diffuse_sample_local(albedo, n, u1, u2)
        f, pdf2 = diffuse_eval_local(albedo, n, wi)
        assert pdf == pytest.approx(pdf2, rel=1e-5)
        assert np.allclose(np.array(f) / pdf, weight, rtol=1e-4)


def test_concentric_disk_uniform():
    u = _uniforms(N, 4)
    xy = np.array([square_to_disk_concentric(a, b) for a, b in u[:50000]])
    assert (np.hypot(xy[:, 0], xy[:, 1]) <= 1 + 1e-6).all()
    r2 = np.hypot(xy[:, 0], xy[:, 1]) ** 2
    phi = np.arctan2(xy[:, 1], xy[:, 0]) % (2 * np.pi)
    h, _, _ = np.histogram2d(r2, phi, bins=[8, 16], range=[[0, 1], [0, 2 * np.pi]])
    chi2_test(h, np.full((8, 16), len(xy) / 128))
    z = np.array([square_to_cosine_hemisphere(a, b)[2] for a, b in u[:2000]])
    assert (z >= 0).all()


def test_triangle_point_uniform():
    tri_v = np.array([[0, 0, 0, 2, 0, 0, 0.5, 1, 0]], np.float32)
    u = _uniforms(60000, 5)
    pts = np.array([sample_triangle_point(tri_v, 0, a, b)[0] for a, b in u])
    # Barycentric coordinates of the samples, histogrammed over a triangular grid: cells
    # of the square [0,1]^2 in (b1, b2) with b1 + b2 <= 1, area-uniform expected.
    m = np.array([[2, 0.5], [0, 1]])
    bary = np.linalg.solve(m, pts[:, :2].T).T
    assert (bary >= -1e-6).all() and (bary.sum(1) <= 1 + 1e-6).all()
    k = 8
    h, _, _ = np.histogram2d(bary[:, 0], bary[:, 1], bins=[k, k], range=[[0, 1], [0, 1]])
    # expected area of each cell inside the triangle b1 + b2 <= 1, by fine subsampling
    g = (np.arange(64) + 0.5) / 64 / k
    area = np.zeros((k, k))
    for i in range(k):
        for j in range(k):
            a, b = i / k + g[:, None], j / k + g[None, :]
            area[i, j] = ((a + b) <= 1).mean() / (k * k)
    chi2_test(h, area / 0.5 * len(pts))
    _, normal, tri_area = sample_triangle_point(tri_v, 0, np.float32(0.3), np.float32(0.4))
    assert tri_area == pytest.approx(1.0) and np.allclose(normal, [0, 0, 1])


def test_discrete_sampling_matches_pmf():
    weights = np.array([0.0, 1.0, 0.0, 3.0, 0.5, 0.0, 2.0], np.float64)
    cdf = np.zeros(len(weights) + 1)
    cdf[1:] = np.cumsum(weights) / weights.sum()
    cdf = cdf.astype(np.float32)
    u = _uniforms(N, 6)[:, 0]
    idx = np.array([sample_discrete(cdf, x) for x in u[:100000]])
    counts = np.bincount(idx, minlength=len(weights))
    assert counts[weights == 0].sum() == 0          # zero-probability entries never chosen
    chi2_test(counts, np.diff(cdf.astype(float)) * len(idx))
    assert sample_discrete(cdf, np.float32(0.0)) == 1
    assert sample_discrete(cdf, np.float32(np.nextafter(np.float32(1), np.float32(0)))) == 6


@njit   # not cached: inspect_asm needs a fresh compile (a cached copy has no assembly)
def _branch_free_picks(cdf, u):
    out = np.empty(u.shape[0], np.int64)
    for i in range(u.shape[0]):
        out[i] = last_at_most(cdf, u[i])
    return out


def test_branch_free_search_is_the_bisection():
    """The CPU's light pick (search.last_at_most, compiled with a cmov) gives
    sample_discrete's index for every u: tables of 2 to 40 entries with runs of zero
    probability, u at and between the entries (ties go to the last equal entry), and NaN
    (index 0, as the bisection)."""
    rng = np.random.default_rng(3)
    for n in list(range(2, 12)) + [17, 40]:
        w = rng.random(n - 1) * (rng.random(n - 1) < 0.6)
        w[rng.integers(n - 1)] = 1.0
        cdf = np.concatenate([[0.0], np.cumsum(w) / w.sum()]).astype(np.float32)
        cdf[-1] = 1.0
        u = np.concatenate([rng.random(500).astype(np.float32), cdf[:-1],
                            np.nextafter(cdf[1:-1], np.float32(0)), [np.float32(np.nan)]])
        want = np.array([sample_discrete(cdf, x) for x in u])
        assert np.array_equal(_branch_free_picks(cdf, u), want)
        assert np.array_equal([last_at_most(cdf, x) for x in u], want)    # interpreted
    assert "cmov" in "".join(_branch_free_picks.inspect_asm().values())


def test_power_heuristic_limits():
    f = np.float32
    assert power_heuristic(f(1), f(1)) == pytest.approx(0.5)
    assert power_heuristic(f(np.inf), f(2)) == 1.0
    assert power_heuristic(f(2), f(np.inf)) == 0.0
    assert power_heuristic(f(0), f(0)) == 0.0
    assert power_heuristic(f(3), f(0)) == 1.0


def test_float32_sincos():
    from pathtracer.kernels.warps import sincos
    xs = np.linspace(-2 * np.pi, 2 * np.pi, 20001).astype(np.float32)
    got = np.array([sincos(x) for x in xs])
    assert np.abs(got[:, 0] - np.sin(xs.astype(float))).max() < 5e-7
    assert np.abs(got[:, 1] - np.cos(xs.astype(float))).max() < 5e-7
