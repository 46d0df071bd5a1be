"""The film: accumulation of passes, tone mapping to display values, image files, metrics.

Codecs come from libraries: imageio (PNG, JPG, BMP, TGA, TIFF), imagecodecs (Radiance RGBE
``.hdr``), OpenEXR (``.exr``); NumPy's ``.npy`` keeps float32 exactly. Outputs are written
atomically (a reader sees the old file or the new one, never half of one).
"""
import io
import os
import tempfile
from dataclasses import dataclass

import numpy as np
from numba import njit

from ._cache import jit_cache, read_only
from .kernels.layout import STAT_BOUNCE_RAYS, STAT_NONFINITE, STAT_SHADOW_RAYS

FLOAT_FORMATS = (".hdr", ".exr", ".npy")
ALL_FORMATS = (".png",) + FLOAT_FORMATS


# ---------------------------------------------------------------------------------------
# Accumulation

@dataclass
class Film:
    """Sums of samples (float64), samples per pixel and ray statistics over the passes of a
    render. ``spp`` counts the samples of the passes; with adaptive sampling a finished
    pixel takes no more, and ``count`` holds each pixel's own number. ``sum_b`` and
    ``count_b``: the part of the sums from the second half of each adaptive pass, for the
    per-pixel error estimate (:func:`pathtracer.progressive.error_estimate`)."""
    height: int
    width: int
    sum: np.ndarray = None
    spp: int = 0
    bounce_rays: int = 0
    shadow_rays: int = 0
    nonfinite: int = 0
    count: np.ndarray = None
    sum_b: np.ndarray = None
    count_b: np.ndarray = None

    def __post_init__(self):
        self.sum = np.zeros((self.height, self.width, 3), np.float64)
        self.count = np.zeros((self.height, self.width), np.int64)

    def add(self, pass_sum, stats, n_samples, active=None, half_b=False):
        """Add one pass: float32 pixel sums over n_samples paths and its stats (layout
        STAT_*); ``active``: the pixels that took part (None: all); ``half_b``: the pass is
        the second half of an adaptive pass."""
        # (the loop below indexes without bounds checks: a pass of another size must not
        # reach it)
        if pass_sum.shape != self.sum.shape or (
                active is not None and active.shape != self.count.shape):
            raise ValueError(f"a pass of shape {pass_sum.shape} for a film of "
                             f"{self.sum.shape}")
        if half_b and self.sum_b is None:
            self.sum_b = np.zeros_like(self.sum)
            self.count_b = np.zeros_like(self.count)
        masked = active is not None
        # (the pass read-only, as it comes from a Ray worker: one compiled version, see
        # _cache.read_only)
        _accumulate(self.sum, self.count, read_only(pass_sum), n_samples,
                    read_only(active) if masked else _NO_MASK, masked,
                    self.sum_b if half_b else self.sum, self.count_b if half_b else self.count,
                    half_b)
        self.spp += n_samples
        # One channel at a time: a strided int64 reduction over (N, 3) is ~6x slower, and
        # this runs after every pass (a GPU pass of a small image takes a few ms).
        self.bounce_rays += int(stats[..., STAT_BOUNCE_RAYS].sum(dtype=np.int64))
        self.shadow_rays += int(stats[..., STAT_SHADOW_RAYS].sum(dtype=np.int64))
        self.nonfinite += int(stats[..., STAT_NONFINITE].sum(dtype=np.int64))

    def image(self):
        """The mean of the samples: linear radiance, float32 H x W x 3."""
        return (self.sum / np.maximum(self.count, 1)[..., None]).astype(np.float32)

    @property
    def camera_rays(self):
        return int(self.count.sum())


_NO_MASK = np.ones((1, 1), np.uint8)
_NO_MASK.flags.writeable = False


@njit(cache=jit_cache())
def _accumulate(total, count, pass_sum, n_samples, active, masked, total_b, count_b, to_b):
    """Film.add's sums in one pass over the pixels. NumPy's form (sum += pass_sum, count
    += n * (active != 0), and again for the second half's sums) made temporaries and
    several passes over memory: 0.45 ms a call for a 256 x 192 image on the H100 machine's
    CPU, twice per adaptive pass (2026-11-25)."""
    h, w = count.shape
    for y in range(h):
        for x in range(w):
            n = n_samples
            if masked and active[y, x] == 0:
                n = 0
            count[y, x] += n
            if to_b:
                count_b[y, x] += n
            for c in range(3):
                v = np.float64(pass_sum[y, x, c])
                total[y, x, c] += v
                if to_b:
                    total_b[y, x, c] += v


RELMSE_EPS = 0.01       # the relMSE metric's denominator term (relmse)


