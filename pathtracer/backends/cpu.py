"""CPU backend: a ``@njit(nogil=True)`` kernel over image rows, run on as many Python
threads as Numba's thread count (rows interleaved over the threads; why threads and not
``prange``: pathtracer.threads), compiled code cached on disk."""
import functools

import numpy as np
from numba import get_num_threads, njit

from .._cache import compile_lock, jit_cache, read_only
from ..threads import run_tasks
from .base import Backend

from ..accel.wide import WIDE_STACK_SIZE, widen_bvh
from ..kernels.device import FAST_MATH_FLAGS
from ..kernels.drivers import DEFERRED, choose_driver
from ..kernels.layout import AOV_WIDTH, ESC_F_WIDTH, ESC_I_WIDTH, ESCAPE_RING
from ..kernels.integrator import make_aov_pixel, make_deferred_pixel, make_render_pixel


def cpu_arrays(arrays, previous=None):
    """The CPU kernels' arrays: the scene's, with the eight-wide BVH (kernels.wide) in the
    ``bvh_box`` and ``bvh_child`` slots (same array types: the kernels' signature does not
    change), collapsed from the binary tree in ~7 ms for the 69k-triangle bunny; all of them
    read-only views (``_cache.read_only``: the same kernel in a Ray worker, whose arrays are
    read-only). ``previous`` ((binary arrays, wide arrays) of an earlier call): reused when
    the geometry is the same arrays (an API re-render that changed a material or the
    camera). Returns (CPU arrays, the pair to pass as ``previous`` next time)."""
    geometry = (arrays.tri_v, arrays.bvh_box, arrays.bvh_child)
    if previous is not None and all(a is b for a, b in zip(previous[0], geometry)):
        wide = previous[1]
    else:
        wide = widen_bvh(*geometry)
    arrays = arrays._replace(bvh_box=wide[0], bvh_child=wide[1])
    return type(arrays)(*(read_only(a) for a in arrays)), (geometry, wide)


def feature_bits(features):
    """A feature set as a string of 0s and 1s (the name of its kernels' compile lock)."""
    return "".join("1" if f else "0" for f in features)


class RowKernel:
    """A compiled kernel ``rows(*args, row_step, first_row)`` that renders the image rows
    first_row, first_row + row_step, ...; called as ``kernel(*args, threads)`` it runs on
    ``threads`` threads (pathtracer.threads.run_tasks), thread j taking the rows j,
    j + threads, ...: every thread gets rows from the whole image (the sky and the object),
    not one band. The first call compiles or loads the kernel in the calling thread, before
    the others start. ``signatures`` and ``overloads`` are the compiled kernel's (as a
    Numba dispatcher's: _cache.compile_lock, bench.cpu_profile)."""

    def __init__(self, rows):
        self.rows = rows

    @property
    def signatures(self):
        return self.rows.signatures

    @property
    def overloads(self):
        return self.rows.overloads

    def __call__(self, *args):
        *args, threads = args
        threads = max(1, int(threads))
        if not self.rows.signatures:
            # compile (or load) the kernel here, once, not in every thread at once: a call
            # over no rows (the first row past any image)
            self.rows(*args, 1, NO_ROWS)
        run_tasks(self.rows, (*args, threads), threads, threads)


NO_ROWS = 1 << 62


