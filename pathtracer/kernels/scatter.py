"""BSDFs in world space: evaluation and sampling in the shading frame, made consistent with
the geometric surface.

``make_scatter(features)`` returns the steps specialised for one feature set (see
:mod:`.integrator`). The local BSDFs are :mod:`.materials` (Lambertian) and
:mod:`.principled` and :mod:`.conductor`; ``kind`` (layout MAT_*) says which one a parameter
tuple belongs to.
"""
import functools
from typing import NamedTuple

from .constants import INV_PI, ONE, TWO, ZERO
from .device import device, step_marker
from .conductor import conductor_eval, conductor_sample
from .layout import MAT_CONDUCTOR, MAT_PRINCIPLED, P_BASE, specialise
from .materials import diffuse_eval_local, diffuse_sample_local
from .normalmap import NM_FLAT_COS, consistent_with_smooth, mapped_frame, mirror_smooth
from .principled import Lobes, make_principled
from .surface import offset_origin
from .vec import add, dot, madd, neg, scale, to_world


@device
def to_local(w, t, s, n):
    return (dot(w, t), dot(w, s), dot(w, n))


@device
def base_color(params):
    """The base colour (albedo) of a parameter tuple."""
    return params[P_BASE], params[P_BASE + 1], params[P_BASE + 2]


@device
def consistent(wo, wo_l, w, w_l, ng):
    """Do the shading frame and the geometric surface agree on whether w is a reflection
    or a transmission of wo?"""
    return (wo_l[2] * w_l[2] > ZERO) == (dot(ng, wo) * dot(ng, w) > ZERO)


@device
def mirror(w, ng):
    """w mirrored across the plane with unit normal ng."""
    return madd(w, ng, -TWO * dot(w, ng))


class ScatterSteps(NamedTuple):
    local_wo: object
    eval_world: object
    sample_world: object
    leave: object
    side_normal: object
    own_skip: object
    bsdf_eval: object      # (the BSDF in the shading frame, for tests)
    bsdf_sample: object


@functools.lru_cache(maxsize=None)
def make_material(features, target="cpu"):
    """(material_eval, material_sample): the BSDF of a material kind (``kind``, layout
    MAT_*) in the local shading frame, for scenes with ``features``."""
    S = specialise(features)
    step = step_marker(target)
    PRINCIPLED = S.principled
    CONDUCTOR = S.conductor
    principled_eval, principled_sample = make_principled(Lobes(*S.lobes))

    @step
    def material_eval(kind, params, wo_l, wi_l):
        if PRINCIPLED:
            if kind == MAT_PRINCIPLED:
                return principled_eval(params, wo_l, wi_l)
        if CONDUCTOR:
            if kind == MAT_CONDUCTOR:
                return conductor_eval(params, wo_l, wi_l)
        return diffuse_eval_local(base_color(params), wo_l, wi_l)

    @step
    def material_sample(kind, params, wo_l, u_choice, u1, u2):
        if PRINCIPLED:
            if kind == MAT_PRINCIPLED:
                return principled_sample(params, wo_l, u_choice, u1, u2)
        if CONDUCTOR:
            if kind == MAT_CONDUCTOR:
                return conductor_sample(params, wo_l, u1, u2)
        return diffuse_sample_local(base_color(params), wo_l, u1, u2)

    return material_eval, material_sample


