"""The eight-wide BVH of the CPU backend, collapsed from the binary BVH (see kernels.wide).

Each wide node starts from a binary node's two children and repeatedly replaces the inner
child of largest surface area by its own two children until it has eight (or only leaves
are left), the usual collapse of a binary SAH tree into a BVH8 (Wald et al. 2008; Embree).
Leaves keep their triangles (the scene's numbering is unchanged: shading reads the same
arrays) and get them packed four to a row for the SIMD triangle test. Linear in the node
count: 7 ms for the 69k-triangle bunny, 0.32-0.36 s for the 1.6M-triangle dragon on the
2-core CPU on a slow day (2026-11-28; the four-wide collapse took 0.34-0.45 s alongside).
"""
import numpy as np
from numba import njit

from .._cache import jit_cache, read_only
from ..kernels.constants import STACK_SIZE
from ..kernels.layout import (BOX_STRIDE, BOX_WIDTH, CHILD_COUNT, CHILD_INDEX, CHILD_STRIDE,
                              TRI_V_WIDTH)
from ..kernels.wide import (GROUP_ROWS, LANES, NODE_ROWS, PACKET_WORDS, WCHILD_COUNT,
                            WCHILD_FIRST, WCHILD_INDEX, WCHILD_INNER, WCHILD_LEAVES,
                            WCHILD_WIDTH, WIDE_ROW, WIDTH)

# closest_hit_wide (and closest_hit_packet) push at most seven (node, distance) pairs more
# than they pop per level of the wide tree, which is no deeper than the binary one
# (MAX_DEPTH = STACK_SIZE - 4 levels); the stack's last PACKET_WORDS words hold the camera
# rays' packet (kernels.wide.closest_hit_packet)
WIDE_TRAVERSAL_WORDS = 2 * (WIDTH - 1) * STACK_SIZE + 8
WIDE_STACK_SIZE = WIDE_TRAVERSAL_WORDS + PACKET_WORDS


@njit(cache=jit_cache())
def _small_subtrees(child, limit):
    """For every binary node: (first, count) of the triangles under it when they are at most
    ``limit`` and one contiguous range (count 0 otherwise). Such a subtree becomes one leaf
    of the wide tree: its triangles take one or two SIMD tests, fewer than the boxes that
    would lead to them (the SAH builder split them for one-at-a-time tests)."""
    n = child.shape[0]
    first = np.full(n, -1, np.int64)
    end = np.full(n, -1, np.int64)
    count = np.zeros(n, np.int64)
    order = np.empty(n, np.int64)       # pre-order; reversed, children come before parents
    stack = np.empty(n + 1, np.int64)
    stack[0] = 0
    sp = 1
    m = 0
    while sp > 0:
        sp -= 1
        b = stack[sp]
        order[m] = b
        m += 1
        for s in range(2):
            if child[b, s * CHILD_STRIDE + CHILD_COUNT] == 0:
                stack[sp] = child[b, s * CHILD_STRIDE + CHILD_INDEX]
                sp += 1
    for q in range(m - 1, -1, -1):
        b = order[q]
        lo = np.int64(-1)
        hi = np.int64(-1)
        total = np.int64(0)
        ok = True
        for s in range(2):
            c = np.int64(child[b, s * CHILD_STRIDE + CHILD_INDEX])
            cnt = np.int64(child[b, s * CHILD_STRIDE + CHILD_COUNT])
            if cnt == 0:
                if count[c] == 0:
                    ok = False
                    continue
                c_lo, c_hi, cnt = first[c], end[c], count[c]
            elif cnt > 0:
                c_lo, c_hi = c, c + cnt
            else:
                continue
            if total == 0:
                lo, hi = c_lo, c_hi
            elif c_lo == hi:
                hi = c_hi
            elif c_hi == lo:
                lo = c_lo
            else:
                ok = False
            total += cnt
        if ok and 0 < total <= limit:
            first[b], end[b], count[b] = lo, hi, total
    return first, count


@njit(cache=jit_cache())
def _take_child(box, child, b, s, sub_first, sub_count, kid_box, kid_index, kid_count, k):
    """Child s of binary node b into slot k of the wide node being made: its box, and its
    (index, count), an inner node of a small subtree turned into a leaf over its range."""
    for a in range(6):
        kid_box[k, a] = box[b, s * BOX_STRIDE + a]
    kid_index[k] = child[b, s * CHILD_STRIDE + CHILD_INDEX]
    kid_count[k] = child[b, s * CHILD_STRIDE + CHILD_COUNT]
    if kid_count[k] == 0 and sub_count[kid_index[k]] > 0:
        kid_count[k] = sub_count[kid_index[k]]
        kid_index[k] = sub_first[kid_index[k]]


