"""Scene compiler: a validated description -> flat float32/int32 arrays + a feature set."""
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..accel import build_bvh
from ..kernels.integrator import Features, SceneArrays
from ..kernels import materials as K
from ..kernels.materials import MAT_DIFFUSE, MAT_PRINCIPLED, MAT_WIDTH, N_SLOTS
from .errors import SceneError
from .images import load_texture, read_image, srgb_to_linear
from .loader import (EnvironmentMap, SceneDescription, TextureSpec, euler_matrix,
                     load_scene_description)
from .meshes import load_obj

# principled number keys -> (material column, texture slot)
NUMBER_COLUMNS = {
    "roughness": (K.M_ROUGHNESS, K.T_ROUGHNESS), "metallic": (K.M_METALLIC, K.T_METALLIC),
    "specular": (K.M_SPECULAR, K.T_SPECULAR), "eta": (K.M_ETA, K.T_ETA),
    "specularTint": (K.M_SPEC_TINT, K.T_SPEC_TINT),
    "anisotropic": (K.M_ANISOTROPIC, K.T_ANISOTROPIC), "sheen": (K.M_SHEEN, K.T_SHEEN),
    "sheenTint": (K.M_SHEEN_TINT, K.T_SHEEN_TINT), "clearcoat": (K.M_CLEARCOAT, K.T_CLEARCOAT),
    "clearcoatGloss": (K.M_CLEARCOAT_GLOSS, K.T_CLEARCOAT_GLOSS),
    "subsurface": (K.M_SUBSURFACE, K.T_SUBSURFACE),
    "transmission": (K.M_TRANSMISSION, K.T_TRANSMISSION),
}
PRINCIPLED_DEFAULTS = {"roughness": 0.5, "metallic": 0.0, "specular": 0.5}


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
    origin_shift: tuple = (0.0, 0.0, 0.0)   # subtracted from all positions (float64)


def load_scene(path, use_cache=True, allow_missing=False):
    """Read, validate and compile the scene file (or thesis scene folder) at ``path``."""
    return compile_scene(load_scene_description(path, allow_missing=allow_missing),
                         use_cache=use_cache)


def _camera_array(cam, shift=np.zeros(3)):
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
    out[0:3] = pos - shift
    out[3:6] = fwd
    out[6:9] = right * tan_x
    out[9:12] = up * tan_y
    if cam.lens_radius > 0:
        out[12] = cam.lens_radius / tan_x
        out[13] = cam.lens_radius / tan_y
        out[14] = cam.focus_distance
    return out


class _Tables:
    """Materials and textures being collected into the kernel's arrays."""

    def __init__(self, scene_file):
        self.rows = []
        self.tex_rows = []
        self.power = []            # mean emitted radiance per material (for light selection)
        self.textures = {}         # key -> index
        self.tex_images = []
        self.tex_params = []
        self.scene_file = scene_file
        self.any_normal_map = False
        self.any_anisotropic = False
        self.any_principled = False

    def texture(self, spec):
        key = (spec.path, spec.color_space, spec.filter, spec.tile, spec.offset, spec.scale)
        if key not in self.textures:
            img = load_texture(spec, self.scene_file)
            self.textures[key] = len(self.tex_images)
            self.tex_images.append(img)
            self.tex_params.append((spec.filter, spec.tile, spec.offset, spec.scale))
        return self.textures[key]

    def add(self, mtype, albedo, emission, two_sided, numbers=None, textures=None,
            normal_map=None):
        row = np.zeros(MAT_WIDTH, np.float32)
        tex = np.full(N_SLOTS, -1, np.int32)
        row[0:3] = albedo
        row[3:6] = emission
        row[K.M_TWO_SIDED] = 1.0 if two_sided else 0.0
        row[K.M_TYPE] = MAT_PRINCIPLED if mtype == "principled" else MAT_DIFFUSE
        textures = textures or {}
        power = float(np.mean(emission))
        if "albedo" in textures:
            tex[K.T_ALBEDO] = self.texture(textures["albedo"])
            row[0:3] = textures["albedo"].scale
        if "emission" in textures:
            t = self.texture(textures["emission"])
            tex[K.T_EMISSION] = t
            row[3:6] = textures["emission"].scale   # non-zero: the material emits
            power = float(np.mean(self.tex_images[t]) * np.mean(textures["emission"].scale))
        if mtype == "principled":
            self.any_principled = True
            nums = dict(PRINCIPLED_DEFAULTS)
            nums.update(numbers or {})
            for k, (col, slot) in NUMBER_COLUMNS.items():
                row[col] = nums.get(k, 0.0)
                if k in textures:
                    tex[slot] = self.texture(textures[k])
            if "eta" not in nums and "eta" not in textures:
                row[K.M_ETA] = 0.0     # derived from specular in the kernel
            if row[K.M_ANISOTROPIC] > 0 or "anisotropic" in textures:
                self.any_anisotropic = True
            if normal_map is not None:
                tex[K.T_NORMAL] = self.texture(normal_map)
                self.any_normal_map = True
        self.rows.append(row)
        self.tex_rows.append(tex)
        self.power.append(power)
        return len(self.rows) - 1

    def arrays(self):
        mat = np.stack(self.rows) if self.rows else np.zeros((1, MAT_WIDTH), np.float32)
        mat_tex = (np.stack(self.tex_rows) if self.tex_rows else
                   np.full((1, N_SLOTS), -1, np.int32))
        if self.tex_images:
            sizes = [im.shape[0] * im.shape[1] for im in self.tex_images]
            tex_data = np.concatenate([im.reshape(-1, 3) for im in self.tex_images])
            tex_int = np.zeros((len(sizes), 4), np.int32)
            tex_f = np.zeros((len(sizes), 7), np.float32)
            offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            if tex_data.shape[0] >= 2 ** 31:
                raise SceneError("textures too large (more than 2^31 texels in all)",
                                 self.scene_file)
            for i, (im, (filt, tile, offset, scale)) in enumerate(zip(self.tex_images,
                                                                       self.tex_params)):
                tex_int[i] = (offs[i], im.shape[1], im.shape[0],
                              1 if filt == "nearest" else 0)
                tex_f[i] = (tile[0], tile[1], offset[0], offset[1], *scale)
        else:
            tex_data = np.zeros((1, 3), np.float32)
            tex_int = np.zeros((1, 4), np.int32)
            tex_f = np.zeros((1, 7), np.float32)
        return mat, mat_tex, tex_data.astype(np.float32), tex_int, tex_f


