"""Warps from the unit square to other domains, with their densities (Mitsuba's naming)."""
import math

from .constants import INV_PI, ONE, PI_OVER_2, PI_OVER_4, TWO, ZERO
from .device import device


@device
def square_to_disk_concentric(u1, u2):
    """Shirley & Chiu 1997 concentric map: area-preserving, low distortion."""
    a = TWO * u1 - ONE
    b = TWO * u2 - ONE
    if a == ZERO and b == ZERO:
        return ZERO, ZERO
    if abs(a) > abs(b):
        r = a
        phi = PI_OVER_4 * (b / a)
    else:
        r = b
        phi = PI_OVER_2 - PI_OVER_4 * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


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
    """Veach 1997, power heuristic with beta = 2: weight of strategy a."""
    a2 = pdf_a * pdf_a
    b2 = pdf_b * pdf_b
    if a2 + b2 == ZERO:
        return ZERO
    return a2 / (a2 + b2)

