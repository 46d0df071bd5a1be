"""Eight-wide BVH traversal with SIMD box and triangle tests (the CPU's traversal).

The binary BVH (:mod:`.traverse`) tests two boxes per node and one triangle at a time, in
scalar code: on the CPU, where a core runs one path at a time, that leaves its vector units
idle. Here the binary tree is collapsed into nodes of up to eight children (Wald et al.
2008, "Getting Rid of Packets"; Embree's BVH8 on AVX2 machines), whose boxes are stored as
struct-of-arrays rows so that one ``<8 x float>`` operation handles a coordinate of all
eight, and the triangles of each leaf are packed in groups of four the same way
(Moller-Trumbore on four triangles at once). Both tests are written as LLVM vector IR
(:func:`slab8`, :func:`triangles4`), as Numba does not vectorise the scalar forms; the
arithmetic is the scalar tests' own, operation for operation, so hit distances and
barycentrics are bit-identical to :func:`.intersect.slab` and
:func:`.intersect.ray_triangle` (tested).

The traversal follows Embree's for one ray: the boxes a ray enters are a bit mask; a single
inner child entered is descended without touching the stack, two are ordered by one
comparison, more are pushed and sorted by entry distance. The stack holds each node's
entry distance, so a node popped after a nearer hit was found is dropped unopened (its
children's boxes lie inside its box). A node's leaves are intersected when it is visited.

Layout (built by :func:`pathtracer.accel.wide.widen_bvh` from the binary BVH). The CPU
backend passes these arrays in the scene's ``bvh_box`` and ``bvh_child`` slots (same types
as the binary tree's), so the kernels' arguments and types do not change:

- ``wide`` float32 (R, 12): rows of 12 floats holding nodes (four rows each: lo_x[8],
  lo_y[8], lo_z[8], hi_x[8], hi_y[8], hi_z[8] of the eight children) and then groups of four
  triangles (three rows each: v0x[4], v0y[4], v0z[4], e1x[4], ..., e2z[4]); lanes past a
  leaf's end are zero triangles (det = 0: never hit). Node n starts at row 4n;
- ``wchild`` int32 (B, 32), row n for node n: index[8], count[8], first[8], then the bit
  masks of its inner children and of its leaves (and six unused). count > 0: a leaf of
  ``count`` triangles, the first being triangle ``first`` (the scene's numbering, which
  shading reads), packed in the groups starting at row ``index``; 0: an inner node whose
  rows start at ``index``; -1: no child (its box is NaN, which no ray enters);
- the traversal stack (int32, ``accel.wide.WIDE_STACK_SIZE``): the closest-hit traversal
  pushes pairs of a node's row and the bits of its entry distance (a float32 >= 0, whose
  bits order as the floats do), the any-hit traversal rows alone.

Only the CPU backend builds these arrays; the GPU keeps the binary tree, whose traversal
was tuned there (vector loads of its nodes, docs/benchmarks.md). This code is plain Numba
and LLVM IR that the CUDA target compiles too (``python -m bench.traversal --backend
cuda``), and there the wide tree lost when it was four-wide: on an H200 it traced
0.64-0.88x the binary one's closest hits and 0.76-0.80x its any hits (docs/benchmarks.md,
2026-11-27).
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
from .loads import vector_alignment

WIDE_ROW = 12         # floats per row of ``wide``
WIDTH = 8             # children per node
NODE_ROWS = 4         # a node's 48 floats
GROUP_ROWS = 3        # a triangle group's 36 floats
LANES = 4             # triangles per group
WCHILD_WIDTH = 32
WCHILD_INDEX = 0
WCHILD_COUNT = 8
WCHILD_FIRST = 16
WCHILD_INNER = 24     # bit k set: child k is an inner node
WCHILD_LEAVES = 25    # bit k set: child k is a leaf


# ---- the vector tests and bit helpers: Python forms (interpreted mode, tests) and their IR ----

def slab8(wide, row, ox, oy, oz, ix, iy, iz, t_max):
    """Entry distances (or INF) of the ray into the eight child boxes of the node whose
    rows start at ``row``: the scalar slab test (intersect.slab) on each."""
    f = wide[row:row + NODE_ROWS].reshape(-1)
    o = (ox, oy, oz)
    inv = (ix, iy, iz)
    w = WIDTH
    return tuple(slab(o, inv, f[k], f[w + k], f[2 * w + k], f[3 * w + k], f[4 * w + k],
                      f[5 * w + k], t_max) for k in range(WIDTH))


def entered(ts):
    """The bit mask of the lanes of ``ts`` (slab8's distances) below INF."""
    return sum(1 << k for k in range(WIDTH) if ts[k] < INF)


def lowest_bit(m):
    """The number of the lowest set bit of m > 0."""
    m = int(m)
    return (m & -m).bit_length() - 1


def float_bits(x):
    """The bits of the float32 x as an int32."""
    return int(np.array(x, np.float32).view(np.int32))


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


def _vector_helpers(context, builder, n=LANES):
    fl = ir.FloatType()
    vn = ir.VectorType(fl, n)
    i32 = ir.IntType(32)

    def splat(x):
        v = ir.Constant(vn, ir.Undefined)
        for k in range(n):
            v = builder.insert_element(v, x, ir.Constant(i32, k))
        return v

    def lanes(v):
        return [builder.extract_element(v, ir.Constant(i32, k)) for k in range(n)]
    return vn, splat, lanes


def _row_loader(context, builder, aryty, ary_value, row_value, row_type, vty):
    """load(k): the floats of vector type vty (four or eight lanes) at offset k from the
    start of row ``row`` of a C-contiguous float32 array (offsets past the row run on into
    the next rows)."""
    ary = context.make_array(aryty)(context, builder, ary_value)
    row = context.cast(builder, row_value, row_type, types.intp)
    start = cgutils.get_item_pointer(context, builder, aryty, ary,
                                     [row, context.get_constant(types.intp, 0)],
                                     wraparound=False)

    # (on the GPU 16-byte aligned: rows of 48 bytes from an allocation aligned to 256,
    # offsets k of whole four- or eight-float vectors)
    align = vector_alignment(context)

    def load(k):
        ptr = builder.gep(start, [context.get_constant(types.intp, k)])
        return builder.load(builder.bitcast(ptr, vty.as_pointer()), align=align)
    return load


def _is_float32_rows(a):
    return isinstance(a, types.Array) and a.ndim == 2 and a.layout == "C" and (
        a.dtype == types.float32)


def _slab_ir(builder, vty, planes, o, inv, t_max):
    """slab's arithmetic on vectors of type vty: (t_near, inside), inside the lanes whose
    box the ray enters before t_max (t_near meaningful there). planes(c): lo_x .. hi_z (c =
    0 .. 5); o, inv: three vectors each; t_max(): the vector (emitted where it is used, so
    the callers' code is what it was before this helper)."""
    n = vty.count

    # Numba's min(a, b) / max(a, b) of floats: select(b < a, b, a) / select(b > a, b, a)
    def vmin(a, b):
        return builder.select(builder.fcmp_ordered("<", b, a), b, a)

    def vmax(a, b):
        return builder.select(builder.fcmp_ordered(">", b, a), b, a)
    near, far = [], []
    for axis in range(3):
        t0 = builder.fmul(builder.fsub(planes(axis), o[axis]), inv[axis])
        t1 = builder.fmul(builder.fsub(planes(3 + axis), o[axis]), inv[axis])
        near.append(vmin(t0, t1))
        far.append(vmax(t0, t1))
    zero = ir.Constant(vty, [0.0] * n)
    t_near = vmax(vmax(near[0], near[1]), vmax(near[2], zero))
    t_far = builder.fmul(vmin(vmin(far[0], far[1]), vmin(far[2], t_max())),
                         ir.Constant(vty, [float(SLAB_SCALE)] * n))
    return t_near, builder.fcmp_ordered("<=", t_near, t_far)


def _moller_trumbore_ir(builder, vty, tri, o, d, t_max):
    """ray_triangle's arithmetic on vectors of type vty, in its order (no contraction: the
    same roundings): (hit, t, b1, b2), hit the lanes with a hit in (0, t_max). tri: the
    nine vectors v0x .. e2z; o, d: three vectors each; t_max(): the vector (as _slab_ir's)."""
    mul, sub, add = builder.fmul, builder.fsub, builder.fadd
    v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z = tri
    ox, oy, oz = o
    dx, dy, dz = d
    px = sub(mul(dy, e2z), mul(dz, e2y))
    py = sub(mul(dz, e2x), mul(dx, e2z))
    pz = sub(mul(dx, e2y), mul(dy, e2x))
    det = add(add(mul(e1x, px), mul(e1y, py)), mul(e1z, pz))
    one = ir.Constant(vty, [1.0] * vty.count)
    zero = ir.Constant(vty, [0.0] * vty.count)
    inv_det = builder.fdiv(one, det)
    sx, sy, sz = sub(ox, v0x), sub(oy, v0y), sub(oz, v0z)
    b1 = mul(add(add(mul(sx, px), mul(sy, py)), mul(sz, pz)), inv_det)
    qx = sub(mul(sy, e1z), mul(sz, e1y))
    qy = sub(mul(sz, e1x), mul(sx, e1z))
    qz = sub(mul(sx, e1y), mul(sy, e1x))
    b2 = mul(add(add(mul(dx, qx), mul(dy, qy)), mul(dz, qz)), inv_det)
    t = mul(add(add(mul(e2x, qx), mul(e2y, qy)), mul(e2z, qz)), inv_det)
    hit = builder.fcmp_unordered("!=", det, zero)
    for cond in (builder.fcmp_ordered(">=", b1, zero), builder.fcmp_ordered("<=", b1, one),
                 builder.fcmp_ordered(">=", b2, zero),
                 builder.fcmp_ordered("<=", add(b1, b2), one),
                 builder.fcmp_ordered(">", t, zero), builder.fcmp_ordered("<", t, t_max())):
        hit = builder.and_(hit, cond)
    return hit, t, b1, b2


@intrinsic
def _slab8_ir(typingctx, wide, row, ox, oy, oz, ix, iy, iz, t_max):
    if not (_is_float32_rows(wide) and isinstance(row, types.Integer)):
        return None
    f32 = types.float32
    sig = types.UniTuple(f32, WIDTH)(wide, row, f32, f32, f32, f32, f32, f32, f32)

    def codegen(context, builder, signature, args):
        v8, splat, lanes = _vector_helpers(context, builder, WIDTH)
        row = _row_loader(context, builder, signature.args[0], args[0], args[1],
                          signature.args[1], v8)
        t_near, inside = _slab_ir(builder, v8, lambda c: row(WIDTH * c),
                                  [splat(a) for a in args[2:5]],
                                  [splat(a) for a in args[5:8]], lambda: splat(args[8]))
        res = builder.select(inside, t_near, ir.Constant(v8, [math.inf] * WIDTH))
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
        ok, t, b1, b2 = _moller_trumbore_ir(
            builder, v4, [row(4 * a) for a in range(9)], [splat(a) for a in args[2:5]],
            [splat(a) for a in args[5:8]], lambda: splat(args[8]))
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


@intrinsic
def _entered_ir(typingctx, ts):
    if not (isinstance(ts, types.UniTuple) and ts.count == WIDTH and ts.dtype == types.float32):
        return None

    def codegen(context, builder, signature, args):
        v8, _, _ = _vector_helpers(context, builder, WIDTH)
        v = ir.Constant(v8, ir.Undefined)
        for k in range(WIDTH):
            v = builder.insert_element(v, builder.extract_value(args[0], k),
                                       ir.Constant(ir.IntType(32), k))
        # (LLVM folds this vector back into slab8's: one compare and a vmovmskps)
        below = builder.fcmp_ordered("<", v, ir.Constant(v8, [math.inf] * WIDTH))
        return builder.zext(builder.bitcast(below, ir.IntType(WIDTH)), ir.IntType(64))
    return types.int64(ts), codegen


@intrinsic
def _lowest_bit_ir(typingctx, m):
    if not isinstance(m, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        ty = args[0].type
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ty, [ty, ir.IntType(1)]), f"llvm.cttz.i{ty.width}")
        return builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 1)])
    return m(m), codegen


