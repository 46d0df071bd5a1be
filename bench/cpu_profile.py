"""Where the CPU render kernel spends its time, per compiled function (Linux ``perf``):

    python -m bench.cpu_profile bunny-studio --seconds 20 --json out.json

Runs itself under ``perf record`` (1999 samples/s per thread): the child compiles the scene's
CPU kernel, writes the address and size of every function Numba compiled for it (from each
library's object code and ``nm``), then renders passes of ``--spp`` for ``--seconds``. The
parent attributes each sampled instruction address to the function that holds it. Shares are
of the samples inside the kernel's own code (compilation, Python and the thread pool are
counted apart as "outside"; of the samples taken while it renders, those outside the
kernel's code are listed by library: libm, Numba's helpers, the thread pool). Functions
that Numba/LLVM inlined are counted in their caller:
the table shows what remains a call (on the CPU everything is inlined into the pass's
loop, the parfor's gufunc, since 2026-11-28: use ``--calls``).
The child compiles into a fresh kernel cache (a kernel loaded from the disk cache keeps no
object code to read the symbols from). ``--calls direct_light,sample_world`` keeps those
steps (or other device functions) as calls (they are inlined on the CPU), so that their
shares show apart.
``--annotate FUNCTION`` also prints that function's
machine code (objdump) with each instruction's share. Needs ``perf``, ``nm`` and
``objdump`` (binutils); no hardware counters are needed (a VM works).
"""
import argparse
import bisect
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
import time

from bench.scenes import CONVERGENCE, convergence_desc


def _libraries(dispatcher):
    seen = []

    def walk(lib):
        if lib not in seen:
            seen.append(lib)
            for other in getattr(lib, "_linking_libraries", ()):
                walk(other)
    for cres in dispatcher.overloads.values():
        walk(cres.library)
    return seen


def child(args):
    """Compile, write the symbol table, render for args.seconds."""
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    scene = compile_scene(convergence_desc(args.scene))
    backend = make_backend("cpu", scene)
    backend.compile()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, lib in enumerate(_libraries(backend.kernel)):
            try:
                data = lib.serialize_using_object_code()
            except Exception:                 # e.g. helper libraries without object code
                continue
            obj = data[2][0] if isinstance(data[2], tuple) else data[2]
            path = os.path.join(tmp, f"{k}.o")
            with open(path, "wb") as f:
                f.write(obj)
            nm = subprocess.run(["nm", "-S", "--defined-only", path], capture_output=True,
                                text=True).stdout
            for line in nm.splitlines():
                parts = line.split()
                # (t, T: local and global code; w, W: weak, the linkonce_odr copies of
                # device functions that the kernel's own module holds, kernels.device)
                if len(parts) == 4 and parts[2] in "tTwW":
                    try:
                        addr = lib.get_pointer_to_function(parts[3])
                    except Exception:
                        continue
                    if addr:
                        rows.append((addr, int(parts[1], 16), parts[3]))
    if args.code:
        # the machine code itself, for --annotate (read from the process's own memory)
        import ctypes
        with open(args.code, "w") as f:
            json.dump({str(a): ctypes.string_at(a, n).hex() for a, n, _ in rows}, f)
    with open(args.syms, "w") as f:
        json.dump(rows, f)
    backend.render_pass(0, 1, 0, scene.max_bounces, scene.rr_depth)
    # (perf records with -k mono: its sample times are this clock's)
    render_start = time.clock_gettime(time.CLOCK_MONOTONIC)
    t0 = time.perf_counter()
    passes = 0
    while time.perf_counter() - t0 < args.seconds:
        backend.render_pass(0, args.spp, 0, scene.max_bounces, scene.rr_depth)
        passes += 1
    elapsed = time.perf_counter() - t0
    paths = passes * args.spp * scene.width * scene.height
    print(json.dumps({"passes": passes, "seconds": elapsed,
                      "m_paths_per_s": paths / elapsed / 1e6, "render_start": render_start,
                      "render_end": time.clock_gettime(time.CLOCK_MONOTONIC)}))


