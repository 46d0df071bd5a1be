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
    return "python " + " ".join([script] + sys.argv[1:])


def median_time(fn, repeats):
    """Median wall time of ``fn()`` over ``repeats`` calls (call it once before to warm up)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


def mitsuba_cornell(width, height, spp, max_depth=8):
    """Mitsuba 3's own Cornell box (the reference's scene) with a box pixel filter."""
    import mitsuba as mi
    d = mi.cornell_box()
    d["sensor"]["film"]["width"] = width
    d["sensor"]["film"]["height"] = height
    d["sensor"]["film"]["rfilter"] = {"type": "box"}
    d["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
    d["integrator"] = {"type": "path", "max_depth": max_depth}
    return mi.load_dict(d)
