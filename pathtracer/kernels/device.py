"""The markers for device functions.

``numba.extending.register_jitable`` makes a plain Python function callable from ``@njit``
and from ``@cuda.jit`` code (numba 0.68 + numba-cuda 0.30, checked on CPU, the CUDA
simulator and H100/H200), while the function stays an ordinary Python object that the
interpreted backend can call.

:func:`step_marker` marks the integrator's named steps (functions that take the scene's
arrays); the kernel factories take the target. On the CPU the steps are inlined at Numba's IR
level: LLVM does not inline functions that large,
and a call that passes a dozen arrays (each expanded to its data pointer, shape and
strides) and checks an error status cost a third of the Cornell box's CPU throughput when
the steps were first split out (measured with ``python -m bench.ab``). ``inline='always'``
breaks the CUDA target (as does a CPU-only inlined overload beside a generic one: typing
errors on H100), so for CUDA the steps are ordinary device functions.
"""
from numba.extending import register_jitable

# LLVM's fast-math flags that the compiled kernels use (CPU always; CUDA with fast=True,
# its default): every flag but nnan and ninf, as the kernels test for NaN and rely on IEEE
# infinities (the slab test divides by zero). On the CPU they let LLVM fuse multiplies and
# adds (FMA) and reorder sums: the Cornell box and the textured scene +5 % camera paths/s on
# 2 EPYC cores, bunny-studio and sun unchanged within the noise (docs/benchmarks.md).
# They change rounding, not the random numbers: CPU, GPU and interpreted images agree to
# rounding, not bit for bit.
FAST_MATH_FLAGS = frozenset({"nsz", "arcp", "contract", "afn", "reassoc"})


def device(fn):
    """Mark ``fn`` as device code shared by the CPU, CUDA and Python backends."""
    return register_jitable(fn)


def step_marker(target):
    """The marker of the integrator's named steps when compiling for ``target``: on the
    CPU inlined at Numba's IR level, elsewhere an ordinary device function."""
    if target == "cpu":
        return register_jitable(inline="always")
    return register_jitable


def entry_marker(target):
    """The marker of the per-pixel and per-sample functions that the backends call."""
    if target == "cpu":
        return register_jitable(_nrt=False)
    return register_jitable
