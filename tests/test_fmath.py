"""The kernels' float32 floor, atan2 and acos (kernels.fmath), compiled and interpreted,
against NumPy in float64; fract against Python's float modulo."""
import math

import numpy as np
from numba import njit

from pathtracer.kernels.device import FAST_MATH_FLAGS
from pathtracer.kernels.fmath import acos_f32, atan2_f32, floor_int, fract
from pathtracer.kernels.layout import WRAP_MIRROR
from pathtracer.kernels.textures import wrap_coordinate


@njit(fastmath=set(FAST_MATH_FLAGS), cache=True)
def _compiled(ys, xs, atan2_out, acos_out, floor_out):
    for i in range(ys.shape[0]):
        atan2_out[i] = atan2_f32(ys[i], xs[i])
        acos_out[i] = acos_f32(min(max(ys[i], np.float32(-1.0)), np.float32(1.0)))
        floor_out[i] = floor_int(xs[i])


def _inputs(rng):
    n = 100_000
    ys = np.concatenate([rng.uniform(-1, 1, n), rng.standard_normal(n) * 1e-3,
                         rng.standard_normal(n) * 1e3,
                         [0, 0, 1, -1, 0.5, -0.5, 1e-30, -1e-30, 0.999999, -0.999999, 3,
                          0]])
    xs = np.concatenate([rng.uniform(-1, 1, n), rng.standard_normal(n),
                         rng.standard_normal(n),
                         [1, -1, 0, 0, 0.5, -2, -1, -1, 1e-20, 5, -2.5, 0]])
    return ys.astype(np.float32), xs.astype(np.float32)


def _ulps(got, ref):
    """|got - ref| in float32 ulps of the reference (float64)."""
    spacing = np.spacing(np.maximum(np.abs(ref), np.float32(1e-30)).astype(np.float32))
    return np.abs(got.astype(np.float64) - ref) / spacing


def test_compiled_forms_match_numpy(rng):
    ys, xs = _inputs(rng)
    a, c = np.zeros_like(ys), np.zeros_like(ys)
    f = np.zeros(ys.shape, np.int64)
    _compiled(ys, xs, a, c, f)
    y64, x64 = ys.astype(np.float64), xs.astype(np.float64)
    assert _ulps(a, np.arctan2(y64, x64)).max() <= 4
    assert _ulps(c, np.arccos(np.clip(y64, -1, 1))).max() <= 4
    np.testing.assert_array_equal(f, np.floor(xs).astype(np.int64))


def test_interpreted_forms_agree_with_the_compiled_ones(rng):
    ys, xs = _inputs(rng)
    a, c = np.zeros_like(ys), np.zeros_like(ys)
    f = np.zeros(ys.shape, np.int64)
    _compiled(ys, xs, a, c, f)
    for i in range(0, ys.shape[0], 997):
        y, x = ys[i], xs[i]
        assert abs(float(atan2_f32(y, x)) - float(a[i])) <= 4e-7 * max(1.0, abs(float(a[i])))
        assert abs(float(acos_f32(np.float32(min(max(y, -1), 1)))) - float(c[i])) <= 1e-6
        assert floor_int(x) == f[i] == math.floor(x)


def test_edge_cases():
    assert atan2_f32(np.float32(0), np.float32(0)) == 0
    assert atan2_f32(np.float32(0), np.float32(-1)) == np.float32(np.pi)
    assert atan2_f32(np.float32(1), np.float32(0)) == np.float32(np.pi / 2)
    assert atan2_f32(np.float32(-1), np.float32(0)) == -np.float32(np.pi / 2)
    assert acos_f32(np.float32(1)) == 0
    assert acos_f32(np.float32(-1)) == np.float32(np.pi)
    assert acos_f32(np.float32(0)) == np.float32(np.pi / 2)


@njit(cache=True)
def _fract_compiled(xs, out, mirror):
    for i in range(xs.shape[0]):
        out[i] = fract(xs[i])
        mirror[i] = wrap_coordinate(xs[i], WRAP_MIRROR)


def test_fract_is_python_modulo(rng):
    """fract(x) (the texture lookups' repeat wrap) and the mirror wrap built on it give
    Python's float32 x % 1 and x % 2 bit for bit, compiled and interpreted: including
    negative numbers whose wrapped value rounds up to 1, integers, huge values and inf."""
    xs = np.concatenate([rng.standard_normal(50_000) * 3, rng.standard_normal(1000) * 1e-9,
                         rng.uniform(-1e6, 1e6, 1000), np.arange(-5, 6),
                         [-1e-9, -0.0, 1e30, -1e30, 3.5, -3.5, np.inf, -np.inf]]
                        ).astype(np.float32)
    with np.errstate(invalid="ignore"):
        want = np.array([x % np.float32(1) for x in xs], np.float32)
        want2 = np.array([x % np.float32(2) for x in xs], np.float32)
    want_mirror = np.where(want2 > 1, np.float32(2) - want2, want2)
    out, mirror = np.empty_like(xs), np.empty_like(xs)
    _fract_compiled(xs, out, mirror)
    np.testing.assert_array_equal(out, want)
    np.testing.assert_array_equal(mirror, want_mirror)
    with np.errstate(invalid="ignore"):
        interpreted = np.array([fract(x) for x in xs], np.float32)
    np.testing.assert_array_equal(interpreted, want)
    assert fract(np.float32(-1e-9)) == np.float32(1.0)   # rounds up: still in [0, 1]
