"""The CUDA kernels compiled to PTX without a GPU: whether they compile for the GPU target
(the CUDA simulator runs Python, not numba-cuda's typing and lowering), their size, float64
instructions and local-memory operations, per scene.

    pip install "numba-cuda[cu13]"        # NVVM and NVRTC as wheels (~450 MB), no driver needed
    python -m bench.ptx_size [--trees OLD NEW] [--json OUT]

Each tree's kernels are compiled in a process of its own (``--trees``: before and after a
change; default: this checkout): the megakernel pass kernel of the four benchmark scenes and
of tests/test_gpu.py's scene with every feature (with alpha too, where the tree has it), and
the wavefront kernels of the scenes that render with them. A static measure: an instruction
count is not a speed (the GPU's A/B is ``python -m bench.ab throughput --backend cuda``).
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

from bench.common import ROOT, write_record

CHILD = r"""
import json, os, pathlib, re, sys, tempfile
from types import SimpleNamespace
import numba
from numba import cuda, types
import numba.cuda.dispatcher as dispatcher
# no GPU: device functions take the compute capability of an H100/H200 (sm_90)
dispatcher.get_current_device = lambda: SimpleNamespace(compute_capability=(9, 0))
from pathtracer.backends import cuda as C
from pathtracer.backends.wavefront import wavefront_kernels
from pathtracer.kernels.layout import Features
from bench.scenes import CONVERGENCE, convergence_scene
sys.path.insert(0, sys.argv[2])               # (this checkout's tests: the full-feature scene)
from tests.test_gpu import _full_feature_scene

def count(ptx):
    lines = [l for l in ptx.splitlines()
             if re.match(r"\s+[a-z@]", l) and not l.strip().startswith("//")]
    return dict(instructions=len(lines), f64=sum(".f64" in l for l in lines),
                local=len(re.findall(r"\.local", ptx)))

def ptx(fn, sig):
    return count(cuda.compile_ptx(fn.py_func, sig, cc=(9, 0), fastmath=True)[0])

i1, i2 = types.Array(types.int32, 1, "C"), types.Array(types.int32, 2, "C")
f2, u2 = types.Array(types.float32, 2, "C"), types.Array(types.uint8, 2, "C")
f3, i3 = types.Array(types.float32, 3, "C"), types.Array(types.int32, 3, "C")
f4, i4 = types.Array(types.float32, 4, "C"), types.Array(types.int32, 4, "C")
I, B = types.int64, types.boolean

def megakernel(s):
    f = s.features
    k = C.pass_kernel(f, C.max_registers_for(f), True, C.regenerates(f, "cuda"))
    return ptx(k, (f4, i4, I, I, I, I, I, numba.typeof(s.arrays), u2))

def wavefront(s):
    a = numba.typeof(s.arrays)
    sigs = ((I, I, I, I, I, a, f2, i2, u2, i1, i1), (i1, i1, I, a, f2, i2, f2, i1, i1, i1),
            (i1, i1, I, a, f2, i2), (i1, i1, i1, I, I, I, I, I, I, I, a, f2, i2, f2, i1),
            (i1, i1, I, I, I, I, I, I, I, a, f2, i2), (I, I, f2, i2, f3, i3, B))
    names = ("start", "extend", "miss", "shade", "finish", "film")
    kernels = wavefront_kernels(s.features, C.WAVE_MAX_REGISTERS, True, True)
    return {n: ptx(k, sig) for n, k, sig in zip(names, kernels, sigs)}

out = {}
for name in CONVERGENCE:
    s = convergence_scene(name).compiled
    out[name] = megakernel(s)
    if name in ("bunny-studio", "sun", "textured"):
        out[name + " wavefront"] = wavefront(s)
HAS_CONDUCTOR = "conductor" in Features._fields
for alpha in ((False, True) if "alpha" in Features._fields else (False,)):
    s = _full_feature_scene(pathlib.Path(tempfile.mkdtemp()), alpha=alpha,
                            conductor=HAS_CONDUCTOR)
    out[f"every feature{' + alpha' if alpha else ''}"] = megakernel(s)
    if not alpha:
        out["every feature wavefront"] = wavefront(s)
print(json.dumps(out))
"""


def measure(tree):
    """{kernel: {instructions, f64, local}} of the tree's kernels (a child process)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.abspath(tree), ROOT]),
               PT_RENDER_CACHE=tempfile.mkdtemp())
    r = subprocess.run([sys.executable, "-c", CHILD, os.path.abspath(tree), ROOT],
                       capture_output=True, text=True, env=env, cwd=tempfile.gettempdir())
    if r.returncode != 0:
        raise SystemExit(f"bench.ptx_size: {tree}: {r.stderr.strip().splitlines()[-1]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trees", nargs="+", default=[ROOT])
    p.add_argument("--json", help="write the record here")
    args = p.parse_args(argv)
    results = {tree: measure(tree) for tree in args.trees}
    names = list(results[args.trees[-1]])
    print("kernel".ljust(34) + "".join(os.path.basename(os.path.normpath(t)).rjust(14)
                                       for t in args.trees) + "   f64")
    for name in names:
        rows = [results[t].get(name) for t in args.trees]
        flat = [r if r is None or "instructions" in r else
                {"instructions": sum(v["instructions"] for v in r.values()),
                 "f64": sum(v["f64"] for v in r.values())} for r in rows]
        print(name.ljust(34) + "".join(
            ("-" if r is None else str(r["instructions"])).rjust(14) for r in flat) +
            "   " + ",".join("-" if r is None else str(r["f64"]) for r in flat))
    if args.json:
        write_record(args.json, trees=args.trees, results=results)
    bad = [n for t in args.trees for n, r in results[t].items()
           if any(v["f64"] for v in ([r] if "f64" in r else r.values()))]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
