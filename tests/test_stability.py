"""Numerical stability on stiff and extreme inputs: no NaN or Inf anywhere (the renderer
never clamps or drops samples, it counts non-finite ones), and images that do not depend
on the scene's scale or position."""
import json
import math
import os

import numpy as np
import pytest

from pathtracer.kernels.principled import principled_eval, principled_sample
from pathtracer.scene import load_scene
from tests.conftest import ROOT, SHARED, needs_shared
from tests.helpers import sphere_mesh, write_scene
from tests.helpers import principled_params as params
from tests.helpers import mean_and_se, run

F = np.float32
CORNELL = os.path.join(ROOT, "scenes", "cornell-box.json")


@pytest.mark.parametrize("kw", [
    dict(roughness=0.0), dict(roughness=1.0), dict(metallic=1.0, roughness=0.0),
    dict(transmission=1.0, roughness=0.0, eta=1.0), dict(transmission=1.0, eta=1.0001),
    dict(transmission=1.0, roughness=0.0, eta=1.0001), dict(transmission=1.0, eta=3.0),
    dict(transmission=1.0, roughness=1.0, eta=0.3), dict(anisotropic=1.0, roughness=0.0),
    dict(clearcoat=1.0, clearcoat_gloss=1.0, roughness=0.0, sheen=1.0, flatness=1.0),
])
def test_bsdf_finite_at_extremes(kw):
    """eval, pdf and sample stay finite for extreme parameters and grazing directions
    (eta exactly 1 with transmission becomes 1.001, as Mitsuba; see the integrator)."""
    p = params(**kw)
    if p[5] == 1.0 and p[13] > 0:
        p = p[:5] + (F(1.001),) + p[6:]
    rng = np.random.default_rng(1)
    for cz in (1.0, 0.5, 1e-3, 1e-6, -1e-6, -1e-3, -0.5, -1.0):
        s = math.sqrt(max(0.0, 1 - cz * cz))
        wo = (F(s), F(0), F(cz))
        for _ in range(300):
            u = rng.random(3).astype(F)
            wi, w, pdf = principled_sample(p, wo, u[0], u[1], u[2])
            assert np.isfinite(pdf) and pdf >= 0
            assert np.all(np.isfinite(w)) and np.all(np.asarray(w) >= 0)
            if pdf > 0:
                assert abs(np.linalg.norm(wi) - 1) < 1e-3
            v = rng.normal(size=3)
            v[2] = v[2] * 1e-4 if rng.random() < 0.3 else v[2]
            v = tuple(F(x) for x in v / np.linalg.norm(v))
            f, pdf2 = principled_eval(p, wo, v)
            assert np.isfinite(pdf2) and np.all(np.isfinite(f)), (kw, wo, v)


def _sphere_scene(material, env, res=24):
    v, f = sphere_mesh(12, 24)
    return {"camera": {"resolution": [res, res], "position": [0, 0.2, 3.5],
                       "lookAt": [0, 0, 0], "fov": 40},
            "render": {"spp": 16, "maxBounces": 12},
            "materials": [dict(material, name="m")],
            "objects": [{"name": "s", "vertices": v, "faces": f, "material": "m",
                         "smooth": True}],
            "environment": env}


@needs_shared
@pytest.mark.parametrize("material", [
    {"roughness": 0.0, "metallic": 1.0}, {"roughness": 1.0},
    {"transmission": 1.0, "roughness": 0.0, "eta": 1.0},
    {"transmission": 1.0, "roughness": 0.0, "eta": 1.0001},
    {"transmission": 1.0, "roughness": 0.05, "eta": 3.0},
    {"transmission": 0.5, "roughness": 0.2, "clearcoat": 1.0, "clearcoatGloss": 1.0},
])
def test_sun_hdri_full_strength(tmp_path, material):
    """The rooitou park HDRI has a sun of ~65,000: every sample must stay finite."""
    env = {"file": os.path.join(SHARED, "assets", "hdri", "rooitou_park_1k.hdr")}
    s = load_scene(write_scene(tmp_path, _sphere_scene(material, env)))
    img = run(s, "cpu", spp=16).film.image()    # run() asserts no non-finite sample
    assert np.isfinite(img).all() and img.min() >= 0


