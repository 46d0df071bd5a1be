"""The triangles of a mesh file as the readers return them (scene.meshes, scene.gltf)."""
from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class ObjMesh:
    positions: np.ndarray          # float32 (F, 3, 3)
    normals: Optional[np.ndarray]  # float32 (F, 3, 3) from `vn`, or None
    uvs: Optional[np.ndarray]      # float32 (F, 3, 2) from `vt`, or None
    face_material: np.ndarray      # int32 (F,): index into materials, -1 = no material
    materials: list                # dicts: name, Kd, Ke, Ks, Ns, Ni, Pr, Pm, map_Kd, map_Bump
    from_cache: bool = False
    # "mtl": materials are .mtl dicts (above); "scene": materials in the JSON scene format
    # (glTF files), read as a scene file's
    material_format: str = "mtl"
    # float32 (F, 3, 3) linear RGB vertex colours that multiply the base colour (glTF's
    # COLOR_0), or None
    colors: Optional[np.ndarray] = None