@intrinsic
def _float_bits_ir(typingctx, x):
    if x != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(32))
    return types.int32(x), codegen


overload(slab8, strict=False)(
    lambda wide, row, ox, oy, oz, ix, iy, iz, t_max:
    (lambda wide, row, ox, oy, oz, ix, iy, iz, t_max:
     _slab8_ir(wide, row, ox, oy, oz, ix, iy, iz, t_max)))
overload(entered, strict=False)(lambda ts: (lambda ts: _entered_ir(ts)))
overload(lowest_bit, strict=False)(lambda m: (lambda m: _lowest_bit_ir(m)))
overload(float_bits, strict=False)(lambda x: (lambda x: _float_bits_ir(x)))
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
def _visit(o, inv_d, t_max, wide, wchild, row):
    """One node's visit: (its children's entry distances, the node's number, the bit masks
    of the leaves and of the inner children that the ray enters before t_max)."""
    ts = slab8(wide, row, o[0], o[1], o[2], inv_d[0], inv_d[1], inv_d[2], t_max)
    hit = entered(ts)
    node = row // NODE_ROWS
    return ts, node, hit & wchild[node, WCHILD_LEAVES], hit & wchild[node, WCHILD_INNER]


@device
def _push(stack, sp, row, t):
    stack[sp] = row
    stack[sp + 1] = float_bits(t)
    return sp + 2


