"""The megakernel drivers: a pixel's paths in one thread, each path a loop over the bounce
(kernels.path). Two forms of the same sums (the same samples added in the same order: the
same image; tests/test_render.py checks it bit for bit):

- ``render_pixel_regenerating``: one loop over the vertices of all the pixel's paths, the
  iteration after a path's last vertex starting the next sample (path regeneration, Novak
  et al. 2010), so that a GPU lane whose path ended does not wait for the warp's longest.
- ``render_pixel_nested``: one path after the other; on the CPU a pixel's camera rays are
  traced eight at a time first (kernels.wide.closest_hit_packet, SIMD over the rays), and
  each path starts from its ray's hit.

Which one runs where: :func:`.choose_driver`.
"""
import functools
from typing import NamedTuple

from ..constants import INF, ONE, ZERO
from ..device import entry_marker, step_marker
from ..path import Hit, make_path
from ..rng import make_sampler
from ..layout import ALPHA_DIMS, D_ALPHA, specialise
from ..wide import PACKET, closest_hit_packet, packet_ray_hit, packet_set_ray

# The fewest camera rays traced as a packet (kernels.wide.closest_hit_packet; fewer: one by
# one): with four of eight lanes used, packets ran 0.97-1.01x the single rays' paths/s
# (4-spp passes), with all eight 1.03-1.06x (16-spp passes; 2-core EPYC, bench.ab,
# 2026-11-29).
PACKET_MIN_RAYS = 5


class Megakernel(NamedTuple):
    regenerating: object    # render_pixel with path regeneration
    nested: object          # render_pixel_nested
    sample: object          # render_sample (one camera path; the deferred driver's too)
    next_lane: object       # next_camera_lane (the CPU's camera packets)