def short_name(symbol):
    """'principled.principled_eval' from a Numba-mangled symbol (Itanium: length-prefixed
    names after _ZN, up to Numba's 'B' + ABI tag)."""
    words, i = [], symbol.find("_ZN") + 3
    if i < 3:
        return symbol[:60]
    while i < len(symbol) and symbol[i].isdigit():
        j = i
        while symbol[j].isdigit():
            j += 1
        n = int(symbol[i:j])
        words.append(symbol[j:j + n])
        i = j + n
    words = [w for w in words if w not in ("pathtracer", "kernels", "_3clocals_3e", "cpython")
             and not w.startswith("make_")]
    return ".".join(words[-2:]) if words else symbol[:60]


def profile(args):
    with tempfile.TemporaryDirectory() as tmp:
        data, syms = os.path.join(tmp, "perf.data"), os.path.join(tmp, "syms.json")
        code = os.path.join(tmp, "code.json")
        cmd = ["perf", "record", "-q", "-k", "mono", "-F", "1999", "-o", data,
               sys.executable, "-m",
               "bench.cpu_profile", args.scene, "--child", "--syms", syms, "--seconds",
               str(args.seconds), "--spp", str(args.spp)] + (
                   ["--code", code] if args.annotate else [])
        # a fresh kernel cache: a kernel loaded from the disk cache keeps no object code to
        # read its symbols from, so the child compiles (untimed: rendering starts after)
        env = dict(os.environ, PT_RENDER_CACHE=os.path.join(tmp, "cache"),
                   PT_RENDER_CPU_CALLS=",".join(args.calls))
        env.pop("NUMBA_CACHE_DIR", None)
        run = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if run.returncode != 0:
            sys.exit(f"perf record failed: {run.stderr.strip()[-500:]}")
        rate = json.loads(run.stdout.strip().splitlines()[-1])
        script = subprocess.run(["perf", "script", "-i", data, "-F", "time,ip,dso"],
                                capture_output=True, text=True).stdout
        with open(syms) as f:
            table = sorted(tuple(r) for r in json.load(f))
        if args.annotate:
            with open(code) as f:
                code_bytes = json.load(f)
    counts, per_ip, libraries, in_window, outside = attribute(
        script, table, (rate["render_start"], rate["render_end"]))
    inside = sum(counts.values())
    shares = {name: c / inside for name, c in counts.most_common()}
    print(f"{args.scene}: {rate['m_paths_per_s']:.3f} M camera paths/s while profiled; "
          f"{inside} samples in the kernel's code, {outside} outside")
    for name, s in list(shares.items())[:args.top]:
        print(f"  {100 * s:5.1f}%  {name}")
    # what the rendering ran outside the kernel's code (libm, Numba's helpers, the thread
    # pool, unknown: JIT code of other libraries), as shares of all its samples
    rendering = in_window + sum(libraries.values())
    lib_shares = {name: c / rendering for name, c in libraries.most_common()}
    print(f"while rendering, {100 * (1 - in_window / max(rendering, 1)):.1f}% of the samples "
          f"were outside the kernel's code:")
    for name, s in list(lib_shares.items())[:6]:
        print(f"  {100 * s:5.1f}%  {name}")
    if args.annotate:
        found = [(addr, sym) for addr, _, sym in table if short_name(sym) == args.annotate]
        if not found:   # a parfor's gufunc is named after its address, new each run
            found = [(addr, sym) for addr, _, sym in table
                     if short_name(sym).startswith(args.annotate)]
        for addr, sym in found:
            annotate(addr, bytes.fromhex(code_bytes[str(addr)]), per_ip, inside,
                     args.annotate_min)
        if not found:
            print(f"--annotate: no compiled function is named {args.annotate!r}; the "
                  f"names are those of the table above (a function inlined into its caller "
                  f"has none of its own)")
    if args.json:
        from bench.common import machine
        with open(args.json, "w") as f:
            json.dump({"command": " ".join(["python -m bench.cpu_profile"] + sys.argv[1:]),
                       "machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M UTC",
                                                                   time.gmtime()),
                       "scene": args.scene, "spp_per_pass": args.spp, "profiled": rate,
                       "samples_in_kernel": inside, "samples_outside": outside,
                       "shares": shares, "rendering_outside_kernel": lib_shares}, f,
                      indent=1)


