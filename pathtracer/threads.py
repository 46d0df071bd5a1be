"""Compiled work on every core through Python threads.

pt-render's compiled loops that run in parallel (the CPU kernels' rows, the BVH builder's
subtrees) are ``@njit(nogil=True)`` functions called from a pool of Python threads, not
``prange`` loops: Numba's parfor pass types a ``prange`` loop's body again and wraps it in
a gufunc and two wrappers, each of which LLVM optimises and emits on its own, which made a
CPU kernel's cold compile take ~1.4x as long (docs/benchmarks.md, "Compile time"). A
function compiled with ``nogil=True`` releases the GIL while it runs, so the threads run
it in parallel as Numba's own would.
"""
import concurrent.futures
import os
import threading

_pools = {}
_pools_lock = threading.Lock()


def pool(workers):
    """A thread pool of ``workers`` threads (one per count, kept for the process; keyed by
    the process too: a child forked after a pool was made has none of its threads, and
    work queued there would never run)."""
    key = (os.getpid(), workers)
    with _pools_lock:
        if key not in _pools:
            _pools[key] = concurrent.futures.ThreadPoolExecutor(
                workers, thread_name_prefix="pt-render")
        return _pools[key]


def join(futures):
    """Wait for every future, also through Ctrl-C (re-raised after they are done): the
    threads write into arrays that are read only when all of them have finished. A
    thread's error is raised here."""
    interrupted = None
    while True:
        try:
            concurrent.futures.wait(futures)
            break
        except KeyboardInterrupt as e:
            interrupted = e
    if interrupted is not None:
        raise interrupted
    for f in futures:
        f.result()


def run_tasks(fn, args, n_tasks, threads):
    """``fn(*args, k)`` for k in range(n_tasks) on at most ``threads`` threads (in this
    thread alone when there is one task or one thread)."""
    if n_tasks <= 1 or threads <= 1:
        for k in range(n_tasks):
            fn(*args, k)
        return
    executor = pool(min(threads, n_tasks))
    join([executor.submit(fn, *args, k) for k in range(n_tasks)])
