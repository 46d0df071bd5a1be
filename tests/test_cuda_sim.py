"""The CUDA kernel under the CUDA simulator (CI has no GPU): same source, same numbers.

The simulator must be switched on before Numba is imported, so it runs in a subprocess.
"""
import json
import os
import subprocess
import sys

from tests.conftest import ROOT

SCRIPT = r"""
import json, sys, tempfile
import numpy as np
sys.path.insert(0, sys.argv[1])
from pathtracer.scene import load_scene, load_scene_description, compile_scene
from pathtracer.backends.cuda import CUDABackend
from pathtracer.backends.cpu import CPUBackend
from tests.helpers import furnace_scene, write_scene
import pathtracer.backends.wavefront as wavefront
# The simulator runs a block's threads as Python threads, all of them, with or without
# work: blocks no larger than these images (and the queue launches' blocks of 32, not 128)
# took this script from 51 to 38 s (kernels cached); the kernels' code and numbers do not
# depend on the shape.
wavefront.BLOCK = 32


def small_cuda(scene, **options):
    return CUDABackend(scene, block=(6, 5), **options)


out = {}
d = load_scene_description(sys.argv[1] + "/scenes/cornell-box.json")
d.camera.resolution = (6, 5)
s = compile_scene(d)
a, sa = [x.copy() for x in small_cuda(s).render_pass(0, 2, 1, 7, 5)]
b, sb = [x.copy() for x in CPUBackend(s).render_pass(0, 2, 1, 7, 5)]
out["cornell_maxdiff"] = float(np.abs(a - b).max())
out["cornell_sum"] = [float(a.sum()), float(b.sum())]
out["stats_equal"] = bool((sa == sb).all())
c, tc = [x.copy() for x in small_cuda(s).render_pass_totals(0, 2, 1, 7, 5)]
out["totals_equal"] = bool((c == a).all() and tc.shape == (1, 1, 3) and
                           (tc.reshape(3) == sb.reshape(-1, 3).sum(axis=0)).all())
# The wavefront kernels (backends.wavefront): the CPU's image, with a pass split into
# sample ranges (max_paths), with every vertex launched apart or the tail finished in one
# launch, and with pixels left out (adaptive sampling)
wave = {}
active = np.ones((5, 6), np.uint8)
active[2, 3] = 0
m5 = small_cuda(s, wavefront=False).render_pass(0, 5, 1, 7, 5)[0].copy()
for name, options in [("finish", dict(wave_levels=2)), ("all", dict(wave_levels=None))]:
    w = small_cuda(s, wavefront=options)
    w.wavefront.max_paths = 60          # 2 of the pass's 5 samples per launch
    x, sx = [v.copy() for v in w.render_pass(0, 5, 1, 7, 5)]
    y, sy = [v.copy() for v in CPUBackend(s).render_pass(0, 5, 1, 7, 5)]
    xa, sxa = [v.copy() for v in w.render_pass(0, 5, 1, 7, 5, active)]
    wave[name] = dict(maxdiff=float(np.abs(x - y).max()), sum=float(x.sum()),
                      # the same code, the same sums in the same order: bit for bit
                      equal_megakernel=bool((x == m5).all()),
                      stats_equal=bool((sx == sy).all()),
                      active_equal=bool((xa[active == 1] == x[active == 1]).all()),
                      inactive_zero=bool((xa[2, 3] == 0).all() and (sxa[2, 3] == 0).all()))
out["wavefront"] = wave
# render_halves (an adaptive pass's two halves from one launch): the numbers of two
# launches, bit for bit; the wavefront with sample ranges of 2 samples, one of which
# straddles the split at 3
halves = {}
for name, be in [("megakernel", small_cuda(s, wavefront=False)),
                 ("wavefront", small_cuda(s, wavefront=dict(wave_levels=None)))]:
    if be.wavefront is not None:
        be.wavefront.max_paths = 60
    (a1, ta1), (b1, tb1) = [[v.copy() for v in h] for h in be.render_halves(2, 3, 1, 7, 5,
                                                                             active)]
    a2, ta2 = [v.copy() for v in be.render_pass_totals(2, 3, 1, 7, 5, active)]
    b2, tb2 = [v.copy() for v in be.render_pass_totals(5, 3, 1, 7, 5, active)]
    halves[name] = dict(equal=bool((a1 == a2).all() and (b1 == b2).all()),
                        totals_equal=bool((ta1 == ta2).all() and (tb1 == tb2).all()),
                        differ=bool((a1 != b1).any()), sum=float(a1.sum() + b1.sum()))
out["halves"] = halves
# The hit queue sorted by material kind (backends.wavefront's sort_hits): a scene with
# diffuse and principled materials, the same numbers bit for bit as one unsorted queue
g = load_scene_description(sys.argv[1] + "/scenes/glass.json")
g.camera.resolution = (6, 5)
gs = compile_scene(g)
sort = {}
for flag in (True, False):
    be = small_cuda(gs, wavefront=dict(wave_levels=None, sort_hits=flag))
    img = be.render_pass(0, 3, 1, 7, 5)[0].copy()
    q = be.wavefront.queue_lengths()
    sort[str(flag)] = dict(img=img.tolist(), hits=q[1], hits_b=q[3])
cg = CPUBackend(gs).render_pass(0, 3, 1, 7, 5)[0]
out["sort"] = dict(equal=sort["True"]["img"] == sort["False"]["img"],
                   maxdiff=float(np.abs(np.array(sort["True"]["img"]) - cg).max()),
                   sorted_hits=[sort["True"]["hits"], sort["True"]["hits_b"]],
                   unsorted_hits=[sort["False"]["hits"], sort["False"]["hits_b"]])
# The progressive loop with each pass launched before the last one is added to the film
# (progressive.render on a backend with launch / collect_pass_totals): the film of the
# same passes one by one; a render that on_pass stops keeps only the passes it saw, and
# the backend renders right after it
from pathtracer import progressive
from pathtracer.film import Film
progressive.PIPELINE_SECONDS = float("inf")     # (the simulator's passes are slow)
pipe = {}
be = small_cuda(s, wavefront=False)
ref = Film(5, 6)
k = 0
for n in (1, 2, 4):
    ref.add(*[v.copy() for v in be.render_pass_totals(k, n, 1, 7, 5)], n)
    k += n
be.compile()                # (its launch of no samples is not counted below)
launches = []
launch = be.launch
be.launch = lambda *a, **kw: (launches.append(a[:2]), launch(*a, **kw))[1]
seen = []
r = progressive.render(s, be, spp=7, seed=1, first_pass=1, pass_seconds=float("inf"),
                       on_pass=lambda f, e: seen.append((f.spp, len(launches))))
pipe["equal"] = bool((r.film.sum == ref.sum).all() and (r.film.count == ref.count).all())
pipe["passes"] = [p[1] for p in r.passes]
pipe["seen"] = seen
pipe["launches"] = launches[:]
stopped = progressive.render(s, be, spp=7, seed=1, first_pass=1, pass_seconds=float("inf"),
                             on_pass=lambda f, e: False)
pipe["stopped_spp"] = stopped.film.spp
again = progressive.render(s, be, spp=7, seed=1, first_pass=1, pass_seconds=float("inf"))
pipe["again_equal"] = bool((again.film.sum == ref.sum).all())
out["pipelined"] = pipe
# Furnace on the simulator: L = Le * sum_{k<=3} a^k.
f = load_scene(write_scene(tempfile.mkdtemp(), furnace_scene(0.5, 0.5, 3, res=(4, 4))))
img, st = small_cuda(f).render_pass(0, 24, 0, 3, 5)
px = (img / 24).reshape(-1, 3)
out["furnace_mean"] = float(px.mean())
out["furnace_se"] = float(px[:, 0].std(ddof=1) / np.sqrt(len(px)))
out["nonfinite"] = int(st[..., 2].sum())
# The features added for scenes written for Mitsuba and glTF: hidden emitters, a
# one-sided material, vertex colours, a tilted environment map and alpha (the glTF quad's
# BLEND: stochastic transparency), CUDA code against the CPU
from pathtracer.film import write_image
from tests.gltf_writers import Builder
tmp = tempfile.mkdtemp()
write_image(tmp + "/sky.hdr", np.random.default_rng(1).random((8, 16, 3)).astype(np.float32))
bld = Builder()
mat = bld.material({"pbrMetallicRoughness": {"metallicFactor": 0,
                                               "baseColorFactor": [1, 1, 1, 0.6]},
                    "alphaMode": "BLEND"})
bld.node(mesh=bld.mesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]],
                       material=mat, colors=[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0]]))
bld.save(tmp + "/vc.glb")
new = {"camera": {"resolution": [6, 5], "position": [0.3, 0.2, 3], "lookAt": [0, 0, 0]},
       "render": {"maxBounces": 3, "hideEmitters": True},
       "materials": [{"name": "back", "type": "diffuse", "albedo": 0.7, "oneSided": True},
                     {"name": "lamp", "type": "diffuse", "albedo": 0, "emission": 3}],
       "objects": [{"name": "vc", "file": "vc.glb"},
                   {"name": "wall", "vertices": [[-2, -2, -1], [-2, 2, -1], [2, 2, -1],
                                                 [2, -2, -1]], "faces": [[0, 1, 2], [0, 2, 3]],
                    "material": "back"},
                   {"name": "lamp", "vertices": [[0.5, 0.5, 0.5], [0.9, 0.5, 0.5],
                                                 [0.9, 0.9, 0.5]], "faces": [[0, 1, 2]],
                    "material": "lamp"}],
       "environment": {"file": "sky.hdr", "matrix": [[1, 0, 0], [0, 0, -1], [0, 1, 0]]}}
ns = load_scene(write_scene(tmp, new))
fe = ns.features
out["new_features"] = [fe.hide_emitters, fe.one_sided, fe.vertex_colors, fe.env_map,
                       fe.alpha]
na = small_cuda(ns).render_pass(0, 2, 1, 7, 5)[0].copy()
nb = CPUBackend(ns).render_pass(0, 2, 1, 7, 5)[0].copy()
out["new_maxdiff"] = float(np.abs(na - nb).max())
out["new_sum"] = float(nb.sum())
print(json.dumps(out))
"""


