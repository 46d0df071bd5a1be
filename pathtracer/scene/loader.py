"""Read and validate a scene file (the contract: ``docs/scene-format.md``).

Every value is checked as it is read, and every error names the file and the JSON path
(``/materials/2/albedo``). Unknown keys are errors (pbrt's ReportUnused, Mitsuba's queried
bit): nothing in a scene is silently ignored. Thesis renderer scene folders are converted
to this format first (``scene.thesis``).
"""
import json
import math
import os
import re
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .. import limits
from ..kernels.layout import MATERIAL_PARAMS, PARAM_BY_KEY
from .errors import SceneError


# ---------------------------------------------------------------------------------------
# Description: what the file says, validated, with defaults filled in.

@dataclass
class Camera:
    resolution: tuple = (640, 360)
    position: tuple = (0.0, 0.0, 0.0)
    look_at: Optional[tuple] = None
    up: tuple = (0.0, 1.0, 0.0)
    rotation: tuple = (0.0, 0.0, 0.0)
    fov: float = 39.6                   # horizontal, degrees
    aperture: float = 0.0
    focus_distance: float = 1.0
    lens_radius: float = 0.0


SAMPLERS = ("sobol", "independent")
LIGHT_SAMPLERS = ("auto", "tree", "power")
TONEMAPS = ("clamp", "aces", "agx")          # pathtracer.tonemap.TONEMAPS


@dataclass
class RenderSettings:
    spp: int = 64
    max_bounces: int = 8
    rr_depth: int = 5
    seed: int = 0
    sampler: str = "sobol"     # or "independent"
    light_sampler: str = "auto"   # or "tree", "power" (scene.compile.use_light_tree)
    exposure: float = 0.0      # EV, 8-bit outputs only (pathtracer.tonemap)
    tonemap: str = "clamp"     # or "aces", "agx"
    hide_emitters: bool = False   # camera rays see no emitter (Mitsuba's hide_emitters)


@dataclass
class TextureSpec:
    path: str
    color_space: str = "linear"      # "sRGB" or "linear"
    filter: str = "trilinear"        # mip-mapped; or "bilinear", "nearest"
    tile: tuple = (1.0, 1.0)
    offset: tuple = (0.0, 0.0)
    scale: tuple = (1.0, 1.0, 1.0)
    pointer: str = ""
    channel: Optional[str] = None    # "r", "g", "b" or "a": one channel of the image
    wrap: tuple = ("repeat", "repeat")   # u, v: "repeat", "mirror" or "clamp"


# principled number parameters: scene key -> (default, lo, hi), from the one parameter
# table (kernels.layout.MATERIAL_PARAMS); eta's lower bound is open (> 0)
PRINCIPLED_NUMBERS = {p.key: (p.default, p.lo, p.hi) for p in MATERIAL_PARAMS
                      if p.kind == "number"}
ALBEDO_DEFAULT = (PARAM_BY_KEY["albedo"].default,) * 3
EMISSION_DEFAULT = (PARAM_BY_KEY["emission"].default,) * 3


@dataclass
class Material:
    name: str
    type: str = "principled"
    albedo: tuple = ALBEDO_DEFAULT
    emission: tuple = EMISSION_DEFAULT
    two_sided: bool = False
    one_sided: bool = False    # reflects on its front side only (black from behind)
    alpha: float = 1.0         # opacity (textures["alpha"]: from a texture)
    alpha_mode: str = "opaque"  # "opaque", "mask" (cut out below alpha_cutoff), "blend"
    alpha_cutoff: float = 0.5
    pointer: str = ""
    numbers: dict = field(default_factory=dict)    # principled number parameters
    textures: dict = field(default_factory=dict)   # parameter key -> TextureSpec
    normal_map: Optional[TextureSpec] = None


@dataclass
class Object:
    name: str
    file: Optional[str] = None
    vertices: Optional[np.ndarray] = None   # float64 (V, 3), inline meshes
    faces: Optional[np.ndarray] = None      # int64 (F, 3), inline meshes
    uvs: Optional[np.ndarray] = None        # float64 (V, 2), inline meshes' "uvs"
    material: Optional[str] = None
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    smooth: bool = False
    pointer: str = ""
    shape_index: int = 0      # which mesh of a Mitsuba .serialized file


@dataclass
class PointLight:
    position: tuple
    intensity: tuple
    # a spot light: where it points (unit), and its cone's inner and outer half-angles
    # (degrees); intensity falls off as glTF's KHR_lights_punctual spot (scene.compile)
    axis: Optional[tuple] = None
    inner_angle: float = 0.0
    outer_angle: float = 45.0


@dataclass
class DirectionalLight:
    """Light from infinitely far away along ``direction`` (unit; where it travels),
    ``irradiance`` (W m^-2) on a surface facing it; compiled as a far point light
    (scene.compile.place_suns)."""
    direction: tuple
    irradiance: tuple


