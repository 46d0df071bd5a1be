"""The light tree: a binary tree over the scene's lights whose nodes bound the lights below
them in space, orientation and power, so that next-event estimation can pick a light by
what it may send to the shading point (kernels.lights.sample_light_tree).

Conty Estevez and Kulla 2018, "Importance Sampling of Many Lights with Adaptive Tree
Splitting", as pbrt-v4's ``BVHLightSampler`` builds it: each light's bounds are its box, the
cone of its normals (half-angle theta_o around an axis), the widest angle theta_e its
emission leaves a normal at, and its power; a node's bounds are their union; splits are
chosen over 12 bins per axis (below SMALL_NODE lights, on the centres' widest axis only) by
the surface area and orientation heuristic (SAOH: power x the orientation cone's measure x
box area, with the node box's aspect ratio on the split axis; a bin's cone is its lights'
mean normal widened to hold them, see _bin_lights). Each leaf holds one light. Host code
compiled with ``@njit``; the lights' bounds are rows of one array that the partition
reorders, so that every pass over a node's lights reads memory in order.

The bounds need not be tight for the renderer to be unbiased, only the same when a light
is picked and when its pick's probability is asked for (kernels.lights): an emitting
triangle that a too-narrow bound never picks at some point is still reached there by BSDF
sampling, whose MIS weight is then 1. Only delta lights (point, spot) rely on the bound
holding them, which the exact cone unions of the nodes do (up to float32 rounding of the
cone's cosine at the very edge of the emission).
"""
import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .._cache import jit_cache
from .bvh import box_area
from ..kernels.layout import (LT_AXIS, LT_CENTRE, LT_COS_E, LT_COS_O, LT_LEFT, LT_LINK_WIDTH,
                              LT_PARENT, LT_POWER, LT_RADIUS2, LT_RIGHT, LT_SIN_O, LT_TWO_SIDED,
                              LT_WIDTH)

N_BINS = 12
SMALL_NODE = 64
# a bounds row of the build (float64; _merge): box, cone axis and half-angle cosine, widest
# emission angle cosine, power (0: empty), two-sided (1.0 or 0.0)
R_LO, R_HI, R_AXIS, R_COS_O, R_COS_E, R_POWER, R_TWO_SIDED, R_WIDTH = 0, 3, 6, 9, 10, 11, 12, 13


class LightBounds(NamedTuple):
    """Per-light bounds, float64 arrays over K lights."""
    lo: np.ndarray         # (K, 3)
    hi: np.ndarray         # (K, 3)
    axis: np.ndarray       # (K, 3) unit
    cos_o: np.ndarray      # (K,)
    cos_e: np.ndarray      # (K,)
    power: np.ndarray      # (K,) > 0
    two_sided: np.ndarray  # (K,) bool


class LightTree(NamedTuple):
    node: np.ndarray       # float32 (L, LT_WIDTH)
    link: np.ndarray       # int32 (L, LT_LINK_WIDTH)
    leaf: np.ndarray       # int32 (K,): the leaf of light k
    depth: int


@njit(cache=jit_cache())
def _rotate(v, axis, angle):
    """v turned by angle about the unit axis (Rodrigues)."""
    c = math.cos(angle)
    s = math.sin(angle)
    kx, ky, kz = axis
    vx, vy, vz = v
    d = kx * vx + ky * vy + kz * vz
    cx = ky * vz - kz * vy
    cy = kz * vx - kx * vz
    cz = kx * vy - ky * vx
    return (vx * c + cx * s + kx * d * (1 - c), vy * c + cy * s + ky * d * (1 - c),
            vz * c + cz * s + kz * d * (1 - c))


@njit(cache=jit_cache())
def _cone_union(wa, cos_a, wb, cos_b):
    """The smallest cone (axis, cos of half-angle) around two cones (pbrt-v4's
    ``Union(DirectionCone, DirectionCone)``)."""
    theta_a = math.acos(min(max(cos_a, -1.0), 1.0))
    theta_b = math.acos(min(max(cos_b, -1.0), 1.0))
    d = wa[0] * wb[0] + wa[1] * wb[1] + wa[2] * wb[2]
    theta_d = math.acos(min(max(d, -1.0), 1.0))
    if min(theta_d + theta_b, math.pi) <= theta_a:
        return wa, cos_a
    if min(theta_d + theta_a, math.pi) <= theta_b:
        return wb, cos_b
    theta_o = (theta_a + theta_d + theta_b) / 2
    if theta_o >= math.pi:
        return (0.0, 0.0, 1.0), -1.0
    theta_r = theta_o - theta_a
    rx = wa[1] * wb[2] - wa[2] * wb[1]
    ry = wa[2] * wb[0] - wa[0] * wb[2]
    rz = wa[0] * wb[1] - wa[1] * wb[0]
    rl = math.sqrt(rx * rx + ry * ry + rz * rz)
    if not rl > 1e-12:
        return (0.0, 0.0, 1.0), -1.0
    w = _rotate(wa, (rx / rl, ry / rl, rz / rl), theta_r)
    return w, math.cos(theta_o)