@device
def closest_hit_wide(o, d, t_max, skip, tri_v, wide, wchild, stack):
    """closest_hit over the eight-wide tree: nearest hit (t, tri, b1, b2) with
    0 < t < t_max, ignoring triangle ``skip``; tri = -1 on a miss."""
    inv_d = safe_inverse(d)
    t_best = t_max
    tri_best = -1
    b1_best = ZERO
    b2_best = ZERO
    row = 0
    sp = 0
    while True:
        ts, node, leaves, inner = _visit(o, inv_d, t_best, wide, wchild, row)
        # the leaves entered, in lane order, each while still in front
        while leaves != 0:
            k = lowest_bit(leaves)
            leaves &= leaves - 1
            if ts[k] <= t_best * SLAB_SCALE:
                t_best, tri_best, b1_best, b2_best = _leaf(
                    o, d, wide, wchild[node, WCHILD_INDEX + k], wchild[node, WCHILD_FIRST + k],
                    wchild[node, WCHILD_COUNT + k], skip, t_best, tri_best, b1_best, b2_best)
        if inner != 0:
            k0 = lowest_bit(inner)
            inner &= inner - 1
            if inner == 0:                      # one: straight down
                row = wchild[node, WCHILD_INDEX + k0]
                continue
            k1 = lowest_bit(inner)
            inner &= inner - 1
            if inner == 0:                      # two: the farther one on the stack
                if ts[k1] < ts[k0]:
                    k0, k1 = k1, k0
                sp = _push(stack, sp, wchild[node, WCHILD_INDEX + k1], ts[k1])
                row = wchild[node, WCHILD_INDEX + k0]
                continue
            # more: all on the stack, sorted so that the nearest is on top
            base = sp
            sp = _push(stack, sp, wchild[node, WCHILD_INDEX + k0], ts[k0])
            sp = _push(stack, sp, wchild[node, WCHILD_INDEX + k1], ts[k1])
            while inner != 0:
                k = lowest_bit(inner)
                inner &= inner - 1
                sp = _push(stack, sp, wchild[node, WCHILD_INDEX + k], ts[k])
            j = base + 2
            while j < sp:                       # insertion sort, farthest lowest
                key_row = stack[j]
                key = stack[j + 1]
                q = j
                while q > base and stack[q - 1] < key:
                    stack[q] = stack[q - 2]
                    stack[q + 1] = stack[q - 1]
                    q -= 2
                stack[q] = key_row
                stack[q + 1] = key
                j += 2
        # the nearest node on the stack still in front (farther ones are dropped unopened)
        limit = float_bits(t_best * SLAB_SCALE)
        while sp > 0 and stack[sp - 1] > limit:
            sp -= 2
        if sp == 0:
            break
        sp -= 2
        row = stack[sp]
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
    """any_hit over the eight-wide tree: True if any triangle other than skip_a and skip_b
    is hit with 0 < t < t_max."""
    inv_d = safe_inverse(d)
    row = 0
    sp = 0
    while True:
        ts, node, leaves, inner = _visit(o, inv_d, t_max, wide, wchild, row)
        while leaves != 0:
            k = lowest_bit(leaves)
            leaves &= leaves - 1
            if _leaf_blocks(o, d, wide, wchild[node, WCHILD_INDEX + k],
                            wchild[node, WCHILD_FIRST + k], wchild[node, WCHILD_COUNT + k],
                            t_max, skip_a, skip_b):
                return True
        if inner != 0:                          # the lowest lane next, the others stacked
            row = wchild[node, WCHILD_INDEX + lowest_bit(inner)]
            inner &= inner - 1
            while inner != 0:
                stack[sp] = wchild[node, WCHILD_INDEX + lowest_bit(inner)]
                sp += 1
                inner &= inner - 1
            continue
        if sp == 0:
            return False
        sp -= 1
        row = stack[sp]



