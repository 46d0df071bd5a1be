"""Mitsuba 3 XML scenes: the Cornell box written for Mitsuba renders as the reference, and
the translation of each element of the supported subset (and the errors outside it)."""
import importlib.util
import math
import os

import numpy as np
import pytest

import pathtracer as pt
from pathtracer.film import relmse
from pathtracer.scene.mitsuba_xml import conductor_table, convert_file
from tests.conftest import ROOT, needs_shared

XML_CORNELL = os.path.join(ROOT, "scenes", "cornell-box-mitsuba.xml")
REFERENCE = os.path.join(os.path.dirname(ROOT), "shared", "reference", "cornell-box",
                         "reference_256_d8.npy")


@needs_shared
def test_xml_cornell_box_renders_as_the_reference():
    """The XML box (rectangles and cubes with to_world transforms, an area emitter) renders
    what the JSON box (the OBJ of the same quads) renders, and both match Mitsuba's image."""
    ref = np.load(REFERENCE)
    xml = pt.render(XML_CORNELL, spp=64, backend="cpu", sampler="sobol")
    assert xml.image.shape == ref.shape
    json_box = pt.render(os.path.join(ROOT, "scenes", "cornell-box.json"), spp=64,
                         backend="cpu", sampler="sobol")
    err_xml, err_json = relmse(xml.image, ref), relmse(json_box.image, ref)
    assert err_xml < 1.2 * err_json + 1e-4, (err_xml, err_json)
    means, ref_means = xml.image.mean(axis=(0, 1)), ref.mean(axis=(0, 1))
    assert np.allclose(means, ref_means, rtol=0.005), (means, ref_means)


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed")
def test_xml_cornell_box_is_loadable_by_mitsuba():
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    scene = mi.load_file(XML_CORNELL, spp=2, res=16)
    img = np.array(mi.render(scene))
    assert img.shape == (16, 16, 3) and img.mean() > 0.05


def write(tmp_path, body, name="scene.xml"):
    path = tmp_path / name
    path.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    return str(path)


SENSOR = """<sensor type="perspective"><float name="fov" value="45"/>
  <transform name="to_world"><lookat origin="0,1,5" target="0,1,0" up="0,1,0"/></transform>
  <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/>
  <rfilter type="box"/></film></sensor>"""


def test_sensor_fov_axes_and_thin_lens(tmp_path):
    for axis, expect in (("x", 45.0), ("y", math.degrees(2 * math.atan(2 * math.tan(
            math.radians(22.5))))), ("smaller", None), ("larger", 45.0)):
        body = SENSOR.replace('<float name="fov" value="45"/>',
                              f'<float name="fov" value="45"/><string name="fov_axis" '
                              f'value="{axis}"/>')
        d, _ = convert_file(write(tmp_path, body))
        if expect is None:        # smaller = y for a 64x32 film
            expect = math.degrees(2 * math.atan(2 * math.tan(math.radians(22.5))))
        assert d["camera"]["fov"] == pytest.approx(expect)
        assert d["camera"]["position"] == [0, 1, 5] and d["camera"]["resolution"] == [64, 32]
    body = SENSOR.replace('type="perspective"', 'type="thinlens"').replace(
        '<float name="fov" value="45"/>', '<float name="fov" value="45"/><float '
        'name="aperture_radius" value="0.01"/><float name="focus_distance" value="4"/>')
    d, _ = convert_file(write(tmp_path, body))
    focal = 0.036 / (2 * math.tan(math.radians(22.5)))
    # the scene format's lens radius = focalLength / (2 aperture) = Mitsuba's radius
    assert focal / (2 * d["camera"]["aperture"]) == pytest.approx(0.01)
    assert d["camera"]["focusDistance"] == 4