@njit(cache=jit_cache())
def _orientation_measure(cos_o, cos_e):
    """M_omega of Conty Estevez and Kulla: the solid-angle measure of the directions a node
    may emit into."""
    theta_o = math.acos(min(max(cos_o, -1.0), 1.0))
    theta_e = math.acos(min(max(cos_e, -1.0), 1.0))
    theta_w = min(theta_o + theta_e, math.pi)
    sin_o = math.sqrt(max(0.0, 1.0 - cos_o * cos_o))
    return (2 * math.pi * (1 - cos_o) +
            math.pi / 2 * (2 * theta_w * sin_o - math.cos(theta_o - 2 * theta_w) -
                           2 * theta_o * sin_o + cos_o))


@njit(cache=jit_cache())
def _merge(acc, lo, hi, w, cos_o, cos_e, power, two_sided):
    """acc (a bounds row, R_*) grown by one set of bounds, in place."""
    if acc[R_POWER] <= 0:
        for c in range(3):
            acc[R_LO + c] = lo[c]
            acc[R_HI + c] = hi[c]
            acc[R_AXIS + c] = w[c]
        acc[R_COS_O] = cos_o
        acc[R_COS_E] = cos_e
        acc[R_POWER] = power
        acc[R_TWO_SIDED] = 1.0 if two_sided else 0.0
        return
    for c in range(3):
        acc[R_LO + c] = min(acc[R_LO + c], lo[c])
        acc[R_HI + c] = max(acc[R_HI + c], hi[c])
    axis, cos_u = _cone_union((acc[R_AXIS], acc[R_AXIS + 1], acc[R_AXIS + 2]), acc[R_COS_O],
                              (w[0], w[1], w[2]), cos_o)
    for c in range(3):
        acc[R_AXIS + c] = axis[c]
    acc[R_COS_O] = cos_u
    acc[R_COS_E] = min(acc[R_COS_E], cos_e)
    acc[R_POWER] += power
    if two_sided:
        acc[R_TWO_SIDED] = 1.0


@njit(cache=jit_cache())
def _merge_row(acc, row):
    """acc grown by another bounds row (a non-empty one), in place."""
    _merge(acc, row[R_LO:R_LO + 3], row[R_HI:R_HI + 3], row[R_AXIS:R_AXIS + 3], row[R_COS_O],
           row[R_COS_E], row[R_POWER], row[R_TWO_SIDED] > 0)


@njit(cache=jit_cache())
def _cost(acc, kr):
    if acc[R_POWER] <= 0:
        return 0.0
    return (acc[R_POWER] * _orientation_measure(acc[R_COS_O], acc[R_COS_E]) * kr *
            box_area(acc[R_LO:R_LO + 3], acc[R_HI:R_HI + 3]))


# a light's row of the build's working array (rows are swapped as lights are partitioned,
# so that every pass over a node's lights reads memory in order)
D_LO, D_HI, D_CENTRE, D_AXIS, D_COS_O, D_COS_E, D_POWER, D_TWO_SIDED, D_WIDTH = (
    0, 3, 6, 9, 12, 13, 14, 15, 16)


