"""A/B comparison of two source trees of pt-render on the same machine, in one run.

Used before and after a change of the kernels (a refactor must not cost speed nor change a
bit of the image): each tree's ``pathtracer`` is imported in its own worker process, so both
are measured by the same benchmark code on the same scene descriptions (this tree's
``bench.scenes``).

    python -m bench.ab throughput --trees OLD NEW [--backend cpu|cuda] [--scenes ...]
    python -m bench.ab throughput --trees OLD NEW --paired 40 [--scenes ...]
    python -m bench.ab images --trees OLD NEW [--spp 4] [--resolution 96x72]

``throughput``: camera paths/s per scene, the median of ``--repeats`` passes after a warm-up
pass, compile excluded; trees alternate for ``--rounds`` rounds (drift on a shared machine
hits both) and each tree's figure is the median over its rounds. ``--paired N`` instead
keeps one worker per tree alive and alternates them, N pairs (A B, B A, ...; never both at
once; each turn an untimed pass, then the timed one): the two timed passes of a pair are
seconds apart, so the ratio of their times hardly sees the machine's drift, which moves
whole rounds by 10-35 % on the 2-core CPU. It reports the median of the N per-pair ratios
with a bootstrap 95 % interval: a tree against itself gave intervals of +-3-4 % there with
40 pairs (rounds of separate processes: +-5-10 %), and a few tenths of a per cent on an
H200 (docs/benchmarks.md, 2026-11-28). But a worker process carries a speed of its own:
the same tree against itself, 200 pairs on the 2-core CPU, measured bunny-studio 0.955
(95 % 0.947-0.965) in one pair of workers (2026-11-29): the same compiled code runs a few
per cent faster or slower from process to process (in one process, four loaded copies
of one kernel ran 1.000-1.066 in one run, 0.979-1.002 in another), so a narrow interval
of one pair of workers does not cover that bias. ``--blocks K`` runs K pairs of fresh
workers (N pairs each, the trees' start order swapped from block to block) and reports
the median of the blocks' ratios with an interval over blocks: use it for effects of a
few per cent on the CPU.
``images``: every scene of ``scenes/`` and of the error-against-time study rendered on the
CPU with each tree; the float32 pixel sums are compared bit for bit.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

# scene -> (resolution, spp per pass) for throughput, per backend
THROUGHPUT = {
    "cpu": {"cornell-box": ((256, 256), 4), "bunny-studio": ((256, 192), 4),
            "sun": ((256, 192), 4), "textured": ((256, 192), 4),
            "bunny-mesh": ((128, 128), 4), "dragon-1.6m": ((128, 128), 4)},
    "cuda": {"cornell-box": ((1024, 1024), 64), "bunny-studio": ((1024, 768), 16),
             "sun": ((1024, 768), 16), "textured": ((1024, 768), 16),
             "bunny-mesh": ((1024, 1024), 16), "dragon-1.6m": ((1024, 1024), 16)},
}
DEFAULT_SCENES = ("cornell-box", "bunny-studio", "sun", "textured")


def _describe(name, resolution):
    """A SceneDescription: a study scene of bench.scenes, the scaling scene around the
    Stanford bunny (69k triangles, "bunny-mesh") or the dragon subdivided to 1.6M
    triangles ("dragon-1.6m", made by shared/tools/make_big_mesh.py), or a file of
    scenes/."""
    from bench.scenes import CONVERGENCE, describe, mesh_desc
    if name in ("bunny-mesh", "dragon-1.6m"):
        from bench.common import SHARED
        from bench.scaling import big_mesh
        obj = (os.path.join(SHARED, "assets", "models", "stanford_bunny.obj")
               if name == "bunny-mesh" else big_mesh(2))
        return mesh_desc(obj, resolution)
    if name in CONVERGENCE:
        source, _ = CONVERGENCE[name]
        if callable(source):
            desc = describe(source(resolution))
        else:
            from pathtracer.scene import load_scene_description
            desc = load_scene_description(source)
    else:
        from pathtracer.scene import load_scene_description
        desc = load_scene_description(os.path.join(ROOT, "scenes", name + ".json"))
    desc.camera.resolution = tuple(resolution)
    return desc


def ptx_instructions(ptx):
    """The number of instructions in PTX text (the kernel's size: the HDRI scenes' warps
    wait on instruction fetch, docs/benchmarks.md)."""
    n = 0
    for line in ptx.splitlines():
        t = line.strip()
        if t and (t[0].isalpha() or t[0] == "@"):   # (labels end in ":", directives start with ".")
            n += 1
    return n


def worker(args):
    """Runs with the tree under test first on sys.path (bench.* is imported before it)."""
    import bench.scenes  # noqa: F401  (this tree's scene descriptions, imported first)
    sys.path.insert(0, os.path.abspath(args.tree))
    import pathtracer
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    assert os.path.abspath(pathtracer.__file__).startswith(os.path.abspath(args.tree))
    res = tuple(int(x) for x in args.resolution.split("x"))
    scene = compile_scene(_describe(args.scene, res))
    options = json.loads(args.options) if args.options else {}
    if options:
        import inspect
        from pathtracer.backends import cuda as cuda_backend
        known = inspect.signature(cuda_backend.CUDABackend).parameters
        options = {k: v for k, v in options.items() if k in known}   # older trees lack some
    backend = make_backend(args.backend, scene, **options)
    t0 = time.perf_counter()
    backend.compile()
    compile_s = time.perf_counter() - t0
    mb, rr = scene.max_bounces, scene.rr_depth
    out = {"tree": args.tree, "scene": args.scene, "backend": args.backend,
           "resolution": res, "spp": args.spp, "compile_s": compile_s}
    if args.backend == "cuda" and args.mode == "time":
        out.update(ptx_instructions=ptx_instructions(backend.ptx()),
                   registers=backend.registers())
    if args.mode == "image":
        img, _ = backend.render_pass(0, args.spp, 7, mb, rr)
        np.save(args.save, np.array(img, np.float32))
        print(json.dumps(out))
        return
    start = [0]

    def one_pass():
        if args.backend == "cuda":
            from numba import cuda
            backend.launch(start[0], args.spp, 0, mb, rr)
            cuda.synchronize()
        else:
            backend.render_pass(start[0], args.spp, 0, mb, rr)
        start[0] += args.spp

    one_pass()
    if args.mode == "serve":
        # per line read ("pass"): an untimed pass, then a timed one, whose time is printed
        # back; end of input: done. (The first pass after the other tree's turn runs with
        # cold caches and sleeping threads: 2x slower at small sizes on the 2-core CPU.)
        print(json.dumps(out), flush=True)
        for line in sys.stdin:
            if line.strip() != "pass":
                break
            one_pass()
            t = time.perf_counter()
            one_pass()
            print(json.dumps({"pass_s": time.perf_counter() - t}), flush=True)
        return
    times = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        one_pass()
        times.append(time.perf_counter() - t)
    t = statistics.median(times)
    out.update(pass_s=times, paths_per_s=res[0] * res[1] * args.spp / t)
    print(json.dumps(out))


def _worker_cmd(tree, scene, backend, resolution, spp, mode, repeats=0, save=None,
                options=None):
    """The command line of one worker (``_worker``) for ``tree``."""
    cmd = [sys.executable, "-m", "bench.ab", "_worker", "--tree", tree, "--scene", scene,
           "--backend", backend, "--resolution", "%dx%d" % tuple(resolution), "--spp",
           str(spp), "--mode", mode, "--repeats", str(repeats)]
    if options:
        cmd += ["--options", options]
    if save:
        cmd += ["--save", save]
    return cmd


def _run_worker(tree, scene, backend, resolution, spp, mode, repeats=0, save=None,
                options=None):
    cmd = _worker_cmd(tree, scene, backend, resolution, spp, mode, repeats, save, options)
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        raise SystemExit(f"bench.ab: worker failed: {' '.join(cmd)}")
    return json.loads(p.stdout.strip().splitlines()[-1])


class _Server:
    """A worker in ``serve`` mode: compiled and warmed up, then one pass per request."""

    def __init__(self, tree, scene, backend, resolution, spp, options=None):
        cmd = _worker_cmd(tree, scene, backend, resolution, spp, "serve", options=options)
        self.cmd = cmd
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, bufsize=1)
        self.info = self._reply()

    def _reply(self):
        for line in self.proc.stdout:
            line = line.strip()
            if line.startswith("{"):
                return json.loads(line)
        raise SystemExit(f"bench.ab: worker ended early: {' '.join(self.cmd)}")

    def time_pass(self):
        self.proc.stdin.write("pass\n")
        return self._reply()["pass_s"]

    def close(self):
        try:
            self.proc.stdin.close()
        except OSError:             # (a worker that died: nothing to tell it)
            pass
        self.proc.wait()


def bootstrap_median_interval(values, n=4000, seed=0):
    """The 2.5 and 97.5 percentiles of the median of ``values`` resampled with replacement."""
    v = np.asarray(values, float)
    meds = np.median(np.random.default_rng(seed).choice(v, (n, len(v))), axis=1)
    return float(np.percentile(meds, 2.5)), float(np.percentile(meds, 97.5))


def paired(args, name, res, spp, record):
    """``throughput --paired``: the two trees' passes alternate in live workers; with
    ``--blocks K``, K such runs of fresh workers, the trees' order swapped from block to
    block (see the module's docstring)."""
    blocks = max(args.blocks, 1)
    times = [[], []]
    block_ratios = []
    ratios = []
    for blk in range(blocks):
        order = (0, 1) if blk % 2 == 0 else (1, 0)      # which tree's worker starts first
        servers = {}
        try:
            for i in order:
                servers[i] = _Server(args.trees[i], name, args.backend, res, spp, args.options)
            got = [[], []]
            for k in range(args.paired):
                for i in (order if k % 2 == 0 else order[::-1]):
                    got[i].append(servers[i].time_pass())
        finally:
            for srv in servers.values():
                srv.close()
        for i in (0, 1):
            times[i] += got[i]
            record["results"].append(dict(servers[i].info, pass_s=got[i], block=blk,
                                          paths_per_s=res[0] * res[1] * spp /
                                          statistics.median(got[i])))
        r = [a / b for a, b in zip(*got)]           # B's paths/s over A's, pair by pair
        ratios += r
        block_ratios.append(statistics.median(r))
    paths = res[0] * res[1] * spp
    labels = args.trees if args.trees[0] != args.trees[1] else [
        f"{t} ({k + 1})" for k, t in enumerate(args.trees)]
    per_tree = {t: paths / statistics.median(ts) for t, ts in zip(labels, times)}
    if blocks > 1:
        # (each block's workers carry their own bias: the interval is over blocks)
        ratio = statistics.median(block_ratios)
        lo, hi = bootstrap_median_interval(block_ratios)
        how = (f"{blocks} blocks of {args.paired} pairs; blocks " +
               " ".join(f"{x:.3f}" for x in block_ratios))
    else:
        ratio = statistics.median(ratios)
        lo, hi = bootstrap_median_interval(ratios)
        how = f"{args.paired} pairs"
    print(f"{name:14s} {args.backend:5s} " + "  ".join(
        f"{t}: {per_tree[t] / 1e6:8.3f} M paths/s" for t in labels) +
        f"   ratio {ratio:.3f} (95 % {lo:.3f}-{hi:.3f}, {how})", flush=True)
    record.setdefault("summary", {})[name] = {
        "paths_per_s": per_tree, "ratio": ratio, "ratio_interval_95": [lo, hi],
        "pairs": args.paired, "blocks": blocks, "block_ratios": block_ratios,
        "pair_ratios": ratios}


def throughput(args):
    from bench.common import command, machine, now, versions
    table = THROUGHPUT[args.backend]
    scenes = args.scenes or [s for s in DEFAULT_SCENES if s in table]
    record = {"command": command(), "machine": machine(), "date": now(),
              "versions": versions(), "backend": args.backend, "trees": args.trees,
              "results": []}
    for name in scenes:
        res, spp = table[name]
        res = args.resolution or res
        spp = args.spp or spp
        if args.paired:
            paired(args, name, res, spp, record)
            continue
        per_tree = {t: [] for t in args.trees}
        for r in range(args.rounds):
            order = args.trees if r % 2 == 0 else args.trees[::-1]
            for tree in order:
                got = _run_worker(tree, name, args.backend, res, spp, "time", args.repeats,
                                  options=args.options)
                per_tree[tree].append(got["paths_per_s"])
                record["results"].append(got)
        medians = {t: statistics.median(v) for t, v in per_tree.items()}
        a, b = (medians[t] for t in args.trees)
        size = {r["tree"]: r["ptx_instructions"] for r in record["results"]
                if r["scene"] == name and "ptx_instructions" in r}
        print(f"{name:14s} {args.backend:5s} " + "  ".join(
            f"{t}: {medians[t] / 1e6:8.3f} M paths/s" +
            (f" ({size[t]} PTX instructions)" if t in size else "") for t in args.trees) +
            f"   ratio {b / a:.3f}", flush=True)
        record.setdefault("summary", {})[name] = {"paths_per_s": medians, "ratio": b / a}
        if size:
            record["summary"][name]["ptx_instructions"] = size
    if args.json:
        with open(args.json, "w") as f:
            json.dump(record, f, indent=1)


def images(args):
    names = sorted(os.path.splitext(os.path.basename(p))[0]
                   for p in glob.glob(os.path.join(ROOT, "scenes", "*.json")))
    names += ["bunny-studio", "sun"]
    names = args.scenes or names
    res = args.resolution
    out = args.out
    os.makedirs(out, exist_ok=True)
    failures = 0
    for name in names:
        imgs = []
        for k, tree in enumerate(args.trees):
            path = os.path.join(out, f"{name}-{k}.npy")
            if not (k == 0 and args.reuse and os.path.exists(path)):
                _run_worker(tree, name, "cpu", res, args.spp, "image", save=path)
            imgs.append(np.load(path))
        a, b = imgs
        same = a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))
        diff = float(np.max(np.abs(a - b))) if a.shape == b.shape else float("nan")
        failures += not same
        print(f"{name:18s} {'bit-identical' if same else 'DIFFERENT'}  max |diff| {diff:.3g}"
              f"  mean {float(a.mean()):.6g}", flush=True)
    if failures:
        raise SystemExit(f"bench.ab: {failures} scene(s) differ")


