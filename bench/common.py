"""Shared helpers for benchmarks: machine description, timing, Mitsuba scenes."""
import datetime
import os
import platform
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
# ../shared beside the clone; PT_RENDER_SHARED points elsewhere (the GPU machine gets a copy)
SHARED = os.environ.get("PT_RENDER_SHARED") or os.path.join(os.path.dirname(ROOT), "shared")
CORNELL = os.path.join(ROOT, "scenes", "cornell-box.json")
CORNELL_REF = os.path.join(SHARED, "reference", "cornell-box", "reference_256_d8.npy")


def machine():
    """One line naming CPU, core count and GPU (if any)."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    gpu = ""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=20).stdout.strip()
        gpu = out.splitlines()[0] if out else ""
    except (OSError, subprocess.SubprocessError):
        pass
    s = f"{cpu}, {os.cpu_count()} cores"
    return s + (f", GPU {gpu}" if gpu else "")


def versions():
    import numba
    import numpy
    v = {"python": platform.python_version(), "numpy": numpy.__version__,
         "numba": numba.__version__}
    for name in ("numba_cuda", "mitsuba"):
        try:
            v[name.replace("_", "-")] = __import__(name).__version__
        except ImportError:
            pass
    return v


def now():
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def command():
    script = os.path.relpath(sys.argv[0], ROOT)
    if script == os.path.join("bench", "__main__.py"):
        script = "-m bench"
    elif script.startswith("bench" + os.sep) and script.endswith(".py"):
        script = "-m " + script[:-3].replace(os.sep, ".")      # python -m bench.sweep ...
    return "python " + " ".join([script] + sys.argv[1:])


def write_record(path, **fields):
    """A benchmark record as JSON at ``path``: the command, machine, date and versions,
    then ``fields``."""
    import json
    with open(path, "w") as f:
        json.dump({"command": command(), "machine": machine(), "date": now(),
                   "versions": versions(), **fields}, f, indent=1)


def median_time(fn, repeats):
    """Median wall time of ``fn()`` over ``repeats`` calls (call it once before to warm up)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


# Dr.Jit's LLVM backend loads the system libLLVM. LLVM 14 is refused and LLVM 15 aborts the
# process while compiling Mitsuba's path integrator ("Cannot select: fminimum", seen on Debian
# 12, 2026-11-23), so a newer one is looked for when the default fails.
_LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM-{v}.so", "/usr/lib/llvm-{v}/lib/libLLVM.so",
                    "/usr/lib/x86_64-linux-gnu/libLLVM.so.{v}.1")
_PROBE = ("import mitsuba as mi, drjit as dr; mi.set_variant({v!r}); "
          "d = mi.cornell_box(); d['sensor']['film']['width'] = 8; "
          "d['sensor']['film']['height'] = 8; "
          "dr.eval(mi.render(mi.load_dict(d), spp=1)); print('ok')")


def _probe_mitsuba(variant, env):
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE.format(v=variant)], env=env,
                           capture_output=True, text=True, timeout=600)
    except subprocess.TimeoutExpired:
        return "timed out"
    if r.returncode == 0 and r.stdout.strip().endswith("ok"):
        return None
    last = [ln for ln in (r.stderr or "").splitlines() if ln.strip()]
    first = next((ln for ln in last if "ERROR" in ln or "Error" in ln), last[-1] if last else "")
    return f"exit {r.returncode}: {first.strip()[:160]}"


_MITSUBA_STATUS = {}


def usable_mitsuba(variant):
    """Whether Mitsuba 3 can render with ``variant`` in this process, as (ok, why not).

    Tried in a child process first, because a failing JIT aborts its process (no exception to
    catch). For ``llvm_*`` variants with no DRJIT_LIBLLVM_PATH set, a newer system libLLVM is
    tried when the default one fails; the one that works is put in this process's environment
    before Mitsuba is imported here."""
    if variant in _MITSUBA_STATUS:
        return _MITSUBA_STATUS[variant]
    try:
        import importlib.util
        if importlib.util.find_spec("mitsuba") is None:
            raise ImportError
    except ImportError:
        _MITSUBA_STATUS[variant] = (False, "Mitsuba not installed (pip install -e .[bench])")
        return _MITSUBA_STATUS[variant]
    why = _probe_mitsuba(variant, dict(os.environ))
    if why and variant.startswith("llvm") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        for v in range(30, 15, -1):
            for pattern in _LLVM_CANDIDATES:
                lib = pattern.format(v=v)
                if os.path.exists(lib) and not _probe_mitsuba(
                        variant, dict(os.environ, DRJIT_LIBLLVM_PATH=lib)):
                    os.environ["DRJIT_LIBLLVM_PATH"] = lib
                    why = None
                    break
            if why is None:
                break
        else:
            why += " (and no newer libLLVM found: e.g. apt install libllvm19)"
    _MITSUBA_STATUS[variant] = (why is None, why)
    return _MITSUBA_STATUS[variant]


def mitsuba_cornell(width, height, spp, max_depth=8, sampler="independent"):
    """Mitsuba 3's own Cornell box (the reference's scene) with a box pixel filter."""
    import mitsuba as mi
    d = mi.cornell_box()
    d["sensor"]["film"]["width"] = width
    d["sensor"]["film"]["height"] = height
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": spp}
    d["integrator"] = {"type": "path", "max_depth": max_depth}
    return mi.load_dict(d)


def mitsuba_pass_times(scene, spp, repeats):
    """(first render s, median s, all s) of Mitsuba rendering ``scene`` (loaded, variant set)
    at ``spp``: a first render (its JIT compile included), then ``repeats`` timed ones, each
    waited for (dr.sync_thread) and with a new seed."""
    import drjit as dr
    import mitsuba as mi
    seed = [0]

    def one():
        img = mi.render(scene, spp=spp, seed=seed[0])
        dr.eval(img)
        dr.sync_thread()
        seed[0] += 1

    t0 = time.perf_counter()
    one()
    first = time.perf_counter() - t0
    t, times = median_time(one, repeats)
    return first, t, times
