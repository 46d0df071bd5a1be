"""CUDA backend: the shared ``render_pixel`` over a grid of (pixel, sample group) threads.

A pass of ``n`` samples per pixel is split into ``groups`` contiguous ranges of samples, and
each thread renders one range of one pixel: lanes of a warp work on nearby pixels of the
same group. One thread per pixel (``groups`` = 1) leaves a small image as one badly
balanced wave (sky pixels end at once, the object's pixels bounce); with groups the launch
has enough threads to fill the GPU at any image size, and short ranges end together, so a
warp waits less for its longest path. Each group sums into its own slice of a scratch film
and a second kernel adds the slices in a fixed order: the image does not depend on thread
timing, and each (pixel, sample) uses the same random numbers as on the CPU.
"""
import functools
import os

import numpy as np
from numba import config, cuda

# Numba warns of "low occupancy" at every launch of fewer than 128 blocks: the compile
# launches (one block) and small images do that by design, and a user can do nothing about
# it. Off unless the user's environment asks for it. Only the config attribute is set:
# changing a NUMBA_* environment variable makes Numba re-read its whole configuration at
# the next compile, which would undo the kernel cache folder pathtracer._cache chose.
if "NUMBA_CUDA_LOW_OCCUPANCY_WARNINGS" not in os.environ:
    try:
        from numba.cuda.core import config as _launch_config   # numba-cuda's own config
    except ImportError:
        _launch_config = config
    for _c in {id(config): config, id(_launch_config): _launch_config}.values():
        _c.CUDA_LOW_OCCUPANCY_WARNINGS = 0

from .._cache import jit_cache
from .base import Backend
from .launch import Launcher

from ..kernels.constants import STACK_SIZE
from ..kernels.device import FAST_MATH_FLAGS
from ..kernels.layout import AOV_WIDTH, specialise
from ..kernels.drivers import WAVEFRONT, choose_driver, wave_min_paths_for
from ..kernels.integrator import SceneArrays, make_aov_pixel, make_render_pixel, regenerates

BLOCK = (16, 8)
# Threads a launch aims at: several waves of the largest GPUs' resident threads (an H200:
# 132 SMs x 2,048), so that the blocks that finish late are a small part of the pass.
TARGET_THREADS = 1 << 23
# ... or fewer, longer threads where render_pixel regenerates paths (scenes without an
# environment, kernels.integrator.regenerates): a lane whose path ended starts the thread's
# next sample, so more samples per thread keep the lanes busy. H100, 2026-11-23
# (bench/gpu_launch.py): the Cornell box 1024^2 x 64 ran 3 % faster at 2^21 than at 2^23.
TARGET_THREADS_REGENERATING = 1 << 21
# The scratch film holds at most this many (group, pixel) slices of rgb + ray counts.
MAX_SLICES = 1 << 23
# Registers per thread: the megakernel wants ~130; capped at 64 (the rest spills to L1)
# twice as many warps fit on an SM, which hides the latency of the divergent traversal and
# shading better than the registers save (H100, 2026-11-23: +11-28 % on every benchmark
# scene; 80 and 96 were in between). bench/gpu_launch.py measures the alternatives.
MAX_REGISTERS = 64
# The kernels of scenes with an HDRI (the principled BSDF, the sky's tables; warps that wait
# on instruction fetch) gain from a tighter cap, the Cornell box loses (H100, 2026-11-24,
# bench.gpu_launch r56 against the default, alternating: bunny-studio +2 %, sun +3-4 %, the
# Cornell box -1.8 %).
MAX_REGISTERS_ENV_MAP = 56
# ... and the wavefront's shading kernels (backends.wavefront) 64: their warps wait on
# memory more than on instruction fetch (H100, 2026-11-24, bench.gpu_launch, 64 against 56
# alternating: bunny-studio +1.7 % at 1024x768 and +1 % at 256x192, the sun +1.4 % and 0).
WAVE_MAX_REGISTERS = 64
AUTO = "auto"


def max_registers_for(features):
    """The register cap of the pass kernel for scenes with ``features``."""
    return MAX_REGISTERS_ENV_MAP if specialise(features).env_map else MAX_REGISTERS


# Which driver renders a pass (the megakernel with or without path regeneration, or the
# wavefront, from how many paths): kernels.drivers.choose_driver, the one table. Where the
# wavefront renders, both it and the megakernel (for small passes) are compiled.


