"""Mesh files: OBJ, read with pywavefront and cached on disk keyed by file content, and PLY
(ASCII or binary), read with plyfile (fast enough not to need the cache).

A cached mesh is an ``.npz`` of unindexed triangles (positions, optional normals) and a
per-face material index, with the .mtl material table beside it as JSON. The key is the
SHA-256 of the OBJ bytes and of every .mtl it names, plus a format version, so an edited
file is re-read and a renamed one is not.
"""
import hashlib
import json
import logging
import os
import re
import tempfile
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .errors import SceneError

CACHE_VERSION = 5


@dataclass
class ObjMesh:
    positions: np.ndarray          # float32 (F, 3, 3)
    normals: Optional[np.ndarray]  # float32 (F, 3, 3) from `vn`, or None
    uvs: Optional[np.ndarray]      # float32 (F, 3, 2) from `vt`, or None
    face_material: np.ndarray      # int32 (F,): index into materials, -1 = no material
    materials: list                # dicts: name, Kd, Ke, Ks, Ns, Ni, Pr, Pm, map_Kd, map_Bump
    from_cache: bool = False
    # "mtl": materials are .mtl dicts (above); "scene": materials in the JSON scene format
    # (glTF files), read as a scene file's
    material_format: str = "mtl"


def cache_dir():
    from .._cache import cache_root
    return os.path.join(cache_root(), "meshes")


def _cache_key(path, data):
    h = hashlib.sha256()
    h.update(f"v{CACHE_VERSION}".encode())
    # The folder too: the .mtl's texture paths are resolved against it, so the same files
    # in another folder name other textures.
    h.update(os.path.dirname(os.path.abspath(path)).encode())
    h.update(data)
    # The .mtl files change the material table: hash them too.
    for m in re.findall(rb"^[ \t]*mtllib[ \t]+(.+?)[ \t]*$", data, re.M):
        mtl = os.path.join(os.path.dirname(path), m.decode("utf-8", "replace"))
        h.update(m)
        if os.path.isfile(mtl):
            with open(mtl, "rb") as f:
                h.update(f.read())
    return h.hexdigest()


MESH_FORMATS = (".obj", ".ply", ".gltf", ".glb")

# PLY vertex properties read as texture coordinates, the first pair present wins
PLY_UV_NAMES = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))


def load_mesh(path, use_cache=True):
    """Triangles (and, for OBJ and glTF, materials) of the mesh file at ``path`` by its
    extension."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".ply":
        return load_ply(path)
    if ext in (".gltf", ".glb"):
        from .gltf import load_gltf_mesh
        return load_gltf_mesh(path)
    return load_obj(path, use_cache=use_cache)


def load_ply(path):
    """Triangles of a PLY mesh (ASCII or binary), read with plyfile: positions, vertex
    normals (nx, ny, nz) and texture coordinates (PLY_UV_NAMES) where the file has them;
    polygons are fanned into triangles. PLY has no materials: the object's own applies."""
    from plyfile import PlyData
    try:
        try:
            # triangles read as one fixed-size array (7.3 s -> 0.09 s for 1.6M binary
            # triangles); a binary file with other polygons refuses this, an ASCII file
            # ignores it: both then take the general path
            ply = PlyData.read(path, known_list_len={"face": {"vertex_indices": 3,
                                                              "vertex_index": 3}})
        except OSError:
            raise
        except Exception:
            ply = PlyData.read(path)
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror or e}", path) from None
    except Exception as e:    # plyfile reports malformed headers and data in several types
        raise SceneError(f"invalid PLY: {' '.join(str(e).split())[:200]}", path) from None
    names = [el.name for el in ply.elements]
    if "vertex" not in names or "face" not in names:
        raise SceneError("a PLY mesh needs 'vertex' and 'face' elements", path)
    v = ply["vertex"].data
    props = set(v.dtype.names)
    if not {"x", "y", "z"} <= props:
        raise SceneError("PLY vertices need x, y and z", path)
    with np.errstate(over="ignore"):     # > float32 range: inf, refused later
        pos = np.stack([v["x"], v["y"], v["z"]], -1).astype(np.float32)
        nrm = (np.stack([v["nx"], v["ny"], v["nz"]], -1).astype(np.float32)
               if {"nx", "ny", "nz"} <= props else None)
        uv = next((np.stack([v[a], v[b]], -1).astype(np.float32) for a, b in PLY_UV_NAMES
                   if {a, b} <= props), None)
    f = ply["face"].data
    key = next((k for k in ("vertex_indices", "vertex_index") if k in f.dtype.names), None)
    if key is None:
        raise SceneError("PLY faces need a vertex_indices list", path)
    polygons = f[key]
    sizes = (np.full(len(polygons), polygons.shape[1]) if polygons.dtype != object else
             np.fromiter((len(p) for p in polygons), np.int64, len(polygons)))
    if len(polygons) and sizes.min() < 3:
        raise SceneError("a PLY face has fewer than 3 vertices", path)
    if polygons.dtype != object:
        tri = polygons.astype(np.int64)
    elif len(polygons) and (sizes == 3).all():
        tri = np.stack(polygons).astype(np.int64)
    else:
        tri = np.array([(p[0], p[i], p[i + 1]) for p in polygons for i in range(1, len(p) - 1)],
                       np.int64).reshape(-1, 3)
    if len(tri) and (tri.min() < 0 or tri.max() >= len(pos)):
        raise SceneError("a PLY face refers to a vertex index that is out of range", path)
    return ObjMesh(pos[tri], nrm[tri] if nrm is not None else None,
                   uv[tri] if uv is not None else None, np.full(len(tri), -1, np.int32), [])


