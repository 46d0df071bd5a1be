"""Mitsuba 3 XML scenes (``pt-render scene.xml``): the common subset, translated to the JSON
scene format and then validated and compiled like any scene. The mapping and every
approximation are documented in docs/scene-format.md ("Mitsuba 3 XML scenes").

Read with the standard library's ElementTree. ``<default name value>`` parameters are
substituted for ``$name`` in attribute values; ``<ref id>`` (``<ref name="bsdf" id=..>``)
names a BSDF declared at the top level. Anything outside the subset is a SceneError naming
the element, never silently dropped; approximations give a warning.
"""
import functools
import io
import math
import os
import re
import xml.etree.ElementTree as ET

import numpy as np

from .errors import SceneError
from .spectra import spectrum_to_rgb, uniform_to_rgb
from .geometry import uv_sphere
from .gltf import cached_file
from .meshes import load_mesh

# principled parameters: Mitsuba name -> scene-format key (kernels.layout's parameter table)
from ..kernels.layout import MATERIAL_PARAMS
PRINCIPLED_KEYS = {p.mitsuba: p.key for p in MATERIAL_PARAMS if p.mitsuba}
# the principled parameters Mitsuba 3 lets a texture give (eta and specular are floats)
PRINCIPLED_TEXTURABLE = {"roughness", "metallic", "specularTint", "anisotropic", "sheen",
                         "sheenTint", "clearcoat", "clearcoatGloss", "subsurface",
                         "transmission"}

# named index of refraction values Mitsuba accepts for dielectrics (its ior table, the common ones)
IOR_NAMES = {"vacuum": 1.0, "air": 1.00028, "water": 1.3330, "ice": 1.31, "acrylic glass": 1.49,
             "polypropylene": 1.49, "bk7": 1.5046, "fused quartz": 1.458, "diamond": 2.419,
             "sapphire": 1.77, "pyrex": 1.470, "polycarbonate": 1.58}


class _Reader:
    def __init__(self, path):
        self.path = path
        self.base = os.path.dirname(path)
        self.defaults = {}
        self.warnings = []
        self.bsdfs = {}        # id -> element
        self.emitters = {}     # id -> top-level <emitter> element
        self.ids = {}          # id -> any top-level element (samplers, films, textures...)
        self.where = {}        # element -> "/scene/shape[3] (id=light)"
        self.search = []       # <path value>: folders searched for files, latest first
        self.parent = {}       # element -> its parent element

    def file(self, name):
        """A file name as Mitsuba's file resolver finds it: absolute, or relative to the
        folders of the scene's ``<path>`` elements (the latest first), then to the scene's
        folder. A name found nowhere is returned as given (resolved against the scene's
        folder later, whose error names it)."""
        if os.path.isabs(name):
            return name
        for folder in self.search + [self.base]:
            candidate = os.path.join(folder, name)
            if os.path.exists(candidate):
                return candidate
        return name

    def error(self, message, el=None):
        return SceneError(message, self.path, self.where.get(el, "/scene") if el is not None
                          else "/scene")

    def warn(self, message, el=None):
        where = self.where.get(el, "") if el is not None else ""
        self.warnings.append(f"{self.path}: {where + ': ' if where else ''}{message}")

    # -- values
    def attr(self, el, name, default=None):
        v = el.get(name, default)
        if isinstance(v, str) and "$" in v:
            def sub(m):
                if m.group(1) not in self.defaults:
                    raise self.error(f"${m.group(1)}: no <default name={m.group(1)!r}>", el)
                return self.defaults[m.group(1)]
            v = re.sub(r"\$([A-Za-z_][A-Za-z0-9_]*)", sub, v)
        return v

    def numbers(self, el, text, count=None):
        try:
            vals = [float(x) for x in re.split(r"[,\s]+", text.strip()) if x]
        except ValueError:
            raise self.error(f"expected numbers, got {text!r}", el) from None
        if count is not None and len(vals) not in ((1, count) if count == 3 else (count,)):
            raise self.error(f"expected {count} numbers, got {text!r}", el)
        if not all(math.isfinite(x) for x in vals):
            raise self.error(f"non-finite number in {text!r}", el)
        return vals

    def params(self, el):
        """{name: (tag, element)} of an element's named children."""
        out = {}
        for child in el:
            name = child.get("name")
            if name is not None:
                out[name] = (child.tag, child)
        return out

    def value(self, el):
        """A plain value of a <float>, <integer>, <boolean>, <string>, <rgb>, <spectrum>,
        <point>, <vector> element."""
        tag = el.tag
        if tag == "float":
            return self.numbers(el, self.attr(el, "value", ""), 1)[0]
        if tag == "integer":
            v = self.numbers(el, self.attr(el, "value", ""), 1)[0]
            if not v.is_integer():
                raise self.error(f"expected an integer, got {v}", el)
            return int(v)
        if tag == "boolean":
            v = self.attr(el, "value", "").strip().lower()
            if v not in ("true", "false"):
                raise self.error(f"expected true or false, got {v!r}", el)
            return v == "true"
        if tag == "string":
            return self.attr(el, "value", "")
        if tag == "rgb":
            v = self.numbers(el, self.attr(el, "value", ""), 3)
            return v * 3 if len(v) == 1 else v
        if tag == "spectrum":
            return self.spectrum(el)
        if tag in ("point", "vector"):
            if el.get("value") is not None:
                return self.numbers(el, self.attr(el, "value"), 3)
            return [float(self.numbers(el, self.attr(el, k, "0"), 1)[0]) for k in "xyz"]
        raise self.error(f"unsupported <{tag}>", el)

    def spectrum(self, el):
        """A <spectrum> as the linear sRGB colour Mitsuba's RGB variants make of it
        (scene.spectra): uniform, wavelength:value pairs or an .spd file; an emitter's
        (a spectrum inside an <emitter>) is integrated without D65 and unclipped."""
        emitter = self.parent.get(el) is not None and self.parent[el].tag == "emitter"
        name = self.attr(el, "filename")
        if name:
            path = self.file(name)
            try:
                table = np.loadtxt(path if os.path.isabs(path) else
                                   os.path.join(self.base, path), comments="#", ndmin=2)
            except (OSError, ValueError) as e:
                raise self.error(f"spectrum file {name}: cannot read it "
                                 f"({' '.join(str(e).split())[:120]})", el) from None
            if table.shape[1] != 2 or len(table) < 2:
                raise self.error(f"spectrum file {name}: expected lines of 'wavelength "
                                 "value'", el)
            return self._pairs(el, table[:, 0], table[:, 1], emitter)
        text = self.attr(el, "value", "")
        if ":" in text:
            try:
                pairs = [tuple(float(x) for x in item.split(":")) for item in
                         re.split(r"\s*,\s*", text.strip()) if item]
                w, v = zip(*pairs)
            except ValueError:
                raise self.error(f"expected wavelength:value pairs, got {text[:60]!r}",
                                 el) from None
            return self._pairs(el, w, v, emitter)
        v = self.numbers(el, text, 1)[0]
        return [float(x) for x in uniform_to_rgb(v, emitter)]

    def _pairs(self, el, w, v, emitter):
        w, v = np.asarray(w, float), np.asarray(v, float)
        if len(w) < 2 or not (np.all(np.diff(w) > 0) and np.isfinite(v).all()):
            raise self.error("a spectrum needs two or more increasing wavelengths with "
                             "finite values", el)
        return [float(x) for x in spectrum_to_rgb(w, v, emitter)]

    KINDS = {"int": ("integer",), "float": ("float", "integer"), "str": ("string",),
             "bool": ("boolean",), "color": ("rgb", "spectrum", "float", "integer"),
             "point": ("point", "vector")}

    def get(self, p, name, kind, default=None):
        """The value of parameter ``name`` of ``p`` (self.params), checked to be of
        ``kind`` (int, float, str, bool, color, point); ``default`` when absent."""
        if name not in p:
            return default
        tag, el = p[name]
        if tag not in self.KINDS[kind]:
            raise self.error(f"{name}: expected <{self.KINDS[kind][0]}>, got <{tag}>", el)
        v = self.value(el)
        if kind == "float":
            return float(v)
        if kind == "color" and tag in ("float", "integer"):
            v = [float(v)] * 3
        if kind == "color" and any(x < 0 for x in v):
            raise self.error(f"{name}: negative colour component in {v}", el)
        return v

    def transform(self, el):
        """The 4x4 matrix of a <transform>: its operations applied in order."""
        if el.tag != "transform":
            raise self.error(f"expected a <transform>, got <{el.tag}>", el)
        m = np.eye(4)
        for op in el:
            if op.tag == "translate":
                t = self._xyz(op, 0.0)
                step = np.eye(4)
                step[:3, 3] = t
            elif op.tag == "scale":
                if op.get("value") is not None:
                    s = self.numbers(op, self.attr(op, "value"))
                    s = s * 3 if len(s) == 1 else s
                    if len(s) != 3:
                        raise self.error("expected 1 or 3 numbers", op)
                else:
                    s = self._xyz(op, 1.0)
                step = np.diag(list(s) + [1.0])
            elif op.tag == "rotate":
                axis = np.array(self._xyz(op, 0.0))
                angle = self.numbers(op, self.attr(op, "angle", "0"), 1)[0]
                if not np.linalg.norm(axis) > 0:
                    raise self.error("rotation axis of zero length", op)
                step = np.eye(4)
                step[:3, :3] = _rotation(axis / np.linalg.norm(axis), math.radians(angle))
            elif op.tag == "matrix":
                v = self.numbers(op, self.attr(op, "value", ""))
                if len(v) == 9:
                    step = np.eye(4)
                    step[:3, :3] = np.reshape(v, (3, 3))
                elif len(v) == 16:
                    step = np.reshape(v, (4, 4))
                else:
                    raise self.error("a matrix takes 9 or 16 numbers", op)
            elif op.tag == "lookat":
                origin = np.array(self.numbers(op, self.attr(op, "origin", ""), 3))
                target = np.array(self.numbers(op, self.attr(op, "target", ""), 3))
                up = np.array(self.numbers(op, self.attr(op, "up", "0 1 0"), 3))
                step = _look_at(origin, target, up)
                if step is None:
                    raise self.error("lookat: origin equals target, or up is along the view",
                                     op)
            else:
                raise self.error(f"unsupported transform operation <{op.tag}>", op)
            m = step @ m
        return m

    def _xyz(self, el, default):
        if el.get("value") is not None:
            v = self.numbers(el, self.attr(el, "value"), 3)
            return v * 3 if len(v) == 1 else v
        return [self.numbers(el, self.attr(el, k, str(default)), 1)[0] for k in "xyz"]


