"""The thesis renderer's scene folders ("Eleven", ../shared/seed/seed-study.md sec. 2.1).

Layout: ``scene.json`` in a lenient JSON dialect (single quotes, unquoted keys, trailing
commas; read with the ``json5`` library), ``Objects/<object>.obj``,
``Textures/<material>_<map>.bmp`` (map: albedo, emission, roughness, metallic, normal; a
file overrides the material's value) and ``HDRI/<name>.hdr``.

Framing: that renderer's camera looks along +Z with +Y up and image x along +X, and it
flips OBJ z on load. That is our right-handed space mirrored in z, so the folder is read
into our space by mirroring the camera instead: position z negated, Euler angles about X and
Y negated (M R M with M = diag(1, 1, -1)), meshes as they are in the files. The image is
the same; its default sensor is 35 mm wide.

A material that gives no value at all (ClockCC0's) is a textured PBR material: its albedo,
roughness, metallic and normal maps are expected, and their absence is reported with every
other missing file. With ``allow_missing`` a missing object is left out, a missing map
keeps the default value, a missing HDRI becomes a grey environment, each with a warning.
"""
import os
import re

from .errors import SceneError

MAPS = ("albedo", "emission", "roughness", "metallic", "normal")
EXPECTED_MAPS = ("albedo", "roughness", "metallic", "normal")
THESIS_SENSOR_WIDTH = 0.035
UNIT_RE = re.compile(r"(?<=[0-9])[ \t]+m(?=[ \t]*[,}\]])")


def is_thesis_folder(path):
    return os.path.isdir(path) and os.path.isfile(os.path.join(path, "scene.json"))


def is_thesis_scene_file(path):
    """FOLDER/scene.json of a thesis folder: one with an Objects/ folder beside it."""
    folder = os.path.dirname(path)
    return os.path.basename(path) == "scene.json" and os.path.isdir(
        os.path.join(folder, "Objects"))


def read_lenient(path, warnings):
    try:
        import json5
    except ImportError:   # pragma: no cover - a declared dependency
        raise SceneError("reading thesis scene folders needs the json5 package", path)
    try:
        with open(path, "r", encoding="utf-8") as f:
            text = f.read()
    except UnicodeDecodeError as e:
        raise SceneError(f"not UTF-8 text (byte {e.start}: {e.reason})", path) from None
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror or e}", path) from None
    if UNIT_RE.search(text):
        line = text.count("\n", 0, UNIT_RE.search(text).start()) + 1
        warnings.append(f"{path}: line {line}: dropped a unit suffix 'm' after a number")
        text = UNIT_RE.sub("", text)
    try:
        return json5.loads(text, allow_duplicate_keys=False)
    except RecursionError:
        raise SceneError("cannot parse (thesis JSON dialect): nested too deeply", path) \
            from None
    except ValueError as e:
        raise SceneError(f"cannot parse (thesis JSON dialect): {e}", path) from None


def _mirror(v):
    if isinstance(v, dict) and set(v) == {"x", "y", "z"}:
        return {"x": v["x"], "y": v["y"], "z": -v["z"] if _num(v["z"]) else v["z"]}
    if isinstance(v, list) and len(v) == 3:
        return [v[0], v[1], -v[2] if _num(v[2]) else v[2]]
    return v


def _num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def convert(folder, allow_missing=False):
    """(scene dict in our format, scene.json path, warnings)."""
    warnings = []
    path = os.path.join(folder, "scene.json")
    src = read_lenient(path, warnings)
    if not isinstance(src, dict):
        raise SceneError("expected an object at the top level", path)
    out = {}
    missing = []
    for key, value in src.items():
        if key == "camera" and isinstance(value, dict):
            cam = dict(value)
            if "position" in cam:
                cam["position"] = _mirror(cam["position"])
            if "rotation" in cam:
                r = cam["rotation"]
                if isinstance(r, dict) and set(r) == {"x", "y", "z"} and all(
                        _num(r[k]) for k in "xyz"):
                    cam["rotation"] = [-r["x"], -r["y"], r["z"]]
            bokeh = cam.pop("bokeh", None)
            if bokeh is False:
                cam["aperture"] = 0
            if "fov" not in cam:
                cam.setdefault("sensorWidth", THESIS_SENSOR_WIDTH)
            out["camera"] = cam
        elif key == "materials" and isinstance(value, list):
            mats = []
            for m in value:
                if not isinstance(m, dict):
                    mats.append(m)
                    continue
                m = dict(m)
                name = m.get("name")
                valueless = set(m) <= {"name"}
                m.setdefault("roughness", 1.0)    # the thesis renderer's default
                for mp in MAPS:
                    f = os.path.join(folder, "Textures", f"{name}_{mp}.bmp")
                    key_for = "normalMap" if mp == "normal" else mp
                    if os.path.isfile(f):
                        cs = "sRGB" if mp in ("albedo", "emission") else "linear"
                        m[key_for] = {"texture": os.path.relpath(f, folder), "colorSpace": cs}
                    elif valueless and mp in EXPECTED_MAPS:
                        missing.append(f)
                mats.append(m)
            out["materials"] = mats
        elif key == "objects" and isinstance(value, list):
            objs = []
            for o in value:
                if isinstance(o, dict) and "file" not in o and isinstance(o.get("name"), str):
                    o = dict(o)
                    f = os.path.join("Objects", o["name"] + ".obj")
                    if not os.path.isfile(os.path.join(folder, f)):
                        missing.append(os.path.join(folder, f))
                        if allow_missing:
                            continue
                    o["file"] = f
                    o.setdefault("smooth", True)   # SMOOTH_SHADING was on
                objs.append(o)
            out["objects"] = objs
        elif key == "hdri" and isinstance(value, dict) and isinstance(value.get("name"), str):
            f = os.path.join(folder, "HDRI", value["name"] + ".hdr")
            if os.path.isfile(f):
                out["hdri"] = value
            else:
                missing.append(f)
                grey = {k: v for k, v in value.items() if k not in ("name",)}
                grey["color"] = [0.5, 0.5, 0.5]
                out["hdri"] = grey
        elif key == "pointLights" and isinstance(value, list):
            out["pointLights"] = [dict(v, position=_mirror(v["position"]))
                                  if isinstance(v, dict) and "position" in v else v
                                  for v in value]
        elif key == "postprocessing" and isinstance(value, dict):
            exp = value.get("exposure", 1)
            if set(value) - {"exposure"} or not _num(exp):
                raise SceneError("postprocessing: only a numeric 'exposure' is known", path,
                                 "/postprocessing")
            if exp != 1:
                warnings.append(f"{path}: postprocessing.exposure {exp} is ignored, as the "
                                "thesis renderer ignored it")
        else:
            out[key] = value
    if missing:
        listing = "".join(f"\n  {m}" for m in missing)
        if not allow_missing:
            raise SceneError(f"{len(missing)} file(s) of this scene folder are missing:"
                             f"{listing}\n(--allow-missing renders with defaults for them)",
                             path)
        warnings.append(f"rendering with defaults for {len(missing)} missing file(s):"
                        f"{listing}")
    return out, path, warnings
