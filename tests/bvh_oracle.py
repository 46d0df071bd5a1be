"""The BVH builder as first written: one thread, node bounds recomputed per node, every
range read three times. A test oracle (tests/test_bvh.py: the fast builder,
pathtracer.accel.bvh._build, makes exactly its tree) and the benchmark's baseline
(bench/bvh_build.py); passed to ``build_bvh(..., _plain=build_plain)``."""
import numpy as np
from numba import njit

from pathtracer._cache import jit_cache
from pathtracer.accel.bvh import C_INTERSECT, C_TRAVERSAL, MAX_DEPTH, box_area
from pathtracer.kernels.constants import STACK_SIZE
from pathtracer.kernels.layout import (BOX_CHILD0, BOX_MAX, BOX_MIN, BOX_STRIDE, BOX_WIDTH,
                                       CHILD0_COUNT, CHILD0_INDEX, CHILD1_COUNT, CHILD1_INDEX,
                                       CHILD_COUNT, CHILD_EMPTY, CHILD_INDEX, CHILD_STRIDE,
                                       CHILD_WIDTH)


@njit(cache=jit_cache())
def build_plain(tri_lo, tri_hi, centroid, n_bins, max_leaf, min_leaf_split, midpoint):
    """The builder as first written (kept to test that the faster _build makes the same
    tree)."""
    n = tri_lo.shape[0]
    order = np.arange(n).astype(np.int32)
    max_nodes = max(1, n)
    box = np.zeros((max_nodes, BOX_WIDTH), np.float32)
    child = np.full((max_nodes, CHILD_WIDTH), CHILD_EMPTY, np.int32)
    n_nodes = 1
    # tasks: (start, end, parent node, side, depth)
    tasks = np.zeros((4 * STACK_SIZE + 8, 5), np.int64)
    n_tasks = 1
    tasks[0, 0] = 0
    tasks[0, 1] = n
    tasks[0, 2] = -1
    tasks[0, 3] = 0
    tasks[0, 4] = 0
    bin_lo = np.empty((3, n_bins, 3))
    bin_hi = np.empty((3, n_bins, 3))
    bin_n = np.empty((3, n_bins), np.int64)
    right_area = np.empty(n_bins)
    right_n = np.empty(n_bins, np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    clo = np.empty(3)
    chi = np.empty(3)
    acc_lo = np.empty(3)
    acc_hi = np.empty(3)
    max_depth = 0
    if n == 0:
        child[0, CHILD0_COUNT] = CHILD_EMPTY
        child[0, CHILD1_COUNT] = CHILD_EMPTY
        return box, child, order, 1, 0
    while n_tasks > 0:
        n_tasks -= 1
        start = tasks[n_tasks, 0]
        end = tasks[n_tasks, 1]
        parent = tasks[n_tasks, 2]
        side = tasks[n_tasks, 3]
        depth = tasks[n_tasks, 4]
        max_depth = max(max_depth, depth)
        count = end - start
        # Bounds of the range's triangles and of their centroids.
        for a in range(3):
            lo[a] = np.inf
            hi[a] = -np.inf
            clo[a] = np.inf
            chi[a] = -np.inf
        for k in range(start, end):
            t = order[k]
            for a in range(3):
                lo[a] = min(lo[a], tri_lo[t, a])
                hi[a] = max(hi[a], tri_hi[t, a])
                clo[a] = min(clo[a], centroid[t, a])
                chi[a] = max(chi[a], centroid[t, a])
        # Find the best binned split.
        best_cost = np.inf
        best_axis = -1
        best_bin = 0
        parent_area = box_area(lo, hi)
        if count >= min_leaf_split and depth < MAX_DEPTH:
            for a in range(3):
                for b in range(n_bins):
                    bin_n[a, b] = 0
                    for c in range(3):
                        bin_lo[a, b, c] = np.inf
                        bin_hi[a, b, c] = -np.inf
            for k in range(start, end):
                t = order[k]
                for a in range(3):
                    extent = chi[a] - clo[a]
                    if extent > 0.0:
                        b = int((centroid[t, a] - clo[a]) * (n_bins / extent))
                        b = min(b, n_bins - 1)
                        bin_n[a, b] += 1
                        for c in range(3):
                            bin_lo[a, b, c] = min(bin_lo[a, b, c], tri_lo[t, c])
                            bin_hi[a, b, c] = max(bin_hi[a, b, c], tri_hi[t, c])
            for a in range(3):
                if chi[a] - clo[a] <= 0.0:
                    continue
                # Suffix sweep: area and count right of each boundary.
                for c in range(3):
                    acc_lo[c] = np.inf
                    acc_hi[c] = -np.inf
                acc_n = 0
                for b in range(n_bins - 1, 0, -1):
                    acc_n += bin_n[a, b]
                    for c in range(3):
                        acc_lo[c] = min(acc_lo[c], bin_lo[a, b, c])
                        acc_hi[c] = max(acc_hi[c], bin_hi[a, b, c])
                    right_n[b] = acc_n
                    right_area[b] = box_area(acc_lo, acc_hi) if acc_n > 0 else 0.0
                # Prefix sweep; boundary b splits bins < b from bins >= b.
                for c in range(3):
                    acc_lo[c] = np.inf
                    acc_hi[c] = -np.inf
                acc_n = 0
                for b in range(1, n_bins):
                    acc_n += bin_n[a, b - 1]
                    for c in range(3):
                        acc_lo[c] = min(acc_lo[c], bin_lo[a, b - 1, c])
                        acc_hi[c] = max(acc_hi[c], bin_hi[a, b - 1, c])
                    if acc_n == 0 or right_n[b] == 0:
                        continue
                    cost = acc_n * box_area(acc_lo, acc_hi) + right_n[b] * right_area[b]
                    if cost < best_cost:
                        best_cost = cost
                        best_axis = a
                        best_bin = b
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
            for b in range(n_bins // 2):
                left += bin_n[a, b]
            if chi[a] - clo[a] > 0.0 and 0 < left < count:
                best_axis = a
                best_bin = n_bins // 2
            make_leaf = count <= max_leaf or best_axis < 0
        mid = start
        if not make_leaf:
            if best_axis >= 0:
                # Partition in place: bins < best_bin go left.
                a = best_axis
                scale = n_bins / (chi[a] - clo[a])
                i = start
                j = end - 1
                while i <= j:
                    b = min(int((centroid[order[i], a] - clo[a]) * scale), n_bins - 1)
                    if b < best_bin:
                        i += 1
                    else:
                        tmp = order[i]
                        order[i] = order[j]
                        order[j] = tmp
                        j -= 1
                mid = i
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
        tasks[n_tasks, 0] = mid
        tasks[n_tasks, 1] = end
        tasks[n_tasks, 2] = node
        tasks[n_tasks, 3] = 1
        tasks[n_tasks, 4] = depth + 1
        n_tasks += 1
        tasks[n_tasks, 0] = start
        tasks[n_tasks, 1] = mid
        tasks[n_tasks, 2] = node
        tasks[n_tasks, 3] = 0
        tasks[n_tasks, 4] = depth + 1
        n_tasks += 1
    return box[:n_nodes].copy(), child[:n_nodes].copy(), order, n_nodes, max_depth