def _rotation(axis, angle):
    """Rodrigues: rotation by ``angle`` radians about the unit ``axis`` (counter-clockwise
    seen from the axis's tip, as Mitsuba's rotate)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    C = 1 - c
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


def _look_at(origin, target, up):
    """Mitsuba's look_at: columns left = up x dir, up' = dir x left, dir, origin."""
    d = target - origin
    if not np.linalg.norm(d) > 0:
        return None
    d = d / np.linalg.norm(d)
    left = np.cross(up, d)
    if not np.linalg.norm(left) > 1e-12:
        return None
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def convert_file(path, params=None):
    """(scene dict in the JSON format, warnings) of the Mitsuba 3 XML file at ``path``.
    ``params``: {name: value} that set the scene's ``$name`` parameters over its
    ``<default>`` values (Mitsuba's ``-D name=value``)."""
    try:
        tree = ET.parse(path)
    except FileNotFoundError:
        raise SceneError("scene file not found", path) from None
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror or e}", path) from None
    except ET.ParseError as e:
        raise SceneError(f"invalid XML: {e}", path) from None
    root = tree.getroot()
    r = _Reader(path)
    if root.tag != "scene":
        raise SceneError(f"expected a Mitsuba <scene> element, got <{root.tag}>", path)
    version = root.get("version", "")
    if re.match(r"0\.", version):
        raise SceneError(f"a Mitsuba 0.6 scene (version {version}): pt-render reads Mitsuba 3's "
                         "names only ('to_world', 'int_ior', 'sample_count', ...)", path)
    if not version.startswith("3"):
        r.warn(f"scene version {version or '(none)'}: read as Mitsuba 3 XML")
    _index(r, root, "/scene")
    r.defaults.update({str(k): str(v) for k, v in (params or {}).items()})
    _expand_includes(r, root, 0)
    for el in root:
        if el.tag == "default":
            name = el.get("name")
            if not name:
                raise r.error("<default> without a name", el)
            r.defaults.setdefault(name, el.get("value", ""))
    _substitute(r, root)
    for el in root:
        if el.tag == "path":
            folder = el.get("value")
            if not folder:
                raise r.error("<path> without a value", el)
            r.search.insert(0, folder if os.path.isabs(folder) else
                            os.path.join(r.base, folder))
    out = {"camera": {}, "render": {}, "materials": [], "objects": []}
    materials = {}     # bsdf id or element -> material name
    for el in root:
        if el.tag == "bsdf":
            bid = el.get("id")
            if not bid:
                raise r.error("a top-level <bsdf> needs an id", el)
            r.bsdfs[bid] = el
        elif el.tag == "emitter" and el.get("id"):
            r.emitters[el.get("id")] = el
        if el.get("id"):
            r.ids[el.get("id")] = el
    have_sensor = False
    for el in root:
        tag = el.tag
        if tag in ("default", "bsdf", "path"):
            continue
        if tag in ("sampler", "film", "rfilter", "texture", "spectrum", "rgb"):
            if not el.get("id"):
                r.warn(f"a top-level <{tag}> without an id is not used", el)
            continue        # used where a <ref> names it
        if tag == "integrator":
            _integrator(r, el, out["render"])
        elif tag == "sensor":
            if have_sensor:
                r.warn("more than one <sensor>: the first is used", el)
                continue
            have_sensor = True
            _sensor(r, el, out)
        elif tag == "shape":
            _shape(r, el, out, materials)
        elif tag == "emitter":
            if el.get("type") == "area" and el.get("id"):
                continue        # a shape's emitter, declared here and used by <ref>
            _emitter(r, el, out)
        else:
            raise r.error(f"<{tag}> is not supported (pt-render reads sensors, shapes, "
                          "BSDFs, emitters and the path integrator)", el)
    if not have_sensor:
        _default_sensor(r, out)
    if not any(el.tag == "integrator" for el in root):
        r.warn("no <integrator>: rendered by the path tracer with pt-render's default of 8 "
               "bounces (Mitsuba's max_depth 9); Mitsuba 3.9.1 asks for one")
    if not out["materials"]:
        del out["materials"]
    return out, r.warnings


MAX_INCLUDE_DEPTH = 8


