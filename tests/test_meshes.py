"""OBJ loading through pywavefront and the content-keyed mesh cache."""
import os

import numpy as np

from pathtracer.kernels import layout as L

from pathtracer.scene import load_scene
from pathtracer.scene.meshes import load_obj
from tests.conftest import needs_shared, ROOT, SHARED
from tests.helpers import write_scene


def test_cache_hit_and_invalidation(tmp_path, monkeypatch):
    monkeypatch.setenv("PT_RENDER_CACHE", str(tmp_path / "cache"))
    obj = tmp_path / "t.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    a = load_obj(str(obj))
    b = load_obj(str(obj))
    assert not a.from_cache and b.from_cache
    assert np.array_equal(a.positions, b.positions)
    obj.write_text("v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n")   # edited: re-read, not reused
    c = load_obj(str(obj))
    assert not c.from_cache and c.positions[0, 1, 0] == 2


def test_mtl_materials_map_to_diffuse_and_emission(tmp_path, monkeypatch):
    monkeypatch.setenv("PT_RENDER_CACHE", str(tmp_path / "cache"))
    scene = load_scene(os.path.join(ROOT, "scenes", "cornell-box.json"))
    mat = scene.arrays.mat
    emissive = mat[:, L.M_EMISSION:L.M_EMISSION + 3].max(1) > 0
    assert emissive.sum() == 1
    assert np.allclose(mat[emissive][0, :6], [0.885809, 0.698859, 0.666422, 18.387, 13.9873,
                                              6.75357])
    # the light quad's 2 triangles are the only lights, each picked with probability 1/2
    assert np.allclose(scene.arrays.light_cdf, [0, 0.5, 1])


def test_faces_without_material_are_grey(tmp_path):
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = {"camera": {"resolution": [4, 4], "position": [0, 0, 3]},
             "objects": [{"name": "t", "file": "t.obj"}]}
    s = load_scene(write_scene(tmp_path, scene))
    assert np.allclose(s.arrays.mat[s.arrays.tri_mat[0], L.M_ALBEDO:L.M_ALBEDO + 3], 0.5)


@needs_shared
def test_file_normals_and_smooth(tmp_path):
    scene = {"camera": {"resolution": [4, 4], "position": [0, 0, 3]},
             "materials": [{"name": "m", "type": "diffuse"}],
             "objects": [{"name": "s", "file": os.path.join(SHARED, "assets", "models",
                                                            "suzanne.obj"),
                          "material": "m", "smooth": True}]}
    s = load_scene(write_scene(tmp_path, scene))
    n = s.arrays.tri_n[:s.n_triangles].reshape(-1, 3, 3)
    assert np.allclose(np.linalg.norm(n, axis=2), 1, atol=1e-5)
    assert s.n_triangles == 968
