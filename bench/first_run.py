"""A new user's first run (issue: the first run): the whole ``pt-render`` command on a
scene with an empty kernel cache (every kernel and the host code compiled), then the same
command again (the cache filled), for one or two source trees, runs alternating so that the
trees see the same machine load.

    python -m bench.first_run [--trees OLD NEW] [--scenes cornell-box textured]
                              [--rounds 2] [--json OUT]

Each run is a fresh process (``python -m pathtracer SCENE --resolution 64x48 --spp 1
--backend cpu``) with ``PYTHONPATH`` the tree and ``PT_RENDER_CACHE`` a new folder; reported:
the wall time of the whole command, the scene's load time and the kernels' compile time as
the command prints them, and the process's peak resident memory.
"""
import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from bench.common import ROOT, write_record


def run_once(tree, scene, cache):
    """One command in a fresh process: {wall_s, load_s, compile_s, peak_mb}."""
    cmd = [sys.executable, "-m", "pathtracer", os.path.join("scenes", scene + ".json"),
           "--resolution", "64x48", "--spp", "1", "--backend", "cpu", "-o",
           os.path.join(cache, "out.png")]
    env = dict(os.environ, PYTHONPATH=tree, PT_RENDER_CACHE=cache)
    env.pop("NUMBA_CACHE_DIR", None)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)       # (the child's own peak memory)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"bench.first_run: {tree} {scene} failed:\n{out[-2000:]}")
    load = re.search(r"loaded in ([\d.]+) s", out)
    ready = re.search(r"kernels ready in ([\d.]+) s", out)
    return {"wall_s": round(wall, 2), "load_s": float(load.group(1)) if load else None,
            "compile_s": float(ready.group(1)) if ready else 0.0,
            "peak_mb": round(usage.ru_maxrss / 1024)}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trees", nargs="+", default=[ROOT])
    p.add_argument("--scenes", nargs="+", default=["cornell-box", "textured"])
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--json", help="write the record here")
    a = p.parse_args(argv)
    trees = [os.path.abspath(t) for t in a.trees]
    rows = []
    for r in range(a.rounds):
        for scene in a.scenes:
            for tree in trees:
                cache = tempfile.mkdtemp(prefix="pt-first-run-")
                try:
                    cold = run_once(tree, scene, cache)
                    warm = run_once(tree, scene, cache)
                finally:
                    shutil.rmtree(cache, ignore_errors=True)
                rows.append({"round": r, "scene": scene, "tree": tree, "cold": cold,
                             "warm": warm})
                print(f"round {r} {scene:12s} {os.path.basename(tree):14s} cold: "
                      f"{cold['wall_s']:6.1f} s (load {cold['load_s']} s, kernels "
                      f"{cold['compile_s']} s, {cold['peak_mb']} MB)  warm: "
                      f"{warm['wall_s']:5.2f} s", flush=True)
    for scene in a.scenes:
        for tree in trees:
            mine = [x for x in rows if x["scene"] == scene and x["tree"] == tree]
            print(f"{scene:12s} {os.path.basename(tree):14s} median cold "
                  f"{statistics.median(x['cold']['wall_s'] for x in mine):.1f} s, kernels "
                  f"{statistics.median(x['cold']['compile_s'] for x in mine):.1f} s, warm "
                  f"{statistics.median(x['warm']['wall_s'] for x in mine):.2f} s")
    if a.json:
        write_record(a.json, trees=trees, rows=rows)


if __name__ == "__main__":
    main()
