"""engine/gather.py piece by piece, on hand-made inputs (no bpy; milliseconds each).

Added for issue 19 item 4 (mutation testing). test_gather_cache.py renders whole rooms; these
tests pin the final gather's pieces exactly:
* ``RadianceEstimates.build`` picks every 1/fraction-th photon and stores the photon map's own
  estimate there; ``lookup`` returns the nearest estimate whose normal agrees (n . n_i > 0.5)
  among the 4 nearest, within the radius cap and its disc;
* ``photon_guided_allocation`` puts the extra rays in the strata the photons came through, in
  proportion to their luminance (integer shares: exact);
* ``final_gather`` under a ceiling whose estimate is known: E = rho E_ceiling exactly, each
  stratum's first ray inside its own (theta, phi) cell, mirrors with their throughput, the
  chunked gather equal to the whole one.
"""
import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from analytic import quad
from lanterna.engine import gather as G
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.gather import RadianceEstimates, final_gather, photon_guided_allocation
from lanterna.engine.photons import PhotonMap
from lanterna.engine.surfaces import SceneSurfaces
from lanterna.engine.scene import Camera, Material, Scene

UP = np.array([0.0, 0.0, 1.0])


def _pmap(pos, power, incoming, normals, bounces):
    return PhotonMap(np.asarray(pos, np.float32), np.asarray(power, np.float32),
                     np.asarray(incoming, np.float16), np.asarray(normals, np.float16),
                     np.asarray(bounces, np.uint8)).build()


# -- Precomputed estimates ----------------------------------------------------------------------

def test_build_takes_every_fraction_th_photon_and_its_estimate():
    rng = np.random.default_rng(0)
    m = 400
    pos = np.column_stack([rng.uniform(0, 1, (m, 2)), np.zeros(m)])
    nrm = np.tile(UP, (m, 1)) * 1.001                      # float16 normals a little long
    pmap = _pmap(pos, rng.uniform(0.1, 1, (m, 3)), -np.tile(UP, (m, 1)), nrm, np.zeros(m))
    est = RadianceEstimates.build(pmap, k=10, max_radius=0.3, fraction=0.25)
    assert len(est) == 100 and est.max_radius == 0.3
    pick = np.linspace(0, m - 1, 100).astype(np.int64)
    np.testing.assert_array_equal(est.positions, pmap.positions[pick])
    np.testing.assert_allclose(np.linalg.norm(est.normals, axis=1), 1.0, rtol=1e-6)
    n64 = pmap.normals[pick].astype(np.float64)
    n64 /= np.linalg.norm(n64, axis=1, keepdims=True)
    expect = pmap.irradiance(pmap.positions[pick].astype(np.float64), n64, k=10, max_radius=0.3)
    np.testing.assert_allclose(est.irradiance, expect.astype(np.float32), rtol=1e-6)
    assert est.positions.dtype == est.normals.dtype == est.irradiance.dtype == np.float32
    st = est.stats
    assert st["estimates"] == 100 and st["fraction"] == 0.25 and st["k"] == 10
    assert st["bytes"] == 3 * est.positions.nbytes and st["seconds"] >= 0
    assert len(RadianceEstimates.build(pmap, fraction=0.25, max_estimates=30)) == 30
    assert len(RadianceEstimates.build(pmap, fraction=1e-6)) == 1
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(2) as pool:
        pooled = RadianceEstimates.build(pmap, k=10, max_radius=0.3, fraction=0.25, pool=pool)
    np.testing.assert_array_equal(pooled.irradiance, est.irradiance)
    empty = RadianceEstimates.build(pmap.subset(np.zeros(m, bool)))
    assert len(empty) == 0 and empty.stats == {"estimates": 0, "seconds": 0.0}
    assert np.all(empty.lookup(np.zeros((2, 3)), np.tile(UP, (2, 1))) == 0)


