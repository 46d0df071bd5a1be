"""Mesh files: OBJ, read with tinyobjloader (its .mtl with pywavefront) and cached on disk
keyed by file content, PLY (ASCII or binary), read with plyfile, and glTF (scene.gltf).

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

import numpy as np

from .errors import SceneError
from .gltf import load_gltf_mesh
from .mesh_data import ObjMesh
from .serialized import read_serialized

CACHE_VERSION = 6


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
    for m in mtllibs(data):
        mtl = os.path.join(os.path.dirname(path), m.decode("utf-8", "replace"))
        h.update(m)
        if os.path.isfile(mtl):
            with open(mtl, "rb") as f:
                h.update(f.read())
    return h.hexdigest()


MESH_FORMATS = (".obj", ".ply", ".gltf", ".glb", ".serialized")

# PLY vertex properties read as texture coordinates, the first pair present wins
PLY_UV_NAMES = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))


def load_mesh(path, use_cache=True, shape_index=0):
    """Triangles (and, for OBJ and glTF, materials) of the mesh file at ``path`` by its
    extension (``shape_index``: which mesh of a Mitsuba .serialized file)."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".ply":
        return load_ply(path)
    if ext == ".serialized":
        return load_serialized(path, shape_index)
    if ext in (".gltf", ".glb"):
        return load_gltf_mesh(path)
    return load_obj(path, use_cache=use_cache)


def load_serialized(path, shape_index=0):
    """Mesh ``shape_index`` of a Mitsuba .serialized file (scene.serialized reads it) as
    per-triangle arrays. Texture coordinates turn to the scene format's convention: v up
    from the image's bottom row is Mitsuba's v flipped, v' = 1 - v, as for its OBJ files."""
    p, faces, normals, uv, _, _ = read_serialized(path, shape_index)
    if uv is not None:
        uv = np.stack([uv[:, 0], 1.0 - uv[:, 1]], -1)
    return ObjMesh(p[faces].astype(np.float32),
                   normals[faces].astype(np.float32) if normals is not None else None,
                   uv[faces].astype(np.float32) if uv is not None else None,
                   np.full(len(faces), -1, np.int32), [])


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
    mesh = _parse(path, data)
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


