"""glTF 2.0: files written by other writers (trimesh's exporter; pygltflib's serialiser from
known geometry, tests/gltf_writers.py) read back: transforms, materials, textures, cameras,
lights, and the glTF Cornell box against Mitsuba's reference."""
import math
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import pathtracer as pt
from pathtracer.film import relmse
from pathtracer.scene import SceneError
from pathtracer.scene.gltf import LUMENS_PER_WATT, read_model
from tests.conftest import ROOT, needs_shared
from tests.gltf_writers import Builder, look_at_rotation, write_cornell_box

trimesh = pytest.importorskip("trimesh")
Image = pytest.importorskip("PIL.Image")

REFERENCE = os.path.join(os.path.dirname(ROOT), "shared", "reference", "cornell-box",
                         "reference_256_d8.npy")
QUAD_V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
QUAD_F = np.array([[0, 1, 2], [0, 2, 3]])
QUAD_UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)


def png(pixels):
    import io
    buf = io.BytesIO()
    Image.fromarray(np.asarray(pixels, np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


# ---------------------------------------------------------------------------------------
# trimesh's exporter

def test_trimesh_scene_graph_transforms_and_factors(tmp_path):
    """Nested node transforms (a parent frame and its child) give the world positions;
    each primitive keeps its material; PBR factors map to the principled material."""
    box = trimesh.creation.box(extents=[1, 2, 3])
    box.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[255, 128, 0, 255], metallicFactor=0.25, roughnessFactor=0.75))
    ico = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    ico.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[0, 0, 255, 255], metallicFactor=1.0, roughnessFactor=0.1))
    scene = trimesh.Scene()
    parent = trimesh.transformations.translation_matrix([10, 0, 0])
    scene.graph.update(frame_to="parent", frame_from=scene.graph.base_frame, matrix=parent)
    rot = trimesh.transformations.rotation_matrix(math.pi / 2, [0, 0, 1])
    scene.add_geometry(box, node_name="box", parent_node_name="parent", transform=rot)
    scene.add_geometry(ico, node_name="ball",
                       transform=trimesh.transformations.translation_matrix([0, 5, 0]))
    path = scene.export(str(tmp_path / "two.glb")) and str(tmp_path / "two.glb")
    m = read_model(path)
    assert len(m.positions) == len(box.faces) + len(ico.faces)
    by_mat = {}
    for k in np.unique(m.face_material):
        p = m.positions[m.face_material == k].reshape(-1, 3)
        by_mat[m.materials[k]["albedo"][2]] = (p.min(0), p.max(0))
    # the box: 1 x 2 x 3 turned a quarter about z (x extent 2, y extent 1) at x = 10
    lo, hi = by_mat[0.0]
    assert np.allclose(lo, [9, -0.5, -1.5], atol=1e-5) and np.allclose(hi, [11, 0.5, 1.5],
                                                                        atol=1e-5)
    lo, hi = by_mat[1.0]
    assert np.allclose((lo + hi) / 2, [0, 5, 0], atol=1e-5)
    mats = {tuple(np.round(mm["albedo"], 3)): mm for mm in m.materials}
    orange = mats[(1.0, round(128 / 255, 3), 0.0)]
    assert orange["metallic"] == pytest.approx(0.25) and orange["roughness"] == pytest.approx(0.75)
    blue = mats[(0.0, 0.0, 1.0)]
    assert blue["metallic"] == 1.0 and blue["roughness"] == pytest.approx(0.1)
    # the normals are the file's, turned with the node (box faces: axis-aligned)
    assert np.allclose(np.abs(m.normals[m.face_material == 0]).max(-1), 1, atol=1e-5)


def test_trimesh_textures_channels_and_orientation(tmp_path):
    """A textured quad: the base colour texture (sRGB) shows the right way up (the albedo
    image of a render: the image's top-left texel at the top-left), and the packed
    metallic-roughness texture is read channel by channel (G roughness, B metallic) times
    the factors."""
    quadrants = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]],
                         np.uint8)
    colors = np.repeat(np.repeat(quadrants, 8, 0), 8, 1)     # 16 x 16, solid quadrants
    mr = np.zeros((2, 2, 3), np.uint8)
    mr[..., 1] = 128
    mr[..., 2] = 255
    mat = trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(colors), metallicRoughnessTexture=Image.fromarray(mr),
        roughnessFactor=0.5, metallicFactor=0.5)
    quad = trimesh.Trimesh(QUAD_V, QUAD_F, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=QUAD_UV, material=mat))
    path = str(tmp_path / "quad.glb")
    trimesh.Scene(quad).export(path)
    m = read_model(path)
    mm = m.materials[0]
    assert mm["roughness"]["channel"] == "g" and mm["roughness"]["scale"] == 0.5
    assert mm["metallic"]["channel"] == "b" and mm["metallic"]["scale"] == 0.5
    scene = pt.load_scene(path, camera={"position": [0, 0, 3], "lookAt": [0, 0, 0],
                                        "fov": 40})
    scene.set("/camera/resolution", [32, 32])
    c = scene.compiled
    # texture 1 (metallic-roughness), channel by channel, before the factor
    from pathtracer.kernels.layout import TEX_FIRST
    t = c.arrays.tex_int
    texels = c.arrays.tex_data
    rough = texels[t[1, TEX_FIRST]:t[1, TEX_FIRST] + 4, :3]
    metal = texels[t[2, TEX_FIRST]:t[2, TEX_FIRST] + 4, :3]
    assert np.allclose(rough, 128 / 255) and np.allclose(metal, 1.0)
    r = pt.render(scene, spp=4, backend="cpu", aovs=True)
    albedo = r.aovs["albedo"]
    centre = albedo[16, 16]
    assert np.allclose(albedo[12, 12], [1, 0, 0], atol=1e-3)    # top-left: red
    assert np.allclose(albedo[12, 20], [0, 1, 0], atol=1e-3)    # top-right: green
    assert np.allclose(albedo[20, 12], [0, 0, 1], atol=1e-3)    # bottom-left: blue
    assert centre.min() > 0


