"""Image textures: trilinear (mip-mapped), bilinear or nearest lookups with tiling, offset
and wrapping, and the ray-cone footprint that picks the mip level.

All textures of a scene share one float32 texel array ``tex_data`` (T, 3), already decoded
to linear values on load (exact piecewise sRGB, see ``scene.textures``). Texture k is
described by ``tex_int[k]`` (first texel, width, height, filter, wrap, mip levels) and
``tex_f[k]`` (tile, offset, scale): the texture section of :mod:`.layout`. Texture coordinates
follow the OBJ convention (v = 0 at the bottom of the image); texel centres lie at
((i + 0.5) / W, (j + 0.5) / H), and coordinates repeat, mirror or clamp to the edge in
each direction (glTF's sampler modes; repeat by default).
"""
import math

import numpy as np

from .constants import HALF, ONE, TWO, ZERO
from .device import device
from .fmath import floor_int, fract
from .loads import load4
from .layout import (FILTER_NEAREST, FILTER_TRILINEAR, TEX_FILTER, TEX_FIRST, TEX_HEIGHT,
                     TEX_LEVELS, TEX_OFFSET, TEX_SCALE, TEX_TILE, TEX_WIDTH, TEX_WRAP, TEXEL_RGB,
                     TRI_UV0, TRI_UV1, TRI_UV2, WRAP_MIRROR, WRAP_REPEAT)
from .vec import cross, dot, normalize

# Incidence cosines below this count as this (a grazing hit picks the coarsest levels
# anyway; the clamp keeps the footprint finite).
COS_MIN = np.float32(1e-3)
SIN2_MIN = np.float32(1e-8)   # below: a head-on hit, the ellipse is a circle
# Trilinear lookups along the major axis at most (GPUs offer 2-16; beyond, the footprint
# is filtered at a coarser level instead).
MAX_ANISOTROPY = 8
NO_FOOTPRINT = (ZERO, ZERO, ZERO, ZERO)


@device
def wrap(i, n):
    """Texel index i wrapped into [0, n) (repeat). Lookups wrap their coordinates into
    [0, 1] first, so i is at most one period off: a compare, not an integer division (64-bit
    modulo is a long software routine on the GPU and a slow divide on the CPU). An index
    further off (only a NaN coordinate's) is clamped, so that no lookup reads outside the
    image."""
    if i < 0:
        i += n
    elif i >= n:
        i -= n
    return min(max(i, 0), n - 1)


@device
def wrap_coordinate(x, mode):
    """A texture coordinate into [0, 1]: repeated, mirrored (period 2) or clamped."""
    if mode == WRAP_REPEAT:
        return fract(x)
    if mode == WRAP_MIRROR:
        x = TWO * fract(x * HALF)            # x % 2 (halving and doubling are exact)
        return TWO - x if x > ONE else x
    return min(max(x, np.float32(0.0)), ONE)


@device
def wrap_index(i, n, mode):
    """A texel index into [0, n): repeated, or clamped to the edge (mirrored coordinates
    meet their mirror image at the edge texel)."""
    if mode == WRAP_REPEAT:
        return wrap(i, n)
    return min(max(i, 0), n - 1)


@device
def texel(tex_data, base, width, i, j):
    k = base + j * width + i
    r, g, b, _ = load4(tex_data, k, TEXEL_RGB)     # one 16-byte load (layout.TEXEL_WIDTH)
    return r, g, b


@device
def bilinear_cell(x, y):
    """The texel (ix, iy) whose centre is at or below-left of image position (x, y), in
    texel units with centres at half-integers, and the fractions (fx, fy) towards the next."""
    x -= HALF
    y -= HALF
    ix = floor_int(x)
    iy = floor_int(y)
    return ix, iy, x - np.float32(ix), y - np.float32(iy)


@device
def bilinear_blend(a, b, c, d, fx, fy):
    """Bilinear mix of rgb texels a (ix, iy), b (ix + 1, iy), c (ix, iy + 1), d (ix + 1,
    iy + 1). The one bilinear filter: textures and the environment map use it."""
    w00 = (ONE - fx) * (ONE - fy)
    w10 = fx * (ONE - fy)
    w01 = (ONE - fx) * fy
    w11 = fx * fy
    return (a[0] * w00 + b[0] * w10 + c[0] * w01 + d[0] * w11,
            a[1] * w00 + b[1] * w10 + c[1] * w01 + d[1] * w11,
            a[2] * w00 + b[2] * w10 + c[2] * w01 + d[2] * w11)


