"""Render the gallery scenes of scenes/ into docs/images/ (README and docs/gallery.md).

    python -m bench.gallery [--spp N] [--backend auto|cpu|cuda] [--out docs/images]
"""
import argparse
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ["cornell-box", "principled-grid", "textured", "glass", "depth-of-field"]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spp", type=int, default=None, help="default: each scene's own")
    p.add_argument("--backend", default="auto")
    p.add_argument("--out", default=os.path.join(ROOT, "docs", "images"))
    p.add_argument("--scenes", nargs="*", default=SCENES)
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    for name in args.scenes:
        cmd = [sys.executable, "-m", "pathtracer", os.path.join(ROOT, "scenes", name + ".json"),
               "-o", os.path.join(args.out, f"gallery-{name}.png"), "--backend", args.backend,
               "--quiet"]
        if args.spp:
            cmd += ["--spp", str(args.spp)]
        t0 = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True)
        print(f"{name}: {time.perf_counter() - t0:.1f} s; {r.stderr.strip().splitlines()[-1]}",
              flush=True)
        if r.returncode:
            return r.returncode
    return 0


if __name__ == "__main__":
    sys.exit(main())
