"""Materials: the parameter table and the diffuse BSDF.

``mat`` (float32, M x MAT_WIDTH) holds one row per material, see the ``M_*`` columns:
albedo rgb, emitted radiance rgb, two-sided emission flag, type, then the principled
parameters. ``eta`` = 0 means "derive the index from ``specular``" (F0 = 0.08 specular =
((eta - 1) / (eta + 1))^2, Burley 2012). ``mat_tex`` (int32, M x N_SLOTS) names the texture
that replaces a parameter (``T_*`` slots), or -1.

BSDFs are evaluated in the local shading frame (z = shading normal turned to the side of
``wo``, except for transmissive principled materials, whose frame keeps the geometric
front side). The integrator rejects any direction whose side of the geometric surface
disagrees with the shading frame's verdict (reflection or transmission), so interpolated
or mapped normals cannot leak light through a surface.
"""
from .constants import INV_PI, ZERO
from .device import device
from .warps import square_to_cosine_hemisphere

MAT_WIDTH = 20
M_ALBEDO = 0
M_EMISSION = 3
M_TWO_SIDED = 6
M_TYPE = 7
M_ROUGHNESS = 8
M_METALLIC = 9
M_SPECULAR = 10
M_ETA = 11
M_SPEC_TINT = 12
M_ANISOTROPIC = 13
M_SHEEN = 14
M_SHEEN_TINT = 15
M_CLEARCOAT = 16
M_CLEARCOAT_GLOSS = 17
M_SUBSURFACE = 18
M_TRANSMISSION = 19

MAT_DIFFUSE = 0
MAT_PRINCIPLED = 1

# Texture slots (columns of mat_tex); scene/compile.py maps each to the column it replaces.
N_SLOTS = 16
T_ALBEDO, T_EMISSION, T_ROUGHNESS, T_METALLIC, T_SPECULAR, T_ETA, T_SPEC_TINT, \
    T_ANISOTROPIC, T_SHEEN, T_SHEEN_TINT, T_CLEARCOAT, T_CLEARCOAT_GLOSS, T_SUBSURFACE, \
    T_TRANSMISSION, T_NORMAL = range(15)


@device
def emits(mat, m, cos_out):
    """Does material m emit towards a direction at cosine cos_out with the front normal?
    (A textured emission keeps its scale in the emission columns.)"""
    if mat[m, 3] > ZERO or mat[m, 4] > ZERO or mat[m, 5] > ZERO:
        return cos_out > ZERO or mat[m, 6] > ZERO
    return False


@device
def diffuse_eval_local(albedo, wo, wi):
    """Lambertian f |cos theta_i| and the cosine-sampling pdf, in the local frame."""
    if wo[2] <= ZERO or wi[2] <= ZERO:
        return (ZERO, ZERO, ZERO), ZERO
    k = wi[2] * INV_PI
    return (albedo[0] * k, albedo[1] * k, albedo[2] * k), k


@device
def diffuse_sample_local(albedo, wo, u1, u2):
    """Cosine-weighted wi: (wi, weight = f cos / pdf, pdf); pdf = 0 means no sample."""
    wi = square_to_cosine_hemisphere(u1, u2)
    if wo[2] <= ZERO or wi[2] <= ZERO:
        return wi, (ZERO, ZERO, ZERO), ZERO
    return wi, (albedo[0], albedo[1], albedo[2]), wi[2] * INV_PI
