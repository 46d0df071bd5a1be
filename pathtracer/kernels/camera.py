"""Camera rays.

``cam`` (float32, 16) holds: origin (0:3), unit forward (3:6), right scaled by
tan(fov_x / 2) (6:9), up scaled by tan(fov_y / 2) (9:12); 12:16 are reserved for the thin lens.
"""
from .constants import ONE, TWO
from .device import device
from .vec import normalize


@device
def pinhole_ray(cam, px, py, u, v, width, height):
    """Ray through image position (px + u, py + v); pixel row 0 is the top of the image."""
    sx = TWO * (px + u) / width - ONE
    sy = ONE - TWO * (py + v) / height
    d = normalize((cam[3] + sx * cam[6] + sy * cam[9],
                   cam[4] + sx * cam[7] + sy * cam[10],
                   cam[5] + sx * cam[8] + sy * cam[11]))
    return (cam[0], cam[1], cam[2]), d
