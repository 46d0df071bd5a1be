"""pathtracer.threads: the pool that runs compiled loops on every core (the CPU kernels'
rows, the BVH builder's subtrees)."""
import threading
import time

import pytest

from pathtracer import threads


def test_run_tasks_runs_every_task_once_on_several_threads():
    seen, names = [], set()
    lock = threading.Lock()

    def task(out, k):
        time.sleep(0.01)           # (long enough for the pool to use more than one thread)
        with lock:
            out.append(k)
            names.add(threading.current_thread().name)
    threads.run_tasks(task, (seen,), 9, 3)
    assert sorted(seen) == list(range(9))
    assert len(names) > 1
    seen.clear()
    threads.run_tasks(task, (seen,), 4, 1)                  # one thread: this one
    assert seen == [0, 1, 2, 3]


def test_a_tasks_error_is_raised_after_every_task_ended():
    done = []

    def task(k):
        if k == 0:
            raise ValueError("task 0")
        time.sleep(0.05)
        done.append(k)
    with pytest.raises(ValueError, match="task 0"):
        threads.run_tasks(task, (), 4, 4)
    assert sorted(done) == [1, 2, 3]       # join waited for the others before raising


def test_join_waits_through_an_interrupt_and_raises_it_after(monkeypatch):
    """Ctrl-C while the threads write into a pass's image: join waits for all of them,
    then raises KeyboardInterrupt (the image is complete when the CLI keeps it)."""
    calls = []
    real_wait = threads.concurrent.futures.wait

    def interrupted_once(futures):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real_wait(futures)
    monkeypatch.setattr(threads.concurrent.futures, "wait", interrupted_once)
    done = []
    futures = [threads.pool(2).submit(lambda: (time.sleep(0.05), done.append(1)))
               for _ in range(2)]
    with pytest.raises(KeyboardInterrupt):
        threads.join(futures)
    assert len(calls) == 2 and done == [1, 1]


def test_a_forked_child_gets_pools_of_its_own():
    """A process forked after the parent's pool ran work still runs tasks (the parent's
    pool threads do not exist in the child)."""
    import multiprocessing
    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork here")
    threads.run_tasks(lambda out, k: out.append(k), ([],), 4, 2)     # the parent's pool
    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_child_runs_tasks, args=(q,))
    p.start()
    p.join(60)
    alive = p.is_alive()
    if alive:
        p.kill()
    assert not alive and q.get(timeout=5) == [0, 1, 2, 3]


def _child_runs_tasks(q):
    seen = []
    lock = threading.Lock()

    def task(k):
        with lock:
            seen.append(k)
    threads.run_tasks(task, (), 4, 2)
    q.put(sorted(seen))
