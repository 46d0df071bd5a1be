"""The path tracer: one per-sample function, specialised per scene and shared by backends.

``make_render_pixel(features)`` closes over a frozen :class:`Features`; branches on those
constants are removed before compilation, so a scene without point lights, emissive
triangles, smooth normals or an environment compiles none of that code (pbrt's wavefront
integrator instantiates per material type the same way; here Python closures do it).

Estimator (Veach 1997, ch. 9; the structure of Mitsuba 3's ``path`` integrator):
unidirectional path tracing with next-event estimation to one light chosen by power,
BSDF sampling, both combined for area lights by the power heuristic, and Russian roulette
after ``rr_depth`` bounces. ``max_bounces`` counts scattering events: 0 shows only emitters
seen directly, 1 is direct lighting (Mitsuba's max_depth = max_bounces + 1).
"""
import functools
import math
from typing import NamedTuple

import numpy as np

from .camera import pinhole_ray
from .constants import INF, OFFSET_REL, ONE, RR_MAX, SHADOW_SHORTEN, ZERO
from .device import device
from .lights import direction_to, sample_discrete, sample_triangle_point
from .materials import diffuse_eval, diffuse_sample, emission, emits
from .rng import path_key, sample_1d
from .traverse import any_hit, closest_hit
from .vec import (add, cross, dot, load3, madd, max_abs, max_comp, mul, neg, normalize,
                  scale)
from .warps import power_heuristic


class Features(NamedTuple):
    """What a scene uses; each flag that is False removes code from the kernel."""
    tri_lights: bool    # emissive triangles (area lights)
    point_lights: bool
    environment: bool   # constant-colour environment
    smooth: bool        # interpolated vertex normals


# Random dimensions: 0-1 pixel position, 2-3 lens (reserved), then per scattering event:
D_LIGHT_SELECT = 0
D_LIGHT_U = 1
D_LIGHT_V = 2
D_BSDF_U = 3
D_BSDF_V = 4
D_RR = 5
D_FIRST_BOUNCE = 4
DIMS_PER_BOUNCE = 8


class SceneArrays(NamedTuple):
    """Everything a kernel reads. Arrays a scene does not use hold one dummy row."""
    cam: np.ndarray            # float32 (16,) see kernels.camera
    tri_v: np.ndarray          # float32 (N, 9): v0, e1, e2
    tri_n: np.ndarray          # float32 (N, 9): vertex normals n0, n1, n2 (smooth only)
    tri_mat: np.ndarray        # int32 (N,)
    mat: np.ndarray            # float32 (M, MAT_WIDTH) see kernels.materials
    tri_light_pdf: np.ndarray  # float32 (N,): selection probability / area; 0 if not emissive
    light_cdf: np.ndarray      # float32 (K + 1,)
    light_ref: np.ndarray      # int32 (K,): triangle index, or -(point light index + 1)
    point_lights: np.ndarray   # float32 (P, 6): position, intensity rgb
    env: np.ndarray            # float32 (3,): environment radiance
    bvh_box: np.ndarray        # float32 (B, 12)
    bvh_child: np.ndarray      # int32 (B, 4)


@device
def offset_origin(p, n):
    """p pushed along n by a few ulps of p's magnitude (scale invariant)."""
    return madd(p, n, max_abs(p) * OFFSET_REL)