def _parse(path, data=None):
    """An OBJ's triangles through tinyobjloader (C++: 1.6M triangles in ~1.5 s where
    pywavefront, pure Python, took 15-28 s), its .mtl materials through pywavefront.

    tinyobjloader reads a malformed coordinate (NaN and infinity included) as 0 without a
    word: :func:`_check_vertex_lines` refuses those first. Its numpy accessors need a
    fix-up: :func:`_numpy`."""
    import tinyobjloader
    if data is None:
        try:
            with open(path, "rb") as f:
                data = f.read()
        except OSError as e:
            raise SceneError(f"cannot read: {e.strerror}", path) from None
    _check_vertex_lines(data, path)
    reader = tinyobjloader.ObjReader()
    config = tinyobjloader.ObjReaderConfig()
    # polygons are fanned here, from their first vertex (as pywavefront and Blender):
    # tinyobjloader would split a quad along its shorter diagonal
    config.triangulate = False
    if not reader.ParseFromFile(path, config):
        error = " ".join(reader.Error().split())
        line = re.search(r"[Ll]ine (\d+)", error)
        where = f" (line {line.group(1)})" if line else ""
        if "`f' line" in error:
            raise SceneError(f"a face refers to a vertex index that is out of range or 0"
                             f"{where}", path)
        raise SceneError(f"invalid OBJ: {error or 'unreadable'}", path)
    warning = reader.Warning()
    if "Degenerated face" in warning:
        raise SceneError("a face has fewer than 3 vertices", path)
    attrib = reader.GetAttrib()
    with np.errstate(over="ignore"):        # > float32 range: inf, refused later
        v = _numpy(attrib.numpy_vertices()).astype(np.float32).reshape(-1, 3)
        vn = _numpy(attrib.numpy_normals()).astype(np.float32).reshape(-1, 3)
        vt = _numpy(attrib.numpy_texcoords()).astype(np.float32).reshape(-1, 2)
    del attrib
    vi, ni, ti, mat_ids = [], [], [], []
    for shape in reader.GetShapes():
        m = shape.mesh
        corners = _numpy(m.numpy_indices()).reshape(-1, 3)   # vertex, normal, texcoord
        ids = _numpy(m.numpy_material_ids())
        if len(corners) != 3 * len(ids):
            # polygons (faces of fewer than 3 vertices were refused above, so 3 corners
            # per face means triangles only). numpy_num_face_vertices copies 4 bytes per
            # 1-byte count: the list is read
            sizes = np.array(m.num_face_vertices, np.int64)
            if len(sizes) != len(ids) or sizes.sum() != len(corners) or sizes.min() < 3:
                raise SceneError("invalid OBJ: a face has fewer than 3 vertices", path)
            corners, ids = _fan(corners, ids, sizes)
        vi.append(corners[:, 0].copy())
        ni.append(corners[:, 1].copy())
        ti.append(corners[:, 2].copy())
        mat_ids.append(np.array(ids, np.int32))
        del corners
    tiny_materials = [mm.name for mm in reader.GetMaterials()]
    del reader
    if not vi:
        return ObjMesh(np.zeros((0, 3, 3), np.float32), None, None, np.zeros(0, np.int32), [])
    def joined(parts):
        return parts[0] if len(parts) == 1 else np.concatenate(parts)
    vi, ni, ti, mat_ids = joined(vi), joined(ni), joined(ti), joined(mat_ids)
    for idx, table, what in ((vi, v, "vertex"), (ni, vn, "normal"),
                             (ti, vt, "texture coordinate")):
        if len(idx) and (idx.max() >= len(table) or (idx.min() < 0 and what == "vertex")):
            raise SceneError(f"a face refers to a {what} index that is out of range", path)
    if "out of bounds" in warning or "out of range" in warning:
        # (an index of 0, or negative past the start, which the reader leaves out)
        raise SceneError("a face refers to a vertex index that is out of range", path)
    positions = _gather(v, vi).reshape(-1, 3, 3)
    del vi
    normals = _gather(vn, ni).reshape(-1, 3, 3) if len(ni) and ni.min() >= 0 else None
    uvs = None
    if len(ti) and ti.max() >= 0:
        # corners without vt: (0, 0), so that the faces that have them keep theirs (a
        # textured material on faces without vt is refused by the compiler)
        uvs = np.where((ti >= 0)[:, None], vt[np.maximum(ti, 0)] if len(vt) else 0.0,
                       0.0).astype(np.float32).reshape(-1, 3, 2)
    materials, face_mat = _obj_materials(path, data, tiny_materials, mat_ids, warning)
    return ObjMesh(positions, normals, uvs, face_mat, materials)


def _numpy(array):
    """An array from one of tinyobjloader's numpy accessors. Each is a fresh contiguous
    array that the binding fills with memcpy (py::array_t<T>(n)), but the 2.0.0rc13 wheels
    report a stride of 0 under NumPy 2, so every element reads as the first: the stride is
    set back to the item size (tests/test_meshes.py checks these against the list
    accessors)."""
    if array.ndim == 1 and len(array) > 1 and array.strides[0] == 0:
        array = np.lib.stride_tricks.as_strided(array, array.shape, (array.itemsize,),
                                                writeable=False)
    return array


def _fan(corners, ids, sizes):
    """Polygons (corner rows, sizes) as triangle fans (0, k, k + 1), and their materials."""
    first = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    n_tri = sizes - 2
    face = np.repeat(np.arange(len(sizes)), n_tri)
    k = np.arange(len(face)) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
    rows = np.stack([first[face], first[face] + k + 1, first[face] + k + 2], -1).reshape(-1)
    return corners[rows], ids[face]


