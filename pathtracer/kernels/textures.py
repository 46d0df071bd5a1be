"""Image textures: bilinear or nearest lookups with tiling, offset and wrapping.

All textures of a scene share one float32 texel array ``tex_data`` (T, 3), already decoded
to linear values on load (exact piecewise sRGB, see ``scene.textures``). Texture k is
described by ``tex_int[k]`` (first texel, width, height, filter) and ``tex_f[k]`` (tile,
offset, scale): the texture section of :mod:`.layout`. Texture coordinates
follow the OBJ convention (v = 0 at the bottom of the image); texel centres lie at
((i + 0.5) / W, (j + 0.5) / H), and coordinates wrap (repeat) in both directions.
"""
import math

import numpy as np

from .constants import HALF, ONE
from .device import device
from .layout import (FILTER_NEAREST, TEX_FILTER, TEX_FIRST, TEX_HEIGHT, TEX_OFFSET, TEX_SCALE,
                     TEX_TILE, TEX_WIDTH)


@device
def wrap(i, n):
    r = i % n
    return r + n if r < 0 else r


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


@device
def tex_lookup(tex_data, tex_int, tex_f, t, u, v):
    """Filtered, scaled rgb value of texture t at texture coordinates (u, v)."""
    base = tex_int[t, TEX_FIRST]
    w = tex_int[t, TEX_WIDTH]
    h = tex_int[t, TEX_HEIGHT]
    # Wrapped to [0, 1] first: a texel index is then small for any finite coordinate
    # (a huge tile or uv would overflow int(floor(x)) and wreck the bilinear fractions).
    uu = (u * tex_f[t, TEX_TILE] + tex_f[t, TEX_OFFSET]) % ONE
    vv = (v * tex_f[t, TEX_TILE + 1] + tex_f[t, TEX_OFFSET + 1]) % ONE
    # (float32 sizes: int * float32 would promote to float64)
    x = uu * np.float32(w)
    y = (ONE - vv) * np.float32(h)           # image row 0 is the top
    if tex_int[t, TEX_FILTER] == FILTER_NEAREST:
        r, g, b = texel(tex_data, base, w, wrap(int(math.floor(x)), w),
                        wrap(int(math.floor(y)), h))
    else:
        ix, iy, fx, fy = bilinear_cell(x, y)
        i0 = wrap(ix, w)
        j0 = wrap(iy, h)
        i1 = wrap(i0 + 1, w)
        j1 = wrap(j0 + 1, h)
        r, g, b = bilinear_blend(texel(tex_data, base, w, i0, j0),
                                 texel(tex_data, base, w, i1, j0),
                                 texel(tex_data, base, w, i0, j1),
                                 texel(tex_data, base, w, i1, j1), fx, fy)
    return r * tex_f[t, TEX_SCALE], g * tex_f[t, TEX_SCALE + 1], b * tex_f[t, TEX_SCALE + 2]