def error_estimate(film):
    """Per pixel, the estimated relMSE of its mean: the two halves of every adaptive pass
    are two independent estimates a and b of the pixel (each from half the samples), so
    (a - b)^2 / 4 estimates the variance of their mean; divided by mean^2 + 0.01 as in the
    relMSE metric, averaged over the channels, and then over each pixel's 3 x 3
    neighbourhood (one pixel's estimate, from one difference, is too noisy to stop on:
    Cycles' adaptive sampling filters it likewise; the image's edge pixels repeated)."""
    return _error_estimate(film.sum, film.sum_b, film.count, film.count_b)


@njit(cache=jit_cache())
def _error_estimate(total, total_b, count, count_b):
    """error_estimate's loops. This runs on the host after every adaptive pass, where a
    GPU pass of a small image takes a few ms; its NumPy form (whole-array operations and
    their temporaries) took 2.4 ms a pass for a 256 x 192 image on the H100 machine's CPU,
    a fifth of the sun's adaptive render there (2026-11-25, docs/benchmarks.md)."""
    h, w = count.shape
    q = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            n = count[y, x]
            nb = count_b[y, x]
            inv_b = 1.0 / max(nb, 1)
            inv_a = 1.0 / max(n - nb, 1)
            inv_n = 1.0 / max(n, 1)
            acc = 0.0
            for c in range(3):
                b = total_b[y, x, c]
                d = (total[y, x, c] - b) * inv_a - b * inv_b       # a - b
                m = total[y, x, c] * inv_n
                acc += d * d / (m * m + RELMSE_EPS)
            q[y, x] = acc * (1.0 / 12.0)     # / 4 (the variance of the mean of a and b), / 3
    # the 3 x 3 mean as two passes of three (rows, then columns)
    rows = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            rows[y, x] = q[y, max(x - 1, 0)] + q[y, x] + q[y, min(x + 1, w - 1)]
    out = np.empty((h, w))
    for y in range(h):
        up = max(y - 1, 0)
        down = min(y + 1, h - 1)
        for x in range(w):
            out[y, x] = (rows[up, x] + rows[y, x] + rows[down, x]) * (1.0 / 9.0)
    return out


def compile_accumulation(adaptive=False):
    """Compile (or load from the disk cache) Film.add's loop, and with ``adaptive``
    the error estimate's, so that a render's clock does not count it."""
    film = Film(1, 1)
    stats = np.zeros((1, 1, 3), np.int32)
    film.add(np.zeros((1, 1, 3), np.float32), stats, 1)
    if adaptive:
        film.add(np.zeros((1, 1, 3), np.float32), stats, 1, _NO_MASK, half_b=True)
        error_estimate(film)


# ---------------------------------------------------------------------------------------
# Transfer functions and tone mapping

def srgb_to_linear(c):
    """The exact piecewise sRGB decoding (IEC 61966-2-1), not a 2.2 power."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(x):
    """The exact piecewise sRGB encoding (IEC 61966-2-1), x clamped to [0, 1] (in the
    input's float precision: a float32 image is not copied to float64)."""
    x = np.asarray(x)
    x = np.clip(np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    out = np.atleast_1d(np.power(x, 1 / 2.4))
    out *= 1.055
    out -= 0.055
    low = np.atleast_1d(x <= 0.0031308)
    out[low] = 12.92 * np.atleast_1d(x)[low]
    return out.reshape(x.shape)


def to_display(image, display=None):
    """8-bit sRGB display values of linear radiance; ``display``: (exposure EV, tone
    curve) (see pathtracer.tonemap; default: no exposure, values clamped to [0, 1])."""
    if display is not None and tuple(display) != (0.0, "clamp"):
        from .tonemap import display_linear
        image = display_linear(image, *display)
    return np.round(linear_to_srgb(image) * 255.0).astype(np.uint8)


# ---------------------------------------------------------------------------------------
# Files

def encode(image, ext, display=None):
    """Bytes of ``image`` (float HxWx3, linear RGB) in the format of extension ``ext``;
    ``display`` (exposure, tone curve) applies to 8-bit formats only: float formats keep
    the linear values."""
    ext = ext.lower()
    if ext == ".png":
        import imageio.v3 as iio
        return iio.imwrite("<bytes>", to_display(image, display), extension=".png")
    if ext == ".hdr":
        import imagecodecs
        return imagecodecs.rgbe_encode(np.ascontiguousarray(image, np.float32))
    if ext == ".exr":
        import OpenEXR
        with tempfile.NamedTemporaryFile(suffix=".exr") as f:
            channels = {"RGB": np.ascontiguousarray(image, np.float32)}
            try:
                OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION,
                              "type": OpenEXR.scanlineimage}, channels).write(f.name)
            except RuntimeError as e:   # OpenEXR reports I/O failures (a full disk) so
                raise OSError(f"cannot write an EXR file: {' '.join(str(e).split())}") \
                    from None
            return open(f.name, "rb").read()
    if ext == ".npy":
        buf = io.BytesIO()
        np.save(buf, np.asarray(image, np.float32))
        return buf.getvalue()
    raise ValueError(f"unsupported image format {ext!r} (use one of {', '.join(ALL_FORMATS)})")


