"""glTF 2.0 models and scenes (``.gltf`` with its buffers and images, or ``.glb``).

The container (JSON, GLB chunks, the object model) is read with pygltflib: it keeps every
field of the file as written, extensions and samplers included, where trimesh's loader
turns a file into its own scene graph and drops what it does not model (texture samplers,
``KHR_texture_transform``, punctual lights, most material extensions). What pygltflib
leaves to the reader is done here with numpy: accessors (strided, normalised and sparse)
become arrays, the node hierarchy becomes world-space triangles, and materials become
materials of the JSON scene format (so they are validated, and mean, exactly as a scene
file's). Specification: https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html

Two uses: an object of a JSON scene (``"file": "model.glb"``: meshes and materials) and a
whole scene (``pt-render model.glb``: also its cameras and ``KHR_lights_punctual`` lights,
with a default camera and environment where it has none): :func:`convert_file`.

Conventions. glTF is right-handed, +Y up, metres, as the scene format. Texture coordinates
have v = 0 at the top of the image, the OBJ convention (ours) at the bottom: v becomes
1 - v. Roughness is perceptual (GGX alpha = roughness^2) as ours; metallic-roughness
textures keep roughness in G and metallic in B. Normal maps are tangent-space, +Y green
(OpenGL), as ours; tangents are computed from the texture coordinates (MikkTSpace-style)
rather than read from ``TANGENT``.
"""
import base64
import binascii
import functools
import hashlib
import math
import os
import tempfile
import urllib.parse
from types import SimpleNamespace
import warnings as _warnings

import numpy as np

from .errors import SceneError
from .mesh_data import ObjMesh

def _uv_transform(ext):
    """KHR_texture_transform's matrix (2 x 3, glTF's texture coordinates): translation x
    rotation x scale, as its specification defines it."""
    su, sv = (float(x) for x in ext.get("scale", [1, 1]))
    ou, ov = (float(x) for x in ext.get("offset", [0, 0]))
    r = float(ext.get("rotation", 0.0))
    c, s = math.cos(r), math.sin(r)
    return np.array([[c * su, s * sv, ou], [-s * su, c * sv, ov]])


def _texture_specs(value):
    """The texture specs (dicts with a "texture") anywhere in a material dict."""
    if isinstance(value, dict):
        if "texture" in value:
            yield value
        else:
            for v in value.values():
                yield from _texture_specs(v)
    elif isinstance(value, list):
        for v in value:
            yield from _texture_specs(v)


# componentType -> numpy type
COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
              5125: np.uint32, 5126: np.float32}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
# sampler constants
NEAREST = 9728
LINEAR = 9729
REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT = 10497, 33071, 33648
WRAP_MODES = {None: "repeat", REPEAT: "repeat", CLAMP_TO_EDGE: "clamp",
              MIRRORED_REPEAT: "mirror"}
# primitive modes
POINTS, LINES, LINE_LOOP, LINE_STRIP, TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN = range(7)

# KHR_lights_punctual gives luminous intensity (candela); the scene format's point light
# takes radiant intensity (W/sr). 683 lm/W, as Blender's glTF importer in its default
# ("Standard") lighting mode: a point light exported from Blender comes back at its power.
LUMENS_PER_WATT = 683.0

SUPPORTED_EXTENSIONS = {
    "KHR_materials_emissive_strength", "KHR_materials_transmission", "KHR_materials_ior",
    "KHR_materials_clearcoat", "KHR_materials_sheen", "KHR_materials_specular",
    "KHR_texture_transform", "KHR_lights_punctual", "KHR_mesh_quantization",
    "KHR_materials_unlit", "KHR_materials_pbrSpecularGlossiness"}
# without these the geometry or the images cannot be read at all
UNREADABLE_EXTENSIONS = {"KHR_draco_mesh_compression", "EXT_meshopt_compression",
                         "KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif"}
IMAGE_TYPES = {"image/png": ".png", "image/jpeg": ".jpg"}
GLTF_EXTENSIONS = (".gltf", ".glb")


def is_gltf(path):
    return os.path.splitext(str(path))[1].lower() in GLTF_EXTENSIONS