def _estimates(pos, nrm, e, max_radius=np.inf):
    est = RadianceEstimates(np.asarray(pos, np.float32), np.asarray(nrm, np.float32),
                            np.asarray(e, np.float32), max_radius=max_radius)
    est._tree = KDTree(est.positions, leafsize=16)
    return est


def test_lookup_nearest_agreeing_estimate():
    """Estimates on the x axis at 0, 0.1, ..., 0.5: the nearest whose normal agrees with the
    point's (n . n_i > 0.5) among the four nearest gives its irradiance; none: 0."""
    c60 = [np.sin(np.radians(55)), 0, np.cos(np.radians(55))]            # cos 0.57: agrees
    c65 = [np.sin(np.radians(65)), 0, np.cos(np.radians(65))]            # cos 0.42: does not
    pos = [[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0], [0.4, 0, 0], [0.5, 0, 0]]
    nrm = [[0, 0, -1.0], c65, c60, [0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0]]
    e = np.outer(np.arange(1, 7), [1.0, 2.0, 3.0])
    est = _estimates(pos, nrm, e)
    q = np.array([[-0.01, 0, 0], [-0.01, 0, 0], [0.51, 0, 0], [0.26, 0, 0]])
    n = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, -1.0], [1.0, 0, 0]])
    out = est.lookup(q, n)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out[0], e[2])      # 1st (down) and 2nd (65 deg) do not agree
    np.testing.assert_array_equal(out[1], e[0])
    np.testing.assert_array_equal(out[2], e[4])
    # Sideways (+x): 55 and 65 degrees agree (cos 0.82, 0.91); nearest of the four is 0.3 ...
    # which does not (its normal is +z), 0.2 is next: e[2].
    np.testing.assert_array_equal(out[3], e[2])
    # The 5th nearest is not looked at: from -0.01 facing up, only 0.0 .. 0.3 are asked; with
    # the agreeing ones removed nothing is left.
    est2 = _estimates(pos, [[0, 0, -1.0]] * 5 + [[0, 0, 1.0]], e)
    assert np.all(est2.lookup(q[:1], n[:1]) == 0)
    assert len(est.lookup(np.zeros((0, 3)), np.zeros((0, 3)))) == 0


def test_lookup_within_the_radius_and_its_disc():
    """With max_radius 0.2: estimates farther than 0.2 or more than 0.25 x 0.2 = 0.05 from the
    point's tangent plane do not count."""
    pos = [[0.15, 0, 0.04], [0.1, 0, 0.06], [0.3, 0, 0.0]]
    est = _estimates(pos, [[0, 0, 1.0]] * 3, [[1.0] * 3, [2.0] * 3, [3.0] * 3], max_radius=0.2)
    q = np.array([[0.0, 0, 0], [0.12, 0, 0.06], [0.45, 0, 0]])
    out = est.lookup(q, np.tile(UP, (3, 1)))
    np.testing.assert_array_equal(out[:, 0], [1.0, 2.0, 3.0])
    far = est.lookup(np.array([[0.6, 0, 0]]), np.array([UP]))
    assert np.all(far == 0)
    unbounded = _estimates(pos, [[0, 0, 1.0]] * 3, [[1.0] * 3, [2.0] * 3, [3.0] * 3])
    np.testing.assert_array_equal(unbounded.lookup(np.array([[0.0, 0, 0], [0.6, 0, 0]]),
                                                   np.tile(UP, (2, 1)))[:, 0], [2.0, 3.0])


# -- Photon-guided allocation -------------------------------------------------------------------

def _towards(j, k, m, n, normal=UP):
    t, b = sampling.orthonormal_basis(np.asarray(normal, float)[None])
    s = (j + 0.5) / m
    phi = 2 * np.pi * (k + 0.5) / n
    return np.sqrt(s) * (np.cos(phi) * t[0] + np.sin(phi) * b[0]) + np.sqrt(1 - s) * np.asarray(normal, float)


