"""The Python API (docs/python-api.md): scenes from dicts, scene.set without recompiling,
results, callbacks; the page's examples are run as written."""
import os
import re

import numpy as np
import pytest

import pathtracer as pt
from pathtracer.backends import cpu as cpu_backend
from tests.conftest import ROOT
from tests.helpers import box_mesh

QUAD = {"vertices": [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]],
        "faces": [[0, 2, 1], [0, 3, 2]]}


def room(emission=(4.0, 3.0, 2.0)):
    """A floor, a box and a quad lamp: diffuse only (the same kernel features as the
    Cornell box: triangle lights, Sobol sampler)."""
    v, f = box_mesh(0.4)
    return {
        "camera": {"resolution": [24, 18], "position": [0, 1, 3.5], "lookAt": [0, 0.5, 0],
                   "fov": 45},
        "render": {"spp": 16, "maxBounces": 4, "seed": 3},
        "materials": [{"name": "white", "type": "diffuse", "albedo": [0.7, 0.6, 0.5]},
                      {"name": "light", "type": "diffuse", "albedo": 0,
                       "emission": list(emission)}],
        "objects": [
            {"name": "floor", **QUAD, "material": "white", "transform": {"scale": [4, 1, 4]}},
            {"name": "box", "vertices": v, "faces": f, "material": "white",
             "transform": {"rotate": [0, 30, 0], "translate": [0, 0.4, 0]}},
            {"name": "lamp", **QUAD, "material": "light",
             "transform": {"scale": 0.5, "rotate": [180, 0, 0], "translate": [0, 2.5, 0]}},
        ],
    }


def kernel_state(scene):
    """What would show a compile: the CPU kernel factory's cache and the kernel's
    compiled signatures."""
    info = cpu_backend.pass_kernel.cache_info()
    kernel = cpu_backend.pass_kernel(scene.features)
    return info.misses, len(kernel.overloads)


def test_emission_twice_exactly_twice_the_image_without_compiling():
    scene = pt.load_scene(room())
    first = pt.render(scene, spp=8, backend="cpu")
    state = kernel_state(scene)
    scene.set("/materials/light/emission", [8.0, 6.0, 4.0])
    assert scene.last_update["bvh"] == "reused"
    second = pt.render(scene, spp=8, backend="cpu")
    assert second.compile_seconds == 0.0
    assert kernel_state(scene) == state
    assert first.image.max() > 0
    # doubling the emission doubles every sample exactly (a power of two): same seed,
    # same random numbers, so the image is exactly twice as bright
    assert np.array_equal(second.image, 2 * first.image)


def test_camera_move_changes_the_image_without_compiling():
    scene = pt.load_scene(room())
    first = pt.render(scene, spp=4, backend="cpu")
    state = kernel_state(scene)
    scene.set("/camera/position", [0.8, 1.4, 3.2])
    assert scene.last_update["bvh"] == "reused"
    moved = pt.render(scene, spp=4, backend="cpu")
    assert moved.compile_seconds == 0.0 and kernel_state(scene) == state
    assert not np.allclose(moved.image, first.image)
    # and back: the same image as before, bit for bit
    scene.set("/camera/position", [0, 1, 3.5])
    assert np.array_equal(pt.render(scene, spp=4, backend="cpu").image, first.image)


def test_transform_rebuilds_the_bvh_and_matches_a_fresh_load():
    scene = pt.load_scene(room())
    pt.render(scene, spp=2, backend="cpu")
    scene.set("/objects/box/transform", {"rotate": [0, 75, 0], "translate": [0.3, 0.4, 0]})
    assert scene.last_update["bvh"] == "built"
    assert scene.last_update["bvh_seconds"] > 0
    changed = pt.render(scene, spp=4, backend="cpu")
    assert changed.compile_seconds == 0.0
    data = room()
    data["objects"][1]["transform"] = {"rotate": [0, 75, 0], "translate": [0.3, 0.4, 0]}
    fresh = pt.render(pt.load_scene(data), spp=4, backend="cpu")
    assert np.array_equal(changed.image, fresh.image)


def test_material_change_matches_a_fresh_load():
    scene = pt.load_scene(room())
    scene.update({"/materials/white/albedo": [0.2, 0.8, 0.3], "/render/maxBounces": 2})
    data = room()
    data["materials"][0]["albedo"] = [0.2, 0.8, 0.3]
    data["render"]["maxBounces"] = 2
    assert np.array_equal(pt.render(scene, spp=4, backend="cpu").image,
                          pt.render(pt.load_scene(data), spp=4, backend="cpu").image)


