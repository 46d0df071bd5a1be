"""First load of big meshes (issue: formats): the OBJ reader (tinyobjloader for the
geometry) against pywavefront's parse of the same file (the reader before), and the
binary PLY of the same mesh, each load in a fresh process with an empty mesh cache, so
that the time includes the cache write and the peak memory is the load's own.

    python -m bench.mesh_load [--k 2 3] [--repeats 3] [--before] [--json OUT]

The meshes are the Stanford dragon subdivided k times by shared/tools/make_big_mesh.py
(k = 2: 1.6M triangles, 3: 6.4M), made once into bench/out/meshes/ (bench.scaling).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

from bench.common import ROOT, command, machine, now, versions
from bench.scaling import big_mesh

CHILD = r"""
import json, os, sys, time
sys.path.insert(0, sys.argv[1])
os.environ["PT_RENDER_CACHE"] = sys.argv[4]
path, way = sys.argv[2], sys.argv[3]
# the modules are imported before the clock starts (a renderer has them loaded already)
import logging, pywavefront, pywavefront.material, tinyobjloader, plyfile
from pathtracer.scene.meshes import load_mesh
logging.getLogger("pywavefront").setLevel(logging.ERROR)
t0 = time.perf_counter()
if way == "pywavefront":
    pywavefront.Wavefront(path, collect_faces=True, create_materials=True, parse=True)
    n = None
else:
    n = len(load_mesh(path).positions)
seconds = time.perf_counter() - t0
# VmHWM, the peak of this process's own memory (ru_maxrss would include the parent's peak
# before the exec: Linux keeps it across execve)
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0].split()[1]
print(json.dumps({"seconds": seconds, "triangles": n, "peak_mb": int(hwm) / 1024}))
"""


def load_once(path, way):
    with tempfile.TemporaryDirectory() as cache:        # an empty mesh cache every time
        out = subprocess.run([sys.executable, "-c", CHILD, ROOT, path, way, cache],
                             capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def ply_of(obj):
    """The binary PLY of an OBJ mesh (plyfile), made once beside it."""
    path = os.path.splitext(obj)[0] + ".ply"
    if not os.path.isfile(path):
        import numpy as np
        from plyfile import PlyData, PlyElement
        from pathtracer.scene.meshes import load_mesh
        pos = load_mesh(obj, use_cache=False).positions.reshape(-1, 3)
        verts, inverse = np.unique(pos, axis=0, return_inverse=True)
        v = np.empty(len(verts), [("x", "f4"), ("y", "f4"), ("z", "f4")])
        v["x"], v["y"], v["z"] = verts.T
        f = np.empty(len(pos) // 3, [("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = inverse.reshape(-1, 3)
        PlyData([PlyElement.describe(v, "vertex"), PlyElement.describe(f, "face")]).write(
            path + ".tmp")
        os.replace(path + ".tmp", path)
    return path


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--k", type=int, nargs="+", default=[2, 3])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--before", action="store_true",
                   help="also time pywavefront's parse (the reader before; once, it is slow)")
    p.add_argument("--json", default=os.path.join(ROOT, "bench", "results", "mesh-load.json"))
    a = p.parse_args(argv)
    rec = {"command": command(), "machine": machine(), "date": now(), "versions": versions(),
           "repeats": a.repeats, "meshes": []}
    rows = []
    for k in a.k:
        obj = big_mesh(k)
        ways = [("OBJ (tinyobjloader)", obj, "load", a.repeats),
                ("binary PLY (plyfile)", ply_of(obj), "load", a.repeats)]
        if a.before:
            ways.append(("OBJ (pywavefront parse, before)", obj, "pywavefront", 1))
        for name, path, way, repeats in ways:
            runs = [load_once(path, way) for _ in range(repeats)]
            m = {"mesh": os.path.basename(obj), "way": name, "file_mb": os.path.getsize(path) / 2**20,
                 "triangles": runs[0]["triangles"],
                 "median_s": statistics.median(r["seconds"] for r in runs),
                 "all_s": [r["seconds"] for r in runs],
                 "peak_mb": max(r["peak_mb"] for r in runs)}
            rec["meshes"].append(m)
            rows.append(f"| {m['mesh']} | {name} | {m['file_mb']:.0f} | {m['median_s']:.2f} "
                        f"({', '.join(f'{x:.2f}' for x in m['all_s'])}) | {m['peak_mb']:.0f} |")
            print(rows[-1], file=sys.stderr)
    print(f"{rec['command']}; {rec['machine']}; {rec['date']}")
    print("\n| mesh | reader | file (MB) | first load, median (s) (runs) | peak memory (MB) |")
    print("|---|---|---|---|---|")
    print("\n".join(rows))
    os.makedirs(os.path.dirname(a.json), exist_ok=True)
    with open(a.json, "w") as f:
        json.dump(rec, f, indent=1)
    print(f"\nwritten to {os.path.relpath(a.json, ROOT)}")


if __name__ == "__main__":
    main()
