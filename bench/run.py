"""The batch benchmark: error against run time (four scenes), throughput, texture filtering,
CUDA block sizes, the thesis's BVH evaluation, scaling to 6.4M triangles and compile times per
feature set, written as CSV (every row with its command, machine and date), PNG plots and a
markdown summary.

    python -m bench --quick            # a few minutes on 2 CPU cores
    python -m bench                    # full CPU run
    python -m bench --gpu              # CUDA (H100 / H200), with Mitsuba's cuda variant if installed
    python -m bench --quick --tiny     # seconds: what CI runs

Mitsuba 3 (`pip install -e .[bench]`) is measured in the same run, on the same device kind
(llvm on the CPU, cuda on the GPU), on every scene `pathtracer.mitsuba` can express. The
Cornell box is measured against Mitsuba's reference by both renderers; the other scenes
against each renderer's own high-spp reference, made on a GPU by `python -m bench.references`
and committed. The big meshes are made by shared/tools/make_big_mesh.py into
bench/out/meshes/ on first use.
"""
import argparse
import csv
import datetime
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench.common import command, machine, median_time, now, usable_mitsuba, versions
from bench.metrics import rays_per_second, relmse, time_to_threshold
from bench.scenes import (CONVERGENCE, convergence_desc, convergence_scene, load_reference,
                          mesh_desc, mitsuba_scene)

FIELDS = ["section", "scene", "renderer", "parameter", "value", "metric", "result", "unit",
          "command", "machine", "date", "versions"]
THRESHOLDS = (1e-2, 1e-3)
SECTIONS = ("convergence", "samplers", "denoise", "adaptive", "throughput", "filtering", "blocks", "bvh", "scaling",
            "compile")
OUR_SAMPLERS = ("sobol", "independent")
MITSUBA_SAMPLERS = ("independent", "multijitter", "ldsampler")


class Results:
    def __init__(self, out):
        self.out = out
        self.rows = []
        self.context = {"command": command(), "machine": machine(), "date": now(),
                        "versions": " ".join(f"{k}={v}" for k, v in versions().items())}

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

def progressive_curve(scene, ref, backend_name, max_spp, adaptive=None, seed=None):
    """(seconds, spp, relMSE against ``ref``) after each pass of one progressive render of
    ``scene`` (a Python-API Scene) through the Python API, as the CLI renders: passes
    doubling from the API's first pass (1 spp on the CPU; on the GPU the spp of
    api.PREVIEW_FIRST_PASS_PATHS paths, 8 at the convergence sizes), in rendering time
    (compile excluded; the error is measured after the render)."""
    import pathtracer as pt
    images = []

    def on_pass(p):
        # Each pass's mean image is taken, as a viewer would, inside the clock; its relMSE
        # (~1-10 ms a pass, as long as a small GPU pass) only after the render. Measured in
        # here and taken out of the clock, it was not rendering time where the GPU renders
        # the next pass meanwhile (progressive.render launches it before on_pass).
        images.append((p.elapsed, p.spp, p.image()))

    pt.render(scene, spp=max_spp, backend=backend_name, callback=on_pass,
              pass_seconds=float("inf"), adaptive=adaptive, seed=seed)
    return [(t, spp, relmse(img, ref)) for t, spp, img in images]


def convergence_ours(backend_name, name, max_spp, adaptive=None):
    """progressive_curve of convergence scene ``name`` against its reference; ``adaptive``:
    adaptive sampling to that per-pixel relMSE (render's ``adaptive``)."""
    ref, _ = load_reference(name)
    return progressive_curve(convergence_scene(name), ref, backend_name, max_spp, adaptive)


def convergence_ours_levels(backend_name, name, max_spp):
    """Rendered as Mitsuba's curve is (convergence_mitsuba): one render of each spp level
    1, 2, 4, ... alone (seed = spp), timed by the render itself (compile excluded, after a
    warm-up render), no intermediate images. The progressive curve (convergence_ours)
    pays for a launch, a copy and an accumulation at every level it passes; this one is
    what ``pt-render --spp N`` costs."""
    import pathtracer as pt
    ref, _ = load_reference(name)
    scene = convergence_scene(name)
    pt.render(scene, spp=1, backend=backend_name, seed=99)     # warm-up (kernels, GPU)
    points = []
    spp = 1
    while spp <= max_spp:
        res = pt.render(scene, spp=spp, backend=backend_name, seed=spp)
        points.append((res.seconds, spp, relmse(res.image, ref)))
        spp *= 2
    return points


