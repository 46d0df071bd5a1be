"""The emission test and the diffuse (Lambertian) BSDF.

Material rows (``mat``, with ``mat_tex`` naming the texture that replaces a parameter) are
laid out in :mod:`.layout`; :mod:`.shading` reads them at a shading point.

BSDFs are evaluated in the local shading frame (z = shading normal turned to the side of
``wo``, except for transmissive principled materials, whose frame keeps the geometric
front side). The integrator rejects any direction whose side of the geometric surface
disagrees with the shading frame's verdict (reflection or transmission), so interpolated
or mapped normals cannot leak light through a surface.
"""
from .constants import INV_PI, ZERO
from .device import device
from .layout import M_EMISSION, M_TWO_SIDED
from .warps import square_to_cosine_hemisphere


@device
def emits(mat, m, cos_out):
    """Does material m emit towards a direction at cosine cos_out with the front normal?
    (A textured emission keeps its scale in the emission columns.)"""
    if mat[m, M_EMISSION] > ZERO or mat[m, M_EMISSION + 1] > ZERO or \
            mat[m, M_EMISSION + 2] > ZERO:
        return cos_out > ZERO or mat[m, M_TWO_SIDED] > ZERO
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
