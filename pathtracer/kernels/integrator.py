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

from .camera import pinhole_ray, thin_lens_ray
from .constants import INF, INV_PI, OFFSET_REL, ONE, ONE_MINUS_EPS, RR_MAX, SHADOW_SHORTEN, ZERO
from .device import device
from .envmap import env_eval, env_pdf, env_sample
from .lights import direction_to, sample_discrete, sample_triangle_point
from .materials import (M_ANISOTROPIC, M_CLEARCOAT, M_CLEARCOAT_GLOSS, M_ETA, M_METALLIC,
                        M_ROUGHNESS, M_SHEEN, M_SHEEN_TINT, M_SPEC_TINT, M_SPECULAR,
                        M_SUBSURFACE, M_TRANSMISSION, M_TYPE, MAT_PRINCIPLED, T_ALBEDO,
                        T_ANISOTROPIC, T_CLEARCOAT, T_CLEARCOAT_GLOSS, T_EMISSION, T_ETA,
                        T_METALLIC, T_NORMAL, T_ROUGHNESS, T_SHEEN, T_SHEEN_TINT,
                        T_SPEC_TINT, T_SPECULAR, T_SUBSURFACE, T_TRANSMISSION,
                        diffuse_eval_local, diffuse_sample_local, emits)
from .principled import lum, principled_eval, principled_sample
from .rng import path_key, sample_1d
from .textures import tex_lookup
from .traverse import any_hit, closest_hit
from .vec import (add, cross, dot, frame, load3, madd, max_abs, max_comp, mul, neg,
                  normalize, scale, to_world)
from .warps import power_heuristic, square_to_triangle


class Features(NamedTuple):
    """What a scene uses; each flag that is False removes code from the kernel."""
    tri_lights: bool    # emissive triangles (area lights)
    point_lights: bool
    environment: bool   # constant-colour environment
    smooth: bool        # interpolated vertex normals
    principled: bool = False   # any principled material
    textures: bool = False     # any texture (parameters or normal maps)
    normal_map: bool = False   # any normal map
    tangents: bool = False     # per-vertex tangents from texture coordinates
    env_map: bool = False      # an HDRI environment (importance sampled)
    thin_lens: bool = False    # aperture > 0


# Random dimensions: 0-1 pixel position, 2-3 lens, then per scattering event:
D_LIGHT_SELECT = 0
D_LIGHT_U = 1
D_LIGHT_V = 2
D_BSDF_U = 3
D_BSDF_V = 4
D_RR = 5
D_BSDF_LOBE = 6
D_FIRST_BOUNCE = 4
DIMS_PER_BOUNCE = 8

ETA_MIN_TRANSMISSIVE = np.float32(1.001)   # eta = 1 is no interface (as Mitsuba)
SPEC_K = np.float32(0.08)
HORIZON_EPS = np.float32(1e-3)
TWO = np.float32(2.0)


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
    env: np.ndarray            # float32 (3,): constant environment radiance
    bvh_box: np.ndarray        # float32 (B, 12)
    bvh_child: np.ndarray      # int32 (B, 4)
    tri_uv: np.ndarray         # float32 (N, 6): uv0, uv1, uv2 (textures only)
    tri_t: np.ndarray          # float32 (N, 12): tangents t0, t1, t2 + handedness (3)
    mat_tex: np.ndarray        # int32 (M, N_SLOTS): texture per parameter or -1
    tex_data: np.ndarray       # float32 (T, 3) linear texels of all textures
    tex_int: np.ndarray        # int32 (K, 4) see kernels.textures
    tex_f: np.ndarray          # float32 (K, 7)
    env_img: np.ndarray        # float32 (H, W, 3) see kernels.envmap
    env_marg: np.ndarray       # float32 (H + 1,)
    env_cond: np.ndarray       # float32 (H, W + 1)
    env_pdf: np.ndarray        # float32 (H, W)
    env_info: np.ndarray       # float32 (4,)


@device
def offset_origin(p, n):
    """p pushed along n by a few ulps of p's magnitude (scale invariant)."""
    return madd(p, n, max_abs(p) * OFFSET_REL)


