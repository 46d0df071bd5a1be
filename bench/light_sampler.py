"""The light tree against picking lights by power (render.lightSampler): error at equal
samples, time per sample, and their product, on a scene of many lights and on the Cornell
box (two light triangles, where "auto" keeps the power sampler):

    python -m bench.light_sampler [--backend cpu|cuda] [--scenes lamps lamps-area cornell-box]
        [--spp 64] [--seeds 4] [--repeats 5] [--ref-spp 4096] [--json PATH] [--mitsuba]

``lamps-area`` is ``lamps`` without its spot and point light, which Mitsuba 3 renders too
(``--mitsuba``: ``llvm_ad_rgb`` on the CPU, ``cuda_ad_rgb`` with ``--backend cuda``; its
``independent`` and ``multijitter`` samplers, each measured against Mitsuba's own reference
of ``--ref-spp`` samples, rendered in chunks of 1,024).

relMSE is measured against one long render of the scene with the tree (``--ref-spp``;
seeds far from the measured ones), the mean over ``--seeds`` renders of ``--spp`` samples;
time per render is the median of ``--repeats`` after a warm-up render, compile excluded.
``error x time`` (relMSE x seconds) is what the time to a given error scales with.
"""
import argparse
import json
import os
import time

import numpy as np

from bench.common import (CORNELL, ROOT, command, machine, mitsuba_pass_times, now, usable_mitsuba,
                          versions)
from bench.metrics import relmse

SCENES = {"lamps": (192, 144), "lamps-area": (192, 144), "sun-spot": (192, 144),
          "cornell-box": (256, 256)}
REFERENCES = {}     # ours, by scene (Mitsuba's rows say how far its own is from ours)


def describe_scene(name, light_sampler, res):
    from pathtracer.scene import load_scene_description
    from bench.scenes import describe, lamps
    if name.startswith("lamps"):
        desc = describe(lamps(res, light_sampler, punctual=name == "lamps"))
    elif name == "sun-spot":
        desc = describe(sun_and_spot(res, light_sampler))
    else:
        desc = load_scene_description(CORNELL)
        desc.render.light_sampler = light_sampler
    desc.camera.resolution = res
    return desc


def sun_and_spot(res, light_sampler):
    """Two lights: a sun (a directional light) and a blue spot light whose pool lies beside
    the sun's shadow of a ball; the spot lights its pool about as much as the sun does, but
    by power the spot gets 0.24 % of the light samples everywhere (its pmf in light_cdf)."""
    plane = os.path.join(ROOT, "scenes", "assets", "plane.obj")
    ball = os.path.join(ROOT, "scenes", "assets", "sphere.obj")
    return {
        "camera": {"resolution": list(res), "position": [0, 6, 9], "lookAt": [0, 0, 0],
                   "fov": 50},
        "render": {"maxBounces": 4, "lightSampler": light_sampler},
        "materials": [{"name": "white", "type": "diffuse", "albedo": 0.7}],
        "objects": [{"name": "floor", "file": plane, "material": "white",
                     "transform": {"scale": [8, 1, 8]}},
                    {"name": "ball", "file": ball, "material": "white", "smooth": True,
                     "transform": {"scale": 0.8, "translate": [-1.5, 0.8, 0]}}],
        "lights": [{"type": "directional", "direction": [0.5, -1, -0.3], "irradiance": 3},
                   {"type": "spot", "position": [2.5, 3, 1], "intensity": [2, 4, 12],
                    "direction": [0, -1, 0], "innerAngle": 15, "outerAngle": 30}],
    }