def attribute(script, table, window):
    """Samples of ``perf script -F time,ip,dso`` output: (samples per compiled function of
    ``table`` (rows of address, size, symbol), samples per instruction address in them,
    samples outside them per library taken within ``window`` (start, end: the rendering's
    CLOCK_MONOTONIC seconds), samples in them within the window, samples outside them)."""
    starts = [r[0] for r in table]
    counts = collections.Counter()
    per_ip = collections.Counter()
    libraries = collections.Counter()
    in_window = 0
    outside = 0
    for line in script.splitlines():
        m = re.match(r"\s*([0-9.]+):\s+([0-9a-f]+)\s+\((.*)\)", line)
        if not m:
            continue
        ip = int(m.group(2), 16)
        rendering = window[0] <= float(m.group(1)) <= window[1]
        k = bisect.bisect_right(starts, ip) - 1
        if k >= 0 and ip < table[k][0] + table[k][1]:
            counts[short_name(table[k][2])] += 1
            per_ip[ip] += 1
            in_window += rendering
        else:
            outside += 1
            if rendering:
                libraries[os.path.basename(m.group(3))] += 1
    return counts, per_ip, libraries, in_window, outside


def annotate(addr, code, per_ip, inside, min_share):
    """Print the disassembly (objdump) of one compiled function, each instruction with its
    share of the kernel's samples; runs of cold instructions are elided. A sample lands on
    the instruction after the one that stalled more often than on that one (skid)."""
    with tempfile.NamedTemporaryFile(suffix=".bin") as f:
        f.write(code)
        f.flush()
        dis = subprocess.run(["objdump", "-D", "-b", "binary", "-m", "i386:x86-64",
                              "--adjust-vma=%#x" % addr, f.name], capture_output=True,
                             text=True).stdout
    lines = []
    for line in dis.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\t(?:[0-9a-f]{2} )+\s*\t(.*)", line)
        if m:
            lines.append((int(m.group(1), 16), m.group(2)))
    total = sum(per_ip.get(a, 0) for a, _ in lines)
    print(f"\n{len(lines)} instructions, {100 * total / max(inside, 1):.1f}% of the kernel's "
          f"samples; instructions with >= {100 * min_share:.2f}% (and 3 before each):")
    hot = {i for i, (a, _) in enumerate(lines) if per_ip.get(a, 0) >= min_share * inside}
    show = sorted({j for i in hot for j in range(max(0, i - 3), i + 1)})
    last = -2
    for i in show:
        if i != last + 1:
            print("   ...")
        a, text = lines[i]
        share = 100 * per_ip.get(a, 0) / max(inside, 1)
        print(f"  {share:5.2f}%  {a - addr:6x}  {text}")
        last = i


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", choices=list(CONVERGENCE))
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--spp", type=int, default=4, help="samples per pixel per pass")
    p.add_argument("--top", type=int, default=20)
    p.add_argument("--json")
    p.add_argument("--calls", type=lambda s: [w for w in s.split(",") if w], default=[],
                   metavar="STEP[,STEP]",
                   help="integrator steps (kernels.device.step_marker) or other device "
                        "functions (closest_hit_wide, any_hit_wide) to keep as calls rather "
                        "than inline, so that the table shows their share apart (the call "
                        "itself costs a little, the traversal's a lot: shares, not speeds)")
    p.add_argument("--annotate", metavar="FUNCTION",
                   help="also print this function's instructions with their sample shares "
                        "(a name as the table prints it, e.g. envmap.env_sample_lit)")
    p.add_argument("--annotate-min", type=float, default=0.002,
                   help="share of the kernel's samples from which --annotate shows an "
                        "instruction (default 0.002)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--syms", help=argparse.SUPPRESS)
    p.add_argument("--code", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        child(args)
    else:
        profile(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