def convergence_mitsuba(variant, name, max_spp):
    """Mitsuba is not progressive: one render per spp level, each timed alone, against
    Mitsuba's reference (the Cornell box: the reference's own scene, `mitsuba_cornell`).
    None when the scene cannot be expressed in Mitsuba or has no Mitsuba reference."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    got = mitsuba_scene(name, "independent")
    if got is None:
        return None
    scene, ref = got
    points = []
    spp = 1
    dr.eval(mi.render(scene, spp=1, seed=99))    # warm-up (kernel compilation)
    while spp <= max_spp:
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=spp)
        dr.eval(img)
        dr.sync_thread()
        points.append((time.perf_counter() - t0, spp, relmse(np.array(img), ref)))
        spp *= 2
    return points


def section_convergence(scenes, backends, mitsuba_variant, max_spp, r):
    """{(scene, renderer): [(seconds, spp, relMSE)]}, and {(scene, renderer): the noise of
    the reference that renderer is measured against} where known."""
    curves, noise = {}, {}
    for name in scenes:
        try:
            _, meta = load_reference(name)
        except FileNotFoundError:
            print(f"bench: no reference for {name} (python -m bench.references on a GPU): "
                  "skipped", file=sys.stderr)
            continue
        for b in backends:
            curves[name, f"pt-render {b}"] = convergence_ours(b, name, max_spp)
            noise[name, f"pt-render {b}"] = meta.get("noise_relmse")
            # each level alone, as Mitsuba's curve: the same method for both renderers
            curves[name, f"pt-render {b} per level"] = convergence_ours_levels(b, name,
                                                                               max_spp)
            noise[name, f"pt-render {b} per level"] = meta.get("noise_relmse")
        if mitsuba_variant:
            peer = f"Mitsuba {mitsuba_variant}"
            pts = convergence_mitsuba(mitsuba_variant, name, max_spp)
            if pts:
                curves[name, peer] = pts
                if name != "cornell-box":
                    noise[name, peer] = load_reference(name, mitsuba=True)[1]["noise_relmse"]
    for (scene, name), pts in curves.items():
        for sec, spp, err in pts:
            r.add("convergence", scene, name, "relMSE", err, "", "spp", spp)
            r.add("convergence", scene, name, "seconds", sec, "s", "spp", spp)
        for th in THRESHOLDS:
            t = time_to_threshold([p[0] for p in pts], [p[2] for p in pts], th)
            r.add("convergence", scene, name, "time_to_relMSE", "" if t is None else t,
                  "s", "threshold", th)
        if noise.get((scene, name)) is not None:
            r.add("convergence", scene, name, "reference_noise_relMSE", noise[scene, name], "")
    _plot_convergence(curves, os.path.join(r.out, "convergence.png"))
    return curves, noise


def _plot_convergence(curves, path):
    """Log-log relMSE against seconds, one panel per scene; skipped (with a message) without
    matplotlib: the CSV holds the data, and `python -m bench --replot CSV` draws it later."""
    try:
        import matplotlib
    except ImportError:
        print("bench: matplotlib not installed: no plot (python -m bench --replot CSV)",
              file=sys.stderr)
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scenes = list(dict.fromkeys(s for s, _ in curves))
    if not scenes:
        return
    cols = min(2, len(scenes))
    rows = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 3.8 * rows), squeeze=False)
    for ax, scene in zip(axes.flat, scenes):
        for (s, name), pts in curves.items():
            if s == scene:
                ax.loglog([p[0] for p in pts], [p[2] for p in pts], "o-", ms=3, label=name)
        for th in THRESHOLDS:
            ax.axhline(th, color="grey", lw=0.5, ls="--")
        ax.set_xlabel("seconds (compile excluded)")
        ax.set_ylabel("relMSE vs reference")
        ax.set_title(scene)
        ax.legend(fontsize=8)
    for ax in list(axes.flat)[len(scenes):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def curves_from_csv(paths):
    """{(scene, renderer): [(seconds, spp, relMSE)]} from the convergence rows of results.csv
    files."""
    data = {}
    for path in paths:
        for row in csv.DictReader(open(path)):
            if row["section"] != "convergence" or row["parameter"] != "spp":
                continue
            d = data.setdefault((row["scene"], row["renderer"]), {}).setdefault(
                int(row["value"]), {})
            d[row["metric"]] = float(row["result"])
    return {key: [(v["seconds"], spp, v["relMSE"]) for spp, v in sorted(pts.items())]
            for key, pts in data.items()}


# ---------------------------------------------------------------------------------------
# Throughput, texture filtering, block sizes, compile times

def mean_and_error(errs):
    """(mean, standard error of the mean) of per-seed relMSEs (0 error for one seed)."""
    errs = np.asarray(errs, np.float64)
    se = float(errs.std(ddof=1) / np.sqrt(len(errs))) if len(errs) > 1 else 0.0
    return float(errs.mean()), se


def ratio_error(a, sa, b, sb):
    """Standard error of a / b from the two means' standard errors (first order, the
    renders of the two samplers independent)."""
    return float(a / b * np.sqrt((sa / a) ** 2 + (sb / b) ** 2)) if a > 0 and b > 0 else 0.0


def section_samplers(scenes, backend_name, mitsuba_variant, spps, seeds, r):
    """relMSE at equal spp, the mean of ``seeds`` renders, of each of our samplers and of
    Mitsuba's independent and low-discrepancy samplers, each renderer against its own
    reference (the Cornell box: Mitsuba's, for both). {(scene, spp): {renderer: (relMSE,
    its standard error)}}; both are recorded (metrics relMSE and relMSE_stderr)."""
    import pathtracer as pt
    out = {}
    for name in scenes:
        try:
            ref, _ = load_reference(name)
        except FileNotFoundError:
            continue
        for sampler in OUR_SAMPLERS:
            scene = convergence_scene(name, sampler)
            for spp in spps:
                out.setdefault((name, spp), {})[f"pt-render {backend_name} {sampler}"] = \
                    mean_and_error([relmse(pt.render(scene, spp=spp, seed=s,
                                                     backend=backend_name).image, ref)
                                    for s in range(seeds)])
        if mitsuba_variant:
            import drjit as dr
            import mitsuba as mi
            mi.set_variant(mitsuba_variant)
            for sampler in MITSUBA_SAMPLERS:
                got = mitsuba_scene(name, sampler)
                if got is None:
                    break
                scene, mref = got
                for spp in spps:
                    errs = []
                    for s in range(seeds):
                        img = mi.render(scene, spp=spp, seed=1000 + s)
                        dr.eval(img)
                        errs.append(relmse(np.array(img), mref))
                    out.setdefault((name, spp), {})[
                        f"Mitsuba {mitsuba_variant} {sampler}"] = mean_and_error(errs)
    for (name, spp), errs in out.items():
        for renderer, (err, se) in errs.items():
            r.add("samplers", name, renderer, "relMSE", err, "", "spp", spp)
            r.add("samplers", name, renderer, "relMSE_stderr", se, "", "spp", spp)
    return out


ADAPTIVE_TARGET = 1e-3    # the image relMSE adaptive sampling aims at: the last threshold
#                           the time is measured to


def median_curve(runs):
    """One (seconds, spp, relMSE) curve from repeated renders of the same deterministic
    passes: at each pass the median of the runs' times (their spp and errors are equal)."""
    if len(runs) == 1 or len({tuple(p[1] for p in pts) for pts in runs}) != 1:
        return runs[0]
    return [(float(np.median([pts[i][0] for pts in runs])),) + tuple(runs[0][i][1:])
            for i in range(len(runs[0]))]