@dataclass
class EnvironmentMap:
    path: Optional[str]        # None: the file is missing and defaults were asked for
    intensity: float = 1.0
    rotation: float = 0.0      # degrees about +Y
    pointer: str = ""
    compensate: bool = True    # MIS compensation of the sampling density (kernels.envmap)
    matrix: Optional[np.ndarray] = None   # 3 x 3 rotation: map directions -> world

    def world_from_map(self):
        """The rotation taking the map's directions into the world's: ``matrix``, or the
        turn by ``rotation`` degrees about +Y (counter-clockwise seen from above)."""
        if self.matrix is not None:
            return np.asarray(self.matrix, np.float64)
        phi = math.radians(self.rotation)
        c, s = math.cos(phi), math.sin(phi)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass
class SceneDescription:
    path: str
    camera: Camera
    render: RenderSettings
    materials: dict            # name -> Material
    objects: list
    point_lights: list
    environment: object = None   # constant radiance rgb tuple, EnvironmentMap, or None
    exposure: float = 1.0        # thesis folders: linear scale of the image
    warnings: list = field(default_factory=list)
    directional_lights: list = field(default_factory=list)


# ---------------------------------------------------------------------------------------
# Typed access to JSON values with paths.

class Node:
    """A JSON object being read: typed getters, and an error for any key left unread."""

    def __init__(self, value, pointer, file):
        if not isinstance(value, dict):
            raise SceneError(f"expected an object, got {_kind(value)}", file, pointer or "/")
        self.value = value
        self.pointer = pointer
        self.file = file
        self.read = set()

    def error(self, message, key=None):
        return SceneError(message, self.file, self.path(key) if key is not None else
                          (self.pointer or "/"))

    def path(self, key):
        return f"{self.pointer}/{key}"

    def has(self, key):
        return key in self.value

    def raw(self, key, default=None):
        self.read.add(key)
        return self.value.get(key, default)

    def number(self, key, default=None, lo=None, hi=None, lo_open=False):
        if key not in self.value:
            return default
        v = _number(self.raw(key), self.file, self.path(key))
        _check_range(v, lo, hi, lo_open, self.file, self.path(key))
        return v

    def integer(self, key, default=None, lo=None, hi=None):
        if key not in self.value:
            return default
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (
                isinstance(v, float) and not v.is_integer()):
            raise SceneError(f"expected an integer, got {_kind(v)}", self.file, self.path(key))
        v = int(v)
        _check_range(v, lo, hi, False, self.file, self.path(key))
        return v

    def boolean(self, key, default=None):
        if key not in self.value:
            return default
        v = self.raw(key)
        if not isinstance(v, bool):
            raise SceneError(f"expected true or false, got {_kind(v)}", self.file, self.path(key))
        return v

    def string(self, key, default=None, choices=None):
        if key not in self.value:
            return default
        v = self.raw(key)
        if not isinstance(v, str):
            raise SceneError(f"expected a string, got {_kind(v)}", self.file, self.path(key))
        if choices is not None and v not in choices:
            raise SceneError(f"expected one of {', '.join(map(repr, choices))}, got {v!r}",
                             self.file, self.path(key))
        return v

    def vector(self, key, default=None):
        if key not in self.value:
            return default
        return _triple(self.raw(key), self.file, self.path(key), ("x", "y", "z"), False)

    def color(self, key, default=None, hi=None):
        """Linear RGB, >= 0 (and <= hi): [r, g, b], a number (grey), {r, g, b} or
        {x, y, z}."""
        if key not in self.value:
            return default
        v = self.raw(key)
        if isinstance(v, (str, dict)) and (isinstance(v, str) or "texture" in v):
            raise SceneError("a texture is not allowed here", self.file, self.path(key))
        return _color(v, self.file, self.path(key), hi)

    def node(self, key):
        return Node(self.raw(key), self.path(key), self.file)

    def items(self, key):
        v = self.raw(key, [])
        if not isinstance(v, list):
            raise SceneError(f"expected a list, got {_kind(v)}", self.file, self.path(key))
        return v

    def finish(self):
        unknown = [k for k in self.value if k not in self.read]
        if unknown:
            raise SceneError(f"unknown key {unknown[0]!r}", self.file, self.path(unknown[0]))


def _kind(v):
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, (int, float)):
        return f"the number {v}"
    if isinstance(v, str):
        return f"the string {v!r}"
    if isinstance(v, list):
        return "a list"
    return "an object"


def _number(v, file, pointer):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SceneError(f"expected a number, got {_kind(v)}", file, pointer)
    try:
        v = float(v)
    except OverflowError:     # an integer beyond float64
        raise SceneError("expected a finite number, got an integer too large for a float",
                         file, pointer) from None
    if not math.isfinite(v):
        raise SceneError(f"expected a finite number, got {v}", file, pointer)
    if abs(v) > limits.FLOAT32_MAX:
        raise SceneError(f"{v:g} is outside the float32 range (|x| <= 3.4e38) the renderer "
                         "computes in", file, pointer)
    return v


def _color(v, file, pointer, hi=None, what="colour components"):
    c = _triple(v, file, pointer, None, True)
    for x in c:
        if x < 0:
            raise SceneError(f"{what} must be >= 0, got {x}", file, pointer)
        if hi is not None and x > hi:
            raise SceneError(f"{what} must be <= {hi:g}, got {x:g}", file, pointer)
    return c


