"""The light tree against picking lights by power (render.lightSampler): error at equal
samples, time per sample, and their product, on a scene of many lights and on the Cornell
box (two light triangles, where "auto" keeps the power sampler):

    python -m bench.light_sampler [--backend cpu|cuda] [--scenes lamps cornell-box]
        [--spp 64] [--seeds 4] [--repeats 5] [--ref-spp 4096] [--json PATH]

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

from bench.common import CORNELL, command, machine, now, versions
from bench.metrics import relmse

SCENES = {"lamps": (192, 144), "cornell-box": (256, 256)}


def describe_scene(name, light_sampler, res):
    from pathtracer.scene import load_scene_description
    from bench.scenes import describe, lamps
    if name == "lamps":
        desc = describe(lamps(res, light_sampler))
    else:
        desc = load_scene_description(CORNELL)
        desc.render.light_sampler = light_sampler
    desc.camera.resolution = res
    return desc


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
            row = {"scene": name, "light_sampler": sampler, "resolution": list(res),
                   "spp": args.spp, "relMSE": err,
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
    record = {"command": command(), "machine": machine(), "date": now(),
              "versions": versions(), "backend": args.backend, "ref_spp": args.ref_spp,
              "rows": rows}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(record, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
