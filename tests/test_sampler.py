"""The sobol sampler (Owen-scrambled Sobol, kernels.rng): the generator matrices, bit-identical
numbers on every backend, stratification at every power of two, independence between pixels
and between dimension sets, and the same image in expectation as the independent sampler."""
import numpy as np
import pytest
from numba import njit

from pathtracer.kernels.layout import (D_BSDF_U, D_FIRST_BOUNCE, D_LIGHT_U, D_PIXEL_X,
                                       DIMS_PER_BOUNCE)
from pathtracer.kernels.rng import (SOBOL_MATRIX, owen_scramble, pixel_key, reverse_bits,
                                    sample_sobol, sobol_component, sobol_set)
from tests.helpers import GOLDEN_SOBOL, chi2_sf, golden_sobol_python_values

# Sobol's first four dimensions, points 0-7 in natural (not Gray-code) order: Joe & Kuo's
# direction numbers (checked against scipy.stats.qmc.Sobol, which lists them in Gray-code
# order: its point n is point n ^ (n >> 1) here).
SOBOL_POINTS = [(0, 0, 0, 0), (.5, .5, .5, .5), (.25, .75, .75, .75), (.75, .25, .25, .25),
                (.125, .625, .375, .125), (.625, .125, .875, .625),
                (.375, .375, .625, .875), (.875, .875, .125, .375)]

# pinned: a change here changes every image rendered with the default sampler
GOLDEN_SOBOL_VALUES = [0.4329643249511719, 0.5619768500328064, 0.3212229609489441,
                       0.6028839349746704, 0.7962217330932617, 0.7142672538757324,
                       0.7956764101982117, 0.11827963590621948, 0.9471274018287659]


def _sobol_point(i, d):
    x = 0
    for k in range(32):
        if (i >> k) & 1:
            x ^= int(SOBOL_MATRIX[d, k])
    return x / 2**32


def test_sobol_matrices_give_the_published_points():
    for i, point in enumerate(SOBOL_POINTS):
        assert tuple(_sobol_point(i, d) for d in range(4)) == point
    # every direction number v_k = m_k / 2**(k+1) with m_k odd: bit 31 - k set, none below
    # (a triangular generator matrix with unit diagonal, what makes each dimension a
    # (0, 1)-sequence)
    for d in range(4):
        for k in range(32):
            v = int(SOBOL_MATRIX[d, k])
            assert (v >> (31 - k)) & 1 == 1 and v & ((1 << (31 - k)) - 1) == 0


def test_owen_scramble_is_a_nested_permutation(rng):
    """An Owen scramble permutes [0, 2**32) such that numbers sharing their top b bits still
    share them after (each subtree of the binary expansion maps onto one subtree)."""
    for seed in rng.integers(0, 2**32, 20):
        seed = np.uint64(seed)
        xs = rng.integers(0, 2**32, 200)
        for x in xs:
            y = int(owen_scramble(np.uint64(x), seed))
            for b in (1, 5, 17):
                x2 = (int(x) & ~((1 << (32 - b)) - 1)) | int(rng.integers(0, 2**(32 - b)))
                y2 = int(owen_scramble(np.uint64(x2), seed))
                assert y >> (32 - b) == y2 >> (32 - b)
        # a permutation: on 2**12 numbers with random low bits, no two collide
        block = [int(owen_scramble(np.uint64(v << 20), seed)) >> 20 for v in range(4096)]
        assert sorted(block) == list(range(4096))
    assert int(reverse_bits(np.uint64(1))) == 2**31
    assert int(reverse_bits(np.uint64(0x12345678))) == int(f"{0x12345678:032b}"[::-1], 2)


@njit(cache=True)
def _compiled_golden(args):
    out = np.empty(len(args), np.float32)
    for i in range(len(args)):
        out[i] = sample_sobol(np.uint64(args[i, 0]), args[i, 1], args[i, 2])
    return out


def test_sobol_python_and_cpu_agree_bit_for_bit():
    py = np.array(golden_sobol_python_values(), np.float32)
    cpu = _compiled_golden(np.array(GOLDEN_SOBOL, np.int64))
    assert np.array_equal(py, cpu)
    assert np.array_equal(py, np.array(GOLDEN_SOBOL_VALUES, np.float32))


