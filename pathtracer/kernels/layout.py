"""The data contract between the scene compiler and the kernels: every column and slot of the
flat arrays, by name.

The scene compiler writes these arrays and the kernels read them; both, the Mitsuba
translator and the tests use the names below, never bare numbers (``tests/test_layout.py``
checks that no other module indexes these arrays with an integer literal). A column that
starts a vector names its first element: ``cam[CAM_FORWARD + 2]`` is the forward vector's z.

:data:`MATERIAL_PARAMS` is the one table of material parameters: scene-format key, default,
range, the column of ``mat`` it fills, the texture slot that may replace it, and its place in
the principled parameter tuple. The loader validates with it, the compiler fills ``mat``
with it, and a test checks it against ``docs/scene-format.md``.
"""
from typing import NamedTuple

import numpy as np

from .device import device


# ---- Camera: cam, float32 (CAM_SIZE,) -------------------------------------------------------
CAM_ORIGIN = 0        # eye point xyz
CAM_FORWARD = 3       # unit view direction
CAM_RIGHT = 6         # right, scaled by tan(fov_x / 2)
CAM_UP = 9            # up, scaled by tan(fov_y / 2)
CAM_LENS_X = 12       # thin lens: lens radius / tan(fov_x / 2)
CAM_LENS_Y = 13       # thin lens: lens radius / tan(fov_y / 2)
CAM_FOCUS = 14        # thin lens: distance of the plane in focus
CAM_CONE = 15         # ray cones: spread per unit distance (scene.compile.cone_spread)
CAM_SIZE = 16

# ---- Triangles: one row per triangle, in BVH leaf order --------------------------------------
# tri_v, float32 (N, TRI_V_WIDTH): first vertex and the two edges from it (the intersection
# test's form); the front side is the counter-clockwise one, cross(e1, e2).
TRI_V0 = 0
TRI_E1 = 3
TRI_E2 = 6
TRI_V_WIDTH = 9
# tri_n, float32 (N, TRI_N_WIDTH): unit vertex normals (smooth shading only)
TRI_N0 = 0
TRI_N1 = 3
TRI_N2 = 6
TRI_N_WIDTH = 9
# tri_uv, float32 (N, TRI_UV_WIDTH): texture coordinates (u, v) of the three vertices
TRI_UV0 = 0
TRI_UV1 = 2
TRI_UV2 = 4
TRI_UV_WIDTH = 6
# tri_t, float32 (N, TRI_T_WIDTH): unit vertex tangents (dp/du), then the handedness sign of
# the bitangent at each vertex (+1 or -1)
TRI_T0 = 0
TRI_T1 = 3
TRI_T2 = 6
TRI_T_SIGN = 9
TRI_T_WIDTH = 12
# tri_col, float32 (N, TRI_COL_WIDTH): linear RGB vertex colours of the three vertices,
# which multiply the base colour (glTF's COLOR_0; vertex colours only)
TRI_COL0 = 0
TRI_COL1 = 3
TRI_COL2 = 6
TRI_COL_WIDTH = 9

# ---- Materials: mat, float32 (M, MAT_WIDTH); mat_tex, int32 (M, N_SLOTS) ---------------------
M_ALBEDO = 0          # rgb; for a textured albedo the texture's scale
M_EMISSION = 3        # rgb; non-zero means "emits" (a textured emission keeps its scale here)
M_TWO_SIDED = 6       # 1: emits on both sides
M_TYPE = 7            # MAT_DIFFUSE, MAT_PRINCIPLED or MAT_CONDUCTOR
M_ROUGHNESS = 8
M_METALLIC = 9
M_SPECULAR = 10
M_ETA = 11            # 0: derived from specular in the kernel
M_SPEC_TINT = 12
M_ANISOTROPIC = 13
M_SHEEN = 14
M_SHEEN_TINT = 15
M_CLEARCOAT = 16
M_CLEARCOAT_GLOSS = 17
M_SUBSURFACE = 18
M_TRANSMISSION = 19
M_ONE_SIDED = 20      # 1: reflects only on its front side, black from behind (oneSided)
M_ALPHA = 21          # opacity in [0, 1] (a textured opacity: its texture, T_ALPHA)
M_ALPHA_MODE = 22     # ALPHA_OPAQUE, ALPHA_MASK or ALPHA_BLEND
M_ALPHA_CUTOFF = 23   # ALPHA_MASK: opaque where the opacity is >= this
MAT_WIDTH = 24