# The upper bounds of colours by what they mean (see pathtracer.limits).
COLOR_LIMITS = {"albedo": limits.MAX_REFLECTANCE, "emission": limits.MAX_RADIANCE}


def _check_range(v, lo, hi, lo_open, file, pointer):
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise SceneError(f"must be {'>' if lo_open else '>='} {lo}, got {v}", file, pointer)
    if hi is not None and v > hi:
        raise SceneError(f"must be <= {hi}, got {v}", file, pointer)


def _triple(v, file, pointer, names, allow_scalar):
    if allow_scalar and isinstance(v, (int, float)) and not isinstance(v, bool):
        x = _number(v, file, pointer)
        return (x, x, x)
    if isinstance(v, list):
        if len(v) != 3:
            raise SceneError(f"expected 3 numbers, got {len(v)}", file, pointer)
        return tuple(_number(x, file, f"{pointer}/{i}") for i, x in enumerate(v))
    if isinstance(v, dict):
        for keys in ((("r", "g", "b"), ("x", "y", "z")) if names is None else (names,)):
            if set(v) == set(keys):
                return tuple(_number(v[k], file, f"{pointer}/{k}") for k in keys)
        want = "{r, g, b} or {x, y, z}" if names is None else "{x, y, z}"
        raise SceneError(f"expected an object with keys {want}, got keys {sorted(v)}", file,
                         pointer)
    what = "a colour" if names is None else "a vector [x, y, z]"
    raise SceneError(f"expected {what}, got {_kind(v)}", file, pointer)


# ---------------------------------------------------------------------------------------
# Parsing.

def _strict_json(path):
    def no_constant(name):
        raise ValueError(f"{name} is not valid JSON")

    def no_duplicates(pairs):
        d = {}
        for k, v in pairs:
            if k in d:
                raise ValueError(f"duplicate key {k!r}")
            d[k] = v
        return d

    try:
        with open(path, "r", encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise SceneError("scene file not found", path) from None
    except IsADirectoryError:
        raise SceneError("is a folder, not a scene file", path) from None
    except UnicodeDecodeError as e:
        raise SceneError(f"not UTF-8 text (byte {e.start}: {e.reason})", path) from None
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror or e}", path) from None
    try:
        return json.loads(text, parse_constant=no_constant, object_pairs_hook=no_duplicates)
    except RecursionError:
        raise SceneError("invalid JSON: nested too deeply", path) from None
    except json.JSONDecodeError as e:
        raise SceneError(f"invalid JSON at line {e.lineno}, column {e.colno}: {e.msg}",
                         path) from None
    except ValueError as e:
        where = ""
        m = re.search(r"-?\b(NaN|Infinity)\b", text) if "valid JSON" in str(e) else None
        if m:
            line = text.count("\n", 0, m.start()) + 1
            col = m.start() - (text.rfind("\n", 0, m.start()) + 1) + 1
            where = f" at line {line}, column {col}"
        raise SceneError(f"invalid JSON{where}: {e}", path) from None


def read_scene_data(path, allow_missing=False, camera=None, environment_given=False,
                    params=None):
    """(parsed JSON in this format, the scene file's absolute path, warnings) of a scene
    file, a Mitsuba 3 XML scene, a glTF 2.0 model or a thesis renderer's scene folder
    (converted); not yet validated. ``params``: a Mitsuba scene's ``$name`` parameters
    ({name: value}, over its ``<default>`` values). ``camera``: which of a glTF file's cameras;
    ``environment_given``: a glTF file gets no default environment (see
    :func:`.gltf.convert_file`)."""
    from .thesis import convert, is_thesis_folder, is_thesis_scene_file
    path = os.path.abspath(path)
    if path.lower().endswith((".gltf", ".glb")) and not os.path.isdir(path):
        from .gltf import convert_file as convert_gltf
        data, warnings = convert_gltf(path, camera, environment_given)
        return data, path, warnings
    if path.lower().endswith(".xml") and not os.path.isdir(path):
        from .mitsuba_xml import convert_file
        data, warnings = convert_file(path, params)
        return data, path, warnings
    if os.path.isdir(path) or is_thesis_scene_file(path):
        folder = path if os.path.isdir(path) else os.path.dirname(path)
        if not is_thesis_folder(folder):
            raise SceneError("is a folder without a scene.json (expected a scene file or a "
                             "thesis renderer scene folder)", path)
        return convert(folder, allow_missing)
    return _strict_json(path), path, []


def load_scene_description(path, allow_missing=False):
    """Parse and validate ``path`` (a scene file, or a thesis renderer's scene folder);
    raises :class:`SceneError` on any bad input."""
    data, path, warnings = read_scene_data(path, allow_missing)
    desc = _describe(data, path)
    desc.warnings.extend(warnings)
    return desc


def describe(data, path, base=None):
    """Validate a scene given as parsed JSON (``path`` names it in error messages;
    relative file names are read from ``base``, by default the folder of ``path``)."""
    return _describe(data, path, base)


