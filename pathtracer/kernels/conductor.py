"""Mitsuba 3's ``conductor`` and ``roughconductor`` BSDFs, term for term: a microfacet
reflector (Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces")
with GGX or Beckmann normals, anisotropic alphas along the tangent (dp/du) and the
bitangent, Smith's separable masking-shadowing, and the exact Fresnel reflectance of a
conductor's complex index of refraction eta + i k per colour channel, times a specular
reflectance (a tint).

Local shading frame and naming as :mod:`.principled`: ``wo`` towards the viewer (Mitsuba's
``si.wi``), ``wi`` the sampled direction; ``eval`` returns f |cos theta_i| (Mitsuba's
``eval``). A smooth conductor (alpha 0, Mitsuba's delta ``conductor``) is the microfacet
lobe at ``ALPHA_MIN``, as the principled BSDF treats roughness 0, so that one code path and
multiple importance sampling serve both.

Sampling: from the visible normals, as Mitsuba (``sample_visible``, its default): GGX's
by Heitz 2018, Beckmann's by Jakob 2014. Beckmann's pdf uses the exact Smith G1 (the
sampler's own density), its value Mitsuba's rational approximation of it (its images), so
a sample's weight is F G1(wi) times their ratio (within 0.4 % of 1). ``conductor_eval``'s
pdf is the density of ``conductor_sample``.

Parameter tuple: the ``P_COND_*`` fields of :mod:`.layout` (P_BASE: the tint).
"""
import math

import numpy as np

from .constants import HALF, ONE, TWO, ZERO
from .device import device
from .layout import (P_BASE, P_COND_ALPHA_U, P_COND_ALPHA_V, P_COND_DISTRIBUTION,
                     P_COND_ETA, P_COND_K)
from .principled import (ALPHA_MIN, PI, TINY, ggx_d, ggx_g1, ggx_pdf_visible,
                         ggx_sample_visible, reflect_about)
from .vec import dot, normalize
from .warps import square_to_disk_concentric

FOUR = np.float32(4.0)
# Mitsuba's rational fit of Smith's Beckmann masking (microfacet.h, smith_g1; Walter et
# al. 2007, eq. 27)
BK_A_MAX = np.float32(1.6)
BK_C1 = np.float32(3.535)
BK_C2 = np.float32(2.181)
BK_C3 = np.float32(2.276)
BK_C4 = np.float32(2.577)
ONE_MINUS_TINY = np.float32(1.0 - 2.0 ** -24)
THREE = np.float32(3.0)
SQRT_PI_INV = np.float32(1.0 / np.sqrt(np.pi))
# Jakob 2014's fit of the inverse slope CDF's exponent, and its Newton iteration
FIT_1 = np.float32(-0.876)
FIT_2 = np.float32(0.4265)
FIT_3 = np.float32(0.0594)
NEWTON_STEPS = 10
NEWTON_TOL = np.float32(1e-5)
U_MIN = np.float32(1e-6)
COS_NORMAL = np.float32(0.9999)
# Giles' single-precision erfinv
ERF_LO = np.float32(-0.99999)
ERF_HI = np.float32(0.99999)
ERF_SPLIT = np.float32(5.0)
ERF_SHIFT = np.float32(2.5)
ERF_A = tuple(np.float32(c) for c in (
    2.81022636e-08, 3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087,
    -0.00125372503, -0.00417768164, 0.246640727, 1.50140941))
ERF_B = tuple(np.float32(c) for c in (
    -0.000200214257, 0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773,
    -0.0076224613, 0.00943887047, 1.00167406, 2.83297682))


@device
def fresnel_conductor(cos_i, eta, k):
    """Unpolarised reflectance of a conductor of complex relative index eta + i k at
    cos_i > 0 (Mitsuba's ``fresnel_conductor``, after K. D. Moeller, "Optics", 1988)."""
    c2 = cos_i * cos_i
    s2 = ONE - c2
    s4 = s2 * s2
    t1 = eta * eta - k * k - s2
    a2pb2 = math.sqrt(max(t1 * t1 + FOUR * k * k * eta * eta, ZERO))
    a = math.sqrt(max(HALF * (a2pb2 + t1), ZERO))
    t2 = TWO * cos_i * a
    r_s = (a2pb2 + c2 - t2) / (a2pb2 + c2 + t2)
    t3 = a2pb2 * c2 + s4
    t4 = t2 * s2
    r_p = r_s * (t3 - t4) / (t3 + t4)
    return HALF * (r_s + r_p)