# Alpha modes (glTF's alphaMode): opaque (the opacity is not read), a cut-out (opaque where
# the opacity reaches the cutoff, else absent) or stochastic transparency (a ray passes with
# probability 1 - opacity).
ALPHA_OPAQUE = 0
ALPHA_MASK = 1
ALPHA_BLEND = 2
# A thin dielectric pane (Mitsuba's thindielectric): a ray passes straight through with
# probability 1 - R', R' = 2R / (1 + R) the pane's reflectance with its interreflections
# summed, R the Fresnel reflectance of index M_THIN_ETA at the ray's angle to the
# triangle; where it does not pass it meets the material, a perfect mirror. Stochastic
# transparency again: unbiased, shadow rays included.
ALPHA_THIN = 3
M_THIN_ETA = M_ALPHA  # (ALPHA_THIN only: the pane's relative index of refraction)

MAT_DIFFUSE = 0
MAT_PRINCIPLED = 1
MAT_CONDUCTOR = 2     # Mitsuba's conductor / roughconductor (kernels.conductor)

# A conductor's row reuses principled columns under its own names: the albedo columns hold
# its specular reflectance (a tint, textured by T_ALBEDO), then the microfacet alphas along
# the tangent (dp/du) and the bitangent (textured by T_COND_ALPHA_U / T_COND_ALPHA_V, read
# as luminance), the complex index of refraction eta + i k per channel (relative to the
# outside medium), and the distribution (COND_GGX or COND_BECKMANN).
M_COND_ALPHA_U = 8
M_COND_ALPHA_V = 9
M_COND_ETA = 10       # rgb
M_COND_K = 13         # rgb
M_COND_DISTRIBUTION = 16
COND_GGX = 0
COND_BECKMANN = 1

# Texture slots: mat_tex[m, T_*] is the texture that replaces a parameter, or NO_TEXTURE.
T_ALBEDO = 0
T_EMISSION = 1
T_ROUGHNESS = 2
T_METALLIC = 3
T_SPECULAR = 4
T_ETA = 5
T_SPEC_TINT = 6
T_ANISOTROPIC = 7
T_SHEEN = 8
T_SHEEN_TINT = 9
T_CLEARCOAT = 10
T_CLEARCOAT_GLOSS = 11
T_SUBSURFACE = 12
T_TRANSMISSION = 13
T_NORMAL = 14
T_ALPHA = 15
N_SLOTS = 16
T_COND_ALPHA_U = T_ROUGHNESS    # a conductor's textured alphas (MAT_CONDUCTOR)
T_COND_ALPHA_V = T_METALLIC
NO_TEXTURE = -1

# ---- The principled parameter tuple (kernels.principled), read at a shading point ------------
P_BASE = 0            # base colour rgb
P_ROUGHNESS = 3
P_METALLIC = 4
P_ETA = 5
P_SPEC_TINT = 6
P_ANISOTROPIC = 7
P_SHEEN = 8
P_SHEEN_TINT = 9
P_CLEARCOAT = 10
P_CLEARCOAT_GLOSS = 11
P_FLATNESS = 12       # the scene's "subsurface" (Mitsuba's name)
P_TRANSMISSION = 13
P_SIZE = 14
# the fields' names, in tuple order (tests build parameter tuples by name)
# A conductor's parameter tuple (MAT_CONDUCTOR; kernels.conductor) keeps P_BASE (its specular
# reflectance) and P_TRANSMISSION (0); between them:
P_COND_ALPHA_U = 3
P_COND_ALPHA_V = 4
P_COND_ETA = 5        # rgb
P_COND_K = 8          # rgb
P_COND_DISTRIBUTION = 11
P_FIELDS = ("r", "g", "b", "roughness", "metallic", "eta", "spec_tint", "anisotropic",
            "sheen", "sheen_tint", "clearcoat", "clearcoat_gloss", "flatness",
            "transmission")


