"""Scene compiler: a validated description -> flat float32/int32 arrays + a feature set."""
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..accel import build_bvh
from ..kernels.integrator import Features, SceneArrays
from ..kernels.materials import MAT_DIFFUSE, MAT_WIDTH
from .errors import SceneError
from .loader import NOT_YET, SceneDescription, euler_matrix, load_scene_description
from .meshes import load_obj


@dataclass
class CompiledScene:
    arrays: SceneArrays
    features: Features
    width: int
    height: int
    spp: int
    max_bounces: int
    rr_depth: int
    seed: int
    n_triangles: int
    description: SceneDescription
    timings: dict = field(default_factory=dict)   # seconds: mesh_load, bvh_build, total
    bvh_depth: int = 0


def load_scene(path, use_cache=True):
    """Read, validate and compile the scene file at ``path``."""
    return compile_scene(load_scene_description(path), use_cache=use_cache)


def _camera_array(cam):
    w, h = cam.resolution
    pos = np.asarray(cam.position, np.float64)
    if cam.look_at is not None:
        fwd = np.subtract(cam.look_at, pos)
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, cam.up)
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
    else:
        r = euler_matrix(cam.rotation)
        fwd, up, right = r @ [0, 0, -1.0], r @ [0, 1.0, 0], r @ [1.0, 0, 0]
    tan_x = math.tan(math.radians(cam.fov) / 2)
    tan_y = tan_x * h / w
    out = np.zeros(16, np.float32)
    out[0:3] = pos
    out[3:6] = fwd
    out[6:9] = right * tan_x
    out[9:12] = up * tan_y
    return out


def _vertex_normals(positions):
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


def _safe_normalize(n, fallback):
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = length > 0
    return np.where(ok, n / np.where(ok, length, 1.0), fallback)


