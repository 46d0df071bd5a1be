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

Sampling: GGX from its visible normals (Heitz 2018), as Mitsuba (``sample_visible``, its
default); Beckmann from D(m) cos theta_m (Walter et al. 2007, eq. 28, drawn as Gaussian
slopes), whose density differs from Mitsuba's visible-normal sampler but not the value
estimated. ``conductor_pdf`` is the density of ``conductor_sample``.

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

FOUR = np.float32(4.0)
# Mitsuba's rational fit of Smith's Beckmann masking (microfacet.h, smith_g1; Walter et
# al. 2007, eq. 27)
BK_A_MAX = np.float32(1.6)
BK_C1 = np.float32(3.535)
BK_C2 = np.float32(2.181)
BK_C3 = np.float32(2.276)
BK_C4 = np.float32(2.577)
ONE_MINUS_TINY = np.float32(1.0 - 2.0 ** -24)


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
def beckmann_sample(ax, ay, u1, u2):
    """A normal with density D(m) cos theta_m: the slopes of Beckmann microfacets are
    Gaussian, (x, y) = r (ax cos phi, ay sin phi) with r^2 = -log(1 - u1)."""
    r = math.sqrt(-math.log(ONE - min(u1, ONE_MINUS_TINY)))
    phi = TWO * PI * u2
    return normalize((-r * ax * math.cos(phi), -r * ay * math.sin(phi), ONE))


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
        pdf = d * h[2] / (FOUR * wo_h) if wo_h > ZERO else ZERO
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
        m = beckmann_sample(ax, ay, u1, u2)
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