@device
def beckmann_d(m, ax, ay):
    """Anisotropic Beckmann distribution D(m) (Mitsuba's ``MicrofacetDistribution::eval``)."""
    c2 = m[2] * m[2]
    if not (c2 > ZERO):
        return ZERO
    x = m[0] / ax
    y = m[1] / ay
    d = math.exp(-(x * x + y * y) / c2) / (PI * ax * ay * c2 * c2)
    return d if d * m[2] > TINY else ZERO


@device
def beckmann_g1(v, m, ax, ay):
    """Smith's masking for Beckmann, Mitsuba's rational approximation; 0 if v sees the
    back of m."""
    if dot(v, m) * v[2] <= ZERO:
        return ZERO
    xy = (ax * v[0]) * (ax * v[0]) + (ay * v[1]) * (ay * v[1])
    if xy == ZERO:
        return ONE
    a = abs(v[2]) / math.sqrt(xy)
    if a >= BK_A_MAX:
        return ONE
    return (BK_C1 * a + BK_C2 * a * a) / (ONE + BK_C3 * a + BK_C4 * a * a)


@device
def erf_inv(x):
    """The inverse error function (Giles 2011, "Approximating the erfinv function", GPU
    Computing Gems Jade, single-precision branch), x clamped inside (-1, 1)."""
    x = min(max(x, ERF_LO), ERF_HI)
    w = -math.log((ONE - x) * (ONE + x))
    if w < ERF_SPLIT:
        w = w - ERF_SHIFT
        p = ERF_A[0]
        p = ERF_A[1] + p * w
        p = ERF_A[2] + p * w
        p = ERF_A[3] + p * w
        p = ERF_A[4] + p * w
        p = ERF_A[5] + p * w
        p = ERF_A[6] + p * w
        p = ERF_A[7] + p * w
        p = ERF_A[8] + p * w
    else:
        w = math.sqrt(w) - THREE
        p = ERF_B[0]
        p = ERF_B[1] + p * w
        p = ERF_B[2] + p * w
        p = ERF_B[3] + p * w
        p = ERF_B[4] + p * w
        p = ERF_B[5] + p * w
        p = ERF_B[6] + p * w
        p = ERF_B[7] + p * w
        p = ERF_B[8] + p * w
    return p * x


@device
def beckmann_slopes(cos_i, u1, u2):
    """Slopes (x, y) of a Beckmann microfacet (alpha 1) visible from a direction at cos_i
    in the xz-plane: Jakob 2014, "An Improved Visible Normal Sampling Routine for the
    Beckmann Distribution" (as Mitsuba and pbrt-v3): x by inverting the slope's CDF (a
    fitted first guess, then safeguarded Newton steps in the erf domain), y a Gaussian."""
    if cos_i > COS_NORMAL:
        # head-on: a 2D Gaussian, its direction and squared radius from the concentric
        # disk point (uniform, independent: no trigonometry, whose float32 range
        # reduction compiles to float64 on the GPU)
        x, y = square_to_disk_concentric(u1, u2)
        r2 = x * x + y * y
        if not (r2 > ZERO):
            return ZERO, ZERO
        k = math.sqrt(-math.log(ONE - min(r2, ONE_MINUS_TINY)) / r2)
        return k * x, k * y
    u1 = max(u1, U_MIN)
    sin_i = math.sqrt(max(ONE - cos_i * cos_i, ZERO))
    tan_i = sin_i / cos_i
    cot_i = ONE / tan_i
    lo = -ONE
    hi = math.erf(cot_i)
    theta_i = math.acos(cos_i)
    fit = ONE + theta_i * (FIT_1 + theta_i * (FIT_2 - FIT_3 * theta_i))
    b = hi - (ONE + hi) * math.pow(ONE - u1, fit)
    norm = ONE / (ONE + hi + SQRT_PI_INV * tan_i * math.exp(-cot_i * cot_i))
    for _ in range(NEWTON_STEPS):
        if not (b >= lo and b <= hi):
            b = HALF * (lo + hi)
        x = erf_inv(b)
        value = norm * (ONE + b + SQRT_PI_INV * tan_i * math.exp(-x * x)) - u1
        if abs(value) < NEWTON_TOL:
            break
        if value > ZERO:
            hi = b
        else:
            lo = b
        b -= value / (norm * (ONE - x * tan_i))
    return erf_inv(b), erf_inv(TWO * max(u2, U_MIN) - ONE)


