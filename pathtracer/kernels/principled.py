"""The principled BSDF (Burley 2012, "Physically Based Shading at Disney"; Burley 2015,
"Extending the Disney BRDF to a BSDF with Integrated Subsurface Scattering"), following
Mitsuba 3's ``principled`` plugin term for term wherever the papers leave a choice, so
that every parameter can be checked against it.

All functions work in the local shading frame (z = shading normal) and use this project's
naming: ``wo`` points to where the light goes (the viewer), ``wi`` to where it comes from
(the sampled direction). Mitsuba calls these ``si.wi`` and ``wo``. ``eval`` returns the BSDF
times |cos theta_i| (as Mitsuba's ``eval``), so ``weight = eval / pdf``.

``params`` is the tuple of parameters (the ``P_*`` fields of :mod:`.layout`), already read
from the material (and its textures) at the shading point. ``eta`` is the interior/exterior index; the side
of ``wo`` (wo.z > 0: outside) decides which way the interface is crossed.

Lobes (Mitsuba's names): diffuse with retro-reflection and Hanrahan-Krueger flattening
("subsurface" / flatness), sheen, the main specular lobe (anisotropic GGX, reflection and,
with ``transmission``, refraction: Walter et al. 2007), and the clearcoat (GTR1, fixed
alpha 0.25 masking). GGX directions are drawn from the distribution of visible normals
(Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4)); the pdf below
is that density, D G1 |wo.m| / |cos theta_o| (the same one Mitsuba's sampler has).

Lobe selection follows Mitsuba: with wo outside, diffuse : clearcoat : specular =
brdf : clearcoat/4 : 1, and the specular part refracts with probability
bsdf * (1 - F(m)) for the sampled microfacet m; inside, reflection F and refraction 1 - F.
The selection probabilities of the diffuse and clearcoat lobes do not depend on m, so the
pdf below is exactly the density of ``principled_sample``.
"""
import functools
import math
from typing import NamedTuple

import numpy as np

from .constants import HALF, INV_PI, ONE, ONE_MINUS_EPS, TWO, ZERO
from .device import device
from .layout import (P_ANISOTROPIC, P_BASE, P_CLEARCOAT, P_CLEARCOAT_GLOSS, P_ETA, P_FLATNESS,
                     P_METALLIC, P_ROUGHNESS, P_SHEEN, P_SHEEN_TINT, P_SPEC_TINT,
                     P_TRANSMISSION)
from .vec import dot, luminance, normalize
from .warps import square_to_cosine_hemisphere, square_to_disk_concentric


TINY = np.float32(1e-20)
ALPHA_MIN = np.float32(0.001)
FOUR = np.float32(4.0)
QUARTER = np.float32(0.25)
CC_ALPHA_HI = np.float32(0.1)
CC_ALPHA_LO = np.float32(0.001)
CC_MASK_ALPHA = np.float32(0.25)
ANISO_K = np.float32(0.9)
SS_K = np.float32(1.25)
F0_CLEARCOAT = np.float32(0.04)
# the dielectric specular lobe's selection weight never falls below this fraction of the
# diffuse lobe's (see spec_weight)
SPEC_SELECT_FLOOR = np.float32(0.25)
PI = np.float32(np.pi)


@device
def sign_of(x):
    return ONE if x >= ZERO else -ONE


@device
def schlick_weight(c):
    m = min(max(ONE - c, ZERO), ONE)
    m2 = m * m
    return m2 * m2 * m


@device
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance for an interface of relative index eta (interior /
    exterior); cos_i < 0 means the ray arrives from inside. Returns (F, cos_t, eta_it,
    eta_ti) as Mitsuba's ``fresnel``; cos_t has the sign opposite to cos_i."""
    outside = cos_i >= ZERO
    rcp_eta = ONE / eta
    eta_it = eta if outside else rcp_eta
    eta_ti = rcp_eta if outside else eta
    cos_t_sqr = ONE - eta_ti * eta_ti * (ONE - cos_i * cos_i)
    ci = abs(cos_i)
    ct = math.sqrt(max(cos_t_sqr, ZERO))
    if eta == ONE:
        f = ZERO
    elif ci == ZERO:
        f = ONE
    else:
        a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
        a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
        f = HALF * (a_s * a_s + a_p * a_p)
    cos_t = -ct if cos_i >= ZERO else ct
    return f, cos_t, eta_it, eta_ti


