"""Renders against analytic answers and the Mitsuba 3 reference, on every backend."""
import os

import numpy as np

from pathtracer.kernels import layout as L
import pytest

from pathtracer.backends import make_backend
from pathtracer.backends.base import Backend
from pathtracer.film import relmse
from pathtracer.progressive import render
from pathtracer.scene import SceneError, load_scene
from tests.conftest import BACKENDS, ROOT, SHARED, gpu
from tests.helpers import furnace_scene, mean_and_se, run, write_scene

CORNELL = os.path.join(ROOT, "scenes", "cornell-box.json")
CORNELL_REF = os.path.join(SHARED, "reference", "cornell-box", "reference_256_d8.npy")
REF_NOISE = 1.95e-5          # the reference's own relMSE (reference_256_d8.json)
MITSUBA_RELMSE_SPP = 0.28    # Mitsuba independent sampler: relMSE ~ 0.28 / spp


# (the GPU machine's bundle of ../shared may leave the reference out: a skip, not an error)
@pytest.mark.skipif(not os.path.isfile(CORNELL_REF), reason="needs ../shared/reference")
@pytest.mark.parametrize("backend", BACKENDS)
def test_cornell_box_matches_mitsuba(backend):
    spp = 64 if backend == "cpu" else 1024
    scene = load_scene(CORNELL)
    img = run(scene, backend, spp=spp).film.image()
    ref = np.load(CORNELL_REF)
    # Per-channel image mean within 0.5% of the reference's (at 64 spp the mean's own
    # noise is ~0.1%).
    ratio = img.mean((0, 1)) / ref.mean((0, 1))
    assert np.all(np.abs(ratio - 1) < 0.005), ratio
    # relMSE at most 2x Mitsuba's at the same spp plus the reference's noise.
    err = relmse(img, ref)
    assert err <= 2 * MITSUBA_RELMSE_SPP / spp + REF_NOISE, err


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("albedo, emission, max_bounces, rr_depth", [
    (0.5, 0.5, 5, 5),
    ([0.9, 0.5, 0.1], [1.0, 0.5, 2.0], 12, 2),   # Russian roulette from bounce 2
    (0.8, 1.0, 0, 5),                             # emitters seen directly only
])
def test_furnace_inside_emitting_sphere(tmp_path, backend, albedo, emission, max_bounces,
                                        rr_depth):
    """Inside a closed shell that emits Le and reflects a: L = Le * sum_{k<=N} a^k."""
    scene_dict = furnace_scene(albedo, emission, max_bounces, res=(24, 24))
    scene_dict["render"]["rrDepth"] = rr_depth
    scene = load_scene(write_scene(tmp_path, scene_dict))
    img = run(scene, backend, spp=64).film.image()
    a = np.broadcast_to(np.asarray(albedo, float), 3)
    le = np.broadcast_to(np.asarray(emission, float), 3)
    expected = le * sum(a ** k for k in range(max_bounces + 1))
    mean, se = mean_and_se(img)
    assert np.all(np.abs(mean - expected) <= 5 * se + 1e-6 * expected), (mean, expected, se)
    assert np.all(se < 0.01 * expected)   # the bound is tight enough to mean something


@pytest.mark.parametrize("backend", BACKENDS)
def test_point_light_irradiance(tmp_path, backend):
    """A point light of intensity I at height h over a Lambertian plane: L = a/pi I cos/d^2."""
    h, intensity, albedo = 1.0, 2.0, 0.8
    s = 50.0
    scene_dict = {
        "camera": {"resolution": [16, 16], "position": [0, 0, 3], "lookAt": [0, 0, 0],
                   "up": [0, 1, 0], "fov": 20},
        "render": {"maxBounces": 1},
        "materials": [{"name": "m", "type": "diffuse", "albedo": albedo}],
        "objects": [{"name": "plane", "vertices": [[-s, -s, 0], [s, -s, 0], [s, s, 0],
                                                   [-s, s, 0]],
                     "faces": [[0, 1, 2], [0, 2, 3]], "material": "m"}],
        "lights": [{"type": "point", "position": [0, 0, h], "intensity": intensity}],
    }
    scene = load_scene(write_scene(tmp_path, scene_dict))
    img = run(scene, backend, spp=256).film.image()
    # The expectation is the pixel-area average (box filter): integrate on a 32x32 grid per
    # pixel. The plane point seen through image position (sx, sy) in [-1, 1]^2 is
    # (sx, sy) * tan(fov/2) * 3 (camera at height 3 looking down).
    t = np.tan(np.radians(10.0))
    sub = (np.arange(16 * 32) + 0.5) / (16 * 32) * 2 - 1
    x = sub[None, :] * t * 3
    y = -sub[:, None] * t * 3
    d2 = x * x + y * y + h * h
    fine = albedo / np.pi * intensity * (h / np.sqrt(d2)) / d2
    blocks = fine.reshape(16, 32, 16, 32)
    expected = blocks.mean(axis=(1, 3))
    # NEE to the one point light is deterministic given the pixel position, so the only
    # noise is the uniform jitter: standard error = within-pixel std / sqrt(spp).
    se = blocks.std(axis=(1, 3)) / np.sqrt(256)
    z = (img[..., 0] - expected) / (se + 1e-7 * expected)
    assert np.abs(z).max() < 5.5, np.abs(z).max()     # ~Sidak for 256 pixels at 1e-5
    assert np.abs(z).mean() < 1.2                      # E|z| = 0.8 for unit normals