def _expand_includes(r, el, depth):
    """Every ``<include filename="..."/>`` among el's children replaced by the children of
    the included file's ``<scene>`` (Mitsuba's include: files relative to the scene's
    folder, as Mitsuba's own XML writer splits materials, geometry, emitters and cameras
    into separate files), recursively."""
    i = 0
    while i < len(el):
        child = el[i]
        if child.tag != "include":
            i += 1
            continue
        name = child.get("filename")
        if not name:
            raise r.error("<include> without a filename", child)
        if depth >= MAX_INCLUDE_DEPTH:
            raise r.error(f"includes nested deeper than {MAX_INCLUDE_DEPTH} (a file that "
                          "includes itself?)", child)
        path = name if os.path.isabs(name) else os.path.join(r.base, name)
        try:
            sub = ET.parse(path).getroot()
        except FileNotFoundError:
            raise r.error(f"included file {name} not found", child) from None
        except OSError as e:
            raise r.error(f"cannot read included file {name}: {e.strerror or e}",
                          child) from None
        except ET.ParseError as e:
            raise r.error(f"included file {name}: invalid XML: {e}", child) from None
        if sub.tag != "scene":
            raise r.error(f"included file {name}: expected a <scene> element, got "
                          f"<{sub.tag}>", child)
        _index(r, sub, f"{r.where.get(child, '/scene')} -> {name}:/scene")
        _expand_includes(r, sub, depth + 1)
        el[i:i + 1] = list(sub)
        i += len(sub)


def _substitute(r, el):
    """``$name`` replaced by its parameter in every attribute below ``el`` (types, ids and
    names too: Bitterli's exports write ``<integrator type="$integrator">``), as Mitsuba's
    parser does; a name without a value is an error naming it."""
    for child in el.iter():
        if child is el or child.tag == "default":
            continue
        for k, v in child.attrib.items():
            if "$" in v:
                child.set(k, r.attr(child, k))


def _index(r, el, where):
    """Name every element by its path, for error messages."""
    counts = {}
    for child in el:
        counts[child.tag] = counts.get(child.tag, 0) + 1
        w = f"{where}/{child.tag}[{counts[child.tag]}]"
        label = child.get("id") or child.get("name")
        if child.get("type"):
            w += f" (type={child.get('type')}{', ' + label if label else ''})"
        elif label:
            w += f" ({label})"
        r.where[child] = w
        r.parent[child] = el
        _index(r, child, w)


# ---------------------------------------------------------------------------------------

# Integrators that wrap another (extra images, polarisation): their nested integrator's
# image is rendered, with a warning
WRAPPERS = {"moment": "its moment images are not written", "aov": "its AOV images are not "
            "written (--aovs writes albedo and normal)", "stokes": "polarisation is not "
            "rendered"}
# Other estimators of the same image: rendered by ours, with a warning
SAME_IMAGE = {"ptracer": "path", "prb": "path", "prb_basic": "path", "path_projective": "path",
              "volpathmis": "volpath", "prbvolpath": "volpath", "direct_projective": "direct"}


def _integrator(r, el, render):
    kind = el.get("type")
    if kind in WRAPPERS:
        inner = [c for c in el if c.tag == "integrator"]
        if not inner:
            raise r.error(f"integrator {kind!r} without a nested integrator: nothing "
                          "pt-render renders", el)
        r.warn(f"integrator {kind!r}: its nested {inner[0].get('type')!r} integrator is "
               f"rendered ({WRAPPERS[kind]})", el)
        return _integrator(r, inner[0], render)
    if kind in SAME_IMAGE:
        r.warn(f"integrator {kind!r} read as {SAME_IMAGE[kind]!r} (another estimator of "
               "the same image)", el)
        kind = SAME_IMAGE[kind]
    p = r.params(el)
    if kind in ("path", "volpath"):
        if kind == "volpath":
            r.warn("volpath read as path (pt-render has no participating media)", el)
        depth = r.get(p, "max_depth", "int", -1)
        if depth == 0:
            raise r.error("max_depth 0 renders nothing", el)
        render["maxBounces"] = 64 if depth < 0 else depth - 1
        if depth < 0:
            r.warn("max_depth -1 (unbounded) read as 64 bounces", el)
        if "rr_depth" in p:
            render["rrDepth"] = r.get(p, "rr_depth", "int")
        if r.get(p, "hide_emitters", "bool", False):
            render["hideEmitters"] = True
        for k in p:
            if k not in ("max_depth", "rr_depth", "hide_emitters"):
                r.warn(f"integrator parameter {k!r} ignored", el)
    elif kind == "direct":
        render["maxBounces"] = 1
        if r.get(p, "hide_emitters", "bool", False):
            render["hideEmitters"] = True
        for k in p:
            if k in ("emitter_samples", "bsdf_samples", "shading_samples"):
                r.warn(f"direct integrator: {k} ignored (one light and one BSDF sample per "
                       "pass, combined by MIS: the same image, other noise; Mitsuba 3.9.1 "
                       "multiplies point, spot and directional lights by emitter_samples "
                       "here, pt-render does not)", p[k][1])
            elif k != "hide_emitters":
                r.warn(f"integrator parameter {k!r} ignored", el)
    else:
        raise r.error(f"integrator {kind!r} is not supported (path, volpath, direct; "
                      f"{', '.join(sorted(SAME_IMAGE))} read as one of them; "
                      f"{', '.join(WRAPPERS)} by their nested one)",
                      el)


def _sensor(r, el, out):
    kind = el.get("type")
    if kind not in ("perspective", "thinlens"):
        raise r.error(f"sensor {kind!r} is not supported (perspective, thinlens)", el)
    p = r.params(el)
    cam = out["camera"]
    width, height = 768, 576                       # Mitsuba's hdrfilm defaults
    for child in el:
        if child.tag == "ref":
            ref = child
            child = r.ids.get(ref.get("id"))
            if child is None or child.tag not in ("film", "sampler"):
                raise r.error(f"<ref id={ref.get('id')!r}>: no top-level film or sampler "
                              "with that id", ref)
        if child.tag == "film":
            fp = r.params(child)
            width = r.get(fp, "width", "int", width)
            height = r.get(fp, "height", "int", height)
            for f in child:
                if f.tag == "rfilter" and f.get("type") != "box":
                    r.warn(f"reconstruction filter {f.get('type')!r}: pt-render uses a box "
                           "filter (one pixel)", f)
                if f.tag == "rfilter" and f.get("type") is None:
                    pass
            if not any(f.tag == "rfilter" for f in child):
                r.warn("no <rfilter>: Mitsuba's default is a Gaussian; pt-render uses a box "
                       "filter (one pixel)", child)
        elif child.tag == "sampler":
            sp = r.params(child)
            if "sample_count" in sp:
                out["render"]["spp"] = r.get(sp, "sample_count", "int")
            if child.get("type") == "independent":
                out["render"]["sampler"] = "independent"
            if "seed" in sp:
                out["render"]["seed"] = r.get(sp, "seed", "int")
    cam["resolution"] = [width, height]
    m = r.transform(p["to_world"][1]) if "to_world" in p else np.eye(4)
    origin = m[:3, 3]
    fwd, up, left = m[:3, 2], m[:3, 1], m[:3, 0]
    if not (np.linalg.norm(fwd) > 0 and np.linalg.norm(up) > 0):
        raise r.error("the sensor's to_world is degenerate", el)
    if np.dot(np.cross(up, fwd), left) <= 0:
        raise r.error("the sensor's to_world mirrors the image (left != up x forward): not "
                      "expressible as a camera position, target and up", el)
    fwd_n = fwd / np.linalg.norm(fwd)
    cam["position"] = origin.tolist()
    cam["lookAt"] = (origin + fwd_n).tolist()
    cam["up"] = (up / np.linalg.norm(up)).tolist()
    tx = _tan_half_fov_x(r, el, p, width / height)
    cam["fov"] = math.degrees(2 * math.atan(tx))
    if kind == "thinlens":
        radius = r.get(p, "aperture_radius", "float", 0.0)
        focus = r.get(p, "focus_distance", "float", 0.0)
        if radius > 0:
            # the scene format's thin lens: radius = focalLength / (2 aperture), with the
            # focal length derived from fov and the default 36 mm sensor width
            focal = 0.036 / (2 * tx)
            cam["aperture"] = focal / (2 * radius)
            cam["focusDistance"] = focus