@device
def schlick_fresnel(r0, cos_i, eta):
    """Mitsuba's ``calc_schlick``: Schlick's approximation, evaluated with the transmitted
    angle when the ray goes towards the optically thinner side."""
    outside = cos_i >= ZERO
    eta_it = eta if outside else ONE / eta
    eta_ti = ONE / eta if outside else eta
    cos_t = math.sqrt(max(ONE - (ONE - cos_i * cos_i) * eta_ti * eta_ti, ZERO))
    w = schlick_weight(abs(cos_i)) if eta_it > ONE else schlick_weight(cos_t)
    return r0 + (ONE - r0) * w


@device
def schlick_r0(eta):
    """Reflectance at normal incidence of a dielectric interface of relative index eta."""
    r0 = (eta - ONE) / (eta + ONE)
    return r0 * r0


@device
def spec_weight(metallic, brdf, bsdf, eta, cos_o):
    """The specular lobe's selection weight on the front side, beside the diffuse lobe's
    ``brdf`` and the clearcoat's: the metallic and transmitting parts whole, the dielectric
    reflection by its Fresnel reflectance at wo (Schlick's, from eta), so that a plastic
    (F0 = 0.04) spends its BSDF samples on the diffuse light it mostly reflects, as a
    selection in proportion to each lobe's albedo does (Cycles weights its closures so).
    The floor (SPEC_SELECT_FLOOR of the diffuse weight) keeps BSDF samples for the
    highlights of large lights in a sharp lobe, which light sampling finds poorly. A weight
    of 1 (Mitsuba's choice) spent half of a plastic's samples on the specular lobe: on
    bunny-studio the new weights lower relMSE at 64 spp by 17 % (docs/benchmarks.md)."""
    r0 = schlick_r0(eta)
    f = r0 + (ONE - r0) * schlick_weight(abs(cos_o))
    return metallic + bsdf + brdf * max(f, SPEC_SELECT_FLOOR)


@device
def reuse_sample(x, start, width):
    """A uniform number x in [start, start + width), which chose that interval, stretched
    back to a uniform number in [0, 1) (sample reuse, as in pbrt's and Mitsuba's lobe
    selection): stratified x give stratified results within each interval."""
    return min(max((x - start) / width, ZERO), ONE_MINUS_EPS)


@device
def ggx_alphas(roughness, anisotropic):
    """Burley 2012 addendum: alpha = roughness^2, stretched by sqrt(1 - 0.9 anisotropic)."""
    r2 = roughness * roughness
    aspect = math.sqrt(ONE - ANISO_K * anisotropic)
    return max(ALPHA_MIN, r2 / aspect), max(ALPHA_MIN, r2 * aspect)


@device
def ggx_d(m, ax, ay):
    """Anisotropic GGX normal distribution D(m) (Walter et al. 2007; Burley 2012)."""
    x = m[0] / ax
    y = m[1] / ay
    s = x * x + y * y + m[2] * m[2]
    d = ONE / (PI * ax * ay * s * s)
    return d if d * m[2] > TINY else ZERO


@device
def ggx_g1(v, m, ax, ay):
    """Smith's masking for anisotropic GGX; 0 if v sees the back of m."""
    xy = (ax * v[0]) * (ax * v[0]) + (ay * v[1]) * (ay * v[1])
    if dot(v, m) * v[2] <= ZERO:
        return ZERO
    if xy == ZERO:
        return ONE
    t = xy / (v[2] * v[2])
    return TWO / (ONE + math.sqrt(ONE + t))


