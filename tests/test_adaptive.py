"""Adaptive sampling (render(..., adaptive=target), --adaptive): pixels stop when their
estimated relMSE is below their share of the target (in proportion to their noise), each
pixel is the mean of its own samples, and the image agrees with uniform sampling."""
import os

import numpy as np

from pathtracer.backends import make_backend
from pathtracer.film import relmse
from pathtracer.progressive import ADAPTIVE_MIN_SPP, RELMSE_EPS, error_estimate, render
from pathtracer.scene import compile_scene, load_scene_description
from tests.conftest import ROOT


def _cornell(res=32):
    desc = load_scene_description(os.path.join(ROOT, "scenes", "cornell-box.json"))
    desc.camera.resolution = (res, res)
    return compile_scene(desc)


def test_adaptive_stops_converged_pixels_and_agrees_with_uniform():
    scene = _cornell()
    backend = make_backend("cpu", scene)
    uniform = render(scene, backend, spp=256, seed=1)
    adaptive = render(scene, backend, spp=256, seed=2, adaptive=1e-3)
    count = adaptive.film.count
    # the least noisy pixels stop early, the noisiest run to the spp limit
    assert count.min() >= ADAPTIVE_MIN_SPP and count.min() < 128
    assert count.max() == 256 and adaptive.film.spp == 256
    assert adaptive.film.camera_rays < 0.9 * uniform.film.camera_rays
    # the same image: the difference is what the noise of the two allows
    a, u = adaptive.film.image(), uniform.film.image()
    assert relmse(a, u) < 1e-2, relmse(a, u)
    assert abs(a.mean() - u.mean()) < 0.01 * u.mean()
    assert adaptive.film.nonfinite == 0


def test_samples_go_in_proportion_to_the_noise():
    """Neyman allocation (progressive.stop_threshold): a pixel's samples grow with its
    estimated standard deviation per sample, sigma; between the groups of pixels that
    stopped after 62, 126 and 254 samples, sigma doubles as the samples do (within 30 %)."""
    scene = _cornell()
    film = render(scene, make_backend("cpu", scene), spp=256, seed=2, adaptive=1e-3).film
    sigma = np.sqrt(error_estimate(film) * film.count)
    groups = [(n, np.median(sigma[film.count == n])) for n in np.unique(film.count)
              if n < film.spp and (film.count == n).sum() >= 20]
    assert len(groups) >= 2, groups
    for (n0, s0), (n1, s1) in zip(groups, groups[1:]):
        assert 0.7 < (s1 / s0) / (n1 / n0) < 1.3, groups


def test_error_estimate_tracks_the_true_error():
    """The estimate (from the two halves of every pass) is the relMSE against a much
    longer render to within a factor of 2 on average."""
    scene = _cornell(24)
    backend = make_backend("cpu", scene)
    ref = render(scene, backend, spp=2048, seed=9).film.image()
    film = render(scene, backend, spp=64, seed=3, adaptive=1e-12).film
    est = error_estimate(film).mean()
    true = relmse(film.image(), ref)
    assert 0.5 < est / true < 2.0, (est, true)


def test_target_reached_ends_the_render():
    """When every pixel has stopped, the image's estimated mean relMSE is at most the
    target (each pixel stopped below target * sigma_i / mean(sigma))."""
    scene = _cornell(16)
    result = render(scene, make_backend("cpu", scene), spp=1 << 20, adaptive=5e-3)
    assert result.film.spp < 1 << 20
    assert result.film.count.min() >= ADAPTIVE_MIN_SPP
    assert error_estimate(result.film).mean() <= 5e-3


def _error_estimate_reference(film):
    """progressive.error_estimate as first written, plainly (before it was rewritten
    for speed)."""
    count_b = np.maximum(film.count_b, 1)[..., None]
    count_a = np.maximum(film.count - film.count_b, 1)[..., None]
    b = film.sum_b / count_b
    a = (film.sum - film.sum_b) / count_a
    mean = film.sum / np.maximum(film.count, 1)[..., None]
    q = ((a - b) ** 2 / 4 / (mean * mean + RELMSE_EPS)).mean(axis=2)
    padded = np.pad(q, 1, mode="edge")
    h, w = q.shape
    return sum(padded[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)) / 9