def _default_sensor(r, out):
    """Mitsuba's camera for a scene without a sensor (its Scene constructor): a 45-degree
    perspective camera looking along +Z from in front of the scene's bounding box, at the
    distance where the box's largest extent fills the view; a 768 x 576 film."""
    lo, hi = _bounds(r, out)
    center, extents = (lo + hi) / 2, hi - lo
    distance = float(extents.max()) / (2 * math.tan(math.radians(22.5)))
    origin = [float(center[0]), float(center[1]), float(lo[2] - distance)]
    out["camera"] = {"resolution": [768, 576], "position": origin,
                     "lookAt": [origin[0], origin[1], origin[2] + 1], "up": [0, 1, 0],
                     "fov": 45.0}
    r.warn("no <sensor>: Mitsuba's default camera (45 degrees, looking along +Z at the "
           "whole scene)")


def _bounds(r, out):
    """The bounding box (lo, hi) of the converted objects, their files read."""
    points = []
    for obj in out["objects"]:
        if "file" in obj:
            path = obj["file"] if os.path.isabs(obj["file"]) else os.path.join(r.base,
                                                                             obj["file"])
            try:
                v = load_mesh(path, shape_index=obj.get("shapeIndex", 0)).positions
            except Exception:   # (any reader's failure): the scene's load reports it
                continue
            v = v.reshape(-1, 3).astype(np.float64)
        else:
            v = np.asarray(obj["vertices"], np.float64)
        if "transform" in obj:
            m = np.asarray(obj["transform"]["matrix"])
            v = v @ m[:3, :3].T + m[:3, 3]
        if len(v):
            points.append(np.array([v.min(0), v.max(0)]))
    if not points:
        return -np.ones(3), np.ones(3)
    both = np.concatenate(points)
    return both.min(0), both.max(0)


def _tan_half_fov_x(r, el, p, aspect):
    """tan(fov_x / 2) of a perspective sensor, by Mitsuba's rule (sensor.h, parse_fov):
    ``fov`` on ``fov_axis`` (x by default; smaller/larger by the film's aspect), else
    ``focal_length`` (default "50mm") on the 35 mm film's diagonal (43.27 mm), kept for
    any aspect ratio: 34.02 degrees horizontally on a square film, 39.6 only on 3:2."""
    if "fov" in p and "focal_length" in p:
        raise r.error("give fov or focal_length, not both (as Mitsuba)", el)
    if "fov" in p:
        fov = r.get(p, "fov", "float")
        if not 0 < fov < 180:
            raise r.error(f"fov {fov:g}: expected degrees in (0, 180)", p["fov"][1])
        axis = r.get(p, "fov_axis", "str", "x").lower()
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
    else:
        text = r.get(p, "focal_length", "str", "50mm").strip()
        text = text[:-2] if text.endswith("mm") else text
        try:
            focal = float(text)
        except ValueError:
            raise r.error(f"focal_length {text!r}: expected millimetres, e.g. \"50mm\"",
                          p["focal_length"][1]) from None
        if not (math.isfinite(focal) and focal > 0):
            raise r.error(f"focal_length {text!r}: expected a positive length",
                          p["focal_length"][1])
        if "fov_axis" in p:
            r.warn("fov_axis ignored: a focal length is on the film's diagonal (as Mitsuba)",
                   p["fov_axis"][1])
        fov = math.degrees(2 * math.atan(math.hypot(36.0, 24.0) / (2 * focal)))
        axis = "diagonal"
    t = math.tan(math.radians(fov) / 2)
    if axis == "x":
        return t
    if axis == "y":
        return t * aspect
    if axis == "diagonal":
        return t / math.sqrt(1 + 1 / (aspect * aspect))
    raise r.error(f"fov_axis {axis!r}: expected x, y, diagonal, smaller or larger", el)


def _rgb_or_texture(r, el, tag_el, scalar=False):
    """A colour or a bitmap texture value in the scene format. ``scalar``: the value feeds
    a number (Mitsuba reads it with ``eval_1``)."""
    tag, v = tag_el
    if tag == "ref":
        target = r.ids.get(v.get("id"))
        if target is None or target.tag not in ("texture", "rgb", "spectrum"):
            raise r.error(f"<ref id={v.get('id')!r}>: no top-level texture with that id", v)
        tag, v = target.tag, target
    if tag == "texture":
        kind = v.get("type")
        if kind not in ("bitmap", "checkerboard", "rawconstant"):
            raise r.error(f"texture {kind!r} is not supported (bitmap, checkerboard, "
                          "rawconstant)", v)
        tp = r.params(v)
        if kind == "rawconstant":
            # a constant value read as it is (no colour conversion): a 1 x 1 linear image
            tag_v, el_v = tp.get("value", ("float", None))
            if el_v is None:
                raise r.error("rawconstant without a value", v)
            value = [float(x) for x in re.split(r"[,\s]+", el_v.get("value").strip())]
            if len(value) not in (1, 3):
                raise r.error("rawconstant: expected one or three numbers", el_v)
            img = np.array([[value * 3 if len(value) == 1 else value]], np.float32)
            buf = io.BytesIO()
            np.save(buf, img, allow_pickle=False)
            return {"texture": cached_file(buf.getvalue(), ".npy", "mitsuba-textures"),
                    "colorSpace": "linear", "filter": "nearest"}
        if kind == "checkerboard":
            # Mitsuba's checkerboard (checkerboard.cpp): color0 where the fractional parts
            # of (u, v) are both above 1/2 or both not, else color1 -- exactly a 2 x 2
            # image looked up nearest and repeated, which is how it is rendered here
            c0 = r.get(tp, "color0", "color", [0.4] * 3)
            c1 = r.get(tp, "color1", "color", [0.2] * 3)
            if scalar:
                # Mitsuba 3.9.1's checkerboard gives the two values the other way round
                # when a number is read from it (its eval_1 against its eval, checked
                # live in tests/test_mitsuba_xml.py): its images are matched
                c0, c1 = c1, c0
            img = np.array([[c0, c1], [c1, c0]], np.float32)
            buf = io.BytesIO()
            np.save(buf, img, allow_pickle=False)
            spec = {"texture": cached_file(buf.getvalue(), ".npy", "mitsuba-textures"),
                    "colorSpace": "linear", "filter": "nearest"}
            known = ("color0", "color1", "to_uv")
        else:
            if "filename" not in tp:
                raise r.error("bitmap without a filename", v)
            spec = {"texture": r.file(r.get(tp, "filename", "str"))}
            raw = r.get(tp, "raw", "bool", False)
            spec["colorSpace"] = "linear" if raw else "sRGB"
            # Mitsuba 3 has no mip-maps: its bitmaps are filtered bilinearly (or nearest)
            ft = r.get(tp, "filter_type", "str") if "filter_type" in tp else "bilinear"
            spec["filter"] = "nearest" if ft == "nearest" else "bilinear"
            known = ("filename", "raw", "filter_type", "wrap_mode", "to_uv")
        wrap = r.get(tp, "wrap_mode", "str", "repeat")
        if wrap not in ("repeat", "mirror", "clamp"):
            raise r.error(f"wrap_mode {wrap!r}: expected repeat, mirror or clamp", v)
        if wrap != "repeat":
            spec["wrap"] = wrap
        if "to_uv" in tp:
            m = r.transform(tp["to_uv"][1])
            # (u, v) -> rows 0 and 1, columns 0, 1 and the translation's 3 (a 4 x 4 given for
            # a 2D transform: its z row and column are not used)
            if not (np.allclose(m[:2, :2], np.diag(np.diag(m[:2, :2]))) and
                    np.allclose(m[:2, 2], 0)):
                raise r.error("to_uv: only a scale and a translation of (u, v) are supported "
                              "(no rotation)", tp["to_uv"][1])
            su, sv, tu, tv = m[0, 0], m[1, 1], m[0, 3], m[1, 3]
            # Mitsuba's rows count from the top at v_m = 1 - v (its mesh loaders flip v):
            # its row s_v v_m + t_v is ours from the bottom at s_v v + (1 - s_v - t_v)
            spec["tile"] = [float(su), float(sv)]
            spec["offset"] = [float(tu), float(1 - sv - tv)]
        for k in tp:
            if k not in known:
                r.warn(f"{kind} parameter {k!r} ignored", v)
        return spec
    return r.get({"value": (tag, v)}, "value", "color")


