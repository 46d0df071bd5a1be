"""Core throughput benchmark (issue: core renderer).

Measures, in one run on one machine:
- camera paths/s and rays/s (camera + bounce + shadow) on the Cornell box, 256x256 on the
  CPU and 1024x1024 on the GPU: median of repeated passes after a warm-up pass;
- cold and warm kernel compile times (cold: an empty Numba cache, in a fresh process; warm:
  a fresh process loading the cache), and the warm start's time to the first pixel;
- load time (first, uncached, and cached) and BVH build time of a large mesh;
- the same scene in Mitsuba 3 (llvm_ad_rgb on CPU, cuda_ad_rgb on GPU) when installed.

Writes a JSON record and prints a markdown table.

    python -m bench.throughput --cpu [--mitsuba] [--big-mesh PATH] [--json OUT]
    python -m bench.throughput --gpu [--mitsuba] [--json OUT]
    python -m bench.throughput --cpu --scenes cornell-box bunny-studio sun [--rounds 3]
        [--samplers sobol independent] [--processes 5]

``--processes K`` (with ``--scenes``): the whole comparison K times, each in a fresh
process, and the median of the K processes' ratios. A process's compiled kernels run a few
per cent faster or slower than the same kernels in another process (on the 2-core CPU the
same tree against itself in one pair of workers measured 0.955, 2026-11-29: bench.ab's
docstring), so rounds within one process share that bias; separate processes do not.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from bench.scenes import CONVERGENCE
from bench.common import (CORNELL, command, machine, median_time, mitsuba_cornell,
                          mitsuba_pass_times,
                          now, usable_mitsuba, versions)


def prepare(backend_name, desc):
    """(scene, backend) of a scene description, for :func:`ours`."""
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    scene = compile_scene(desc)
    return scene, make_backend(backend_name, scene)


def ours(backend_name, resolution, spp_per_pass, repeats, prepared=None):
    """pt-render's pass times on the Cornell box at ``resolution``, or with ``prepared``
    (scene, backend) of :func:`prepare` (any scene at its own resolution, its BVH built and
    kernel compiled once for several calls)."""
    if prepared is None:
        from pathtracer.scene import load_scene_description
        desc = load_scene_description(CORNELL)
        desc.camera.resolution = resolution
        prepared = prepare(backend_name, desc)
    scene, backend = prepared
    resolution = (scene.width, scene.height)
    t0 = time.perf_counter()
    backend.compile()
    compile_s = time.perf_counter() - t0
    mb, rr = scene.max_bounces, scene.rr_depth
    state = {"start": 0}

    def one_pass():
        if backend_name == "cuda":
            from numba import cuda
            backend.launch(state["start"], spp_per_pass, 0, mb, rr)
            cuda.synchronize()
        else:
            backend.render_pass(state["start"], spp_per_pass, 0, mb, rr)
        state["start"] += spp_per_pass

    one_pass()  # warm-up
    t, times = median_time(one_pass, repeats)
    # Ray counts of one pass (same scene and spp: counts are stable to << 1%).
    _, stats = backend.render_pass(state["start"], spp_per_pass, 0, mb, rr)
    totals = stats.reshape(-1, 3).sum(axis=0, dtype="int64")
    paths = resolution[0] * resolution[1] * spp_per_pass
    return {
        "renderer": f"pt-render {backend_name}", "resolution": list(resolution),
        "spp_per_pass": spp_per_pass, "repeats": repeats, "pass_s_median": t,
        "pass_s_all": times, "paths_per_s": paths / t,
        "rays_per_s": (paths + int(totals[0]) + int(totals[1])) / t,
        "bounce_rays_per_path": int(totals[0]) / paths,
        "shadow_rays_per_path": int(totals[1]) / paths,
        "nonfinite": int(totals[2]), "compile_s_this_process": compile_s,
    }


def mitsuba(variant, resolution, spp, repeats):
    ok, why = usable_mitsuba(variant)
    if not ok:
        print(f"throughput: Mitsuba {variant} cannot render here ({why})", file=sys.stderr)
        return None
    import mitsuba as mi
    mi.set_variant(variant)
    scene = mitsuba_cornell(resolution[0], resolution[1], spp)
    first, t, times = mitsuba_pass_times(scene, spp, repeats)
    return {"renderer": f"Mitsuba {mi.__version__} {variant}", "resolution": list(resolution),
            "spp_per_pass": spp, "repeats": repeats, "pass_s_median": t, "pass_s_all": times,
            "paths_per_s": resolution[0] * resolution[1] * spp / t, "first_render_s": first}


def convergence_scenes(names, spp, repeats, rounds, samplers=("sobol",)):
    """pt-render's CPU backend and Mitsuba llvm_ad_rgb on the convergence scenes ``names``
    at their benchmark sizes (bench.scenes.CONVERGENCE; Mitsuba's scenes as the
    convergence section renders them, with its independent sampler), in ``rounds`` rounds
    that alternate the two renderers' order: this machine's speed drifts by 10-30 % over
    minutes, so only figures taken side by side compare. Each round records each
    renderer's median pass. ``samplers``: ours with each of these samplers in every round
    (the first is the record's main figure): the Sobol sampler's hashing cost the CPU
    9-20 % of its paths/s on 2026-11-28 (docs/benchmarks.md), and Mitsuba's figures are of
    its independent sampler."""
    from bench.scenes import mitsuba_scene
    from bench.scenes import convergence_desc
    out = []
    ok, why = usable_mitsuba("llvm_ad_rgb")
    if not ok:
        print(f"throughput: Mitsuba llvm_ad_rgb cannot render here ({why})", file=sys.stderr)
    for name in names:
        got = None
        if ok:
            import mitsuba as mi
            mi.set_variant("llvm_ad_rgb")
            got = mitsuba_scene(name, "independent")
        prepared = {}                       # (the BVH and the kernel once, not each round)
        for sampler in samplers:
            desc = convergence_desc(name)
            desc.render.sampler = sampler
            prepared[sampler] = prepare("cpu", desc)
        res = list(desc.camera.resolution)
        paths = res[0] * res[1] * spp
        rows = {"mitsuba": [], **{sampler: [] for sampler in samplers}}
        for k in range(rounds):
            order = (*samplers, "mitsuba") if k % 2 == 0 else ("mitsuba", *samplers[::-1])
            for who in order:
                if who != "mitsuba":
                    rows[who].append(ours("cpu", None, spp, repeats,
                                          prepared=prepared[who])["paths_per_s"])
                elif got is not None:
                    _, t, _ = mitsuba_pass_times(got[0], spp, repeats)
                    rows["mitsuba"].append(paths / t)
        rec = {"scene": name, "resolution": res, "spp_per_pass": spp, "repeats": repeats,
               "rounds": rounds, "sampler": samplers[0],
               "pt_render_paths_per_s": rows[samplers[0]],
               "mitsuba_paths_per_s": rows["mitsuba"]}
        if len(samplers) > 1:
            rec["pt_render_paths_per_s_by_sampler"] = {x: rows[x] for x in samplers}
        if rows["mitsuba"]:
            rec["ratio_of_medians"] = float(np.median(rows[samplers[0]]) /
                                            np.median(rows["mitsuba"]))
            rec["ratio_per_round"] = [a / b for a, b in zip(rows[samplers[0]],
                                                            rows["mitsuba"])]
            if len(samplers) > 1:
                rec["ratio_of_medians_by_sampler"] = {
                    x: float(np.median(rows[x]) / np.median(rows["mitsuba"]))
                    for x in samplers}
        out.append(rec)
        line = ", ".join(f"pt-render {x} {np.median(rows[x]) / 1e6:.3f}" for x in samplers)
        if rows["mitsuba"]:
            line += (f", Mitsuba {np.median(rows['mitsuba']) / 1e6:.3f} M paths/s: "
                     + ", ".join(f"{x} {np.median(rows[x]) / np.median(rows['mitsuba']):.3f}x"
                                 for x in samplers)
                     + f" ({samplers[0]} per round "
                     + ", ".join(f"{v:.3f}" for v in rec["ratio_per_round"]) + ")")
        else:
            line += " M paths/s"
        print(f"{name}: {line}", flush=True)
    return out


COMPILE_PROBE = r"""
import sys, time, json
t0 = time.perf_counter()
from pathtracer.scene import compile_scene, load_scene_description
from pathtracer.backends import make_backend
desc = load_scene_description(sys.argv[1]); desc.camera.resolution = (64, 64)
scene = compile_scene(desc)
backend = make_backend(sys.argv[2], scene)
t1 = time.perf_counter()
backend.compile()
t2 = time.perf_counter()
backend.render_pass(0, 1, 0, scene.max_bounces, scene.rr_depth)
t3 = time.perf_counter()
features = [k for k, v in scene.features._asdict().items() if v]
print(json.dumps({"import_and_load_s": t1 - t0, "compile_s": t2 - t1,
                  "first_pass_s": t3 - t2, "to_first_pixel_s": t3 - t0,
                  "features": features}))
"""


def compile_times(backend_name, scene_path=CORNELL):
    """Cold (empty cache) and warm (cache filled by the cold run) compile, fresh processes."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold", "warm"):
            r = subprocess.run([sys.executable, "-c", COMPILE_PROBE, scene_path, backend_name],
                               capture_output=True, text=True, env=env)
            if r.returncode != 0:
                out[label] = {"error": r.stderr.strip().splitlines()[-1:]}
            else:
                out[label] = json.loads(r.stdout.strip().splitlines()[-1])
    return out