class MaterialParam(NamedTuple):
    """One material parameter of the scene format."""
    key: str              # the scene file's key
    kind: str             # "color" (rgb) or "number"
    default: object       # the scene format's default; None: derived (eta from specular)
    lo: object            # smallest allowed value (None: unbounded)
    hi: object            # largest allowed value (None: unbounded)
    column: int           # first column of mat
    slot: int             # texture slot of mat_tex
    field: int            # index in the principled parameter tuple (-1: not in it)
    principled_only: bool
    mitsuba: str          # Mitsuba 3's `principled` parameter ("": none)


MATERIAL_PARAMS = (
    MaterialParam("albedo", "color", 0.5, 0.0, None, M_ALBEDO, T_ALBEDO, P_BASE, False,
                  "base_color"),
    MaterialParam("emission", "color", 0.0, 0.0, None, M_EMISSION, T_EMISSION, -1, False,
                  ""),
    MaterialParam("roughness", "number", 0.5, 0.0, 1.0, M_ROUGHNESS, T_ROUGHNESS,
                  P_ROUGHNESS, True, "roughness"),
    MaterialParam("metallic", "number", 0.0, 0.0, 1.0, M_METALLIC, T_METALLIC, P_METALLIC,
                  True, "metallic"),
    MaterialParam("specular", "number", 0.5, 0.0, 1.0, M_SPECULAR, T_SPECULAR, -1, True,
                  "specular"),
    MaterialParam("specularTint", "number", 0.0, 0.0, 1.0, M_SPEC_TINT, T_SPEC_TINT,
                  P_SPEC_TINT, True, "spec_tint"),
    MaterialParam("anisotropic", "number", 0.0, 0.0, 1.0, M_ANISOTROPIC, T_ANISOTROPIC,
                  P_ANISOTROPIC, True, "anisotropic"),
    MaterialParam("sheen", "number", 0.0, 0.0, 1.0, M_SHEEN, T_SHEEN, P_SHEEN, True, "sheen"),
    MaterialParam("sheenTint", "number", 0.0, 0.0, 1.0, M_SHEEN_TINT, T_SHEEN_TINT,
                  P_SHEEN_TINT, True, "sheen_tint"),
    MaterialParam("clearcoat", "number", 0.0, 0.0, 1.0, M_CLEARCOAT, T_CLEARCOAT,
                  P_CLEARCOAT, True, "clearcoat"),
    MaterialParam("clearcoatGloss", "number", 0.0, 0.0, 1.0, M_CLEARCOAT_GLOSS,
                  T_CLEARCOAT_GLOSS, P_CLEARCOAT_GLOSS, True, "clearcoat_gloss"),
    MaterialParam("subsurface", "number", 0.0, 0.0, 1.0, M_SUBSURFACE, T_SUBSURFACE,
                  P_FLATNESS, True, "flatness"),
    MaterialParam("transmission", "number", 0.0, 0.0, 1.0, M_TRANSMISSION, T_TRANSMISSION,
                  P_TRANSMISSION, True, "spec_trans"),
    # eta: > 0 (lower bound open); absent, it follows from specular (F0 = 0.08 specular)
    MaterialParam("eta", "number", None, 0.0, None, M_ETA, T_ETA, P_ETA, True, "eta"),
)
PARAM_BY_KEY = {p.key: p for p in MATERIAL_PARAMS}
# eta when neither eta nor specular is given: specular 0.5 -> F0 = 0.04 -> eta = 1.5
DEFAULT_ETA = 1.5