# fast=True: NVVM's approximate division and square root and flushed denormals (ftz=1,
# prec_div=0, prec_sqrt=0, fma=1) and LLVM's fast-math flags except nnan and ninf: the
# kernels test for NaN and rely on IEEE infinities (the slab test divides by zero).
# (FAST_MATH_FLAGS: kernels.device)


# Device functions called, not inlined, in the pass kernel. NVVM inlines every device
# function; the principled BSDF's evaluation, reached from next-event estimation and from
# BSDF sampling's folded lobes, then appears several times in a kernel whose warps already
# stall on instruction fetch 64-73 % of the time (Nsight Compute, docs/benchmarks.md). One
# called copy: H100, 2026-11-24, bunny-studio +14.5 %, sun +23.9 %, the Cornell box (no
# principled material) unchanged. Also calling principled_sample, the environment lookups
# or the scatter steps measured no better or worse; calling the traversal cost 12 %.
NOINLINE = ("principled_eval",)


def _call_not_inlined():
    """Mark Numba's calls of the NOINLINE functions with LLVM's noinline call-site
    attribute, so that NVVM keeps one copy of each. Numba offers no switch for it: the
    calling convention that numba-cuda's device-function calls go through is wrapped. A
    numba-cuda without it compiles inlined kernels (the same images, slower); the kernel
    cache is keyed by this file's source, so a change here recompiles."""
    try:
        from numba.cuda.core.callconv import MinimalCallConv
    except ImportError:
        return
    if getattr(MinimalCallConv, "_pt_render_noinline", False) or \
            not hasattr(MinimalCallConv, "call_function"):
        return
    original = MinimalCallConv.call_function
    # Itanium-style mangled names carry each name component with its length
    marks = tuple(f"{len(name)}{name}" for name in NOINLINE)

    def call_function(self, builder, callee, resty, argtys, args):
        if "pathtracer" not in callee.name or not any(m in callee.name for m in marks):
            return original(self, builder, callee, resty, argtys, args)
        plain_call = builder.call

        def call(fn, *rest, **kw):
            instr = plain_call(fn, *rest, **kw)
            if fn is callee:
                instr.attributes.add("noinline")
            return instr
        builder.call = call
        try:
            return original(self, builder, callee, resty, argtys, args)
        finally:
            del builder.call

    MinimalCallConv.call_function = call_function
    MinimalCallConv._pt_render_noinline = True


if not config.ENABLE_CUDASIM:
    _call_not_inlined()


def _aligned(d_scene):
    """The device scene, after checking what kernels.loads' 128-bit loads of BVH nodes and
    environment texels need: 16-byte aligned rows (cuda.to_device allocates at 256-byte
    boundaries; a misaligned vector load would fault)."""
    if not config.ENABLE_CUDASIM:
        for name, axis in (("bvh_box", 0), ("bvh_child", 0), ("env_img", 1)):
            a = getattr(d_scene, name)
            if a.device_ctypes_pointer.value % 16 or (a.strides[axis] % 16):
                raise RuntimeError(f"pt-render: {name} on the GPU is not 16-byte aligned")
    return d_scene


@functools.lru_cache(maxsize=None)
def pass_kernel(features, max_registers=None, fast=False, regenerate=None):
    """The pass kernel for scenes with ``features`` (``regenerate``: force render_pixel's
    path regeneration on or off; None: kernels.integrator.regenerates)."""
    if regenerate is None:
        regenerate = regenerates(features, "cuda")
    render_pixel = make_render_pixel(features, "cuda", bool(regenerate))
    fastmath = set(FAST_MATH_FLAGS) if fast else False

    # Numba's disk cache keys on the kernel's code and closure values, not on the jit
    # options: the options' own key is read below so that each set is cached apart.
    options_key = ((max_registers or 0) * 2 + bool(fast)) * 2 + bool(regenerate)

    # the simulator runs Python: it takes neither option
    options = {} if config.ENABLE_CUDASIM else dict(max_registers=max_registers,
                                                    fastmath=fastmath)

    @cuda.jit(cache=jit_cache(), **options)
    def render_pass(out, stats, sample_start, n_samples, seed, max_bounces, rr_depth, scene,
                    active):
        """Group g = blockIdx.z renders its share of samples [sample_start, + n_samples)
        into out[g], stats[g] (pixels where active is 0: zeros)."""
        if options_key < 0:     # never: makes the options part of the cache key
            return
        px, py = cuda.grid(2)
        g = cuda.blockIdx.z
        groups = cuda.gridDim.z
        if px < out.shape[2] and py < out.shape[1]:
            if active[py, px]:
                lo = (n_samples * g) // groups
                hi = (n_samples * (g + 1)) // groups
                stack = cuda.local.array(STACK_SIZE, np.int32)
                render_pixel(px, py, sample_start + lo, hi - lo, seed, max_bounces, rr_depth,
                             scene, stack, out[g], stats[g])
            else:
                for c in range(3):
                    out[g, py, px, c] = 0.0
                    stats[g, py, px, c] = 0

    return render_pass


