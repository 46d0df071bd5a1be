"""Memory estimates checked before allocating: a render that cannot fit fails at once
with the size it needs, instead of dying in the middle of an allocation.

The film figure is measured: the peak resident memory of ``pt-render`` at 3072^2 minus
at 512^2 pixels (CPU backend, PNG + EXR output), per pixel: 83 bytes, 168 with
``--reference`` (2-core machine, 2026-11-23); 192 covers both. The texel and triangle
figures are counted from the arrays the loader and compiler allocate, not measured.
"""
import os

from .errors import InputError

# Host bytes per pixel of a render: the float64 film, the pass buffer and ray counters,
# the mean image and the transient arrays of encoding it (PNG + EXR), a relMSE reference
# (measured, see above).
FILM_BYTES_PER_PIXEL = 192
# GPU bytes per pixel: pass sums and counters of up to two sample groups.
DEVICE_BYTES_PER_PIXEL = 48
# Host bytes per triangle while compiling (float64 world-space copies, BVH build,
# per-triangle kernel arrays); the parsed mesh itself is not included.
TRIANGLE_BYTES = 1200
# A texture: its decoded 8-bit/float source, the float32 texels, the concatenated table
# (16 bytes a texel, layout.TEXEL_WIDTH; with the mip levels of a trilinear texture, a
# third more, and the halving's temporary).
TEXEL_BYTES = 56

GIB = 2.0 ** 30


def available_bytes():
    """Memory this process can still allocate without swapping (Linux: MemAvailable, or
    the cgroup limit if lower); None where unknown."""
    avail = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            return None
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as f:
                limit = f.read().strip()
            if limit.isdigit():
                used = _cgroup_usage(os.path.dirname(path))
                if used is not None:
                    avail = min(avail, max(0, int(limit) - used))
            break
        except OSError:
            continue
    return avail


def _cgroup_usage(folder):
    for name in ("memory.current", "memory.usage_in_bytes"):
        try:
            with open(os.path.join(folder, name)) as f:
                return int(f.read().strip())
        except (OSError, ValueError):
            continue
    return None


def _gib(n):
    return f"{n / GIB:.1f} GiB" if n >= 0.1 * GIB else f"{n / 2 ** 20:.0f} MiB"


def require(nbytes, what, advice, error=InputError):
    """Raise ``error`` if ``nbytes`` is more than this machine has available."""
    avail = available_bytes()
    if avail is not None and nbytes > avail:
        raise error(f"{what} needs about {_gib(nbytes)} of memory; this machine has "
                    f"{_gib(avail)} available: {advice}")


def check_film(width, height, backend="auto"):
    require(width * height * FILM_BYTES_PER_PIXEL, f"a {width}x{height} image",
            "lower the resolution")
    if backend == "cuda" or backend == "auto":
        check_device(width * height * DEVICE_BYTES_PER_PIXEL, f"a {width}x{height} image",
                     "lower the resolution", only_if_present=backend == "auto")


def device_free_bytes(only_if_present=False):
    """The current CUDA device's free memory in bytes; None under the simulator, without a
    driver or device, or (``only_if_present``) where numba finds no GPU."""
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return None
    try:
        from numba import cuda
        if only_if_present and not cuda.is_available():
            return None
        return cuda.current_context().get_memory_info()[0]
    except Exception:   # no driver, no device: the backend reports that itself
        return None


def check_device(nbytes, what, advice, only_if_present=True):
    """The same check against the current CUDA device's free memory (skipped when no GPU
    is in use)."""
    free = device_free_bytes(only_if_present)
    if free is None:
        return
    if nbytes > free:
        raise InputError(f"{what} needs about {_gib(nbytes)} of GPU memory; the GPU has "
                         f"{_gib(free)} free: {advice}")
