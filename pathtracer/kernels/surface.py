"""The surface at a hit: texture coordinates, material parameters, emission, the shading
frame and where rays leave from.

``make_surface(features)`` returns these steps specialised for one feature set (see
:mod:`.integrator`); each takes only the arrays it reads.
"""
import functools
import math
from typing import NamedTuple

import numpy as np

from .constants import HORIZON_EPS, ONE, OFFSET_REL, TWO, ZERO
from .device import device, step_marker
from .layout import (ALPHA_BLEND, ALPHA_MASK, M_ALPHA, M_ALPHA_CUTOFF, M_ALPHA_MODE, T_ALPHA,
                     P_ANISOTROPIC, P_BASE, P_CLEARCOAT, P_CLEARCOAT_GLOSS, P_ETA,
                     P_FLATNESS, P_METALLIC, P_ROUGHNESS, P_SHEEN, P_SHEEN_TINT,
                     P_SPEC_TINT, P_TRANSMISSION, M_ALBEDO, M_ANISOTROPIC, M_CLEARCOAT,
                     M_CLEARCOAT_GLOSS, M_EMISSION,
                     M_ETA, M_METALLIC, M_ROUGHNESS, M_SHEEN, M_SHEEN_TINT, M_SPEC_TINT,
                     M_SPECULAR, M_SUBSURFACE, M_TRANSMISSION, M_TYPE, MAT_PRINCIPLED,
                     M_COND_ALPHA_U, M_COND_ALPHA_V, M_COND_DISTRIBUTION, M_COND_ETA,
                     M_COND_K, MAT_CONDUCTOR, MAT_DIFFUSE, T_COND_ALPHA_U, T_COND_ALPHA_V,
                     T_ALBEDO, T_ANISOTROPIC, T_CLEARCOAT, T_CLEARCOAT_GLOSS,
                     T_EMISSION, T_ETA, T_METALLIC, T_NORMAL, T_ROUGHNESS, T_SHEEN,
                     T_SHEEN_TINT, T_SPEC_TINT, T_SPECULAR, T_SUBSURFACE, T_TRANSMISSION,
                     TRI_COL0, TRI_COL1, TRI_COL2, TRI_N0, TRI_N1, TRI_N2, TRI_T0, TRI_T1,
                     TRI_T2, TRI_T_SIGN, TRI_UV0,
                     TRI_UV1, TRI_UV2, specialise)
from .normalmap import clamp_mapped_normal, mapped_normal_seeing
from .principled import fresnel_dielectric
from .textures import NO_FOOTPRINT, make_tex_lookup
from .vec import (add, cross, dot, frame, load3, luminance, madd, max_abs, neg, normalize,
                  scale)

ETA_MIN_TRANSMISSIVE = np.float32(1.001)   # eta = 1 is no interface (as Mitsuba)
SPEC_K = np.float32(0.08)                  # F0 = SPEC_K * specular (Burley 2012)


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


@device
def interpolate3(arr, tri, c0, c1, c2, b1, b2):
    """Barycentric interpolation of the three vectors of row tri at columns c0, c1, c2."""
    b0 = ONE - b1 - b2
    return add(add(scale(load3(arr, tri, c0), b0), scale(load3(arr, tri, c1), b1)),
               scale(load3(arr, tri, c2), b2))


@device
def thin_pane_reflects(eta, cos_d, u):
    """Does a ray at |cos| cos_d to a thin dielectric pane of index eta reflect (rather
    than pass straight through)? With probability R' = 2R / (1 + R): the reflectance of
    the pane's two interfaces with every interreflection (Mitsuba's thindielectric)."""
    r = fresnel_dielectric(cos_d, eta)[0]
    return u < TWO * r / (ONE + r)


@device
def unit(x):
    return min(max(x, ZERO), ONE)


class SurfaceSteps(NamedTuple):
    tri_uv_at: object
    opacity_at: object
    material_at: object
    tinted: object
    emitted: object
    shading_frame: object
    ray_origin: object


