"""Scene descriptions translated to Mitsuba 3 scene dictionaries (``mitsuba.load_dict``): the
peer renderer of the benchmarks and of the agreement tests.

Only what both renderers express the same way is translated: a pinhole camera with lookAt,
OBJ and PLY meshes with a transform, diffuse and principled materials, their image textures
and normal maps, and a constant or HDRI environment. Anything else raises NotExpressible,
and the benchmark leaves Mitsuba out of that scene.

Textures become Mitsuba's ``bitmap``: sRGB-decoded or ``raw``, with the same wrap mode and
the scene's tile and offset as its ``to_uv``. Mitsuba has no mip-maps, so a ``trilinear``
texture (our default) is looked up bilinearly there: the same image where a texture is
magnified, a sharper (aliased) one where it is minified. A number parameter read from a
colour image is the image's luminance in both renderers.
"""
import os

import numpy as np

from .kernels.layout import MATERIAL_PARAMS

# scene-format principled parameter -> Mitsuba `principled` parameter (the parameter table)
MITSUBA_NAMES = {p.key: p.mitsuba for p in MATERIAL_PARAMS if p.mitsuba}


class NotExpressible(ValueError):
    pass


def mitsuba_bsdf(material):
    """Mitsuba BSDF of a material given in the scene format's names (a dict)."""
    if material.get("type") == "diffuse":
        return {"type": "diffuse", "reflectance": _rgb(material["albedo"])}
    if material.get("type") == "conductor":
        au = material.get("alphaU", 0.0)
        return {"type": "roughconductor", "distribution": material.get("distribution", "ggx"),
                "alpha_u": au, "alpha_v": material.get("alphaV", au),
                "eta": _rgb(material.get("eta", [0.0] * 3)),
                "k": _rgb(material.get("k", [1.0] * 3)),
                "specular_reflectance": _rgb(material.get("albedo", [1.0] * 3))}
    if material.get("roughness") == 0.0 and material.get("transmission") == 1.0:
        return {"type": "dielectric", "int_ior": material["eta"], "ext_ior": 1.0}
    out = {"type": "principled"}
    for k, v in material.items():
        if k == "albedo":
            out["base_color"] = _rgb(v)
        elif k != "type":
            out[MITSUBA_NAMES[k]] = v
    return out


def _rgb(v):
    """A colour given as [r, g, b], or a Mitsuba texture dictionary as it is."""
    return v if isinstance(v, dict) else {"type": "rgb", "value": v}


# Mitsuba 3's principled takes textures for these parameters only (eta and specular are
# plain floats there)
TEXTURABLE = {"albedo", "roughness", "metallic", "specularTint", "anisotropic", "sheen",
              "sheenTint", "clearcoat", "clearcoatGloss", "subsurface", "transmission"}


def mitsuba_texture(spec, what, flip_v=True):
    """Mitsuba's ``bitmap`` of a TextureSpec. ``flip_v``: the mesh loader turns v into
    1 - v (Mitsuba's OBJ loader does, as its bitmaps count rows from the top; the scene
    format's v = 0 is the bottom row), so that the lookup at our (u, v), tiled as
    (u tile + offset), is Mitsuba's at to_uv (u, v')."""
    import mitsuba as mi
    if not os.path.isfile(spec.path) or spec.channel is not None:
        raise NotExpressible(f"{what}: a texture that is not an image file, or one channel "
                             "of an image")
    if tuple(spec.scale) != (1.0, 1.0, 1.0):
        raise NotExpressible(f"{what}: a texture with a scale")
    if spec.wrap[0] != spec.wrap[1]:
        raise NotExpressible(f"{what}: different wrap modes along u and v")
    (tu, tv), (ou, ov) = spec.tile, spec.offset
    # our texel row from the bottom is v tile + offset; Mitsuba's row from the top is
    # to_uv's v: with v' = 1 - v that is tv v' + (1 - ov - tv), without the flip -tv v + 1 - ov
    sv, bv = (tv, 1.0 - ov - tv) if flip_v else (-tv, 1.0 - ov)
    T = mi.ScalarTransform4f
    return {"type": "bitmap", "filename": spec.path, "raw": spec.color_space != "sRGB",
            "filter_type": "nearest" if spec.filter == "nearest" else "bilinear",
            "wrap_mode": spec.wrap[0],
            "to_uv": T().translate([float(ou), float(bv), 0.0]) @ T().scale(
                [float(tu), float(sv), 1.0])}


