"""Texture and environment images: read (through the film's one reader), checked, made RGB."""
import numpy as np

from ..film import read_raw, srgb_to_linear
from ..memory import TEXEL_BYTES, require
from .errors import SceneError

__all__ = ["read_image", "load_texture", "srgb_to_linear"]


def _decode(path, where, scene_file):
    """Raw pixels (H, W, C) as decoded, whether they are floats; any failure is a
    SceneError naming the file and the scene key."""
    try:
        img, is_float = read_raw(path)
    except MemoryError:
        raise SceneError(f"image {path}: not enough memory to decode it", scene_file or path,
                         where) from None
    except Exception as e:   # each codec reports a damaged file with its own type
        raise SceneError(f"cannot read image {path}: {' '.join(str(e).split()) or type(e).__name__}",
                         scene_file or path, where) from None
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or img.shape[0] == 0 or img.shape[1] == 0 or img.shape[2] == 0:
        raise SceneError(f"image {path} has an unexpected shape {img.shape}",
                         scene_file or path, where)
    return img, is_float


def _rgb(img):
    if img.shape[2] == 1:
        return np.repeat(img, 3, axis=2)
    if img.shape[2] == 2:            # grey + alpha
        return np.repeat(img[:, :, :1], 3, axis=2)
    return img[:, :, :3]


def _check_values(img, path, where, scene_file, allow_negative):
    if img.dtype.kind == "f" and not np.isfinite(img).all():
        raise SceneError(f"image {path} contains NaN or infinite values", scene_file or path,
                         where)
    if not allow_negative and img.dtype.kind == "f" and (img < 0).any():
        raise SceneError(f"image {path} contains negative values (as light or reflectance "
                         f"they must be >= 0; the smallest is {float(img.min()):g})",
                         scene_file or path, where)


def read_image(path, where=None, scene_file=None):
    """float64 (H, W, 3) pixels (integer formats scaled to [0, 1], not decoded) and whether
    they are already linear floats (HDR); values must be finite and >= 0."""
    img, is_float = _decode(path, where, scene_file)
    img = _rgb(img)
    _check_values(img, path, where, scene_file, allow_negative=False)
    if img.dtype.kind in "ui":
        return img.astype(np.float64) / np.iinfo(img.dtype).max, False
    return img.astype(np.float64), is_float


_LUTS = {}


def _lut(dtype, srgb):
    """The float32 value of every code of an 8- or 16-bit integer type (sRGB-decoded or
    linear): such textures decode by table lookup, with no float64 copy of the image."""
    key = (np.dtype(dtype), srgb)
    if key not in _LUTS:
        top = np.iinfo(dtype).max
        values = np.arange(top + 1) / top
        _LUTS[key] = (srgb_to_linear(values) if srgb else values).astype(np.float32)
    return _LUTS[key]


def load_texture(spec, scene_file=None, allow_negative=False):
    """Linear float32 (H, W, 3) texels of a TextureSpec. Values must be finite and, unless
    ``allow_negative`` (normal maps), >= 0. Decoding keeps to float32 (an 8192^2 8-bit
    texture peaks near 1 GB, not 6.6 GB)."""
    img, is_float = _decode(spec.path, spec.pointer, scene_file)
    h, w = img.shape[:2]
    require(h * w * TEXEL_BYTES, f"texture {spec.path} ({w}x{h})",
            "use a smaller texture", error=lambda m: SceneError(m, scene_file or spec.path,
                                                                spec.pointer))
    channel = getattr(spec, "channel", None)
    if channel is not None:
        n = img.shape[2]
        if n <= 2:                 # grey (+ alpha): r, g and b are the grey
            src = 0 if channel != "a" else (1 if n == 2 else None)
        else:
            src = "rgba".index(channel) if "rgba".index(channel) < n else None
        if src is None:            # no alpha channel: opaque
            top = np.iinfo(img.dtype).max if img.dtype.kind in "ui" else 1.0
            img = np.full(img.shape[:2] + (1,), top, img.dtype)
        else:
            img = img[:, :, src:src + 1]
    img = _rgb(img)
    _check_values(img, spec.path, spec.pointer, scene_file, allow_negative)
    if img.dtype.kind in "ui" and img.dtype.itemsize <= 2:
        return _lut(img.dtype, spec.color_space == "sRGB")[img]
    if img.dtype.kind in "ui":
        img = img.astype(np.float64) / np.iinfo(img.dtype).max
        is_float = False
    if spec.color_space == "sRGB" and not is_float:
        img = srgb_to_linear(img)
    if img.dtype.kind == "f" and np.abs(img).max(initial=0) > np.finfo(np.float32).max:
        raise SceneError(f"image {spec.path} has values beyond the float32 range",
                         scene_file or spec.path, spec.pointer)
    return np.asarray(img, np.float32)


def _halve(img, axis):
    """``img`` (float32) shrunk along ``axis`` from n to max(1, n // 2) texels, each new
    texel the exact mean of the source interval it covers (a box filter of n / (n // 2)
    texels: odd sizes mix up to three source texels with fractional weights)."""
    n = img.shape[axis]
    if n == 1:
        return img
    m = n // 2
    if n == 2 * m:                    # even: plain pairs (strided views, one new array)
        even = [slice(None)] * img.ndim
        odd = [slice(None)] * img.ndim
        even[axis] = slice(0, n, 2)
        odd[axis] = slice(1, n, 2)
        out = np.add(img[tuple(even)], img[tuple(odd)], dtype=np.float32)
        out *= np.float32(0.5)
        return out
    ratio = n / m
    lo = np.arange(m) * ratio          # new texel i covers [lo_i, lo_i + ratio) of the source
    out = None
    first = np.floor(lo).astype(np.int64)
    for k in range(4):                 # ratio < 3: at most 4 source texels overlap
        j = first + k
        w = np.clip(np.minimum(j + 1, lo + ratio) - np.maximum(j, lo), 0.0, None) / ratio
        shape = [1] * img.ndim
        shape[axis] = m
        term = img.take(np.minimum(j, n - 1), axis=axis) * w.astype(np.float32).reshape(shape)
        out = term if out is None else out + term
    return out.astype(np.float32)


def mip_chain(img):
    """The mip levels of ``img`` (H, W, 3) float32, finest first, one at a time, down to
    1 x 1: level k is max(1, H >> k) x max(1, W >> k), each texel the mean of the finer
    texels it covers (area-weighted for odd sizes), so every level has the image's mean.
    Linear values are averaged (the texels are decoded from sRGB first). One level at a
    time: the scene compiler writes each into the texel array before making the next."""
    level = img
    yield level
    while level.shape[0] > 1 or level.shape[1] > 1:
        level = _halve(_halve(level, 0), 1)
        yield level


def mip_pyramid(img):
    """All of mip_chain's levels, as a list."""
    return list(mip_chain(np.ascontiguousarray(img, np.float32)))


def mip_levels(height, width):
    """How many levels mip_pyramid makes for a height x width image (down to 1 x 1)."""
    return max(int(height), int(width)).bit_length()


def mip_texels(height, width, levels):
    """Texels in the first ``levels`` levels of a height x width image's pyramid."""
    return sum(max(1, height >> k) * max(1, width >> k) for k in range(levels))
