"""Checks that need a real CUDA GPU (skipped elsewhere; run on the device machine)."""
import numpy as np

from pathtracer.kernels.rng import path_key, sample_1d, sample_sobol
from tests.conftest import gpu
from tests.helpers import (GOLDEN, GOLDEN_SOBOL, golden_python_values as _python_values,
                           golden_sobol_python_values)


@gpu
def test_rng_identical_on_gpu():
    from numba import cuda

    @cuda.jit
    def k(args, out):
        i = cuda.grid(1)
        if i < args.shape[0]:
            out[i] = sample_1d(path_key(args[i, 0], args[i, 1], args[i, 3]), args[i, 2])

    args = np.array(GOLDEN, np.int64)
    out = np.zeros(len(args), np.float32)
    k[1, 32](args, out)
    assert np.array_equal(out, np.array(_python_values(), np.float32))


@gpu
def test_sobol_identical_on_gpu():
    from numba import cuda

    @cuda.jit
    def k(args, out):
        i = cuda.grid(1)
        if i < args.shape[0]:
            out[i] = sample_sobol(np.uint64(args[i, 0]), args[i, 1], args[i, 2])

    args = np.array(GOLDEN_SOBOL, np.int64)
    out = np.zeros(len(args), np.float32)
    k[1, 32](args, out)
    assert np.array_equal(out, np.array(golden_sobol_python_values(), np.float32))


@gpu
def test_no_float64_in_ptx():
    """Kernel math is float32: no double-precision instruction in the render kernel."""
    import os

    from pathtracer.backends import make_backend
    from pathtracer.scene import load_scene
    from tests.conftest import ROOT
    scene = load_scene(os.path.join(ROOT, "scenes", "cornell-box.json"))
    backend = make_backend("cuda", scene)
    backend.compile()
    ptx = backend.ptx()
    f64 = [line for line in ptx.splitlines() if ".f64" in line]
    assert not f64, f64[:10]


