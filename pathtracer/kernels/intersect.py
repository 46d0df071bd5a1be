"""Ray-primitive tests.

Triangles are stored as rows of ``tri_v`` (float32, N x 9): vertex v0, then the edges
e1 = v1 - v0 and e2 = v2 - v0, precomputed for the Moller-Trumbore test (Moller & Trumbore
1997, "Fast, Minimum Storage Ray/Triangle Intersection"). Acceptance conditions are written
positively (``u >= 0 and ...``) so that a NaN from a degenerate triangle is a miss.
"""
from .constants import BIG, INF, ONE, SLAB_SCALE, ZERO
from .device import device
from .layout import TRI_E1, TRI_E2, TRI_V0


@device
def ray_triangle(o, d, tri_v, i, t_max):
    """Hit distance and barycentrics (t, b1, b2) of the ray with triangle i, or t = INF.

    Only hits with 0 < t < t_max count. Zero-area triangles (det == 0) and rays parallel to
    the triangle's plane never hit.
    """
    e1x = tri_v[i, TRI_E1]
    e1y = tri_v[i, TRI_E1 + 1]
    e1z = tri_v[i, TRI_E1 + 2]
    e2x = tri_v[i, TRI_E2]
    e2y = tri_v[i, TRI_E2 + 1]
    e2z = tri_v[i, TRI_E2 + 2]
    # p = d x e2
    px = d[1] * e2z - d[2] * e2y
    py = d[2] * e2x - d[0] * e2z
    pz = d[0] * e2y - d[1] * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == ZERO:
        return INF, ZERO, ZERO
    inv_det = ONE / det
    sx = o[0] - tri_v[i, TRI_V0]
    sy = o[1] - tri_v[i, TRI_V0 + 1]
    sz = o[2] - tri_v[i, TRI_V0 + 2]
    b1 = (sx * px + sy * py + sz * pz) * inv_det
    if not (b1 >= ZERO and b1 <= ONE):
        return INF, ZERO, ZERO
    # q = s x e1
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    b2 = (d[0] * qx + d[1] * qy + d[2] * qz) * inv_det
    if not (b2 >= ZERO and b1 + b2 <= ONE):
        return INF, ZERO, ZERO
    t = (e2x * qx + e2y * qy + e2z * qz) * inv_det
    if not (t > ZERO and t < t_max):
        return INF, ZERO, ZERO
    return t, b1, b2


@device
def safe_inverse(d):
    """1/d per component, with BIG for zero components (so 0 * inv is 0, never NaN)."""
    ix = ONE / d[0] if d[0] != ZERO else BIG
    iy = ONE / d[1] if d[1] != ZERO else BIG
    iz = ONE / d[2] if d[2] != ZERO else BIG
    return (ix, iy, iz)


@device
def slab(o, inv_d, lox, loy, loz, hix, hiy, hiz, t_max):
    """Entry distance of the ray into the box (lo, hi), or INF (the traversal loads a
    node's boxes with vector loads, kernels.loads).

    Slab test; t_far is scaled up by SLAB_SCALE so rounding never culls a touched box.
    """
    tx0 = (lox - o[0]) * inv_d[0]
    tx1 = (hix - o[0]) * inv_d[0]
    ty0 = (loy - o[1]) * inv_d[1]
    ty1 = (hiy - o[1]) * inv_d[1]
    tz0 = (loz - o[2]) * inv_d[2]
    tz1 = (hiz - o[2]) * inv_d[2]
    t_near = max(max(min(tx0, tx1), min(ty0, ty1)), max(min(tz0, tz1), ZERO))
    t_far = min(min(max(tx0, tx1), max(ty0, ty1)), min(max(tz0, tz1), t_max)) * SLAB_SCALE
    if t_near <= t_far:
        return t_near
    return INF