def _obj_material(tables, mm, obj_dir, scene_file, where):
    """A .mtl material: Kd (+ Ke) only -> diffuse; otherwise principled (Kd -> albedo,
    Ke -> emission, Pr or Ns -> roughness, Pm -> metallic, Ni -> eta, map_Kd -> albedo
    texture, map_Bump / norm -> normal map). Ns maps to GGX alpha = sqrt(2 / (Ns + 2))
    (Walter et al. 2007's Phong-Beckmann match), roughness = sqrt(alpha)."""
    if mm.get("undefined"):
        raise SceneError(f"usemtl {mm['name']!r}: no such material in the .mtl file(s) (or "
                         "give the object a 'material')", scene_file, where)
    specular = any(x > 0 for x in mm["Ks"]) or mm.get("Pr") is not None or \
        mm.get("Pm") is not None
    textures = {}

    def tex(name, cs):
        p = os.path.join(obj_dir, name)
        if not os.path.isfile(p):
            raise SceneError(f"texture {name!r} of OBJ material {mm['name']!r} not found: {p}",
                             scene_file, where)
        return TextureSpec(path=p, color_space=cs, pointer=where)

    if mm.get("map_Kd"):
        textures["albedo"] = tex(mm["map_Kd"], "sRGB")
    normal_map = tex(mm["map_Bump"], "linear") if mm.get("map_Bump") else None
    if not specular and normal_map is None:
        return tables.add("diffuse", tuple(mm["Kd"]), tuple(mm["Ke"]), False,
                          textures=textures)
    numbers = {}
    if mm.get("Pr") is not None:
        numbers["roughness"] = min(max(mm["Pr"], 0.0), 1.0)
    elif mm.get("Ns", 0) > 0:
        numbers["roughness"] = min(1.0, (2.0 / (mm["Ns"] + 2.0)) ** 0.25)
    if mm.get("Pm") is not None:
        numbers["metallic"] = min(max(mm["Pm"], 0.0), 1.0)
    if mm.get("Ni", 1.0) not in (0.0, 1.0):
        numbers["eta"] = mm["Ni"]
    return tables.add("principled", tuple(mm["Kd"]), tuple(mm["Ke"]), False, numbers,
                      textures, normal_map)


def _vertex_tangents(pos, nrm, uv):
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


def _environment_arrays(env, scene_file):
    """Image, sampling distribution and info of an environment map (see kernels.envmap)."""
    img, is_float = read_image(env.path, env.pointer, scene_file)
    if not is_float:
        img = srgb_to_linear(img)
    return environment_distribution(np.maximum(img, 0.0) * env.intensity)


