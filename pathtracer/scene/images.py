"""Texture and environment images: read (through the film's one reader), checked, made RGB."""
import numpy as np

from ..film import read_pixels, srgb_to_linear
from .errors import SceneError

__all__ = ["read_image", "load_texture", "srgb_to_linear"]


def read_image(path, where=None, scene_file=None):
    """float64 (H, W, 3) pixels and whether they are already linear floats (HDR); any
    failure is a SceneError naming the file and the scene key."""
    try:
        img, is_float = read_pixels(path)
    except Exception as e:
        raise SceneError(f"cannot read image {path}: {e}", scene_file or path,
                         where) from None
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or img.shape[0] == 0 or img.shape[1] == 0:
        raise SceneError(f"image {path} has an unexpected shape {img.shape}",
                         scene_file or path, where)
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    elif img.shape[2] == 2:            # grey + alpha
        img = np.repeat(img[:, :, :1], 3, axis=2)
    else:
        img = img[:, :, :3]
    if not np.isfinite(img).all():
        raise SceneError(f"image {path} contains NaN or infinite values", scene_file or path,
                         where)
    return img, is_float


def load_texture(spec, scene_file=None):
    """Linear float32 (H, W, 3) texels of a TextureSpec."""
    img, is_float = read_image(spec.path, spec.pointer, scene_file)
    if spec.color_space == "sRGB" and not is_float:
        img = srgb_to_linear(img)
    return img.astype(np.float32)
