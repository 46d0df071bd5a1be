"""High-spp references for the error-against-time study (every scene but the Cornell box,
whose reference is Mitsuba 3's). Made on a GPU and committed in bench/references/, because a
CPU cannot make them in reasonable time:

    python -m bench.references --spp 65536 [--scenes bunny-studio sun] [--backend cuda]
    python -m bench.references --mitsuba cuda_ad_rgb --spp 65536    # Mitsuba 3's own

Mitsuba's curves on these scenes are measured against Mitsuba's own reference
(`<scene>-mitsuba.npz`), so that both renderers' errors are their noise alone; how far the two
references differ is stored as `agreement_relmse`.

Each reference is the mean of two independent halves (seeds far from those the benchmark
uses); the halves' difference estimates the reference's own noise, stored with it, so a
relMSE measured against it can be read with its floor in mind.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench.common import command, machine, now, versions
from bench.metrics import relmse
from bench.scenes import (CONVERGENCE, REFERENCES, convergence_desc, load_reference,
                          reference_path)

SEEDS = (1_000_003, 2_000_029)


def reference_noise(half_a, half_b, eps=0.01):
    """Expected relMSE of (a + b) / 2 against the noise-free image, from two independent
    unbiased halves: E[(a - b)^2] = 2 var(half) and var(mean) = var(half) / 2, so the mean's
    variance is E[(a - b)^2] / 4 (per pixel, with relMSE's denominator)."""
    a = np.asarray(half_a, np.float64)
    b = np.asarray(half_b, np.float64)
    m = (a + b) / 2
    return float(np.mean((a - b) ** 2 / 4 / (m * m + eps)))


def make_reference(name, spp, backend_name):
    from pathtracer.backends import make_backend
    from pathtracer.progressive import render
    from pathtracer.scene import compile_scene
    scene = compile_scene(convergence_desc(name))
    backend = make_backend(backend_name, scene)
    halves, seconds = [], 0.0
    for seed in SEEDS:
        t0 = time.perf_counter()
        res = render(scene, backend, spp=spp // 2, seed=seed, pass_seconds=2.0)
        seconds += time.perf_counter() - t0
        halves.append(res.film.image().astype(np.float64))
    image = ((halves[0] + halves[1]) / 2).astype(np.float32)
    meta = {"scene": name, "spp": spp, "seeds": list(SEEDS), "backend": backend_name,
            "resolution": [scene.width, scene.height], "seconds": seconds,
            "noise_relmse": reference_noise(*halves), "command": command(),
            "machine": machine(), "date": now(), "versions": versions()}
    return image, meta


def make_mitsuba_reference(name, spp, variant, chunk=1024):
    import mitsuba as mi

    from pathtracer.mitsuba import mitsuba_dict
    mi.set_variant(variant)
    scene = mi.load_dict(mitsuba_dict(convergence_desc(name)))
    halves, t0 = [], time.perf_counter()
    n = max(1, spp // 2 // chunk)
    for seed in SEEDS:
        acc = 0.0
        for k in range(n):
            acc = acc + np.array(mi.render(scene, spp=spp // 2 // n, seed=seed + k), np.float64)
        halves.append(acc / n)
    image = ((halves[0] + halves[1]) / 2).astype(np.float32)
    meta = {"scene": name, "spp": 2 * n * (spp // 2 // n), "seeds": list(SEEDS),
            "renderer": f"Mitsuba {mi.__version__} {variant}",
            "resolution": [image.shape[1], image.shape[0]],
            "seconds": time.perf_counter() - t0, "noise_relmse": reference_noise(*halves),
            "command": command(), "machine": machine(), "date": now(), "versions": versions()}
    try:
        meta["agreement_relmse"] = relmse(image, load_reference(name)[0])
    except FileNotFoundError:
        pass
    return image, meta


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spp", type=int, default=65536)
    p.add_argument("--backend", default="cuda")
    p.add_argument("--scenes", nargs="*", default=[n for n in CONVERGENCE if n != "cornell-box"])
    p.add_argument("--mitsuba", metavar="VARIANT", help="Mitsuba 3's reference instead")
    p.add_argument("--out", default=REFERENCES)
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    if a.mitsuba:
        from bench.common import usable_mitsuba
        ok, why = usable_mitsuba(a.mitsuba)
        if not ok:
            p.error(f"Mitsuba {a.mitsuba} cannot render here: {why}")
    for name in a.scenes:
        if a.mitsuba:
            from pathtracer.mitsuba import NotExpressible
            try:
                image, meta = make_mitsuba_reference(name, a.spp, a.mitsuba)
            except NotExpressible as e:
                print(f"{name}: not expressible in Mitsuba ({e}): skipped", flush=True)
                continue
        else:
            image, meta = make_reference(name, a.spp, a.backend)
        path = os.path.join(a.out, os.path.basename(reference_path(name, bool(a.mitsuba))))
        np.savez_compressed(path, image=image, meta=json.dumps(meta))
        print(f"{name}: {meta['spp']} spp in {meta['seconds']:.1f} s, reference noise "
              f"(relMSE) {meta['noise_relmse']:.3g}, against ours "
              f"{meta.get('agreement_relmse', float('nan')):.3g} -> {path}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