@functools.lru_cache(maxsize=None)
def aov_kernel(features):
    aov_pixel = make_aov_pixel(features, "cuda")

    @cuda.jit(cache=jit_cache())
    def aov_pass(out, n_samples, seed, scene):
        px, py = cuda.grid(2)
        if px < out.shape[1] and py < out.shape[0]:
            stack = cuda.local.array(STACK_SIZE, np.int32)
            aov_pixel(px, py, n_samples, seed, scene, stack, out)

    return aov_pass


@cuda.jit(cache=jit_cache())
def sum_groups(parts, part_stats, groups, out, stats):
    """out = parts[0] + parts[1] + ... (in that order), the same for the ray counts."""
    px, py = cuda.grid(2)
    if px < out.shape[1] and py < out.shape[0]:
        for c in range(3):
            acc = parts[0, py, px, c]
            n = part_stats[0, py, px, c]
            for g in range(1, groups):
                acc += parts[g, py, px, c]
                n += part_stats[g, py, px, c]
            out[py, px, c] = acc
            stats[py, px, c] = n


@cuda.jit(cache=jit_cache())
def sum_stats(stats, totals):
    """totals[c] += the sum of stats[:, :, c]: a thread per row (grid-stride), one atomic
    add per row and channel (a work item's ray counts, without copying the per-pixel
    counts)."""
    for y in range(cuda.grid(1), stats.shape[0], cuda.gridsize(1)):
        for c in range(stats.shape[2]):
            acc = np.int64(0)
            for x in range(stats.shape[1]):
                acc += stats[y, x, c]
            cuda.atomic.add(totals, c, acc)


@cuda.jit(cache=jit_cache())
def zero_int64(a):
    """a[:] = 0 on the GPU (in launch order: no wait for the host, unlike a copy from
    pageable host memory, which waits for the GPU)."""
    i = cuda.grid(1)
    if i < a.shape[0]:
        a[i] = 0


def _same(new, old):
    """Whether a re-compiled scene array equals the one already on the GPU: memoised arrays
    are the same object; small ones re-built from the description (materials, camera,
    lights) usually have equal contents, and comparing is cheaper than an upload (~0.4 ms
    each through numba-cuda)."""
    if new is old:
        return True
    if new.shape != old.shape or new.dtype != old.dtype:
        return False
    # bitwise, so that -0.0 and 0.0 (or two NaN) are told apart as the kernel would
    return np.array_equal(new.reshape(-1).view(np.uint8), old.reshape(-1).view(np.uint8))