def _number(r, tag_el, what):
    tag, v = tag_el
    if tag in ("float", "integer"):
        return float(r.value(v))
    raise r.error(f"{what}: expected a <float> (textured values are not supported here)", v)


def _bsdf(r, el, name):
    """The scene-format material of a Mitsuba BSDF element. Mitsuba's reflective BSDFs
    (diffuse, principled without transmission, conductors) are black from behind unless
    wrapped in twosided: oneSided (checked against Mitsuba 3.9.1's evaluation)."""
    mat = _bsdf_kind(r, el, name)
    if el.get("type") not in ("twosided", "mask", "null", "thindielectric") and \
            not mat.get("transmission"):
        mat["oneSided"] = True
    return mat


def _bsdf_kind(r, el, name):
    kind = el.get("type")
    p = r.params(el)
    if kind == "twosided":
        inner = [c for c in el if c.tag in ("bsdf", "ref")]
        if len(inner) != 1:
            raise r.error("twosided takes one BSDF (two different sides are not supported)",
                          el)
        # twoSided would make an emitter emit on both sides, which a Mitsuba area
        # emitter never does: here only the BSDF reflects on both sides
        mat = _bsdf(r, _deref(r, inner[0]), name)
        mat.pop("oneSided", None)
        return mat
    if kind == "mask":
        # Mitsuba's mask: its nested BSDF where a ray meets it with probability `opacity`
        # (a float or a texture, default 0.5), else a null interaction: stochastic
        # transparency, alphaMode blend (a textured opacity read as its luminance)
        inner = [c for c in el if c.tag in ("bsdf", "ref")]
        if len(inner) != 1:
            raise r.error("mask takes one BSDF", el)
        mat = _bsdf(r, _deref(r, inner[0]), name)
        opacity = p.get("opacity", ("float", None))
        if opacity[0] in ("texture", "ref"):
            mat["alpha"] = _rgb_or_texture(r, el, opacity, scalar=True)
        else:
            mat["alpha"] = min(max(float(r.value(opacity[1])), 0.0), 1.0) \
                if opacity[1] is not None else 0.5
        mat["alphaMode"] = "blend"
        return mat
    if kind == "null":
        # Mitsuba's null BSDF: rays pass through the surface as if it were not there (it
        # bounds media, or carries an emitter): a cut-out everywhere (alpha 0, mask)
        _only(r, el, p, ())
        return {"name": name, "type": "diffuse", "alpha": 0.0, "alphaMode": "mask"}
    if kind == "diffuse":
        mat = {"name": name, "type": "diffuse"}
        if "reflectance" in p:
            mat["albedo"] = _rgb_or_texture(r, el, p["reflectance"])
        return mat
    if kind == "principled":
        mat = {"name": name, "type": "principled"}
        for k, (tag, v) in p.items():
            if k == "base_color":
                mat["albedo"] = _rgb_or_texture(r, el, (tag, v))
            elif k in PRINCIPLED_KEYS and PRINCIPLED_KEYS[k] not in ("albedo", "emission"):
                if tag in ("texture", "ref") and PRINCIPLED_KEYS[k] in PRINCIPLED_TEXTURABLE:
                    # a textured number, read as the texture's luminance (as Mitsuba reads
                    # a colour texture given for a float parameter)
                    tex = _rgb_or_texture(r, el, (tag, v), scalar=True)
                    if isinstance(tex, dict):
                        tex["colorSpace"] = "linear"
                    mat[PRINCIPLED_KEYS[k]] = tex
                else:
                    mat[PRINCIPLED_KEYS[k]] = _number(r, (tag, v), k)
            else:
                raise r.error(f"principled parameter {k!r} is not supported", v)
        return mat
    if kind in ("dielectric", "thindielectric", "roughdielectric"):
        if kind == "thindielectric":
            # a thin pane: reflects R' = 2R / (1 + R), passes the rest straight through
            for key in ("specular_reflectance", "specular_transmittance"):
                if key in p and r.get(p, key, "color") != [1.0, 1.0, 1.0]:
                    raise r.error(f"thindielectric {key} other than 1 is not supported", el)
            _only(r, el, p, ("int_ior", "ext_ior", "specular_reflectance",
                             "specular_transmittance"))
            return {"name": name, "type": "thindielectric",
                    "eta": _ior(r, p, "int_ior", 1.5046) / _ior(r, p, "ext_ior", 1.000277)}
        eta = _ior(r, p, "int_ior", 1.5046) / _ior(r, p, "ext_ior", 1.000277)
        mat = {"name": name, "type": "principled", "albedo": 1.0, "transmission": 1.0,
               "roughness": 0.0, "eta": eta}
        if kind == "roughdielectric":
            mat["roughness"] = _roughness(r, el, p)
            r.warn("roughdielectric read as the principled BSDF's rough transmission "
                   "(the same GGX microfacets; Fresnel and energy differ slightly)", el)
        _only(r, el, p, ("int_ior", "ext_ior", "alpha", "distribution", "specular_reflectance",
                         "specular_transmittance"))
        return mat
    if kind in ("conductor", "roughconductor"):
        # exact: Mitsuba's microfacet conductor with the complex Fresnel term (the
        # conductor material kind, kernels.conductor)
        eta, k = _conductor_eta_k(r, el, p)
        mat = {"name": name, "type": "conductor", "eta": eta, "k": k}
        if "specular_reflectance" in p:
            mat["albedo"] = _rgb_or_texture(r, el, p["specular_reflectance"])
        if kind == "roughconductor":
            mat["distribution"] = _distribution(r, el, p)
            if "alpha_u" in p or "alpha_v" in p:
                if "alpha" in p:
                    raise r.error("give alpha or alpha_u and alpha_v, not both", el)
                mat["alphaU"] = _alpha_value(r, el, p, "alpha_u")
                mat["alphaV"] = _alpha_value(r, el, p, "alpha_v")
            else:
                mat["alphaU"] = _alpha_value(r, el, p, "alpha")
        _only(r, el, p, ("material", "alpha", "distribution", "specular_reflectance", "eta",
                         "k", "ext_eta", "alpha_u", "alpha_v", "sample_visible"))
        return mat
    if kind in ("plastic", "roughplastic"):
        return _plastic(r, el, p, name, kind)
    if kind == "normalmap":
        # a tangent-space normal map (a raw bitmap, 2c - 1 per channel) over its nested BSDF
        inner = [c for c in el if c.tag in ("bsdf", "ref")]
        if len(inner) != 1 or "normalmap" not in p:
            raise r.error("normalmap takes one nested BSDF and a 'normalmap' texture", el)
        mat = _bsdf(r, _deref(r, inner[0]), name)
        tex = _rgb_or_texture(r, el, p["normalmap"])
        if not isinstance(tex, dict):
            raise r.error("normalmap: the 'normalmap' must be a bitmap texture", el)
        tex["colorSpace"] = "linear"
        mat["normalMap"] = tex
        if mat.get("type") == "diffuse":
            # (normal maps are read by the principled material; a Lambertian one is its
            # diffuse lobe with the retro-reflection off: roughness 0, specular 0)
            mat = {"name": name, "type": "principled", "albedo": mat.get("albedo", 0.5),
                   "roughness": 0.0, "specular": 0.0, "metallic": 0.0,
                   "normalMap": tex, **({"oneSided": True} if mat.get("oneSided") else {})}
            r.warn("normalmap over a diffuse BSDF: rendered by the principled BSDF's diffuse "
                   "lobe (Burley's, a little darker than Lambert's at grazing angles)", el)
        return mat
    raise r.error(f"BSDF {kind!r} is not supported: diffuse, principled, dielectric, "
                  "roughdielectric, conductor, roughconductor, plastic, roughplastic, "
                  "normalmap, mask, null, twosided", el)