def test_set_validates_like_the_file_and_leaves_the_scene_on_error():
    scene = pt.load_scene(room())
    before = scene.data
    with pytest.raises(pt.SceneError, match=r"<scene dict>: /materials/1/emission: "):
        scene.set("/materials/light/emission", [-1, 0, 0])
    with pytest.raises(pt.SceneError, match=r"no item named 'nope' \(names: white, light\)"):
        scene.set("/materials/nope/albedo", 0.5)
    with pytest.raises(pt.SceneError, match=r"/camera/bogus: unknown key 'bogus'"):
        scene.set("/camera/bogus", 1)
    with pytest.raises(pt.SceneError, match="expected a JSON path"):
        scene.set("camera/position", [0, 0, 0])
    assert scene.data == before
    assert scene.get("/materials/light/emission") == [4.0, 3.0, 2.0]
    assert scene.get("/objects/2/name") == "lamp"


def test_numpy_values_and_removing_a_key():
    scene = pt.load_scene(room())
    scene.set("/camera/position", np.array([0.0, 1.0, 3.0], np.float32))
    assert scene.get("/camera/position") == [0.0, 1.0, 3.0]
    scene.set("/render/seed", None)           # the default applies
    assert scene.seed == 0


def test_callback_stops_the_render_and_sees_progress():
    scene = pt.load_scene(room())
    seen = []

    def cb(p):
        assert p.image().shape == (18, 24, 3)
        assert 0 < p.fraction <= 1 and p.samples_per_second > 0
        seen.append(p.spp)
        return p.spp < 4
    r = pt.render(scene, spp=4096, backend="cpu", callback=cb)
    assert r.interrupted and r.spp == seen[-1] and 4 <= r.spp < 4096
    assert seen == sorted(seen)
    assert seen[0] == 1          # the CPU's first seen pass: one sample per pixel


def test_first_pass_spp():
    """A render's first pass: the largest power of 2 spp within the paths allowed and the
    samples asked for, at least 1 (api.PREVIEW_FIRST_PASS_PATHS, FIRST_PASS_PATHS)."""
    from pathtracer.api import first_pass_spp
    assert first_pass_spp(64, 256 * 256, 1 << 19) == 8
    assert first_pass_spp(64, 256 * 192, 1 << 19) == 8          # 10.7 would overshoot
    assert first_pass_spp(4, 256 * 256, 1 << 19) == 4            # no more than asked
    assert first_pass_spp(6, 256 * 256, 1 << 19) == 4
    assert first_pass_spp(None, 256 * 256, 1 << 19) == 8         # a time-limited render
    assert first_pass_spp(None, 1024 * 1024, 1 << 19) == 1       # never below 1
    assert first_pass_spp(4096, 432, 0) == 1
    assert first_pass_spp(1, 10, 1 << 30) == 1


@pytest.mark.skipif(not __import__("pathtracer.backends", fromlist=["x"]).cuda_available(),
                    reason="no CUDA GPU")
def test_cuda_callback_starts_with_a_pass_that_fills_the_gpu():
    from pathtracer.api import PREVIEW_FIRST_PASS_PATHS, first_pass_spp
    scene = pt.load_scene(room())
    seen = []

    def cb(p):
        seen.append(p.spp)
        return len(seen) < 3
    pt.render(scene, spp=4096, backend="cuda", callback=cb)
    first = first_pass_spp(4096, 24 * 18, PREVIEW_FIRST_PASS_PATHS["cuda"])
    assert first > 1 and seen[:2] == [first, 3 * first]


def test_result_save_and_repr_png(tmp_path):
    r = pt.render(room(), spp=2, backend="cpu")
    png = r._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    files = r.save(tmp_path / "a.png")
    assert [os.path.basename(f) for f in files] == ["a.png", "a.exr"]
    from pathtracer.film import read_image
    assert np.array_equal(read_image(str(tmp_path / "a.exr")), r.image)
    assert np.array_equal(r.display_image(), __import__("imageio.v3").v3.imread(files[0]))
    with pytest.raises(ValueError, match="unknown image format"):
        r.save(tmp_path / "a.jpg")


def test_render_argument_errors():
    scene = pt.load_scene(room())
    for kw, msg in (({"spp": 0}, "spp must be"), ({"seed": -1}, "seed must be"),
                    ({"time": float("nan")}, "time must be"),
                    ({"sampler": "halton"}, "sampler must be"),
                    ({"spp": 2.5}, "spp must be an integer")):
        with pytest.raises((ValueError, TypeError), match=msg):
            pt.render(scene, backend="cpu", **kw)
    with pytest.raises(TypeError, match="a path or a dict"):
        pt.load_scene(42)


