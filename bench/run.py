"""The batch benchmark: error against run time, throughput, texture filtering, CUDA block
sizes and compile times, written as CSV (every row with its command, machine and date),
PNG plots and a markdown summary.

    python -m bench --quick            # a few minutes on 2 CPU cores
    python -m bench                    # full CPU run
    python -m bench --gpu              # CUDA (H100 / H200), with Mitsuba's cuda variant if installed
    python -m bench --quick --tiny     # seconds: what CI runs

Mitsuba 3 (`pip install -e .[bench]`) is measured in the same run where a scene can be
expressed in it (the Cornell box), on the same device kind (llvm on the CPU, cuda on the GPU).
"""
import argparse
import csv
import datetime
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench.common import CORNELL, CORNELL_REF, command, machine, now, versions  # noqa: E402
from bench.metrics import rays_per_second, relmse, time_to_threshold  # noqa: E402

FIELDS = ["section", "scene", "renderer", "parameter", "value", "metric", "result", "unit",
          "command", "machine", "date"]
THRESHOLDS = (1e-2, 1e-3)
SECTIONS = ("convergence", "throughput", "filtering", "blocks", "bvh", "compile")


class Results:
    def __init__(self, out):
        self.out = out
        self.rows = []
        self.context = {"command": command(), "machine": machine(), "date": now()}

    def add(self, section, scene, renderer, metric, result, unit, parameter="", value=""):
        self.rows.append(dict(section=section, scene=scene, renderer=renderer,
                              parameter=parameter, value=value, metric=metric, result=result,
                              unit=unit, **self.context))

    def write(self):
        with open(os.path.join(self.out, "results.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, FIELDS)
            w.writeheader()
            w.writerows(self.rows)


# ---------------------------------------------------------------------------------------
# Error against run time

def _cornell(resolution):
    from pathtracer.scene import compile_scene, load_scene_description
    desc = load_scene_description(CORNELL)
    desc.camera.resolution = resolution
    return compile_scene(desc)


def convergence_ours(backend_name, max_spp, res):
    """(seconds, spp, relMSE) after each progressive pass, compile excluded."""
    from pathtracer.backends import make_backend
    from pathtracer.render import render
    ref = np.load(CORNELL_REF)
    scene = _cornell(res)
    backend = make_backend(backend_name, scene)
    backend.compile()
    points = []

    def on_pass(film, elapsed):
        points.append((elapsed, film.spp, relmse(film.image(), ref)))

    # passes of 1, 2, 4, ... spp: the error is measured at doubling sample counts
    render(scene, backend, spp=max_spp, on_pass=on_pass, pass_seconds=float("inf"))
    return points


def convergence_mitsuba(variant, max_spp, res):
    """Mitsuba is not progressive: one render per spp level, each timed alone."""
    import drjit as dr
    import mitsuba as mi

    from bench.common import mitsuba_cornell
    mi.set_variant(variant)
    ref = np.load(CORNELL_REF)
    points = []
    spp = 1
    scene = mitsuba_cornell(res[0], res[1], 1)
    dr.eval(mi.render(scene, spp=1, seed=99))    # warm-up (kernel compilation)
    while spp <= max_spp:
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=spp)
        dr.eval(img)
        dr.sync_thread()
        points.append((time.perf_counter() - t0, spp, relmse(np.array(img), ref)))
        spp *= 2
    return points


def section_convergence(res, backends, mitsuba_variant, max_spp, r):
    curves = {}
    for b in backends:
        curves[f"pt-render {b}"] = convergence_ours(b, max_spp, res)
    if mitsuba_variant:
        try:
            curves[f"Mitsuba {mitsuba_variant}"] = convergence_mitsuba(mitsuba_variant,
                                                                       max_spp, res)
        except ImportError:
            print("bench: Mitsuba not installed: no peer in the convergence plot",
                  file=sys.stderr)
    for name, pts in curves.items():
        for sec, spp, err in pts:
            r.add("convergence", "cornell-box", name, "relMSE", err, "", "spp", spp)
            r.add("convergence", "cornell-box", name, "seconds", sec, "s", "spp", spp)
        for th in THRESHOLDS:
            t = time_to_threshold([p[0] for p in pts], [p[2] for p in pts], th)
            r.add("convergence", "cornell-box", name, "time_to_relMSE", "" if t is None else t,
                  "s", "threshold", th)
    _plot_convergence(curves, os.path.join(r.out, "convergence.png"), res)
    return curves


def _plot_convergence(curves, path, res):
    """Log-log relMSE against seconds; skipped (with a message) without matplotlib: the CSV
    holds the data, and `python -m bench --replot DIR` draws it later."""
    try:
        import matplotlib
    except ImportError:
        print("bench: matplotlib not installed: no plot (python -m bench --replot DIR)",
              file=sys.stderr)
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, pts in curves.items():
        ax.loglog([p[0] for p in pts], [p[2] for p in pts], "o-", label=name)
    for th in THRESHOLDS:
        ax.axhline(th, color="grey", lw=0.5, ls="--")
    ax.set_xlabel("seconds (compile excluded)")
    ax.set_ylabel("relMSE vs Mitsuba reference")
    ax.set_title(f"Cornell box {res[0]}x{res[1]}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def curves_from_csv(paths):
    """{renderer: [(seconds, spp, relMSE)]} from the convergence rows of results.csv files."""
    data = {}
    for path in paths:
        for row in csv.DictReader(open(path)):
            if row["section"] != "convergence" or row["parameter"] != "spp":
                continue
            d = data.setdefault(row["renderer"], {}).setdefault(int(row["value"]), {})
            d[row["metric"]] = float(row["result"])
    return {name: [(v["seconds"], spp, v["relMSE"]) for spp, v in sorted(pts.items())]
            for name, pts in data.items()}


# ---------------------------------------------------------------------------------------
# Throughput, texture filtering, block sizes, compile times

def section_throughput(backends, res, spp, repeats, r):
    from bench.throughput import ours
    out = {}
    for b in backends:
        rec = ours(b, res, spp, repeats)
        name = f"pt-render {b}"
        paths = res[0] * res[1] * spp
        per_path = rec["bounce_rays_per_path"], rec["shadow_rays_per_path"]
        rays = rays_per_second(paths, per_path[0] * paths, per_path[1] * paths,
                               rec["pass_s_median"])
        r.add("throughput", "cornell-box", name, "camera_paths_per_s", rec["paths_per_s"], "1/s")
        r.add("throughput", "cornell-box", name, "rays_per_s", rays, "1/s")
        r.add("throughput", "cornell-box", name, "bounce_rays_per_path", per_path[0], "")
        r.add("throughput", "cornell-box", name, "shadow_rays_per_path", per_path[1], "")
        out[name] = rec
    return out


def _pass_time(backend, scene, spp, repeats):
    from bench.common import median_time
    backend.compile()
    backend.render_pass(0, spp, 0, scene.max_bounces, scene.rr_depth)
    t, _ = median_time(lambda: backend.render_pass(0, spp, 0, scene.max_bounces,
                                                   scene.rr_depth), repeats)
    return t


def section_filtering(backend_name, res, spp, repeats, r):
    """Bilinear against nearest texture filtering on scenes/textured.json."""
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene, load_scene_description
    desc = load_scene_description(os.path.join(ROOT, "scenes", "textured.json"))
    desc.camera.resolution = res
    out = {}
    for filt in ("bilinear", "nearest"):
        scene = compile_scene(desc)
        scene.arrays.tex_int[:, 3] = 1 if filt == "nearest" else 0
        t = _pass_time(make_backend(backend_name, scene), scene, spp, repeats)
        out[filt] = res[0] * res[1] * spp / t
        r.add("filtering", "textured", f"pt-render {backend_name}", "camera_paths_per_s",
              out[filt], "1/s", "filter", filt)
    return out


def section_blocks(res, spp, repeats, r):
    from pathtracer.backends.cuda import CUDABackend
    scene = _cornell(res)
    out = {}
    for block in ((8, 8), (16, 8), (16, 16), (32, 4), (32, 8), (64, 2)):
        t = _pass_time(CUDABackend(scene, block=block), scene, spp, repeats)
        out[block] = res[0] * res[1] * spp / t
        r.add("cuda_blocks", "cornell-box", "pt-render cuda", "camera_paths_per_s", out[block],
              "1/s", "block", f"{block[0]}x{block[1]}")
    return out


def _mesh_scene_desc(obj, res):
    """A mesh (scaled to unit size) in a white furnace-like setting: diffuse 0.8, a constant
    sky, seen whole; 3 bounces. Traversal dominates its cost."""
    from pathtracer.scene import load_scene_description
    from pathtracer.scene.meshes import load_obj
    import json
    import tempfile
    pos = load_obj(obj).positions.reshape(-1, 3)
    lo, hi = pos.min(0), pos.max(0)
    size = float((hi - lo).max())
    centre = ((lo + hi) / 2).tolist()
    scene = {"camera": {"resolution": list(res), "position": [0.3, 0.4, 2.2],
                        "lookAt": [0, 0, 0], "fov": 35},
             "render": {"maxBounces": 3},
             "materials": [{"name": "m", "type": "diffuse", "albedo": 0.8}],
             "objects": [{"name": "o", "file": obj, "material": "m", "smooth": False,
                          "transform": {"matrix": [
                              [1 / size, 0, 0, -centre[0] / size],
                              [0, 1 / size, 0, -centre[1] / size],
                              [0, 0, 1 / size, -centre[2] / size], [0, 0, 0, 1]]}}],
             "environment": {"color": 1.0}}
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(scene, f)
    desc = load_scene_description(f.name)
    os.unlink(f.name)
    return desc


def section_bvh(backend_name, meshes, res, spp, repeats, variants, r):
    """The thesis's evaluation with clear metrics: build time, SAH cost, nodes and traversal
    speed (camera paths/s) for brute force (one leaf), midpoint splits, and binned SAH over
    bin counts and leaf sizes."""
    from pathtracer.accel.bvh import sah_cost
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    out = []
    for label, obj, brute in meshes:
        desc = _mesh_scene_desc(obj, res)
        for name, options in variants:
            if options.get("split") == "none" and not brute:
                continue
            builds = []
            for _ in range(3):
                scene = compile_scene(desc, bvh_options=options)
                builds.append(scene.timings["bvh_build"])
            from pathtracer.accel import build_bvh
            cost = sah_cost(build_bvh(_positions(scene), **options))
            t = _pass_time(make_backend(backend_name, scene), scene, spp, repeats)
            pps = res[0] * res[1] * spp / t
            row = dict(mesh=label, triangles=scene.n_triangles, variant=name,
                       build_s=float(np.median(builds)), sah_cost=cost,
                       nodes=len(scene.arrays.bvh_box), paths_per_s=pps)
            out.append(row)
            for k in ("build_s", "sah_cost", "nodes", "paths_per_s"):
                r.add("bvh", label, f"pt-render {backend_name}", k, row[k], "", "variant", name)
    return out


def _positions(scene):
    """Triangle vertices (N, 3, 3) back from the compiled v0, e1, e2 rows."""
    tv = scene.arrays.tri_v[:scene.n_triangles].astype(np.float32)
    v0 = tv[:, 0:3]
    return np.stack([v0, v0 + tv[:, 3:6], v0 + tv[:, 6:9]], axis=1)


def section_compile(backends, r):
    from bench.throughput import compile_times
    out = {}
    for b in backends:
        rec = compile_times(b)
        out[b] = rec
        for label, v in rec.items():
            if "error" in v:
                continue
            r.add("compile", "cornell-box", f"pt-render {b}", "compile_s", v["compile_s"], "s",
                  "cache", label)
            r.add("compile", "cornell-box", f"pt-render {b}", "to_first_pixel_s",
                  v["to_first_pixel_s"], "s", "cache", label)
    return out


# ---------------------------------------------------------------------------------------

def summary(r, curves, thr, filt, blocks, bvh, comp, args):
    lines = [f"# Benchmark run ({r.context['date']})", "",
             f"- command: `{r.context['command']}`", f"- machine: {r.context['machine']}",
             f"- versions: {versions()}", "",
             "## Error against run time (Cornell box, relMSE vs the Mitsuba reference)", "",
             "| renderer | spp | seconds | relMSE |", "|---|---|---|---|"]
    for name, pts in curves.items():
        for sec, spp, err in pts:
            lines.append(f"| {name} | {spp} | {sec:.3g} | {err:.3g} |")
    lines += ["", "| renderer | time to relMSE 1e-2 | time to relMSE 1e-3 |", "|---|---|---|"]
    for name, pts in curves.items():
        tt = [time_to_threshold([p[0] for p in pts], [p[2] for p in pts], th)
              for th in THRESHOLDS]
        lines.append(f"| {name} | " + " | ".join("not reached" if t is None else f"{t:.3g} s"
                                                for t in tt) + " |")
    if curves:
        lines += ["", "![convergence](convergence.png)"]
    lines += ["", "## Throughput (Cornell box)", "", "| renderer | M camera paths/s | M rays/s |",
              "|---|---|---|"]
    for name, rec in thr.items():
        paths = rec["paths_per_s"]
        rays = paths * (1 + rec["bounce_rays_per_path"] + rec["shadow_rays_per_path"])
        lines.append(f"| {name} | {paths / 1e6:.3g} | {rays / 1e6:.3g} |")
    if filt:
        lines += ["", "## Texture filtering (textured.json)", "",
                  "| filter | M camera paths/s |", "|---|---|"]
        lines += [f"| {k} | {v / 1e6:.3g} |" for k, v in filt.items()]
    if blocks:
        lines += ["", "## CUDA block sizes (Cornell box)", "", "| block | M camera paths/s |",
                  "|---|---|"]
        lines += [f"| {b[0]}x{b[1]} | {v / 1e6:.4g} |" for b, v in blocks.items()]
    if bvh:
        lines += ["", "## BVH (thesis evaluation, clear metrics)", "",
                  "| mesh | triangles | variant | build s | SAH cost | nodes | M camera paths/s |",
                  "|---|---|---|---|---|---|---|"]
        for b in bvh:
            lines.append(f"| {b['mesh']} | {b['triangles']} | {b['variant']} | "
                         f"{b['build_s']:.3g} | {b['sah_cost']:.3g} | {b['nodes']} | "
                         f"{b['paths_per_s'] / 1e6:.3g} |")
    lines += ["", "## Compile times (Cornell box, fresh processes)", "",
              "| backend | cache | compile s | to first pixel s |", "|---|---|---|---|"]
    for b, rec in comp.items():
        for label, v in rec.items():
            if "error" not in v:
                lines.append(f"| {b} | {label} | {v['compile_s']:.3g} | "
                             f"{v['to_first_pixel_s']:.3g} |")
    with open(os.path.join(r.out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a few minutes on 2 CPU cores")
    p.add_argument("--tiny", action="store_true", help="with --quick: seconds (CI)")
    p.add_argument("--gpu", action="store_true", help="CUDA backend (and Mitsuba cuda_ad_rgb)")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--out", help="output folder (default bench/out/<date>)")
    p.add_argument("--sections", nargs="*", default=SECTIONS, choices=SECTIONS,
                   help="run only these")
    p.add_argument("--replot", nargs="+", metavar="CSV",
                   help="only draw convergence.png (in --out) from these results.csv files")
    args = p.parse_args(argv)
    if args.replot:
        out = args.out or os.path.dirname(os.path.abspath(args.replot[0]))
        _plot_convergence(curves_from_csv(args.replot), os.path.join(out, "convergence.png"),
                          (256, 256))
        return 0
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%d-%H%M%S")
    out = args.out or os.path.join(ROOT, "bench", "out", stamp)
    os.makedirs(out, exist_ok=True)
    r = Results(out)
    backends = ["cuda"] if args.gpu else ["cpu"]
    peer = None if args.no_mitsuba else ("cuda_ad_rgb" if args.gpu else "llvm_ad_rgb")
    if args.quick and args.tiny:
        max_spp, tp, repeats, filt_res = 4, ((64, 64), 2), 2, (32, 24)
    elif args.quick:
        max_spp, tp, repeats, filt_res = 64, ((128, 128), 8), 3, (160, 120)
    elif args.gpu:
        max_spp, tp, repeats, filt_res = 4096, ((1024, 1024), 64), 7, (1280, 960)
    else:
        max_spp, tp, repeats, filt_res = 1024, ((256, 256), 16), 7, (320, 240)
    t0 = time.perf_counter()
    want = set(args.sections)
    curves = (section_convergence((256, 256), backends, peer, max_spp, r)
              if "convergence" in want else {})
    thr = section_throughput(backends, tp[0], tp[1], repeats, r) if "throughput" in want else {}
    filt = (section_filtering(backends[0], filt_res, 2 if args.tiny else 8, repeats, r)
            if "filtering" in want else {})
    blocks = (section_blocks((1024, 1024), 16, repeats, r)
              if args.gpu and "blocks" in want else {})
    bvh = []
    if "bvh" in want:
        from bench.common import SHARED
        models = os.path.join(SHARED, "assets", "models")
        meshes = [("suzanne", os.path.join(models, "suzanne.obj"), True),
                  ("bunny-lowres", os.path.join(models, "stanford_bunny_lowres.obj"), True)]
        if not args.tiny:
            meshes += [("dragon-100k", os.path.join(models, "stanford_dragon_100k.obj"),
                        args.gpu)]
        variants = [("brute force", dict(split="none")), ("midpoint", dict(split="midpoint")),
                    ("SAH 16 bins, leaf 8", dict())]
        if not args.tiny:
            variants += [(f"SAH {b} bins, leaf 8", dict(n_bins=b)) for b in (4, 8, 12, 32)]
            variants += [(f"SAH 16 bins, leaf {k}", dict(max_leaf=k)) for k in (1, 2, 4, 16)]
        bres = (32, 32) if args.tiny else ((256, 256) if args.gpu else (96, 96))
        bvh = section_bvh(backends[0], meshes, bres, 1 if args.tiny else 4, repeats,
                          variants, r)
    comp = section_compile(backends, r) if "compile" in want else {}
    r.write()
    summary(r, curves, thr, filt, blocks, bvh, comp, args)
    print(f"bench: {len(r.rows)} rows in {time.perf_counter() - t0:.0f} s -> {out}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