def test_guided_allocation_puts_extra_rays_where_the_photons_came_from():
    """Photons near the point that bounced at least once and came through strata (1, 2) and
    (3, 5) with luminance 1 : 3: 8 extra rays split 2 : 6 (integers: exact whatever the
    rounding number). Photons that did not bounce, lie on a surface facing the other way or
    came from below do not count."""
    m, n = 4, 8
    rng = np.random.default_rng(1)
    cnt = 40
    pos = np.column_stack([rng.uniform(-0.01, 0.01, (cnt, 2)), np.zeros(cnt)])
    towards = np.array([_towards(1, 2, m, n)] * 10 + [_towards(3, 5, m, n)] * 10
                       + [_towards(0, 0, m, n)] * 20)
    power = np.array([[1.0, 1.0, 1.0]] * 10 + [[3.0, 3.0, 3.0]] * 10 + [[50.0] * 3] * 20)
    normals = np.tile(UP, (cnt, 1))
    bounces = np.ones(cnt)
    bounces[20:25] = 0                                         # direct: ignored
    normals[25:30] = -UP                                       # other side: ignored
    towards[30:35] *= [1, 1, -1]                               # from below: ignored
    bounces[35:40] = 0
    pmap = _pmap(pos, power, -towards, normals, bounces)
    alloc = photon_guided_allocation(np.zeros((3, 3)), np.tile(UP, (3, 1)), pmap, m, n, 8.0,
                                     k=cnt, rng=np.random.default_rng(2))
    assert alloc.shape == (3, m * n) and alloc.dtype == np.int64
    expect = np.ones(m * n, np.int64)
    expect[1 * n + 2] += 2
    expect[3 * n + 5] += 6
    for row in alloc:
        np.testing.assert_array_equal(row, expect)
    # Nothing to steer by: one ray per stratum.
    ones = np.ones((3, m * n), np.int64)
    np.testing.assert_array_equal(photon_guided_allocation(np.zeros((3, 3)), np.tile(UP, (3, 1)),
                                                           None, m, n, 8.0), ones)
    np.testing.assert_array_equal(photon_guided_allocation(np.zeros((3, 3)), np.tile(UP, (3, 1)),
                                                           pmap, m, n, 0.0), ones)
    assert photon_guided_allocation(np.zeros((0, 3)), np.zeros((0, 3)), pmap, m, n, 8.0).shape == (0, m * n)


def test_guided_allocation_rounds_at_random_without_bias():
    """Shares of 1/3 and 2/3 of one extra ray: floor(share + u) is 1 with probability share;
    over 3000 points the counts are binomial (5 SD)."""
    m, n = 2, 4
    towards = np.array([_towards(0, 1, m, n)] * 5 + [_towards(1, 3, m, n)] * 5)
    power = np.array([[1.0] * 3] * 5 + [[2.0] * 3] * 5)
    pmap = _pmap(np.zeros((10, 3)), power, -towards, np.tile(UP, (10, 1)), np.ones(10))
    p = 3000
    alloc = photon_guided_allocation(np.zeros((p, 3)), np.tile(UP, (p, 1)), pmap, m, n, 1.0, k=10,
                                     rng=np.random.default_rng(3))
    extra = alloc - 1
    assert extra.min() == 0 and extra.max() == 1
    assert np.count_nonzero(extra[:, [0, 2, 3, 4, 5, 6]]) == 0
    for cell, share in ((1, 1 / 3), (7, 2 / 3)):
        assert abs(extra[:, cell].sum() - share * p) < 5 * np.sqrt(p * share * (1 - share))


# -- The final gather ---------------------------------------------------------------------------

class _Stub:
    """Stands in for RadianceEstimates: the irradiance at a hit is a function of the hit."""

    def __init__(self, fn):
        self.fn = fn
        self.calls = []

    def lookup(self, x, n):
        self.calls.append((x.copy(), n.copy()))
        return self.fn(x, n)