@njit(cache=jit_cache())
def _bin_lights(data, start, end, dim, c_lo, extent, bins):
    """Each bin's bounds (rows as _merge's) over the lights data[start:end] binned by their
    centres on axis dim. A bin's cone is the power-weighted mean normal widened to hold
    every light's cone: not the smallest cone (pbrt-v4 unions cones light by light), but it
    holds them all and costs a dot product per light instead of inverse trigonometry; it
    only weighs the split (the tree's own nodes get exact unions)."""
    # (loops, not slice assignments: Numba compiles each of those slowly, seconds on a
    # first run; docs/benchmarks.md, "Compile time")
    for b in range(bins.shape[0]):
        for c in range(bins.shape[1]):
            bins[b, c] = 0.0
        bins[b, R_COS_O] = 1.0
        bins[b, R_COS_E] = 1.0
    for i in range(start, end):
        b = min(N_BINS - 1, int(N_BINS * (data[i, D_CENTRE + dim] - c_lo) / extent))
        if bins[b, R_POWER] <= 0:
            for c in range(3):
                bins[b, R_LO + c] = data[i, D_LO + c]
                bins[b, R_HI + c] = data[i, D_HI + c]
        else:
            for c in range(3):
                bins[b, R_LO + c] = min(bins[b, R_LO + c], data[i, D_LO + c])
                bins[b, R_HI + c] = max(bins[b, R_HI + c], data[i, D_HI + c])
        power = data[i, D_POWER]
        bins[b, R_POWER] += power
        for c in range(3):
            bins[b, R_AXIS + c] += power * data[i, D_AXIS + c]
        bins[b, R_COS_E] = min(bins[b, R_COS_E], data[i, D_COS_E])
        if data[i, D_TWO_SIDED] > 0:
            bins[b, R_TWO_SIDED] = 1.0
    for b in range(N_BINS):
        n = math.sqrt(bins[b, R_AXIS] ** 2 + bins[b, R_AXIS + 1] ** 2 +
                      bins[b, R_AXIS + 2] ** 2)
        if n > 1e-12 * bins[b, R_POWER]:
            for c in range(3):
                bins[b, R_AXIS + c] /= n
        else:
            bins[b, R_AXIS] = 0.0
            bins[b, R_AXIS + 1] = 0.0
            bins[b, R_AXIS + 2] = 1.0
            bins[b, R_COS_O] = -1.0
    for i in range(start, end):
        b = min(N_BINS - 1, int(N_BINS * (data[i, D_CENTRE + dim] - c_lo) / extent))
        d = (bins[b, R_AXIS] * data[i, D_AXIS] + bins[b, R_AXIS + 1] * data[i, D_AXIS + 1] +
             bins[b, R_AXIS + 2] * data[i, D_AXIS + 2])
        cos_o = data[i, D_COS_O]
        if cos_o < 1.0:
            d = math.cos(min(math.pi, math.acos(min(max(d, -1.0), 1.0)) +
                             math.acos(max(cos_o, -1.0))))
        bins[b, R_COS_O] = min(bins[b, R_COS_O], d)


@njit(cache=jit_cache())
def _push(stack, top, node, start, end, parent, level):
    """The build's task (node over lights start..end-1, its parent, its depth) put on the
    stack at top; returns the new top."""
    stack[top, 0] = node
    stack[top, 1] = start
    stack[top, 2] = end
    stack[top, 3] = parent
    stack[top, 4] = level
    return top + 1