class GltfModel:
    """A glTF file read into world-space triangles, materials in the scene format,
    cameras and lights."""

    def __init__(self, path):
        self.path = os.path.abspath(path)
        self.base = os.path.dirname(self.path)
        self.warnings = []
        self._buffers = {}
        self._materials = {}     # glTF material index (None: the default) -> our index
        self.materials = []      # dicts in the JSON scene format
        self.cameras = []        # (name, camera dict in the scene format's keys)
        self.lights = []         # point and directional lights in the scene format
        self.emissive = False
        self._where = None        # what is being read, for errors about malformed values
        self.gltf = self._load()
        try:
            self._check_extensions()
            self._read_scene()
        except SceneError:
            raise
        except (TypeError, AttributeError, ValueError, KeyError, IndexError,
                OverflowError) as e:
            # pygltflib does not check the types of values: a wrong one surfaces here
            detail = " ".join(str(e).split())[:120]
            raise self.error(f"invalid glTF: a value of the wrong type or shape "
                             f"({type(e).__name__}: {detail})", self._where) from None

    # -- errors and warnings
    def error(self, message, where=None):
        return SceneError(message, self.path, where)

    def warn(self, message):
        if message not in self.warnings:
            self.warnings.append(message)

    # -- container
    def _load(self):
        from pygltflib import GLTF2
        if not os.path.isfile(self.path):
            raise self.error("file not found")
        try:
            with open(self.path, "rb") as f:
                head = f.read(4)
            with _warnings.catch_warnings():
                # dataclasses_json warns of every null where the object model wants a value
                _warnings.simplefilter("ignore", RuntimeWarning)
                g = (GLTF2().load_binary(self.path) if head == b"glTF" else
                     GLTF2().load_json(self.path))
        except OSError as e:
            raise self.error(f"cannot read: {e.strerror or e}") from None
        except Exception as e:    # pygltflib reports malformed JSON and chunks in many types
            raise self.error(f"invalid glTF: {' '.join(str(e).split())[:200] or type(e).__name__}"
                             ) from None
        if g is None:
            raise self.error("invalid glTF (not a glTF JSON or GLB file)")
        version = str(getattr(g.asset, "version", "") or "")
        if not version.startswith("2"):
            raise self.error(f"glTF version {version or '(none)'}: only glTF 2.0 is read",
                             "/asset/version")
        return g

    def _check_extensions(self):
        g = self.gltf
        required = set(g.extensionsRequired or [])
        used = set(g.extensionsUsed or []) | required
        unreadable = sorted(required & (UNREADABLE_EXTENSIONS | (used - SUPPORTED_EXTENSIONS)))
        if unreadable:
            raise self.error(f"requires {', '.join(unreadable)}, which pt-render does not read "
                             "(re-export the file without it)", "/extensionsRequired")
        ignored = sorted(used - SUPPORTED_EXTENSIONS)
        if ignored:
            self.warn(f"extensions not supported, ignored: {', '.join(ignored)}")

    def _buffer(self, i):
        if i in self._buffers:
            return self._buffers[i]
        g = self.gltf
        where = f"/buffers/{i}"
        if not 0 <= i < len(g.buffers):
            raise self.error(f"buffer {i} does not exist", where)
        uri = g.buffers[i].uri
        if uri is None:
            data = g.binary_blob() if i == 0 else None
            if data is None:
                raise self.error("a buffer without a uri needs the GLB binary chunk", where)
        else:
            data = self._uri_bytes(uri, where + "/uri")
        length = g.buffers[i].byteLength or 0
        if len(data) < length:
            raise self.error(f"buffer has {len(data)} bytes, byteLength says {length}", where)
        self._buffers[i] = data = bytes(data)
        return data

    def _uri_bytes(self, uri, where):
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            try:
                return (base64.b64decode(payload, validate=False) if head.endswith(";base64")
                        else urllib.parse.unquote_to_bytes(payload))
            except (binascii.Error, ValueError) as e:
                raise self.error(f"invalid data URI: {e}", where) from None
        path = os.path.join(self.base, urllib.parse.unquote(uri))
        try:
            with open(path, "rb") as f:
                return f.read()
        except OSError as e:
            raise self.error(f"cannot read {path}: {e.strerror or e}", where) from None

    def _view(self, index, where):
        g = self.gltf
        if index is None or not 0 <= index < len(g.bufferViews):
            raise self.error(f"bufferView {index} does not exist", where)
        bv = g.bufferViews[index]
        data = self._buffer(bv.buffer)
        start = bv.byteOffset or 0
        if start + bv.byteLength > len(data):
            raise self.error(f"bufferView {index} runs past the end of its buffer", where)
        return data, start, bv.byteLength, bv.byteStride

    def accessor(self, index, where):
        """The elements of accessor ``index`` as an array (count, width): floats for float and
        normalised accessors, integers otherwise."""
        g = self.gltf
        where = f"/accessors/{index}" if index is not None else where
        if index is None or not 0 <= index < len(g.accessors):
            raise self.error(f"accessor {index} does not exist", where)
        a = g.accessors[index]
        if a.componentType not in COMPONENTS or a.type not in WIDTHS:
            raise self.error(f"unknown componentType {a.componentType} or type {a.type!r}",
                             where)
        dtype = np.dtype(COMPONENTS[a.componentType]).newbyteorder("<")
        width = WIDTHS[a.type]
        count = int(a.count or 0)
        if a.bufferView is None:
            out = np.zeros((count, width), dtype)
        else:
            data, start, length, stride = self._view(a.bufferView, where)
            elem = dtype.itemsize * width
            stride = stride or elem
            offset = a.byteOffset or 0
            if count and offset + stride * (count - 1) + elem > length:
                raise self.error(f"accessor {index} runs past the end of its bufferView", where)
            out = np.ndarray((count, width), dtype, data, start + offset,
                             (stride, dtype.itemsize)).copy() if count else \
                np.zeros((0, width), dtype)
        if a.sparse is not None and a.sparse.count:
            out = out.copy()
            s = a.sparse
            idx_type = COMPONENTS.get(s.indices.componentType)
            if idx_type is None:
                raise self.error("sparse indices need an unsigned integer type", where)
            data, start, _, _ = self._view(s.indices.bufferView, where + "/sparse/indices")
            idx = np.frombuffer(data, np.dtype(idx_type).newbyteorder("<"), s.count,
                                start + (s.indices.byteOffset or 0))
            data, start, _, _ = self._view(s.values.bufferView, where + "/sparse/values")
            vals = np.frombuffer(data, dtype, s.count * width,
                                 start + (s.values.byteOffset or 0)).reshape(-1, width)
            if idx.size and idx.max() >= count:
                raise self.error("a sparse index is out of range", where + "/sparse")
            out[idx.astype(np.int64)] = vals
        if a.normalized and dtype.kind in "iu":
            top = float(np.iinfo(dtype).max)
            out = np.maximum(out.astype(np.float64) / top, -1.0)
        return out

    # -- the node hierarchy
    def _read_scene(self):
        g = self.gltf
        scenes = g.scenes or []
        if scenes:
            s = g.scene if g.scene is not None else 0
            if not 0 <= s < len(scenes):
                raise self.error(f"scene {s} does not exist", "/scene")
            roots = list(scenes[s].nodes or [])
        else:     # no scene: every node that is no node's child
            children = {c for n in g.nodes for c in (n.children or [])}
            roots = [i for i in range(len(g.nodes)) if i not in children]
        parts = []
        stack = [(r, np.eye(4)) for r in reversed(roots)]
        seen = set()
        while stack:
            i, parent = stack.pop()
            where = self._where = f"/nodes/{i}"
            if not isinstance(i, int) or not 0 <= i < len(g.nodes):
                raise self.error(f"node {i} does not exist", where)
            if i in seen:
                raise self.error("a node appears twice in the hierarchy (a cycle or a shared "
                                 "child)", where)
            seen.add(i)
            node = g.nodes[i]
            world = parent @ self._local(node, where)
            if node.mesh is not None:
                parts.extend(self._mesh(node.mesh, world, f"{where}/mesh"))
            if node.camera is not None:
                self._camera(node, world, where)
            light = (node.extensions or {}).get("KHR_lights_punctual")
            if light is not None:
                self._light(light, world, where)
            for c in reversed(node.children or []):
                stack.append((c, world))
        if parts:
            self.positions = np.concatenate([p[0] for p in parts])
            # a primitive without NORMAL is flat shaded (the specification), so the
            # normals are always given: a smooth object never averages them across faces
            self.normals = np.concatenate([
                p[1] if p[1] is not None else
                np.repeat(_face_normals(p[0])[:, None], 3, 1).astype(np.float32)
                for p in parts])
            has_uv = [p[2] is not None for p in parts]
            self.uvs = (np.concatenate([p[2] if p[2] is not None else
                                        np.zeros((len(p[0]), 3, 2), np.float32)
                                        for p in parts]) if any(has_uv) else None)
            self.face_material = np.concatenate([np.full(len(p[0]), p[3], np.int32)
                                                 for p in parts])
            # COLOR_0: white where a primitive has none (the base colour unchanged)
            self.colors = (np.concatenate([p[4] if p[4] is not None else
                                           np.ones((len(p[0]), 3, 3), np.float32)
                                           for p in parts])
                           if any(p[4] is not None for p in parts) else None)
        else:
            self.positions = np.zeros((0, 3, 3), np.float32)
            self.normals = self.uvs = self.colors = None
            self.face_material = np.zeros(0, np.int32)
        if not np.isfinite(self.positions).all():
            raise self.error("vertex positions contain NaN or infinity")

    def _local(self, node, where):
        if node.matrix is not None and list(node.matrix) != [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,
                                                              0, 0, 0, 0, 1]:
            m = np.asarray(node.matrix, np.float64)
            if m.shape != (16,) or not np.isfinite(m).all():
                raise self.error("matrix must be 16 finite numbers", where + "/matrix")
            return m.reshape(4, 4).T            # stored column-major
        t = np.asarray(node.translation if node.translation is not None else [0, 0, 0],
                       np.float64)
        q = np.asarray(node.rotation if node.rotation is not None else [0, 0, 0, 1], np.float64)
        s = np.asarray(node.scale if node.scale is not None else [1, 1, 1], np.float64)
        if t.shape != (3,) or q.shape != (4,) or s.shape != (3,) or not (
                np.isfinite(t).all() and np.isfinite(q).all() and np.isfinite(s).all()):
            raise self.error("translation, rotation, scale must be 3, 4, 3 finite numbers",
                             where)
        norm = np.linalg.norm(q)
        if norm == 0:
            raise self.error("rotation quaternion is zero", where + "/rotation")
        x, y, z, w = q / norm
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        m = np.eye(4)
        m[:3, :3] = r * s          # T * R * S
        m[:3, 3] = t
        return m

    # -- meshes
    def _mesh(self, index, world, where):
        g = self.gltf
        if not 0 <= index < len(g.meshes):
            raise self.error(f"mesh {index} does not exist", where)
        out = []
        m3, t = world[:3, :3], world[:3, 3]
        det = np.linalg.det(m3)
        for k, prim in enumerate(g.meshes[index].primitives):
            pw = self._where = f"/meshes/{index}/primitives/{k}"
            mode = TRIANGLES if prim.mode is None else prim.mode
            if mode in (POINTS, LINES, LINE_LOOP, LINE_STRIP):
                self.warn(f"{pw}: points and lines are not rendered")
                continue
            if mode not in (TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN):
                raise self.error(f"unknown primitive mode {mode}", pw + "/mode")
            attrs = prim.attributes
            if getattr(attrs, "POSITION", None) is None:
                raise self.error("a primitive needs POSITION", pw + "/attributes")
            pos = self.accessor(attrs.POSITION, pw).astype(np.float64)[:, :3]
            n = len(pos)
            idx = (self.accessor(prim.indices, pw + "/indices").reshape(-1).astype(np.int64)
                   if prim.indices is not None else np.arange(n))
            if idx.size and (idx.min() < 0 or idx.max() >= n):
                raise self.error(f"an index is out of range (0..{n - 1})", pw + "/indices")
            tri = _triangles(idx, mode)
            if not len(tri):
                continue
            mat, texcoord, uv_matrix = self._material(prim.material, pw)
            nrm = None
            if getattr(attrs, "NORMAL", None) is not None:
                nrm = self.accessor(attrs.NORMAL, pw).astype(np.float64)[:, :3]
            uv = None
            name = f"TEXCOORD_{texcoord}"
            acc = getattr(attrs, name, None)
            if acc is not None:
                uv = self.accessor(acc, pw).astype(np.float64)[:, :2].copy()
                if uv_matrix is not None:               # a rotated KHR_texture_transform
                    uv = uv @ uv_matrix[:, :2].T + uv_matrix[:, 2]
                uv[:, 1] = 1.0 - uv[:, 1]               # glTF: v = 0 at the image's top
            elif texcoord:
                self.warn(f"{pw}: its material's textures use {name}, which it lacks")
            p = pos[tri] @ m3.T + t
            nw = None
            if nrm is not None:
                nw = nrm[tri] @ np.linalg.inv(m3)       # normals: the inverse transpose
                length = np.linalg.norm(nw, axis=-1, keepdims=True)
                nw = np.where(length > 0, nw / np.where(length > 0, length, 1), 0.0)
            uvt = uv[tri] if uv is not None else None
            col = self._vertex_colors(attrs, pw, n)
            colt = col[tri] if col is not None else None
            if det < 0:       # a mirroring transform: keep the front side counter-clockwise
                p = p[:, [0, 2, 1]]
                nw = nw[:, [0, 2, 1]] if nw is not None else None
                uvt = uvt[:, [0, 2, 1]] if uvt is not None else None
                colt = colt[:, [0, 2, 1]] if colt is not None else None
            out.append((p.astype(np.float32), None if nw is None else nw.astype(np.float32),
                        None if uvt is None else uvt.astype(np.float32), mat,
                        None if colt is None else colt.astype(np.float32)))
        return out

    def _vertex_colors(self, attrs, pw, n):
        """COLOR_0 (linear RGB, VEC3 or VEC4; float or normalised integers), which the
        specification multiplies into the base colour; None without it. Its alpha is not
        read (a warning where it is not 1); other COLOR_n sets are named in a warning."""
        extra = sorted(k for k in vars(attrs) if k.startswith("COLOR_") and k != "COLOR_0"
                       and getattr(attrs, k) is not None) if hasattr(attrs, "__dict__") else []
        if extra:
            self.warn(f"{pw}: vertex colour sets {', '.join(extra)} are not read (COLOR_0 is)")
        acc = getattr(attrs, "COLOR_0", None)
        if acc is None:
            return None
        col = self.accessor(acc, pw).astype(np.float64)
        if col.ndim != 2 or col.shape[1] not in (3, 4) or len(col) != n:
            raise self.error("COLOR_0 must be VEC3 or VEC4 with one value per vertex",
                             pw + "/attributes/COLOR_0")
        if not np.isfinite(col).all():
            raise self.error("COLOR_0 holds NaN or infinity", pw + "/attributes/COLOR_0")
        if col.shape[1] == 4 and not np.allclose(col[:, 3], 1.0):
            self.warn(f"{pw}: COLOR_0's alpha is not read (rendered opaque)")
        return np.clip(col[:, :3], 0.0, 1.0)

    # -- materials
    def _material(self, index, where):
        """(our material index, the texture coordinate set its textures use, the 2 x 3
        matrix of a rotated texture transform to apply to those coordinates or None)."""
        if index in self._materials:
            return self._materials[index]
        g = self.gltf
        if index is None:
            # the glTF default material: base colour 1, metallic 1, roughness 1
            got = (self._add({"name": "gltf-default", "albedo": 1.0, "metallic": 1.0,
                              "roughness": 1.0, "_pointer": "(the default material)"}), 0,
                   None)
            self._materials[index] = got
            return got
        if not 0 <= index < len(g.materials):
            raise self.error(f"material {index} does not exist", where + "/material")
        m = g.materials[index]
        mw = self._where = f"/materials/{index}"
        ext = m.extensions or {}
        pbr = m.pbrMetallicRoughness
        out = {"name": f"{index}:{m.name}" if m.name else f"material-{index}", "_pointer": mw}
        sets = []
        base = list(pbr.baseColorFactor) if pbr and pbr.baseColorFactor else [1, 1, 1, 1]
        metallic = pbr.metallicFactor if pbr and pbr.metallicFactor is not None else 1.0
        roughness = pbr.roughnessFactor if pbr and pbr.roughnessFactor is not None else 1.0
        out["albedo"] = base[:3]
        out["metallic"] = metallic
        out["roughness"] = roughness
        if pbr and pbr.baseColorTexture is not None:
            out["albedo"] = self._texture(pbr.baseColorTexture, "sRGB", base[:3], None,
                                          mw + "/pbrMetallicRoughness/baseColorTexture", sets)
        if pbr and pbr.metallicRoughnessTexture is not None:
            w = mw + "/pbrMetallicRoughness/metallicRoughnessTexture"
            out["roughness"] = self._texture(pbr.metallicRoughnessTexture, "linear", roughness,
                                             "g", w, sets)
            out["metallic"] = self._texture(pbr.metallicRoughnessTexture, "linear", metallic,
                                            "b", w, sets)
        if m.normalTexture is not None:
            scale = m.normalTexture.scale if m.normalTexture.scale is not None else 1.0
            if scale != 1.0:
                self.warn(f"{mw}/normalTexture: scale {scale:g} not supported (read as 1)")
            out["normalMap"] = self._texture(m.normalTexture, "linear", None, None,
                                             mw + "/normalTexture", sets)
        emissive = list(m.emissiveFactor) if m.emissiveFactor is not None else [0, 0, 0]
        strength = float((ext.get("KHR_materials_emissive_strength") or {}).get(
            "emissiveStrength", 1.0))
        emissive = [c * strength for c in emissive]
        if m.emissiveTexture is not None and max(emissive) > 0:
            out["emission"] = self._texture(m.emissiveTexture, "sRGB", emissive, None,
                                            mw + "/emissiveTexture", sets)
        elif max(emissive) > 0:
            out["emission"] = emissive
        if max(emissive) > 0:
            self.emissive = True
            if m.doubleSided:
                out["twoSided"] = True
        self._alpha(m, pbr, base, out, mw, sets)
        if "KHR_materials_pbrSpecularGlossiness" in ext:
            self._specular_glossiness(ext["KHR_materials_pbrSpecularGlossiness"], out, mw, sets)
        if "KHR_materials_unlit" in ext:
            out = self._unlit(out, m, mw)
            got = (self._add(out), sets[0][0] if sets else 0, None)
            self._materials[index] = got
            return got
        self._extensions(ext, out, mw, sets)
        if (out["metallic"] == 0 and out.get("specular") == 0 and "eta" not in out
                and "normalMap" not in out
                and not any(out.get(k) for k in ("transmission", "clearcoat", "sheen"))):
            # glTF's diffuse lobe is Lambertian (the specification's BRDF); with the
            # specular lobe off (KHR_materials_specular factor 0) and no metal, that is
            # exactly the diffuse material, where the principled one's is Burley's
            out = {k: v for k, v in out.items() if k in ("name", "_pointer", "albedo",
                                                         "emission", "twoSided")}
            out["type"] = "diffuse"
        texcoord = sets[0][0] if sets else 0
        if len({s[0] for s in sets}) > 1:
            self.warn(f"{mw}: textures on several texture coordinate sets; all read with "
                      f"TEXCOORD_{texcoord}")
        uv_matrix = self._rotated_transform(out, sets, mw)
        got = (self._add(out), texcoord, uv_matrix)
        self._materials[index] = got
        return got

    def _rotated_transform(self, out, sets, mw):
        """A KHR_texture_transform with a rotation, which a texture's tile and offset cannot
        express: where every texture of the material has the same transform, it is applied
        to the material's texture coordinates (returned: glTF's 2 x 3 matrix, for the
        primitive's UVs) and the textures read them as they are; else the rotation is
        ignored with a warning (their tile and offset kept)."""
        rotated = [m for _, m in sets if m is not None and m[0, 1] != 0.0]
        if not rotated:
            return None
        if len(rotated) != len(sets) or any(not np.array_equal(m, rotated[0])
                                            for m in rotated):
            self.warn(f"{mw}: KHR_texture_transform rotations that differ between the "
                      "material's textures are not supported (ignored)")
            return None
        for spec in _texture_specs(out):
            spec.pop("tile", None)
            spec.pop("offset", None)
        return rotated[0]

    def _unlit(self, out, m, mw):
        """KHR_materials_unlit: the surface shows its base colour whatever the lighting. A
        path tracer has no such surface; it is rendered as one that emits its base colour
        (a texture too) and reflects nothing: the camera sees exactly its base colour,
        but it also lights what is near it a little, which glTF's unlit surface would
        not (a warning says so). Emits on both sides when doubleSided."""
        self.emissive = True
        self.warn(f"{mw}: KHR_materials_unlit rendered as a surface emitting its base colour "
                  "(it also lights its surroundings, which an unlit glTF surface would not)")
        unlit = {"name": out["name"], "_pointer": out["_pointer"], "type": "diffuse",
                 "albedo": 0.0, "emission": out["albedo"]}
        if isinstance(unlit["emission"], list) and max(unlit["emission"]) <= 0:
            unlit["emission"] = [0.0, 0.0, 0.0]
        if m.doubleSided:
            unlit["twoSided"] = True
        return unlit

    def _specular_glossiness(self, sg, out, mw, sets):
        """KHR_materials_pbrSpecularGlossiness, converted to metallic-roughness by the
        conversion the Khronos sample viewer and Blender's importer use for factors
        (solveMetallic: the metallic factor whose dielectric F0 of 0.04 and base colour
        reproduce the diffuse and specular colours' perceived brightness; roughness = 1 -
        glossiness). A diffuse texture stays the base colour's texture (its factor the
        scale); the specular-glossiness texture is not converted per texel (a warning)."""
        w = mw + "/extensions/KHR_materials_pbrSpecularGlossiness"
        diffuse = np.array((sg.get("diffuseFactor") or [1, 1, 1, 1])[:3], float)
        specular = np.array(sg.get("specularFactor") or [1, 1, 1], float)
        gloss = float(sg.get("glossinessFactor", 1.0))
        dielectric = 0.04

        def brightness(c):
            return float(np.sqrt(0.299 * c[0] ** 2 + 0.587 * c[1] ** 2 + 0.114 * c[2] ** 2))
        one_minus = 1.0 - float(specular.max())
        d, sp = brightness(diffuse), brightness(specular)
        metallic = 0.0
        if sp >= dielectric:
            a = dielectric
            b = d * one_minus / (1 - dielectric) + sp - 2 * dielectric
            c = dielectric - sp
            metallic = float(np.clip((-b + np.sqrt(max(b * b - 4 * a * c, 0.0))) / (2 * a),
                                     0.0, 1.0))
        from_diffuse = diffuse * one_minus / (1 - dielectric) / max(1 - metallic, 1e-4)
        from_specular = (specular - dielectric * (1 - metallic)) / max(metallic, 1e-4)
        base = np.clip(from_diffuse + (from_specular - from_diffuse) * metallic ** 2, 0, 1)
        out["albedo"] = base.tolist()
        out["metallic"] = metallic
        out["roughness"] = float(np.clip(1.0 - gloss, 0.0, 1.0))
        if sg.get("diffuseTexture") is not None:
            out["albedo"] = self._texture(_info(sg["diffuseTexture"]), "sRGB", base.tolist(),
                                          None, w + "/diffuseTexture", sets)
        if sg.get("specularGlossinessTexture") is not None:
            self.warn(f"{w}: specularGlossinessTexture is not converted per texel (its "
                      "factors are)")

    def _extensions(self, ext, out, mw, sets):
        tr = ext.get("KHR_materials_transmission")
        if tr:
            factor = float(tr.get("transmissionFactor", 0.0))
            out["transmission"] = factor
            if tr.get("transmissionTexture") is not None:
                out["transmission"] = self._texture(
                    _info(tr["transmissionTexture"]), "linear", factor, "r",
                    mw + "/extensions/KHR_materials_transmission/transmissionTexture", sets)
        ior = ext.get("KHR_materials_ior")
        if ior and float(ior.get("ior", 1.5)) > 0:
            out["eta"] = float(ior.get("ior", 1.5))
        spec = ext.get("KHR_materials_specular")
        if spec:
            factor = float(spec.get("specularFactor", 1.0))
            color = [float(c) for c in spec.get("specularColorFactor", [1, 1, 1])]
            if "eta" in out:
                self.warn(f"{mw}: KHR_materials_specular with KHR_materials_ior: only the "
                          "index of refraction is used")
            else:
                # F0 = ((1.5 - 1) / (1.5 + 1))^2 * colour * factor = 0.08 * specular
                out["specular"] = min(1.0, 0.5 * factor * float(np.mean(color)))
                if spec.get("specularTexture") is not None:
                    # the factor's texture: its alpha channel (linear)
                    out["specular"] = self._texture(
                        _info(spec["specularTexture"]), "linear", out["specular"], "a",
                        mw + "/extensions/KHR_materials_specular/specularTexture", sets)
            if spec.get("specularColorTexture") is not None:
                self.warn(f"{mw}: KHR_materials_specular specularColorTexture is not read "
                          "(the colour factor's mean is)")
        cc = ext.get("KHR_materials_clearcoat")
        if cc:
            out["clearcoat"] = min(1.0, float(cc.get("clearcoatFactor", 0.0)))
            r = float(cc.get("clearcoatRoughnessFactor", 0.0))
            # the principled coat's alpha runs 0.1 (gloss 0) to 0.001 (gloss 1); glTF's
            # coat alpha is roughness^2
            out["clearcoatGloss"] = min(1.0, max(0.0, (0.1 - r * r) / 0.099))
            if cc.get("clearcoatTexture") is not None:
                # the factor's texture: its red channel
                out["clearcoat"] = self._texture(
                    _info(cc["clearcoatTexture"]), "linear", out["clearcoat"], "r",
                    mw + "/extensions/KHR_materials_clearcoat/clearcoatTexture", sets)
            for k in ("clearcoatRoughnessTexture", "clearcoatNormalTexture"):
                if cc.get(k) is not None:
                    self.warn(f"{mw}: KHR_materials_clearcoat {k} is not read")
        sh = ext.get("KHR_materials_sheen")
        if sh:
            color = [float(c) for c in sh.get("sheenColorFactor", [0, 0, 0])]
            out["sheen"] = min(1.0, max(color))
            if sh.get("sheenColorTexture") or sh.get("sheenRoughnessTexture"):
                self.warn(f"{mw}: KHR_materials_sheen textures are not read")

    def _add(self, material):
        self.materials.append(material)
        return len(self.materials) - 1

    def _alpha(self, m, pbr, base, out, mw, sets):
        """alphaMode MASK (with alphaCutoff) and BLEND: the opacity is the base colour's
        alpha (its factor times its texture's alpha channel, which is linear); OPAQUE
        ignores it, as the specification says. BLEND is rendered as stochastic
        transparency (a ray passes with probability 1 - alpha), whose mean is the blend."""
        mode = m.alphaMode or "OPAQUE"
        if mode == "OPAQUE":
            return
        if mode not in ("MASK", "BLEND"):
            raise self.error(f"alphaMode {mode!r}: expected OPAQUE, MASK or BLEND",
                             mw + "/alphaMode")
        out["alphaMode"] = mode.lower()
        if mode == "MASK":
            out["alphaCutoff"] = 0.5 if m.alphaCutoff is None else float(m.alphaCutoff)
        alpha = float(base[3]) if len(base) > 3 else 1.0
        out["alpha"] = alpha
        if pbr and pbr.baseColorTexture is not None:
            out["alpha"] = self._texture(pbr.baseColorTexture, "linear", alpha, "a",
                                         mw + "/pbrMetallicRoughness/baseColorTexture", sets)

    def _texture(self, info, color_space, scale, channel, where, sets):
        """A texture value in the scene format for a glTF textureInfo."""
        g = self.gltf
        index = info.index
        if index is None or not 0 <= index < len(g.textures):
            raise self.error(f"texture {index} does not exist", where + "/index")
        tex = g.textures[index]
        self._where = where
        ext = (getattr(info, "extensions", None) or {}).get("KHR_texture_transform") or {}
        texcoord = ext.get("texCoord", info.texCoord or 0)
        sets.append((int(texcoord), _uv_transform(ext) if ext else None))
        spec = {"texture": self._image(tex, f"/textures/{index}"), "colorSpace": color_space}
        if channel:
            spec["channel"] = channel
        if scale is not None:
            spec["scale"] = scale
        if tex.sampler is not None:
            if not 0 <= tex.sampler < len(g.samplers):
                raise self.error(f"sampler {tex.sampler} does not exist",
                                 f"/textures/{index}/sampler")
            s = g.samplers[tex.sampler]
            if s.magFilter == NEAREST:
                spec["filter"] = "nearest"
            elif s.minFilter in (NEAREST, LINEAR):      # minified without mip-maps
                spec["filter"] = "bilinear"
            modes = []
            for axis, mode in (("wrapS", s.wrapS), ("wrapT", s.wrapT)):
                if mode not in WRAP_MODES:
                    raise self.error(f"{axis} {mode}: expected 10497 (REPEAT), 33071 "
                                     "(CLAMP_TO_EDGE) or 33648 (MIRRORED_REPEAT)",
                                     f"/samplers/{tex.sampler}/{axis}")
                modes.append(WRAP_MODES[mode])
            if modes != ["repeat", "repeat"]:
                spec["wrap"] = modes
        if ext:
            su, sv = (float(x) for x in ext.get("scale", [1, 1]))
            ou, ov = (float(x) for x in ext.get("offset", [0, 0]))
            # (a rotation: the material's texture coordinates are transformed instead, see
            # _rotated_transform) v flipped (ours = 1 - glTF's): v' = sv v + (1 - sv - ov) in our coordinates
            spec["tile"] = [su, sv]
            spec["offset"] = [ou, 1.0 - sv - ov]
        return spec

    def _image(self, tex, where):
        """The path of the texture's image: the file itself, or an embedded image written
        once to the cache, named by its content."""
        g = self.gltf
        source = tex.source
        if source is None:
            exts = sorted((tex.extensions or {}).keys())
            raise self.error("texture without a source image" +
                             (f" (only in {', '.join(exts)}, not supported)" if exts else ""),
                             where)
        if not 0 <= source < len(g.images):
            raise self.error(f"image {source} does not exist", where + "/source")
        img = g.images[source]
        iw = f"/images/{source}"
        if img.uri is not None and not img.uri.startswith("data:"):
            return os.path.join(self.base, urllib.parse.unquote(img.uri))
        if img.uri is not None:
            mime = img.uri[5:].split(";")[0].split(",")[0]
            data = self._uri_bytes(img.uri, iw + "/uri")
        else:
            mime = img.mimeType or ""
            buf, start, length, _ = self._view(img.bufferView, iw)
            data = buf[start:start + length]
        suffix = IMAGE_TYPES.get(mime)
        if suffix is None:
            raise self.error(f"image type {mime or '(none)'} not supported (PNG or JPEG)", iw)
        return cached_file(data, suffix)

    # -- cameras and lights
    def _camera(self, node, world, where):
        g = self.gltf
        i = node.camera
        if not 0 <= i < len(g.cameras):
            raise self.error(f"camera {i} does not exist", where + "/camera")
        c = g.cameras[i]
        name = c.name or node.name or f"camera-{i}"
        if c.type != "perspective" or c.perspective is None:
            self.cameras.append((name, i, None))
            return
        p = c.perspective
        m3 = world[:3, :3]
        position = world[:3, 3]
        forward = m3 @ np.array([0.0, 0.0, -1.0])
        up = m3 @ np.array([0.0, 1.0, 0.0])
        if np.linalg.norm(forward) == 0 or np.linalg.norm(np.cross(forward, up)) == 0:
            raise self.error("the camera's node transform is degenerate", where)
        forward /= np.linalg.norm(forward)
        cam = {"position": position.tolist(), "lookAt": (position + forward).tolist(),
               "up": (up / np.linalg.norm(up)).tolist(), "yfov": float(p.yfov),
               "aspectRatio": float(p.aspectRatio) if p.aspectRatio else None}
        self.cameras.append((name, i, cam))

    def _node_direction(self, world, kind, where):
        """The unit direction a spot or directional light shines in: its node's -Z."""
        d = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        if not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise self.error(f"a {kind} light's node transform is degenerate", where)
        return (d / np.linalg.norm(d)).tolist()

    def _light(self, ref, world, where):
        lights = ((self.gltf.extensions or {}).get("KHR_lights_punctual") or {}).get(
            "lights") or []
        i = ref.get("light")
        if not isinstance(i, int) or not 0 <= i < len(lights):
            raise self.error(f"light {i} does not exist",
                             where + "/extensions/KHR_lights_punctual")
        light = lights[i]
        self._where = f"/extensions/KHR_lights_punctual/lights/{i}"
        if not isinstance(light, dict):
            raise self.error("a light must be an object", self._where)
        kind = light.get("type")
        if kind not in ("point", "spot", "directional"):
            raise self.error(f"a {kind!r} light: KHR_lights_punctual lights are point, spot or "
                             "directional", f"/extensions/KHR_lights_punctual/lights/{i}")
        color = [float(c) for c in light.get("color", [1, 1, 1])]
        intensity = float(light.get("intensity", 1.0))
        if kind == "directional":
            # the scene format's directional light, which scene.compile renders as a far
            # point light (place_suns)
            self.lights.append({"type": "directional",
                                "direction": self._node_direction(world, kind, where),
                                "irradiance": [c * intensity / LUMENS_PER_WATT
                                               for c in color]})
            self.warn(f"directional light {i}: rendered as a point light 1000 times the "
                      "scene's radius away (the same irradiance at the scene's centre, "
                      "within 0.2 % across it)")
            return
        out = {"type": "point", "position": world[:3, 3].tolist(),
               "intensity": [c * intensity / LUMENS_PER_WATT for c in color]}
        if kind == "spot":
            # the cone's angles in radians (glTF's defaults)
            spot = light.get("spot") or {}
            outer = float(spot.get("outerConeAngle", math.pi / 4))
            inner = float(spot.get("innerConeAngle", 0.0))
            if not (0 <= inner < outer <= math.pi / 2):
                raise self.error("a spot light's cone angles must satisfy 0 <= innerConeAngle "
                                 f"< outerConeAngle <= pi/2, got {inner:g} and {outer:g}",
                                 f"/extensions/KHR_lights_punctual/lights/{i}/spot")
            out.update(type="spot", direction=self._node_direction(world, kind, where),
                       innerAngle=math.degrees(inner), outerAngle=math.degrees(outer))
        self.lights.append(out)


