"""Environment map: an equirectangular image lit from infinitely far away.

Mapping (scene format): a world direction d is first turned by -rotation about +Y, then
u = 0.5 + atan2(d.x, -d.z) / (2 pi), v = acos(d.y) / pi (v = 0: top row), and the image is
read bilinearly with texel centres at ((i + 0.5) / W, (j + 0.5) / H), wrapping in u and
clamping in v.

Importance sampling: the density over [0,1]^2 is the bilinear interpolation, between texel
centres and with the lookup's wrapping and clamping, of luminance x sin(theta) at the texel
centres: so it follows the bilinearly looked-up radiance, not a staircase of it (a
piecewise-constant density, PBRT 3rd ed. sec. 14.2.4, leaves a sharp sun's bilinear skirt
with up to 4x too little density: the fireflies of a sunlit scene). Mitsuba 3's envmap
samples a bilinear density the same way (its Marginal2D). Sampling: a row cell (between two
texel-centre rows; half cells at the clamped top and bottom) from the marginal CDF, v within
it from its linear density, then a column cell from the row's CDF interpolated to that v
(CDFs of bilinear patches are linear in v), and u within it from its linear density. A point
(u, v) maps to a direction with solid-angle density p(u, v) / (2 pi^2 sin theta), the
Jacobian of the mapping (the thesis renderer used 2 pi sin theta, pi too large). By default
the texel weights are max(luminance - mean, 0) x sin(theta) rather than luminance x
sin(theta) (MIS compensation: see :func:`environment_tables`).

Arrays: ``env_img`` (H, W, 4) per texel the radiance (rgb, the intensity applied) and the
density p(u, v) at its centre (layout ENV_DENSITY), so that a bilinear cell is four 16-byte
loads and one load serves both the radiance and the density; ``env_marg`` (H + 2,) the CDF
over the H + 1 row cells; ``env_cond`` (H, W + 1) per texel row the unnormalised cumulative
masses of its column cells (the last entry: the row's total); ``env_guide`` int32
(H + 1, G + 1) the guide tables of these searches (below); ``env_info`` (see
:mod:`.layout`): the rotation's cosine and sine and the probability that next-event
estimation picks the environment.

Guide tables (the cutpoint method: Chen and Asau 1974; Devroye 1986, sec. III.2.4): an
inversion search of a cumulative table over n cells starts from the bracket that a table of
G + 1 quantiles gives it rather than from all n cells. Entry b of row j (j < H) is the last
column cell i with env_cond[j, i] <= (b / G) x the row's total, and of row H the last row
cell k with env_marg[k] <= b / G; a u in [b / G, (b + 1) / G) then lies in the cells from
entry b to entry b + 1, typically one to three (a bisection of a 1,024-column row took ten
dependent steps, each two loads that often missed the cache, and mispredicted half of its
branches: the two searches were most of the sampling's 15 % of bunny-studio's CPU time).
The column search runs on a row interpolated between two texel rows (its CDF is the
mixture of the two rows' normalised CDFs), so its answer lies between the two rows' own
answers: the bracket is the union of the two rows' brackets. Up to rounding (a u within
a float's rounding of a quantile), the cell found is the bisection's (tested; the images
of bench.ab were bit-identical with fast-math off). The CPU uses the guides (bunny-studio
+5.6 % camera paths/s on 2 EPYC cores); the GPU searches all cells with the same halving
loop (a bisection before: bunny-studio 1.014x, sun 1.022x, textured 1.006x on an H200),
as with the guides there the textured scene's 256-column map lost 1.2 % (all 2026-11-28,
``python -m bench.ab throughput``).

The device functions sample and evaluate these tables; :func:`environment_tables`, beside
them, is the host code (NumPy) that builds them, so the two sides of the density stay
together.
"""
import math

import numpy as np