def environment_distribution(img):
    """(image, marginal CDF, conditional CDFs, cell densities) of an equirectangular map,
    or None when it is black everywhere."""
    h, w = img.shape[:2]
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    # mean of the bilinear reconstruction over each cell: [1, 6, 1] / 8 in u (wrapping)
    # and v (clamped), so a cell is never given zero weight where the lookup is not zero
    k = (np.roll(lum, 1, axis=1) + 6 * lum + np.roll(lum, -1, axis=1)) / 8
    up = np.vstack([k[:1], k[:-1]])
    down = np.vstack([k[1:], k[-1:]])
    k = (up + 6 * k + down) / 8
    sin_t = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    wgt = k * sin_t[:, None]
    total = wgt.sum()
    if not total > 0:
        return None
    pdf = wgt * (w * h) / total
    rows = wgt.sum(axis=1)
    marg = np.concatenate([[0.0], np.cumsum(rows) / rows.sum()])
    cond = np.zeros((h, w + 1))
    for j in range(h):
        if rows[j] > 0:
            cond[j, 1:] = np.cumsum(wgt[j]) / rows[j]
        else:
            cond[j, 1:] = np.arange(1, w + 1) / w
    marg = marg.astype(np.float32)
    cond = cond.astype(np.float32)
    marg[-1] = 1.0
    cond[:, -1] = 1.0
    return img.astype(np.float32), marg, cond, pdf.astype(np.float32)


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