@pytest.mark.parametrize("backend", BACKENDS)
def test_constant_environment(tmp_path, backend):
    """An upward Lambertian plane under a constant sky: L = albedo * sky, every sample."""
    s = 1000.0
    sky = [0.5, 1.0, 2.0]
    scene_dict = {
        "camera": {"resolution": [8, 8], "position": [0, 0, 1], "lookAt": [0, 0, 0],
                   "up": [0, 1, 0], "fov": 30},
        "render": {"maxBounces": 1},
        "materials": [{"name": "m", "type": "diffuse", "albedo": 0.6}],
        "objects": [{"name": "plane", "vertices": [[-s, -s, 0], [s, -s, 0], [s, s, 0],
                                                   [-s, s, 0]],
                     "faces": [[0, 1, 2], [0, 2, 3]], "material": "m"}],
        "environment": {"color": sky},
    }
    scene = load_scene(write_scene(tmp_path, scene_dict))
    img = run(scene, backend, spp=16).film.image()
    expected = 0.6 * np.array(sky)
    off = np.argwhere(~np.isclose(img, expected, rtol=1e-5))
    assert len(off) == 0, f"{len(off)} values off, first {off[:4].tolist()}: " \
        f"{[img[tuple(i)] for i in off[:4]]}"
    img0 = run(scene, backend, spp=4, max_bounces=0).film.image()
    assert np.all(img0 == 0)


def test_smooth_normals_render_finite(tmp_path):
    """Smooth shading on a coarse sphere lit by a point light: finite, no leaks on the
    unlit side (a shading normal never brings light below the geometric surface)."""
    from tests.helpers import sphere_mesh
    v, f = sphere_mesh(6, 12)
    scene_dict = {
        "camera": {"resolution": [32, 32], "position": [0, 0, 4], "lookAt": [0, 0, 0],
                   "fov": 40},
        "render": {"maxBounces": 3},
        "materials": [{"name": "m", "type": "diffuse", "albedo": 0.7}],
        "objects": [{"name": "s", "vertices": v, "faces": f, "material": "m", "smooth": True}],
        "lights": [{"type": "point", "position": [10, 0, 0], "intensity": 100}],
    }
    scene = load_scene(write_scene(tmp_path, scene_dict))
    assert scene.features.smooth
    img = run(scene, "cpu", spp=16).film.image()
    scene_dict["objects"][0]["smooth"] = False
    flat = run(load_scene(write_scene(tmp_path, scene_dict, "flat.json")), "cpu",
               spp=16).film.image()
    # Smooth shading redistributes light over the lit side but keeps its total close to
    # the flat-shaded one, and puts none on the far side.
    assert img[:, 16:].sum() == pytest.approx(flat[:, 16:].sum(), rel=0.1)
    assert img[:, :12].max() == 0 and flat[:, :12].max() == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_spot_light_irradiance(tmp_path, backend):
    """A spot light of intensity I at height h pointing down at a Lambertian plane:
    L = a/pi I cos/d^2 t^2, t = clamp((cos - cos_outer) / (cos_inner - cos_outer), 0, 1)
    (glTF's falloff): full inside the inner cone, dark outside the outer one. As
    test_point_light_irradiance: the expectation averaged over each pixel, a z-test."""
    h, intensity, albedo = 1.0, 2.0, 0.8
    inner, outer = 10.0, 25.0
    s = 50.0
    scene_dict = {
        "camera": {"resolution": [16, 16], "position": [0, 0, 3], "lookAt": [0, 0, 0],
                   "up": [0, 1, 0], "fov": 40},
        "render": {"maxBounces": 1},
        "materials": [{"name": "m", "type": "diffuse", "albedo": albedo}],
        "objects": [{"name": "plane", "vertices": [[-s, -s, 0], [s, -s, 0], [s, s, 0],
                                                   [-s, s, 0]],
                     "faces": [[0, 1, 2], [0, 2, 3]], "material": "m"}],
        "lights": [{"type": "spot", "position": [0, 0, h], "intensity": intensity,
                    "direction": [0, 0, -1], "innerAngle": inner, "outerAngle": outer}],
    }
    scene = load_scene(write_scene(tmp_path, scene_dict))
    spp = 256
    img = run(scene, backend, spp=spp).film.image()
    t = np.tan(np.radians(20.0))
    sub = (np.arange(16 * 32) + 0.5) / (16 * 32) * 2 - 1
    x = sub[None, :] * t * 3
    y = -sub[:, None] * t * 3
    d2 = x * x + y * y + h * h
    cos = h / np.sqrt(d2)
    cone = np.clip((cos - np.cos(np.radians(outer))) /
                   (np.cos(np.radians(inner)) - np.cos(np.radians(outer))), 0, 1) ** 2
    fine = albedo / np.pi * intensity * cos / d2 * cone
    blocks = fine.reshape(16, 32, 16, 32)
    expected = blocks.mean(axis=(1, 3))
    se = blocks.std(axis=(1, 3)) / np.sqrt(spp)
    z = (img[..., 0] - expected) / (se + 1e-6 * expected.max())
    assert np.abs(z).max() < 5.5, np.abs(z).max()
    assert (img[expected == 0] == 0).all()            # outside the cone: dark
    assert img[..., 0].max() == pytest.approx(albedo / np.pi * intensity, rel=0.02)
    for bad, words in (({"direction": [0, 0, -1], "outerAngle": 95}, "outerAngle"),
                       ({"direction": [0, 0, -1], "innerAngle": 30, "outerAngle": 20},
                        "innerAngle"),
                       ({}, "direction")):
        scene_dict["lights"] = [dict({"type": "spot", "position": [0, 0, 1]}, **bad)]
        with pytest.raises(SceneError, match=words):
            load_scene(write_scene(tmp_path, scene_dict, "bad.json"))


