"""Four-wide BVH traversal with SIMD box and triangle tests (the CPU's traversal).

The binary BVH (:mod:`.traverse`) tests two boxes per node and one triangle at a time, in
scalar code: on the CPU, where a core runs one path at a time, that leaves its vector units
idle. Here the binary tree is collapsed into nodes of up to four children (Wald et al. 2008,
"Getting Rid of Packets"; Embree's BVH4), whose boxes are stored as struct-of-arrays rows so
that one ``<4 x float>`` operation handles a coordinate of all four, and the triangles of
each leaf are packed in groups of four the same way (Moller-Trumbore on four triangles at
once). Both tests are written as LLVM vector IR (:func:`slab4`, :func:`triangles4`), as
Numba does not vectorise the scalar forms; the arithmetic is the scalar tests' own,
operation for operation, so hit distances and barycentrics are bit-identical to
:func:`.intersect.slab` and :func:`.intersect.ray_triangle` (tested).

Layout (built by :func:`pathtracer.accel.wide.widen_bvh` from the binary BVH). The CPU
backend passes these arrays in the scene's ``bvh_box`` and ``bvh_child`` slots (same types
as the binary tree's), so the kernels' arguments and types do not change:

- ``wide`` float32 (R, 12): rows of 12 floats holding nodes (two rows each: lo_x[4],
  lo_y[4], lo_z[4], hi_x[4], hi_y[4], hi_z[4] of the four children) and then groups of four
  triangles (three rows each: v0x[4], v0y[4], v0z[4], e1x[4], ..., e2z[4]); lanes past a
  leaf's end are zero triangles (det = 0: never hit). Node n starts at row 2n, so 12 floats
  per row wastes nothing;
- ``wchild`` int32 (B, 12), row n for node n: index[4], count[4], first[4]. count > 0: a
  leaf of ``count`` triangles, the first being triangle ``first`` (the scene's numbering,
  which shading reads), packed in the groups starting at row ``index``; 0: an inner node
  whose rows start at ``index``; -1: no child (its box is NaN, which no ray enters).

Only the CPU backend builds these arrays; the GPU keeps the binary tree, whose traversal
was tuned there (vector loads of its nodes, docs/benchmarks.md). This code is plain Numba
and LLVM IR that the CUDA target compiles too (``python -m bench.traversal --backend
cuda``), and there it loses: on an H200 the wide tree traced 0.64-0.88x the binary one's
closest hits and 0.76-0.80x its any hits (docs/benchmarks.md, 2026-11-27).
"""
import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from .constants import INF, SLAB_SCALE, ZERO
from .device import device
from .intersect import ray_triangle, safe_inverse, slab
from .loads import load4, vector_alignment

WIDE_ROW = 12         # floats per row of ``wide``
NODE_ROWS = 2         # a node's 24 floats
GROUP_ROWS = 3        # a triangle group's 36 floats
WCHILD_WIDTH = 12
WCHILD_INDEX = 0
WCHILD_COUNT = 4
WCHILD_FIRST = 8
LANES = 4


# ---- the two vector tests: Python forms (interpreted mode, tests) and their IR -----------------

def slab4(wide, row, ox, oy, oz, ix, iy, iz, t_max):
    """Entry distances (or INF) of the ray into the four child boxes of the node whose rows
    start at ``row``: the scalar slab test (intersect.slab) on each."""
    f = wide[row:row + NODE_ROWS].reshape(-1)
    o = (ox, oy, oz)
    inv = (ix, iy, iz)
    return tuple(slab(o, inv, f[k], f[4 + k], f[8 + k], f[12 + k], f[16 + k], f[20 + k],
                      t_max) for k in range(LANES))


def triangles4(wide, row, ox, oy, oz, dx, dy, dz, t_max, skip_a, skip_b):
    """(t0..t3, b1_0..b1_3, b2_0..b2_3) of the ray with the four triangles of the group at
    ``row``: t = INF where ray_triangle misses and for lanes skip_a and skip_b (lane
    numbers, any value)."""
    f = wide[row:row + GROUP_ROWS].reshape(-1)
    o = (ox, oy, oz)
    d = (dx, dy, dz)
    ts, b1s, b2s = [], [], []
    for k in range(LANES):
        tri = np.array([[f[4 * a + k] for a in range(9)]], np.float32)
        t, b1, b2 = ray_triangle(o, d, tri, 0, t_max)
        ts.append(INF if k in (skip_a, skip_b) else t)
        b1s.append(b1)
        b2s.append(b2)
    return tuple(ts) + tuple(b1s) + tuple(b2s)


