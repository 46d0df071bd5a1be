"""Iterative binned-SAH BVH builder (host code, compiled with ``@njit``).

Binning follows Wald 2007, "On fast Construction of SAH-based Bounding Volume Hierarchies":
centroids are binned on all three axes, prefix/suffix sweeps give the SAH cost of every bin
boundary, and the cheaper of the best split and a leaf wins. The tree is built with an
explicit task stack (no recursion, as tinybvh's ``BVH::Build``) and written straight into
the traversal layout of :mod:`pathtracer.kernels.traverse` (both child boxes in the parent).
Triangles are reordered so every leaf is a contiguous range.
"""
from typing import NamedTuple

import numpy as np
import numba
from numba import njit
from numba.cpython.unsafe.numbers import leading_zeros, trailing_zeros

from .._cache import jit_cache
from ..threads import run_tasks
from .simd import HI, ROW, bin_indices, centres, copy_row, min_into, swap_rows
from ..kernels.constants import STACK_SIZE
from ..kernels.layout import (BOX_CHILD0, BOX_CHILD1, BOX_MAX, BOX_MIN, BOX_STRIDE, BOX_WIDTH,
                              CHILD0_COUNT, CHILD0_INDEX, CHILD1_COUNT, CHILD1_INDEX,
                              CHILD_COUNT, CHILD_EMPTY, CHILD_INDEX, CHILD_STRIDE, CHILD_WIDTH)

# SAH constants: cost of one node visit relative to one triangle test.
C_TRAVERSAL = 1.0
C_INTERSECT = 1.0
MAX_DEPTH = STACK_SIZE - 4  # deeper subtrees become leaves: the traversal stack never overflows
# Parallel build: above PARALLEL_MIN triangles, the first pass builds the top of the tree
# and leaves subtrees of at most 2/threads of the triangles (and at least DEFER_MIN), which
# are then built in parallel: two threads build the root's two subtrees.
PARALLEL_MIN = 1 << 16
DEFER_MIN = 1 << 10
DEFERRED = -7                # a child count marking a subtree built by another run
MAX_BINS = 64                # a node's filled bins are bits of an int64 (_run)


class BVH(NamedTuple):
    box: np.ndarray    # float32 (M, BOX_WIDTH): both children's boxes (kernels.layout)
    child: np.ndarray  # int32 (M, CHILD_WIDTH): both children's (index, count)
    order: np.ndarray  # int32 (N,): new triangle k is input triangle order[k]
    depth: int


@njit(cache=jit_cache())
def box_area(lo, hi):
    """Surface area of the box lo..hi (0 for an empty or inverted one)."""
    dx = max(hi[0] - lo[0], 0.0)
    dy = max(hi[1] - lo[1], 0.0)
    dz = max(hi[2] - lo[2], 0.0)
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@njit(cache=jit_cache())
def _row_centre(rows, k, a):
    """The centre of triangle row k's box (accel.simd: lo and the negated hi) on axis a, in
    float64: 0.5 * (lo + hi), exact (half the sum of two float32 values), so it is computed
    where needed instead of stored and moved with the triangles."""
    return 0.5 * (np.float64(rows[k, a]) - np.float64(rows[k, HI + a]))


@njit(cache=jit_cache())
def _row_area(acc):
    """box_area of the box in row 0 of acc (a bounds row: lo, then the negated hi)."""
    dx = max(-np.float64(acc[0, HI]) - np.float64(acc[0, 0]), 0.0)
    dy = max(-np.float64(acc[0, HI + 1]) - np.float64(acc[0, 1]), 0.0)
    dz = max(-np.float64(acc[0, HI + 2]) - np.float64(acc[0, 2]), 0.0)
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@njit(cache=jit_cache())
def _axis(a, x0, x1, x2):
    """x_a of three per-axis values kept in locals (registers), not an array."""
    return x0 if a == 0 else (x1 if a == 1 else x2)


@njit(cache=jit_cache())
def _grow(bounds, m0, m1, m2):
    """(lo0, lo1, lo2, hi0, hi1, hi2) ``bounds`` grown to take in the point m."""
    return (min(bounds[0], m0), min(bounds[1], m1), min(bounds[2], m2),
            max(bounds[3], m0), max(bounds[4], m1), max(bounds[5], m2))