def make_tex_lookup(wrap_modes, mipmaps=False):
    """``tex_lookup`` for scenes whose textures all repeat (``wrap_modes`` False: the modes
    column is not read, the repeat code alone is compiled) or not, with mip-mapped
    (trilinear) textures or without (``mipmaps`` False: the footprint is not read and
    every lookup is the bilinear or nearest one of the image itself)."""
    WRAP_MODES = bool(wrap_modes)
    MIPMAPS = bool(mipmaps)

    @device
    def bilinear_at(tex_data, base, w, h, uu, vv, mode_u, mode_v):
        """Bilinear rgb of the w x h image at texel base, at wrapped coordinates (uu, vv)."""
        # (float32 sizes: int * float32 would promote to float64)
        x = uu * np.float32(w)
        y = (ONE - vv) * np.float32(h)           # image row 0 is the top
        ix, iy, fx, fy = bilinear_cell(x, y)
        if WRAP_MODES:
            i0 = wrap_index(ix, w, mode_u)
            j0 = wrap_index(iy, h, mode_v)
            i1 = wrap_index(ix + 1, w, mode_u)
            j1 = wrap_index(iy + 1, h, mode_v)
        else:
            i0 = wrap(ix, w)
            j0 = wrap(iy, h)
            i1 = i0 + 1 if i0 + 1 < w else 0
            j1 = j0 + 1 if j0 + 1 < h else 0
        return bilinear_blend(texel(tex_data, base, w, i0, j0), texel(tex_data, base, w, i1, j0),
                              texel(tex_data, base, w, i0, j1), texel(tex_data, base, w, i1, j1),
                              fx, fy)

    @device
    def mip_pair(base, w, h, levels, lod):
        """The two mip levels around ``lod`` (Williams 1983, "Pyramidal Parametrics"):
        (base, w, h) of level floor(lod) (at most the last), of the level after it, and the
        fraction towards that one. Level k is max(1, w >> k) x max(1, h >> k) texels and
        follows level k - 1 in the texel array. Computed once per lookup, not per probe:
        the walk down the chain is the same for all of an anisotropic lookup's probes."""
        lod = min(lod, np.float32(levels - 1))
        level = floor_int(lod)
        frac = lod - np.float32(level)
        for _ in range(level):
            base += w * h
            w = max(1, w >> 1)
            h = max(1, h >> 1)
        return base, w, h, base + w * h, max(1, w >> 1), max(1, h >> 1), frac

    @device
    def trilinear_at(tex_data, mips, uu, vv, mode_u, mode_v):
        """Trilinear rgb at wrapped coordinates (uu, vv): the bilinear values of the two
        mip levels ``mips`` (mip_pair), mixed by its fraction."""
        base, w, h, base1, w1, h1, frac = mips
        r, g, b = bilinear_at(tex_data, base, w, h, uu, vv, mode_u, mode_v)
        if frac > ZERO:
            r1, g1, b1 = bilinear_at(tex_data, base1, w1, h1, uu, vv, mode_u, mode_v)
            r += (r1 - r) * frac
            g += (g1 - g) * frac
            b += (b1 - b) * frac
        return r, g, b

    @device
    def wrapped(su, sv, mode_u, mode_v):
        # Wrapped to [0, 1] first: a texel index is then small for any finite coordinate
        # (a huge tile or uv would overflow int(floor(x)) and wreck the bilinear fractions).
        if WRAP_MODES:
            return wrap_coordinate(su, mode_u), wrap_coordinate(sv, mode_v)
        return fract(su), fract(sv)

    @device
    def anisotropic(tex_data, base, w, h, levels, su, sv, au, av, major, minor, mode_u,
                    mode_v):
        """The mean of n trilinear lookups spread evenly along the major axis (au, av) (in
        tiled coordinates; ``major`` texels long), at the level of the longer of the minor
        axis and major / n, n = major / minor up to MAX_ANISOTROPY: the footprint
        assembly of GPU anisotropic filtering (Schilling, Knittel, Strasser 1996,
        "Texram"; the ellipse from ray cones as Akenine-Moeller et al. 2021, "Improved
        Shader and Texture Level of Detail Using Ray Cones")."""
        n = MAX_ANISOTROPY
        if major < minor * np.float32(MAX_ANISOTROPY):
            n = max(1, int(math.ceil(major / max(minor, ONE))))
        width = max(minor, major / np.float32(n))
        lod = ZERO
        if width > ONE:
            lod = math.log2(width)
        r = ZERO
        g = ZERO
        b = ZERO
        inv = ONE / np.float32(n)
        mips = mip_pair(base, w, h, levels, lod)
        for i in range(n):
            x = (np.float32(i) + HALF) * inv - HALF
            uu, vv = wrapped(su + au * x, sv + av * x, mode_u, mode_v)
            c = trilinear_at(tex_data, mips, uu, vv, mode_u, mode_v)
            r += c[0]
            g += c[1]
            b += c[2]
        return r * inv, g * inv, b * inv

    @device
    def tex_lookup(tex_data, tex_int, tex_f, t, u, v, fp):
        """Filtered, scaled rgb value of texture t at texture coordinates (u, v). ``fp``:
        the footprint the lookup stands for, (au, av, bu, bv), the major and minor axes of
        a ray cone's ellipse on the surface in texture coordinates (cone_footprint;
        NO_FOOTPRINT for a point), which a trilinear texture filters over."""
        base = tex_int[t, TEX_FIRST]
        w = tex_int[t, TEX_WIDTH]
        h = tex_int[t, TEX_HEIGHT]
        tile_u = tex_f[t, TEX_TILE]
        tile_v = tex_f[t, TEX_TILE + 1]
        su = u * tile_u + tex_f[t, TEX_OFFSET]
        sv = v * tile_v + tex_f[t, TEX_OFFSET + 1]
        mode_u = WRAP_REPEAT
        mode_v = WRAP_REPEAT
        if WRAP_MODES:
            mode_u = tex_int[t, TEX_WRAP] & 3
            mode_v = (tex_int[t, TEX_WRAP] >> 2) & 3
        filt = tex_int[t, TEX_FILTER]
        if MIPMAPS:
            if filt == FILTER_TRILINEAR:
                # the ellipse's axes in texels of the (tiled) image
                tu = np.float32(w) * tile_u
                tv = np.float32(h) * tile_v
                major = math.sqrt((fp[0] * tu) ** 2 + (fp[1] * tv) ** 2)
                minor = math.sqrt((fp[2] * tu) ** 2 + (fp[3] * tv) ** 2)
                if max(major, minor) > ONE:      # else: within a texel of the image
                    return scaled(tex_f, t, anisotropic(
                        tex_data, base, w, h, tex_int[t, TEX_LEVELS], su, sv,
                        fp[0] * tile_u, fp[1] * tile_v, major, minor, mode_u, mode_v))
        uu, vv = wrapped(su, sv, mode_u, mode_v)
        if filt == FILTER_NEAREST:
            ix = floor_int(uu * np.float32(w))
            iy = floor_int((ONE - vv) * np.float32(h))
            if WRAP_MODES:
                rgb = texel(tex_data, base, w, wrap_index(ix, w, mode_u),
                            wrap_index(iy, h, mode_v))
            else:
                rgb = texel(tex_data, base, w, wrap(ix, w), wrap(iy, h))
        else:
            rgb = bilinear_at(tex_data, base, w, h, uu, vv, mode_u, mode_v)
        return scaled(tex_f, t, rgb)

    return tex_lookup


