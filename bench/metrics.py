"""The benchmark's own metrics, kept small so that tests can pin them down."""
import math

from pathtracer.film import relmse  # noqa: F401  (the one relMSE definition)


def time_to_threshold(times, errors, threshold):
    """Time at which a run's error first reaches ``threshold``, interpolated linearly in
    log(time)-log(error) between the two measurements that bracket it (error ~ c / time is
    a straight line there). None when no measurement reaches it; never extrapolated.

    ``times`` increase; ``errors`` are the errors measured at those times."""
    pts = [(t, e) for t, e in zip(times, errors) if t > 0 and e > 0]
    for i, (t, e) in enumerate(pts):
        if e <= threshold:
            if i == 0:
                return t
            t0, e0 = pts[i - 1]
            if e0 <= threshold:      # not monotone: the earlier one already crossed
                return t0
            a = (math.log(threshold) - math.log(e0)) / (math.log(e) - math.log(e0))
            return math.exp(math.log(t0) + a * (math.log(t) - math.log(t0)))
    return None


def rays_per_second(camera_paths, bounce_rays, shadow_rays, seconds):
    """Rays traced per second: each camera path is one camera ray, plus the bounce and shadow
    rays the kernels counted."""
    if seconds <= 0:
        raise ValueError("seconds must be > 0")
    return (camera_paths + bounce_rays + shadow_rays) / seconds
