"""Scene compiler: a validated description -> flat float32/int32 arrays + a feature set.

One function per stage, in the order ``compile_scene`` runs them (pbrt-v4's
``CreateMaterials``, ``CreateAggregate``, ``CreateLights``):

1. :func:`compile_materials`: the scene's materials (``mat``, ``mat_tex`` and the texels);
2. :func:`gather_geometry`: every object's triangles in world space, with the OBJ files'
   own materials added to the tables;
3. :func:`compile_triangles`: re-centring, the BVH, and the per-triangle arrays in its leaf
   order;
4. :func:`compile_environment`: the constant colour or the HDRI with its sampling tables
   (built by ``kernels.envmap.environment_tables``, beside the sampler that reads them);
5. :func:`compile_lights`: one power-proportional distribution over emissive triangles and
   point lights, and each emissive triangle's light pdf.

Every column is written by its name in :mod:`pathtracer.kernels.layout`.
"""
import math
import os
import time
import dataclasses
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .. import limits
from ..accel import build_bvh
from ..kernels.envmap import environment_tables
from ..kernels.layout import (CAM_CONE, CAM_FOCUS, CAM_FORWARD, CAM_LENS_X, CAM_LENS_Y, CAM_ORIGIN,
                              CAM_RIGHT,
                              CAM_SIZE, CAM_UP, ENV_INFO_SIZE, ENV_P_SELECT, ENV_ROT,
                              ENV_TEXEL_WIDTH,
                              FILTER_BILINEAR, FILTER_NEAREST, FILTER_TRILINEAR,
                              LT_LINK_WIDTH, LT_WIDTH,
                              ALPHA_BLEND, ALPHA_MASK, ALPHA_OPAQUE, ALPHA_THIN, M_ALPHA, M_ALPHA_CUTOFF,
                              M_ALPHA_MODE, T_ALPHA,
                              M_ALBEDO, M_ANISOTROPIC, M_EMISSION, M_ETA, M_ONE_SIDED,
                              M_TWO_SIDED, M_TYPE, COND_BECKMANN, COND_GGX,
                              M_COND_ALPHA_U, M_COND_ALPHA_V, M_COND_DISTRIBUTION, M_COND_ETA,
                              M_COND_K, MAT_CONDUCTOR, T_COND_ALPHA_U, T_COND_ALPHA_V,
                              MAT_DIFFUSE, MAT_PRINCIPLED, MAT_WIDTH, MATERIAL_PARAMS, N_SLOTS,
                              NO_TEXTURE, PL_AXIS, PL_CONE_OFFSET, PL_CONE_SCALE, PL_INTENSITY,
                              PL_POSITION, PL_WIDTH, T_ALBEDO, T_EMISSION,
                              T_NORMAL, TEX_F_WIDTH, TEX_FILTER, TEX_WRAP, WRAP_CLAMP, WRAP_MIRROR,
                              WRAP_REPEAT, TEX_FIRST, TEX_HEIGHT, TEX_INT_WIDTH, TEX_LEVELS,
                              TEXEL_WIDTH,
                              TEX_OFFSET, TEX_SCALE, TEX_TILE, TEX_WIDTH, TRI_E1, TRI_E2,
                              TRI_COL_WIDTH, TRI_N_WIDTH, TRI_T0, TRI_T_SIGN, TRI_T_WIDTH,
                              TRI_UV_WIDTH, TRI_V0,
                              TRI_V_WIDTH, Features, SceneArrays, point_light_ref)
from ..kernels import layout as L
from ..accel.light_tree import LightBounds, build_light_tree
from .errors import SceneError
from .geometry import safe_normalize, vertex_normals, vertex_tangents
from .images import (load_texture, mip_chain, mip_levels, mip_texels, read_image,
                     srgb_to_linear)
from .loader import (EnvironmentMap, SceneDescription, TextureSpec, euler_matrix,
                     load_scene_description, scene_material)
from .meshes import load_mesh
from ..memory import TRIANGLE_BYTES, require

PRINCIPLED_NUMBERS = [p for p in MATERIAL_PARAMS if p.kind == "number"]
DEFAULT_GREY = (0.5, 0.5, 0.5)   # objects without a material


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
    warnings: list = field(default_factory=list)


def for_spp(scene, spp):
    """``scene`` with its ray cones set for a render of ``spp`` samples per pixel (see
    cone_spread): the scene itself when nothing changes (no trilinear texture, or its own
    spp), else a copy with a new camera row."""
    if not scene.features.mipmaps or spp is None or int(spp) == scene.spp:
        return scene
    cam = scene.arrays.cam.copy()
    cam[CAM_CONE] *= _narrowing(spp) / _narrowing(scene.spp)
    return dataclasses.replace(scene, arrays=scene.arrays._replace(cam=cam))


class CompileMemo:
    """What a re-compile of the same scene can take from the last one (the Python API's
    ``Scene.set``): decoded meshes, textures and environment tables by file (path, size,
    modification time), objects in world space by their transform, and the triangles with
    their BVH while the geometry is unchanged. Entries the last compile did not use are
    dropped, so a sweep over transforms does not accumulate copies."""

    def __init__(self):
        self.entries = {}
        self.used = set()

    def get(self, key, make):
        self.used.add(key)
        if key not in self.entries:
            self.entries[key] = make()
        return self.entries[key]

    def start(self):
        self.used = set()

    def prune(self):
        self.entries = {k: v for k, v in self.entries.items() if k in self.used}


def file_key(path):
    """A file's identity for CompileMemo: path, size and modification time (a file changed
    on disk is read again)."""
    if path is None:
        return (None,)
    try:
        st = os.stat(path)
        return (path, st.st_size, st.st_mtime_ns)
    except OSError:
        return (path, None, None)     # reading it reports the error


def load_scene(path, use_cache=True, allow_missing=False):
    """Read, validate and compile the scene file (or thesis scene folder) at ``path``."""
    return compile_scene(load_scene_description(path, allow_missing=allow_missing),
                         use_cache=use_cache)