# ---- Lights ------------------------------------------------------------------------------------
# point_lights, float32 (P, PL_WIDTH): point and spot lights. A spot light's intensity is
# scaled by t^2, t = clamp(cos * PL_CONE_SCALE + PL_CONE_OFFSET, 0, 1), cos the cosine between
# PL_AXIS (where it points) and the direction to the lit point (glTF KHR_lights_punctual's
# falloff); a point light has scale 0 and offset 1.
PL_POSITION = 0
PL_INTENSITY = 3
PL_AXIS = 6
PL_CONE_SCALE = 9
PL_CONE_OFFSET = 10
PL_WIDTH = 11
# light_ref[k]: triangle index of light k, or point_light_ref(p) for point light p
# The light tree (render.lightSampler "tree"; kernels.lights, accel.light_tree): one node per
# row of lt_node, float32 (L, LT_WIDTH), the bounds of the lights below it (Conty Estevez and
# Kulla 2018; pbrt-v4's LightBounds): the sphere around their box, the cone of their normals
# (axis, cos and sin of its half-angle theta_o), the cosine of the widest emission angle
# around a normal (theta_e), their summed power, and whether any emits on both sides; in
# three 16-byte groups (kernels.loads).
LT_CENTRE = 0         # xyz
LT_RADIUS2 = 3        # squared radius of the sphere around the box
LT_AXIS = 4           # xyz: unit axis of the normals' cone
LT_POWER = 7
LT_COS_O = 8
LT_SIN_O = 9
LT_COS_E = 10
LT_TWO_SIDED = 11     # 1.0 or 0.0
LT_WIDTH = 12
# lt_link, int32 (L, LT_LINK_WIDTH): an inner node's two children, a leaf's light (LT_LEFT =
# leaf_light_ref(k), negative, for light k of light_ref), and each node's parent (-1: root).
# tri_light_leaf, int32 (N,): the leaf of an emissive triangle (-1: none).
LT_LEFT = 0
LT_RIGHT = 1
LT_PARENT = 2
LT_LINK_WIDTH = 3
# env_img, float32 (H, W, ENV_TEXEL_WIDTH): per texel of the environment map its radiance
# (rgb, the intensity applied) and the sampling density p(u, v) at its centre (see
# kernels.envmap), so that a texel is one 16-byte load
ENV_DENSITY = 3
ENV_TEXEL_WIDTH = 4
# env_info, float32 (ENV_INFO_SIZE,)
ENV_P_SELECT = 0      # probability that next-event estimation picks the environment
ENV_ROT = 1           # 3 x 3 rotation, row-major, taking world directions into the map's frame
ENV_INFO_SIZE = 12

# ---- Textures: tex_int, int32 (K, TEX_INT_WIDTH); tex_f, float32 (K, TEX_F_WIDTH) ------------
TEX_FIRST = 0         # index of the first texel in tex_data
TEX_WIDTH = 1
TEX_HEIGHT = 2
TEX_FILTER = 3        # FILTER_BILINEAR, FILTER_NEAREST or FILTER_TRILINEAR
TEX_WRAP = 4          # u's WRAP_* in bits 0-1, v's in bits 2-3
TEX_LEVELS = 5        # mip levels stored from TEX_FIRST on (1: the image alone)
TEX_INT_WIDTH = 6
# a texel in tex_data: r, g, b and a zero, so that one 16-byte load reads it (kernels.loads)
TEXEL_RGB = 0
TEXEL_WIDTH = 4
TEX_TILE = 0          # u, v
TEX_OFFSET = 2        # u, v
TEX_SCALE = 4         # r, g, b
TEX_F_WIDTH = 7
FILTER_BILINEAR = 0
FILTER_NEAREST = 1
FILTER_TRILINEAR = 2  # mip-mapped (level k: max(1, width >> k) x max(1, height >> k))
WRAP_REPEAT = 0
WRAP_CLAMP = 1        # clamp to the edge texels
WRAP_MIRROR = 2       # mirrored repeat