def adaptive_repeats(args):
    """Renders per curve of the adaptive section: 5 on the GPU (a render to 1e-3 takes
    ~0.1 s there), 1 on the CPU (seconds) and in quick runs."""
    return 5 if args.gpu and not args.quick else 1


def section_adaptive(scenes, backend_name, max_spp, r, repeats=1):
    """Time to relMSE 1e-2 and 1e-3 with uniform and with adaptive sampling (target
    ADAPTIVE_TARGET), both progressive from 1 (2) spp; with ``repeats`` > 1, after a
    warm-up render, each pass's time is the median of that many renders (a GPU render of
    these scenes to 1e-3 takes ~0.1 s, and one curve's crossing moves by ~20 % between
    runs). {scene: {mode: points}}."""
    out = {}
    for name in scenes:
        try:
            load_reference(name)
        except FileNotFoundError:
            continue
        for mode, target in (("uniform", None), ("adaptive", ADAPTIVE_TARGET)):
            if repeats > 1:
                convergence_ours(backend_name, name, max_spp, adaptive=target)   # warm-up
            pts = median_curve([convergence_ours(backend_name, name, max_spp,
                                                 adaptive=target) for _ in range(repeats)])
            out.setdefault(name, {})[mode] = pts
            renderer = f"pt-render {backend_name} {mode}"
            for th in THRESHOLDS:
                t = time_to_threshold([p[0] for p in pts], [p[2] for p in pts], th)
                r.add("adaptive", name, renderer, "time_to_relMSE", "" if t is None else t,
                      "s", "threshold", th)
            for sec, spp, err in pts:
                r.add("adaptive", name, renderer, "relMSE", err, "", "seconds", sec)
    return out


def section_denoise(scenes, backend_name, low_spp, high_spp, repeats, r, seeds=1):
    """relMSE of the raw image at low_spp, of it denoised (Open Image Denoise with our
    albedo and normal images; biased) and of the raw image at high_spp, against the scene's
    reference, each the mean over ``seeds`` renders (seeds 0, 1, ...; the albedo and
    normal images drawn with the same seed) with its standard error; the denoiser's and the
    auxiliary pass's times (median of ``repeats``). The denoiser runs where `pt-render
    --denoise` runs it for this backend (on the GPU for cuda where OIDN's CUDA device
    works); then its CPU time and the relMSE between the two devices' images are recorded
    too. {scene: record}."""
    from pathtracer.backends import make_backend
    from pathtracer.denoise import AOV_SPP, denoise, resolve_device
    from pathtracer.progressive import render
    from pathtracer.scene import compile_scene
    out = {}
    for name in scenes:
        try:
            ref, _ = load_reference(name)
        except FileNotFoundError:
            continue
        scene = compile_scene(convergence_desc(name))
        backend = make_backend(backend_name, scene)
        backend.compile()
        backend.aovs(1, 0)                                   # compile the auxiliary pass
        device = resolve_device("auto", backend_name)
        errs = {"raw_low": [], "denoised_low": [], "raw_high": []}
        for seed in range(seeds):
            low = render(scene, backend, spp=low_spp, seed=seed).film.image()
            aovs = backend.aovs(AOV_SPP, seed)
            if seed == 0:
                low0, aovs0 = low, aovs                     # (timed below)
            errs["raw_low"].append(relmse(low, ref))
            errs["denoised_low"].append(relmse(denoise(low, aovs, device), ref))
            errs["raw_high"].append(relmse(render(scene, backend, spp=high_spp,
                                                  seed=seed).film.image(), ref))
        t_aov, _ = median_time(lambda: backend.aovs(AOV_SPP, 0), repeats)
        times = {}
        for d in sorted({device, "cpu"}):
            denoise(low0, aovs0, d)                          # the denoiser's set-up
            times[d], _ = median_time(lambda: denoise(low0, aovs0, d), repeats)
        t_dn = times[device]
        rec = {"low_spp": low_spp, "high_spp": high_spp, "seeds": seeds,
               "denoise_device": device, "denoise_s": t_dn, "aov_s": t_aov}
        if device != "cpu":
            rec["denoise_cpu_s"] = times["cpu"]
            rec["gpu_vs_cpu_relMSE"] = relmse(denoise(low0, aovs0, device),
                                              denoise(low0, aovs0, "cpu"))
        for k, v in errs.items():
            rec[k], rec[k + "_stderr"] = mean_and_error(v)
        out[name] = rec
        for k in errs:
            r.add("denoise", name, f"pt-render {backend_name}", f"relMSE_{k}", rec[k], "",
                  "spp", low_spp if k != "raw_high" else high_spp)
        r.add("denoise", name, f"pt-render {backend_name}", "denoise_seconds", t_dn, "s",
              "pixels", scene.width * scene.height)
        if device != "cpu":
            r.add("denoise", name, f"pt-render {backend_name}", "denoise_seconds_cpu",
                  times["cpu"], "s", "pixels", scene.width * scene.height)
            r.add("denoise", name, f"pt-render {backend_name}", "denoised_gpu_vs_cpu_relMSE",
                  rec["gpu_vs_cpu_relMSE"], "", "spp", low_spp)
        r.add("denoise", name, f"pt-render {backend_name}", "aov_seconds", t_aov, "s",
              "spp", AOV_SPP)
    return out


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