def _vector_helpers(context, builder):
    fl = ir.FloatType()
    v4 = ir.VectorType(fl, LANES)
    i32 = ir.IntType(32)

    def splat(x):
        v = ir.Constant(v4, ir.Undefined)
        for k in range(LANES):
            v = builder.insert_element(v, x, ir.Constant(i32, k))
        return v

    def lanes(v):
        return [builder.extract_element(v, ir.Constant(i32, k)) for k in range(LANES)]
    return v4, splat, lanes


def _row_loader(context, builder, aryty, ary_value, row_value, row_type, v4):
    """load(k): the four floats at offset k from the start of row ``row`` of a C-contiguous
    float32 array (offsets past the row run on into the next rows)."""
    ary = context.make_array(aryty)(context, builder, ary_value)
    row = context.cast(builder, row_value, row_type, types.intp)
    start = cgutils.get_item_pointer(context, builder, aryty, ary,
                                     [row, context.get_constant(types.intp, 0)],
                                     wraparound=False)

    # (on the GPU 16-byte aligned: rows of 48 bytes from an allocation aligned to 256,
    # offsets k of whole vectors)
    align = vector_alignment(context)

    def load(k):
        ptr = builder.gep(start, [context.get_constant(types.intp, k)])
        return builder.load(builder.bitcast(ptr, v4.as_pointer()), align=align)
    return load


def _is_float32_rows(a):
    return isinstance(a, types.Array) and a.ndim == 2 and a.layout == "C" and (
        a.dtype == types.float32)


@intrinsic
def _slab4_ir(typingctx, wide, row, ox, oy, oz, ix, iy, iz, t_max):
    if not (_is_float32_rows(wide) and isinstance(row, types.Integer)):
        return None
    f32 = types.float32
    sig = types.UniTuple(f32, LANES)(wide, row, f32, f32, f32, f32, f32, f32, f32)

    def codegen(context, builder, signature, args):
        v4, splat, lanes = _vector_helpers(context, builder)
        row = _row_loader(context, builder, signature.args[0], args[0], args[1],
                          signature.args[1], v4)
        o = [splat(a) for a in args[2:5]]
        inv = [splat(a) for a in args[5:8]]

        # Numba's min(a, b) / max(a, b) of floats: select(b < a, b, a) / select(b > a, b, a)
        def vmin(a, b):
            return builder.select(builder.fcmp_ordered("<", b, a), b, a)

        def vmax(a, b):
            return builder.select(builder.fcmp_ordered(">", b, a), b, a)
        near, far = [], []
        for axis in range(3):
            t0 = builder.fmul(builder.fsub(row(4 * axis), o[axis]), inv[axis])
            t1 = builder.fmul(builder.fsub(row(12 + 4 * axis), o[axis]), inv[axis])
            near.append(vmin(t0, t1))
            far.append(vmax(t0, t1))
        zero = ir.Constant(v4, [0.0] * LANES)
        t_near = vmax(vmax(near[0], near[1]), vmax(near[2], zero))
        t_far = builder.fmul(vmin(vmin(far[0], far[1]), vmin(far[2], splat(args[8]))),
                             ir.Constant(v4, [float(SLAB_SCALE)] * LANES))
        res = builder.select(builder.fcmp_ordered("<=", t_near, t_far), t_near,
                             ir.Constant(v4, [math.inf] * LANES))
        return context.make_tuple(builder, signature.return_type, lanes(res))
    return sig, codegen


