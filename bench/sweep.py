"""Parameter sweep benchmark (issue: Python API): the roughness of a principled sphere from
0 to 1 in STEPS renders, timed three ways in one run on one machine:

- **API**: ``pathtracer.load_scene`` once, then per step ``scene.set`` + ``pathtracer.render``
  (no recompilation: the step's wall time minus its rendering time is the overhead);
- **CLI**: STEPS separate ``pt-render`` processes on STEPS scene files (kernels from the
  warm disk cache; each process pays Python start-up, imports, scene load, BVH, cache load,
  and writing the image);
- **Mitsuba 3** through its Python API: ``mi.load_dict`` once, then per step
  ``params[key] = value; params.update(); mi.render(scene, spp=SPP)`` and waiting for the
  image (``llvm_ad_rgb`` on the CPU, ``cuda_ad_rgb`` on the GPU); its rendering time is
  that of the same render repeated without a change, and its overhead the difference.

Each reports the first step apart (it compiles) and the median of the others. Writes a JSON
record and prints a markdown table.

Also times ``scene.set`` by kind of change on scenes/principled-grid.json (BVH reused or
rebuilt).

    python -m bench.sweep --backend cpu [--mitsuba] [--steps 20] [--spp 16] [--json OUT]
    python -m bench.sweep --backend cuda --mitsuba
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

from bench.common import ROOT, command, machine, now, usable_mitsuba, versions

ASSETS = os.path.join(ROOT, "scenes", "assets")


def sweep_scene(width, height, spp, roughness=0.0):
    """A principled sphere (half metallic, orange) on a grey ground under a constant sky."""
    return {
        "camera": {"resolution": [width, height], "position": [0, 0.6, 2.6],
                   "lookAt": [0, 0.05, 0], "fov": 40},
        "render": {"spp": spp, "maxBounces": 8},
        "materials": [{"name": "ground", "type": "diffuse", "albedo": 0.5},
                      {"name": "ball", "albedo": [0.9, 0.55, 0.25], "metallic": 0.5,
                       "roughness": roughness}],
        "objects": [{"name": "ground", "file": os.path.join(ASSETS, "plane.obj"),
                     "material": "ground",
                     "transform": {"scale": [8, 1, 8], "translate": [0, -0.4, 0]}},
                    {"name": "ball", "file": os.path.join(ASSETS, "sphere.obj"),
                     "material": "ball", "smooth": True,
                     "transform": {"scale": 0.4, "translate": [0, 0, 0]}}],
        "environment": {"color": [0.8, 0.9, 1.0]},
    }


def values(steps):
    return [i / (steps - 1) for i in range(steps)]


def summary(walls, extra=None):
    out = {"first_s": walls[0], "median_s": statistics.median(walls[1:]),
           "total_s": sum(walls), "walls_s": walls}
    out.update(extra or {})
    return out


def run_api(backend, steps, spp, width, height):
    import pathtracer as pt
    t0 = time.perf_counter()
    scene = pt.load_scene(sweep_scene(width, height, spp))
    load_s = time.perf_counter() - t0
    walls, renders, sets, compiles = [], [], [], []
    for v in values(steps):
        t0 = time.perf_counter()
        scene.set("/materials/ball/roughness", v)
        t1 = time.perf_counter()
        r = pt.render(scene, spp=spp, backend=backend)
        walls.append(time.perf_counter() - t0)
        sets.append(t1 - t0)
        renders.append(r.seconds)
        compiles.append(r.compile_seconds)
        assert r.spp == spp
    overhead = [w - r for w, r in zip(walls, renders)]
    return summary(walls, {"load_s": load_s, "render_median_s": statistics.median(renders[1:]),
                           "set_median_s": statistics.median(sets[1:]),
                           "overhead_median_s": statistics.median(overhead[1:]),
                           "compile_first_s": compiles[0],
                           "compile_later_s": max(compiles[1:]), "backend": r.backend})


def run_cli(backend, steps, spp, width, height):
    walls, renders = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i, v in enumerate(values(steps)):
            path = os.path.join(tmp, f"step{i}.json")
            with open(path, "w") as f:
                json.dump(sweep_scene(width, height, spp, v), f)
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "pathtracer", path, "--spp", str(spp),
                                "--backend", backend, "--quiet", "-o",
                                os.path.join(tmp, f"step{i}.exr")],
                               capture_output=True, text=True, cwd=ROOT)
            walls.append(time.perf_counter() - t0)
            if r.returncode != 0:
                raise RuntimeError(f"pt-render failed: {r.stderr[-500:]}")
            m = re.search(r"(\d+) spp in ([0-9.]+) s", r.stderr)
            renders.append(float(m.group(2)))
    overhead = [w - r for w, r in zip(walls, renders)]
    return summary(walls, {"render_median_s": statistics.median(renders[1:]),
                           "overhead_median_s": statistics.median(overhead[1:])})


def run_mitsuba(variant, steps, spp, width, height):
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(variant)
    from pathtracer.api import load_scene
    from pathtracer.mitsuba import mitsuba_dict
    t0 = time.perf_counter()
    scene = mi.load_dict(mitsuba_dict(load_scene(sweep_scene(width, height, spp)).description,
                                      spp=spp))
    load_s = time.perf_counter() - t0
    params = mi.traverse(scene)
    keys = [k for k in params.keys() if "mat-ball" in k and k.endswith("roughness.value")]
    if len(keys) != 1:
        raise RuntimeError(f"no single roughness parameter in {list(params.keys())}")
    walls = []
    for v in values(steps):
        t0 = time.perf_counter()
        params[keys[0]] = v
        params.update()
        img = mi.render(scene, spp=spp)
        dr.eval(img)
        dr.sync_thread()
        walls.append(time.perf_counter() - t0)
    # the same render without a parameter change: Mitsuba's rendering alone, so that the
    # difference estimates what a change costs it
    again = []
    for _ in range(max(3, steps // 4)):
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp)
        dr.eval(img)
        dr.sync_thread()
        again.append(time.perf_counter() - t0)
    render_s = statistics.median(again)
    return summary(walls, {"load_s": load_s, "parameter": keys[0], "render_median_s": render_s,
                           "overhead_median_s": statistics.median(walls[1:]) - render_s})


UPDATES = (("material value", "/materials/r2m1/roughness", lambda i: 0.1 * (i % 10)),
           ("camera position", "/camera/position", lambda i: [0.1 * (i % 5), 2.6, 5.2]),
           ("environment intensity", "/environment/intensity", lambda i: 0.5 + 0.1 * (i % 5)),
           ("object transform", "/objects/r2m1/transform",
            lambda i: {"scale": 0.4, "translate": [0.0, 0.1 * (i % 5), 0.0]}))


def run_updates(repeats=5):
    """What ``scene.set`` costs on scenes/principled-grid.json (33,122 triangles, textured,
    HDRI): the median time of each kind of change, and whether the BVH was rebuilt."""
    import pathtracer as pt
    scene = pt.load_scene(os.path.join(ROOT, "scenes", "principled-grid.json"))
    out = {"scene": "scenes/principled-grid.json", "triangles": scene.n_triangles,
           "load_s": scene.last_update["seconds"]}
    for label, path, value in UPDATES:
        times, bvh, states = [], [], set()
        for i in range(repeats + 1):
            scene.set(path, value(i + 1))
            if i:
                times.append(scene.last_update["seconds"])
                bvh.append(scene.last_update["bvh_seconds"])
                states.add(scene.last_update["bvh"])
        out[label] = {"path": path, "set_median_s": statistics.median(times),
                      "bvh_median_s": statistics.median(bvh), "bvh": "/".join(sorted(states))}
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--backend", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--resolution", default="256x256")
    p.add_argument("--mitsuba", action="store_true")
    p.add_argument("--no-cli", action="store_true")
    p.add_argument("--no-updates", action="store_true")
    p.add_argument("--json", default=None)
    a = p.parse_args(argv)
    w, h = (int(x) for x in a.resolution.split("x"))
    rec = {"command": command(), "machine": machine(), "date": now(), "versions": versions(),
           "steps": a.steps, "spp": a.spp, "resolution": [w, h], "backend": a.backend}
    rec["api"] = run_api(a.backend, a.steps, a.spp, w, h)
    if not a.no_cli:
        rec["cli"] = run_cli(a.backend, a.steps, a.spp, w, h)
    if a.mitsuba:
        variant = "llvm_ad_rgb" if a.backend == "cpu" else "cuda_ad_rgb"
        ok, why = usable_mitsuba(variant)
        rec["mitsuba"] = run_mitsuba(variant, a.steps, a.spp, w, h) if ok else {"error": why}
        rec["mitsuba"]["variant"] = variant
    if not a.no_updates:
        rec["updates"] = run_updates()
    out = a.json or os.path.join(ROOT, "bench", "results", f"sweep-{a.backend}.json")
    with open(out, "w") as f:
        json.dump(rec, f, indent=1)
    print(f"{rec['command']}; {rec['machine']}; {rec['date']}")
    print(f"{a.steps} renders, {w}x{h}, {a.spp} spp, roughness 0 -> 1\n")
    print("| way | first render (s) | later renders, median (s) | of which rendering (s) "
          "| overhead per re-render (s) | sweep total (s) |")
    print("|---|---|---|---|---|---|")
    for name, label in (("api", "pt-render Python API"), ("cli", "pt-render CLI, one process "
                                                                    "per render"),
                        ("mitsuba", "Mitsuba 3 Python API")):
        r = rec.get(name)
        if not r or "error" in r:
            if r:
                print(f"| {label} | {r['error']} | | | | |")
            continue
        rend = f"{r['render_median_s']:.4f}" if "render_median_s" in r else "-"
        over = f"{r['overhead_median_s']:.4f}" if "overhead_median_s" in r else "-"
        print(f"| {label} | {r['first_s']:.3f} | {r['median_s']:.4f} | {rend} | {over} | "
              f"{r['total_s']:.2f} |")
    u = rec.get("updates")
    if u:
        print(f"\nscene.set on {u['scene']} ({u['triangles']} triangles; loaded in "
              f"{u['load_s']:.2f} s):\n")
        print("| change | path | scene.set, median (s) | BVH |")
        print("|---|---|---|---|")
        for label, _, _ in UPDATES:
            r = u[label]
            bvh = r["bvh"] + (f" ({r['bvh_median_s']:.3f} s)" if r["bvh"] == "built" else "")
            print(f"| {label} | `{r['path']}` | {r['set_median_s']:.4f} | {bvh} |")
    print(f"\nwritten to {os.path.relpath(out, ROOT)}")


if __name__ == "__main__":
    main()