@device
def tangent_on(t, n):
    """t made orthogonal to the unit normal n and normalised; any tangent if t is along n."""
    t = madd(t, n, -dot(t, n))
    if dot(t, t) > ZERO:
        return normalize(t)
    return frame(n)[0]


@device
def _lift_term(p, vk, nk, ng, bk):
    if dot(nk, ng) < ZERO:
        nk = neg(nk)
    h = min(dot((p[0] - vk[0], p[1] - vk[1], p[2] - vk[2]), nk), ZERO)
    return scale(nk, -bk * h)


@device
def terminator_lift(p, b1, b2, v0, e1, e2, n0, n1, n2, ng):
    """Shadow terminator (Hanika 2021, "Hacking the Shadow Terminator", Ray Tracing Gems II
    ch. 4): the point p of a smooth-shaded triangle lifted onto the curved surface its vertex
    normals describe (the barycentric mean of p's projections onto the vertices' tangent
    planes, only ever outwards, towards ng). Rays leaving on ng's side start there, so that a
    coarse smooth mesh shadows itself less in flat facets."""
    b0 = ONE - b1 - b2
    lift = add(add(_lift_term(p, v0, n0, ng, b0), _lift_term(p, add(v0, e1), n1, ng, b1)),
               _lift_term(p, add(v0, e2), n2, ng, b2))
    return add(p, lift)


