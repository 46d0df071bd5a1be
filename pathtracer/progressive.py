"""Progressive rendering: passes of growing size accumulated into a float64 film, optionally
with adaptive sampling."""
import signal
import time
from dataclasses import dataclass, field

import numpy as np

from . import limits
from .errors import Interrupted
from .film import RELMSE_EPS, Film, compile_accumulation, error_estimate  # noqa: F401
from .scene.compile import for_spp


@dataclass
class RenderResult:
    film: Film
    seconds: float           # rendering time, compile excluded
    compile_seconds: float
    interrupted: bool = False
    stopped: bool = False    # on_pass returned False
    signal: int = 0          # the signal that stopped the render (SIGINT for Ctrl-C)
    passes: list = field(default_factory=list)   # (elapsed s, spp) after each pass


# A headless render's pass grows at most this many times over the last one's samples
HEADLESS_GROWTH = 64
# Adaptive sampling: every pixel takes this many samples before its error is judged
ADAPTIVE_MIN_SPP = 16
# A uniform render's next pass is launched before the last one is added to the film (see
# render) after passes shorter than this: on_pass may stop the render with it in flight
PIPELINE_SECONDS = 0.05


def stop_threshold(film, target, err):
    """Per pixel, the estimated relMSE below which the pixel stops: target * sigma_i /
    mean(sigma), sigma_i the pixel's estimated relative standard deviation per sample
    (from ``err``, the error_estimate, times its samples). Samples then go to pixels in
    proportion to sigma_i, the allocation that minimises the image's mean relMSE for a
    given number of samples (Neyman allocation: the sum of sigma_i^2 / n_i under a fixed
    sum of n_i is least at n_i proportional to sigma_i), and when every pixel has stopped
    the mean of their estimated relMSE is at most ``target`` (the mean of target *
    sigma_i / mean(sigma)). A threshold of ``target`` everywhere spent samples in
    proportion to sigma_i^2 instead: on the sun scene on an H100 it reached relMSE 1e-3 in
    0.82x of uniform sampling's time, this rule in 0.70x (docs/benchmarks.md)."""
    sigma = np.sqrt(err * np.maximum(film.count, 1))
    mean = sigma.mean()
    if not mean > 0:
        return target
    sigma *= target / mean
    return sigma


