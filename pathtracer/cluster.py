"""Rendering on a Ray cluster (``pt-render --ray ADDRESS``; ``pip install -e .[cluster]``).

Ray (https://docs.ray.io) runs the workers: one actor per worker, each with a GPU when the
cluster has them (Ray sets ``CUDA_VISIBLE_DEVICES``), else a share of a node's CPUs (its
Numba threads set to that share). The driver (this process) runs the progressive loop,
the progress bar and the saves; :class:`~pathtracer.distribute.SplitBackend` sends the work
items. A scene goes into Ray's object store once (``ray.put``) and each node fetches it
once, whatever the number of items; the items carry a reference to it, so a restarted
actor fetches it again.

Fault tolerance is Ray's: actors are created with ``max_restarts=-1`` and
``max_task_retries=-1``, so when a worker dies (its process killed, its node lost) Ray
starts it again (on another node if need be) and re-runs the items it had in flight; an
item is a pure function of its arguments, so the re-run returns the same sums and the
image is the same.
"""
import os

from .errors import InputError

_pools = {}


def _ray():
    try:
        import ray
    except ImportError:
        raise InputError("--ray needs Ray: pip install -e '.[cluster]' (or pip install "
                         "ray)") from None
    return ray


def connect(address, num_cpus=None):
    """Join the cluster at ``address`` ('auto', 'ray://host:10001', 'host:6379'), or start
    a Ray runtime on this machine ('local')."""
    ray = _ray()
    if ray.is_initialized():
        return ray
    options = dict(include_dashboard=False, log_to_driver=False,
                   configure_logging=True, logging_level="ERROR")
    try:
        if address == "local":
            ray.init(num_cpus=num_cpus, **options)
        else:
            ray.init(address=address, **options)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise InputError(f"--ray {address}: cannot connect ({' '.join(str(e).split())[:300]})"
                         ) from None
    return ray


def _actor_class(ray):
    from .distribute import ItemRenderer

    class Worker(ItemRenderer):
        def __init__(self):
            from .backends import cuda_available
            super().__init__("cuda" if cuda_available() else "cpu",
                             fetch=lambda box: ray.get(box[0]))

        def pid(self):
            return os.getpid()

    return ray.remote(max_restarts=-1, max_task_retries=-1)(Worker)


class RayPool:
    """Ray actors as SplitBackend workers (same interface as distribute.ThreadPool)."""

    def __init__(self, address, workers=None):
        ray = self.ray = connect(address)
        res = ray.cluster_resources()
        gpus = int(res.get("GPU", 0))
        cpus = int(res.get("CPU", 1))
        if workers is None:
            workers = gpus if gpus else 1
        if workers < 1:
            raise InputError(f"--ray-workers must be at least 1, got {workers}")
        Worker = _actor_class(ray)
        if gpus >= workers:
            options = dict(num_gpus=1, num_cpus=1)
        else:
            # Numba's CPU threads: the worker's share of the CPUs, set in the environment
            # the worker process starts with (Numba reads it once its threads run)
            share = max(1, cpus // workers)
            options = dict(num_cpus=share,
                           runtime_env={"env_vars": {"NUMBA_NUM_THREADS": str(share)}})
        self.actors = [Worker.options(**options).remote() for _ in range(workers)]
        self.infos = ray.get([a.info.remote() for a in self.actors])
        self.label = f"Ray {address}: " + ", ".join(
            sorted({f"{i['device']}@{i['host']}" for i in self.infos}))
        self._refs = []

    def __len__(self):
        return len(self.actors)

    def submit(self, w, method, *args):
        return getattr(self.actors[w], method).remote(*args)

    def wait(self, handles):
        done, _ = self.ray.wait(handles, num_returns=1)
        return done

    def result(self, handle):
        return self.ray.get(handle)

    def box(self, scene):
        """The scene in the object store, once; the driver keeps the reference (a restarted
        actor reads it again). Inside a list, so that Ray hands the actor the reference and
        not the scene with every item."""
        ref = self.ray.put(scene)
        self._refs = [ref]
        return [ref]

    def pids(self):
        return self.ray.get([a.pid.remote() for a in self.actors])

    def close(self):
        for a in self.actors:
            self.ray.kill(a)
        self.actors = []


def pool(address, workers=None):
    """A pool for ``address`` and ``workers``, kept for the next render of this process
    (a batch of scenes reuses the actors and their compiled kernels)."""
    key = (address, workers)
    if key not in _pools:
        _pools[key] = RayPool(address, workers)
    return _pools[key]


def shutdown():
    for p in _pools.values():
        p.close()
    _pools.clear()
    ray = _ray()
    if ray.is_initialized():
        ray.shutdown()