def compile_scene(desc, use_cache=True, bvh_options=None, memo=None):
    """Flat arrays and feature set of a scene description. ``bvh_options`` (benchmarks):
    keyword arguments of ``accel.build_bvh`` (n_bins, max_leaf, split). ``memo`` (a
    :class:`CompileMemo`): reuse what an earlier compile of the same scene read and built;
    ``timings['bvh']`` then says whether the BVH was 'built' or 'reused'."""
    t_start = time.perf_counter()
    if memo is not None:
        memo.start()
    tables, mat_index = compile_materials(desc, memo)
    objects, t_mesh = gather_geometry(desc, tables, mat_index, use_cache, memo)
    mat, mat_tex, tex_data, tex_int, tex_f = tables.arrays()
    use_textures = len(tables.tex_images) > 0
    _check_uvs(desc, objects, tables)
    use_tangents = any(o.uv is not None for o in objects) and (
        tables.any_normal_map or tables.any_anisotropic)
    bvh_state = "built"
    if memo is None:
        tri = compile_triangles(objects, use_textures, use_tangents, bvh_options)
    else:
        tri, bvh_state = _memo_triangles(memo, objects, use_textures, use_tangents,
                                         bvh_options)
    lights = compile_lights(desc, tri, mat, tables.power, tri.shift)
    env = compile_environment(desc, has_lights=len(lights.light_ref_list) > 0, memo=memo)
    tree = None
    if use_light_tree(desc.render.light_sampler, len(lights.light_ref_list),
                      lights.has_point_lights):
        tree = build_light_tree(lights.bounds)
    tri_light_pdf = triangle_light_pdfs(lights, tri, env.p_lights, tree is not None)
    lt_node, lt_link, tri_light_leaf = light_tree_arrays(tree, lights, tri)
    features = Features(
        tri_lights=lights.has_tri_lights, point_lights=lights.has_point_lights,
        environment=env.constant, smooth=tri.smooth, principled=tables.any_principled,
        textures=use_textures, normal_map=tables.any_normal_map and use_textures,
        tangents=use_tangents, env_map=env.has_map, thin_lens=desc.camera.lens_radius > 0,
        sobol=desc.render.sampler == "sobol",
        wrap_modes=use_textures and any(p[4] != ("repeat", "repeat") for p in tables.tex_params),
        mipmaps=use_textures and any(p[0] == "trilinear" for p in tables.tex_params),
        light_tree=tree is not None, hide_emitters=desc.render.hide_emitters,
        vertex_colors=tri.has_colors, one_sided=bool((mat[:, M_ONE_SIDED] > 0).any()),
        alpha=bool((mat[:, M_ALPHA_MODE] != ALPHA_OPAQUE).any()),
        conductor=tables.any_conductor, **principled_lobes(mat, mat_tex))
    cam = camera_array(desc.camera, tri.shift, desc.render.spp)
    if not (np.isfinite(cam).all() and np.abs(cam).max() <= limits.FLOAT32_MAX):
        raise SceneError("the camera's numbers overflow float32 (position, fov, aperture or "
                         "focus distance)", desc.path, "/camera")
    arrays = SceneArrays(
        cam=cam, tri_v=tri.tri_v, tri_n=tri.tri_n,
        tri_mat=tri.tri_mat, mat=mat, tri_light_pdf=tri_light_pdf,
        light_cdf=lights.light_cdf, light_ref=lights.light_ref,
        point_lights=lights.point_lights, env=env.color, bvh_box=tri.bvh.box,
        bvh_child=tri.bvh.child, tri_uv=tri.tri_uv, tri_t=tri.tri_t, mat_tex=mat_tex,
        tex_data=tex_data, tex_int=tex_int, tex_f=tex_f, env_img=env.img, env_marg=env.marg,
        env_cond=env.cond, env_guide=env.guide, env_info=env.info, lt_node=lt_node,
        lt_link=lt_link, tri_light_leaf=tri_light_leaf, tri_col=tri.tri_col)
    w, h = desc.camera.resolution
    r = desc.render
    timings = {"mesh_load": t_mesh,
               "bvh_build": tri.bvh_seconds if bvh_state == "built" else 0.0,
               "bvh": bvh_state, "total": time.perf_counter() - t_start}
    if memo is not None:
        memo.prune()
    return CompiledScene(arrays, features, w, h, r.spp, r.max_bounces, r.rr_depth, r.seed,
                         tri.n, desc, timings, tri.bvh.depth, tuple(tri.shift))


# ---------------------------------------------------------------------------------------
# Camera

def cone_spread(pixel_angle, spp):
    """A ray cone's spread per unit distance (layout CAM_CONE): the angle of a pixel
    narrowed by max(1/8, 1/sqrt(spp)), pbrt-v4's scale of camera ray differentials
    (Pharr, Jakob, Humphreys 2023, sec. 5.2.5): the samples of a pixel already average
    over it, so a texture footprint of the whole pixel would blur twice; the more samples,
    the less of the footprint is left to the texture filter."""
    return pixel_angle * _narrowing(spp)


def _narrowing(spp):
    return max(0.125, 1.0 / math.sqrt(max(int(spp), 1)))


def camera_array(cam, shift=np.zeros(3), spp=1):
    """The kernel's camera row (layout CAM_*) of a Camera, positions moved by -shift; the
    ray cone's spread is that of a render of ``spp`` samples per pixel."""
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
    out = np.zeros(CAM_SIZE, np.float32)
    out[CAM_ORIGIN:CAM_ORIGIN + 3] = pos - shift
    out[CAM_FORWARD:CAM_FORWARD + 3] = fwd
    out[CAM_RIGHT:CAM_RIGHT + 3] = right * tan_x
    out[CAM_UP:CAM_UP + 3] = up * tan_y
    if cam.lens_radius > 0:
        out[CAM_LENS_X] = cam.lens_radius / tan_x
        out[CAM_LENS_Y] = cam.lens_radius / tan_y
        out[CAM_FOCUS] = cam.focus_distance
    out[CAM_CONE] = cone_spread(2 * tan_y / h, spp)     # a pixel's angle at the centre
    return out


# ---------------------------------------------------------------------------------------
# Stage 1: materials and textures

# Features flag: (material column, texture slot) of the principled parameter it follows
LOBE_PARAMS = {"clearcoat": (L.M_CLEARCOAT, L.T_CLEARCOAT), "sheen": (L.M_SHEEN, L.T_SHEEN),
               "transmission": (L.M_TRANSMISSION, L.T_TRANSMISSION),
               "flatness": (L.M_SUBSURFACE, L.T_SUBSURFACE),
               "spec_tint": (L.M_SPEC_TINT, L.T_SPEC_TINT),
               "anisotropic": (L.M_ANISOTROPIC, L.T_ANISOTROPIC)}


