"""The one marker for device functions.

``numba.extending.register_jitable`` makes a plain Python function callable from ``@njit``
and from ``@cuda.jit`` code (numba 0.68 + numba-cuda 0.30, checked on CPU, the CUDA
simulator and H100/H200), while the function stays an ordinary Python object that the
interpreted backend can call. ``inline='always'`` would break the CUDA target, so it is
never used.
"""
from numba.extending import register_jitable


def device(fn):
    """Mark ``fn`` as device code shared by the CPU, CUDA and Python backends."""
    return register_jitable(fn)
