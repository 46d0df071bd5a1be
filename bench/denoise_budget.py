"""A denoised image's samples spread evenly or where its noise is, at the same mean spp:

    python -m bench.denoise_budget --scenes cornell-box bunny-studio --spp 16 --seeds 4 \
        --json out.json

For each scene and seed: the raw image at ``--spp`` (uniform) and at ``--high`` spp, and an
adaptive image of the same mean ``--spp``: ``--first`` spp per pixel in two halves, then the
rest of the budget, (spp - first) x pixels samples, in passes of ``--step`` spp to the
pixels in proportion to their estimated relMSE to the power ``--power`` (the halves'
squared difference over the mean's square + 0.01, as pathtracer.progressive.error_estimate
has it per pixel before its 3x3 mean), that estimate widened to each pixel's 3x3 maximum
(an edge's neighbours are often as far off as the pixel that shows it). The uniform and
the adaptive image are denoised (pathtracer.denoise: Open Image Denoise, our albedo and
normal images). Printed and recorded: the relMSE of each against
the scene's reference, the mean over the seeds. An experiment, not a renderer mode: each
pixel is the plain mean of its samples, and choosing its count from its own first samples
is the usual adaptive sampler's (small) bias.
"""
import argparse
import sys

import numpy as np

from bench.common import write_record
from bench.scenes import CONVERGENCE, convergence_desc, load_reference


def max3x3(a):
    """Each pixel's maximum over its 3x3 neighbourhood (edges clamped)."""
    p = np.pad(a, 1, mode="edge")
    h, w = a.shape
    return np.max([p[i:i + h, j:j + w] for i in range(3) for j in range(3)], axis=0)


def adaptive_image(backend, scene, seed, spp, first, step, power):
    """(image, samples per pixel) of the adaptive split described in the module's text."""
    from pathtracer.progressive import RELMSE_EPS
    h, w = scene.height, scene.width
    mb, rr = scene.max_bounces, scene.rr_depth
    half = first // 2
    a = backend.render_pass(0, half, seed, mb, rr)[0].astype(np.float64)
    b = backend.render_pass(half, half, seed, mb, rr)[0].astype(np.float64)
    total = a + b
    mean = total / (2 * half)
    err = max3x3((((a - b) / (2 * half)) ** 2 / (mean * mean + RELMSE_EPS)).mean(-1))
    passes = (spp - 2 * half) * h * w // step          # passes of `step` spp to hand out
    share = err ** power
    x = share / share.sum() * passes if share.sum() > 0 else np.full((h, w), passes / (h * w))
    k = np.floor(x).astype(np.int64)
    rest = int(passes - k.sum())
    if rest > 0:                                      # the largest remainders
        k.flat[np.argsort(-(x - k), axis=None)[:rest]] += 1
    count = np.full((h, w), 2 * half, np.int64)
    j = 0
    while (k > j).any():
        active = (k > j).astype(np.uint8)
        out = backend.render_pass(2 * half + j * step, step, seed, mb, rr, active)[0]
        total += np.where(active[..., None] > 0, out, 0.0)
        count += active * step
        j += 1
    return (total / count[..., None]).astype(np.float32), count


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+", default=["cornell-box", "bunny-studio"],
                   choices=sorted(CONVERGENCE))
    p.add_argument("--spp", type=int, default=16, help="the mean samples per pixel")
    p.add_argument("--high", type=int, default=256, help="the raw image to compare with")
    p.add_argument("--first", type=int, default=8, help="uniform spp before the split (even)")
    p.add_argument("--step", type=int, default=4, help="spp per adaptive pass")
    p.add_argument("--power", type=float, default=1.0)
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--backend", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--json")
    args = p.parse_args(argv)
    if not 2 <= args.first < args.spp or args.first % 2:
        p.error("--first: an even number of spp, at least 2 and below --spp")
    for name in ("step", "seeds", "high"):
        if getattr(args, name) < 1:
            p.error(f"--{name}: at least 1")
    from pathtracer.backends import make_backend
    from pathtracer.denoise import AOV_SPP, denoise, resolve_device
    from pathtracer.film import relmse
    from pathtracer.progressive import render
    from pathtracer.scene import compile_scene
    device = resolve_device("auto", args.backend)
    rows = []
    for name in args.scenes:
        try:
            ref, _ = load_reference(name)
        except FileNotFoundError:
            print(f"{name}: no reference, skipped", flush=True)
            continue
        scene = compile_scene(convergence_desc(name))
        backend = make_backend(args.backend, scene)
        backend.compile()
        errs = {}
        for seed in range(args.seeds):
            uniform = render(scene, backend, spp=args.spp, seed=seed).film.image()
            aovs = backend.aovs(AOV_SPP, seed)
            adaptive, count = adaptive_image(backend, scene, seed, args.spp, args.first,
                                             args.step, args.power)
            high = render(scene, backend, spp=args.high, seed=seed).film.image()
            for key, img in (("uniform_raw", uniform),
                             ("uniform_denoised", denoise(uniform, aovs, device)),
                             ("adaptive_raw", adaptive),
                             ("adaptive_denoised", denoise(adaptive, aovs, device)),
                             ("raw_high", high)):
                errs.setdefault(key, []).append(relmse(img, ref))
            errs.setdefault("adaptive_mean_spp", []).append(float(count.mean()))
            errs.setdefault("adaptive_max_spp", []).append(int(count.max()))
        row = {"scene": name, "spp": args.spp, "high_spp": args.high, "first": args.first,
               "step": args.step, "power": args.power, "seeds": args.seeds,
               "denoise_device": device}
        row.update({k: float(np.mean(v)) for k, v in errs.items()})
        rows.append(row)
        hi = row["raw_high"]
        print(f"{name}: relMSE, mean of {args.seeds} seeds: raw {args.high} spp {hi:.3g}; "
              f"{args.spp} spp uniform denoised {row['uniform_denoised']:.3g} "
              f"({row['uniform_denoised'] / hi:.2f}x), adaptive (mean "
              f"{row['adaptive_mean_spp']:.1f} spp, at most {row['adaptive_max_spp']:.0f}) "
              f"denoised {row['adaptive_denoised']:.3g} ({row['adaptive_denoised'] / hi:.2f}x); "
              f"raw uniform {row['uniform_raw']:.3g}, adaptive {row['adaptive_raw']:.3g}",
              flush=True)
    if args.json:
        write_record(args.json, backend=args.backend, rows=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