@functools.lru_cache(maxsize=None)
def make_surface(features, target="cpu"):
    """The surface steps for scenes with ``features`` (branches on unused features removed
    before compilation; conditions are constants alone, which is what Numba prunes)."""
    S = specialise(features)
    step = step_marker(target)
    TEXTURES = S.textures
    PRINCIPLED = S.principled
    CONDUCTOR = S.conductor
    GLOSSY = S.glossy
    SMOOTH = S.smooth
    TANGENTS = S.tangents
    NORMAL_MAP = S.normal_map
    tex_lookup = make_tex_lookup(S.wrap_modes, S.mipmaps)

    @step
    def param1(mat, mat_tex, tex_data, tex_int, tex_f, m, slot, col, u, v, fp):
        """A number parameter of material m, from its texture when it has one (fp: the
        lookup's footprint in texture coordinates, see textures.cone_footprint)."""
        if TEXTURES:
            t = mat_tex[m, slot]
            if t >= 0:
                r, g, b = tex_lookup(tex_data, tex_int, tex_f, t, u, v, fp)
                return luminance(r, g, b)
        return mat[m, col]

    @step
    def param3(mat, mat_tex, tex_data, tex_int, tex_f, m, slot, col, u, v, fp):
        """A colour parameter of material m, from its texture when it has one."""
        if TEXTURES:
            t = mat_tex[m, slot]
            if t >= 0:
                return tex_lookup(tex_data, tex_int, tex_f, t, u, v, fp)
        return mat[m, col], mat[m, col + 1], mat[m, col + 2]

    @step
    def tri_uv_at(tri_uv, tri, b1, b2):
        """Texture coordinates at barycentrics (b1, b2) of triangle tri."""
        if TEXTURES:
            b0 = ONE - b1 - b2
            return (b0 * tri_uv[tri, TRI_UV0] + b1 * tri_uv[tri, TRI_UV1] +
                    b2 * tri_uv[tri, TRI_UV2],
                    b0 * tri_uv[tri, TRI_UV0 + 1] + b1 * tri_uv[tri, TRI_UV1 + 1] +
                    b2 * tri_uv[tri, TRI_UV2 + 1])
        return ZERO, ZERO

    @step
    def opacity_at(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v, u_blend):
        """Whether material m's surface stops a ray at texture coordinates (u, v): always,
        unless its alpha mode is ALPHA_MASK (where the opacity, M_ALPHA or its texture read
        at the base level, reaches M_ALPHA_CUTOFF) or ALPHA_BLEND (with probability the
        opacity: ``u_blend`` a uniform number; stochastic transparency, unbiased, as
        Cycles and pbrt-v4 do)."""
        mode = mat[m, M_ALPHA_MODE]
        if mode != ALPHA_MASK and mode != ALPHA_BLEND:
            return True
        a = param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ALPHA, M_ALPHA, u, v,
                   NO_FOOTPRINT)
        if mode == ALPHA_MASK:
            return a >= mat[m, M_ALPHA_CUTOFF]
        return u_blend < a

    @step
    def emitted(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v, fp):
        """Emitted radiance of material m at texture coordinates (u, v)."""
        return param3(mat, mat_tex, tex_data, tex_int, tex_f, m, T_EMISSION, M_EMISSION, u, v,
                      fp)

    @step
    def principled_at(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v, fp):
        """The principled parameter tuple (layout P_*) of material m at (u, v)."""
        base = param3(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ALBEDO, M_ALBEDO, u, v,
                      fp)
        transmission = unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m,
                                   T_TRANSMISSION, M_TRANSMISSION, u, v, fp))
        eta = param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ETA, M_ETA, u, v, fp)
        if not (eta > ZERO):
            # derived from specular: F0 = 0.08 specular = ((eta - 1) / (eta + 1))^2
            spec = unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_SPECULAR,
                               M_SPECULAR, u, v, fp))
            eta = TWO / (ONE - math.sqrt(SPEC_K * spec)) - ONE
        if transmission > ZERO and eta == ONE:
            eta = ETA_MIN_TRANSMISSIVE
        return (max(base[0], ZERO), max(base[1], ZERO), max(base[2], ZERO),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ROUGHNESS,
                            M_ROUGHNESS, u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_METALLIC,
                            M_METALLIC, u, v, fp)),
                eta,
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_SPEC_TINT,
                            M_SPEC_TINT, u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ANISOTROPIC,
                            M_ANISOTROPIC, u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_SHEEN, M_SHEEN,
                            u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_SHEEN_TINT,
                            M_SHEEN_TINT, u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_CLEARCOAT,
                            M_CLEARCOAT, u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_CLEARCOAT_GLOSS,
                            M_CLEARCOAT_GLOSS, u, v, fp)),
                unit(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_SUBSURFACE,
                            M_SUBSURFACE, u, v, fp)),
                transmission)

    @step
    def conductor_at(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v, fp):
        """The conductor parameter tuple (layout P_COND_*) of material m at (u, v)."""
        tint = param3(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ALBEDO, M_ALBEDO, u, v,
                      fp)
        return (max(tint[0], ZERO), max(tint[1], ZERO), max(tint[2], ZERO),
                max(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_COND_ALPHA_U,
                           M_COND_ALPHA_U, u, v, fp), ZERO),
                max(param1(mat, mat_tex, tex_data, tex_int, tex_f, m, T_COND_ALPHA_V,
                           M_COND_ALPHA_V, u, v, fp), ZERO),
                mat[m, M_COND_ETA], mat[m, M_COND_ETA + 1], mat[m, M_COND_ETA + 2],
                mat[m, M_COND_K], mat[m, M_COND_K + 1], mat[m, M_COND_K + 2],
                mat[m, M_COND_DISTRIBUTION], ZERO, ZERO)

    @step
    def material_at(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v, fp):
        """(kind, parameter tuple) of material m at (u, v): kind MAT_DIFFUSE (which fills
        only the base colour, and eta 1), MAT_PRINCIPLED or MAT_CONDUCTOR."""
        kind = MAT_DIFFUSE
        if GLOSSY:
            kind = int(mat[m, M_TYPE])
        if PRINCIPLED:
            if kind == MAT_PRINCIPLED:
                return kind, principled_at(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v,
                                           fp)
        if CONDUCTOR:
            if kind == MAT_CONDUCTOR:
                return kind, conductor_at(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v,
                                          fp)
        alb = param3(mat, mat_tex, tex_data, tex_int, tex_f, m, T_ALBEDO, M_ALBEDO, u, v,
                     fp)
        return MAT_DIFFUSE, (alb[0], alb[1], alb[2], ZERO, ZERO, ONE, ZERO, ZERO, ZERO,
                             ZERO, ZERO, ZERO, ZERO, ZERO)

    @step
    def mapped_normal(mat_tex, tex_data, tex_int, tex_f, tri_t, tri, m, u, v, fp, ns,
                      tangent):
        """The world-space normal of material m's normal map at (u, v) (OpenGL convention:
        +Y, green, along the bitangent n x t times the handedness of the UV mapping), in the
        frame of the smooth normal ns and its tangent; ns where there is no normal map."""
        tn = mat_tex[m, T_NORMAL]
        if tn >= 0:
            c = tex_lookup(tex_data, tex_int, tex_f, tn, u, v, fp)
            bt = scale(cross(ns, tangent), tri_t[tri, TRI_T_SIGN])
            nm = add(add(scale(tangent, TWO * c[0] - ONE), scale(bt, TWO * c[1] - ONE)),
                     scale(ns, TWO * c[2] - ONE))
            if dot(nm, nm) > ZERO:
                return normalize(nm)
        return ns

    @step
    def shading_frame(tri_n, tri_t, mat_tex, tex_data, tex_int, tex_f, tri, m, b1, b2, e1,
                      ng, wo, transmissive, u, v, fp):
        """(ng, ns, tangent, bitangent, wp): the geometric normal, the orthonormal shading
        frame and the normal-mapped normal wp in that frame ((0, 0, 1) without a normal
        map), all turned to wo's side unless the material is transmissive (an interface
        with an inside keeps the geometric front side; anything else reflects on both
        sides). The frame's normal is the interpolated one (smooth meshes), never the
        mapped one: normal-mapped lobes are folded across the smooth surface (see
        .normalmap), so that shading does not depend on the triangle. A normal that would
        put wo below its horizon is bent towards wo just enough to see it, or a lit
        surface would turn black."""
        side = ONE
        if dot(ng, wo) < ZERO and not transmissive:
            side = -ONE
        ns = ng
        if SMOOTH:
            ns = normalize(interpolate3(tri_n, tri, TRI_N0, TRI_N1, TRI_N2, b1, b2))
            if dot(ns, ng) < ZERO:
                ns = neg(ns)
        tangent = (ZERO, ZERO, ZERO)
        bitangent = (ZERO, ZERO, ZERO)
        has_tangent = False
        if TANGENTS:
            tt = interpolate3(tri_t, tri, TRI_T0, TRI_T1, TRI_T2, b1, b2)
            tt = madd(tt, ns, -dot(tt, ns))
            if dot(tt, tt) > ZERO:
                tangent = normalize(tt)
                has_tangent = True
        nm = ns
        if NORMAL_MAP:
            if has_tangent:
                nm = mapped_normal(mat_tex, tex_data, tex_int, tex_f, tri_t, tri, m, u, v, fp, ns,
                                   tangent)
        if side < ZERO:
            ng = neg(ng)
            ns = neg(ns)
            nm = neg(nm)
        s_o = ONE if dot(ng, wo) >= ZERO else -ONE
        c_o = dot(ns, wo) * s_o
        if c_o < HORIZON_EPS:
            ns = normalize(madd(ns, wo, s_o * (HORIZON_EPS - c_o)))
        if has_tangent:
            tangent = tangent_on(tangent, ns)
        elif GLOSSY:
            # Without texture coordinates the tangent is dp/du of the triangle's
            # barycentric parameterisation, its first edge, projected onto the shading
            # normal: Mitsuba 3's choice, so that anisotropy can be checked against it.
            tangent = tangent_on(e1, ns)
        else:
            tangent, bitangent = frame(ns)   # isotropic BSDFs only: any tangent will do
        if GLOSSY or TANGENTS:
            bitangent = cross(ns, tangent)
        wp = (ZERO, ZERO, ONE)
        if NORMAL_MAP:
            if has_tangent:
                wp = clamp_mapped_normal((dot(nm, tangent), dot(nm, bitangent), dot(nm, ns)))
                wp = mapped_normal_seeing(wp, (dot(wo, tangent), dot(wo, bitangent),
                                               dot(wo, ns)))
        return ng, ns, tangent, bitangent, wp

    @step
    def ray_origin(tri_n, tri, p, b1, b2, v0, e1, e2, ng):
        """Where rays leaving on ng's side start: p (lifted off smooth-shaded triangles,
        see terminator_lift) pushed off the surface along ng."""
        if SMOOTH:
            p = terminator_lift(p, b1, b2, v0, e1, e2, load3(tri_n, tri, TRI_N0),
                                load3(tri_n, tri, TRI_N1), load3(tri_n, tri, TRI_N2), ng)
        return offset_origin(p, ng)

    @step
    def tinted(params, tri_col, tri, b1, b2):
        """The parameter tuple with its base colour times the vertex colour interpolated at
        barycentrics (b1, b2) of triangle tri (glTF: COLOR_0 multiplies the base colour).
        Called only where the scene has vertex colours (Features.vertex_colors)."""
        b0 = ONE - b1 - b2
        c = madd(madd(scale(load3(tri_col, tri, TRI_COL0), b0), load3(tri_col, tri, TRI_COL1),
                      b1), load3(tri_col, tri, TRI_COL2), b2)
        return (params[P_BASE] * c[0], params[P_BASE + 1] * c[1], params[P_BASE + 2] * c[2],
                params[P_ROUGHNESS], params[P_METALLIC], params[P_ETA], params[P_SPEC_TINT],
                params[P_ANISOTROPIC], params[P_SHEEN], params[P_SHEEN_TINT],
                params[P_CLEARCOAT], params[P_CLEARCOAT_GLOSS], params[P_FLATNESS],
                params[P_TRANSMISSION])

    return SurfaceSteps(tri_uv_at, opacity_at, material_at, tinted, emitted, shading_frame, ray_origin)