@intrinsic
def _triangles4_ir(typingctx, wide, row, ox, oy, oz, dx, dy, dz, t_max, skip_a, skip_b):
    if not (_is_float32_rows(wide) and isinstance(row, types.Integer)
            and isinstance(skip_a, types.Integer) and isinstance(skip_b, types.Integer)):
        return None
    f32 = types.float32
    sig = types.UniTuple(f32, 3 * LANES)(wide, row, f32, f32, f32, f32, f32, f32, f32,
                                         skip_a, skip_b)

    def codegen(context, builder, signature, args):
        v4, splat, lanes = _vector_helpers(context, builder)
        row = _row_loader(context, builder, signature.args[0], args[0], args[1],
                          signature.args[1], v4)
        mul, sub, add = builder.fmul, builder.fsub, builder.fadd
        v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z = [row(4 * a) for a in range(9)]
        ox, oy, oz = [splat(a) for a in args[2:5]]
        dx, dy, dz = [splat(a) for a in args[5:8]]
        # ray_triangle's arithmetic, in its order (no contraction: the same roundings)
        px = sub(mul(dy, e2z), mul(dz, e2y))
        py = sub(mul(dz, e2x), mul(dx, e2z))
        pz = sub(mul(dx, e2y), mul(dy, e2x))
        det = add(add(mul(e1x, px), mul(e1y, py)), mul(e1z, pz))
        one = ir.Constant(v4, [1.0] * LANES)
        zero = ir.Constant(v4, [0.0] * LANES)
        inv_det = builder.fdiv(one, det)
        sx, sy, sz = sub(ox, v0x), sub(oy, v0y), sub(oz, v0z)
        b1 = mul(add(add(mul(sx, px), mul(sy, py)), mul(sz, pz)), inv_det)
        qx = sub(mul(sy, e1z), mul(sz, e1y))
        qy = sub(mul(sz, e1x), mul(sx, e1z))
        qz = sub(mul(sx, e1y), mul(sy, e1x))
        b2 = mul(add(add(mul(dx, qx), mul(dy, qy)), mul(dz, qz)), inv_det)
        t = mul(add(add(mul(e2x, qx), mul(e2y, qy)), mul(e2z, qz)), inv_det)
        ok = builder.fcmp_unordered("!=", det, zero)
        for cond in (builder.fcmp_ordered(">=", b1, zero), builder.fcmp_ordered("<=", b1, one),
                     builder.fcmp_ordered(">=", b2, zero),
                     builder.fcmp_ordered("<=", add(b1, b2), one),
                     builder.fcmp_ordered(">", t, zero),
                     builder.fcmp_ordered("<", t, splat(args[8]))):
            ok = builder.and_(ok, cond)
        i64 = ir.IntType(64)
        vi = ir.VectorType(i64, LANES)
        lane_no = ir.Constant(vi, list(range(LANES)))
        for skip, skip_ty in ((args[9], signature.args[9]), (args[10], signature.args[10])):
            s = context.cast(builder, skip, skip_ty, types.int64)
            sv = ir.Constant(vi, ir.Undefined)
            for k in range(LANES):
                sv = builder.insert_element(sv, s, ir.Constant(ir.IntType(32), k))
            ok = builder.and_(ok, builder.icmp_signed("!=", lane_no, sv))
        t = builder.select(ok, t, ir.Constant(v4, [math.inf] * LANES))
        return context.make_tuple(builder, signature.return_type,
                                  lanes(t) + lanes(b1) + lanes(b2))
    return sig, codegen


overload(slab4, strict=False)(
    lambda wide, row, ox, oy, oz, ix, iy, iz, t_max:
    (lambda wide, row, ox, oy, oz, ix, iy, iz, t_max:
     _slab4_ir(wide, row, ox, oy, oz, ix, iy, iz, t_max)))
overload(triangles4, strict=False)(
    lambda wide, row, ox, oy, oz, dx, dy, dz, t_max, skip_a, skip_b:
    (lambda wide, row, ox, oy, oz, dx, dy, dz, t_max, skip_a, skip_b:
     _triangles4_ir(wide, row, ox, oy, oz, dx, dy, dz, t_max, skip_a, skip_b)))


# ---- traversal ----------------------------------------------------------------------------
# The signatures are traverse.closest_hit's and any_hit's (the integrator calls either with
# the scene's tri_v, bvh_box and bvh_child); tri_v, the scalar triangles, is not read here.

@device
def _leaf(o, d, wide, row, first, count, skip, t_best, tri_best, b1_best, b2_best):
    """The leaf's triangles first .. first + count - 1 (groups from row ``row``) in order; a
    hit replaces the best only if strictly nearer, as the scalar leaf loop does."""
    k = 0
    while k < count:
        r = triangles4(wide, row, o[0], o[1], o[2], d[0], d[1], d[2], t_best,
                       skip - first - k, -1)
        for lane in range(LANES):
            if r[lane] < t_best:
                t_best = r[lane]
                tri_best = first + k + lane
                b1_best = r[LANES + lane]
                b2_best = r[2 * LANES + lane]
        k += LANES
        row += GROUP_ROWS
    return t_best, tri_best, b1_best, b2_best