# ---------------------------------------------------------------------------------------
# pygltflib's serialiser

def quad_file(tmp_path, material=None, name="q.glb", **node):
    b = Builder()
    mi = b.material(material) if material is not None else None
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV * [1, -1] + [0, 1], material=mi), **node)
    return b, b.save(tmp_path / name)


def test_extensions_map_to_the_principled_parameters(tmp_path):
    _, path = quad_file(tmp_path, {
        "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0,
                                 "roughnessFactor": 0.2},
        "emissiveFactor": [1, 0.5, 0.25],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4},
                       "KHR_materials_transmission": {"transmissionFactor": 0.9},
                       "KHR_materials_ior": {"ior": 1.33},
                       "KHR_materials_clearcoat": {"clearcoatFactor": 0.5,
                                                   "clearcoatRoughnessFactor": 0.1},
                       "KHR_materials_sheen": {"sheenColorFactor": [0.2, 0.4, 0.3]}}})
    mm = read_model(path).materials[0]
    assert mm["emission"] == [4, 2, 1]
    assert mm["transmission"] == 0.9 and mm["eta"] == 1.33
    assert mm["clearcoat"] == 0.5 and mm["clearcoatGloss"] == pytest.approx((0.1 - 0.01) / 0.099)
    assert mm["sheen"] == pytest.approx(0.4)
    # KHR_materials_specular without an ior: F0 = 0.04 x factor = 0.08 x specular
    _, path = quad_file(tmp_path, {"extensions": {"KHR_materials_specular": {
        "specularFactor": 0.5}}}, name="s.glb")
    assert read_model(path).materials[0]["specular"] == pytest.approx(0.25)
    # metallic 0 + specular 0: glTF's Lambertian lobe alone, our diffuse material
    _, path = quad_file(tmp_path, {"pbrMetallicRoughness": {"metallicFactor": 0},
                                   "extensions": {"KHR_materials_specular": {
                                       "specularFactor": 0}}}, name="d.glb")
    assert read_model(path).materials[0]["type"] == "diffuse"
    # no material: the glTF default (white, metallic 1, roughness 1)
    _, path = quad_file(tmp_path, None, name="n.glb")
    mm = read_model(path).materials[0]
    assert (mm["albedo"], mm["metallic"], mm["roughness"]) == (1.0, 1.0, 1.0)


def test_texture_transform_sampler_and_unsupported_things_warn(tmp_path):
    b = Builder()
    t = b.image(png(np.full((2, 2, 3), 200)), sampler={"magFilter": 9728, "wrapS": 33071})
    mi = b.material({"pbrMetallicRoughness": {"baseColorTexture": {
        "index": t, "extensions": {"KHR_texture_transform": {"offset": [0.25, 0.1],
                                                             "scale": [2, 3]}}}},
        "alphaMode": "BLEND", "normalTexture": {"index": t, "scale": 0.5}})
    b.used.add("KHR_texture_transform")
    b.used.add("KHR_materials_volume")
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV, material=mi))
    m = read_model(b.save(tmp_path / "t.glb"))
    spec = m.materials[0]["albedo"]
    assert spec["filter"] == "nearest" and spec["wrap"] == ["clamp", "repeat"]
    # glTF v' = 3 v + 0.1 with v flipped: ours v' = 3 v + (1 - 3 - 0.1)
    assert spec["tile"] == [2, 3] and spec["offset"] == [0.25, pytest.approx(-2.1)]
    text = " | ".join(m.warnings)
    for words in ("scale 0.5", "KHR_materials_volume"):
        assert words in text, words
    # alphaMode BLEND is read (the base colour texture's alpha channel), not warned
    assert "alphaMode" not in text
    alpha = m.materials[0]["alpha"]
    assert m.materials[0]["alphaMode"] == "blend" and alpha["channel"] == "a"
    assert alpha["colorSpace"] == "linear" and alpha["filter"] == "nearest"
    # the mapping is right: a texel lookup at glTF uv (u, v) reads what glTF reads
    u, v = 0.3, 0.2                                  # glTF coordinates, v down
    gu, gv = 2 * u + 0.25, 3 * v + 0.1               # glTF's transformed coordinates
    ou, ov = u * 2 + 0.25, (1 - v) * 3 + spec["offset"][1]    # ours
    assert ou == pytest.approx(gu) and (1 - ov) % 1 == pytest.approx(gv % 1)