@njit(cache=jit_cache())
def _collapse(box, child, merge):
    n = box.shape[0]
    sub_first, sub_count = _small_subtrees(child, merge)
    # (room for as many wide nodes as binary ones, but each row is filled only when its node
    # is made: the wide tree has ~a fifth as many, and filling all rows cost most of the
    # collapse's time on the 1.6M-triangle dragon)
    wbox = np.empty((n, NODE_ROWS * WIDE_ROW), np.float32)
    wchild = np.empty((n, WCHILD_WIDTH), np.int32)
    todo_bin = np.empty(n + 1, np.int64)      # (binary node, wide node, wide depth)
    todo_wide = np.empty(n + 1, np.int64)
    todo_depth = np.empty(n + 1, np.int64)
    todo_bin[0] = 0
    todo_wide[0] = 0
    todo_depth[0] = 1
    n_todo = 1
    n_wide = 1
    depth = 1
    kid_box = np.empty((WIDTH, 6), np.float32)
    kid_index = np.empty(WIDTH, np.int64)
    kid_count = np.empty(WIDTH, np.int64)
    while n_todo > 0:
        n_todo -= 1
        b = todo_bin[n_todo]
        w = todo_wide[n_todo]
        for q in range(wbox.shape[1]):
            wbox[w, q] = np.nan
        for q in range(WCHILD_WIDTH):
            wchild[w, q] = 0
        for j in range(WIDTH):
            wchild[w, WCHILD_COUNT + j] = -1
        d = todo_depth[n_todo]
        depth = max(depth, d)
        k = 0
        for s in range(2):
            if child[b, s * CHILD_STRIDE + CHILD_COUNT] >= 0:
                _take_child(box, child, b, s, sub_first, sub_count, kid_box, kid_index,
                            kid_count, k)
                k += 1
        while k < WIDTH:
            best = -1
            best_area = np.float32(-1.0)
            for j in range(k):
                if kid_count[j] == 0:
                    ex = kid_box[j, 3] - kid_box[j, 0]
                    ey = kid_box[j, 4] - kid_box[j, 1]
                    ez = kid_box[j, 5] - kid_box[j, 2]
                    area = ex * ey + ey * ez + ez * ex
                    if area > best_area:
                        best_area = area
                        best = j
            if best < 0:
                break
            inner = kid_index[best]
            slot = best                 # its first child takes its place, the second a new slot
            placed = 0
            for s in range(2):
                if child[inner, s * CHILD_STRIDE + CHILD_COUNT] >= 0:
                    j = slot if placed == 0 else k
                    _take_child(box, child, inner, s, sub_first, sub_count, kid_box,
                                kid_index, kid_count, j)
                    if placed == 1:
                        k += 1
                    placed += 1
            if placed == 0:             # an inner node without children: drop it
                k -= 1
                for a in range(6):
                    kid_box[best, a] = kid_box[k, a]
                kid_index[best] = kid_index[k]
                kid_count[best] = kid_count[k]
        for j in range(k):
            for a in range(3):
                wbox[w, WIDTH * a + j] = kid_box[j, a]
                wbox[w, WIDTH * (3 + a) + j] = kid_box[j, 3 + a]
            if kid_count[j] == 0:
                wchild[w, WCHILD_INDEX + j] = NODE_ROWS * n_wide     # its first row
                wchild[w, WCHILD_COUNT + j] = 0
                wchild[w, WCHILD_INNER] |= 1 << j
                todo_bin[n_todo] = kid_index[j]
                todo_wide[n_todo] = n_wide
                todo_depth[n_todo] = d + 1
                n_todo += 1
                n_wide += 1
            else:
                wchild[w, WCHILD_FIRST + j] = kid_index[j]
                wchild[w, WCHILD_COUNT + j] = kid_count[j]
                wchild[w, WCHILD_LEAVES] |= 1 << j
    return wbox[:n_wide].copy(), wchild[:n_wide].copy(), depth


@njit(cache=jit_cache())
def _pack(tri_v, wbox, wchild):
    """The ``wide`` array: the nodes' rows, then every leaf's triangles in groups of four
    (lanes past its end stay zero); the leaf entries get their first group's row."""
    n_nodes = wbox.shape[0]
    n_groups = 0
    for node in range(n_nodes):
        for j in range(WIDTH):
            count = wchild[node, WCHILD_COUNT + j]
            if count > 0:
                n_groups += (count + LANES - 1) // LANES
    wide = np.zeros((NODE_ROWS * n_nodes + GROUP_ROWS * n_groups, WIDE_ROW), np.float32)
    flat = wide.reshape(-1)
    for q in range(n_nodes):
        for c in range(wbox.shape[1]):
            wide[NODE_ROWS * q + c // WIDE_ROW, c % WIDE_ROW] = wbox[q, c]
    row = NODE_ROWS * n_nodes
    for node in range(n_nodes):
        for j in range(WIDTH):
            count = wchild[node, WCHILD_COUNT + j]
            if count > 0:
                first = wchild[node, WCHILD_FIRST + j]
                wchild[node, WCHILD_INDEX + j] = row
                for t in range(count):
                    base = (row + GROUP_ROWS * (t // LANES)) * WIDE_ROW + t % LANES
                    for a in range(TRI_V_WIDTH):
                        flat[base + LANES * a] = tri_v[first + t, a]
                row += GROUP_ROWS * ((count + LANES - 1) // LANES)
    return wide


def widen_bvh(tri_v, bvh_box, bvh_child, merge=LANES):
    """(wide, wchild) of kernels.wide from a scene's binary BVH arrays and triangles;
    subtrees of at most ``merge`` triangles become one leaf."""
    assert bvh_box.shape[1] == BOX_WIDTH and tri_v.shape[1] == TRI_V_WIDTH
    # (read-only, as in a Ray worker: one compiled version, see _cache.read_only)
    tri_v, bvh_box, bvh_child = read_only(tri_v), read_only(bvh_box), read_only(bvh_child)
    wbox, wchild, depth = _collapse(bvh_box, bvh_child, merge)
    assert 2 * (WIDTH - 1) * depth + 2 <= WIDE_TRAVERSAL_WORDS, depth
    return _pack(tri_v, wbox, wchild), wchild
