"""PLY meshes (objects[].file *.ply), read with plyfile: files written by other writers
(trimesh, binary and ASCII; plyfile with polygons) give the same triangles, normals and
texture coordinates as the OBJ of the same mesh, and render the same; bad files are named
errors."""
import math

import numpy as np
import pytest

from pathtracer.scene import load_scene
from pathtracer.scene.errors import SceneError
from pathtracer.scene.geometry import uv_sphere
from pathtracer.scene.meshes import load_mesh
from tests.helpers import run, write_scene
from tests.test_normal_map import write_sphere_obj

N_THETA, N_PHI = 8, 16


def write_sphere_ply(path, encoding):
    """The UV sphere of write_sphere_obj, written by trimesh (another writer than our
    reader): float32 positions and normals, float64 s, t."""
    trimesh = pytest.importorskip("trimesh")
    v, f, uv = uv_sphere(N_THETA, N_PHI, seam=True)
    mesh = trimesh.Trimesh(vertices=v, faces=f, vertex_normals=v,
                           visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    with open(path, "wb") as fh:
        fh.write(mesh.export(file_type="ply", encoding=encoding))


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_ply_from_trimesh_equals_the_obj(tmp_path, encoding):
    write_sphere_obj(str(tmp_path / "s.obj"), N_THETA, N_PHI)
    write_sphere_ply(str(tmp_path / "s.ply"), encoding)
    obj = load_mesh(str(tmp_path / "s.obj"), use_cache=False)
    ply = load_mesh(str(tmp_path / "s.ply"))
    assert ply.positions.shape == obj.positions.shape
    assert np.allclose(ply.positions, obj.positions, atol=1e-6)
    assert np.allclose(ply.normals, obj.normals, atol=1e-6)
    assert np.allclose(ply.uvs, obj.uvs, atol=1e-6)
    # and it renders the same (a textured, smooth, lit sphere)
    images = []
    for name in ("s.obj", "s.ply"):
        scene = {"camera": {"resolution": [24, 24], "position": [0, 0, 3.5],
                            "lookAt": [0, 0, 0], "fov": 40},
                 "render": {"spp": 16, "maxBounces": 2},
                 "materials": [{"name": "m", "albedo": {"texture": "c.png", "filter": "nearest",
                                                        "tile": [4, 2]}}],
                 "objects": [{"name": "ball", "file": name, "material": "m", "smooth": True}],
                 "environment": {"color": [0.9, 0.8, 0.7]}}
        images.append(run(load_scene(write_scene(tmp_path, scene, name + ".json"),
                                     use_cache=False), "cpu").film.image())
    assert np.allclose(images[0], images[1], atol=1e-3), np.abs(images[0] - images[1]).max()


@pytest.fixture(autouse=True)
def _checker(tmp_path):
    import imageio.v3 as iio
    img = np.zeros((4, 4, 3), np.uint8)
    img[::2, ::2] = img[1::2, 1::2] = 230
    img[..., 1] //= 2
    iio.imwrite(tmp_path / "c.png", img)


@pytest.mark.parametrize("text", [True, False], ids=["ascii", "binary"])
def test_ply_polygons_are_fanned_and_other_uv_names_read(tmp_path, text):
    """A quad and a pentagon written by plyfile, uvs named u, v, no normals (binary: the
    fast fixed-triangle read refuses the file and the general one reads it)."""
    from plyfile import PlyData, PlyElement
    angles = np.linspace(0, 2 * math.pi, 6)[:-1]
    verts = [(0, 0, 0, 0.0, 0.0), (1, 0, 0, 1.0, 0.0), (1, 1, 0, 1.0, 1.0), (0, 1, 0, 0.0, 1.0)]
    verts += [(3 + math.cos(a), math.sin(a), 0, 0.5, 0.5) for a in angles]
    vertex = np.array(verts, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("u", "f4"),
                                    ("v", "f4")])
    face = np.array([(np.array([0, 1, 2, 3]),), (np.arange(4, 9),)],
                    dtype=[("vertex_indices", object)])
    PlyData([PlyElement.describe(vertex, "vertex"), PlyElement.describe(face, "face")],
            text=text).write(str(tmp_path / "p.ply"))
    mesh = load_mesh(str(tmp_path / "p.ply"))
    assert mesh.positions.shape == (2 + 3, 3, 3)
    assert mesh.normals is None and mesh.uvs is not None
    area = 0.5 * np.linalg.norm(np.cross(mesh.positions[:, 1] - mesh.positions[:, 0],
                                         mesh.positions[:, 2] - mesh.positions[:, 0]), axis=1)
    pentagon = 5 / 2 * math.sin(2 * math.pi / 5)
    assert area[:2].sum() == pytest.approx(1.0) and area[2:].sum() == pytest.approx(pentagon,
                                                                                   rel=1e-5)
    assert np.allclose(mesh.uvs[0], [[0, 0], [1, 0], [1, 1]])
    assert (mesh.face_material == -1).all()


@pytest.mark.parametrize("content,message", [
    (b"not a ply file\n", "invalid PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
     b"0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "out of range"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n0 0 0\n", "'face'"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
     b"0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "fewer than 3"),
])
def test_bad_ply_files_are_named_errors(tmp_path, content, message):
    (tmp_path / "bad.ply").write_bytes(content)
    with pytest.raises(SceneError, match=message):
        load_mesh(str(tmp_path / "bad.ply"))
    scene = {"camera": {"resolution": [4, 3]}, "materials": [{"name": "m"}],
             "objects": [{"name": "b", "file": "bad.ply", "material": "m"}]}
    with pytest.raises(SceneError, match=message):
        load_scene(write_scene(tmp_path, scene))