def test_defaults_refs_materials_and_emitters(tmp_path):
    body = SENSOR + """
<default name="rough" value="0.3"/>
<integrator type="path"><integer name="max_depth" value="5"/><integer name="rr_depth" value="3"/></integrator>
<bsdf type="principled" id="gold"><rgb name="base_color" value="1 0.8 0.3"/>
  <float name="metallic" value="1"/><float name="roughness" value="$rough"/>
  <float name="spec_trans" value="0"/></bsdf>
<bsdf type="twosided" id="paper"><bsdf type="diffuse"><spectrum name="reflectance" value="0.7"/></bsdf></bsdf>
<shape type="cube" id="box"><ref id="gold"/></shape>
<shape type="rectangle" id="card"><ref name="bsdf" id="paper"/>
  <transform name="to_world"><scale value="2"/><translate y="-1"/></transform></shape>
<shape type="sphere" id="ball"><float name="radius" value="0.5"/><point name="center" x="1" y="0" z="0"/>
  <bsdf type="dielectric"><string name="int_ior" value="bk7"/></bsdf></shape>
<shape type="rectangle" id="mirror"><bsdf type="roughconductor"><string name="material" value="none"/>
  <float name="alpha" value="0.04"/></bsdf></shape>
<emitter type="point"><point name="position" value="0, 3, 0"/><rgb name="intensity" value="5"/></emitter>
<emitter type="envmap"><string name="filename" value="sky.hdr"/><float name="scale" value="2"/>
  <transform name="to_world"><rotate y="1" angle="200"/></transform></emitter>
"""
    d, warnings = convert_file(write(tmp_path, body))
    mats = {m["name"]: m for m in d["materials"]}
    # a Mitsuba BSDF outside twosided is black from behind (oneSided); inside, not
    assert mats["gold"] == {"name": "gold", "type": "principled", "albedo": [1, 0.8, 0.3],
                            "metallic": 1.0, "roughness": 0.3, "transmission": 0.0,
                            "oneSided": True}
    assert mats["paper"] == {"name": "paper", "type": "diffuse", "albedo": [0.7] * 3}
    glass = mats[d["objects"][2]["material"]]
    assert glass["transmission"] == 1 and glass["eta"] == pytest.approx(1.5046 / 1.000277)
    mirror = mats[d["objects"][3]["material"]]
    assert mirror["type"] == "conductor" and mirror["alphaU"] == pytest.approx(0.04)
    assert mirror["k"] == [1.0] * 3 and mirror["distribution"] == "beckmann"
    assert d["render"] == {"maxBounces": 4, "rrDepth": 3}
    card = np.array(d["objects"][1]["transform"]["matrix"])
    assert np.allclose(card[:3, :3], 2 * np.eye(3)) and np.allclose(card[:3, 3], [0, -1, 0])
    ball = d["objects"][2]
    assert ball["smooth"] and any("tessellated" in w for w in warnings)
    assert np.allclose(np.array(ball["transform"]["matrix"])[:3, 3], [1, 0, 0])
    assert d["lights"] == [{"type": "point", "position": [0, 3, 0], "intensity": [5.0] * 3}]
    # Mitsuba's envmap turned by A about +Y is ours turned by A - 180
    assert d["environment"] == {"file": "sky.hdr", "intensity": 2.0,
                                "rotation": pytest.approx(20.0)}


def test_directional_emitter(tmp_path):
    """Mitsuba's directional emitter (radiating along `direction`, or along +Z of
    to_world) is the scene format's directional light; giving both is an error."""
    head = SENSOR + '<shape type="rectangle"><bsdf type="diffuse"/></shape>\n'
    d, _ = convert_file(write(tmp_path, head + '<emitter type="directional"><vector '
                              'name="direction" value="1, -2, 0.5"/><rgb name="irradiance" '
                              'value="3"/></emitter>'))
    assert d["lights"] == [{"type": "directional", "direction": [1.0, -2.0, 0.5],
                            "irradiance": [3.0] * 3}]
    d, _ = convert_file(write(tmp_path, head + '<emitter type="directional"><transform '
                              'name="to_world"><rotate x="1" angle="90"/></transform>'
                              '</emitter>'))
    light, = d["lights"]
    assert np.allclose(light["direction"], [0, -1, 0], atol=1e-12)     # +Z turned about +X
    assert light["irradiance"] == [1.0] * 3
    with pytest.raises(pt.SceneError, match="not both"):
        convert_file(write(tmp_path, head + '<emitter type="directional"><vector '
                           'name="direction" value="0, 0, 1"/><transform name="to_world">'
                           '<rotate x="1" angle="90"/></transform></emitter>'))


def test_spot_emitter(tmp_path):
    """Mitsuba's spot emitter (at to_world's origin, pointing along its +Z; cutoff_angle
    default 20, beam_width 3/4 of it) is the scene format's spot light, with a warning that
    the falloff between the two angles is glTF's curve."""
    head = SENSOR + '<shape type="rectangle"><bsdf type="diffuse"/></shape>\n'
    d, warnings = convert_file(write(tmp_path, head + '<emitter type="spot"><transform '
                                     'name="to_world"><lookat origin="0, 2, 0" target="0, 0, '
                                     '0" up="0, 0, 1"/></transform><rgb name="intensity" '
                                     'value="4"/></emitter>'))
    light, = d["lights"]
    assert light["type"] == "spot" and np.allclose(light["position"], [0, 2, 0])
    assert np.allclose(light["direction"], [0, -1, 0], atol=1e-12)
    assert light["intensity"] == [4.0] * 3
    assert light["outerAngle"] == 20 and light["innerAngle"] == 15
    assert any("spot emitter" in w for w in warnings)
    scene = pt.load_scene(write(tmp_path, head + '<emitter type="spot"><float '
                                'name="cutoff_angle" value="30"/><float name="beam_width" '
                                'value="10"/></emitter>', "s2.xml"))
    light, = scene.data["lights"]
    assert (light["innerAngle"], light["outerAngle"]) == (10, 30)
    with pytest.raises(pt.SceneError, match="beam_width"):
        convert_file(write(tmp_path, head + '<emitter type="spot"><float name="cutoff_angle" '
                           'value="10"/><float name="beam_width" value="12"/></emitter>',
                           "s3.xml"))


