"""Mitsuba's ``.serialized`` meshes: a reader of our own, as no library reads the format.

The format is documented with Mitsuba's ``serialized`` shape plugin (Mitsuba 3,
``src/shapes/serialized.cpp``): a file holds one or more meshes, each a 4-byte header
(uint16 0x041C, uint16 version 3 or 4) followed by a zlib stream of

    uint32 flags      0x1 vertex normals, 0x2 texture coordinates, 0x8 vertex colours,
                      0x10 face normals, 0x1000 single / 0x2000 double precision
    (version 4) a NUL-terminated UTF-8 name
    uint64 vertex count, uint64 triangle count
    positions (3 per vertex), [normals (3)], [texture coordinates (2)], [colours (3)]
    triangles: uint32 indices (uint64 beyond 2^32 vertices)

all little-endian; the file ends with the meshes' byte offsets (uint64 each in version 4,
uint32 in version 3) and their count (uint32). Read with numpy and the standard library's
zlib; tested against the same meshes as Mitsuba 3 loads them (tests/test_serialized.py).
"""
import struct
import zlib

import numpy as np

from .errors import SceneError

MAGIC = 0x041C
HAS_NORMALS, HAS_TEXCOORDS, HAS_COLORS, FACE_NORMALS = 0x1, 0x2, 0x8, 0x10
DOUBLE = 0x2000


def _offsets(data, version, path):
    """Byte offsets of the file's meshes, from the dictionary at its end."""
    if len(data) < 8:
        raise SceneError("not a Mitsuba .serialized mesh (too short)", path)
    count = struct.unpack_from("<I", data, len(data) - 4)[0]
    size = 8 if version == 4 else 4
    start = len(data) - 4 - size * count
    if count == 0 or start < 0:
        raise SceneError(f"a .serialized file's mesh table is damaged ({count} meshes)", path)
    offsets = np.frombuffer(data, "<u8" if size == 8 else "<u4", count, start)
    if (offsets >= len(data)).any():
        raise SceneError("a .serialized file's mesh table points past its end", path)
    return [int(o) for o in offsets]


def read_serialized(path, shape_index=0):
    """(positions (V, 3), faces (F, 3) int64, normals (V, 3) or None, texture coordinates
    (V, 2) or None, face_normals flag, name) of mesh ``shape_index`` of the file, as stored
    (float64; texture coordinates as Mitsuba stores them)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise SceneError(f"cannot read: {e.strerror or e}", path) from None
    if len(data) < 4:
        raise SceneError("not a Mitsuba .serialized mesh (too short)", path)
    magic, version = struct.unpack_from("<HH", data, 0)
    if magic != MAGIC:
        raise SceneError(f"not a Mitsuba .serialized mesh (header {magic:#06x}, expected "
                         f"{MAGIC:#06x})", path)
    if version not in (3, 4):
        raise SceneError(f".serialized version {version}: only versions 3 and 4 exist", path)
    offset = 0
    if shape_index:
        offsets = _offsets(data, version, path)
        if shape_index >= len(offsets):
            raise SceneError(f"shape_index {shape_index}: the file holds {len(offsets)} "
                             f"meshes (0..{len(offsets) - 1})", path)
        offset = offsets[shape_index]
        magic, version = struct.unpack_from("<HH", data, offset) if offset + 4 <= len(
            data) else (0, 0)
        if magic != MAGIC or version not in (3, 4):
            raise SceneError(f"mesh {shape_index}: no .serialized header at its offset", path)
    try:
        # one mesh's stream; decompressobj stops at its end (the next header follows)
        stream = zlib.decompressobj()
        raw = stream.decompress(data[offset + 4:])
        if not stream.eof:
            raise SceneError("a .serialized mesh ends before its data does (truncated)", path)
    except zlib.error as e:
        raise SceneError(f"a .serialized mesh's compressed data is damaged ({e})", path) \
            from None
    try:
        return _parse(raw, version, path)
    except (struct.error, ValueError, IndexError):
        raise SceneError("a .serialized mesh ends before its data does (truncated)",
                         path) from None


def _parse(raw, version, path):
    flags = struct.unpack_from("<I", raw, 0)[0]
    pos = 4
    name = ""
    if version == 4:
        end = raw.index(b"\0", pos)
        name = raw[pos:end].decode("utf-8", "replace")
        pos = end + 1
    n_vert, n_tri = struct.unpack_from("<QQ", raw, pos)
    pos += 16
    real = np.dtype("<f8" if flags & DOUBLE else "<f4")

    def take(dtype, count):
        nonlocal pos
        a = np.frombuffer(raw, dtype, count, pos)
        pos += a.nbytes
        return a
    p = take(real, 3 * n_vert).reshape(-1, 3).astype(np.float64)
    normals = take(real, 3 * n_vert).reshape(-1, 3).astype(np.float64) \
        if flags & HAS_NORMALS else None
    uv = take(real, 2 * n_vert).reshape(-1, 2).astype(np.float64) \
        if flags & HAS_TEXCOORDS else None
    if flags & HAS_COLORS:
        take(real, 3 * n_vert)         # vertex colours: not read (as Mitsuba 3)
    index = np.dtype("<u8" if n_vert > 0xFFFFFFFF else "<u4")
    faces = take(index, 3 * n_tri).reshape(-1, 3).astype(np.int64)
    if faces.size and faces.max() >= n_vert:
        raise SceneError(f"a triangle's vertex index {int(faces.max())} is out of range "
                         f"(0..{n_vert - 1})", path)
    return p, faces, normals, uv, bool(flags & FACE_NORMALS), name


__all__ = ["read_serialized"]
