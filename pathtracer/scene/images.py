"""Reading texture and environment images (imageio; Radiance .hdr through imagecodecs)."""
import os

import numpy as np

from .errors import SceneError


def srgb_to_linear(c):
    """The exact piecewise sRGB decoding (IEC 61966-2-1), not a 2.2 power."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def read_image(path, where=None, scene_file=None):
    """float64 (H, W, C) pixels and whether they are already linear floats (HDR)."""
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".hdr":
            import imagecodecs
            with open(path, "rb") as f:
                data = f.read()
            img = np.asarray(imagecodecs.rgbe_decode(data), np.float64)
            is_float = True
        else:
            import imageio.v3 as iio
            raw = iio.imread(path)
            is_float = raw.dtype.kind == "f"
            if raw.dtype.kind in "ui":
                img = raw.astype(np.float64) / np.iinfo(raw.dtype).max
            elif raw.dtype == bool:
                img = raw.astype(np.float64)
            else:
                img = raw.astype(np.float64)
    except SceneError:
        raise
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
