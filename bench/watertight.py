"""How many rays slip between triangles that share an edge (the ray-triangle test is not
watertight), on the CPU's two traversals:

    python -m bench.watertight --rays 100000 --json out.json

Rays start at a distance from a closed UV sphere (one vertex per pole, no seam) and are
aimed at random points on its edges, a fifth of them exactly at a vertex. Only rays that
clearly cross the surface there are kept: every triangle that holds a corner of the
aimed-at edge (or the aimed-at vertex) faces the ray the same way, at a cosine of at least
MIN_COSINE. At the sphere's silhouette, where triangles around the point face the ray both
ways, a ray aimed at an edge may only graze the surface, and the float32 rounding of its
origin and direction (about 1e-7 of their size) may rightly take it past. So every miss
(closest hit) and every unoccluded shadow ray (any hit) of a kept ray is a ray that slipped
through a crack. Cases: the sphere's rings, segments, radius and centre, and the rays'
distance from its centre. (Until 2026-11-27 every ray was kept: most of the rays then
counted as slipping through grazed the silhouette.) Second, the same count for a quad
split into two triangles, flat or bent along their shared edge, with rays from above aimed
at that edge.
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
    return (v, f) + mesh_arrays(v, f)


def mesh_arrays(v, f):
    """(tri_v in BVH order, BVH) of float32 vertices v and faces f."""
    v0, v1, v2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    bvh = build_bvh(np.stack([v0, v1, v2], 1))
    tri_v = np.concatenate([v0, v1 - v0, v2 - v0], 1).astype(np.float32)[bvh.order]
    return tri_v, bvh


def count_slips(rec, o, d, tri_v, bvh):
    """rec with, per traversal (TRACERS), the rays (o, d) that hit nothing (closest hit)
    and that nothing occludes (any hit)."""
    for name in TRACERS:
        box, child = (bvh.box, bvh.child) if name == "binary" else widen_bvh(
            tri_v, bvh.box, bvh.child)
        tri, occluded = trace(name, o, d, tri_v, box, child)
        rec[f"{name}_missed"] = int((tri < 0).sum())
        rec[f"{name}_unoccluded"] = int((~occluded).sum())
    return rec


def edge_rays(v, f, center, distance, n, rng):
    """Rays from random points at ``distance`` from ``center`` towards points on random
    edges (a fifth of them exactly at a vertex), those that cross the surface there (see
    the module docstring): 84 % of the n drawn at distance 3 from the 16 x 32 sphere."""
    fi = rng.integers(0, len(f), n)
    k = rng.integers(0, 3, n)
    ia, ib = f[fi, k], f[fi, (k + 1) % 3]
    a = v[ia].astype(np.float64)
    b = v[ib].astype(np.float64)
    s = rng.random(n)
    s[rng.random(n) < 0.2] = 0.0
    target = a + s[:, None] * (b - a)
    u = rng.normal(size=(n, 3))
    o = np.asarray(center) + u / np.linalg.norm(u, axis=1)[:, None] * distance
    d = target - o
    d /= np.linalg.norm(d, axis=1)[:, None]
    crossing = _crossing(v, f, ia, np.where(s == 0.0, -1, ib), d)
    return o[crossing].astype(np.float32), d[crossing].astype(np.float32)


MIN_COSINE = 0.02


def _crossing(v, f, ia, ib, d):
    """Whether every face holding vertex ia or ib (ia alone where ib < 0) faces direction d
    the same way, at a cosine of at least MIN_COSINE, per ray."""
    p = v.astype(np.float64)[f]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    holds = [[] for _ in range(len(v))]           # faces by vertex
    for face, corners in enumerate(f):
        for c in corners:
            holds[c].append(face)
    out = np.empty(len(d), bool)
    for r in range(len(d)):
        faces = holds[ia[r]] + (holds[ib[r]] if ib[r] >= 0 else [])
        cosine = normal[faces] @ d[r]
        out[r] = bool((cosine >= MIN_COSINE).all() or (cosine <= -MIN_COSINE).all())
    return out


def measure(cases=CASES, rays=100_000, seed=11):
    """One record per case: rays that slipped through, per traversal and query."""
    out = []
    for n_theta, n_phi, radius, center, distance in cases:
        v, f, tri_v, bvh = sphere(n_theta, n_phi, radius, center)
        o, d = edge_rays(v, f, center, distance, rays, np.random.default_rng(seed))
        rec = {"rings": n_theta, "segments": n_phi, "radius": radius, "centre": list(center),
               "distance": distance, "triangles": len(f), "rays_drawn": rays,
               "rays": len(o)}
        out.append(count_slips(rec, o, d, tri_v, bvh))
    return out


# two triangles sharing an edge (a quad split along p-q, its far corners r and s lifted by
# ``bend`` out of the plane): (size, offset of every coordinate, distance of the ray
# origins, bend)
QUAD_CASES = [(1.0, 0.0, 3.0, 0.0), (1.0, 0.0, 3.0, 0.2), (1e-3, 5.0, 1.0, 0.2),
              (0.01, 20.0, 3.0, 0.2)]


def quad(size, offset, bend):
    """(vertices p, q, r, s; faces (p, q, r) and (q, p, s)) of the split quad, both
    facing +z."""
    v = np.array([[0, 0, 0], [1, 0.3, 0], [0.2, 1, bend], [0.7, -1, bend]]) * size + offset
    return v.astype(np.float32), np.array([[0, 1, 2], [1, 0, 3]])


def measure_quads(cases=QUAD_CASES, rays=100_000, seed=11):
    """One record per case: of rays from above (within about 30 degrees of +z) aimed at
    points of the shared edge away from its ends (10-90 % along it), those that hit
    neither triangle; every one crosses the quad there."""
    out = []
    for size, offset, distance, bend in cases:
        v, f = quad(size, offset, bend)
        rng = np.random.default_rng(seed)
        p, q = v[0].astype(np.float64), v[1].astype(np.float64)
        target = p + (0.1 + 0.8 * rng.random(rays))[:, None] * (q - p)
        up = rng.normal(size=(rays, 3))
        up[:, 2] = np.abs(up[:, 2]) + 2.0
        o = target + up / np.linalg.norm(up, axis=1)[:, None] * distance
        d = target - o
        d /= np.linalg.norm(d, axis=1)[:, None]
        rec = {"size": size, "offset": offset, "distance": distance, "bend": bend,
               "rays": rays}
        out.append(count_slips(rec, o.astype(np.float32), d.astype(np.float32),
                               *mesh_arrays(v, f)))
    return out


def main(argv=None):
    from bench.common import machine, now, versions
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rays", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=11)
    p.add_argument("--json")
    a = p.parse_args(argv)
    records = measure(rays=a.rays, seed=a.seed)
    print(f"rays drawn per case: {a.rays}")
    print("| sphere (rings x segments, radius, centre) | ray distance | rays crossing | "
          "binary: missed / unoccluded | wide: missed / unoccluded |")
    print("|---|---|---|---|---|")
    for r in records:
        print(f"| {r['rings']}x{r['segments']}, r {r['radius']:g}, at {tuple(r['centre'])} | "
              f"{r['distance']:g} | {r['rays']} | {r['binary_missed']} / "
              f"{r['binary_unoccluded']} | "
              f"{r['wide_missed']} / {r['wide_unoccluded']} |")
    quads = measure_quads(rays=a.rays, seed=a.seed)
    print()
    print("| split quad (size, offset, bend) | ray distance | rays | binary: missed / "
          "unoccluded | wide: missed / unoccluded |")
    print("|---|---|---|---|---|")
    for r in quads:
        print(f"| {r['size']:g}, {r['offset']:g}, {r['bend']:g} | {r['distance']:g} | "
              f"{r['rays']} | {r['binary_missed']} / {r['binary_unoccluded']} | "
              f"{r['wide_missed']} / {r['wide_unoccluded']} |")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"command": "python -m bench.watertight " + " ".join(
                sys.argv[1:] if argv is None else argv), "machine": machine(), "date": now(),
                "versions": versions(), "cases": records, "quads": quads}, fh, indent=1)


if __name__ == "__main__":
    main()
