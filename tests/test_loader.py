"""Scene loading: every bad input is one clear line naming file and JSON path; exit 2."""
import json
import os
import subprocess
import sys

import numpy as np

from pathtracer.kernels import layout as L
import pytest

from pathtracer.scene import SceneError, load_scene, load_scene_description
from tests.conftest import ROOT
from tests.helpers import box_mesh, write_scene

CORNELL = os.path.join(ROOT, "scenes", "cornell-box.json")


def minimal(**extra):
    v, f = box_mesh()
    scene = {"camera": {"resolution": [8, 8], "position": [0, 0, 5], "lookAt": [0, 0, 0]},
             "materials": [{"name": "white", "type": "diffuse", "albedo": 0.8}],
             "objects": [{"name": "box", "vertices": v, "faces": f, "material": "white"}]}
    scene.update(extra)
    return scene


def error_of(tmp_path, scene, raw=None):
    path = os.path.join(str(tmp_path), "s.json")
    with open(path, "w") as f:
        f.write(raw if raw is not None else json.dumps(scene))
    with pytest.raises(SceneError) as e:
        load_scene(path)
    return str(e.value), path


@pytest.mark.parametrize("mutate, pointer, words", [
    (lambda s: s["camera"].update(fovv=3), "/camera/fovv", "unknown key"),
    (lambda s: s["materials"][0].update(albedo="x.png"), "/materials/0/albedo", "texture file not found"),
    (lambda s: s["materials"][0].update(albedo="x.gif"), "/materials/0/albedo", "unsupported texture format"),
    (lambda s: s["materials"][0].update(albedo={"texture": "x.png", "filter": "cubic"}),
     "/materials/0/albedo/texture", "texture file not found"),
    (lambda s: s["materials"][0].update(roughness=0.3), "/materials/0/roughness", "principled"),
    (lambda s: s["materials"][0].update(type="principled", roughness=1.5), "/materials/0/roughness", "must be <= 1"),
    (lambda s: s["materials"][0].update(type="principled", eta=1.3, specular=0.5), "/materials/0/eta", "not both"),
    (lambda s: s["materials"][0].update(type="principled", eta=0), "/materials/0/eta", "must be > 0"),
    (lambda s: s["materials"][0].update(albedo=[1, 2]), "/materials/0/albedo", "3 numbers"),
    (lambda s: s["materials"][0].update(albedo=-1), "/materials/0/albedo", ">= 0"),
    (lambda s: s["materials"][0].update(type="glass"), "/materials/0/type", "one of"),
    (lambda s: s["objects"][0].update(material="nope"), "/objects/0/material", "unknown material"),
    (lambda s: s["objects"][0].update(smooth="yes"), "/objects/0/smooth", "true or false"),
    (lambda s: s["objects"][0]["faces"].append([0, 1, 99]), "/objects/0/faces/12/2", "out of range"),
    (lambda s: s["objects"][0].update(file="missing.obj", vertices=None, faces=None) or
     s["objects"][0].pop("vertices") or s["objects"][0].pop("faces"), "/objects/0/file", "not found"),
    (lambda s: s.update(render={"spp": 0}), "/render/spp", ">= 1"),
    (lambda s: s.update(render={"maxBounces": 1.5}), "/render/maxBounces", "integer"),
    (lambda s: s["camera"].update(aperture=-1), "/camera/aperture", "must be >= 0"),
    (lambda s: s.update(environment={"file": "sky.hdr"}), "/environment/file", "not found"),
    (lambda s: s.update(environment={"file": "sky.hdr", "color": 1}), "/environment/color", "not both"),
    (lambda s: s.update(environment={"file": "sky.hdr", "misCompensation": 1}),
     "/environment/misCompensation", "true or false"),
    (lambda s: s.update(environment={"color": 1, "misCompensation": False}),
     "/environment/misCompensation", "unknown key"),
    (lambda s: s.update(lights=[{"type": "area", "position": [0, 0, 0]}]), "/lights/0/type", "one of"),
    (lambda s: s["objects"][0].update(transform={"scale": 0}), "/objects/0/transform", "singular"),
    (lambda s: s.update(extra=1), "/extra", "unknown key"),
    (lambda s: s.pop("camera"), "/", "camera"),
])
def test_errors_name_the_json_path(tmp_path, mutate, pointer, words):
    scene = minimal()
    mutate(scene)
    msg, path = error_of(tmp_path, scene)
    assert msg.startswith(path + ": " + pointer + ":") or (pointer == "/" and path in msg), msg
    assert words in msg
    assert "\n" not in msg


def test_nan_coordinates(tmp_path):
    scene = minimal()
    raw = json.dumps(scene).replace("[-1.0, -1.0, -1.0]", "[NaN, -1.0, -1.0]", 1)
    msg, _ = error_of(tmp_path, None, raw)
    assert "NaN" in msg and "line 1" in msg


