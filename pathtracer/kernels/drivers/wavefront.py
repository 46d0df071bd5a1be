"""The wavefront driver: the same path, one vertex per kernel launch (the GPU's form for
scenes whose warps diverge most; :func:`.choose_driver`).

A pass's paths (pixel, sample) are numbered path = (sample - sample_start) * pixels +
pixel, so that a warp's lanes hold nearby pixels of one sample. Their state lives in
paths_f / paths_i between launches (layout PATH_*); a launch runs one step for the paths
of a queue (backends.wavefront: wave_start; per vertex wave_trace, then wave_miss for the
rays that left and wave_shade for the hits; wave_finish for the paths still alive after
the last vertex launched apart; wave_film). Every path draws the numbers the megakernel
draws and takes the same steps (kernels.path), and wave_film adds a pixel's samples in
sample order: the image is render_pixel_nested's.
"""
import functools
from typing import NamedTuple

import numpy as np

from ..constants import ZERO
from ..device import entry_marker, step_marker
from ..layout import (HIT_B1, HIT_B2, HIT_T, PATH_BETA, PATH_BOUNCE, PATH_BOUNCE_RAYS,
                      PATH_CONE, PATH_D, PATH_O, PATH_PDF_PREV, PATH_RADIANCE,
                      PATH_SHADOW_RAYS, PATH_SKIP, STAT_BOUNCE_RAYS, STAT_NONFINITE,
                      STAT_SHADOW_RAYS, specialise)
from ..path import Hit, make_path
from ..rng import make_sampler, udiv32


class Wavefront(NamedTuple):
    """The entries of the wavefront driver."""
    start: object
    trace: object
    store_hit: object
    miss: object
    shade: object
    finish: object
    film: object