def test_area_emitter_gets_its_own_material(tmp_path):
    body = SENSOR + """<bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.8"/></bsdf>
<shape type="rectangle" id="lamp"><ref id="white"/><emitter type="area">
  <rgb name="radiance" value="10, 9, 8"/></emitter></shape>
<shape type="rectangle" id="wall"><ref id="white"/></shape>"""
    d, _ = convert_file(write(tmp_path, body))
    mats = {m["name"]: m for m in d["materials"]}
    assert d["objects"][0]["material"] == "lamp-emitter"
    assert mats["lamp-emitter"]["emission"] == [10, 9, 8]
    assert mats["lamp-emitter"]["albedo"] == [0.8] * 3 and "emission" not in mats["white"]
    scene = pt.load_scene(write(tmp_path, body))     # validated by the loader too
    assert scene.features.tri_lights


@pytest.mark.parametrize("body, message", [
    ('<bsdf type="pplastic" id="p"/>' '<shape type="cube"><ref id="p"/></shape>',
     "BSDF 'pplastic' is not supported"),
    ('<shape type="bsplinecurve"/>', "shape 'bsplinecurve' is not supported"),
    ('<shape type="cube"><ref id="nope"/></shape>', "no BSDF with that id"),
    ('<shape type="cube"><bsdf type="conductor"><string name="material" value="Xx"/></bsdf>'
     '</shape>', "not one of Mitsuba's"),
    ('<medium type="homogeneous"/>', "<medium> is not supported"),
    ('<shape type="obj"><string name="filename" value="$mesh"/></shape>', "$mesh: no <default"),
    ('<emitter type="projector"/>', "emitter 'projector' is not supported"),
    ('<integrator type="bdpt"/>', "integrator 'bdpt' is not supported"),
])
def test_unsupported_elements_are_named(tmp_path, body, message):
    with pytest.raises(pt.SceneError, match=message.replace("$", r"\$").replace("(", r"\(")) \
            as e:
        convert_file(write(tmp_path, SENSOR + body))
    assert "scene.xml" in str(e.value) and "/scene/" in str(e.value)


def test_bad_files(tmp_path):
    with pytest.raises(pt.SceneError, match="invalid XML"):
        convert_file(write(tmp_path, "<shape"))
    bad = tmp_path / "other.xml"
    bad.write_text("<html/>")
    with pytest.raises(pt.SceneError, match="expected a Mitsuba <scene>"):
        convert_file(str(bad))
    old = tmp_path / "old.xml"
    old.write_text('<scene version="0.6.0"><shape type="cube"/></scene>')
    with pytest.raises(pt.SceneError, match="Mitsuba 0.6 scene"):
        convert_file(str(old))
    with pytest.raises(pt.SceneError, match="not found"):
        pt.load_scene(str(tmp_path / "missing.xml"))


def test_included_files_as_mitsubas_writer_splits_them(tmp_path):
    """Mitsuba's XML writer (mitsuba.python.xml.WriteXML, split_files=True) puts
    materials, geometry, emitters and cameras in files of their own that the main file
    <include>s: the Cornell box split that way reads as the single file does; a missing or
    self-including file is a named error."""
    import xml.etree.ElementTree as ETree
    root = ETree.parse(XML_CORNELL).getroot()
    parts = {"bsdf": "mats.xml", "shape": "geom.xml", "emitter": "emit.xml",
             "sensor": "cams.xml"}
    main = ETree.Element("scene", root.attrib)
    subs = {f: ETree.Element("scene", root.attrib) for f in parts.values()}
    for el in root:
        (subs[parts[el.tag]] if el.tag in parts else main).append(el)
    for f, sub in subs.items():
        ETree.ElementTree(sub).write(tmp_path / f)
        ETree.SubElement(main, "include", filename=f)
    ETree.ElementTree(main).write(tmp_path / "main.xml")
    split, _ = convert_file(str(tmp_path / "main.xml"))
    whole, _ = convert_file(XML_CORNELL)
    assert split == whole
    (tmp_path / "loop.xml").write_text('<scene version="3.0.0"><include filename="loop.xml"/>'
                                       "</scene>")
    with pytest.raises(pt.SceneError, match="nested deeper"):
        convert_file(str(tmp_path / "loop.xml"))
    (tmp_path / "gone.xml").write_text('<scene version="3.0.0"><include filename="x.xml"/>'
                                       "</scene>")
    with pytest.raises(pt.SceneError, match="included file x.xml not found") as e:
        convert_file(str(tmp_path / "gone.xml"))
    assert "include[1]" in str(e.value)


