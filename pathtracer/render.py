"""Progressive rendering: passes of growing size accumulated into a float64 film."""
import signal
import time
from dataclasses import dataclass, field

from . import limits
from .errors import Interrupted
from .film import Film


@dataclass
class RenderResult:
    film: Film
    seconds: float           # rendering time, compile excluded
    compile_seconds: float
    interrupted: bool = False
    signal: int = 0          # the signal that stopped the render (SIGINT for Ctrl-C)
    passes: list = field(default_factory=list)   # (elapsed s, spp) after each pass


def render(scene, backend, spp=None, time_limit=None, seed=None, max_bounces=None,
           rr_depth=None, pass_seconds=0.5, on_pass=None):
    """Render ``scene`` with ``backend`` until ``spp`` samples per pixel or ``time_limit``
    seconds, whichever comes first (spp defaults to the scene's unless a time is given).

    Pass sizes start at 1 spp and double while a pass is shorter than ``pass_seconds``, so
    the image refreshes quickly at first and overhead stays small later. ``on_pass(film,
    elapsed)`` is called after every pass. Ctrl-C (or any :class:`~.errors.Interrupted`)
    stops the render and returns the samples of the passes completed (``interrupted`` and
    ``signal`` are set). A render never exceeds ``limits.MAX_SPP`` samples per pixel (the
    random streams are indexed by 32-bit sample numbers).
    """
    seed = scene.seed if seed is None else seed
    max_bounces = scene.max_bounces if max_bounces is None else max_bounces
    rr_depth = scene.rr_depth if rr_depth is None else rr_depth
    if spp is None and time_limit is None:
        spp = scene.spp
    film = Film(scene.height, scene.width)
    t0 = time.perf_counter()
    backend.compile()
    compile_seconds = time.perf_counter() - t0
    result = RenderResult(film, 0.0, compile_seconds)
    n = 1
    start = time.perf_counter()
    try:
        while True:
            elapsed = time.perf_counter() - start
            if (spp is not None and film.spp >= spp) or film.spp >= limits.MAX_SPP:
                break
            if time_limit is not None and elapsed >= time_limit:
                break
            n = min(n, limits.MAX_PASS_SAMPLES, limits.MAX_SPP - film.spp)
            if spp is not None:
                n = min(n, spp - film.spp)
            t_pass = time.perf_counter()
            pass_sum, stats = backend.render_pass(film.spp, n, seed, max_bounces, rr_depth)
            film.add(pass_sum, stats, n)
            dt = time.perf_counter() - t_pass
            elapsed = time.perf_counter() - start
            result.passes.append((elapsed, film.spp))
            if on_pass is not None:
                on_pass(film, elapsed)
            # Grow the pass while it is short; aim the last pass at the time limit.
            if dt < pass_seconds:
                n *= 2
            elif dt > 2 * pass_seconds and n > 1:
                n //= 2
            if time_limit is not None and dt > 0:
                left = time_limit - elapsed
                if left > 0:   # (float: a huge time limit must not overflow an int)
                    n = max(1, int(min(float(n), left / (dt / n))))
    except KeyboardInterrupt as e:
        result.interrupted = True
        result.signal = e.signum if isinstance(e, Interrupted) else int(signal.SIGINT)
    result.seconds = time.perf_counter() - start
    return result
