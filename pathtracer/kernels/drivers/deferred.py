"""The CPU's driver for scenes with an environment map: escaped rays looked up a few paths
later.

A ray that leaves the scene reads a random cell of the map (8 MB of texels for a 1k HDRI,
beyond a core's L2), and a core running one path at a time waits for those loads.
``render_pixel_deferred`` queues each finished path (the megakernel's render_sample) in a
ring of ESCAPE_RING records per image row (esc_f, esc_i; layout ESC_*): its radiance so far
and, for a ray that left, the map's cell (env_locate) with its texels prefetched; the record
is finished (escaped_in_cell, add_sample into out) when the ring comes round to its slot,
ESCAPE_RING paths later, or by drain_escapes at the row's end. Records are finished in the
order they were queued, so each pixel's samples are added in sample order, as
render_pixel_nested adds them (the same image, bit for bit: tests/test_render.py).
"""
import functools
from typing import NamedTuple

from ..constants import ZERO
from ..device import entry_marker, step_marker
from ..emitters import make_emitters
from ..envmap import env_locate, env_prefetch
from ..layout import (ESC_BETA, ESC_FX, ESC_FY, ESC_I0, ESC_I1, ESC_J0, ESC_J1, ESC_OUT,
                      ESC_PDF_PREV, ESC_PX, ESC_RADIANCE, ESC_Y, ESCAPE_RING,
                      STAT_BOUNCE_RAYS, STAT_NONFINITE, STAT_SHADOW_RAYS)
from ..path import make_path
from ..vec import add, mul, scale
from .megakernel import make_megakernel


class Deferred(NamedTuple):
    """The pixel function and the row's last step."""
    pixel: object
    drain: object


@functools.lru_cache(maxsize=None)
def make_deferred(features, target="cpu"):
    """:class:`Deferred` for scenes with ``features`` (an environment map)."""
    step = step_marker(target)
    entry_inlined = entry_marker(target, inlined=True)
    P = make_path(features, target)
    (add_sample) = (
        P.add_sample)
    M = make_megakernel(features, target)
    escaped_in_cell = make_emitters(features, target).escaped_in_cell
    render_sample, next_camera_lane = M.sample, M.next_lane

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
    def queue_record(esc_f, esc_i, slot, px, path, out_ray, scene):
        """A finished path of pixel column px in ``slot`` (render_sample's answer); a ray
        that left gets its map cell located and the cell's texels prefetched."""
        esc_i[slot, ESC_PX] = px
        for c in range(3):
            esc_f[slot, ESC_RADIANCE + c] = path.radiance[c]
        esc_i[slot, ESC_OUT] = 1 if out_ray else 0
        if out_ray:
            i0, i1, j0, j1, fx, fy, y = env_locate(scene.env_img, scene.env_info, path.d)
            env_prefetch(scene.env_img, i0, i1, j0, j1)
            esc_i[slot, ESC_I0] = i0
            esc_i[slot, ESC_I1] = i1
            esc_i[slot, ESC_J0] = j0
            esc_i[slot, ESC_J1] = j1
            esc_f[slot, ESC_FX] = fx
            esc_f[slot, ESC_FY] = fy
            esc_f[slot, ESC_Y] = y
            esc_f[slot, ESC_PDF_PREV] = path.pdf_prev
            for c in range(3):
                esc_f[slot, ESC_BETA + c] = path.beta[c]

    @entry_inlined
    def render_pixel_deferred(px, py, sample_start, n_samples, seed, max_bounces, rr_depth,
                              scene, stack, esc_f, esc_i, queued, out, stats):
        """render_pixel_nested's sums, each path's escaped ray finished ESCAPE_RING paths
        later (see above); ``queued``: the row's paths queued so far (the ring's position);
        returns it. The row's last records are finished by drain_escapes."""
        shape = (out.shape[0], out.shape[1])
        for c in range(3):
            out[py, px, c] = ZERO
        stats[py, px, STAT_NONFINITE] = 0
        n_bounce = 0
        n_shadow = 0
        for s in range(sample_start, sample_start + n_samples):
            lane = next_camera_lane(px, py, s, sample_start, n_samples, seed, shape, scene, stack)
            path, nb, ns, out_ray = render_sample(px, py, s, seed, shape,
                                                  (max_bounces, rr_depth), scene, stack, lane)
            slot = queued % ESCAPE_RING
            if queued >= ESCAPE_RING:
                finish_record(esc_f, esc_i, slot, py, scene, out, stats)
            queue_record(esc_f, esc_i, slot, px, path, out_ray, scene)
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

    return Deferred(render_pixel_deferred, drain_escapes)