# ---- BVH: node k holds both children (Aila & Laine 2009) ---------------------------------------
# bvh_box, float32 (B, BOX_WIDTH): child c's box starts at BOX_CHILD0 + c * BOX_STRIDE and
# holds min xyz (BOX_MIN), then max xyz (BOX_MAX)
BOX_CHILD0 = 0
BOX_CHILD1 = 6
BOX_STRIDE = 6
BOX_MIN = 0
BOX_MAX = 3
BOX_WIDTH = 12
# bvh_child, int32 (B, CHILD_WIDTH): child c's (index, count) start at c * CHILD_STRIDE;
# count > 0: a leaf over triangles index .. index + count - 1; 0: an inner node with that
# index; CHILD_EMPTY: no child
CHILD_INDEX = 0       # within a child's pair
CHILD_COUNT = 1
CHILD0_INDEX = 0
CHILD0_COUNT = 1
CHILD1_INDEX = 2
CHILD1_COUNT = 3
CHILD_STRIDE = 2
CHILD_WIDTH = 4
CHILD_EMPTY = -1

# ---- Film statistics: stats, int32 (H, W, STATS_WIDTH) -----------------------------------------
STAT_BOUNCE_RAYS = 0
STAT_SHADOW_RAYS = 1
STAT_NONFINITE = 2
STATS_WIDTH = 3

# ---- The CPU's ring of finished paths whose escaped ray is looked up later ----------------------
# (drivers.deferred): per image row float32 (ESCAPE_RING, ESC_F_WIDTH) and
# int32 (ESCAPE_RING, ESC_I_WIDTH)
ESCAPE_RING = 8       # paths between a cell's prefetch and its lookup
ESC_RADIANCE = 0      # the path's radiance before its escaped ray (3)
ESC_BETA = 3          # the throughput of the ray that left (3)
ESC_PDF_PREV = 6      # the density of the BSDF sample that made it (0: the camera's ray)
ESC_FX = 7            # the map cell's fractions and the direction's cos theta (env_locate)
ESC_FY = 8
ESC_Y = 9
ESC_F_WIDTH = 10
ESC_PX = 0            # the pixel's column
ESC_OUT = 1           # 1: the path's last ray left the scene
ESC_I0 = 2            # the cell's texel columns and rows (env_locate)
ESC_I1 = 3
ESC_J0 = 4
ESC_J1 = 5
ESC_I_WIDTH = 6

# ---- Paths under way in the wavefront kernels: float32 (PATH_F_WIDTH, N), int32 --------------
# (PATH_I_WIDTH, N), a row per field so that a warp's lanes (consecutive paths) read
# consecutive words; the closest hits of a queue: float32 (HIT_F_WIDTH, N), int32 (N,)
PATH_O = 0            # xyz
PATH_D = 3            # xyz
PATH_BETA = 6         # rgb
PATH_RADIANCE = 9     # rgb
PATH_PDF_PREV = 12
PATH_CONE = 13
PATH_F_WIDTH = 14
PATH_SKIP = 0
PATH_BOUNCE = 1
PATH_BOUNCE_RAYS = 2
PATH_SHADOW_RAYS = 3
PATH_I_WIDTH = 4
HIT_T = 0
HIT_B1 = 1
HIT_B2 = 2
HIT_F_WIDTH = 3

# ---- Auxiliary images for the denoiser: aovs, float32 (H, W, AOV_WIDTH) -----------------------
AOV_ALBEDO = 0        # rgb
AOV_NORMAL = 3        # xyz, world space
AOV_WIDTH = 6

# ---- Random dimensions of a path (kernels.rng) -------------------------------------------------
# In sets of four (the sobol sampler draws each set from one 4-D Sobol sequence, the first
# two dimensions of a set best stratified): set 0 the camera, then per scattering event a
# light set and a BSDF set.
D_PIXEL_X = 0
D_PIXEL_Y = 1
D_LENS_U = 2
D_LENS_V = 3
D_FIRST_BOUNCE = 4    # then DIMS_PER_BOUNCE per scattering event:
D_LIGHT_U = 0         # light set: position on the light (or environment direction)
D_LIGHT_V = 1
D_LIGHT_SELECT = 2    # which light; dimension 3 of the set is unused
D_BSDF_U = 4          # BSDF set: direction
D_BSDF_V = 5
D_BSDF_LOBE = 6       # reflection or refraction (the lobe: by reusing D_BSDF_U)
D_RR = 7              # Russian roulette
DIMS_PER_BOUNCE = 8
# Stochastic transparency (ALPHA_BLEND) draws its numbers from the independent hash
# (rng.sample_1d of the path's key), far above the sampler's dimensions: for the surfaces a
# ray passes on the way to its hit at bounce b, dimension D_ALPHA + b * ALPHA_DIMS + k
# (the k-th surface met), its shadow ray's from D_ALPHA_SHADOW on likewise.
D_ALPHA = 1 << 20
D_ALPHA_SHADOW = 1 << 21
ALPHA_DIMS = 64


