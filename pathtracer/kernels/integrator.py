"""The path tracer: one per-sample function, specialised per scene and shared by backends.

``make_render_pixel(features)`` closes over the scene's :class:`~.layout.Specialisation`;
branches on those constants are removed before compilation, so a scene without point
lights, emissive triangles, smooth normals or an environment compiles none of that code
(pbrt's wavefront integrator instantiates per material type the same way; here Python
closures do it).

Estimator (Veach 1997, ch. 9; the structure of Mitsuba 3's ``path`` integrator):
unidirectional path tracing with next-event estimation to one emitter, BSDF sampling, both
combined by the power heuristic, and Russian roulette after ``rr_depth`` bounces.
``max_bounces`` counts scattering events: 0 shows only emitters seen directly, 1 is direct
lighting (Mitsuba's max_depth = max_bounces + 1).

A path is a loop over named steps: ``camera_ray``, ``closest_hit``, the emitter reached
(``escaped`` or ``hit_emission``, weighted by MIS), the surface (``material_at``,
``shading_frame``, ``ray_origin``), next-event estimation (``sample_emitter`` for every
light kind, then one shadow-ray-and-MIS tail, ``direct_light``), BSDF sampling
(``sample_world``) and ``russian_roulette``. The steps live in :mod:`.surface`,
:mod:`.scatter` and :mod:`.emitters`.
"""
import functools
import math
from typing import NamedTuple

import numpy as np

from .camera import pinhole_ray, thin_lens_ray
from .constants import INF, ONE, RR_MAX, ZERO
from .device import entry_marker, step_marker
from .emitters import make_emitters
from .envmap import env_locate, env_prefetch
from .layout import (AOV_ALBEDO, AOV_NORMAL, CAM_CONE, D_BSDF_LOBE, D_BSDF_U, D_BSDF_V,
                     D_FIRST_BOUNCE, D_LENS_U, D_LENS_V, D_LIGHT_SELECT, D_LIGHT_U, D_LIGHT_V,
                     D_PIXEL_X, D_PIXEL_Y, D_RR, DIMS_PER_BOUNCE, M_ONE_SIDED,
                     ESC_BETA, ESC_FX, ESC_FY,
                     ESC_I0, ESC_I1, ESC_J0, ESC_J1, ESC_OUT, ESC_PDF_PREV, ESC_PX,
                     ESC_RADIANCE, ESC_Y, ESCAPE_RING, HIT_B1, HIT_B2, HIT_T,
                     P_BASE, P_METALLIC, PATH_BETA, PATH_BOUNCE, PATH_BOUNCE_RAYS,
                     PATH_CONE, PATH_D, PATH_O, PATH_PDF_PREV, PATH_RADIANCE,
                     PATH_SHADOW_RAYS, PATH_SKIP,
                     P_ROUGHNESS, P_TRANSMISSION, STAT_BOUNCE_RAYS, STAT_NONFINITE,
                     STAT_SHADOW_RAYS, TRI_E1, TRI_E2, TRI_V0, Features, SceneArrays,
                     specialise)
from .rng import make_pair_opener, make_sampler, udiv32
from .scatter import make_scatter
from .surface import make_surface
from .textures import NO_FOOTPRINT, cone_footprint
from .traverse import any_hit, closest_hit
from .wide import (PACKET, any_hit_wide, closest_hit_packet, closest_hit_wide,
                   packet_ray_hit, packet_set_ray)
from .vec import (add, cross, dot, load3, madd, max_comp, mul, neg, normalize, scale,
                  to_world)
from .warps import power_heuristic

__all__ = ["Features", "SceneArrays", "make_render_pixel", "make_wavefront"]


# Auxiliary images for the denoiser (aov_pixel): a surface counts as specular, and the
# albedo and normal are taken further along the path, when its GGX roughness is below this
# and it is mostly metal or glass (the principled BSDF has no true delta lobe).
AOV_SPECULAR_ROUGHNESS = np.float32(0.1)
AOV_MAX_SPECULAR = 8        # specular surfaces followed at most
HALF_F = np.float32(0.5)
# The fewest camera rays traced as a packet (kernels.wide.closest_hit_packet; fewer: one by
# one): with four of eight lanes used, packets ran 0.97-1.01x the single rays' paths/s
# (4-spp passes), with all eight 1.03-1.06x (16-spp passes; 2-core EPYC, bench.ab,
# 2026-11-29).
PACKET_MIN_RAYS = 5
# Trilinear textures are filtered over ray-cone footprints at the camera's hit and the
# first bounce's; later hits read the image itself (bilinearly). Filtering every bounce
# cost 29 % of the textured scene's paths/s on an H100 (2026-11-23, bench.ab) for lookups
# whose aliasing the indirect light's own averaging hides.
MIP_LAST_BOUNCE = 1


def regenerates(features, target):
    """Whether ``render_pixel`` for ``target`` runs a pixel's paths with path regeneration
    (Novak et al. 2010, "Path regeneration for interactive path tracing"): one loop over
    the vertices of all its paths (``path_vertex``), where the iteration after a path's
    last vertex starts the next sample, so that a GPU lane whose path ended does not wait
    for the warp's longest path. On the GPU in scenes without an environment (the Cornell
    box: +15 %, H100, 2026-11-23, docs/benchmarks.md). Not in scenes with one, whose
    vertices diverge anyway (the BVH, the principled lobes, the environment's tables):
    there one path after the other measured 4-9 % faster. Not on the CPU, where a thread
    runs one path at a time either way and the regenerating loop measured slower (the
    Cornell box 0.68x, 2-core EPYC, bench.ab). Either way the same samples are added in
    the same order: the same image."""
    return target == "cuda" and not specialise(features).any_environment


@functools.lru_cache(maxsize=None)
def make_render_pixel(features, target="cpu", regenerate=None):
    """Compile-time specialisation: returns ``render_pixel`` for scenes with ``features``
    (``regenerate``: path regeneration or not; None: :func:`regenerates`)."""
    if regenerate is None:
        regenerate = regenerates(features, target)
    kernels = make_kernels(features, target)
    return kernels[0] if regenerate else kernels[2]


@functools.lru_cache(maxsize=None)
def make_aov_pixel(features, target="cpu"):
    """``aov_pixel`` (albedo and normal images for the denoiser) for scenes with
    ``features``."""
    return make_kernels(features, target)[1]