def _describe(data, path, base=None):
    root = Node(data, "", path)
    base = os.path.dirname(path) if base is None else base
    if not root.has("camera"):
        raise root.error("missing required key 'camera'")
    camera = _camera(root.node("camera"))
    render = _render(root.node("render")) if root.has("render") else RenderSettings()
    materials = {}
    for i, m in enumerate(root.items("materials")):
        mat = _material(Node(m, f"/materials/{i}", path), base)
        if mat.name in materials:
            raise SceneError(f"duplicate material name {mat.name!r}", path, f"/materials/{i}/name")
        materials[mat.name] = mat
    objects = [_object(Node(o, f"/objects/{i}", path), base, materials)
               for i, o in enumerate(root.items("objects"))]
    names = set()
    for o in objects:
        if o.name in names:
            raise SceneError(f"duplicate object name {o.name!r}", path, f"{o.pointer}/name")
        names.add(o.name)
    every_light = [_light(Node(v, f"/lights/{i}", path))
                   for i, v in enumerate(root.items("lights"))]
    lights = [li for li in every_light if isinstance(li, PointLight)]
    suns = [li for li in every_light if isinstance(li, DirectionalLight)]
    for i, v in enumerate(root.items("pointLights")):   # thesis alias
        n = Node(v, f"/pointLights/{i}", path)
        pos = _coordinate(n, "position", (0.0, 0.0, 0.0))
        lights.append(PointLight(pos, n.color("radiance", (1.0, 1.0, 1.0),
                                               hi=limits.MAX_RADIANCE)))
        n.finish()
    environment = None
    if root.has("environment"):
        environment = _environment(root.node("environment"), base)
    if root.has("hdri"):                                # thesis alias
        if root.has("environment"):
            raise root.error("give 'environment' or 'hdri', not both", "hdri")
        environment = _environment(root.node("hdri"), base, thesis=True)
    root.finish()
    return SceneDescription(path, camera, render, materials, objects, lights, environment,
                            directional_lights=suns)


def _camera(n, sensor_default=0.036):
    cam = Camera()
    if n.has("resolution"):
        if n.has("xRes") or n.has("yRes"):
            raise n.error("give 'resolution' or 'xRes'/'yRes', not both", "resolution")
        v = n.raw("resolution")
        if not isinstance(v, list) or len(v) != 2:
            raise n.error("expected [width, height]", "resolution")
        cam.resolution = tuple(_positive_int(x, n.file, f"{n.path('resolution')}/{i}")
                               for i, x in enumerate(v))
    else:
        cam.resolution = (n.integer("xRes", cam.resolution[0], lo=1, hi=limits.MAX_DIMENSION),
                          n.integer("yRes", cam.resolution[1], lo=1, hi=limits.MAX_DIMENSION))
    if cam.resolution[0] * cam.resolution[1] > limits.MAX_PIXELS:
        raise n.error(f"at most {limits.MAX_PIXELS} pixels, got "
                      f"{cam.resolution[0] * cam.resolution[1]}",
                      "resolution" if n.has("resolution") else "xRes")
    cam.position = _coordinate(n, "position", cam.position)
    cam.look_at = _coordinate(n, "lookAt", None)
    cam.up = n.vector("up", cam.up)
    cam.rotation = n.vector("rotation", cam.rotation)
    if n.has("lookAt") and n.has("rotation"):
        raise n.error("give 'lookAt' or 'rotation', not both", "rotation")
    if cam.look_at is not None:
        fwd = np.subtract(cam.look_at, cam.position)
        if np.linalg.norm(fwd) == 0:
            raise n.error("lookAt equals position", "lookAt")
        if np.linalg.norm(np.cross(fwd, cam.up)) <= 1e-12 * np.linalg.norm(fwd) * max(
                np.linalg.norm(cam.up), 1e-300):
            raise n.error("up is parallel to the viewing direction (or zero)", "up")
    sensor_width = n.number("sensorWidth", sensor_default, lo=0, lo_open=True)
    if n.has("focalLength"):
        if n.has("fov"):
            raise n.error("give 'fov' or 'focalLength', not both", "focalLength")
        focal = n.number("focalLength", lo=0, lo_open=True)
        tan_half = sensor_width / (2 * focal)
        cam.fov = math.degrees(2 * math.atan(tan_half))
        fov_key = "focalLength"
    else:
        cam.fov = n.number("fov", cam.fov, lo=0, lo_open=True)
        if cam.fov >= 180:
            raise n.error(f"must be < 180 degrees, got {cam.fov}", "fov")
        tan_half = math.tan(math.radians(cam.fov) / 2)
        focal = sensor_width / (2 * tan_half)
        fov_key = "fov"
    # (limits: float32 ray directions lose the image's extent outside this range)
    if not limits.MIN_TAN_HALF_FOV <= tan_half <= limits.MAX_TAN_HALF_FOV:
        lo = math.degrees(2 * math.atan(limits.MIN_TAN_HALF_FOV))
        hi = math.degrees(2 * math.atan(limits.MAX_TAN_HALF_FOV))
        raise n.error(f"the field of view must be within [{lo:.6g}, {hi:.7g}] degrees, got "
                      f"{cam.fov:.9g}", fov_key)
    cam.aperture = n.number("aperture", 0.0, lo=0)
    cam.focus_distance = n.number("focusDistance", 1.0, lo=0, lo_open=True,
                                  hi=limits.MAX_COORDINATE)
    # f-number -> lens radius (scene units: focalLength and sensorWidth are metres)
    cam.lens_radius = focal / (2 * cam.aperture) if cam.aperture > 0 else 0.0
    if cam.lens_radius > limits.MAX_COORDINATE:
        raise n.error(f"the lens radius focalLength / (2 aperture) = {cam.lens_radius:g} "
                      f"exceeds {limits.MAX_COORDINATE:g}", "aperture")
    n.finish()
    return cam


