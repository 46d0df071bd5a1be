"""Paths per second of one render pass with each sampler, on one convergence scene:

    python -m bench.sampler_speed cornell-box --spp 64 --backend cuda

A pass of ``spp`` samples per pixel at the scene's convergence resolution, the median of
``--repeats`` after a warm-up pass, compile excluded; both samplers in the same process.
"""
import argparse
import time

import numpy as np

from bench.scenes import CONVERGENCE, convergence_desc


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", choices=list(CONVERGENCE))
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--backend", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    for sampler in ("independent", "sobol"):
        desc = convergence_desc(args.scene)
        desc.render.sampler = sampler
        scene = compile_scene(desc)
        backend = make_backend(args.backend, scene)
        backend.compile()
        backend.render_pass(0, 1, 0, scene.max_bounces, scene.rr_depth)
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            backend.render_pass(0, args.spp, 0, scene.max_bounces, scene.rr_depth)
            times.append(time.perf_counter() - t)
        t = float(np.median(times))
        print(f"{args.scene} {sampler}: {t:.4f} s, "
              f"{scene.width * scene.height * args.spp / t / 1e6:.3f} M camera paths/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
