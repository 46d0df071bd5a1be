"""Camera rays.

``cam`` (float32, CAM_SIZE; the camera section of :mod:`.layout`) holds the eye point, the
unit forward vector, right and up scaled by tan(fov / 2) and, for the thin lens, the lens
radius in those units and the focus distance.
"""
from .constants import ONE, TWO
from .device import device
from .layout import (CAM_FOCUS, CAM_FORWARD, CAM_LENS_X, CAM_LENS_Y, CAM_ORIGIN, CAM_RIGHT,
                     CAM_UP)
from .vec import normalize
from .warps import square_to_disk_concentric


@device
def pinhole_ray(cam, px, py, u, v, width, height):
    """Ray through image position (px + u, py + v); pixel row 0 is the top of the image."""
    sx = TWO * (px + u) / width - ONE
    sy = ONE - TWO * (py + v) / height
    d = normalize((cam[CAM_FORWARD] + sx * cam[CAM_RIGHT] + sy * cam[CAM_UP],
                   cam[CAM_FORWARD + 1] + sx * cam[CAM_RIGHT + 1] + sy * cam[CAM_UP + 1],
                   cam[CAM_FORWARD + 2] + sx * cam[CAM_RIGHT + 2] + sy * cam[CAM_UP + 2]))
    return (cam[CAM_ORIGIN], cam[CAM_ORIGIN + 1], cam[CAM_ORIGIN + 2]), d


@device
def thin_lens_ray(cam, px, py, u, v, lu, lv, width, height):
    """Thin-lens ray (Pharr et al., PBRT 3rd ed., sec. 6.2.3): from a uniform point of the
    lens disk through the point where the pinhole ray meets the plane in focus, a plane
    perpendicular to the view direction at the focus distance."""
    sx = TWO * (px + u) / width - ONE
    sy = ONE - TWO * (py + v) / height
    # Unnormalised pinhole direction: forward component 1, so origin + dir * focus lies on
    # the plane in focus.
    dx = cam[CAM_FORWARD] + sx * cam[CAM_RIGHT] + sy * cam[CAM_UP]
    dy = cam[CAM_FORWARD + 1] + sx * cam[CAM_RIGHT + 1] + sy * cam[CAM_UP + 1]
    dz = cam[CAM_FORWARD + 2] + sx * cam[CAM_RIGHT + 2] + sy * cam[CAM_UP + 2]
    f = cam[CAM_FOCUS]
    lx, ly = square_to_disk_concentric(lu, lv)
    lx *= cam[CAM_LENS_X]
    ly *= cam[CAM_LENS_Y]
    ox = cam[CAM_ORIGIN] + lx * cam[CAM_RIGHT] + ly * cam[CAM_UP]
    oy = cam[CAM_ORIGIN + 1] + lx * cam[CAM_RIGHT + 1] + ly * cam[CAM_UP + 1]
    oz = cam[CAM_ORIGIN + 2] + lx * cam[CAM_RIGHT + 2] + ly * cam[CAM_UP + 2]
    d = normalize((cam[CAM_ORIGIN] + dx * f - ox, cam[CAM_ORIGIN + 1] + dy * f - oy,
                   cam[CAM_ORIGIN + 2] + dz * f - oz))
    return (ox, oy, oz), d