@functools.lru_cache(maxsize=None)
def make_kernels(features, target="cpu"):
    """Compile-time specialisation: (render_pixel with path regeneration, aov_pixel,
    render_pixel_nested: one path after the other) for scenes with ``features``."""
    S = specialise(features)
    step = step_marker(target)
    entry = entry_marker(target)
    entry_inlined = entry_marker(target, inlined=True)
    THIN_LENS = S.thin_lens
    TRI_LIGHTS = S.tri_lights
    ANY_ENVIRONMENT = S.any_environment
    NEE = S.nee
    MIPMAPS = S.mipmaps
    VERTEX_COLORS = S.vertex_colors
    ONE_SIDED = S.one_sided
    # The CPU traverses the eight-wide BVH (kernels.wide: SIMD box and triangle tests), whose
    # arrays its backend puts in the scene's bvh_box and bvh_child; the GPU the binary one.
    WIDE = target == "cpu"
    trace_closest = closest_hit_wide if WIDE else closest_hit
    trace_any = any_hit_wide if WIDE else any_hit
    # The CPU traces a pixel's camera rays eight at a time (kernels.wide.closest_hit_packet:
    # SIMD over the rays; camera_packet below), and each path starts from its ray's hit.
    CAMERA_PACKETS = WIDE
    start_path, open_set, draw = make_sampler(S.sobol, table=target == "cpu")
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
    surface = make_surface(features, target)
    scatter = make_scatter(features, target)
    emitters = make_emitters(features, target)
    tri_uv_at, material_at, tinted, shading_frame, ray_origin = (
        surface.tri_uv_at, surface.material_at, surface.tinted, surface.shading_frame,
        surface.ray_origin)
    local_wo, eval_world, sample_world, leave, side_normal, own_skip = (
        scatter.local_wo, scatter.eval_world, scatter.sample_world, scatter.leave,
        scatter.side_normal, scatter.own_skip)
    sample_emitter, hit_emission, escaped, escaped_in_cell = (
        emitters.sample_emitter, emitters.hit_emission, emitters.escaped,
        emitters.escaped_in_cell)

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
    def start_camera_path(cam, px, py, state, width, height):
        """A path's state at its camera ray: (o, d, beta, radiance, pdf_prev, skip,
        bounce, cone)."""
        o, d = camera_ray(cam, px, py, state, width, height)
        # beta: the throughput, product of f cos / pdf (and 1/q of RR); pdf_prev: the
        # solid-angle pdf of the BSDF sample that made the ray, 0 for the camera ray
        # (emission seen directly: no MIS); skip: the triangle the ray leaves (never
        # re-hit), -1 none; bounce: scattering events so far; cone: the ray cone's width
        # at o (mip-mapped textures only)
        return o, d, (ONE, ONE, ONE), (ZERO, ZERO, ZERO), ZERO, -1, 0, ZERO

    @step
    def store_pixel(out, stats, px, py, r, g, b, n_bounce_rays, n_shadow_rays, n_bad):
        out[py, px, 0] = r
        out[py, px, 1] = g
        out[py, px, 2] = b
        stats[py, px, STAT_BOUNCE_RAYS] = n_bounce_rays
        stats[py, px, STAT_SHADOW_RAYS] = n_shadow_rays
        stats[py, px, STAT_NONFINITE] = n_bad

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
    def footprint(tri_uv, tri, e1, e2, ng, d, t, cone, spread):
        """(cone, fp): the ray cone's width at the hit t along d (it grows by ``spread``
        per unit distance) and its footprint in texture coordinates there, which trilinear
        textures filter over (Akenine-Moeller et al. 2019, Ray Tracing Gems ch.
        20). The cone keeps the camera's pixel spread after a bounce: the widening by surface
        curvature and roughness (their 2021 paper) is left out, so that the first bounce's
        hit is filtered less than it could be, never more (see MIP_LAST_BOUNCE)."""
        cone += spread * t
        return cone, cone_footprint(tri_uv, tri, e1, e2, ng, d, cone)

    @step
    def direct_light(beta, is_principled, params, wo, wo_l, tangent, bitangent, ns, ng, wp,
                     ng_tri, p, origin, tri, wi, t_max, le, pdf_light, is_delta, light_tri, tri_v,
                     bvh_box, bvh_child, stack):
        """The one shadow-ray-and-MIS tail of next-event estimation, for every emitter
        kind (a sample_emitter record): (radiance added, shadow rays traced). ng: the
        side normal (see side_normal), ng_tri: the triangle's."""
        f, pdf_bsdf = eval_world(is_principled, params, wo, wo_l, wi, tangent, bitangent, ns,
                                 ng, wp)
        if not (max_comp(f) > ZERO):
            return (ZERO, ZERO, ZERO), 0
        if trace_any(leave(p, ng, wi, origin), wi, t_max, own_skip(tri, ng_tri, ng, wi),
                     light_tri, tri_v, bvh_box, bvh_child, stack):
            return (ZERO, ZERO, ZERO), 1
        if is_delta:
            weight = ONE / pdf_light
        else:
            weight = power_heuristic(pdf_light, pdf_bsdf) / pdf_light
        return scale(mul(mul(beta, f), le), weight), 1

    @step
    def path_vertex(o, d, beta, radiance, pdf_prev, skip, bounce, cone, spread, state,
                    max_bounces, rr_depth, scene, stack):
        """One vertex of a path: the ray (o, d) traced, the emitter it reaches added
        (MIS-weighted), then at a surface next-event estimation and the BSDF sample that
        makes the next ray. Returns the path's new (o, d, beta, radiance, pdf_prev, skip,
        bounce, cone), the shadow rays traced, the bounce rays made (1 once a BSDF sample
        made the next ray, counted even where Russian roulette then ends the path) and
        whether the path goes on."""
        t, tri, b1, b2 = trace_closest(o, d, INF, skip, scene.tri_v, scene.bvh_box,
                                       scene.bvh_child, stack)
        return shade_hit(o, d, beta, radiance, pdf_prev, skip, bounce, cone, spread, state,
                         max_bounces, rr_depth, scene, stack, t, tri, b1, b2)

    @step
    def shade_hit(o, d, beta, radiance, pdf_prev, skip, bounce, cone, spread, state,
                  max_bounces, rr_depth, scene, stack, t, tri, b1, b2):
        """path_vertex after its closest-hit query (t, tri, b1, b2: trace_closest's answer
        for the ray (o, d)); the wavefront kernels run the two halves apart."""
        n_shadow_rays = 0
        if tri < 0:
            if ANY_ENVIRONMENT:
                le, weight = escaped(scene.env, scene.env_img, scene.env_info, d, pdf_prev)
                radiance = add(radiance, scale(mul(beta, le), weight))
            return o, d, beta, radiance, pdf_prev, skip, bounce, cone, 0, 0, False
        # ---- the surface hit ----
        v0 = load3(scene.tri_v, tri, TRI_V0)
        e1 = load3(scene.tri_v, tri, TRI_E1)
        e2 = load3(scene.tri_v, tri, TRI_E2)
        p = madd(madd(v0, e1, b1), e2, b2)
        ng = normalize(cross(e1, e2))   # front side: counter-clockwise winding
        wo = neg(d)
        m = scene.tri_mat[tri]
        tu, tv = tri_uv_at(scene.tri_uv, tri, b1, b2)
        fp = NO_FOOTPRINT
        if MIPMAPS:
            if bounce <= MIP_LAST_BOUNCE:
                cone, fp = footprint(scene.tri_uv, tri, e1, e2, ng, d, t, cone, spread)
        if TRI_LIGHTS:
            le, weight, hit_light = hit_emission(
                scene.mat, scene.mat_tex, scene.tex_data, scene.tex_int, scene.tex_f,
                scene.tri_light_pdf, scene.lt_node, scene.lt_link, scene.tri_light_leaf,
                tri, m, dot(ng, wo), o, t, pdf_prev, tu, tv, fp)
            if hit_light:
                radiance = add(radiance, scale(mul(beta, le), weight))
        if bounce >= max_bounces:
            return o, d, beta, radiance, pdf_prev, skip, bounce, cone, 0, 0, False
        if ONE_SIDED:
            # a one-sided material (Mitsuba's BSDFs outside twosided) seen from behind is
            # black: the path ends
            if scene.mat[m, M_ONE_SIDED] > ZERO and not (dot(ng, wo) > ZERO):
                return o, d, beta, radiance, pdf_prev, skip, bounce, cone, 0, 0, False
        is_principled, params = material_at(scene.mat, scene.mat_tex, scene.tex_data,
                                            scene.tex_int, scene.tex_f, m, tu, tv, fp)
        if VERTEX_COLORS:
            params = tinted(params, scene.tri_col, tri, b1, b2)
        ng, ns, tangent, bitangent, wp = shading_frame(
            scene.tri_n, scene.tri_t, scene.mat_tex, scene.tex_data, scene.tex_int,
            scene.tex_f, tri, m, b1, b2, e1, ng, wo, params[P_TRANSMISSION] > ZERO, tu, tv,
            fp)
        wo_l = local_wo(wo, tangent, bitangent, ns)
        origin = ray_origin(scene.tri_n, tri, p, b1, b2, v0, e1, e2, ng)
        ng_tri = ng
        ng = side_normal(ng, ns, wp)
        dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE
        if OPEN_PAIR:
            light_dims, dims = open_pair(state, dim + D_LIGHT_U)
        # ---- next-event estimation: one emitter sample, one shadow ray ----
        if NEE:
            if OPEN_LIGHT_SET:
                light_dims = open_set(state, dim + D_LIGHT_U)
            wi, t_max, le, pdf_light, is_delta, light_tri = sample_emitter(
                scene, p, origin, draw(state, light_dims, dim + D_LIGHT_SELECT),
                draw(state, light_dims, dim + D_LIGHT_U),
                draw(state, light_dims, dim + D_LIGHT_V))
            if pdf_light > ZERO:
                contribution, traced = direct_light(
                    beta, is_principled, params, wo, wo_l, tangent, bitangent, ns, ng, wp,
                    ng_tri, p, origin, tri, wi, t_max, le, pdf_light, is_delta, light_tri,
                    scene.tri_v, scene.bvh_box, scene.bvh_child, stack)
                radiance = add(radiance, contribution)
                n_shadow_rays += traced
        # ---- BSDF sampling: the next ray ----
        if OPEN_BSDF_SET:
            dims = open_set(state, dim + D_BSDF_U)
        wi, weight, pdf_bsdf = sample_world(
            is_principled, params, wo, wo_l, tangent, bitangent, ns, ng, wp,
            draw(state, dims, dim + D_BSDF_LOBE), draw(state, dims, dim + D_BSDF_U),
            draw(state, dims, dim + D_BSDF_V))
        if not (pdf_bsdf > ZERO):
            return (o, d, beta, radiance, pdf_prev, skip, bounce, cone, n_shadow_rays, 0,
                    False)
        beta = mul(beta, weight)
        pdf_prev = pdf_bsdf
        o = leave(p, ng, wi, origin)
        d = wi
        skip = own_skip(tri, ng_tri, ng, wi)
        bounce += 1
        beta, alive = russian_roulette(beta, bounce, rr_depth, state, dim, dims)
        return (o, d, beta, radiance, pdf_prev, skip, bounce, cone, n_shadow_rays, 1,
                alive)


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

    @entry
    def render_pixel(px, py, sample_start, n_samples, seed, max_bounces, rr_depth, scene,
                     stack, out, stats):
        """Add the paths of samples [sample_start, + n_samples) of pixel (px, py) to
        out[py, px] (float32 rgb sums, in sample order; see add_sample) and count rays and
        non-finite samples in stats[py, px] (layout STAT_*). One loop over the vertices of
        all the paths, with path regeneration (see regenerates; render_pixel_nested is
        the other way)."""
        width = out.shape[1]
        spread = ZERO
        if MIPMAPS:
            spread = scene.cam[CAM_CONE]
        r, g, b = ZERO, ZERO, ZERO      # the pixel's sums
        n_bad = 0
        n_bounce_rays = 0
        n_shadow_rays = 0
        # the path under way: started at the top of the loop whenever alive is False
        state = start_path(py * width + px, sample_start, seed)
        o = d = beta = radiance = (ZERO, ZERO, ZERO)
        pdf_prev = cone = ZERO
        skip = bounce = 0
        alive = False
        started = 0                     # paths started
        while True:
            if not alive:
                if started > 0:
                    r, g, b, n_bad = add_sample(r, g, b, n_bad, radiance)
                if started == n_samples:
                    break
                state = start_path(py * width + px, sample_start + started, seed)
                started += 1
                o, d, beta, radiance, pdf_prev, skip, bounce, cone = start_camera_path(
                    scene.cam, px, py, state, width, out.shape[0])
            (o, d, beta, radiance, pdf_prev, skip, bounce, cone, shadow_rays, bounce_rays,
             alive) = path_vertex(o, d, beta, radiance, pdf_prev, skip, bounce, cone, spread,
                                  state, max_bounces, rr_depth, scene, stack)
            n_shadow_rays += shadow_rays
            n_bounce_rays += bounce_rays
        store_pixel(out, stats, px, py, r, g, b, n_bounce_rays, n_shadow_rays, n_bad)

    @step
    def camera_packet(px, py, sample_first, n_rays, seed, width, height, scene, stack):
        """The camera rays of samples sample_first .. + n_rays (n_rays <= PACKET) of pixel
        (px, py) traced together, their hits left in the stack's packet for render_sample
        (lane: sample - sample_first)."""
        for lane in range(n_rays):
            state = start_path(py * width + px, sample_first + lane, seed)
            o, d = camera_ray(scene.cam, px, py, state, width, height)
            packet_set_ray(stack, lane, o, d, INF)
        for lane in range(n_rays, PACKET):      # (an unused lane enters no box)
            packet_set_ray(stack, lane, (ZERO, ZERO, ZERO), (ONE, ONE, ONE), -ONE)
        closest_hit_packet(scene.bvh_box, scene.bvh_child, stack)

    @step
    def next_camera_lane(px, py, s, sample_start, n_samples, seed, width, height, scene,
                         stack):
        """Sample s's lane of the camera packet, tracing the next packet of the pixel's rays
        (up to PACKET, from sample s) first when s starts one; -1: the sample traces its
        own camera ray (elsewhere than on the CPU, and the last few samples of a pass
        that leave fewer than PACKET_MIN_RAYS: a packet half empty costs what it saves,
        2-core EPYC, bench.ab, 2026-11-29)."""
        if not CAMERA_PACKETS:
            return -1
        lane = (s - sample_start) % PACKET
        n_rays = min(PACKET, sample_start + n_samples - (s - lane))
        if n_rays < PACKET_MIN_RAYS:
            return -1
        if lane == 0:
            camera_packet(px, py, s, n_rays, seed, width, height, scene, stack)
        return lane

    @step
    def start_sample(px, py, sample_index, seed, width, height, scene, stack, lane):
        """A camera path's start: (sampler state, camera ray o, d, whether the ray's hit
        is known, and if so the hit t, tri, b1, b2): lane ``lane`` of the camera packet
        (next_camera_lane) when it is >= 0 on the CPU, else a camera ray to trace."""
        state = start_path(py * width + px, sample_index, seed)
        camera_hit = False
        if CAMERA_PACKETS:          # (a constant: elsewhere the branch is not compiled)
            camera_hit = lane >= 0
        if camera_hit:
            o, d, t, tri, b1, b2 = packet_ray_hit(stack, lane)
            return state, o, d, True, t, tri, b1, b2
        o, d = camera_ray(scene.cam, px, py, state, width, height)
        return state, o, d, False, INF, -1, ZERO, ZERO

    @entry_inlined
    def render_sample(px, py, sample_index, seed, width, height, max_bounces, rr_depth,
                      scene, stack, lane):
        """Radiance (r, g, b) of one camera path through pixel (px, py), with the number of
        bounce rays and shadow rays it traced: render_pixel_nested's path, path_vertex's
        steps written out in one loop. On the GPU, in the scenes that run one path after
        the other (see regenerates), this loop compiles 4-7 % faster than path_vertex
        called in it, although NVVM inlines both completely (H100, 2026-11-23); the two
        are kept equal by tests/test_render.py (the same image, bit for bit).

        Returns (r, g, b, bounce rays, shadow rays, out_ray, beta, d, pdf_prev): where
        out_ray, the path's last ray (o, d) left the scene towards an environment, whose
        radiance (weighted by MIS against pdf_prev, the density of the BSDF sample that made
        the ray, and by the throughput beta) the caller adds to (r, g, b) with escaped
        (render_pixel_nested) or later (the CPU's render_pixel_deferred).

        ``lane`` >= 0 (on the CPU): the camera ray and its hit are that lane of the packet
        that camera_packet traced (next_camera_lane)."""
        state, o, d, camera_hit, t_cam, tri_cam, b1_cam, b2_cam = start_sample(
            px, py, sample_index, seed, width, height, scene, stack, lane)
        beta = (ONE, ONE, ONE)      # path throughput: product of f cos / pdf (and 1/q of RR)
        radiance = (ZERO, ZERO, ZERO)
        pdf_prev = ZERO             # solid-angle pdf of the BSDF sample that made this ray;
        #                             0 for the camera ray (emission seen directly: no MIS)
        skip = -1                   # triangle the ray leaves (never re-hit)
        bounce = 0                  # scattering events so far
        cone = ZERO                 # ray-cone width at o (mip-mapped textures only)
        spread = ZERO
        if MIPMAPS:
            spread = scene.cam[CAM_CONE]
        n_bounce_rays = 0
        n_shadow_rays = 0
        out_ray = False
        while True:
            if camera_hit:
                t, tri, b1, b2 = t_cam, tri_cam, b1_cam, b2_cam
                camera_hit = False
            else:
                t, tri, b1, b2 = trace_closest(o, d, INF, skip, scene.tri_v, scene.bvh_box,
                                               scene.bvh_child, stack)
            if tri < 0:
                # (the caller adds what the ray sees: see the docstring)
                out_ray = ANY_ENVIRONMENT
                break
            # ---- the surface hit ----
            v0 = load3(scene.tri_v, tri, TRI_V0)
            e1 = load3(scene.tri_v, tri, TRI_E1)
            e2 = load3(scene.tri_v, tri, TRI_E2)
            p = madd(madd(v0, e1, b1), e2, b2)
            ng = normalize(cross(e1, e2))   # front side: counter-clockwise winding
            wo = neg(d)
            m = scene.tri_mat[tri]
            tu, tv = tri_uv_at(scene.tri_uv, tri, b1, b2)
            fp = NO_FOOTPRINT
            if MIPMAPS:
                if bounce <= MIP_LAST_BOUNCE:
                    cone, fp = footprint(scene.tri_uv, tri, e1, e2, ng, d, t, cone, spread)
            if TRI_LIGHTS:
                le, weight, hit_light = hit_emission(
                    scene.mat, scene.mat_tex, scene.tex_data, scene.tex_int, scene.tex_f,
                    scene.tri_light_pdf, scene.lt_node, scene.lt_link, scene.tri_light_leaf,
                    tri, m, dot(ng, wo), o, t, pdf_prev, tu, tv, fp)
                if hit_light:
                    radiance = add(radiance, scale(mul(beta, le), weight))
            if bounce >= max_bounces:
                break
            if ONE_SIDED:
                if scene.mat[m, M_ONE_SIDED] > ZERO and not (dot(ng, wo) > ZERO):
                    break
            is_principled, params = material_at(scene.mat, scene.mat_tex, scene.tex_data,
                                                scene.tex_int, scene.tex_f, m, tu, tv, fp)
            if VERTEX_COLORS:
                params = tinted(params, scene.tri_col, tri, b1, b2)
            ng, ns, tangent, bitangent, wp = shading_frame(
                scene.tri_n, scene.tri_t, scene.mat_tex, scene.tex_data, scene.tex_int,
                scene.tex_f, tri, m, b1, b2, e1, ng, wo, params[P_TRANSMISSION] > ZERO, tu, tv,
                fp)
            wo_l = local_wo(wo, tangent, bitangent, ns)
            origin = ray_origin(scene.tri_n, tri, p, b1, b2, v0, e1, e2, ng)
            ng_tri = ng
            ng = side_normal(ng, ns, wp)
            dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE
            if OPEN_PAIR:
                light_dims, dims = open_pair(state, dim + D_LIGHT_U)
            # ---- next-event estimation: one emitter sample, one shadow ray ----
            if NEE:
                if OPEN_LIGHT_SET:
                    light_dims = open_set(state, dim + D_LIGHT_U)
                wi, t_max, le, pdf_light, is_delta, light_tri = sample_emitter(
                    scene, p, origin, draw(state, light_dims, dim + D_LIGHT_SELECT),
                    draw(state, light_dims, dim + D_LIGHT_U),
                    draw(state, light_dims, dim + D_LIGHT_V))
                if pdf_light > ZERO:
                    contribution, traced = direct_light(
                        beta, is_principled, params, wo, wo_l, tangent, bitangent, ns, ng, wp,
                        ng_tri, p, origin, tri, wi, t_max, le, pdf_light, is_delta, light_tri,
                        scene.tri_v, scene.bvh_box, scene.bvh_child, stack)
                    radiance = add(radiance, contribution)
                    n_shadow_rays += traced
            # ---- BSDF sampling: the next ray ----
            if OPEN_BSDF_SET:
                dims = open_set(state, dim + D_BSDF_U)
            wi, weight, pdf_bsdf = sample_world(
                is_principled, params, wo, wo_l, tangent, bitangent, ns, ng, wp,
                draw(state, dims, dim + D_BSDF_LOBE), draw(state, dims, dim + D_BSDF_U),
                draw(state, dims, dim + D_BSDF_V))
            if not (pdf_bsdf > ZERO):
                break
            beta = mul(beta, weight)
            pdf_prev = pdf_bsdf
            o = leave(p, ng, wi, origin)
            d = wi
            skip = own_skip(tri, ng_tri, ng, wi)
            bounce += 1
            n_bounce_rays += 1
            beta, alive = russian_roulette(beta, bounce, rr_depth, state, dim, dims)
            if not alive:
                break
        return (radiance[0], radiance[1], radiance[2], n_bounce_rays, n_shadow_rays, out_ray,
                beta, d, pdf_prev)

    @entry_inlined
    def render_pixel_nested(px, py, sample_start, n_samples, seed, max_bounces, rr_depth,
                            scene, stack, out, stats):
        """render_pixel's sums one path after the other (see regenerates)."""
        height = out.shape[0]
        width = out.shape[1]
        r, g, b = ZERO, ZERO, ZERO
        n_bad = 0
        n_bounce = 0
        n_shadow = 0
        for s in range(sample_start, sample_start + n_samples):
            lane = next_camera_lane(px, py, s, sample_start, n_samples, seed, width, height,
                                    scene, stack)
            sr, sg, sb, nb, ns, out_ray, beta, d, pdf_prev = render_sample(
                px, py, s, seed, width, height, max_bounces, rr_depth, scene, stack, lane)
            radiance = (sr, sg, sb)
            if out_ray:
                le, weight = escaped(scene.env, scene.env_img, scene.env_info, d, pdf_prev)
                radiance = add(radiance, scale(mul(beta, le), weight))
            r, g, b, n_bad = add_sample(r, g, b, n_bad, radiance)
            n_bounce += nb
            n_shadow += ns
        store_pixel(out, stats, px, py, r, g, b, n_bounce, n_shadow, n_bad)

    # ---- The CPU's form for environment maps: escaped rays looked up a few paths later ----
    # A ray that leaves the scene reads a random cell of the map (8 MB of texels for a 1k
    # HDRI, beyond a core's L2), and a core running one path at a time waits for those
    # loads. render_pixel_deferred queues each finished path in a ring of ESCAPE_RING
    # records per image row (esc_f, esc_i; layout ESC_*): its radiance so far and, for a
    # ray that left, the map's cell (env_locate) with its texels prefetched; the record is
    # finished (escaped_in_cell, add_sample into out) when the ring comes round to its
    # slot, ESCAPE_RING paths later, or by drain_escapes at the row's end. Records are
    # finished in the order they were queued, so each pixel's samples are added in sample
    # order, as render_pixel_nested adds them.

    @step
    def finish_record(esc_f, esc_i, slot, py, scene, out, stats):
        """The record in ``slot`` added to its pixel's sums in row py: its radiance and,
        if its last ray left, the sky's radiance there (MIS-weighted, times its beta)."""
        px = esc_i[slot, ESC_PX]
        radiance = (esc_f[slot, ESC_RADIANCE], esc_f[slot, ESC_RADIANCE + 1],
                    esc_f[slot, ESC_RADIANCE + 2])
        if esc_i[slot, ESC_OUT] != 0:
            le, weight = escaped_in_cell(
                scene.env_img, scene.env_info, esc_i[slot, ESC_I0], esc_i[slot, ESC_I1],
                esc_i[slot, ESC_J0], esc_i[slot, ESC_J1], esc_f[slot, ESC_FX],
                esc_f[slot, ESC_FY], esc_f[slot, ESC_Y], esc_f[slot, ESC_PDF_PREV])
            beta = (esc_f[slot, ESC_BETA], esc_f[slot, ESC_BETA + 1], esc_f[slot, ESC_BETA + 2])
            radiance = add(radiance, scale(mul(beta, le), weight))
        r, g, b, n_bad = add_sample(out[py, px, 0], out[py, px, 1], out[py, px, 2],
                                    stats[py, px, STAT_NONFINITE], radiance)
        out[py, px, 0] = r
        out[py, px, 1] = g
        out[py, px, 2] = b
        stats[py, px, STAT_NONFINITE] = n_bad

    @step
    def queue_record(esc_f, esc_i, slot, px, radiance, out_ray, beta, d, pdf_prev, scene):
        """A finished path of pixel column px in ``slot`` (render_sample's answer); a ray
        that left gets its map cell located and the cell's texels prefetched."""
        esc_i[slot, ESC_PX] = px
        esc_f[slot, ESC_RADIANCE] = radiance[0]
        esc_f[slot, ESC_RADIANCE + 1] = radiance[1]
        esc_f[slot, ESC_RADIANCE + 2] = radiance[2]
        esc_i[slot, ESC_OUT] = 1 if out_ray else 0
        if out_ray:
            i0, i1, j0, j1, fx, fy, y = env_locate(scene.env_img, scene.env_info, d)
            env_prefetch(scene.env_img, i0, i1, j0, j1)
            esc_i[slot, ESC_I0] = i0
            esc_i[slot, ESC_I1] = i1
            esc_i[slot, ESC_J0] = j0
            esc_i[slot, ESC_J1] = j1
            esc_f[slot, ESC_FX] = fx
            esc_f[slot, ESC_FY] = fy
            esc_f[slot, ESC_Y] = y
            esc_f[slot, ESC_PDF_PREV] = pdf_prev
            esc_f[slot, ESC_BETA] = beta[0]
            esc_f[slot, ESC_BETA + 1] = beta[1]
            esc_f[slot, ESC_BETA + 2] = beta[2]

    @entry_inlined
    def render_pixel_deferred(px, py, sample_start, n_samples, seed, max_bounces, rr_depth,
                              scene, stack, esc_f, esc_i, queued, out, stats):
        """render_pixel_nested's sums, each path's escaped ray finished ESCAPE_RING paths
        later (see above); ``queued``: the row's paths queued so far (the ring's position);
        returns it. The row's last records are finished by drain_escapes."""
        height = out.shape[0]
        width = out.shape[1]
        for c in range(3):
            out[py, px, c] = ZERO
        stats[py, px, STAT_NONFINITE] = 0
        n_bounce = 0
        n_shadow = 0
        for s in range(sample_start, sample_start + n_samples):
            lane = next_camera_lane(px, py, s, sample_start, n_samples, seed, width, height,
                                    scene, stack)
            sr, sg, sb, nb, ns, out_ray, beta, d, pdf_prev = render_sample(
                px, py, s, seed, width, height, max_bounces, rr_depth, scene, stack, lane)
            slot = queued % ESCAPE_RING
            if queued >= ESCAPE_RING:
                finish_record(esc_f, esc_i, slot, py, scene, out, stats)
            queue_record(esc_f, esc_i, slot, px, (sr, sg, sb), out_ray, beta, d, pdf_prev,
                         scene)
            queued += 1
            n_bounce += nb
            n_shadow += ns
        stats[py, px, STAT_BOUNCE_RAYS] = n_bounce
        stats[py, px, STAT_SHADOW_RAYS] = n_shadow
        return queued

    @entry_inlined
    def drain_escapes(esc_f, esc_i, queued, py, scene, out, stats):
        """Finish the records still in the ring after the row's ``queued`` paths, oldest
        first."""
        for q in range(max(queued - ESCAPE_RING, 0), queued):
            finish_record(esc_f, esc_i, q % ESCAPE_RING, py, scene, out, stats)

    @entry
    def aov_pixel(px, py, n_samples, seed, scene, stack, out):
        """The denoiser's auxiliary images at pixel (px, py) (layout AOV_*): the albedo
        (base colour) and the world-space shading normal at the first
        surface that is not specular (AOV_SPECULAR_ROUGHNESS), the mean of n_samples camera
        rays (the sampler's own camera and BSDF numbers). A ray that leaves the scene gives
        the environment's radiance clamped to [0, 1] as albedo and a zero normal (Open Image
        Denoise's convention for "no surface"); an emitter's albedo is its base colour plus
        its radiance, clamped to [0, 1]."""
        height = out.shape[0]
        width = out.shape[1]
        acc = (ZERO, ZERO, ZERO)
        nacc = (ZERO, ZERO, ZERO)
        for sample in range(n_samples):
            state = start_path(py * width + px, sample, seed)
            o, d = camera_ray(scene.cam, px, py, state, width, height)
            skip = -1
            cone = ZERO
            spread = ZERO
            if MIPMAPS:
                spread = scene.cam[CAM_CONE]
            albedo = (ZERO, ZERO, ZERO)
            normal = (ZERO, ZERO, ZERO)
            for bounce in range(AOV_MAX_SPECULAR + 1):
                t, tri, b1, b2 = trace_closest(o, d, INF, skip, scene.tri_v, scene.bvh_box,
                                               scene.bvh_child, stack)
                if tri < 0:
                    if ANY_ENVIRONMENT:
                        le, weight = escaped(scene.env, scene.env_img, scene.env_info, d, ZERO)
                        albedo = (min(max(le[0], ZERO), ONE), min(max(le[1], ZERO), ONE),
                                  min(max(le[2], ZERO), ONE))
                    break
                v0 = load3(scene.tri_v, tri, TRI_V0)
                e1 = load3(scene.tri_v, tri, TRI_E1)
                e2 = load3(scene.tri_v, tri, TRI_E2)
                p = madd(madd(v0, e1, b1), e2, b2)
                ng = normalize(cross(e1, e2))
                wo = neg(d)
                m = scene.tri_mat[tri]
                tu, tv = tri_uv_at(scene.tri_uv, tri, b1, b2)
                fp = NO_FOOTPRINT
                if MIPMAPS:
                    if bounce <= MIP_LAST_BOUNCE:
                        cone, fp = footprint(scene.tri_uv, tri, e1, e2, ng, d, t, cone,
                                             spread)
                is_principled, params = material_at(scene.mat, scene.mat_tex, scene.tex_data,
                                                    scene.tex_int, scene.tex_f, m, tu, tv, fp)
                if VERTEX_COLORS:
                    params = tinted(params, scene.tri_col, tri, b1, b2)
                # an emitter: its base colour plus its radiance, clamped to [0, 1] as the
                # sky's is; with the base colour alone a light and the ceiling around it
                # have one albedo, and the denoiser blurs the light's edge into the ceiling
                le = (ZERO, ZERO, ZERO)
                if TRI_LIGHTS:
                    # (zero radiance where the surface does not emit towards wo)
                    le, _, _ = hit_emission(
                        scene.mat, scene.mat_tex, scene.tex_data, scene.tex_int, scene.tex_f,
                        scene.tri_light_pdf, scene.lt_node, scene.lt_link, scene.tri_light_leaf,
                        tri, m, dot(ng, wo), o, t, ZERO, tu, tv, fp)
                ng, ns, tangent, bitangent, wp = shading_frame(
                    scene.tri_n, scene.tri_t, scene.mat_tex, scene.tex_data, scene.tex_int,
                    scene.tex_f, tri, m, b1, b2, e1, ng, wo, params[P_TRANSMISSION] > ZERO,
                    tu, tv, fp)
                albedo = (min(max(params[P_BASE] + le[0], ZERO), ONE),
                          min(max(params[P_BASE + 1] + le[1], ZERO), ONE),
                          min(max(params[P_BASE + 2] + le[2], ZERO), ONE))
                normal = to_world(wp, tangent, bitangent, ns)
                specular = is_principled and params[P_ROUGHNESS] < AOV_SPECULAR_ROUGHNESS and (
                    params[P_METALLIC] > HALF_F or params[P_TRANSMISSION] > HALF_F)
                if not specular or bounce == AOV_MAX_SPECULAR:
                    break
                wo_l = local_wo(wo, tangent, bitangent, ns)
                origin = ray_origin(scene.tri_n, tri, p, b1, b2, v0, e1, e2, ng)
                ng_tri = ng
                ng = side_normal(ng, ns, wp)
                dim = D_FIRST_BOUNCE + bounce * DIMS_PER_BOUNCE
                dims = open_set(state, dim + D_BSDF_U)
                wi, weight, pdf_bsdf = sample_world(
                    is_principled, params, wo, wo_l, tangent, bitangent, ns, ng, wp,
                    draw(state, dims, dim + D_BSDF_LOBE), draw(state, dims, dim + D_BSDF_U),
                    draw(state, dims, dim + D_BSDF_V))
                if not (pdf_bsdf > ZERO):
                    break
                o = leave(p, ng, wi, origin)
                d = wi
                skip = own_skip(tri, ng_tri, ng, wi)
            acc = add(acc, albedo)
            nacc = add(nacc, normal)
        inv = ONE / np.float32(max(n_samples, 1))
        for c in range(3):
            out[py, px, AOV_ALBEDO + c] = acc[c] * inv
            out[py, px, AOV_NORMAL + c] = nacc[c] * inv

    # ---- The wavefront form: the same path, one vertex per kernel launch ----
    # A pass's paths (pixel, sample) are numbered path = (sample - sample_start) * pixels
    # + pixel, so that a warp's lanes hold nearby pixels of one sample. Their state lives
    # in paths_f / paths_i between launches (layout PATH_*); a launch runs one step for the
    # paths of a queue (backends.wavefront: wave_start; per vertex wave_trace, then
    # wave_miss for the rays that left and wave_shade for the hits; wave_finish for the
    # paths still alive after the last vertex launched apart; wave_film). Every path draws
    # the numbers render_sample draws and takes the same steps, and wave_film adds a
    # pixel's samples in sample order: the image is render_pixel_nested's.

    @step
    def load_path(paths_f, paths_i, path):
        o = (paths_f[PATH_O, path], paths_f[PATH_O + 1, path], paths_f[PATH_O + 2, path])
        d = (paths_f[PATH_D, path], paths_f[PATH_D + 1, path], paths_f[PATH_D + 2, path])
        beta = (paths_f[PATH_BETA, path], paths_f[PATH_BETA + 1, path],
                paths_f[PATH_BETA + 2, path])
        radiance = (paths_f[PATH_RADIANCE, path], paths_f[PATH_RADIANCE + 1, path],
                    paths_f[PATH_RADIANCE + 2, path])
        return (o, d, beta, radiance, paths_f[PATH_PDF_PREV, path], paths_i[PATH_SKIP, path],
                paths_i[PATH_BOUNCE, path], paths_f[PATH_CONE, path])

    @step
    def store_path(paths_f, paths_i, path, o, d, beta, radiance, pdf_prev, skip, bounce,
                   cone):
        for c in range(3):
            paths_f[PATH_O + c, path] = o[c]
            paths_f[PATH_D + c, path] = d[c]
            paths_f[PATH_BETA + c, path] = beta[c]
            paths_f[PATH_RADIANCE + c, path] = radiance[c]
        paths_f[PATH_PDF_PREV, path] = pdf_prev
        paths_f[PATH_CONE, path] = cone
        paths_i[PATH_SKIP, path] = skip
        paths_i[PATH_BOUNCE, path] = bounce

    @step
    def path_pixel(path, pixels):
        """(pixel, sample - sample_start) of path number ``path`` (see the numbering
        above), with a 32-bit division: path < 2**32."""
        q = np.int64(udiv32(path, pixels))
        return path - q * pixels, q

    @step
    def resume_path(path, sample_start, width, height, seed, scene, paths_f, paths_i):
        """Path ``path`` as a launch takes it up: its sampler state, the camera's cone
        spread and its stored state (load_path)."""
        pixel, offset = path_pixel(path, width * height)
        state = start_path(pixel, sample_start + offset, seed)
        spread = ZERO
        if MIPMAPS:
            spread = scene.cam[CAM_CONE]
        return state, spread, load_path(paths_f, paths_i, path)

    @entry
    def wave_start(path, sample_start, width, height, seed, scene, paths_f, paths_i):
        """Path ``path``'s camera ray (see the numbering above)."""
        pixel, offset = path_pixel(path, width * height)
        px, py = path_pixel(pixel, width)
        state = start_path(pixel, sample_start + offset, seed)
        o, d, beta, radiance, pdf_prev, skip, bounce, cone = start_camera_path(
            scene.cam, px, py, state, width, height)
        store_path(paths_f, paths_i, path, o, d, beta, radiance, pdf_prev, skip, bounce, cone)
        paths_i[PATH_BOUNCE_RAYS, path] = 0
        paths_i[PATH_SHADOW_RAYS, path] = 0

    @entry
    def wave_trace(path, scene, paths_f, paths_i, stack):
        """The closest hit (t, tri, b1, b2) of path ``path``'s ray (tri < 0: none)."""
        o = (paths_f[PATH_O, path], paths_f[PATH_O + 1, path], paths_f[PATH_O + 2, path])
        d = (paths_f[PATH_D, path], paths_f[PATH_D + 1, path], paths_f[PATH_D + 2, path])
        return trace_closest(o, d, INF, paths_i[PATH_SKIP, path], scene.tri_v,
                             scene.bvh_box, scene.bvh_child, stack)

    @entry
    def store_hit(hits_f, hits_i, slot, t, tri, b1, b2):
        hits_f[HIT_T, slot] = t
        hits_f[HIT_B1, slot] = b1
        hits_f[HIT_B2, slot] = b2
        hits_i[slot] = tri

    @entry
    def wave_miss(path, scene, paths_f, paths_i):
        """Path ``path``, whose ray left the scene: its end (shade_hit's first branch, the
        environment's radiance MIS-weighted), apart from the paths that hit a surface, so
        that their shading runs in full warps."""
        if ANY_ENVIRONMENT:
            d = (paths_f[PATH_D, path], paths_f[PATH_D + 1, path], paths_f[PATH_D + 2, path])
            beta = (paths_f[PATH_BETA, path], paths_f[PATH_BETA + 1, path],
                    paths_f[PATH_BETA + 2, path])
            le, weight = escaped(scene.env, scene.env_img, scene.env_info, d,
                                 paths_f[PATH_PDF_PREV, path])
            contribution = scale(mul(beta, le), weight)
            for c in range(3):
                paths_f[PATH_RADIANCE + c, path] += contribution[c]

    @entry
    def wave_shade(path, slot, sample_start, width, height, seed, max_bounces, rr_depth,
                   scene, paths_f, paths_i, hits_f, hits_i, stack):
        """The rest of path ``path``'s vertex (shade_hit) at the hit in ``slot``: whether
        the path goes on."""
        state, spread, (o, d, beta, radiance, pdf_prev, skip, bounce, cone) = resume_path(
            path, sample_start, width, height, seed, scene, paths_f, paths_i)
        (o, d, beta, radiance, pdf_prev, skip, bounce, cone, shadow_rays, bounce_rays,
         alive) = shade_hit(o, d, beta, radiance, pdf_prev, skip, bounce, cone, spread, state,
                            max_bounces, rr_depth, scene, stack, hits_f[HIT_T, slot],
                            hits_i[slot], hits_f[HIT_B1, slot], hits_f[HIT_B2, slot])
        store_path(paths_f, paths_i, path, o, d, beta, radiance, pdf_prev, skip, bounce, cone)
        paths_i[PATH_BOUNCE_RAYS, path] += bounce_rays
        paths_i[PATH_SHADOW_RAYS, path] += shadow_rays
        return alive

    @entry
    def wave_finish(path, sample_start, width, height, seed, max_bounces, rr_depth, scene,
                    paths_f, paths_i, stack):
        """Path ``path`` from its stored ray to its end (path_vertex in a loop, as
        render_pixel's megakernel does): the wavefront's last launch, for the few long
        paths that outlive its first vertices."""
        state, spread, (o, d, beta, radiance, pdf_prev, skip, bounce, cone) = resume_path(
            path, sample_start, width, height, seed, scene, paths_f, paths_i)
        n_bounce_rays = 0
        n_shadow_rays = 0
        alive = True
        while alive:
            (o, d, beta, radiance, pdf_prev, skip, bounce, cone, shadow_rays, bounce_rays,
             alive) = path_vertex(o, d, beta, radiance, pdf_prev, skip, bounce, cone, spread,
                                  state, max_bounces, rr_depth, scene, stack)
            n_shadow_rays += shadow_rays
            n_bounce_rays += bounce_rays
        for c in range(3):
            paths_f[PATH_RADIANCE + c, path] = radiance[c]
        paths_i[PATH_BOUNCE_RAYS, path] += n_bounce_rays
        paths_i[PATH_SHADOW_RAYS, path] += n_shadow_rays

    @entry
    def wave_film(px, py, s0, n_samples, paths_f, paths_i, out, stats, first):
        """Add pixel (px, py)'s paths of the launch's samples [s0, s0 + n_samples) (in
        sample order) to out[py, px] and stats[py, px] (layout STAT_*): from zero where
        ``first``, else to what an earlier launch of the pass left there."""
        width = out.shape[1]
        pixel = py * width + px
        pixels = width * out.shape[0]
        if first:
            r, g, b = ZERO, ZERO, ZERO
            n_bounce = 0
            n_shadow = 0
            n_bad = 0
        else:
            r, g, b = out[py, px, 0], out[py, px, 1], out[py, px, 2]
            n_bounce = stats[py, px, STAT_BOUNCE_RAYS]
            n_shadow = stats[py, px, STAT_SHADOW_RAYS]
            n_bad = stats[py, px, STAT_NONFINITE]
        for s in range(s0, s0 + n_samples):
            path = s * pixels + pixel
            r, g, b, n_bad = add_sample(r, g, b, n_bad, (
                paths_f[PATH_RADIANCE, path], paths_f[PATH_RADIANCE + 1, path],
                paths_f[PATH_RADIANCE + 2, path]))
            n_bounce += paths_i[PATH_BOUNCE_RAYS, path]
            n_shadow += paths_i[PATH_SHADOW_RAYS, path]
        store_pixel(out, stats, px, py, r, g, b, n_bounce, n_shadow, n_bad)

    wavefront = Wavefront(wave_start, wave_trace, store_hit, wave_miss, wave_shade,
                          wave_finish, wave_film)
    return (render_pixel, aov_pixel, render_pixel_nested, wavefront,
            Deferred(render_pixel_deferred, drain_escapes))


class Deferred(NamedTuple):
    """The CPU's pixel function for scenes with an environment map, whose escaped rays are
    looked up a few paths later (see make_kernels), and the row's last step."""
    pixel: object
    drain: object


@functools.lru_cache(maxsize=None)
def make_deferred_pixel(features, target="cpu"):
    """:class:`Deferred` for scenes with ``features`` (an environment map)."""
    return make_kernels(features, target)[4]


class Wavefront(NamedTuple):
    """The entries of the wavefront form of the path tracer (make_wavefront)."""
    start: object
    trace: object
    store_hit: object
    miss: object
    shade: object
    finish: object
    film: object


@functools.lru_cache(maxsize=None)
def make_wavefront(features, target="cuda"):
    """The wavefront entries (:class:`Wavefront`) for scenes with ``features``."""
    return make_kernels(features, target)[3]