def section_filtering(backend_name, res, spp, repeats, r, grazing_spps=(4, 16, 64),
                      reference_spp=4096, grazing_res=(96, 48), seeds=4,
                      filters=("trilinear", "bilinear", "nearest")):
    """Texture filters: camera paths/s of scenes/textured.json with each filter, and the
    error of each on a checkerboard plane at grazing angles (bench.scenes.grazing_plane):
    relMSE at a few spp against the converged bilinear image (the true pixel averages)."""
    import tempfile
    from pathtracer.backends import make_backend
    from pathtracer.film import relmse
    from pathtracer.progressive import render
    from pathtracer.scene import compile_scene, load_scene, load_scene_description
    from bench.scenes import grazing_plane
    out = {"paths_per_s": {}, "grazing": {}}
    for filt in filters:
        desc = load_scene_description(os.path.join(ROOT, "scenes", "textured.json"))
        desc.camera.resolution = res
        for m in desc.materials.values():
            for spec in list(m.textures.values()) + (
                    [m.normal_map] if m.normal_map is not None else []):
                spec.filter = filt
        scene = compile_scene(desc)
        t = _pass_time(make_backend(backend_name, scene), scene, spp, repeats)
        out["paths_per_s"][filt] = res[0] * res[1] * spp / t
        r.add("filtering", "textured", f"pt-render {backend_name}", "camera_paths_per_s",
              out["paths_per_s"][filt], "1/s", "filter", filt)
    if not grazing_spps:
        return out
    with tempfile.TemporaryDirectory() as folder:
        def image(filt, n, seed):
            scene = load_scene(grazing_plane(folder, filt, grazing_res))
            return render(scene, make_backend(backend_name, scene), spp=n,
                          seed=seed).film.image()
        ref = image("bilinear", reference_spp, 1_000_003)
        for filt in filters:
            for n in grazing_spps:
                e = float(np.mean([relmse(image(filt, n, s), ref) for s in range(seeds)]))
                out["grazing"][(filt, n)] = e
                r.add("filtering", "grazing-plane", f"pt-render {backend_name}", "relmse", e,
                      "", "filter, spp", f"{filt}, {n}")
    return out


def _cornell(resolution):
    from pathtracer.scene import compile_scene
    desc = convergence_desc("cornell-box")
    desc.camera.resolution = resolution
    return compile_scene(desc)


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


def section_bvh(backend_name, meshes, res, spp, repeats, variants, r):
    """The thesis's evaluation with clear metrics: build time, SAH cost, nodes and traversal
    speed (camera paths/s) for brute force (one leaf), midpoint splits, and binned SAH over
    bin counts and leaf sizes."""
    from pathtracer.accel.bvh import sah_cost
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    out = []
    for label, obj, brute in meshes:
        desc = mesh_desc(obj, res)
        for name, options in variants:
            if options.get("split") == "none" and not brute:
                continue
            builds = []
            while len(builds) < 3:     # median of 3 builds; one where a build takes > 2 s
                scene = compile_scene(desc, bvh_options=options)
                builds.append(scene.timings["bvh_build"])
                if builds[0] > 2.0:
                    break
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


