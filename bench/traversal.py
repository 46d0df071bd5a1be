"""Closest-hit and any-hit rays/s of the binary and the CPU's eight-wide BVH, on one scene:

    python -m bench.traversal bunny-studio --rays 400000 --json out.json
    python -m bench.traversal bunny-studio --backend cuda --rays 4000000
    python -m bench.traversal bunny-studio --order origin
    python -m bench.traversal bunny-studio --mitsuba

``--mitsuba``: also Mitsuba 3's ``ray_intersect_preliminary`` and ``ray_test`` on the same
rays and triangles (``llvm_ad_rgb`` on the CPU, ``cuda_ad_rgb`` with ``--backend cuda``:
Embree / OptiX), each call a new ray batch evaluated and waited for; its rays start 1e-4
scene sizes along their direction instead of skipping the triangle they leave, and its hits
are checked to agree with ours on >= 99.9 % of the rays.

Rays start on the scene's triangles (a uniform triangle, its centroid) in uniformly random
directions, the triangle they leave skipped: rays as a path's bounce and shadow rays see
the mesh, not camera rays. ``--order random`` (the default) traces them in that random
order, so that each ray's nodes are mostly not in the core's caches; ``--order origin``
traces the same rays sorted by the triangle they leave (the BVH orders triangles by place),
as a render on the CPU traces a pixel's samples one after another, whose bounce rays start
close together: there the nodes near them stay cached (on the 2-core CPU, bunny-studio,
2026-11-28: the then four-wide tree's closest hits 1.08-1.14x and any hits 1.20-1.31x faster
so, the binary tree's closest hits 1.45-1.65x). One traversal stack per 256 rays (the renderer allocates one per
image row; one per ray made the allocator part of the figure). Both trees trace the same
rays on all threads; the hits are checked equal (the same triangle, or the same distance:
a ray through an edge two triangles share hits both at one t, and either may win).
Median of ``--repeats`` after a warm-up, compile excluded.
"""
import argparse
import json
import sys
import time

import numpy as np
from numba import cuda, njit, prange
from numba.extending import register_jitable

from bench.scenes import CONVERGENCE, convergence_desc
from pathtracer.accel.wide import WIDE_STACK_SIZE, widen_bvh
from pathtracer.kernels.constants import INF
from pathtracer.kernels.traverse import any_hit, closest_hit
from pathtracer.kernels.wide import any_hit_wide, closest_hit_wide


CHUNK = 256     # rays per stack allocation, as the renderer allocates one per image row


def ray_steps(closest, occluded):
    """(trace_ray, shadow_ray): ray i of the arrays through ``closest`` (writing t and the
    triangle) or ``occluded`` (writing any hit), with the caller's traversal stack; the one
    per-ray body of the CPU loops and the CUDA kernels below."""
    @register_jitable
    def trace_ray(i, o, d, skip, tri_v, box, child, t_out, tri_out, any_out, stack):
        t, tri, b1, b2 = closest((o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]),
                                 INF, skip[i], tri_v, box, child, stack)
        t_out[i] = t
        tri_out[i] = tri

    @register_jitable
    def shadow_ray(i, o, d, skip, tri_v, box, child, t_out, tri_out, any_out, stack):
        any_out[i] = occluded((o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]), INF,
                              skip[i], -1, tri_v, box, child, stack)
    return trace_ray, shadow_ray