# ---- camera rays in packets: eight rays traced together, SIMD over the rays ----------------
# A pixel's camera rays (its samples of a pass) leave the same eye point (or lens) in
# nearly the same direction, so they visit the same nodes and leaves. One ray at a time, a
# traversal is a chain of dependent steps (load a node, test its boxes, pick the next) that
# leaves the core waiting between them: a bunny-studio camera ray took ~115 ns for ~3 node
# visits and ~1.2 triangle groups, cached and predicted (docs/benchmarks.md, 2026-11-29).
# Traced together (Wald, Slusallek, Benthin and Wagner 2001, "Interactive Rendering with
# Coherent Ray Tracing"; Embree's packet kernels), each child box is tested against the
# eight rays in one <8 x float> slab test and each triangle against the eight rays in one
# Moller-Trumbore test; a node is opened when any ray enters it, and each ray keeps its own
# nearest hit. The tests' arithmetic is slab's and ray_triangle's (as slab8's and
# triangles4's), operation for operation, and each ray tests triangles in leaf order with a
# strictly-nearer rule, so a ray's hit is the one closest_hit_wide finds (tested), but for
# two triangles at exactly the same distance, which the two visit orders may order
# differently.
#
# The packet lives in the last PACKET_WORDS words of the traversal stack (int32; its
# floats stored as their bits), so the kernels' arguments do not change; the traversals
# use the stack from its start and never reach it (accel.wide.WIDE_STACK_SIZE). Rows of
# PACKET lanes: the rays' origins (3 rows), 1/direction (3), directions (3), the nearest hit
# distance so far (t_max to start with; -1 for an unused lane, which enters no box), b1,
# b2, and the triangle hit (-1: none).