def sample_groups(width, height, n_samples, target_threads=TARGET_THREADS):
    """How many sample groups a pass of n_samples per pixel is split into."""
    pixels = width * height
    want = -(-target_threads // pixels)
    return max(1, min(n_samples, want, MAX_SLICES // pixels))


class CUDABackend(Backend):
    name = "cuda"
    pass_seconds = 0.25
    pipelined = True

    def __init__(self, scene, block=BLOCK, max_registers=AUTO, fast=True,
                 target_threads=None, regenerate=None, wavefront=AUTO):
        """max_registers: the pass kernel's register cap (None: no cap; AUTO:
        max_registers_for the scene's features, WAVE_MAX_REGISTERS for the wavefront's
        shading kernels); wavefront: render with the wavefront kernels (backends.wavefront)
        instead of the megakernel (True, or a dict of WavefrontLaunch's options; AUTO:
        kernels.drivers.choose_driver)."""
        self.scene = scene
        wave_registers = max_registers
        if max_registers == AUTO:
            max_registers = max_registers_for(scene.features)
            wave_registers = WAVE_MAX_REGISTERS
        self.block = tuple(block)
        if regenerate is None:
            regenerate = regenerates(scene.features, "cuda")
        wave_threads = target_threads
        # passes of fewer paths than this render with the megakernel (kernels.drivers.WAVE_MIN_PATHS)
        self.wave_min_paths = 0
        if wavefront == AUTO:
            from .wavefront import fits
            wavefront = (choose_driver("cuda", scene.features) == WAVEFRONT
                         and fits(scene.width, scene.height))
            self.wave_min_paths = wave_min_paths_for(scene.features)
        if target_threads is None:
            target_threads = TARGET_THREADS_REGENERATING if regenerate else TARGET_THREADS
        self.target_threads = target_threads
        self.wavefront = None
        if wavefront:
            from .wavefront import WavefrontLaunch
            wave_options = dict(wavefront) if isinstance(wavefront, dict) else {}
            if wave_threads is not None:
                wave_options.setdefault("wave_threads", wave_threads)
            self.wavefront = WavefrontLaunch(scene.features, scene.width, scene.height,
                                             wave_registers, fast, self.block, **wave_options)
        self.kernel = pass_kernel(scene.features, max_registers, bool(fast), bool(regenerate))
        # the launches of each pass, their arguments' packing kept (backends.launch)
        self._launch_pass = Launcher(self.kernel)
        self._launch_sum = Launcher(sum_groups)
        self._launch_zero = Launcher(zero_int64)
        self._launch_stats = Launcher(sum_stats)
        self.d_scene = _aligned(SceneArrays(*[cuda.to_device(a) for a in scene.arrays]))
        h, w = scene.height, scene.width
        self.d_out = cuda.device_array((h, w, 3), np.float32)
        self.d_stats = cuda.device_array((h, w, 3), np.int32)
        self._parts = None   # scratch film (float sums, ray counts), see _scratch
        self._views = {}     # its views by (groups, halves), see _scratch
        self._totals = None  # a work item's ray counts (render_rows)
        self._copies = None  # the stream of render_rows_async's copies
        self._halves = None  # the second half's film of render_halves (device, host)
        self.d_all_pixels = cuda.to_device(np.ones((h, w), np.uint8))
        self._compiled = False
        self.out = cuda.pinned_array((h, w, 3), np.float32)
        self.stats = cuda.pinned_array((h, w, 3), np.int32)
        self.grid = ((w + self.block[0] - 1) // self.block[0],
                     (h + self.block[1] - 1) // self.block[1])

    def update(self, scene):
        """Render ``scene`` from now on: the same features and image size (the Python
        API's re-render; nothing is compiled). Only the arrays that changed are copied to
        the GPU (an unchanged BVH and mesh stay where they are)."""
        old = self.scene.arrays
        self.d_scene = _aligned(SceneArrays(*[d if _same(a, o) else cuda.to_device(a)
                                              for a, o, d in zip(scene.arrays, old,
                                                                 self.d_scene)]))
        self.scene = scene

    def compile(self):
        """Compile (or load from the disk cache) the kernels a render launches without
        rendering, so that no pass pays for it; once per backend."""
        if self._compiled:
            return
        if self.wavefront is not None:
            self.wavefront.compile(self.d_scene, self.d_out, self.d_stats)
        if self.wavefront is None or self.wave_min_paths > 0:
            self.launch(0, 0, 0, 0, 0, megakernel=True)
        parts, part_stats = self._scratch(1)     # views of the film: same types, no memory
        sum_groups[(1, 1), (1, 1)](parts, part_stats, 1, self.d_out, self.d_stats)
        # (the ray-count sum of render_pass_totals: its first compile cost the first pass of
        # a progressive render 0.28 s on an H100, counted as rendering by bench's curves)
        self._totals_of_pass()
        cuda.synchronize()
        self._compiled = True

    def _scratch(self, groups, halves=False):
        """The scratch film for ``groups`` sample groups: a view of one allocation that
        only grows (progressive passes double their samples until the launch is full);
        ``halves``: never the film itself (render_halves sums two films from it)."""
        # the same view objects for the same groups, so that the launches find their
        # packing kept (backends.launch: a new view is typed and flattened again)
        key = (groups, halves)
        views = self._views.get(key)
        if views is not None:
            return views
        if groups == 1 and not halves:
            views = (self.d_out.reshape((1,) + self.d_out.shape),
                     self.d_stats.reshape((1,) + self.d_stats.shape))
        else:
            if self._parts is None or self._parts[0].shape[0] < groups:
                h, w = self.scene.height, self.scene.width
                self._parts = (cuda.device_array((groups, h, w, 3), np.float32),
                               cuda.device_array((groups, h, w, 3), np.int32))
                self._views = {k: v for k, v in self._views.items() if k == (1, False)}
            views = (self._parts[0][:groups], self._parts[1][:groups])
        self._views[key] = views
        return views

    def _wavefront_renders(self, n_samples, megakernel=False):
        """Whether a launch of n_samples per pixel goes to the wavefront kernels."""
        return self.wavefront is not None and not megakernel and \
            n_samples * self.scene.width * self.scene.height >= self.wave_min_paths

    def launch(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None,
               megakernel=False, split=None):
        """Start a pass without waiting (for timing the kernel alone); ``megakernel``:
        with the megakernel even where the wavefront kernels would render it; ``split``
        (render_halves): the samples from the split-th on go to the second half's film.
        The megakernel then runs twice the sample groups a launch of ``split`` samples
        would, and sums the first half of the groups apart from the second, so that each
        half is summed as its own launch would sum it."""
        d_active = self.d_all_pixels if active is None else cuda.to_device(active)
        d_out_b, d_stats_b = self._half_films()[:2] if split is not None else (None, None)
        if self._wavefront_renders(n_samples, megakernel):
            self.wavefront.launch(self.d_scene, self.d_out, self.d_stats, d_active,
                                  sample_start, n_samples, seed, max_bounces, rr_depth,
                                  split, d_out_b, d_stats_b)
            return
        groups = sample_groups(self.scene.width, self.scene.height,
                               n_samples if split is None else split, self.target_threads)
        total = groups if split is None else 2 * groups
        parts, part_stats = self._scratch(total, halves=split is not None)
        self._launch_pass(self.grid + (total,), self.block, parts, part_stats, sample_start,
                          n_samples, seed, max_bounces, rr_depth, self.d_scene, d_active)
        if split is not None:
            self._launch_sum(self.grid, self.block, parts[:groups], part_stats[:groups],
                             groups, self.d_out, self.d_stats)
            self._launch_sum(self.grid, self.block, parts[groups:], part_stats[groups:],
                             groups, d_out_b, d_stats_b)
        elif groups > 1:
            self._launch_sum(self.grid, self.block, parts, part_stats, groups, self.d_out,
                             self.d_stats)

    def render_pass(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None):
        self.launch(sample_start, n_samples, seed, max_bounces, rr_depth, active)
        self.d_out.copy_to_host(self.out)
        self.d_stats.copy_to_host(self.stats)
        return self.out, self.stats

    def _totals_of_pass(self, d_stats=None):
        """The pass's ray counts summed on the GPU (int64, 3): a few bytes copied instead
        of H x W x 3 counts and three strided sums on the host."""
        self._sum_totals(d_stats)
        self._totals.copy_to_host(self._totals_host)
        return self._totals_host

    def _sum_totals(self, d_stats=None):
        """Launch the sum of the pass's ray counts into self._totals (no wait)."""
        if self._totals is None:
            self._totals = cuda.device_array(3, np.int64)
            self._totals_host = cuda.pinned_array(3, np.int64)
        self._launch_zero(1, 32, self._totals)
        # (128 blocks at least: fewer make Numba warn of low occupancy)
        self._launch_stats(max(128, (self.scene.height + 31) // 32), 32,
                           self.d_stats if d_stats is None else d_stats, self._totals)

    def render_pass_totals(self, sample_start, n_samples, seed, max_bounces, rr_depth,
                           active=None):
        """render_pass with the ray counts summed on the GPU: (sums, counts 1 x 1 x 3).
        What the progressive loop calls (the film only adds the counts up); render_pass
        keeps the per-pixel counts (the parity tests compare them with the CPU's)."""
        self.launch(sample_start, n_samples, seed, max_bounces, rr_depth, active)
        return self.collect_pass_totals()

    def collect_pass_totals(self):
        """The sums and ray counts of the pass ``launch`` started last, as
        render_pass_totals returns them: waits for it. The sums are a pinned buffer that
        the next collect overwrites; the next pass may be launched before they are read
        (the progressive loop launches it ahead of adding this one to its film)."""
        self.d_out.copy_to_host(self.out)
        return self.out, self._totals_of_pass().reshape(1, 1, 3)

    def render_halves(self, sample_start, half, seed, max_bounces, rr_depth, active=None):
        """The two halves of an adaptive pass, samples [sample_start, + half) and the
        ``half`` after them, as two render_pass_totals results ((sums, counts 1 x 1 x 3)
        each), from one launch (``launch``'s split): the same numbers as two launches, with
        half the launches (a pass of the sun at 256x192 on an H100 ~25 % cheaper in a
        warmed process; no change in time to error that the benchmark resolves:
        docs/benchmarks.md, "Environment maps: MIS compensation")."""
        w, h = self.scene.width, self.scene.height
        if not self._wavefront_renders(2 * half) and \
                2 * sample_groups(w, h, half, self.target_threads) * w * h > MAX_SLICES:
            # (a scratch film twice the largest one: two launches instead)
            return (tuple(np.array(a) for a in self.render_pass_totals(
                        sample_start, half, seed, max_bounces, rr_depth, active)),
                    self.render_pass_totals(sample_start + half, half, seed, max_bounces,
                                            rr_depth, active))
        _, d_stats_b, out_b = self._half_films()
        self.launch(sample_start, 2 * half, seed, max_bounces, rr_depth, active, split=half)
        self.d_out.copy_to_host(self.out)
        totals_a = self._totals_of_pass().reshape(1, 1, 3).copy()
        self._half_films()[0].copy_to_host(out_b)
        return (self.out, totals_a), (out_b, self._totals_of_pass(d_stats_b).reshape(1, 1, 3))

    def _half_films(self):
        """The second half's film of render_halves (device sums and counts, pinned host
        sums), allocated once (prepare_halves: before an adaptive render's clock starts,
        as __init__ allocates the first film)."""
        if self._halves is None:
            h, w = self.scene.height, self.scene.width
            self._halves = (cuda.device_array((h, w, 3), np.float32),
                            cuda.device_array((h, w, 3), np.int32),
                            cuda.pinned_array((h, w, 3), np.float32))
        return self._halves

    def prepare_halves(self):
        """Allocate what render_halves needs (an adaptive render calls it before it starts
        its clock)."""
        self._half_films()

    def render_rows(self, sample_start, n_samples, seed, max_bounces, rr_depth, row0, row1,
                    active=None):
        """A work item of a split render (pathtracer.distribute): the sums of rows
        [row0, row1) (float32, a new array) and the ray counts of the pass (int64, 3), summed
        on the GPU so that only the rows come back."""
        self.launch(sample_start, n_samples, seed, max_bounces, rr_depth, active)
        totals = self._totals_of_pass().copy()
        rows = self.out[row0:row1]                   # pinned: the fastest copy
        self.d_out[row0:row1].copy_to_host(rows)
        return np.array(rows), totals

    def stage_buffers(self):
        """Host buffers for render_rows_async: a pinned float32 H x W x 3 film and three
        pinned ray counts."""
        return (cuda.pinned_array((self.scene.height, self.scene.width, 3), np.float32),
                cuda.pinned_array(3, np.int64))

    def render_rows_async(self, sample_start, n_samples, seed, max_bounces, rr_depth, row0,
                          row1, active, stage):
        """render_rows without waiting for the GPU: the pass is launched, and the copies of
        rows [row0, row1) of its sums and of its ray counts into ``stage``
        (stage_buffers()) are queued behind it; returns a CUDA event that completes when
        they have landed. The next launch may follow at once (it waits on the GPU for the
        copies: they run on a stream of their own, which synchronises with the default
        stream that the kernels run on), so the GPU is not idle while the host takes an
        item's sums (a split render, pathtracer.distribute)."""
        if self._copies is None:
            self._copies = cuda.stream()
        film, totals = stage
        self.launch(sample_start, n_samples, seed, max_bounces, rr_depth, active)
        self._sum_totals()
        self._totals.copy_to_host(totals, stream=self._copies)
        self.d_out[row0:row1].copy_to_host(film[row0:row1], stream=self._copies)
        done = cuda.event(timing=False)
        done.record(stream=self._copies)
        return done

    def aovs(self, n_samples, seed):
        """The denoiser's albedo and normal images (float32 H x W x AOV_WIDTH, see aov_pixel)."""
        d = cuda.device_array((self.scene.height, self.scene.width, AOV_WIDTH), np.float32)
        aov_kernel(self.scene.features)[self.grid, self.block](d, n_samples, seed,
                                                               self.d_scene)
        return d.copy_to_host()

    def ptx(self):
        """PTX of the compiled pass kernel (to check for float64 instructions)."""
        mega = "\n".join(self.kernel.inspect_asm().values())
        if self.wavefront is not None:
            return self.wavefront.ptx() + "\n" + mega
        return mega

    def registers(self):
        """Registers per thread of the compiled pass kernel(s)."""
        regs = {str(k): v for k, v in self.kernel.get_regs_per_thread().items()}
        if self.wavefront is not None:
            regs = {"megakernel": v for v in regs.values()}
            if self.wave_min_paths == 0:    # the megakernel is not launched
                regs = {}
            regs.update(self.wavefront.registers())
        return regs
