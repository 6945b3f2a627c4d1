"""engine/irradiance_cache.py piece by piece, on hand-made inputs (no bpy; milliseconds each).

Added for issue 19 item 4 (mutation testing). test_irradiance_cache.py checks the gather
formulas against closed-form fields and the interpolation against brute force; these tests
pin the remaining pieces exactly, on a few records or strata worked out by hand:
* the ring weights and the checkerboard noise estimate in closed form; R with and without
  the misses; the gradient limiter; the neighbour check's parameters (tolerance, r_min,
  reach, the noise allowance);
* the cache's bookkeeping: growth past its first allocation, the round trip with non-default
  options, the index cache per ``a``, the grid's coarsening in a huge scene, the stats.
"""
import numpy as np
import pytest

from lanterna.engine import irradiance_cache as IC
from lanterna.engine.irradiance_cache import (IrradianceCache, consistent_radii, directions_to_world,
                                              frames_from_normals, gather_directions,
                                              irradiance_and_gradients,
                                              limit_translational_gradient)

UP = np.array([0.0, 0.0, 1.0])


# -- Gather directions and one gather's numbers -------------------------------------------------

def test_gather_directions_shapes_and_centres():
    """No rng: the stratum centres; count without rng: that many copies; a 2-D xi: squeezed."""
    d, j, k = gather_directions(2, 3)
    assert d.shape == (6, 3) and j.tolist() == [0, 0, 0, 1, 1, 1] and k.tolist() == [0, 1, 2, 0, 1, 2]
    s = (j + 0.5) / 2
    phi = 2 * np.pi / 3 * (k + 0.5)
    np.testing.assert_allclose(d, np.column_stack([np.sqrt(s) * np.cos(phi), np.sqrt(s) * np.sin(phi),
                                                   np.sqrt(1 - s)]), rtol=1e-12, atol=1e-15)
    many, _, _ = gather_directions(2, 3, count=4)
    assert many.shape == (4, 6, 3) and np.all(many == d)
    one, _, _ = gather_directions(2, 3, rng=np.random.default_rng(0))
    assert one.shape == (6, 3)
    xi = np.zeros((6, 2))
    xi[:, 0] = 1.0                                            # the ring's outer edge, clipped at 1
    edge, _, _ = gather_directions(2, 3, xi=xi)
    assert edge.shape == (6, 3)
    np.testing.assert_allclose(edge[3:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(edge[:3, 2], np.sqrt(0.5), rtol=1e-12)
    phi0 = np.mod(np.arctan2(edge[:3, 1], edge[:3, 0]), 2 * np.pi)   # xi1 = 0: each cell's first edge
    np.testing.assert_allclose(phi0, 2 * np.pi / 3 * np.arange(3), atol=1e-12)
    frames = frames_from_normals(np.array([UP, [1.0, 0, 0]]))
    w = directions_to_world(d, frames)                        # (K, 3) broadcast to every frame
    assert w.shape == (2, 6, 3)
    np.testing.assert_allclose(w[0] @ UP, d[:, 2], rtol=1e-12)
    np.testing.assert_allclose(w[1] @ [1.0, 0, 0], d[:, 2], rtol=1e-12)


def test_ring_weights_in_closed_form():
    """M = 2: s = 0, 1/2, 1; F(s) = asin(sqrt s) - sqrt(s (1 - s)): F = 0, pi/4 - 1/2, pi/2, so
    the mean tan over the rings is 2 (pi/4 - 1/2), 2 (pi/4 + 1/2); the wall weights
    sin cos^2 at the ring boundary = sqrt(1/2) / 2, and sin(theta+) - sin(theta-)."""
    mean_tan, wall_theta, wall_phi = IC._ring_weights(2)
    np.testing.assert_allclose(mean_tan, [2 * (np.pi / 4 - 0.5), 2 * (np.pi / 4 + 0.5)], rtol=1e-12)
    np.testing.assert_allclose(wall_theta, [np.sqrt(0.5) / 2], rtol=1e-12)
    np.testing.assert_allclose(wall_phi, [np.sqrt(0.5), 1 - np.sqrt(0.5)], rtol=1e-12)
    mean_tan, wall_theta, wall_phi = IC._ring_weights(1)
    np.testing.assert_allclose(mean_tan, [np.pi / 2], rtol=1e-12)
    assert wall_theta.shape == (0,) and wall_phi.tolist() == [1.0]


def test_harmonic_mean_distance_with_and_without_misses():
    """Strata at distances 1, 2, 4 and one miss: Ward's R = 4 / (1 + 1/2 + 1/4) counts the miss
    as infinitely far; over the hits only R = 3 / (7/4). A distance of 0 is raised to
    min_distance."""
    r = np.array([[[1.0, 2.0], [4.0, np.inf]]])
    frames = frames_from_normals(UP[None])
    L = np.ones((1, 2, 2, 3))
    assert irradiance_and_gradients(L, r, 2, 2, frames).radius[0] == pytest.approx(4 / 1.75)
    assert irradiance_and_gradients(L, r, 2, 2, frames, misses_count=False).radius[0] == pytest.approx(3 / 1.75)
    r0 = np.array([[[0.0, 2.0], [4.0, np.inf]]])
    R = irradiance_and_gradients(L, r0, 2, 2, frames, min_distance=0.5).radius[0]
    assert R == pytest.approx(4 / (2 + 0.5 + 0.25))
    # (P, M*N, C) radiance and (P, M*N) distances are the same gather.
    g = irradiance_and_gradients(L.reshape(1, 4, 3), r.reshape(1, 4), 2, 2, frames)
    np.testing.assert_allclose(g.irradiance, [[np.pi] * 3], rtol=1e-12)


def test_gradients_of_a_two_by_two_gather_by_hand():
    """M = N = 2 with the frame t = x, b = y (normal z). Radiance 1 in stratum (0, 0) and 0
    elsewhere, all strata at distance 2:
    * rotational: U = pi / 4 sinc(1/2) mean_tan_0 u(pi/2) with u(pi/2) = b, grad_r = n x U;
    * translational: the theta wall of column 0 (weight wall_theta_0 / 2, difference
      L_10 - L_00 = -1, along u(pi/2) = b, x 2 sin(pi/2) = 2) and the phi walls of ring 0 at
      phi = 0 (L_00 - L_01 = 1, along v(0) = b) and phi = pi (L_01 - L_00 = -1, along
      v(pi) = -b), each weighted (sin(theta_0+) - 0) / 2."""
    t, b, n = np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), np.array([UP])
    L = np.zeros((1, 2, 2, 1))
    L[0, 0, 0, 0] = 1.0
    g = irradiance_and_gradients(L, np.full((1, 2, 2), 2.0), 2, 2, (t, b, n))
    mean_tan, wall_theta, wall_phi = IC._ring_weights(2)
    U = np.pi / 4 * np.sinc(0.5) * mean_tan[0] * np.array([0, 1.0, 0])
    np.testing.assert_allclose(g.rot_grad[0, 0], np.cross(UP, U), atol=1e-12)
    theta_wall = 2.0 * (wall_theta[0] / 2 * -1.0) * np.array([0, 1.0, 0])
    phi_walls = (wall_phi[0] / 2) * (1.0 * np.array([0, 1.0, 0]) + -1.0 * np.array([0, -1.0, 0]))
    np.testing.assert_allclose(g.trans_grad[0, 0], theta_wall + phi_walls, atol=1e-12)
    assert g.irradiance[0, 0] == pytest.approx(np.pi / 4)
    # The same with the bright stratum on ring 1: the theta wall's sign flips.
    L2 = np.zeros((1, 2, 2, 1))
    L2[0, 1, 0, 0] = 1.0
    g2 = irradiance_and_gradients(L2, np.full((1, 2, 2), 2.0), 2, 2, (t, b, n))
    phi_walls2 = (wall_phi[1] / 2) * (np.array([0, 1.0, 0]) + np.array([0, 1.0, 0]))
    np.testing.assert_allclose(g2.trans_grad[0, 0], -theta_wall + phi_walls2, atol=1e-12)
    # The nearer of two distances weighs a wall: stratum (1, 0) at 0.5 m.
    r3 = np.full((1, 2, 2), 2.0)
    r3[0, 1, 0] = 0.5
    g3 = irradiance_and_gradients(L, r3, 2, 2, (t, b, n))
    np.testing.assert_allclose(g3.trans_grad[0, 0], 4 * theta_wall + phi_walls, atol=1e-12)
    # One ring (M = 1): no theta walls.
    g1 = irradiance_and_gradients(L[:, :1], np.full((1, 1, 2), 2.0), 1, 2, (t, b, n))
    np.testing.assert_allclose(g1.trans_grad[0, 0], (1 / 2) * (np.array([0, 1.0, 0]) - np.array([0, -1.0, 0])),
                               atol=1e-12)


def test_checkerboard_variance_by_hand():
    """2 x 2 strata with channel sums a, b / c, d: halves {a, d} and {b, c};
    var = pi^2 (mean(a, d) - mean(b, c))^2 x 2 x 2 / 4^2. One stratum: 0."""
    L = np.zeros((1, 2, 2, 3))
    L[0, 0, 0] = [1.0, 0, 0]            # a = 1
    L[0, 0, 1] = [0, 2.0, 1.0]          # b = 3
    L[0, 1, 0] = [0, 0, 5.0]            # c = 5
    L[0, 1, 1] = [4.0, 0, 0]            # d = 4
    var = IC._stratified_variance(L)
    assert var[0] == pytest.approx(np.pi ** 2 * (2.5 - 4.0) ** 2 * 4 / 16)
    assert IC._stratified_variance(np.ones((2, 1, 1, 3))).tolist() == [0.0, 0.0]
    L3 = np.arange(12, dtype=float).reshape(1, 1, 3, 4)     # 1 x 3: halves {0, 2} and {1}
    sums = L3.sum(axis=3)[0, 0]
    expect = np.pi ** 2 * ((sums[0] + sums[2]) / 2 - sums[1]) ** 2 * 2 / 9
    assert IC._stratified_variance(L3)[0] == pytest.approx(expect)


def test_translational_gradient_limiter():
    """Scaled by R_raw / R where R was clamped up (never up); then no channel faster than
    E / R."""
    grad = np.zeros((3, 2, 3))
    grad[:, :, 0] = [[3.0, 0.5], [3.0, 0.5], [3.0, 0.5]]
    E = np.array([[2.0, 2.0], [2.0, 2.0], [2.0, 2.0]])
    raw = np.array([0.5, np.inf, 4.0])
    R = np.array([1.0, 1.0, 1.0])
    out = limit_translational_gradient(grad, E, raw, R)
    # Record 0: x 0.5 -> (1.5, 0.25), limit 2: unchanged. Record 1: raw inf = R: (3, 0.5)
    # -> channel 0 limited to 2. Record 2: raw > R: not scaled up; (3 -> 2, 0.5).
    np.testing.assert_allclose(out[:, :, 0], [[1.5, 0.25], [2.0, 0.5], [2.0, 0.5]], rtol=1e-12)
    assert np.all(out[:, :, 1:] == 0)
    assert np.all(limit_translational_gradient(np.zeros((1, 1, 3)), np.zeros((1, 1)), np.ones(1),
                                               np.ones(1)) == 0)


# -- The neighbour check's parameters -----------------------------------------------------------

def _line(values, spacing=0.1, radius=1.0):
    k = len(values)
    c = IrradianceCache()
    c.add(np.column_stack([np.arange(k) * spacing, np.zeros(k), np.zeros(k)]), np.tile(UP, (k, 1)),
          np.repeat(np.asarray(values, float)[:, None], 3, axis=1), np.full(k, radius))
    return c


def test_consistent_radii_by_hand():
    """Two records 0.1 apart, R = 1, E = 1 and 0.2 (channel sums 3 and 0.6), a = 0.3: excess
    2.4 beyond tol x mean = 0.3 x 1.8, so both get R <= 0.1 x (0.54 / 2.4) / 0.3 = 0.075. A
    tolerance of 2.0 lets them be; r_min is a floor. The pair is checked when d / R <
    reach x a: reach 1 (0.1 < 0.3) sees it, reach 0.3 (0.1 > 0.09) does not."""
    c = _line([1.0, 0.2])
    zero = np.zeros(2)
    np.testing.assert_allclose(consistent_radii(c, 0.3, zero), [0.075, 0.075], rtol=1e-12)
    assert np.all(np.isinf(consistent_radii(c, 0.3, zero, tolerance=2.0)))
    np.testing.assert_allclose(consistent_radii(c, 0.3, zero, r_min=0.2), [0.2, 0.2])
    np.testing.assert_allclose(consistent_radii(c, 0.3, zero, r_min=np.array([0.0, 0.1])), [0.075, 0.1])
    np.testing.assert_allclose(consistent_radii(c, 0.3, zero, reach=1.0), [0.075, 0.075], rtol=1e-12)
    assert np.all(np.isinf(consistent_radii(c, 0.3, zero, reach=0.3)))
    # Noise: sigma = median(sd / E) over lit records; the excess shrinks by z sigma
    # sqrt(E_i^2 + E_j^2). sd = 0.1 E gives sigma 0.1 and z = 4: 2.4 - 0.4 sqrt(9.36) = 1.176,
    # R <= 0.1 x 0.54 / 1.176 / 0.3.
    var = (0.1 * np.array([3.0, 0.6])) ** 2
    np.testing.assert_allclose(consistent_radii(c, 0.3, var), 0.1 * 0.54 / (2.4 - 0.4 * np.sqrt(9.36)) / 0.3,
                               rtol=1e-12)
    np.testing.assert_allclose(consistent_radii(c, 0.3, var, z=0.0), [0.075, 0.075], rtol=1e-12)
    # One record, or records too far apart to see each other: no bound.
    assert np.all(np.isinf(consistent_radii(_line([1.0]), 0.3, np.zeros(1))))
    assert np.all(np.isinf(consistent_radii(_line([1.0, 0.2], spacing=5.0), 0.3, zero)))
    # Dark records do not set the noise level (E = 0 would divide by zero).
    dark = _line([0.0, 0.0, 1.0], spacing=0.1)
    b = consistent_radii(dark, 0.3, np.array([5.0, 5.0, 0.0]))
    assert np.all(np.isfinite(b[[1, 2]]))


def test_neighbour_predictions_by_hand():
    """Three records at x = 0, 0.2, 0.7 with a gradient 0.5 / m in x: each predicts the others
    within its reach (a R = 0.6 m) by E_i + 0.5 (x_j - x_i); never itself; 0 and 0.7 are too
    far apart."""
    k = 3
    c = IrradianceCache()
    grad = np.zeros((k, 3, 3))
    grad[:, :, 0] = 0.5
    c.add(np.array([[0.0, 0, 0], [0.2, 0, 0], [0.7, 0, 0]]), np.tile(UP, (k, 1)),
          np.array([[1.0] * 3, [2.0] * 3, [3.0] * 3]), np.ones(k), trans_grad=grad)
    j, i, d, pred = c.neighbour_predictions(0.6)
    pairs = sorted(zip(j.tolist(), i.tolist()))
    assert pairs == [(0, 1), (1, 0), (1, 2), (2, 1)]
    for jj, ii, dd, pp in zip(j, i, d, pred):
        xj, xi = c.positions[jj, 0], c.positions[ii, 0]
        assert dd == pytest.approx(abs(xj - xi))
        np.testing.assert_allclose(pp, c.irradiance[ii] + 0.5 * (xj - xi), rtol=1e-12)
    _, _, _, flat = c.neighbour_predictions(0.6, use_gradients=False)
    assert set(flat[:, 0].tolist()) <= {1.0, 2.0, 3.0}
    empty = IrradianceCache().neighbour_predictions(0.6)
    assert [len(x) for x in empty] == [0, 0, 0, 0] and empty[3].shape == (0, 3)


# -- The cache's bookkeeping --------------------------------------------------------------------

def test_add_grows_and_keeps_every_record():
    """1500 records added in three batches (past the first allocation of 1024): all kept, in
    order, normals normalised, missing gradients zero, the indices returned."""
    rng = np.random.default_rng(1)
    c = IrradianceCache(channels=2)
    pos = rng.uniform(0, 1, (1500, 3))
    nrm = rng.normal(size=(1500, 3)) * 3.0
    E = rng.uniform(0, 1, (1500, 2))
    idx = [c.add(pos[a:b], nrm[a:b], E[a:b], np.full(b - a, 0.1)) for a, b in ((0, 1000), (1000, 1001), (1001, 1500))]
    assert idx[0].tolist() == list(range(1000)) and idx[1].tolist() == [1000]
    assert idx[2].tolist() == list(range(1001, 1500))
    assert len(c) == 1500
    np.testing.assert_array_equal(c.positions, pos)
    np.testing.assert_array_equal(c.irradiance, E)
    np.testing.assert_allclose(c.normals, nrm / np.linalg.norm(nrm, axis=1, keepdims=True), rtol=1e-12)
    assert np.all(c.rot_grad == 0) and np.all(c.trans_grad == 0) and np.all(c.usage == 0)
    assert c.rot_grad.shape == (1500, 2, 3)
    with pytest.raises(ValueError):
        c.add([[0, 0, 0.0]], [UP], [[1.0, 1.0]], [0.0])
    with pytest.raises(ValueError):
        IrradianceCache(index="octree")


def test_round_trip_keeps_options_and_records():
    rng = np.random.default_rng(2)
    c = IrradianceCache(channels=3, index="kdtree", radius_ratio=2.0, e_min=1e-4, cell_fraction=0.5)
    c.add(rng.uniform(0, 1, (50, 3)), UP + 0.1 * rng.normal(size=(50, 3)), rng.uniform(0, 1, (50, 3)),
          rng.uniform(0.05, 0.3, 50), rng.normal(size=(50, 3, 3)), rng.normal(size=(50, 3, 3)))
    q, qn = rng.uniform(0, 1, (200, 3)), np.tile(UP, (200, 1))
    c.interpolate(q, qn, 0.4)
    back = IrradianceCache.from_arrays(c.to_arrays())
    assert (back.channels, back.index, back.radius_ratio, back.e_min, back.cell_fraction) == \
        (3, "kdtree", 2.0, 1e-4, 0.5)
    for key in IrradianceCache.ARRAY_FIELDS:
        np.testing.assert_array_equal(getattr(back, key), getattr(c, key))
    for x, y in zip(back.interpolate(q, qn, 0.4, count_usage=False), c.interpolate(q, qn, 0.4, count_usage=False)):
        np.testing.assert_array_equal(x, y)
    assert back.usage.sum() > 0


def test_interpolate_edge_cases_and_usage():
    c = IrradianceCache()
    E, cov, ws, cnt = c.interpolate(np.zeros((2, 3)), np.tile(UP, (2, 1)), 0.3)
    assert E.shape == (2, 3) and not cov.any() and np.all(ws == 0) and cnt.dtype == np.int64
    c.add([[0.0, 0, 0], [0.05, 0, 0]], [UP, UP], [[1.0] * 3, [3.0] * 3], [1.0, 1.0])
    for a in (0.0, -1.0, float("nan")):
        E, cov, ws, cnt = c.interpolate(np.zeros((1, 3)), UP[None], a)
        assert not cov.any() and np.all(E == 0)
    q = np.array([[0.02, 0, 0], [0.02, 0, 0], [5.0, 0, 0]])
    E, cov, ws, cnt = c.interpolate(q, np.tile(UP, (3, 1)), 0.3, chunk=1)
    w = np.array([1 / 0.02, 1 / 0.03])
    np.testing.assert_allclose(E[0], (w @ [1.0, 3.0]) / w.sum() * np.ones(3), rtol=1e-12)
    np.testing.assert_allclose(ws[:2], w.sum(), rtol=1e-12)
    assert cnt.tolist() == [2, 2, 0] and cov.tolist() == [True, True, False]
    assert c.usage.tolist() == [2, 2]
    c.reset_usage()
    assert c.usage.tolist() == [0, 0]


def test_index_structures_are_cached_per_a():
    """The grid index is built per value of a (at most four kept); the kd-tree index once."""
    c = IrradianceCache()
    c.add(np.random.default_rng(3).uniform(0, 1, (30, 3)), np.tile(UP, (30, 1)), np.ones((30, 3)),
          np.full(30, 0.2))
    for a in (0.1, 0.2, 0.3, 0.4, 0.5):
        c.interpolate(np.zeros((1, 3)), UP[None], a)
    assert len(c._indexes) == 4 and 0.1 not in c._indexes and 0.5 in c._indexes
    first = c._structures(0.5)
    assert c._structures(0.5) is first
    t = IrradianceCache(index="kdtree")
    t.add(np.zeros((1, 3)), UP[None], np.ones((1, 3)), [0.2])
    t.interpolate(np.zeros((1, 3)), UP[None], 0.1)
    t.interpolate(np.zeros((1, 3)), UP[None], 0.3)
    assert list(t._indexes) == [None]


def test_radius_classes_and_grid_candidates():
    """Radius classes: R in [ratio^c, ratio^(c+1)); the grid lists a record in every cell its
    influence box overlaps, so a point within a R of it is always a candidate."""
    c = IrradianceCache(radius_ratio=2.0)
    R = np.array([0.3, 0.6, 1.1, 0.26, 2.5])
    c.add(np.zeros((5, 3)) + np.arange(5)[:, None] * [1.0, 0, 0], np.tile(UP, (5, 1)), np.ones((5, 3)), R)
    classes = c._radius_classes()
    got = sorted(sorted(m.tolist()) for m in classes)
    assert got == [[0, 3], [1], [2], [4]]
    assert c.stats()["radius_classes"] == 4
    # Candidates: a point 0.99 a R_i from record i (every direction) finds it.
    rng = np.random.default_rng(4)
    for i in range(5):
        d = rng.normal(size=(50, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts = c.positions[i] + 0.99 * 0.5 * R[i] * d
        q, r = c.candidates(pts, 0.5)
        assert set(q[r == i].tolist()) == set(range(50)), i
    assert len(IrradianceCache().candidates(np.zeros((3, 3)), 0.3)[0]) == 0


def test_grid_in_a_huge_scene_with_tiny_radii():
    """Records 1e-9 m wide spread over 1e9 m: the cell count would overflow 64-bit keys, so
    the cells grow until it fits; the answers stay exact."""
    c = IrradianceCache()
    pos = np.array([[0.0, 0, 0], [1e9, 1e9, 1e9], [5e8, 0, 0]])
    c.add(pos, np.tile(UP, (3, 1)), [[1.0] * 3, [2.0] * 3, [3.0] * 3], np.full(3, 1e-9))
    q = pos + [1e-10, 0, 0]
    E, cov, _, cnt = c.interpolate(q, np.tile(UP, (3, 1)), 0.3)
    assert cov.all() and cnt.tolist() == [1, 1, 1]
    np.testing.assert_allclose(E[:, 0], [1.0, 2.0, 3.0])
    g = c._structures(0.3)[0]
    assert float(np.prod(g.dims.astype(float))) <= 2.0 ** 62


def test_tree_index_asks_for_more_neighbours_when_full():
    """40 records at one place (more than the first k = 16 the kd-tree asks for): a point
    next to them is served by all 40."""
    c = IrradianceCache(index="kdtree")
    c.add(np.zeros((40, 3)) + np.linspace(0, 1e-3, 40)[:, None], np.tile(UP, (40, 1)),
          np.ones((40, 3)), np.ones(40))
    E, cov, ws, cnt = c.interpolate(np.array([[0.01, 0, 0]]), UP[None], 0.3)
    assert cnt.tolist() == [40]


def test_stats_fields():
    c = IrradianceCache()
    c.add(np.array([[0.0, 0, 0], [1.0, 0, 0], [5.0, 0, 0]]), np.tile(UP, (3, 1)), np.ones((3, 3)),
          [1.0, 1.0, 0.5])
    c.interpolate(np.array([[0.1, 0, 0], [0.05, 0, 0], [1.0, 0, 0]]), np.tile(UP, (3, 1)), 0.3)
    s = c.stats()
    assert s["records"] == 3 and s["usage"].tolist() == [2, 1, 0]
    assert s["usage_mean"] == pytest.approx(1.0) and s["usage_max"] == 2 and s["unused_records"] == 1
    assert s["index"] == "grid" and s["radius_classes"] == 2 and s["index_build_seconds"] >= 0
    per_record = 8 * (3 + 3 + 3 + 1 + 9 + 9 + 9) + 8
    tables = c._geo.nbytes + c._val.nbytes
    index = sum(g.nbytes for v in c._indexes.values() for g in v)
    assert s["memory_bytes"] == 3 * per_record + tables + index
    assert s["allocated_bytes"] == 1024 * per_record + tables + index
    empty = IrradianceCache().stats()
    assert empty["records"] == 0 and empty["usage_mean"] == 0.0 and empty["usage_max"] == 0
    assert empty["radius_classes"] == 0


def test_pairs_from_ranges():
    row, pos = IC._pairs_from_ranges(np.array([5, 0, 9]), np.array([2, 0, 3]))
    assert row.tolist() == [0, 0, 2, 2, 2] and pos.tolist() == [5, 6, 9, 10, 11]


def test_harmonic_mean_over_the_hits_of_each_point_alone():
    """Two gathers without a miss, over the hits only: each point's R is its own harmonic mean
    (4 strata / sum of 1/r), not a count pooled over the points."""
    r = np.array([[[1.0, 2.0], [4.0, 4.0]], [[3.0, 3.0], [3.0, 3.0]]])
    frames = frames_from_normals(np.tile(UP, (2, 1)))
    g = irradiance_and_gradients(np.ones((2, 2, 2, 3)), r, 2, 2, frames, misses_count=False)
    np.testing.assert_allclose(g.radius, [4 / 2.0, 3.0], rtol=1e-12)


def test_records_with_tilted_normals_serve_their_own_points():
    """Records on tilted surfaces (every normal component non-zero), each asked at its own
    position with its own normal: error 0 (w = 1 / e_min), the record's value exactly; a
    point whose normal faces away from the record's (n . n_i = -0.54) is not served."""
    n1 = np.array([0.48, 0.6, 0.64])
    n2 = np.array([-0.6, -0.48, 0.64])
    c = IrradianceCache(channels=1)
    c.add([[0.0, 0, 0], [5.0, 0, 0]], [n1, n2], [[2.0], [7.0]], [1.0, 1.0])
    E, cov, ws, cnt = c.interpolate([[0.0, 0, 0], [5.0, 0, 0]], [n1, n2], 0.3)
    np.testing.assert_allclose(E[:, 0], [2.0, 7.0], rtol=1e-12)
    assert cov.all() and cnt.tolist() == [1, 1]
    np.testing.assert_allclose(ws, 1.0 / c.e_min, rtol=1e-9)
    away = np.array([0.48, -0.6, -0.64])                  # n1 . away = 0.2304 - 0.36 - 0.4096
    E, cov, _ws, _cnt = c.interpolate([[0.0, 0, 0]], [away], 0.3)
    assert not cov.any() and E[0, 0] == 0


def test_value_problems_name_each_damaged_field():
    """Saved records with non-finite positions and gradients, a negative irradiance, a zero
    radius, a negative usage count: each is named, in order; sound records give none."""
    c = IrradianceCache(channels=3)
    c.add([[0.0, 0, 0], [1.0, 0, 0]], [UP, UP], [[1.0] * 3, [2.0] * 3], [0.5, 0.5])
    arrays = c.to_arrays()
    assert IrradianceCache.value_problems(arrays) == []
    bad = {k: np.array(v, copy=True) for k, v in arrays.items()}
    bad["positions"][0, 1] = np.nan
    bad["rot_grad"][1, 0, 2] = np.inf
    bad["trans_grad"][0, 2, 0] = -np.inf
    bad["irradiance"][1, 1] = -1.0
    bad["radius"][0] = 0.0
    bad["usage"][1] = -3
    assert IrradianceCache.value_problems(bad) == [
        "record positions are not finite", "record rot grad are not finite",
        "record trans grad are not finite", "record irradiance is not finite in [0, 1e30] W/m^2",
        "record radii are not finite and positive", "record usage counts are negative"]


@pytest.mark.parametrize("name, inside, outside", [("channels", (1, 64), (0, 65)),
                                                   ("radius_ratio", (1.0 + 1e-9, 1e3), (1.0, 1001.0)),
                                                   ("e_min", (1e-300, 1.0), (0.0, 1.5)),
                                                   ("cell_fraction", (0.05, 20.0), (0.04, 20.5))])
def test_options_accept_their_range_and_refuse_the_rest(name, inside, outside):
    """Each option's bounds are accepted, values just outside and non-finite ones refused."""
    for value in inside:
        assert getattr(IrradianceCache(**{name: value}), name) == value
    for value in (*outside, float("nan"), float("inf")):
        with pytest.raises(ValueError, match=name):
            IrradianceCache(**{name: value})
