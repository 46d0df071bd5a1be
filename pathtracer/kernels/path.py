"""The path tracer's bounce, written once: every driver (:mod:`.drivers`) is a loop around it.

``make_path(features, target)`` closes over the scene's :class:`~.layout.Specialisation`;
branches on those constants are removed before compilation, so a scene without point
lights, emissive triangles, smooth normals or an environment compiles none of that code
(pbrt-v4's wavefront integrator instantiates per material type the same way; here Python
closures do it).

Estimator (Veach 1997, ch. 9; the structure of Mitsuba 3's ``path`` integrator and of
pbrt-v4's ``PathIntegrator::Li``): unidirectional path tracing with next-event estimation
to one emitter, BSDF sampling, both combined by the power heuristic, and Russian roulette
after ``rr_depth`` bounces. ``max_bounces`` counts scattering events: 0 shows only emitters
seen directly, 1 is direct lighting (Mitsuba's max_depth = max_bounces + 1).

A vertex is named steps over small records: the ray's hit (:class:`Hit`, the traversal's
answer), the surface there (:class:`Geometry`: ``surface_geometry``), the emitter reached
(``escaped_path`` or ``emission_at``, weighted by MIS), the material and shading frame
(:class:`Shading`: ``surface_shading``), next-event estimation (``sample_emitter`` for
every light kind, then one shadow-ray-and-MIS tail, ``direct_light``), BSDF sampling
(``next_ray``) and ``russian_roulette``; ``shade_surface`` is their sequence and
``path_vertex`` the traversal and one of the two ends. The path between vertices is a
:class:`PathState`. The steps under these live in :mod:`.surface`, :mod:`.scatter` and
:mod:`.emitters`.
"""
import functools
import math
from typing import NamedTuple

import numpy as np

from .camera import pinhole_ray, thin_lens_ray
from .constants import INF, ONE, RR_MAX, ZERO
from .device import device, step_marker
from .emitters import make_emitters
from .layout import (ALPHA_DIMS, ALPHA_THIN, M_ALPHA_MODE, M_THIN_ETA, D_ALPHA, D_ALPHA_SHADOW, CAM_CONE, D_BSDF_LOBE, D_BSDF_U, D_BSDF_V, D_FIRST_BOUNCE, D_LENS_U,
                     D_LENS_V, D_LIGHT_SELECT, D_LIGHT_U, D_LIGHT_V, D_PIXEL_X, D_PIXEL_Y,
                     D_RR, DIMS_PER_BOUNCE, M_ONE_SIDED, P_TRANSMISSION, STAT_BOUNCE_RAYS,
                     STAT_NONFINITE, STAT_SHADOW_RAYS, TRI_E1, TRI_E2, TRI_V0, specialise)
from .rng import make_pair_opener, make_sampler, sample_1d
from .scatter import make_scatter
from .surface import make_surface, thin_pane_reflects
from .textures import NO_FOOTPRINT, cone_footprint
from .traverse import any_hit, closest_hit
from .vec import add, cross, dot, load3, madd, max_comp, mul, neg, normalize, scale
from .warps import power_heuristic
from .wide import any_hit_wide, closest_hit_wide

# Trilinear textures are filtered over ray-cone footprints at the camera's hit and the
# first bounce's; later hits read the image itself (bilinearly). Filtering every bounce
# cost 29 % of the textured scene's paths/s on an H100 (2026-11-23, bench.ab) for lookups
# whose aliasing the indirect light's own averaging hides.
MIP_LAST_BOUNCE = 1


@device
def hit_point(tri_v, tri, b1, b2):
    """The point of triangle tri at barycentrics (b1, b2)."""
    return madd(madd(load3(tri_v, tri, TRI_V0), load3(tri_v, tri, TRI_E1), b1),
                load3(tri_v, tri, TRI_E2), b2)


class PathState(NamedTuple):
    """A path between two vertices (the drivers carry it from one bounce to the next)."""
    o: tuple            # the ray's origin and direction
    d: tuple
    beta: tuple         # the throughput: product of f cos / pdf (and 1/q of RR)
    radiance: tuple     # radiance gathered so far
    pdf_prev: float     # solid-angle pdf of the BSDF sample that made the ray; 0 for the
    #                     camera ray (emission seen directly: no MIS)
    skip: int           # the triangle the ray leaves (never re-hit), -1 none
    bounce: int         # scattering events so far
    cone: float         # the ray cone's width at o (mip-mapped textures only)