def test_nan_in_obj_file(tmp_path):
    (tmp_path / "n.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = minimal()
    scene["objects"][0] = {"name": "o", "file": "n.obj", "material": "white"}
    msg, _ = error_of(tmp_path, scene)
    assert "/objects/0/file" in msg and "NaN" in msg


def test_bad_json_names_line(tmp_path):
    msg, path = error_of(tmp_path, None, '{"camera": {}\n,,}')
    assert path in msg and "line 2" in msg


def test_duplicate_keys_rejected(tmp_path):
    msg, _ = error_of(tmp_path, None, '{"camera": {}, "camera": {}}')
    assert "duplicate key" in msg


@pytest.mark.parametrize("face", ["1 2 7", "-1 -2 -9", "0 1 2"])
def test_obj_index_out_of_range(tmp_path, face):
    """Too large, too negative (pywavefront would wrap it silently) and zero indices."""
    (tmp_path / "bad.obj").write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nf {face}\n")
    scene = minimal()
    scene["objects"][0] = {"name": "o", "file": "bad.obj", "material": "white"}
    msg, _ = error_of(tmp_path, scene)
    assert "bad.obj" in msg and "out of range" in msg


def test_obj_negative_indices_and_quads(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n")
    scene = minimal()
    scene["objects"][0] = {"name": "o", "file": "quad.obj", "material": "white"}
    s = load_scene(write_scene(tmp_path, scene))
    assert s.n_triangles == 2
    # Both triangles keep the quad's counter-clockwise winding: normal +z.
    e1 = s.arrays.tri_v[:2, L.TRI_E1:L.TRI_E1 + 3]
    e2 = s.arrays.tri_v[:2, L.TRI_E2:L.TRI_E2 + 3]
    n = np.cross(e1, e2)
    assert (n[:, 2] > 0).all()


def test_cli_error_is_one_line_exit_2(tmp_path):
    scene = minimal()
    scene["materials"][0]["roughness"] = 0.3
    path = write_scene(tmp_path, scene)
    r = subprocess.run([sys.executable, "-m", "pathtracer", path, "-o",
                        str(tmp_path / "x.png")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "/materials/0/roughness" in lines[0] and "Traceback" not in r.stderr


def test_thesis_aliases_and_vector_objects(tmp_path):
    scene = minimal(pointLights=[{"position": {"x": 0, "y": 3, "z": 0},
                                  "radiance": {"r": 1, "g": 2, "b": 3}}],
                    hdri={"color": [0.1, 0.2, 0.3]})
    scene["camera"] = {"xRes": 12, "yRes": 6, "position": [0, 0, 5], "rotation": [0, 0, 0]}
    s = load_scene(write_scene(tmp_path, scene))
    assert (s.width, s.height) == (12, 6)
    assert s.features.point_lights and s.features.environment
    assert np.allclose(s.arrays.point_lights[0, L.PL_POSITION:L.PL_INTENSITY + 3],
                       [0, 3, 0, 1, 2, 3])
    assert np.allclose(s.arrays.env, [0.1, 0.2, 0.3])


def test_camera_conventions(tmp_path):
    # focalLength/sensorWidth give the same fov as fov; rotation [0,0,0] looks along -Z.
    a = minimal()
    a["camera"] = {"resolution": [10, 5], "focalLength": 0.05, "sensorWidth": 0.036}
    b = minimal()
    b["camera"] = {"resolution": [10, 5], "fov": float(np.degrees(2 * np.arctan(0.018 / 0.05)))}
    ca = load_scene(write_scene(tmp_path, a, "a.json")).arrays.cam
    cb = load_scene(write_scene(tmp_path, b, "b.json")).arrays.cam
    assert np.allclose(ca, cb)
    assert np.allclose(ca[3:6], [0, 0, -1])
    assert np.isclose(ca[9 + 1] / ca[6], 0.5)   # tan(fov_y/2) = tan(fov_x/2) * h / w
    # rotation: 90 degrees about Y turns -Z into -X
    c = minimal()
    c["camera"] = {"resolution": [4, 4], "rotation": [0, 90, 0]}
    cc = load_scene(write_scene(tmp_path, c, "c.json")).arrays.cam
    assert np.allclose(cc[3:6], [-1, 0, 0], atol=1e-6)


def test_transform_and_mirroring(tmp_path):
    scene = minimal()
    scene["objects"][0]["transform"] = {"translate": [1, 2, 3], "rotate": [0, 0, 90],
                                        "scale": [2, 1, 1]}
    s = load_scene(write_scene(tmp_path, scene))
    v = s.arrays.tri_v[:12, L.TRI_V0:L.TRI_V0 + 3] + s.origin_shift    # the compiler re-centres the scene
    assert np.allclose(s.origin_shift, [1, 2, 3])
    assert np.allclose(v.min(0), [0, 0, 2]) and np.allclose(v.max(0), [2, 4, 4])
    # A mirroring matrix keeps triangles facing outward.
    scene["objects"][0]["transform"] = {"matrix": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0],
                                                   [0, 0, 0, 1]]}
    s = load_scene(write_scene(tmp_path, scene))
    tv = s.arrays.tri_v[:12]
    n = np.cross(tv[:, 3:6], tv[:, 6:9])
    c = tv[:, 0:3] + (tv[:, 3:6] + tv[:, 6:9]) / 3
    assert (np.einsum("ij,ij->i", n, c) > 0).all()


def test_cornell_scene_matches_reference_description():
    d = load_scene_description(CORNELL)
    assert d.camera.resolution == (256, 256) and d.render.max_bounces == 7
    s = load_scene(CORNELL)
    assert s.n_triangles == 36 and s.features.tri_lights and not s.features.point_lights


def test_sampler_key(tmp_path):
    """render.sampler: sobol by default (the scene format), independent on request; the
    kernel is specialised on it."""
    path = write_scene(tmp_path, minimal())
    assert load_scene(path).features.sobol
    path = write_scene(tmp_path, minimal(render={"sampler": "independent"}))
    assert not load_scene(path).features.sobol
    msg, _ = error_of(tmp_path, minimal(render={"sampler": "halton"}))
    assert "/render/sampler" in msg and "'sobol'" in msg