def test_camera_and_point_light(tmp_path):
    b = Builder()
    b.node(mesh=b.mesh(QUAD_V, QUAD_F))
    b.doc["cameras"].append({"type": "perspective", "name": "cam",
                             "perspective": {"yfov": math.radians(30), "aspectRatio": 2.0,
                                             "znear": 0.1}})
    b.node(camera=0, translation=[1, 2, 5], rotation=look_at_rotation([1, 2, 5], [0, 0, 0]))
    li = b.light({"type": "point", "color": [1, 0.5, 0.25], "intensity": 683})
    b.node(translation=[0, 3, 0], extensions={"KHR_lights_punctual": {"light": li}})
    path = b.save(tmp_path / "c.glb")
    scene = pt.load_scene(path)
    cam = scene.data["camera"]
    assert cam["resolution"] == [640, 320]
    assert np.allclose(cam["position"], [1, 2, 5])
    fwd = np.subtract(cam["lookAt"], cam["position"])
    assert np.allclose(fwd / np.linalg.norm(fwd), -np.array([1, 2, 5]) / math.sqrt(30))
    # vertical 30 degrees on a 2:1 image
    assert math.tan(math.radians(cam["fov"]) / 2) == pytest.approx(2 * math.tan(math.radians(15)))
    light, = scene.data["lights"]
    assert np.allclose(light["position"], [0, 3, 0])
    assert np.allclose(light["intensity"], np.array([1, 0.5, 0.25]) * 683 / LUMENS_PER_WATT)
    # the lighting rule: the default environment besides the file's lights, unless the
    # caller says --env none (the file's lights alone)
    assert scene.data["environment"] == {"color": [1.0, 1.0, 1.0]}
    assert any("besides its punctual lights" in w for w in scene.warnings)
    assert "environment" not in pt.load_scene(path, environment="none").data
    # choosing: by name, by index, or framing
    assert pt.load_scene(path, camera="cam").data["camera"] == cam
    auto = pt.load_scene(path, camera="auto").data["camera"]
    assert auto["lookAt"] == [0.0, 0.0, 0.0] and auto["position"][2] > 1
    with pytest.raises(SceneError, match="no such camera"):
        pt.load_scene(path, camera="7")


def test_directional_light_is_a_far_point_light_with_the_suns_irradiance(tmp_path):
    """A glTF directional light (along the node's -Z, illuminance in lux) is the scene
    format's directional light (irradiance lux / 683 W m^-2), which the compiler renders as
    a point light SUN_DISTANCE radii of the geometry's sphere away against its direction,
    giving that irradiance at the sphere's centre; a warning says so. Beside a point lamp
    it does not take every light sample: the light pdf counts the power that reaches the
    geometry."""
    from pathtracer.kernels import layout as L
    from pathtracer.scene.compile import SUN_DISTANCE, reaching_fraction
    b = Builder()
    b.node(mesh=b.mesh(QUAD_V * 2 + [1, 0, 0], QUAD_F))   # centre (1, 0, 0), radius 2 sqrt 2
    sun = b.light({"type": "directional", "color": [1, 0.9, 0.8], "intensity": 683 * 3})
    direction = np.array([1.0, -2.0, 0.5]) / math.sqrt(5.25)
    b.node(translation=[5, 5, 5], rotation=look_at_rotation([0, 0, 0], direction),
           extensions={"KHR_lights_punctual": {"light": sun}})
    lamp = b.light({"type": "point", "intensity": 683 * 10})
    b.node(translation=[1, 0, 1], extensions={"KHR_lights_punctual": {"light": lamp}})
    path = b.save(tmp_path / "sun.glb")
    scene = pt.load_scene(path)
    assert any("directional light 0" in w for w in scene.warnings)
    directional, = [li for li in scene.data["lights"] if li["type"] == "directional"]
    assert np.allclose(directional["direction"], direction, atol=1e-9)
    assert np.allclose(directional["irradiance"], np.array([1, 0.9, 0.8]) * 3)
    arrays, shift = scene.compiled.arrays, np.asarray(scene.compiled.origin_shift)
    rows = arrays.point_lights.astype(np.float64)
    positions = rows[:, L.PL_POSITION:L.PL_POSITION + 3] + shift
    far = int(np.argmax(np.linalg.norm(positions - [1, 0, 0], axis=1)))
    centre, radius = np.array([1.0, 0.0, 0.0]), 2 * math.sqrt(2)
    offset = positions[far] - centre
    distance = np.linalg.norm(offset)
    assert distance == pytest.approx(SUN_DISTANCE * radius, rel=1e-6)
    assert np.allclose(-offset / distance, direction, atol=1e-6)
    irradiance = rows[far, L.PL_INTENSITY:L.PL_INTENSITY + 3] / distance ** 2
    assert np.allclose(irradiance, np.array([1, 0.9, 0.8]) * 3, rtol=1e-5)
    # the light distribution: the sun's share is the power reaching the geometry's sphere
    pmf = np.diff(arrays.light_cdf.astype(np.float64))
    sun_power = 4 * math.pi * 2.7 * distance ** 2 * reaching_fraction(positions[far],
                                                                     (centre, radius))
    lamp_power = 4 * math.pi * 10
    assert sorted(pmf) == pytest.approx(sorted([sun_power, lamp_power]) / np.float64(
        sun_power + lamp_power), rel=1e-3)
    assert min(pmf) > 0.1                  # the lamp still gets its share of light samples


def test_reaching_fraction_is_the_solid_angle_of_the_geometrys_sphere():
    from pathtracer.scene.compile import reaching_fraction
    sphere = (np.zeros(3), 1.0)
    assert reaching_fraction([0.5, 0, 0], sphere) == 1.0           # inside
    for d in (1.5, 10.0, 1e4):
        cos_a = math.sqrt(1 - 1 / d ** 2)
        assert reaching_fraction([0, d, 0], sphere) == pytest.approx((1 - cos_a) / 2,
                                                                    rel=1e-9)
    # far away: the disc's area over the sphere of radius d, pi / (4 pi d^2)
    assert reaching_fraction([0, 0, 1e6], sphere) == pytest.approx(0.25e-12, rel=1e-6)
    assert reaching_fraction([3, 0, 0], None) == 1.0