PACKET = 8
PK_O = 0
PK_INV = 3
PK_D = 6
PK_T = 9
PK_B1 = 10
PK_B2 = 11
PK_TRI = 12
PK_ROWS = 13
PACKET_WORDS = PK_ROWS * PACKET


def bits_float(b):
    """The float32 whose bits are the int32 b (float_bits' inverse)."""
    return np.float32(np.array(b, np.int32).view(np.float32))


def _packet_floats(stack):
    """The packet's rows as float32 (PK_ROWS, PACKET), a view (the Python forms)."""
    return stack[stack.shape[0] - PACKET_WORDS:].view(np.float32).reshape(PK_ROWS, PACKET)


def box_rays8(wide, row, k, stack):
    """(mask, t_min): the bit mask of the packet's rays that enter child k's box of the
    node at ``row`` before their nearest hit so far (slab, as closest_hit_wide tests it),
    and the least entry distance among them (INF if none)."""
    f = wide[row:row + NODE_ROWS].reshape(-1)
    p = _packet_floats(stack)
    mask = 0
    t_min = INF
    for r in range(PACKET):
        t = slab((p[PK_O, r], p[PK_O + 1, r], p[PK_O + 2, r]),
                 (p[PK_INV, r], p[PK_INV + 1, r], p[PK_INV + 2, r]),
                 f[k], f[WIDTH + k], f[2 * WIDTH + k], f[3 * WIDTH + k], f[4 * WIDTH + k],
                 f[5 * WIDTH + k], p[PK_T, r])
        if t < INF:
            mask |= 1 << r
            t_min = min(t_min, t)
    return mask, np.float32(t_min)