def _size(text):
    """``WxH`` as (W, H)."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT (e.g. 96x72)")
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must be positive")
    return w, h


def _tree(text):
    """A source tree to measure: a folder (a commit is checked out into one first)."""
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a folder: give a source tree, e.g. a revision's from "
            f"`mkdir DIR && git archive REV pathtracer scenes cli.py | tar -x -C DIR`")
    return text


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.ab", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("throughput")
    t.add_argument("--trees", nargs=2, required=True, type=_tree)
    t.add_argument("--backend", choices=("cpu", "cuda"), default="cpu")
    t.add_argument("--scenes", nargs="*")
    t.add_argument("--repeats", type=int, default=5)
    t.add_argument("--rounds", type=int, default=2)
    t.add_argument("--paired", type=int, default=0, metavar="N",
                   help="N pairs of passes from two live workers, alternating (instead of "
                        "--rounds and --repeats): the per-pair ratio's median and interval")
    t.add_argument("--blocks", type=int, default=1, metavar="K",
                   help="with --paired: K runs of fresh workers (the trees' order swapped "
                        "each block); the ratio is the median of the blocks' medians, its "
                        "interval over blocks")
    t.add_argument("--resolution", type=_size, help="WxH instead of the scene's benchmark "
                   "size")
    t.add_argument("--spp", type=int, help="samples per pixel per pass (default: the "
                   "scene's)")
    t.add_argument("--json")
    t.add_argument("--options", help='backend options of the trees that take them, as JSON '
                   '(e.g. \'{"target_threads": 1}\')')
    i = sub.add_parser("images")
    i.add_argument("--trees", nargs=2, required=True, type=_tree)
    i.add_argument("--scenes", nargs="*")
    i.add_argument("--spp", type=int, default=4)
    i.add_argument("--resolution", type=_size, default="96x72")
    i.add_argument("--out", default=os.path.join(ROOT, "bench", "out", "ab-images"))
    i.add_argument("--reuse", action="store_true",
                   help="reuse the first tree's images saved by an earlier run in --out")
    w = sub.add_parser("_worker")
    for k in ("--tree", "--scene", "--backend", "--resolution", "--mode", "--save"):
        w.add_argument(k)
    w.add_argument("--spp", type=int)
    w.add_argument("--repeats", type=int, default=5)
    w.add_argument("--options")
    args = p.parse_args(argv)
    if args.cmd == "throughput" and args.blocks > 1 and not args.paired:
        t.error("--blocks applies to --paired")
    {"throughput": throughput, "images": images, "_worker": worker}[args.cmd](args)


if __name__ == "__main__":
    main()