def compile_scene(desc, use_cache=True):
    t_start = time.perf_counter()
    # ---- Materials: the scene's, then each OBJ's .mtl ones, then the default grey ----
    mat_rows = []
    mat_index = {}
    for name, m in desc.materials.items():
        mat_index[name] = len(mat_rows)
        mat_rows.append((m.albedo, m.emission, m.two_sided))
    default_mat = None

    def default_material():
        nonlocal default_mat
        if default_mat is None:
            default_mat = len(mat_rows)
            mat_rows.append(((0.5, 0.5, 0.5), (0.0, 0.0, 0.0), False))
        return default_mat

    # ---- Geometry ----
    positions, normals, tri_mat, smooth_flags = [], [], [], []
    t_mesh = 0.0
    for obj in desc.objects:
        where = obj.pointer
        if obj.file is not None:
            t0 = time.perf_counter()
            mesh = load_obj(obj.file, use_cache=use_cache)
            t_mesh += time.perf_counter() - t0
            pos = mesh.positions.astype(np.float64)
            file_normals = mesh.normals.astype(np.float64) if mesh.normals is not None else None
            if obj.material is not None:
                mats = np.full(len(pos), mat_index[obj.material], np.int32)
            else:
                local = np.empty(len(mesh.materials) + 1, np.int32)
                for i, mm in enumerate(mesh.materials):
                    specular = any(x > 0 for x in mm["Ks"])
                    if specular or mm["map_Kd"] or mm["map_Bump"]:
                        raise SceneError(
                            f"OBJ material {mm['name']!r} has specular terms or maps, which map "
                            f"to a principled material; that {NOT_YET}", desc.path,
                            f"{where}/file")
                    local[i] = len(mat_rows)
                    mat_rows.append((tuple(mm["Kd"]), tuple(mm["Ke"]), False))
                local[-1] = default_material() if (mesh.face_material < 0).any() else 0
                mats = local[mesh.face_material]
        else:
            pos = obj.vertices[obj.faces]
            file_normals = None
            mats = np.full(len(pos), mat_index[obj.material] if obj.material is not None
                           else default_material(), np.int32)
        if not np.isfinite(pos).all():
            raise SceneError("vertex coordinates contain NaN or infinity", desc.path,
                             f"{where}/{'file' if obj.file else 'vertices'}")
        # Transform: positions by M, normals by the inverse transpose; a mirroring transform
        # swaps two vertices so that the front side (counter-clockwise) stays the front.
        m3, t = obj.matrix[:3, :3], obj.matrix[:3, 3]
        pos = pos @ m3.T + t
        if np.linalg.det(m3) < 0:
            pos = pos[:, [0, 2, 1]]
            if file_normals is not None:
                file_normals = file_normals[:, [0, 2, 1]]
        if not np.isfinite(pos).all() or np.abs(pos).max(initial=0) > 1e30:
            raise SceneError("transformed vertex coordinates overflow", desc.path, where)
        face_n = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
        face_n = _safe_normalize(face_n, np.array([0.0, 0.0, 1.0]))
        if obj.smooth:
            if file_normals is not None:
                vn = file_normals @ np.linalg.inv(m3)
            else:
                vn = _vertex_normals(pos)
            vn = _safe_normalize(vn, face_n[:, None, :])
        else:
            vn = np.repeat(face_n[:, None, :], 3, axis=1)
        positions.append(pos)
        normals.append(vn)
        tri_mat.append(mats)
        smooth_flags.append(obj.smooth)

    if positions:
        pos = np.concatenate(positions)
        vn = np.concatenate(normals)
        tmat = np.concatenate(tri_mat)
    else:
        pos = np.zeros((0, 3, 3))
        vn = np.zeros((0, 3, 3))
        tmat = np.zeros(0, np.int32)
    pos32 = pos.astype(np.float32)

    # ---- BVH; triangles reordered so each leaf is a contiguous range ----
    t0 = time.perf_counter()
    bvh = build_bvh(pos32)
    t_bvh = time.perf_counter() - t0
    pos32 = pos32[bvh.order]
    vn = vn[bvh.order]
    tmat = tmat[bvh.order]
    n_tri = len(pos32)

    mat = np.zeros((max(1, len(mat_rows)), MAT_WIDTH), np.float32)
    for i, (albedo, emission, two_sided) in enumerate(mat_rows):
        mat[i, 0:3] = albedo
        mat[i, 3:6] = emission
        mat[i, 6] = 1.0 if two_sided else 0.0
        mat[i, 7] = MAT_DIFFUSE

    tri_v = np.zeros((max(1, n_tri), 9), np.float32)
    if n_tri:
        tri_v[:n_tri, 0:3] = pos32[:, 0]
        tri_v[:n_tri, 3:6] = pos32[:, 1] - pos32[:, 0]
        tri_v[:n_tri, 6:9] = pos32[:, 2] - pos32[:, 0]

    # ---- Lights: one power-proportional distribution over emitters ----
    weights, refs = [], []
    area = np.zeros(n_tri)
    if n_tri:
        e1 = tri_v[:n_tri, 3:6].astype(np.float64)
        e2 = tri_v[:n_tri, 6:9].astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
        mat_power = mat[:, 3:6].mean(axis=1).astype(np.float64) * np.where(mat[:, 6] > 0, 2, 1)
        tri_power = math.pi * area * mat_power[tmat]
        emissive = np.nonzero(tri_power > 0)[0]
        weights.extend(tri_power[emissive])
        refs.extend(emissive.tolist())
    for i, light in enumerate(desc.point_lights):
        p = 4 * math.pi * float(np.mean(light.intensity))
        if p > 0:
            weights.append(p)
            refs.append(-(i + 1))
    weights = np.asarray(weights, np.float64)
    cdf = np.zeros(len(weights) + 1, np.float64)
    if len(weights):
        cdf[1:] = np.cumsum(weights) / weights.sum()
    light_cdf = cdf.astype(np.float32)
    light_cdf[-1] = 1.0
    light_ref = np.asarray(refs if refs else [0], np.int32)
    tri_light_pdf = np.zeros(max(1, n_tri), np.float32)
    for k, ref in enumerate(refs):
        if ref >= 0:
            pmf = float(light_cdf[k + 1]) - float(light_cdf[k])
            tri_light_pdf[ref] = pmf / area[ref]
    point_lights = np.zeros((max(1, len(desc.point_lights)), 6), np.float32)
    for i, light in enumerate(desc.point_lights):
        point_lights[i, 0:3] = light.position
        point_lights[i, 3:6] = light.intensity

    has_tri_lights = any(r >= 0 for r in refs)
    has_point_lights = any(r < 0 for r in refs)
    smooth = any(smooth_flags)
    tri_n = np.zeros((max(1, n_tri) if smooth else 1, 9), np.float32)
    if smooth and n_tri:
        tri_n[:n_tri] = vn.reshape(n_tri, 9)
    tri_mat_arr = np.zeros(max(1, n_tri), np.int32)
    tri_mat_arr[:n_tri] = tmat

    env = np.zeros(3, np.float32)
    if desc.environment is not None:
        env[:] = desc.environment
    features = Features(tri_lights=has_tri_lights, point_lights=has_point_lights,
                        environment=desc.environment is not None and bool(env.any()),
                        smooth=smooth)
    arrays = SceneArrays(
        cam=_camera_array(desc.camera), tri_v=tri_v, tri_n=tri_n, tri_mat=tri_mat_arr,
        mat=mat, tri_light_pdf=tri_light_pdf, light_cdf=light_cdf, light_ref=light_ref,
        point_lights=point_lights, env=env, bvh_box=bvh.box, bvh_child=bvh.child)
    w, h = desc.camera.resolution
    r = desc.render
    timings = {"mesh_load": t_mesh, "bvh_build": t_bvh,
               "total": time.perf_counter() - t_start}
    return CompiledScene(arrays, features, w, h, r.spp, r.max_bounces, r.rr_depth, r.seed,
                         n_tri, desc, timings, bvh.depth)