def _full_feature_scene(tmp_path, alpha=True, conductor=True):
    """Every kernel feature at once: principled materials with textures (mirrored and
    clamped) and a normal map, emissive triangles, a point light, a tilted HDRI, smooth
    normals, a thin lens, vertex colours, hidden emitters, (``conductor``) an anisotropic
    Beckmann conductor and (``alpha``) a glTF quad with
    alphaMode BLEND (the wavefront renders every feature but alpha)."""
    import imageio.v3 as iio

    from tests.helpers import sphere_mesh, write_scene
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "a.png", rng.integers(0, 255, (8, 8, 3), dtype=np.uint8))
    iio.imwrite(tmp_path / "n.png", np.full((4, 4, 3), [128, 160, 230], np.uint8))
    np.save(tmp_path / "sky.npy", rng.random((16, 32, 3)).astype(np.float32) * 3)
    obj = tmp_path / "quad.obj"
    obj.write_text("v -3 -1 -3\nv 3 -1 -3\nv 3 -1 3\nv -3 -1 3\nvt 0 0\nvt 4 0\nvt 4 4\n"
                   "vt 0 4\nvn 0 1 0\nf 1/1/1 4/4/1 3/3/1\nf 1/1/1 3/3/1 2/2/1\n")
    v, f = sphere_mesh(10, 20)
    from tests.gltf_writers import Builder
    b = Builder()
    mat = b.material({"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 0.6],
                                               "metallicFactor": 0, "roughnessFactor": 0.6},
                      **({"alphaMode": "BLEND"} if alpha else {})})
    quad = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    b.node(mesh=b.mesh(quad, [[0, 2, 1], [0, 3, 2]], material=mat,
                       colors=[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0]]),
           translation=[-1.5, -0.5, 1])
    b.save(tmp_path / "vc.glb")
    c, s_ = np.cos(0.4), np.sin(0.4)
    scene = {
        "camera": {"resolution": [48, 32], "position": [0, 1, 5], "lookAt": [0, 0, 0],
                   "aperture": 8, "focusDistance": 5},
        "render": {"maxBounces": 6, "rrDepth": 2, "hideEmitters": True},
        "materials": [
            {"name": "floor", "albedo": {"texture": "a.png", "wrap": ["mirror", "clamp"]},
             "roughness": 0.4, "normalMap": "n.png", "anisotropic": 0.5,
             "specularTint": 0.5, "subsurface": 0.3},
            {"name": "glass", "transmission": 1, "roughness": 0.1, "eta": 1.5,
             "clearcoat": 0.5, "sheen": 0.3},
            {"name": "lamp", "type": "diffuse", "albedo": 0, "emission": 4, "oneSided": True}
        ] + ([{"name": "gold", "type": "conductor", "eta": [0.143, 0.375, 1.442],
               "k": [3.983, 2.386, 1.603], "alphaU": 0.3, "alphaV": 0.1,
               "distribution": "beckmann"}] if conductor else []),
        "objects": [
            {"name": "floor", "file": "quad.obj", "material": "floor"},
            {"name": "ball", "vertices": v, "faces": f, "material": "glass", "smooth": True},
            {"name": "lamp", "vertices": v, "faces": f, "material": "lamp",
             "transform": {"translate": [2, 2, 0], "scale": 0.3}},
            {"name": "coloured", "file": "vc.glb"},
            {"name": "metal", "vertices": v, "faces": f,
             "material": "gold" if conductor else "glass", "smooth": True,
             "transform": {"translate": [-2, 0.5, -1], "scale": 0.4}}],
        "lights": [{"position": [-2, 3, 1], "intensity": 5}],
        "environment": {"file": "sky.npy",
                        "matrix": [[1, 0, 0], [0, c, -s_], [0, s_, c]]},     # tilted about X
    }
    from pathtracer.scene import load_scene
    s = load_scene(write_scene(tmp_path, scene))
    # every flag but the constant-colour environment (the HDRI replaces it)
    assert all(v for k, v in s.features._asdict().items()
               if k not in ("environment", "alpha", "conductor")), s.features
    assert getattr(s.features, "conductor", False) == conductor
    assert getattr(s.features, "alpha", False) == alpha
    return s


@gpu
def test_no_float64_in_full_feature_ptx(tmp_path):
    from pathtracer.backends import make_backend
    backend = make_backend("cuda", _full_feature_scene(tmp_path))
    backend.compile()
    f64 = [line for line in backend.ptx().splitlines() if ".f64" in line]
    assert not f64, f64[:10]


@gpu
def test_principled_eval_is_called_not_inlined(tmp_path):
    """backends.cuda.NOINLINE: the principled BSDF's evaluation stays one called function
    in the PTX of a scene with principled materials (the instruction-cache saving)."""
    from pathtracer.backends import make_backend
    from pathtracer.backends.cuda import NOINLINE
    backend = make_backend("cuda", _full_feature_scene(tmp_path))
    backend.compile()
    import re
    ptx = backend.ptx()
    for name in NOINLINE:
        mark = re.escape(f"{len(name)}{name}")
        # (PTX puts a declaration's or a call's parts on several lines)
        funcs = re.findall(r"\.func\b[^{;]*?" + mark, ptx)
        calls = re.findall(r"\bcall(?:\.uni)?\b[^;]*?" + mark, ptx)
        assert funcs and calls, (name, len(funcs), len(calls))