@device
def beckmann_sample_visible(v, ax, ay, u1, u2):
    """A microfacet normal from the visible-normal distribution of anisotropic Beckmann
    seen from v (v.z > 0): v stretched to the alpha-1 configuration, slopes drawn there
    (beckmann_slopes), rotated to v's azimuth and stretched back."""
    vs = normalize((ax * v[0], ay * v[1], v[2]))
    sxy = math.sqrt(vs[0] * vs[0] + vs[1] * vs[1])
    cos_phi = ONE
    sin_phi = ZERO
    if sxy > ZERO:
        cos_phi = vs[0] / sxy
        sin_phi = vs[1] / sxy
    sx, sy = beckmann_slopes(vs[2], u1, u2)
    x = cos_phi * sx - sin_phi * sy
    y = sin_phi * sx + cos_phi * sy
    return normalize((-ax * x, -ay * y, ONE))


@device
def beckmann_g1_exact(v, m, ax, ay):
    """Smith's masking for Beckmann, exact (Walter et al. 2007, eq. 25): the visible-normal
    density of beckmann_sample_visible is D G1 |v.m| / v.z with this G1."""
    if dot(v, m) * v[2] <= ZERO:
        return ZERO
    xy = (ax * v[0]) * (ax * v[0]) + (ay * v[1]) * (ay * v[1])
    if xy == ZERO:
        return ONE
    a = abs(v[2]) / math.sqrt(xy)
    lam = (math.erf(a) - ONE) * HALF + math.exp(-a * a) / (TWO * a) * SQRT_PI_INV
    return ONE / (ONE + lam)


@device
def beckmann_pdf_visible(v, m, ax, ay):
    return beckmann_d(m, ax, ay) * beckmann_g1_exact(v, m, ax, ay) * abs(dot(v, m)) / v[2]


@device
def conductor_alphas(params):
    return (max(ALPHA_MIN, params[P_COND_ALPHA_U]), max(ALPHA_MIN, params[P_COND_ALPHA_V]))


@device
def conductor_eval(params, wo, wi):
    """(f(wo, wi) |cos theta_i| as rgb, pdf of conductor_sample producing wi)."""
    if wo[2] <= ZERO or wi[2] <= ZERO:
        return (ZERO, ZERO, ZERO), ZERO
    ax, ay = conductor_alphas(params)
    h = normalize((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]))
    wo_h = dot(wo, h)
    if params[P_COND_DISTRIBUTION] > HALF:
        d = beckmann_d(h, ax, ay)
        g = beckmann_g1(wo, h, ax, ay) * beckmann_g1(wi, h, ax, ay)
        pdf = beckmann_pdf_visible(wo, h, ax, ay) / (FOUR * wo_h) if wo_h > ZERO else ZERO
    else:
        d = ggx_d(h, ax, ay)
        g = ggx_g1(wo, h, ax, ay) * ggx_g1(wi, h, ax, ay)
        pdf = ggx_pdf_visible(wo, h, ax, ay) / (FOUR * wo_h) if wo_h > ZERO else ZERO
    v = d * g / (FOUR * wo[2])
    if not (v > ZERO):
        return (ZERO, ZERO, ZERO), pdf
    c = min(wo_h, ONE)
    return ((params[P_BASE] * v *
             fresnel_conductor(c, params[P_COND_ETA], params[P_COND_K])),
            (params[P_BASE + 1] * v *
             fresnel_conductor(c, params[P_COND_ETA + 1], params[P_COND_K + 1])),
            (params[P_BASE + 2] * v *
             fresnel_conductor(c, params[P_COND_ETA + 2], params[P_COND_K + 2]))), pdf


@device
def conductor_sample(params, wo, u1, u2):
    """(wi, weight = f |cos| / pdf, pdf); pdf = 0 means no sample."""
    if wo[2] <= ZERO:
        return (ZERO, ZERO, ONE), (ZERO, ZERO, ZERO), ZERO
    ax, ay = conductor_alphas(params)
    if params[P_COND_DISTRIBUTION] > HALF:
        m = beckmann_sample_visible(wo, ax, ay, u1, u2)
    else:
        m = ggx_sample_visible(wo, ax, ay, u1, u2)
    wi = reflect_about(wo, m)
    if wi[2] <= ZERO:
        return wi, (ZERO, ZERO, ZERO), ZERO
    f, pdf = conductor_eval(params, wo, wi)
    if not (pdf > ZERO):
        return wi, (ZERO, ZERO, ZERO), ZERO
    inv = ONE / pdf
    return wi, (f[0] * inv, f[1] * inv, f[2] * inv), pdf