def _coordinate(n, key, default):
    """A position: a vector with every |component| <= limits.MAX_COORDINATE."""
    v = n.vector(key, default)
    if v is not None and max(abs(x) for x in v) > limits.MAX_COORDINATE:
        raise n.error(f"coordinates must be within +-{limits.MAX_COORDINATE:g}, got "
                      f"{max(v, key=abs):g}", key)
    return v


def _positive_int(v, file, pointer, hi=limits.MAX_DIMENSION):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (
            isinstance(v, float) and not v.is_integer()) or v < 1:
        raise SceneError(f"expected a positive integer, got {_kind(v)}", file, pointer)
    if v > hi:
        raise SceneError(f"must be <= {hi}, got {v:g}", file, pointer)
    return int(v)


def _render(n):
    r = RenderSettings(
        spp=n.integer("spp", 64, lo=1, hi=limits.MAX_SPP),
        max_bounces=n.integer("maxBounces", 8, lo=0, hi=limits.MAX_BOUNCES),
        rr_depth=n.integer("rrDepth", 5, lo=0, hi=limits.MAX_BOUNCES),
        seed=n.integer("seed", 0, lo=0, hi=limits.MAX_SEED),
        sampler=n.string("sampler", "sobol", choices=SAMPLERS),
        light_sampler=n.string("lightSampler", "auto", choices=LIGHT_SAMPLERS),
        exposure=n.number("exposure", 0.0, lo=-limits.MAX_EXPOSURE, hi=limits.MAX_EXPOSURE),
        tonemap=n.string("tonemap", "clamp", choices=TONEMAPS),
        hide_emitters=n.boolean("hideEmitters", False))
    n.finish()
    return r


def _material(n, base):
    name = n.string("name")
    if name is None:
        raise n.error("missing required key 'name'")
    mtype = n.string("type", "principled",
                     choices=("principled", "diffuse", "conductor", "thindielectric"))
    if n.has("albedo") and n.has("baseColor"):
        raise n.error("give 'albedo' or 'baseColor', not both", "baseColor")
    m = Material(name=name, type=mtype, pointer=n.pointer)
    key = "albedo" if n.has("albedo") or not n.has("baseColor") else "baseColor"
    m.albedo = _color_or_texture(n, key, (1.0, 1.0, 1.0) if mtype == "conductor" else
                                 ALBEDO_DEFAULT, base, "sRGB", m, "albedo",
                                 COLOR_LIMITS["albedo"])
    m.emission = _color_or_texture(n, "emission", EMISSION_DEFAULT, base, "sRGB", m,
                                   "emission", COLOR_LIMITS["emission"])
    m.two_sided = n.boolean("twoSided", False)
    m.one_sided = n.boolean("oneSided", False)
    _alpha(n, m, base)
    if mtype == "principled":
        if n.has("eta") and n.has("specular"):
            raise n.error("give 'specular' or 'eta', not both (each sets the other)", "eta")
        for k, (default, lo, hi) in PRINCIPLED_NUMBERS.items():
            if not n.has(k):
                if default is not None:
                    m.numbers[k] = default
                continue
            v = n.raw(k)
            if isinstance(v, (str, dict)):
                m.textures[k] = _texture_spec(n, k, base, "linear")
                m.numbers[k] = default if default is not None else 0.0
            else:
                m.numbers[k] = n.number(k, lo=lo, hi=hi, lo_open=(k == "eta"))
        if n.has("normalMap"):
            m.normal_map = _texture_spec(n, "normalMap", base, "linear")
    elif mtype == "thindielectric":
        # a thin pane (Mitsuba's thindielectric): a mirror where a ray reflects, nothing
        # where it passes (alpha mode "thin", kernels.layout.ALPHA_THIN)
        for key in ("alphaMode", "alpha", "alphaCutoff"):
            if n.has(key):
                raise n.error(f"a thindielectric pane has no '{key}' (it is its own "
                              "transparency)", key)
        m.alpha_mode = "thin"
        m.alpha = n.number("eta", 1.5, lo=0.0, hi=limits.MAX_IOR, lo_open=True)
    elif mtype == "conductor":
        _conductor(n, m, base)
        if n.has("normalMap"):
            m.normal_map = _texture_spec(n, "normalMap", base, "linear")
    else:
        for k in list(PRINCIPLED_NUMBERS) + ["normalMap"]:
            if n.has(k):
                raise n.error(f"'{k}' belongs to the principled material, not 'diffuse'", k)
    n.finish()
    return m


