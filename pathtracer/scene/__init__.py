"""Host side: JSON scene -> validated description -> flat kernel arrays + feature set."""
from .errors import SceneError
from .loader import load_scene_description
from .compile import CompiledScene, compile_scene, load_scene

__all__ = ["SceneError", "load_scene_description", "CompiledScene", "compile_scene",
           "load_scene"]