def _info(d):
    """A textureInfo given as a plain dict (inside an extension) as an object."""
    return SimpleNamespace(index=d.get("index"), texCoord=d.get("texCoord", 0),
                           extensions=d.get("extensions"))


def _triangles(idx, mode):
    if mode == TRIANGLES:
        return idx[:len(idx) // 3 * 3].reshape(-1, 3)
    k = np.arange(max(len(idx) - 2, 0))
    if mode == TRIANGLE_STRIP:     # every other triangle reversed, to keep the winding
        even = k % 2 == 0
        a = np.where(even, idx[k], idx[k + 1])
        b = np.where(even, idx[k + 1], idx[k])
        return np.stack([a, b, idx[k + 2]], -1)
    return np.stack([np.full(len(k), idx[0]), idx[k + 1], idx[k + 2]], -1)   # fan


def _face_normals(p):
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).astype(np.float64)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.where(length > 0, n / np.where(length > 0, length, 1), [0.0, 0.0, 1.0])


def cached_file(data, suffix, kind="gltf-images"):
    """The path of a file in the cache folder ``kind`` holding ``data`` (named by its
    content, written once): embedded glTF images, Mitsuba's procedural textures."""
    from .._cache import cache_root
    name = hashlib.sha256(data).hexdigest()[:32] + suffix
    for folder in (os.path.join(cache_root(), kind),
                   os.path.join(tempfile.gettempdir(), "pt-render-" + kind)):
        path = os.path.join(folder, name)
        if os.path.isfile(path):
            return path
        try:
            os.makedirs(folder, exist_ok=True)
            tmp = f"{path}.{os.getpid()}.tmp"
            with open(tmp, "wb") as f:
                f.write(data)
            os.replace(tmp, path)
            return path
        except OSError:
            continue
    raise SceneError(f"cannot write a generated image ({kind}) to a cache folder")