@pytest.mark.skipif(not __import__("pathtracer.backends", fromlist=["x"]).cuda_available(),
                    reason="no CUDA GPU")
def test_cuda_set_and_rerender_without_compiling():
    """On the GPU: emission x2 gives exactly twice the image, a camera move a new one, and
    neither compiles (the backend and its kernel are kept; changed arrays re-uploaded)."""
    from pathtracer.backends import cuda as cuda_backend
    scene = pt.load_scene(room())
    first = pt.render(scene, spp=8, backend="cuda")
    misses = cuda_backend.pass_kernel.cache_info().misses
    scene.set("/materials/light/emission", [8.0, 6.0, 4.0])
    second = pt.render(scene, spp=8, backend="cuda")
    assert second.compile_seconds == 0.0
    assert np.array_equal(second.image, 2 * first.image)
    # only the arrays whose contents changed were uploaded again (the materials' table)
    (be, _), = scene._backends.values()
    kept = list(be.d_scene)
    scene.set("/materials/light/emission", [8.0, 6.0, 4.0])     # the same value again
    pt.render(scene, spp=1, backend="cuda")
    assert all(a is b for a, b in zip(be.d_scene, kept))
    scene.set("/camera/position", [0.8, 1.4, 3.2])
    moved = pt.render(scene, spp=8, backend="cuda")
    assert moved.compile_seconds == 0.0 and not np.allclose(moved.image, second.image)
    assert cuda_backend.pass_kernel.cache_info().misses == misses
    # the same images as the CPU's (one kernel source)
    cpu = pt.render(scene, spp=8, backend="cpu").image
    assert np.isclose(moved.image.sum(), cpu.sum(), rtol=1e-2)
    close = np.isclose(moved.image, cpu, rtol=1e-3, atol=1e-3 * float(cpu.max())).all(-1)
    assert close.mean() > 0.99      # a rounding may flip a rare discrete decision


def test_gpu_upload_skips_arrays_with_equal_contents():
    """The GPU backend's re-upload test is bitwise: equal copies are kept, a sign of zero
    or a dtype or shape change is not."""
    from pathtracer.backends.cuda import _same
    a = np.array([[0.0, 1.5], [2.0, 3.0]], np.float32)
    assert _same(a, a) and _same(a, a.copy()) and _same(a.T.copy().T, a)
    assert not _same(a, np.array([[-0.0, 1.5], [2.0, 3.0]], np.float32))
    assert not _same(a, a.astype(np.float64)) and not _same(a, a.reshape(-1))
    assert not _same(a, np.where(a == 3.0, np.nextafter(a, np.float32(4)), a))


def test_python_api_doc(tmp_path, monkeypatch):
    """Every python block of docs/python-api.md, in order, in one namespace, from the
    repository root (outputs redirected to a temporary folder)."""
    text = open(os.path.join(ROOT, "docs", "python-api.md"), encoding="utf-8").read()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 5
    os.symlink(os.path.join(ROOT, "scenes"), tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for i, code in enumerate(blocks):
        exec(compile(code, f"docs/python-api.md block {i + 1}", "exec"), namespace)
    assert (tmp_path / "cornell.png").exists() and (tmp_path / "cornell.exr").exists()
    means = namespace["means"]
    assert len(means) == 5 and all(m > 0 for m in means)


def test_recompile_keeps_textures_and_bvh_arrays():
    """A camera change re-uses the texels and the BVH arrays themselves (the GPU backend
    re-uploads only arrays that are new objects)."""
    scene = pt.load_scene(os.path.join(ROOT, "scenes", "textured.json"))
    before = scene.compiled.arrays
    scene.set("/camera/position", [0.2, 1.0, 3.0])
    after = scene.compiled.arrays
    for name in ("tex_data", "bvh_box", "bvh_child", "tri_v", "tri_n", "env_img", "env_cond"):
        assert getattr(after, name) is getattr(before, name), name
    assert after.cam is not before.cam


def test_wavefront_threshold_follows_the_scene_features():
    """Scenes with mip-mapped textures hand passes to the wavefront kernels from a lower
    size (kernels.drivers.wave_min_paths_for); the table needs no GPU."""
    from pathtracer.kernels.drivers import (WAVE_MIN_PATHS, WAVE_MIN_PATHS_MIPMAPS,
                                            wave_min_paths_for)
    plain = pt.load_scene(room()).compiled.features
    assert wave_min_paths_for(plain) == WAVE_MIN_PATHS
    textured = pt.load_scene(os.path.join(ROOT, "scenes", "textured.json")).compiled.features
    assert wave_min_paths_for(textured) == WAVE_MIN_PATHS_MIPMAPS < WAVE_MIN_PATHS
