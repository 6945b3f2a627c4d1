"""engine/hair.py: curves as closed tubes of triangles, checked by exact geometry."""
import math
from collections import Counter

import numpy as np
import pytest

from lanterna.engine import hair


def closed_and_outward(tubes):
    """(open or doubled edges, signed volume) of the tubes, coincident vertices merged."""
    v = tubes.vertices.astype(np.float64)
    _, merged = np.unique(np.round(v / 1e-6).astype(np.int64), axis=0, return_inverse=True)
    t = merged.reshape(-1)[tubes.triangles]
    edges = Counter(map(tuple, np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])))
    bad = [e for e, n in edges.items() if n != 1 or edges.get((e[1], e[0]), 0) != 1]
    c = v[tubes.triangles]
    volume = np.einsum("ij,ij->i", c[:, 0], np.cross(c[:, 1], c[:, 2])).sum() / 6.0
    return len(bad), volume


def width_along(tubes, direction):
    """The tube's extent across ``direction``'s perpendicular in the plane z = const, for a
    straight vertical tube: its projected width seen from ``direction``."""
    side = np.cross([0.0, 0.0, 1.0], direction)
    side /= np.linalg.norm(side)
    proj = tubes.vertices.astype(np.float64) @ side
    return proj.max() - proj.min()


def test_a_straight_tube_is_closed_outward_and_as_wide_as_the_round_curve_on_average():
    r = 0.1
    tubes = hair.tessellate_curves([[0, 0, 0], [0, 0, 1]], [r, r], [0, 2])
    bad, volume = closed_and_outward(tubes)
    assert bad == 0
    big = r * (math.pi / 6) / math.sin(math.pi / 6)       # the hexagon's circumradius
    assert volume == pytest.approx(1.5 * math.sqrt(3) * big ** 2, rel=1e-5)
    # Perimeter 2 pi r: by Cauchy's formula the mean projected width over directions is 2r.
    angles = np.linspace(0.0, math.pi, 721)[:-1]
    widths = [width_along(tubes, [math.cos(a), math.sin(a), 0.0]) for a in angles]
    assert np.mean(widths) == pytest.approx(2 * r, rel=1e-4)
    # Shading normals point away from the axis (and along it on the caps).
    centre = tubes.vertices.astype(np.float64) * [1, 1, 0]
    radial = np.einsum("ij,ij->i", tubes.normals, centre)
    on_side = np.abs(tubes.normals[:, 2]) < 0.5
    assert np.all(radial[on_side] > 0) and np.all(np.abs(tubes.normals[~on_side, 2]) > 0.999)


def test_many_strands_seen_from_one_side_average_the_round_width():
    """Each curve's polygon is turned by its own fraction of a side (a hexagon's width
    changes by 15 % as it turns): 200 parallel strands seen from +y are 2r wide on average."""
    r, n = 0.05, 200
    x = np.arange(n) * 1.0
    points = np.stack([np.repeat(x, 2), np.zeros(2 * n), np.tile([0.0, 1.0], n)], axis=1)
    tubes = hair.tessellate_curves(points, np.full(2 * n, r), np.arange(0, 2 * n + 1, 2))
    widths = []
    for c in range(n):
        mine = tubes.vertices[tubes.vertex_curves == c].astype(np.float64)
        widths.append(np.ptp(mine[:, 0]))
    widths = np.array(widths)
    assert widths.min() < 1.83 * r and widths.max() > 2.07 * r     # they do differ
    assert np.mean(widths) == pytest.approx(2 * r, rel=0.005)


def catmull_rom(p0, p1, p2, p3, t):
    return 0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t ** 2
                  + (-p0 + 3 * p1 - 3 * p2 + p3) * t ** 3)


