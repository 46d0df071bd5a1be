"""Light selection and sampling.

All lights (emissive triangles and point lights) share one discrete distribution,
``light_cdf`` (float32, K + 1; cdf[0] = 0, cdf[K] = 1), proportional to emitted power;
``light_ref[k]`` is the triangle index of light k, or ``layout.point_light_ref(p)`` for
point light p. The
selection probability of triangle i divided by its area is ``tri_light_pdf[i]`` (0 for
triangles that do not emit), which turns a BSDF-sampled hit into a light pdf for MIS.
Probabilities are differences of the float32 CDF, so the pmf used in MIS is exactly the one
used for sampling.
"""
import math

from .constants import HALF, ONE, ZERO
from .device import device
from .layout import TRI_E1, TRI_E2, TRI_V0
from .vec import cross, dot, length, load3, madd, scale, sub
from .warps import square_to_triangle


@device
def sample_discrete(cdf, u):
    """Index k with cdf[k] <= u < cdf[k + 1] (never an entry of zero probability)."""
    lo = 0
    hi = cdf.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo


@device
def sample_triangle_point(tri_v, i, u1, u2):
    """Uniform point on triangle i, with its unit geometric normal and area."""
    b1, b2 = square_to_triangle(u1, u2)
    v0 = load3(tri_v, i, TRI_V0)
    e1 = load3(tri_v, i, TRI_E1)
    e2 = load3(tri_v, i, TRI_E2)
    q = madd(madd(v0, e1, b1), e2, b2)
    n = cross(e1, e2)
    len_n = length(n)
    return q, scale(n, ONE / len_n) if len_n > ZERO else n, HALF * len_n


@device
def direction_to(p, q):
    """Unit direction from p to q, and the distance."""
    to = sub(q, p)
    dist = math.sqrt(dot(to, to))
    return scale(to, ONE / dist) if dist > ZERO else to, dist