@pytest.mark.parametrize("backend", BACKENDS)
def test_directional_light_irradiance(tmp_path, backend):
    """A directional light of irradiance E at 60 degrees from a Lambertian plane's normal:
    L = a/pi E cos 60 everywhere (compiled as a point light 1,000 radii of the geometry
    away: within 0.2 % across it). Beside it a point lamp far from the plane still gets its
    share of light samples, so its light is not noise: by power (as much as the power that
    reaches the geometry, scene.compile.reaching_fraction) and with the light tree ("auto"
    for two lights with a point light among them)."""
    albedo, e = 0.8, 2.0
    theta = np.radians(60.0)
    scene_dict = {
        "camera": {"resolution": [8, 8], "position": [0, 0, 3], "lookAt": [0, 0, 0],
                   "up": [0, 1, 0], "fov": 20},
        "render": {"maxBounces": 1},
        "materials": [{"name": "m", "type": "diffuse", "albedo": albedo}],
        "objects": [{"name": "plane", "vertices": [[-2, -2, 0], [2, -2, 0], [2, 2, 0],
                                                   [-2, 2, 0]],
                     "faces": [[0, 1, 2], [0, 2, 3]], "material": "m"}],
        "lights": [{"type": "directional", "direction": [np.sin(theta), 0, -np.cos(theta)],
                    "irradiance": e}],
    }
    scene = load_scene(write_scene(tmp_path, scene_dict))
    img = run(scene, backend, spp=4).film.image()
    want = albedo / np.pi * e * np.cos(theta)
    assert np.abs(img / want - 1).max() < 2e-3
    # with a lamp 20 above the plane (outside the geometry's sphere) the two add up (were
    # the far point light's whole power counted, the lamp would get ~1e-5 of the light
    # samples: its light would be missing at 64 spp)
    scene_dict["lights"].append({"type": "point", "position": [0, 0, 20], "intensity": 400})
    lamp = albedo / np.pi * 400 / 400        # a/pi I cos / d^2 at the centre (cos ~ 1)
    for sampler in ("power", "auto"):
        scene_dict["render"]["lightSampler"] = sampler
        both = load_scene(write_scene(tmp_path, scene_dict, f"both-{sampler}.json"))
        assert both.features.light_tree == (sampler == "auto")
        img = run(both, backend, spp=64).film.image()
        assert np.allclose(img.mean(), want + lamp, rtol=0.02), sampler
    for bad, words in (({"type": "directional"}, "direction"),
                       ({"type": "directional", "direction": [0, 0, 0]}, "nonzero"),
                       ({"type": "directional", "direction": [0, 0, -1], "position": [0, 0, 1]},
                        "position")):
        scene_dict["lights"] = [bad]
        with pytest.raises(SceneError, match=words):
            load_scene(write_scene(tmp_path, scene_dict, "bad.json"))