@functools.lru_cache(maxsize=None)
def make_megakernel(features, target="cpu"):
    """The megakernel's per-pixel entries (:class:`Megakernel`) for scenes with
    ``features`` on ``target``."""
    S = specialise(features)
    step = step_marker(target)
    entry = entry_marker(target)
    entry_inlined = entry_marker(target, inlined=True)
    P = make_path(features, target)
    (add_sample, camera_ray, escaped_path, path_state, path_vertex, shade_surface,
     spread_of, start_camera_path, store_pixel, trace_hit) = (
        P.add_sample, P.camera_ray, P.escaped_path, P.path_state, P.path_vertex,
        P.shade_surface, P.spread_of, P.start_camera_path, P.store_pixel, P.trace_hit)
    start_path = make_sampler(S.sobol, table=target == "cpu")[0]
    ANY_ENVIRONMENT = S.any_environment
    # The CPU traces a pixel's camera rays eight at a time (camera_packet below), and each
    # path starts from its ray's hit.
    # (Not with alpha: a camera ray may pass the surface its packet hit.)
    CAMERA_PACKETS = target == "cpu" and not S.alpha

    @entry
    def render_pixel(px, py, sample_start, n_samples, seed, max_bounces, rr_depth, scene,
                     stack, out, stats):
        """Add the paths of samples [sample_start, + n_samples) of pixel (px, py) to
        out[py, px] (float32 rgb sums, in sample order; see path.add_sample) and count
        rays and non-finite samples in stats[py, px] (layout STAT_*), with path
        regeneration."""
        width = out.shape[1]
        spread = spread_of(scene)
        r, g, b = ZERO, ZERO, ZERO      # the pixel's sums
        n_bad = 0
        n_bounce_rays = 0
        n_shadow_rays = 0
        # the path under way: started at the top of the loop whenever alive is False
        state = start_path(py * width + px, sample_start, seed)
        zero3 = (ZERO, ZERO, ZERO)
        path = path_state(zero3, zero3, zero3, zero3, ZERO, 0, 0, ZERO)
        alive = False
        started = 0                     # paths started
        while True:
            if not alive:
                if started > 0:
                    r, g, b, n_bad = add_sample(r, g, b, n_bad, path.radiance)
                if started == n_samples:
                    break
                state = start_path(py * width + px, sample_start + started, seed)
                started += 1
                o, d = camera_ray(scene.cam, px, py, state, width, out.shape[0])
                path = start_camera_path(o, d)
            path, shadow_rays, bounce_rays, alive = path_vertex(
                path, spread, state, max_bounces, rr_depth, scene, stack)
            n_shadow_rays += shadow_rays
            n_bounce_rays += bounce_rays
        store_pixel(out, stats, px, py, (r, g, b), (n_bounce_rays, n_shadow_rays, n_bad))

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
    def next_camera_lane(px, py, s, sample_start, n_samples, seed, shape, scene, stack):
        """Sample s's lane of the camera packet, tracing the next packet of the pixel's rays
        (up to PACKET, from sample s) first when s starts one; -1: the sample traces its
        own camera ray (elsewhere than on the CPU, and the last few samples of a pass
        that leave fewer than PACKET_MIN_RAYS: a packet half empty costs what it saves,
        2-core EPYC, bench.ab, 2026-11-29). shape: the image's (height, width)."""
        if not CAMERA_PACKETS:
            return -1
        lane = (s - sample_start) % PACKET
        n_rays = min(PACKET, sample_start + n_samples - (s - lane))
        if n_rays < PACKET_MIN_RAYS:
            return -1
        if lane == 0:
            camera_packet(px, py, s, n_rays, seed, shape[1], shape[0], scene, stack)
        return lane

    @entry_inlined
    def render_sample(px, py, sample_index, seed, shape, limits, scene, stack, lane):
        """One camera path through pixel (px, py) (shape: the image's (height, width);
        limits: (max_bounces, rr_depth)): (its PathState, bounce rays, shadow rays,
        whether its last ray left the scene towards an environment). The caller adds
        what that ray sees (path.escaped_path, or the deferred driver later).
        ``lane`` >= 0 (on the CPU): the camera ray and its hit are that lane of the packet
        that camera_packet traced (next_camera_lane)."""
        state = start_path(py * shape[1] + px, sample_index, seed)
        camera_hit = False
        if CAMERA_PACKETS:          # (a constant: elsewhere the branch is not compiled)
            camera_hit = lane >= 0
        if camera_hit:
            o, d, t, tri, b1, b2 = packet_ray_hit(stack, lane)
        else:
            o, d = camera_ray(scene.cam, px, py, state, shape[1], shape[0])
            t, tri, b1, b2 = INF, -1, ZERO, ZERO
        path = start_camera_path(o, d)
        spread = spread_of(scene)
        n_bounce_rays = 0
        n_shadow_rays = 0
        while True:
            if not camera_hit:
                t, tri, b1, b2 = trace_hit(scene, path.o, path.d, path.skip, state[0],
                                           D_ALPHA + path.bounce * ALPHA_DIMS, stack)
            camera_hit = False
            if tri < 0:
                return path, n_bounce_rays, n_shadow_rays, ANY_ENVIRONMENT
            path, shadow_rays, bounce_rays, alive = shade_surface(
                path, Hit(t, tri, b1, b2), spread, state, limits[0], limits[1], scene, stack)
            n_shadow_rays += shadow_rays
            n_bounce_rays += bounce_rays
            if not alive:
                return path, n_bounce_rays, n_shadow_rays, False

    @entry_inlined
    def render_pixel_nested(px, py, sample_start, n_samples, seed, max_bounces, rr_depth,
                            scene, stack, out, stats):
        """render_pixel's sums, one path after the other."""
        shape = (out.shape[0], out.shape[1])
        r, g, b = ZERO, ZERO, ZERO
        n_bad = 0
        n_bounce = 0
        n_shadow = 0
        for s in range(sample_start, sample_start + n_samples):
            lane = next_camera_lane(px, py, s, sample_start, n_samples, seed, shape, scene,
                                    stack)
            path, nb, ns, out_ray = render_sample(px, py, s, seed, shape,
                                                  (max_bounces, rr_depth), scene, stack, lane)
            if out_ray:
                path = escaped_path(scene, path)
            r, g, b, n_bad = add_sample(r, g, b, n_bad, path.radiance)
            n_bounce += nb
            n_shadow += ns
        store_pixel(out, stats, px, py, (r, g, b), (n_bounce, n_shadow, n_bad))

    return Megakernel(render_pixel, render_pixel_nested, render_sample, next_camera_lane)
