"""pt-render: a physically based path tracer; one Numba kernel source for CPU and CUDA."""
from . import _cache

_cache.configure()   # before any cached function is decorated (see _cache)

from .scene import SceneError, load_scene  # noqa: E402
from .render import render  # noqa: E402

__version__ = "0.1.0"
__all__ = ["SceneError", "load_scene", "render", "__version__"]