# ---------------------------------------------------------------------------------------
# Fuzzing: a mutated Mitsuba file loads or fails with one SceneError, never anything else

import xml.etree.ElementTree as ET  # noqa: E402

from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

BAD_ATTRS = ["", "x", "nan", "inf", "-1", "1e39", "0", "1 2", "1,2,3,4", "$nope", "-0.5",
             "999999999999999999999", "true", "rectangle", "none", "bk7"]
TYPES = ["diffuse", "principled", "plastic", "cube", "sphere", "obj", "area", "point",
         "envmap", "path", "perspective", "thinlens", "box", "bitmap", "twosided"]
TAGS = ["float", "integer", "rgb", "spectrum", "string", "boolean", "point", "transform",
        "bsdf", "shape", "emitter", "ref", "medium", "texture", "translate", "matrix"]


@st.composite
def mutated_xml(draw):
    root = ET.parse(XML_CORNELL).getroot()
    for _ in range(draw(st.integers(1, 4))):
        elements = list(root.iter())
        el = draw(st.sampled_from(elements))
        action = draw(st.sampled_from(["attr", "attr", "delete", "type", "tag", "add"]))
        if action == "attr" and el.attrib:
            key = draw(st.sampled_from(sorted(el.attrib)))
            el.set(key, draw(st.sampled_from(BAD_ATTRS)))
        elif action == "delete" and el is not root:
            parent = next(p for p in root.iter() if el in list(p))
            parent.remove(el)
        elif action == "type":
            el.set("type", draw(st.sampled_from(TYPES)))
        elif action == "tag" and el is not root:
            el.tag = draw(st.sampled_from(TAGS))
        elif action == "add":
            child = ET.SubElement(el, draw(st.sampled_from(TAGS)))
            child.set("name", draw(st.sampled_from(["value", "fov", "radiance", "to_world",
                                                    "filename", "bsdf"])))
            child.set("value", draw(st.sampled_from(BAD_ATTRS)))
    return ET.tostring(root, encoding="unicode")


@pytest.mark.filterwarnings("ignore")
@settings(max_examples=int(os.environ.get("PT_FUZZ_EXAMPLES", "60")), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
          derandomize=not os.environ.get("PT_FUZZ_RANDOM"))
@given(text=mutated_xml())
def test_fuzzed_mitsuba_xml_loads_or_names_the_error(tmp_path, text):
    path = tmp_path / "fuzz.xml"
    path.write_text(text)
    try:
        scene = pt.load_scene(str(path))
    except pt.SceneError as e:
        assert "\n" not in str(e) and str(e)
        return
    assert scene.width > 0 and scene.n_triangles >= 0


# Mitsuba 3.9.1's horizontal field of view (mi.traverse(sensor)["x_fov"]) of a perspective
# sensor for (its parameters, film width, height): printed by Mitsuba on 2026-12-07, kept
# here so that CI (without Mitsuba) checks the rule; test_default_fov_matches_mitsuba_live
# asks Mitsuba itself where it is installed.
MITSUBA_X_FOV = [
    ({}, 64, 64, 34.0221), ({}, 64, 32, 42.3117), ({}, 32, 64, 21.9021),
    ({"focal_length": "35mm"}, 64, 64, 47.2163), ({"focal_length": "35mm"}, 64, 32, 57.8712),
    ({"focal_length": "35mm"}, 32, 64, 30.9038),
    ({"fov": 30, "fov_axis": "smaller"}, 64, 32, 56.3736),
    ({"fov": 30, "fov_axis": "smaller"}, 32, 64, 30.0),
    ({"fov": 30, "fov_axis": "larger"}, 32, 64, 15.2615),
    ({"fov": 30, "fov_axis": "diagonal"}, 64, 64, 21.4572),
    ({"fov": 30, "fov_axis": "diagonal"}, 64, 32, 26.9547),
    ({"fov": 30, "fov_axis": "y"}, 32, 64, 15.2615),
]


def _sensor_xml(params, width, height):
    body = "".join(f'<string name="{k}" value="{v}"/>' if isinstance(v, str) else
                   f'<float name="{k}" value="{v}"/>' for k, v in params.items())
    return (f'<sensor type="perspective">{body}<transform name="to_world"><lookat '
            f'origin="0,0,5" target="0,0,0" up="0,1,0"/></transform><film type="hdrfilm">'
            f'<integer name="width" value="{width}"/><integer name="height" '
            f'value="{height}"/><rfilter type="box"/></film></sensor>')


