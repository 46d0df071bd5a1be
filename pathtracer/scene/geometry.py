"""Mesh geometry on the host: vertex normals and tangents of unindexed triangles (NumPy)."""
import numpy as np


def vertex_tangents(pos, nrm, uv):
    """Per-vertex tangents from texture coordinates (the idea of MikkTSpace: per-face
    tangents from the uv derivatives, accumulated over vertices that share position,
    normal and uv, then made orthogonal to the vertex normal), and the handedness sign of
    the bitangent. pos, nrm (F, 3, 3), uv (F, 3, 2); returns (F, 3, 3), (F, 3)."""
    e1 = pos[:, 1] - pos[:, 0]
    e2 = pos[:, 2] - pos[:, 0]
    d1 = uv[:, 1] - uv[:, 0]
    d2 = uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    ft = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r        # dp/du
    fb = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r        # dp/dv
    # weight by the face's angle-independent area share: unnormalised derivatives of a
    # bigger face weigh more, as MikkTSpace's area weighting
    key = np.concatenate([pos.reshape(-1, 3), nrm.reshape(-1, 3), uv.reshape(-1, 2)], axis=1)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    acc_t = np.zeros((inv.max() + 1, 3))
    acc_b = np.zeros((inv.max() + 1, 3))
    np.add.at(acc_t, inv, np.repeat(ft, 3, axis=0))
    np.add.at(acc_b, inv, np.repeat(fb, 3, axis=0))
    t = acc_t[inv].reshape(-1, 3, 3)
    b = acc_b[inv].reshape(-1, 3, 3)
    t = t - nrm * np.sum(t * nrm, axis=2, keepdims=True)
    length = np.linalg.norm(t, axis=2, keepdims=True)
    t = np.where(length > 1e-30, t / np.where(length > 1e-30, length, 1.0), 0.0)
    sign = np.where(np.sum(np.cross(nrm, t) * b, axis=2) < 0, -1.0, 1.0)
    return t, sign


def vertex_normals(positions):
    """Area-weighted vertex normals for unindexed triangles (F, 3, 3), welding equal
    positions; a vertex whose normals cancel gets its face's normal."""
    flat = positions.reshape(-1, 3)
    _, inverse = np.unique(flat, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    face_n = np.cross(positions[:, 1] - positions[:, 0], positions[:, 2] - positions[:, 0])
    acc = np.zeros((inverse.max() + 1 if len(inverse) else 0, 3))
    for k in range(3):
        np.add.at(acc, inverse[k::3], face_n)
    return acc[inverse].reshape(-1, 3, 3)


def safe_normalize(n, fallback):
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = length > 0
    return np.where(ok, n / np.where(ok, length, 1.0), fallback)


def uv_sphere(n_theta, n_phi, radius=1.0, seam=False):
    """A UV sphere centred at the origin, triangles counter-clockwise seen from outside.

    ``seam=False``: a closed mesh, one vertex at each pole and ``n_phi`` on each of the
    ``n_theta - 1`` rings; returns (vertices (V, 3), faces (F, 3) int). ``seam=True``: a
    grid of (n_theta + 1) x (n_phi + 1) vertices whose first and last columns coincide (the
    texture seam) and whose pole rows repeat the pole, with texture coordinates u = phi /
    2 pi, v = 1 - theta / pi; returns (vertices, faces, uvs (V, 2)). Unit normals are
    vertices / radius. theta is measured from +y, phi from +x towards -z."""
    if seam:
        t = np.pi * np.arange(n_theta + 1) / n_theta
        p = 2 * np.pi * np.arange(n_phi + 1) / n_phi
        tt, pp = np.meshgrid(t, p, indexing="ij")
        unit = np.stack([np.sin(tt) * np.cos(pp), np.cos(tt), -np.sin(tt) * np.sin(pp)], -1)
        unit[:, -1] = unit[:, 0]     # the seam's columns the same points (welded normals)
        unit[0, :], unit[-1, :] = unit[0, 0], unit[-1, 0]     # and each pole one point
        uvs = np.stack([pp / (2 * np.pi), 1 - tt / np.pi], -1).reshape(-1, 2)
        faces = []
        for i in range(n_theta):
            for j in range(n_phi):
                a = i * (n_phi + 1) + j
                b, c, d = a + 1, a + n_phi + 1, a + n_phi + 2
                if i > 0:                       # the pole rows' first triangles are empty
                    faces.append((a, c, b))
                if i < n_theta - 1:
                    faces.append((b, c, d))
        return radius * unit.reshape(-1, 3), np.array(faces, np.int64), uvs
    verts = [(0.0, 1.0, 0.0)]
    for i in range(1, n_theta):
        t = np.pi * i / n_theta
        for j in range(n_phi):
            p = 2 * np.pi * j / n_phi
            verts.append((np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)))
    verts.append((0.0, -1.0, 0.0))
    bottom = len(verts) - 1

    def ring(i, j):
        return 1 + (i - 1) * n_phi + (j % n_phi)

    faces = []
    for j in range(n_phi):
        faces.append((0, ring(1, j), ring(1, j + 1)))
        faces.append((bottom, ring(n_theta - 1, j + 1), ring(n_theta - 1, j)))
    for i in range(1, n_theta - 1):
        for j in range(n_phi):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            faces += [(a, c, b), (b, c, d)]
    return radius * np.array(verts), np.array(faces, np.int64)
