"""The benchmark's scenes: the four of the error-against-time study and the mesh scenes of
the BVH and scaling studies. Scenes that need data from ../shared are built here as scene
dictionaries (the scene format), so that ``PT_RENDER_SHARED`` can point at a copy."""
import json
import os
import sys
import tempfile

import numpy as np

from bench.common import CORNELL, CORNELL_REF, ROOT, SHARED, mitsuba_cornell

SCENES_DIR = os.path.join(ROOT, "scenes")
MODELS = os.path.join(SHARED, "assets", "models")
HDRI = os.path.join(SHARED, "assets", "hdri")
REFERENCES = os.path.join(ROOT, "bench", "references")


def describe(scene):
    """A SceneDescription from a scene dictionary (paths in it absolute)."""
    from pathtracer.scene import load_scene_description
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(scene, f)
    try:
        return load_scene_description(f.name)
    finally:
        os.unlink(f.name)


def fit_matrix(obj, size=1.0, floor=None):
    """A transform matrix scaling the OBJ's largest extent to ``size`` and centring it, or, with
    ``floor``, standing it on the plane y = floor."""
    from pathtracer.scene.meshes import load_obj
    pos = load_obj(obj).positions.reshape(-1, 3).astype(np.float64)
    lo, hi = pos.min(0), pos.max(0)
    s = size / float((hi - lo).max())
    t = -s * (lo + hi) / 2
    if floor is not None:
        t[1] = floor - s * lo[1]
    return [[s, 0, 0, t[0]], [0, s, 0, t[1]], [0, 0, s, t[2]], [0, 0, 0, 1]]


def _ground(material):
    return {"name": "ground", "file": os.path.join(SCENES_DIR, "assets", "plane.obj"),
            "material": material, "transform": {"scale": [8, 1, 8]}}


def bunny_studio(res):
    """The full Stanford bunny (69k triangles, smooth) in a glossy principled material on a
    diffuse floor, lit only by the studio HDRI (small bright softboxes)."""
    bunny = os.path.join(MODELS, "stanford_bunny.obj")
    return {
        "camera": {"resolution": list(res), "position": [0.4, 1.0, 3.2],
                   "lookAt": [0, 0.4, 0], "fov": 30},
        "render": {"maxBounces": 8},
        "materials": [{"name": "floor", "type": "diffuse", "albedo": 0.6},
                      {"name": "bunny", "albedo": [0.75, 0.45, 0.25], "roughness": 0.35,
                       "clearcoat": 0.5}],
        "objects": [_ground("floor"),
                    {"name": "bunny", "file": bunny, "material": "bunny", "smooth": True,
                     "transform": {"matrix": fit_matrix(bunny, 1.0, floor=0.0)}}],
        "environment": {"file": os.path.join(HDRI, "studio_small_03_1k.hdr"), "rotation": 60,
                        "intensity": 0.5},
    }


def sun(res):
    """Suzanne (rough gold) and a diffuse sphere on a floor under rooitou park, whose
    unclipped sun (about 65% of the map's power in 0.02% of its texels) casts hard shadows:
    the hard case for environment sampling. This Suzanne carries its own vertex normals, so
    that Mitsuba shades it with the same normals (each renderer computes missing ones its
    own way)."""
    suzanne = os.path.join(MODELS, "suzanne.obj")
    sphere = os.path.join(SCENES_DIR, "assets", "sphere.obj")
    return {
        "camera": {"resolution": list(res), "position": [0.0, 1.3, 2.6],
                   "lookAt": [0, 0.35, 0], "fov": 36},
        "render": {"maxBounces": 8},
        "materials": [{"name": "floor", "type": "diffuse", "albedo": 0.5},
                      {"name": "gold", "albedo": [1.0, 0.78, 0.34], "metallic": 1.0,
                       "roughness": 0.3},
                      {"name": "white", "type": "diffuse", "albedo": 0.8}],
        "objects": [_ground("floor"),
                    {"name": "suzanne", "file": suzanne, "material": "gold", "smooth": True,
                     "transform": {"matrix": fit_matrix(suzanne, 0.9, floor=0.0)}},
                    {"name": "ball", "file": sphere, "material": "white", "smooth": True,
                     "transform": {"scale": 0.3, "translate": [0.8, 0.3, -0.3]}}],
        "environment": {"file": os.path.join(HDRI, "rooitou_park_1k.hdr"), "rotation": 100},
    }