@pytest.mark.parametrize("params, width, height, x_fov", MITSUBA_X_FOV)
def test_default_fov_and_focal_length_as_mitsuba(tmp_path, params, width, height, x_fov):
    """Without fov, Mitsuba's 50 mm lens spans the 35 mm film's diagonal whatever the
    aspect (34.02 degrees on a square film, not 39.6): the camera sees what Mitsuba's does."""
    d, _ = convert_file(write(tmp_path, _sensor_xml(params, width, height)))
    assert d["camera"]["fov"] == pytest.approx(x_fov, abs=1e-3)


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed")
def test_default_fov_matches_mitsuba_live(tmp_path):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    for params, width, height, _ in MITSUBA_X_FOV:
        path = write(tmp_path, _sensor_xml(params, width, height))
        sensor = mi.load_file(path).sensors()[0]
        ours = convert_file(path)[0]["camera"]["fov"]
        x_fov = mi.traverse(sensor)["x_fov"]
        x_fov = x_fov[0] if hasattr(x_fov, "__len__") else x_fov
        assert ours == pytest.approx(float(x_fov), abs=1e-3)


def test_fov_and_focal_length_together_is_an_error(tmp_path):
    with pytest.raises(pt.SceneError, match="fov or focal_length"):
        convert_file(write(tmp_path, _sensor_xml({"fov": 30, "focal_length": "35mm"}, 8, 8)))
    with pytest.raises(pt.SceneError, match="focal_length"):
        convert_file(write(tmp_path, _sensor_xml({"focal_length": "wide"}, 8, 8)))


def test_a_scene_without_a_sensor_gets_mitsubas_default_camera(tmp_path):
    """Mitsuba's Scene adds a 45-degree camera looking along +Z from in front of the scene's
    bounding box when a file has no sensor (include fragments often have none)."""
    d, warnings = convert_file(write(tmp_path, '<shape type="cube"><transform name="to_world">'
                                     '<translate x="1" z="2"/></transform></shape>'))
    distance = 2 / (2 * math.tan(math.radians(22.5)))
    cam = d["camera"]
    assert cam["fov"] == 45 and cam["resolution"] == [768, 576]
    assert np.allclose(cam["position"], [1, 0, 1 - distance])
    assert np.allclose(np.subtract(cam["lookAt"], cam["position"]), [0, 0, 1])
    assert any("default camera" in w for w in warnings)


def test_rectangle_and_sphere_texture_coordinates_as_mitsubas(tmp_path):
    """Mitsuba's rectangle has (u, v) = ((x + 1) / 2, (y + 1) / 2) and its sphere u = phi /
    2 pi, v = theta / pi about local +Z; this format's v is 1 - Mitsuba's."""
    d, _ = convert_file(write(tmp_path, SENSOR + '<shape type="rectangle"/><shape '
                              'type="sphere"/>'))
    rect, sphere = d["objects"]
    for (x, y, _), (u, v) in zip(rect["vertices"], rect["uvs"]):
        assert (u, 1 - v) == ((x + 1) / 2, (y + 1) / 2)
    p, uv = np.array(sphere["vertices"]), np.array(sphere["uvs"])
    theta = np.arccos(np.clip(p[:, 2], -1, 1))
    assert np.allclose(1 - uv[:, 1], theta / np.pi)
    phi = np.arctan2(p[:, 1], p[:, 0]) % (2 * np.pi)
    ring = np.sin(theta) > 1e-6
    assert np.allclose(np.cos(phi[ring] - 2 * np.pi * uv[ring, 0]), 1)


def test_checkerboard_is_mitsubas_pattern(tmp_path):
    """A checkerboard texture is a 2 x 2 image looked up nearest: color0 where frac(u) and
    frac(v) are on the same side of 1/2; its to_uv scale tiles it."""
    body = SENSOR + """<bsdf type="diffuse" id="b"><texture type="checkerboard" name="reflectance">
      <rgb name="color0" value="0.1 0.2 0.3"/><rgb name="color1" value="0.9"/>
      <transform name="to_uv"><scale x="4" y="2"/></transform></texture></bsdf>
      <shape type="rectangle"><ref id="b"/></shape>"""
    d, _ = convert_file(write(tmp_path, body))
    tex = d["materials"][0]["albedo"]
    img = np.load(tex["texture"])
    assert img.shape == (2, 2, 3) and np.allclose(img[0, 0], [0.1, 0.2, 0.3])
    assert np.allclose(img[0, 1], 0.9) and np.allclose(img[1, 1], img[0, 0])
    assert tex["filter"] == "nearest" and tex["colorSpace"] == "linear"
    assert tex["tile"] == [4, 2] and tex["offset"] == [0, 1 - 2]


# What Mitsuba 3.9.1's scalar_rgb variant makes of the spectra of its own Cornell box
# (../shared/realworld/mi_cbox/cbox.xml: reflectances by wavelength and the lamp's
# radiance), read back from its BSDFs and emitter on 2026-12-07.
MITSUBA_CBOX_RGB = {"red": [0.49132, 0.049228, 0.050922], "box": [0.735013, 0.735625, 0.736264],
                    "green": [0.068283, 0.39776, 0.086291], "light": [0.776367, 0.77981, 0.776029],
                    "emission": [20.71084, 10.85463, 2.77115]}