def _conductor(n, m, base):
    """A conductor (Mitsuba's conductor / roughconductor): ``albedo`` is its specular
    reflectance (a tint, default 1), ``eta`` and ``k`` its complex index of refraction per
    channel (default 0 and 1: a perfect mirror), ``alphaU`` / ``alphaV`` the microfacet
    alphas along the tangent and the bitangent (default 0: smooth; ``alphaV`` defaults to
    ``alphaU``; a number or a one-channel texture) and ``distribution`` ggx or beckmann."""
    m.numbers["eta"] = tuple(n.color("eta", (0.0, 0.0, 0.0), hi=limits.MAX_IOR))
    m.numbers["k"] = tuple(n.color("k", (1.0, 1.0, 1.0), hi=limits.MAX_IOR))
    for key in ("alphaU", "alphaV"):
        if not n.has(key):
            continue
        v = n.raw(key)
        if isinstance(v, (str, dict)):
            m.textures[key] = _texture_spec(n, key, base, "linear")
            m.numbers[key] = 0.0
        else:
            m.numbers[key] = n.number(key, lo=0.0, hi=1.0)
    if "alphaU" in m.numbers and "alphaV" not in m.numbers:
        m.numbers["alphaV"] = m.numbers["alphaU"]
        if "alphaU" in m.textures:
            m.textures["alphaV"] = m.textures["alphaU"]
    m.numbers["distribution"] = n.string("distribution", "ggx", choices=("ggx", "beckmann"))


ALPHA_MODES = ("opaque", "mask", "blend")


def _alpha(n, m, base):
    """A material's opacity: ``alpha`` (a number in [0, 1] or a one-channel texture, e.g.
    an image's alpha with ``"channel": "a"``), ``alphaMode`` (opaque: alpha is not read;
    mask: a cut-out, opaque where alpha >= ``alphaCutoff``; blend: stochastic transparency)
    and ``alphaCutoff`` (default 0.5), as glTF's alphaMode."""
    m.alpha_mode = n.string("alphaMode", "opaque", choices=ALPHA_MODES)
    m.alpha_cutoff = n.number("alphaCutoff", 0.5, lo=0.0, hi=1.0)
    if n.has("alpha"):
        v = n.raw("alpha")
        if isinstance(v, (str, dict)):
            m.textures["alpha"] = _texture_spec(n, "alpha", base, "linear")
        else:
            m.alpha = n.number("alpha", lo=0.0, hi=1.0)


def scene_material(data, file):
    """A Material from a dict in this format made by a model reader (glTF): validated as a
    scene file's material; its errors name ``file`` and the dict's ``_pointer``."""
    data = dict(data)
    pointer = data.pop("_pointer", "")
    return _material(Node(data, pointer, file), os.path.dirname(os.path.abspath(file)))


def _color_or_texture(n, key, default, base, color_space, material, slot, hi):
    if not n.has(key):
        return default
    v = n.raw(key)
    if isinstance(v, str) or (isinstance(v, dict) and "texture" in v):
        material.textures[slot] = _texture_spec(n, key, base, color_space)
        return (1.0, 1.0, 1.0)
    return n.color(key, default, hi=hi)


TEXTURE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".hdr", ".exr", ".tga", ".tif",
                      ".tiff", ".npy")      # .npy: an H x W x 3 array (linear floats)


def _texture_spec(n, key, base, color_space):
    """A texture: a path string, or {texture, colorSpace, filter, tile, offset, scale}."""
    v = n.raw(key)
    where = n.path(key)
    if isinstance(v, str):
        spec = TextureSpec(path=_texture_path(v, base, n.file, where), color_space=color_space,
                           pointer=where)
    else:
        t = Node(v, where, n.file)
        p = t.string("texture")
        if p is None:
            raise t.error("missing required key 'texture' (a texture is a path string or "
                          "an object with 'texture')")
        spec = TextureSpec(path=_texture_path(p, base, n.file, t.path("texture")),
                           color_space=t.string("colorSpace", color_space,
                                                choices=("sRGB", "linear")),
                           filter=t.string("filter", "trilinear",
                                           choices=("trilinear", "bilinear", "nearest")),
                           pointer=where)
        spec.channel = t.string("channel", None, choices=("r", "g", "b", "a"))
        if t.has("wrap"):
            w = t.raw("wrap")
            modes = ("repeat", "mirror", "clamp")
            if isinstance(w, str) and w in modes:
                spec.wrap = (w, w)
            elif isinstance(w, list) and len(w) == 2 and all(x in modes for x in w):
                spec.wrap = tuple(w)
            else:
                raise t.error("expected 'repeat', 'mirror' or 'clamp', or [u, v] of them",
                              "wrap")
        spec.tile = _pair(t, "tile", (1.0, 1.0))
        spec.offset = _pair(t, "offset", (0.0, 0.0))
        if t.has("scale"):
            spec.scale = _color(t.raw("scale"), t.file, t.path("scale"), limits.MAX_RADIANCE,
                                "scale components")
        t.finish()
    return spec