@device
def ggx_sample_visible(v, ax, ay, u1, u2):
    """A microfacet normal from the visible-normal distribution seen from v (v.z > 0).
    Heitz 2018, with the disk point from the concentric map (no trigonometry)."""
    vh = normalize((ax * v[0], ay * v[1], v[2]))
    lensq = vh[0] * vh[0] + vh[1] * vh[1]
    if lensq > ZERO:
        inv = ONE / math.sqrt(lensq)
        t1 = (-vh[1] * inv, vh[0] * inv, ZERO)
    else:
        t1 = (ONE, ZERO, ZERO)
    t2 = (vh[1] * t1[2] - vh[2] * t1[1], vh[2] * t1[0] - vh[0] * t1[2],
          vh[0] * t1[1] - vh[1] * t1[0])
    p1, p2 = square_to_disk_concentric(u1, u2)
    s = HALF * (ONE + vh[2])
    p2 = (ONE - s) * math.sqrt(max(ONE - p1 * p1, ZERO)) + s * p2
    p3 = math.sqrt(max(ONE - p1 * p1 - p2 * p2, ZERO))
    nh = (p1 * t1[0] + p2 * t2[0] + p3 * vh[0], p1 * t1[1] + p2 * t2[1] + p3 * vh[1],
          p1 * t1[2] + p2 * t2[2] + p3 * vh[2])
    return normalize((ax * nh[0], ay * nh[1], max(nh[2], ZERO)))


@device
def ggx_pdf_visible(v, m, ax, ay):
    """Density of ggx_sample_visible: D(m) G1(v, m) |v.m| / v.z (v.z > 0)."""
    return ggx_d(m, ax, ay) * ggx_g1(v, m, ax, ay) * abs(dot(v, m)) / v[2]


@device
def gtr1_d(m, alpha):
    """Burley's GTR1 (Berry) distribution of the clearcoat."""
    a2 = alpha * alpha
    c2 = m[2] * m[2]
    d = (a2 - ONE) / (PI * math.log(a2) * (ONE + (a2 - ONE) * c2))
    return d if d * m[2] > TINY else ZERO


@device
def gtr1_sample(alpha, u1, u2):
    """A normal with density D(m) cos theta_m. The azimuth comes from the concentric disk
    point's direction and cos^2 theta from its squared radius (uniform, independent)."""
    x, y = square_to_disk_concentric(u1, u2)
    r2 = x * x + y * y
    a2 = alpha * alpha
    cos2 = (ONE - math.exp((ONE - r2) * math.log(a2))) / (ONE - a2)
    cos_t = math.sqrt(min(max(cos2, ZERO), ONE))
    sin_t = math.sqrt(max(ONE - cos2, ZERO))
    if r2 > ZERO:
        inv = ONE / math.sqrt(r2)
        return (x * inv * sin_t, y * inv * sin_t, cos_t)
    return (sin_t, ZERO, cos_t)


@device
def smith_ggx1(v, m, alpha):
    """Isotropic GGX masking of the clearcoat (Mitsuba's ``smith_ggx1``)."""
    c = abs(v[2])
    c2 = c * c
    if v[2] == ONE:
        res = ONE
    else:
        t2 = (ONE - c2) / c2
        res = TWO / (ONE + math.sqrt(ONE + alpha * alpha * t2))
    if dot(v, m) * v[2] <= ZERO:
        return ZERO
    return res


@device
def mac_mic_compatible(m, wo, wi, cos_o, reflection):
    """Macro- and microsurface agree: wo (and wi) on the facet's side for reflection,
    wi on the other side for refraction."""
    s = sign_of(cos_o)
    a = dot(wo, m) * s
    b = dot(wi, m) * s
    if reflection:
        return a > ZERO and b > ZERO
    return a > ZERO and b < ZERO


@device
def reflect_about(w, m):
    k = TWO * dot(w, m)
    return (k * m[0] - w[0], k * m[1] - w[1], k * m[2] - w[2])


class Lobes(NamedTuple):
    """Which optional parts of the principled BSDF a kernel compiles (False: the scene's
    materials leave that parameter at 0 everywhere, so the part would add nothing). The
    specialised functions compute the same numbers as the full ones for such materials: a
    zero parameter's terms are skipped, not approximated. Compiling the unused lobes out
    shortens the GPU kernel, which the HDRI scenes' warps wait on for instructions (see
    docs/benchmarks.md)."""
    dielectric: bool = True    # False: every material is all metal (metallic 1)
    clearcoat: bool = True
    sheen: bool = True
    transmission: bool = True
    flatness: bool = True
    spec_tint: bool = True
    anisotropic: bool = True


ALL_LOBES = Lobes()


