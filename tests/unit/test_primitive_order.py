"""The order an upload hands triangles and instances to the BVH builder (scene.h bvh_order).

Lavapipe's builder splits its input in halves at (first + last) / 2 without sorting, one
primitive per leaf, so the input order alone decides the tree. These tests build that tree in
Python and compare its surface-area cost (the summed half-areas of its inner boxes, MacDonald &
Booth 1990) under our order and under the Morton order the core used before.
"""
import numpy as np
import parallax_core as pc


def lavapipe_tree_area(lo, hi, order):
    """Summed half-areas of the inner nodes of the tree lavapipe builds over `order`."""
    lo, hi = lo[order], hi[order]
    total, stack = 0.0, [(0, len(order) - 1)]
    while stack:
        first, last = stack.pop()
        d = hi[first:last + 1].max(0) - lo[first:last + 1].min(0)
        total += d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
        split = (first + last) // 2
        if first < split:
            stack.append((first, split))
        if split + 1 < last:
            stack.append((split + 1, last))
    return total


def morton_order(lo, hi):
    """Box centres along a 30-bit Morton curve, each axis normalised to the centres' extent."""
    c = (lo + hi) / 2
    ext = c.max(0) - c.min(0)
    q = (c - c.min(0)) / np.where(ext > 0, ext, 1)
    q = np.minimum((q * 1024).astype(np.uint64), 1023)
    code = np.zeros(len(c), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + 2 - axis)
    return np.argsort(code, kind="stable")


def grid(origin, u, v, n):
    """A parallelogram (origin, edges u and v) in 2 n^2 triangles: (T, 3 corners, 3)."""
    tris = []
    for i in range(n):
        for j in range(n):
            p = [origin + u * (i + a) / n + v * (j + b) / n for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))]
            tris += [(p[0], p[1], p[2]), (p[0], p[2], p[3])]
    return np.array(tris, np.float32)


def boxes(triangles):
    return np.ascontiguousarray(triangles.min(1)), np.ascontiguousarray(triangles.max(1))


def shuffled(triangles, seed=0):
    return triangles[np.random.default_rng(seed).permutation(len(triangles))]


def test_room_of_walls_gets_a_cheaper_tree_than_morton():
    # A 10 x 6 x 3 m room, every wall a 16 x 16 grid: Morton gives the thin axis of each wall
    # as many splits as the long ones; the surface-area axis choice does not.
    o, x, y, z = np.zeros(3), np.array([10.0, 0, 0]), np.array([0, 6.0, 0]), np.array([0, 0, 3.0])
    room = shuffled(np.concatenate([grid(o, x, y, 16), grid(o + z, x, y, 16), grid(o, x, z, 16),
                                    grid(o + y, x, z, 16), grid(o, y, z, 16), grid(o + x, y, z, 16)]))
    lo, hi = boxes(room)
    ours = np.array(pc.primitive_order(lo, hi))
    assert sorted(ours.tolist()) == list(range(len(room)))
    area, morton = lavapipe_tree_area(lo, hi, ours), lavapipe_tree_area(lo, hi, morton_order(lo, hi))
    assert area < 0.7 * morton, (area, morton)  # measured 0.53


def test_soup_and_tilted_strip():
    rng = np.random.default_rng(1)
    soup = (rng.random((3000, 1, 3)) * 10 + rng.normal(0, 0.05, (3000, 3, 3))).astype(np.float32)
    lo, hi = boxes(soup)
    ours = lavapipe_tree_area(lo, hi, np.array(pc.primitive_order(lo, hi)))
    assert ours < 0.7 * lavapipe_tree_area(lo, hi, morton_order(lo, hi))  # measured 0.49
    strip = shuffled(grid(np.zeros(3), np.array([20.0, 1.0, 0.5]), np.array([0, 0.5, 0.1]), 24))
    lo, hi = boxes(strip)
    ours = lavapipe_tree_area(lo, hi, np.array(pc.primitive_order(lo, hi)))
    assert ours <= lavapipe_tree_area(lo, hi, morton_order(lo, hi))  # measured 0.92


def test_degenerate_input():
    lo = np.zeros((5, 3), np.float32)  # five identical points
    assert sorted(pc.primitive_order(lo, lo)) == list(range(5))
    one = np.ones((1, 3), np.float32)
    assert pc.primitive_order(one, one) == [0]
    empty = np.zeros((0, 3), np.float32)
    assert pc.primitive_order(empty, empty) == []
