"""Environment map: an equirectangular image lit from infinitely far away.

Mapping (scene format): a world direction d is first turned by -rotation about +Y, then
u = 0.5 + atan2(d.x, -d.z) / (2 pi), v = acos(d.y) / pi (v = 0: top row), and the image is
read bilinearly with texel centres at ((i + 0.5) / W, (j + 0.5) / H), wrapping in u and
clamping in v.

Importance sampling (Pharr, Jakob, Humphreys, PBRT 3rd ed., sec. 14.2.4): a piecewise-
constant 2-D distribution over the W x H cells of [0,1]^2, a marginal over rows and a
conditional per row. A cell's weight is its mean luminance under the bilinear
reconstruction times sin(theta) of its centre. A point (u, v) drawn uniformly inside the
chosen cell maps to a direction with solid-angle density p(u, v) / (2 pi^2 sin theta):
the Jacobian of the mapping, exact (the thesis renderer used 2 pi sin theta, pi too large).

Arrays: ``env_img`` (H, W, 3) radiance with the intensity applied; ``env_marg`` (H + 1,)
and ``env_cond`` (H, W + 1) CDFs; ``env_pdf`` (H, W) the density p(u, v) of each cell;
``env_info`` (see :mod:`.layout`): the rotation's cosine and sine and the probability that
next-event estimation picks the environment.

The device functions sample and evaluate these tables; :func:`environment_tables`, beside
them, is the host code (NumPy) that builds them, so the two sides of the density stay
together.
"""
import math

import numpy as np

from .constants import HALF, LUM_B, LUM_G, LUM_R, ONE, PI, TWO_PI, ZERO
from .device import device
from .layout import ENV_COS_ROT, ENV_SIN_ROT
from .lights import sample_discrete
from .textures import bilinear_blend, bilinear_cell
from .warps import sincos

INV_TWO_PI = np.float32(1.0 / (2.0 * np.pi))
INV_PI_F = np.float32(1.0 / np.pi)
TWO_PI_SQ = np.float32(2.0 * np.pi * np.pi)


@device
def env_uv(env_info, d):
    """Texture coordinates (u, v) in [0, 1] of world direction d."""
    c = env_info[ENV_COS_ROT]
    s = env_info[ENV_SIN_ROT]
    x = d[0] * c - d[2] * s
    z = d[0] * s + d[2] * c
    y = min(max(d[1], -ONE), ONE)
    u = HALF + math.atan2(x, -z) * INV_TWO_PI
    v = math.acos(y) * INV_PI_F
    return u, v, y


@device
def env_eval(env_img, env_info, d):
    """Radiance arriving from direction d (bilinear)."""
    h = env_img.shape[0]
    w = env_img.shape[1]
    u, v, _ = env_uv(env_info, d)
    # float32 sizes: int * float32 would promote to float64
    ix, iy, fx, fy = bilinear_cell(u * np.float32(w), v * np.float32(h))
    i0 = ix % w
    if i0 < 0:
        i0 += w
    i1 = i0 + 1
    if i1 >= w:
        i1 = 0
    j0 = min(max(iy, 0), h - 1)
    j1 = min(max(iy + 1, 0), h - 1)
    return bilinear_blend(
        (env_img[j0, i0, 0], env_img[j0, i0, 1], env_img[j0, i0, 2]),
        (env_img[j0, i1, 0], env_img[j0, i1, 1], env_img[j0, i1, 2]),
        (env_img[j1, i0, 0], env_img[j1, i0, 1], env_img[j1, i0, 2]),
        (env_img[j1, i1, 0], env_img[j1, i1, 1], env_img[j1, i1, 2]), fx, fy)


@device
def env_pdf(env_pdf_arr, env_info, d):
    """Solid-angle density with which env_sample produces direction d."""
    h = env_pdf_arr.shape[0]
    w = env_pdf_arr.shape[1]
    u, v, y = env_uv(env_info, d)
    sin_t = math.sqrt(max(ONE - y * y, ZERO))
    if sin_t <= ZERO:
        return ZERO
    i = min(max(int(u * np.float32(w)), 0), w - 1)
    j = min(max(int(v * np.float32(h)), 0), h - 1)
    return env_pdf_arr[j, i] / (TWO_PI_SQ * sin_t)


@device
def env_sample(env_marg, env_cond, env_pdf_arr, env_info, u1, u2):
    """(direction, solid-angle pdf); pdf = 0 means no sample."""
    h = env_pdf_arr.shape[0]
    w = env_pdf_arr.shape[1]
    j = sample_discrete(env_marg, u1)
    span = env_marg[j + 1] - env_marg[j]
    fv = (u1 - env_marg[j]) / span if span > ZERO else HALF
    i = sample_discrete(env_cond[j], u2)
    span = env_cond[j, i + 1] - env_cond[j, i]
    fu = (u2 - env_cond[j, i]) / span if span > ZERO else HALF
    fv = min(max(fv, ZERO), ONE)
    fu = min(max(fu, ZERO), ONE)
    v = (np.float32(j) + fv) / np.float32(h)
    u = (np.float32(i) + fu) / np.float32(w)
    theta = v * PI
    phi = (u - HALF) * TWO_PI
    sin_t, cos_t = sincos(theta)
    sin_p, cos_p = sincos(phi)
    xm = sin_t * sin_p
    zm = -sin_t * cos_p
    c = env_info[ENV_COS_ROT]
    s = env_info[ENV_SIN_ROT]
    d = (xm * c + zm * s, cos_t, -xm * s + zm * c)
    if sin_t <= ZERO:
        return d, ZERO
    return d, env_pdf_arr[j, i] / (TWO_PI_SQ * sin_t)


# ---- Host side: the tables the functions above read ----------------------------------------

def environment_tables(img):
    """(image, marginal CDF, conditional CDFs, cell densities) of an equirectangular map
    (float H x W x 3, linear radiance), or None when it is black everywhere. NumPy, on the
    host: the piecewise-constant 2-D distribution that :func:`env_sample` draws from and
    :func:`env_pdf` evaluates."""
    h, w = img.shape[:2]
    lum = img @ np.array([LUM_R, LUM_G, LUM_B], np.float64)
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