@njit(cache=True)
def _points(pixel, seed, first, n, dset):
    """n samples from sample index ``first`` of dimension set ``dset``: (n, 4) float64."""
    out = np.empty((n, 4))
    pix = pixel_key(pixel, seed)
    for i in range(n):
        s = sobol_set(pix, reverse_bits(np.uint64(first + i)), dset)
        for c in range(4):
            out[i, c] = sobol_component(s, c)
    return out


def _is_net(x, y, m):
    """Whether the 2**m points (x, y) are a (0, m, 2)-net: one point in every elementary
    interval [a/2^k, (a+1)/2^k) x [b/2^(m-k), (b+1)/2^(m-k))."""
    for k in range(m + 1):
        cells = (np.floor(x * 2**k).astype(np.int64) * 2**(m - k) +
                 np.floor(y * 2**(m - k)).astype(np.int64))
        if len(np.unique(cells)) != 2**m:
            return False
    return True


SETS = [D_PIXEL_X // 4, (D_FIRST_BOUNCE + D_LIGHT_U) // 4, (D_FIRST_BOUNCE + D_BSDF_U) // 4,
        (D_FIRST_BOUNCE + 7 * DIMS_PER_BOUNCE + D_BSDF_U) // 4, 4000]


@pytest.mark.parametrize("dset", SETS)
def test_every_power_of_two_is_stratified(dset):
    """The first two dimensions of every set are a (0, m, 2)-net for each block of 2**m
    samples (the first 2**m and the next), every dimension alone one point per 1/2**m
    stratum: so an image at any power-of-two spp, rendered in passes of any size, is
    stratified in every pixel."""
    for pixel in (0, 1, 777, 65535):
        for m in range(1, 9):
            for first in (0, 2**m):
                p = _points(pixel, 3, first, 2**m, dset)
                assert _is_net(p[:, 0], p[:, 1], m), (pixel, m, first)
                for c in range(4):
                    assert len(np.unique(np.floor(p[:, c] * 2**m))) == 2**m
    # and the independent sampler is not (the check can fail)
    u = np.random.default_rng(1).random((64, 2))
    assert not _is_net(u[:, 0], u[:, 1], 6)


@njit(cache=True)
def _pairs(n_pixels, n_samples, set_a, comp_a, set_b, comp_b, pixel_step):
    out = np.empty((n_pixels * n_samples, 2))
    k = 0
    for p in range(n_pixels):
        pa = pixel_key(p, 11)
        pb = pixel_key(p + pixel_step, 11)
        for i in range(n_samples):
            out[k, 0] = sobol_component(sobol_set(pa, reverse_bits(np.uint64(i)), set_a), comp_a)
            out[k, 1] = sobol_component(sobol_set(pb, reverse_bits(np.uint64(i)), set_b), comp_b)
            k += 1
    return out


@pytest.mark.parametrize("what", ["sets", "dimensions", "pixels", "bounces"])
def test_independent_across_sets_dimensions_and_pixels(what):
    """What the stratification does not couple is independent: the same sample's numbers in
    two sets (padding), two dimensions of one set's pairs beyond the net, and neighbouring
    pixels; chi-square on a 16 x 16 grid over 4096 pixels x 16 samples (p > 1e-4)."""
    args = {"sets": (1, 0, 2, 0, 0), "dimensions": (2, 1, 2, 2, 0),
            "pixels": (0, 0, 0, 0, 1), "bounces": (2, 0, 4, 0, 0)}[what]
    xy = _pairs(4096, 16, *args)
    h, _, _ = np.histogram2d(xy[:, 0], xy[:, 1], bins=16, range=[[0, 1], [0, 1]])
    expected = len(xy) / 256
    stat = ((h - expected) ** 2 / expected).sum()
    assert chi2_sf(stat, 255) > 1e-4
    assert abs(np.corrcoef(xy[:, 0], xy[:, 1])[0, 1]) < 0.02