@functools.lru_cache(maxsize=None)
def make_render_pixel(features):
    """Compile-time specialisation: returns ``render_pixel`` for scenes with ``features``."""
    TRI_LIGHTS = bool(features.tri_lights)
    POINT_LIGHTS = bool(features.point_lights)
    ANY_LIGHTS = TRI_LIGHTS or POINT_LIGHTS
    ENVIRONMENT = bool(features.environment)
    SMOOTH = bool(features.smooth)
    PRINCIPLED = bool(features.principled)
    TEXTURES = bool(features.textures)
    NORMAL_MAP = bool(features.normal_map) and TEXTURES
    TANGENTS = bool(features.tangents)
    ENV_MAP = bool(features.env_map)
    THIN_LENS = bool(features.thin_lens)
    NEE = ANY_LIGHTS or ENV_MAP
    # Shading normals that differ from the geometric ones: fold lobes (see eval_world).
    FOLD = SMOOTH or NORMAL_MAP
    # Lambertian materials and flat shading only: the cheapest path (the Cornell box's)
    LEAN = not PRINCIPLED and not FOLD

    @device
    def param1(scene, m, slot, col, u, v):
        """A number parameter of material m, from its texture when it has one."""
        if TEXTURES:
            t = scene.mat_tex[m, slot]
            if t >= 0:
                r, g, b = tex_lookup(scene.tex_data, scene.tex_int, scene.tex_f, t, u, v)
                return lum(r, g, b)
        return scene.mat[m, col]

    @device
    def param3(scene, m, slot, col, u, v):
        if TEXTURES:
            t = scene.mat_tex[m, slot]
            if t >= 0:
                return tex_lookup(scene.tex_data, scene.tex_int, scene.tex_f, t, u, v)
        return scene.mat[m, col], scene.mat[m, col + 1], scene.mat[m, col + 2]

    @device
    def unit(x):
        return min(max(x, ZERO), ONE)

    @device
    def tri_uv_at(scene, tri, b1, b2):
        if TEXTURES:
            b0 = ONE - b1 - b2
            return (b0 * scene.tri_uv[tri, 0] + b1 * scene.tri_uv[tri, 2] +
                    b2 * scene.tri_uv[tri, 4],
                    b0 * scene.tri_uv[tri, 1] + b1 * scene.tri_uv[tri, 3] +
                    b2 * scene.tri_uv[tri, 5])
        return ZERO, ZERO

    @device
    def emitted(scene, m, u, v):
        return param3(scene, m, T_EMISSION, 3, u, v)

    @device
    def material_params(scene, m, u, v):
        """The principled parameter tuple of material m at texture coordinates (u, v)."""
        base = param3(scene, m, T_ALBEDO, 0, u, v)
        transmission = unit(param1(scene, m, T_TRANSMISSION, M_TRANSMISSION, u, v))
        eta = param1(scene, m, T_ETA, M_ETA, u, v)
        if not (eta > ZERO):
            spec = unit(param1(scene, m, T_SPECULAR, M_SPECULAR, u, v))
            eta = TWO / (ONE - math.sqrt(SPEC_K * spec)) - ONE
        if transmission > ZERO and eta == ONE:
            eta = ETA_MIN_TRANSMISSIVE
        return (max(base[0], ZERO), max(base[1], ZERO), max(base[2], ZERO),
                unit(param1(scene, m, T_ROUGHNESS, M_ROUGHNESS, u, v)),
                unit(param1(scene, m, T_METALLIC, M_METALLIC, u, v)),
                eta,
                unit(param1(scene, m, T_SPEC_TINT, M_SPEC_TINT, u, v)),
                unit(param1(scene, m, T_ANISOTROPIC, M_ANISOTROPIC, u, v)),
                unit(param1(scene, m, T_SHEEN, M_SHEEN, u, v)),
                unit(param1(scene, m, T_SHEEN_TINT, M_SHEEN_TINT, u, v)),
                unit(param1(scene, m, T_CLEARCOAT, M_CLEARCOAT, u, v)),
                unit(param1(scene, m, T_CLEARCOAT_GLOSS, M_CLEARCOAT_GLOSS, u, v)),
                unit(param1(scene, m, T_SUBSURFACE, M_SUBSURFACE, u, v)),
                transmission)

    @device
    def bsdf_eval(is_principled, p, wo_l, wi_l):
        if PRINCIPLED:
            if is_principled:
                return principled_eval(p, wo_l, wi_l)
        return diffuse_eval_local((p[0], p[1], p[2]), wo_l, wi_l)

    @device
    def bsdf_sample(is_principled, p, wo_l, u_lobe, u1, u2):
        if PRINCIPLED:
            if is_principled:
                return principled_sample(p, wo_l, u_lobe, u1, u2)
        return diffuse_sample_local((p[0], p[1], p[2]), wo_l, u1, u2)

    @device
    def to_local(w, t, s, n):
        return (dot(w, t), dot(w, s), dot(w, n))

    @device
    def leave(p, ng, w, origin):
        """Origin of a ray leaving p towards w: on w's side of the surface. Only
        transmissive materials send rays to the other side of ng (turned to wo)."""
        if PRINCIPLED:
            if dot(ng, w) < ZERO:
                return offset_origin(p, neg(ng))
        return origin

    @device
    def consistent(wo, wo_l, w, w_l, ng):
        """Do the shading frame and the geometric surface agree on whether w is a
        reflection or a transmission of wo?"""
        return (wo_l[2] * w_l[2] > ZERO) == (dot(ng, wo) * dot(ng, w) > ZERO)

    @device
    def mirror(w, ng):
        return madd(w, ng, -TWO * dot(w, ng))

    @device
    def eval_world(is_principled, p, wo, wo_l, wi, t, s, n, ng):
        """BSDF * |cos| and pdf for world direction wi.

        Where the shading normal differs from the geometric one, part of a lobe can point
        to the wrong side of the surface (a reflection below it, or a refraction that stays
        above). Counting it would leak light through the surface and dropping it would lose
        energy (a white furnace would not render white), so that part is folded back:
        mirrored across the geometric tangent plane. The effective BSDF at wi is the
        original one at wi (if wi is on its proper side) plus the original one at the mirror
        image of wi (if that one was on the wrong side); sampling applies the same mirror,
        so eval, pdf and sample stay consistent."""
        if LEAN:
            # diffuse only, flat shading: n is ng turned to wo (bent only at grazing wo)
            cos_i = dot(n, wi)
            if cos_i <= ZERO or dot(ng, wi) <= ZERO:
                return (ZERO, ZERO, ZERO), ZERO
            k = cos_i * INV_PI
            return (p[0] * k, p[1] * k, p[2] * k), k
        wi_l = to_local(wi, t, s, n)
        f = (ZERO, ZERO, ZERO)
        pdf = ZERO
        if consistent(wo, wo_l, wi, wi_l, ng):
            f, pdf = bsdf_eval(is_principled, p, wo_l, wi_l)
        if FOLD:
            wm = mirror(wi, ng)
            wm_l = to_local(wm, t, s, n)
            if not consistent(wo, wo_l, wm, wm_l, ng):
                f2, pdf2 = bsdf_eval(is_principled, p, wo_l, wm_l)
                f = add(f, f2)
                pdf += pdf2
        return f, pdf

    @device
    def render_sample(px, py, sample_index, seed, width, height, max_bounces, rr_depth,
                      scene, stack):
        """Radiance (r, g, b) of one camera path through pixel (px, py), with the number of
        bounce rays and shadow rays it traced."""
        key = path_key(py * width + px, sample_index, seed)
        if THIN_LENS:
            o, d = thin_lens_ray(scene.cam, np.float32(px), np.float32(py),
                                 sample_1d(key, 0), sample_1d(key, 1), sample_1d(key, 2),
                                 sample_1d(key, 3), np.float32(width), np.float32(height))
        else:
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
        p_env = ZERO
        if ENV_MAP:
            p_env = scene.env_info[2]
        while True:
            t, tri, b1, b2 = closest_hit(o, d, INF, skip, scene.tri_v, scene.bvh_box,
                                         scene.bvh_child, stack)
            if tri < 0:
                if ENV_MAP:
                    le = env_eval(scene.env_img, scene.env_info, d)
                    weight = ONE
                    if pdf_prev > ZERO:
                        weight = power_heuristic(
                            pdf_prev, p_env * env_pdf(scene.env_pdf, scene.env_info, d))
                    radiance = add(radiance, scale(mul(beta, le), weight))
                elif ENVIRONMENT:
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
            tu, tv = tri_uv_at(scene, tri, b1, b2)

            # ---- Emission reached by this ray (MIS against light sampling) ----
            if TRI_LIGHTS:
                if emits(scene.mat, m, cos_o):
                    weight = ONE
                    if pdf_prev > ZERO:
                        pdf_light = scene.tri_light_pdf[tri] * t * t / abs(cos_o)
                        weight = power_heuristic(pdf_prev, pdf_light)
                    radiance = add(radiance, scale(mul(beta, emitted(scene, m, tu, tv)),
                                                   weight))

            if bounce >= max_bounces:
                break

            # ---- Material and shading frame ----
            # (nested ifs on the constants: Numba prunes a branch only when its condition
            # is a constant alone, and an unpruned branch is compiled even if never taken)
            is_principled = False
            alb = param3(scene, m, T_ALBEDO, 0, tu, tv)
            bp = (alb[0], alb[1], alb[2], ZERO, ZERO, ONE, ZERO, ZERO, ZERO, ZERO,
                  ZERO, ZERO, ZERO, ZERO)
            if PRINCIPLED:
                is_principled = scene.mat[m, M_TYPE] == MAT_PRINCIPLED
                if is_principled:
                    bp = material_params(scene, m, tu, tv)
            # A transmissive material is an interface with an inside: its frame keeps the
            # geometric front side. Anything else reflects on both sides: turn to wo.
            side = ONE
            if cos_o < ZERO and not (bp[13] > ZERO):
                side = -ONE
            ns = ng
            if SMOOTH:
                b0 = ONE - b1 - b2
                ns = normalize(add(add(scale(load3(scene.tri_n, tri, 0), b0),
                                       scale(load3(scene.tri_n, tri, 3), b1)),
                                   scale(load3(scene.tri_n, tri, 6), b2)))
                if dot(ns, ng) < ZERO:
                    ns = neg(ns)
            tangent = (ZERO, ZERO, ZERO)
            bitangent = (ZERO, ZERO, ZERO)
            has_tangent = False
            if TANGENTS:
                b0 = ONE - b1 - b2
                tt = add(add(scale(load3(scene.tri_t, tri, 0), b0),
                             scale(load3(scene.tri_t, tri, 3), b1)),
                         scale(load3(scene.tri_t, tri, 6), b2))
                tt = madd(tt, ns, -dot(tt, ns))
                if dot(tt, tt) > ZERO:
                    tangent = normalize(tt)
                    has_tangent = True
            if NORMAL_MAP:
                tn = scene.mat_tex[m, T_NORMAL]
                if tn >= 0 and has_tangent:
                    c = tex_lookup(scene.tex_data, scene.tex_int, scene.tex_f, tn, tu, tv)
                    # OpenGL convention: +Y (green) along the bitangent n x t (times the
                    # handedness of the UV mapping).
                    bt = scale(cross(ns, tangent), scene.tri_t[tri, 9])
                    mx = TWO * c[0] - ONE
                    my = TWO * c[1] - ONE
                    mz = TWO * c[2] - ONE
                    nm = add(add(scale(tangent, mx), scale(bt, my)), scale(ns, mz))
                    if dot(nm, nm) > ZERO:
                        ns = normalize(nm)
                        tangent = madd(tangent, ns, -dot(tangent, ns))
                        if dot(tangent, tangent) > ZERO:
                            tangent = normalize(tangent)
                        else:
                            has_tangent = False
            if side < ZERO:
                ng = neg(ng)
                ns = neg(ns)
            # A shading normal that puts wo below its horizon (normal maps, coarse meshes)
            # is bent towards wo just enough to see it: otherwise a lit surface turns black.
            s_o = ONE if dot(ng, wo) >= ZERO else -ONE
            c_o = dot(ns, wo) * s_o
            if c_o < HORIZON_EPS:
                ns = normalize(madd(ns, wo, s_o * (HORIZON_EPS - c_o)))
            if has_tangent:
                tangent = tangent_on(tangent, ns)
            elif PRINCIPLED:
                # Without texture coordinates the tangent is dp/du of the triangle's
                # barycentric parameterisation, its first edge, projected onto the shading
                # normal: Mitsuba 3's choice, so that anisotropy can be checked against it.
                tangent = tangent_on(e1, ns)
            else:
                tangent, bitangent = frame(ns)   # isotropic BSDFs only: any tangent will do
            if PRINCIPLED or TANGENTS:
                bitangent = cross(ns, tangent)
            if LEAN:
                wo_l = (ZERO, ZERO, ONE)     # unused by the Lambertian lobe but its side
            else:
                wo_l = to_local(wo, tangent, bitangent, ns)
            p_out = p
            if SMOOTH:
                p_out = terminator_lift(p, b1, b2, v0, e1, e2, load3(scene.tri_n, tri, 0),
                                        load3(scene.tri_n, tri, 3), load3(scene.tri_n, tri, 6),
                                        ng)
            origin = offset_origin(p_out, ng)   # the side of wo (all rays, but transmission)
            dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE

            # ---- Next-event estimation: the environment, or one light chosen by power ----
            # (nested ifs on constants, so that unused strategies are not compiled; inline,
            # because a call that passes the scene's arrays costs more than the work)
            if NEE:
                u_sel = sample_1d(key, dim + D_LIGHT_SELECT)
                u1 = sample_1d(key, dim + D_LIGHT_U)
                u2 = sample_1d(key, dim + D_LIGHT_V)
                do_lights = True
                if ENV_MAP:
                    if u_sel < p_env:
                        do_lights = False
                        wi, pdf_dir = env_sample(scene.env_marg, scene.env_cond, scene.env_pdf,
                                                 scene.env_info, u1, u2)
                        if pdf_dir > ZERO:
                            f, pdf_bsdf = eval_world(is_principled, bp, wo, wo_l, wi, tangent,
                                                     bitangent, ns, ng)
                            if max_comp(f) > ZERO:
                                n_shadow_rays += 1
                                if not any_hit(leave(p, ng, wi, origin), wi, INF, tri, -1,
                                               scene.tri_v, scene.bvh_box, scene.bvh_child,
                                               stack):
                                    pdf_light = p_env * pdf_dir
                                    weight = power_heuristic(pdf_light, pdf_bsdf) / pdf_light
                                    le = env_eval(scene.env_img, scene.env_info, wi)
                                    radiance = add(radiance, scale(mul(mul(beta, f), le), weight))

                    else:
                        u_sel = min((u_sel - p_env) / (ONE - p_env), ONE_MINUS_EPS)
                if ANY_LIGHTS:
                    if do_lights:
                        k = sample_discrete(scene.light_cdf, u_sel)
                        ref = scene.light_ref[k]
                        if TRI_LIGHTS:
                            if ref >= 0:
                                q, nl, _ = sample_triangle_point(scene.tri_v, ref, u1, u2)
                                wi, dist = direction_to(p, q)
                                cos_l = -dot(nl, wi)
                                lm = scene.tri_mat[ref]
                                # tri_light_pdf = selection pmf / area: the same density the
                                # emission-hit MIS above uses (0 for zero-area triangles).
                                pdf_area = scene.tri_light_pdf[ref]
                                if dist > ZERO and pdf_area > ZERO and emits(scene.mat, lm, cos_l):
                                    f, pdf_bsdf = eval_world(is_principled, bp, wo, wo_l, wi,
                                                             tangent, bitangent, ns, ng)
                                    if max_comp(f) > ZERO:
                                        n_shadow_rays += 1
                                        if not any_hit(leave(p, ng, wi, origin), wi,
                                                       dist * SHADOW_SHORTEN, tri, ref,
                                                       scene.tri_v, scene.bvh_box,
                                                       scene.bvh_child, stack):
                                            pdf_light = pdf_area * dist * dist / abs(cos_l)
                                            weight = power_heuristic(pdf_light,
                                                                     pdf_bsdf) / pdf_light
                                            lu, lv = ZERO, ZERO
                                            if TEXTURES:
                                                # texture coordinates of the light sample point
                                                lb1, lb2 = square_to_triangle(u1, u2)
                                                lu, lv = tri_uv_at(scene, ref, lb1, lb2)
                                            radiance = add(radiance, scale(
                                                mul(mul(beta, f), emitted(scene, lm, lu, lv)),
                                                weight))
                        if POINT_LIGHTS:
                            if ref < 0:
                                pl = -ref - 1
                                pmf = scene.light_cdf[k + 1] - scene.light_cdf[k]
                                if ENV_MAP:
                                    pmf *= ONE - p_env
                                wi, dist = direction_to(p, load3(scene.point_lights, pl, 0))
                                if dist > ZERO:
                                    f, pdf_bsdf = eval_world(is_principled, bp, wo, wo_l, wi,
                                                             tangent, bitangent, ns, ng)
                                    if max_comp(f) > ZERO:
                                        n_shadow_rays += 1
                                        if not any_hit(leave(p, ng, wi, origin), wi,
                                                       dist * SHADOW_SHORTEN, tri, -1,
                                                       scene.tri_v, scene.bvh_box,
                                                       scene.bvh_child, stack):
                                            # Delta light: no MIS; irradiance falls off as 1/d^2
                                            le = load3(scene.point_lights, pl, 3)
                                            radiance = add(radiance, scale(
                                                mul(mul(beta, f), le),
                                                ONE / (pmf * dist * dist)))

            # ---- BSDF sampling: the next ray ----
            wi_l, weight, pdf_bsdf = bsdf_sample(is_principled, bp, wo_l,
                                                 sample_1d(key, dim + D_BSDF_LOBE),
                                                 sample_1d(key, dim + D_BSDF_U),
                                                 sample_1d(key, dim + D_BSDF_V))
            if not (pdf_bsdf > ZERO):
                break
            wi = to_world(wi_l, tangent, bitangent, ns)   # unit: orthonormal frame
            if LEAN:
                if dot(ng, wi) <= ZERO:
                    break
            elif not consistent(wo, wo_l, wi, wi_l, ng):
                if not FOLD:
                    break   # the shading frame and the surface disagree: absorbed
                # folded back across the surface (see eval_world)
                wi = mirror(wi, ng)
            if FOLD:
                f, pdf_bsdf = eval_world(is_principled, bp, wo, wo_l, wi, tangent, bitangent,
                                         ns, ng)
                if not (pdf_bsdf > ZERO):
                    break
                weight = scale(f, ONE / pdf_bsdf)
            beta = mul(beta, weight)
            pdf_prev = pdf_bsdf
            o = leave(p, ng, wi, origin)
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