def test_degenerate_triangles(tmp_path):
    """Zero-area triangles, slivers, and two coincident faces with different materials."""
    v = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, 0, 0], [1e-7, 0, 0],
         [2, 1e-8, 0], [-2, 0, 0]]
    faces = [[0, 1, 2], [0, 2, 3], [4, 4, 5], [4, 5, 6], [4, 6, 7], [0, 0, 0]]
    scene = {"camera": {"resolution": [16, 16], "position": [0.1, 0.2, 3], "lookAt": [0, 0, 0]},
             "materials": [{"name": "a", "type": "diffuse", "albedo": 0.5},
                           {"name": "b", "albedo": 0.9, "emission": 2.0}],
             "objects": [{"name": "p", "vertices": v, "faces": faces, "material": "a"},
                         {"name": "q", "vertices": v, "faces": faces[:2], "material": "b"}],
             "lights": [{"position": [0, 0, 2], "intensity": 3}],
             "environment": {"color": 0.2}}
    s = load_scene(write_scene(tmp_path, scene))
    img = run(s, "cpu", spp=16).film.image()
    assert np.isfinite(img).all()


def _cornell(transform, cam_map):
    scene = json.load(open(CORNELL))
    scene["objects"][0]["file"] = os.path.join(ROOT, "scenes", "cornell-box", "cbox.obj")
    scene["objects"][0]["transform"] = transform
    cam = scene["camera"]
    cam["position"] = cam_map(np.array(cam["position"], float)).tolist()
    cam["lookAt"] = cam_map(np.array(cam["lookAt"], float)).tolist()
    cam["resolution"] = [32, 32]
    return scene


@pytest.mark.parametrize("name,transform,cam_map", [
    ("scaled 1e-4", {"scale": 1e-4}, lambda p: p * 1e-4),
    ("scaled 1e4", {"scale": 1e4}, lambda p: p * 1e4),
    ("moved 1e5", {"translate": [1e5, -1e5, 1e5]}, lambda p: p + [1e5, -1e5, 1e5]),
])
def test_scale_and_position_invariance(tmp_path, name, transform, cam_map):
    """Ray offsets are relative and the scene is re-centred before float32 rounding, so a
    scaled or far-moved Cornell box renders the plain one's image within noise."""
    plain = load_scene(write_scene(tmp_path, _cornell({}, lambda p: p), "plain.json"))
    other = load_scene(write_scene(tmp_path, _cornell(transform, cam_map), "other.json"))
    a = run(plain, "cpu", spp=64).film.image()
    b = run(other, "cpu", spp=64, seed=1).film.image()
    ma, sa = mean_and_se(a)
    mb, sb = mean_and_se(b)
    assert np.all(np.abs(ma - mb) < 4 * np.hypot(sa, sb)), (name, ma, mb)
    # per pixel: the difference to the plain image is no larger than between two seeds
    a2 = run(plain, "cpu", spp=64, seed=2).film.image()
    assert ((a - b) ** 2).mean() < 1.3 * ((a - a2) ** 2).mean(), name



def test_shadow_terminator_lift_reaches_the_smooth_surface():
    """On a coarse sphere (vertices on the unit sphere, exact vertex normals) the lifted
    point moves outwards only and lands closer to the sphere than the facet point; on a
    flat patch (equal normals) it does not move."""
    from pathtracer.kernels.surface import terminator_lift
    rng = np.random.default_rng(4)
    ratios = []
    for _ in range(200):
        v = rng.normal(size=(3, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        v = v[0] + 0.5 * (v - v[0])          # a facet of about 30 degrees
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        e1, e2 = v[1] - v[0], v[2] - v[0]
        ng = np.cross(e1, e2)
        ng /= np.linalg.norm(ng)
        if ng @ v[0] < 0:
            ng = -ng
        b1, b2 = rng.random(2) * 0.5
        p = v[0] + b1 * e1 + b2 * e2
        f = lambda x: tuple(F(c) for c in x)
        q = np.array(terminator_lift(f(p), F(b1), F(b2), f(v[0]), f(e1), f(e2), f(v[0]),
                                     f(v[1]), f(v[2]), f(ng)))
        gap = 1 - np.linalg.norm(p)
        assert (q - p) @ ng >= -1e-6                      # outwards only
        ratios.append(abs(1 - np.linalg.norm(q)) / gap)
    # distance to the true surface: 0.58 of the facet point's on average (measured), never
    # worse; without the lift the ratio is 1
    assert np.mean(ratios) < 0.7 and np.max(ratios) < 1.0, (np.mean(ratios), np.max(ratios))
    flat = terminator_lift(f(p), F(0.2), F(0.3), f(v[0]), f(e1), f(e2), f(ng), f(ng), f(ng),
                           f(ng))
    assert np.allclose(flat, p, atol=1e-6)
