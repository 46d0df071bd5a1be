"""The stateless RNG: fixed golden values, the same on every backend, and uniform."""
import numpy as np
from numba import njit

from pathtracer.kernels import rng as bits
from pathtracer.kernels.rng import path_key, pcg_hash, sample_1d
from tests.helpers import GOLDEN, golden_python_values as _python_values

# First values of the stream, pinned: a change here changes every image.


@njit(cache=True)
def _compiled(args):
    out = np.empty(len(args), np.float32)
    for i in range(len(args)):
        p, s, d, seed = args[i]
        out[i] = sample_1d(path_key(p, s, seed), d)
    return out


def _pcg_reference(v):
    """Jarzynski & Olano 2020, listing of pcg_hash, transcribed with Python ints
    (uint32 arithmetic made explicit with % 2**32)."""
    state = (v * 747796405 + 2891336453) % 2**32
    word = (((state >> ((state >> 28) + 4)) ^ state) * 277803737) % 2**32
    return (word >> 22) ^ word


def test_pcg_hash_matches_reference(rng):
    xs = [0, 1, 2**31, 2**32 - 1] + rng.integers(0, 2**32, 2000).tolist()
    for x in xs:
        assert int(pcg_hash(np.uint64(x))) == _pcg_reference(x)


def test_python_and_cpu_agree_bit_for_bit():
    py = np.array(_python_values(), np.float32)
    cpu = _compiled(np.array(GOLDEN, np.int64))
    assert np.array_equal(py, cpu)
    assert np.all((py >= 0) & (py < 1))
    assert len(set(py.tolist())) == len(py)


@njit(cache=True)
def _compiled_bits(xs, seeds):
    out = np.empty((len(xs), 8), np.uint64)
    for i in range(len(xs)):
        x = xs[i]
        out[i, 7] = bits.udiv32(x, seeds[i] | np.uint64(1))
        out[i, 0] = bits.pcg_hash(x)
        out[i, 1] = bits.reverse_bits(x)
        out[i, 2] = bits.lk_permutation(x, seeds[i])
        out[i, 3], out[i, 4], out[i, 5] = bits.sobol_digits(x)
        out[i, 6] = bits.owen_scramble(x, seeds[i])
    return out


def test_32_bit_ir_equals_the_python_bodies(rng):
    """The hashes (and udiv32, the wavefront's path numbering) compile to 32-bit LLVM IR
    (rng._ir32) and run as their plain Python bodies when interpreted: both must give every
    bit the same, at the edges of 32 bits too."""
    xs = np.array([0, 1, 2, 2**31, 2**32 - 1] + rng.integers(0, 2**32, 3000).tolist(),
                  np.uint64)
    seeds = np.array([2**32 - 1, 0, 7, 1, 2**31] + rng.integers(0, 2**32, 3000).tolist(),
                     np.uint64)
    got = _compiled_bits(xs, seeds)
    for i, (x, seed) in enumerate(zip(xs, seeds)):
        want = [bits.pcg_hash(x), bits.reverse_bits(x), bits.lk_permutation(x, seed),
                *bits.sobol_digits(x), bits.owen_scramble(x, seed),
                int(x) // (int(seed) | 1)]
        assert [int(v) for v in got[i]] == [int(v) for v in want], (int(x), int(seed))
    # known values: reverse_bits(2) = 2**30; the Sobol digits (reversed bit order) of
    # index 0: none; of index 1: 1/2 in each dimension; of index 2: 3/4
    assert int(got[2, 1]) == 2**30
    assert [int(v) for v in got[0, 3:6]] == [0, 0, 0]
    assert [int(v) for v in got[1, 3:6]] == [1, 1, 1]
    assert [int(v) for v in got[2, 3:6]] == [3, 3, 3]


def test_uniform_pairs_chi2():
    """Consecutive dimensions of many paths fill the unit square uniformly (chi-square on
    a 16x16 grid; p-value threshold 1e-4)."""
    from tests.helpers import chi2_sf
    n = 200_000
    keys = [path_key(i % 4096, i // 4096, 7) for i in range(0, n)]
    u = np.array([sample_1d(k, 4) for k in keys], np.float64)
    v = np.array([sample_1d(k, 5) for k in keys], np.float64)
    h, _, _ = np.histogram2d(u, v, bins=16, range=[[0, 1], [0, 1]])
    expected = n / 256
    stat = ((h - expected) ** 2 / expected).sum()
    assert chi2_sf(stat, 255) > 1e-4
    assert abs(np.corrcoef(u, v)[0, 1]) < 0.01
