"""One render spread over several devices: the GPUs of this machine (``--devices``) or the
workers of a Ray cluster (``--ray``, :mod:`pathtracer.cluster`).

A pass of the progressive loop (samples [s, s + n) of every pixel) is cut into *work
items*, each a range of image rows and a range of samples. A worker renders an item with
an ordinary backend (the rows outside it masked off) and returns the item's sums (float32,
its rows only) and its ray counts; the driver adds the items **in item order** into a
float64 pass, which the film adds like a one-device pass. Every sample is a pure function
of (pixel, sample index, seed) (:mod:`pathtracer.kernels.rng`), so which worker renders an
item changes nothing, and a split render is the same image whatever the load balance:
it differs from a one-device render only in how the float32 pass sums are rounded (each
item is summed on its own), by a few float32 ulps per pixel (tests/test_distribute.py
states and checks the tolerance).

:class:`SplitBackend` has a backend's interface (``render_pass``, ``compile``, ``update``,
``aovs``), so progressive saves, the progress bar, time budgets, adaptive sampling and
resume work unchanged. Load balance is dynamic: every worker keeps two items in flight and
takes the next one when one returns, so a slow or busy device takes fewer.

Workers are driven through a *pool* with ``submit(worker, method, *args)`` and
``wait(handles)``: :class:`ThreadPool` runs one thread per local device (a CUDA context
is current per thread, so each GPU's backend lives in its own thread); the Ray pool
(:mod:`pathtracer.cluster`) runs one actor per worker. Both call the same
:class:`ItemRenderer`.
"""
import dataclasses
import itertools
import os
import queue
import threading
import time
import weakref
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor
from concurrent.futures import wait as wait_futures
from typing import NamedTuple

import numpy as np

from .backends.base import FIRST_PASS_PATHS, Backend

# Items per worker and pass: enough that the last item of a pass (when the other workers
# may wait) is a small part of it, few enough that each item still fills a GPU...
ITEMS_PER_WORKER = 4
# ... and no shorter than this (estimated from the last pass's speed): each item costs a
# launch, a copy and the driver's sum (~1-5 ms), so the short first passes of a render
# (1, 2, 4 spp) are cut into fewer items.
MIN_ITEM_SECONDS = 0.1
IN_FLIGHT = 2            # items queued on each worker, so that it never waits for the driver
# Pinned buffers per local GPU that an item's sums are copied into: the GPU's thread
# launches the next item while another thread converts the last one to float64 (see
# ThreadPool); two let the copy of one item overlap the conversion of the one before.
STAGES = 2
# A pass of a split render aims at this many seconds: longer than one device's passes,
# so that the per-pass synchronisation of the workers costs little.
PASS_SECONDS = 1.0
# Arrays that change between renders of one scene (the camera row narrowed for the spp)
# travel with every item when smaller than this; larger changes ship the scene again.
PATCH_BYTES = 1 << 16


class WorkItem(NamedTuple):
    """Rows [row0, row1) and samples [sample0, sample0 + n) of every pixel in them."""
    row0: int
    row1: int
    sample0: int
    n: int