@njit(cache=jit_cache())
def _rows_bounds(rows, start, end, lo, hi, clo, chi):
    """Into lo/hi and clo/chi: the bounds of triangle rows start..end-1 and of their
    centres."""
    for a in range(3):
        lo[a] = np.inf
        hi[a] = -np.inf
        clo[a] = np.inf
        chi[a] = -np.inf
    for k in range(start, end):
        for a in range(3):
            lo[a] = min(lo[a], rows[k, a])
            hi[a] = max(hi[a], -rows[k, HI + a])
            m = _row_centre(rows, k, a)
            clo[a] = min(clo[a], m)
            chi[a] = max(chi[a], m)


@njit(cache=jit_cache())
def _run(rows, order, tasks, task_box, n_tasks, box, child, n_bins, max_leaf,
         min_leaf_split, midpoint, defer, deferred, deferred_box):
    """The build loop over the task stack ``tasks`` (rows: start, end, parent node, side,
    depth, bounds known; ``task_box``: lo, hi, centroid lo, centroid hi) into the node
    arrays ``box``/``child`` (node 0 is the root of whatever ``tasks`` holds). A task of
    DEFER_MIN to ``defer`` triangles (0: never) that would become an inner node below the
    root is not built but appended to ``deferred`` (same row layout; its bounds in
    ``deferred_box``), its node box already written in its parent: another run builds it.
    Returns (nodes, depth, deferred count)."""
    bins = np.empty((3 * n_bins, ROW), np.float32)    # axis a's bin b: row a * n_bins + b
    acc = np.empty((1, ROW), np.float32)
    bin_n = np.empty((3, n_bins), np.int64)
    right_area = np.empty(n_bins)
    right_n = np.empty(n_bins, np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    clo = np.empty(3)
    chi = np.empty(3)
    side_b = np.empty((2, 12))     # the children's bounds, as task_box rows
    n_nodes = 1
    n_deferred = 0
    max_depth = 0
    while n_tasks > 0:
        n_tasks -= 1
        start = tasks[n_tasks, 0]
        end = tasks[n_tasks, 1]
        parent = tasks[n_tasks, 2]
        side = tasks[n_tasks, 3]
        depth = tasks[n_tasks, 4]
        max_depth = max(max_depth, depth)
        count = end - start
        if defer > 0 and parent >= 0 and DEFER_MIN <= count <= defer and count > max_leaf and \
                count >= min_leaf_split and depth < MAX_DEPTH:
            # another run builds this subtree; its box goes into the parent now
            if not tasks[n_tasks, 5]:
                _rows_bounds(rows, start, end, lo, hi, clo, chi)
                for a in range(3):
                    task_box[n_tasks, a] = lo[a]
                    task_box[n_tasks, 3 + a] = hi[a]
                    task_box[n_tasks, 6 + a] = clo[a]
                    task_box[n_tasks, 9 + a] = chi[a]
                tasks[n_tasks, 5] = 1
            for c in range(6):
                deferred[n_deferred, c] = tasks[n_tasks, c]
            for c in range(12):
                deferred_box[n_deferred, c] = task_box[n_tasks, c]
            b = BOX_CHILD0 + BOX_STRIDE * side
            for c in range(3):
                box[parent, b + BOX_MIN + c] = task_box[n_tasks, c]
                box[parent, b + BOX_MAX + c] = task_box[n_tasks, 3 + c]
            child[parent, CHILD_STRIDE * side + CHILD_INDEX] = n_deferred
            child[parent, CHILD_STRIDE * side + CHILD_COUNT] = DEFERRED
            n_deferred += 1
            continue
        if tasks[n_tasks, 5]:
            for a in range(3):
                lo[a] = task_box[n_tasks, a]
                hi[a] = task_box[n_tasks, 3 + a]
                clo[a] = task_box[n_tasks, 6 + a]
                chi[a] = task_box[n_tasks, 9 + a]
        else:
            _rows_bounds(rows, start, end, lo, hi, clo, chi)
        # Find the best binned split.
        best_cost = np.inf
        best_axis = -1
        best_bin = 0
        parent_area = box_area(lo, hi)
        binned = False
        if count >= min_leaf_split and depth < MAX_DEPTH:
            binned = True
            # A bin is marked in its axis's bit mask when first filled (its bounds and count
            # set then): nothing is cleared per node, and the sweeps visit only the filled
            # bins, so a small node's work follows its triangles, not n_bins.
            mask0 = 0
            mask1 = 0
            mask2 = 0
            inv0 = n_bins / (chi[0] - clo[0]) if chi[0] - clo[0] > 0.0 else 0.0
            inv1 = n_bins / (chi[1] - clo[1]) if chi[1] - clo[1] > 0.0 else 0.0
            inv2 = n_bins / (chi[2] - clo[2]) if chi[2] - clo[2] > 0.0 else 0.0
            for k in range(start, end):
                # (an axis without extent, inv 0, fills bin 0: never read, see below)
                b0, b1, b2 = bin_indices(rows, k, clo[0], clo[1], clo[2], inv0, inv1, inv2,
                                         n_bins - 1)
                for a in range(3):
                    b = _axis(a, b0, b1, b2)
                    bit = np.int64(1) << b
                    m = _axis(a, mask0, mask1, mask2)
                    if (m & bit) == 0:
                        if a == 0:
                            mask0 |= bit
                        elif a == 1:
                            mask1 |= bit
                        else:
                            mask2 |= bit
                        copy_row(bins, a * n_bins + b, rows, k)
                        bin_n[a, b] = 1
                    else:
                        min_into(bins, a * n_bins + b, rows, k)
                        bin_n[a, b] += 1
            for a in range(3):
                if chi[a] - clo[a] <= 0.0:
                    continue
                filled = _axis(a, mask0, mask1, mask2)
                # Suffix sweep over the filled bins, highest first: right_n[b] and
                # right_area[b] of filled bin b are the count and area of the bins >= b.
                for c in range(ROW):
                    acc[0, c] = np.inf
                acc_n = 0
                m = filled
                while m != 0:
                    b = 63 - leading_zeros(m)
                    m ^= np.int64(1) << b
                    acc_n += bin_n[a, b]
                    min_into(acc, 0, bins, a * n_bins + b)
                    right_n[b] = acc_n
                    right_area[b] = _row_area(acc)
                # Prefix sweep. Boundary c splits bins < c from bins >= c; between two
                # filled bins b < b' every boundary b < c <= b' costs the same, and the
                # first of them, b + 1, is the one a sweep over all boundaries keeps.
                for c in range(ROW):
                    acc[0, c] = np.inf
                acc_n = 0
                m = filled
                while m != 0:
                    b = trailing_zeros(m)
                    m ^= np.int64(1) << b
                    if m == 0:
                        break
                    acc_n += bin_n[a, b]
                    min_into(acc, 0, bins, a * n_bins + b)
                    left_a = _row_area(acc)
                    nxt = trailing_zeros(m)
                    cost = acc_n * left_a + right_n[nxt] * right_area[nxt]
                    if cost < best_cost:
                        best_cost = cost
                        best_axis = a
                        best_bin = b + 1
        split_cost = np.inf
        if best_axis >= 0:
            split_cost = C_TRAVERSAL + C_INTERSECT * best_cost / max(parent_area, 1e-300)
        leaf_cost = C_INTERSECT * count
        make_leaf = count < min_leaf_split or depth >= MAX_DEPTH or (
            leaf_cost <= split_cost and count <= max_leaf)
        if midpoint and count >= min_leaf_split and depth < MAX_DEPTH:
            # The thesis's "plane division" (for comparison only): the middle of the
            # centroid bounds' longest axis, leaves by size alone; SAH's choice only where
            # the middle leaves one side empty.
            a = 0
            for c in range(1, 3):
                if chi[c] - clo[c] > chi[a] - clo[a]:
                    a = c
            left = 0
            filled = _axis(a, mask0, mask1, mask2)
            for b in range(n_bins // 2):
                if (filled >> b) & 1:
                    left += bin_n[a, b]
            if chi[a] - clo[a] > 0.0 and 0 < left < count:
                best_axis = a
                best_bin = n_bins // 2
            make_leaf = count <= max_leaf or best_axis < 0
        mid = start
        known = 0
        if not make_leaf:
            if best_axis >= 0:
                # Partition in place (bins < best_bin go left), the per-triangle arrays
                # with the order; the children's centroid bounds on the way, their
                # triangle bounds from the bins.
                a = best_axis
                scale = n_bins / (chi[a] - clo[a])
                # the children's centroid bounds in registers (in side_b each bound's load
                # waited on its last store, every triangle)
                left_c = (np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf)
                right_c = left_c
                ca = clo[a]
                last = n_bins - 1
                i = start
                j = end - 1
                while i <= j:
                    m0, m1, m2 = centres(rows, i)
                    ma = _axis(a, m0, m1, m2)
                    b = min(int((ma - ca) * scale), last)
                    if b < best_bin:
                        left_c = _grow(left_c, m0, m1, m2)
                        i += 1
                    else:
                        right_c = _grow(right_c, m0, m1, m2)
                        tmp = order[i]
                        order[i] = order[j]
                        order[j] = tmp
                        swap_rows(rows, i, j)
                        j -= 1
                for q in range(2):
                    for c in range(3):
                        side_b[q, c] = np.inf
                        side_b[q, 3 + c] = -np.inf
                for c in range(6):
                    side_b[0, 6 + c] = left_c[c]
                    side_b[1, 6 + c] = right_c[c]
                mid = i
                if binned:
                    filled = _axis(a, mask0, mask1, mask2)
                    for b in range(n_bins):
                        if (filled >> b) & 1 == 0:
                            continue
                        q = 0 if b < best_bin else 1
                        for c in range(3):
                            side_b[q, c] = min(side_b[q, c], bins[a * n_bins + b, c])
                            side_b[q, 3 + c] = max(side_b[q, 3 + c],
                                                   -bins[a * n_bins + b, HI + c])
                    known = 1
            else:
                # All centroids coincide: no spatial split exists; halve the range so the
                # leaves stay small (keeps the worst case bounded for degenerate input).
                mid = start + count // 2
        # Where this range's node lives: the root is node 0; others fill a parent slot.
        if parent < 0:
            node = 0
            if make_leaf:
                # A whole scene in one leaf: root with one leaf child and one empty child.
                for c in range(3):
                    box[0, BOX_CHILD0 + BOX_MIN + c] = lo[c]
                    box[0, BOX_CHILD0 + BOX_MAX + c] = hi[c]
                child[0, CHILD0_INDEX] = start
                child[0, CHILD0_COUNT] = count
                child[0, CHILD1_INDEX] = 0
                child[0, CHILD1_COUNT] = CHILD_EMPTY
                continue
        else:
            b = BOX_CHILD0 + BOX_STRIDE * side
            for c in range(3):
                box[parent, b + BOX_MIN + c] = lo[c]
                box[parent, b + BOX_MAX + c] = hi[c]
            k = CHILD_STRIDE * side
            if make_leaf:
                child[parent, k + CHILD_INDEX] = start
                child[parent, k + CHILD_COUNT] = count
                continue
            node = n_nodes
            n_nodes += 1
            child[parent, k + CHILD_INDEX] = node
            child[parent, k + CHILD_COUNT] = 0
        # Children tasks: right first so the left subtree is built (and laid out) first.
        for q in range(1, -1, -1):
            tasks[n_tasks, 0] = mid if q == 1 else start
            tasks[n_tasks, 1] = end if q == 1 else mid
            tasks[n_tasks, 2] = node
            tasks[n_tasks, 3] = q
            tasks[n_tasks, 4] = depth + 1
            tasks[n_tasks, 5] = known
            if known:
                for c in range(12):
                    task_box[n_tasks, c] = side_b[q, c]
            n_tasks += 1
    return n_nodes, max_depth, n_deferred


def _build(tri_rows, n_bins, max_leaf, min_leaf_split, midpoint, threads):
    """The tree, the triangle order, node count and depth. The per-triangle bounds
    (``tri_rows``, rows of accel.simd; scratch, changed) are reordered along with
    ``order`` (the partitions swap them; centres are computed from them where needed),
    so every pass reads them in sequence; a node's bounds come with its task (from the
    parent's bins and partition), so each range is read twice (bin, partition), not three
    times. The top of the tree is built first (_build_top), down to subtrees of at most
    2/threads of the triangles, which are then built on threads (_subtree) and the nodes
    numbered as one sequential build numbers them (_assemble): the tree is exactly that of
    the plain formulation, tests/bvh_oracle.build_plain (tested), for any thread count."""
    box, child, order, n_top, depth, deferred, deferred_box, n_def = _build_top(
        tri_rows, n_bins, max_leaf, min_leaf_split, midpoint, threads)
    if n_def == 0:
        return box[:n_top].copy(), child[:n_top].copy(), order, n_top, depth
    offsets = np.zeros(n_def + 1, np.int64)
    offsets[1:] = np.cumsum(deferred[:n_def, 1] - deferred[:n_def, 0])
    sub_box = np.zeros((offsets[n_def], BOX_WIDTH), np.float32)
    sub_child = np.full((offsets[n_def], CHILD_WIDTH), CHILD_EMPTY, np.int32)
    sub_nodes = np.zeros(n_def, np.int64)
    sub_depth = np.zeros(n_def, np.int64)
    run_tasks(_subtree, (tri_rows, order, deferred, deferred_box, offsets, sub_box, sub_child,
                         sub_nodes, sub_depth, n_bins, max_leaf, min_leaf_split, midpoint),
              n_def, threads)
    depth = max(depth, int(sub_depth.max()))
    out_box, out_child, total = _assemble(box, child, n_top, sub_box, sub_child, offsets,
                                          sub_nodes)
    return out_box, out_child, order, total, depth


@njit(cache=jit_cache())
def _build_top(tri_rows, n_bins, max_leaf, min_leaf_split, midpoint, threads):
    """The top of the tree (all of it below PARALLEL_MIN triangles): its nodes, the
    triangle order, node count, depth and the deferred subtrees' tasks (_run)."""
    n = tri_rows.shape[0]
    order = np.arange(n).astype(np.int32)
    # Deferred tasks are children of top nodes of more than `defer` triangles, at most
    # threads / 2 of them per depth: at most threads * (MAX_DEPTH + 1) deferred.
    rows_def = max(threads, 1) * (MAX_DEPTH + 1) + 8
    deferred = np.zeros((rows_def, 6), np.int64)
    deferred_box = np.zeros((rows_def, 12))
    if n == 0:
        box = np.zeros((1, BOX_WIDTH), np.float32)
        child = np.full((1, CHILD_WIDTH), CHILD_EMPTY, np.int32)
        return box, child, order, 1, 0, deferred, deferred_box, 0
    # reordered in place: the caller's array is scratch (build_bvh makes it)
    n_rows = 4 * STACK_SIZE + 8
    tasks = np.zeros((n_rows, 6), np.int64)
    task_box = np.zeros((n_rows, 12))
    tasks[0, 1] = n
    tasks[0, 2] = -1
    box = np.zeros((max(1, n), BOX_WIDTH), np.float32)
    child = np.full((max(1, n), CHILD_WIDTH), CHILD_EMPTY, np.int32)
    defer = (2 * n) // max(threads, 1) if n >= PARALLEL_MIN else 0
    n_top, depth, n_def = _run(tri_rows, order, tasks, task_box, 1, box, child,
                               n_bins, max_leaf, min_leaf_split, midpoint, defer, deferred,
                               deferred_box)
    return box, child, order, n_top, depth, deferred, deferred_box, n_def


@njit(nogil=True, cache=jit_cache())
def _subtree(tri_rows, order, deferred, deferred_box, offsets, sub_box, sub_child,
             sub_nodes, sub_depth, n_bins, max_leaf, min_leaf_split, midpoint, k):
    """Build deferred subtree k (the subtrees' triangle ranges are disjoint: one thread
    each) into rows offsets[k]... of sub_box/sub_child with its own node numbering (its
    root: 0)."""
    rows = 4 * STACK_SIZE + 8
    tasks = np.zeros((rows, 6), np.int64)
    task_box = np.zeros((rows, 12))
    for c in range(6):
        tasks[0, c] = deferred[k, c]
    for c in range(12):
        task_box[0, c] = deferred_box[k, c]
    tasks[0, 2] = -1                       # the subtree's root: node 0 of its rows
    lo = offsets[k]
    hi = offsets[k + 1]
    none = np.zeros((1, 6), np.int64)
    none_box = np.zeros((1, 12))
    # (defer as an int64, not the literal 0: a literal argument would make Numba
    # compile a second _run for it, 7 s of the builder's ~20 s cold compile)
    nodes, depth, _ = _run(tri_rows, order, tasks, task_box, 1, sub_box[lo:hi],
                           sub_child[lo:hi], n_bins, max_leaf, min_leaf_split,
                           midpoint, np.int64(0), none, none_box)
    sub_nodes[k] = nodes
    sub_depth[k] = depth


@njit(cache=jit_cache())
def _assemble(box, child, n_top, sub_box, sub_child, offsets, sub_nodes):
    """One node array from the top tree and the subtrees, numbered in the order a
    sequential build creates nodes: depth first, left child first (pre-order)."""
    total = n_top
    for k in range(sub_nodes.shape[0]):
        total += sub_nodes[k]
    out_box = np.zeros((total, BOX_WIDTH), np.float32)
    out_child = np.full((total, CHILD_WIDTH), CHILD_EMPTY, np.int32)
    # stack of (tree: -1 top or subtree k, node in that tree, output parent, side)
    stack = np.zeros((4 * STACK_SIZE + 64, 4), np.int64)
    stack[0, 0] = -1
    stack[0, 1] = 0
    stack[0, 2] = -1
    n_stack = 1
    n_out = 0
    while n_stack > 0:
        n_stack -= 1
        tree = stack[n_stack, 0]
        node = stack[n_stack, 1]
        out_parent = stack[n_stack, 2]
        side = stack[n_stack, 3]
        me = n_out
        n_out += 1
        if out_parent >= 0:
            out_child[out_parent, CHILD_STRIDE * side + CHILD_INDEX] = me
            out_child[out_parent, CHILD_STRIDE * side + CHILD_COUNT] = 0
        if tree < 0:
            row_box = box[node]
            row_child = child[node]
        else:
            row_box = sub_box[offsets[tree] + node]
            row_child = sub_child[offsets[tree] + node]
        for c in range(BOX_WIDTH):
            out_box[me, c] = row_box[c]
        # children: push right first, so the left subtree is numbered first
        for q in range(1, -1, -1):
            index = row_child[CHILD_STRIDE * q + CHILD_INDEX]
            count = row_child[CHILD_STRIDE * q + CHILD_COUNT]
            if count == DEFERRED:              # (top tree only) subtree `index`
                stack[n_stack, 0] = index
                stack[n_stack, 1] = 0
            elif count == 0:                   # an inner node of the same tree
                stack[n_stack, 0] = tree
                stack[n_stack, 1] = index
            else:                              # a leaf or an empty slot: copied
                out_child[me, CHILD_STRIDE * q + CHILD_INDEX] = index
                out_child[me, CHILD_STRIDE * q + CHILD_COUNT] = count
                continue
            stack[n_stack, 2] = me
            stack[n_stack, 3] = q
            n_stack += 1
    return out_box, out_child, total


def build_bvh(tri_verts, n_bins=16, max_leaf=8, split="sah", _plain=None, _threads=None):
    """Build a BVH over triangles ``tri_verts`` (float32, N x 3 x 3).

    ``split``: "sah" (binned SAH, the renderer's), or, for the benchmark's comparisons,
    "midpoint" (middle of the longest axis) and "none" (one leaf: brute force).
    Returns a :class:`BVH`; reorder the triangle arrays with ``bvh.order`` before use.
    """
    if split not in ("sah", "midpoint", "none"):
        raise ValueError(f"unknown split {split!r}")
    tri_verts = np.ascontiguousarray(tri_verts, dtype=np.float32)
    if tri_verts.ndim != 3 or tri_verts.shape[1:] != (3, 3):
        raise ValueError(f"triangles must be N x 3 x 3, not {tri_verts.shape}")
    if not 2 <= int(n_bins) <= MAX_BINS:
        raise ValueError(f"n_bins must be 2 to {MAX_BINS}, not {n_bins}")
    min_leaf_split = len(tri_verts) + 1 if split == "none" else 2
    if _plain is not None:
        # a test oracle's builder (tests/bvh_oracle.py: the builder as first written)
        tri_lo, tri_hi = _triangle_bounds(tri_verts)
        centroid = 0.5 * (tri_lo.astype(np.float64) + tri_hi.astype(np.float64))
        box, child, order, _, depth = _plain(tri_lo, tri_hi, centroid, int(n_bins),
                                             int(max_leaf), min_leaf_split,
                                             split == "midpoint")
    else:
        threads = numba.get_num_threads() if _threads is None else int(_threads)
        box, child, order, _, depth = _build(_triangle_rows(tri_verts), int(n_bins),
                                             int(max_leaf), min_leaf_split,
                                             split == "midpoint", threads)
    _widen(box)
    return BVH(box, child, order, int(depth))


def _triangle_bounds(tri_verts):
    """Per-triangle bounds (float32, N x 3 each); vertices are finite (the scene loader
    checks)."""
    rows = _triangle_rows(tri_verts)
    return rows[:, :3].copy(), -rows[:, HI:HI + 3]


def _triangle_rows(tri_verts):
    """Per-triangle bounds as the builder's rows (accel.simd): lo, 0, -hi, 0 (float32), on
    every thread."""
    rows = np.zeros((tri_verts.shape[0], ROW), np.float32)
    chunks = _chunks(tri_verts.shape[0])
    run_tasks(_triangle_rows_chunk, (tri_verts, rows, chunks), chunks, chunks)
    return rows


def _chunks(n):
    """How many pieces a loop over n items is cut into for the threads (one below 64k)."""
    return max(1, min(numba.get_num_threads(), n >> 16))


@njit(nogil=True, cache=jit_cache())
def _triangle_rows_chunk(tri_verts, rows, chunks, k):
    n = tri_verts.shape[0]
    for t in range(n * k // chunks, n * (k + 1) // chunks):
        for a in range(3):
            x0 = tri_verts[t, 0, a]
            x1 = tri_verts[t, 1, a]
            x2 = tri_verts[t, 2, a]
            rows[t, a] = min(x0, min(x1, x2))
            rows[t, HI + a] = -max(x0, max(x1, x2))


def _widen(box):
    """Push every bound two float32 ulps outward, in place. A ray with a zero direction
    component whose origin lies exactly on a box face would otherwise get the slab
    (0 * BIG = 0) and miss the box; with widened boxes no triangle vertex lies on a face."""
    chunks = _chunks(box.shape[0])
    run_tasks(_widen_chunk, (box, chunks), chunks, chunks)


@njit(nogil=True, cache=jit_cache())
def _widen_chunk(box, chunks, k):
    down = np.float32(-np.inf)
    up = np.float32(np.inf)
    n = box.shape[0]
    for t in range(n * k // chunks, n * (k + 1) // chunks):
        for side in (BOX_CHILD0, BOX_CHILD1):
            for c in range(3):
                lo = box[t, side + BOX_MIN + c]
                hi = box[t, side + BOX_MAX + c]
                box[t, side + BOX_MIN + c] = np.nextafter(np.nextafter(lo, down), down)
                box[t, side + BOX_MAX + c] = np.nextafter(np.nextafter(hi, up), up)


def sah_cost(bvh):
    """SAH cost of the tree (C_trav per inner node visit, C_int per triangle test),
    normalised by the root's surface area: the expected cost of a random ray."""
    box = bvh.box.astype(np.float64)
    child = bvh.child

    def corners(k, side):
        b = BOX_CHILD0 + BOX_STRIDE * side
        return (box[k, b + BOX_MIN:b + BOX_MIN + 3], box[k, b + BOX_MAX:b + BOX_MAX + 3])

    def area(lo, hi):
        d = np.maximum(hi - lo, 0.0)
        return 2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])

    root_lo, root_hi = corners(0, 0)
    if child[0, CHILD1_COUNT] >= 0:
        lo1, hi1 = corners(0, 1)
        root_lo, root_hi = np.minimum(root_lo, lo1), np.maximum(root_hi, hi1)
    root_area = area(root_lo, root_hi)
    if root_area <= 0:
        return float("nan")
    cost = C_TRAVERSAL  # the root is always visited
    for k in range(box.shape[0]):
        for side in range(2):
            n = child[k, CHILD_STRIDE * side + CHILD_COUNT]
            if n < 0:
                continue
            a = area(*corners(k, side)) / root_area
            cost += a * (C_TRAVERSAL if n == 0 else C_INTERSECT * n)
    return cost
