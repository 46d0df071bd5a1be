"""Image files: 8-bit sRGB PNG, float RGB Radiance .hdr and OpenEXR, written atomically.

Codecs come from libraries: imageio (PNG), imagecodecs (Radiance RGBE), OpenEXR (EXR).
"""
import os
import tempfile

import numpy as np

FLOAT_FORMATS = (".hdr", ".exr", ".npy")
ALL_FORMATS = (".png",) + FLOAT_FORMATS


def linear_to_srgb(x):
    """The exact piecewise sRGB transfer function (IEC 61966-2-1), x clamped to [0, 1]."""
    x = np.clip(np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def encode(image, ext):
    """Bytes of ``image`` (float HxWx3, linear RGB) in the format of extension ``ext``."""
    ext = ext.lower()
    if ext == ".png":
        import imageio.v3 as iio
        rgb8 = np.round(linear_to_srgb(image) * 255.0).astype(np.uint8)
        return iio.imwrite("<bytes>", rgb8, extension=".png")
    if ext == ".hdr":
        import imagecodecs
        return imagecodecs.rgbe_encode(np.ascontiguousarray(image, np.float32))
    if ext == ".exr":
        import OpenEXR
        with tempfile.NamedTemporaryFile(suffix=".exr") as f:
            channels = {"RGB": np.ascontiguousarray(image, np.float32)}
            OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                         channels).write(f.name)
            return open(f.name, "rb").read()
    if ext == ".npy":
        import io
        buf = io.BytesIO()
        np.save(buf, np.asarray(image, np.float32))
        return buf.getvalue()
    raise ValueError(f"unsupported image format {ext!r} (use one of {', '.join(ALL_FORMATS)})")


def write_image(path, image):
    """Write atomically: a reader sees the old file or the new one, never half of one."""
    data = encode(image, os.path.splitext(path)[1])
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=os.path.splitext(path)[1])
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        # mkstemp makes the file private (0600); give it the permissions of a normal file.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def read_image(path):
    """Float linear RGB (HxWx3, float32) from .npy, .hdr, .exr or an sRGB .png."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".npy":
        img = np.load(path)
    elif ext == ".hdr":
        import imagecodecs
        with open(path, "rb") as f:
            img = imagecodecs.rgbe_decode(f.read())
    elif ext == ".exr":
        import OpenEXR
        with OpenEXR.File(path) as f:
            ch = f.channels()
            img = ch["RGB"].pixels if "RGB" in ch else np.stack(
                [ch[c].pixels for c in "RGB"], axis=-1)
    elif ext == ".png":
        import imageio.v3 as iio
        x = iio.imread(path)[..., :3].astype(np.float64) / 255.0
        img = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    else:
        raise ValueError(f"unsupported image format {ext!r}")
    img = np.asarray(img, np.float32)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"expected an RGB image, got shape {img.shape}")
    return img[..., :3]