@gpu
def test_full_feature_parity(tmp_path):
    """CPU and CUDA run the same code on a scene with every feature: same random numbers,
    images equal to float tolerance."""
    from pathtracer.backends import make_backend
    s = _full_feature_scene(tmp_path)
    a, sa = [x.copy() for x in make_backend("cpu", s).render_pass(0, 16, 1, 6, 2)]
    b, sb = [x.copy() for x in make_backend("cuda", s).render_pass(0, 16, 1, 6, 2)]
    assert np.isfinite(a).all() and np.isfinite(b).all()
    assert np.isclose(a.sum(), b.sum(), rtol=1e-3)
    close = np.isclose(a, b, rtol=1e-3, atol=1e-3 * max(1.0, float(a.max()))).all(-1)
    assert close.mean() > 0.99      # a rounding may flip a rare discrete decision


@gpu
def test_wavefront_equals_megakernel(tmp_path):
    """The wavefront kernels (backends.wavefront) and the megakernel run the same steps on
    the same random numbers and add a pixel's samples in the same order: the same image
    and ray counts, with the pass in one launch or in sample ranges, with the tail finished
    in one launch or every vertex launched apart, and with pixels left out."""
    from pathtracer.backends.cuda import CUDABackend
    s = _full_feature_scene(tmp_path, alpha=False)
    mega = CUDABackend(s, wavefront=False)
    a, sa = [x.copy() for x in mega.render_pass(0, 16, 1, 6, 2)]
    active = np.ones((s.height, s.width), np.uint8)
    active[::3, ::2] = 0
    am, _ = [x.copy() for x in mega.render_pass(0, 16, 1, 6, 2, active)]
    for options in (dict(), dict(wave_levels=None), dict(max_paths=s.width * s.height * 5)):
        wave = CUDABackend(s, wavefront=options)
        b, sb = [x.copy() for x in wave.render_pass(0, 16, 1, 6, 2)]
        assert np.allclose(a, b, rtol=1e-5, atol=1e-6), (options, np.abs(a - b).max())
        assert (sa == sb).all(), options
        bm, _ = [x.copy() for x in wave.render_pass(0, 16, 1, 6, 2, active)]
        assert np.allclose(am, bm, rtol=1e-5, atol=1e-6), options
        assert (bm[active == 0] == 0).all()


@gpu
def test_launcher_launches_as_the_dispatcher():
    """backends.launch.Launcher: the kept packing is used for device arrays passed again,
    a new device array of the same type is packed anew, scalars change per launch, and
    another type or a host array goes through the dispatcher (a host array is copied back,
    as Numba does) without upsetting the launches after it."""
    from numba import cuda

    from pathtracer.backends.launch import Launcher

    @cuda.jit
    def axpy(out, x, a, add):
        i = cuda.grid(1)
        if i < out.shape[0]:
            out[i] = out[i] + a * x[i] if add else a * x[i]

    launch = Launcher(axpy)
    x = np.arange(100, dtype=np.float32)
    d_x, d_out = cuda.to_device(x), cuda.to_device(np.zeros(100, np.float32))
    launch(1, 128, d_out, d_x, np.float32(2.0), False)      # compiles, binds
    assert launch._kernel is not None
    launch(1, 128, d_out, d_x, np.float32(3.0), True)       # the kept packing
    assert np.array_equal(d_out.copy_to_host(), 5 * x)
    d_x2 = cuda.to_device(x + 1)                            # a new array: packed anew
    launch(1, 128, d_out, d_x2, np.float32(1.0), True)
    assert np.array_equal(d_out.copy_to_host(), 5 * x + x + 1)
    host = np.zeros(100, np.float32)                        # a host array: the dispatcher
    launch(1, 128, host, d_x, np.float32(2.0), False)
    assert np.array_equal(host, 2 * x)
    d64 = cuda.to_device(np.zeros(100, np.float64))         # another type: the dispatcher
    launch(1, 128, d64, cuda.to_device(x.astype(np.float64)), 0.5, False)
    assert np.array_equal(d64.copy_to_host(), 0.5 * x)
    launch(1, 128, d_out, d_x, np.float32(4.0), False)      # and back
    cuda.synchronize()
    assert np.array_equal(d_out.copy_to_host(), 4 * x)


