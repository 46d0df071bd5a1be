"""pt-render: a physically based path tracer; one Numba kernel source for CPU and CUDA.

The Python API (docs/python-api.md)::

    import pathtracer as pt
    scene = pt.load_scene("scenes/cornell.json")     # or a dict in the same format
    result = pt.render(scene, spp=64)                # .image, .spp, .seconds, .save()
    scene.set("/materials/light/emission", [34, 24, 8])
    result = pt.render(scene, spp=64)                # nothing recompiled
"""
from . import _cache

_cache.configure()   # before any cached function is decorated (see _cache)

from .scene import SceneError  # noqa: E402
from .api import Progress, Result, Scene, load_scene, render  # noqa: E402

__version__ = "0.1.0"
__all__ = ["SceneError", "Scene", "load_scene", "render", "Result", "Progress",
           "__version__"]