def test_spot_light(tmp_path):
    """A glTF spot light (along its node's -Z, cone angles in radians, glTF's defaults 0 and
    pi/4) is the scene format's spot light; its cone is the kernels' (layout PL_CONE_*:
    glTF's falloff); an unknown light type or bad angles are clear errors."""
    from pathtracer.kernels import layout as L
    b = Builder()
    b.node(mesh=b.mesh(QUAD_V, QUAD_F))
    li = b.light({"type": "spot", "intensity": 683 * 2, "spot": {"innerConeAngle": 0.2,
                                                                  "outerConeAngle": 0.5}})
    b.node(translation=[0, 0, 3], rotation=look_at_rotation([0, 0, 3], [0, 0, 0]),
           extensions={"KHR_lights_punctual": {"light": li}})
    b.node(translation=[0, 0, 4], extensions={"KHR_lights_punctual": {
        "light": b.light({"type": "spot", "spot": {}})}})
    scene = pt.load_scene(b.save(tmp_path / "spot.glb"))
    spot, default = scene.data["lights"]
    assert spot["type"] == "spot" and np.allclose(spot["direction"], [0, 0, -1])
    assert spot["innerAngle"] == pytest.approx(math.degrees(0.2))
    assert spot["outerAngle"] == pytest.approx(math.degrees(0.5))
    assert np.allclose(spot["intensity"], 2.0)
    assert default["innerAngle"] == 0 and default["outerAngle"] == pytest.approx(45)
    assert np.allclose(default["direction"], [0, 0, -1])       # a node without rotation
    row = scene.compiled.arrays.point_lights[0].astype(np.float64)
    scale = 1 / (math.cos(0.2) - math.cos(0.5))
    assert row[L.PL_CONE_SCALE] == pytest.approx(scale, rel=1e-6)
    assert row[L.PL_CONE_OFFSET] == pytest.approx(-math.cos(0.5) * scale, rel=1e-6)
    for k, (bad, words) in enumerate((
            ({"type": "area"}, "point, spot or directional"),
            ({"type": "spot", "spot": {"innerConeAngle": 0.5, "outerConeAngle": 0.5}},
             "cone angles"))):
        b = Builder()
        b.node(mesh=b.mesh(QUAD_V, QUAD_F))
        b.node(extensions={"KHR_lights_punctual": {"light": b.light(bad)}})
        with pytest.raises(SceneError, match=words):
            read_model(b.save(tmp_path / f"bad{k}.glb"))


def test_required_extension_is_a_clear_error(tmp_path):
    b = Builder()
    b.node(mesh=b.mesh(QUAD_V, QUAD_F))
    b.doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    with pytest.raises(SceneError, match="KHR_draco_mesh_compression"):
        read_model(b.save(tmp_path / "draco.glb"))