def _room(ceiling=Material("ceiling", diffuse=[0.6, 0.4, 0.2]), extra=()):
    tris = [quad([0, 0, 0], [60.0, 0, 0], [0, 60.0, 0]), quad([0, 0, 1.0], [60.0, 0, 0], [0, 60.0, 0]),
            *extra]
    mats = [Material("floor", diffuse=0.5), ceiling] + ([Material("black", diffuse=0.0)] if extra else [])
    mids = [0, 0, 1, 1] + [2] * sum(len(t) for t in extra)
    scene = Scene(triangles=np.concatenate(tris).astype(np.float32), material_ids=np.array(mids, np.int32),
                  materials=mats, camera=Camera.look_at([0, -1, 0.5], [0, 0, 0])).validate()
    return scene, Accelerator(scene.triangles, threads=1), SceneSurfaces(scene)


def _constant(e):
    return _Stub(lambda x, n: np.tile(np.asarray(e, np.float32), (len(x), 1)))


def test_gather_under_a_lit_ceiling_is_rho_times_its_irradiance():
    """Every ray hits the ceiling, whose estimate is E_c = (2, 3, 4): L = rho_c / pi E_c in
    every stratum and E = pi / (M N) sum L = rho_c E_c, to rounding. The estimates are asked
    at the hit points with the ceiling's normal turned towards the ray (-z)."""
    scene, accel, arrays = _room()
    stub = _constant([2.0, 3.0, 4.0])
    pts = np.array([[0.0, 0, 0], [1.0, 2.0, 0]])
    st = {}
    e, L, r = final_gather(pts, np.tile(UP, (2, 1)), np.tile(UP, (2, 1)), stub, accel, arrays,
                           np.random.default_rng(4), m=4, n=8, stats=st)
    rho = np.array([0.6, 0.4, 0.2])
    np.testing.assert_allclose(e, np.tile(rho * [2.0, 3.0, 4.0], (2, 1)), rtol=1e-6)
    np.testing.assert_allclose(L, np.broadcast_to(rho / np.pi * [2.0, 3.0, 4.0], (2, 4, 8, 3)), rtol=1e-6)
    assert L.shape == (2, 4, 8, 3) and r.shape == (2, 4, 8)
    x, n = stub.calls[0]
    np.testing.assert_allclose(x[:, 2], 1.0, atol=1e-5)
    np.testing.assert_array_equal(n, np.tile([0.0, 0.0, -1.0], (len(n), 1)))
    assert st["gather_rays"] == 64 and st["gather_points"] == 2 and st["gather_seconds"] >= 0
    final_gather(pts, np.tile(UP, (2, 1)), np.tile(UP, (2, 1)), stub, accel, arrays,
                 np.random.default_rng(4), m=4, n=8, stats=st)
    assert st["gather_rays"] == 128 and st["gather_points"] == 4


def test_each_stratum_s_ray_lies_in_its_cell():
    """Stratum (j, k)'s first ray: its hit distance under a ceiling 1 m up gives
    sin^2(theta) = 1 - 1/r^2 in [j/M, (j+1)/M]; the estimate returns the hit's azimuth,
    which lies in [2 pi k / N, 2 pi (k+1) / N] in the point's frame."""
    m, n = 5, 7
    scene, accel, arrays = _room()
    t, b = sampling.orthonormal_basis(UP[None])

    def azimuth(x, nrm):
        phi = np.mod(np.arctan2(x @ b[0], x @ t[0]), 2 * np.pi)
        return np.column_stack([phi, np.zeros(len(x)), np.zeros(len(x))]).astype(np.float32)

    _e, L, r = final_gather(np.zeros((1, 3)), UP[None], UP[None], _Stub(azimuth), accel, arrays,
                            np.random.default_rng(5), m=m, n=n)
    sin2 = 1 - 1 / r[0] ** 2
    j = np.arange(m)[:, None]
    assert np.all(sin2 >= j / m - 1e-5) and np.all(sin2 <= (j + 1) / m + 1e-5)
    phi = L[0, :, :, 0] * np.pi / 0.6                      # L = rho / pi x azimuth
    k = np.arange(n)[None, :]
    assert np.all(phi >= 2 * np.pi * k / n - 1e-4) and np.all(phi <= 2 * np.pi * (k + 1) / n + 1e-4)


