"""Camera rays.

``cam`` (float32, 16) holds: origin (0:3), unit forward (3:6), right scaled by
tan(fov_x / 2) (6:9), up scaled by tan(fov_y / 2) (9:12); for the thin lens, the lens radius
divided by tan(fov_x / 2) and by tan(fov_y / 2) (12, 13) and the focus distance (14).
"""
from .constants import ONE, TWO
from .device import device
from .vec import normalize
from .warps import square_to_disk_concentric


@device
def pinhole_ray(cam, px, py, u, v, width, height):
    """Ray through image position (px + u, py + v); pixel row 0 is the top of the image."""
    sx = TWO * (px + u) / width - ONE
    sy = ONE - TWO * (py + v) / height
    d = normalize((cam[3] + sx * cam[6] + sy * cam[9],
                   cam[4] + sx * cam[7] + sy * cam[10],
                   cam[5] + sx * cam[8] + sy * cam[11]))
    return (cam[0], cam[1], cam[2]), d


@device
def thin_lens_ray(cam, px, py, u, v, lu, lv, width, height):
    """Thin-lens ray (Pharr et al., PBRT 3rd ed., sec. 6.2.3): from a uniform point of the
    lens disk through the point where the pinhole ray meets the plane in focus, a plane
    perpendicular to the view direction at the focus distance."""
    sx = TWO * (px + u) / width - ONE
    sy = ONE - TWO * (py + v) / height
    # Unnormalised pinhole direction: forward component 1, so origin + dir * focus lies on
    # the plane in focus.
    dx = cam[3] + sx * cam[6] + sy * cam[9]
    dy = cam[4] + sx * cam[7] + sy * cam[10]
    dz = cam[5] + sx * cam[8] + sy * cam[11]
    f = cam[14]
    lx, ly = square_to_disk_concentric(lu, lv)
    lx *= cam[12]
    ly *= cam[13]
    ox = cam[0] + lx * cam[6] + ly * cam[9]
    oy = cam[1] + lx * cam[7] + ly * cam[10]
    oz = cam[2] + lx * cam[8] + ly * cam[11]
    d = normalize((cam[0] + dx * f - ox, cam[1] + dy * f - oy, cam[2] + dz * f - oz))
    return (ox, oy, oz), d