def principled_lobes(mat, mat_tex):
    """The Features flags of the principled BSDF's optional parts: whether some principled
    material sets the parameter above 0 or reads it from a texture (the kernel clamps it to
    [0, 1], so a value of 0 or below turns the part off); ``dielectric``: whether one has
    metallic below 1 (or textured)."""
    principled = mat[:, M_TYPE] == MAT_PRINCIPLED
    flags = {"dielectric": bool(np.any(principled & (
        (mat[:, L.M_METALLIC] < 1) | (mat_tex[:, L.T_METALLIC] != NO_TEXTURE))))}
    flags.update({name: bool(np.any(principled & (
        (mat[:, col] > 0) | (mat_tex[:, slot] != NO_TEXTURE)))) for name, (col, slot)
        in LOBE_PARAMS.items()})
    return flags


class MaterialTables:
    """Materials and textures being collected into the kernel's arrays."""

    def __init__(self, scene_file, memo=None):
        self.memo = memo
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
        self.any_conductor = False
        self._default = None

    def texture(self, spec, slot=None):
        """The index of the texture of ``spec`` (loaded once); ``slot``: the parameter it
        feeds ('normalMap' allows negative texels; 'emission' and 'albedo' bound the
        texel x scale products, see limits)."""
        key = (spec.path, spec.color_space, spec.filter, spec.tile, spec.offset, spec.scale,
               spec.channel, spec.wrap)
        if key not in self.textures:
            def load():
                return load_texture(spec, self.scene_file, allow_negative=slot == "normalMap")
            img = load() if self.memo is None else self.memo.get(
                ("texture", file_key(spec.path)) + key[1:] + (slot == "normalMap",), load)
            top = float(np.abs(img).max(initial=0)) * max(spec.scale)
            bound = {"emission": limits.MAX_RADIANCE, "albedo": limits.MAX_REFLECTANCE}.get(
                slot, limits.MAX_RADIANCE)
            if top > bound:
                raise SceneError(f"texture {spec.path}: its largest value x scale = {top:g} "
                                 f"exceeds {bound:g} (the bound of {slot or 'this value'})",
                                 self.scene_file, spec.pointer)
            self.textures[key] = len(self.tex_images)
            self.tex_images.append(img)
            self.tex_params.append((spec.filter, spec.tile, spec.offset, spec.scale,
                                    spec.wrap))
        return self.textures[key]

    def default_material(self):
        """The grey diffuse material of objects that name none (added once, when needed)."""
        if self._default is None:
            self._default = self.add("diffuse", DEFAULT_GREY, (0.0, 0.0, 0.0), False)
        return self._default

    def add(self, mtype, albedo, emission, two_sided, numbers=None, textures=None,
            normal_map=None, one_sided=False, alpha=(1.0, "opaque", 0.5)):
        """A material's row (``alpha``: opacity, mode and cutoff, loader.Material's)."""
        row = np.zeros(MAT_WIDTH, np.float32)
        row[M_ONE_SIDED] = 1.0 if one_sided else 0.0
        tex = np.full(N_SLOTS, NO_TEXTURE, np.int32)
        textures = textures or {}
        opacity, mode, cutoff = alpha
        row[M_ALPHA] = opacity
        row[M_ALPHA_MODE] = {"opaque": ALPHA_OPAQUE, "mask": ALPHA_MASK,
                             "blend": ALPHA_BLEND, "thin": ALPHA_THIN}[mode]
        row[M_ALPHA_CUTOFF] = cutoff
        if mode != "opaque" and "alpha" in textures:
            tex[T_ALPHA] = self.texture(textures["alpha"], "alpha")
        row[M_ALBEDO:M_ALBEDO + 3] = albedo
        row[M_EMISSION:M_EMISSION + 3] = emission
        row[M_TWO_SIDED] = 1.0 if two_sided else 0.0
        row[M_TYPE] = {"principled": MAT_PRINCIPLED, "conductor": MAT_CONDUCTOR,
                       "thindielectric": MAT_CONDUCTOR}.get(mtype, MAT_DIFFUSE)
        power = float(np.mean(emission))
        if "albedo" in textures:
            tex[T_ALBEDO] = self.texture(textures["albedo"], "albedo")
            row[M_ALBEDO:M_ALBEDO + 3] = textures["albedo"].scale
        if "emission" in textures:
            t = self.texture(textures["emission"], "emission")
            tex[T_EMISSION] = t
            row[M_EMISSION:M_EMISSION + 3] = textures["emission"].scale   # non-zero: emits
            power = float(np.mean(self.tex_images[t]) * np.mean(textures["emission"].scale))
        if mtype == "conductor":
            self._conductor(row, tex, numbers or {}, textures)
        if mtype == "thindielectric":
            # where a ray does not pass the pane, a perfect mirror (white: the pane's
            # reflectance is the probability of meeting it)
            row[M_ALBEDO:M_ALBEDO + 3] = 1.0
            self._conductor(row, tex, {}, {})
        if normal_map is not None:
            tex[T_NORMAL] = self.texture(normal_map, "normalMap")
            self.any_normal_map = True
        if mtype == "principled":
            self.any_principled = True
            numbers = numbers or {}
            for prm in PRINCIPLED_NUMBERS:
                default = prm.default if prm.default is not None else 0.0
                row[prm.column] = numbers.get(prm.key, default)
                if prm.key in textures:
                    tex[prm.slot] = self.texture(textures[prm.key], prm.key)
            if "eta" not in numbers and "eta" not in textures:
                row[M_ETA] = 0.0     # derived from specular in the kernel
            if row[M_ANISOTROPIC] > 0 or "anisotropic" in textures:
                self.any_anisotropic = True
        self.rows.append(row)
        self.tex_rows.append(tex)
        self.power.append(power)
        return len(self.rows) - 1

    def _conductor(self, row, tex, numbers, textures):
        """A conductor's columns (layout M_COND_*): tint in the albedo columns, alphas,
        eta and k (defaults: a perfect mirror, Mitsuba's material 'none')."""
        self.any_conductor = True
        row[M_COND_ALPHA_U] = numbers.get("alphaU", 0.0)
        row[M_COND_ALPHA_V] = numbers.get("alphaV", row[M_COND_ALPHA_U])
        row[M_COND_ETA:M_COND_ETA + 3] = numbers.get("eta", (0.0, 0.0, 0.0))
        row[M_COND_K:M_COND_K + 3] = numbers.get("k", (1.0, 1.0, 1.0))
        row[M_COND_DISTRIBUTION] = (COND_BECKMANN if numbers.get("distribution") == "beckmann"
                                    else COND_GGX)
        for key, slot in (("alphaU", T_COND_ALPHA_U), ("alphaV", T_COND_ALPHA_V)):
            if key in textures:
                tex[slot] = self.texture(textures[key], key)
        if row[M_COND_ALPHA_U] != row[M_COND_ALPHA_V] or "alphaU" in textures or \
                "alphaV" in textures:
            self.any_anisotropic = True     # tangents from texture coordinates

    def arrays(self):
        """mat, mat_tex, tex_data, tex_int, tex_f (layout: materials and textures)."""
        mat = np.stack(self.rows) if self.rows else np.zeros((1, MAT_WIDTH), np.float32)
        mat_tex = (np.stack(self.tex_rows) if self.tex_rows else
                   np.full((1, N_SLOTS), NO_TEXTURE, np.int32))
        if not self.tex_images:
            return (mat, mat_tex, np.zeros((1, TEXEL_WIDTH), np.float32),
                    np.zeros((1, TEX_INT_WIDTH), np.int32), np.zeros((1, TEX_F_WIDTH), np.float32))
        mipmapped = [p[0] == "trilinear" for p in self.tex_params]
        levels = [mip_levels(*im.shape[:2]) if mip else 1
                  for im, mip in zip(self.tex_images, mipmapped)]
        sizes = [mip_texels(*im.shape[:2], n) for im, n in zip(self.tex_images, levels)]

        def texels():
            # one allocation; each mip level written in place from the one before. A texel
            # is a row of TEXEL_WIDTH floats (rgb and a zero): one 16-byte load reads it
            out = np.zeros((sum(sizes), TEXEL_WIDTH), np.float32)
            at = 0
            for im, mip in zip(self.tex_images, mipmapped):
                for level in (mip_chain(im) if mip else [im]):
                    out[at:at + level.shape[0] * level.shape[1], :3] = level.reshape(-1, 3)
                    at += level.shape[0] * level.shape[1]
            return out
        if sum(sizes) >= 2 ** 31:     # (checked before the texel array is allocated)
            raise SceneError("textures too large (more than 2^31 texels in all, mip levels "
                             "included)", self.scene_file)
        # a re-compile with the same textures keeps the same array (the GPU keeps its copy)
        tex_data = texels() if self.memo is None else self.memo.get(
            ("texels",) + tuple(id(im) for im in self.tex_images) + tuple(mipmapped), texels)
        tex_int = np.zeros((len(sizes), TEX_INT_WIDTH), np.int32)
        tex_f = np.zeros((len(sizes), TEX_F_WIDTH), np.float32)
        offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        wraps = {"repeat": WRAP_REPEAT, "clamp": WRAP_CLAMP, "mirror": WRAP_MIRROR}
        filters = {"nearest": FILTER_NEAREST, "bilinear": FILTER_BILINEAR,
                   "trilinear": FILTER_TRILINEAR}
        for i, (im, (filt, tile, offset, scale, wrap)) in enumerate(zip(self.tex_images,
                                                                         self.tex_params)):
            tex_int[i, TEX_WRAP] = wraps[wrap[0]] | (wraps[wrap[1]] << 2)
            tex_int[i, TEX_FIRST] = offs[i]
            tex_int[i, TEX_WIDTH] = im.shape[1]
            tex_int[i, TEX_HEIGHT] = im.shape[0]
            tex_int[i, TEX_FILTER] = filters[filt]
            tex_int[i, TEX_LEVELS] = levels[i]
            tex_f[i, TEX_TILE:TEX_TILE + 2] = tile
            tex_f[i, TEX_OFFSET:TEX_OFFSET + 2] = offset
            tex_f[i, TEX_SCALE:TEX_SCALE + 3] = scale
        if tex_data.dtype != np.float32 or not tex_data.flags.c_contiguous:
            tex_data = np.ascontiguousarray(tex_data, np.float32)
        return mat, mat_tex, tex_data, tex_int, tex_f


