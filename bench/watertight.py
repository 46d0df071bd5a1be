"""How many rays slip between triangles that share an edge (the ray-triangle test is not
watertight), on the CPU's two traversals:

    python -m bench.watertight --rays 100000 --json out.json

Rays start at a distance from a closed UV sphere (one vertex per pole, no seam) and are
aimed at random points on its edges, a fifth of them exactly at a vertex. From outside,
every such ray crosses the surface, so every miss (closest hit) and every unoccluded
shadow ray (any hit) is a ray that slipped through a crack. Cases: the sphere's rings,
segments, radius and centre, and the rays' distance from its centre.
"""
import argparse
import json
import sys

import numpy as np

from bench.traversal import tracers
from pathtracer.accel.bvh import build_bvh
from pathtracer.accel.wide import widen_bvh
from pathtracer.kernels.traverse import any_hit, closest_hit
from pathtracer.kernels.wide import any_hit_wide, closest_hit_wide
from pathtracer.scene.geometry import uv_sphere

# (rings, segments, radius, centre, distance of the ray origins from the centre)
CASES = [(16, 32, 1.0, (0.0, 0.0, 0.0), 3.0),
         (16, 32, 1.0, (0.3, -0.7, 0.2), 3.0),
         (24, 48, 5.0, (-20.0, 3.0, 7.0), 7.5),
         (64, 128, 1.0, (0.0, 0.0, 0.0), 3.0),
         (16, 32, 0.1, (10.0, 5.0, -3.0), 3.0),
         (16, 32, 0.05, (20.0, 10.0, -6.0), 3.0),
         (8, 16, 1e-3, (1.0, 2.0, 3.0), 1.0)]


TRACERS = {"binary": tracers(closest_hit, any_hit),
           "wide": tracers(closest_hit_wide, any_hit_wide)}


def trace(name, o, d, tri_v, box, child):
    """(hit triangle or -1, occluded) of each ray through tree ``name``'s arrays."""
    closest, shadow = TRACERS[name]
    skip = np.full(len(o), -1, np.int32)
    t = np.empty(len(o), np.float32)
    tri = np.empty(len(o), np.int32)
    occluded = np.empty(len(o), np.bool_)
    closest(o, d, skip, tri_v, box, child, t, tri, occluded)
    shadow(o, d, skip, tri_v, box, child, t, tri, occluded)
    return tri, occluded


def sphere(n_theta, n_phi, radius, center):
    """(vertices, faces, tri_v in BVH order, BVH) of a closed UV sphere."""
    v, f = uv_sphere(n_theta, n_phi)
    v = (v * radius + np.asarray(center)).astype(np.float32)
    v0, v1, v2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    bvh = build_bvh(np.stack([v0, v1, v2], 1))
    tri_v = np.concatenate([v0, v1 - v0, v2 - v0], 1).astype(np.float32)[bvh.order]
    return v, f, tri_v, bvh


def edge_rays(v, f, center, distance, n, rng):
    """Rays from random points at ``distance`` from ``center`` towards points on random
    edges (a fifth of them exactly at a vertex)."""
    fi = rng.integers(0, len(f), n)
    k = rng.integers(0, 3, n)
    a = v[f[fi, k]].astype(np.float64)
    b = v[f[fi, (k + 1) % 3]].astype(np.float64)
    s = rng.random(n)
    s[rng.random(n) < 0.2] = 0.0
    target = a + s[:, None] * (b - a)
    u = rng.normal(size=(n, 3))
    o = np.asarray(center) + u / np.linalg.norm(u, axis=1)[:, None] * distance
    d = target - o
    d /= np.linalg.norm(d, axis=1)[:, None]
    return o.astype(np.float32), d.astype(np.float32)


def measure(cases=CASES, rays=100_000, seed=11):
    """One record per case: rays that slipped through, per traversal and query."""
    out = []
    for n_theta, n_phi, radius, center, distance in cases:
        v, f, tri_v, bvh = sphere(n_theta, n_phi, radius, center)
        o, d = edge_rays(v, f, center, distance, rays, np.random.default_rng(seed))
        rec = {"rings": n_theta, "segments": n_phi, "radius": radius, "centre": list(center),
               "distance": distance, "triangles": len(f), "rays": rays}
        for name in TRACERS:
            box, child = (bvh.box, bvh.child) if name == "binary" else widen_bvh(
                tri_v, bvh.box, bvh.child)
            tri, occluded = trace(name, o, d, tri_v, box, child)
            rec[f"{name}_missed"] = int((tri < 0).sum())
            rec[f"{name}_unoccluded"] = int((~occluded).sum())
        out.append(rec)
    return out


def main(argv=None):
    from bench.common import machine, now, versions
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rays", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=11)
    p.add_argument("--json")
    a = p.parse_args(argv)
    records = measure(rays=a.rays, seed=a.seed)
    print(f"rays per case: {a.rays}")
    print("| sphere (rings x segments, radius, centre) | ray distance | binary: missed / "
          "unoccluded | wide: missed / unoccluded |")
    print("|---|---|---|---|")
    for r in records:
        print(f"| {r['rings']}x{r['segments']}, r {r['radius']:g}, at {tuple(r['centre'])} | "
              f"{r['distance']:g} | {r['binary_missed']} / {r['binary_unoccluded']} | "
              f"{r['wide_missed']} / {r['wide_unoccluded']} |")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"command": "python -m bench.watertight " + " ".join(
                sys.argv[1:] if argv is None else argv), "machine": machine(), "date": now(),
                "versions": versions(), "cases": records}, fh, indent=1)


if __name__ == "__main__":
    main()
