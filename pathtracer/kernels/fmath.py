"""float32 floor, atan2 and acos for kernel code, in place of the C library's.

On the CPU Numba compiles ``int(math.floor(x))`` of a float32 into a call of its helper
library's ``numba_floorf`` and ``math.atan2`` / ``math.acos`` into calls of libm's ``atan2f``
(which calls ``atanf``) and ``acosf``: real calls, which also make LLVM keep every live float
of the caller in memory around them (x86-64's vector registers are all caller-saved), inside
the path loop. These are inline code instead:

- :func:`floor_int`: LLVM's ``llvm.floor`` intrinsic (one rounding instruction on x86-64
  and on the GPU), then the conversion to an integer: the same numbers as
  ``int(math.floor(x))``;
- :func:`atan2_f32` and :func:`acos_f32`: Cephes' single-precision arctangent and arcsine
  polynomials (Moshier, "Methods and Programs for Mathematical Functions", 1989; ``atanf.c``,
  ``asinf.c``), relative error about 1e-7, with the usual range reductions; results within
  4 float32 ulps of the exact values (tests/test_fmath.py), as libm's float32 ones are.

All three are plain Python too (the interpreted backend runs them as written).
"""
import math

from llvmlite import ir
from numba import types
from numba.extending import intrinsic, overload

from .constants import F32, HALF, ONE, PI, PI_OVER_2, PI_OVER_4, TWO, ZERO
from .device import device

_TAN_PI_8 = F32(0.4142135623730950)
_AT0 = F32(8.05374449538e-2)
_AT1 = F32(-1.38776856032e-1)
_AT2 = F32(1.99777106478e-1)
_AT3 = F32(-3.33329491539e-1)
_AS0 = F32(4.2163199048e-2)
_AS1 = F32(2.4181311049e-2)
_AS2 = F32(4.5470025998e-2)
_AS3 = F32(7.4953002686e-2)
_AS4 = F32(1.6666752422e-1)


def floor_int(x):
    """int(math.floor(x)) of a float32 x (finite, within int64)."""
    return int(math.floor(x))


@intrinsic
def _floor_int_ir(typingctx, x):
    if not isinstance(x, types.Float):
        return None
    sig = types.int64(x)

    def codegen(context, builder, signature, args):
        (v,) = args
        fn = builder.module.declare_intrinsic("llvm.floor", [v.type])
        return builder.fptosi(builder.call(fn, [v]), ir.IntType(64))
    return sig, codegen


overload(floor_int, strict=False)(lambda x: (lambda x: _floor_int_ir(x)))


def floor_f32(x):
    """math.floor(x) of a float32 x as a float32 (any x: no integer in between)."""
    return type(x)(math.floor(x)) if math.isfinite(x) else x


@intrinsic
def _floor_f32_ir(typingctx, x):
    if not isinstance(x, types.Float):
        return None
    sig = x(x)

    def codegen(context, builder, signature, args):
        (v,) = args
        fn = builder.module.declare_intrinsic("llvm.floor", [v.type])
        return builder.call(fn, [v])
    return sig, codegen


overload(floor_f32, strict=False)(lambda x: (lambda x: _floor_f32_ir(x)))


@device
def fract(x):
    """x % 1 of a float32 x, in [0, 1] (1 only by rounding: x = -1e-9 gives 1 - 1e-9, which
    rounds to 1), bit for bit as Python's float modulo: x - floor(x) is the same real number
    rounded once. Numba compiles ``%`` of floats to fmod and a sign fix-up, which the GPU
    runs as a routine of dozens of instructions; this is one rounding instruction and a
    subtraction."""
    return x - floor_f32(x)


@device
def atan_unit(a):
    """atan(a) for 0 <= a <= 1 (Cephes atanf: one reduction at tan(pi/8), then an odd
    polynomial of degree 9)."""
    big = a > _TAN_PI_8
    z = (a - ONE) / (a + ONE) if big else a
    z2 = z * z
    r = (((_AT0 * z2 + _AT1) * z2 + _AT2) * z2 + _AT3) * z2 * z + z
    return r + PI_OVER_4 if big else r


@device
def atan2_f32(y, x):
    """The angle of (x, y) in [-pi, pi], as math.atan2 (0 for the origin; the sign of a
    zero y is not kept: +pi for (x < 0, y = -0), where atan2 gives -pi)."""
    ax = abs(x)
    ay = abs(y)
    hi = max(ax, ay)
    if not (hi > ZERO):
        return ZERO
    r = atan_unit(min(ax, ay) / hi)
    if ay > ax:
        r = PI_OVER_2 - r
    if x < ZERO:
        r = PI - r
    return -r if y < ZERO else r


@device
def asin_half(a):
    """asin(a) for 0 <= a <= 1/2 (Cephes asinf's polynomial)."""
    z = a * a
    return ((((_AS0 * z + _AS1) * z + _AS2) * z + _AS3) * z + _AS4) * z * a + a


@device
def acos_f32(x):
    """acos(x) in [0, pi] for -1 <= x <= 1 (Cephes asinf's reduction: above 1/2,
    acos(a) = 2 asin(sqrt((1 - a) / 2)))."""
    a = abs(x)
    if a > HALF:
        r = TWO * asin_half(math.sqrt(HALF * (ONE - a)))
    else:
        r = PI_OVER_2 - asin_half(a)
    return PI - r if x < ZERO else r