@functools.lru_cache(maxsize=None)
def make_scatter(features, target="cpu"):
    """The scattering steps for scenes with ``features``."""
    S = specialise(features)
    step = step_marker(target)
    PRINCIPLED = S.principled
    FOLD = S.fold
    LEAN = S.lean
    NORMAL_MAP = S.normal_map
    material_eval, material_sample = make_material(features, target)

    @step
    def mapped_lobe(kind, params, tm, bm, wp, wo_l, wi_l):
        """The material in the normal-mapped frame (tm, bm, wp), directions in the smooth
        frame: f |cos| and pdf."""
        return material_eval(kind, params, to_local(wo_l, tm, bm, wp),
                             to_local(wi_l, tm, bm, wp))

    @step
    def mapped_eval(kind, params, wp, wo_l, wi_l):
        """f |cos| and pdf of a normal-mapped material in the smooth frame: the material
        shaded with the mapped normal wp, the part of its lobes on the wrong side of the
        smooth surface folded back across it (see .normalmap)."""
        tm, bm = mapped_frame(wp)
        f = (ZERO, ZERO, ZERO)
        pdf = ZERO
        if consistent_with_smooth(wp, wo_l, wi_l):
            f, pdf = mapped_lobe(kind, params, tm, bm, wp, wo_l, wi_l)
        wm = mirror_smooth(wi_l)
        if not consistent_with_smooth(wp, wo_l, wm):
            f2, pdf2 = mapped_lobe(kind, params, tm, bm, wp, wo_l, wm)
            f = add(f, f2)
            pdf += pdf2
        return f, pdf

    @step
    def mapped_sample(kind, params, wp, wo_l, u_choice, u1, u2):
        """(wi, weight, pdf) of mapped_eval: the material sampled in the mapped frame, a
        direction on the wrong side of the smooth surface mirrored across it."""
        tm, bm = mapped_frame(wp)
        wi_m, weight, pdf = material_sample(kind, params, to_local(wo_l, tm, bm, wp),
                                            u_choice, u1, u2)
        if not (pdf > ZERO):
            return wi_m, weight, ZERO
        wi = to_world(wi_m, tm, bm, wp)
        folded = False
        if not consistent_with_smooth(wp, wo_l, wi):
            wi = mirror_smooth(wi)
            folded = True
        else:
            folded = not consistent_with_smooth(wp, wo_l, mirror_smooth(wi))
        if folded:
            # two lobes meet at wi: the effective f and pdf are their sums
            f, pdf = mapped_eval(kind, params, wp, wo_l, wi)
            if not (pdf > ZERO):
                return wi, weight, ZERO
            weight = scale(f, ONE / pdf)
        return wi, weight, pdf

    @step
    def bsdf_eval(kind, params, wp, wo_l, wi_l):
        """f |cos| and pdf in the shading frame: the material, normal-mapped where wp (the
        mapped normal in that frame) is not the frame's z."""
        if NORMAL_MAP:
            if wp[2] < NM_FLAT_COS:
                return mapped_eval(kind, params, wp, wo_l, wi_l)
        return material_eval(kind, params, wo_l, wi_l)

    @step
    def bsdf_sample(kind, params, wp, wo_l, u_choice, u1, u2):
        if NORMAL_MAP:
            if wp[2] < NM_FLAT_COS:
                return mapped_sample(kind, params, wp, wo_l, u_choice, u1, u2)
        return material_sample(kind, params, wo_l, u_choice, u1, u2)

    @step
    def local_wo(wo, t, s, n):
        """wo in the shading frame (the Lambertian-only kernel needs only its side)."""
        if LEAN:
            return (ZERO, ZERO, ONE)
        return to_local(wo, t, s, n)

    @step
    def eval_world(kind, params, wo, wo_l, wi, t, s, n, ng, wp):
        """BSDF * |cos| and pdf for world direction wi.

        Where the shading normal differs from the geometric one, part of a lobe can point
        to the wrong side of the surface (a reflection below it, or a refraction that stays
        above). Counting it would leak light through the surface and dropping it would lose
        energy (a white furnace would not render white), so that part is folded back:
        mirrored across the geometric tangent plane. The effective BSDF at wi is the
        original one at wi (if wi is on its proper side) plus the original one at the mirror
        image of wi (if that one was on the wrong side); sampling applies the same mirror,
        so eval, pdf and sample stay consistent. wp: the mapped normal in the frame
        (t, s, n) ((0, 0, 1) without a normal map; see .normalmap)."""
        if LEAN:
            # diffuse only, flat shading: n is ng turned to wo (bent only at grazing wo)
            cos_i = dot(n, wi)
            if cos_i <= ZERO or dot(ng, wi) <= ZERO:
                return (ZERO, ZERO, ZERO), ZERO
            k = cos_i * INV_PI
            albedo = base_color(params)
            return (albedo[0] * k, albedo[1] * k, albedo[2] * k), k
        wi_l = to_local(wi, t, s, n)
        f = (ZERO, ZERO, ZERO)
        pdf = ZERO
        if consistent(wo, wo_l, wi, wi_l, ng):
            f, pdf = bsdf_eval(kind, params, wp, wo_l, wi_l)
        if FOLD:
            wm = mirror(wi, ng)
            wm_l = to_local(wm, t, s, n)
            if not consistent(wo, wo_l, wm, wm_l, ng):
                f2, pdf2 = bsdf_eval(kind, params, wp, wo_l, wm_l)
                f = add(f, f2)
                pdf += pdf2
        return f, pdf

    @step
    def sample_world(kind, params, wo, wo_l, t, s, n, ng, wp, u_choice, u1, u2):
        """(wi, weight = f |cos| / pdf, pdf) of a sampled world direction; pdf = 0: the
        path is absorbed. A direction on the wrong side of the geometric surface is folded
        back (see eval_world), whose effective BSDF and pdf then give the weight."""
        wi_l, weight, pdf_bsdf = bsdf_sample(kind, params, wp, wo_l, u_choice, u1, u2)
        if not (pdf_bsdf > ZERO):
            return wi_l, weight, ZERO
        wi = to_world(wi_l, t, s, n)   # unit: orthonormal frame
        folded = False
        if LEAN:
            if dot(ng, wi) <= ZERO:
                return wi, weight, ZERO
        elif not consistent(wo, wo_l, wi, wi_l, ng):
            if not FOLD:
                return wi, weight, ZERO   # the shading frame and the surface disagree
            wi = mirror(wi, ng)
            folded = True
        if FOLD:
            # The sample's own f / pdf is the effective one unless wi was folded or its
            # mirror image is on the wrong side (then eval_world adds that part): the
            # usual case needs no second BSDF evaluation.
            if not folded:
                wm = mirror(wi, ng)
                folded = not consistent(wo, wo_l, wm, to_local(wm, t, s, n), ng)
            if folded:
                f, pdf_bsdf = eval_world(kind, params, wo, wo_l, wi, t, s, n, ng, wp)
                if not (pdf_bsdf > ZERO):
                    return wi, weight, ZERO
                weight = scale(f, ONE / pdf_bsdf)
        return wi, weight, pdf_bsdf

    @step
    def leave(p, ng, w, origin):
        """Origin of a ray leaving p towards w: on w's side of the surface. Only
        transmissive materials send rays to the other side of ng (turned to wo)."""
        if PRINCIPLED:
            if dot(ng, w) < ZERO:
                return offset_origin(p, neg(ng))
        return origin

    @step
    def side_normal(ng, ns, wp):
        """The normal whose plane decides whether a direction is a reflection or a
        transmission (eval_world, sample_world and leave take it as ng): the triangle's,
        but the smooth frame's on a normal-mapped surface. There the lobes are already
        folded across the smooth surface (mapped_eval), and folding them again across the
        triangle would depend on the triangle: where light grazes, a coarse mesh would
        show its facets. Rays into the wedge between the two planes are instead tested
        against their own triangle (own_skip)."""
        if NORMAL_MAP:
            if wp[2] < NM_FLAT_COS:
                return ns
        return ng

    @step
    def own_skip(tri, ng_tri, n_side, w):
        """The triangle a ray leaving triangle tri towards w must not hit: tri itself, or
        none (-1) for a ray into the wedge between the side normal's plane and the
        triangle's own (ng_tri), which may have to cross its own triangle: then it is
        blocked by it, as by any other surface (no light passes the mesh)."""
        if NORMAL_MAP:
            if (dot(n_side, w) > ZERO) != (dot(ng_tri, w) > ZERO):
                return -1
        return tri

    return ScatterSteps(local_wo, eval_world, sample_world, leave, side_normal, own_skip,
                        bsdf_eval, bsdf_sample)
