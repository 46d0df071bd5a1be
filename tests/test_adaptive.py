"""Adaptive sampling (render(..., adaptive=target), --adaptive): pixels stop when their
estimated relMSE is below the target, each pixel is the mean of its own samples, and the
image agrees with uniform sampling."""
import os

from pathtracer.backends import make_backend
from pathtracer.film import relmse
from pathtracer.progressive import ADAPTIVE_MIN_SPP, error_estimate, render
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
    adaptive = render(scene, backend, spp=256, seed=2, adaptive=3e-3)
    count = adaptive.film.count
    # the light seen directly has no noise: those pixels stop at the first check
    assert count.min() >= ADAPTIVE_MIN_SPP and count.min() < 64
    assert count.max() == 256 and adaptive.film.spp == 256
    assert adaptive.film.camera_rays < 0.8 * uniform.film.camera_rays
    # the same image: the difference is what the noise of the two allows
    a, u = adaptive.film.image(), uniform.film.image()
    assert relmse(a, u) < 1e-2, relmse(a, u)
    assert abs(a.mean() - u.mean()) < 0.01 * u.mean()
    assert adaptive.film.nonfinite == 0


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
    scene = _cornell(16)
    result = render(scene, make_backend("cpu", scene), spp=1 << 20, adaptive=5e-2)
    assert result.film.spp < 1 << 20
    assert result.film.count.min() >= ADAPTIVE_MIN_SPP