def tracers(closest, occluded):
    """(trace, shadow): compiled loops over rays, in parallel over chunks of CHUNK rays,
    of ``closest`` (writing t and the triangle) and ``occluded`` (writing any hit)."""
    def loop(ray):
        @njit(parallel=True)
        def run(o, d, skip, tri_v, box, child, t_out, tri_out, any_out):
            n = o.shape[0]
            for c in prange((n + CHUNK - 1) // CHUNK):
                stack = np.empty(WIDE_STACK_SIZE, np.int32)
                for i in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
                    ray(i, o, d, skip, tri_v, box, child, t_out, tri_out, any_out, stack)
        return run
    return tuple(loop(ray) for ray in ray_steps(closest, occluded))


def cuda_tracers(closest, occluded, stack_size, block=128):
    """tracers' (trace, shadow) as CUDA kernels, one ray per thread with its own stack of
    ``stack_size`` int32 in local memory (as the renderer's GPU kernels keep it); called
    with device arrays."""
    def launcher(ray):
        @cuda.jit
        def kernel(o, d, skip, tri_v, box, child, t_out, tri_out, any_out):
            i = cuda.grid(1)
            if i < o.shape[0]:
                stack = cuda.local.array(stack_size, np.int32)
                ray(i, o, d, skip, tri_v, box, child, t_out, tri_out, any_out, stack)

        def run(o, *rest):
            kernel[(o.shape[0] + block - 1) // block, block](o, *rest)
            cuda.synchronize()
        return run
    return tuple(launcher(ray) for ray in ray_steps(closest, occluded))


def make_rays(tri_v, n_rays, order, seed=1):
    """(origins, directions, skip) of n_rays rays from uniformly chosen triangles' centroids
    in uniformly random directions; ``order`` "origin" sorts them by the triangle they
    leave (the same rays as "random", another order)."""
    rng = np.random.default_rng(seed)
    skip = rng.integers(0, len(tri_v), n_rays).astype(np.int32)
    dirs = rng.normal(size=(n_rays, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    if order == "origin":
        by_origin = np.argsort(skip, kind="stable")
        skip, dirs = skip[by_origin], np.ascontiguousarray(dirs[by_origin])
    tv = tri_v[skip]
    origins = (tv[:, 0:3] + tv[:, 3:6] / 3 + tv[:, 6:9] / 3).astype(np.float32)
    return origins, dirs, skip


def mitsuba_rates(tri_v, origins, dirs, ours_hit, backend, repeats):
    """({variant, closest_hit_rays_per_s, any_hit_rays_per_s}, fraction of rays whose
    hit or miss agrees with ours) of Mitsuba 3 on the same triangles and rays, or (None,
    None) with a note when Mitsuba cannot run here."""
    from bench.common import usable_mitsuba
    variant = "cuda_ad_rgb" if backend == "cuda" else "llvm_ad_rgb"
    ok, why = usable_mitsuba(variant)
    if not ok:
        print(f"Mitsuba left out: {why}")
        return None, None
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(variant)
    from pathtracer.kernels.layout import TRI_E1, TRI_E2, TRI_V0
    v0, e1, e2 = (tri_v[:, c:c + 3].astype(np.float32) for c in (TRI_V0, TRI_E1, TRI_E2))
    verts = np.concatenate([v0, v0 + e1, v0 + e2], axis=1).reshape(-1, 3)
    mesh = mi.Mesh("triangles", len(verts), len(tri_v), has_vertex_normals=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(verts.ravel())
    params["faces"] = mi.UInt32(np.arange(len(verts), dtype=np.uint32))
    params.update()
    scene = mi.load_dict({"type": "scene", "triangles": mesh})
    # (rays leave their triangle by a small step: Mitsuba has no triangle to skip)
    step = np.float32(1e-4 * np.abs(verts).max())
    o = origins + step * dirs
    base = mi.Ray3f(mi.Point3f(*[mi.Float(o[:, k]) for k in range(3)]),
                    mi.Vector3f(*[mi.Float(dirs[:, k]) for k in range(3)]))

    def fresh():
        # a new variable each call: Dr.Jit would otherwise reuse the last call's result
        return mi.Ray3f(base.o + dr.opaque(mi.Float, 0.0), base.d)

    def closest():
        pi = scene.ray_intersect_preliminary(fresh())
        dr.eval(pi.t, pi.prim_index)
        dr.sync_thread()
        return pi

    def occluded():
        r = scene.ray_test(fresh())
        dr.eval(r)
        dr.sync_thread()
    rec = {"variant": variant}
    for label, fn in (("closest_hit", closest), ("any_hit", occluded)):
        fn()
        fn()
        times = []
        for _ in range(repeats):
            s = time.perf_counter()
            fn()
            times.append(time.perf_counter() - s)
        rec[label + "_rays_per_s"] = len(origins) / float(np.median(times))
    agree = float((np.isfinite(np.array(closest().t)) == ours_hit).mean())
    return rec, agree


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", choices=list(CONVERGENCE))
    p.add_argument("--rays", type=int, default=400_000)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--backend", default="cpu", choices=("cpu", "cuda"),
                   help="cuda: both trees traversed on the GPU, one ray per thread (the "
                        "renderer's GPU kernels traverse the binary tree)")
    p.add_argument("--order", default="random", choices=("random", "origin"),
                   help="origin: the rays sorted by the triangle they leave, as coherent "
                        "as a pixel's bounce rays in a render (default: random order)")
    p.add_argument("--mitsuba", action="store_true",
                   help="also Mitsuba 3's closest and any hits on the same rays")
    p.add_argument("--json")
    args = p.parse_args(argv)
    from pathtracer.scene import compile_scene
    from bench.common import machine, now, versions
    scene = compile_scene(convergence_desc(args.scene))
    a = scene.arrays
    n_tri = scene.n_triangles
    origins, dirs, skip = make_rays(a.tri_v, args.rays, args.order)
    t0 = time.perf_counter()
    wide, wchild = widen_bvh(a.tri_v, a.bvh_box, a.bvh_child)
    widen_s = time.perf_counter() - t0
    if args.backend == "cuda":
        from pathtracer.kernels.constants import STACK_SIZE
        trees = {"binary": (cuda_tracers(closest_hit, any_hit, STACK_SIZE), a.bvh_box,
                            a.bvh_child),
                 "wide": (cuda_tracers(closest_hit_wide, any_hit_wide, WIDE_STACK_SIZE),
                               wide, wchild)}
        put, get = cuda.to_device, (lambda x: x.copy_to_host())
    else:
        trees = {"binary": (tracers(closest_hit, any_hit), a.bvh_box, a.bvh_child),
                 "wide": (tracers(closest_hit_wide, any_hit_wide), wide, wchild)}
        put = get = (lambda x: x)
    rays = [put(x) for x in (origins, dirs, skip, a.tri_v)]
    out = {}
    hits = {}
    agree = None
    for name, ((trace, shadow), box, child) in trees.items():
        t = put(np.empty(args.rays, np.float32))
        tri = put(np.empty(args.rays, np.int32))
        hit = put(np.empty(args.rays, np.bool_))
        box, child = put(box), put(child)
        rec = {}
        for label, fn in (("closest_hit", trace), ("any_hit", shadow)):
            t_c = time.perf_counter()
            fn(*rays, box, child, t, tri, hit)      # compile, warm up
            rec[label + "_first_call_s"] = time.perf_counter() - t_c
            times = []
            for _ in range(args.repeats):
                s = time.perf_counter()
                fn(*rays, box, child, t, tri, hit)
                times.append(time.perf_counter() - s)
            rec[label + "_rays_per_s"] = args.rays / float(np.median(times))
        hits[name] = (get(tri).copy(), get(hit).copy(), get(t).copy())
        out[name] = rec
        print(f"{args.scene} {name} ({args.order} order): closest hit {rec['closest_hit_rays_per_s'] / 1e6:.2f} M "
              f"rays/s, any hit {rec['any_hit_rays_per_s'] / 1e6:.2f} M rays/s")
    if args.mitsuba:
        rec, agree = mitsuba_rates(a.tri_v, origins, dirs, hits["binary"][0] >= 0,
                                   args.backend, args.repeats)
        if rec is not None:
            out["mitsuba"] = rec
            print(f"{args.scene} mitsuba {rec['variant']} ({args.order} order): closest hit "
                  f"{rec['closest_hit_rays_per_s'] / 1e6:.2f} M rays/s, any hit "
                  f"{rec['any_hit_rays_per_s'] / 1e6:.2f} M rays/s; hits agree on "
                  f"{agree:.5f} of the rays")
    (tri_a, hit_a, t_a), (tri_b, hit_b, t_b) = hits["binary"], hits["wide"]
    same = bool(((tri_a == tri_b) | (t_a == t_b)).all() and (hit_a == hit_b).all())
    print(f"same hits: {same}; hit fraction {float((hits['binary'][0] >= 0).mean()):.3f}; "
          f"collapse {widen_s * 1e3:.1f} ms (first call includes its compile)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"command": "python -m bench.traversal " + " ".join(sys.argv[1:]),
                       "machine": machine(), "date": now(), "versions": versions(),
                       "scene": args.scene, "backend": args.backend, "rays": args.rays,
                       "order": args.order,
                       "triangles": int(n_tri),
                       "binary_nodes": int(len(a.bvh_box)), "wide_nodes": int(len(wchild)),
                       "wide_bytes": int(wide.nbytes + wchild.nbytes),
                       "binary_bytes": int(a.bvh_box.nbytes + a.bvh_child.nbytes),
                       "same_hits": same, "mitsuba_hits_agree": agree, "results": out}, f,
                      indent=1)
    return 0 if same and (agree is None or agree >= 0.999) else 1


if __name__ == "__main__":
    sys.exit(main())
