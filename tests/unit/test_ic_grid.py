"""The irradiance cache's lookup grid (ic_grid, techniques/irradiance_cache.cpp): a query at a
point reads one bucket per level in use (ic_lookup, shaders/techniques/irradiance_cache.glsl)
and must meet every entry whose influence sphere (radius accuracy * R) holds the point, each
once. Checked against brute force with the shader's lookup written out here."""
from __future__ import annotations

import numpy as np

import parallax_core as pc

LEVELS = 7  # IC_GRID_LEVELS
HEADER = 2 * LEVELS  # IC_GRID_HEADER


def bucket(cell, mask):
    """ic_grid_bucket (shaders/shared/techniques.h) on uint32."""
    c = cell.astype(np.int64).astype(np.uint32)
    h = (c[..., 0] * np.uint32(73856093)) ^ (c[..., 1] * np.uint32(19349663)) ^ (c[..., 2] * np.uint32(83492791))
    return h & np.uint32(mask)


def lookup(grid, point):
    """The slots the shader's loop visits at `point`, in its order."""
    found, starts = [], grid["starts"]
    for level in range(LEVELS):
        if not grid["levels"] >> level & 1:
            continue
        side = np.float32(grid["cell"]) * np.float32(1 << level)
        cell = np.floor(point.astype(np.float32) / side)
        b = HEADER + int(starts[2 * level]) + int(bucket(cell, starts[2 * level + 1]))
        found += list(grid["slots"][starts[b]:starts[b + 1]])
    return found


def test_every_covering_entry_is_found_once():
    rng = np.random.default_rng(1)
    accuracy, min_radius = 0.2, 0.05
    n = 3000
    positions = rng.uniform(-2.0, 2.0, (n, 3)).astype(np.float32)
    # Radii over the clamp's whole range [R_min, 64 R_min], many at its ends.
    radii = (min_radius * np.exp2(np.where(rng.random(n) < 0.4, rng.choice([0.0, 6.0], n), rng.uniform(0, 6, n))))
    radii = radii.astype(np.float32)
    grid = pc._native.ic_grid(positions, radii, accuracy, min_radius)
    grid["starts"], grid["slots"] = np.asarray(grid["starts"]), np.asarray(grid["slots"])
    assert abs(grid["cell"] / (2 * accuracy * min_radius) - 1) < 1e-6
    # Each place carries its entry's sphere (IcCandidate), as the query tests it.
    assert np.array_equal(np.asarray(grid["reach"], np.float32), np.float32(accuracy) * radii[grid["slots"]])
    # Points near entries (inside, on and just outside their spheres) and anywhere.
    near = positions[rng.integers(0, n, 2000)] + rng.normal(0, 1, (2000, 3)) * (accuracy * radii.max() / 2)
    points = np.concatenate([near, rng.uniform(-2.5, 2.5, (1000, 3))]).astype(np.float32)
    influence = accuracy * radii
    met = 0
    for p in points:
        found = lookup(grid, p)
        assert len(found) == len(set(found)), "an entry listed twice in one query"
        inside = set(np.flatnonzero(np.linalg.norm(positions - p, axis=1) < influence * 0.9999))
        assert inside <= set(found), sorted(inside - set(found))
        met += len(inside)
    assert met > 1000  # the points did fall into spheres
    # Each entry is listed in at most 8 buckets, and the tables are not crowded.
    assert len(grid["slots"]) <= 8 * n
    assert len(grid["starts"]) - HEADER - 1 >= 2 * len(grid["slots"])


def test_empty_cache():
    grid = pc._native.ic_grid(np.zeros((0, 3), np.float32), np.zeros(0, np.float32), 0.2, 0.1)
    assert grid["levels"] == 0 and len(grid["slots"]) == 0 and list(grid["starts"]) == [0] * (HEADER + 1)
