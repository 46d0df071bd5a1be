"""Light selection and sampling.

All lights (emissive triangles and point lights) share one discrete distribution,
``light_cdf`` (float32, K + 1; cdf[0] = 0, cdf[K] = 1), proportional to emitted power;
``light_ref[k]`` is the triangle index of light k, or ``layout.point_light_ref(p)`` for
point light p. The
selection probability of triangle i divided by its area is ``tri_light_pdf[i]`` (0 for
triangles that do not emit), which turns a BSDF-sampled hit into a light pdf for MIS.
Probabilities are differences of the float32 CDF, so the pmf used in MIS is exactly the one
used for sampling.

With the light tree (``render.lightSampler``; built by ``accel.light_tree``) the choice
depends on the shading point instead: :func:`sample_light_tree` walks from the root to a
leaf, at each node going to a child with probability proportional to that child's
:func:`light_importance` seen from the point (Conty Estevez and Kulla 2018, "Importance
Sampling of Many Lights with Adaptive Tree Splitting"; the importance is pbrt-v4's
``LightBounds::Importance`` without the receiver's normal, which a BSDF-sampled hit no longer
knows). :func:`light_tree_pmf` walks the same nodes back up from a light's leaf, so a
BSDF-sampled hit on an emitter gets the density that next-event estimation used.
"""
import math

import numpy as np

from .constants import HALF, ONE, ONE_MINUS_EPS, ZERO
from .device import device
from .layout import (LT_AXIS, LT_CENTRE, LT_COS_O, LT_LEFT, LT_PARENT, LT_RIGHT, TRI_E1,
                     TRI_E2, TRI_V0)
from .loads import load4
from .vec import cross, dot, length, load3, madd, scale, sub
from .warps import square_to_triangle


@device
def sample_discrete(cdf, u):
    """Index k with cdf[k] <= u < cdf[k + 1] (never an entry of zero probability): a
    bisection (the GPU's; the CPU picks lights with search.last_at_most, the same index
    without a branch per step)."""
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


# Importance divides by at least this squared distance: finite (the tree's powers sum to 1)
# where a shading point coincides with a point light, whose importance is then 1e30 x its
# power instead of infinite (which made the pick's probability NaN)
MIN_DIST2 = np.float32(1e-30)


@device
def cos_sub_clamped(sin_a, cos_a, sin_b, cos_b):
    """cos(max(0, a - b)) for angles in [0, pi] given by their sines and cosines."""
    if cos_a > cos_b:
        return ONE
    return cos_a * cos_b + sin_a * sin_b


@device
def sin_sub_clamped(sin_a, cos_a, sin_b, cos_b):
    """sin(max(0, a - b)) for angles in [0, pi] given by their sines and cosines."""
    if cos_a > cos_b:
        return ZERO
    return sin_a * cos_b - cos_a * sin_b


@device
def light_importance(lt_node, n, p):
    """An upper bound, up to a common factor, of what the lights under node n can send to
    point p: power / distance^2 times the cosine of the smallest angle between the
    direction to p and the normals' cone, widened by the angle that the sphere around the
    node's box subtends (pbrt-v4, ``LightBounds::Importance``); 0 where p is outside every
    light's emission (behind one-sided emitters, outside spot cones)."""
    cx, cy, cz, r2 = load4(lt_node, n, LT_CENTRE)
    ax, ay, az, power = load4(lt_node, n, LT_AXIS)
    cos_o, sin_o, cos_e, two_sided = load4(lt_node, n, LT_COS_O)
    to = (p[0] - cx, p[1] - cy, p[2] - cz)
    d2 = dot(to, to)
    if not (d2 > r2):
        # p inside the node's sphere: every direction may reach it
        return power / max(max(r2, d2), MIN_DIST2)
    # the half-angle the node's sphere subtends from p
    sin2_b = r2 / d2
    cos_b = math.sqrt(ONE - sin2_b)
    sin_b = math.sqrt(sin2_b)
    cos_w = dot((ax, ay, az), to) / math.sqrt(d2)
    if two_sided > ZERO:
        cos_w = abs(cos_w)
    sin_w = math.sqrt(max(ZERO, ONE - cos_w * cos_w))
    cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o)
    sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o)
    cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b)
    if cos_p <= cos_e:
        return ZERO
    return power * cos_p / max(d2, MIN_DIST2)


@device
def sample_light_tree(lt_node, lt_link, p, u):
    """(k, pmf): light k (of light_ref) picked for point p by walking the tree with u, and
    the probability of that pick; k = -1 where no light can reach p."""
    n = 0
    pmf = ONE
    while True:
        c0 = lt_link[n, LT_LEFT]
        if c0 < 0:
            return -c0 - 1, pmf
        c1 = lt_link[n, LT_RIGHT]
        i0 = light_importance(lt_node, c0, p)
        total = i0 + light_importance(lt_node, c1, p)
        if not (total > ZERO):
            return -1, ZERO
        p0 = i0 / total
        if u < p0:
            u = min(u / p0, ONE_MINUS_EPS)
            pmf *= p0
            n = c0
        else:
            u = min((u - p0) / (ONE - p0), ONE_MINUS_EPS)
            pmf *= ONE - p0
            n = c1


@device
def light_tree_pmf(lt_node, lt_link, leaf, p):
    """The probability that sample_light_tree picks the light of node ``leaf`` for point p:
    the same choices, walked up from the leaf."""
    pmf = ONE
    n = leaf
    parent = lt_link[n, LT_PARENT]
    while parent >= 0:
        c0 = lt_link[parent, LT_LEFT]
        i0 = light_importance(lt_node, c0, p)
        total = i0 + light_importance(lt_node, lt_link[parent, LT_RIGHT], p)
        if not (total > ZERO):
            return ZERO
        p0 = i0 / total
        pmf *= p0 if n == c0 else ONE - p0
        n = parent
        parent = lt_link[n, LT_PARENT]
    return pmf