def compile_materials(desc, memo=None):
    """The scene's own materials: the tables, and each material's row by name."""
    tables = MaterialTables(desc.path, memo)
    mat_index = {}
    for name, m in desc.materials.items():
        mat_index[name] = tables.add(m.type, m.albedo, m.emission, m.two_sided, m.numbers,
                                     m.textures, m.normal_map, m.one_sided,
                                     (m.alpha, m.alpha_mode, m.alpha_cutoff))
    return tables, mat_index


def obj_material(tables, mm, obj_dir, scene_file, where):
    """A .mtl material: Kd (+ Ke) only -> diffuse; otherwise principled (Kd -> albedo,
    Ke -> emission, Pr or Ns -> roughness, Pm -> metallic, Ni -> eta, map_Kd -> albedo
    texture, map_Bump / norm -> normal map). Ns maps to GGX alpha = sqrt(2 / (Ns + 2))
    (Walter et al. 2007's Phong-Beckmann match), roughness = sqrt(alpha)."""
    if mm.get("undefined"):
        raise SceneError(f"usemtl {mm['name']!r}: no such material in the .mtl file(s) (or "
                         "give the object a 'material')", scene_file, where)
    _check_mtl(mm, scene_file, where)
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


def _check_uvs(desc, objects, tables):
    """A textured material (a normal map included) on a mesh without texture coordinates
    would look up one texel everywhere: an error rather than a silently wrong image."""
    slot_names = {p.slot: p.key for p in MATERIAL_PARAMS}
    slot_names[T_NORMAL] = "normalMap"
    slot_names[T_ALPHA] = "alpha"
    for obj, geo in zip(desc.objects, objects):
        if geo.uv is not None or not len(geo.materials):
            continue
        for row in np.unique(geo.materials):
            names = dict(slot_names)
            if tables.rows[row][M_TYPE] == MAT_CONDUCTOR:
                names.update({T_COND_ALPHA_U: "alphaU", T_COND_ALPHA_V: "alphaV"})
            used = [names.get(k, str(k)) for k in np.nonzero(
                tables.tex_rows[row] != NO_TEXTURE)[0]]
            if used:
                what = "its OBJ file has no 'vt' lines" if obj.file else \
                    "inline meshes have none"
                raise SceneError(f"a material with textures ({', '.join(used)}) is used on an "
                                 f"object without texture coordinates ({what}): give the mesh "
                                 "UVs or use a material without textures", desc.path,
                                 obj.pointer)


# The ranges of .mtl values (as the scene's own: see limits and the parameter table).
MTL_RANGES = {"Kd": (0.0, limits.MAX_REFLECTANCE), "Ks": (0.0, limits.MAX_REFLECTANCE),
              "Ke": (0.0, limits.MAX_RADIANCE), "Ns": (0.0, limits.FLOAT32_MAX),
              "Ni": (0.0, limits.FLOAT32_MAX), "Pr": (0.0, 1.0), "Pm": (0.0, 1.0)}


