"""Denoising: the albedo and normal images the renderer gives Open Image Denoise, the
denoiser's effect on error, and the command's outputs (CPU; pyoidn is a dependency)."""
import os
import subprocess
import sys

import numpy as np
import pytest

from pathtracer.backends import make_backend
from pathtracer.denoise import denoise
from pathtracer.errors import InputError
from pathtracer.film import read_image, relmse
from pathtracer.scene import load_scene
from tests.conftest import ROOT
from tests.helpers import box_mesh, furnace_scene, run, write_scene


def _wall_scene(wall, mirror=None, res=(24, 16)):
    """A camera on +z looking at a wall (a flat box face at z = -2) that fills the left
    half of the view; the right half sees a constant sky of 0.3 (blue 2.0). ``mirror``: a
    material between camera and wall, facing the camera, over the left half."""
    v, f = box_mesh()
    objects = [{"name": "wall", "vertices": v, "faces": f, "material": "wall",
                "transform": {"scale": [2, 4, 0.1], "translate": [-2, 0, -2.1]}}]
    materials = [dict(wall, name="wall")]
    if mirror is not None:
        materials.append(dict(mirror, name="mirror"))
        objects.append({"name": "mirror", "vertices": v, "faces": f, "material": "mirror",
                        "transform": {"scale": [2, 4, 0.01],
                                      "rotate": [0, 10, 0], "translate": [-2, 0, -1]}})
    return {"camera": {"resolution": list(res), "position": [0, 0, 3], "lookAt": [0, 0, 0],
                       "fov": 60},
            "render": {"spp": 4, "maxBounces": 2},
            "materials": materials, "objects": objects,
            "environment": {"color": [0.3, 0.3, 2.0]}}


def test_albedo_and_normal_images(tmp_path):
    """Where the camera sees the wall: its albedo and its normal (+z, towards the camera);
    where it sees the sky: the sky's radiance clamped to [0, 1] and a zero normal."""
    scene = load_scene(write_scene(tmp_path, _wall_scene(
        {"type": "diffuse", "albedo": [0.2, 0.5, 0.8]})))
    aov = make_backend("cpu", scene).aovs(4, 0)
    left, right = aov[4:-4, :8], aov[4:-4, -6:]
    assert np.allclose(left[..., :3], [0.2, 0.5, 0.8], atol=1e-6)
    assert np.allclose(left[..., 3:], [0, 0, 1], atol=1e-5)
    assert np.allclose(right[..., :3], [0.3, 0.3, 1.0], atol=1e-6)
    assert np.allclose(right[..., 3:], 0)


def test_emitters_albedo_adds_their_radiance(tmp_path):
    """An emitting wall: its albedo image is its base colour plus its radiance, clamped to
    [0, 1] as the sky's is, so a light differs from a surface of the same colour around it
    (the denoiser keeps the light's edge)."""
    scene = load_scene(write_scene(tmp_path, _wall_scene(
        {"type": "diffuse", "albedo": [0.2, 0.5, 0.8], "emission": [0.1, 0.15, 3.0],
         "twoSided": True})))
    aov = make_backend("cpu", scene).aovs(4, 0)
    assert np.allclose(aov[4:-4, :8, :3], [0.3, 0.65, 1.0], atol=1e-5)
    assert np.allclose(aov[4:-4, -6:, :3], [0.3, 0.3, 1.0], atol=1e-6)


def test_specular_surfaces_are_looked_through(tmp_path):
    """A smooth metal mirror in front of the wall: the albedo image shows the wall seen in
    the mirror (or the sky), not the mirror's base colour; a rough metal is a surface."""
    wall = {"type": "diffuse", "albedo": [0.2, 0.5, 0.8]}
    mirror = {"albedo": [0.9, 0.1, 0.1], "metallic": 1.0, "roughness": 0.0}
    aov = make_backend("cpu", load_scene(write_scene(
        tmp_path, _wall_scene(wall, mirror)))).aovs(4, 0)
    seen = aov[6:-6, 2:6, :3].reshape(-1, 3)
    assert not np.any(np.all(np.isclose(seen, [0.9, 0.1, 0.1], atol=1e-3), axis=1))
    rough = dict(mirror, roughness=0.5)
    aov = make_backend("cpu", load_scene(write_scene(
        tmp_path, _wall_scene(wall, rough), "rough.json"))).aovs(4, 0)
    assert np.allclose(aov[6:-6, 2:6, :3], [0.9, 0.1, 0.1], atol=1e-6)


