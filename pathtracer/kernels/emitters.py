"""Emitters: sampling a direction towards one (next-event estimation) and the light pdf of
an emitter that a BSDF-sampled ray reached (for multiple importance sampling).

Every light kind (HDRI environment, emissive triangle, point light) is sampled through one
function, :func:`sample_emitter` of ``make_emitters(features)``, that returns the same
record (as Mitsuba 3's ``Emitter::sample_direction`` and pbrt-v4's ``SampleLd`` do):

    (wi, t_max, radiance, pdf_light, is_delta, light_tri)

``wi`` the unit direction from the shading point, ``t_max`` how far a shadow ray must be
clear (INF for the environment), ``radiance`` the emitted radiance (for a point light, the
intensity) arriving along ``wi``, ``pdf_light`` the solid-angle density of ``wi``, selection
included (for a point light the pmf times distance squared, so that radiance / pdf_light is
the irradiance term), ``is_delta`` whether MIS against BSDF sampling is impossible (point
lights) and ``light_tri`` the light's triangle, which the shadow ray must not hit (-1 when
none). ``pdf_light`` = 0 means no sample.

The environment's radiance comes with its sample: the map's texels hold radiance and
sampling density side by side (kernels.envmap), so the four texels that the sample's density
is read from give the radiance at the sampled point too, without the inverse trigonometry
of a lookup by direction (as Mitsuba's envmap evaluates its sample). (Until 2026-11-27 the
record carried the sample's map coordinates and the radiance was looked up after the shadow
ray, from an image apart from the densities: a second lookup, which for every occluded
sample had cost 12 % on an H100.)
"""
import functools
from typing import NamedTuple

from .constants import INF, ONE, ONE_MINUS_EPS, SHADOW_SHORTEN, ZERO
from .device import device, step_marker
from .envmap import env_locate, env_lookup_cell, env_sample_lit
from .layout import (ENV_P_SELECT, PL_AXIS, PL_CONE_OFFSET, PL_CONE_SCALE, PL_INTENSITY,
                     PL_POSITION, point_light_index, specialise)
from .lights import (direction_to, light_tree_pmf, sample_discrete, sample_light_tree,
                     sample_triangle_point)
from .materials import emits
from .search import last_at_most
from .surface import make_surface
from .textures import NO_FOOTPRINT
from .vec import dot, load3, scale
from .warps import power_heuristic, square_to_triangle

NO_RADIANCE = (ZERO, ZERO, ZERO)


@device
def mis_weight_hit(pdf_prev, pdf_light):
    """Weight of emission reached by a ray that BSDF sampling made with density pdf_prev
    against light sampling's pdf_light (power heuristic, Veach 1997); 1 for camera rays
    (pdf_prev = 0: emission seen directly has no other strategy)."""
    if pdf_prev > ZERO:
        return power_heuristic(pdf_prev, pdf_light)
    return ONE


class EmitterSteps(NamedTuple):
    sample_emitter: object
    hit_emission: object
    escaped: object
    escaped_in_cell: object