def _fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of light meeting an interface of relative index
    eta (transmitted side over incident side) at cos_i (numpy arrays); 1 where it is
    totally reflected."""
    sin2_t = (1 - cos_i ** 2) / eta ** 2
    cos_t = np.sqrt(np.clip(1 - sin2_t, 0, None))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return np.where(sin2_t >= 1, 1.0, 0.5 * (rs ** 2 + rp ** 2))


def _diffuse_fresnel(eta, n=20000):
    """The cosine-weighted hemispherical average of the Fresnel reflectance (Mitsuba's
    fresnel_diffuse_reflectance): 2 * integral of F(cos) cos d(cos)."""
    c = (np.arange(n) + 0.5) / n
    return float(2 * np.mean(_fresnel_dielectric(c, eta) * c))


def _plastic(r, el, p, name, kind):
    """Mitsuba's plastic and roughplastic: a diffuse base under a dielectric coat. Here the
    principled BSDF approximates it (a warning): its specular lobe with the coat's
    reflectance at normal incidence F0 (specular = F0 / 0.08; GGX of the same alpha,
    smooth for plastic), and its diffuse lobe with the base's reflectance scaled as
    Mitsuba scales it at normal incidence: (1 - F0)^2 / eta^2 / (1 - F_dr) (nonlinear:
    / (1 - rho F_dr)), F_dr the coat's internal diffuse Fresnel reflectance. Burley's
    diffuse and Schlick's Fresnel then differ from Mitsuba's (1 - F) transmission terms
    away from normal incidence."""
    eta = _ior(r, p, "int_ior", 1.49) / _ior(r, p, "ext_ior", 1.000277)
    # a colour, or a texture (whose scale takes the factor below; with nonlinear, the
    # factor of a mid-grey texel)
    base = _rgb_or_texture(r, el, p["diffuse_reflectance"]) if "diffuse_reflectance" in p \
        else [0.5] * 3
    texture = base if isinstance(base, dict) else None
    rho = [0.5] * 3 if texture is not None else base
    spec = r.get(p, "specular_reflectance", "color", [1.0] * 3)
    nonlinear = r.get(p, "nonlinear", "bool", False)
    f0 = ((eta - 1) / (eta + 1)) ** 2
    f_dr = _diffuse_fresnel(1 / eta)
    rho = np.asarray(rho, float)
    scale = (1 - f0) ** 2 / eta ** 2 / ((1 - rho * f_dr) if nonlinear else (1 - f_dr))
    albedo = [float(x) for x in np.clip(rho * scale, 0, 1)]
    if texture is not None:
        texture["scale"] = [float(x) for x in np.broadcast_to(scale, 3)]
        albedo = texture
    mat = {"name": name, "type": "principled", "metallic": 0.0, "albedo": albedo,
           "specular": float(min(1.0, f0 / 0.08 * float(np.mean(spec)))),
           "roughness": _roughness(r, el, p) if kind == "roughplastic" else 0.0}
    _only(r, el, p, ("int_ior", "ext_ior", "diffuse_reflectance", "specular_reflectance",
                     "nonlinear", "alpha", "distribution", "sample_visible"))
    r.warn(f"{kind} approximated by the principled BSDF (its specular lobe at the coat's "
           f"F0 = {f0:.4f}, its diffuse lobe with the base's reflectance x "
           f"{float(np.mean(scale)):.3f}, Mitsuba's internal scattering at normal incidence)",
           el)
    return mat


@functools.lru_cache(maxsize=1)
def conductor_table():
    """{name: (eta rgb, k rgb)} of Mitsuba's named conductors (data/conductors.csv)."""
    path = os.path.join(os.path.dirname(__file__), "data", "conductors.csv")
    out = {}
    with open(path) as f:
        for line in f:
            if line.strip() and not line.startswith("#"):
                name, *v = line.strip().split(",")
                out[name] = (np.array(v[:3], float), np.array(v[3:], float))
    return out


def _conductor_eta_k(r, el, p):
    """A conductor's complex index of refraction eta + i k per channel, relative to
    ext_eta: Mitsuba's named materials (its RGB values of their spectral data), or eta
    and k given; 'none' (the default) is a perfect mirror (eta 0, k 1: reflectance 1)."""
    material = r.get(p, "material", "str", "none")
    if "eta" in p or "k" in p:
        if material != "none":
            raise r.error("give a conductor's material or its eta and k, not both", el)
        eta = np.array(r.get(p, "eta", "color", [0.0] * 3))
        k = np.array(r.get(p, "k", "color", [1.0] * 3))
    elif material == "none":
        eta, k = np.zeros(3), np.ones(3)
    else:
        table = conductor_table()
        if material not in table:
            raise r.error(f"conductor material {material!r}: not one of Mitsuba's "
                          f"({', '.join(sorted(table))})", el)
        eta, k = table[material]
    ext = _ior(r, p, "ext_eta", 1.0)
    return [float(x) for x in eta / ext], [float(x) for x in k / ext]


def _alpha_value(r, el, p, key):
    """A microfacet alpha of Mitsuba (default 0.1): a number in [0, 1] or a texture."""
    if key not in p:
        return 0.1
    tag, v = p[key]
    if tag in ("texture", "ref"):
        tex = _rgb_or_texture(r, el, p[key], scalar=True)
        if isinstance(tex, dict):
            tex["colorSpace"] = "linear"
        return tex
    alpha = _number(r, p[key], key)
    if not 0 <= alpha <= 1:
        raise r.error(f"{key} {alpha:g} outside [0, 1]", v)
    return alpha