def section_scaling(backend_name, meshes, res, spp, repeats, r):
    """Paths/s, memory and build times from 1k to 6.4M triangles, one process per mesh."""
    from bench.scaling import growth_exponent, run
    out = []
    for label, obj in meshes:
        rec = run(obj, backend_name, res, spp, repeats)
        if "error" in rec:
            print(f"bench: scaling {label}: {rec['error']}", file=sys.stderr)
            continue
        rec["mesh"] = label
        out.append(rec)
        n = rec["triangles"]
        for k in ("triangles", "load_s", "bvh_build_s", "bvh_nodes", "paths_per_s",
                  "ns_per_path", "host_bytes", "peak_rss_bytes", "device_bytes", "widen_s",
                  "wide_nodes", "wide_bytes"):
            if k in rec:
                r.add("scaling", label, f"pt-render {backend_name}", k, rec[k], "")
        for k in ("host_bytes", "host_geometry_bytes", "device_bytes", "wide_bytes"):
            if k in rec:
                r.add("scaling", label, f"pt-render {backend_name}", k + "_per_triangle",
                      rec[k] / n, "B")
    _plot_scaling(out, os.path.join(r.out, "scaling.png"), backend_name)
    # one shape at growing triangle counts: the dragon and its subdivisions (other meshes
    # differ in how much of the image they cover, which changes the time per path too)
    fam = [x for x in out if x["mesh"].startswith("dragon")]
    if len(fam) >= 2:
        slope = growth_exponent([x["triangles"] for x in fam], [x["ns_per_path"] for x in fam])
        r.add("scaling", "dragon family", f"pt-render {backend_name}",
              "time_per_path_exponent", slope, "")
    return out


def _plot_scaling(recs, path, backend_name):
    try:
        import matplotlib
    except ImportError:
        return
    if not recs:
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = [x["triangles"] for x in recs]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    a.loglog(n, [x["ns_per_path"] for x in recs], "o-")
    a.set_xlabel("triangles")
    a.set_ylabel("ns per camera path")
    a.set_title(f"time per path ({backend_name})")
    b.semilogx(n, [x["host_bytes"] / x["triangles"] for x in recs], "o-", label="host, all")
    b.semilogx(n, [x["host_geometry_bytes"] / x["triangles"] for x in recs], "s--",
               label="host, triangles + BVH")
    if all("device_bytes" in x for x in recs):
        b.semilogx(n, [x["device_bytes"] / x["triangles"] for x in recs], "^-",
                   label="device (measured)")
    b.set_ylim(0, 2 * max(x["host_geometry_bytes"] / x["triangles"] for x in recs))
    b.set_xlabel("triangles")
    b.set_ylabel("bytes per triangle")
    b.set_title("memory")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def compile_scenes():
    """(label, scene file) per kernel feature set: the sun scene is written out as a file."""
    import tempfile

    from bench.scenes import SCENES_DIR, sun
    sun_file = os.path.join(tempfile.mkdtemp(prefix="pt-render-bench-"), "sun-scene.json")
    with open(sun_file, "w") as f:
        json.dump(sun((64, 64)), f)
    return [("cornell-box", os.path.join(SCENES_DIR, "cornell-box.json")),
            ("sun", sun_file),
            ("textured", os.path.join(SCENES_DIR, "textured.json")),
            ("glass", os.path.join(SCENES_DIR, "glass.json")),
            ("depth-of-field", os.path.join(SCENES_DIR, "depth-of-field.json"))]


def section_compile(backends, scenes, r):
    """Cold and warm kernel compile per scene feature set, fresh processes."""
    from bench.throughput import compile_times
    out = {}
    for b in backends:
        for label, path in scenes:
            rec = compile_times(b, path)
            out[b, label] = rec
            for cache, v in rec.items():
                if "error" in v:
                    print(f"bench: compile {label} ({b}, {cache}): {v['error']}",
                          file=sys.stderr)
                    continue
                for k in ("compile_s", "to_first_pixel_s"):
                    r.add("compile", label, f"pt-render {b}", k, v[k], "s", "cache", cache)
    return out


# ---------------------------------------------------------------------------------------

def _fmt_time(t):
    return "not reached" if t is None else f"{t:.3g} s"


