"""A search of a cumulative table without a mispredicted branch per step (the CPU's).

Sampling a discrete distribution by inversion finds the last entry of a cumulative table
that is <= u. A bisection branches on every comparison, and which way it goes is a coin
flip: on the CPU about half of the steps mispredict (~13 cycles each on Zen 3). For the
light pick (``emitters``: the scene's light CDF) a search that halves the candidate range
with a select instead (Khuong and Morin 2017, "Array Layouts for Comparison-Based
Searching", the branch-free binary search) gave the Cornell box +4.7 % camera paths/s on
2 EPYC cores (``python -m bench.ab throughput --paired 24``, 2026-11-28). It finds the same
index as a bisection over a non-decreasing table in the same number of steps.

LLVM turns such a select back into a branch when its condition compares a loaded value
(x86 "cmov conversion": it expects a predictable branch), so the select is emitted with
LLVM's ``!unpredictable`` metadata, which keeps it a ``cmov`` (:func:`select_le`; CUDA
would get a plain select, interpreted code a conditional expression). Not everywhere a
win: the environment map's searches, whose tables miss the cache, ran slower so (each step
then waits for its load; bunny-studio 0.91x, sun 0.84x): they use guide tables instead
(``envmap``), and the GPU keeps the bisection.
"""
from llvmlite import ir
from numba import types
from numba.extending import intrinsic, overload

from .device import device


def select_le(x, u, a, b):
    """``a if x <= u else b`` (x, u floats; a, b integers), compiled as a compare and a
    select that the CPU's code generator keeps branch-free (see the module's docstring).
    The compare is part of the intrinsic: a select on a boolean passed in lost its
    ``!unpredictable`` mark when LLVM re-formed it (a branch again, numba 0.68 / LLVM 22)."""
    return a if x <= u else b


@intrinsic
def _select_le_ir(typingctx, x, u, a, b):
    if not (isinstance(x, types.Float) and isinstance(u, types.Float)
            and isinstance(a, types.Integer) and isinstance(b, types.Integer)):
        return None
    fty = typingctx.unify_types(x, u)
    ty = typingctx.unify_types(a, b)

    def codegen(context, builder, signature, args):
        xs, us, as_, bs = signature.args
        # (ordered: a NaN compares false, as in Python)
        c = builder.fcmp_ordered("<=", context.cast(builder, args[0], xs, fty),
                                 context.cast(builder, args[1], us, fty))
        r = builder.select(c, context.cast(builder, args[2], as_, ty),
                           context.cast(builder, args[3], bs, ty))
        if "cuda" not in type(context).__module__:
            r.set_metadata("unpredictable", builder.module.add_metadata([]))
        return r
    return ty(x, u, a, b), codegen


overload(select_le, strict=False)(
    lambda x, u, a, b: (lambda x, u, a, b: _select_le_ir(x, u, a, b)))


@device
def last_at_most(cdf, u):
    """The last index k < len(cdf) - 1 with cdf[k] <= u, for a non-decreasing cdf with
    cdf[0] <= u: halving the candidates [k, k + n), keeping the upper part when its first
    entry is <= u."""
    k = 0
    n = cdf.shape[0] - 1
    while n > 1:
        half = n >> 1
        k = select_le(cdf[k + half], u, k + half, k)
        n -= half
    return k