def _texture_path(p, base, file, where):
    path = os.path.join(base, p)
    if not os.path.splitext(path)[1].lower() in TEXTURE_EXTENSIONS:
        raise SceneError(f"unsupported texture format {os.path.splitext(p)[1]!r} "
                         f"(use one of {', '.join(TEXTURE_EXTENSIONS)})", file, where)
    if not os.path.isfile(path):
        raise SceneError(f"texture file not found: {path}", file, where)
    return path


def _pair(n, key, default):
    if not n.has(key):
        return default
    v = n.raw(key)
    if not isinstance(v, list) or len(v) != 2:
        raise n.error("expected [u, v]", key)
    out = tuple(_number(x, n.file, f"{n.path(key)}/{i}") for i, x in enumerate(v))
    for i, x in enumerate(out):
        # beyond this, float32 texture coordinates keep no fraction to look up
        _check_range(abs(x), None, limits.MAX_UV, False, n.file, f"{n.path(key)}/{i}")
    return out


def _object(n, base, materials):
    name = n.string("name")
    if name is None:
        raise n.error("missing required key 'name'")
    obj = Object(name=name, pointer=n.pointer)
    if n.has("file"):
        if n.has("vertices") or n.has("faces"):
            raise n.error("give 'file' or inline 'vertices'/'faces', not both", "file")
        obj.file = os.path.join(base, n.string("file"))
        if not os.path.isfile(obj.file):
            raise n.error(f"file not found: {obj.file}", "file")
        ext = os.path.splitext(obj.file)[1].lower()
        if ext not in (".obj", ".ply", ".gltf", ".glb", ".serialized"):
            raise n.error(f"unsupported mesh format {ext!r}: this version reads OBJ (.obj), "
                          "PLY (.ply), glTF 2.0 (.gltf, .glb) and Mitsuba's .serialized",
                          "file")
        if ext == ".serialized":
            obj.shape_index = n.integer("shapeIndex", 0, lo=0, hi=2 ** 31 - 1)
    elif n.has("vertices") and n.has("faces"):
        obj.vertices = _array(n, "vertices", float, 3)
        obj.faces = _array(n, "faces", int, 3)
        nv = len(obj.vertices)
        bad = np.argwhere((obj.faces < 0) | (obj.faces >= nv))
        if len(bad):
            i, j = bad[0]
            raise SceneError(f"vertex index {obj.faces[i, j]} out of range (0..{nv - 1})",
                             n.file, f"{n.path('faces')}/{i}/{j}")
        if n.has("uvs"):
            obj.uvs = _array(n, "uvs", float, 2)
            if len(obj.uvs) != nv:
                raise n.error(f"expected one [u, v] per vertex ({nv}), got {len(obj.uvs)}",
                              "uvs")
            if not (np.isfinite(obj.uvs).all() and
                    np.abs(obj.uvs).max(initial=0) <= limits.MAX_UV):
                raise n.error(f"texture coordinates must be finite and within "
                              f"+-{limits.MAX_UV:g}", "uvs")
    else:
        raise n.error("needs 'file', or 'vertices' and 'faces'")
    obj.material = n.string("material", None)
    if obj.material is not None and obj.material not in materials:
        raise n.error(f"unknown material {obj.material!r}", "material")
    if n.has("transform"):
        obj.matrix = _transform(n.node("transform"))
    # glTF meshes carry their shading normals: smooth unless told otherwise
    obj.smooth = n.boolean("smooth", obj.file is not None and
                           os.path.splitext(obj.file)[1].lower() in (".gltf", ".glb"))
    n.finish()
    return obj


def _array(n, key, kind, width):
    v = n.raw(key)
    where = n.path(key)
    if not isinstance(v, list):
        raise SceneError(f"expected a list, got {_kind(v)}", n.file, where)
    out = np.empty((len(v), width), dtype=np.float64 if kind is float else np.int64)
    for i, row in enumerate(v):
        if not isinstance(row, list) or len(row) != width:
            raise SceneError(f"expected a list of {width} numbers", n.file, f"{where}/{i}")
        for j, x in enumerate(row):
            p = f"{where}/{i}/{j}"
            if kind is float:
                out[i, j] = _number(x, n.file, p)
            else:
                if isinstance(x, bool) or not isinstance(x, int):
                    raise SceneError(f"expected an integer index, got {_kind(x)}", n.file, p)
                if not 0 <= x < 2 ** 31:
                    raise SceneError(f"vertex index {x} out of range", n.file, p)
                out[i, j] = x
    return out