def lamps(res, light_sampler="auto", punctual=True):
    """The Stanford bunny (principled, smooth) on a diffuse floor lit by many small lights:
    an 8 x 8 grid of lamps (one-sided squares facing down, 128 triangles in 64 colours and
    powers) spread over a floor far wider than the view, a small emissive sphere beside
    the bunny (2,240 triangles), and with ``punctual`` a spot light from above and a point
    light: most lights are far from most shading points, the case the light tree
    (render.lightSampler) is for. Without ``punctual`` Mitsuba renders it too (area
    lights only)."""
    bunny = os.path.join(MODELS, "stanford_bunny.obj")
    plane = os.path.join(SCENES_DIR, "assets", "plane.obj")
    rng = np.random.default_rng(7)
    materials = [{"name": "floor", "type": "diffuse", "albedo": 0.6},
                 {"name": "bunny", "albedo": [0.75, 0.45, 0.25], "roughness": 0.35},
                 {"name": "bulb", "type": "diffuse", "albedo": 0.0,
                  "emission": [40.0, 30.0, 20.0]}]
    objects = [_ground("floor"),
               {"name": "bunny", "file": bunny, "material": "bunny", "smooth": True,
                "transform": {"matrix": fit_matrix(bunny, 1.0, floor=0.0)}},
               {"name": "bulb", "file": os.path.join(SCENES_DIR, "assets", "sphere.obj"),
                "material": "bulb", "transform": {"scale": 0.05, "translate": [0.7, 0.3, 0.3]}}]
    for i in range(8):
        for j in range(8):
            x, z, s = -7 + 2 * i, -7 + 2 * j, 0.12
            name = f"lamp{i}{j}"
            materials.append({"name": name, "type": "diffuse", "albedo": 0.0,
                              "emission": (rng.random(3) * 6 + 1).round(2).tolist()})
            # the unit plane (facing +y) turned 180 degrees about x: facing down
            objects.append({"name": name, "file": plane, "material": name,
                            "transform": {"matrix": [[s, 0, 0, x], [0, -s, 0, 1.5],
                                                     [0, 0, -s, z], [0, 0, 0, 1]]}})
    scene = {
        "camera": {"resolution": list(res), "position": [0.4, 1.0, 3.2],
                   "lookAt": [0, 0.4, 0], "fov": 40},
        "render": {"maxBounces": 8, "lightSampler": light_sampler},
        "materials": materials, "objects": objects,
    }
    if punctual:
        scene["lights"] = [{"type": "spot", "position": [0, 2.5, 0], "intensity": 4,
                            "direction": [0, -1, 0], "innerAngle": 10, "outerAngle": 25},
                           {"type": "point", "position": [-1.5, 1.2, 1.0], "intensity": 0.5}]
    return scene


# name: (description builder or scene file, resolution); the reference of every scene but the
# Cornell box (whose reference is Mitsuba's) is ours at high spp: `python -m bench.references`
CONVERGENCE = {
    "cornell-box": (CORNELL, (256, 256)),
    "bunny-studio": (bunny_studio, (256, 192)),
    "textured": (os.path.join(SCENES_DIR, "textured.json"), (256, 192)),
    "sun": (sun, (256, 192)),
}


def convergence_desc(name):
    from pathtracer.scene import load_scene_description
    source, res = CONVERGENCE[name]
    desc = describe(source(res)) if callable(source) else load_scene_description(source)
    desc.camera.resolution = res
    return desc