def test_nonfinite_samples_are_counted(tmp_path):
    """The NaN/Inf counter works (so 'nonfinite == 0' in the other tests means something)."""
    scene = load_scene(write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(4, 4))))
    scene.arrays.mat[0, L.M_EMISSION] = np.nan   # poison the emission behind the loader's back
    result = render(scene, make_backend("cpu", scene), spp=2)
    assert result.film.nonfinite == 4 * 4 * 2
    # ... and left out of the image, which stays finite
    assert np.isfinite(result.film.image()).all()


SPECIALISATION_PROBE = r"""
import sys
import numpy as np
from numba import njit
sys.path.insert(0, sys.argv[1])
from pathtracer.kernels.integrator import Features, make_render_pixel
from pathtracer.scene import load_scene
scene = load_scene(sys.argv[1] + "/scenes/cornell-box.json")
render_pixel = make_render_pixel(Features(*(bool(int(c)) for c in sys.argv[2])))

@njit(error_model="numpy")   # not cached: inspect_llvm needs a fresh compile
def one_pixel(out, stats, stack, scene_arrays):
    render_pixel(0, 0, 0, 1, 0, 3, 5, scene_arrays, stack, out, stats)

from pathtracer.accel.wide import WIDE_STACK_SIZE
from pathtracer.backends.cpu import cpu_arrays
one_pixel(np.zeros((1, 1, 3), np.float32), np.zeros((1, 1, 3), np.int32),
          np.zeros(WIDE_STACK_SIZE, np.int32), cpu_arrays(scene.arrays)[0])
ir = "\n".join(one_pixel.inspect_llvm().values())
# the kernel's size as its count of instructions (the IR's length in characters varies from
# process to process with the lengths of generated names, by more than a small feature adds)
import re
print(sum(1 for line in ir.splitlines() if re.match(r"\s+(%\S+ = )?[a-z]", line)))
# the steps that the CPU always inlines, by their mangled names (e.g.
# 12make_kernels12_3clocals_3e12direct_light), and those still called
from pathtracer.kernels.device import CPU_INLINED
def mangled(qualname):
    parts = [p.replace("<locals>", "_3clocals_3e") for p in qualname.split(".")]
    return "".join("%d%s" % (len(p), p) for p in parts)
callees = set(re.findall(r"call [^@\n]*@\"?([\w.$]+)", ir))
print(len(CPU_INLINED), ",".join(sorted(q for q in CPU_INLINED
                                       if any(mangled(q) in c for c in callees))) or "-")
"""