def triangle_rays8(wide, group_row, lane, tri, stack):
    """The triangle in lane ``lane`` of the group at ``group_row`` (triangle number tri)
    against the packet's rays: each ray that hits it strictly nearer than its nearest hit
    so far takes it (t, b1, b2, tri)."""
    f = wide[group_row:group_row + GROUP_ROWS].reshape(-1)
    row = np.array([[f[LANES * a + lane] for a in range(9)]], np.float32)
    p = _packet_floats(stack)
    tris = stack[stack.shape[0] - PACKET:]
    for r in range(PACKET):
        t, b1, b2 = ray_triangle((p[PK_O, r], p[PK_O + 1, r], p[PK_O + 2, r]),
                                 (p[PK_D, r], p[PK_D + 1, r], p[PK_D + 2, r]), row, 0,
                                 p[PK_T, r])
        if t < p[PK_T, r]:
            p[PK_T, r] = t
            p[PK_B1, r] = b1
            p[PK_B2, r] = b2
            tris[r] = tri


def _packet_row(context, builder, stack_ty, stack_value, r, vty):
    """A pointer to row r of the packet (vty: <8 x float> or <8 x i32>)."""
    ary = context.make_array(stack_ty)(context, builder, stack_value)
    n = builder.extract_value(ary.shape, 0)
    start = builder.sub(n, context.get_constant(types.intp, PACKET_WORDS - PACKET * r))
    return builder.bitcast(builder.gep(ary.data, [start]), vty.as_pointer())


def _scalar_at(context, builder, wide_ty, wide_value, row_value, row_ty, offset):
    """wide's float at flat index row * WIDE_ROW + offset (offset: an LLVM intp value)."""
    ary = context.make_array(wide_ty)(context, builder, wide_value)
    row = context.cast(builder, row_value, row_ty, types.intp)
    idx = builder.add(builder.mul(row, context.get_constant(types.intp, WIDE_ROW)), offset)
    return builder.load(builder.gep(ary.data, [idx]))


def _is_int32_vector(a):
    return isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and (
        a.dtype == types.int32)