@njit(cache=jit_cache())
def _build(lo, hi, axis, cos_o, cos_e, power, two_sided, node, link, leaf):
    k_lights = lo.shape[0]
    order = np.arange(k_lights)
    data = np.empty((k_lights, D_WIDTH))
    for k in range(k_lights):
        for c in range(3):
            data[k, D_LO + c] = lo[k, c]
            data[k, D_HI + c] = hi[k, c]
            data[k, D_CENTRE + c] = (lo[k, c] + hi[k, c]) * 0.5
            data[k, D_AXIS + c] = axis[k, c]
        data[k, D_COS_O] = cos_o[k]
        data[k, D_COS_E] = cos_e[k]
        data[k, D_POWER] = power[k]
        data[k, D_TWO_SIDED] = 1.0 if two_sided[k] else 0.0
    blo = np.empty(3)
    bhi = np.empty(3)
    clo = np.empty(3)
    chi = np.empty(3)
    # tasks: (node, start, end, parent, depth)
    stack = np.empty((max(1, k_lights), 5), np.int64)
    top = _push(stack, 0, 0, 0, k_lights, -1, 1)
    next_node = 1
    depth = 1
    bins = np.zeros((N_BINS, R_WIDTH))
    left = np.zeros((N_BINS, R_WIDTH))
    acc = np.zeros(R_WIDTH)
    while top > 0:
        top -= 1
        n = stack[top, 0]
        start = stack[top, 1]
        end = stack[top, 2]
        parent = stack[top, 3]
        level = stack[top, 4]
        depth = max(depth, level)
        link[n, LT_PARENT] = parent
        if end - start == 1:
            k = order[start]
            link[n, LT_LEFT] = -(k + 1)
            link[n, LT_RIGHT] = -1
            leaf[k] = n
            continue
        # the node's box and its centroids' box
        for c in range(3):
            blo[c] = np.inf
            bhi[c] = -np.inf
            clo[c] = np.inf
            chi[c] = -np.inf
        for i in range(start, end):
            for c in range(3):
                blo[c] = min(blo[c], data[i, D_LO + c])
                bhi[c] = max(bhi[c], data[i, D_HI + c])
                clo[c] = min(clo[c], data[i, D_CENTRE + c])
                chi[c] = max(chi[c], data[i, D_CENTRE + c])
        diag_max = max(bhi[0] - blo[0], max(bhi[1] - blo[1], bhi[2] - blo[2]))
        best_cost = np.inf
        best_dim = -1
        best_bin = -1
        widest = 0
        for dim in range(1, 3):
            if chi[dim] - clo[dim] > chi[widest] - clo[widest]:
                widest = dim
        for dim in range(3):
            extent = chi[dim] - clo[dim]
            if not extent > 0:
                continue
            if end - start <= SMALL_NODE and dim != widest:
                continue    # (small nodes: the centres' widest axis only; most nodes are small)
            _bin_lights(data, start, end, dim, clo[dim], extent, bins)
            edge = bhi[dim] - blo[dim]
            kr = diag_max / edge if edge > 0 else 1.0
            # prefix unions (bins 0..b), then suffix unions swept from the right
            for c in range(R_WIDTH):
                acc[c] = 0.0
            for b in range(N_BINS - 1):
                if bins[b, R_POWER] > 0:
                    _merge_row(acc, bins[b])
                for c in range(R_WIDTH):
                    left[b, c] = acc[c]
            for c in range(R_WIDTH):
                acc[c] = 0.0
            for b in range(N_BINS - 1, 0, -1):
                if bins[b, R_POWER] > 0:
                    _merge_row(acc, bins[b])
                if acc[R_POWER] > 0 and left[b - 1, R_POWER] > 0:
                    cost = _cost(left[b - 1], kr) + _cost(acc, kr)
                    if cost < best_cost:
                        best_cost = cost
                        best_dim = dim
                        best_bin = b - 1
        mid = start
        if best_dim >= 0:
            extent = chi[best_dim] - clo[best_dim]
            # partition: lights in bins <= best_bin first (rows and order swapped alike)
            j = start
            for i in range(start, end):
                b = min(N_BINS - 1, int(N_BINS * (data[i, D_CENTRE + best_dim] -
                                                  clo[best_dim]) / extent))
                if b <= best_bin:
                    if i != j:
                        tmp = order[j]
                        order[j] = order[i]
                        order[i] = tmp
                        for c in range(D_WIDTH):
                            t = data[j, c]
                            data[j, c] = data[i, c]
                            data[i, c] = t
                    j += 1
            mid = j
        if mid <= start or mid >= end:
            mid = (start + end) // 2     # coincident centroids: split the range in two
        c0 = next_node
        c1 = next_node + 1
        next_node += 2
        link[n, LT_LEFT] = c0
        link[n, LT_RIGHT] = c1
        top = _push(stack, top, c1, mid, end, n, level + 1)
        top = _push(stack, top, c0, start, mid, n, level + 1)
    # bounds bottom-up: children are numbered after their parents
    rows = np.zeros((next_node, R_WIDTH))
    for n in range(next_node - 1, -1, -1):
        first = link[n, LT_LEFT]
        if first < 0:
            k = -first - 1
            _merge(rows[n], lo[k], hi[k], axis[k], cos_o[k], cos_e[k], power[k],
                   two_sided[k])
        else:
            for side in range(2):
                c = link[n, LT_LEFT + side * (LT_RIGHT - LT_LEFT)]
                _merge_row(rows[n], rows[c])
    for n in range(next_node):
        r2 = 0.0
        for c in range(3):
            node[n, LT_CENTRE + c] = (rows[n, R_LO + c] + rows[n, R_HI + c]) / 2
            r2 += ((rows[n, R_HI + c] - rows[n, R_LO + c]) / 2) ** 2
            node[n, LT_AXIS + c] = rows[n, R_AXIS + c]
        # (rounded up, so that the float32 sphere still holds the box)
        node[n, LT_RADIUS2] = r2 * (1 + 1e-6)
        node[n, LT_COS_O] = rows[n, R_COS_O]
        node[n, LT_SIN_O] = math.sqrt(max(0.0, 1.0 - rows[n, R_COS_O] * rows[n, R_COS_O]))
        node[n, LT_COS_E] = rows[n, R_COS_E]
        node[n, LT_POWER] = rows[n, R_POWER]
        node[n, LT_TWO_SIDED] = rows[n, R_TWO_SIDED]
    return next_node, depth


def build_light_tree(bounds):
    """The :class:`LightTree` over lights with :class:`LightBounds` ``bounds`` (at least one
    light). Power is normalised to sum 1 at the root (only ratios matter; float32-safe)."""
    k = len(bounds.power)
    if k < 1:
        raise ValueError("a light tree needs at least one light")
    power = np.asarray(bounds.power, np.float64)
    power = power / power.sum()
    node = np.zeros((2 * k - 1, LT_WIDTH), np.float32)
    link = np.full((2 * k - 1, LT_LINK_WIDTH), -1, np.int32)
    leaf = np.full(k, -1, np.int32)
    n, depth = _build(np.ascontiguousarray(bounds.lo, np.float64),
                      np.ascontiguousarray(bounds.hi, np.float64),
                      np.ascontiguousarray(bounds.axis, np.float64),
                      np.ascontiguousarray(bounds.cos_o, np.float64),
                      np.ascontiguousarray(bounds.cos_e, np.float64), power,
                      np.ascontiguousarray(bounds.two_sided, np.bool_), node, link, leaf)
    assert n == 2 * k - 1
    return LightTree(node, link, leaf, int(depth))