@gpu
def test_kept_launches_render_as_the_dispatcher(tmp_path, monkeypatch):
    """Passes launched with the kept packing (the default) and through Numba's dispatcher
    (PT_RENDER_PLAIN_LAUNCH=1) give the same image and ray counts bit for bit, on the
    megakernel (sample groups summed) and the wavefront, over several passes."""
    from pathtracer.backends.cuda import CUDABackend
    s = _full_feature_scene(tmp_path)
    results = {}
    for plain in ("1", "0"):
        monkeypatch.setenv("PT_RENDER_PLAIN_LAUNCH", plain)
        for wavefront in (False, True):
            be = CUDABackend(s, wavefront=wavefront)
            for start, n in ((0, 1), (1, 2), (3, 16)):
                results[plain, wavefront, start] = [
                    x.copy() for x in be.render_pass(start, n, 1, 6, 2)]
            assert (be._launch_pass._kernel is not None) == (plain == "0" and not wavefront)
            if wavefront:       # (the extend kernel's launcher bound: the kept packing used)
                assert (be.wavefront._launchers[1]._kernel is not None) == (plain == "0")
    for (plain, wavefront, start), (a, sa) in results.items():
        if plain == "0":
            b, sb = results["1", wavefront, start]
            assert (a == b).all() and (sa == sb).all(), (wavefront, start)


@gpu
def test_adaptive_halves_in_one_launch(tmp_path):
    """render_halves (an adaptive pass's two halves from one launch) gives the numbers of
    two render_pass_totals launches bit for bit, on the megakernel and on the wavefront
    (sample ranges of 3 samples, one of them straddling the split at 8), with pixels left
    out."""
    from pathtracer.backends.cuda import CUDABackend
    s = _full_feature_scene(tmp_path)
    active = np.ones((s.height, s.width), np.uint8)
    active[::3, ::2] = 0
    for options in (False, dict(max_paths=s.width * s.height * 3)):
        be = CUDABackend(s, wavefront=options)
        be.prepare_halves()
        (a1, ta1), (b1, tb1) = [[v.copy() for v in h]
                                for h in be.render_halves(4, 8, 1, 6, 2, active)]
        a2, ta2 = [v.copy() for v in be.render_pass_totals(4, 8, 1, 6, 2, active)]
        b2, tb2 = [v.copy() for v in be.render_pass_totals(12, 8, 1, 6, 2, active)]
        assert (a1 == a2).all() and (b1 == b2).all(), options
        assert (ta1 == ta2).all() and (tb1 == tb2).all(), options
        assert (a1 != b1).any() and (a1[active == 0] == 0).all()


@gpu
def test_aov_parity(tmp_path):
    """The denoiser's albedo and normal images are the same on the CPU and the GPU."""
    from pathtracer.backends import make_backend
    s = _full_feature_scene(tmp_path)
    a = make_backend("cpu", s).aovs(8, 3)
    b = make_backend("cuda", s).aovs(8, 3)
    assert np.isfinite(a).all() and np.isfinite(b).all()
    close = np.isclose(a, b, rtol=1e-3, atol=1e-3).all(-1)
    assert close.mean() > 0.99


@gpu
def test_split_over_gpus_equals_one_gpu():
    """--devices: every GPU (device 0 twice on a one-GPU machine: two workers, two
    threads) renders items of each pass; the image is the one-GPU image up to float32
    rounding, from the same paths (tests/test_distribute.py states the tolerance)."""
    import os
    from numba import cuda
    import pathtracer as pt
    from tests.conftest import ROOT
    from tests.test_distribute import assert_same_render
    devices = list(range(len(cuda.gpus)))
    if len(devices) == 1:
        devices = [0, 0]
    scene = pt.load_scene(os.path.join(ROOT, "scenes", "cornell-box.json"),
                          _overrides={"resolution": (160, 120)})
    a = pt.render(scene, spp=96, backend="cuda")
    b = pt.render(scene, spp=96, backend="cuda", devices=devices)
    assert_same_render(a, b)
    assert len(b.shares) == len(devices) and min(b.shares) > 0
    c = pt.render(scene, spp=96, backend="cuda", devices=devices, adaptive=0.01)
    d = pt.render(scene, spp=96, backend="cuda", adaptive=0.01)
    assert_same_render(d, c)