@device
def closest_hit_wide(o, d, t_max, skip, tri_v, wide, wchild, stack):
    """closest_hit over the four-wide tree: nearest hit (t, tri, b1, b2) with
    0 < t < t_max, ignoring triangle ``skip``; tri = -1 on a miss."""
    inv_d = safe_inverse(d)
    t_best = t_max
    tri_best = -1
    b1_best = ZERO
    b2_best = ZERO
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        row = stack[sp]
        t0, t1, t2, t3 = slab4(wide, row, o[0], o[1], o[2], inv_d[0], inv_d[1], inv_d[2],
                               t_best)
        node = row // NODE_ROWS
        c0, c1, c2, c3 = load4(wchild, node, WCHILD_INDEX)
        n0, n1, n2, n3 = load4(wchild, node, WCHILD_COUNT)
        f0, f1, f2, f3 = load4(wchild, node, WCHILD_FIRST)
        # the children nearest first: a five-comparator sorting network
        if t1 < t0:
            t0, t1, c0, c1, n0, n1, f0, f1 = t1, t0, c1, c0, n1, n0, f1, f0
        if t3 < t2:
            t2, t3, c2, c3, n2, n3, f2, f3 = t3, t2, c3, c2, n3, n2, f3, f2
        if t2 < t0:
            t0, t2, c0, c2, n0, n2, f0, f2 = t2, t0, c2, c0, n2, n0, f2, f0
        if t3 < t1:
            t1, t3, c1, c3, n1, n3, f1, f3 = t3, t1, c3, c1, n3, n1, f3, f1
        if t2 < t1:
            t1, t2, c1, c2, n1, n2, f1, f2 = t2, t1, c2, c1, n2, n1, f2, f1
        # inner children on the stack, farthest lowest; leaves intersected at once, nearest
        # first, a farther one only while still in front (see traverse.closest_hit)
        if t3 < INF and n3 == 0:
            stack[sp] = c3
            sp += 1
        if t2 < INF and n2 == 0:
            stack[sp] = c2
            sp += 1
        if t1 < INF and n1 == 0:
            stack[sp] = c1
            sp += 1
        if t0 < INF and n0 == 0:
            stack[sp] = c0
            sp += 1
        if t0 < INF and n0 > 0:
            t_best, tri_best, b1_best, b2_best = _leaf(
                o, d, wide, c0, f0, n0, skip, t_best, tri_best, b1_best, b2_best)
        if t1 < INF and n1 > 0 and t1 <= t_best * SLAB_SCALE:
            t_best, tri_best, b1_best, b2_best = _leaf(
                o, d, wide, c1, f1, n1, skip, t_best, tri_best, b1_best, b2_best)
        if t2 < INF and n2 > 0 and t2 <= t_best * SLAB_SCALE:
            t_best, tri_best, b1_best, b2_best = _leaf(
                o, d, wide, c2, f2, n2, skip, t_best, tri_best, b1_best, b2_best)
        if t3 < INF and n3 > 0 and t3 <= t_best * SLAB_SCALE:
            t_best, tri_best, b1_best, b2_best = _leaf(
                o, d, wide, c3, f3, n3, skip, t_best, tri_best, b1_best, b2_best)
    if tri_best < 0:
        return INF, -1, ZERO, ZERO
    return t_best, tri_best, b1_best, b2_best


@device
def _leaf_blocks(o, d, wide, row, first, count, t_max, skip_a, skip_b):
    k = 0
    while k < count:
        r = triangles4(wide, row, o[0], o[1], o[2], d[0], d[1], d[2], t_max,
                       skip_a - first - k, skip_b - first - k)
        if r[0] < INF or r[1] < INF or r[2] < INF or r[3] < INF:
            return True
        k += LANES
        row += GROUP_ROWS
    return False


@device
def any_hit_wide(o, d, t_max, skip_a, skip_b, tri_v, wide, wchild, stack):
    """any_hit over the four-wide tree: True if any triangle other than skip_a and skip_b is
    hit with 0 < t < t_max."""
    inv_d = safe_inverse(d)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        row = stack[sp]
        ts = slab4(wide, row, o[0], o[1], o[2], inv_d[0], inv_d[1], inv_d[2], t_max)
        node = row // NODE_ROWS
        for k in range(LANES):
            if ts[k] < INF:
                n = wchild[node, WCHILD_COUNT + k]
                if n == 0:
                    stack[sp] = wchild[node, WCHILD_INDEX + k]
                    sp += 1
                elif n > 0 and _leaf_blocks(o, d, wide, wchild[node, WCHILD_INDEX + k],
                                            wchild[node, WCHILD_FIRST + k], n, t_max, skip_a,
                                            skip_b):
                    return True
    return False