def _material(m, flip_v=True):
    if "emission" in m.textures or (any(m.emission) and m.two_sided):
        raise NotExpressible(f"material {m.name}: a textured or two-sided emission")
    d = {"type": m.type, "albedo": list(m.albedo)}
    if m.type == "principled":
        d.update(m.numbers)
    for key, spec in m.textures.items():
        if key not in TEXTURABLE:
            raise NotExpressible(f"material {m.name}: a texture for {key}")
        d[key] = mitsuba_texture(spec, f"material {m.name}, {key}", flip_v)
    bsdf = mitsuba_bsdf(d)
    if m.normal_map is not None:
        bsdf = {"type": "normalmap", "bsdf": bsdf,
                "normalmap": mitsuba_texture(m.normal_map, f"material {m.name}, normal map",
                                             flip_v)}
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
    if desc.point_lights or desc.directional_lights:
        raise NotExpressible("point or directional lights")
    w, h = cam.resolution
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": desc.render.max_bounces + 1,
                        "hide_emitters": desc.render.hide_emitters,
                        "rr_depth": desc.render.rr_depth},
         "sensor": {"type": "perspective", "fov": cam.fov, "fov_axis": "x",
                    "to_world": T().look_at(origin=list(cam.position),
                                            target=list(cam.look_at), up=list(cam.up)),
                    "film": {"type": "hdrfilm", "width": w, "height": h,
                             "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                    "sampler": {"type": sampler, "sample_count": spp}}}
    kinds = {}
    for i, o in enumerate(desc.objects):
        if o.file is None or o.material is None:
            raise NotExpressible(f"object {o.name}: inline mesh or OBJ materials")
        kind = os.path.splitext(o.file)[1].lower().lstrip(".")
        if kind not in ("obj", "ply"):
            raise NotExpressible(f"object {o.name}: a {kind or 'file'} mesh")
        kinds.setdefault(o.material, set()).add(kind)
    for name, m in desc.materials.items():
        used = kinds.get(name, {"obj"})
        if len(used) > 1 and (m.textures or m.normal_map is not None):
            raise NotExpressible(f"material {name}: textures on both OBJ and PLY meshes")
        # Mitsuba's OBJ loader flips v, its PLY loader does not
        d["mat-" + name] = _material(m, flip_v="obj" in used)
    for i, o in enumerate(desc.objects):
        kind = os.path.splitext(o.file)[1].lower().lstrip(".")
        d[f"obj-{i}"] = {"type": kind, "filename": o.file, "face_normals": not o.smooth,
                         "to_world": T(np.asarray(o.matrix, float).tolist()),
                         "bsdf": {"type": "ref", "id": "mat-" + o.material}}
        emission = desc.materials[o.material].emission
        if any(emission):
            # an area light on the front side, as ours (a one-sided emission)
            d[f"obj-{i}"]["emitter"] = {"type": "area",
                                        "radiance": {"type": "rgb", "value": list(emission)}}
    env = desc.environment
    if env is None:
        pass
    elif isinstance(env, tuple):
        d["env"] = {"type": "constant", "radiance": {"type": "rgb", "value": list(env)}}
    else:
        # Mitsuba's envmap turned 180 degrees about +Y is the scene format's mapping; the
        # scene's rotation (counter-clockwise seen from above) adds to it
        m = np.eye(4)
        m[:3, :3] = env.world_from_map() @ np.diag([-1.0, 1.0, -1.0])
        d["env"] = {"type": "envmap", "filename": env.path, "scale": env.intensity,
                    "to_world": T(m)}
    return d