def test_cuda_kernel_on_simulator():
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    r = subprocess.run([sys.executable, "-c", SCRIPT, ROOT], capture_output=True, text=True,
                       env=env, cwd=ROOT, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["cornell_sum"][0] > 0
    # The simulator runs the same float32 code as the CPU backend.
    assert out["cornell_maxdiff"] < 1e-4, out
    assert out["stats_equal"]
    assert out["totals_equal"]      # render_pass_totals: the same sums, the counts summed
    expected = 0.5 * (1 + 0.5 + 0.25 + 0.125)
    assert abs(out["furnace_mean"] - expected) < 5 * out["furnace_se"] + 1e-6, out
    assert out["nonfinite"] == 0
    for name, got in out["wavefront"].items():
        assert got["sum"] > 0 and got["maxdiff"] < 1e-4, (name, got)
        assert got["equal_megakernel"], (name, got)
        assert got["stats_equal"] and got["active_equal"] and got["inactive_zero"], (name, got)
    for name, got in out["halves"].items():
        assert got["sum"] > 0 and got["differ"], (name, got)
        assert got["equal"] and got["totals_equal"], (name, got)
    sort = out["sort"]
    # both queues were used at the first vertex, and they hold what one queue held
    assert min(sort["sorted_hits"]) > 0 and sort["unsorted_hits"][1] == 0, sort
    assert sum(sort["sorted_hits"]) == sort["unsorted_hits"][0], sort
    assert sort["equal"] and sort["maxdiff"] < 1e-3, sort
    pipe = out["pipelined"]
    assert pipe["equal"] and pipe["passes"] == [1, 3, 7], pipe
    # each pass but the last was followed by the next one's launch before on_pass saw it
    assert pipe["seen"] == [[1, 2], [3, 3], [7, 3]], pipe
    assert pipe["launches"] == [[0, 1], [1, 2], [3, 4]], pipe
    assert pipe["stopped_spp"] == 1 and pipe["again_equal"], pipe
    assert out["new_features"] == [True] * 5 and out["new_sum"] > 0, out
    assert out["new_maxdiff"] < 1e-4, out