def _check_mtl(mm, scene_file, where):
    """Every number of a .mtl material finite and in range (pywavefront reads 'nan' and
    negative values as given)."""
    for key, (lo, hi) in MTL_RANGES.items():
        v = mm.get(key)
        if v is None:
            continue
        for x in (v if isinstance(v, (list, tuple)) else [v]):
            if not (isinstance(x, (int, float)) and math.isfinite(x) and lo <= x <= hi):
                raise SceneError(f".mtl material {mm['name']!r}: {key} must be within "
                                 f"[{lo:g}, {hi:g}], got {x}", scene_file, where)


# ---------------------------------------------------------------------------------------
# Stage 2: every object's triangles in world space

class ObjectGeometry(NamedTuple):
    positions: np.ndarray        # float64 (F, 3, 3), world space
    normals: np.ndarray          # float64 (F, 3, 3) unit vertex normals (face normals if flat)
    uv: object                   # float64 (F, 3, 2), or None
    materials: np.ndarray        # int32 (F,) material rows
    smooth: bool
    colors: object = None        # float64 (F, 3, 3) vertex colours (glTF COLOR_0), or None


def gather_geometry(desc, tables, mat_index, use_cache=True, memo=None):
    """([ObjectGeometry], seconds spent reading mesh files)."""
    objects = []
    t_mesh = 0.0
    for obj in desc.objects:
        pos, file_normals, uv, mats, colors, seconds = _object_triangles(
            obj, desc, tables, mat_index, use_cache, memo)
        t_mesh += seconds
        if memo is None:
            objects.append(_to_world(obj, desc, pos, file_normals, uv, mats, colors))
            continue
        # the same mesh under the same transform: the same world-space arrays (the
        # materials, cheap, are always taken anew)
        key = ("world", id(pos), obj.matrix.tobytes(), bool(obj.smooth))
        if obj.file is None:
            key += (obj.vertices.tobytes(), obj.faces.tobytes(),
                    None if obj.uvs is None else obj.uvs.tobytes())
        geo = memo.get(key, lambda: _to_world(obj, desc, pos, file_normals, uv, mats, colors))
        objects.append(geo._replace(materials=mats))
    return objects, t_mesh


def _memo_triangles(memo, objects, use_textures, use_tangents, bvh_options):
    """compile_triangles, or its last result when every object's world-space arrays are
    the same ones and so are the per-face materials: (Triangles, 'built' or 'reused')."""
    key = ("triangles", tuple((id(o.positions), id(o.normals), id(o.uv), id(o.colors),
                               o.smooth) for o in objects), use_textures, use_tangents,
           repr(sorted((bvh_options or {}).items())))
    mats = [o.materials for o in objects]
    got = memo.entries.get(key)
    if got is not None and len(got[1]) == len(mats) and all(
            np.array_equal(a, b) for a, b in zip(got[1], mats)):
        memo.used.add(key)
        return got[0], "reused"
    tri = compile_triangles(objects, use_textures, use_tangents, bvh_options)
    memo.entries[key] = (tri, mats, objects)   # (the objects keep the ids valid)
    memo.used.add(key)
    return tri, "built"


def _object_triangles(obj, desc, tables, mat_index, use_cache, memo=None):
    """Triangles of one object in its own space, with per-face material rows, and the
    seconds spent reading its mesh file."""
    where = obj.pointer
    if obj.file is None:
        pos = obj.vertices[obj.faces]
        if memo is not None:     # the same array object for the same inline mesh
            pos = memo.get(("inline", obj.vertices.tobytes(), obj.faces.tobytes()),
                           lambda: pos)
        mats = np.full(len(pos), mat_index[obj.material] if obj.material is not None
                       else tables.default_material(), np.int32)
        uv = obj.uvs[obj.faces] if obj.uvs is not None else None
        return pos, None, uv, mats, None, 0.0
    t0 = time.perf_counter()

    def read():
        try:
            mesh = load_mesh(obj.file, use_cache=use_cache, shape_index=obj.shape_index)
        except SceneError as e:
            if e.pointer or e.file != obj.file:
                raise
            # the scene's key too, not only the mesh file
            raise SceneError(f"{obj.file}: {e.message}", desc.path, f"{where}/file") from None
        return (mesh, mesh.positions.astype(np.float64),
                mesh.normals.astype(np.float64) if mesh.normals is not None else None,
                mesh.uvs.astype(np.float64) if mesh.uvs is not None else None)
    mesh, pos, file_normals, uv = read() if memo is None else memo.get(
        ("mesh", file_key(obj.file), obj.shape_index, use_cache), read)
    seconds = time.perf_counter() - t0
    if obj.material is not None:
        mats = np.full(len(pos), mat_index[obj.material], np.int32)
    else:
        local = np.empty(len(mesh.materials) + 1, np.int32)
        for i, mm in enumerate(mesh.materials):
            if mesh.material_format == "scene":      # glTF: scene-format materials
                m = scene_material(mm, obj.file)
                local[i] = tables.add(m.type, m.albedo, m.emission, m.two_sided, m.numbers,
                                      m.textures, m.normal_map, m.one_sided,
                                      (m.alpha, m.alpha_mode, m.alpha_cutoff))
            else:
                local[i] = obj_material(tables, mm, os.path.dirname(obj.file), desc.path,
                                        f"{where}/file")
        local[-1] = tables.default_material() if (mesh.face_material < 0).any() else 0
        mats = local[mesh.face_material]
    colors = getattr(mesh, "colors", None)
    if colors is not None and obj.material is not None:
        colors = None        # the object's own material replaces the file's (and its colours)
    return pos, file_normals, uv, mats, colors, seconds


def _to_world(obj, desc, pos, file_normals, uv, mats, colors=None):
    """Transform: positions by M, normals by the inverse transpose; a mirroring transform
    swaps two vertices so that the front side (counter-clockwise) stays the front."""
    where = obj.pointer
    if not np.isfinite(pos).all():
        raise SceneError("vertex coordinates contain NaN or infinity", desc.path,
                         f"{where}/{'file' if obj.file else 'vertices'}")
    m3, t = obj.matrix[:3, :3], obj.matrix[:3, 3]
    pos = pos @ m3.T + t
    if np.linalg.det(m3) < 0:
        pos = pos[:, [0, 2, 1]]
        if file_normals is not None:
            file_normals = file_normals[:, [0, 2, 1]]
        if uv is not None:
            uv = uv[:, [0, 2, 1]]
        if colors is not None:
            colors = colors[:, [0, 2, 1]]
    if not np.isfinite(pos).all() or np.abs(pos).max(initial=0) > limits.MAX_COORDINATE:
        raise SceneError(f"transformed vertex coordinates overflow (|x| <= "
                         f"{limits.MAX_COORDINATE:g})", desc.path, where)
    if uv is not None and not (np.isfinite(uv).all() and
                               np.abs(uv).max(initial=0) <= limits.FLOAT32_MAX):
        raise SceneError("texture coordinates contain NaN, infinite or float32-overflowing "
                         "values", desc.path, f"{where}/file")
    face_n = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
    face_n = safe_normalize(face_n, np.array([0.0, 0.0, 1.0]))
    if obj.smooth:
        vn = file_normals @ np.linalg.inv(m3) if file_normals is not None else \
            vertex_normals(pos)
        vn = safe_normalize(vn, face_n[:, None, :])
    else:
        vn = np.repeat(face_n[:, None, :], 3, axis=1)
    return ObjectGeometry(pos, vn, uv, mats, bool(obj.smooth),
                          None if colors is None else np.asarray(colors, np.float64))