def euler_matrix(degrees):
    """Rotation about X, then Y, then Z (right-handed, degrees): Rz @ Ry @ Rx."""
    ax, ay, az = np.radians(degrees)
    cx, sx, cy, sy, cz, sz = (np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az),
                              np.sin(az))
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _transform(n):
    if n.has("matrix"):
        for k in ("translate", "rotate", "scale"):
            if n.has(k):
                raise n.error("give 'matrix' or translate/rotate/scale, not both", k)
        v = n.raw("matrix")
        rows = v if isinstance(v, list) else None
        if rows is None or len(rows) != 4 or any(not isinstance(r, list) or len(r) != 4
                                                 for r in rows):
            raise n.error("expected a 4x4 row-major matrix (4 lists of 4 numbers)", "matrix")
        m = np.array([[_number(x, n.file, f"{n.path('matrix')}/{i}/{j}")
                       for j, x in enumerate(r)] for i, r in enumerate(rows)])
        if not np.allclose(m[3], [0, 0, 0, 1]):
            raise n.error("the last row must be [0, 0, 0, 1] (affine transforms only)", "matrix")
    else:
        s = n.raw("scale", 1.0) if n.has("scale") else 1.0
        if isinstance(s, (int, float)) and not isinstance(s, bool):
            sv = (_number(s, n.file, n.path("scale")),) * 3
        else:
            sv = _triple(s, n.file, n.path("scale"), ("x", "y", "z"), False)
        m = np.eye(4)
        m[:3, :3] = euler_matrix(n.vector("rotate", (0.0, 0.0, 0.0))) @ np.diag(sv)
        m[:3, 3] = n.vector("translate", (0.0, 0.0, 0.0))
    if abs(np.linalg.det(m[:3, :3])) < 1e-300:
        raise n.error("the transform is singular (zero scale)")
    n.finish()
    return m


def _direction(n):
    """The required key 'direction' of a spot or directional light, as a unit vector."""
    if not n.has("direction"):
        raise n.error("missing required key 'direction'")
    d = np.asarray(n.vector("direction"), np.float64)
    length = float(np.linalg.norm(d))
    if not (np.isfinite(length) and length > 0):
        raise n.error("the direction must be a nonzero vector", "direction")
    return tuple((d / length).tolist())


def _light(n):
    kind = n.string("type", "point", choices=("point", "spot", "directional"))
    if kind == "directional":
        light = DirectionalLight(_direction(n), n.color("irradiance", (1.0, 1.0, 1.0),
                                                        hi=limits.MAX_RADIANCE))
        n.finish()
        return light
    if not n.has("position"):
        raise n.error("missing required key 'position'")
    light = PointLight(_coordinate(n, "position", None),
                       n.color("intensity", (1.0, 1.0, 1.0), hi=limits.MAX_RADIANCE))
    if kind == "spot":
        light.axis = _direction(n)
        outer = n.number("outerAngle", 45.0)
        inner = n.number("innerAngle", 0.0)
        if not 0 < outer <= 90:
            raise n.error(f"outerAngle must be in (0, 90] degrees, got {outer:g}", "outerAngle")
        if not 0 <= inner < outer:
            raise n.error(f"innerAngle must be in [0, outerAngle), got {inner:g}", "innerAngle")
        light.inner_angle, light.outer_angle = float(inner), float(outer)
    n.finish()
    return light


def _environment(n, base, thesis=False):
    file_key = "name" if thesis else "file"
    if n.has(file_key) and n.has("color"):
        raise n.error(f"give 'color' or '{file_key}', not both", "color")
    rotation = 0.0
    if thesis:
        # The thesis renderer shifted the map by xOffset of its width; its yOffset never
        # worked (it was written into xOffset), so only 0 is accepted.
        x_off = n.number("xOffset", 0.0)
        if n.number("yOffset", 0.0) != 0.0:
            raise n.error("yOffset is not supported (the thesis renderer ignored it too); "
                          "use 0", "yOffset")
        # Its mapping, expressed in ours (after its z flip), is turned by a quarter turn.
        rotation = 360.0 * (x_off - 0.25)
    else:
        rotation = n.number("rotation", 0.0)
    matrix = None
    if n.has("matrix"):
        if n.has("rotation"):
            raise n.error("give 'rotation' or 'matrix', not both", "matrix")
        matrix = _array(n, "matrix", float, 3)
        if matrix.shape != (3, 3) or not np.allclose(matrix @ matrix.T, np.eye(3), atol=1e-5) \
                or not np.linalg.det(matrix) > 0:
            raise n.error("expected a 3 x 3 rotation (orthonormal rows, determinant 1)",
                          "matrix")
    intensity = n.number("intensity", 1.0, lo=0, hi=limits.MAX_RADIANCE)
    if n.has(file_key):
        name = n.string(file_key)
        path = os.path.join(base, "HDRI", name + ".hdr") if thesis else os.path.join(base, name)
        compensate = True if thesis else n.boolean("misCompensation", True)
        n.finish()
        if not os.path.isfile(path):
            raise n.error(f"environment map not found: {path}", file_key)
        return EnvironmentMap(path, intensity, rotation, n.path(file_key), compensate, matrix)
    if not n.has("color"):
        raise n.error(f"needs 'color' or '{file_key}'")
    color = n.color("color")
    n.finish()
    radiance = tuple(c * intensity for c in color)
    if max(radiance) > limits.MAX_RADIANCE:
        raise n.error(f"color x intensity = {max(radiance):g} exceeds the largest radiance, "
                      f"{limits.MAX_RADIANCE:g}", "color")
    return radiance