def convergence_scene(name, sampler=None):
    """The convergence scene ``name`` as a Python-API Scene (pathtracer.load_scene) at its
    benchmark resolution; ``sampler`` overrides the scene's."""
    from pathtracer.api import load_scene
    source, res = CONVERGENCE[name]
    overrides = {"resolution": res, "sampler": sampler}
    if callable(source):
        return load_scene(source(res), _overrides=overrides)
    return load_scene(source, _overrides=overrides)


def reference_path(name, mitsuba=False):
    return os.path.join(REFERENCES, f"{name}{'-mitsuba' if mitsuba else ''}.npz")


def load_reference(name, mitsuba=False):
    """(image, metadata) of a scene's reference (ours, or with ``mitsuba`` Mitsuba's own);
    FileNotFoundError when it was not made. The Cornell box has one: Mitsuba's."""
    if name == "cornell-box":
        return np.load(CORNELL_REF), {"source": "Mitsuba 3 (shared/reference/cornell-box)"}
    with np.load(reference_path(name, mitsuba), allow_pickle=False) as z:
        return z["image"], json.loads(str(z["meta"]))


def mesh_desc(obj, res, bounces=3):
    """A mesh (scaled to unit size) in a white-furnace-like setting: diffuse 0.8, a constant
    sky, seen whole; 3 bounces. Traversal dominates its cost."""
    obj = os.path.abspath(obj)
    return describe({
        "camera": {"resolution": list(res), "position": [0.3, 0.4, 2.2], "lookAt": [0, 0, 0],
                   "fov": 35},
        "render": {"maxBounces": bounces},
        "materials": [{"name": "m", "type": "diffuse", "albedo": 0.8}],
        "objects": [{"name": "o", "file": obj, "material": "m", "smooth": False,
                     "transform": {"matrix": fit_matrix(obj)}}],
        "environment": {"color": 1.0}})


def grazing_plane(folder, filt, res=(64, 32), spp=4):
    """A black-and-white checkerboard plane seen at grazing angles under a uniform sky of
    1, direct light only (a diffuse albedo a reflects exactly a, so all noise is the
    texture's): what aliases without mip-maps (issue 14's texture-filtering check). Writes
    the texture, the plane and ``<filt>.json`` into ``folder``; returns the scene's path."""
    import imageio.v3 as iio
    n, sq = 256, 32
    yy, xx = np.mgrid[0:n, 0:n]
    chk = ((xx // sq + yy // sq) % 2 * 255).astype(np.uint8)
    iio.imwrite(os.path.join(folder, "chk.png"), np.repeat(chk[:, :, None], 3, 2))
    with open(os.path.join(folder, "plane.obj"), "w") as f:
        f.write("v -1 0 1\nv 1 0 1\nv 1 0 -1\nv -1 0 -1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                "vn 0 1 0\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")
    scene = {"camera": {"resolution": list(res), "position": [0, 0.5, 0],
                        "lookAt": [0, 0, -6], "fov": 40},
             "render": {"spp": spp, "maxBounces": 1},
             "materials": [{"name": "m", "type": "diffuse",
                            "albedo": {"texture": "chk.png", "filter": filt,
                                       "tile": [50, 50]}}],
             "objects": [{"name": "p", "file": "plane.obj", "material": "m",
                          "transform": {"scale": 50}}],
             "environment": {"color": 1.0}}
    path = os.path.join(folder, f"{filt}.json")
    with open(path, "w") as f:
        json.dump(scene, f)
    return path


def mitsuba_scene(name, sampler):
    """Mitsuba's scene of a convergence scene with its sampler of type ``sampler``, and its
    reference; None when Mitsuba cannot render it."""
    import mitsuba as mi

    from pathtracer.mitsuba import NotExpressible, mitsuba_dict
    try:
        ref, _ = load_reference(name, mitsuba=True)
        scene = (mitsuba_cornell(ref.shape[1], ref.shape[0], 1, sampler=sampler)
                 if name == "cornell-box" else
                 mi.load_dict(mitsuba_dict(convergence_desc(name), sampler=sampler)))
    except (FileNotFoundError, NotExpressible) as e:
        print(f"bench: no Mitsuba renders of {name}: {e}", file=sys.stderr)
        return None
    return scene, ref