def test_specialisation_removes_unused_code():
    """A kernel for a scene without point lights, environment, smooth normals, principled
    materials, textures, an HDRI or a thin lens compiles none of their code: each flag,
    when set, adds code to the base kernel; and no variant calls a step (all inlined on the
    CPU). Each variant is
    compiled in a fresh process (the IR of one process depends on what it compiled before)."""
    import subprocess
    import sys
    from concurrent.futures import ThreadPoolExecutor
    # tri lights, then + point lights / constant env / smooth / principled / textures /
    # env map / thin lens / one-sided materials / alpha / conductors (flags in Features
    # order). (Hidden emitters
    # are left out: their early return lets LLVM drop the camera ray's MIS branch, so
    # that kernel came out 3 instructions smaller than the base, 2026-12-07.)
    variants = ("1000", "1100", "1010", "1001", "10001", "100001", "100000001",
                "1000000001", "1" + "0" * 15 + "1", "1" + "0" * 16 + "1",
                "1" + "0" * 17 + "1")

    def probe(flags):      # (a compile is single-threaded: one process per core)
        r = subprocess.run([sys.executable, "-c", SPECIALISATION_PROBE, ROOT, flags],
                           capture_output=True, text=True, cwd=ROOT, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        size, n_steps, called = r.stdout.split()[-3:]
        return int(size), int(n_steps), called
    with ThreadPoolExecutor(max(1, min(4, os.cpu_count() or 1))) as pool:
        probes = list(pool.map(probe, variants))
    sizes = [size for size, _, _ in probes]
    assert all(size > sizes[0] for size in sizes[1:]), " ".join(
        f"{f}:{n}" for f, n in zip(variants, sizes))
    # ... and the CPU kernels call none of the integrator's steps: each is inlined (a
    # decorator shared by several steps once inlined only the first: kernels.device)
    for flags, (_, n_steps, called) in zip(variants, probes):
        assert n_steps > 20 and called == "-", (flags, called)


@gpu
def test_cpu_cuda_parity():
    """Same seed and spp: CPU and CUDA draw the same random numbers and run the same
    float32 code; images agree to float tolerance (FMA contraction differs), ray counts
    exactly unless a rounding flips a Russian-roulette decision."""
    scene = load_scene(CORNELL)
    cpu = make_backend("cpu", scene)
    cuda = make_backend("cuda", scene)
    a, sa = [x.copy() for x in cpu.render_pass(0, 8, 3, 7, 5)]
    b, sb = [x.copy() for x in cuda.render_pass(0, 8, 3, 7, 5)]
    assert np.abs(a - b).max() < 1e-3 * max(1.0, float(a.max()))
    assert np.isclose(a.sum(), b.sum(), rtol=1e-5)
    assert (sa == sb).all(-1).mean() > 0.999


@pytest.mark.parametrize("name", ["cornell-box", "principled-grid"])
def test_path_regeneration_changes_no_bit(name):
    """render_pixel runs a pixel's paths with path regeneration (the GPU in scenes without
    an environment), render_pixel_nested one after the other (the CPU, and the GPU in
    scenes with one; drivers.choose_driver), both around the one bounce (kernels.path):
    both add the same samples in the same order, so the sums and ray counts agree bit for
    bit. Run interpreted, on a few pixels (the principled grid: an
    HDRI, textures, glass and metal)."""
    from pathtracer.kernels.constants import STACK_SIZE
    from pathtracer.kernels.integrator import make_render_pixel
    scene = load_scene(os.path.join(ROOT, "scenes", name + ".json"))
    w, h = scene.width, scene.height
    pixels = [(w // 2, h // 2), (w // 3, h // 4)]
    images = []
    for regenerate in (True, False):
        render_pixel = make_render_pixel(scene.features, "python", regenerate)
        out = np.zeros((h, w, 3), np.float32)
        stats = np.zeros((h, w, 3), np.int32)
        stack = np.empty(STACK_SIZE, np.int32)
        with np.errstate(all="ignore"):
            for px, py in pixels:
                render_pixel(px, py, 3, 3, 1, 7, 3, scene.arrays, stack, out, stats)
        images.append((out, stats))
    (a, sa), (b, sb) = images
    assert a.any() and (sa[..., L.STAT_BOUNCE_RAYS] > 0).any()
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(sa, sb)


def test_escapes_looked_up_later_change_no_bit():
    """The CPU's form for scenes with an environment map (drivers.deferred)
    queues each finished path in a ring of ESCAPE_RING records per row and finishes a path
    whose ray left the scene (the map's lookup, MIS, the pixel's sum) when the ring comes
    round, or at the row's end (drain_escapes): the sums and counts equal
    render_pixel_nested's bit for bit. Interpreted, on a row of more paths than the ring
    holds, with paths that leave and paths that end on a surface (at most two bounces; the
    principled grid: an HDRI)."""
    from pathtracer.kernels.constants import STACK_SIZE
    from pathtracer.kernels.integrator import make_deferred_pixel, make_render_pixel
    scene = load_scene(os.path.join(ROOT, "scenes", "principled-grid.json"))
    w, h = scene.width, scene.height
    py = 3 * h // 4             # (the spheres' feet: paths that leave and paths that end)
    columns = range(w // 2 - 3, w // 2 + 3)
    n_samples = 3
    assert len(columns) * n_samples > L.ESCAPE_RING
    nested = make_render_pixel(scene.features, "python", False)
    deferred = make_deferred_pixel(scene.features, "python")
    stack = np.empty(STACK_SIZE, np.int32)
    a, sa = np.zeros((h, w, 3), np.float32), np.zeros((h, w, 3), np.int32)
    b, sb = np.full((h, w, 3), np.nan, np.float32), np.full((h, w, 3), -1, np.int32)
    esc_f = np.full((L.ESCAPE_RING, L.ESC_F_WIDTH), np.nan, np.float32)
    esc_i = np.full((L.ESCAPE_RING, L.ESC_I_WIDTH), -1, np.int32)
    left = []
    queued = 0
    with np.errstate(all="ignore"):
        for px in columns:
            nested(px, py, 3, n_samples, 1, 2, 3, scene.arrays, stack, a, sa)
            queued = deferred.pixel(px, py, 3, n_samples, 1, 2, 3, scene.arrays, stack, esc_f,
                                    esc_i, queued, b, sb)
            # (whether each of the pixel's paths left the scene, from its record)
            left += [esc_i[q % L.ESCAPE_RING, L.ESC_OUT] for q in range(queued - n_samples,
                                                                       queued)]
        deferred.drain(esc_f, esc_i, queued, py, scene.arrays, b, sb)
    assert queued == len(columns) * n_samples
    assert 0 < sum(left) < len(left) and set(left) == {0, 1}
    np.testing.assert_array_equal(a[py, columns], b[py, columns])
    np.testing.assert_array_equal(sa[py, columns], sb[py, columns])
    assert a[py, columns].all() and (sa[py, columns, L.STAT_BOUNCE_RAYS] > 0).any()


@pytest.mark.parametrize("name", ["cornell-box", "principled-grid"])
def test_camera_packets_trace_the_single_rays_paths(name):
    """The CPU traces a pixel's camera rays in packets of eight when a pass has at least
    PACKET_MIN_RAYS of them (drivers.megakernel.next_camera_lane; kernels.wide.closest_hit_packet),
    one by one otherwise: one pass of 16 samples and 16 passes of one draw the same paths
    (the same ray counts, pixel by pixel) and sum to the same image up to rounding (the
    camera ray is computed in another inlined copy, which LLVM's fast-math contracts its
    own way: 4e-5 of the brightest pixel's sum on the principled grid, 2026-11-29; a camera
    ray's wrong hit would move a pixel by a sample's worth). The Cornell box renders one
    path after the other, the principled grid (an HDRI) through the ring of escaped rays."""
    from pathtracer.kernels.drivers.megakernel import PACKET_MIN_RAYS
    from pathtracer.scene import compile_scene, load_scene_description
    assert 1 < PACKET_MIN_RAYS <= 16
    desc = load_scene_description(os.path.join(ROOT, "scenes", name + ".json"))
    desc.camera.resolution = (24, 18)
    backend = make_backend("cpu", compile_scene(desc))
    a, sa = [x.copy() for x in backend.render_pass(3, 16, 5, 7, 3)]
    b, sb = np.zeros_like(a), np.zeros_like(sa)
    for s in range(3, 19):
        out, stats = backend.render_pass(s, 1, 5, 7, 3)
        b += out
        sb += stats
    np.testing.assert_array_equal(sa, sb)
    assert (sa[..., L.STAT_BOUNCE_RAYS] > 0).any() and a.max() > 0
    assert np.abs(a - b).max() <= 1e-3 * a.max()


def test_cpu_rows_interleaved_over_threads_give_the_same_image():
    """The CPU kernels deal rows to their threads interleaved (backends.cpu.interleaved_row):
    for any thread count, on an image whose height no count divides, every row is rendered
    once and the pass and the AOVs are the same bit for bit. (The count is the kernels'
    argument, so counts beyond this machine's cores are tested too.)"""
    from pathtracer.backends import cpu
    from pathtracer.scene import compile_scene, load_scene_description
    desc = load_scene_description(os.path.join(ROOT, "scenes", "cornell-box.json"))
    desc.camera.resolution = (20, 13)
    scene = compile_scene(desc)
    render_pass, aov_pass = cpu.pass_kernel(scene.features), cpu.aov_kernel(scene.features)
    arrays = cpu.cpu_arrays(scene.arrays)[0]
    # (read-only, as the backend passes it: the backend's kernel, not another compile)
    from pathtracer._cache import read_only
    active = read_only(np.ones((13, 20), np.uint8))
    got = []
    for threads in (1, 2, 3, 7, 16):
        out = np.zeros((13, 20, 3), np.float32)
        stats = np.zeros((13, 20, 3), np.int32)
        aov = np.zeros((13, 20, L.AOV_WIDTH), np.float32)
        render_pass(out, stats, 0, 2, 3, 5, 3, arrays, active, threads)
        aov_pass(aov, 2, 3, arrays, threads)
        got.append((out, stats, aov))
    a, sa, va = got[0]
    assert (sa[..., L.STAT_BOUNCE_RAYS] > 0).all(axis=1).all()   # every row was rendered
    for b, sb, vb in got[1:]:
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(sa, sb)
        np.testing.assert_array_equal(va, vb)


def test_cpu_pass_kernels_are_cacheable():
    """The CPU pass and AOV kernels can go to the disk cache (a kernel that touches a
    dynamic global, such as numba.get_num_threads() inside it, is compiled afresh in
    every process, 7-14 s, with a NumbaWarning): rendering one leaves index files for both
    in the kernel folder."""
    import glob

    from pathtracer import _cache
    from pathtracer.scene import compile_scene, load_scene_description
    if not _cache.jit_cache() or not _cache._state["folder"]:
        pytest.skip("kernel disk cache off here")
    desc = load_scene_description(os.path.join(ROOT, "scenes", "cornell-box.json"))
    desc.camera.resolution = (4, 3)
    backend = make_backend("cpu", compile_scene(desc))
    backend.render_pass(0, 1, 0, 3, 3)
    backend.aovs(1, 0)
    names = [os.path.basename(f) for f in
             glob.glob(os.path.join(_cache._state["folder"], "**", "*.nbi"), recursive=True)]
    assert any("render_pass" in n and "cpu" in n for n in names), names[:20]
    assert any("aov_pass" in n and "cpu" in n for n in names), names[:20]


def test_headless_passes_aim_at_pass_seconds(monkeypatch):
    """A render nobody watches sizes each pass after the first from the last pass's speed,
    so that it lasts about pass_seconds (at most HEADLESS_GROWTH times the last pass's
    samples): few passes, each of which costs a synchronisation. Timed with a fake clock
    that a fake backend advances by a fixed cost per pass plus a cost per sample."""
    from pathtracer import progressive
    clock = [0.0]
    monkeypatch.setattr(progressive.time, "perf_counter", lambda: clock[0])
    scene = load_scene(CORNELL)
    h, w = scene.height, scene.width
    fixed, per_sample, pass_seconds = 0.002, 1e-4, 0.1

    class Fake(Backend):
        name = "fake"

        def __init__(self):
            self.scene = scene
            self.sizes = []

        def update(self, s):
            self.scene = s

        def compile(self):
            pass

        def render_pass(self, sample_start, n, seed, max_bounces, rr_depth, active=None):
            assert sample_start == sum(self.sizes)       # the samples follow each other
            self.sizes.append(n)
            clock[0] += fixed + n * per_sample
            return np.zeros((h, w, 3)), np.zeros((1, 1, 3), np.int64)

    b = Fake()
    r = render(scene, b, spp=5000, pass_seconds=pass_seconds, first_pass=4, headless=True)
    assert r.film.spp == 5000 and sum(b.sizes) == 5000
    assert b.sizes[0] == 4
    # the second pass from the first's speed (fixed cost included): 4 * 0.1 / 0.0024
    assert b.sizes[1] == min(progressive.HEADLESS_GROWTH * 4, int(4 * pass_seconds / 0.0024))
    # then (the fixed cost counted as samples at first) 85-100 % of pass_seconds, within
    # 2 % from the fourth pass on (the last pass: what is left)
    for k, n in enumerate(b.sizes[2:-1], 2):
        seconds = fixed + n * per_sample
        assert 0.85 * pass_seconds < seconds <= pass_seconds, b.sizes
        assert k < 3 or seconds > 0.98 * pass_seconds, b.sizes
    assert len(b.sizes) <= 2 + 5000 * per_sample / (pass_seconds - fixed) + 1
    # the growth cap: a first pass timed at almost nothing
    b2, fixed, per_sample = Fake(), 1e-6, 1e-9
    render(scene, b2, spp=3000, pass_seconds=pass_seconds, first_pass=1, headless=True)
    assert all(b < a * progressive.HEADLESS_GROWTH + 1 for a, b in zip(b2.sizes, b2.sizes[1:]))
    assert b2.sizes[:3] == [1, 64, 2935]


def test_passes_launched_ahead_grow_as_passes_waited_for(monkeypatch):
    """On a backend that can start a pass without waiting (launch, collect_pass_totals) the
    next pass is launched before the last one's on_pass; the time on_pass takes (a save,
    a preview) is not the launched pass's own: passes still double while short (a fake
    backend whose 'GPU' renders while the host runs on_pass, on a fake clock)."""
    from pathtracer import progressive
    clock = [0.0]
    monkeypatch.setattr(progressive.time, "perf_counter", lambda: clock[0])
    scene = load_scene(CORNELL)
    h, w = scene.height, scene.width

    class Fake(Backend):
        name = "fake"
        pipelined = True

        def __init__(self):
            self.scene = scene
            self.sizes, self.pending = [], []

        def update(self, s):
            self.scene = s

        def compile(self):
            pass

        def launch(self, sample_start, n, seed, max_bounces, rr_depth, active=None):
            assert sample_start == sum(self.sizes) and active is None
            self.sizes.append(n)
            start = max([clock[0]] + [done for done, _ in self.pending])
            self.pending.append((start + n * 1e-5, n))      # when the 'GPU' is done

        def render_pass(self, *args):
            raise AssertionError("a uniform render launches and collects its passes")

        def collect_pass_totals(self):
            done, n = self.pending.pop(0)
            clock[0] = max(clock[0], done) + 1e-4          # the wait and the copy
            return np.full((h, w, 3), float(n)), np.zeros((1, 1, 3), np.int64)

    def on_pass(film, elapsed):
        clock[0] += 0.3         # longer than pass_seconds

    b = Fake()
    r = render(scene, b, spp=63, pass_seconds=0.25, first_pass=1, on_pass=on_pass)
    assert b.sizes == [1, 2, 4, 8, 16, 32] and r.film.spp == 63
    assert [p[1] for p in r.passes] == [1, 3, 7, 15, 31, 63]
    assert np.allclose(r.film.image(), 1.0)     # each pass's sums added once, in order


@pytest.mark.parametrize("env", ["constant", "map"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_hide_emitters_hides_only_what_the_camera_sees_directly(tmp_path, backend, env):
    """render.hideEmitters (Mitsuba's hide_emitters): the sky and an emissive quad seen
    directly render black; every other sample is the same path as without it (the same
    numbers: the same values), so the lit floor and the sky in the mirror are unchanged."""
    sky = ({"color": [0.5, 1.0, 2.0]} if env == "constant" else
           {"file": os.path.join(ROOT, "scenes", "assets", "studio_small_03_256.hdr")})
    s = 4.0
    quad = [[-s, -1, -s], [s, -1, -s], [s, -1, s], [-s, -1, s]]
    scene_dict = {
        "camera": {"resolution": [24, 16], "position": [0, 0.5, 4], "lookAt": [0, 0, 0],
                   "fov": 70},
        "render": {"maxBounces": 3},
        "materials": [{"name": "floor", "type": "diffuse", "albedo": 0.6},
                      {"name": "lamp", "type": "diffuse", "albedo": 0, "emission": 5,
                       "twoSided": True},
                      {"name": "mirror", "metallic": 1, "roughness": 0, "albedo": 1}],
        "objects": [{"name": "floor", "vertices": quad, "faces": [[0, 2, 1], [0, 3, 2]],
                     "material": "floor"},
                    {"name": "lamp", "vertices": [[-2.5, -0.5, 0], [-1.5, -0.5, 0],
                                                  [-1.5, 0.5, 0], [-2.5, 0.5, 0]],
                     "faces": [[0, 1, 2], [0, 2, 3]], "material": "lamp"},
                    {"name": "mirror", "vertices": [[1, -1, -1], [2.5, -1, 0.5],
                                                    [2.5, 1, 0.5], [1, 1, -1]],
                     "faces": [[0, 1, 2], [0, 2, 3]], "material": "mirror"}],
        "environment": sky,
    }
    shown = run(load_scene(write_scene(tmp_path, scene_dict)), backend, spp=8).film.image()
    scene_dict["render"]["hideEmitters"] = True
    hidden_scene = load_scene(write_scene(tmp_path, scene_dict))
    assert hidden_scene.features.hide_emitters
    hidden = run(hidden_scene, backend, spp=8).film.image()
    # what each pixel's camera rays hit, from a run without bounces (max_bounces 0: only the
    # emission seen directly) on the visible-emitter scene
    direct = run(load_scene(write_scene(tmp_path, dict(scene_dict, render={
        "maxBounces": 0}))), backend, spp=8).film.image()
    sees_emitter = direct.max(axis=2) > 0
    assert sees_emitter.sum() >= 40 and (~sees_emitter).sum() >= 40
    assert np.all(direct[~sees_emitter] == 0)
    # the emitters the camera sees directly are gone: exactly their direct term
    np.testing.assert_allclose(hidden, np.maximum(shown - direct, 0), rtol=1e-4, atol=1e-5)
    # the sky in the mirror and the lit floor stay
    assert hidden[~sees_emitter].mean() > 0.05
    zero = run(hidden_scene, backend, spp=4, max_bounces=0).film.image()
    assert np.all(zero == 0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_one_sided_material_is_black_from_behind(tmp_path, backend):
    """oneSided (Mitsuba's BSDFs outside twosided): a quad lit from both sides under a
    constant sky shows its albedo x sky from the front and nothing from behind; without
    oneSided both sides reflect."""
    quad = {"name": "q", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
            "faces": [[0, 1, 2], [0, 2, 3]], "material": "m"}     # front: +z
    def render(one_sided, z):
        scene = {"camera": {"resolution": [8, 8], "position": [0, 0, z], "lookAt": [0, 0, 0],
                            "fov": 20},
                 "render": {"maxBounces": 1},
                 "materials": [{"name": "m", "type": "diffuse", "albedo": 0.6,
                                "oneSided": one_sided}],
                 "objects": [quad], "environment": {"color": 1.0}}
        s = load_scene(write_scene(tmp_path, scene))
        assert s.features.one_sided == one_sided
        return run(s, backend, spp=8).film.image()
    # a lone quad under a uniform sky: its upper hemisphere is all sky, L = albedo
    assert np.allclose(render(True, 3), 0.6, rtol=1e-4)
    assert np.all(render(True, -3) == 0)
    assert np.allclose(render(False, -3), 0.6, rtol=1e-4)
