"""Stateless counter-based random numbers, identical on every backend.

A sample is a pure function of (pixel, sample index, dimension, seed): nothing is stored
between calls, so CPU threads, CUDA threads and the interpreted backend all draw the same
stream, and any single path can be replayed alone (``--backend python --pixel``).

The hash is PCG's output permutation used as a hash (Jarzynski & Olano 2020, "Hash
Functions for GPU Rendering", JCGT 9(3)). Arithmetic is on uint64 holding 32-bit values,
masked after every step: compiled code and interpreted NumPy then agree bit for bit, and no
int64 operand sneaks in (int64 op uint64 is typed float64 by Numba).

Dimension layout of one path (as pbrt's IndependentSampler): 0-1 pixel position, 2-3 lens,
then DIMS_PER_BOUNCE consecutive dimensions per scattering event (see integrator).
"""
import numpy as np

from .device import device

M32 = np.uint64(0xFFFFFFFF)
_MUL = np.uint64(747796405)
_INC = np.uint64(2891336453)
_MUL2 = np.uint64(277803737)
_GOLDEN = np.uint64(0x9E3779B9)
_S4 = np.uint64(4)
_S8 = np.uint64(8)
_S22 = np.uint64(22)
_S28 = np.uint64(28)
_TO_UNIT = np.float32(1.0 / 16777216.0)


@device
def pcg_hash(x):
    """32-bit -> 32-bit hash; x is a uint64 below 2**32."""
    state = (x * _MUL + _INC) & M32
    word = (((state >> ((state >> _S28) + _S4)) ^ state) * _MUL2) & M32
    return (word >> _S22) ^ word


@device
def path_key(pixel, sample, seed):
    """Key of one camera path; pixel, sample and seed are non-negative integers < 2**32."""
    h = pcg_hash((pcg_hash(np.uint64(seed) & M32) + np.uint64(pixel)) & M32)
    return pcg_hash((h + np.uint64(sample)) & M32)


@device
def sample_1d(key, dim):
    """Uniform float32 in [0, 1) for dimension ``dim`` of the path with ``key``."""
    h = pcg_hash((key + np.uint64(dim) * _GOLDEN) & M32)
    return np.float32(h >> _S8) * _TO_UNIT