@functools.lru_cache(maxsize=4)
def _read(path, mtime, size):
    return GltfModel(path)


def read_model(path):
    """The :class:`GltfModel` of ``path`` (re-read when the file changes)."""
    try:
        st = os.stat(path)
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror or e}", path) from None
    return _read(os.path.abspath(path), st.st_mtime_ns, st.st_size)


def load_gltf_mesh(path):
    """The triangles and materials of a glTF file as an ObjMesh (materials as scene-format
    dicts); warnings go through Python's warnings."""
    model = read_model(path)
    for w in model.warnings:
        _warnings.warn(f"{path}: {w}", stacklevel=2)
    return ObjMesh(model.positions, model.normals, model.uvs, model.face_material,
                   model.materials, material_format="scene", colors=model.colors)


# ---------------------------------------------------------------------------------------
# pt-render model.glb: a whole scene

DEFAULT_WIDTH = 640
DEFAULT_FOV = 39.6          # the scene format's default horizontal field of view


def convert_file(path, camera=None, environment_given=False):
    """(scene dict in the JSON format, warnings) for ``pt-render model.glb``. ``camera``:
    None (the file's first camera, else a framing one), "auto" (framing), or a camera's
    index or name in the file. ``environment_given``: the caller sets the environment (no
    default one)."""
    model = read_model(path)
    warnings = list(model.warnings)
    cam = _choose_camera(model, camera, warnings)
    data = {"camera": cam,
            "objects": [{"name": os.path.splitext(os.path.basename(path))[0] or "model",
                         "file": model.path, "smooth": True}]}
    if model.lights:
        data["lights"] = model.lights
    if not environment_given:
        # The lighting rule: a model is lit by the default environment unless the caller
        # chooses one (--env FILE) or none (--env none: the file's own lights alone).
        # Emissive materials and punctual lights add to it, never replace it: a model whose
        # only emitter is an emissive texture (a helmet's lamps, a bottle's label) would
        # otherwise render black, as four Khronos sample models did until 2026-12-07.
        data["environment"] = {"color": [1.0, 1.0, 1.0]}
        own = [w for w, has in (("punctual lights", model.lights),
                                ("emissive materials", model.emissive)) if has]
        warnings.append("lit by a uniform white environment (radiance 1)"
                        + (f" besides its {' and '.join(own)}" if own else "")
                        + ": --env FILE for an HDRI"
                        + (", --env none for its own lights alone" if own else ""))
    return data, warnings