def _gather(table, idx):
    """table[idx] for rows of a float32 table, gathered as whole rows (as one void item:
    1.7x faster than fancy indexing of a 2-D array)."""
    rows = np.ascontiguousarray(table).view(np.dtype((np.void, table.shape[1] * 4))).reshape(-1)
    return rows[idx].view(np.float32).reshape(-1, table.shape[1])


# The bytes a coordinate may contain (digits, sign, point, exponent) and separators
_NUMBER_BYTES = np.zeros(256, bool)
_NUMBER_BYTES[np.frombuffer(b"0123456789+-.eE \t\r\n", np.uint8)] = True
_SPACE = np.zeros(256, bool)
_SPACE[np.frombuffer(b" \t\r\n", np.uint8)] = True
# tokens a vertex line needs, keyword included: v x y z, vn x y z, vt u
_MIN_TOKENS = np.array([0, 4, 4, 2], np.int32)
_CHUNK = 1 << 24


def _check_vertex_lines(data, path):
    """Every v, vn and vt line holds only numbers, enough of them. tinyobjloader reads a
    malformed coordinate ('zz', 'nan', 'inf', a missing one) as 0 without a word; this
    check, vectorised over 16 MB chunks of whole lines, refuses such a file instead (0.2 s
    for 60 MB)."""
    arr = np.frombuffer(data, np.uint8)
    begin, line_base = 0, 0
    while begin < len(arr):
        end = min(len(arr), begin + _CHUNK)
        if end < len(arr):
            nl = data.rfind(b"\n", begin, end)
            end = nl + 1 if nl >= begin else len(arr)
        line_base = _check_chunk(arr[begin:end], line_base, path)
        begin = end


def _check_chunk(chunk, line_base, path):
    is_nl = chunk == 10
    starts = np.flatnonzero(is_nl) + 1
    starts = np.concatenate(([0], starts[starts < len(chunk)]))
    n_lines = int(len(starts))
    first = chunk[starts]
    second = chunk[np.minimum(starts + 1, len(chunk) - 1)]
    kind = np.where(first != ord("v"), 0,
                    np.where(second == ord("n"), 2, np.where(second == ord("t"), 3,
                                                             np.where(_SPACE[second], 1, 0))))
    for i in np.flatnonzero((first == 32) | (first == 9)):    # indented lines: rare
        line = bytes(chunk[starts[i]:starts[i + 1] if i + 1 < n_lines else len(chunk)])
        _check_line(line.strip(), line_base + i + 1, path)
    vlines = np.flatnonzero(kind)
    if not len(vlines):
        return line_base + n_lines
    # only the span from the first to the last vertex line (they come in blocks)
    lo = int(starts[vlines[0]])
    hi = int(starts[vlines[-1] + 1]) if vlines[-1] + 1 < n_lines else len(chunk)
    span = chunk[lo:hi]
    ok = _NUMBER_BYTES[span]
    ok[starts[vlines] - lo] = True                              # the keyword: v
    two = vlines[kind[vlines] >= 2]
    ok[np.minimum(starts[two] + 1 - lo, len(span) - 1)] = True  # vn, vt
    bad = np.flatnonzero(~ok) + lo
    if len(bad):
        line = np.searchsorted(starts, bad, side="right") - 1
        hit = kind[line] > 0
        if hit.any():
            i = int(line[int(np.argmax(hit))])
            raise SceneError(f"line {line_base + i + 1}: a vertex line with something other "
                             "than numbers (NaN and infinity included)", path)
    space = _SPACE[span]
    token = ~space
    token[1:] &= space[:-1]
    count = np.concatenate(([0], np.cumsum(token, dtype=np.int32)))
    ends = np.append(starts[1:], len(chunk))
    v_lo, v_hi = starts[vlines] - lo, ends[vlines] - lo
    short = count[v_hi] - count[v_lo] < _MIN_TOKENS[kind[vlines]]
    if short.any():
        i = int(vlines[int(np.argmax(short))])
        raise SceneError(f"line {line_base + i + 1}: a vertex line with too few numbers",
                         path)
    return line_base + n_lines


