"""``pt-render SCENE``: render a scene file progressively to PNG + a float image."""
import argparse
import csv
import os
import signal
import sys
import time

from .film import ALL_FORMATS, read_image, relmse, write_image
from .scene import SceneError


def _resolution(text):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 512x512, got {text!r}")


def _nonneg_int(text):
    v = int(text)
    if v < 0:
        raise argparse.ArgumentTypeError("must be >= 0")
    return v


def _pos_int(text):
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError("must be >= 1")
    return v


def _pos_float(text):
    v = float(text)
    if not v > 0:
        raise argparse.ArgumentTypeError("must be > 0")
    return v


def build_parser():
    p = argparse.ArgumentParser(
        prog="pt-render",
        description="Physically based path tracer (Numba, CPU and CUDA). Renders SCENE "
                    "progressively: the image is rewritten at growing intervals, and Ctrl-C "
                    "stops the render and keeps what is done.")
    p.add_argument("scene", help="scene file (JSON, see docs/scene-format.md), or a thesis "
                   "renderer scene folder")
    p.add_argument("-o", "--output", default=None,
                   help="output image; the extension picks the format: .png (8-bit sRGB, "
                        "with a lossless float .exr beside it), .hdr, .exr or .npy (float linear RGB). "
                        "Default: the scene's name with .png, in the current folder")
    p.add_argument("--spp", type=_pos_int, help="samples per pixel (default: the scene's)")
    p.add_argument("--time", type=_pos_float, metavar="SECONDS",
                   help="render until this much time is spent (with --spp: whichever first)")
    p.add_argument("--backend", choices=("auto", "cpu", "cuda", "python"), default="auto",
                   help="auto: CUDA when a GPU is present, else CPU; python: interpreted "
                        "(slow, for debugging)")
    p.add_argument("--seed", type=_nonneg_int, help="random seed (default: the scene's)")
    p.add_argument("--resolution", type=_resolution, metavar="WxH",
                   help="override the camera resolution")
    p.add_argument("--max-bounces", type=_nonneg_int, help="override render.maxBounces")
    p.add_argument("--reference", metavar="IMAGE",
                   help="reference image (.npy, .hdr, .exr): print elapsed s, spp and relMSE "
                        "after each pass and write them as CSV (see --reference-csv)")
    p.add_argument("--reference-csv", metavar="PATH",
                   help="where the relMSE table goes (default: OUTPUT_STEM.relmse.csv)")
    p.add_argument("--pixel", metavar="X,Y", help="python backend: render only this pixel")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-missing", action="store_true",
                   help="thesis scene folders: render with defaults for missing files "
                        "(objects left out, textures at their default values, a grey "
                        "environment for a missing HDRI), with a warning")
    return p


def _fail(message):
    print(f"pt-render: error: {message}", file=sys.stderr)
    return 2