class Hit(NamedTuple):
    """The closest hit of a ray (the traversal's answer): tri < 0 where none."""
    t: float
    tri: int
    b1: float
    b2: float


class Geometry(NamedTuple):
    """The surface at a hit: position, triangle frame, material index and texture
    coordinates with their filter footprint."""
    p: tuple
    v0: tuple
    e1: tuple
    e2: tuple
    ng: tuple           # the triangle's unit normal (front: counter-clockwise winding)
    wo: tuple           # towards the ray's origin
    m: int
    tu: float
    tv: float
    fp: tuple           # texture footprint (textures.NO_FOOTPRINT: none)


class Shading(NamedTuple):
    """The material and shading frame at a surface, and where rays leave it."""
    kind: int           # layout MAT_*: which BSDF params feeds
    params: tuple
    ng: tuple           # the side normal (scatter.side_normal)
    ng_tri: tuple       # the triangle's normal as the shading frame left it
    ns: tuple
    tangent: tuple
    bitangent: tuple
    wp: tuple           # the mapped normal in the shading frame
    wo_l: tuple         # wo in the shading frame
    origin: tuple       # where rays leave (surface.ray_origin)


class PathSteps(NamedTuple):
    """The steps of :func:`make_path` that drivers call."""
    camera_ray: object
    start_camera_path: object
    path_state: object
    surface_geometry: object
    surface_shading: object
    emission_at: object
    next_ray: object
    escaped_path: object
    shade_surface: object
    path_vertex: object
    trace_hit: object
    add_sample: object
    store_pixel: object
    spread_of: object


class SurfaceSteps(NamedTuple):
    """The steps at a surface hit (:func:`make_surface_steps`)."""
    trace_hit: object
    surface_geometry: object
    emission_at: object
    surface_shading: object
    direct_light: object
    next_ray: object
    sample_emitter: object


