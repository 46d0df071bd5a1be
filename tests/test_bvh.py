"""BVH: structure invariants, and traversal equal to brute force on real and adversarial
geometry."""
import os

import numpy as np

from pathtracer.kernels import layout as L
import pytest
from numba import njit, prange

from pathtracer.accel import build_bvh, sah_cost
from pathtracer.kernels.constants import INF, STACK_SIZE
from pathtracer.kernels.intersect import ray_triangle
from pathtracer.kernels.traverse import _load_node, any_hit, closest_hit
from pathtracer.kernels.wide import (PACKET, any_hit_wide, closest_hit_packet,
                                     closest_hit_wide, packet_ray_hit, packet_set_ray)
from pathtracer.accel.wide import WIDE_STACK_SIZE, WIDE_TRAVERSAL_WORDS, widen_bvh
from pathtracer.scene.meshes import load_obj
from tests.conftest import SHARED, needs_shared
from tests.bvh_oracle import build_plain


def tri_rows(pos):
    tri_v = np.zeros((max(1, len(pos)), L.TRI_V_WIDTH), np.float32)
    tri_v[:len(pos), L.TRI_V0:L.TRI_V0 + 3] = pos[:, 0]
    tri_v[:len(pos), L.TRI_E1:L.TRI_E1 + 3] = pos[:, 1] - pos[:, 0]
    tri_v[:len(pos), L.TRI_E2:L.TRI_E2 + 3] = pos[:, 2] - pos[:, 0]
    return tri_v


@njit(cache=True)
def trace_all(origins, dirs, tri_v, box, child, skips):
    n = origins.shape[0]
    out_t = np.empty(n, np.float32)
    out_i = np.empty(n, np.int32)
    out_any = np.empty(n, np.bool_)
    stack = np.empty(STACK_SIZE, np.int32)
    for k in range(n):
        o = (origins[k, 0], origins[k, 1], origins[k, 2])
        d = (dirs[k, 0], dirs[k, 1], dirs[k, 2])
        t, i, b1, b2 = closest_hit(o, d, INF, skips[k], tri_v, box, child, stack)
        out_t[k] = t
        out_i[k] = i
        out_any[k] = any_hit(o, d, INF, skips[k], -1, tri_v, box, child, stack)
    return out_t, out_i, out_any


@njit(cache=True)
def trace_all_wide(origins, dirs, tri_v, wide, wchild, skips, skips_b):
    n = origins.shape[0]
    out_t = np.empty(n, np.float32)
    out_i = np.empty(n, np.int32)
    out_b = np.empty((n, 2), np.float32)
    out_any = np.empty(n, np.bool_)
    stack = np.empty(WIDE_STACK_SIZE, np.int32)
    for k in range(n):
        o = (origins[k, 0], origins[k, 1], origins[k, 2])
        d = (dirs[k, 0], dirs[k, 1], dirs[k, 2])
        t, i, b1, b2 = closest_hit_wide(o, d, INF, skips[k], tri_v, wide, wchild, stack)
        out_t[k] = t
        out_i[k] = i
        out_b[k, 0] = b1
        out_b[k, 1] = b2
        out_any[k] = any_hit_wide(o, d, INF, skips[k], skips_b[k], tri_v, wide, wchild,
                                  stack)
    return out_t, out_i, out_b, out_any