@device
def scaled(tex_f, t, rgb):
    return (rgb[0] * tex_f[t, TEX_SCALE], rgb[1] * tex_f[t, TEX_SCALE + 1],
            rgb[2] * tex_f[t, TEX_SCALE + 2])


@device
def in_uv(tri_uv, tri, e1, e2, ng, world2, a):
    """The texture-coordinate change (du, dv) along the vector a in the plane of triangle
    tri (edges e1, e2, unit normal ng, twice its area world2): a = s e1 + t e2 solved
    with cross products, then the same mix of the uv edges."""
    s = dot(cross(a, e2), ng) / world2
    t = dot(cross(e1, a), ng) / world2
    return (s * (tri_uv[tri, TRI_UV1] - tri_uv[tri, TRI_UV0]) +
            t * (tri_uv[tri, TRI_UV2] - tri_uv[tri, TRI_UV0]),
            s * (tri_uv[tri, TRI_UV1 + 1] - tri_uv[tri, TRI_UV0 + 1]) +
            t * (tri_uv[tri, TRI_UV2 + 1] - tri_uv[tri, TRI_UV0 + 1]))


@device
def cone_footprint(tri_uv, tri, e1, e2, ng, d, width):
    """The footprint (au, av, bu, bv) of a ray cone ``width`` wide where a ray along d
    meets triangle tri (edges e1, e2, unit normal ng): the ellipse the cone cuts from the
    surface, its major axis (width / |cos|, along d's projection onto the surface) and
    minor axis (width, across it), both as full-length vectors in texture coordinates
    (Akenine-Moeller, Nilsson, Andersson, Barre-Brisebois, Toth, Karras 2019, "Texture
    Level of Detail Strategies for Real-Time Ray Tracing", Ray Tracing Gems ch. 20, whose
    isotropic level is log2 of the major axis; here both axes are kept for anisotropic
    filtering)."""
    world2 = dot(cross(e1, e2), ng)           # twice the triangle's area
    if not (world2 > ZERO):
        return NO_FOOTPRINT
    cos = dot(ng, d)
    along = (d[0] - cos * ng[0], d[1] - cos * ng[1], d[2] - cos * ng[2])
    s2 = dot(along, along)
    if s2 > SIN2_MIN:
        s = ONE / math.sqrt(s2)
        along = (along[0] * s, along[1] * s, along[2] * s)
    else:                                     # head-on: a circle; any axis will do
        along = normalize(e1)
    across = cross(ng, along)
    long = width / max(abs(cos), COS_MIN)
    au, av = in_uv(tri_uv, tri, e1, e2, ng, world2,
                   (along[0] * long, along[1] * long, along[2] * long))
    bu, bv = in_uv(tri_uv, tri, e1, e2, ng, world2,
                   (across[0] * width, across[1] * width, across[2] * width))
    return au, av, bu, bv


# every mode (the tests' and the interpreted backend's lookup)
tex_lookup = make_tex_lookup(True, True)
