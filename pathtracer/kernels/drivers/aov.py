"""The denoiser's auxiliary images (albedo, normal): the bounce's first-hit steps
(kernels.path: surface_geometry, emission_at, surface_shading, next_ray) followed through
specular surfaces."""
import functools

import numpy as np

from ..constants import ONE, ZERO
from ..device import device, entry_marker
from ..emitters import make_emitters
from ..layout import (ALPHA_DIMS, D_ALPHA, AOV_ALBEDO, AOV_NORMAL, D_BSDF_LOBE, D_BSDF_U, D_BSDF_V,
                      D_FIRST_BOUNCE, DIMS_PER_BOUNCE, MAT_CONDUCTOR, MAT_PRINCIPLED, P_BASE,
                      P_COND_ALPHA_U, P_COND_ALPHA_V, P_METALLIC, P_ROUGHNESS,
                      P_TRANSMISSION, specialise)
from ..path import Hit, make_path
from ..rng import make_sampler
from ..vec import add, to_world

# A surface counts as specular, and the albedo and normal are taken further along the path,
# when its GGX roughness is below this and it is mostly metal or glass (the principled BSDF
# has no true delta lobe).
AOV_SPECULAR_ROUGHNESS = np.float32(0.1)
AOV_MAX_SPECULAR = 8        # specular surfaces followed at most
HALF_F = np.float32(0.5)
# (a conductor's alpha is the square of the principled BSDF's roughness)
AOV_SPECULAR_ALPHA = np.float32(0.01)


@device
def aov_specular(kind, params):
    """Is the material a mirror or clear glass, which the denoiser's albedo and normal
    images look through?"""
    if kind == MAT_CONDUCTOR:
        return max(params[P_COND_ALPHA_U], params[P_COND_ALPHA_V]) < AOV_SPECULAR_ALPHA
    return kind == MAT_PRINCIPLED and params[P_ROUGHNESS] < AOV_SPECULAR_ROUGHNESS \
        and (params[P_METALLIC] > HALF_F or params[P_TRANSMISSION] > HALF_F)


@device
def clamp01(x):
    return min(max(x, ZERO), ONE)


@functools.lru_cache(maxsize=None)
def make_aov(features, target="cpu"):
    """``aov_pixel`` for scenes with ``features`` on ``target``."""
    S = specialise(features)
    entry = entry_marker(target)
    P = make_path(features, target)
    (camera_ray, emission_at, next_ray, path_state, spread_of, start_camera_path,
     surface_geometry, surface_shading, trace_hit) = (
        P.camera_ray, P.emission_at, P.next_ray, P.path_state, P.spread_of,
        P.start_camera_path, P.surface_geometry, P.surface_shading, P.trace_hit)
    start_path, open_set, draw = make_sampler(S.sobol, table=target == "cpu")
    ANY_ENVIRONMENT = S.any_environment
    TRI_LIGHTS = S.tri_lights
    escaped = make_emitters(features, target).escaped

    @entry
    def aov_pixel(px, py, n_samples, seed, scene, stack, out):
        """The denoiser's auxiliary images at pixel (px, py) (layout AOV_*): the albedo
        (base colour) and the world-space shading normal at the first surface that is not
        specular (AOV_SPECULAR_ROUGHNESS), the mean of n_samples camera rays (the sampler's
        own camera and BSDF numbers). A ray that leaves the scene gives the environment's
        radiance clamped to [0, 1] as albedo and a zero normal (Open Image Denoise's
        convention for "no surface"); an emitter's albedo is its base colour plus its
        radiance, clamped to [0, 1]: with the base colour alone a light and the ceiling
        around it have one albedo, and the denoiser blurs the light's edge into the
        ceiling."""
        height = out.shape[0]
        width = out.shape[1]
        acc = (ZERO, ZERO, ZERO)
        nacc = (ZERO, ZERO, ZERO)
        spread = spread_of(scene)
        for sample in range(n_samples):
            state = start_path(py * width + px, sample, seed)
            o, d = camera_ray(scene.cam, px, py, state, width, height)
            path = start_camera_path(o, d)
            cone = ZERO
            albedo = (ZERO, ZERO, ZERO)
            normal = (ZERO, ZERO, ZERO)
            for bounce in range(AOV_MAX_SPECULAR + 1):
                t, tri, b1, b2 = trace_hit(scene, o, d, path.skip, state[0],
                                           D_ALPHA + bounce * ALPHA_DIMS, stack)
                if tri < 0:
                    if ANY_ENVIRONMENT:
                        le = escaped(scene.env, scene.env_img, scene.env_info, d, ZERO)[0]
                        albedo = (clamp01(le[0]), clamp01(le[1]), clamp01(le[2]))
                    break
                hit = Hit(t, tri, b1, b2)
                geo, cone = surface_geometry(scene, d, hit, bounce, cone, spread)
                sh = surface_shading(scene, hit, geo)
                le = (ZERO, ZERO, ZERO)
                if TRI_LIGHTS:
                    # (zero radiance where the surface does not emit towards wo)
                    le = emission_at(scene, o, hit, geo, ZERO)[0]
                albedo = (clamp01(sh.params[P_BASE] + le[0]),
                          clamp01(sh.params[P_BASE + 1] + le[1]),
                          clamp01(sh.params[P_BASE + 2] + le[2]))
                normal = to_world(sh.wp, sh.tangent, sh.bitangent, sh.ns)
                specular = aov_specular(sh.kind, sh.params)
                if not specular or bounce == AOV_MAX_SPECULAR:
                    break
                dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE
                dims = open_set(state, dim + D_BSDF_U)
                o, d, skip, _, pdf_bsdf = next_ray(
                    sh, geo, tri, draw(state, dims, dim + D_BSDF_LOBE),
                    draw(state, dims, dim + D_BSDF_U), draw(state, dims, dim + D_BSDF_V))
                if not (pdf_bsdf > ZERO):
                    break
                path = path_state(o, d, path.beta, path.radiance, ZERO, skip, bounce + 1,
                                    cone)
            acc = add(acc, albedo)
            nacc = add(nacc, normal)
        inv = ONE / np.float32(max(n_samples, 1))
        for c in range(3):
            out[py, px, AOV_ALBEDO + c] = acc[c] * inv
            out[py, px, AOV_NORMAL + c] = nacc[c] * inv

    return aov_pixel