def big_mesh(path):
    from pathtracer.accel import build_bvh
    from pathtracer.scene.meshes import load_obj
    with tempfile.TemporaryDirectory() as cache:
        os.environ["PT_RENDER_CACHE"] = cache
        t0 = time.perf_counter()
        mesh = load_obj(path)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        mesh2 = load_obj(path)
        second = time.perf_counter() - t0
        assert mesh2.from_cache
        del os.environ["PT_RENDER_CACHE"]
    build_bvh(mesh.positions[:100])  # compile the builder outside the timing
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        bvh = build_bvh(mesh.positions)
        times.append(time.perf_counter() - t0)
    times.sort()
    return {"mesh": os.path.basename(path), "triangles": int(len(mesh.positions)),
            "load_first_s": first, "load_cached_s": second, "bvh_build_s_median": times[1],
            "bvh_build_s_all": times, "bvh_nodes": int(len(bvh.box)), "bvh_depth": bvh.depth}


def _run_child(argv):
    """``python -m bench.throughput ARGV`` in a fresh process; one that fails ends the run
    with a one-line message (its own error is above it)."""
    r = subprocess.run([sys.executable, "-m", "bench.throughput", *argv])
    if r.returncode != 0:
        sys.exit(f"bench.throughput: a child process failed (exit {r.returncode}): "
                 f"python -m bench.throughput {' '.join(argv)}")