def write_image(path, image, display=None):
    """Write atomically: a reader sees the old file or the new one, never half of one."""
    write_images([path], image, display)


def write_images(paths, image, display=None):
    """Write ``image`` (or, a list, image i to path i) to each of ``paths`` (a PNG and its
    float twin; with the denoiser also the raw image and the auxiliary images) as one unit: every
    file is encoded and written to a temporary file beside its target first, and only
    when all are complete are they renamed over the targets, so the files never come
    from different passes and a reader never sees half of one. On failure nothing is
    replaced and no temporary file is left. ``display``: see encode."""
    images = image if isinstance(image, (list, tuple)) else [image] * len(paths)
    data = [encode(im, os.path.splitext(p)[1], display) for im, p in zip(images, paths)]
    temps = []
    try:
        umask = os.umask(0)
        os.umask(umask)
        for path, blob in zip(paths, data):
            folder = os.path.dirname(os.path.abspath(path))
            fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-",
                                       suffix=os.path.splitext(path)[1])
            temps.append(tmp)
            with os.fdopen(fd, "wb") as f:
                f.write(blob)
                f.flush()
                os.fsync(f.fileno())
            # mkstemp makes the file private (0600); give it a normal file's permissions.
            os.chmod(tmp, 0o666 & ~umask)
        for path, tmp in zip(paths, temps):
            os.replace(tmp, path)
    except BaseException:
        for tmp in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)
        raise


def read_raw(path):
    """The pixels of an image file as its codec returns them (H x W [x C], integer or
    float) and whether they are floats. The one image reader, for textures, environment
    maps and reference images."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".npy":
        img = np.load(path, allow_pickle=False)
        if img.dtype.kind not in "uif":
            raise ValueError(f"expected a numeric array, got dtype {img.dtype}")
        return img, img.dtype.kind == "f"
    if ext == ".hdr":
        import imagecodecs
        with open(path, "rb") as f:
            return imagecodecs.rgbe_decode(f.read()), True
    if ext == ".exr":
        import OpenEXR
        with OpenEXR.File(path) as f:
            ch = f.channels()
            # OpenEXR's reader merges R, G, B (and A) into one "RGB" or "RGBA" entry; a file
            # with other layers keeps them apart; a grey one is "Y"
            for merged in ("RGBA", "RGB"):
                if merged in ch:
                    return ch[merged].pixels, True
            names = [c for c in "RGBA" if c in ch]
            if names[:3] == ["R", "G", "B"]:
                return np.stack([ch[c].pixels for c in names], axis=-1), True
            if "Y" in ch:
                return ch["Y"].pixels[..., None], True
            raise ValueError(f"no RGB, RGBA or Y channels (it has {', '.join(sorted(ch))})")
    import imageio.v3 as iio
    raw = iio.imread(path)
    return raw, raw.dtype.kind == "f"


def read_pixels(path):
    """(pixels, is_float) of an image file: float64 H x W x C, scaled to [0, 1] for
    integer formats (not decoded: sRGB stays sRGB), and whether the file holds floats."""
    raw, is_float = read_raw(path)
    if raw.dtype.kind in "ui":
        return raw.astype(np.float64) / np.iinfo(raw.dtype).max, False
    return raw.astype(np.float64), is_float


def read_image(path):
    """Float linear RGB (HxWx3, float32) of an output or reference image: .npy, .hdr,
    .exr, or an 8-bit sRGB .png (decoded)."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in ALL_FORMATS:
        raise ValueError(f"unsupported image format {ext!r}")
    img, is_float = read_pixels(path)
    if not is_float:
        img = srgb_to_linear(img)
    img = np.asarray(img, np.float32)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"expected an RGB image, got shape {img.shape}")
    return img[..., :3]


# ---------------------------------------------------------------------------------------
# Metrics

def relmse(image, reference, eps=0.01):
    """Relative MSE: mean over pixels and channels of (x - ref)^2 / (ref^2 + eps)."""
    x = np.asarray(image, np.float64)
    r = np.asarray(reference, np.float64)
    return float(np.mean((x - r) ** 2 / (r * r + eps)))