def test_strips_fans_mirrors_sparse_and_normalised_accessors(tmp_path):
    b = Builder()
    strip = b.mesh(QUAD_V[[0, 1, 3, 2]], mode=5)               # two triangles, one strip
    fan = b.mesh(QUAD_V, mode=6)
    b.node(mesh=strip)
    b.node(mesh=fan, scale=[-1, 1, 1], translation=[5, 0, 0])   # a mirror
    # normalised unsigned-short texture coordinates (KHR_mesh_quantization)
    q = b.accessor(np.array([[0, 0], [65535, 0], [65535, 65535], [0, 65535]], np.uint16),
                   5123, normalized=True)
    mesh = b.mesh(QUAD_V, QUAD_F)
    b.doc["meshes"][mesh]["primitives"][0]["attributes"]["TEXCOORD_0"] = q
    b.node(mesh=mesh, translation=[0, 5, 0])
    m = read_model(b.save(tmp_path / "modes.glb"))
    assert len(m.positions) == 6
    n = np.cross(m.positions[:, 1] - m.positions[:, 0], m.positions[:, 2] - m.positions[:, 0])
    assert (n[:, 2] > 0).all()       # every triangle faces +z, the mirrored ones too
    assert np.allclose(m.uvs[4:].reshape(-1, 2).max(0), 1) and m.uvs[4:].min() == 0
    # a sparse accessor: zeros with two positions replaced
    b = Builder()
    base = b.accessor(np.zeros((3, 3), np.float32))
    b.doc["accessors"][base].pop("bufferView")
    b.doc["accessors"][base]["sparse"] = {
        "count": 2, "indices": {"bufferView": b.view(np.array([1, 2], np.uint32).tobytes()),
                                "componentType": 5125},
        "values": {"bufferView": b.view(np.array([[1, 0, 0], [0, 1, 0]], np.float32).tobytes())}}
    b.doc["meshes"].append({"primitives": [{"attributes": {"POSITION": base}}]})
    b.node(mesh=0)
    m = read_model(b.save(tmp_path / "sparse.glb"))
    assert np.allclose(m.positions[0], [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_broken_files_are_one_line_errors(tmp_path):
    b = Builder()
    b.node(mesh=b.mesh(QUAD_V, QUAD_F))
    b.doc["accessors"][0]["count"] = 1000                 # past the end of its view
    with pytest.raises(SceneError, match="past the end"):
        read_model(b.save(tmp_path / "long.glb"))
    b = Builder()
    b.node(mesh=b.mesh(QUAD_V, [[0, 1, 9]]))
    with pytest.raises(SceneError, match="out of range"):
        read_model(b.save(tmp_path / "index.glb"))
    b = Builder()
    b.node(children=[1])
    b.node(root=False, children=[0])
    with pytest.raises(SceneError, match="twice"):
        read_model(b.save(tmp_path / "cycle.glb"))
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    with pytest.raises(SceneError, match="bad.glb"):
        read_model(str(bad))
    whole = open(write_cornell_box(tmp_path / "whole.glb"), "rb").read()
    for cut in (12, 20, 100, len(whole) // 2, len(whole) - 7):   # truncated files
        bad.write_bytes(whole[:cut])
        with pytest.raises(SceneError):
            pt.load_scene(str(bad)).compiled
    text = tmp_path / "bad.gltf"
    text.write_text('{"asset": {"version": "1.0"}}')
    with pytest.raises(SceneError, match="only glTF 2.0"):
        read_model(str(text))


def test_gltf_with_external_buffer_and_image(tmp_path):
    """A .gltf with its .bin and a .png beside it (uris, one with a space, URL-encoded)."""
    b = Builder()
    t = b.image(png(np.full((2, 2, 3), 255)))
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV, material=b.material(
        {"pbrMetallicRoughness": {"baseColorTexture": {"index": t}}})))
    b.save(tmp_path / "x.glb")
    from pygltflib import GLTF2
    g = GLTF2().load(str(tmp_path / "x.glb"))
    (tmp_path / "my data.bin").write_bytes(g.binary_blob())
    (tmp_path / "white.png").write_bytes(png(np.full((2, 2, 3), 255)))
    g.buffers[0].uri = "my%20data.bin"
    g.images[0].bufferView = None
    g.images[0].uri = "white.png"
    g.save_json(str(tmp_path / "x.gltf"))
    m = read_model(str(tmp_path / "x.gltf"))
    assert len(m.positions) == 2
    assert m.materials[0]["albedo"]["texture"] == str(tmp_path / "white.png")


# ---------------------------------------------------------------------------------------
# whole scenes

@needs_shared
def test_gltf_cornell_box_renders_as_the_reference(tmp_path):
    """A Cornell box written by pygltflib from the quads of scenes/cornell-box renders as
    the JSON box does, and both match Mitsuba's image; the committed scenes/cornell-box.glb
    is that file."""
    path = write_cornell_box(tmp_path / "cbox.glb")
    with open(path, "rb") as f, open(os.path.join(ROOT, "scenes", "cornell-box.glb"), "rb") as g:
        assert f.read() == g.read()
    ref = np.load(REFERENCE)
    # its lamp alone, as in the reference: --env none (else the default sky adds to it)
    scene = pt.load_scene(path, environment="none")
    assert not scene.warnings
    scene.set("/camera/resolution", list(ref.shape[1::-1]))
    scene.set("/render", {"maxBounces": 7})
    got = pt.render(scene, spp=64, backend="cpu", sampler="sobol")
    json_box = pt.render(os.path.join(ROOT, "scenes", "cornell-box.json"), spp=64,
                         backend="cpu", sampler="sobol")
    err, err_json = relmse(got.image, ref), relmse(json_box.image, ref)
    assert err < 1.2 * err_json + 1e-4, (err, err_json)
    assert np.allclose(got.image.mean((0, 1)), ref.mean((0, 1)), rtol=0.005)


def test_gltf_object_in_a_json_scene(tmp_path):
    """"file": "model.glb" in a JSON scene: its meshes and materials, under the object's
    own transform; "material" replaces the file's materials; smooth by default."""
    _, path = quad_file(tmp_path, {"pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1]}},
                        translation=[0, 0, -1])
    scene = {"camera": {"resolution": [16, 16], "position": [0, 0, 4], "lookAt": [0, 0, 0]},
             "materials": [{"name": "grey", "type": "diffuse", "albedo": 0.3}],
             "objects": [{"name": "q", "file": "q.glb", "transform": {"translate": [0, 0, 2]}}],
             "environment": {"color": 1}}
    s = pt.load_scene(scene, base=str(tmp_path))
    c = s.compiled
    # tri_v rows: the first vertex, then two edges; the quad lies at z = -1 + 2
    from pathtracer.kernels import layout as L
    z = c.arrays.tri_v[:, L.TRI_V0 + 2] + c.origin_shift[2]
    assert np.allclose(z, 1.0, atol=1e-5)
    assert np.allclose(c.arrays.tri_v[:, [L.TRI_E1 + 2, L.TRI_E2 + 2]], 0, atol=1e-6)
    assert c.features.smooth          # the file's normals (glTF objects: smooth)
    red = pt.render(s, spp=4, backend="cpu", aovs=True).aovs["albedo"][8, 8]
    assert np.allclose(red, [1, 0, 0], atol=1e-3)
    s.set("/objects/q/material", "grey")
    grey = pt.render(s, spp=4, backend="cpu", aovs=True).aovs["albedo"][8, 8]
    assert np.allclose(grey, 0.3, atol=1e-3)


def test_cli_renders_a_glb_with_camera_and_env_flags(tmp_path):
    """pt-render model.glb: a framing camera and a default environment (with a warning),
    --camera X,Y,Z:X,Y,Z and --env replace them."""
    _, path = quad_file(tmp_path, {"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1],
                                                            "metallicFactor": 0}})
    out = tmp_path / "q.npy"
    run = subprocess.run([sys.executable, "-m", "pathtracer", path, "-o", str(out), "--spp",
                          "2", "--resolution", "24x16", "--backend", "cpu", "--quiet"],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert "uniform white environment" in run.stderr
    img = np.load(out)
    assert img.shape == (16, 24, 3) and img[8, 12].mean() > 0.1
    hdr = os.path.join(ROOT, "scenes", "assets", "studio_small_03_256.hdr")
    run = subprocess.run([sys.executable, "-m", "pathtracer", path, "-o", str(out), "--spp",
                          "2", "--resolution", "24x16", "--backend", "cpu", "--quiet",
                          "--camera", "0,0,-4:0,0,0", "--env", hdr],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert "uniform white" not in run.stderr
    run = subprocess.run([sys.executable, "-m", "pathtracer", path, "--camera", "3",
                          "--backend", "cpu", "--quiet", "-o", str(out)],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 2 and "no such camera" in run.stderr
    assert run.stderr.count("\n") == 1
    box = os.path.join(ROOT, "scenes", "cornell-box.json")
    for flags, words in ((["--camera", "front"], "is for glTF files"),
                         (["--env", str(tmp_path / "none.hdr")], "environment map not found")):
        run = subprocess.run([sys.executable, "-m", "pathtracer", box, *flags, "--quiet",
                              "-o", str(out)], capture_output=True, text=True, cwd=ROOT)
        assert run.returncode == 2 and words in run.stderr and run.stderr.count("\n") == 1


def _paths(doc, prefix=()):
    """Every (path, value) of a JSON document, containers included."""
    yield prefix, doc
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, prefix + (i,))


def test_fuzz_mutated_gltf_files_fail_only_with_scene_errors(tmp_path_factory):
    """One value of a textured glTF file's JSON replaced (a number, string, list, object,
    null, or an index out of range): the reader renders it or raises a one-line SceneError,
    never another exception."""
    import copy
    import json
    from hypothesis import HealthCheck, given, settings, strategies as st
    folder = tmp_path_factory.mktemp("fuzz")
    b = Builder()
    t = b.image(png(np.full((4, 4, 3), 100)), sampler={"magFilter": 9728})
    mi = b.material({"pbrMetallicRoughness": {"baseColorTexture": {"index": t},
                                              "metallicRoughnessTexture": {"index": t}},
                     "normalTexture": {"index": t},
                     "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 0.5}}})
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, normals=np.tile([0, 0, 1], (4, 1)), uvs=QUAD_UV,
                       material=mi), translation=[0, 0, 1], children=[1])
    b.doc["cameras"].append({"type": "perspective", "perspective": {"yfov": 0.8}})
    b.node(root=False, camera=0, rotation=[0, 0, 0, 1])
    li = b.light({"type": "point", "intensity": 5})
    b.node(extensions={"KHR_lights_punctual": {"light": li}})
    blob = bytes(b.blob)
    doc = json.loads(json.dumps({k: v for k, v in b.doc.items() if v != []}))
    doc["extensionsUsed"] = sorted(b.used)
    doc["buffers"] = [{"byteLength": len(blob)}]
    paths = [p for p, _ in _paths(doc) if p]
    values = st.one_of(st.integers(-3, 70000), st.floats(allow_nan=True, allow_infinity=True),
                       st.text(max_size=4), st.none(), st.booleans(),
                       st.lists(st.integers(-1, 5), max_size=5), st.just({}))

    @settings(max_examples=int(os.environ.get("GLTF_FUZZ_EXAMPLES", 80)), deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.sampled_from(paths), values)
    def check(path, value):
        from pygltflib import GLTF2
        d = copy.deepcopy(doc)
        target = d
        for k in path[:-1]:
            target = target[k]
        target[path[-1]] = value
        try:
            g = GLTF2.from_dict(d)
            g.set_binary_blob(blob)
            file = folder / "f.glb"
            g.save_binary(str(file))
        except Exception:
            return        # pygltflib's writer refuses it: not a file to read
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                pt.load_scene(str(file)).compiled     # read, translated, validated, compiled
        except SceneError as e:
            assert "\n" not in str(e)
    check()


def test_an_emissive_texture_adds_to_the_default_light(tmp_path):
    """A model whose only emitter is a mostly black emissive texture (DamagedHelmet,
    WaterBottle) is lit by the default environment too: not a black image. A scene with
    no light at all renders black with a DarkImageWarning that says why."""
    from pathtracer.errors import DarkImageWarning
    b = Builder()
    emit = np.zeros((4, 4, 3))
    emit[0, 0] = 255                      # one lit texel of sixteen
    t = b.image(png(emit), sampler={"magFilter": 9728})
    mi = b.material({"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1],
                                              "metallicFactor": 0},
                     "emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": t}})
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV * [1, -1] + [0, 1], material=mi))
    path = b.save(tmp_path / "e.glb")
    scene = pt.load_scene(path)
    assert scene.data["environment"] == {"color": [1.0, 1.0, 1.0]}
    scene.set("/camera/resolution", [16, 12])
    with warnings.catch_warnings():
        warnings.simplefilter("error", DarkImageWarning)
        img = pt.render(scene, spp=4, backend="cpu").image
    assert np.median(img) > 0.3            # the quad under the white sky, not black
    dark = pt.load_scene(path, environment="none")
    dark.set("/camera/resolution", [16, 12])
    dark.set("/camera/position", [0, 0, -50])      # behind the one-sided emitter: black
    with pytest.warns(DarkImageWarning, match="black or nearly"):
        pt.render(dark, spp=2, backend="cpu")
    unlit = pt.load_scene({"camera": {"resolution": [8, 8], "position": [0, 0, 3],
                                      "lookAt": [0, 0, 0]},
                           "objects": [{"name": "q", "vertices": QUAD_V.tolist(),
                                        "faces": QUAD_F.tolist()}]})
    with pytest.warns(DarkImageWarning, match="no light"):
        pt.render(unlit, spp=1, backend="cpu")