class Features(NamedTuple):
    """What a scene uses; each flag that is False removes code from the kernel."""
    tri_lights: bool    # emissive triangles (area lights)
    point_lights: bool
    environment: bool   # constant-colour environment
    smooth: bool        # interpolated vertex normals
    principled: bool = False   # any principled material
    textures: bool = False     # any texture (parameters or normal maps)
    normal_map: bool = False   # any normal map
    tangents: bool = False     # per-vertex tangents from texture coordinates
    env_map: bool = False      # an HDRI environment (importance sampled)
    thin_lens: bool = False    # aperture > 0
    sobol: bool = False        # Owen-scrambled Sobol sampler (else independent)
    wrap_modes: bool = False   # a texture that mirrors or clamps (else all repeat)
    mipmaps: bool = False      # a mip-mapped (trilinear) texture: ray cones are traced
    light_tree: bool = False   # lights picked by the light tree (else by power alone)
    # emitters seen directly by the camera are not shown (Mitsuba's hide_emitters: camera
    # rays that escape or reach an emissive surface add nothing; seen in a mirror or through
    # glass they are)
    hide_emitters: bool = False
    vertex_colors: bool = False   # per-vertex colours multiply the base colour (tri_col)
    one_sided: bool = False       # a material that is black from behind (oneSided)
    alpha: bool = False           # a cut-out or stochastically transparent material
    conductor: bool = False       # a conductor material (MAT_CONDUCTOR)
    # The principled parameters some material sets above 0 (or textures): the BSDF's parts
    # that need them are compiled only then (kernels.principled.Lobes). True by default:
    # a feature set built without them compiles the whole BSDF. dielectric: some principled
    # material is not all metal (metallic below 1 or textured).
    dielectric: bool = True
    clearcoat: bool = True
    sheen: bool = True
    transmission: bool = True
    flatness: bool = True      # the scene's "subsurface"
    spec_tint: bool = True
    anisotropic: bool = True


class Specialisation(NamedTuple):
    """Compile-time constants derived from :class:`Features`: the kernel factories close
    over these, and Numba removes every branch on a constant that is False."""
    tri_lights: bool
    point_lights: bool
    any_lights: bool       # emissive triangles or point lights
    environment: bool      # constant-colour environment
    env_map: bool
    any_environment: bool  # either kind of environment: escaped rays see it
    nee: bool              # any light to sample: next-event estimation
    smooth: bool
    principled: bool
    textures: bool
    normal_map: bool
    tangents: bool
    thin_lens: bool
    fold: bool             # shading normals differ from geometric ones: fold lobes back
    lean: bool             # Lambertian and flat shading only: the cheapest path
    sobol: bool            # the Owen-scrambled Sobol sampler
    wrap_modes: bool       # texture wrap modes other than repeat
    mipmaps: bool          # trilinear textures: ray-cone footprints for their lookups
    lobes: tuple           # kernels.principled.Lobes: the principled BSDF's parts compiled
    light_tree: bool       # lights picked by the light tree at each shading point
    hide_emitters: bool    # camera rays see no emitter (render.hideEmitters)
    vertex_colors: bool    # interpolated vertex colours multiply the base colour
    one_sided: bool        # some material reflects on its front side only
    alpha: bool            # some material is cut out or transparent (M_ALPHA_MODE)
    conductor: bool        # some material is a conductor (MAT_CONDUCTOR)
    glossy: bool           # principled or conductor: BSDFs beyond Lambert's


