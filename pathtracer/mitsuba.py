"""Scene descriptions translated to Mitsuba 3 scene dictionaries (``mitsuba.load_dict``): the
peer renderer of the benchmarks and of the agreement tests.

Only what both renderers express the same way is translated: a pinhole camera with lookAt,
OBJ meshes with a transform, diffuse and principled materials without textures, and a
constant or HDRI environment. Anything else raises NotExpressible, and the benchmark leaves
Mitsuba out of that scene.
"""
import numpy as np

from .kernels.layout import MATERIAL_PARAMS

# scene-format principled parameter -> Mitsuba `principled` parameter (the parameter table)
MITSUBA_NAMES = {p.key: p.mitsuba for p in MATERIAL_PARAMS if p.mitsuba}


class NotExpressible(ValueError):
    pass


def mitsuba_bsdf(material):
    """Mitsuba BSDF of a material given in the scene format's names (a dict)."""
    if material.get("type") == "diffuse":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": material["albedo"]}}
    if material.get("roughness") == 0.0 and material.get("transmission") == 1.0:
        return {"type": "dielectric", "int_ior": material["eta"], "ext_ior": 1.0}
    out = {"type": "principled"}
    for k, v in material.items():
        if k == "albedo":
            out["base_color"] = {"type": "rgb", "value": v}
        elif k != "type":
            out[MITSUBA_NAMES[k]] = v
    return out


def _material(m):
    if m.textures or m.normal_map is not None or any(m.emission):
        raise NotExpressible(f"material {m.name}: textures or emission")
    d = {"type": m.type, "albedo": list(m.albedo)}
    if m.type == "principled":
        d.update(m.numbers)
    bsdf = mitsuba_bsdf(d)
    # our surfaces reflect on both sides; Mitsuba's reflect on the front only
    return bsdf if d.get("transmission", 0) > 0 else {"type": "twosided", "bsdf": bsdf}


def mitsuba_dict(desc, spp=1, sampler="independent"):
    """The Mitsuba scene dictionary of a SceneDescription (raises NotExpressible); ``sampler``
    is the type of Mitsuba's sampler (independent, stratified, multijitter, ldsampler, ...)."""
    import mitsuba as mi
    T = mi.ScalarTransform4f
    cam = desc.camera
    if cam.look_at is None or cam.lens_radius > 0:
        raise NotExpressible("camera without lookAt, or a thin lens")
    if desc.point_lights:
        raise NotExpressible("point lights")
    w, h = cam.resolution
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": desc.render.max_bounces + 1,
                        "rr_depth": desc.render.rr_depth},
         "sensor": {"type": "perspective", "fov": cam.fov, "fov_axis": "x",
                    "to_world": T().look_at(origin=list(cam.position),
                                            target=list(cam.look_at), up=list(cam.up)),
                    "film": {"type": "hdrfilm", "width": w, "height": h,
                             "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                    "sampler": {"type": sampler, "sample_count": spp}}}
    for name, m in desc.materials.items():
        d["mat-" + name] = _material(m)
    for i, o in enumerate(desc.objects):
        if o.file is None or o.material is None:
            raise NotExpressible(f"object {o.name}: inline mesh or OBJ materials")
        d[f"obj-{i}"] = {"type": "obj", "filename": o.file, "face_normals": not o.smooth,
                         "to_world": T(np.asarray(o.matrix, float).tolist()),
                         "bsdf": {"type": "ref", "id": "mat-" + o.material}}
    env = desc.environment
    if env is None:
        pass
    elif isinstance(env, tuple):
        d["env"] = {"type": "constant", "radiance": {"type": "rgb", "value": list(env)}}
    else:
        # Mitsuba's envmap turned 180 degrees about +Y is the scene format's mapping; the
        # scene's rotation (counter-clockwise seen from above) adds to it
        d["env"] = {"type": "envmap", "filename": env.path, "scale": env.intensity,
                    "to_world": T().rotate([0, 1, 0], 180 + env.rotation)}
    return d