from .constants import HALF, LUM_B, LUM_G, LUM_R, ONE, PI, TWO_PI, ZERO
from .device import device
from .fmath import acos_f32, atan2_f32
from .layout import ENV_DENSITY, ENV_ROT, ENV_TEXEL_WIDTH
from .loads import load4_texel, prefetch
from .textures import bilinear_blend, bilinear_cell
from .warps import sincos

INV_TWO_PI = np.float32(1.0 / (2.0 * np.pi))
INV_PI_F = np.float32(1.0 / np.pi)
TWO_PI_SQ = np.float32(2.0 * np.pi * np.pi)


@device
def env_uv(env_info, d):
    """Texture coordinates (u, v) in [0, 1] of world direction d (turned into the map's
    frame by env_info's rotation: any orientation, as Mitsuba's envmap to_world)."""
    x = (env_info[ENV_ROT] * d[0] + env_info[ENV_ROT + 1] * d[1] +
         env_info[ENV_ROT + 2] * d[2])
    y = (env_info[ENV_ROT + 3] * d[0] + env_info[ENV_ROT + 4] * d[1] +
         env_info[ENV_ROT + 5] * d[2])
    z = (env_info[ENV_ROT + 6] * d[0] + env_info[ENV_ROT + 7] * d[1] +
         env_info[ENV_ROT + 8] * d[2])
    y = min(max(y, -ONE), ONE)
    u = HALF + atan2_f32(x, -z) * INV_TWO_PI
    v = acos_f32(y) * INV_PI_F
    return u, v, y


@device
def env_cell(w, h, u, v):
    """The four texels (columns i0, i1, rows j0, j1) around (u, v) of a W x H map, wrapping
    in u and clamping in v, and the fractions (fx, fy) between them: the one bilinear
    lookup of the radiance (env_eval) and of the density (env_pdf)."""
    # float32 sizes: int * float32 would promote to float64
    ix, iy, fx, fy = bilinear_cell(u * np.float32(w), v * np.float32(h))
    # u lies in [0, 1], so ix in [-1, w - 1]: a compare, not an integer division (a NaN
    # direction's index is clamped: no lookup reads outside the map)
    i0 = ix + w if ix < 0 else ix
    i0 = min(max(i0, 0), w - 1)
    i1 = i0 + 1
    if i1 >= w:
        i1 = 0
    return i0, i1, min(max(iy, 0), h - 1), min(max(iy + 1, 0), h - 1), fx, fy


@device
def cell_texels(env_img, i0, i1, j0, j1):
    """The four texels (r, g, b, density) of an env_cell, a 16-byte load each."""
    return (load4_texel(env_img, j0, i0), load4_texel(env_img, j0, i1),
            load4_texel(env_img, j1, i0), load4_texel(env_img, j1, i1))


@device
def radiance_in_cell(env_img, i0, i1, j0, j1, fx, fy):
    """The bilinear blend of the radiance of the four texels of an env_cell."""
    t00, t10, t01, t11 = cell_texels(env_img, i0, i1, j0, j1)
    return bilinear_blend(t00, t10, t01, t11, fx, fy)


@device
def density_in_texels(t00, t10, t01, t11, fx, fy, sin_t):
    """The solid-angle density at a point of an env_cell (its texels, fractions fx, fy)
    whose direction has sin theta sin_t > 0: the bilinear blend of the texel-centre
    densities over the Jacobian."""
    a = t00[ENV_DENSITY] + fx * (t10[ENV_DENSITY] - t00[ENV_DENSITY])
    b = t01[ENV_DENSITY] + fx * (t11[ENV_DENSITY] - t01[ENV_DENSITY])
    return (a + fy * (b - a)) / (TWO_PI_SQ * sin_t)


@device
def env_eval(env_img, env_info, d):
    """Radiance arriving from direction d (bilinear)."""
    h = env_img.shape[0]
    w = env_img.shape[1]
    u, v, _ = env_uv(env_info, d)
    i0, i1, j0, j1, fx, fy = env_cell(w, h, u, v)
    return radiance_in_cell(env_img, i0, i1, j0, j1, fx, fy)


