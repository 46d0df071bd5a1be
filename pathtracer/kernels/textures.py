"""Image textures: bilinear or nearest lookups with tiling, offset and wrapping.

All textures of a scene share one float32 texel array ``tex_data`` (T, 3), already decoded
to linear values on load (exact piecewise sRGB, see ``scene.textures``). Texture k is
described by ``tex_int[k]`` (first texel, width, height, filter) and ``tex_f[k]`` (tile,
offset, scale): the texture section of :mod:`.layout`. Texture coordinates
follow the OBJ convention (v = 0 at the bottom of the image); texel centres lie at
((i + 0.5) / W, (j + 0.5) / H), and coordinates repeat, mirror or clamp to the edge in
each direction (glTF's sampler modes; repeat by default).
"""
import math

import numpy as np

from .constants import HALF, ONE
from .device import device
from .layout import (FILTER_NEAREST, TEX_FILTER, TEX_FIRST, TEX_HEIGHT, TEX_OFFSET, TEX_SCALE,
                     TEX_TILE, TEX_WIDTH, TEX_WRAP, WRAP_MIRROR, WRAP_REPEAT)


@device
def wrap(i, n):
    r = i % n
    return r + n if r < 0 else r


@device
def wrap_coordinate(x, mode):
    """A texture coordinate into [0, 1]: repeated, mirrored (period 2) or clamped."""
    if mode == WRAP_REPEAT:
        return x % ONE
    if mode == WRAP_MIRROR:
        x = x % np.float32(2.0)
        return np.float32(2.0) - x if x > ONE else x
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
    return tex_data[k, 0], tex_data[k, 1], tex_data[k, 2]


@device
def bilinear_cell(x, y):
    """The texel (ix, iy) whose centre is at or below-left of image position (x, y), in
    texel units with centres at half-integers, and the fractions (fx, fy) towards the next."""
    x -= HALF
    y -= HALF
    ix = int(math.floor(x))
    iy = int(math.floor(y))
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


def make_tex_lookup(wrap_modes):
    """``tex_lookup`` for scenes whose textures all repeat (``wrap_modes`` False: the modes
    column is not read, the repeat code alone is compiled) or not."""
    WRAP_MODES = bool(wrap_modes)

    @device
    def tex_lookup(tex_data, tex_int, tex_f, t, u, v):
        """Filtered, scaled rgb value of texture t at texture coordinates (u, v)."""
        base = tex_int[t, TEX_FIRST]
        w = tex_int[t, TEX_WIDTH]
        h = tex_int[t, TEX_HEIGHT]
        su = u * tex_f[t, TEX_TILE] + tex_f[t, TEX_OFFSET]
        sv = v * tex_f[t, TEX_TILE + 1] + tex_f[t, TEX_OFFSET + 1]
        # Wrapped to [0, 1] first: a texel index is then small for any finite coordinate
        # (a huge tile or uv would overflow int(floor(x)) and wreck the bilinear fractions).
        mode_u = WRAP_REPEAT
        mode_v = WRAP_REPEAT
        if WRAP_MODES:
            mode_u = tex_int[t, TEX_WRAP] & 3
            mode_v = (tex_int[t, TEX_WRAP] >> 2) & 3
            uu = wrap_coordinate(su, mode_u)
            vv = wrap_coordinate(sv, mode_v)
        else:
            uu = su % ONE
            vv = sv % ONE
        # (float32 sizes: int * float32 would promote to float64)
        x = uu * np.float32(w)
        y = (ONE - vv) * np.float32(h)           # image row 0 is the top
        if tex_int[t, TEX_FILTER] == FILTER_NEAREST:
            ix = int(math.floor(x))
            iy = int(math.floor(y))
            if WRAP_MODES:
                r, g, b = texel(tex_data, base, w, wrap_index(ix, w, mode_u),
                                wrap_index(iy, h, mode_v))
            else:
                r, g, b = texel(tex_data, base, w, wrap(ix, w), wrap(iy, h))
        else:
            ix, iy, fx, fy = bilinear_cell(x, y)
            if WRAP_MODES:
                i0 = wrap_index(ix, w, mode_u)
                j0 = wrap_index(iy, h, mode_v)
                i1 = wrap_index(ix + 1, w, mode_u)
                j1 = wrap_index(iy + 1, h, mode_v)
            else:
                i0 = wrap(ix, w)
                j0 = wrap(iy, h)
                i1 = wrap(i0 + 1, w)
                j1 = wrap(j0 + 1, h)
            r, g, b = bilinear_blend(texel(tex_data, base, w, i0, j0),
                                     texel(tex_data, base, w, i1, j0),
                                     texel(tex_data, base, w, i0, j1),
                                     texel(tex_data, base, w, i1, j1), fx, fy)
        return (r * tex_f[t, TEX_SCALE], g * tex_f[t, TEX_SCALE + 1],
                b * tex_f[t, TEX_SCALE + 2])

    return tex_lookup


# every mode (the tests' and the interpreted backend's lookup)
tex_lookup = make_tex_lookup(True)
