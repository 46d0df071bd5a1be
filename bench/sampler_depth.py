"""Where a sampler's gain is made: the Cornell box's noise per path depth, for our samplers
and Mitsuba 3's, in one run:

    python -m bench.sampler_depth --spp 64 --seeds 8 --depths 1 2 7 --json out.json

For each maximum depth (our ``maxBounces``: 1 is direct light only; Mitsuba's ``max_depth``
is one more) every sampler renders the box ``--seeds`` times with different seeds. No
reference is needed (the renders of a depth-limited box have none): the error is the
relative variance between the seeds' images, mean over pixels and channels of
var / (m^2 + 0.01), with m the mean of *all* the renders of that depth (every sampler's,
so that each sampler's variance is divided by the same image; an unbiased renderer's
relMSE against a noiseless reference is this variance). Printed with its ratio to the same
renderer's independent sampler; the increments between depths show which bounces a
sampler stratifies. Mitsuba renders its own Cornell box (the reference's scene,
``bench.common.mitsuba_cornell``) with ``llvm_ad_rgb`` (``--gpu``: we render with CUDA and
Mitsuba with ``cuda_ad_rgb``).
"""
import argparse
import json
import sys

import numpy as np

from bench.common import command, machine, now, usable_mitsuba, versions

OURS = ("independent", "sobol")
MITSUBA = ("independent", "multijitter", "ldsampler", "stratified")


def relative_variances(stacks):
    """{name: relative variance} of {name: (seeds, H, W, 3) renders}, each divided by the
    pooled mean of every stack (see the module's docstring)."""
    pooled = np.mean([s.mean(0) for s in stacks.values()], axis=0)
    den = pooled * pooled + 0.01
    return {k: float((s.var(0, ddof=1) / den).mean()) for k, s in stacks.items()}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--depths", type=int, nargs="+", default=[1, 2, 7],
                   help="our maxBounces (1: direct light only)")
    p.add_argument("--gpu", action="store_true")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--json", help="write the figures here")
    args = p.parse_args(argv)
    if args.seeds < 2:
        p.error("--seeds: at least 2 (a variance between renders)")
    if min(args.depths) < 1:
        p.error("--depths: at least 1 (0 is the light seen directly: no noise to compare)")
    import pathtracer as pt
    from bench.common import mitsuba_cornell
    from bench.scenes import CONVERGENCE, convergence_scene
    backend = "cuda" if args.gpu else "cpu"
    variant = "cuda_ad_rgb" if args.gpu else "llvm_ad_rgb"
    use_mitsuba = not args.no_mitsuba
    if use_mitsuba:
        ok, why = usable_mitsuba(variant)
        if not ok:
            print(f"sampler_depth: no Mitsuba ({why})", file=sys.stderr)
            use_mitsuba = False
    width, height = CONVERGENCE["cornell-box"][1]
    rows = []
    for depth in args.depths:
        stacks = {}
        for sampler in OURS:
            scene = convergence_scene("cornell-box", sampler)
            stacks[f"pt-render {backend} {sampler}"] = np.array(
                [pt.render(scene, spp=args.spp, seed=s, max_bounces=depth,
                           backend=backend).image for s in range(args.seeds)], np.float64)
        if use_mitsuba:
            import drjit as dr
            import mitsuba as mi
            mi.set_variant(variant)
            for sampler in MITSUBA:
                scene = mitsuba_cornell(width, height, args.spp, max_depth=depth + 1,
                                        sampler=sampler)
                ims = []
                for s in range(args.seeds):
                    img = mi.render(scene, spp=args.spp, seed=1000 + s)
                    dr.eval(img)
                    ims.append(np.array(img))
                stacks[f"Mitsuba {variant} {sampler}"] = np.array(ims, np.float64)
        var = relative_variances(stacks)
        for name, v in var.items():
            base = var[name.rsplit(" ", 1)[0] + " independent"]
            rows.append({"max_bounces": depth, "renderer": name, "relative_variance": v,
                         "ratio_to_independent": v / base})
            print(f"maxBounces {depth}: {name}: {v:.4g} ({v / base:.3f})", flush=True)
    record = {"command": command(), "machine": machine(), "date": now(),
              "versions": versions(), "scene": "cornell-box", "resolution": [width, height],
              "spp": args.spp, "seeds": args.seeds, "rows": rows}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(record, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