def _only(r, el, p, allowed):
    for k in p:
        if k not in allowed:
            raise r.error(f"parameter {k!r} of {el.get('type')} is not supported", p[k][1])


def _ior(r, p, key, default):
    if key not in p:
        return default
    tag, v = p[key]
    if tag == "string":
        name = r.get(p, key, "str").lower()
        if name not in IOR_NAMES:
            raise r.error(f"index of refraction {name!r}: not in pt-render's table "
                          f"({', '.join(sorted(IOR_NAMES))}); give a number", v)
        return IOR_NAMES[name]
    eta = r.get(p, key, "float")
    if not eta > 0:
        raise r.error(f"{key}: an index of refraction must be > 0, got {eta}", v)
    return eta


def _roughness(r, el, p):
    """Mitsuba's microfacet alpha -> the principled roughness (alpha = roughness^2); its
    default distribution, Beckmann, is rendered as GGX of the same alpha (a warning)."""
    _beckmann_as_ggx(r, el, p)
    if "alpha_u" in p or "alpha_v" in p:
        raise r.error("anisotropic alpha_u/alpha_v: supported on roughconductor only", el)
    alpha = _number(r, p["alpha"], "alpha") if "alpha" in p else 0.1
    if not 0 <= alpha <= 1:
        raise r.error(f"alpha {alpha} outside [0, 1]", el)
    return math.sqrt(alpha)


def _distribution(r, el, p):
    """Mitsuba's microfacet distribution (its default: Beckmann)."""
    dist = r.get(p, "distribution", "str", "beckmann")
    if dist not in ("ggx", "beckmann"):
        raise r.error(f"microfacet distribution {dist!r}: expected ggx or beckmann", el)
    return dist


def _beckmann_as_ggx(r, el, p):
    """The principled BSDF's microfacets are GGX: Beckmann is rendered as GGX of the same
    alpha (a warning)."""
    if _distribution(r, el, p) == "beckmann":
        r.warn("the Beckmann distribution is rendered as GGX with the same alpha (the "
               "principled BSDF's; GGX has the longer tails)", el)


def _deref(r, el):
    if el.tag == "ref":
        bid = el.get("id")
        if bid not in r.bsdfs:
            raise r.error(f"<ref id={bid!r}>: no BSDF with that id", el)
        return r.bsdfs[bid]
    return el


def _material_of(r, bsdf_el, out, materials):
    key = bsdf_el.get("id") or id(bsdf_el)
    if key not in materials:
        name = bsdf_el.get("id") or f"bsdf-{len(materials) + 1}"
        out["materials"].append(_bsdf(r, bsdf_el, name))
        materials[key] = name
    return materials[key]


def _shape_name(el, out):
    return el.get("id") or f"shape-{len(out['objects']) + 1}"


def _shape(r, el, out, materials):
    kind = el.get("type")
    p = r.params(el)
    obj = {"name": _shape_name(el, out)}
    m = r.transform(p["to_world"][1]) if "to_world" in p else np.eye(4)
    if kind in ("obj", "ply", "serialized"):
        if "filename" not in p:
            raise r.error(f"{kind} shape without a filename", el)
        obj["file"] = r.file(r.get(p, "filename", "str"))
        face_normals = r.get(p, "face_normals", "bool", False)
        obj["smooth"] = not face_normals
        if kind == "serialized":
            if not obj["file"].lower().endswith(".serialized"):
                raise r.error("a serialized shape's file must end in .serialized", el)
            index = r.get(p, "shape_index", "int", 0)
            if index < 0:
                raise r.error(f"shape_index {index}: must be >= 0", p["shape_index"][1])
            if index:
                obj["shapeIndex"] = index
    elif kind == "rectangle":
        obj["vertices"] = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
        obj["faces"] = [[0, 1, 2], [0, 2, 3]]
        # Mitsuba's (u, v) = ((x + 1) / 2, (y + 1) / 2), v turned to this format's 1 - v
        obj["uvs"] = [[0, 1], [1, 1], [1, 0], [0, 0]]
    elif kind == "cube":
        obj["vertices"], obj["faces"] = _cube()
    elif kind == "sphere":
        radius = r.get(p, "radius", "float", 1.0)
        center = r.get(p, "center", "point", [0.0, 0.0, 0.0])
        # Mitsuba's sphere: its pole on local +Z, u = phi / 2 pi from +X towards +Y, v =
        # theta / pi; uv_sphere's seamed grid has its pole on +Y and phi towards -Z, and
        # v = 1 - theta / pi already (this format's v): turned onto Mitsuba's axes
        v, f, uv = uv_sphere(64, 128, 1.0, seam=True)
        v = v @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]).T
        obj["vertices"], obj["faces"], obj["uvs"] = v.tolist(), f.tolist(), uv.tolist()
        obj["smooth"] = True
        local = np.eye(4)
        local[:3, :3] *= radius
        local[:3, 3] = center
        m = m @ local
        r.warn(f"sphere tessellated into {len(f):,} triangles (smooth normals)", el)
    elif kind == "disk":
        # Mitsuba's disk: the unit disk at z = 0 facing +z (to_world scales it): a fan
        ring = 2 * np.pi * np.arange(DISK_SEGMENTS) / DISK_SEGMENTS
        obj["vertices"] = [[0.0, 0.0, 0.0]] + [[float(np.cos(a)), float(np.sin(a)), 0.0]
                                               for a in ring]
        obj["faces"] = [[0, 1 + k, 1 + (k + 1) % DISK_SEGMENTS] for k in range(DISK_SEGMENTS)]
        r.warn(f"disk tessellated into {DISK_SEGMENTS} triangles", el)
    elif kind == "cylinder":
        # Mitsuba's cylinder: an open tube of `radius` from p0 to p1 (default the unit
        # tube along +z), facing outward; tessellated with smooth normals
        radius = r.get(p, "radius", "float", 1.0)
        p0 = np.array(r.get(p, "p0", "point", [0.0, 0.0, 0.0]), float)
        p1 = np.array(r.get(p, "p1", "point", [0.0, 0.0, 1.0]), float)
        axis = p1 - p0
        if not (radius > 0 and np.linalg.norm(axis) > 0):
            raise r.error("cylinder: radius and length must be > 0", el)
        w = axis / np.linalg.norm(axis)
        u = np.cross(w, [1.0, 0, 0] if abs(w[0]) < 0.9 else [0, 1.0, 0])
        u /= np.linalg.norm(u)
        v_ = np.cross(w, u)
        ring = 2 * np.pi * np.arange(DISK_SEGMENTS) / DISK_SEGMENTS
        circle = [radius * (np.cos(a) * u + np.sin(a) * v_) for a in ring]
        verts = [p0 + c for c in circle] + [p1 + c for c in circle]
        n = DISK_SEGMENTS
        faces = []
        for k in range(n):
            a0, a1, b0, b1 = k, (k + 1) % n, n + k, n + (k + 1) % n
            faces += [[a0, a1, b1], [a0, b1, b0]]
        if r.get(p, "flip_normals", "bool", False):
            faces = [[a, c, b] for a, b, c in faces]
        obj["vertices"], obj["faces"] = [x.tolist() for x in verts], faces
        obj["smooth"] = True
        r.warn(f"cylinder tessellated into {len(faces)} triangles (smooth normals; no caps, "
               "as Mitsuba's)", el)
    else:
        raise r.error(f"shape {kind!r} is not supported (obj, ply, serialized, rectangle, "
                      "cube, sphere, disk, cylinder)",
                      el)
    for k in p:
        if p[k][0] in ("ref", "bsdf", "emitter"):
            continue        # <ref name="bsdf" id=...>: read below
        if k not in ("filename", "face_normals", "to_world", "radius", "center",
                     "shape_index", "p0", "p1") and not (k == "flip_normals" and
                                                          kind == "cylinder"):
            if k == "flip_normals":
                raise r.error("flip_normals is not supported", p[k][1])
            r.warn(f"shape parameter {k!r} ignored", p[k][1])
    if not np.allclose(m, np.eye(4)):
        obj["transform"] = {"matrix": m.tolist()}
    bsdf_el = None
    emitter = None
    for child in el:
        if child.tag == "ref" and child.get("id") in r.emitters:
            child = r.emitters[child.get("id")]      # an emitter declared at the top level
        if child.tag in ("bsdf", "ref"):
            bsdf_el = _deref(r, child)
        elif child.tag == "emitter":
            if child.get("type") != "area":
                raise r.error(f"a shape's emitter must be 'area', got {child.get('type')!r}",
                              child)
            ep = r.params(child)
            emitter = r.get(ep, "radiance", "color", [1.0, 1.0, 1.0])
    if bsdf_el is not None:
        name = _material_of(r, bsdf_el, out, materials)
    elif emitter is None:
        name = _material_of(r, _DEFAULT_BSDF, out, materials)
    else:
        name = None
    if emitter is not None:
        # an emitting shape gets its own copy of its material, with the emission
        base = next((dict(m_) for m_ in out["materials"] if m_["name"] == name),
                    {"type": "diffuse", "albedo": 0.5})
        if base.get("alphaMode") == "mask" and base.get("alpha") == 0.0:
            raise r.error("an area emitter on a surface with the null BSDF (light that "
                          "rays pass through) is not supported", el)
        base["name"] = f"{obj['name']}-emitter"
        base["emission"] = emitter
        out["materials"].append(base)
        name = base["name"]
    obj["material"] = name
    out["objects"].append(obj)