def summary(r, res, args):
    curves, noise = res["convergence"]
    lines = [f"# Benchmark run ({r.context['date']})", "",
             f"- command: `{r.context['command']}`", f"- machine: {r.context['machine']}",
             f"- versions: {r.context['versions']}", ""]
    if curves:
        lines += ["## Error against run time", "",
                  "relMSE against each scene's reference, compile excluded. The Cornell box: "
                  "Mitsuba 3's reference (shared/reference) for both renderers. The others: "
                  "each renderer's own high-spp reference (`bench/references/`), so each "
                  "curve is that renderer's noise alone. `pt-render B`: one progressive "
                  "render (passes doubling from 1 spp on the CPU, from 8 spp on the GPU at these "
                  "sizes, the error measured after each and its time taken out); `pt-render B per level` and Mitsuba: each spp level "
                  "rendered alone.", "",
                  "| scene | renderer | time to relMSE 1e-2 | time to relMSE 1e-3 | "
                  "last spp | last seconds | last relMSE | reference noise |",
                  "|---|---|---|---|---|---|---|---|"]
        for (scene, name), pts in curves.items():
            tt = [time_to_threshold([p[0] for p in pts], [p[2] for p in pts], th)
                  for th in THRESHOLDS]
            sec, spp, err = pts[-1]
            nz = noise.get((scene, name))
            lines.append(f"| {scene} | {name} | {_fmt_time(tt[0])} | {_fmt_time(tt[1])} | "
                         f"{spp} | {sec:.3g} | {err:.3g} | "
                         f"{'' if nz is None else f'{nz:.2g}'} |")
        lines += ["", "![convergence](convergence.png)"]
    if res["samplers"]:
        names = sorted({k for errs in res["samplers"].values() for k in errs},
                       key=lambda k: (not k.startswith("pt-render"), k))
        lines += ["", "## Samplers: relMSE at equal spp", "",
                  f"Mean of {args.seeds} seeds (+- its standard error); each renderer against "
                  "its own reference (the Cornell box: Mitsuba's). In brackets: the ratio to "
                  "the same renderer's independent sampler (+- its standard error).", "",
                  "| scene | spp | " + " | ".join(names) + " |",
                  "|---|---|" + "---|" * len(names)]
        for (scene, spp), errs in res["samplers"].items():
            cells = []
            for k in names:
                bk = k.rsplit(" ", 1)[0] + " independent"
                if k not in errs:
                    cells.append("")
                    continue
                e, se = errs[k]
                base, sb = errs.get(bk, (None, 0.0))
                cells.append(f"{e:.3g} +- {se:.2g}" +
                             (f" ({e / base:.3f} +- {ratio_error(e, se, base, sb):.3f})"
                              if base and k != bk else ""))
            lines.append(f"| {scene} | {spp} | " + " | ".join(cells) + " |")
    if res["adaptive"]:
        lines += ["", f"## Adaptive sampling (target image relMSE {ADAPTIVE_TARGET:g})", "",
                  f"Progressive renders; each pass's time is the median of "
                  f"{adaptive_repeats(args)} render(s)"
                  + (" after a warm-up render." if adaptive_repeats(args) > 1 else "."), "",
                  "| scene | time to 1e-2 uniform | adaptive | time to 1e-3 uniform | adaptive | "
                  "ratio at 1e-3 |", "|---|---|---|---|---|---|"]
        for scene, modes in res["adaptive"].items():
            tt = {m: [time_to_threshold([p[0] for p in pts], [p[2] for p in pts], th)
                      for th in THRESHOLDS] for m, pts in modes.items()}
            u, a = tt["uniform"], tt["adaptive"]
            ratio = f"{a[1] / u[1]:.2f}" if a[1] and u[1] else ""
            lines.append(f"| {scene} | {_fmt_time(u[0])} | {_fmt_time(a[0])} | "
                         f"{_fmt_time(u[1])} | {_fmt_time(a[1])} | {ratio} |")
    if res["denoise"]:
        lines += ["", "## Denoising (Open Image Denoise; biased)", "",
                  "relMSE against each scene's reference, the mean over the seeds given (+- its "
                  "standard error); the denoiser is guided by our albedo and normal images "
                  "(first non-specular hit); it runs where `pt-render --denoise` runs it "
                  "(the GPU when rendering with CUDA, where OIDN's CUDA device works).", "",
                  "| scene | seeds | raw, low spp | denoised, low spp | raw, high spp | "
                  "denoised / raw high | denoise s (device) | albedo+normal pass s |",
                  "|---|---|---|---|---|---|---|---|"]
        for scene, x in res["denoise"].items():
            def pm(k):
                return f"{x[k]:.3g} +- {x[k + '_stderr']:.2g}"
            lines.append(f"| {scene} | {x['seeds']} | {pm('raw_low')} ({x['low_spp']} spp) | "
                         f"{pm('denoised_low')} | {pm('raw_high')} ({x['high_spp']} spp) | "
                         f"{x['denoised_low'] / x['raw_high']:.2f} | "
                         f"{x['denoise_s']:.3g} ({x.get('denoise_device', 'cpu')}"
                         + (f"; CPU {x['denoise_cpu_s']:.3g}" if "denoise_cpu_s" in x else "")
                         + f") | {x['aov_s']:.3g} |")
    thr = res["throughput"]
    if thr:
        lines += ["", "## Throughput (Cornell box)", "",
                  "| renderer | M camera paths/s | M rays/s: camera | bounce | shadow | all |",
                  "|---|---|---|---|---|---|"]
        for name, rec in thr.items():
            paths = rec["paths_per_s"]
            bounce = paths * rec["bounce_rays_per_path"]
            shadow = paths * rec["shadow_rays_per_path"]
            lines.append(f"| {name} | {paths / 1e6:.3g} | {paths / 1e6:.3g} | "
                         f"{bounce / 1e6:.4g} | {shadow / 1e6:.4g} | "
                         f"{(paths + bounce + shadow) / 1e6:.4g} |")
    if res["filtering"]:
        flt = res["filtering"]
        spps = sorted({n for _, n in flt["grazing"]})
        lines += ["", "## Texture filtering", "",
                  "| filter | M camera paths/s (textured.json) | " +
                  " | ".join(f"grazing plane relMSE, {n} spp" for n in spps) + " |",
                  "|---|---|" + "---|" * len(spps)]
        lines += [f"| {k} | {v / 1e6:.3g} | " +
                  " | ".join(f"{flt['grazing'][(k, n)]:.3g}" for n in spps) + " |"
                  for k, v in flt["paths_per_s"].items()]
    if res["blocks"]:
        lines += ["", "## CUDA block sizes (Cornell box)", "", "| block | M camera paths/s |",
                  "|---|---|"]
        lines += [f"| {b[0]}x{b[1]} | {v / 1e6:.4g} |" for b, v in res["blocks"].items()]
    if res["bvh"]:
        lines += ["", "## BVH (thesis evaluation, clear metrics)", "",
                  "| mesh | triangles | variant | build s | SAH cost | nodes | M camera paths/s |",
                  "|---|---|---|---|---|---|---|"]
        for b in res["bvh"]:
            lines.append(f"| {b['mesh']} | {b['triangles']} | {b['variant']} | "
                         f"{b['build_s']:.3g} | {b['sah_cost']:.3g} | {b['nodes']} | "
                         f"{b['paths_per_s'] / 1e6:.3g} |")
    if res["scaling"]:
        lines += ["", "## Scaling with the triangle count", "",
                  "| mesh | triangles | load s (cached?) | BVH build s | M camera paths/s | "
                  "ns per path | host B/triangle (geometry) | device B/triangle | peak RSS MB | "
                  "CPU wide tree: nodes, B/triangle, collapse s |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for x in res["scaling"]:
            n = x["triangles"]
            dev = f"{x['device_bytes'] / n:.0f}" if "device_bytes" in x else "n/a"
            wide = (f"{x['wide_nodes']}, {x['wide_bytes'] / n:.0f}, {x['widen_s']:.3g}"
                    if "wide_nodes" in x else "n/a")
            lines.append(f"| {x['mesh']} | {n} | {x['load_s']:.3g} "
                         f"({'yes' if x['load_from_cache'] else 'no'}) | "
                         f"{x['bvh_build_s']:.3g} | {x['paths_per_s'] / 1e6:.3g} | "
                         f"{x['ns_per_path']:.3g} | {x['host_bytes'] / n:.0f} "
                         f"({x['host_geometry_bytes'] / n:.0f}) | {dev} | "
                         f"{x['peak_rss_bytes'] / 1e6:.0f} | {wide} |")
        for row in r.rows:
            if row["metric"] == "time_per_path_exponent":
                lines += ["", f"Time per path grows as N^{row['result']:.3f} over the dragon "
                              "and its subdivisions (least squares in log-log)."]
    if res["compile"]:
        lines += ["", "## Compile times per scene feature set (fresh processes)", "",
                  "| backend | scene | features | cold compile s | warm compile s | "
                  "warm: to first pixel s |", "|---|---|---|---|---|---|"]
        for (b, label), rec in res["compile"].items():
            cold, warm = rec.get("cold", {}), rec.get("warm", {})
            if "error" in cold or "error" in warm:
                continue
            lines.append(f"| {b} | {label} | {', '.join(cold['features']) or 'lean'} | "
                         f"{cold['compile_s']:.3g} | {warm['compile_s']:.3g} | "
                         f"{warm['to_first_pixel_s']:.3g} |")
    with open(os.path.join(r.out, "summary.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def _bvh_meshes(args):
    from bench.common import SHARED
    from bench.scaling import big_mesh
    models = os.path.join(SHARED, "assets", "models")
    meshes = [("suzanne", os.path.join(models, "suzanne.obj"), True),
              ("bunny-lowres", os.path.join(models, "stanford_bunny_lowres.obj"), True)]
    if not args.tiny:
        # brute force over 100k triangles: on the GPU only (0.5 M paths/s)
        meshes += [("dragon-100k", os.path.join(models, "stanford_dragon_100k.obj"),
                    args.gpu)]
    if not args.quick:
        meshes += [("dragon-1600k", big_mesh(2), False)]
    return meshes


def _scaling_meshes(args):
    from bench.common import SHARED
    from bench.scaling import big_mesh
    models = os.path.join(SHARED, "assets", "models")
    meshes = [("suzanne", os.path.join(models, "suzanne.obj")),
              ("bunny-lowres", os.path.join(models, "stanford_bunny_lowres.obj"))]
    if not args.tiny:
        meshes += [("bunny", os.path.join(models, "stanford_bunny.obj")),
                   ("dragon-100k", os.path.join(models, "stanford_dragon_100k.obj"))]
    if not args.quick:
        meshes += [(f"dragon-{100 * 4 ** k}k", big_mesh(k))
                   for k in range(1, args.max_subdivision + 1)]
    return meshes


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a few minutes on 2 CPU cores")
    p.add_argument("--tiny", action="store_true", help="with --quick: seconds (CI)")
    p.add_argument("--gpu", action="store_true", help="CUDA backend (and Mitsuba cuda_ad_rgb)")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--out", help="output folder (default bench/out/<date>)")
    p.add_argument("--sections", nargs="*", default=SECTIONS, choices=SECTIONS,
                   help="run only these")
    p.add_argument("--scenes", nargs="*", default=list(CONVERGENCE), choices=list(CONVERGENCE),
                   help="error-against-time scenes")
    p.add_argument("--max-spp", type=int, default=None,
                   help="the error-against-time curves' last spp level (default 1024 on the "
                        "CPU, 16384 with --gpu; the sun needs ~4096 to pass relMSE 1e-3)")
    p.add_argument("--max-subdivision", type=int, default=3, choices=(0, 1, 2, 3),
                   help="scaling: largest subdivided dragon (3: 6.4M triangles)")
    p.add_argument("--seeds", type=int, default=None,
                   help="samplers: renders per sampler and spp, each with its own seed "
                        "(default 4; --quick 3; --tiny 1); denoise: renders per image "
                        "(the same default; 1 with --quick)")
    p.add_argument("--replot", nargs="+", metavar="CSV",
                   help="only draw convergence.png (in --out) from these results.csv files")
    args = p.parse_args(argv)
    if args.tiny and not args.quick:
        p.error("--tiny goes with --quick")
    if args.seeds is None:
        args.seeds = 1 if args.tiny else 3 if args.quick else 4
    elif args.seeds < 1:
        p.error("--seeds must be at least 1")
    if args.replot:
        out = args.out or os.path.dirname(os.path.abspath(args.replot[0]))
        _plot_convergence(curves_from_csv(args.replot), os.path.join(out, "convergence.png"))
        return 0
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%d-%H%M%S")
    out = args.out or os.path.join(ROOT, "bench", "out", stamp)
    os.makedirs(out, exist_ok=True)
    r = Results(out)
    b = "cuda" if args.gpu else "cpu"
    peer = None if args.no_mitsuba else ("cuda_ad_rgb" if args.gpu else "llvm_ad_rgb")
    if peer and "convergence" in args.sections:
        ok, why = usable_mitsuba(peer)
        if not ok:
            print(f"bench: Mitsuba {peer} cannot render here ({why}): no peer curves",
                  file=sys.stderr)
            peer = None
    if args.tiny:
        max_spp, tp, repeats, filt_res, mres = 2, ((64, 64), 2), 2, (32, 24), ((32, 32), 1)
    elif args.quick:
        max_spp, tp, repeats, filt_res, mres = 64, ((128, 128), 8), 3, (160, 120), ((64, 64), 4)
    elif args.gpu:
        max_spp, tp, repeats, filt_res, mres = (16384, ((1024, 1024), 64), 7, (1280, 960),
                                                ((256, 256), 4))
    else:
        max_spp, tp, repeats, filt_res, mres = 1024, ((256, 256), 16), 7, (320, 240), ((96, 96), 4)
    if args.max_spp:
        max_spp = args.max_spp
    t0 = time.perf_counter()
    want = set(args.sections)
    res = {"convergence": ({}, {}), "samplers": {}, "denoise": {}, "adaptive": {}, "throughput": {}, "filtering": {}, "blocks": {}, "bvh": [],
           "scaling": [], "compile": {}}
    if "convergence" in want:
        res["convergence"] = section_convergence(args.scenes, [b], peer, max_spp, r)
    if "samplers" in want:
        spps = (2,) if args.tiny else (64,) if args.quick or not args.gpu else (64, 1024)
        # tiny (CI): one scene, so that CI compiles one more kernel, not four
        res["samplers"] = section_samplers(args.scenes[:1] if args.tiny else args.scenes, b,
                                           peer, spps, args.seeds, r)
    if "adaptive" in want:
        res["adaptive"] = section_adaptive(args.scenes[:1] if args.tiny else args.scenes, b,
                                           max_spp, r, adaptive_repeats(args))
    if "denoise" in want:
        res["denoise"] = section_denoise(
            args.scenes[:1] if args.tiny else args.scenes, b, 2 if args.tiny else 16,
            4 if args.tiny else 256, 1 if args.tiny else 3, r,
            seeds=1 if args.quick else args.seeds)
    if "throughput" in want:
        res["throughput"] = section_throughput([b], tp[0], tp[1], repeats, r)
    if "filtering" in want:
        res["filtering"] = section_filtering(
            b, filt_res, 2 if args.tiny else 8, repeats, r,
            grazing_spps=() if args.tiny else (4, 16, 64),   # (tiny: no more compiles)
            reference_spp=64 if args.tiny else 4096,
            grazing_res=(32, 16) if args.tiny else (96, 48), seeds=1 if args.tiny else 4,
            # (tiny: trilinear only, the convergence section's kernel; bilinear and nearest
            # share another, ~35 s of CI's compile time)
            filters=("trilinear",) if args.tiny else ("trilinear", "bilinear", "nearest"))
    if args.gpu and "blocks" in want:
        res["blocks"] = section_blocks((1024, 1024), 16, repeats, r)
    if "bvh" in want:
        variants = [("brute force", dict(split="none")), ("midpoint", dict(split="midpoint")),
                    ("SAH 16 bins, leaf 8", dict())]
        if not args.tiny:
            variants += [(f"SAH {n} bins, leaf 8", dict(n_bins=n)) for n in (4, 8, 12, 32)]
            variants += [(f"SAH 16 bins, leaf {k}", dict(max_leaf=k)) for k in (1, 2, 4, 16)]
        res["bvh"] = section_bvh(b, _bvh_meshes(args), mres[0], mres[1], repeats, variants, r)
    if "scaling" in want:
        res["scaling"] = section_scaling(b, _scaling_meshes(args), mres[0], mres[1],
                                         3 if args.quick else 5, r)
    if "compile" in want:
        scenes = compile_scenes()
        res["compile"] = section_compile([b], scenes[:1] if args.tiny else
                                         scenes[::2] if args.quick else scenes, r)
    r.write()
    summary(r, res, args)
    print(f"bench: {len(r.rows)} rows in {time.perf_counter() - t0:.0f} s -> {out}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