@njit(cache=True)
def trace_all_packets(origins, dirs, wide, wchild, n_lanes):
    """closest_hit_packet's hits (t, triangle, b1, b2) of the rays in packets of n_lanes
    consecutive rays (the last one as many as are left; unused lanes t_max -1)."""
    n = origins.shape[0]
    out_t = np.empty(n, np.float32)
    out_i = np.empty(n, np.int32)
    out_b = np.empty((n, 2), np.float32)
    stack = np.empty(WIDE_STACK_SIZE, np.int32)
    for first in range(0, n, n_lanes):
        used = min(n_lanes, n - first)
        for lane in range(PACKET):
            if lane < used:
                k = first + lane
                packet_set_ray(stack, lane, (origins[k, 0], origins[k, 1], origins[k, 2]),
                               (dirs[k, 0], dirs[k, 1], dirs[k, 2]), INF)
            else:
                packet_set_ray(stack, lane, (np.float32(0), np.float32(0), np.float32(0)),
                               (np.float32(1), np.float32(1), np.float32(1)), np.float32(-1))
        closest_hit_packet(wide, wchild, stack)
        for lane in range(used):
            _, _, t, i, b1, b2 = packet_ray_hit(stack, lane)
            out_t[first + lane] = t
            out_i[first + lane] = i
            out_b[first + lane, 0] = b1
            out_b[first + lane, 1] = b2
    return out_t, out_i, out_b


def check_packets(origins, dirs, wide, wchild, tw, iw, bw):
    """The camera rays' packets (kernels.wide.closest_hit_packet) find each ray's hit of
    closest_hit_wide (tw, iw, bw; rays that skip no triangle): the same distance and
    barycentrics, the triangle the same but at a tie; in packets of 8 rays and, with
    unused lanes, of 3."""
    for n_lanes in (PACKET, 3):
        tp, ip, bp = trace_all_packets(origins, dirs, wide, wchild, n_lanes)
        assert np.array_equal(tp, tw)
        same = ip == iw
        assert (same | (tp == tw)).all()
        assert np.array_equal(bp[same], bw[same])


@njit(cache=True, parallel=True)
def brute_force(origins, dirs, tri_v, n_tri, skips, skips_b):
    """The nearest hit of each ray over all triangles but skips[k] and skips_b[k]."""
    n = origins.shape[0]
    out_t = np.empty(n, np.float32)
    out_i = np.empty(n, np.int32)
    for k in prange(n):
        o = (origins[k, 0], origins[k, 1], origins[k, 2])
        d = (dirs[k, 0], dirs[k, 1], dirs[k, 2])
        best = INF
        best_i = -1
        for i in range(n_tri):
            if i == skips[k] or i == skips_b[k]:
                continue
            t, b1, b2 = ray_triangle(o, d, tri_v, i, best)
            if t < best:
                best = t
                best_i = i
        out_t[k] = best
        out_i[k] = best_i
    return out_t, out_i


def check_against_brute_force(pos, origins, dirs, skips=None, **options):
    bvh = build_bvh(pos, **options)
    pos = pos[bvh.order]
    tri_v = tri_rows(pos)
    if skips is None:
        skips = np.full(len(origins), -1, np.int32)
    origins = origins.astype(np.float32)
    dirs = dirs.astype(np.float32)
    t, i, a = trace_all(origins, dirs, tri_v, bvh.box, bvh.child, skips)
    tb, ib = brute_force(origins, dirs, tri_v, len(pos), skips,
                         np.full(len(origins), -1, np.int32))
    # Same distance exactly (same arithmetic); the triangle may differ only at equal t
    # (a ray through a shared edge or vertex hits both triangles at the same t).
    assert np.array_equal(t, tb)
    same = (i == ib) | (t == tb)
    assert same.all()
    assert np.array_equal(a, ib >= 0)   # any-hit agrees with the existence of a hit
    # The CPU's eight-wide tree (kernels.wide): the same hits, bit for bit, from the same
    # arithmetic in SIMD form; any-hit also with a second skipped triangle (its hit).
    wide, wchild = widen_bvh(tri_v, bvh.box, bvh.child)
    check_wide_structure(bvh, wide, wchild, tri_v, len(pos))
    tw, iw, bw, aw = trace_all_wide(origins, dirs, tri_v, wide, wchild, skips,
                                    np.full(len(origins), -1, np.int32))
    assert np.array_equal(tw, tb)
    assert ((iw == ib) | (tw == tb)).all()
    assert np.array_equal(aw, ib >= 0)
    for k in np.nonzero(iw >= 0)[0][:200]:       # the barycentrics are ray_triangle's
        o, d = tuple(origins[k]), tuple(dirs[k])
        assert ray_triangle(o, d, tri_v, iw[k], INF) == (tw[k], bw[k, 0], bw[k, 1])
    _, _, _, aw2 = trace_all_wide(origins, dirs, tri_v, wide, wchild, skips, ib)
    _, ib2 = brute_force(origins, dirs, tri_v, len(pos), skips, ib)
    assert np.array_equal(aw2, ib2 >= 0)
    free = skips < 0
    check_packets(origins[free], dirs[free], wide, wchild, tw[free], iw[free], bw[free])
    return bvh, t, i


