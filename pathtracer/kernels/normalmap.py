"""Normal mapping that does not depend on the triangle.

A normal map gives a shading normal ``wp`` that can lean far from the smooth
(interpolated) normal. Part of the lobes of a BSDF shaded with ``wp`` then points to the
wrong side of the surface: a reflection below it or a transmission that stays above.
Dropping that part loses energy (a white furnace renders grey), counting it leaks light
through the surface; we fold it back, mirrored across the surface, so that the BSDF keeps
its albedo and nothing crosses.

Until issue 17 the fold was across each triangle's own plane (its geometric normal). On a
coarse mesh that plane differs from triangle to triangle by up to the angle between
neighbouring vertex normals, so where light or view graze the surface the lobes were cut
differently on every triangle and a coarse normal-mapped sphere showed its facets
(``scenes/textured.json``). Now a normal-mapped surface is folded across the *smooth*
surface, the plane of the interpolated normal, which is continuous over the mesh
(``scatter.mapped_eval``); and that plane, not the triangle's, decides what is a
reflection and a transmission and on which side rays leave (``scatter.side_normal``). A
ray into the thin wedge between the smooth plane and the triangle's may have to cross its
own triangle; it is then tested against it like any other surface (``scatter.own_skip``),
so light still does not pass the mesh.

Measured alternatives (docs/architecture.md, "Normal mapping"): Schüßler et al. 2017
("Microfacet-based Normal Mapping for Robust Monte Carlo Path Tracing") is also free of
facets, but its microsurface shadows the light that comes from where the mapped normal
leans (a 15 degree tilt already loses 14 % of the reflection towards its own side), so a
normal map shows much less relief than in Mitsuba 3 or Cycles; its one-bounce form also
loses energy (0.47 of a white Lambertian's reflection at 80 degrees). Folding across the
smooth surface keeps Mitsuba's look and all the energy.

Directions here are in the smooth shading frame (z = the interpolated normal).
"""
import math

import numpy as np

from .constants import HORIZON_EPS, ONE, ZERO
from .device import device
from .vec import dot, madd, normalize

# A mapped normal within this cosine of the smooth normal is the smooth normal.
NM_FLAT_COS = np.float32(1.0 - 1e-6)
# Mapped normals are kept at least this far above the smooth horizon (cos >= it): texels
# that point lower (a map's error, or a flipped channel) are clamped to it.
NM_MIN_COS = np.float32(0.02)


@device
def clamp_mapped_normal(wp):
    """The unit mapped normal (smooth frame) kept above the smooth horizon: its elevation
    clamped to NM_MIN_COS (a texel pointing straight down gives the smooth normal)."""
    if wp[2] >= NM_MIN_COS:
        return normalize(wp)
    r = math.sqrt(wp[0] * wp[0] + wp[1] * wp[1])
    if not (r > ZERO):
        return ZERO, ZERO, ONE
    s = math.sqrt(ONE - NM_MIN_COS * NM_MIN_COS) / r
    return wp[0] * s, wp[1] * s, NM_MIN_COS


@device
def mapped_normal_seeing(wp, wo):
    """wp bent towards wo (smooth frame) just enough that wo is HORIZON_EPS above its
    horizon on wo's side of the smooth surface (the rule of the frame's own normal)."""
    s = ONE if wo[2] >= ZERO else -ONE
    c = dot(wp, wo) * s
    if c < HORIZON_EPS:
        return normalize(madd(wp, wo, s * (HORIZON_EPS - c)))
    return wp


@device
def mapped_frame(wp):
    """(tm, bm): the tangent and bitangent of the mapped frame: the smooth tangent x made
    orthogonal to the unit mapped normal wp (as a normal-mapped shading frame does), and
    wp x tm."""
    tm = normalize((ONE - wp[0] * wp[0], -wp[0] * wp[1], -wp[0] * wp[2]))
    bm = (wp[1] * tm[2] - wp[2] * tm[1], wp[2] * tm[0] - wp[0] * tm[2],
          wp[0] * tm[1] - wp[1] * tm[0])
    return tm, bm


@device
def mirror_smooth(w):
    """w mirrored across the smooth surface."""
    return w[0], w[1], -w[2]


@device
def consistent_with_smooth(wp, wo, w):
    """Do the mapped frame and the smooth surface agree on whether w is a reflection or a
    transmission of wo?"""
    return (dot(wo, wp) * dot(w, wp) > ZERO) == (wo[2] * w[2] > ZERO)
