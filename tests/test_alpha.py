"""Alpha: cut-outs (alphaMode "mask") and stochastic transparency ("blend") in camera, bounce
and shadow rays; glTF's alphaMode read into them.

- A masked quad renders what the same shape cut in geometry renders, shadow included, to
  float rounding: a ray that passes a cut-out goes on from the hit point in the same
  direction with the same random numbers, so the paths are the same.
- Stochastic transparency is unbiased: where every path crosses the surface at most once,
  its image converges to alpha x the opaque render + (1 - alpha) x the transparent one.
"""
import json
import os

import numpy as np
import pytest

import pathtracer as pt
from pathtracer.film import relmse
from pathtracer.kernels import layout as L
from pathtracer.scene import SceneError

QUAD = [[-1, 1, -1], [1, 1, -1], [1, 1, 1], [-1, 1, 1]]


def shadow_scene(alpha=None, mode="mask", cut=False, res=(32, 32)):
    """A floor lit by a small area light above, a leaf quad in between: its opacity from
    ``alpha`` (a number or a texture) with ``mode``, or (``cut``) only its left half, in
    geometry."""
    mats = [{"name": "floor", "type": "diffuse", "albedo": 0.8},
            {"name": "lamp", "type": "diffuse", "albedo": 0, "emission": 30},
            {"name": "leaf", "type": "diffuse", "albedo": 0.5}]
    if alpha is not None:
        mats[2].update(alpha=alpha, alphaMode=mode)
    leaf = {"name": "leaf", "vertices": QUAD, "faces": [[0, 2, 1], [0, 3, 2]],
            "uvs": [[0, 0], [1, 0], [1, 1], [0, 1]], "material": "leaf"}
    if cut:
        leaf = {"name": "leaf", "faces": [[0, 2, 1], [0, 3, 2]], "material": "leaf",
                "vertices": [[-1, 1, -1], [0, 1, -1], [0, 1, 1], [-1, 1, 1]]}
    return {"camera": {"resolution": list(res), "position": [0, 5, 0.01],
                       "lookAt": [0, 0, 0], "fov": 60},
            "render": {"maxBounces": 3},
            "materials": mats,
            "objects": [
                {"name": "floor", "material": "floor", "faces": [[0, 2, 1], [0, 3, 2]],
                 "vertices": [[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]]},
                {"name": "lamp", "material": "lamp", "faces": [[0, 1, 2], [0, 2, 3]],
                 "vertices": [[-.3, 2, -.3], [.3, 2, -.3], [.3, 2, .3], [-.3, 2, .3]]},
                leaf]}


def blend_scene(alpha, mode="blend", res=(24, 24)):
    """A quad (diffuse, lit by a constant sky) in front of an emissive black backdrop: every
    path crosses the quad at most once (its own shadow and bounce rays leave its front)."""
    return {"camera": {"resolution": list(res), "position": [0, 0, 3], "lookAt": [0, 0, 0],
                       "fov": 40},
            "render": {"maxBounces": 3},
            "environment": {"color": [0.6, 0.7, 0.9]},
            "materials": [{"name": "q", "type": "diffuse", "albedo": [0.8, 0.3, 0.2],
                           "alpha": alpha, "alphaMode": mode},
                          {"name": "back", "type": "diffuse", "albedo": 0,
                           "emission": [0.2, 1.0, 0.4]}],
            "objects": [
                {"name": "q", "material": "q", "faces": [[0, 1, 2], [0, 2, 3]],
                 "vertices": [[-.6, -.6, 0], [.6, -.6, 0], [.6, .6, 0], [-.6, .6, 0]]},
                {"name": "b", "material": "back", "faces": [[0, 1, 2], [0, 2, 3]],
                 "vertices": [[-3, -3, -1], [3, -3, -1], [3, 3, -1], [-3, 3, -1]]}]}


@pytest.fixture(scope="module")
def half_mask(tmp_path_factory):
    """A 2 x 2 opacity texture: opaque in its left column (u < 0.5), clear in its right."""
    path = str(tmp_path_factory.mktemp("alpha") / "half.npy")
    a = np.zeros((2, 2, 1), np.float32)
    a[:, 0] = 1.0
    np.save(path, a)
    return {"texture": path, "filter": "nearest", "wrap": ["clamp", "clamp"]}


def test_a_masked_quad_renders_as_the_shape_cut_in_geometry(half_mask):
    masked = pt.render(shadow_scene(half_mask), spp=32, backend="cpu", seed=1).image
    cut = pt.render(shadow_scene(cut=True), spp=32, backend="cpu", seed=1).image
    whole = pt.render(shadow_scene(), spp=32, backend="cpu", seed=1).image
    assert relmse(masked, cut) < 1e-8, relmse(masked, cut)
    # (and the cut-out matters: the whole leaf's image is another one)
    assert relmse(whole, cut) > 1e-2


