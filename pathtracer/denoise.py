"""Denoising with Intel Open Image Denoise (OIDN) through its maintained Python binding,
``pyoidn`` (PyPI), on the CPU or, where OIDN's CUDA device runs (an NVIDIA GPU and its
driver: pyoidn's wheel carries the CUDA device library), on the GPU.

Which device (``--denoise-device``, ``render(denoise_device=...)``): ``auto`` denoises on
the GPU when the render itself runs on CUDA and OIDN's CUDA device works here, else on the
CPU; ``cpu`` and ``cuda`` force one (``cuda`` is an error where it cannot run). The two
devices run the same network; their results differ by rounding (tested on the GPU).

The renderer supplies OIDN's auxiliary images (``backend.aovs``, kernel ``aov_pixel``): the
albedo (base colour) and the world-space shading normal at the first surface that is not
specular (metal or glass with roughness below 0.1 is looked through), averaged over
``AOV_SPP`` camera rays per pixel; a ray that leaves the scene gives the environment's
radiance clamped to [0, 1] as albedo and a zero normal, and an emitting surface its base
colour plus its radiance, clamped to [0, 1] (so that a light differs from the same-coloured
surface around it: the Cornell box's denoised relMSE 6.1e-4 -> 5.8e-4, docs/benchmarks.md).
The colour is denoised as HDR (linear radiance, any range). A denoised image is an
estimate, not an unbiased one: the raw image is always written beside it.
"""
import importlib
import warnings

import numpy as np

from .errors import InputError
from .kernels.layout import AOV_ALBEDO, AOV_NORMAL

AOV_SPP = 16    # camera rays per pixel of the auxiliary images


def check_available():
    """Raise InputError, before any rendering, when pyoidn cannot be imported."""
    try:
        importlib.import_module("pyoidn")
    except Exception as e:      # ImportError, or a library that fails to load
        raise InputError(f"--denoise needs Open Image Denoise's Python binding: pip install "
                         f"'pt-render[denoise]' (or pyoidn) ({type(e).__name__}: {e})") from None


DEVICES = ("auto", "cpu", "cuda")


def cuda_denoiser_available():
    """Whether OIDN's CUDA device can run here (pyoidn, its CUDA library, a GPU)."""
    try:
        import pyoidn
        return bool(pyoidn.Device.is_cuda_available(0))
    except Exception:           # no pyoidn, no driver, a library that fails to load
        return False


def resolve_device(device, backend):
    """"cpu" or "cuda": where ``device`` (one of DEVICES) denoises a render on
    ``backend`` (the backend's name, e.g. "cuda", "cpu")."""
    if device not in DEVICES:
        raise InputError(f"--denoise-device: one of {', '.join(DEVICES)}, got {device!r}")
    if device == "cpu":
        return "cpu"
    if device == "cuda":
        if not cuda_denoiser_available():
            raise InputError("--denoise-device cuda: Open Image Denoise's CUDA device does not "
                             "run here (it needs an NVIDIA GPU, its driver and pyoidn's CUDA "
                             "library); use --denoise-device cpu")
        return "cuda"
    return "cuda" if str(backend).startswith("cuda") and cuda_denoiser_available() else "cpu"


class _CudaFilter:
    """OIDN's RT filter on its CUDA device for images of one size, with its four images in
    device buffers. Kept for the next call of the same size: a progressive render
    denoises at every save, and creating and committing a filter (loading the network)
    costs more than running it."""

    def __init__(self, height, width):
        import pyoidn
        self.shape = (height, width)
        self.nbytes = height * width * 3 * 4
        self.device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CUDA)
        self.filter = None
        self.buffers = {}
        try:
            self.device.commit()
            self._check("device")
            self.filter = pyoidn.Filter(self.device, pyoidn.OIDN_FILTER_TYPE_RT)
            self._check("filter")
            for name in ("color", "albedo", "normal", "output"):
                self.buffers[name] = pyoidn.Buffer(self.device, self.nbytes,
                                                   storage=pyoidn.OIDN_STORAGE_DEVICE)
                self._check(f"{name} buffer")
                self.filter.set_image(name, self.buffers[name], pyoidn.OIDN_FORMAT_FLOAT3,
                                      width, height)
            self.filter.set_bool("hdr", True)
            self.filter.set_quality(pyoidn.OIDN_QUALITY_HIGH)
            self.filter.commit()
            self._check("filter commit")
        except BaseException:
            self.release()
            raise

    def _check(self, what):
        message = self.device.get_error()
        if message is not None:
            raise RuntimeError(f"Open Image Denoise (CUDA), {what}: {message}")

    def run(self, color, albedo, normal):
        for name, image in (("color", color), ("albedo", albedo), ("normal", normal)):
            self.buffers[name].write(0, self.nbytes, image)
        self.filter.execute()
        self._check("execution")
        out = np.empty(self.shape + (3,), np.float32)
        self.buffers["output"].read(0, self.nbytes, out)   # (synchronous: after the filter)
        self._check("read-back")
        return out

    def release(self):
        if self.filter is not None:
            self.filter.release()
            self.filter = None
        for b in self.buffers.values():
            b.release()
        self.buffers = {}
        if self.device is not None:
            self.device.release()
            self.device = None


_cuda_filter = [None]
_cuda_failed = []       # the GPU denoiser's error, once it has failed in this process


def _denoise_cuda(color, albedo, normal):
    f = _cuda_filter[0]
    if f is None or f.shape != color.shape[:2]:
        if f is not None:
            f.release()
        _cuda_filter[0] = None
        f = _cuda_filter[0] = _CudaFilter(*color.shape[:2])
    return f.run(color, albedo, normal)


def denoise(color, aovs, device="cpu"):
    """The denoised image (float32 HxWx3) of ``color`` (linear HDR) with the auxiliary
    images ``aovs``: {"albedo", "normal"}, or one H x W x AOV_WIDTH array (layout AOV_*),
    on ``device``, "cpu" or "cuda" (see resolve_device)."""
    import pyoidn
    if isinstance(aovs, dict):
        albedo, normal = aovs["albedo"], aovs["normal"]
    else:
        albedo = aovs[..., AOV_ALBEDO:AOV_ALBEDO + 3]
        normal = aovs[..., AOV_NORMAL:AOV_NORMAL + 3]
    albedo = np.ascontiguousarray(np.clip(albedo, 0.0, 1.0), np.float32)
    normal = np.ascontiguousarray(np.clip(normal, -1.0, 1.0), np.float32)
    color = np.ascontiguousarray(np.maximum(color, 0.0), np.float32)
    if device == "cuda" and not _cuda_failed:
        try:
            return _denoise_cuda(color, albedo, normal)
        except RuntimeError as e:
            # (e.g. no GPU memory left for a large image): a long render's saves go on,
            # denoised on the CPU from here, rather than stop at a save
            _cuda_failed.append(str(e))
            if _cuda_filter[0] is not None:
                _cuda_filter[0].release()
                _cuda_filter[0] = None
            warnings.warn(f"{e}; denoising on the CPU instead")
    return pyoidn.denoise(color, albedo, normal, hdr=True)