@intrinsic
def _box_rays8_ir(typingctx, wide, row, k, stack):
    if not (_is_float32_rows(wide) and isinstance(row, types.Integer)
            and isinstance(k, types.Integer) and _is_int32_vector(stack)):
        return None
    sig = types.Tuple((types.int64, types.float32))(wide, row, k, stack)

    def codegen(context, builder, signature, args):
        v8, splat, lanes = _vector_helpers(context, builder, PACKET)
        wide_ty, row_ty, k_ty, stack_ty = signature.args
        k_value = context.cast(builder, args[2], k_ty, types.intp)

        def plane(c):       # child k's coordinate c (lo_x .. hi_z), for every ray
            off = builder.add(k_value, context.get_constant(types.intp, WIDTH * c))
            return splat(_scalar_at(context, builder, wide_ty, args[0], args[1], row_ty, off))

        def packet(r):
            return builder.load(_packet_row(context, builder, stack_ty, args[3], r, v8),
                                align=4)

        t_near, inside = _slab_ir(builder, v8, plane,
                                  [packet(PK_O + a) for a in range(3)],
                                  [packet(PK_INV + a) for a in range(3)],
                                  lambda: packet(PK_T))
        mask = builder.zext(builder.bitcast(inside, ir.IntType(PACKET)), ir.IntType(64))
        t = builder.select(inside, t_near, ir.Constant(v8, [math.inf] * PACKET))
        t_min = lanes(t)[0]
        for x in lanes(t)[1:]:
            t_min = builder.select(builder.fcmp_ordered("<", x, t_min), x, t_min)
        return context.make_tuple(builder, signature.return_type, [mask, t_min])
    return sig, codegen


@intrinsic
def _triangle_rays8_ir(typingctx, wide, group_row, lane, tri, stack):
    if not (_is_float32_rows(wide) and isinstance(group_row, types.Integer)
            and isinstance(lane, types.Integer) and isinstance(tri, types.Integer)
            and _is_int32_vector(stack)):
        return None
    sig = types.none(wide, group_row, lane, tri, stack)

    def codegen(context, builder, signature, args):
        v8, splat, _ = _vector_helpers(context, builder, PACKET)
        wide_ty, row_ty, lane_ty, tri_ty, stack_ty = signature.args
        lane_value = context.cast(builder, args[2], lane_ty, types.intp)

        def vertex(a):      # the triangle's float a (v0x .. e2z), for every ray
            off = builder.add(lane_value, context.get_constant(types.intp, LANES * a))
            return splat(_scalar_at(context, builder, wide_ty, args[0], args[1], row_ty, off))

        def row_ptr(r, vty=v8):
            return _packet_row(context, builder, stack_ty, args[4], r, vty)

        def packet(r):
            return builder.load(row_ptr(r), align=4)
        t_best = packet(PK_T)
        ok, t, b1, b2 = _moller_trumbore_ir(
            builder, v8, [vertex(a) for a in range(9)], [packet(PK_O + a) for a in range(3)],
            [packet(PK_D + a) for a in range(3)], lambda: t_best)
        builder.store(builder.select(ok, t, t_best), row_ptr(PK_T), align=4)
        builder.store(builder.select(ok, b1, packet(PK_B1)), row_ptr(PK_B1), align=4)
        builder.store(builder.select(ok, b2, packet(PK_B2)), row_ptr(PK_B2), align=4)
        vi = ir.VectorType(ir.IntType(32), PACKET)
        tri32 = builder.trunc(context.cast(builder, args[3], tri_ty, types.int64),
                              ir.IntType(32))
        tris = ir.Constant(vi, ir.Undefined)
        for r in range(PACKET):
            tris = builder.insert_element(tris, tri32, ir.Constant(ir.IntType(32), r))
        old = builder.load(row_ptr(PK_TRI, vi), align=4)
        builder.store(builder.select(ok, tris, old), row_ptr(PK_TRI, vi), align=4)
        return context.get_dummy_value()
    return sig, codegen


@intrinsic
def _bits_float_ir(typingctx, b):
    if b != types.int32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.FloatType())
    return types.float32(b), codegen


overload(box_rays8, strict=False)(
    lambda wide, row, k, stack: (lambda wide, row, k, stack: _box_rays8_ir(wide, row, k, stack)))
overload(triangle_rays8, strict=False)(
    lambda wide, group_row, lane, tri, stack:
    (lambda wide, group_row, lane, tri, stack:
     _triangle_rays8_ir(wide, group_row, lane, tri, stack)))
overload(bits_float, strict=False)(lambda b: (lambda b: _bits_float_ir(b)))