@functools.lru_cache(maxsize=None)
def make_principled(lobes=ALL_LOBES):
    """(principled_eval, principled_sample) compiling only the lobes in ``lobes``."""
    DIELECTRIC, CLEARCOAT, SHEEN, TRANSMISSION, FLATNESS, SPEC_TINT, ANISOTROPIC = (
        bool(x) for x in lobes)

    @device
    def lobe_weights(params, metallic):
        """(brdf, bsdf): the weights of the diffuse-reflecting and the transmitting part."""
        if TRANSMISSION:
            spec_trans = params[P_TRANSMISSION]
            return (ONE - metallic) * (ONE - spec_trans), (ONE - metallic) * spec_trans
        return ONE - metallic, ZERO

    @device
    def principled_eval(params, wo, wi):
        """(f(wo, wi) |cos theta_i| as rgb, pdf of principled_sample producing wi)."""
        base_r = params[P_BASE]
        base_g = params[P_BASE + 1]
        base_b = params[P_BASE + 2]
        roughness = params[P_ROUGHNESS]
        metallic = params[P_METALLIC] if DIELECTRIC else ONE
        eta = params[P_ETA]
        # A lobe the scene's materials never use is a constant zero: its code is not compiled.
        spec_tint = params[P_SPEC_TINT] if SPEC_TINT else ZERO
        anisotropic = params[P_ANISOTROPIC] if ANISOTROPIC else ZERO
        sheen = params[P_SHEEN] if SHEEN else ZERO
        sheen_tint = params[P_SHEEN_TINT] if SHEEN else ZERO
        clearcoat = params[P_CLEARCOAT] if CLEARCOAT else ZERO
        cc_gloss = params[P_CLEARCOAT_GLOSS] if CLEARCOAT else ZERO
        flatness = params[P_FLATNESS] if FLATNESS else ZERO
        cos_o = wo[2]
        cos_i = wi[2]
        if cos_o == ZERO or cos_i == ZERO:
            return (ZERO, ZERO, ZERO), ZERO
        brdf, bsdf = lobe_weights(params, metallic)
        reflect = cos_o * cos_i > ZERO
        front = cos_o > ZERO
        eta_path = eta if front else ONE / eta
        ax, ay = ggx_alphas(roughness, anisotropic)

        k = ONE if reflect else eta_path
        wh = normalize((wo[0] + wi[0] * k, wo[1] + wi[1] * k, wo[2] + wi[2] * k))
        if wh[2] < ZERO:
            wh = (-wh[0], -wh[1], -wh[2])
        wo_h = dot(wo, wh)
        wi_h = dot(wi, wh)
        f_diel, _, eta_it, _ = fresnel_dielectric(wo_h, eta)
        compat = mac_mic_compatible(wh, wo, wi, cos_o, reflect)

        vr = ZERO
        vg = ZERO
        vb = ZERO
        d = ggx_d(wh, ax, ay)
        g = ggx_g1(wo, wh, ax, ay) * ggx_g1(wi, wh, ax, ay)

        if reflect and compat and f_diel > ZERO:
            # Principled Fresnel (Mitsuba's principled_fresnel): true dielectric Fresnel,
            # blended with Schlick terms for the metallic and the tinted dielectric parts.
            if front:
                l = luminance(base_r, base_g, base_b)
                tr = base_r / l if l > ZERO else ONE
                tg = base_g / l if l > ZERO else ONE
                tb = base_b / l if l > ZERO else ONE
                r0 = schlick_r0(eta_it)
                if SPEC_TINT:
                    kd = (ONE - metallic) * (ONE - spec_tint) * f_diel
                    kt = (ONE - metallic) * spec_tint
                    fr = kd + metallic * schlick_fresnel(base_r, wo_h, eta) + \
                        kt * schlick_fresnel(tr * r0, wo_h, eta)
                    fg = kd + metallic * schlick_fresnel(base_g, wo_h, eta) + \
                        kt * schlick_fresnel(tg * r0, wo_h, eta)
                    fb = kd + metallic * schlick_fresnel(base_b, wo_h, eta) + \
                        kt * schlick_fresnel(tb * r0, wo_h, eta)
                else:
                    kd = (ONE - metallic) * f_diel
                    fr = kd + metallic * schlick_fresnel(base_r, wo_h, eta)
                    fg = kd + metallic * schlick_fresnel(base_g, wo_h, eta)
                    fb = kd + metallic * schlick_fresnel(base_b, wo_h, eta)
            else:
                fr = bsdf * f_diel
                fg = fr
                fb = fr
            s = d * g / (FOUR * abs(cos_o))
            vr += fr * s
            vg += fg * s
            vb += fb * s

        if TRANSMISSION and bsdf > ZERO and (not reflect) and compat and f_diel < ONE:
            # Walter et al. 2007, eq. 21, for radiance: the (1/eta)^2 of radiance compression
            # and the eta^2 of the Jacobian cancel.
            den = wo_h + eta_path * wi_h
            t = bsdf * abs((ONE - f_diel) * d * g * eta_path * eta_path * wo_h * wi_h /
                           (cos_o * den * den)) / (eta_path * eta_path)
            vr += math.sqrt(base_r) * t
            vg += math.sqrt(base_g) * t
            vb += math.sqrt(base_b) * t

        cc_alpha = CC_ALPHA_HI + (CC_ALPHA_LO - CC_ALPHA_HI) * cc_gloss
        if CLEARCOAT and clearcoat > ZERO and reflect and compat and front:
            fcc = schlick_fresnel(F0_CLEARCOAT, wo_h, eta)
            dcc = gtr1_d(wh, cc_alpha)
            gcc = smith_ggx1(wo, wh, CC_MASK_ALPHA) * smith_ggx1(wi, wh, CC_MASK_ALPHA)
            c = clearcoat * QUARTER * fcc * dcc * gcc * abs(cos_i)
            vr += c
            vg += c
            vb += c

        if reflect and front:
            fo = schlick_weight(abs(cos_i))
            fi = schlick_weight(abs(cos_o))
            cos_d = dot(wh, wi)
            if brdf > ZERO:
                f_diff = (ONE - HALF * fi) * (ONE - HALF * fo)
                rr = TWO * roughness * cos_d * cos_d
                f_retro = rr * (fo + fi + fo * fi * (rr - ONE))
                fss90 = HALF * rr
                fss = (ONE + (fss90 - ONE) * fo) * (ONE + (fss90 - ONE) * fi)
                f_ss = SS_K * (fss * (ONE / (abs(cos_i) + abs(cos_o)) - HALF) + HALF)
                lobe = f_diff + f_retro
                if FLATNESS:
                    lobe = lobe + (f_ss - lobe) * flatness
                c = brdf * abs(cos_i) * INV_PI * lobe
                vr += c * base_r
                vg += c * base_g
                vb += c * base_b
            if SHEEN and sheen > ZERO and metallic < ONE:
                fd = schlick_weight(abs(cos_d))
                l = luminance(base_r, base_g, base_b)
                tr = base_r / l if l > ZERO else ONE
                tg = base_g / l if l > ZERO else ONE
                tb = base_b / l if l > ZERO else ONE
                c = sheen * (ONE - metallic) * fd * abs(cos_i)
                vr += c * (ONE + (tr - ONE) * sheen_tint)
                vg += c * (ONE + (tg - ONE) * sheen_tint)
                vb += c * (ONE + (tb - ONE) * sheen_tint)

        # ---- pdf ----
        if front:
            # (all metal without a dielectric part: the weight is 1, no Fresnel compiled)
            p_spec = spec_weight(metallic, brdf, bsdf, eta, cos_o) if DIELECTRIC else ONE
            p_cc = QUARTER * clearcoat
            p_diff = brdf
        else:
            p_spec = ONE
            p_cc = ZERO
            p_diff = ZERO
        total = p_spec + p_cc + p_diff
        if front:
            p_trans = bsdf * (ONE - f_diel)
        else:
            p_trans = ONE - f_diel
        if bsdf <= ZERO and front:
            p_trans = ZERO
        p_trans = p_trans * p_spec
        p_refl = p_spec - p_trans
        pdf = ZERO
        wo_up = wo if cos_o > ZERO else (-wo[0], -wo[1], -wo[2])
        if reflect:
            dwh = abs(ONE / (FOUR * wi_h))
        else:
            den = wo_h + eta_path * wi_h
            dwh = abs(eta_path * eta_path * wi_h / (den * den))
        if compat:
            vis = ggx_pdf_visible(wo_up, wh, ax, ay)
            if reflect:
                pdf += p_refl * vis * dwh
                if CLEARCOAT and p_cc > ZERO:
                    pdf += p_cc * gtr1_d(wh, cc_alpha) * wh[2] * dwh
            else:
                pdf += p_trans * vis * dwh
        if reflect and p_diff > ZERO:
            pdf += p_diff * abs(cos_i) * INV_PI
        return (vr, vg, vb), pdf / total

    @device
    def principled_sample(params, wo, u_choice, u1, u2):
        """(wi, weight = eval / pdf, pdf); pdf = 0: no sample (absorbed). (u1, u2): the
        direction's pair, u1 also picking the lobe; u_choice: reflection or refraction."""
        roughness = params[P_ROUGHNESS]
        metallic = params[P_METALLIC] if DIELECTRIC else ONE
        eta = params[P_ETA]
        anisotropic = params[P_ANISOTROPIC] if ANISOTROPIC else ZERO
        clearcoat = params[P_CLEARCOAT] if CLEARCOAT else ZERO
        cc_gloss = params[P_CLEARCOAT_GLOSS] if CLEARCOAT else ZERO
        cos_o = wo[2]
        zero3 = (ZERO, ZERO, ZERO)
        if cos_o == ZERO:
            return zero3, zero3, ZERO
        brdf, bsdf = lobe_weights(params, metallic)
        front = cos_o > ZERO
        if not front and bsdf <= ZERO:
            return zero3, zero3, ZERO
        ax, ay = ggx_alphas(roughness, anisotropic)
        s = sign_of(cos_o)
        wo_up = (wo[0] * s, wo[1] * s, wo[2] * s)
        if front:
            p_cc = QUARTER * clearcoat
            p_diff = brdf
            p_sp = spec_weight(metallic, brdf, bsdf, eta, cos_o) if DIELECTRIC else ONE
        else:
            p_cc = ZERO
            p_diff = ZERO
            p_sp = ONE
        total = p_sp + p_cc + p_diff
        # The lobe is picked by the direction's first number, which is then stretched back
        # to [0, 1) within the lobe's share (reuse_sample): each lobe's directions are a
        # strip of the stratified (u1, u2) pair, stratified too, where a separate lobe
        # number left them a scattered subset of it (bunny-studio, 64 spp: relMSE -5 %,
        # docs/benchmarks.md). u_choice decides reflection against refraction.
        x = u1 * total
        reflected = True
        if x < p_diff:
            wi = square_to_cosine_hemisphere(reuse_sample(x, ZERO, p_diff), u2)
        elif CLEARCOAT and x < p_diff + p_cc:
            cc_alpha = CC_ALPHA_HI + (CC_ALPHA_LO - CC_ALPHA_HI) * cc_gloss
            m = gtr1_sample(cc_alpha, reuse_sample(x, p_diff, p_cc), u2)
            wi = reflect_about(wo, m)
        else:
            m = ggx_sample_visible(wo_up, ax, ay, reuse_sample(x, p_diff + p_cc, p_sp), u2)
            f, cos_t, _, eta_ti = fresnel_dielectric(dot(wo, m), eta)
            p_trans = (bsdf * (ONE - f)) if front else (ONE - f)
            if TRANSMISSION and u_choice < p_trans:
                c = dot(wo, m) * eta_ti + cos_t
                wi = (-wo[0] * eta_ti + m[0] * c, -wo[1] * eta_ti + m[1] * c,
                      -wo[2] * eta_ti + m[2] * c)
                reflected = False
            else:
                wi = reflect_about(wo, m)
        # A microfacet reflection that leaves below the macro surface (or a refraction that
        # stays on wo's side) is absorbed, as in Mitsuba: eval would otherwise account for it
        # under another lobe's density.
        if (wo[2] * wi[2] > ZERO) != reflected:
            return wi, zero3, ZERO
        val, pdf = principled_eval(params, wo, wi)
        if not (pdf > ZERO):
            return wi, zero3, ZERO
        inv = ONE / pdf
        return wi, (val[0] * inv, val[1] * inv, val[2] * inv), pdf

    return principled_eval, principled_sample


# The full BSDF (every lobe): the tests' reference and the kernels of scenes that use all.
principled_eval, principled_sample = make_principled()