def test_stochastic_transparency_converges_to_the_alpha_weighted_mean():
    spp = 512
    blend = pt.render(blend_scene(0.3), spp=spp, backend="cpu", seed=1).image
    again = pt.render(blend_scene(0.3), spp=spp, backend="cpu", seed=2).image
    opaque = pt.render(blend_scene(0.3, "opaque"), spp=spp, backend="cpu", seed=3).image
    clear = pt.render(blend_scene(0.0), spp=spp, backend="cpu", seed=4).image
    mix = 0.3 * opaque + 0.7 * clear
    # the difference from the mixture is noise: about that between two seeds of the blend
    # (measured 4.4e-5 against 8.7e-5 at 1,024 spp), and far below the gap to either end
    noise = relmse(blend, again)
    assert relmse(blend, mix) < 3 * noise, (relmse(blend, mix), noise)
    assert relmse(blend, opaque) > 30 * noise and relmse(blend, clear) > 30 * noise
    np.testing.assert_allclose(blend.mean((0, 1)), mix.mean((0, 1)), rtol=0.01)


def test_alpha_extremes_are_opaque_and_clear():
    """Interpreted: blend at opacity 1 is the opaque image and at 0 the cleared one, bit for
    bit; an opaque mode ignores the opacity."""
    def image(alpha, mode):
        return pt.render(blend_scene(alpha, mode, res=(6, 6)), spp=4, backend="python",
                         seed=1).image
    np.testing.assert_array_equal(image(1.0, "blend"), image(0.3, "opaque"))
    np.testing.assert_array_equal(image(0.0, "blend"), image(0.0, "mask"))
    assert not np.array_equal(image(0.0, "blend"), image(1.0, "blend"))


def test_scenes_without_alpha_compile_none_of_it(half_mask):
    assert not pt.load_scene(shadow_scene()).compiled.features.alpha
    assert not pt.load_scene(shadow_scene(0.3, "opaque")).compiled.features.alpha
    scene = pt.load_scene(shadow_scene(half_mask))
    assert scene.compiled.features.alpha
    mat = scene.compiled.arrays.mat
    assert (mat[:, L.M_ALPHA_MODE] == L.ALPHA_MASK).sum() == 1
    assert (scene.compiled.arrays.mat_tex[:, L.T_ALPHA] >= 0).sum() == 1


@pytest.mark.parametrize("material, message", [
    ({"alpha": 1.5, "alphaMode": "blend"}, "alpha"),
    ({"alpha": 0.5, "alphaMode": "cutout"}, "alphaMode"),
    ({"alpha": 0.5, "alphaMode": "mask", "alphaCutoff": -0.1}, "alphaCutoff"),
])
def test_bad_alpha_keys_are_one_line_errors(material, message):
    scene = blend_scene(0.5)
    scene["materials"][0] = {"name": "q", "type": "diffuse", **material}
    with pytest.raises(SceneError) as e:
        pt.load_scene(scene)
    assert message in str(e.value) and "\n" not in str(e.value)


def _gltf_quad(tmp_path, mode, factor_alpha, cutoff=None):
    """A glTF quad whose base colour has alpha ``factor_alpha`` and alphaMode ``mode``."""
    import base64
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    data = pos.tobytes() + idx.tobytes()
    material = {"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0.2, factor_alpha]},
                "alphaMode": mode}
    if cutoff is not None:
        material["alphaCutoff"] = cutoff
    gltf = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
                                    "material": 0}]}],
        "materials": [material],
        "buffers": [{"byteLength": len(data), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [-1, -1, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}]}
    path = os.path.join(str(tmp_path), f"quad-{mode}.gltf")
    with open(path, "w") as f:
        json.dump(gltf, f)
    return path


@pytest.mark.parametrize("mode, alpha, cutoff, expect", [
    ("OPAQUE", 0.2, None, L.ALPHA_OPAQUE),
    ("MASK", 0.2, 0.1, L.ALPHA_MASK),
    ("MASK", 0.2, None, L.ALPHA_MASK),
    ("BLEND", 0.2, None, L.ALPHA_BLEND),
])
def test_gltf_alpha_modes_are_read(tmp_path, recwarn, mode, alpha, cutoff, expect):
    scene = pt.load_scene(_gltf_quad(tmp_path, mode, alpha, cutoff))
    mat = scene.compiled.arrays.mat
    rows = mat[mat[:, L.M_ALPHA_MODE] == expect]
    assert len(rows) >= 1
    if expect != L.ALPHA_OPAQUE:
        assert np.isclose(rows[0, L.M_ALPHA], alpha)
        assert np.isclose(rows[0, L.M_ALPHA_CUTOFF], 0.5 if cutoff is None else cutoff) \
            or expect == L.ALPHA_BLEND
    assert not any("alphaMode" in str(w.message) for w in recwarn)