@functools.lru_cache(maxsize=None)
def make_surface_steps(features, target="cpu"):
    """The bounce's steps at a surface (:class:`SurfaceSteps`) for scenes with
    ``features`` on ``target``: the geometry, the emission seen, the material and shading
    frame, next-event estimation's shadow-ray tail and BSDF sampling."""
    S = specialise(features)
    step = step_marker(target)
    MIPMAPS = S.mipmaps
    VERTEX_COLORS = S.vertex_colors
    ALPHA = S.alpha
    # The CPU traverses the eight-wide BVH (kernels.wide: SIMD box and triangle tests), whose
    # arrays its backend puts in the scene's bvh_box and bvh_child; the GPU the binary one.
    trace_any = any_hit_wide if target == "cpu" else any_hit
    trace_closest = closest_hit_wide if target == "cpu" else closest_hit
    surface = make_surface(features, target)
    scatter = make_scatter(features, target)
    emitters = make_emitters(features, target)
    tri_uv_at, material_at, tinted, shading_frame, ray_origin = (
        surface.tri_uv_at, surface.material_at, surface.tinted, surface.shading_frame,
        surface.ray_origin)
    opacity_at = surface.opacity_at
    local_wo, eval_world, sample_world, leave, side_normal, own_skip = (
        scatter.local_wo, scatter.eval_world, scatter.sample_world, scatter.leave,
        scatter.side_normal, scatter.own_skip)
    hit_emission = emitters.hit_emission

    @step
    def stops_ray(scene, tri, b1, b2, d, key, dim):
        """Whether triangle tri's surface stops a ray along d at (b1, b2) (alpha: cut-outs,
        stochastic transparency, surface.opacity_at, and thin dielectric panes,
        surface.thin_pane_reflects; the number from the path's key and dimension
        ``dim``)."""
        m = scene.tri_mat[tri]
        u = sample_1d(key, dim)
        if scene.mat[m, M_ALPHA_MODE] == ALPHA_THIN:
            ng = normalize(cross(load3(scene.tri_v, tri, TRI_E1),
                                 load3(scene.tri_v, tri, TRI_E2)))
            return thin_pane_reflects(scene.mat[m, M_THIN_ETA], abs(dot(d, ng)), u)
        tu, tv = tri_uv_at(scene.tri_uv, tri, b1, b2)
        return opacity_at(scene.mat, scene.mat_tex, scene.tex_data, scene.tex_int,
                          scene.tex_f, m, tu, tv, u)

    @step
    def trace_hit(scene, o, d, skip, key, dim, stack):
        """The closest surface that stops the ray (o, d): trace_closest's (t, tri, b1, b2),
        and in scenes with alpha the hits that let the ray pass skipped (the ray goes on
        from each; t counts from o). ``key``, ``dim``: the path's key (its sampler state's
        first word) and the first dimension of the numbers that transparency draws."""
        t, tri, b1, b2 = trace_closest(o, d, INF, skip, scene.tri_v, scene.bvh_box,
                                       scene.bvh_child, stack)
        if ALPHA:
            t_done = ZERO
            k = 0
            while tri >= 0 and k < ALPHA_DIMS and not stops_ray(scene, tri, b1, b2, d, key,
                                                                 dim + k):
                # on from the hit point (from the triangle's own coordinates: not pushed
                # off the surface, the triangle itself skipped)
                t_done += t
                o = hit_point(scene.tri_v, tri, b1, b2)
                t, tri, b1, b2 = trace_closest(o, d, INF, tri, scene.tri_v, scene.bvh_box,
                                               scene.bvh_child, stack)
                k += 1
            t += t_done
        return t, tri, b1, b2

    @step
    def occluded(scene, o, d, t_max, skips, key, stack):
        """Whether the shadow ray (o, d) meets a surface that stops it before t_max:
        trace_any, skipping skips (the shading point's and the light's triangles); in
        scenes with alpha a loop of closest hits past the surfaces that let it through."""
        if not ALPHA:
            return trace_any(o, d, t_max, skips[0], skips[1], scene.tri_v, scene.bvh_box,
                             scene.bvh_child, stack)
        skip = skips[0]
        for k in range(ALPHA_DIMS):
            t, tri, b1, b2 = trace_closest(o, d, t_max, skip, scene.tri_v, scene.bvh_box,
                                           scene.bvh_child, stack)
            if tri < 0 or tri == skips[1]:
                return False
            if stops_ray(scene, tri, b1, b2, d, key[0], key[1] + k):
                return True
            o = hit_point(scene.tri_v, tri, b1, b2)
            t_max -= t
            skip = tri
        return True

    @step
    def surface_geometry(scene, d, hit, bounce, cone, spread):
        """(Geometry at ``hit`` of the ray along d, the ray cone's width there). The cone
        grows by ``spread`` per unit distance; trilinear textures filter over its
        footprint (Akenine-Moeller et al. 2019, Ray Tracing Gems ch. 20) up to
        MIP_LAST_BOUNCE. It keeps the camera's pixel spread after a bounce: the widening by
        surface curvature and roughness (their 2021 paper) is left out, so that the first
        bounce's hit is filtered less than it could be, never more."""
        tri = hit.tri
        v0 = load3(scene.tri_v, tri, TRI_V0)
        e1 = load3(scene.tri_v, tri, TRI_E1)
        e2 = load3(scene.tri_v, tri, TRI_E2)
        p = madd(madd(v0, e1, hit.b1), e2, hit.b2)
        ng = normalize(cross(e1, e2))   # front side: counter-clockwise winding
        tu, tv = tri_uv_at(scene.tri_uv, tri, hit.b1, hit.b2)
        fp = NO_FOOTPRINT
        if MIPMAPS:
            if bounce <= MIP_LAST_BOUNCE:
                cone += spread * hit.t
                fp = cone_footprint(scene.tri_uv, tri, e1, e2, ng, d, cone)
        return Geometry(p, v0, e1, e2, ng, neg(d), scene.tri_mat[tri], tu, tv, fp), cone

    @step
    def emission_at(scene, o, hit, geo, pdf_prev):
        """(le, MIS weight, whether the surface emits towards wo) of an emissive
        triangle reached from o by a BSDF sample of density pdf_prev (0: seen directly)."""
        return hit_emission(
            scene.mat, scene.mat_tex, scene.tex_data, scene.tex_int, scene.tex_f,
            scene.tri_light_pdf, scene.lt_node, scene.lt_link, scene.tri_light_leaf, hit.tri,
            geo.m, dot(geo.ng, geo.wo), o, hit.t, pdf_prev, geo.tu, geo.tv, geo.fp)

    @step
    def surface_shading(scene, hit, geo):
        """The material (with vertex colours) and the shading frame at the surface."""
        kind, params = material_at(scene.mat, scene.mat_tex, scene.tex_data,
                                            scene.tex_int, scene.tex_f, geo.m, geo.tu, geo.tv,
                                            geo.fp)
        if VERTEX_COLORS:
            params = tinted(params, scene.tri_col, hit.tri, hit.b1, hit.b2)
        ng, ns, tangent, bitangent, wp = shading_frame(
            scene.tri_n, scene.tri_t, scene.mat_tex, scene.tex_data, scene.tex_int,
            scene.tex_f, hit.tri, geo.m, hit.b1, hit.b2, geo.e1, geo.ng, geo.wo,
            params[P_TRANSMISSION] > ZERO, geo.tu, geo.tv, geo.fp)
        origin = ray_origin(scene.tri_n, hit.tri, geo.p, hit.b1, hit.b2, geo.v0, geo.e1,
                            geo.e2, ng)
        return Shading(kind, params, side_normal(ng, ns, wp), ng, ns, tangent,
                       bitangent, wp, local_wo(geo.wo, tangent, bitangent, ns), origin)

    @step
    def direct_light(beta, sh, geo, tri, emitter, scene, stack, key):
        """The one shadow-ray-and-MIS tail of next-event estimation, for every emitter
        kind (``emitter``: a sample_emitter record): (radiance added, shadow rays
        traced). ``key``: (path key, first dimension) of transparency's numbers."""
        wi, t_max, le, pdf_light, is_delta, light_tri = emitter
        f, pdf_bsdf = eval_world(sh.kind, sh.params, geo.wo, sh.wo_l, wi,
                                 sh.tangent, sh.bitangent, sh.ns, sh.ng, sh.wp)
        if not (max_comp(f) > ZERO):
            return (ZERO, ZERO, ZERO), 0
        if occluded(scene, leave(geo.p, sh.ng, wi, sh.origin), wi, t_max,
                    (own_skip(tri, sh.ng_tri, sh.ng, wi), light_tri), key, stack):
            return (ZERO, ZERO, ZERO), 1
        if is_delta:
            weight = ONE / pdf_light
        else:
            weight = power_heuristic(pdf_light, pdf_bsdf) / pdf_light
        return scale(mul(mul(beta, f), le), weight), 1

    @step
    def next_ray(sh, geo, tri, u_lobe, u1, u2):
        """BSDF sampling: (o, d, skip) of the next ray, its weight f cos / pdf and pdf
        (pdf 0: no sample)."""
        wi, weight, pdf_bsdf = sample_world(sh.kind, sh.params, geo.wo, sh.wo_l,
                                            sh.tangent, sh.bitangent, sh.ns, sh.ng, sh.wp,
                                            u_lobe, u1, u2)
        return (leave(geo.p, sh.ng, wi, sh.origin), wi, own_skip(tri, sh.ng_tri, sh.ng, wi),
                weight, pdf_bsdf)

    return SurfaceSteps(trace_hit, surface_geometry, emission_at, surface_shading, direct_light, next_ray,
                        emitters.sample_emitter)


