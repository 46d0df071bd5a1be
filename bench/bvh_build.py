"""BVH build time (issue: CPU speed): the builder against its plain formulation
(``build_bvh(..., _plain=tests.bvh_oracle.build_plain)``: one thread, node bounds recomputed per node, triangles
read through the order array) on one mesh file, in one run: median of 3 builds after a
warm-up, with the SAH cost and node count (equal trees: the two make the same tree).

    python -m bench.bvh_build MESH.(obj|ply) [--json OUT]
"""
import argparse
import json
import os
import statistics
import time

from bench.common import ROOT, command, machine, now, versions


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mesh")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", default=os.path.join(ROOT, "bench", "results", "bvh-build.json"))
    a = p.parse_args(argv)
    import numpy as np
    from pathtracer.accel.bvh import build_bvh, sah_cost
    from pathtracer.scene.meshes import load_mesh
    pos = load_mesh(a.mesh).positions
    rec = {"command": command(), "machine": machine(), "date": now(), "versions": versions(),
           "mesh": os.path.basename(a.mesh), "triangles": int(len(pos))}
    trees = {}
    from tests.bvh_oracle import build_plain
    for name, plain in (("plain", build_plain), ("builder", None)):
        build_bvh(pos[:1000], _plain=plain)          # compile (or load) outside the timing
        build_bvh(pos, _plain=plain)                 # warm-up
        times = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            bvh = build_bvh(pos, _plain=plain)
            times.append(time.perf_counter() - t0)
        trees[name] = bvh
        rec[name] = {"median_s": statistics.median(times), "all_s": times,
                     "sah_cost": sah_cost(bvh), "nodes": int(len(bvh.box)),
                     "depth": bvh.depth}
    rec["same_tree"] = all(np.array_equal(x, y) for x, y in
                           zip(trees["plain"][:3], trees["builder"][:3]))
    with open(a.json, "w") as f:
        json.dump(rec, f, indent=1)
    print(f"{rec['command']}; {rec['machine']}; {rec['date']}")
    print(f"{rec['mesh']}: {rec['triangles']} triangles; same tree: {rec['same_tree']}")
    for name in ("plain", "builder"):
        r = rec[name]
        print(f"  {name:8s} {r['median_s']:.3f} s (all {', '.join(f'{t:.3f}' for t in r['all_s'])})"
              f"  SAH {r['sah_cost']:.2f}  {r['nodes']} nodes  depth {r['depth']}")


if __name__ == "__main__":
    main()