# ---------------------------------------------------------------------------------------
# Stage 3: triangles, BVH, per-triangle arrays

class Triangles(NamedTuple):
    tri_v: np.ndarray
    tri_n: np.ndarray
    tri_uv: np.ndarray
    tri_t: np.ndarray
    tri_mat: np.ndarray
    bvh: object
    bvh_seconds: float
    shift: np.ndarray      # float64 (3,): subtracted from every position
    area: np.ndarray       # float64 (n,)
    n: int
    smooth: bool
    tri_col: np.ndarray = None   # float32 (n or 1, TRI_COL_WIDTH): vertex colours
    has_colors: bool = False


def compile_triangles(objects, use_textures, use_tangents, bvh_options=None):
    """All objects' triangles in BVH leaf order, in the kernel's per-triangle arrays (those
    a scene does not use hold one dummy row)."""
    tangents, tsign = [], []
    for o in objects:
        if use_tangents and o.uv is not None:
            t, sg = vertex_tangents(o.positions, o.normals, o.uv)
        else:
            t, sg = np.zeros_like(o.positions), np.ones(o.positions.shape[:2])
        tangents.append(t)
        tsign.append(sg)

    def cat(parts, empty_shape, dtype=np.float64):
        return np.concatenate(parts) if parts else np.zeros(empty_shape, dtype)

    pos = cat([o.positions for o in objects], (0, 3, 3))
    vn = cat([o.normals for o in objects], (0, 3, 3))
    tmat = cat([o.materials for o in objects], 0, np.int32)
    uvs = cat([o.uv if o.uv is not None else np.zeros((len(o.positions), 3, 2))
               for o in objects], (0, 3, 2))
    tan = cat(tangents, (0, 3, 3))
    tsg = cat(tsign, (0, 3))
    has_colors = any(o.colors is not None for o in objects)
    cols = cat([o.colors if o.colors is not None else np.ones((len(o.positions), 3, 3))
                for o in objects], (0, 3, 3)) if has_colors else np.ones((len(pos), 0))
    smooth = any(o.smooth for o in objects)
    # Re-centre the scene on its bounding box (in float64) before rounding to float32: a
    # scene far from the origin keeps the precision of one at the origin, so moving a
    # scene does not change its image. Camera and lights move with it.
    shift = np.zeros(3)
    if len(pos):
        shift = 0.5 * (pos.reshape(-1, 3).min(axis=0) + pos.reshape(-1, 3).max(axis=0))
    require(len(pos) * TRIANGLE_BYTES, f"{len(pos)} triangles",
            "use fewer or simpler meshes", error=SceneError)
    pos32 = (pos - shift).astype(np.float32)

    # BVH; triangles reordered so each leaf is a contiguous range
    t0 = time.perf_counter()
    bvh = build_bvh(pos32, **(bvh_options or {}))
    t_bvh = time.perf_counter() - t0
    pos32, vn, tmat, uvs, tan, tsg, cols = (a[bvh.order] for a in (pos32, vn, tmat, uvs, tan,
                                                                   tsg, cols))
    n_tri = len(pos32)
    rows = max(1, n_tri)

    tri_v = np.zeros((rows, TRI_V_WIDTH), np.float32)
    tri_v[:n_tri, TRI_V0:TRI_V0 + 3] = pos32[:, 0]
    tri_v[:n_tri, TRI_E1:TRI_E1 + 3] = pos32[:, 1] - pos32[:, 0]
    tri_v[:n_tri, TRI_E2:TRI_E2 + 3] = pos32[:, 2] - pos32[:, 0]
    area = np.zeros(n_tri)
    if n_tri:
        e1 = tri_v[:n_tri, TRI_E1:TRI_E1 + 3].astype(np.float64)
        e2 = tri_v[:n_tri, TRI_E2:TRI_E2 + 3].astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    tri_n = np.zeros((rows if smooth else 1, TRI_N_WIDTH), np.float32)
    if smooth:
        tri_n[:n_tri] = vn.reshape(n_tri, TRI_N_WIDTH)
    tri_mat = np.zeros(rows, np.int32)
    tri_mat[:n_tri] = tmat
    tri_uv = np.zeros((rows if use_textures else 1, TRI_UV_WIDTH), np.float32)
    if use_textures:
        tri_uv[:n_tri] = uvs.reshape(n_tri, TRI_UV_WIDTH)
    tri_t = np.zeros((rows if use_tangents else 1, TRI_T_WIDTH), np.float32)
    if use_tangents:
        tri_t[:n_tri, TRI_T0:TRI_T0 + 9] = tan.reshape(n_tri, 9)
        tri_t[:n_tri, TRI_T_SIGN:TRI_T_SIGN + 3] = tsg
    tri_col = np.ones((rows if has_colors else 1, TRI_COL_WIDTH), np.float32)
    if has_colors:
        tri_col[:n_tri] = cols.reshape(n_tri, TRI_COL_WIDTH)
    return Triangles(tri_v, tri_n, tri_uv, tri_t, tri_mat, bvh, t_bvh, shift, area, n_tri,
                     smooth, tri_col, has_colors)


# ---------------------------------------------------------------------------------------
# Stage 4: the environment

class Environment(NamedTuple):
    color: np.ndarray      # float32 (3,) constant radiance (zero with a map)
    img: np.ndarray        # texels: radiance and density (kernels.envmap)
    marg: np.ndarray
    cond: np.ndarray
    guide: np.ndarray
    info: np.ndarray
    has_map: bool
    constant: bool         # a constant colour that is not black
    p_lights: float        # probability that next-event estimation picks a light instead