def ring_centres(tubes, sides=hair.SIDES):
    """Centres of the side rings (the first V - caps vertices come ring by ring)."""
    caps = len(tubes.vertices) - (len(tubes.vertices) // sides) * sides
    assert caps == 0
    return tubes.vertices.astype(np.float64).reshape(-1, sides, 3).mean(axis=1)


def test_the_spline_passes_through_the_points_and_is_catmull_rom_between_them():
    points = np.array([[0, 0, 0], [0.0, 0, 1], [1, 0, 2], [2, 1, 2]], float)
    tubes = hair.tessellate_curves(points, np.full(4, 0.01), [0, 4])
    n_rings = int(np.sum(tubes.vertex_curves == 0)) // hair.SIDES
    centres = ring_centres(tubes)[: n_rings]
    # The four points are ring centres, in order.
    hits = [int(np.argmin(np.linalg.norm(centres - p, axis=1))) for p in points]
    assert hits == sorted(hits) and hits[0] == 0
    for p, i in zip(points, hits):
        np.testing.assert_allclose(centres[i], p, atol=1e-6)
    # Between points 1 and 2 the centres lie on the uniform Catmull-Rom spline.
    between = centres[hits[1]: hits[2] + 1]
    ts = np.linspace(0.0, 1.0, len(between))
    expected = np.array([catmull_rom(points[0], points[1], points[2], points[3], t) for t in ts])
    np.testing.assert_allclose(between, expected, atol=1e-6)
    assert len(between) > 2                               # a bent piece is cut
    # Straight pieces: only the points.
    linear = hair.tessellate_curves(points, np.full(4, 0.01), [0, 4], smooth=False)
    np.testing.assert_allclose(ring_centres(linear)[:4], points, atol=1e-6)


def test_a_curl_through_every_direction_neither_twists_nor_collapses():
    """A helix whose tangent sweeps past -z (where a fixed basis flips): every side quad keeps
    its size and faces out, and the tube stays closed."""
    s = np.linspace(0.0, 4 * math.pi, 40)
    points = np.stack([np.cos(s), np.sin(s), 0.15 * s], axis=1)
    points = points @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)   # axis along -y
    r = 0.05
    tubes = hair.tessellate_curves(points, np.full(len(points), r), [0, len(points)])
    bad, volume = closed_and_outward(tubes)
    assert bad == 0 and volume > 0
    c = tubes.vertices[tubes.triangles].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    side = area[: len(area) - 2 * (hair.SIDES - 2)]
    assert side.min() > 0.2 * np.median(side)
    geometric = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    shading = tubes.normals[tubes.triangles].astype(np.float64).sum(axis=1)
    assert np.all(np.einsum("ij,ij->i", geometric, shading) > 0)


def test_a_tapered_tip_closes_and_a_cone_leans_its_normals():
    tubes = hair.tessellate_curves([[0, 0, 0], [0, 0, 1]], [0.2, 0.0], [0, 2])
    bad, _ = closed_and_outward(tubes)
    assert bad == 0
    side = np.abs(tubes.normals[:, 2]) < 0.999
    # The cone's normal: (1, 0.2) normalised in (radial, z).
    np.testing.assert_allclose(tubes.normals[side, 2], 0.2 / math.hypot(1, 0.2), atol=1e-5)


def test_bad_curves_are_skipped_and_counted():
    points = np.array([[0, 0, 0], [0, 0, 1],            # good
                       [5, 0, 0],                       # one point
                       [1, 0, 0], [1, 0, np.nan],       # NaN
                       [2, 0, 0], [2, 0, 1]], float)    # radius 0 everywhere: draws nothing
    radii = np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.0, 0.0])
    tubes = hair.tessellate_curves(points, radii, [0, 2, 3, 5, 7])
    assert tubes.skipped == 2
    assert set(np.unique(tubes.vertex_curves)) == {0}
    assert np.all(np.isfinite(tubes.vertices))
    with pytest.raises(ValueError):
        hair.tessellate_curves(points, radii[:3], [0, 2, 3])
    empty = hair.tessellate_curves(np.zeros((0, 3)), np.zeros(0), [0])
    assert len(empty.triangles) == 0


def test_too_many_triangles_cost_sides_and_pieces_with_a_note():
    s = np.linspace(0.0, math.pi, 6)
    one = np.stack([np.cos(s), np.sin(s), 0 * s], axis=1)
    points = np.concatenate([one + [0, 0, z] for z in range(100)])
    offsets = np.arange(0, 601, 6)
    full = hair.tessellate_curves(points, np.full(600, 0.01), offsets)
    budget = len(full.triangles) // 12
    small = hair.tessellate_curves(points, np.full(600, 0.01), offsets, max_triangles=budget)
    assert len(small.triangles) <= budget
    assert any("not subdivided" in n for n in small.notes)
    assert any("sides instead of 6" in n for n in small.notes)
