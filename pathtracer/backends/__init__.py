"""Backends: thin launchers of the kernel drivers (kernels.drivers), each implementing the
protocol of :class:`.base.Backend`.

``cpu`` (``@njit``, rows on every core's thread), ``cuda`` (one thread per pixel) and
``python`` (the same code interpreted: slow, for debugging one pixel).
"""


import importlib.util


def cuda_available(simulator=False):
    """Is a CUDA GPU usable? Numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1) counts only
    with ``simulator``: ``auto`` never picks it, ``--backend cuda`` may use it."""
    import os
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return simulator
    try:
        from numba import cuda
        return bool(cuda.is_available())
    except Exception:
        return False


def make_backend(name, scene, **options):
    """Backend ``name`` ('auto', 'cpu', 'cuda' or 'python') for a compiled scene."""
    if name == "auto":
        name = "cuda" if cuda_available() else "cpu"
    if name == "cpu":
        from .cpu import CPUBackend
        return CPUBackend(scene, **options)
    if name == "cuda":
        if not cuda_available(simulator=True):
            if importlib.util.find_spec("numba_cuda") is None:
                raise RuntimeError("--backend cuda needs numba-cuda: pip install "
                                   "'pt-render[cuda]'")
            raise RuntimeError("--backend cuda: no CUDA GPU is available (numba.cuda finds none)")
        from .cuda import CUDABackend
        return CUDABackend(scene, **options)
    if name == "python":
        from .python import PythonBackend
        return PythonBackend(scene, **options)
    raise ValueError(f"unknown backend {name!r}")