@functools.lru_cache(maxsize=None)
def make_wavefront(features, target="cuda"):
    """The wavefront entries (:class:`Wavefront`) for scenes with ``features``. Not for
    scenes with alpha: its trace launch has no sampler state for stochastic transparency
    (choose_driver gives them the megakernel)."""
    S = specialise(features)
    if S.alpha:
        raise ValueError("the wavefront driver does not render scenes with alpha")
    step = step_marker(target)
    entry = entry_marker(target)
    P = make_path(features, target)
    (add_sample, camera_ray, escaped_path, path_state, path_vertex, shade_surface,
     spread_of, start_camera_path, store_pixel, trace_hit) = (
        P.add_sample, P.camera_ray, P.escaped_path, P.path_state, P.path_vertex,
        P.shade_surface, P.spread_of, P.start_camera_path, P.store_pixel, P.trace_hit)
    start_path = make_sampler(S.sobol, table=target == "cpu")[0]
    ANY_ENVIRONMENT = S.any_environment

    @step
    def load3f(paths_f, slot, path):
        return paths_f[slot, path], paths_f[slot + 1, path], paths_f[slot + 2, path]

    @step
    def load_path(paths_f, paths_i, path):
        return path_state(load3f(paths_f, PATH_O, path), load3f(paths_f, PATH_D, path),
                            load3f(paths_f, PATH_BETA, path),
                            load3f(paths_f, PATH_RADIANCE, path),
                            paths_f[PATH_PDF_PREV, path], paths_i[PATH_SKIP, path],
                            paths_i[PATH_BOUNCE, path], paths_f[PATH_CONE, path])

    @step
    def store_path(paths_f, paths_i, path, state):
        for c in range(3):
            paths_f[PATH_O + c, path] = state.o[c]
            paths_f[PATH_D + c, path] = state.d[c]
            paths_f[PATH_BETA + c, path] = state.beta[c]
            paths_f[PATH_RADIANCE + c, path] = state.radiance[c]
        paths_f[PATH_PDF_PREV, path] = state.pdf_prev
        paths_f[PATH_CONE, path] = state.cone
        paths_i[PATH_SKIP, path] = state.skip
        paths_i[PATH_BOUNCE, path] = state.bounce

    @step
    def path_pixel(path, pixels):
        """(pixel, sample - sample_start) of path number ``path`` (see the numbering
        above), with a 32-bit division: path < 2**32."""
        q = np.int64(udiv32(path, pixels))
        return path - q * pixels, q

    @step
    def resume_path(path, sample_start, shape, seed, paths_f, paths_i):
        """Path ``path`` as a launch takes it up: its sampler state and its stored
        PathState. shape: the image's (height, width)."""
        pixel, offset = path_pixel(path, shape[0] * shape[1])
        state = start_path(pixel, sample_start + offset, seed)
        return state, load_path(paths_f, paths_i, path)

    @entry
    def wave_start(path, sample_start, width, height, seed, scene, paths_f, paths_i):
        """Path ``path``'s camera ray (see the numbering above)."""
        pixel, offset = path_pixel(path, width * height)
        px, py = path_pixel(pixel, width)
        state = start_path(pixel, sample_start + offset, seed)
        o, d = camera_ray(scene.cam, px, py, state, width, height)
        store_path(paths_f, paths_i, path, start_camera_path(o, d))
        paths_i[PATH_BOUNCE_RAYS, path] = 0
        paths_i[PATH_SHADOW_RAYS, path] = 0

    @entry
    def wave_trace(path, scene, paths_f, paths_i, stack):
        """The closest hit (t, tri, b1, b2) of path ``path``'s ray (tri < 0: none)."""
        return trace_hit(scene, load3f(paths_f, PATH_O, path), load3f(paths_f, PATH_D, path),
                         paths_i[PATH_SKIP, path], 0, 0, stack)

    @entry
    def store_hit(hits_f, hits_i, slot, t, tri, b1, b2):
        hits_f[HIT_T, slot] = t
        hits_f[HIT_B1, slot] = b1
        hits_f[HIT_B2, slot] = b2
        hits_i[slot] = tri

    @entry
    def wave_miss(path, scene, paths_f, paths_i):
        """Path ``path``, whose ray left the scene: its end (path.escaped_path), apart from
        the paths that hit a surface, so that their shading runs in full warps."""
        if ANY_ENVIRONMENT:
            radiance = escaped_path(scene, load_path(paths_f, paths_i, path)).radiance
            for c in range(3):
                paths_f[PATH_RADIANCE + c, path] = radiance[c]

    @entry
    def wave_shade(path, slot, sample_start, width, height, seed, max_bounces, rr_depth,
                   scene, paths_f, paths_i, hits_f, hits_i, stack):
        """The rest of path ``path``'s vertex (path.shade_surface) at the hit in ``slot``:
        whether the path goes on."""
        state, p = resume_path(path, sample_start, (height, width), seed, paths_f, paths_i)
        hit = Hit(hits_f[HIT_T, slot], hits_i[slot], hits_f[HIT_B1, slot],
                  hits_f[HIT_B2, slot])
        p, shadow_rays, bounce_rays, alive = shade_surface(
            p, hit, spread_of(scene), state, max_bounces, rr_depth, scene, stack)
        store_path(paths_f, paths_i, path, p)
        paths_i[PATH_BOUNCE_RAYS, path] += bounce_rays
        paths_i[PATH_SHADOW_RAYS, path] += shadow_rays
        return alive

    @entry
    def wave_finish(path, sample_start, width, height, seed, max_bounces, rr_depth, scene,
                    paths_f, paths_i, stack):
        """Path ``path`` from its stored ray to its end (path_vertex in a loop, as the
        megakernel runs it): the wavefront's last launch, for the few long paths that
        outlive its first vertices."""
        state, p = resume_path(path, sample_start, (height, width), seed, paths_f, paths_i)
        spread = spread_of(scene)
        n_bounce_rays = 0
        n_shadow_rays = 0
        alive = True
        while alive:
            p, shadow_rays, bounce_rays, alive = path_vertex(
                p, spread, state, max_bounces, rr_depth, scene, stack)
            n_shadow_rays += shadow_rays
            n_bounce_rays += bounce_rays
        for c in range(3):
            paths_f[PATH_RADIANCE + c, path] = p.radiance[c]
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
            r, g, b, n_bad = add_sample(r, g, b, n_bad,
                                          load3f(paths_f, PATH_RADIANCE, path))
            n_bounce += paths_i[PATH_BOUNCE_RAYS, path]
            n_shadow += paths_i[PATH_SHADOW_RAYS, path]
        store_pixel(out, stats, px, py, (r, g, b), (n_bounce, n_shadow, n_bad))

    return Wavefront(wave_start, wave_trace, store_hit, wave_miss, wave_shade, wave_finish,
                     wave_film)
