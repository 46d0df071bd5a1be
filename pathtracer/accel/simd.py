"""Vector operations on rows of eight float32, for the BVH builder (host code, CPU only).

The builder keeps each triangle's bounds as one row of eight float32 (``tri_rows``):
``[lo_x, lo_y, lo_z, 0, -hi_x, -hi_y, -hi_z, 0]``. With the upper bounds negated, the
bounds of a set of triangles are the lane-wise minimum of their rows, so adding a triangle
to a bin is one ``<8 x float>`` load, minimum and store (:func:`min_into`) instead of six
scalar minima and maxima. Numba does not vectorise those scalar forms (its arrays may
alias), so these helpers are written as LLVM IR; they are generic vector IR (``minnum``,
``fpext``, ``fptosi``), compiled for whatever CPU runs them. The float64 arithmetic of
:func:`centres` and :func:`bin_indices` is the scalar code's, lane by lane (the same IEEE
operations in the same order, no fast-math flags), so bins and splits, and so the tree,
are those of the plain builder (``tests/test_bvh.py``).
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

ROW = 8                       # floats per triangle row and per bin row
HI = 4                        # the negated upper bounds start at lane 4

_V8 = ir.VectorType(ir.FloatType(), ROW)
_V4D = ir.VectorType(ir.DoubleType(), 4)
_V4I = ir.VectorType(ir.IntType(32), 4)
_I32 = ir.IntType(32)


def _is_rows(a):
    return (isinstance(a, types.Array) and a.ndim == 2 and a.layout == "C"
            and a.dtype == types.float32)


def _row_pointer(context, builder, aryty, ary_value, row_value, row_type):
    """A <8 x float>* to the start of row ``row`` of a C-contiguous float32 (R, 8) array."""
    ary = context.make_array(aryty)(context, builder, ary_value)
    row = context.cast(builder, row_value, row_type, types.intp)
    p = cgutils.get_item_pointer(context, builder, aryty, ary,
                                 [row, context.get_constant(types.intp, 0)], wraparound=False)
    return builder.bitcast(p, _V8.as_pointer())


def _minnum(builder, a, b):
    # llvm.minnum with no NaN operands (the builder's bounds are finite): one vminps on
    # x86. (A compare and select stored back to a's address became a masked store,
    # vmaskmovps, which is slow on AMD Zen: ad hoc, 2026-11-28.)
    fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_V8, [_V8, _V8]),
                                        "llvm.minnum.v8f32")
    return builder.call(fn, [a, b], fastmath=("nnan",))


@intrinsic
def min_into(typingctx, dst, i, src, k):
    """dst[i, :8] = minimum(dst[i, :8], src[k, :8]), lane by lane."""
    if not (_is_rows(dst) and _is_rows(src)):
        return None

    def codegen(context, builder, sig, args):
        pd = _row_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
        ps = _row_pointer(context, builder, sig.args[2], args[2], args[3], sig.args[3])
        a = builder.load(pd, align=4)
        builder.store(_minnum(builder, a, builder.load(ps, align=4)), pd, align=4)
        return context.get_dummy_value()
    return types.none(dst, i, src, k), codegen


@intrinsic
def copy_row(typingctx, dst, i, src, k):
    """dst[i, :8] = src[k, :8]."""
    if not (_is_rows(dst) and _is_rows(src)):
        return None

    def codegen(context, builder, sig, args):
        pd = _row_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
        ps = _row_pointer(context, builder, sig.args[2], args[2], args[3], sig.args[3])
        builder.store(builder.load(ps, align=4), pd, align=4)
        return context.get_dummy_value()
    return types.none(dst, i, src, k), codegen


@intrinsic
def swap_rows(typingctx, a, i, j):
    """Swap rows i and j of a."""
    if not _is_rows(a):
        return None

    def codegen(context, builder, sig, args):
        pi = _row_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
        pj = _row_pointer(context, builder, sig.args[0], args[0], args[2], sig.args[2])
        x = builder.load(pi, align=4)
        y = builder.load(pj, align=4)
        builder.store(y, pi, align=4)
        builder.store(x, pj, align=4)
        return context.get_dummy_value()
    return types.none(a, i, j), codegen


def _centres_ir(context, builder, sig, args):
    """<4 x double> 0.5 * (lo - (-hi)) of the row (lane 3: 0), as bvh._row_centre computes
    each axis: 0.5 * (lo + hi) in float64 (x - (-y) is x + y in IEEE arithmetic)."""
    b = builder
    v = b.load(_row_pointer(context, b, sig.args[0], args[0], args[1], sig.args[1]), align=4)
    undef = ir.Constant(_V8, ir.Undefined)
    lo = b.fpext(b.shuffle_vector(v, undef, ir.Constant(_V4I, [0, 1, 2, 3])), _V4D)
    neg_hi = b.fpext(b.shuffle_vector(v, undef, ir.Constant(_V4I, [4, 5, 6, 7])), _V4D)
    return b.fmul(ir.Constant(_V4D, [0.5] * 4), b.fsub(lo, neg_hi))


@intrinsic
def centres(typingctx, rows, k):
    """The centre of row k's box on each axis (three float64), as bvh._row_centre gives them."""
    if not _is_rows(rows):
        return None
    sig = types.UniTuple(types.float64, 3)(rows, k)

    def codegen(context, builder, sig, args):
        c = _centres_ir(context, builder, sig, args)
        out = [builder.extract_element(c, ir.Constant(_I32, j)) for j in range(3)]
        return context.make_tuple(builder, sig.return_type, out)
    return sig, codegen


@intrinsic
def bin_indices(typingctx, rows, k, clo0, clo1, clo2, inv0, inv1, inv2, last):
    """Row k's bin on each axis (three int64): min(int((centre - clo) * inv), last), the
    scalar builder's float64 expression on all three axes at once. An axis with inv = 0
    (no extent) gets bin 0."""
    if not _is_rows(rows) or not isinstance(last, types.Integer):
        return None
    f64 = types.float64
    sig = types.UniTuple(types.int64, 3)(rows, k, f64, f64, f64, f64, f64, f64, last)

    def codegen(context, builder, sig, args):
        b = builder

        def vector(xs):
            out = ir.Constant(_V4D, [0.0] * 4)
            for j, x in enumerate(xs):
                out = b.insert_element(out, x, ir.Constant(_I32, j))
            return out
        c = _centres_ir(context, b, sig, args)
        # (the bins are below 2**31: n_bins is at most bvh.MAX_BINS)
        index = b.fptosi(b.fmul(b.fsub(c, vector(args[2:5])), vector(args[5:8])), _V4I)
        last32 = b.trunc(args[8], _I32) if args[8].type.width > 32 else args[8]
        top = b.shuffle_vector(b.insert_element(ir.Constant(_V4I, ir.Undefined), last32,
                                                ir.Constant(_I32, 0)),
                               ir.Constant(_V4I, ir.Undefined), ir.Constant(_V4I, [0] * 4))
        index = b.select(b.icmp_signed(">", index, top), top, index)
        out = [b.sext(b.extract_element(index, ir.Constant(_I32, j)), ir.IntType(64))
               for j in range(3)]
        return context.make_tuple(b, sig.return_type, out)
    return sig, codegen