def test_denoising_removes_most_of_the_noise(tmp_path):
    """A furnace whose every pixel is exactly 0.5 * (1 + 0.5 + 0.25) = 0.875: at 4 spp the
    denoised image is at least 2x closer to it than the raw one (relMSE; measured 2.6x: the
    normal image of the faceted sphere keeps the facets' edges, colour alone gives 9x)."""
    scene = load_scene(write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(64, 48))))
    raw = run(scene, "cpu", spp=4).film.image()
    aov = make_backend("cpu", scene).aovs(4, 0)
    truth = np.full_like(raw, 0.875)
    den = denoise(raw, aov)
    assert den.shape == raw.shape and den.dtype == np.float32
    assert relmse(den, truth) < relmse(raw, truth) / 2, (relmse(den, truth),
                                                         relmse(raw, truth))


def _pt_render(*args, env=None):
    return subprocess.run([sys.executable, "-m", "pathtracer", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, env=env)


def test_command_writes_denoised_raw_and_aovs(tmp_path):
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(32, 24)))
    out = tmp_path / "img.png"
    r = _pt_render(scene, "-o", out, "--spp", 4, "--denoise", "--aovs", "--quiet",
                   "--backend", "cpu")
    assert r.returncode == 0, r.stderr
    for name in ("img.png", "img.exr", "img-raw.png", "img-raw.exr", "img-albedo.exr",
                 "img-normal.exr"):
        assert (tmp_path / name).exists(), name
    den, raw = read_image(str(tmp_path / "img.exr")), read_image(str(tmp_path / "img-raw.exr"))
    # the plumbing (the denoiser's effect is measured above and in the benchmark)
    assert np.isfinite(den).all() and not np.array_equal(den, raw)
    assert abs(den.mean() - 0.875) < 0.05 and abs(raw.mean() - 0.875) < 0.05
    # (the shell emits: albedo 0.5 plus radiance 0.5)
    assert np.allclose(read_image(str(tmp_path / "img-albedo.exr")), 1.0, atol=1e-6)
    assert "denoised" in r.stderr


@pytest.mark.parametrize("flag", ["--denoise"])
def test_missing_denoiser_is_a_one_line_error(tmp_path, flag):
    """Without a loadable pyoidn, --denoise fails before rendering, in one line, exit 2."""
    fake = tmp_path / "fake"
    fake.mkdir()
    (fake / "pyoidn.py").write_text("raise ImportError('libOpenImageDenoise.so: not found')\n")
    env = dict(os.environ, PYTHONPATH=f"{fake}{os.pathsep}{ROOT}")
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(8, 8)))
    r = _pt_render(scene, "-o", tmp_path / "x.png", flag, env=env)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "pyoidn" in lines[0], r.stderr
    assert not (tmp_path / "x.png").exists()


def test_denoise_device_follows_the_render():
    """auto: the CPU unless the render runs on CUDA and OIDN's CUDA device runs here;
    cpu is always the CPU; an unknown name is an input error."""
    from pathtracer.denoise import cuda_denoiser_available, resolve_device
    assert resolve_device("auto", "cpu") == "cpu"
    assert resolve_device("cpu", "cuda") == "cpu"
    assert resolve_device("auto", "cuda") == ("cuda" if cuda_denoiser_available() else "cpu")
    with pytest.raises(InputError):
        resolve_device("gpu", "cuda")


def test_cuda_denoiser_without_a_gpu_is_a_one_line_error(tmp_path):
    """--denoise-device cuda where OIDN's CUDA device cannot run: exit 2 before rendering,
    one line that names the way out, nothing written."""
    from pathtracer.denoise import cuda_denoiser_available
    if cuda_denoiser_available():
        pytest.skip("OIDN's CUDA device runs here (tests/test_gpu.py uses it)")
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(8, 8)))
    r = _pt_render(scene, "-o", tmp_path / "x.png", "--denoise", "--denoise-device", "cuda",
                   "--backend", "cpu")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--denoise-device cpu" in lines[0], r.stderr
    assert not (tmp_path / "x.png").exists()


def test_a_failing_gpu_denoiser_falls_back_to_the_cpu(tmp_path, monkeypatch):
    """When OIDN's CUDA device fails mid-render (say, no GPU memory left for a large image),
    the save warns once and denoises on the CPU from then on, instead of stopping the
    render at a save."""
    import pathtracer.denoise as dn
    calls = []

    def broken(*args):
        calls.append(1)
        raise RuntimeError("Open Image Denoise (CUDA), execution: out of memory")
    monkeypatch.setattr(dn, "_denoise_cuda", broken)
    monkeypatch.setattr(dn, "_cuda_failed", [])
    scene = load_scene(write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(24, 16))))
    raw = run(scene, "cpu", spp=2).film.image()
    aov = make_backend("cpu", scene).aovs(2, 0)
    with pytest.warns(UserWarning, match="denoising on the CPU instead"):
        first = denoise(raw, aov, "cuda")
    assert np.array_equal(first, denoise(raw, aov, "cpu"))
    assert np.array_equal(denoise(raw, aov, "cuda"), first) and len(calls) == 1