def _choose_camera(model, camera, warnings):
    cams = model.cameras
    chosen = None
    if camera not in (None, "auto"):
        for k, (name, index, cam) in enumerate(cams):
            if str(camera) in (name, str(index)):
                chosen = (name, cam)
                break
        else:
            names = ", ".join(f"{i} ({n})" for n, i, _ in cams) or "none"
            raise SceneError(f"--camera {camera}: no such camera in the file (cameras: "
                             f"{names}; or 'auto')", model.path)
        if chosen[1] is None:
            raise SceneError(f"camera {camera}: only perspective cameras are supported",
                             model.path)
    elif camera is None and cams:
        name, index, cam = cams[0]
        if cam is None:
            warnings.append(f"camera {index} ({name}) is orthographic, not supported: a "
                            "framing camera is used")
        else:
            chosen = (name, cam)
    if chosen is not None:
        c = chosen[1]
        aspect = c["aspectRatio"] or 16 / 9
        height = max(1, round(DEFAULT_WIDTH / aspect))
        tan_x = math.tan(c["yfov"] / 2) * DEFAULT_WIDTH / height
        return {"resolution": [DEFAULT_WIDTH, height], "position": c["position"],
                "lookAt": c["lookAt"], "up": c["up"],
                "fov": math.degrees(2 * math.atan(tan_x))}
    return framing_camera(model.positions)


def framing_camera(positions, width=DEFAULT_WIDTH, height=360, fov=DEFAULT_FOV):
    """A camera in front of (+Z) and a little above the model, far enough that its bounding
    sphere fills the smaller field of view."""
    if len(positions):
        p = positions.reshape(-1, 3).astype(np.float64)
        lo, hi = p.min(0), p.max(0)
    else:
        lo, hi = -np.ones(3), np.ones(3)
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    tan_x = math.tan(math.radians(fov) / 2)
    tan_small = min(tan_x, tan_x * height / width)
    distance = radius / math.sin(math.atan(tan_small)) * 1.05
    direction = np.array([0.0, 0.3, 1.0]) / math.hypot(0.3, 1.0)
    return {"resolution": [width, height], "position": (center + distance * direction).tolist(),
            "lookAt": center.tolist(), "fov": fov}
