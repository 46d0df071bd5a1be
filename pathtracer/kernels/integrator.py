"""The path tracer's entry points for the backends: each a driver (:mod:`.drivers`) around
the one bounce (:mod:`.path`), specialised per scene.

``make_render_pixel(features, target)`` returns the per-pixel function of the megakernel
driver that :func:`.drivers.choose_driver` picks for ``target``; ``make_deferred_pixel``,
``make_aov_pixel`` and ``make_wavefront`` the other drivers' entries.
"""
import functools

from .drivers import (REGENERATING, Deferred, Wavefront, choose_driver, make_aov,
                      make_deferred, make_megakernel, make_wavefront)
from .layout import Features, SceneArrays

__all__ = ["Deferred", "Features", "SceneArrays", "Wavefront", "make_aov_pixel",
           "make_deferred_pixel", "make_render_pixel", "make_wavefront", "regenerates"]


def regenerates(features, target):
    """Whether the megakernel for ``target`` runs a pixel's paths with path regeneration
    (drivers.choose_driver: the GPU in scenes without an environment)."""
    return choose_driver(target, features, paths=0) == REGENERATING


@functools.lru_cache(maxsize=None)
def make_render_pixel(features, target="cpu", regenerate=None):
    """``render_pixel`` for scenes with ``features`` (``regenerate``: path regeneration
    or not; None: :func:`regenerates`)."""
    if regenerate is None:
        regenerate = regenerates(features, target)
    kernels = make_megakernel(features, target)
    return kernels.regenerating if regenerate else kernels.nested


def make_aov_pixel(features, target="cpu"):
    """``aov_pixel`` (albedo and normal images for the denoiser) for scenes with
    ``features``."""
    return make_aov(features, target)


def make_deferred_pixel(features, target="cpu"):
    """:class:`Deferred` for scenes with ``features`` (an environment map)."""
    return make_deferred(features, target)