@needs_shared
def test_spectra_become_the_colours_mitsubas_rgb_mode_makes():
    path = os.path.join(os.path.dirname(ROOT), "shared", "realworld", "mi_cbox", "cbox.xml")
    d, _ = convert_file(path)
    mats = {m["name"]: m for m in d["materials"]}
    for name in ("red", "box", "green", "light"):
        assert np.allclose(mats[name]["albedo"], MITSUBA_CBOX_RGB[name], rtol=1e-4, atol=1e-5)
    lamp, = [m for m in d["materials"] if "emission" in m]
    assert np.allclose(lamp["emission"], MITSUBA_CBOX_RGB["emission"], rtol=1e-4)


def test_uniform_spectrum_of_an_emitter_is_mitsubas_white(tmp_path):
    """<spectrum value="2"> is grey for a reflectance but 2 x xyz_to_srgb(1, 1, 1) =
    (2.41, 1.90, 1.82) for an emitter in Mitsuba's RGB variants (its spectral white)."""
    body = SENSOR + """<emitter type="constant"><spectrum name="radiance" value="2"/></emitter>
      <shape type="rectangle"><bsdf type="diffuse"><spectrum name="reflectance" value="0.5"/></bsdf>
      </shape>
      <shape type="rectangle"><transform name="to_world"><translate z="-2"/></transform>
      <bsdf type="diffuse"><spectrum name="reflectance" filename="refl.spd"/></bsdf></shape>"""
    (tmp_path / "refl.spd").write_text("# a flat spectrum\n400 0.3\n700 0.3\n")
    d, _ = convert_file(write(tmp_path, body))
    assert np.allclose(d["environment"]["color"], [2.40959, 1.89658, 1.81783], rtol=1e-4)
    assert d["materials"][0]["albedo"] == [0.5] * 3
    # a flat 400-700 nm reflectance: grey up to the D65-weighted tails outside it
    assert np.allclose(d["materials"][1]["albedo"], 0.3, rtol=0.01)
    bad = SENSOR + '<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" ' \
                   'value="500:0.5, 400:0.2"/></bsdf></shape>'
    with pytest.raises(pt.SceneError, match="increasing wavelengths"):
        convert_file(write(tmp_path, bad))


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed")
def test_spectrum_conversion_matches_mitsubas_own():
    import mitsuba as mi
    from pathtracer.scene.spectra import spectrum_to_rgb
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(3)
    for k in range(50):
        n = int(rng.integers(2, 30))
        w = np.sort(rng.uniform(300, 900, n))
        v = rng.uniform(0, 0.6, n)
        for emitter in (False, True):
            theirs = np.array(mi.spectrum_list_to_srgb(w.tolist(), v.tolist(), not emitter,
                                                       not emitter))
            assert np.allclose(spectrum_to_rgb(w, v, emitter), theirs, rtol=1e-4, atol=1e-6)


def test_plastic_and_beckmann_are_approximated_with_warnings(tmp_path):
    """plastic/roughplastic: the principled BSDF at the coat's F0 (eta 1.49: F0 0.0387,
    specular 0.484) with the base's reflectance scaled by Mitsuba's internal scattering at
    normal incidence, (1 - F0)^2 / eta^2 / (1 - F_dr), F_dr = 0.5907 (Mitsuba's
    fresnel_diffuse_reflectance(1 / 1.49)); Mitsuba's default Beckmann as GGX. Each with a
    warning."""
    body = SENSOR + """<shape type="cube"><bsdf type="roughplastic">
      <rgb name="diffuse_reflectance" value="0.5 0.25 0.1"/><float name="alpha" value="0.09"/>
      </bsdf></shape>
      <shape type="cube"><bsdf type="plastic"><boolean name="nonlinear" value="true"/>
      </bsdf></shape>"""
    d, warnings = convert_file(write(tmp_path, body))
    rough, smooth = d["materials"]
    eta, f_dr = 1.49 / 1.000277, 0.5907325
    f0 = ((eta - 1) / (eta + 1)) ** 2
    scale = (1 - f0) ** 2 / eta ** 2 / (1 - f_dr)
    assert rough["specular"] == pytest.approx(f0 / 0.08, rel=1e-3)
    assert np.allclose(rough["albedo"], np.array([0.5, 0.25, 0.1]) * scale, rtol=2e-3)
    assert rough["roughness"] == pytest.approx(0.3) and smooth["roughness"] == 0
    assert smooth["albedo"][0] == pytest.approx(0.5 * (1 - f0) ** 2 / eta ** 2 /
                                                (1 - 0.5 * f_dr), rel=2e-3)
    assert any("Beckmann" in w for w in warnings)
    assert sum("approximated by the principled BSDF" in w for w in warnings) == 2


