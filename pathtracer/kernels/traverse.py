"""BVH traversal over the flat node arrays built by :mod:`pathtracer.accel.bvh`.

Node k stores both children's boxes (Aila & Laine 2009 layout, so one node visit tests two
boxes) and their (index, count) pairs, see the BVH section of :mod:`.layout`: a child with
count n > 0 is a leaf over triangles c .. c+n-1, with n == 0 an inner node with index c, and
with n < 0 empty. Node 0 is the root.
"""
from .constants import INF, SLAB_SCALE, ZERO
from .device import device
from .intersect import ray_triangle, safe_inverse, slab
from .layout import (BOX_CHILD0, BOX_CHILD1, BOX_MAX, BOX_MIN, BOX_WIDTH, CHILD0_COUNT,
                     CHILD0_INDEX, CHILD1_COUNT, CHILD1_INDEX, CHILD_WIDTH)
from .loads import load4

# _load_node reads the node layout as four 128-bit rows
assert (BOX_CHILD0, BOX_CHILD1, BOX_MIN, BOX_MAX, BOX_WIDTH) == (0, 6, 0, 3, 12)
assert (CHILD0_INDEX, CHILD0_COUNT, CHILD1_INDEX, CHILD1_COUNT, CHILD_WIDTH) == (0, 1, 2, 3, 4)


@device
def _load_node(bvh_box, bvh_child, node):
    """Node ``node``'s two child boxes and (index, count) pairs in four 128-bit loads (the
    layout of kernels.layout: lo0 hi0 lo1 hi1, then c0 n0 c1 n1; tested against it)."""
    lx0, ly0, lz0, hx0 = load4(bvh_box, node, BOX_CHILD0 + BOX_MIN)
    hy0, hz0, lx1, ly1 = load4(bvh_box, node, BOX_CHILD0 + BOX_MAX + 1)
    lz1, hx1, hy1, hz1 = load4(bvh_box, node, BOX_CHILD1 + BOX_MIN + 2)
    c0, n0, c1, n1 = load4(bvh_child, node, CHILD0_INDEX)
    return lx0, ly0, lz0, hx0, hy0, hz0, lx1, ly1, lz1, hx1, hy1, hz1, c0, n0, c1, n1


@device
def _intersect_leaf(o, d, tri_v, first, count, skip, t_best, tri_best, b1_best, b2_best):
    for i in range(first, first + count):
        if i != skip:
            t, b1, b2 = ray_triangle(o, d, tri_v, i, t_best)
            if t < t_best:
                t_best = t
                tri_best = i
                b1_best = b1
                b2_best = b2
    return t_best, tri_best, b1_best, b2_best


@device
def closest_hit(o, d, t_max, skip, tri_v, bvh_box, bvh_child, stack):
    """Nearest hit (t, tri, b1, b2) with 0 < t < t_max, ignoring triangle ``skip``; tri = -1
    on a miss. ``stack`` is int32 scratch of STACK_SIZE entries owned by the caller."""
    inv_d = safe_inverse(d)
    t_best = t_max
    tri_best = -1
    b1_best = ZERO
    b2_best = ZERO
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        (lx0, ly0, lz0, hx0, hy0, hz0, lx1, ly1, lz1, hx1, hy1, hz1,
         c0, n0, c1, n1) = _load_node(bvh_box, bvh_child, node)
        t0 = slab(o, inv_d, lx0, ly0, lz0, hx0, hy0, hz0, t_best) if n0 >= 0 else INF
        t1 = slab(o, inv_d, lx1, ly1, lz1, hx1, hy1, hz1, t_best) if n1 >= 0 else INF
        # Nearer child first: swap so that child 0 is the nearer one.
        if t1 < t0:
            c0, c1 = c1, c0
            n0, n1 = n1, n0
            t0, t1 = t1, t0
        # Inner children go on the stack, far one below the near one.
        if t1 < INF and n1 == 0:
            stack[sp] = c1
            sp += 1
        if t0 < INF and n0 == 0:
            stack[sp] = c0
            sp += 1
        # Leaf children are intersected at once; the far leaf only if still in front (with
        # the slab test's rounding slack: a flat box's entry may round past a nearer hit).
        if t0 < INF and n0 > 0:
            t_best, tri_best, b1_best, b2_best = _intersect_leaf(
                o, d, tri_v, c0, n0, skip, t_best, tri_best, b1_best, b2_best)
        if t1 < INF and t1 <= t_best * SLAB_SCALE and n1 > 0:
            t_best, tri_best, b1_best, b2_best = _intersect_leaf(
                o, d, tri_v, c1, n1, skip, t_best, tri_best, b1_best, b2_best)
    if tri_best < 0:
        return INF, -1, ZERO, ZERO
    return t_best, tri_best, b1_best, b2_best


@device
def any_hit(o, d, t_max, skip_a, skip_b, tri_v, bvh_box, bvh_child, stack):
    """True if any triangle other than skip_a and skip_b is hit with 0 < t < t_max
    (shadow rays: the shading point's and the light sample's triangles are skipped)."""
    inv_d = safe_inverse(d)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        (lx0, ly0, lz0, hx0, hy0, hz0, lx1, ly1, lz1, hx1, hy1, hz1,
         c0, n0, c1, n1) = _load_node(bvh_box, bvh_child, node)
        for side in range(2):
            c = c0 if side == 0 else c1
            n = n0 if side == 0 else n1
            if side == 0:
                t = slab(o, inv_d, lx0, ly0, lz0, hx0, hy0, hz0, t_max) if n >= 0 else INF
            else:
                t = slab(o, inv_d, lx1, ly1, lz1, hx1, hy1, hz1, t_max) if n >= 0 else INF
            if t < INF:
                if n == 0:
                    stack[sp] = c
                    sp += 1
                else:
                    for i in range(c, c + n):
                        if i != skip_a and i != skip_b:
                            t, b1, b2 = ray_triangle(o, d, tri_v, i, t_max)
                            if t < INF:
                                return True
    return False