@functools.lru_cache(maxsize=None)
def make_emitters(features, target="cpu"):
    """The emitter steps for scenes with ``features``."""
    S = specialise(features)
    step = step_marker(target)
    TRI_LIGHTS = S.tri_lights
    POINT_LIGHTS = S.point_lights
    ANY_LIGHTS = S.any_lights
    LIGHT_TREE = S.light_tree
    ENV_MAP = S.env_map
    ENVIRONMENT = S.environment
    TEXTURES = S.textures
    surface = make_surface(features, target)
    tri_uv_at = surface.tri_uv_at
    # the light pick's search: on the CPU without a mispredicted branch per step (the
    # Cornell box +4.7 % camera paths/s, 2 EPYC cores); on the GPU the bisection, whose
    # branch the warp's lanes mostly take alike (the select-based one: Cornell 0.996x on
    # an H200; both 2026-11-28, python -m bench.ab)
    pick_light = last_at_most if target == "cpu" else sample_discrete
    # the sky's searches from guide-table brackets on the CPU only (kernels.envmap)
    ENV_GUIDED = target == "cpu"
    # render.hideEmitters: a camera ray (the one ray with pdf_prev = 0: every BSDF sample
    # that continues a path has pdf > 0) sees no emitter, as Mitsuba 3's hide_emitters
    HIDE = S.hide_emitters
    emitted = surface.emitted

    @step
    def sample_environment(env_marg, env_cond, env_guide, env_img, env_info, u1, u2):
        wi, pdf_dir, le, _, _ = env_sample_lit(env_marg, env_cond, env_guide, env_img,
                                               env_info, u1, u2, ENV_GUIDED)
        if not (pdf_dir > ZERO):
            return wi, INF, NO_RADIANCE, ZERO, False, -1
        return wi, INF, le, env_info[ENV_P_SELECT] * pdf_dir, False, -1

    @step
    def sample_triangle_light(tri_v, tri_mat, tri_uv, tri_light_pdf, mat, mat_tex, tex_data,
                              tex_int, tex_f, ref, pmf, p, u1, u2):
        q, nl, _ = sample_triangle_point(tri_v, ref, u1, u2)
        wi, dist = direction_to(p, q)
        cos_l = -dot(nl, wi)
        lm = tri_mat[ref]
        # tri_light_pdf = selection pmf / area: the same density hit_emission uses (0 for
        # zero-area triangles); with the light tree, pmf is the tree's pick (else 1)
        pdf_area = tri_light_pdf[ref] * pmf
        if not (dist > ZERO and pdf_area > ZERO and emits(mat, lm, cos_l)):
            return wi, ZERO, NO_RADIANCE, ZERO, False, -1
        lu, lv = ZERO, ZERO
        if TEXTURES:
            # texture coordinates of the sampled point, from the sampler's barycentrics
            lb1, lb2 = square_to_triangle(u1, u2)
            lu, lv = tri_uv_at(tri_uv, ref, lb1, lb2)
        return (wi, dist * SHADOW_SHORTEN, emitted(mat, mat_tex, tex_data, tex_int, tex_f, lm,
                                                   lu, lv, NO_FOOTPRINT),
                pdf_area * dist * dist / abs(cos_l), False, ref)

    @step
    def sample_point_light(point_lights, pmf, ref, p):
        pl = point_light_index(ref)
        wi, dist = direction_to(p, load3(point_lights, pl, PL_POSITION))
        # a spot light's cone (layout PL_CONE_*; 1 for a point light)
        t = min(max(-dot(wi, load3(point_lights, pl, PL_AXIS)) *
                    point_lights[pl, PL_CONE_SCALE] + point_lights[pl, PL_CONE_OFFSET], ZERO),
                ONE)
        if not (dist > ZERO and t > ZERO):
            return wi, ZERO, NO_RADIANCE, ZERO, True, -1
        # a delta light: radiance / pdf_light = intensity / (pmf * dist^2)
        return (wi, dist * SHADOW_SHORTEN, scale(load3(point_lights, pl, PL_INTENSITY), t * t),
                pmf * dist * dist, True, -1)

    @step
    def sample_emitter(scene, p, origin, u_sel, u1, u2):
        """One emitter sample seen from p (see the module's docstring): the environment
        with probability env_info[ENV_P_SELECT], otherwise one light chosen in proportion
        to its power, or with the light tree by its importance seen from ``origin`` (where
        the surface's reflected rays start: hit_emission weighs their hits with the pick's
        probability there)."""
        if ENV_MAP:
            p_env = scene.env_info[ENV_P_SELECT]
            if u_sel < p_env:
                return sample_environment(scene.env_marg, scene.env_cond, scene.env_guide,
                                          scene.env_img, scene.env_info, u1, u2)
            u_sel = min((u_sel - p_env) / (ONE - p_env), ONE_MINUS_EPS)
        if ANY_LIGHTS:
            if LIGHT_TREE:
                k, pmf = sample_light_tree(scene.lt_node, scene.lt_link, origin, u_sel)
                if k < 0:
                    return (ZERO, ZERO, ONE), ZERO, NO_RADIANCE, ZERO, False, -1
            else:
                k = pick_light(scene.light_cdf, u_sel)
                pmf = ONE
            ref = scene.light_ref[k]
            if TRI_LIGHTS:
                if ref >= 0:
                    return sample_triangle_light(
                        scene.tri_v, scene.tri_mat, scene.tri_uv, scene.tri_light_pdf,
                        scene.mat, scene.mat_tex, scene.tex_data, scene.tex_int, scene.tex_f,
                        ref, pmf, p, u1, u2)
            if POINT_LIGHTS:
                if not LIGHT_TREE:
                    pmf = scene.light_cdf[k + 1] - scene.light_cdf[k]
                if ENV_MAP:
                    pmf *= ONE - scene.env_info[ENV_P_SELECT]
                return sample_point_light(scene.point_lights, pmf, ref, p)
        return (ZERO, ZERO, ONE), ZERO, NO_RADIANCE, ZERO, False, -1

    @step
    def hit_emission(mat, mat_tex, tex_data, tex_int, tex_f, tri_light_pdf, lt_node, lt_link,
                     tri_light_leaf, tri, m, cos_o, o, t, pdf_prev, u, v, fp):
        """(emitted radiance, MIS weight, emits) of triangle tri (material m) reached at
        distance t by a ray from o, seen at cosine cos_o with its front normal; fp: the
        footprint of the texture lookup (see textures.cone_footprint)."""
        if not emits(mat, m, cos_o):
            return NO_RADIANCE, ZERO, False
        if HIDE:
            if not (pdf_prev > ZERO):
                return NO_RADIANCE, ZERO, False
        pdf_light = ZERO
        if pdf_prev > ZERO:
            pdf_light = tri_light_pdf[tri] * t * t / abs(cos_o)
            if LIGHT_TREE:
                # the tree's pick seen from the ray's origin (sample_emitter's origin for
                # reflected rays; a transmitted ray starts a few ulps away on the other
                # side, where the importance differs by rounding)
                pdf_light *= light_tree_pmf(lt_node, lt_link, tri_light_leaf[tri], o)
            # The footprint filters only what the camera sees directly: a MIS-weighted hit
            # sees the unfiltered emission, as the light sample it is weighed against does.
            fp = NO_FOOTPRINT
        return (emitted(mat, mat_tex, tex_data, tex_int, tex_f, m, u, v, fp),
                mis_weight_hit(pdf_prev, pdf_light), True)

    @step
    def escaped(env, env_img, env_info, d, pdf_prev):
        """(radiance, MIS weight) of the environment seen by a ray leaving the scene along
        d. A constant environment is not sampled by next-event estimation: weight 1."""
        if HIDE:
            if not (pdf_prev > ZERO):
                return NO_RADIANCE, ZERO
        if ENV_MAP:
            # (the radiance and, for MIS, the density from one mapping of d to the map)
            i0, i1, j0, j1, fx, fy, y = env_locate(env_img, env_info, d)
            return escaped_in_cell(env_img, env_info, i0, i1, j0, j1, fx, fy, y, pdf_prev)
        if ENVIRONMENT:
            return (env[0], env[1], env[2]), ONE
        return NO_RADIANCE, ZERO

    @step
    def escaped_in_cell(env_img, env_info, i0, i1, j0, j1, fx, fy, y, pdf_prev):
        """escaped for an environment map, given the cell its direction reads
        (envmap.env_locate: i0, i1, j0, j1, fx, fy, y)."""
        if HIDE:
            if not (pdf_prev > ZERO):
                return NO_RADIANCE, ZERO
        le, pdf_dir = env_lookup_cell(env_img, i0, i1, j0, j1, fx, fy, y, pdf_prev > ZERO)
        return le, mis_weight_hit(pdf_prev, env_info[ENV_P_SELECT] * pdf_dir)

    return EmitterSteps(sample_emitter, hit_emission, escaped, escaped_in_cell)