def test_vertex_colors_multiply_the_base_color(tmp_path):
    """COLOR_0 (here normalised bytes, VEC4) multiplies the base colour, interpolated over
    each triangle (the albedo image shows it); an object's own material drops it; a file
    without it compiles no vertex-colour code."""
    b = Builder()
    mi = b.material({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1],
                                              "metallicFactor": 0}})
    red, blue = [255, 0, 0, 255], [0, 0, 255, 255]
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, material=mi, colors=[red, blue, blue, red]))
    path = b.save(tmp_path / "vc.glb")
    scene = pt.load_scene(path, camera={"position": [0, 0, 3], "lookAt": [0, 0, 0],
                                        "resolution": [32, 8], "fov": 30})
    assert scene.features.vertex_colors
    albedo = pt.render(scene, spp=4, backend="cpu", aovs=True).aovs["albedo"]
    row = albedo[4]
    hit = row.max(axis=1) < 0.99          # the quad fills the row: no sky (albedo 1)
    assert hit.all()
    left, right = row[hit][0], row[hit][-1]
    assert left[0] > 0.4 and left[2] < 0.1 and right[2] > 0.4 and right[0] < 0.1
    assert np.all(row[hit][:, 1] < 1e-3)                  # green: zero everywhere
    # left to right the red falls as the blue rises, their sum the base colour 0.5
    assert np.allclose(row[hit][:, 0] + row[hit][:, 2], 0.5, atol=0.02)
    assert np.all(np.diff(row[hit][:, 0]) <= 1e-4)
    json_scene = {"camera": {"resolution": [8, 8], "position": [0, 0, 3], "lookAt": [0, 0, 0]},
                  "objects": [{"name": "q", "file": path, "material": "grey"}],
                  "materials": [{"name": "grey", "type": "diffuse"}],
                  "environment": {"color": 1}}
    assert not pt.load_scene(json_scene, base=str(tmp_path)).features.vertex_colors
    _, plain = quad_file(tmp_path, {"pbrMetallicRoughness": {"metallicFactor": 0}})
    assert not pt.load_scene(plain).features.vertex_colors