def specialise(features):
    """The :class:`Specialisation` of a feature set."""
    f = Features(*(bool(x) for x in features))
    any_lights = f.tri_lights or f.point_lights
    normal_map = f.normal_map and f.textures
    fold = f.smooth or normal_map
    return Specialisation(
        tri_lights=f.tri_lights, point_lights=f.point_lights, any_lights=any_lights,
        environment=f.environment, env_map=f.env_map,
        any_environment=f.environment or f.env_map, nee=any_lights or f.env_map,
        smooth=f.smooth, principled=f.principled, textures=f.textures,
        normal_map=normal_map, tangents=f.tangents, thin_lens=f.thin_lens, fold=fold,
        lean=not (f.principled or f.conductor) and not fold, sobol=f.sobol,
        wrap_modes=f.wrap_modes and f.textures, mipmaps=f.mipmaps and f.textures,
        lobes=(f.dielectric, f.clearcoat, f.sheen, f.transmission, f.flatness, f.spec_tint,
               f.anisotropic),
        light_tree=f.light_tree and any_lights, hide_emitters=f.hide_emitters,
        vertex_colors=f.vertex_colors, one_sided=f.one_sided, alpha=f.alpha,
        conductor=f.conductor, glossy=f.principled or f.conductor)


class SceneArrays(NamedTuple):
    """Everything a kernel reads. Arrays a scene does not use hold one dummy row."""
    cam: np.ndarray            # float32 (CAM_SIZE,)
    tri_v: np.ndarray          # float32 (N, TRI_V_WIDTH)
    tri_n: np.ndarray          # float32 (N, TRI_N_WIDTH) (smooth only)
    tri_mat: np.ndarray        # int32 (N,)
    mat: np.ndarray            # float32 (M, MAT_WIDTH)
    # float32 (N,): selection probability / area; 0 if not emissive. With the light tree:
    # the probability of picking a light rather than the environment / area (the tree's
    # pmf, which depends on the shading point, multiplies it).
    tri_light_pdf: np.ndarray
    light_cdf: np.ndarray      # float32 (K + 1,)
    light_ref: np.ndarray      # int32 (K,): triangle index, or point_light_ref(p)
    point_lights: np.ndarray   # float32 (P, PL_WIDTH)
    env: np.ndarray            # float32 (3,): constant environment radiance
    bvh_box: np.ndarray        # float32 (B, BOX_WIDTH)
    bvh_child: np.ndarray      # int32 (B, CHILD_WIDTH)
    tri_uv: np.ndarray         # float32 (N, TRI_UV_WIDTH) (textures only)
    tri_t: np.ndarray          # float32 (N, TRI_T_WIDTH) (tangents only)
    mat_tex: np.ndarray        # int32 (M, N_SLOTS)
    tex_data: np.ndarray       # float32 (T, TEXEL_WIDTH) linear texels of all textures
    tex_int: np.ndarray        # int32 (K, TEX_INT_WIDTH)
    tex_f: np.ndarray          # float32 (K, TEX_F_WIDTH)
    env_img: np.ndarray        # float32 (H, W, ENV_TEXEL_WIDTH) see kernels.envmap
    env_marg: np.ndarray       # float32 (H + 2,)
    env_cond: np.ndarray       # float32 (H, W + 1)
    env_guide: np.ndarray      # int32 (H + 1, G + 1): the searches' guide tables
    env_info: np.ndarray       # float32 (ENV_INFO_SIZE,)
    lt_node: np.ndarray        # float32 (L, LT_WIDTH) (light tree only)
    lt_link: np.ndarray        # int32 (L, LT_LINK_WIDTH) (light tree only)
    tri_light_leaf: np.ndarray  # int32 (N,) (light tree only)
    tri_col: np.ndarray        # float32 (N, TRI_COL_WIDTH) (vertex colours only)


@device
def point_light_ref(p):
    """light_ref entry of point light p (negative: triangles have indices >= 0)."""
    return -(p + 1)


@device
def leaf_light_ref(k):
    """lt_link[n, LT_LEFT] of a leaf over light k (negative: inner nodes' children are >= 1)."""
    return -(k + 1)


@device
def point_light_index(ref):
    """The point light of a negative light_ref entry."""
    return -ref - 1