def compile_scene(desc, use_cache=True, bvh_options=None):
    """Flat arrays and feature set of a scene description. ``bvh_options`` (benchmarks):
    keyword arguments of ``accel.build_bvh`` (n_bins, max_leaf, split)."""
    t_start = time.perf_counter()
    # ---- Materials: the scene's, then each OBJ's .mtl ones, then the default grey ----
    tables = _Tables(desc.path)
    mat_index = {}
    for name, m in desc.materials.items():
        mat_index[name] = tables.add(m.type, m.albedo, m.emission, m.two_sided, m.numbers,
                                     m.textures, m.normal_map)
    default_mat = None

    def default_material():
        nonlocal default_mat
        if default_mat is None:
            default_mat = tables.add("diffuse", (0.5, 0.5, 0.5), (0.0, 0.0, 0.0), False)
        return default_mat

    # ---- Geometry ----
    positions, normals, tri_mat, smooth_flags, uvs_list, has_uvs = [], [], [], [], [], []
    t_mesh = 0.0
    for obj in desc.objects:
        where = obj.pointer
        if obj.file is not None:
            t0 = time.perf_counter()
            mesh = load_obj(obj.file, use_cache=use_cache)
            t_mesh += time.perf_counter() - t0
            pos = mesh.positions.astype(np.float64)
            file_normals = mesh.normals.astype(np.float64) if mesh.normals is not None else None
            uv = mesh.uvs.astype(np.float64) if mesh.uvs is not None else None
            if obj.material is not None:
                mats = np.full(len(pos), mat_index[obj.material], np.int32)
            else:
                local = np.empty(len(mesh.materials) + 1, np.int32)
                for i, mm in enumerate(mesh.materials):
                    local[i] = _obj_material(tables, mm, os.path.dirname(obj.file), desc.path,
                                             f"{where}/file")
                local[-1] = default_material() if (mesh.face_material < 0).any() else 0
                mats = local[mesh.face_material]
        else:
            pos = obj.vertices[obj.faces]
            file_normals = None
            uv = None
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
            if uv is not None:
                uv = uv[:, [0, 2, 1]]
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
        has_uvs.append(uv is not None)
        uvs_list.append(uv if uv is not None else np.zeros((len(pos), 3, 2)))

    mat, mat_tex, tex_data, tex_int, tex_f = tables.arrays()
    use_textures = len(tables.tex_images) > 0
    use_tangents = any(has_uvs) and (tables.any_normal_map or tables.any_anisotropic)
    tangents, tsign = [], []
    for pos_o, vn_o, uv_o, ok in zip(positions, normals, uvs_list, has_uvs):
        if use_tangents and ok:
            t, sg = _vertex_tangents(pos_o, vn_o, uv_o)
        else:
            t, sg = np.zeros_like(pos_o), np.ones(pos_o.shape[:2])
        tangents.append(t)
        tsign.append(sg)
    if positions:
        pos = np.concatenate(positions)
        vn = np.concatenate(normals)
        tmat = np.concatenate(tri_mat)
        uvs = np.concatenate(uvs_list)
        tan = np.concatenate(tangents)
        tsg = np.concatenate(tsign)
    else:
        pos = np.zeros((0, 3, 3))
        vn = np.zeros((0, 3, 3))
        tmat = np.zeros(0, np.int32)
        uvs = np.zeros((0, 3, 2))
        tan = np.zeros((0, 3, 3))
        tsg = np.zeros((0, 3))
    # Re-centre the scene on its bounding box (in float64) before rounding to float32: a
    # scene far from the origin keeps the precision of one at the origin, so moving a
    # scene does not change its image. Camera and lights move with it.
    shift = np.zeros(3)
    if len(pos):
        shift = 0.5 * (pos.reshape(-1, 3).min(axis=0) + pos.reshape(-1, 3).max(axis=0))
    pos32 = (pos - shift).astype(np.float32)

    # ---- BVH; triangles reordered so each leaf is a contiguous range ----
    t0 = time.perf_counter()
    bvh = build_bvh(pos32, **(bvh_options or {}))
    t_bvh = time.perf_counter() - t0
    pos32 = pos32[bvh.order]
    vn = vn[bvh.order]
    tmat = tmat[bvh.order]
    uvs = uvs[bvh.order]
    tan = tan[bvh.order]
    tsg = tsg[bvh.order]
    n_tri = len(pos32)

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
        mat_power = np.asarray(tables.power, np.float64) * np.where(mat[:, 6] > 0, 2, 1)
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
    # ---- Environment ----
    env = np.zeros(3, np.float32)
    env_img = np.zeros((1, 1, 3), np.float32)
    env_marg = np.array([0.0, 1.0], np.float32)
    env_cond = np.array([[0.0, 1.0]], np.float32)
    env_pdf = np.zeros((1, 1), np.float32)
    env_info = np.array([1.0, 0.0, 0.0, 0.0], np.float32)
    has_env_map = False
    if isinstance(desc.environment, EnvironmentMap):
        got = _environment_arrays(desc.environment, desc.path)
        if got is not None:
            env_img, env_marg, env_cond, env_pdf = got
            has_env_map = True
            phi = math.radians(desc.environment.rotation)
            # Next-event estimation picks the environment with probability 1/2 when there
            # are other lights (Mitsuba picks uniformly among emitters), else always.
            p_env = 0.5 if len(refs) else 1.0
            env_info[:] = (math.cos(phi), math.sin(phi), p_env, 0.0)
    elif desc.environment is not None:
        env[:] = desc.environment

    tri_light_pdf = np.zeros(max(1, n_tri), np.float32)
    p_lights = 1.0 - float(env_info[2]) if has_env_map else 1.0
    for k, ref in enumerate(refs):
        if ref >= 0:
            pmf = (float(light_cdf[k + 1]) - float(light_cdf[k])) * p_lights
            tri_light_pdf[ref] = pmf / area[ref]
    point_lights = np.zeros((max(1, len(desc.point_lights)), 6), np.float32)
    for i, light in enumerate(desc.point_lights):
        point_lights[i, 0:3] = np.asarray(light.position) - shift
        point_lights[i, 3:6] = light.intensity

    has_tri_lights = any(r >= 0 for r in refs)
    has_point_lights = any(r < 0 for r in refs)
    smooth = any(smooth_flags)
    tri_n = np.zeros((max(1, n_tri) if smooth else 1, 9), np.float32)
    if smooth and n_tri:
        tri_n[:n_tri] = vn.reshape(n_tri, 9)
    tri_mat_arr = np.zeros(max(1, n_tri), np.int32)
    tri_mat_arr[:n_tri] = tmat
    tri_uv = np.zeros((max(1, n_tri) if use_textures else 1, 6), np.float32)
    if use_textures and n_tri:
        tri_uv[:n_tri] = uvs.reshape(n_tri, 6)
    tri_t = np.zeros((max(1, n_tri) if use_tangents else 1, 12), np.float32)
    if use_tangents and n_tri:
        tri_t[:n_tri, :9] = tan.reshape(n_tri, 9)
        tri_t[:n_tri, 9:12] = tsg

    features = Features(tri_lights=has_tri_lights, point_lights=has_point_lights,
                        environment=(not has_env_map and desc.environment is not None and
                                     bool(env.any())),
                        smooth=smooth, principled=tables.any_principled,
                        textures=use_textures,
                        normal_map=tables.any_normal_map and use_textures,
                        tangents=use_tangents, env_map=has_env_map,
                        thin_lens=desc.camera.lens_radius > 0)
    arrays = SceneArrays(
        cam=_camera_array(desc.camera, shift), tri_v=tri_v, tri_n=tri_n, tri_mat=tri_mat_arr,
        mat=mat, tri_light_pdf=tri_light_pdf, light_cdf=light_cdf, light_ref=light_ref,
        point_lights=point_lights, env=env, bvh_box=bvh.box, bvh_child=bvh.child,
        tri_uv=tri_uv, tri_t=tri_t, mat_tex=mat_tex, tex_data=tex_data, tex_int=tex_int,
        tex_f=tex_f, env_img=env_img, env_marg=env_marg, env_cond=env_cond, env_pdf=env_pdf,
        env_info=env_info)
    w, h = desc.camera.resolution
    r = desc.render
    timings = {"mesh_load": t_mesh, "bvh_build": t_bvh,
               "total": time.perf_counter() - t_start}
    return CompiledScene(arrays, features, w, h, r.spp, r.max_bounces, r.rr_depth, r.seed,
                         n_tri, desc, timings, bvh.depth, tuple(shift))