def _check_line(line, number, path):
    parts = line.split()
    if not parts or parts[0] not in (b"v", b"vn", b"vt"):
        return
    need = {b"v": 3, b"vn": 3, b"vt": 1}[parts[0]]
    try:
        values = [float(x) for x in parts[1:]]
    except ValueError:
        values = None
    if values is None or not all(np.isfinite(values)):
        raise SceneError(f"line {number}: a vertex line with something other than numbers "
                         "(NaN and infinity included)", path)
    if len(values) < need:
        raise SceneError(f"line {number}: a vertex line with too few numbers", path)


def _obj_materials(path, data, names, mat_ids, warning):
    """The .mtl materials of the faces' material ids (tinyobjloader's, by name) with their
    values as pywavefront reads them, and each face's index into that list (-1: none)."""
    import pywavefront.material
    logging.getLogger("pywavefront").setLevel(logging.ERROR)
    parsed = {}
    for lib in mtllibs(data):
        mtl = os.path.join(os.path.dirname(path), lib.decode("utf-8", "replace"))
        if not os.path.isfile(mtl):
            continue
        try:
            parsed.update(pywavefront.material.MaterialParser(mtl).materials)
        except Exception as e:     # pywavefront reports malformed lines with various types
            raise SceneError(f"invalid .mtl file {mtl}: {e}", path) from None
    extra = _mtl_extras(path, data)
    used = np.unique(mat_ids[mat_ids >= 0])
    materials = []
    local = np.full(len(names) + 1, -1, np.int32)
    for i in used:
        name = names[i]
        mat = parsed.get(name)
        if mat is None:
            materials.append({"undefined": True, "name": name})
        else:
            materials.append({
                "undefined": False,
                "name": name, "Kd": list(mat.diffuse[:3]), "Ke": list(mat.emissive[:3]),
                "Ks": list(mat.specular[:3]), "Ns": float(mat.shininess),
                "Ni": float(mat.optical_density),
                "Pr": extra.get(name, {}).get("Pr"), "Pm": extra.get(name, {}).get("Pm"),
                "map_Kd": mat.texture.path if mat.texture else None,
                "map_Bump": (mat.texture_bump.path if mat.texture_bump else
                             extra.get(name, {}).get("norm"))})
        local[i] = len(materials) - 1
    # usemtl of a material no .mtl defines (tinyobjloader warns, and gives its faces the
    # previous material): an error only where the scene gives the object no material
    for name in dict.fromkeys(re.findall(r"material \[ '(.*?)' \] not found", warning)):
        materials.append({"undefined": True, "name": name})
    return materials, local[np.where(mat_ids >= 0, mat_ids, len(names))]


def mtllibs(data):
    """The .mtl names of an OBJ's ``mtllib`` lines (as bytes). The lines are found by
    substring search: a multi-line regular expression over a 60 MB file takes 0.1 s."""
    out = []
    pos = data.find(b"mtllib")
    while pos >= 0:
        start = data.rfind(b"\n", 0, pos) + 1
        end = data.find(b"\n", pos)
        line = data[start:end if end >= 0 else len(data)]
        m = re.fullmatch(rb"[ \t]*mtllib[ \t]+(.+?)[ \t\r]*", line)
        if m:
            out.append(m.group(1))
        pos = data.find(b"mtllib", pos + 6)
    return out


def _mtl_extras(path, data):
    """PBR keys of the .mtl files that pywavefront does not read: Pr (roughness), Pm
    (metallic) and norm (normal map), per material name."""
    out = {}
    for lib in mtllibs(data):
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