def check_wide_structure(bvh, wide, wchild, tri_v, n):
    """Every triangle in exactly one wide leaf, packed in its lane; every wide child box is
    one of the binary tree's boxes; inner children point at later nodes; the nodes' masks
    of inner children and leaves are their counts'; the traversal stack suffices."""
    from pathtracer.kernels import wide as W
    seen = np.zeros(n, int)
    binary_boxes = {tuple(b) for b in bvh.box.reshape(-1, 6).tolist()}
    flat = wide.reshape(-1)
    n_nodes = len(wchild)
    depth = np.zeros(n_nodes, int)
    depth[0] = 1
    node_floats = W.NODE_ROWS * W.WIDE_ROW
    for k in range(n_nodes):
        node = flat[node_floats * k:node_floats * (k + 1)]
        inner = leaves = 0
        for j in range(W.WIDTH):
            cnt = wchild[k, W.WCHILD_COUNT + j]
            box = tuple(node[[j + W.WIDTH * a for a in range(6)]].tolist())
            if cnt < 0:
                assert np.isnan(box).all()
                continue
            assert box in binary_boxes
            if cnt == 0:
                inner |= 1 << j
                row = wchild[k, W.WCHILD_INDEX + j]
                assert row % W.NODE_ROWS == 0 and k < row // W.NODE_ROWS < n_nodes
                depth[row // W.NODE_ROWS] = depth[k] + 1
            else:
                leaves |= 1 << j
                first, row = wchild[k, W.WCHILD_FIRST + j], wchild[k, W.WCHILD_INDEX + j]
                assert row >= W.NODE_ROWS * n_nodes
                seen[first:first + cnt] += 1
                for t in range(cnt):
                    group = flat[W.WIDE_ROW * (row + W.GROUP_ROWS * (t // W.LANES)):][:36]
                    assert np.array_equal(group[t % W.LANES::W.LANES], tri_v[first + t])
        assert (wchild[k, W.WCHILD_INNER], wchild[k, W.WCHILD_LEAVES]) == (inner, leaves)
    assert (seen == 1).all()
    assert 2 * (W.WIDTH - 1) * depth.max() + 2 <= WIDE_TRAVERSAL_WORDS


def check_structure(bvh, pos):
    n = len(pos)
    seen = np.zeros(n, int)
    lo = pos.min(axis=1)
    hi = pos.max(axis=1)
    for k in range(len(bvh.box)):
        for side in range(2):
            c, cnt = bvh.child[k, 2 * side], bvh.child[k, 2 * side + 1]
            b = bvh.box[k, 6 * side:6 * side + 6]
            if cnt > 0:
                seen[c:c + cnt] += 1
                idx = bvh.order[c:c + cnt]
                assert (lo[idx] >= b[0:3]).all() and (hi[idx] <= b[3:6]).all()
            elif cnt == 0:
                # the child's own children lie inside this box
                cb = bvh.box[c]
                for s2 in range(2):
                    if bvh.child[c, 2 * s2 + 1] >= 0:
                        assert (cb[6 * s2:6 * s2 + 3] >= b[0:3]).all()
                        assert (cb[6 * s2 + 3:6 * s2 + 6] <= b[3:6]).all()
    assert (seen == 1).all(), "every triangle in exactly one leaf"
    assert sorted(bvh.order.tolist()) == list(range(n))
    assert bvh.depth < STACK_SIZE - 2


def random_rays(rng, n, lo, hi):
    center = (lo + hi) / 2
    extent = (hi - lo).max()
    origins = center + (rng.random((n, 3)) - 0.5) * 3 * extent
    targets = lo + rng.random((n, 3)) * (hi - lo)
    d = targets - origins
    return origins, d / np.linalg.norm(d, axis=1, keepdims=True)


@needs_shared
def test_bunny_random_rays(rng):
    mesh = load_obj(os.path.join(SHARED, "assets", "models", "stanford_bunny.obj"),
                    use_cache=False)
    pos = mesh.positions
    lo, hi = pos.reshape(-1, 3).min(0), pos.reshape(-1, 3).max(0)
    origins, dirs = random_rays(rng, 8000, lo, hi)   # 2 x 8000 x 69k brute-force tests
    bvh, t, i = check_against_brute_force(pos, origins, dirs)
    check_structure(bvh, pos)
    assert (i >= 0).mean() > 0.3   # the rays do hit the bunny
    # The SAH tree is far cheaper than a single leaf over all triangles.
    assert sah_cost(bvh) < len(pos) / 100


def test_edges_vertices_parallel_and_degenerate(rng):
    # A grid of unit squares (2 triangles each) in the z = 0 plane, plus degenerate
    # triangles: zero-area (repeated vertex), collinear, and a sliver.
    tris = []
    for x in range(4):
        for y in range(4):
            a, b, c, d = [x, y, 0], [x + 1, y, 0], [x + 1, y + 1, 0], [x, y + 1, 0]
            tris += [[a, b, c], [a, c, d]]
    tris += [[[1, 1, 1], [1, 1, 1], [2, 2, 1]],           # zero area
             [[0, 0, 2], [1, 1, 2], [2, 2, 2]],           # collinear
             [[0, 0, 3], [4, 0, 3], [4, 1e-7, 3]]]        # sliver
    pos = np.array(tris, np.float32)
    origins, dirs = [], []
    # Straight down through every grid vertex, edge midpoint and the diagonal.
    for x in np.arange(0, 4.01, 0.5):
        for y in np.arange(0, 4.01, 0.5):
            origins.append([x, y, 5])
            dirs.append([0, 0, -1])
    # Rays parallel to the plane, in the plane and just above it.
    for z in (0.0, 1e-6):
        for y in np.arange(0, 4.01, 0.5):
            origins.append([-1, y, z])
            dirs.append([1, 0, 0])
    # Random oblique rays.
    o, d = random_rays(rng, 3000, np.array([0, 0, -1.0]), np.array([4, 4, 3.0]))
    origins = np.concatenate([np.array(origins, float), o])
    dirs = np.concatenate([np.array(dirs, float), d])
    bvh, t, i = check_against_brute_force(pos, origins, dirs)
    check_structure(bvh, pos)
    n_down = 81
    # Every vertical ray over the grid's closed area hits it, none is lost on an edge.
    assert (i[:n_down] >= 0).all()
    # Rays lying in the plane of the grid never hit it (det == 0).
    assert (i[n_down:n_down + 9] < 0).all()


def test_skip_triangle(rng):
    pos = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                    [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], np.float32)
    bvh = build_bvh(pos)
    first = int(np.nonzero(bvh.order == 0)[0][0])
    o = np.array([[0.2, 0.2, -1.0]])
    d = np.array([[0, 0, 1.0]])
    _, t, i = check_against_brute_force(pos, o, d, np.array([first], np.int32))
    assert t[0] == pytest.approx(2.0) and i[0] != first


@pytest.mark.parametrize("n", [0, 1, 2, 7])
def test_tiny_scenes(n, rng):
    pos = rng.random((n, 3, 3)).astype(np.float32)
    origins, dirs = random_rays(rng, 200, np.zeros(3), np.ones(3))
    bvh, _, _ = check_against_brute_force(pos, origins, dirs)
    if n:
        check_structure(bvh, pos)


def test_coincident_centroids():
    """Many triangles sharing one centroid: no spatial split exists; still correct."""
    base = np.array([[-1, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    pos = np.stack([base * (1 + 0.01 * k) for k in range(100)])
    pos -= pos.mean(axis=1, keepdims=True)
    rng = np.random.default_rng(1)
    origins, dirs = random_rays(rng, 500, pos.reshape(-1, 3).min(0), pos.reshape(-1, 3).max(0))
    bvh, _, _ = check_against_brute_force(pos, origins, dirs)
    check_structure(bvh, pos)


@pytest.mark.parametrize("options", [dict(split="midpoint"), dict(split="none"),
                                     dict(n_bins=4, max_leaf=1), dict(n_bins=32, max_leaf=16)])
def test_benchmark_variants_trace_the_same(rng, options):
    """The benchmark's variants (midpoint splits, one brute-force leaf, bin and leaf sweeps)
    find the same hits as brute force, and are valid trees."""
    v = (rng.random((3000, 3, 3)) * 0.1 + rng.random((3000, 1, 3))).astype(np.float32)
    origins, dirs = random_rays(rng, 3000, v.reshape(-1, 3).min(0), v.reshape(-1, 3).max(0))
    bvh, _, _ = check_against_brute_force(v, origins, dirs, **options)
    check_structure(bvh, v)
    if options.get("split") == "none":
        assert len(bvh.box) == 1 and bvh.child[0, L.CHILD0_COUNT] == len(v)


@pytest.mark.parametrize("split", ["sah", "midpoint", "none"])
def test_fast_builder_makes_the_plain_builders_tree(rng, split):
    """The builder that carries node bounds with its tasks and reorders the triangle data
    makes exactly the tree of the plain one (same nodes, boxes, order): images unchanged."""
    from pathtracer.accel.bvh import PARALLEL_MIN
    meshes = [rng.random((3000, 3, 3)).astype(np.float32),
              # above PARALLEL_MIN: the top, the subtrees built in parallel, the assembly
              rng.random((PARALLEL_MIN + 5000, 3, 3)).astype(np.float32),
              np.repeat(rng.random((1, 3, 3)), 50, axis=0).astype(np.float32),
              (rng.random((2000, 1, 3)) + rng.normal(0, 0.01, (2000, 3, 3))).astype(np.float32)]
    bunny = os.path.join(SHARED, "assets", "models", "stanford_bunny.obj")
    if os.path.exists(bunny):
        meshes.append(load_obj(bunny).positions)
    # one ground-plane-like sliver beside a cloud: the root's split is unbalanced
    sliver = rng.random((PARALLEL_MIN + 3000, 3, 3)).astype(np.float32)
    sliver[:2000] *= np.float32([100.0, 0.001, 100.0])
    meshes.append(sliver)
    # a plane (one axis without extent: its bins are never read) and a mesh of one point
    plane = rng.random((3000, 3, 3)).astype(np.float32)
    plane[:, :, 2] = 0.5
    meshes += [plane, np.zeros((40, 3, 3), np.float32)]
    for pos in meshes:
        plain = build_bvh(pos, split=split, _plain=build_plain)
        # the thread count sets how much of the top is built before the parallel subtrees
        for threads in ((None, 1, 7, 64) if len(pos) >= PARALLEL_MIN else (None,)):
            fast = build_bvh(pos, split=split, _threads=threads)
            assert fast.depth == plain.depth
            for a, b in zip(fast[:3], plain[:3]):
                assert np.array_equal(a, b)


@pytest.mark.parametrize("n_bins", [2, 5, 63, 64])
def test_fast_builder_makes_the_plain_builders_tree_for_any_bin_count(rng, n_bins):
    """The builder's filled bins are bits of an int64: up to 64 bins, the plain tree; more
    are refused."""
    pos = (rng.random((4000, 1, 3)) + rng.normal(0, 0.02, (4000, 3, 3))).astype(np.float32)
    plain = build_bvh(pos, n_bins=n_bins, _plain=build_plain)
    fast = build_bvh(pos, n_bins=n_bins)
    for a, b in zip(fast[:3], plain[:3]):
        assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="n_bins"):
        build_bvh(pos, n_bins=65)


@njit(cache=True)
def _load_nodes(box, child):
    out = np.empty((box.shape[0], 16))
    for k in range(box.shape[0]):
        v = _load_node(box, child, k)      # 12 float32 then 4 int32: indexed statically
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = v[0], v[1], v[2], v[3]
        out[k, 4], out[k, 5], out[k, 6], out[k, 7] = v[4], v[5], v[6], v[7]
        out[k, 8], out[k, 9], out[k, 10], out[k, 11] = v[8], v[9], v[10], v[11]
        out[k, 12], out[k, 13], out[k, 14], out[k, 15] = v[12], v[13], v[14], v[15]
    return out


def test_node_loads_read_the_node_layout(rng):
    """The traversal reads a node with four 128-bit loads (kernels.loads): compiled and
    interpreted, they give each child's box and (index, count) as the layout names them."""
    v = rng.random((3000, 3, 3)).astype(np.float32)
    bvh = build_bvh(v)
    want = np.concatenate(
        [bvh.box[:, L.BOX_CHILD0 + L.BOX_MIN:L.BOX_CHILD0 + L.BOX_MIN + 3],
         bvh.box[:, L.BOX_CHILD0 + L.BOX_MAX:L.BOX_CHILD0 + L.BOX_MAX + 3],
         bvh.box[:, L.BOX_CHILD1 + L.BOX_MIN:L.BOX_CHILD1 + L.BOX_MIN + 3],
         bvh.box[:, L.BOX_CHILD1 + L.BOX_MAX:L.BOX_CHILD1 + L.BOX_MAX + 3],
         bvh.child[:, [L.CHILD0_INDEX, L.CHILD0_COUNT, L.CHILD1_INDEX, L.CHILD1_COUNT]]],
        axis=1).astype(np.float64)
    assert np.array_equal(_load_nodes(bvh.box, bvh.child), want)
    for k in (0, len(bvh.box) // 2, len(bvh.box) - 1):
        assert np.array_equal(np.array(_load_node(bvh.box, bvh.child, k), np.float64), want[k])


def test_wide_traversal_interpreted_matches_compiled(rng):
    """The eight-wide traversal run as plain Python (the vector tests' and bit helpers'
    Python forms: kernels.wide.slab8, triangles4, entered, lowest_bit, float_bits) finds
    what the compiled SIMD code finds."""
    pos = rng.random((300, 3, 3)).astype(np.float32)
    pos[:, 1:] = pos[:, :1] + 0.3 * (pos[:, 1:] - 0.5)       # small triangles in a cube
    bvh = build_bvh(pos)
    tri_v = tri_rows(pos[bvh.order])
    wide, wchild = widen_bvh(tri_v, bvh.box, bvh.child)
    origins, dirs = random_rays(rng, 60, np.zeros(3), np.ones(3))
    origins, dirs = origins.astype(np.float32), dirs.astype(np.float32)
    skips = np.full(len(origins), -1, np.int32)
    tw, iw, bw, aw = trace_all_wide(origins, dirs, tri_v, wide, wchild, skips, skips)
    stack = np.empty(WIDE_STACK_SIZE, np.int32)
    with np.errstate(all="ignore"):
        for k in range(len(origins)):
            o, d = tuple(origins[k]), tuple(dirs[k])
            t, i, b1, b2 = closest_hit_wide(o, d, INF, -1, tri_v, wide, wchild, stack)
            assert (t, i, b1, b2) == (tw[k], iw[k], bw[k, 0], bw[k, 1])
            assert any_hit_wide(o, d, INF, -1, -1, tri_v, wide, wchild, stack) == aw[k]
    assert (iw >= 0).sum() > 10
    # the camera rays' packets (box_rays8, triangle_rays8, bits_float in Python), eight
    # rays from one point into the cube, then a packet of five (three lanes unused)
    eye = np.array([0.5, 0.5, -1.0], np.float32)
    aims = (0.2 + 0.6 * rng.random((PACKET + 5, 3)) - eye).astype(np.float32)
    aims /= np.linalg.norm(aims, axis=1)[:, None]
    hits = 0
    for first, used in ((0, PACKET), (PACKET, 5)):
        for lane in range(PACKET):
            if lane < used:
                packet_set_ray(stack, lane, tuple(eye), tuple(aims[first + lane]), INF)
            else:
                packet_set_ray(stack, lane, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), -1.0)
        with np.errstate(all="ignore"):
            closest_hit_packet(wide, wchild, stack)
        rays = np.repeat(eye[None], used, 0), aims[first:first + used]
        tc, ic, bc = trace_all_packets(*rays, wide, wchild, PACKET)
        for lane in range(used):
            o, d, t, i, b1, b2 = packet_ray_hit(stack, lane)
            assert (o, d) == (tuple(eye), tuple(aims[first + lane]))
            assert (t, i, b1, b2) == (tc[lane], ic[lane], bc[lane, 0], bc[lane, 1])
            hits += i >= 0
    assert hits > 6


def test_rays_leaving_a_triangle_near_its_edge_do_not_meet_the_neighbours_band():
    """On a convex mesh a neighbour's plane runs just above a triangle near their shared
    edge: a ray leaving the triangle there must not hit the neighbour (a ray-triangle test
    that accepts hits a little outside triangles, to close the cracks between them, did:
    docs/benchmarks.md, "A band against cracks"). Rays from points within 1e-4
    (barycentric) of an edge of a flat-shaded closed sphere, outwards, at least 0.01 from
    tangent: none hits the sphere again."""
    from bench.watertight import sphere
    from bench.traversal import tracers
    rng = np.random.default_rng(1)
    v, f, tri_v, bvh = sphere(16, 32, 1.0, (0.0, 0.0, 0.0))
    n = 50000
    fi = rng.integers(0, len(f), n)
    a = rng.random(n) * (1 - 1e-4)
    b = rng.random(n) * 1e-4                   # near the edge v0-v1
    v0, v1, v2 = (v[f[fi, k]].astype(np.float64) for k in range(3))
    p = v0 + a[:, None] * (v1 - v0) + b[:, None] * (v2 - v0)
    ng = np.cross(v1 - v0, v2 - v0)
    ng /= np.linalg.norm(ng, axis=1)[:, None]
    ng *= np.sign((ng * p).sum(1))[:, None]
    u = rng.normal(size=(n, 3))
    u -= (u * ng).sum(1)[:, None] * ng         # tangent, then lifted to 0.01 .. 1
    u /= np.linalg.norm(u, axis=1)[:, None]
    c = 0.01 + 0.99 * rng.random(n)
    d = (u * np.sqrt(1 - c * c)[:, None] + ng * c[:, None]).astype(np.float32)
    o = (p + ng * 2.0 ** -21 * np.abs(p).max(1)[:, None]).astype(np.float32)
    order = np.empty(len(f), np.int64)
    order[bvh.order] = np.arange(len(f))
    skip = order[fi].astype(np.int32)
    wide = widen_bvh(tri_v, bvh.box, bvh.child)
    for (closest, shadow), (box, child) in (
            (tracers(closest_hit, any_hit), (bvh.box, bvh.child)),
            (tracers(closest_hit_wide, any_hit_wide), wide)):
        t = np.empty(n, np.float32)
        tri = np.empty(n, np.int32)
        occluded = np.empty(n, np.bool_)
        closest(o, d, skip, tri_v, box, child, t, tri, occluded)
        assert (tri < 0).all()
        shadow(o, d, skip, tri_v, box, child, t, tri, occluded)
        assert not occluded.any()
