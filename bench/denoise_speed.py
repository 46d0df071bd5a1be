"""Open Image Denoise's time per image on the CPU and on the GPU, at the sizes people render:

    python -m bench.denoise_speed --scene cornell-box --sizes 256x192 1024x768 1920x1080 \
        --backend cuda --json out.json

For each size: the scene rendered at ``--spp`` on ``--backend``, its albedo and normal
images (pathtracer.denoise.AOV_SPP rays per pixel), then the denoiser on each device
that runs here (the CPU always; the GPU where OIDN's CUDA device works): the median of
``--repeats`` calls after one call that sets the filter up (that first call's time is
reported apart: it loads the network). Also the relMSE between the two devices' images
(they run the same network: rounding). Each call includes what `pt-render --denoise`
pays: copying the three images in and the result out.
"""
import argparse
import sys
import time

import numpy as np

from bench.common import median_time, write_record
from bench.scenes import convergence_desc


def _size(text):
    w, h = text.lower().split("x")
    return int(w), int(h)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cornell-box")
    p.add_argument("--sizes", type=_size, nargs="+", default=[(256, 192), (1024, 768)])
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--backend", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json")
    args = p.parse_args(argv)
    from pathtracer.backends import make_backend
    from pathtracer.denoise import AOV_SPP, cuda_denoiser_available, denoise
    from pathtracer.film import relmse
    from pathtracer.progressive import render
    from pathtracer.scene import compile_scene
    devices = ["cpu"] + (["cuda"] if cuda_denoiser_available() else [])
    rows = []
    for w, h in args.sizes:
        desc = convergence_desc(args.scene)
        desc.camera.resolution = (w, h)
        scene = compile_scene(desc)
        backend = make_backend(args.backend, scene)
        backend.compile()
        image = render(scene, backend, spp=args.spp).film.image()
        aovs = backend.aovs(AOV_SPP, 0)
        out = {}
        for d in devices:
            t0 = time.perf_counter()
            out[d] = denoise(image, aovs, d)
            first = time.perf_counter() - t0
            t, _ = median_time(lambda: denoise(image, aovs, d), args.repeats)
            rows.append({"scene": args.scene, "width": w, "height": h, "spp": args.spp,
                         "device": d, "denoise_s": t, "first_call_s": first})
            print(f"{args.scene} {w}x{h}: denoise on {d}: {t * 1e3:.1f} ms "
                  f"(first call {first:.2f} s)", flush=True)
        if len(out) == 2:
            diff = relmse(out["cuda"], out["cpu"])
            rows[-1]["gpu_vs_cpu_relMSE"] = diff
            print(f"{args.scene} {w}x{h}: relMSE between the GPU's and the CPU's image "
                  f"{diff:.3g}", flush=True)
    if args.json:
        write_record(args.json, backend=args.backend, rows=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