def load_obj(path, use_cache=True):
    """Triangles and materials of the OBJ at ``path``; raises SceneError naming the file."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror}", path) from None
    key = _cache_key(path, data)
    cpath = os.path.join(cache_dir(), key + ".npz")
    if use_cache and os.path.isfile(cpath):
        try:
            return _read_cache(cpath)
        except Exception:   # a damaged cache entry is re-made, never trusted
            pass
    mesh = _parse(path)
    if use_cache:
        _write_cache(cpath, mesh)
    return mesh


def _read_cache(cpath):
    with np.load(cpath, allow_pickle=False) as z:
        normals = z["normals"] if z["has_normals"] else None
        uvs = z["uvs"] if z["has_uvs"] else None
        return ObjMesh(z["positions"], normals, uvs, z["face_material"],
                       json.loads(str(z["materials"])), from_cache=True)


def _write_cache(cpath, mesh):
    try:
        os.makedirs(os.path.dirname(cpath), exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(cpath), suffix=".tmp.npz")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, positions=mesh.positions,
                     normals=mesh.normals if mesh.normals is not None else np.zeros((0, 3, 3),
                                                                                    np.float32),
                     has_normals=mesh.normals is not None, face_material=mesh.face_material,
                     uvs=mesh.uvs if mesh.uvs is not None else np.zeros((0, 3, 2), np.float32),
                     has_uvs=mesh.uvs is not None,
                     materials=json.dumps(mesh.materials))
        os.replace(tmp, cpath)
    except OSError as e:   # a read-only cache folder only costs speed
        from .._cache import warn
        warn(f"mesh cache not written ({e.strerror or e}); the mesh will be parsed again next run")


def _parse(path):
    import pywavefront
    logging.getLogger("pywavefront").setLevel(logging.ERROR)
    try:
        scene = pywavefront.Wavefront(path, collect_faces=True, create_materials=True,
                                      parse=True)
    except (IndexError, ValueError) as e:
        if _mixed_face_forms(path):
            raise SceneError("faces of one material mix the forms v, v/vt, v//vn and "
                             "v/vt/vn; the OBJ reader (pywavefront) needs one form per "
                             "material: export with UVs and normals on every face",
                             path) from None
        if isinstance(e, IndexError):
            raise SceneError("a face refers to a vertex, normal or texture coordinate "
                             "index that is out of range", path) from None
        raise SceneError(f"invalid OBJ: {e}", path) from None
    except FileNotFoundError as e:
        raise SceneError(f"file not found: {e.filename or e}", path) from None
    except Exception as e:   # pywavefront reports malformed lines with various types
        raise SceneError(f"invalid OBJ: {e}", path) from None
    for m in scene.mesh_list:
        if m.faces and min(min(f) for f in m.faces) < 0:
            raise SceneError("a face refers to a vertex index that is out of range", path)
    positions, normals, uvs, face_mat, materials = [], [], [], [], []
    all_have_normals = True
    any_uvs = any("T2F" in m.vertex_format for m in scene.materials.values() if m.vertices)
    extra = _mtl_extras(path)
    for mat in scene.materials.values():
        if not mat.vertices:
            continue
        fmt = mat.vertex_format.split("_")
        sizes = {"T2F": 2, "C3F": 3, "N3F": 3, "V3F": 3}
        offsets, stride = {}, 0
        for part in fmt:
            offsets[part] = stride
            stride += sizes[part]
        if len(mat.vertices) % (3 * stride):
            # pywavefront leaves out the value of an index past the end of its list
            raise SceneError("a face refers to a texture coordinate or normal index that is "
                             "out of range, or a face has fewer than 3 vertices", path)
        with np.errstate(over="ignore"):     # > float32 range: inf, refused later
            v = np.asarray(mat.vertices, dtype=np.float32).reshape(-1, stride)
        o = offsets["V3F"]
        positions.append(v[:, o:o + 3].reshape(-1, 3, 3))
        if "N3F" in offsets:
            o = offsets["N3F"]
            normals.append(v[:, o:o + 3].reshape(-1, 3, 3))
        else:
            all_have_normals = False
        if "T2F" in offsets:
            o = offsets["T2F"]
            uvs.append(v[:, o:o + 2].reshape(-1, 3, 2))
        else:
            # faces of a material without vt: (0, 0), so that the other materials keep
            # theirs (a textured material without vt is refused by the compiler)
            uvs.append(np.zeros((len(v) // 3, 3, 2), np.float32))
        # pywavefront names faces without `usemtl` "default<N>"; those get no material.
        index = -1 if (mat.is_default and re.fullmatch(r"default\d+", mat.name)) else len(materials)
        if index >= 0:
            materials.append({
                # usemtl of a material no .mtl defines: an error only where the scene
                # does not give the object a material of its own
                "undefined": bool(mat.is_default),
                "name": mat.name, "Kd": list(mat.diffuse[:3]), "Ke": list(mat.emissive[:3]),
                "Ks": list(mat.specular[:3]), "Ns": float(mat.shininess),
                "Ni": float(mat.optical_density),
                "Pr": extra.get(mat.name, {}).get("Pr"), "Pm": extra.get(mat.name, {}).get("Pm"),
                "map_Kd": mat.texture.path if mat.texture else None,
                "map_Bump": (mat.texture_bump.path if mat.texture_bump else
                             extra.get(mat.name, {}).get("norm"))})
        face_mat.append(np.full(len(v) // 3, index, np.int32))
    if not positions:
        return ObjMesh(np.zeros((0, 3, 3), np.float32), None, None, np.zeros(0, np.int32), [])
    return ObjMesh(np.concatenate(positions),
                   np.concatenate(normals) if all_have_normals and normals else None,
                   np.concatenate(uvs) if any_uvs else None,
                   np.concatenate(face_mat), materials)


def _mixed_face_forms(path):
    """Do the face lines of ``path`` use more than one index form (v, v/vt, v//vn,
    v/vt/vn)? Only to explain a failure of the reader."""
    forms = set()
    try:
        with open(path, "rb") as f:
            for line in f:
                if line.startswith(b"f ") or line.startswith(b"f\t"):
                    for token in line.split()[1:]:
                        parts = token.split(b"/")
                        forms.add((len(parts) > 1 and parts[1] != b"", len(parts) > 2))
    except OSError:
        return False
    return len(forms) > 1


def _mtl_extras(path):
    """PBR keys of the .mtl files that pywavefront does not read: Pr (roughness), Pm
    (metallic) and norm (normal map), per material name."""
    out = {}
    try:
        with open(path, "rb") as f:
            libs = re.findall(rb"^[ \t]*mtllib[ \t]+(.+?)[ \t]*$", f.read(), re.M)
    except OSError:
        return out
    for lib in libs:
        mtl = os.path.join(os.path.dirname(path), lib.decode("utf-8", "replace"))
        try:
            with open(mtl, "r", encoding="utf-8", errors="replace") as f:
                lines = f.read().splitlines()
        except OSError:
            continue
        cur = None
        for line in lines:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "newmtl" and len(parts) > 1:
                cur = out.setdefault(" ".join(parts[1:]), {})
            elif cur is not None and parts[0] in ("Pr", "Pm") and len(parts) > 1:
                try:
                    cur[parts[0]] = float(parts[1])
                except ValueError:
                    pass
            elif cur is not None and parts[0] == "norm" and len(parts) > 1:
                cur["norm"] = parts[-1]
    return out