def test_gather_misses_emitters_and_mirrors():
    """Nothing above: every ray misses (E = 0, r = inf). A black emitting ceiling: nothing
    (its light is direct light). A mirror ceiling (rho_s = 0.5) sends the rays back to the
    floor (rho 0.5, E_f = (2, 3, 4)): E = 0.5 x 0.5 x E_f with one mirror bounce allowed, 0
    with none; the distances are those to the mirror."""
    _scene, accel, arrays = _room()
    sky = Scene(triangles=quad([0, 0, 0], [60.0, 0, 0], [0, 60.0, 0]), material_ids=np.zeros(2, np.int32),
                materials=[Material("floor", diffuse=0.5)], camera=Camera.look_at([0, -1, 0.5], [0, 0, 0]))
    e, L, r = final_gather(np.zeros((1, 3)), UP[None], UP[None], _constant([1.0] * 3),
                           Accelerator(sky.triangles, threads=1), SceneSurfaces(sky),
                           np.random.default_rng(6), m=2, n=4)
    assert np.all(e == 0) and np.all(np.isinf(r))
    _s, accel, arrays = _room(Material("lamp", diffuse=0.0, exitance=5.0))
    e, _, r = final_gather(np.zeros((1, 3)), UP[None], UP[None], _constant([1.0] * 3), accel, arrays,
                           np.random.default_rng(6), m=2, n=4)
    assert np.all(e == 0) and np.all(r >= 1.0 - 1e-5) and np.all(np.isfinite(r))
    _s, accel, arrays = _room(Material("mirror", diffuse=0.0, specular=0.5))
    stub = _constant([2.0, 3.0, 4.0])
    st = {}
    e, _, r = final_gather(np.zeros((1, 3)), UP[None], UP[None], stub, accel, arrays,
                           np.random.default_rng(6), m=2, n=4, stats=st)
    np.testing.assert_allclose(e[0], 0.25 * np.array([2.0, 3.0, 4.0]), rtol=1e-6)
    assert st["gather_rays"] == 16                         # 8 to the mirror, 8 back down
    np.testing.assert_allclose(np.abs(stub.calls[0][0][:, 2]), 0.0, atol=1e-5)
    np.testing.assert_array_equal(stub.calls[0][1], np.tile(UP, (8, 1)))
    e0, _, r0 = final_gather(np.zeros((1, 3)), UP[None], UP[None], stub, accel, arrays,
                             np.random.default_rng(6), m=2, n=4, max_specular=0)
    assert np.all(e0 == 0)
    np.testing.assert_array_equal(r0, r)                  # the distance to the mirror either way
    assert np.all(r >= 1.0 - 1e-5) and np.all(np.isfinite(r))