DISK_SEGMENTS = 128      # triangles of a tessellated disk, segments of a cylinder

# Mitsuba's default BSDF: diffuse with reflectance 0.5
_DEFAULT_BSDF = ET.Element("bsdf", {"type": "diffuse", "id": "default-diffuse"})


def _cube():
    """Mitsuba's cube: [-1, 1]^3, 12 triangles facing outward."""
    v = [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        for tri in ((a, b, c), (a, c, d)):
            p0, p1, p2 = (np.array(v[i], float) for i in tri)
            if np.dot(np.cross(p1 - p0, p2 - p0), p0 + p1 + p2) < 0:
                tri = (tri[0], tri[2], tri[1])
            faces.append(list(tri))
    return v, faces


def _emitter(r, el, out):
    kind = el.get("type")
    p = r.params(el)
    if kind == "point":
        pos = r.get(p, "position", "point")
        if pos is None:
            m = r.transform(p["to_world"][1]) if "to_world" in p else np.eye(4)
            pos = m[:3, 3].tolist()
        intensity = r.get(p, "intensity", "color", [1.0, 1.0, 1.0])
        out.setdefault("lights", []).append({"type": "point", "position": pos,
                                             "intensity": intensity})
    elif kind == "directional":
        # it radiates along +Z of to_world, or along `direction`
        if "direction" in p:
            if "to_world" in p:
                raise r.error("directional emitter: give 'direction' or 'to_world', not both",
                              el)
            d = r.get(p, "direction", "point")
        else:
            m = r.transform(p["to_world"][1]) if "to_world" in p else np.eye(4)
            d = (m[:3, :3] @ np.array([0.0, 0.0, 1.0])).tolist()
        out.setdefault("lights", []).append({
            "type": "directional", "direction": list(d),
            "irradiance": r.get(p, "irradiance", "color", [1.0, 1.0, 1.0])})
    elif kind == "spot":
        # it points along +Z of to_world, from its origin; Mitsuba's falloff is linear in the
        # angle from beam_width (full) to cutoff_angle (dark), ours glTF's (quadratic in the
        # cosine between the same angles): close, not equal, so a warning says so
        m = r.transform(p["to_world"][1]) if "to_world" in p else np.eye(4)
        cutoff = r.get(p, "cutoff_angle", "float", 20.0)
        beam = r.get(p, "beam_width", "float", cutoff * 3 / 4)
        if not (0 < cutoff <= 90 and 0 <= beam < cutoff):
            raise r.error(f"spot emitter: cutoff_angle {cutoff:g} and beam_width {beam:g} "
                          "(degrees) must satisfy 0 <= beam_width < cutoff_angle <= 90", el)
        if "texture" in p:
            raise r.error("spot emitter: a texture is not supported", el)
        out.setdefault("lights", []).append({
            "type": "spot", "position": m[:3, 3].tolist(),
            "direction": (m[:3, :3] @ np.array([0.0, 0.0, 1.0])).tolist(),
            "intensity": r.get(p, "intensity", "color", [1.0, 1.0, 1.0]),
            "innerAngle": float(beam), "outerAngle": float(cutoff)})
        r.warn("spot emitter: its falloff between beam_width and cutoff_angle follows glTF's "
               "curve (quadratic in the cosine), not Mitsuba's (linear in the angle)", el)
    elif kind == "constant":
        if "environment" in out:
            raise r.error("more than one environment emitter", el)
        out["environment"] = {"color": r.get(p, "radiance", "color", [1.0, 1.0, 1.0])}
    elif kind == "envmap":
        if "environment" in out:
            raise r.error("more than one environment emitter", el)
        if "filename" not in p:
            raise r.error("envmap without a filename", el)
        env = {"file": r.file(r.get(p, "filename", "str"))}
        if "scale" in p:
            env["intensity"] = r.get(p, "scale", "float")
        m = r.transform(p["to_world"][1]) if "to_world" in p else np.eye(4)
        # the scene format's map is Mitsuba's envmap turned 180 degrees about +Y
        # (pathtracer/mitsuba.py): its orientation in the world is to_world's rotation
        # times that half turn. A uniform scale (which Mitsuba's envmap ignores) goes.
        rot = m[:3, :3] / np.cbrt(np.linalg.det(m[:3, :3])) if np.linalg.det(
            m[:3, :3]) > 0 else m[:3, :3]
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-5) or not np.linalg.det(rot) > 0:
            raise r.error("envmap to_world: expected a rotation (no shear, mirror or "
                          "non-uniform scale)", el)
        world = rot @ np.diag([-1.0, 1.0, -1.0])
        if np.allclose(world[1], [0, 1, 0], atol=1e-9) and np.allclose(world[:, 1], [0, 1, 0],
                                                                       atol=1e-9):
            env["rotation"] = math.degrees(math.atan2(world[0, 2], world[0, 0]))
        else:
            env["matrix"] = world.tolist()
        out["environment"] = env
    elif kind == "area":
        raise r.error("an area emitter belongs inside a <shape>", el)
    else:
        raise r.error(f"emitter {kind!r} is not supported (point, spot, directional, "
                      "constant, envmap, area)",
                      el)