@needs_shared
def test_vertex_color_test_model_shows_no_crosses():
    """Khronos's VertexColorTest: its top row of checks is multiplied by red, green and blue
    vertex colours to hide the crosses of the other channels and must then look like the
    bottom ("sample pass") row. Compared in the albedo image, row against row: 0.021 here,
    0.068 with vertex colours ignored (measured 2026-12-07 at 200x150)."""
    path = os.path.join(os.path.dirname(ROOT), "shared", "realworld", "gltf_VertexColorTest",
                        "VertexColorTest.gltf")
    scene = pt.load_scene(path)
    scene.set("/camera/resolution", [200, 150])
    a = pt.render(scene, spp=2, backend="cpu", aovs=True).aovs["albedo"]
    red = (a[..., 0] > 0.5) & (a[..., 1] < 0.2) & (a[..., 2] < 0.2)
    ys = np.unique(np.nonzero(red)[0])
    gap = int(np.argmax(np.diff(ys)))
    top, bottom = ys[:gap + 1], ys[gap + 1:]
    assert len(top) > 5 and len(bottom) > 5          # the two rows' red checks
    off = bottom[0] - top[0]
    y0, y1 = top[0] - 2, top[-1] + 3
    board = np.nonzero((a[y0:y1].max(axis=2) > 0.05).any(axis=0))[0]
    x0, x1 = board[0], board[-1] + 1
    diff = np.abs(a[y0:y1, x0:x1] - a[y0 + off:y1 + off, x0:x1]).mean()
    assert diff < 0.035, diff


def test_unlit_material_shows_its_base_colour(tmp_path):
    """KHR_materials_unlit: the camera sees exactly the base colour, whatever the light (it
    is rendered as a surface emitting it, reflecting nothing; a warning says so)."""
    b = Builder()
    b.used.add("KHR_materials_unlit")
    mi = b.material({"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.3, 1]},
                     "extensions": {"KHR_materials_unlit": {}}})
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, material=mi))
    path = b.save(tmp_path / "u.glb")
    scene = pt.load_scene(path, camera={"position": [0, 0, 3], "lookAt": [0, 0, 0],
                                        "resolution": [8, 8], "fov": 20})
    assert any("KHR_materials_unlit" in w for w in scene.warnings)
    img = pt.render(scene, spp=4, backend="cpu").image
    assert np.allclose(img, [0.8, 0.1, 0.3], rtol=1e-5)