@device
def env_pdf(env_img, env_info, d):
    """Solid-angle density with which env_sample produces direction d: the bilinear
    interpolation of the texel-centre densities, as env_eval interpolates radiance."""
    return env_lookup(env_img, env_info, d, True)[1]


@device
def env_lookup(env_img, env_info, d, with_pdf):
    """(env_eval, env_pdf if with_pdf else 0) of direction d from one mapping to (u, v)
    and one load of the cell's texels: what a ray that escaped needs."""
    i0, i1, j0, j1, fx, fy, y = env_locate(env_img, env_info, d)
    return env_lookup_cell(env_img, i0, i1, j0, j1, fx, fy, y, with_pdf)


@device
def env_locate(env_img, env_info, d):
    """The cell of the map that direction d reads (env_cell: i0, i1, j0, j1, fx, fy) and
    d's y (cos theta): env_lookup's first half, which reads no texel (the CPU locates an
    escaped ray's cell when it queues the path and prefetches the texels, and looks them up
    with env_lookup_cell a few paths later: drivers.deferred)."""
    h = env_img.shape[0]
    w = env_img.shape[1]
    u, v, y = env_uv(env_info, d)
    i0, i1, j0, j1, fx, fy = env_cell(w, h, u, v)
    return i0, i1, j0, j1, fx, fy, y


@device
def env_prefetch(env_img, i0, i1, j0, j1):
    """Prefetch the four texels of an env_cell (on the CPU; nothing elsewhere)."""
    prefetch(env_img, j0, i0)
    prefetch(env_img, j0, i1)
    prefetch(env_img, j1, i0)
    prefetch(env_img, j1, i1)


@device
def env_lookup_cell(env_img, i0, i1, j0, j1, fx, fy, y, with_pdf):
    """env_lookup's second half: the radiance and (if with_pdf) the density at a point of
    an env_cell, y its direction's cos theta."""
    t00, t10, t01, t11 = cell_texels(env_img, i0, i1, j0, j1)
    pdf = ZERO
    if with_pdf:
        sin_t = math.sqrt(max(ONE - y * y, ZERO))
        if sin_t > ZERO:
            pdf = density_in_texels(t00, t10, t01, t11, fx, fy, sin_t)
    return bilinear_blend(t00, t10, t01, t11, fx, fy), pdf


@device
def sample_linear(a, b, xi):
    """t in [0, 1] with density proportional to (1 - t) a + t b (a, b >= 0), by inverting
    its CDF: the root of a quadratic, in the form that is stable when a is close to b."""
    den = a + math.sqrt(max(a * a + xi * (b * b - a * a), ZERO))
    if not (den > ZERO):
        return xi
    return min(xi * (a + b) / den, ONE)


@device
def _lerp_row(env_cond, j0, j1, t, i):
    return env_cond[j0, i] + t * (env_cond[j1, i] - env_cond[j0, i])


@device
def env_sample(env_marg, env_cond, env_guide, env_img, env_info, u1, u2, guided):
    """(direction, solid-angle pdf); pdf = 0 means no sample."""
    d, pdf, _, _, _ = env_sample_lit(env_marg, env_cond, env_guide, env_img, env_info, u1,
                                     u2, guided)
    return d, pdf