def compile_environment(desc, has_lights, memo=None):
    """The environment's arrays. Next-event estimation picks an HDRI with probability 1/2
    when there are other lights (Mitsuba picks uniformly among emitters), else always."""
    color = np.zeros(3, np.float32)
    img = np.zeros((1, 1, ENV_TEXEL_WIDTH), np.float32)
    marg = np.array([0.0, 1.0], np.float32)
    cond = np.array([[0.0, 1.0]], np.float32)
    guide = np.zeros((2, 2), np.int32)
    info = np.zeros(ENV_INFO_SIZE, np.float32)
    info[ENV_ROT:ENV_ROT + 9] = np.eye(3).reshape(-1)
    has_map = False
    if isinstance(desc.environment, EnvironmentMap):
        env_map = desc.environment
        got = _environment_map_tables(env_map, desc.path) if memo is None else memo.get(
            ("environment", file_key(env_map.path), env_map.intensity, env_map.compensate),
            lambda: _environment_map_tables(env_map, desc.path))
        if got is not None:
            img, marg, cond, guide = got
            has_map = True
            # world -> map: the transpose of the map's orientation in the world
            info[ENV_ROT:ENV_ROT + 9] = env_map.world_from_map().T.reshape(-1)
            info[ENV_P_SELECT] = 0.5 if has_lights else 1.0
    elif desc.environment is not None:
        color[:] = desc.environment
    constant = not has_map and desc.environment is not None and bool(color.any())
    p_lights = 1.0 - float(info[ENV_P_SELECT]) if has_map else 1.0
    return Environment(color, img, marg, cond, guide, info, has_map, constant, p_lights)


def _environment_map_tables(env, scene_file):
    """Image and sampling tables of an environment map (kernels.envmap), or None if black."""
    img, is_float = read_image(env.path, env.pointer, scene_file)
    if not is_float:
        img = srgb_to_linear(img)
    top = float(img.max(initial=0)) * env.intensity
    if top > limits.MAX_RADIANCE:
        raise SceneError(f"environment map {env.path}: its brightest texel x intensity = "
                         f"{top:g} exceeds the largest radiance, {limits.MAX_RADIANCE:g}",
                         scene_file, env.pointer)
    return environment_tables(img * env.intensity, compensate=env.compensate)


# ---------------------------------------------------------------------------------------
# Stage 5: lights

class Lights(NamedTuple):
    light_cdf: np.ndarray
    light_ref: np.ndarray
    light_ref_list: list
    point_lights: np.ndarray
    has_tri_lights: bool
    has_point_lights: bool
    bounds: LightBounds    # of light_ref's lights, for the light tree


# render.lightSampler "auto" picks the light tree from this many lights on, or from two when
# one of them is a point, spot or directional light: one emissive quad (two triangles)
# gains nothing from it (its triangles share one box, normal and power: every pick is 1/2)
# and the tree costs it 8 % of its paths/s (docs/benchmarks.md, "The light tree")
LIGHT_TREE_MIN_LIGHTS = 3


def use_light_tree(light_sampler, n_lights, has_point_lights=False):
    """Whether the scene's lights are picked by the light tree (kernels.lights): "tree"
    always (with at least two lights to choose from), "power" never, "auto" from
    LIGHT_TREE_MIN_LIGHTS lights on, or two with a point light among them."""
    if light_sampler == "power" or n_lights < 2:
        return False
    return (light_sampler == "tree" or n_lights >= LIGHT_TREE_MIN_LIGHTS or
            has_point_lights)