@device
def packet_set_ray(stack, lane, o, d, t_max):
    """Lane ``lane`` of the packet: the ray (o, d) with no hit yet before t_max (-1: an
    unused lane)."""
    inv = safe_inverse(d)
    base = stack.shape[0] - PACKET_WORDS + lane
    for a in range(3):
        stack[base + PACKET * (PK_O + a)] = float_bits(o[a])
        stack[base + PACKET * (PK_INV + a)] = float_bits(inv[a])
        stack[base + PACKET * (PK_D + a)] = float_bits(d[a])
    stack[base + PACKET * PK_T] = float_bits(t_max)
    stack[base + PACKET * PK_B1] = float_bits(ZERO)
    stack[base + PACKET * PK_B2] = float_bits(ZERO)
    stack[base + PACKET * PK_TRI] = -1


@device
def packet_ray_hit(stack, lane):
    """Lane ``lane``'s ray and nearest hit: (o, d, t, tri, b1, b2), t = INF and tri = -1 on a
    miss (closest_hit_wide's answer)."""
    base = stack.shape[0] - PACKET_WORDS + lane
    o = (bits_float(stack[base + PACKET * PK_O]), bits_float(stack[base + PACKET * (PK_O + 1)]),
         bits_float(stack[base + PACKET * (PK_O + 2)]))
    d = (bits_float(stack[base + PACKET * PK_D]), bits_float(stack[base + PACKET * (PK_D + 1)]),
         bits_float(stack[base + PACKET * (PK_D + 2)]))
    tri = stack[base + PACKET * PK_TRI]
    if tri < 0:
        return o, d, INF, -1, ZERO, ZERO
    return (o, d, bits_float(stack[base + PACKET * PK_T]), tri,
            bits_float(stack[base + PACKET * PK_B1]), bits_float(stack[base + PACKET * PK_B2]))


@device
def _packet_t_max(stack):
    """The farthest nearest-hit distance of the packet's rays (a node entered beyond it by
    every ray is of no use to any)."""
    base = stack.shape[0] - PACKET_WORDS + PACKET * PK_T
    t = bits_float(stack[base])
    for r in range(1, PACKET):
        t = max(t, bits_float(stack[base + r]))
    return t


@device
def closest_hit_packet(wide, wchild, stack):
    """The nearest hits of the packet's rays (packet_set_ray), left in the packet
    (packet_ray_hit): closest_hit_wide's for each ray, the nodes visited in the order of
    the least entry distance of the rays that enter them."""
    row = 0
    sp = 0
    while True:
        node = row // NODE_ROWS
        children = wchild[node, WCHILD_LEAVES] | wchild[node, WCHILD_INNER]
        base = sp
        while children != 0:
            k = lowest_bit(children)
            children &= children - 1
            mask, t_min = box_rays8(wide, row, k, stack)
            if mask == 0:
                continue
            count = wchild[node, WCHILD_COUNT + k]
            if count > 0:                   # a leaf: its triangles in order
                group_row = wchild[node, WCHILD_INDEX + k]
                first = wchild[node, WCHILD_FIRST + k]
                for j in range(count):
                    triangle_rays8(wide, group_row + GROUP_ROWS * (j // LANES), j % LANES,
                                   first + j, stack)
            else:                           # an inner node: pushed, this node's sorted
                key = float_bits(t_min)     # (farthest lowest)
                q = sp
                while q > base and stack[q - 1] < key:
                    stack[q] = stack[q - 2]
                    stack[q + 1] = stack[q - 1]
                    q -= 2
                stack[q] = wchild[node, WCHILD_INDEX + k]
                stack[q + 1] = key
                sp += 2
        # (closest_hit_wide's pop, against the farthest of the rays' nearest hits; a helper
        # shared by the two changed closest_hit_wide's code: bunny-studio 0.967x, bench.ab)
        limit = float_bits(_packet_t_max(stack) * SLAB_SCALE)
        while sp > 0 and stack[sp - 1] > limit:
            sp -= 2
        if sp == 0:
            return
        sp -= 2
        row = stack[sp]