@functools.lru_cache(maxsize=None)
def make_path(features, target="cpu"):
    """The bounce's steps (:class:`PathSteps`) for scenes with ``features`` on ``target``."""
    S = specialise(features)
    step = step_marker(target)
    THIN_LENS = S.thin_lens
    TRI_LIGHTS = S.tri_lights
    ANY_ENVIRONMENT = S.any_environment
    NEE = S.nee
    MIPMAPS = S.mipmaps
    ONE_SIDED = S.one_sided
    open_set, draw = make_sampler(S.sobol, table=target == "cpu")[1:]
    # The CPU's sobol sampler returns a set's four numbers when the set is opened
    # (rng.make_sampler), so Russian roulette draws from the BSDF set the bounce opened
    # (its dimension D_RR is that set's last); elsewhere it opens the set again, which
    # keeps one tuple fewer alive across the BSDF sample on the GPU.
    RR_FROM_BSDF_SET = target == "cpu"
    # The CPU's sobol sampler opens a bounce's light and BSDF sets together (their hashes
    # and scrambles in shared vectors, rng.sobol_floats_pair); elsewhere each is opened
    # where it is drawn (on the GPU the BSDF set's state would live across the light
    # sample). Compile-time switches: one of each pair of branches below is removed.
    OPEN_PAIR = NEE and S.sobol and target == "cpu"
    OPEN_LIGHT_SET = NEE and not OPEN_PAIR
    OPEN_BSDF_SET = not OPEN_PAIR
    open_pair = make_pair_opener(S.sobol, table=target == "cpu")
    V = make_surface_steps(features, target)
    (surface_geometry, emission_at, surface_shading, direct_light, next_ray) = (
        V.surface_geometry, V.emission_at, V.surface_shading, V.direct_light, V.next_ray)
    sample_emitter, trace_hit = V.sample_emitter, V.trace_hit
    escaped = make_emitters(features, target).escaped

    @step
    def path_state(o, d, beta, radiance, pdf_prev, skip, bounce, cone):
        """A PathState (its integers of one type wherever it is made: the drivers' loops
        carry it)."""
        return PathState(o, d, beta, radiance, pdf_prev, np.int64(skip), np.int64(bounce),
                         cone)

    @step
    def spread_of(scene):
        """The camera's ray-cone spread per unit distance (mip-mapped textures only)."""
        if MIPMAPS:
            return scene.cam[CAM_CONE]
        return ZERO

    @step
    def camera_ray(cam, px, py, state, width, height):
        """A uniform position in pixel (px, py) and, for the thin lens, on the lens."""
        dims = open_set(state, D_PIXEL_X)
        if THIN_LENS:
            return thin_lens_ray(cam, np.float32(px), np.float32(py),
                                 draw(state, dims, D_PIXEL_X), draw(state, dims, D_PIXEL_Y),
                                 draw(state, dims, D_LENS_U), draw(state, dims, D_LENS_V),
                                 np.float32(width), np.float32(height))
        return pinhole_ray(cam, np.float32(px), np.float32(py), draw(state, dims, D_PIXEL_X),
                           draw(state, dims, D_PIXEL_Y), np.float32(width),
                           np.float32(height))

    @step
    def start_camera_path(o, d):
        """The PathState of a camera ray (o, d)."""
        return path_state(o, d, (ONE, ONE, ONE), (ZERO, ZERO, ZERO), ZERO, -1, 0, ZERO)

    @step
    def store_pixel(out, stats, px, py, rgb, counts):
        """rgb: the pixel's sums; counts: (bounce rays, shadow rays, non-finite samples)."""
        for c in range(3):
            out[py, px, c] = rgb[c]
        stats[py, px, STAT_BOUNCE_RAYS] = counts[0]
        stats[py, px, STAT_SHADOW_RAYS] = counts[1]
        stats[py, px, STAT_NONFINITE] = counts[2]

    @step
    def add_sample(r, g, b, n_bad, radiance):
        """The pixel's sums with one path's radiance added: a NaN or infinite sample is
        counted and left out of the sum (as zero), so that one bad path does not turn its
        pixel, and the image file, into NaN; the count makes it visible instead (the
        command warns, the tests require it to be zero)."""
        sr, sg, sb = radiance
        if math.isfinite(sr) and math.isfinite(sg) and math.isfinite(sb):
            return r + sr, g + sg, b + sb, n_bad
        return r, g, b, n_bad + 1

    @step
    def russian_roulette(beta, bounce, rr_depth, state, dim, bsdf_dims):
        """(beta, alive): after rr_depth bounces a path continues with probability
        q = min(max beta, RR_MAX) and survivors are reweighted by 1/q (unbiased).
        ``bsdf_dims``: the bounce's opened BSDF set (D_RR is in it)."""
        beta_max = max_comp(beta)
        if beta_max <= ZERO:
            return beta, False
        if bounce >= rr_depth:
            q = min(beta_max, RR_MAX)
            rr_dims = bsdf_dims if RR_FROM_BSDF_SET else open_set(state, dim + D_RR)
            if draw(state, rr_dims, dim + D_RR) >= q:
                return beta, False
            beta = scale(beta, ONE / q)
        return beta, True

    @step
    def escaped_path(scene, path):
        """The path whose ray left the scene, with the environment's radiance it sees
        (MIS-weighted against the BSDF sample that made the ray)."""
        if ANY_ENVIRONMENT:
            le, weight = escaped(scene.env, scene.env_img, scene.env_info, path.d,
                                 path.pdf_prev)
            return path_state(path.o, path.d, path.beta,
                              add(path.radiance, scale(mul(path.beta, le), weight)),
                              path.pdf_prev, path.skip, path.bounce, path.cone)
        return path

    @step
    def shade_surface(path, hit, spread, state, max_bounces, rr_depth, scene, stack):
        """The vertex at a surface ``hit`` (tri >= 0) of the path's ray: the emission seen
        there (MIS-weighted), next-event estimation and the BSDF sample that makes the next
        ray. Returns (the path's new state, shadow rays traced, bounce rays made: 1 once a
        BSDF sample made the next ray, counted even where Russian roulette then ends the
        path, whether the path goes on)."""
        o, d, beta, radiance, pdf_prev, skip, bounce, cone = path
        geo, cone = surface_geometry(scene, d, hit, bounce, cone, spread)
        if TRI_LIGHTS:
            le, weight, hit_light = emission_at(scene, o, hit, geo, pdf_prev)
            if hit_light:
                radiance = add(radiance, scale(mul(beta, le), weight))
        ended = path_state(o, d, beta, radiance, pdf_prev, skip, bounce, cone)
        if bounce >= max_bounces:
            return ended, 0, 0, False
        if ONE_SIDED:
            # a one-sided material (Mitsuba's BSDFs outside twosided) seen from behind is
            # black: the path ends
            if scene.mat[geo.m, M_ONE_SIDED] > ZERO and not (dot(geo.ng, geo.wo) > ZERO):
                return ended, 0, 0, False
        sh = surface_shading(scene, hit, geo)
        dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE
        n_shadow_rays = 0
        if OPEN_PAIR:
            light_dims, dims = open_pair(state, dim + D_LIGHT_U)
        # ---- next-event estimation: one emitter sample, one shadow ray ----
        if NEE:
            if OPEN_LIGHT_SET:
                light_dims = open_set(state, dim + D_LIGHT_U)
            emitter = sample_emitter(scene, geo.p, sh.origin,
                                     draw(state, light_dims, dim + D_LIGHT_SELECT),
                                     draw(state, light_dims, dim + D_LIGHT_U),
                                     draw(state, light_dims, dim + D_LIGHT_V))
            if emitter[3] > ZERO:       # pdf_light
                contribution, n_shadow_rays = direct_light(
                    beta, sh, geo, hit.tri, emitter, scene, stack,
                    (state[0], D_ALPHA_SHADOW + bounce * ALPHA_DIMS))
                radiance = add(radiance, contribution)
        # ---- BSDF sampling: the next ray ----
        if OPEN_BSDF_SET:
            dims = open_set(state, dim + D_BSDF_U)
        o_next, wi, skip_next, weight, pdf_bsdf = next_ray(
            sh, geo, hit.tri, draw(state, dims, dim + D_BSDF_LOBE),
            draw(state, dims, dim + D_BSDF_U), draw(state, dims, dim + D_BSDF_V))
        if not (pdf_bsdf > ZERO):
            return (path_state(o, d, beta, radiance, pdf_prev, skip, bounce, cone),
                    n_shadow_rays, 0, False)
        beta, alive = russian_roulette(mul(beta, weight), bounce + 1, rr_depth, state, dim,
                                       dims)
        return (path_state(o_next, wi, beta, radiance, pdf_bsdf, skip_next, bounce + 1,
                           cone), n_shadow_rays, 1, alive)

    @step
    def path_vertex(path, spread, state, max_bounces, rr_depth, scene, stack):
        """One vertex of a path: the ray traced, then escaped_path or shade_surface
        (shade_surface's answer)."""
        t, tri, b1, b2 = trace_hit(scene, path.o, path.d, path.skip, state[0],
                                   D_ALPHA + path.bounce * ALPHA_DIMS, stack)
        if tri < 0:
            return escaped_path(scene, path), 0, 0, False
        return shade_surface(path, Hit(t, tri, b1, b2), spread, state, max_bounces,
                             rr_depth, scene, stack)

    return PathSteps(camera_ray, start_camera_path, path_state, surface_geometry,
                     surface_shading, emission_at, next_ray, escaped_path, shade_surface,
                     path_vertex, trace_hit, add_sample, store_pixel, spread_of)