def main(argv=None):
    args = build_parser().parse_args(argv)
    # Ctrl-C must not be swallowed by a library: restore Python's default handler.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    scene_path = args.scene
    output = args.output or os.path.splitext(os.path.basename(scene_path.rstrip("/")))[0] + ".png"
    ext = os.path.splitext(output)[1].lower()
    if ext not in ALL_FORMATS:
        return _fail(f"--output {output}: unknown image format {ext!r} "
                     f"(use {', '.join(ALL_FORMATS)})")
    out_dir = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(out_dir):
        return _fail(f"--output {output}: folder {out_dir} does not exist")
    float_output = os.path.splitext(output)[0] + ".exr" if ext == ".png" else None

    from .scene import load_scene_description, compile_scene
    t0 = time.perf_counter()
    try:
        desc = load_scene_description(scene_path, allow_missing=args.allow_missing)
        for w in desc.warnings:
            print(f"pt-render: warning: {w}", file=sys.stderr)
        if args.resolution:
            desc.camera.resolution = args.resolution
        scene = compile_scene(desc)
    except SceneError as e:
        return _fail(str(e))
    load_seconds = time.perf_counter() - t0

    reference = None
    if args.reference:
        try:
            reference = read_image(args.reference)
        except (OSError, ValueError) as e:
            return _fail(f"--reference {args.reference}: {e}")
        if reference.shape[:2] != (scene.height, scene.width):
            return _fail(f"--reference {args.reference}: size {reference.shape[1]}x"
                         f"{reference.shape[0]} differs from the image's "
                         f"{scene.width}x{scene.height}")

    pixels = None
    if args.pixel:
        if args.backend != "python":
            return _fail("--pixel needs --backend python")
        try:
            x, y = (int(v) for v in args.pixel.split(","))
        except ValueError:
            return _fail(f"--pixel: expected X,Y, got {args.pixel!r}")
        if not (0 <= x < scene.width and 0 <= y < scene.height):
            return _fail(f"--pixel {x},{y} is outside the {scene.width}x{scene.height} image")
        pixels = [(x, y)]

    from .backends import make_backend
    try:
        backend = make_backend(args.backend, scene, **({"pixels": pixels} if pixels else {}))
    except RuntimeError as e:
        return _fail(str(e))

    spp = args.spp if args.spp is not None else (None if args.time else scene.spp)
    log = sys.stderr
    print(f"pt-render: {scene_path}: {scene.width}x{scene.height}, {scene.n_triangles} "
          f"triangles, loaded in {load_seconds:.2f} s (BVH {scene.timings['bvh_build']:.2f} s); "
          f"backend {backend.name}; features "
          f"{', '.join(k for k, v in scene.features._asdict().items() if v) or 'none'}",
          file=log)

    from .render import render
    from .progress import Progress
    t0 = time.perf_counter()
    if not args.quiet:
        print("pt-render: compiling kernels (cached on disk after the first run)...", file=log)
    backend.compile()
    compile_seconds = time.perf_counter() - t0
    if not args.quiet:
        print(f"pt-render: kernels ready in {compile_seconds:.2f} s", file=log)
    progress = Progress(spp, args.time, scene.width * scene.height, quiet=args.quiet,
                        stream=log)
    rows = []
    next_write = [1.0]

    def save(film):
        image = film.image()
        write_image(output, image)
        if float_output:
            write_image(float_output, image)

    def on_pass(film, elapsed):
        progress.update(film.spp, elapsed)
        if reference is not None:
            err = relmse(film.image(), reference)
            rows.append((elapsed, film.spp, err))
            progress.write(f"{elapsed:10.3f} s {film.spp:8d} spp  relMSE {err:.6g}")
        if elapsed >= next_write[0]:
            save(film)
            next_write[0] = elapsed * 2   # refresh at growing intervals

    if reference is not None:
        progress.write(f"{'elapsed':>12} {'spp':>12}  relMSE")
    result = render(scene, backend, spp=spp, time_limit=args.time, seed=args.seed,
                    max_bounces=args.max_bounces, on_pass=on_pass,
                    pass_seconds=0.25 if backend.name == "cuda" else 0.5)
    progress.close()
    film = result.film
    if film.spp == 0:
        print("pt-render: stopped before the first pass; no image written", file=log)
        return 130 if result.interrupted else 1
    save(film)
    if reference is not None:
        csv_path = args.reference_csv or os.path.splitext(output)[0] + ".relmse.csv"
        with open(csv_path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["elapsed_s", "spp", "relmse"])
            w.writerows(rows)
        print(f"pt-render: relMSE table written to {csv_path}", file=log)
    paths = film.camera_rays / result.seconds if result.seconds > 0 else float("nan")
    rays = (film.camera_rays + film.bounce_rays + film.shadow_rays)
    print(f"pt-render: {film.spp} spp in {result.seconds:.2f} s (compile "
          f"{compile_seconds:.2f} s): {paths / 1e6:.3f} M camera paths/s, "
          f"{rays / max(result.seconds, 1e-9) / 1e6:.3f} M rays/s; wrote {output}"
          + (f" and {float_output}" if float_output else ""), file=log)
    if film.nonfinite:
        print(f"pt-render: WARNING: {film.nonfinite} samples were NaN or infinite "
              "(kept in the image; please report this scene)", file=log)
    if result.interrupted:
        print("pt-render: interrupted; the image holds the samples done so far", file=log)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