def split_pass(height, sample_start, n_samples, parts):
    """The work items of a pass: about ``parts`` of them, cut by samples first (each item a
    whole image, which fills a GPU), and by rows too when the pass has fewer samples than
    parts (the first passes of 1, 2, 4 spp). Together they cover every (row, sample) of the
    pass exactly once, in a fixed order."""
    if n_samples <= 0:
        return [WorkItem(0, height, sample_start, 0)]
    chunks = max(1, min(n_samples, parts))
    bands = max(1, min(height, -(-parts // chunks)))
    items = []
    for c in range(chunks):
        s0 = sample_start + n_samples * c // chunks
        s1 = sample_start + n_samples * (c + 1) // chunks
        for b in range(bands):
            items.append(WorkItem(height * b // bands, height * (b + 1) // bands, s0, s1 - s0))
    return items


def shippable(scene):
    """The part of a compiled scene a worker needs (arrays, features, size, settings),
    without the description it was compiled from."""
    return dataclasses.replace(scene, description=None, warnings=[], timings={})


class ItemRenderer:
    """A worker's side: the backend of its current scene, rendering work items. ``fetch(box)``
    turns the scene box a driver sends into the scene (Ray: the object-store reference is
    read once per scene, not per item)."""

    def __init__(self, backend_name, device=None, fetch=None):
        self.backend_name = backend_name
        self.device = device
        self.fetch = fetch or (lambda box: box[0])
        self.kind = None
        self.scene_key = None
        self.base = None
        self.patch_key = None
        self.backend = None
        self.stages = {}         # stage number -> pinned (sums, counts) (render's ``stage``)
        if device is not None:
            from numba import cuda
            cuda.select_device(device)

    def _use(self, scene_key, box, patch_key, patch):
        if scene_key != self.scene_key:
            self.base = self.fetch(box)
            self.scene_key = scene_key
            self.patch_key = None
        if patch_key != self.patch_key:
            scene = self.base
            if patch:
                scene = dataclasses.replace(scene, arrays=scene.arrays._replace(**patch))
            kind = (scene.features, scene.width, scene.height)
            if self.backend is None or self.kind != kind:
                # one backend at a time: a kept pool (a batch) does not hold every earlier
                # scene's arrays (the compiled kernels stay cached per feature set)
                from .backends import make_backend
                self.backend = None
                self.backend = make_backend(self.backend_name, scene)
                self.kind = kind
            elif self.backend.scene is not scene:
                self.backend.update(scene)
            self.patch_key = patch_key
        return self.backend

    def info(self):
        """What this worker is (for the log)."""
        import socket
        name = self.backend_name
        if self.device is not None:
            name += f":{self.device}"
        elif self.backend_name == "cuda":
            from numba import cuda
            name += f" ({cuda.get_current_device().name.decode()})"
        return {"host": socket.gethostname(), "pid": os.getpid(), "device": name}

    def compile(self, scene_key, box, patch_key, patch):
        t0 = time.perf_counter()
        self._use(scene_key, box, patch_key, patch).compile()
        return time.perf_counter() - t0

    def render(self, scene_key, box, patch_key, patch, item, seed, max_bounces, rr_depth,
               active_rows=None, stage=None):
        """The item's sums (float32 rows x width x 3) and ray counts (int64, 3). ``stage``
        (CUDA): the item is launched without waiting for it, its sums and counts are
        copied into this worker's pinned buffers of that number, and the result is
        (event, sums, counts): views of the buffers, filled once the CUDA event has
        completed, and valid until the same stage is used again."""
        backend = self._use(scene_key, box, patch_key, patch)
        h = backend.scene.height
        r0, r1 = item.row0, item.row1
        mask = None
        if (r0, r1) != (0, h) or active_rows is not None:
            mask = np.zeros((h, backend.scene.width), np.uint8)
            mask[r0:r1] = 1 if active_rows is None else active_rows
        if hasattr(backend, "render_rows"):       # CUDA: counts summed on the GPU
            if stage is None:
                return backend.render_rows(item.sample0, item.n, seed, max_bounces,
                                           rr_depth, r0, r1, mask)
            buffers = self.stages.get(stage)
            if buffers is None or buffers[0].shape != (h, backend.scene.width, 3):
                buffers = self.stages[stage] = backend.stage_buffers()
            done = backend.render_rows_async(item.sample0, item.n, seed, max_bounces,
                                             rr_depth, r0, r1, mask, buffers)
            return done, buffers[0][r0:r1], buffers[1]
        out, stats = backend.render_pass(item.sample0, item.n, seed, max_bounces, rr_depth,
                                         mask)
        # (one channel at a time: a strided reduction over the last axis is much slower)
        return (np.array(out[r0:r1], np.float32),
                np.array([stats[r0:r1, :, c].sum(dtype=np.int64) for c in range(3)]))

    def aovs(self, scene_key, box, patch_key, patch, n_samples, seed):
        return self._use(scene_key, box, patch_key, patch).aovs(n_samples, seed)


def _select_device(device):
    """A converter thread's initializer: the GPU's context current (to wait for its
    events)."""
    if device is not None:
        from numba import cuda
        cuda.select_device(device)


class ThreadPool:
    """Local workers, one thread each (every GPU's CUDA context and backend live in its
    thread). CPU workers take turns (a CPU backend already uses every core, and Numba's
    default threading layer runs one parallel region at a time): they serve tests of the
    split itself, not speed.

    A GPU worker's item runs in two steps: its thread launches the item, with the copies
    of its sums and ray counts into a pinned stage buffer queued behind it on the GPU, and
    takes the next item at once; a second thread of that worker waits for the copies and
    converts the sums to the float64 array the driver adds (NumPy releases the GIL). The
    GPU so always has the next item queued: the waits for an item's end, its copies and
    conversion (~5 ms for a 1024^2 image) used to sit between two of its launches
    (docs/benchmarks.md, "Two GPUs")."""

    def __init__(self, kinds):
        """``kinds``: one (backend name, CUDA device or None) per worker."""
        self.kinds = list(kinds)
        self.executors = [ThreadPoolExecutor(1, thread_name_prefix=f"pt-render-device{i}")
                          for i in range(len(self.kinds))]
        self.converters = [ThreadPoolExecutor(1, thread_name_prefix=f"pt-render-sums{i}",
                                              initializer=_select_device,
                                              initargs=(device,))
                           if name == "cuda" else None
                           for i, (name, device) in enumerate(self.kinds)]
        # per worker, the numbers of its stage buffers not in use (ItemRenderer.stages)
        self.free_stages = [queue.SimpleQueue() for _ in self.kinds]
        for q in self.free_stages:
            for k in range(STAGES):
                q.put(k)
        self.cpu_lock = threading.Lock()
        self.closed = False
        self.workers = [ex.submit(ItemRenderer, name, device).result()
                        for ex, (name, device) in zip(self.executors, self.kinds)]
        self.label = ", ".join(f"{n}:{d}" if d is not None else n for n, d in self.kinds)
        if any(name == "cuda" for name, _ in self.kinds):
            _hold_at_exit(self)

    # Workers compile one after another (SplitBackend.compile): a worker's compile
    # launches every kernel a render uses, which loads them into its GPU's context; two
    # threads loading the same Numba kernels into two contexts at once is not known to be
    # safe in numba-cuda, and this order is the one tested on two GPUs. Its cost was not
    # measurable: the split's compile after a one-GPU render of the scene took 0.041 /
    # 0.052 s in this order and 0.047 / 0.055 s at once (Cornell / bunny-studio, two
    # H200s, bench/results/distributed-gpus-h200x2*.json, 2026-11-26).
    one_at_a_time = True

    def __len__(self):
        return len(self.workers)

    def _render_staged(self, w, args):
        """A GPU item in two steps (see the class's docstring): a future of (float64 sums,
        counts)."""
        done = Future()
        worker, stages, converter = self.workers[w], self.free_stages[w], self.converters[w]

        def on_gpu():
            stage = stages.get()             # waits while both stages are being converted
            try:
                copied, sums, counts = worker.render(*args, stage=stage)
            except BaseException as e:
                stages.put(stage)
                done.set_exception(e)
                return

            def convert():
                try:
                    copied.synchronize()
                    done.set_result((sums.astype(np.float64), counts.copy()))
                except BaseException as e:
                    done.set_exception(e)
                finally:
                    stages.put(stage)
            converter.submit(convert)
        self.executors[w].submit(on_gpu)
        return done

    def submit(self, w, method, *args):
        worker = self.workers[w]
        if self.kinds[w][0] == "cuda":
            if method == "render":
                return self._render_staged(w, args)
            return self.executors[w].submit(getattr(worker, method), *args)

        def locked():
            with self.cpu_lock:
                return getattr(worker, method)(*args)
        return self.executors[w].submit(locked)

    def wait(self, handles):
        done, _ = wait_futures(handles, return_when=FIRST_COMPLETED)
        return done

    def result(self, handle):
        return handle.result()

    def box(self, scene):
        return [scene]

    def close(self):
        """End the threads, after the work queued on them (the GPU threads first: they
        hand conversions on)."""
        if self.closed:
            return
        self.closed = True
        for ex in self.executors:
            ex.shutdown(wait=True)
        for c in self.converters:
            if c is not None:
                c.shutdown(wait=True)


# Pools whose GPUs' deallocations are held at the interpreter's exit
_gpu_pools = weakref.WeakSet()
_exit_hook = []      # (one entry once the hook is registered)
# The holds entered at exit: kept alive, as a hold collected as garbage would end itself
_held = []


def _hold_this_context():
    """Hold this thread's context's pending deallocations: Numba then only queues the
    frees and module unloads that finalizers ask for."""
    from numba import cuda
    cuda.synchronize()
    held = cuda.current_context().deallocations.disable()
    held.__enter__()            # (never left: the process is exiting)
    _held.append(held)


def _hold_gpu_deallocations():
    """At the interpreter's exit, before the workers' threads are joined: each GPU's
    context stops freeing (its pending deallocations held), and the process's exit gives
    the driver's resources back. After a split render over two H200s, Numba's
    exit-time finalizers unloading the kernels' modules aborted the process ("double
    free or corruption") or crashed it, whatever context was current and also from the
    worker's own thread with its context reset there (numba-cuda 0.30.4, 2026-11-26;
    tests/test_gpu.py). Only at exit: a GPU's context is shared with every other thread
    that uses that GPU."""
    done = set()
    for pool in list(_gpu_pools):
        for (name, device), ex in zip(pool.kinds, pool.executors):
            if name != "cuda" or device in done:
                continue
            done.add(device)
            try:
                if not pool.closed:
                    ex.submit(_hold_this_context).result()
                else:   # (its threads have ended: the device's context, from this one)
                    from numba import cuda
                    with cuda.gpus[device]:
                        _hold_this_context()
            except Exception:      # (a worker broken, a device gone: nothing to save)
                pass


def _hold_at_exit(pool):
    """Register _hold_gpu_deallocations (once) with the hook that concurrent.futures itself
    uses: threading's exit hooks run last-in first-out before the threads are joined, so
    the workers' threads still take work."""
    if not _exit_hook:
        _exit_hook.append(_hold_gpu_deallocations)
        register = getattr(threading, "_register_atexit", None)
        if register is not None:
            try:
                register(_hold_gpu_deallocations)
            except RuntimeError:      # (called during the interpreter's exit)
                pass
    _gpu_pools.add(pool)


def _same(a, b):
    return a is b or (a.shape == b.shape and a.dtype == b.dtype and
                      np.array_equal(a.reshape(-1).view(np.uint8), b.reshape(-1).view(np.uint8)))


# Scene keys, unique in this process: workers (a Ray pool outlives a backend: a batch of
# scenes) recognise the scene they hold by its key.
_scene_keys = itertools.count(1)


class SplitBackend(Backend):
    """A backend that renders each pass on all workers of ``pool`` (see the module's
    docstring). ``name``: the workers' backend kind; ``pass_seconds``: what the
    progressive loop aims a pass at."""
    pass_seconds = PASS_SECONDS

    def __init__(self, scene, pool, name, items_per_worker=ITEMS_PER_WORKER):
        self.pool = pool
        self.name = name
        self.items_per_worker = items_per_worker
        self.scene = None
        self._key = None
        self._ship(scene)
        self.items_done = [0] * len(pool)      # samples x rows each worker rendered
        self.compile_seconds = []
        self.rate = None                        # pixel samples per second, all workers
        self._total = None                      # the pass sums, reused (see render_pass)

    def _ship(self, scene):
        self._key = (os.getpid(), next(_scene_keys))
        self.base = scene
        self.box = self.pool.box(shippable(scene))
        self.patch = {}
        self.patch_key = 0
        self.scene = scene

    def _args(self):
        return (self._key, self.box, self.patch_key, self.patch)

    def update(self, scene):
        """Render ``scene`` from now on: arrays that differ from the shipped scene travel
        with the items when small (the camera row of ``for_spp``), else the scene is
        shipped again."""
        base = self.base
        if (scene.features, scene.width, scene.height) == (base.features, base.width,
                                                           base.height):
            patch = {f: a for f, a, b in zip(scene.arrays._fields, scene.arrays, base.arrays)
                     if not _same(a, b)}
            if sum(a.nbytes for a in patch.values()) <= PATCH_BYTES:
                self.patch = patch
                self.patch_key += 1
                self.scene = scene
                return
        self._ship(scene)

    @property
    def label(self):
        return f"{len(self.pool)} workers ({self.pool.label})"

    def compile(self):
        """Compile (or load from the disk cache) the kernels on every worker: at once, or
        one worker after another where the pool asks for it (``pool.one_at_a_time``: the
        GPUs of this process, see ThreadPool)."""
        n = len(self.pool)
        if getattr(self.pool, "one_at_a_time", False):
            self.compile_seconds = [self.pool.result(self.pool.submit(w, "compile",
                                                                      *self._args()))
                                    for w in range(n)]
            return
        handles = [self.pool.submit(w, "compile", *self._args()) for w in range(n)]
        self.compile_seconds = [self.pool.result(h) for h in handles]

    def aovs(self, n_samples, seed):
        return self.pool.result(self.pool.submit(0, "aovs", *self._args(), n_samples, seed))

    @property
    def first_pass_paths(self):
        """Paths a first pass may take when nobody sees the intermediate images (see
        api.render): every worker's share, as for one device of its kind."""
        return FIRST_PASS_PATHS.get(self.name, 0) * len(self.pool)

    def render_pass(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None):
        """The pass's sums (float64 H x W x 3: a buffer reused by the next pass, as the
        CUDA backend's is, or the first item's array) and ray counts (1 x 1 x 3)."""
        h, w = self.scene.height, self.scene.width
        workers = len(self.pool)
        per_worker = 1
        if self.rate:
            seconds = n_samples * h * w / self.rate / workers
            per_worker = int(min(self.items_per_worker, max(1, seconds / MIN_ITEM_SECONDS)))
        items = split_pass(h, sample_start, n_samples, per_worker * workers)
        t0 = time.perf_counter()
        total = None
        # The first items cut by rows (one sample chunk) cover every row once: they are
        # copied, not added to zeros (0 + x is x: the same sums, without a 24 MB fill per
        # pass of a 1024^2 image); a first item of every row that is already float64 (a
        # GPU worker's, converted in its thread) becomes the pass's sums, not copied.
        first_chunk = sum(1 for it in items if it.sample0 == items[0].sample0)
        stats = np.zeros(3, np.int64)
        args = self._args()
        todo = list(range(len(items)))[::-1]       # popped from the end: item order
        flying = {}                                 # handle -> (worker, item index)
        load = [0] * len(self.pool)
        results = {}
        added = 0

        def feed():     # round robin: every worker gets an item before any gets two
            for wk in [wk for depth in range(IN_FLIGHT) for wk in range(workers)
                       if load[wk] <= depth]:
                if todo and load[wk] < IN_FLIGHT:
                    i = todo.pop()
                    it = items[i]
                    rows = None if active is None else active[it.row0:it.row1]
                    handle = self.pool.submit(wk, "render", *args, it, seed, max_bounces,
                                              rr_depth, rows)
                    flying[handle] = (wk, i)
                    load[wk] += 1
        feed()
        while flying:
            for handle in self.pool.wait(list(flying)):
                wk, i = flying.pop(handle)
                load[wk] -= 1
                results[i] = self.pool.result(handle)
                it = items[i]
                self.items_done[wk] += it.n * (it.row1 - it.row0)
            feed()
            while added in results:                 # in item order: a fixed rounding
                it = items[added]
                sums, counts = results.pop(added)
                if first_chunk == 1 and added == 0 and sums.dtype == np.float64 and \
                        sums.shape == (h, w, 3):
                    total = sums
                elif added < first_chunk:
                    if total is None:
                        if self._total is None or self._total.shape != (h, w, 3):
                            self._total = np.empty((h, w, 3), np.float64)
                        total = self._total
                    total[it.row0:it.row1] = sums
                else:
                    total[it.row0:it.row1] += sums
                stats += counts
                added += 1
        if active is None and n_samples > 0:
            self.rate = n_samples * h * w / max(time.perf_counter() - t0, 1e-9)
        return total, stats.reshape(1, 1, 3)

    def shares(self):
        """Each worker's share of the samples rendered so far."""
        total = sum(self.items_done) or 1
        return [d / total for d in self.items_done]


def local_devices(spec):
    """CUDA device numbers for ``--devices`` ('all' or '0,1,...'), checked against the
    GPUs present."""
    from numba import cuda
    from .errors import InputError
    try:
        present = len(cuda.gpus)
    except Exception:
        present = 0
    if present == 0:
        raise InputError("--devices: no CUDA GPU is available (numba.cuda finds none)")
    if spec.strip().lower() == "all":
        return list(range(present))
    try:
        ids = [int(x, 10) for x in spec.split(",")]
    except ValueError:
        raise InputError(f"--devices: expected 'all' or GPU numbers such as 0,1; got "
                         f"{spec!r}") from None
    bad = [i for i in ids if not 0 <= i < present]
    if bad or len(set(ids)) != len(ids):
        raise InputError(f"--devices {spec}: this machine has GPUs 0..{present - 1}, each "
                         "at most once")
    return ids
