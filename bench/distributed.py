"""Beyond one device: a render split over several GPUs (``--devices``) or Ray workers
(``--ray``), against the one-device render of the same scene in the same run.

    python -m bench.distributed gpus [--scenes cornell-box bunny-studio] [--repeats 3]
                                     [--devices 0 1]
    python -m bench.distributed ray [--workers 2] [--scenes cornell-box]

``gpus``: per scene, paths/s of whole renders (progressive passes, compile excluded) on one
GPU and on all GPUs (or those of ``--devices``; SplitBackend, one thread per GPU),
alternating, the median of ``--repeats`` after a warm-up render of each; the speed-up,
each GPU's share of the samples, and how far the split image is from the one-GPU image
(max per-pixel relative difference, with values below 1e-3 compared absolutely, and the
relMSE between them).
``ray``: the same on the CPU with a local Ray runtime (``--ray local --ray-workers N``)
against the single-process CPU render; Ray's start (runtime and workers, their kernels
loaded from the disk cache) is reported apart from the renders.
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

from bench.common import ROOT, command, machine, now, versions

SETTINGS = {   # scene -> (resolution, spp) per mode: a one-device render of a few seconds
    "gpus": {"cornell-box": ((1024, 1024), 2048), "bunny-studio": ((1024, 768), 1024)},
    "ray": {"cornell-box": ((256, 256), 64), "bunny-studio": ((256, 192), 16)},
}


def load(name, res):
    import pathtracer as pt
    if name == "bunny-studio":
        from bench.scenes import bunny_studio
        return pt.load_scene(bunny_studio(res))
    return pt.load_scene(os.path.join(ROOT, "scenes", name + ".json"),
                         _overrides={"resolution": tuple(res)})


def difference(a, b):
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    rel = np.abs(a - b) / np.maximum(np.maximum(np.abs(a), np.abs(b)), 1e-3)
    return {"max_rel_diff": float(rel.max()),
            "relmse_between": float(np.mean((a - b) ** 2 / (a * a + 0.01)))}


def run(mode, scenes, repeats, workers, spp_scale=1, devices="all"):
    import pathtracer as pt
    record = {"command": command(), "machine": machine(), "date": now(),
              "versions": versions(), "mode": mode, "scenes": {}}
    if mode == "gpus":
        from numba import cuda
        record["gpus"] = [cuda.gpus[i].name.decode() if isinstance(cuda.gpus[i].name, bytes)
                          else str(cuda.gpus[i].name) for i in range(len(cuda.gpus))]
        one = dict(backend="cuda")
        split = dict(devices=devices)
        record["devices"] = devices
    else:
        t0 = time.perf_counter()
        from pathtracer import cluster
        pool = cluster.pool("local", workers)
        record["ray_start_s"] = time.perf_counter() - t0
        record["ray_workers"] = pool.label
        one = dict(backend="cpu")
        split = dict(ray="local", ray_workers=workers)
    for name in scenes:
        res, spp = SETTINGS[mode][name]
        spp = int(spp * spp_scale)
        scene = load(name, res)
        row = {"resolution": list(res), "spp": spp, "one": [], "split": []}
        warm = {}
        for key, opts in (("one", one), ("split", split)):
            t0 = time.perf_counter()
            r = pt.render(scene, spp=max(1, spp // 16), **opts)
            warm[key] = time.perf_counter() - t0
            row[f"{key}_first_render_s"] = warm[key]
            row[f"{key}_compile_s"] = r.compile_seconds
        images = {}
        for _ in range(repeats):
            for key, opts in (("one", one), ("split", split)):
                r = pt.render(scene, spp=spp, **opts)
                row[key].append(r.stats["paths_per_second"])
                images[key] = r.image
                print(f"{name} {key}: {r.stats['paths_per_second'] / 1e6:.1f} M paths/s "
                      f"({r.seconds:.2f} s)", file=sys.stderr, flush=True)
                if key == "split":
                    row["shares"] = r.shares      # (cumulative over the renders)
        row["one_paths_per_s"] = statistics.median(row["one"])
        row["split_paths_per_s"] = statistics.median(row["split"])
        row["speedup"] = row["split_paths_per_s"] / row["one_paths_per_s"]
        row.update(difference(images["one"], images["split"]))
        record["scenes"][name] = row
        print(f"{name}: one {row['one_paths_per_s'] / 1e6:.1f}, split "
              f"{row['split_paths_per_s'] / 1e6:.1f} M paths/s: {row['speedup']:.3f}x; "
              f"shares {[round(s, 3) for s in row['shares']]}; max rel diff "
              f"{row['max_rel_diff']:.2e}", flush=True)
    if mode == "ray":
        from pathtracer import cluster
        cluster.shutdown()
    return record


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mode", choices=("gpus", "ray"))
    p.add_argument("--scenes", nargs="+", default=None)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--workers", type=int, default=2, help="ray: the number of Ray workers")
    p.add_argument("--devices", type=int, nargs="+", default=None,
                   help="gpus: split over these CUDA device numbers (default: all)")
    p.add_argument("--spp-scale", type=float, default=1,
                   help="renders this many times longer (the steady state of long renders: "
                        "the first passes of a render are short and each pass costs a "
                        "synchronisation of the workers)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    scenes = args.scenes or list(SETTINGS[args.mode])
    if args.devices is not None and args.mode != "gpus":
        p.error("--devices: the gpus mode's option")
    record = run(args.mode, scenes, args.repeats, args.workers, args.spp_scale,
                 args.devices if args.devices is not None else "all")
    out = args.out or os.path.join(ROOT, "bench", "results", f"distributed-{args.mode}.json")
    with open(out, "w") as f:
        json.dump(record, f, indent=1)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