@device
def env_sample_lit(env_marg, env_cond, env_guide, env_img, env_info, u1, u2, guided):
    """(direction, solid-angle pdf, radiance, u, v): env_sample, the radiance that env_eval
    gives the direction (the bilinear blend at the sampled point of the cell whose texels
    the density was read from: one load of four texels), and its map coordinates.
    ``guided`` (a constant of the caller): the searches start from the guide tables'
    brackets (the CPU), else from all cells (the GPU: see the module's docstring); the
    same cells either way."""
    h = env_img.shape[0]
    w = env_img.shape[1]
    n_guide = env_guide.shape[1] - 1
    # the row cell k lies between texel rows k - 1 and k (clamped: half cells at the ends)
    k = 0
    n = h + 1
    if guided:
        b = min(int(u1 * np.float32(n_guide)), n_guide - 1)
        k = env_guide[h, b]
        n = env_guide[h, b + 1] - k + 1
    while n > 1:
        half = n >> 1
        if env_marg[k + half] <= u1:
            k += half
        n -= half
    span = env_marg[k + 1] - env_marg[k]
    xi = min(max((u1 - env_marg[k]) / span, ZERO), ONE) if span > ZERO else HALF
    j0 = max(k - 1, 0)
    j1 = min(k, h - 1)
    t = sample_linear(env_cond[j0, w], env_cond[j1, w], xi)
    # the column cell i (between texel columns i and i + 1, wrapping) from the row CDF at t,
    # within the union of the two rows' guide brackets (a row without mass has no say)
    target = u2 * _lerp_row(env_cond, j0, j1, t, w)
    lo = 0
    n = w
    if guided:
        b = min(int(u2 * np.float32(n_guide)), n_guide - 1)
        lo0 = env_guide[j0, b]
        hi0 = env_guide[j0, b + 1]
        lo1 = env_guide[j1, b]
        hi1 = env_guide[j1, b + 1]
        if not env_cond[j0, w] > ZERO:
            lo0 = lo1
            hi0 = hi1
        elif not env_cond[j1, w] > ZERO:
            lo1 = lo0
            hi1 = hi0
        lo = min(lo0, lo1)
        n = max(hi0, hi1) - lo + 1
    while n > 1:
        half = n >> 1
        if _lerp_row(env_cond, j0, j1, t, lo + half) <= target:
            lo += half
        n -= half
    c0 = _lerp_row(env_cond, j0, j1, t, lo)
    c1 = _lerp_row(env_cond, j0, j1, t, lo + 1)
    xi2 = min(max((target - c0) / (c1 - c0), ZERO), ONE) if c1 > c0 else HALF
    i1 = lo + 1 if lo + 1 < w else 0
    t00, t10, t01, t11 = cell_texels(env_img, lo, i1, j0, j1)
    a = t00[ENV_DENSITY] + t * (t01[ENV_DENSITY] - t00[ENV_DENSITY])
    b = t10[ENV_DENSITY] + t * (t11[ENV_DENSITY] - t10[ENV_DENSITY])
    s = sample_linear(a, b, xi2)
    p_uv = a + s * (b - a)
    radiance = bilinear_blend(t00, t10, t01, t11, s, t)
    if k == 0:
        v = HALF * t / np.float32(h)
    elif k == h:
        v = (np.float32(h) - HALF + HALF * t) / np.float32(h)
    else:
        v = (np.float32(k) - HALF + t) / np.float32(h)
    u = (np.float32(lo) + HALF + s) / np.float32(w)
    if u >= ONE:
        u -= ONE
    theta = v * PI
    phi = (u - HALF) * TWO_PI
    sin_t, cos_t = sincos(theta)
    sin_p, cos_p = sincos(phi)
    xm = sin_t * sin_p
    zm = -sin_t * cos_p
    # back to the world: the transpose of the rotation
    d = (env_info[ENV_ROT] * xm + env_info[ENV_ROT + 3] * cos_t + env_info[ENV_ROT + 6] * zm,
         env_info[ENV_ROT + 1] * xm + env_info[ENV_ROT + 4] * cos_t +
         env_info[ENV_ROT + 7] * zm,
         env_info[ENV_ROT + 2] * xm + env_info[ENV_ROT + 5] * cos_t +
         env_info[ENV_ROT + 8] * zm)
    if sin_t <= ZERO:
        return d, ZERO, radiance, u, v
    return d, p_uv / (TWO_PI_SQ * sin_t), radiance, u, v


# ---- Host side: the tables the functions above read ----------------------------------------