def test_mirror_bounces_are_capped_and_multiply():
    """Two parallel mirrors (rho_s 0.5 and 0.8 above): a ray alternates between them and is
    dropped after max_specular bounces: no diffuse surface is ever reached, E = 0; the rays
    traced are (max_specular + 1) per ray."""
    scene = Scene(triangles=np.concatenate([quad([0, 0, 0], [60.0, 0, 0], [0, 60.0, 0]),
                                            quad([0, 0, 1.0], [60.0, 0, 0], [0, 60.0, 0])]),
                  material_ids=np.array([0, 0, 1, 1], np.int32),
                  materials=[Material("low", diffuse=0.0, specular=0.5),
                             Material("high", diffuse=0.0, specular=0.8)],
                  camera=Camera.look_at([0, -1, 0.5], [0, 0, 0])).validate()
    st = {}
    e, _, _ = final_gather(np.array([[0.0, 0, 0.5]]), UP[None], UP[None], _constant([1.0] * 3),
                           Accelerator(scene.triangles, threads=1), SceneSurfaces(scene),
                           np.random.default_rng(7), m=2, n=2, max_specular=3, stats=st)
    assert np.all(e == 0) and st["gather_rays"] == 4 * 4
    # A diffuse floor under the upper mirror, reached after one bounce off it with weight 0.8.
    scene, accel, arrays = _room(Material("mirror", diffuse=0.0, specular=0.8))
    e, _, _ = final_gather(np.array([[0.0, 0, 0.5]]), UP[None], UP[None], _constant([1.0] * 3),
                           accel, arrays, np.random.default_rng(7), m=2, n=2, max_specular=3)
    np.testing.assert_allclose(e[0], [0.4, 0.4, 0.4], rtol=1e-6)


def test_gather_in_chunks_is_the_gather_at_once(monkeypatch):
    """With fewer rays per call than the points need, the points go in chunks; the random
    numbers are drawn in the same order, so the result is the same, bit for bit."""
    scene, accel, arrays = _room()
    t, b = sampling.orthonormal_basis(UP[None])
    stub = _Stub(lambda x, n: np.column_stack([x[:, 0] ** 2, x[:, 1] ** 2, np.ones(len(x))]).astype(np.float32))
    pts = np.column_stack([np.linspace(-3, 3, 9), np.linspace(1, 2, 9), np.zeros(9)])
    nn = np.tile(UP, (9, 1))
    whole = final_gather(pts, nn, nn, stub, accel, arrays, np.random.default_rng(8), m=3, n=5)
    monkeypatch.setattr(G, "GATHER_RAYS_PER_CALL", 40)          # 2 points (30 rays) a chunk
    parts = final_gather(pts, nn, nn, stub, accel, arrays, np.random.default_rng(8), m=3, n=5)
    for a, b_ in zip(whole, parts):
        np.testing.assert_array_equal(a, b_)
    assert whole[0].shape == (9, 3) and whole[1].shape == (9, 3, 5, 3) and whole[2].shape == (9, 3, 5)
    assert len({tuple(row) for row in whole[0]}) == 9           # the points differ


def test_guided_gather_takes_the_mean_of_each_stratum():
    """With a guide, strata get several rays; each stratum's radiance is the mean of its rays
    (a constant ceiling: the same L), and r is the first ray's distance."""
    scene, accel, arrays = _room()
    m, n = 2, 4
    towards = np.array([_towards(1, 3, m, n)] * 5)
    guide = _pmap(np.zeros((5, 3)), np.ones((5, 3)), -towards, np.tile(UP, (5, 1)), np.ones(5))
    st = {}
    e, L, r = final_gather(np.zeros((1, 3)), UP[None], UP[None], _constant([2.0, 3.0, 4.0]), accel,
                           arrays, np.random.default_rng(9), m=m, n=n, guide=guide, guide_extra=2.0,
                           stats=st)
    rho = np.array([0.6, 0.4, 0.2])
    np.testing.assert_allclose(L[0], np.broadcast_to(rho / np.pi * [2.0, 3.0, 4.0], (m, n, 3)), rtol=1e-6)
    np.testing.assert_allclose(e[0], rho * [2.0, 3.0, 4.0], rtol=1e-6)
    assert st["gather_rays"] == m * n + 2 * m * n              # 16 extra rays, all in (1, 3)
    sin2 = 1 - 1 / r[0] ** 2
    assert np.all(sin2 >= np.arange(m)[:, None] / m - 1e-5)
    assert np.all(sin2 <= (np.arange(m)[:, None] + 1) / m + 1e-5)