def geometry_sphere(tri):
    """(centre, radius) of the sphere around the box of every triangle (in tri_v's shifted
    coordinates), or None without triangles."""
    if not tri.n:
        return None
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for start in range(0, tri.n, 1 << 20):        # (a few MB of temporaries at a time)
        v = tri.tri_v[start:min(tri.n, start + (1 << 20))]
        v0 = v[:, TRI_V0:TRI_V0 + 3]
        for corner in (v0, v0 + v[:, TRI_E1:TRI_E1 + 3], v0 + v[:, TRI_E2:TRI_E2 + 3]):
            lo = np.minimum(lo, corner.min(0))
            hi = np.maximum(hi, corner.max(0))
    return (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2


def reaching_fraction(position, sphere):
    """The fraction of a point light's flux (at ``position``) that falls into the sphere
    around the geometry: 1 inside it, else the solid angle of the sphere over 4 pi,
    (1 - cos a) / 2 with sin a = r / d, written r^2 / d^2 / (2 (1 + cos a)) (no
    cancellation for far lights)."""
    if sphere is None or not sphere[1] > 0:
        return 1.0
    d = float(np.linalg.norm(np.asarray(position, np.float64) - sphere[0]))
    if d <= sphere[1]:
        return 1.0
    x2 = (sphere[1] / d) ** 2
    return x2 / (2.0 * (1.0 + math.sqrt(1.0 - x2)))


# A directional light is rendered as a point light this many radii of the sphere around the
# geometry away (place_suns)
SUN_DISTANCE = 1000.0


def place_suns(suns, sphere, shift):
    """Each DirectionalLight as a PointLight (world coordinates) SUN_DISTANCE radii of the
    geometry's sphere (in shifted coordinates; None: no geometry) away against its
    direction, with the intensity that gives its irradiance at the sphere's centre: across
    the sphere the direction then varies by under 0.06 degrees and the irradiance by under
    0.2 % (the kernels have no light at infinity but the environment; Mitsuba's
    `directional` emitter is the exact one). The distance is capped where the intensity,
    irradiance x distance^2, would leave float32 (geometry ~1e14 across)."""
    from .loader import PointLight
    centre, radius = sphere if sphere is not None else (np.zeros(3), 0.0)
    out = []
    for sun in suns:
        e = np.asarray(sun.irradiance, np.float64)
        distance = SUN_DISTANCE * max(radius, 1e-3)
        if e.max() > 0:
            distance = min(distance, math.sqrt(1e36 / e.max()))
        position = centre + np.asarray(shift, np.float64) - np.asarray(
            sun.direction, np.float64) * distance
        out.append(PointLight(tuple(position.tolist()), tuple((e * distance ** 2).tolist())))
    return out


def compile_lights(desc, tri, mat, mat_power, shift):
    """One discrete distribution over emissive triangles and point lights, proportional to
    emitted power (kernels.lights); a point light outside the sphere around the geometry
    counts only the power that falls into that sphere (reaching_fraction: a light far away,
    such as a directional light made a point light by place_suns, would otherwise take
    nearly every light sample from the lights that light the scene as much)."""
    suns = getattr(desc, "directional_lights", ())
    sphere = geometry_sphere(tri) if (desc.point_lights or suns) else None
    point_list = list(desc.point_lights) + place_suns(suns, sphere, shift)
    weights, refs = [], []
    bounds = []           # LightBounds' seven fields, for the triangles and the point lights
    if tri.n:
        two_sided = np.where(mat[:, M_TWO_SIDED] > 0, 2, 1)
        mat_pow = np.asarray(mat_power, np.float64) * two_sided
        tri_power = math.pi * tri.area * mat_pow[tri.tri_mat[:tri.n]]
        emissive = np.nonzero(tri_power > 0)[0]
        weights.extend(tri_power[emissive])
        refs.extend(emissive.tolist())
        if len(emissive):
            bounds.append(_triangle_bounds(tri, mat, emissive, tri_power[emissive]))
    point_bounds = []
    for i, light in enumerate(point_list):
        # a spot light's power: about 2 pi (1 - cos of its cone's mean half-angle) I
        solid = 4 * math.pi if light.axis is None else 2 * math.pi * (1 - math.cos(
            math.radians((light.inner_angle + light.outer_angle) / 2)))
        mean_i = float(np.mean(light.intensity))
        p = solid * mean_i * reaching_fraction(
            np.asarray(light.position, np.float64) - shift, sphere)
        if p > 0:
            weights.append(p)
            refs.append(point_light_ref(i))
            point_bounds.append(_point_bounds(light, shift, mean_i))
    if point_bounds:
        bounds.append(tuple(np.asarray(f) for f in zip(*point_bounds)))
    weights = np.asarray(weights, np.float64)
    cdf = np.zeros(len(weights) + 1, np.float64)
    if len(weights):
        cdf[1:] = np.cumsum(weights) / weights.sum()
    light_cdf = cdf.astype(np.float32)
    light_cdf[-1] = 1.0
    light_ref = np.asarray(refs if refs else [0], np.int32)
    point_lights = np.zeros((max(1, len(point_list)), PL_WIDTH), np.float32)
    for i, light in enumerate(point_list):
        point_lights[i, PL_POSITION:PL_POSITION + 3] = np.asarray(light.position) - shift
        point_lights[i, PL_INTENSITY:PL_INTENSITY + 3] = light.intensity
        point_lights[i, PL_CONE_OFFSET] = 1.0          # a point light: no cone
        if light.axis is not None:
            # glTF KHR_lights_punctual's spot falloff: t = clamp(cos * scale + offset, 0, 1)
            # squared, t = 0 at the outer angle and 1 inside the inner one
            cos_in = math.cos(math.radians(light.inner_angle))
            cos_out = math.cos(math.radians(light.outer_angle))
            cone_scale = 1.0 / max(1e-3, cos_in - cos_out)
            point_lights[i, PL_AXIS:PL_AXIS + 3] = light.axis
            point_lights[i, PL_CONE_SCALE] = cone_scale
            point_lights[i, PL_CONE_OFFSET] = -cos_out * cone_scale
    light_bounds = LightBounds(*(np.concatenate([b[f] for b in bounds]) if bounds else
                                 np.zeros((0, 3) if f < 3 else 0) for f in range(7)))
    return Lights(light_cdf, light_ref, refs, point_lights, any(r >= 0 for r in refs),
                  any(r < 0 for r in refs), light_bounds)


def _triangle_bounds(tri, mat, emissive, power):
    """LightBounds' fields of the emissive triangles (shifted coordinates): the triangle's
    box, its normal as a cone of half-angle 0, emission up to 90 degrees from it."""
    v = tri.tri_v[emissive].astype(np.float64)
    v0 = v[:, TRI_V0:TRI_V0 + 3]
    v1 = v0 + v[:, TRI_E1:TRI_E1 + 3]
    v2 = v0 + v[:, TRI_E2:TRI_E2 + 3]
    n = np.cross(v[:, TRI_E1:TRI_E1 + 3], v[:, TRI_E2:TRI_E2 + 3])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    k = len(emissive)
    return (np.minimum(np.minimum(v0, v1), v2), np.maximum(np.maximum(v0, v1), v2), n,
            np.ones(k), np.zeros(k), np.asarray(power, np.float64),
            mat[tri.tri_mat[emissive], M_TWO_SIDED] > 0)


def _point_bounds(light, shift, mean_intensity):
    """LightBounds' fields of a point or spot light (shifted coordinates). Its power for
    the tree is pi I, so that power / distance^2 bounds its irradiance as the triangles'
    pi L A does theirs (pbrt-v4 counts 4 pi I); a spot light's normals are its inner cone,
    its emission reaches outer - inner beyond (pbrt-v4's SpotLight::Bounds)."""
    p = np.asarray(light.position, np.float64) - shift
    if light.axis is None:
        axis, cos_o, cos_e = (0.0, 0.0, 1.0), -1.0, 0.0
    else:
        axis = light.axis
        cos_o = math.cos(math.radians(light.inner_angle))
        cos_e = math.cos(math.radians(max(0.0, light.outer_angle - light.inner_angle)))
    return p, p, np.asarray(axis, np.float64), cos_o, cos_e, math.pi * mean_intensity, False


def light_tree_arrays(tree, lights, tri):
    """(lt_node, lt_link, tri_light_leaf) for SceneArrays: the tree's, or one dummy row
    each without it."""
    if tree is None:
        return (np.zeros((1, LT_WIDTH), np.float32),
                np.full((1, LT_LINK_WIDTH), -1, np.int32), np.full(1, -1, np.int32))
    tri_light_leaf = np.full(max(1, tri.n), -1, np.int32)
    for k, ref in enumerate(lights.light_ref_list):
        if ref >= 0:
            tri_light_leaf[ref] = tree.leaf[k]
    return tree.node, tree.link, tri_light_leaf


def triangle_light_pdfs(lights, tri, p_lights, with_tree=False):
    """Each triangle's selection probability (times p_lights, the chance that a light
    rather than the environment is sampled) over its area: the area density with which
    next-event estimation samples it, 0 for triangles that do not emit. With the light
    tree the selection probability depends on the shading point and is left out (the
    kernels multiply by the tree's)."""
    tri_light_pdf = np.zeros(max(1, tri.n), np.float32)
    for k, ref in enumerate(lights.light_ref_list):
        if ref >= 0:
            pmf = 1.0 if with_tree else (float(lights.light_cdf[k + 1]) -
                                         float(lights.light_cdf[k]))
            tri_light_pdf[ref] = pmf * p_lights / tri.area[ref]
    return tri_light_pdf
