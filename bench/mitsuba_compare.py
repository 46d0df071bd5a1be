"""The same Mitsuba 3 scene files through Mitsuba 3 and pt-render: do the images agree?

    python -m bench.mitsuba_compare FILE_OR_DIR [...] [--size 64] [--spp 256]
        [--mi-spp 1024] [--json OUT.json] [--save DIR]

Each scene file (a folder: every Mitsuba scene file below it that both renderers load) is
rendered at a small size (its film's width scaled to ``--size`` pixels, the aspect kept;
written to a temporary copy beside the file, so relative paths still resolve) by Mitsuba 3
(``llvm_ad_rgb``, ``--mi-spp`` samples, the reference) and by pt-render on the CPU
(``--spp`` samples). (A film declared in an ``<include>``d file keeps its own size: the
material-preview scenes of Mitsuba's documentation render at 960 x 720.) Reported per file: the channel means of both and their ratio, the relMSE
of ours against Mitsuba's and the reference's own noise (relMSE of two independent Mitsuba
renders of half its samples each, halved: an estimate of the reference's error), and
pt-render's warnings. A file agrees when every channel mean is within 1 % (or within 3
standard errors of the difference of the two means) and relMSE is within the noise of
both renders (see ``agrees``).
"""
import argparse
import os
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET

import numpy as np

from .common import write_record
from .scene_survey import scene_files


def resized_copy(path, size):
    """A copy of the scene file beside it with its film ``size`` pixels wide (the aspect
    kept) and the box filter Mitsuba's comparison needs (ours is a box filter); returns its
    path and the film size."""
    tree = ET.parse(path)
    root = tree.getroot()
    films = [f for s in root.iter("sensor") for f in s.iter("film")]
    if not films:             # a file without a sensor: both use their default camera
        films = []
    width, height = 768, 576
    for film in films:
        for el in film:
            if el.tag == "integer" and el.get("name") == "width":
                width = int(el.get("value")) if el.get("value", "").isdigit() else width
            if el.tag == "integer" and el.get("name") == "height":
                height = int(el.get("value")) if el.get("value", "").isdigit() else height
    new_w = size
    new_h = max(1, round(size * height / width))
    for film in films:
        for el in list(film):
            if el.tag == "integer" and el.get("name") in ("width", "height"):
                film.remove(el)
            if el.tag == "rfilter":
                film.remove(el)
        ET.SubElement(film, "integer", name="width", value=str(new_w))
        ET.SubElement(film, "integer", name="height", value=str(new_h))
        ET.SubElement(film, "rfilter", type="box")
    fd, out = tempfile.mkstemp(suffix=".xml", prefix=".cmp-", dir=os.path.dirname(path))
    os.close(fd)
    tree.write(out)
    return out, (new_w, new_h)


def render_mitsuba(path, spp, seed=0):
    """Mitsuba's image; a file without an integrator gets the path tracer pt-render uses
    for it (max_depth 9: its default of 8 bounces)."""
    import mitsuba as mi
    scene = mi.load_file(path)
    integrator = None
    if scene.integrator() is None:
        integrator = mi.load_dict({"type": "path", "max_depth": 9})
    return np.array(mi.render(scene, integrator=integrator, spp=spp, seed=seed),
                    np.float64)[..., :3]


def render_ours(path, spp):
    import pathtracer as pt
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = pt.load_scene(path)
        r = pt.render(scene, spp=spp, backend="cpu")
    return (np.asarray(r.image, np.float64), list(scene.warnings) +
            [str(w.message) for w in caught], r.seconds)


def relmse(img, ref, eps=1e-2):
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + eps)))


def agrees(row):
    """Channel means within 1 % (or within 3 standard errors), relMSE within 3x the noise
    both renders are expected to have (ours at its spp: Mitsuba's noise scaled by the
    ratio of sample counts, a rough model for two unbiased path tracers)."""
    means_ok = all(abs(o - m) <= max(0.01 * abs(m), 3 * se, 1e-4) for o, m, se in zip(
        row["ours_mean"], row["mitsuba_mean"], row["mean_se"]))
    noise = row["ref_noise"] * (1 + row["mi_spp"] / row["spp"])
    return means_ok and row["relmse"] <= 3 * noise + 1e-4


def compare(path, size, spp, mi_spp):
    copy, (w, h) = resized_copy(path, size)
    try:
        a = render_mitsuba(copy, mi_spp // 2, seed=1)
        b = render_mitsuba(copy, mi_spp // 2, seed=2)
        ref = (a + b) / 2
        ours, warns, seconds = render_ours(copy, spp)
    finally:
        os.unlink(copy)
    # per-pixel differences of the two half references: the reference's noise
    ref_noise = relmse(a, b) / 4
    diff = (ours - ref).reshape(-1, 3)
    row = {"file": path, "size": [w, h], "spp": spp, "mi_spp": mi_spp,
           "ours_mean": ours.reshape(-1, 3).mean(0).tolist(),
           "mitsuba_mean": ref.reshape(-1, 3).mean(0).tolist(),
           "mean_se": (diff.std(0, ddof=1) / np.sqrt(len(diff))).tolist(),
           "relmse": relmse(ours, ref), "ref_noise": ref_noise, "seconds": seconds,
           "warnings": warns}
    row["agrees"] = agrees(row)
    return row, ours, ref


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.mitsuba_compare", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="+")
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--mi-spp", type=int, default=1024)
    ap.add_argument("--json")
    ap.add_argument("--save", help="write ours and Mitsuba's images (.npy) here")
    args = ap.parse_args(argv)
    if args.size < 4 or args.spp < 1 or args.mi_spp < 2:
        ap.error("--size >= 4, --spp >= 1, --mi-spp >= 2")
    try:
        import mitsuba as mi
    except ImportError:
        ap.error("needs Mitsuba 3 (pip install -e .[bench])")
    mi.set_variant("llvm_ad_rgb")
    import pathtracer as pt
    files = []
    for p in args.paths:
        files += scene_files([p]) if os.path.isdir(p) else [p]
    rows = []
    for i, path in enumerate(files):
        try:
            row, ours, ref = compare(path, args.size, args.spp, args.mi_spp)
        except pt.SceneError as e:
            print(f"[{i + 1}/{len(files)}] {path}: not loaded by pt-render: "
                  f"{' '.join(str(e).split())[:160]}", flush=True)
            continue
        except Exception as e:
            print(f"[{i + 1}/{len(files)}] {path}: {type(e).__name__}: "
                  f"{' '.join(str(e).split())[:160]}", flush=True)
            continue
        rows.append(row)
        if args.save:
            os.makedirs(args.save, exist_ok=True)
            stem = os.path.splitext(os.path.basename(path))[0]
            np.save(os.path.join(args.save, stem + "-ours.npy"), ours.astype(np.float32))
            np.save(os.path.join(args.save, stem + "-mitsuba.npy"), ref.astype(np.float32))
        ratio = [o / m if m else float("nan") for o, m in zip(row["ours_mean"],
                                                               row["mitsuba_mean"])]
        print(f"[{i + 1}/{len(files)}] {path}: {'agrees' if row['agrees'] else 'DIFFERS'}"
              f"  means ours/mitsuba {', '.join(f'{x:.4f}' for x in ratio)}  relMSE "
              f"{row['relmse']:.2e} (reference noise {row['ref_noise']:.1e})", flush=True)
    n_ok = sum(r["agrees"] for r in rows)
    print(f"\n{len(rows)} files rendered by both; {n_ok} agree")
    if args.json:
        write_record(args.json, files=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