def in_processes(a):
    """``--processes K``: this command without --processes, K times in fresh processes;
    per scene the median over processes of each one's ratio of medians."""
    rec = {"command": command(), "machine": machine(), "date": now(), "versions": versions(),
           "processes": []}
    argv = ["--cpu", "--scenes", *a.scenes, "--rounds", str(a.rounds), "--repeats",
            str(a.repeats), "--spp", str(a.spp), "--samplers", *a.samplers]
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.processes):
            out = os.path.join(tmp, f"{k}.json")
            print(f"process {k + 1} of {a.processes}", flush=True)
            _run_child([*argv, "--json", out])
            with open(out) as f:
                rec["processes"].append(json.load(f)["scenes"])
    rec["summary"] = {}
    print(f"\n{rec['command']}\n{rec['machine']}, {rec['date']}\n")
    for name in a.scenes:
        rows = [next(r for r in scenes if r["scene"] == name) for scenes in rec["processes"]]
        if not all("ratio_of_medians_by_sampler" in r or "ratio_of_medians" in r
                   for r in rows):
            continue
        # (one sampler: a record has ratio_of_medians alone)
        by = {x: [r["ratio_of_medians_by_sampler"][x] if "ratio_of_medians_by_sampler" in r
                  else r["ratio_of_medians"] for r in rows]
              for x in dict.fromkeys(a.samplers)}
        rec["summary"][name] = {x: {"ratio_per_process": v, "median": float(np.median(v))}
                                for x, v in by.items()}
        print(f"{name}: " + "; ".join(
            f"{x} {np.median(v):.3f}x Mitsuba (processes " +
            ", ".join(f"{r:.3f}" for r in v) + ")" for x, v in by.items()), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rec, f, indent=1)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cpu", action="store_true")
    p.add_argument("--gpu", action="store_true")
    p.add_argument("--mitsuba", action="store_true", help="also measure Mitsuba 3")
    p.add_argument("--big-mesh", help="OBJ for load/BVH timings (make_big_mesh.py output)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scenes", nargs="+", metavar="SCENE", choices=list(CONVERGENCE),
                   help="with --cpu: instead, these convergence scenes (%(choices)s) at "
                        "their benchmark sizes, pt-render's CPU backend and Mitsuba "
                        "llvm_ad_rgb in alternating rounds")
    p.add_argument("--rounds", type=int, default=3, help="rounds per scene (--scenes)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel per pass (--scenes)")
    p.add_argument("--samplers", nargs="+", choices=("sobol", "independent"),
                   default=["sobol"], help="(--scenes) ours with each of these samplers, "
                   "the first the main figure (Mitsuba runs its independent sampler)")
    p.add_argument("--processes", type=int, default=1, metavar="K",
                   help="(--scenes) the comparison in K fresh processes; the record keeps "
                        "each process's rounds and the median of their ratios")
    p.add_argument("--json", help="write the record here")
    a = p.parse_args()
    if a.scenes and not a.cpu:
        p.error("--scenes measures the CPU backend: give --cpu")
    if a.samplers != ["sobol"] and not a.scenes:
        p.error("--samplers applies to --scenes")
    if a.processes > 1:
        if not a.scenes:
            p.error("--processes applies to --scenes")
        return in_processes(a)
    rec = {"command": command(), "machine": machine(), "date": now(), "versions": versions(),
           "results": []}
    if a.cpu and a.scenes:
        rec["scenes"] = convergence_scenes(a.scenes, a.spp, a.repeats, a.rounds,
                                           tuple(dict.fromkeys(a.samplers)))
    elif a.cpu:
        rec["results"].append(ours("cpu", (256, 256), 16, a.repeats))
        if a.mitsuba:
            rec["results"].append(mitsuba("llvm_ad_rgb", (256, 256), 16, a.repeats))
            rec["results"] = [x for x in rec["results"] if x]
        rec["compile_cpu"] = compile_times("cpu")
    if a.gpu:
        rec["results"].append(ours("cuda", (1024, 1024), 64, a.repeats))
        if a.mitsuba:
            rec["results"].append(mitsuba("cuda_ad_rgb", (1024, 1024), 64, a.repeats))
            rec["results"] = [x for x in rec["results"] if x]
        rec["compile_cuda"] = compile_times("cuda")
    if a.big_mesh:
        rec["big_mesh"] = big_mesh(a.big_mesh)
    print(f"\n{rec['command']}\n{rec['machine']}, {rec['date']}\n")
    print("| renderer | resolution | spp/pass | median pass (s) | M camera paths/s | M rays/s |")
    print("|---|---|---|---|---|---|")
    for r in rec["results"]:
        rays = f"{r['rays_per_s'] / 1e6:.1f}" if "rays_per_s" in r else "n/a"
        print(f"| {r['renderer']} | {r['resolution'][0]}x{r['resolution'][1]} | "
              f"{r['spp_per_pass']} | {r['pass_s_median']:.4f} | {r['paths_per_s'] / 1e6:.2f} "
              f"| {rays} |")
    for k in ("compile_cpu", "compile_cuda", "big_mesh"):
        if k in rec:
            print(f"\n{k}: {json.dumps(rec[k], indent=1)}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rec, f, indent=1)


if __name__ == "__main__":
    main()
