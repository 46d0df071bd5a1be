"""Denoising with Intel Open Image Denoise (OIDN) through its maintained Python binding,
``pyoidn`` (PyPI), on the CPU.

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

import numpy as np

from .errors import InputError
from .kernels.layout import AOV_ALBEDO, AOV_NORMAL

AOV_SPP = 16    # camera rays per pixel of the auxiliary images


def check_available():
    """Raise InputError, before any rendering, when pyoidn cannot be imported."""
    try:
        importlib.import_module("pyoidn")
    except Exception as e:      # ImportError, or a library that fails to load
        raise InputError(f"--denoise needs Open Image Denoise's Python binding "
                         f"(pip install pyoidn): {type(e).__name__}: {e}") from None


def denoise(color, aovs):
    """The denoised image (float32 HxWx3) of ``color`` (linear HDR) with the auxiliary
    images ``aovs``: {"albedo", "normal"}, or one H x W x AOV_WIDTH array (layout AOV_*)."""
    import pyoidn
    if isinstance(aovs, dict):
        albedo, normal = aovs["albedo"], aovs["normal"]
    else:
        albedo = aovs[..., AOV_ALBEDO:AOV_ALBEDO + 3]
        normal = aovs[..., AOV_NORMAL:AOV_NORMAL + 3]
    albedo = np.ascontiguousarray(np.clip(albedo, 0.0, 1.0), np.float32)
    normal = np.ascontiguousarray(np.clip(normal, -1.0, 1.0), np.float32)
    color = np.ascontiguousarray(np.maximum(color, 0.0), np.float32)
    return pyoidn.denoise(color, albedo, normal, hdr=True)
