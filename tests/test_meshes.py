"""OBJ loading (tinyobjloader for the geometry, pywavefront for the .mtl) and the
content-keyed mesh cache."""
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


def test_tinyobjloader_numpy_accessors_match_its_lists(tmp_path):
    """The stride fix-up of tinyobjloader's numpy accessors (meshes._numpy) reads what its
    list accessors give, on a file with normals, texture coordinates and two materials."""
    import tinyobjloader
    from pathtracer.scene.meshes import _numpy
    obj = tmp_path / "t.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0.5\nvt 0 0\nvt 1 0\nvt 1 1\n"
                   "vn 0 0 1\nvn 0 1 0\nusemtl a\nf 1/1/1 2/2/1 3/3/2\nusemtl b\n"
                   "f 1/1/2 3/3/1 4/2/2\n")
    r = tinyobjloader.ObjReader()
    assert r.ParseFromFile(str(obj), tinyobjloader.ObjReaderConfig())
    a = r.GetAttrib()
    assert np.array_equal(_numpy(a.numpy_vertices()), a.vertices)
    assert np.array_equal(_numpy(a.numpy_normals()), a.normals)
    assert np.array_equal(_numpy(a.numpy_texcoords()), a.texcoords)
    m = r.GetShapes()[0].mesh
    corners = _numpy(m.numpy_indices()).reshape(-1, 3)
    assert np.array_equal(corners[:, 0], m.vertex_indices())
    assert np.array_equal(corners[:, 1], m.normal_indices())
    assert np.array_equal(corners[:, 2], m.texcoord_indices())
    assert np.array_equal(_numpy(m.numpy_material_ids()), m.material_ids)


def test_faces_mixing_index_forms(tmp_path):
    """v, v/vt, v//vn and v/vt/vn faces in one material: per-corner texture coordinates
    where given ((0, 0) elsewhere); normals only if every corner has one."""
    obj = tmp_path / "m.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0.25 0.5\nvt 1 0\nvt 1 1\n"
                   "vn 0 0 1\nf 1/1 2/2 3/3\nf 1 3 4\nf 1//1 2//1 3//1\n")
    m = load_obj(str(obj), use_cache=False)
    assert m.positions.shape == (3, 3, 3) and m.normals is None
    assert np.allclose(m.uvs[0], [[0.25, 0.5], [1, 0], [1, 1]]) and not m.uvs[1:].any()


def test_malformed_vertex_lines_are_refused(tmp_path):
    """tinyobjloader reads 'nan', 'inf', words and missing numbers as 0: refused by name
    and line instead (indented lines too)."""
    import pytest
    from pathtracer.scene import SceneError
    for body, line, words in (("v 0 0 0\nv 1 nan 0\n", 2, "other than numbers"),
                              ("v 0 0 0\nvn 0 0 -inf\n", 2, "other than numbers"),
                              ("# x\nv 0 0 0\n\n  v 1 zz 0\n", 4, "other than numbers"),
                              ("v 0 0 0\nv 1 0\n", 2, "too few"),
                              ("v 0 0 0\nvt\n", 2, "too few")):
        obj = tmp_path / "bad.obj"
        obj.write_text(body + "v 1 1 1\nf 1 2 3\n")
        with pytest.raises(SceneError, match=f"line {line}: .*{words}"):
            load_obj(str(obj), use_cache=False)
    # numbers in every legal spelling are accepted
    obj.write_text("v -1.5e+2 +0.25 .5\nv 1E-3 2. 0\r\nv 0 1 0 1.0\nf 1 2 3\n")
    assert np.allclose(load_obj(str(obj), use_cache=False).positions[0, 0], [-150, 0.25, 0.5])
