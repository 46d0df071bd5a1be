"""Warps from the unit square to other domains, with their densities (Mitsuba's naming)."""
import math

import numpy as np

from .constants import F32, INV_PI, ONE, PI_OVER_4, TWO, ZERO
from .device import device
from .fmath import floor_int


# Taylor coefficients of sin and cos; on |x| <= pi/4 the truncation error is below 2e-9,
# under float32 rounding.
_S3 = F32(-1.0 / 6.0)
_S5 = F32(1.0 / 120.0)
_S7 = F32(-1.0 / 5040.0)
_S9 = F32(1.0 / 362880.0)
_C2 = F32(-0.5)
_C4 = F32(1.0 / 24.0)
TWO_OVER_PI = F32(2.0 / np.pi)
PI_OVER_2_F = F32(np.pi / 2.0)
HALF_F = F32(0.5)
_C6 = F32(-1.0 / 720.0)
_C8 = F32(1.0 / 40320.0)
_C10 = F32(-1.0 / 3628800.0)


@device
def sincos_quarter(x):
    """(sin x, cos x) for |x| <= pi/4, in float32 only.

    libdevice's sinf/cosf carry a float64 path for huge arguments; angles in warps are
    bounded, so a short polynomial is exact to float32 and keeps .f64 out of the PTX.
    """
    x2 = x * x
    s = x * (ONE + x2 * (_S3 + x2 * (_S5 + x2 * (_S7 + x2 * _S9))))
    c = ONE + x2 * (_C2 + x2 * (_C4 + x2 * (_C6 + x2 * (_C8 + x2 * _C10))))
    return s, c


@device
def sincos(x):
    """(sin x, cos x) for |x| <= 2 pi in float32: reduced to the nearest multiple of pi/2,
    then the quarter polynomial (libdevice's sinf carries a float64 path, see above)."""
    k = floor_int(x * TWO_OVER_PI + HALF_F)
    r = x - np.float32(k) * PI_OVER_2_F
    s, c = sincos_quarter(r)
    q = k & 3
    if q == 0:
        return s, c
    if q == 1:
        return c, -s
    if q == 2:
        return -s, -c
    return -c, s


@device
def square_to_disk_concentric(u1, u2):
    """Shirley & Chiu 1997 concentric map: area-preserving, low distortion."""
    a = TWO * u1 - ONE
    b = TWO * u2 - ONE
    if a == ZERO and b == ZERO:
        return ZERO, ZERO
    if abs(a) > abs(b):
        # phi = pi/4 * b/a in [-pi/4, pi/4]
        s, c = sincos_quarter(PI_OVER_4 * (b / a))
        return a * c, a * s
    # phi = pi/2 - pi/4 * a/b: cos(phi) = sin(pi/4 a/b), sin(phi) = cos(pi/4 a/b)
    s, c = sincos_quarter(PI_OVER_4 * (a / b))
    return b * s, b * c


@device
def square_to_cosine_hemisphere(u1, u2):
    """Malley's method: a uniform disk point lifted to the hemisphere around +z."""
    x, y = square_to_disk_concentric(u1, u2)
    z = math.sqrt(max(ZERO, ONE - x * x - y * y))
    return (x, y, z)


@device
def square_to_cosine_hemisphere_pdf(cos_theta):
    return max(cos_theta, ZERO) * INV_PI


@device
def square_to_triangle(u1, u2):
    """Barycentrics (b1, b2) of a uniform point on a triangle (pbrt-v3 UniformSampleTriangle)."""
    su = math.sqrt(u1)
    return su * (ONE - u2), su * u2


@device
def power_heuristic(pdf_a, pdf_b):
    """Veach 1997, power heuristic with beta = 2: weight of strategy a, a^2 / (a^2 + b^2).

    Written as 1 / (1 + (b/a)^2) so that an infinite pdf (a light seen exactly edge-on:
    cos = 0 in the area-to-solid-angle conversion) gives the limit weight 1 or 0, never
    inf/inf = NaN; a zero pdf gets weight 0.
    """
    if not (pdf_a > ZERO):
        return ZERO
    r = pdf_b / pdf_a
    return ONE / (ONE + r * r)