def render(scene, backend, spp=None, time_limit=None, seed=None, max_bounces=None,
           rr_depth=None, pass_seconds=0.5, on_pass=None, adaptive=None, first_pass=1,
           film=None, footprint_spp=None, headless=False):
    """Render ``scene`` with ``backend`` until ``spp`` samples per pixel or ``time_limit``
    seconds, whichever comes first (spp defaults to the scene's unless a time is given).

    Pass sizes start at ``first_pass`` spp (1: the image refreshes quickly at first;
    api.render starts a GPU's at a pass that fills it, and a caller that shows no
    intermediate image larger still, as each pass costs a launch and a copy; an adaptive
    render's at 2 to ADAPTIVE_MIN_SPP) and double while a pass is shorter than
    ``pass_seconds``, so overhead stays
    small later; ``headless`` (nobody sees the intermediate images): every pass after the
    first is aimed at ``pass_seconds`` from the last pass's speed (adaptive renders: 4x
    growth while 4x stays under it), as every pass costs a synchronisation, a copy and the
    film's sum (~10-20 ms for a 1024^2 image, which is what a split render over several
    GPUs waits for at each pass). ``on_pass(film, elapsed)`` is called after every pass
    (returning False ends the render). Ctrl-C (or any :class:`~.errors.Interrupted`)
    stops the render and returns the samples of the passes completed (``interrupted`` and
    ``signal`` are set). A render never exceeds ``limits.MAX_SPP`` samples per pixel (the
    random streams are indexed by 32-bit sample numbers).

    ``adaptive`` (a target relMSE of the image): adaptive sampling. Every pass is rendered
    in two halves (kept apart for :func:`error_estimate`); after ADAPTIVE_MIN_SPP samples a
    pixel whose estimated relMSE is below its share of the target (:func:`stop_threshold`:
    noisier pixels get a larger share) takes no more samples, and the render ends when
    every pixel has (the image's mean relMSE then at most the target, as estimated) or at
    ``spp`` / ``time_limit``. Each pixel is the plain mean of its
    own samples (nothing clamped); stopping on a noisy estimate of the error is the only
    source of bias, as in every adaptive sampler.

    ``film``: a film to continue (a resumed render, :mod:`pathtracer.resume`): its passes
    are kept and the render goes on with the samples after them (sample indices
    ``film.spp``, ...), the ones an uninterrupted render would have drawn; with adaptive
    sampling its finished pixels stay finished. ``footprint_spp``: the spp the texture
    footprints are narrowed for (default ``spp``; a resumed render keeps its first one).
    """
    seed = scene.seed if seed is None else seed
    max_bounces = scene.max_bounces if max_bounces is None else max_bounces
    rr_depth = scene.rr_depth if rr_depth is None else rr_depth
    if spp is None and time_limit is None:
        spp = scene.spp
    # texture footprints narrow with more samples
    scene = for_spp(scene, spp if footprint_spp is None else footprint_spp)
    if backend.scene is not scene:
        backend.update(scene)
    if film is None:
        film = Film(scene.height, scene.width)
    elif (film.height, film.width) != (scene.height, scene.width):
        raise ValueError(f"the film to continue is {film.width}x{film.height}, the scene "
                         f"{scene.width}x{scene.height}")
    if adaptive and film.spp > 0 and film.sum_b is None:
        # its samples were not taken in halves: the error estimate has nothing to compare
        raise ValueError(f"the film to continue ({film.spp} spp) was rendered without "
                         "adaptive sampling: it cannot go on adaptively")
    t0 = time.perf_counter()
    backend.compile()
    compile_accumulation(adaptive=bool(adaptive))
    compile_seconds = time.perf_counter() - t0
    # the film only adds the ray counts up: a backend that can sum them itself (CUDA: on
    # the GPU) returns the totals rather than H x W x 3 counts per pass
    render_pass = backend.render_pass_totals
    if adaptive:
        backend.prepare_halves()
    result = RenderResult(film, 0.0, compile_seconds)
    # an adaptive pass has two halves; its first passes (before ADAPTIVE_MIN_SPP samples,
    # when no pixel is judged yet) take first_pass too, at most ADAPTIVE_MIN_SPP
    n = max(2, min(int(first_pass), ADAPTIVE_MIN_SPP)) // 2 * 2 if adaptive else \
        max(1, int(first_pass))
    active = None
    if adaptive and film.spp >= ADAPTIVE_MIN_SPP:
        # a resumed adaptive render: a pixel that stopped (fewer samples than the film's)
        # stays stopped, the others are judged again as after any pass
        err = error_estimate(film)
        active = ((film.count == film.spp) &
                  (err > stop_threshold(film, adaptive, err))).astype(np.uint8)
    # A uniform render on a backend that can start a pass without waiting for it (CUDA:
    # ``launch``, then ``collect_pass_totals``) launches the next pass before it adds this
    # one to the film and calls on_pass, so the GPU renders while the host does that (a
    # small image's progressive render: ~0.5 ms a pass). Only after short passes
    # (PIPELINE_SECONDS): a pass launched ahead is lost when on_pass stops the render.
    pipelined = not adaptive and backend.pipelined

    def finished(done, elapsed):
        return (spp is not None and done >= spp) or done >= limits.MAX_SPP or \
            (time_limit is not None and elapsed >= time_limit)

    def clamp(n, done):
        n = min(n, limits.MAX_PASS_SAMPLES, limits.MAX_SPP - done)
        return min(n, spp - done) if spp is not None else n

    def next_size(n, dt, elapsed):
        """The next pass's samples after a pass of n took dt: grow the pass while it is
        short; aim the last pass at the time limit."""
        if headless and not adaptive:
            # nobody waits for an image: aim the next pass at pass_seconds from this
            # one's speed (at most HEADLESS_GROWTH times larger: a first pass of a few
            # ms is timed coarsely, and includes the launch and copy)
            n = max(1, int(min(HEADLESS_GROWTH * n, n * pass_seconds / max(dt, 1e-6))))
        elif headless and dt < pass_seconds / 4:
            n *= 4
        elif dt < pass_seconds:
            n *= 2
        elif dt > 2 * pass_seconds and n > 1:
            n //= 2
        if time_limit is not None and dt > 0:
            left = time_limit - elapsed
            if left > 0:   # (float: a huge time limit must not overflow an int)
                n = max(1, int(min(float(n), left / (dt / n))))
        return n

    ahead = None    # (launch time, samples) of the pass launched ahead, pipelined
    callback_s = 0.0    # how long the last on_pass took
    start = time.perf_counter()
    try:
        while True:
            if ahead is None:
                elapsed = time.perf_counter() - start
                if finished(film.spp, elapsed):
                    break
                if active is not None and not active.any():
                    break
                n = clamp(n, film.spp)
                t_pass = time.perf_counter()
                launched = False
            else:
                (t_pass, n), launched, ahead = ahead, True, None
            if adaptive and n >= 2:
                half = n // 2
                n = 2 * half
                first = film.spp
                # both halves from one launch where the backend can (CUDA), else one
                # launch each (lazily: a pass's buffers are added before the next one)
                halves = backend.render_halves(first, half, seed, max_bounces, rr_depth,
                                               active)
                for k, (pass_sum, stats) in enumerate(halves):
                    film.add(pass_sum, stats, half, active, half_b=k == 1)
                dt = time.perf_counter() - t_pass
            elif active is not None:
                pass_sum, stats = render_pass(film.spp, n, seed, max_bounces, rr_depth, active)
                film.add(pass_sum, stats, n, active)
                dt = time.perf_counter() - t_pass
            elif pipelined:
                if not launched:
                    backend.launch(film.spp, n, seed, max_bounces, rr_depth)
                t_wait = time.perf_counter()
                pass_sum, stats = backend.collect_pass_totals()
                now = time.perf_counter()
                # a pass launched ahead ran on the GPU through the last pass's on_pass (which
                # may save files): that time is not the pass's own, as it was not before
                # pipelining, but its wait here is
                dt = max(now - t_pass - callback_s, now - t_wait) if launched else \
                    now - t_pass
                done = film.spp + n
                elapsed = time.perf_counter() - start
                if dt < PIPELINE_SECONDS and not finished(done, elapsed):
                    n_next = clamp(next_size(n, dt, elapsed), done)
                    backend.launch(done, n_next, seed, max_bounces, rr_depth)
                    ahead = (time.perf_counter(), n_next)
                film.add(pass_sum, stats, n)
            else:
                pass_sum, stats = render_pass(film.spp, n, seed, max_bounces, rr_depth)
                film.add(pass_sum, stats, n)
                dt = time.perf_counter() - t_pass
            elapsed = time.perf_counter() - start
            result.passes.append((elapsed, film.spp))
            if adaptive and film.spp >= ADAPTIVE_MIN_SPP:
                err = error_estimate(film)
                going = err > stop_threshold(film, adaptive, err)
                active = (going if active is None else going & (active != 0)).astype(np.uint8)
            t_callback = time.perf_counter()
            if on_pass is not None and on_pass(film, elapsed) is False:
                result.stopped = True
                break
            callback_s = time.perf_counter() - t_callback
            if ahead is None:
                n = next_size(n, dt, elapsed)
    except KeyboardInterrupt as e:
        result.interrupted = True
        result.signal = e.signum if isinstance(e, Interrupted) else int(signal.SIGINT)
    result.seconds = time.perf_counter() - start
    return result