@functools.lru_cache(maxsize=None)
def make_render_pixel(features):
    """Compile-time specialisation: returns ``render_pixel`` for scenes with ``features``."""
    TRI_LIGHTS = bool(features.tri_lights)
    POINT_LIGHTS = bool(features.point_lights)
    ANY_LIGHTS = TRI_LIGHTS or POINT_LIGHTS
    ENVIRONMENT = bool(features.environment)
    SMOOTH = bool(features.smooth)

    @device
    def render_sample(px, py, sample_index, seed, width, height, max_bounces, rr_depth,
                      scene, stack):
        """Radiance (r, g, b) of one camera path through pixel (px, py), with the number of
        bounce rays and shadow rays it traced."""
        key = path_key(py * width + px, sample_index, seed)
        o, d = pinhole_ray(scene.cam, np.float32(px), np.float32(py), sample_1d(key, 0),
                           sample_1d(key, 1), np.float32(width), np.float32(height))
        beta = (ONE, ONE, ONE)      # path throughput: product of f cos / pdf (and 1/q of RR)
        radiance = (ZERO, ZERO, ZERO)
        pdf_prev = ZERO             # solid-angle pdf of the BSDF sample that made this ray;
        #                             0 for the camera ray (emission seen directly: no MIS)
        skip = -1                   # triangle the ray leaves (never re-hit)
        bounce = 0                  # scattering events so far
        n_bounce_rays = 0
        n_shadow_rays = 0
        while True:
            t, tri, b1, b2 = closest_hit(o, d, INF, skip, scene.tri_v, scene.bvh_box,
                                         scene.bvh_child, stack)
            if tri < 0:
                if ENVIRONMENT:
                    # Constant environment: reached only by BSDF sampling (weight 1).
                    radiance = add(radiance, mul(beta, (scene.env[0], scene.env[1],
                                                        scene.env[2])))
                break

            # ---- Surface interaction ----
            v0 = load3(scene.tri_v, tri, 0)
            e1 = load3(scene.tri_v, tri, 3)
            e2 = load3(scene.tri_v, tri, 6)
            p = madd(madd(v0, e1, b1), e2, b2)
            ng = normalize(cross(e1, e2))   # front side: counter-clockwise winding
            wo = neg(d)
            cos_o = dot(ng, wo)
            m = scene.tri_mat[tri]

            # ---- Emission reached by this ray (MIS against light sampling) ----
            if TRI_LIGHTS:
                if emits(scene.mat, m, cos_o):
                    weight = ONE
                    if pdf_prev > ZERO:
                        pdf_light = scene.tri_light_pdf[tri] * t * t / abs(cos_o)
                        weight = power_heuristic(pdf_prev, pdf_light)
                    radiance = add(radiance, scale(mul(beta, emission(scene.mat, m)), weight))

            if bounce >= max_bounces:
                break

            # Both sides of a surface reflect: turn the normals to the side of wo.
            if cos_o < ZERO:
                ng = neg(ng)
            n = ng
            if SMOOTH:
                b0 = ONE - b1 - b2
                ns = normalize(add(add(scale(load3(scene.tri_n, tri, 0), b0),
                                       scale(load3(scene.tri_n, tri, 3), b1)),
                                   scale(load3(scene.tri_n, tri, 6), b2)))
                n = ns if dot(ns, ng) >= ZERO else neg(ns)
            origin = offset_origin(p, ng)
            dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE

            # ---- Next-event estimation: one light, chosen by power ----
            if ANY_LIGHTS:
                k = sample_discrete(scene.light_cdf, sample_1d(key, dim + D_LIGHT_SELECT))
                ref = scene.light_ref[k]
                u1 = sample_1d(key, dim + D_LIGHT_U)
                u2 = sample_1d(key, dim + D_LIGHT_V)
                if TRI_LIGHTS and ref >= 0:
                    q, nl, _ = sample_triangle_point(scene.tri_v, ref, u1, u2)
                    wi, dist = direction_to(p, q)
                    cos_l = -dot(nl, wi)
                    lm = scene.tri_mat[ref]
                    # tri_light_pdf = selection pmf / area: the same density the
                    # emission-hit MIS above uses (0 for zero-area triangles).
                    pdf_area = scene.tri_light_pdf[ref]
                    if dist > ZERO and pdf_area > ZERO and emits(scene.mat, lm, cos_l):
                        f, pdf_bsdf = diffuse_eval(scene.mat, m, n, ng, wi)
                        if pdf_bsdf > ZERO:
                            n_shadow_rays += 1
                            if not any_hit(origin, wi, dist * SHADOW_SHORTEN, tri, ref,
                                           scene.tri_v, scene.bvh_box, scene.bvh_child, stack):
                                pdf_light = pdf_area * dist * dist / abs(cos_l)
                                weight = power_heuristic(pdf_light, pdf_bsdf) / pdf_light
                                radiance = add(radiance, scale(
                                    mul(mul(beta, f), emission(scene.mat, lm)), weight))
                if POINT_LIGHTS and ref < 0:
                    pl = -ref - 1
                    pmf = scene.light_cdf[k + 1] - scene.light_cdf[k]
                    wi, dist = direction_to(p, load3(scene.point_lights, pl, 0))
                    if dist > ZERO:
                        f, pdf_bsdf = diffuse_eval(scene.mat, m, n, ng, wi)
                        if pdf_bsdf > ZERO:
                            n_shadow_rays += 1
                            if not any_hit(origin, wi, dist * SHADOW_SHORTEN, tri, -1,
                                           scene.tri_v, scene.bvh_box, scene.bvh_child, stack):
                                # Delta light: no MIS; irradiance falls off with 1/d^2.
                                radiance = add(radiance, scale(
                                    mul(mul(beta, f), load3(scene.point_lights, pl, 3)),
                                    ONE / (pmf * dist * dist)))

            # ---- BSDF sampling: the next ray ----
            wi, weight, pdf_bsdf = diffuse_sample(scene.mat, m, n, ng,
                                                  sample_1d(key, dim + D_BSDF_U),
                                                  sample_1d(key, dim + D_BSDF_V))
            if pdf_bsdf <= ZERO:
                break
            beta = mul(beta, weight)
            pdf_prev = pdf_bsdf
            o = origin
            d = wi
            skip = tri
            bounce += 1
            n_bounce_rays += 1

            # ---- Russian roulette (unbiased: survivors are reweighted by 1/q) ----
            beta_max = max_comp(beta)
            if beta_max <= ZERO:
                break
            if bounce >= rr_depth:
                q = min(beta_max, RR_MAX)
                if sample_1d(key, dim + D_RR) >= q:
                    break
                beta = scale(beta, ONE / q)
        return radiance[0], radiance[1], radiance[2], n_bounce_rays, n_shadow_rays

    @device
    def render_pixel(px, py, sample_start, n_samples, seed, max_bounces, rr_depth, scene,
                     stack, out, stats):
        """Add n_samples paths of pixel (px, py) to out[py, px] (float32 rgb sums) and
        count rays and non-finite samples in stats[py, px] (bounce, shadow, non-finite).
        Non-finite samples are not dropped: they are counted and reach the image."""
        height = out.shape[0]
        width = out.shape[1]
        r = ZERO
        g = ZERO
        b = ZERO
        n_bounce = 0
        n_shadow = 0
        n_bad = 0
        for s in range(sample_start, sample_start + n_samples):
            sr, sg, sb, nb, ns = render_sample(px, py, s, seed, width, height, max_bounces,
                                               rr_depth, scene, stack)
            if not (math.isfinite(sr) and math.isfinite(sg) and math.isfinite(sb)):
                n_bad += 1
            r += sr
            g += sg
            b += sb
            n_bounce += nb
            n_shadow += ns
        out[py, px, 0] = r
        out[py, px, 1] = g
        out[py, px, 2] = b
        stats[py, px, 0] = n_bounce
        stats[py, px, 1] = n_shadow
        stats[py, px, 2] = n_bad

    return render_pixel