def test_error_estimate_equals_its_first_form():
    """error_estimate is written for speed (in place on whole arrays, a separable 3 x 3 mean);
    it must give what the first, plain form gives, up to rounding, including pixels that
    stopped (fewer samples) and black ones."""
    from pathtracer.film import Film
    rng = np.random.default_rng(5)
    film = Film(37, 53)
    stats = np.zeros((1, 1, 3), np.int64)
    for k in range(4):
        active = None if k < 2 else (rng.random((37, 53)) < 0.6).astype(np.uint8)
        part = (rng.random((37, 53, 3)) ** 6 * 40).astype(np.float32)
        part[:5] = 0.0
        film.add(part, stats, 8, active, half_b=k % 2 == 1)
    got, want = error_estimate(film), _error_estimate_reference(film)
    assert got.shape == want.shape == (37, 53)
    assert np.allclose(got, want, rtol=1e-12, atol=0)
    assert want.max() > 0


def test_film_add_sums_what_numpy_sums():
    """Film.add (one Numba loop) adds a pass to the sums, the counts of the pixels that
    took part, and for a second half also to sum_b / count_b, as the plain NumPy form
    does; a pass of another shape is refused, not read out of bounds."""
    import pytest
    from pathtracer.film import Film
    rng = np.random.default_rng(11)
    film = Film(5, 7)
    want_sum = np.zeros((5, 7, 3))
    want_count = np.zeros((5, 7), np.int64)
    want_sum_b = np.zeros((5, 7, 3))
    want_count_b = np.zeros((5, 7), np.int64)
    stats = np.ones((5, 7, 3), np.int32)
    for k in range(6):
        active = None if k < 2 else (rng.random((5, 7)) < 0.5).astype(np.uint8)
        part = rng.random((5, 7, 3)).astype(np.float32)
        if active is not None:
            part *= active[..., None]
        film.add(part, stats, 4, active, half_b=k % 2 == 1)
        added = 4 if active is None else 4 * (active != 0)
        want_sum += part
        want_count += added
        if k % 2 == 1:
            want_sum_b += part
            want_count_b += added
    assert np.array_equal(film.sum, want_sum) and np.array_equal(film.count, want_count)
    assert np.array_equal(film.sum_b, want_sum_b)
    assert np.array_equal(film.count_b, want_count_b)
    assert film.spp == 24 and film.bounce_rays == 6 * 35
    with pytest.raises(ValueError):
        film.add(np.zeros((7, 5, 3), np.float32), stats, 1)
    with pytest.raises(ValueError):
        film.add(np.zeros((5, 7, 3), np.float32), stats, 1, np.ones((7, 5), np.uint8))


def test_a_uniform_film_is_not_continued_adaptively():
    """A film rendered without adaptive sampling has no halves to estimate the error from:
    continuing it adaptively is refused with a message, not a Numba typing error."""
    import pytest
    scene = _cornell(16)
    backend = make_backend("cpu", scene)
    film = render(scene, backend, spp=32).film
    with pytest.raises(ValueError, match="without adaptive sampling"):
        render(scene, backend, spp=64, adaptive=1e-3, film=film)
    # an adaptive film goes on adaptively
    film = render(scene, backend, spp=32, adaptive=1e-3).film
    assert render(scene, backend, spp=64, adaptive=1e-3, film=film).film.spp <= 64


def test_adaptive_first_pass_takes_first_pass_in_halves():
    """An adaptive render's first pass is ``first_pass`` samples (two halves), at least 2
    and at most ADAPTIVE_MIN_SPP (no pixel is judged before that many)."""
    scene = _cornell(24)
    backend = make_backend("cpu", scene)
    for first, expected in ((1, 2), (2, 2), (8, 8), (64, ADAPTIVE_MIN_SPP)):
        r = render(scene, backend, spp=64, seed=1, adaptive=1e-3, first_pass=first)
        assert r.passes[0][1] == expected, first
