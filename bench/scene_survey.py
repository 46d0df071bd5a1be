"""Which scene files of a folder load: pt-render's reader against Mitsuba 3's.

    python -m bench.scene_survey DIR [DIR ...] [--mitsuba] [--json OUT.json]

Every ``*.xml`` under the folders whose root element is a Mitsuba ``<scene>`` (files that
an ``<include>`` pulls in are scenes too, and are counted as Mitsuba counts them: whatever
it loads) is loaded by ``pathtracer.load_scene`` (read, validated and compiled: meshes,
textures, BVH; no rendering) and, with ``--mitsuba``, by ``mitsuba.load_file`` (scalar RGB
variant). The report: per file pt-render's result (``ok`` or the error's first line) and
Mitsuba's; the totals; and the errors grouped by their message (what blocks most files
first). This is the measure of issue 61 ("at least 120 of the 130 files that Mitsuba 3.9.1
loads must load").
"""
import argparse
import collections
import os
import re
import sys
import time
import warnings
import xml.etree.ElementTree as ET

from .common import write_record


def scene_files(folders):
    """Mitsuba scene files under ``folders``, sorted."""
    out = []
    for top in folders:
        for d, _, names in os.walk(top):
            for n in names:
                if not n.endswith(".xml"):
                    continue
                path = os.path.join(d, n)
                try:
                    root = ET.parse(path).getroot()
                except (ET.ParseError, OSError):
                    continue
                if root.tag == "scene":
                    out.append(path)
    return sorted(out)


def load_ours(path):
    """'ok' or the one-line reason pt-render does not load ``path``."""
    import pathtracer as pt
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            pt.load_scene(path)
        return "ok"
    except pt.SceneError as e:
        return " ".join(str(e).split())
    except Exception as e:          # a bug: reported as such, the survey goes on
        return f"BUG {type(e).__name__}: {' '.join(str(e).split())[:200]}"


def load_mitsuba(path):
    import mitsuba as mi
    try:
        mi.load_file(path)
        return "ok"
    except Exception as e:
        return " ".join(str(e).split())[:200]


def blocker(reason):
    """An error's message without its file and element path, for grouping."""
    msg = reason.split(": ", 1)[-1] if reason.startswith("/") else reason
    msg = re.sub(r"^.*?\.xml: ", "", msg)
    msg = re.sub(r"^/scene\S*( \([^)]*\))?: ", "", msg)
    return re.sub(r"'[^']*'|\"[^\"]*\"|\d+(\.\d+)?", "…", msg)[:120]


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.scene_survey", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", nargs="+")
    ap.add_argument("--mitsuba", action="store_true", help="also load each file with Mitsuba 3")
    ap.add_argument("--json", help="write the per-file results here")
    args = ap.parse_args(argv)
    for f in args.folders:
        if not os.path.isdir(f):
            ap.error(f"{f}: not a folder")
    if args.mitsuba:
        try:
            import mitsuba as mi
        except ImportError:
            ap.error("--mitsuba needs Mitsuba 3 (pip install -e .[bench])")
        mi.set_variant("scalar_rgb")
    files = scene_files(args.folders)
    rows = []
    t0 = time.perf_counter()
    for i, path in enumerate(files):
        ours = load_ours(path)
        theirs = load_mitsuba(path) if args.mitsuba else None
        rows.append({"file": path, "ours": ours, "mitsuba": theirs})
        rel = os.path.relpath(path)
        print(f"[{i + 1}/{len(files)}] {rel}: {ours}"
              + (f"  | mitsuba: {theirs}" if theirs is not None else ""), flush=True)
    ok = sum(r["ours"] == "ok" for r in rows)
    print(f"\n{len(files)} scene files, {time.perf_counter() - t0:.0f} s: pt-render loads {ok}")
    if args.mitsuba:
        mi_ok = [r for r in rows if r["mitsuba"] == "ok"]
        both = sum(r["ours"] == "ok" for r in mi_ok)
        print(f"Mitsuba loads {len(mi_ok)}; pt-render loads {both} of those")
    groups = collections.Counter(blocker(r["ours"]) for r in rows if r["ours"] != "ok"
                                 and (not args.mitsuba or r["mitsuba"] == "ok"))
    print("\nwhat stops pt-render" + (" (files Mitsuba loads)" if args.mitsuba else "") + ":")
    for msg, n in groups.most_common():
        print(f"{n:4d}  {msg}")
    if args.json:
        write_record(args.json, files=rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