def test_disk_and_cylinder_are_tessellated_facing_out(tmp_path):
    """Mitsuba's disk (the unit disk at z = 0 facing +z) and open cylinder (radius, p0, p1,
    facing outward unless flip_normals): tessellated, with their area and sidedness."""
    body = SENSOR + """<shape type="disk"/>
      <shape type="cylinder"><float name="radius" value="0.5"/><point name="p0" value="0,0,0"/>
      <point name="p1" value="0,2,0"/></shape>"""
    d, warnings = convert_file(write(tmp_path, body))
    disk, tube = d["objects"]
    for obj, area, outward in ((disk, math.pi, None), (tube, 2 * math.pi * 0.5 * 2, True)):
        v = np.array(obj["vertices"])[np.array(obj["faces"])]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        assert 0.5 * np.linalg.norm(n, axis=1).sum() == pytest.approx(area, rel=2e-3)
        if outward:
            radial = v.mean(1) * [1, 0, 1]        # the tube's axis is +y
            assert (np.einsum("ij,ij->i", n, radial) > 0).all()
        else:
            assert (n[:, 2] > 0).all()
    assert sum("tessellated" in w for w in warnings) == 2


def test_parameters_from_the_command_line_and_path_folders(tmp_path):
    """-D name=value (load_scene's params) sets $name over <default>, in any attribute (a
    type too); <path> folders are searched for the files a scene names."""
    from pathtracer.cli import build_parser
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    body = """<default name="w" value="8"/><default name="kind" value="direct"/>
      <path value="meshes"/>
      <integrator type="$kind"/>
      <sensor type="perspective"><transform name="to_world"><lookat origin="0,0,3"
        target="0,0,0" up="0,1,0"/></transform><film type="hdrfilm">
        <integer name="width" value="$w"/><integer name="height" value="4"/></film></sensor>
      <shape type="obj"><string name="filename" value="tri.obj"/></shape>"""
    path = write(tmp_path, body)
    s = pt.load_scene(path)
    assert s.data["camera"]["resolution"] == [8, 4] and s.data["render"]["maxBounces"] == 1
    assert s.data["objects"][0]["file"] == str(tmp_path / "meshes" / "tri.obj")
    s = pt.load_scene(path, params={"w": 16, "kind": "path"})
    assert s.data["camera"]["resolution"] == [16, 4] and s.data["render"]["maxBounces"] == 64
    args = build_parser().parse_args([path, "-D", "w=16", "--define", "kind=path"])
    assert dict(args.define) == {"w": "16", "kind": "path"}
    with pytest.raises(SystemExit):
        build_parser().parse_args([path, "-D", "nothing"])
    with pytest.raises(pt.SceneError, match="for Mitsuba XML scenes"):
        pt.load_scene(os.path.join(ROOT, "scenes", "cornell-box.json"), params={"a": 1})
    with pytest.raises(pt.SceneError, match="for Mitsuba XML scenes"):
        pt.load_scene({"camera": {}}, params={"a": 1})


def test_normalmap_bsdf_gives_its_nested_material_a_normal_map(tmp_path):
    body = SENSOR + """<shape type="cube"><bsdf type="normalmap">
      <texture name="normalmap" type="bitmap"><boolean name="raw" value="true"/>
      <string name="filename" value="n.png"/></texture>
      <bsdf type="roughconductor"><float name="alpha" value="0.04"/>
      <string name="distribution" value="ggx"/></bsdf></bsdf></shape>"""
    d, warnings = convert_file(write(tmp_path, body))
    m = d["materials"][0]
    assert m["type"] == "conductor" and m["alphaU"] == pytest.approx(0.04)
    assert m["normalMap"]["texture"].endswith("n.png")
    assert m["normalMap"]["colorSpace"] == "linear" and m["oneSided"]


def test_conductors_are_read_exactly(tmp_path):
    """conductor / roughconductor -> the conductor material: Mitsuba's named metals as
    eta and k over ext_eta, alpha_u / alpha_v as they are (alpha_v > alpha_u too), its
    default distribution (Beckmann), textured alphas, material 'none' a perfect mirror."""
    body = SENSOR + """<shape type="cube"><bsdf type="roughconductor">
      <float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.3"/>
      <string name="material" value="Au"/><float name="ext_eta" value="1.5"/>
      <rgb name="specular_reflectance" value="0.9 0.8 0.7"/></bsdf></shape>
      <shape type="cube"><bsdf type="conductor"/></shape>
      <shape type="rectangle"><bsdf type="roughconductor"><string name="distribution" value="ggx"/>
      <texture type="checkerboard" name="alpha"><float name="color0" value="0.1"/>
      <float name="color1" value="0.4"/></texture></bsdf></shape>"""
    d, warnings = convert_file(write(tmp_path, body))
    aniso, mirror, textured = d["materials"]
    eta, k = conductor_table()["Au"]
    assert aniso["type"] == "conductor" and aniso["distribution"] == "beckmann"
    assert (aniso["alphaU"], aniso["alphaV"]) == (0.05, 0.3)
    assert np.allclose(aniso["eta"], eta / 1.5) and np.allclose(aniso["k"], k / 1.5)
    assert aniso["albedo"] == [0.9, 0.8, 0.7] and aniso["oneSided"]
    assert mirror["eta"] == [0.0] * 3 and mirror["k"] == [1.0] * 3 and "alphaU" not in mirror
    assert textured["distribution"] == "ggx" and textured["alphaU"]["colorSpace"] == "linear"
    assert not any("approximated" in w or "Schlick" in w for w in warnings)
    scene = pt.load_scene(write(tmp_path, body))
    assert scene.features.conductor