def test_specular_glossiness_converts_to_metallic_roughness(tmp_path):
    """KHR_materials_pbrSpecularGlossiness: a dielectric (specular 0.04) keeps its diffuse
    colour as base colour with metallic 0; a metal (dark diffuse, coloured specular)
    becomes metallic with the specular colour as its base; roughness = 1 - glossiness."""
    def material(sg):
        b = Builder()
        b.used.add("KHR_materials_pbrSpecularGlossiness")
        mi = b.material({"extensions": {"KHR_materials_pbrSpecularGlossiness": sg}})
        b.node(mesh=b.mesh(QUAD_V, QUAD_F, material=mi))
        return read_model(b.save(tmp_path / f"sg{len(sg)}{sg.get('glossinessFactor')}.glb")
                          ).materials[0]
    plastic = material({"diffuseFactor": [0.5, 0.2, 0.1, 1], "specularFactor": [0.04] * 3,
                        "glossinessFactor": 0.7})
    assert plastic["metallic"] == 0 and np.allclose(plastic["albedo"], [0.5, 0.2, 0.1])
    assert plastic["roughness"] == pytest.approx(0.3)
    gold = material({"diffuseFactor": [0, 0, 0, 1], "specularFactor": [1.0, 0.78, 0.34],
                     "glossinessFactor": 0.9})
    assert gold["metallic"] > 0.99 and np.allclose(gold["albedo"], [1.0, 0.78, 0.34],
                                                   atol=0.01)
    assert gold["roughness"] == pytest.approx(0.1)


def test_texture_transform_rotation_moves_the_texture_coordinates(tmp_path):
    """KHR_texture_transform with a rotation (TextureTransformTest's rotated arrows): the
    same transform on every texture of a material is applied to the material's texture
    coordinates (translation x rotation x scale, as the extension defines it), so a
    lookup reads where glTF reads; transforms that differ between a material's textures
    keep their offset and scale and name the rotation in a warning."""
    import math
    b = Builder()
    t = b.image(png(np.full((2, 2, 3), 200)))
    xf = {"offset": [0.25, 0.1], "rotation": 0.5, "scale": [2, 3]}
    mi = b.material({"pbrMetallicRoughness": {
        "baseColorTexture": {"index": t, "extensions": {"KHR_texture_transform": xf}},
        "metallicRoughnessTexture": {"index": t, "extensions": {"KHR_texture_transform": xf}}}})
    b.used.add("KHR_texture_transform")
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV, material=mi))
    m = read_model(b.save(tmp_path / "r.glb"))
    assert not any("rotation" in w for w in m.warnings), m.warnings
    assert "tile" not in m.materials[0]["albedo"] and "offset" not in m.materials[0]["albedo"]
    c, s = math.cos(0.5), math.sin(0.5)
    for face, tri in zip(QUAD_F, m.uvs):
        for k, vertex in enumerate(face):
            u, v = QUAD_UV[vertex]                  # glTF coordinates
            gu = c * 2 * u + s * 3 * v + 0.25       # the extension's matrix
            gv = -s * 2 * u + c * 3 * v + 0.1
            assert tri[k] == pytest.approx([gu, 1 - gv]), (u, v)      # ours: v flipped
    # different transforms on one material: offset and scale kept, the rotation warned
    b = Builder()
    t = b.image(png(np.full((2, 2, 3), 200)))
    mi = b.material({"pbrMetallicRoughness": {
        "baseColorTexture": {"index": t, "extensions": {"KHR_texture_transform": xf}},
        "metallicRoughnessTexture": {"index": t}}})
    b.used.add("KHR_texture_transform")
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV, material=mi))
    m = read_model(b.save(tmp_path / "d.glb"))
    assert any("rotations that differ" in w for w in m.warnings)
    assert m.materials[0]["albedo"]["tile"] == [2, 3]


def test_clearcoat_and_specular_factor_textures_are_read(tmp_path):
    """KHR_materials_clearcoat's clearcoatTexture (red channel) and KHR_materials_specular's
    specularTexture (alpha channel) multiply their factors: the principled parameters'
    textures (linear), the factor as the texture's scale; the textures the principled BSDF
    cannot express are named in warnings."""
    b = Builder()
    t = b.image(png(np.full((2, 2, 3), 200)))
    mi = b.material({"pbrMetallicRoughness": {"metallicFactor": 0},
                     "extensions": {
                         "KHR_materials_clearcoat": {"clearcoatFactor": 0.5,
                                                     "clearcoatTexture": {"index": t},
                                                     "clearcoatRoughnessTexture": {"index": t}},
                         "KHR_materials_specular": {"specularFactor": 0.5,
                                                    "specularTexture": {"index": t},
                                                    "specularColorTexture": {"index": t}}}})
    b.used.update({"KHR_materials_clearcoat", "KHR_materials_specular"})
    b.node(mesh=b.mesh(QUAD_V, QUAD_F, uvs=QUAD_UV, material=mi))
    m = read_model(b.save(tmp_path / "c.glb"))
    mm = m.materials[0]
    assert mm["clearcoat"]["channel"] == "r" and mm["clearcoat"]["scale"] == 0.5
    assert mm["specular"]["channel"] == "a" and mm["specular"]["scale"] == pytest.approx(0.25)
    assert mm["clearcoat"]["colorSpace"] == "linear" == mm["specular"]["colorSpace"]
    text = " | ".join(m.warnings)
    assert "clearcoatRoughnessTexture" in text and "specularColorTexture" in text
    assert "clearcoatTexture is" not in text and "specularTexture is" not in text
    # and it loads and renders as a scene (the textures compiled into the principled slots)
    scene = pt.load_scene(str(tmp_path / "c.glb"))
    from pathtracer.kernels.layout import T_CLEARCOAT, T_SPECULAR
    tex = scene.compiled.arrays.mat_tex
    assert (tex[:, T_CLEARCOAT] >= 0).any() and (tex[:, T_SPECULAR] >= 0).any()