def guide_size(w, h):
    """G, the number of quantile intervals of the guide tables of a W x H map: about four
    cells of the longer of the two searches (W columns, H + 1 row cells) per interval."""
    return max(max(w, h + 1) // 4, 1)


def guide_table(cum, n_guide):
    """Entry b (0 <= b <= n_guide) of the guide of the cumulative masses ``cum`` (n + 1
    values from 0 over n cells, non-decreasing): the last cell i < n with cum[i] <=
    (b / n_guide) x cum[n]. All n - 1 for a table without mass."""
    cum = np.asarray(cum, np.float64)
    q = np.arange(n_guide + 1, dtype=np.float64) / n_guide * cum[-1]
    g = np.searchsorted(cum, q, side="right") - 1
    return np.clip(g, 0, len(cum) - 2)


def environment_tables(img, compensate=True):
    """(texels, marginal CDF, conditional cumulative masses, guide tables) of an
    equirectangular map (float H x W x 3, linear radiance): texels H x W x 4, the radiance
    and the density at the texel's centre (layout ENV_DENSITY); or None when the map is
    black everywhere. NumPy, on the host: the bilinear 2-D distribution that :func:`env_sample`
    draws from and :func:`env_pdf` evaluates.

    compensate: sample in proportion to max(luminance - mean luminance, 0) rather than to the
    luminance (MIS compensation, Karlik et al. 2019, "MIS Compensation: Optimizing Sampling
    Techniques in Multiple Importance Sampling"; pbrt-v4's ImageInfiniteLight does the same
    for its light samples). The map is always combined with BSDF sampling by MIS, and BSDF
    sampling alone already handles the part of the sky that is near its average well: the
    light samples go to the bright part, where they help. Still unbiased: where the density
    is 0, the MIS weight of the BSDF sample is 1. A map that is nowhere above its mean (a
    constant one) keeps the plain density."""
    h, w = img.shape[:2]
    lum = np.maximum(img @ np.array([LUM_R, LUM_G, LUM_B], np.float64), 0.0)
    sin_t = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    wgt = lum * sin_t[:, None]
    if compensate and wgt.sum() > 0:
        # the mean over the sphere (texels weighted by their solid angle, ~ sin theta)
        mean = wgt.sum() / (sin_t.sum() * w)
        above = np.maximum(lum - mean, 0.0) * sin_t[:, None]
        # (a map within rounding of its mean: keep the plain density)
        if above.sum() > 1e-6 * wgt.sum():
            wgt = above
    # column cell i spans texel centres i and i + 1 (wrapping): mass (w_i + w_i+1) / 2
    cells = 0.5 * (wgt + np.roll(wgt, -1, axis=1))
    rows = wgt.sum(axis=1)                     # = cells.sum(axis=1)
    # row cells: half a cell above row 0, between rows k - 1 and k, half below row h - 1
    height = np.ones(h + 1)
    height[0] = height[-1] = 0.5
    above = np.concatenate([rows[:1], rows])
    below = np.concatenate([rows, rows[-1:]])
    mass = height * 0.5 * (above + below)
    total = mass.sum()
    if not total > 0:
        return None
    scale = w * h / total                      # so that p(u, v) integrates to 1 over [0,1]^2
    marg = np.concatenate([[0.0], np.cumsum(mass) / total])
    cond = np.zeros((h, w + 1))
    cond[:, 1:] = np.cumsum(cells, axis=1) * scale
    marg = marg.astype(np.float32)
    marg[-1] = 1.0
    cond = cond.astype(np.float32)
    # (the guides of the float32 tables that the sampler searches)
    n_guide = guide_size(w, h)
    guide = np.empty((h + 1, n_guide + 1), np.int32)
    for j in range(h):
        guide[j] = guide_table(cond[j], n_guide)
    guide[h] = guide_table(marg, n_guide)
    texels = np.empty((h, w, ENV_TEXEL_WIDTH), np.float32)
    texels[..., :3] = img
    texels[..., ENV_DENSITY] = wgt * scale
    return texels, marg, cond, guide