def test_null_bsdf_lets_rays_through(tmp_path):
    """null: a surface every ray passes (a cut-out everywhere); with an area emitter on it
    (light that rays pass through) an error."""
    body = SENSOR + '<shape type="cube"><bsdf type="null"/></shape>'
    (m,) = convert_file(write(tmp_path, body))[0]["materials"]
    assert m["alpha"] == 0.0 and m["alphaMode"] == "mask" and not m.get("oneSided")
    lit = SENSOR + ('<shape type="cube"><bsdf type="null"/><emitter type="area">'
                    '<rgb name="radiance" value="1"/></emitter></shape>')
    with pytest.raises(pt.SceneError, match="null BSDF"):
        convert_file(write(tmp_path, lit))


def test_mask_bsdf_is_stochastic_transparency(tmp_path):
    """Mitsuba's mask: its nested BSDF with probability `opacity` (a float, default 0.5, or
    a texture), else a null interaction: alphaMode blend over the nested material, which
    keeps its own sides (a twosided one reflects on both). Against Mitsuba 3.9.1 (opacity
    0.3 over a two-sided diffuse quad under a constant sky, `python -m bench.mitsuba_compare`,
    2026-12-07): channel means 1.0000 / 0.9999 / 0.9999 of Mitsuba's."""
    quad = ('<shape type="rectangle"><bsdf type="mask">{opacity}<bsdf type="twosided">'
            '<bsdf type="diffuse"/></bsdf></bsdf></shape>')
    for opacity, alpha in (('<float name="opacity" value="0.3"/>', 0.3), ("", 0.5)):
        d, _ = convert_file(write(tmp_path, SENSOR + quad.format(opacity=opacity)))
        (m,) = d["materials"]
        assert m["alphaMode"] == "blend" and m["alpha"] == pytest.approx(alpha)
        assert not m.get("oneSided")
    (tmp_path / "leaf.png").write_bytes(b"")
    d, _ = convert_file(write(tmp_path, SENSOR + quad.format(
        opacity='<texture type="bitmap" name="opacity"><string name="filename" '
                'value="leaf.png"/></texture>')))
    (m,) = d["materials"]
    assert m["alphaMode"] == "blend" and m["alpha"]["texture"].endswith("leaf.png")
    # a mask over a one-sided BSDF stays one-sided
    d, _ = convert_file(write(tmp_path, SENSOR + '<shape type="rectangle"><bsdf type="mask">'
                              '<bsdf type="diffuse"/></bsdf></shape>'))
    assert d["materials"][0]["oneSided"] and d["materials"][0]["alphaMode"] == "blend"


def test_checkerboard_read_as_a_number_as_mitsuba_reads_it(tmp_path):
    """Mitsuba 3.9.1's checkerboard gives color0 where frac(u) and frac(v) are on the same
    side of 1/2 as a colour (eval) but color1 there as a number (eval_1): a checkerboard
    that feeds a number (a conductor's alpha, a principled number, a mask's opacity) is
    read with its values exchanged, so that the images agree (Mitsuba's
    test_textured_roughconductor_path: relMSE at the noise with, 1,000x it without)."""
    body = SENSOR + """<shape type="rectangle"><bsdf type="roughconductor">
      <texture type="checkerboard" name="alpha"><float name="color0" value="0.1"/>
      <float name="color1" value="0.4"/></texture></bsdf></shape>"""
    tex = convert_file(write(tmp_path, body))[0]["materials"][0]["alphaU"]
    img = np.load(tex["texture"])
    # the top-left texel (u < 1/2, v > 1/2: the sides differ) holds color0 for a colour
    # (test_checkerboard_is_mitsubas_pattern) and color1 for a number
    assert np.allclose(img[0, 0], 0.4) and np.allclose(img[0, 1], 0.1)


def test_checkerboard_values_against_mitsuba_live():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    t = mi.load_dict({"type": "checkerboard", "color0": 0.1, "color1": 0.4})
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(0.25, 0.75)          # the sides differ: color1 as a colour
    assert np.allclose(t.eval(si), 0.4) and t.eval_1(si) == pytest.approx(0.1)