def render(backend, scene, spp, seed):
    """The image of ``spp`` samples, in one pass up to 256 spp."""
    from pathtracer.progressive import render as progressive
    return progressive(scene, backend, spp=spp, seed=seed, first_pass=min(spp, 256),
                       headless=True).film.image()


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--ref-spp", type=int, default=4096)
    p.add_argument("--scale", type=int, default=1, help="resolution x this")
    p.add_argument("--json", default=None)
    p.add_argument("--mitsuba", action="store_true",
                   help="Mitsuba 3 on lamps-area in the same run")
    args = p.parse_args(argv)
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    rows = []
    for name in args.scenes:
        res = tuple(x * args.scale for x in SCENES[name])
        scenes, backends = {}, {}
        for sampler in ("power", "tree"):
            scenes[sampler] = compile_scene(describe_scene(name, sampler, res))
            assert scenes[sampler].features.light_tree == (sampler == "tree")
            t = time.perf_counter()
            backends[sampler] = make_backend(args.backend, scenes[sampler])
            backends[sampler].compile()
            print(f"{name} {sampler}: compiled in {time.perf_counter() - t:.1f} s", flush=True)
        t = time.perf_counter()
        ref = render(backends["tree"], scenes["tree"], args.ref_spp, 1_000_003)
        ref_seconds = time.perf_counter() - t
        REFERENCES[name] = ref
        for sampler in ("power", "tree"):
            scene, backend = scenes[sampler], backends[sampler]
            errors = [relmse(render(backend, scene, args.spp, seed), ref)
                      for seed in range(args.seeds)]
            render(backend, scene, args.spp, 0)
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                render(backend, scene, args.spp, 0)
                times.append(time.perf_counter() - t)
            seconds = float(np.median(times))
            err = float(np.mean(errors))
            row = {"scene": name, "renderer": "pt-render", "light_sampler": sampler,
                   "resolution": list(res), "spp": args.spp, "relMSE": err,
                   "relMSE_stderr": float(np.std(errors, ddof=1) / np.sqrt(len(errors)))
                   if len(errors) > 1 else None,
                   "seconds": seconds, "times": times,
                   "M_paths_per_s": res[0] * res[1] * args.spp / seconds / 1e6,
                   "error_x_time": err * seconds, "lights": int(len(scene.arrays.light_ref)),
                   "tree_nodes": int(scene.arrays.lt_node.shape[0]) if sampler == "tree" else 0}
            rows.append(row)
            print(f"{name} {sampler}: relMSE {err:.3e} at {args.spp} spp, {seconds:.4f} s "
                  f"({row['M_paths_per_s']:.2f} M paths/s), error x time "
                  f"{row['error_x_time']:.3e}", flush=True)
        a, b = rows[-2], rows[-1]
        print(f"{name} tree / power: relMSE {b['relMSE'] / a['relMSE']:.3f}x, time "
              f"{b['seconds'] / a['seconds']:.3f}x, error x time "
              f"{b['error_x_time'] / a['error_x_time']:.3f}x (reference {args.ref_spp} spp, "
              f"{ref_seconds:.1f} s)", flush=True)
    if args.mitsuba and "lamps-area" in args.scenes:
        rows += mitsuba_rows(args)
    record = {"command": command(), "machine": machine(), "date": now(),
              "versions": versions(), "backend": args.backend, "ref_spp": args.ref_spp,
              "rows": rows}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(record, f, indent=1)
    return 0


def mitsuba_rows(args):
    """Mitsuba 3's relMSE at --spp (against its own reference) and time per render on
    lamps-area, with its independent and multijitter samplers."""
    variant = "cuda_ad_rgb" if args.backend == "cuda" else "llvm_ad_rgb"
    ok, why = usable_mitsuba(variant)
    if not ok:
        print(f"Mitsuba left out: {why}")
        return [{"scene": "lamps-area", "renderer": "mitsuba", "skipped": why}]
    import drjit as dr
    import mitsuba as mi
    from pathtracer.mitsuba import mitsuba_dict
    mi.set_variant(variant)
    res = tuple(x * args.scale for x in SCENES["lamps-area"])
    desc = describe_scene("lamps-area", "power", res)
    rows = []
    ref = None
    for sampler in ("independent", "multijitter"):
        scene = mi.load_dict(mitsuba_dict(desc, spp=args.spp, sampler=sampler))
        if ref is None:
            chunks = max(1, args.ref_spp // 1024)
            t = time.perf_counter()
            acc = 0
            for c in range(chunks):
                img = mi.render(scene, spp=min(args.ref_spp, 1024), seed=1_000_003 + c)
                dr.eval(img)
                acc = acc + np.array(img, np.float64)
            ref = acc / chunks
            agreement = relmse(ref[..., :3], REFERENCES["lamps-area"])
            print(f"lamps-area Mitsuba reference: {chunks} x {min(args.ref_spp, 1024)} spp, "
                  f"{time.perf_counter() - t:.1f} s; relMSE against ours {agreement:.2e}",
                  flush=True)
        errors = [relmse(np.array(mi.render(scene, spp=args.spp, seed=s))[..., :3], ref[..., :3])
                  for s in range(args.seeds)]
        first, seconds, times = mitsuba_pass_times(scene, args.spp, args.repeats)
        err = float(np.mean(errors))
        row = {"scene": "lamps-area", "renderer": "mitsuba", "variant": variant,
               "sampler": sampler, "resolution": list(res), "spp": args.spp, "relMSE": err,
               "relMSE_stderr": float(np.std(errors, ddof=1) / np.sqrt(len(errors)))
               if len(errors) > 1 else None, "seconds": seconds, "times": times,
               "first_render_s": first, "reference_agreement_relMSE": agreement,
               "M_paths_per_s": res[0] * res[1] * args.spp / seconds / 1e6,
               "error_x_time": err * seconds}
        rows.append(row)
        print(f"lamps-area Mitsuba {sampler}: relMSE {err:.3e} at {args.spp} spp, "
              f"{seconds:.4f} s ({row['M_paths_per_s']:.2f} M paths/s), error x time "
              f"{row['error_x_time']:.3e}", flush=True)
    return rows


if __name__ == "__main__":
    raise SystemExit(main())
