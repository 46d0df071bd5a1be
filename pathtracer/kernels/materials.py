"""Materials.

``mat`` (float32, M x MAT_WIDTH) holds one row per material: albedo rgb (0:3), emitted
radiance rgb (3:6), two-sided emission flag (6), type code (7). Directions are in world
space; ``n`` is the shading normal already turned to the side of ``wo`` and ``ng`` the
geometric normal on that same side. A direction below the geometric surface never
scatters, whatever the shading normal says, so interpolated normals cannot leak light.
"""
from .constants import INV_PI, ZERO
from .device import device
from .vec import dot, frame, to_world
from .warps import square_to_cosine_hemisphere

MAT_WIDTH = 8
MAT_DIFFUSE = 0


@device
def emission(mat, m):
    return (mat[m, 3], mat[m, 4], mat[m, 5])


@device
def emits(mat, m, cos_out):
    """Does material m emit towards a direction at cosine cos_out with the front normal?"""
    if mat[m, 3] > ZERO or mat[m, 4] > ZERO or mat[m, 5] > ZERO:
        return cos_out > ZERO or mat[m, 6] > ZERO
    return False


@device
def diffuse_eval(mat, m, n, ng, wi):
    """Lambertian BSDF times the cosine, f(wo, wi) |n . wi|, and the pdf of sampling wi."""
    cos_i = dot(n, wi)
    if cos_i <= ZERO or dot(ng, wi) <= ZERO:
        return (ZERO, ZERO, ZERO), ZERO
    k = cos_i * INV_PI
    return (mat[m, 0] * k, mat[m, 1] * k, mat[m, 2] * k), k


@device
def diffuse_sample(mat, m, n, ng, u1, u2):
    """Cosine-weighted direction: (wi, weight = f cos / pdf, pdf); pdf = 0 means no sample."""
    local = square_to_cosine_hemisphere(u1, u2)
    t, s = frame(n)
    wi = to_world(local, t, s, n)
    if local[2] <= ZERO or dot(ng, wi) <= ZERO:
        return wi, (ZERO, ZERO, ZERO), ZERO
    return wi, (mat[m, 0], mat[m, 1], mat[m, 2]), local[2] * INV_PI