EXIT_AFTER_SPLIT = """
import os
import pathtracer as pt
for name, res in (("cornell-box", (512, 512)), ("principled-grid", (512, 384))):
    scene = pt.load_scene(os.path.join("scenes", name + ".json"),
                          _overrides={"resolution": res})
    pt.render(scene, spp=64, backend="cuda")
    devices = "all" if len(__import__("numba").cuda.gpus) > 1 else [0, 0]
    r = pt.render(scene, spp=256, backend="cuda", devices=devices)
    assert min(r.shares) > 0
print("rendered")
"""


@gpu
def test_process_exits_cleanly_after_a_split_render():
    """A process that rendered over several GPUs (the megakernel's Cornell box and a
    wavefront scene with an HDRI) exits with status 0. Before the pool held its GPUs'
    pending deallocations at exit (distribute._hold_gpu_deallocations), numba-cuda's
    exit-time module unloads aborted such a process with "double free or corruption"
    (`python -m bench.distributed gpus` and this test, 2x H200, 2026-11-26)."""
    import subprocess
    import sys
    from tests.conftest import ROOT
    p = subprocess.run([sys.executable, "-c", EXIT_AFTER_SPLIT], cwd=ROOT,
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0 and "rendered" in p.stdout, (p.returncode, p.stderr[-3000:])


@gpu
def test_denoiser_on_the_gpu_matches_the_cpu(tmp_path):
    """OIDN's CUDA device runs the CPU's network: the same denoised image up to rounding
    (relMSE between the two ~1e-6 on the H200: bench.denoise_speed), as close to the
    truth as the CPU's; a second image size gets its own filter; and `pt-render --backend
    cuda --denoise` denoises on the GPU by default."""
    import pytest
    from pathtracer.backends import make_backend
    from pathtracer.denoise import cuda_denoiser_available, denoise
    from pathtracer.film import relmse
    from pathtracer.scene import load_scene
    from tests.helpers import furnace_scene, run, write_scene
    from tests.test_denoise import _pt_render
    if not cuda_denoiser_available():
        pytest.skip("pyoidn's CUDA device library does not load here")
    for res in ((64, 48), (40, 32)):
        scene = load_scene(write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=res)))
        raw = run(scene, "cuda", spp=4).film.image()
        aov = make_backend("cuda", scene).aovs(4, 0)
        truth = np.full_like(raw, 0.875)
        on_cpu = denoise(raw, aov, "cpu")
        on_gpu = denoise(raw, aov, "cuda")
        assert on_gpu.shape == raw.shape and on_gpu.dtype == np.float32
        assert relmse(on_gpu, on_cpu) < 1e-5, relmse(on_gpu, on_cpu)
        print("relMSE between the devices' images", relmse(on_gpu, on_cpu))
        err_gpu, err_cpu = relmse(on_gpu, truth), relmse(on_cpu, truth)
        # (errors of ~1e-4: rounding differences of 1e-6 move them by a few per cent)
        assert abs(err_gpu - err_cpu) <= 0.1 * err_cpu, (err_gpu, err_cpu)
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(32, 24)), "cmd.json")
    r = _pt_render(scene, "-o", tmp_path / "img.npy", "--spp", 4, "--denoise", "--quiet",
                   "--backend", "cuda")
    assert r.returncode == 0, r.stderr
    assert "Open Image Denoise, GPU" in r.stderr, r.stderr
    assert (tmp_path / "img.npy").exists() and (tmp_path / "img-raw.npy").exists()
