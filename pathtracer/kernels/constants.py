"""Typed float32 constants for kernel code.

Numba types a Python float literal as float64, and float32 * float64 promotes to float64,
which on the GPU means slow double-precision instructions. Kernel code therefore uses these
named float32 globals (captured as typed constants) instead of bare literals.
"""
import numpy as np

F32 = np.float32

ZERO = F32(0.0)
ONE = F32(1.0)
TWO = F32(2.0)
HALF = F32(0.5)
PI = F32(np.pi)
INV_PI = F32(1.0 / np.pi)
TWO_PI = F32(2.0 * np.pi)
PI_OVER_4 = F32(np.pi / 4.0)
PI_OVER_2 = F32(np.pi / 2.0)
INF = F32(np.inf)

# Largest float32 below 1: keeps samples in [0, 1) (pbrt's OneMinusEpsilon).
ONE_MINUS_EPS = F32(np.nextafter(np.float32(1.0), np.float32(0.0)))

# Robust slab test: scale t_far by 1 + 2*gamma(3) so rounding never culls a box that the
# ray touches (Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2)).
SLAB_SCALE = F32(1.0000004)

# Ray origins are pushed off a surface along its geometric normal by this fraction of the
# hit point's largest coordinate (a few float32 ulps; relative, so scaling or translating a
# scene does not change which self-intersections are avoided). The originating triangle is
# also skipped by index, so the offset only has to clear neighbouring triangles.
OFFSET_REL = F32(2.0 ** -21)
# Shadow rays stop this fraction short of the light sample point.
SHADOW_SHORTEN = F32(1.0 - 2.0 ** -16)

# 1/0 replacement in reciprocal ray directions: big but finite, so that 0 * it is 0, not NaN.
BIG = F32(1e30)

# A shading normal that would put wo below its horizon is bent towards wo until wo is this
# far (cosine) above it: a lit surface must not turn black where a normal leans away.
HORIZON_EPS = F32(1e-3)

# Russian roulette never continues with more than this probability (as Mitsuba's `path`).
RR_MAX = F32(0.95)

# Luminance of linear sRGB / Rec. 709 RGB: the coefficients Mitsuba 3 uses (its
# ``luminance()``), so that texture-driven scalars, the principled BSDF's tints and the
# environment's sampling density all weigh colours the same way.
LUM_R = F32(0.212671)
LUM_G = F32(0.715160)
LUM_B = F32(0.072169)

# Traversal stack depth; the BVH builder caps tree depth below this.
STACK_SIZE = 64
