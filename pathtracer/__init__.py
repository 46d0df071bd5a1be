"""pt-render: a physically based path tracer; one Numba kernel source for CPU and CUDA."""
from .scene import SceneError, load_scene
from .render import render

__version__ = "0.1.0"
__all__ = ["SceneError", "load_scene", "render", "__version__"]