@functools.lru_cache(maxsize=None)
def pass_kernel(features):
    """The pass kernel (a :class:`RowKernel`) for scenes with ``features``: the driver that
    kernels.drivers.choose_driver picks (deferred: each row's paths go through a ring whose
    records are finished a few paths later, the escaped rays' texels prefetched meanwhile;
    nested: render_pixel adds a pixel's paths itself)."""
    deferred = choose_driver("cpu", features) == DEFERRED
    if deferred:
        render_pixel, drain = make_deferred_pixel(features)
    else:
        render_pixel, drain = make_render_pixel(features), None
    ring = ESCAPE_RING if deferred else 0

    # error_model='numpy': float division by zero gives inf/nan as on the GPU, not an exception.
    # nogil: the kernel's threads (RowKernel) and other Python threads (the live preview's
    # server) run while a pass renders.
    # fastmath: kernels.device.FAST_MATH_FLAGS (no nnan / ninf), as the GPU's default.
    # (branches on ``deferred``, a closure constant, are removed before typing)
    @njit(nogil=True, cache=jit_cache(), error_model="numpy", fastmath=set(FAST_MATH_FLAGS))
    def render_pass(out, stats, sample_start, n_samples, seed, max_bounces, rr_depth, scene,
                    active, row_step, first_row):
        stack = np.empty(WIDE_STACK_SIZE, np.int32)   # traversal scratch
        esc_f = np.empty((ring, ESC_F_WIDTH), np.float32)
        esc_i = np.empty((ring, ESC_I_WIDTH), np.int32)
        for py in range(first_row, out.shape[0], row_step):
            queued = 0
            for px in range(out.shape[1]):
                if active[py, px]:
                    if deferred:
                        queued = render_pixel(px, py, sample_start, n_samples, seed,
                                              max_bounces, rr_depth, scene, stack, esc_f,
                                              esc_i, queued, out, stats)
                    else:
                        render_pixel(px, py, sample_start, n_samples, seed, max_bounces,
                                     rr_depth, scene, stack, out, stats)
                else:                                # adaptive sampling: a finished pixel
                    for c in range(out.shape[2]):
                        out[py, px, c] = 0.0
                        stats[py, px, c] = 0
            if deferred:
                drain(esc_f, esc_i, queued, py, scene, out, stats)

    return RowKernel(render_pass)


@functools.lru_cache(maxsize=None)
def aov_kernel(features):
    aov_pixel = make_aov_pixel(features)

    @njit(nogil=True, cache=jit_cache(), error_model="numpy", fastmath=set(FAST_MATH_FLAGS))
    def aov_pass(out, n_samples, seed, scene, row_step, first_row):
        stack = np.empty(WIDE_STACK_SIZE, np.int32)
        for py in range(first_row, out.shape[0], row_step):
            for px in range(out.shape[1]):
                aov_pixel(px, py, n_samples, seed, scene, stack, out)

    return RowKernel(aov_pass)


class CPUBackend(Backend):
    name = "cpu"

    def __init__(self, scene):
        self.scene = scene
        self.arrays, self._wide = cpu_arrays(scene.arrays)
        self.kernel = pass_kernel(scene.features)
        self.out = np.zeros((scene.height, scene.width, 3), np.float32)
        self.stats = np.zeros((scene.height, scene.width, 3), np.int32)
        self.all_pixels = read_only(np.ones((scene.height, scene.width), np.uint8))
        self._compiled = False

    def update(self, scene):
        """Render ``scene`` from now on: the same features and image size (the Python
        API's re-render; nothing is compiled)."""
        self.scene = scene
        self.arrays, self._wide = cpu_arrays(scene.arrays, self._wide)

    def compile(self):
        """Compile (or load from the disk cache) without rendering; once per backend."""
        if not self._compiled:
            self.render_pass(0, 0, 0, 0, 0)
            self._compiled = True

    def aovs(self, n_samples, seed):
        """The denoiser's albedo and normal images (float32 H x W x AOV_WIDTH, see aov_pixel)."""
        out = np.zeros((self.scene.height, self.scene.width, AOV_WIDTH), np.float32)
        kernel = aov_kernel(self.scene.features)
        with compile_lock("cpu-aov-" + feature_bits(self.scene.features), kernel):
            kernel(out, n_samples, seed, self.arrays, get_num_threads())
        return out

    def render_pass(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None):
        """Sums over n_samples paths per pixel (float32 HxWx3) and ray/NaN counts (HxWx3);
        ``active`` (uint8 HxW, adaptive sampling): only the pixels where it is not 0."""
        # (the thread count is an argument: get_num_threads() inside the kernel is a
        # dynamic global, which Numba's disk cache refuses)
        if not self.kernel.signatures:
            # the first call compiles (or loads) the kernel: a pass of no samples, under the
            # kernel's compile lock, so that a process waiting for it waits for no render
            with compile_lock("cpu-pass-" + feature_bits(self.scene.features), self.kernel):
                self._launch(0, 0, 0, 0, 0, None)
        self._launch(sample_start, n_samples, seed, max_bounces, rr_depth, active)
        return self.out, self.stats

    def _launch(self, sample_start, n_samples, seed, max_bounces, rr_depth, active):
        # (the mask read-only, as from a Ray driver: one compiled kernel, _cache.read_only)
        self.kernel(self.out, self.stats, sample_start, n_samples, seed, max_bounces, rr_depth,
                    self.arrays, self.all_pixels if active is None else read_only(active),
                    get_num_threads())
