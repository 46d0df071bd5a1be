"""Mitsuba's .serialized meshes: files written here by the documented format (a writer of
a few lines below, versions 3 and 4, several meshes, single and double precision) read back
exactly, read as Mitsuba 3 reads them (where it is installed), and damaged files refused
with one line."""
import importlib.util
import struct
import zlib

import numpy as np
import pytest

import pathtracer as pt
from pathtracer.scene import SceneError
from pathtracer.scene.meshes import load_serialized
from pathtracer.scene.serialized import read_serialized


def write_serialized(path, meshes, version=4, double=False):
    """meshes: [(positions (V, 3), faces (F, 3), normals or None, uvs or None, name)]."""
    real = "<f8" if double else "<f4"
    out, offsets = bytearray(), []
    for p, f, n, uv, name in meshes:
        offsets.append(len(out))
        flags = (0x2000 if double else 0x1000) | (0x1 if n is not None else 0) | (
            0x2 if uv is not None else 0)
        body = struct.pack("<I", flags)
        if version == 4:
            body += name.encode() + b"\0"
        body += struct.pack("<QQ", len(p), len(f)) + np.asarray(p, real).tobytes()
        for extra in (n, uv):
            if extra is not None:
                body += np.asarray(extra, real).tobytes()
        body += np.asarray(f, "<u4").tobytes()
        out += struct.pack("<HH", 0x041C, version) + zlib.compress(body)
    out += np.asarray(offsets, "<u8" if version == 4 else "<u4").tobytes()
    out += struct.pack("<I", len(meshes))
    path.write_bytes(bytes(out))
    return str(path)


def meshes():
    rng = np.random.default_rng(7)
    quad = (np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float),
            np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0.0, 0.0, 1.0], (4, 1)),
            np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float), "quad")
    cloud = rng.normal(size=(30, 3))
    tris = rng.integers(0, 30, size=(20, 3))
    return [quad, (cloud, tris, None, None, "cloud"),
            (cloud * 2, tris[::-1], None, rng.random((30, 2)), "")]


@pytest.mark.parametrize("version, double", [(4, False), (4, True), (3, False)])
def test_written_meshes_read_back(tmp_path, version, double):
    path = write_serialized(tmp_path / "m.serialized", meshes(), version, double)
    for k, (p, f, n, uv, name) in enumerate(meshes()):
        rp, rf, rn, ruv, face_normals, rname = read_serialized(path, k)
        tol = 0 if double else 1e-6
        assert np.allclose(rp, p, atol=tol) and np.array_equal(rf, f)
        assert (rn is None) == (n is None) and (ruv is None) == (uv is None)
        if uv is not None:
            assert np.allclose(ruv, uv, atol=tol)
        assert rname == (name if version == 4 else "") and not face_normals
    # as per-triangle arrays, v turned to the scene format's (1 - v)
    mesh = load_serialized(path, 0)
    assert mesh.positions.shape == (2, 3, 3)
    assert np.allclose(mesh.uvs[0, :, 1], 1 - meshes()[0][3][[0, 1, 2], 1])


def test_damaged_files_are_one_line_errors(tmp_path):
    good = (tmp_path / "g.serialized")
    write_serialized(good, meshes())
    data = good.read_bytes()
    cases = {b"\x00\x00" + data[2:]: "not a Mitsuba .serialized",
             data[:30]: "truncated|damaged", data[:3]: "too short"}
    for i, (blob, message) in enumerate(cases.items()):
        bad = tmp_path / f"b{i}.serialized"
        bad.write_bytes(blob)
        with pytest.raises(SceneError, match=message):
            read_serialized(str(bad))
    with pytest.raises(SceneError, match="holds 3 meshes"):
        read_serialized(str(good), 3)
    # the table's entry of mesh 1 pointing into the table itself (past any header)
    table = len(data) - 4 - 3 * 8
    moved = bytearray(data)
    moved[table + 8:table + 16] = struct.pack("<Q", len(data) - 2)
    bad = tmp_path / "moved.serialized"
    bad.write_bytes(bytes(moved))
    with pytest.raises(SceneError, match="no .serialized header"):
        read_serialized(str(bad), 1)


def test_a_mitsuba_scene_with_serialized_shapes_loads(tmp_path):
    write_serialized(tmp_path / "m.serialized", meshes())
    xml = tmp_path / "s.xml"
    xml.write_text("""<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,6" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
    <rfilter type="box"/></film></sensor>
  <emitter type="constant"/>
  <shape type="serialized"><string name="filename" value="m.serialized"/></shape>
  <shape type="serialized"><string name="filename" value="m.serialized"/>
    <integer name="shape_index" value="2"/><boolean name="face_normals" value="true"/></shape>
</scene>""")
    scene = pt.load_scene(str(xml))
    assert scene.data["objects"][1]["shapeIndex"] == 2
    assert scene.compiled.n_triangles == 2 + 20      # the quad and mesh 2
    img = pt.render(scene, spp=1, backend="cpu").image
    assert img.shape == (16, 16, 3) and np.isfinite(img).all()


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed")
def test_meshes_read_as_mitsuba_reads_them(tmp_path):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    path = write_serialized(tmp_path / "m.serialized", meshes())
    for k in range(3):
        shape = mi.load_dict({"type": "serialized", "filename": path, "shape_index": k})
        params = mi.traverse(shape)
        p, f, _, uv, _, _ = read_serialized(path, k)
        assert np.allclose(np.array(params["vertex_positions"]).reshape(-1, 3), p, atol=1e-6)
        assert np.array_equal(np.array(params["faces"]).reshape(-1, 3), f)
        if uv is not None:
            assert np.allclose(np.array(params["vertex_texcoords"]).reshape(-1, 2), uv,
                               atol=1e-6)
