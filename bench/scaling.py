"""Scaling with the triangle count: one mesh per fresh process (so that peak memory and device
memory are the mesh's own), reporting load and BVH build times, host and device bytes, and
traversal speed. `python -m bench` runs it over 1k to 6.4M triangles; alone:

    python -m bench.scaling MESH.obj --backend cpu|cuda [--res W H] [--spp N] [--repeats N]

The big meshes are the Stanford dragon subdivided by shared/tools/make_big_mesh.py (k = 1, 2,
3: 400k, 1.6M, 6.4M triangles), made once into bench/out/meshes/.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench.common import SHARED, median_time

MESH_DIR = os.path.join(ROOT, "bench", "out", "meshes")


def big_mesh(k):
    """Path of the dragon subdivided k times (100k x 4^k triangles), made if missing."""
    path = os.path.join(MESH_DIR, f"dragon_{100 * 4 ** k}k.obj")
    if not os.path.isfile(path):
        os.makedirs(MESH_DIR, exist_ok=True)
        tool = os.path.join(SHARED, "tools", "make_big_mesh.py")
        t0 = time.perf_counter()
        subprocess.run([sys.executable, tool, path + ".tmp", str(k)], check=True,
                       stdout=subprocess.DEVNULL)
        os.replace(path + ".tmp", path)
        print(f"bench: made {os.path.basename(path)} in {time.perf_counter() - t0:.0f} s",
              file=sys.stderr)
    return path


def measure(obj, backend_name, res, spp, repeats):
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    from bench.scenes import mesh_desc
    from pathtracer.scene.meshes import load_obj
    t0 = time.perf_counter()
    mesh = load_obj(obj)                # parses the OBJ unless the mesh cache has it
    load = {"load_s": time.perf_counter() - t0, "load_from_cache": mesh.from_cache}
    del mesh
    desc = mesh_desc(obj, res)
    from pathtracer.accel import build_bvh
    build_bvh(load_obj(obj).positions[:64])     # load the builder's compiled code first
    t0 = time.perf_counter()
    scene = compile_scene(desc)
    compile_s = time.perf_counter() - t0
    n = scene.n_triangles
    host = {k: int(a.nbytes) for k, a in scene.arrays._asdict().items()}
    rec = {"triangles": n, **load, "scene_compile_s": compile_s,
           "mesh_load_s": scene.timings["mesh_load"], "bvh_build_s": scene.timings["bvh_build"],
           "bvh_nodes": int(len(scene.arrays.bvh_box)), "bvh_depth": int(scene.bvh_depth),
           "host_bytes": sum(host.values()),
           "host_geometry_bytes": sum(host[k] for k in ("tri_v", "tri_n", "tri_mat",
                                                         "tri_light_pdf", "tri_uv", "tri_t",
                                                         "bvh_box", "bvh_child"))}
    if backend_name == "cuda":
        from numba import cuda
        ctx = cuda.current_context()
        free0 = ctx.get_memory_info()[0]
        backend = make_backend("cuda", scene)
        cuda.synchronize()
        film = backend.d_out.nbytes + backend.d_stats.nbytes
        rec["device_bytes"] = int(free0 - ctx.get_memory_info()[0] - film)
    else:
        backend = make_backend(backend_name, scene)
    if backend_name == "cpu":
        # the CPU's eight-wide tree (kernels.wide), collapsed from the binary one per backend
        from pathtracer.backends.cpu import cpu_arrays
        t0 = time.perf_counter()
        _, (_, (wide, wchild)) = cpu_arrays(scene.arrays)
        rec["widen_s"] = time.perf_counter() - t0
        rec["wide_nodes"] = int(len(wchild))
        rec["wide_bytes"] = int(wide.nbytes + wchild.nbytes)
    backend.compile()
    backend.render_pass(0, spp, 0, scene.max_bounces, scene.rr_depth)     # warm-up
    t, _ = median_time(lambda: backend.render_pass(0, spp, 0, scene.max_bounces,
                                                   scene.rr_depth), repeats)
    rec["paths_per_s"] = res[0] * res[1] * spp / t
    rec["ns_per_path"] = 1e9 * t / (res[0] * res[1] * spp)
    rec["peak_rss_bytes"] = peak_rss()
    return rec


def peak_rss():
    """Peak resident memory of this process, import and kernels included. Linux's VmHWM
    starts afresh at exec; ru_maxrss does not (a child started by a big parent inherits the
    parent's size), so it is only the fallback."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def run(obj, backend_name, res, spp, repeats):
    """measure() in a fresh process; returns its record, or {"error": ...}."""
    cmd = [sys.executable, "-m", "bench.scaling", obj, "--backend", backend_name, "--res",
           str(res[0]), str(res[1]), "--spp", str(spp), "--repeats", str(repeats)]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if r.returncode != 0:
        return {"error": (r.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(r.stdout.strip().splitlines()[-1])


def growth_exponent(triangles, seconds):
    """Least-squares slope of log(seconds) against log(triangles): time ~ N^slope."""
    import numpy as np
    x, y = np.log(np.asarray(triangles, float)), np.log(np.asarray(seconds, float))
    return float(np.polyfit(x, y, 1)[0])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("mesh")
    p.add_argument("--backend", default="cpu")
    p.add_argument("--res", type=int, nargs=2, default=(96, 96))
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args(argv)
    print(json.dumps(measure(a.mesh, a.backend, tuple(a.res), a.spp, a.repeats)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
