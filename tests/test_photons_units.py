"""engine/photons.py piece by piece, on hand-made inputs (no bpy; milliseconds each).

Added for issue 19 item 4 (mutation testing): each test pins a piece of the photon map that
the end-to-end tests in test_photons.py average away, against an exact answer wherever the
code is exact:
* the Morton order against an independent bit-by-bit interleave; the bounds, the defaults;
* one bounce of tracing (Russian roulette, 9.2) where every stored photon, the absorbed and escaped flux and the ray count follow exactly from the
  number of survivors;
* the radiance estimate (Eq. 9.11 with the disc, side and k-th-photon rules) on a few
  photons placed by hand, and on random photons against a brute-force estimate;
* emission per light type: where photons start, where they go, what they carry.
Statistical checks state their bound: a binomial count is held to 5 standard deviations of
the binomial (P(|z| > 5) = 6e-7), a mean of N cosines to 5 standard errors of that mean.
"""
import numpy as np
import pytest

from analytic import quad
from lanterna.engine import photons as P
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator, offset_distance
from lanterna.engine.lights import LUMINANCE, spot_mask
from lanterna.engine.photons import (EmittedPhotons, PhotonMap, auto_max_radius, auto_photon_count,
                                     build_photon_map, column_bounds, emit_photons,
                                     morton_order, trace_photons)
from lanterna.engine.scene import (AreaLight, Camera, Material, PointLight, Scene, SpotLight,
                                   SunLight, World)


def _scene(tris, materials, mids=None, lights=(), world=None, eye=(0.0, -3.0, 1.0)):
    tris = np.asarray(tris, np.float32)
    mids = np.zeros(len(tris), np.int32) if mids is None else np.asarray(mids, np.int32)
    return Scene(triangles=tris, material_ids=mids, materials=list(materials),
                 camera=Camera.look_at(eye, [0, 0, 0]), lights=list(lights),
                 world=world or World()).validate()


# -- Morton order, bounds, defaults -----------------------------------------------------------

def _reference_morton(points, lo, hi):
    """Independent Z-order code: 10-bit cells, bit b of x, y, z at 3b, 3b + 1, 3b + 2."""
    p = np.asarray(points, np.float64)
    cells = np.clip(np.floor((p - lo) * (1023.0 / (hi - lo))), 0, 1023).astype(np.int64)
    code = np.zeros(len(p), np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


def test_spread_bits_interleaves_every_third_bit():
    v = np.array([0, 1, 2, 3, 5, 512, 1023], np.uint32)
    expected = [0, 1, 8, 9, 65, 1 << 27, 0x09249249]
    assert P._spread_bits(v).tolist() == expected


def test_morton_order_sorts_by_the_z_order_code():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-2.0, 3.0, (500, 3)).astype(np.float32)
    lo, hi = pts.min(axis=0).astype(np.float64), pts.max(axis=0).astype(np.float64)
    order = morton_order(pts)
    code = _reference_morton(pts, lo, hi)
    assert sorted(order.tolist()) == list(range(500))
    assert np.all(np.diff(code[order]) >= 0)
    # The corners of a box: z, then y, then x is the most significant bit.
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], np.float32)
    shuffled = corners[[5, 2, 7, 0, 3, 6, 1, 4]]
    assert np.array_equal(shuffled[morton_order(shuffled)], corners)
    # Given bounds: points outside are clipped into the end cells.
    pts2 = np.array([[5.0, 0, 0], [-5.0, 0, 0], [0.5, 0.5, 0.5]], np.float32)
    order2 = morton_order(pts2, np.zeros(3), np.ones(3))
    assert order2.tolist() == [1, 2, 0]
    assert morton_order(np.zeros((0, 3))).dtype == np.int64 and len(morton_order(np.zeros((0, 3)))) == 0
    flat = np.array([[0.2, 1.0, 3.0], [0.1, 1.0, 3.0]], np.float32)    # zero extent in y, z
    assert morton_order(flat).tolist() == [1, 0]
    # A box a few millimetres wide gets all 1024 cells per axis, as a large one does.
    small = rng.uniform(0.0, 3e-3, (500, 3)).astype(np.float32) + np.float32(0.2)
    order = morton_order(small)
    code = _reference_morton(small, small.min(axis=0).astype(float), small.max(axis=0).astype(float))
    assert np.all(np.diff(code[order]) >= 0)
    # Just past the bounds (cell 1025): clipped to the last cell, not wrapped to cell 1.
    past = np.array([[1.002, 0.0, 0.0], [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]], np.float32)
    assert morton_order(past, np.zeros(3), np.ones(3)).tolist() == [2, 1, 0]
    # The first cell is cell 0: (1.5 / 1023, 0, 0) lies in cell 1, after the origin.
    pair = np.array([[1.5 / 1023, 0.0, 0.0], [0.0, 0.0, 0.0]], np.float32)
    assert morton_order(pair, np.zeros(3), np.ones(3)).tolist() == [1, 0]


def test_column_bounds():
    pts = np.array([[1.0, -2.0, 3.0], [-1.0, 5.0, 0.5], [0.0, 0.0, 4.0]], np.float32)
    lo, hi = column_bounds(pts)
    assert lo.dtype == np.float32 and hi.dtype == np.float32
    assert lo.tolist() == [-1.0, -2.0, 0.5] and hi.tolist() == [1.0, 5.0, 4.0]


def test_auto_photon_count_is_two_per_pixel_between_200k_and_2m():
    assert auto_photon_count(300_000) == 600_000
    assert auto_photon_count(50_000) == 200_000
    assert auto_photon_count(100_000) == 200_000
    assert auto_photon_count(5_000_000) == 2_000_000
    assert isinstance(auto_photon_count(300_000), int)


def test_auto_max_radius_from_the_diffuse_area():
    """4 sqrt(k A / (pi N)) over the triangles with a diffuse reflectance (a black emitter's
    area does not count); 5 % of the extent without triangles, photons or diffuse area."""
    floor = quad([0, 0, 0], [1.0, 0, 0], [0, 1.0, 0])                 # 4 m^2, white
    lamp = quad([0, 0, 2.0], [0.5, 0, 0], [0, 0.5, 0])                # 1 m^2, black emitter
    mats = [Material("white", diffuse=0.5), Material("lamp", diffuse=0.0, exitance=1.0)]
    scene = _scene(np.concatenate([floor, lamp]), mats, [0, 0, 1, 1])
    assert auto_max_radius(scene, 1000, 50) == pytest.approx(4 * np.sqrt(50 * 4 / (np.pi * 1000)),
                                                             rel=1e-12)
    fallback = 0.05 * scene.extent
    assert auto_max_radius(scene, 0, 50) == pytest.approx(fallback, rel=1e-12)
    black = _scene(lamp, [Material("lamp", diffuse=0.0, exitance=1.0)])
    assert auto_max_radius(black, 1000, 50) == pytest.approx(0.05 * black.extent, rel=1e-12)
    small_black = _scene(lamp * np.float32(0.1), [Material("lamp", diffuse=0.0, exitance=1.0)],
                         eye=(0.0, -0.1, 0.3))
    assert small_black.extent < 1
    assert auto_max_radius(small_black, 1000, 50) == pytest.approx(0.05 * small_black.extent, rel=1e-12)
    tri = _scene(floor[:1] * np.float32(0.5), [Material("white")])      # one triangle, 0.5 m^2
    assert auto_max_radius(tri, 1000, 50) == pytest.approx(4 * np.sqrt(50 * 0.5 / (np.pi * 1000)), rel=1e-6)
    empty = Scene(triangles=np.zeros((0, 3, 3), np.float32), material_ids=np.zeros(0, np.int32),
                  materials=[Material("m")], camera=Camera.look_at([0, -3, 1], [0, 0, 0]))
    assert auto_max_radius(empty, 1000, 50) == pytest.approx(0.05 * max(empty.extent, 1e-9))


# -- Russian roulette and one bounce of tracing -------------------------------------------------

def _down_photons(count, power, x0=0.0, height=0.5, direction=(0.0, 0.0, -1.0)):
    rng = np.random.default_rng(1)
    o = np.column_stack([rng.uniform(-0.5, 0.5, count) + x0, rng.uniform(-0.5, 0.5, count),
                         np.full(count, height)])
    d = np.tile(np.asarray(direction, float) / np.linalg.norm(direction), (count, 1))
    return EmittedPhotons(o, d, np.tile(np.asarray(power, float), (count, 1)))


def test_one_bounce_on_an_open_floor_is_exact():
    """Photons straight down onto a floor of rho = (0.5, 0.25, 0.1), nothing above: each is
    stored once where it lands (power as emitted, no bounce, arriving downwards, the normal
    towards it); a share P_d = 0.5 survives with power x rho / P_d and escapes. Exactly:
    absorbed = emitted x (1 - rho), escaped = survivors x power x rho / P_d, rays = N +
    survivors."""
    n, power = 2000, np.array([0.3, 0.2, 0.1])
    rho = np.array([0.5, 0.25, 0.1])
    scene = _scene(quad([0, 0, 0], [2.0, 0, 0], [0, 2.0, 0]), [Material("floor", diffuse=rho)])
    accel = Accelerator(scene.triangles, threads=1)
    emitted = _down_photons(n, power)
    pmap = trace_photons(scene, accel, emitted, np.random.default_rng(2))
    assert len(pmap) == n
    np.testing.assert_allclose(pmap.positions[:, :2], emitted.origins[:, :2], atol=1e-6)
    assert np.abs(pmap.positions[:, 2]).max() < 1e-6
    assert np.all(pmap.power == power.astype(np.float32)) and np.all(pmap.bounces == 0)
    assert np.all(pmap.incoming == np.float16([0, 0, -1])) and np.all(pmap.normals == np.float16([0, 0, 1]))
    st = pmap.stats
    survivors = st["rays"] - n
    assert abs(survivors - 0.5 * n) < 5 * np.sqrt(n * 0.25)
    np.testing.assert_allclose(st["flux_emitted"], n * power, rtol=1e-12)
    # (rtol 1e-6: the material table is float32)
    np.testing.assert_allclose(st["flux_absorbed"], n * power * (1 - rho), rtol=1e-6)
    np.testing.assert_allclose(st["flux_escaped"], survivors * power * rho / 0.5, rtol=1e-6)
    np.testing.assert_allclose(st["flux_stored_first_hit"], n * power, rtol=1e-6)
    assert st["capped_paths"] == 0 and st["flux_capped"] == [0.0, 0.0, 0.0]
    assert st["emitted"] == n and st["stored"] == n and st["bytes"] == pmap.nbytes == 37 * n
    # Every photon leaves the floor upwards, from above it: none is stored twice.
    log = []
    trace_photons(scene, accel, emitted, np.random.default_rng(2), ray_log=log)
    assert [entry[0] for entry in log] == ["photon", "photon"] and len(log[1][1]) == survivors
    assert np.all(log[1][1][:, 2] > 0) and np.all(log[1][2][:, 2] > 0)


def test_mirror_floor_reflects_onto_a_ceiling():
    """A mirror floor (rho_s = 1: every photon survives, power x 1) under a diffuse ceiling:
    photons travelling along (0.6, 0, -0.8) are not stored on the mirror; they reach the
    ceiling along (0.6, 0, 0.8), 1.125 m farther in x, stored with one bounce and the ceiling's
    normal turned towards them (-z)."""
    n = 500
    mirror = quad([0, 0, 0], [3.0, 0, 0], [0, 3.0, 0])
    ceiling = quad([0, 0, 1.0], [3.0, 0, 0], [0, 3.0, 0])
    mats = [Material("mirror", diffuse=0.0, specular=1.0), Material("ceiling", diffuse=0.4)]
    scene = _scene(np.concatenate([mirror, ceiling]), mats, [0, 0, 1, 1])
    accel = Accelerator(scene.triangles, threads=1)
    emitted = _down_photons(n, [1.0, 2.0, 3.0], direction=(0.6, 0.0, -0.8))
    pmap = trace_photons(scene, accel, emitted, np.random.default_rng(3))
    first = pmap.bounces == 1
    assert first.sum() == n
    at = pmap.positions[first]
    np.testing.assert_allclose(at[:, 0], emitted.origins[:, 0] + 1.125, atol=1e-4)
    np.testing.assert_allclose(at[:, 2], 1.0, atol=1e-5)
    np.testing.assert_allclose(pmap.incoming[first].astype(float), np.tile([0.6, 0, 0.8], (n, 1)), atol=1e-3)
    assert np.all(pmap.normals[first] == np.float16([0, 0, -1]))
    np.testing.assert_allclose(pmap.power[first], np.tile([1.0, 2.0, 3.0], (n, 1)))
    assert pmap.stats["flux_stored_first_hit"] == [0.0, 0.0, 0.0]
    # The mirror absorbs nothing; the ceiling absorbs 0.6 of every photon reaching it.
    absorbed = np.array(pmap.stats["flux_absorbed"])
    assert absorbed[0] >= 0.6 * n * 1.0 - 1e-9


def test_a_surface_both_diffuse_and_specular_splits_the_survivors():
    """Floor rho_d = (0.3, 0.15, 0.06), rho_s = (0.1, 0.5, 0.25): P_d = 0.3, P_s = 0.5. The
    photons reaching a diffuse ceiling (rho 0.5) after one bounce carry power x rho_d / P_d =
    (1, 0.5, 0.2) when they bounced diffusely and x rho_s / P_s = (0.2, 1, 0.5) when they came
    along the mirror direction; their numbers are binomial (5 SD)."""
    n = 4000
    floor = quad([0, 0, 0], [50.0, 0, 0], [0, 50.0, 0])
    ceiling = quad([0, 0, 1.0], [50.0, 0, 0], [0, 50.0, 0])
    mats = [Material("mixed", diffuse=[0.3, 0.15, 0.06], specular=[0.1, 0.5, 0.25]),
            Material("ceiling", diffuse=0.5)]
    scene = _scene(np.concatenate([floor, ceiling]), mats, [0, 0, 1, 1])
    accel = Accelerator(scene.triangles, threads=1)
    emitted = _down_photons(n, [1.0, 1.0, 1.0], direction=(0.6, 0.0, -0.8))
    pmap = trace_photons(scene, accel, emitted, np.random.default_rng(4))
    up = (pmap.bounces == 1) & (pmap.positions[:, 2] > 0.5)
    inc = pmap.incoming[up].astype(float)
    mirror = np.all(np.abs(inc - [0.6, 0, 0.8]) < 2e-3, axis=1)
    assert np.allclose(pmap.power[up][mirror], [0.2, 1.0, 0.5], rtol=1e-6)
    assert np.allclose(pmap.power[up][~mirror], [1.0, 0.5, 0.2], rtol=1e-6)
    for count, p in ((mirror.sum(), 0.5), ((~mirror).sum(), 0.3)):
        assert abs(count - p * n) < 5 * np.sqrt(n * p * (1 - p))


def test_paths_between_two_mirrors_are_capped():
    """A photon bouncing between two parallel mirrors never dies: it is cut after
    ``max_bounces`` bounces, counted in capped_paths and flux_capped; nothing is stored; one
    ray per segment (max_bounces + 1 segments)."""
    n = 50
    tris = np.concatenate([quad([0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]),
                           quad([0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0])])
    scene = _scene(tris, [Material("mirror", diffuse=0.0, specular=1.0)])
    accel = Accelerator(scene.triangles, threads=1)
    emitted = _down_photons(n, [1.0, 0.5, 0.25])
    pmap = trace_photons(scene, accel, emitted, np.random.default_rng(5), max_bounces=5)
    st = pmap.stats
    assert len(pmap) == 0
    for key, dtype, shape in (("positions", np.float32, (0, 3)), ("power", np.float32, (0, 3)),
                              ("incoming", np.float16, (0, 3)), ("normals", np.float16, (0, 3)),
                              ("bounces", np.uint8, (0,))):
        assert getattr(pmap, key).dtype == dtype and getattr(pmap, key).shape == shape, key
    assert st["capped_paths"] == n and st["rays"] == 6 * n
    assert st["photons_per_light"] == {} and st["stored"] == 0
    np.testing.assert_allclose(st["flux_capped"], [n * 1.0, n * 0.5, n * 0.25])
    assert st["flux_absorbed"] == [0.0, 0.0, 0.0] and st["flux_escaped"] == [0.0, 0.0, 0.0]
    assert st["flux_stored_first_hit"] == [0.0, 0.0, 0.0]
    # The default cap is 128 bounces: 129 segments.
    default = trace_photons(scene, accel, _down_photons(5, [1.0, 1.0, 1.0]), np.random.default_rng(5))
    assert default.stats["rays"] == 129 * 5 and default.stats["capped_paths"] == 5


def test_bounce_counter_is_stored_and_saturates():
    """Between a white floor and a white ceiling photons bounce many times; stored bounce
    numbers run 0, 1, 2, ... with no gaps and never exceed the cap."""
    tris = np.concatenate([quad([0, 0, 0], [100.0, 0, 0], [0, 100.0, 0]),
                           quad([0, 0, 1.0], [100.0, 0, 0], [0, 100.0, 0])])
    scene = _scene(tris, [Material("white", diffuse=0.9)])
    accel = Accelerator(scene.triangles, threads=1)
    pmap = trace_photons(scene, accel, _down_photons(400, [1.0, 1.0, 1.0]),
                         np.random.default_rng(6), max_bounces=3)
    assert set(np.unique(pmap.bounces).tolist()) == {0, 1, 2, 3}
    assert pmap.stats["capped_paths"] > 0
    # White (rho = 1) plates 1 m apart, 100 m wide: photons bounce hundreds of times; the
    # stored count saturates at 255 instead of wrapping to 0.
    white = _scene(tris, [Material("white", diffuse=1.0)])
    pmap = trace_photons(white, Accelerator(white.triangles, threads=1), _down_photons(10, [1.0] * 3),
                         np.random.default_rng(7), max_bounces=300)
    assert np.count_nonzero(pmap.bounces == 0) == 10 and pmap.bounces.max() == 255
    assert np.count_nonzero(pmap.bounces == 255) > 10


def test_mixed_batches_store_only_at_diffuse_hits_and_count_every_escape():
    """Photons traced together, each to its own fate: one up into the sky (escapes at
    once), one onto a black plate (absorbed), one onto a mirror that sends it to a diffuse
    ceiling, one onto a diffuse patch; a fifth onto a second mirror that sends it back up into
    the sky. Stored: the patch's photon (no bounce) and the ceiling's (one bounce) only; the
    escaped flux adds up over both bounces; the near-black diffuse surfaces absorb the rest."""
    mats = [Material("black", diffuse=0.0), Material("mirror", diffuse=0.0, specular=1.0),
            Material("patch", diffuse=1e-9), Material("ceiling", diffuse=1e-9)]
    tris = [quad([-3.0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]), quad([0.0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]),
            quad([3.0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]), quad([1.1, 0, 1.0], [0.3, 0, 0], [0, 0.3, 0]),
            quad([-6.0, 0, 0], [0.5, 0, 0], [0, 0.5, 0])]
    scene = _scene(np.concatenate(tris), mats, [0, 0, 1, 1, 2, 2, 3, 3, 1, 1])
    accel = Accelerator(scene.triangles, threads=1)
    o = np.array([[0.0, 0.0, 0.5], [-3.0, 0.0, 0.5], [0.0, 0.0, 0.5], [3.0, 0.0, 0.5], [-6.0, 0.0, 0.5]])
    d = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, 0.0, -0.8], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    power = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5]])
    for count in (4, 5):       # the first four alone: a single photon is left after one bounce
        pmap = trace_photons(scene, accel, EmittedPhotons(o[:count], d[:count], power[:count]),
                             np.random.default_rng(8))
        st = pmap.stats
        assert len(pmap) == 2, count
        on_patch = pmap.positions[:, 0] > 2
        np.testing.assert_allclose(pmap.positions[on_patch], [[3.0, 0.0, 0.0]], atol=1e-5)
        np.testing.assert_allclose(pmap.positions[~on_patch], [[1.125, 0.0, 1.0]], atol=1e-4)
        assert pmap.bounces[on_patch].tolist() == [0] and pmap.bounces[~on_patch].tolist() == [1]
        np.testing.assert_allclose(st["flux_escaped"], [1.0, 0.0, 0.0] if count == 4 else [1.5, 0.5, 0.5])
        np.testing.assert_allclose(st["flux_absorbed"], [1.0, 2.0, 2.0], rtol=1e-6)
        assert st["rays"] == (5 if count == 4 else 7)
        assert st["flux_stored_first_hit"] == [1.0, 1.0, 1.0]


# -- The estimate on hand-made photons ----------------------------------------------------------

def _map(positions, power, incoming=None, normals=None, bounces=None, library="pykdtree"):
    k = len(positions)
    incoming = np.tile([0.0, 0.0, -1.0], (k, 1)) if incoming is None else incoming
    normals = np.tile([0.0, 0.0, 1.0], (k, 1)) if normals is None else normals
    bounces = np.zeros(k) if bounces is None else bounces
    return PhotonMap(np.asarray(positions, np.float32), np.asarray(power, np.float32),
                     np.asarray(incoming, np.float16), np.asarray(normals, np.float16),
                     np.asarray(bounces, np.uint8)).build(library)


def _ring(radii, z=None):
    ang = np.linspace(0, 2 * np.pi, len(radii), endpoint=False) + 0.3
    z = np.zeros(len(radii)) if z is None else z
    return np.column_stack([np.cos(ang) * radii, np.sin(ang) * radii, z])


@pytest.mark.parametrize("library", ["pykdtree", "scipy"])
def test_estimate_counts_k_minus_one_photons_over_the_kth_radius(library):
    """Photons 0.1, 0.2, 0.3, 0.4 m from the point, powers 1..4 (x (1, 2, 3) in RGB): with
    k = 4 the 4th marks r = 0.4 and is not counted, E = (1 + 2 + 3) / (pi 0.4^2); with
    max_radius 0.35 only three are found, all count, over the cap: E = 6 / (pi 0.35^2)."""
    pos = _ring([0.1, 0.2, 0.3, 0.4])
    power = np.outer([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0])
    pmap = _map(pos, power, library=library)
    q, up = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(pmap.irradiance(q, up, k=4)[0], 6 * np.array([1, 2, 3]) / (np.pi * 0.16), rtol=1e-5)
    np.testing.assert_allclose(pmap.irradiance(q, up, k=4, max_radius=0.35)[0],
                               6 * np.array([1, 2, 3]) / (np.pi * 0.35 ** 2), rtol=1e-5)
    np.testing.assert_allclose(pmap.irradiance(q, up, k=3)[0], 3 * np.array([1, 2, 3]) / (np.pi * 0.09), rtol=1e-5)
    # k beyond the map is clipped to it; query's missing neighbours have distance inf and
    # index len(map).
    dist, idx = pmap.query(q, 10, max_radius=0.25)
    assert dist.shape == (1, 4) and idx[0, 2:].tolist() == [4, 4]
    np.testing.assert_allclose(dist[0, :2], [0.1, 0.2], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(pmap.positions[idx[0, :2]], axis=1), [0.1, 0.2], rtol=1e-6)
    assert np.all(np.isinf(dist[0, 2:]))
    # No photon within the cap: nothing.
    assert np.all(pmap.irradiance(q + [5.0, 0, 0], up, k=4, max_radius=1.0) == 0)
    st = {"queries": 5, "query_seconds": 100.0}
    t0 = __import__("time").perf_counter()
    pmap.irradiance(np.zeros((3, 3)), np.tile(up, (3, 1)), k=4, stats=st)
    pmap.irradiance(np.zeros((2, 3)), np.tile(up, (2, 1)), k=4, stats=st)
    elapsed = __import__("time").perf_counter() - t0
    assert st["queries"] == 10 and 100.0 <= st["query_seconds"] <= 100.0 + elapsed


def test_estimate_defaults_and_degenerate_maps():
    """k defaults to 50: 60 photons at 0.01, 0.02, ... m: the 50th marks r = 0.5 and 49 count.
    Photons all at the query point: r = 0, no estimate (0, not inf). A map of one photon asked
    for two neighbours: the missing one is no photon."""
    radii = np.arange(1, 61) * 0.01
    pmap = _map(_ring(radii), np.ones((60, 3)))
    q, up = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]])
    assert pmap.irradiance(q, up)[0, 0] == pytest.approx(49 / (np.pi * 0.25), rel=1e-5)
    same = _map(np.zeros((4, 3)), np.ones((4, 3)))
    assert np.all(same.irradiance(q, up, k=4) == 0)
    single = _map(np.array([[0.1, 0.0, 0.0]]), np.ones((1, 3)))
    assert np.all(single.irradiance(q, up, k=2, max_radius=0.05) == 0)        # none within
    assert np.all(single.irradiance(q, up, k=2, max_radius=0.5) == 0)         # k -> 1: the radius


def test_estimate_filters_side_direction_disc_and_bounces():
    """Eight photons at 0.1 .. 0.8 m, the 8th marking r = 0.8: each filter drops its photon.
    #2 arrived from below (incoming (0.6, 0, 0.8)), #3 lies on a surface facing down, #4 lies
    0.25 r + 0.01 above the plane, #5 0.19 above (inside the disc); #2 and #6 bounced once.
    All of it on the plane z = 0.7."""
    radii = np.arange(1, 9) * 0.1
    z = np.zeros(8)
    z[3], z[4] = 0.25 * 0.8 + 0.01, 0.19
    pos = _ring(radii)
    pos[:, 2] = z
    # Put each photon at its own distance from the origin (the ring keeps |xy| = r).
    pos[:, :2] *= (np.sqrt(radii ** 2 - z ** 2) / radii)[:, None]
    incoming = np.tile([0.0, 0.0, -1.0], (8, 1))
    incoming[1] = [0.6, 0.0, 0.8]
    normals = np.tile([0.0, 0.0, 1.0], (8, 1))
    normals[2] = [0.0, 0.0, -1.0]
    bounces = np.zeros(8)
    bounces[[1, 5]] = 1
    power = np.outer(2.0 ** np.arange(8), [1.0, 1.0, 1.0])
    pos[:, 2] += 0.7
    pmap = _map(pos, power, incoming, normals, bounces)
    q, up = np.array([[0.0, 0.0, 0.7]]), np.array([[0.0, 0.0, 1.0]])
    area = np.pi * 0.64
    e = pmap.irradiance(q, up, k=8)[0, 0]
    assert e == pytest.approx((1 + 16 + 32 + 64) / area, rel=1e-5)
    e1 = pmap.irradiance(q, up, k=8, min_bounces=1)[0, 0]
    assert e1 == pytest.approx(32 / area, rel=1e-5)
    e_thick = pmap.irradiance(q, up, k=8, disc_thickness=0.3)[0, 0]
    assert e_thick == pytest.approx((1 + 8 + 16 + 32 + 64) / area, rel=1e-5)
    # Seen from the other side the surviving photon is the one of the surface facing down
    # but it arrived downwards, i.e. from that side's back: nothing counts.
    assert pmap.irradiance(q, -up, k=8)[0, 0] == 0.0


def test_cone_filter_weights_and_normalisation():
    """Jensen's cone filter: photon at d weighs 1 - d / (k_c r), the sum divided by
    (1 - 2 / (3 k_c)) pi r^2."""
    pos = _ring([0.1, 0.2, 0.3, 0.4])
    pmap = _map(pos, np.ones((4, 3)))
    kc, r = 1.1, 0.4
    w = sum(1 - d / (kc * r) for d in (0.1, 0.2, 0.3))
    expected = w / ((1 - 2 / (3 * kc)) * np.pi * r * r)
    e = pmap.irradiance(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), k=4, cone_filter=kc)
    assert e[0, 0] == pytest.approx(expected, rel=1e-5)


def _brute_estimate(pos, power, inc, nrm, q, qn, k, max_radius):
    out = np.zeros((len(q), 3))
    for i in range(len(q)):
        d = np.linalg.norm(pos - q[i], axis=1)
        order = np.argsort(d)[:k]
        order = order[d[order] <= max_radius]
        full = len(order) == k
        r = d[order[-1]] if full else max_radius
        use = order[:-1] if full else order
        h = np.abs((pos[use] - q[i]) @ qn[i])
        ok = (inc[use] @ qn[i] < 0) & (nrm[use] @ qn[i] > 0.5) & (h <= 0.25 * r)
        out[i] = power[use][ok].sum(axis=0) / (np.pi * r * r)
    return out


def test_estimate_matches_brute_force_over_several_chunks():
    """200 photons on a plane, half facing each way, against a brute-force Eq. 9.11 at 9000
    points (more than one chunk of 8192, asked out of order): the same to float32 rounding."""
    rng = np.random.default_rng(7)
    m = 200
    pos = np.column_stack([rng.uniform(0, 1, (m, 2)), np.zeros(m)]).astype(np.float32)
    side = np.where(rng.random(m) < 0.5, 1.0, -1.0)
    nrm = np.column_stack([np.zeros((m, 2)), side])
    inc = -nrm
    power = rng.uniform(0.1, 1.0, (m, 3)).astype(np.float32)
    pmap = _map(pos, power, inc, nrm)
    q = np.column_stack([rng.uniform(0, 1, (9000, 2)), np.zeros(9000)])
    qn = np.tile([0.0, 0.0, 1.0], (9000, 1))
    qn[::3] *= -1
    e = pmap.irradiance(q, qn, k=12, max_radius=0.2)
    ref = _brute_estimate(pos.astype(float), power.astype(float), inc, nrm, q, qn, 12, 0.2)
    np.testing.assert_allclose(e, ref, rtol=2e-5, atol=1e-9)
    assert np.count_nonzero(e[:, 0]) > 8000


def test_subset_nbytes_and_round_trip():
    pos = _ring([0.1, 0.2, 0.3, 0.4, 0.5])
    pmap = _map(pos, np.outer(np.arange(1, 6), [1, 1, 1]), bounces=[0, 1, 2, 0, 1], library="scipy")
    pmap.stats["marker"] = 7
    sub = pmap.subset(pmap.bounces > 0)
    assert len(sub) == 3 and sub._tree is None and sub.library == pmap.library
    assert sub.stats == pmap.stats and sub.stats is not pmap.stats
    assert sorted(sub.power[:, 0].tolist()) == sorted(pmap.power[pmap.bounces > 0, 0].tolist())
    assert np.array_equal(sub.positions, pmap.positions[pmap.bounces > 0])
    assert pmap.nbytes == 5 * 37
    arrays = pmap.to_arrays()
    assert bool(arrays["built"]) and str(arrays["library"]) == "scipy"
    back = PhotonMap.from_arrays(arrays)
    assert back.library == "scipy" and type(back._tree).__name__ == "cKDTree"
    for key in PhotonMap.ARRAY_FIELDS:
        assert np.array_equal(getattr(back, key), getattr(pmap, key)) and \
            getattr(back, key).dtype == getattr(pmap, key).dtype
    assert back.stats["marker"] == 7 and back._tree is not None
    unbuilt = PhotonMap.from_arrays(arrays, build=False)
    assert unbuilt._tree is None and not bool(sub.to_arrays()["built"])
    with pytest.raises(ValueError, match="kd-tree library"):
        PhotonMap(*(getattr(pmap, k) for k in PhotonMap.ARRAY_FIELDS)).build("octree")
    one = PhotonMap(*(getattr(pmap, k)[:1] for k in PhotonMap.ARRAY_FIELDS))
    assert not bool(one.to_arrays()["built"])
    assert bool(PhotonMap(*(getattr(pmap, k)[:0] for k in PhotonMap.ARRAY_FIELDS)).to_arrays()["built"])


def test_build_sorts_the_photons_along_the_morton_curve():
    """build() (and loading a map saved unbuilt) stores the photons in Morton order over their
    bounds, every column permuted alike; reorder=False keeps the order."""
    rng = np.random.default_rng(12)
    pos = rng.uniform(-1, 1, (300, 3)).astype(np.float32)
    power = np.column_stack([np.arange(300.0), np.zeros(300), np.zeros(300)])
    raw = lambda: PhotonMap(pos.copy(), power.astype(np.float32), np.tile(np.float16([0, 0, -1]), (300, 1)),  # noqa: E731
                            np.tile(np.float16([0, 0, 1]), (300, 1)), (np.arange(300) % 7).astype(np.uint8))
    code = _reference_morton(pos, pos.min(axis=0).astype(float), pos.max(axis=0).astype(float))
    t0 = __import__("time").perf_counter()
    built = raw().build()
    elapsed = __import__("time").perf_counter() - t0
    perm = built.power[:, 0].astype(int)
    assert np.all(np.diff(code[perm]) >= 0)
    assert np.array_equal(built.positions, pos[perm]) and np.array_equal(built.bounces, perm % 7)
    np.testing.assert_array_equal(built.lo, pos.min(axis=0))
    np.testing.assert_array_equal(built.hi, pos.max(axis=0))
    assert 0 <= built.stats["build_seconds"] <= elapsed and built.stats["library"] == "pykdtree"
    kept = raw().build(reorder=False)
    assert np.array_equal(kept.positions, pos)
    loaded = PhotonMap.from_arrays(raw().to_arrays())
    assert np.array_equal(loaded.power[:, 0].astype(int), perm)


# -- Emission per light type --------------------------------------------------------------------

FLOOR = quad([0, 0, 0], [2.0, 0, 0], [0, 2.0, 0])


def _plain(lights=(), world=None, extra=(), materials=None, mids=None):
    tris = np.concatenate([FLOOR, *extra]) if len(extra) else FLOOR
    return _scene(tris, materials or [Material("white")], mids, lights, world)


def _rng():
    return sampling.rng_for(3, sampling.STREAM_PHOTON)


def test_point_light_emission():
    light = PointLight("P", [0.2, -0.1, 1.0], [40.0, 20.0, 10.0])
    scene = _plain([light])
    em = emit_photons(scene, 10_000, _rng())
    n = 10_000
    assert em.per_light == {"P": n} and em.power.shape == (n, 3)
    assert np.all(em.power == np.array([40.0, 20.0, 10.0]) / n)
    off = em.origins - light.position
    np.testing.assert_allclose(np.linalg.norm(em.directions, axis=1), 1.0, rtol=1e-12)
    eps = offset_distance(light.position[None], scene.extent)[0]
    np.testing.assert_allclose(off, em.directions * eps, rtol=1e-9, atol=1e-15)
    # Uniform on the sphere: each component's mean is 0 with SD sqrt(1/3 / n).
    assert np.all(np.abs(em.directions.mean(axis=0)) < 5 * np.sqrt(1 / 3 / n))


@pytest.mark.parametrize("blend", [0.0, 0.4])
def test_spot_light_emission(blend):
    """Photons in the cone only, the power weighted by the mask and adding up to the flux in
    the cone, Phi / (4 pi) x 2 pi integral of the mask over cos(theta)."""
    half = np.radians(35.0)
    light = SpotLight("S", [0.0, 0.0, 1.5], [0.3, 0.0, -1.0], [100.0, 50.0, 25.0],
                      half_angle=half, blend=blend)
    scene = _plain([light])
    em = emit_photons(scene, 20_000, _rng())
    cos = em.directions @ light.direction
    assert np.all(cos >= np.cos(half) - 1e-9)
    # Closed form: the smoothstep over the outer blend share integrates to half of it. The
    # engine integrates the mask by the trapezoid rule on 2048 intervals, which cuts half an
    # interval off a sharp edge: 1/4096 = 2.4e-4 relative, hence rtol 3e-4.
    cone = light.flux / 2 * (1 - np.cos(half)) * (1 - blend / 2)
    np.testing.assert_allclose(em.power.sum(axis=0), cone, rtol=3e-4)
    ratio = em.power[:, 0] / spot_mask(cos, np.cos(half), blend)
    ok = spot_mask(cos, np.cos(half), blend) > 1e-3
    np.testing.assert_allclose(ratio[ok], ratio[ok][0], rtol=1e-9)
    off = em.origins - light.position
    eps = offset_distance(light.position[None], scene.extent)[0]
    np.testing.assert_allclose(off, em.directions * eps, rtol=1e-9, atol=1e-15)


def test_sun_emission_covers_the_scene():
    """A disc of radius R (half the bounds' diagonal) 2R up-sun of the centre, perpendicular
    to the sun; all photons along the sun; flux E pi R^2."""
    sun = SunLight("Sun", [0.3, 0.2, -1.0], [2.0, 1.0, 0.5])
    scene = _plain([sun])
    lo, hi = scene.bounds()
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    em = emit_photons(scene, 5000, _rng())
    assert np.all(em.directions == sun.direction)
    np.testing.assert_allclose(em.power.sum(axis=0), sun.irradiance * np.pi * radius ** 2, rtol=1e-9)
    rel = em.origins - (center - sun.direction * 2 * radius)
    np.testing.assert_allclose(rel @ sun.direction, 0.0, atol=1e-9)
    r = np.linalg.norm(rel, axis=1)
    assert r.max() <= radius * (1 + 1e-9) and r.max() > 0.95 * radius
    # Area-uniform on the disc: the mean of r^2 is R^2 / 2 (SD of the mean R^2 / sqrt(12 n)).
    assert abs((r ** 2).mean() - radius ** 2 / 2) < 5 * radius ** 2 / np.sqrt(12 * 5000)
    # A scene of a few millimetres: the disc shrinks with it.
    tiny = _scene(FLOOR * np.float32(1e-3), [Material("white")], lights=[sun], eye=(0, -3e-3, 1e-3))
    lo, hi = tiny.bounds()
    em = emit_photons(tiny, 1000, _rng())
    np.testing.assert_allclose(em.power.sum(axis=0), sun.irradiance * np.pi * (np.linalg.norm(hi - lo) / 2) ** 2,
                               rtol=1e-9)


@pytest.mark.parametrize("shape", ["RECTANGLE", "DISK", "ELLIPSE"])
def test_area_light_emission(shape):
    """Points on the light (inside the rectangle / ellipse), pushed off it along the normal;
    cosine directions about the normal (mean cos 2/3, SD of one 1/sqrt(18)); collimated:
    along the normal."""
    m = np.eye(4)
    m[:3, :3] = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]   # emits up (+z)
    m[:3, 3] = [0.3, 0.1, 0.5]
    light = AreaLight("A", shape, m, 1.2, 0.6 if shape != "DISK" else 1.2, [30.0, 20.0, 10.0])
    scene = _plain([light])
    n = 8000
    em = emit_photons(scene, n, _rng())
    assert np.all(em.power == np.array([30.0, 20.0, 10.0]) / n)
    rel = em.origins - light.center
    on_light = em.origins - np.outer(rel @ light.normal, light.normal)
    eps = offset_distance(on_light, scene.extent)
    np.testing.assert_allclose(rel @ light.normal, eps, rtol=1e-9)
    u = rel @ light.axis_u / (light.axis_u @ light.axis_u)
    v = rel @ light.axis_v / (light.axis_v @ light.axis_v)
    if shape == "RECTANGLE":
        assert np.all(np.abs(u) <= 1 + 1e-9) and np.all(np.abs(v) <= 1 + 1e-9)
        assert np.abs(u).max() > 0.99 and np.abs(v).max() > 0.99
        assert abs(u.mean()) < 5 * np.sqrt(1 / 3 / n) and abs(v.mean()) < 5 * np.sqrt(1 / 3 / n)
    else:
        # Area-uniform in the ellipse: u^2 + v^2 is uniform on [0, 1] (mean 1/2, SD 1/sqrt(12)).
        assert np.all(u * u + v * v <= 1 + 1e-9) and (u * u + v * v).max() > 0.99
        assert abs((u * u + v * v).mean() - 0.5) < 5 / np.sqrt(12 * n)
    cos = em.directions @ light.normal
    assert np.all(cos > 0)
    assert abs(cos.mean() - 2 / 3) < 5 / np.sqrt(18 * n)
    beam = AreaLight("B", shape, m, 1.2, 1.2, [30.0, 20.0, 10.0], collimated=True)
    em = emit_photons(_plain([beam]), 1000, _rng())
    assert np.all(em.directions == beam.normal)


def test_emissive_mesh_emission():
    """Two emitting triangles: a one-sided (emit_both_sides False) 2 m^2 quad of exitance
    (3, 2, 1) facing up and a two-sided 0.5 m^2 quad of (1, 1, 4) facing up. Flux M A sides;
    photons per triangle in proportion to that, each photon with its triangle's colour scaled
    to the meshes' luminance flux; the one-sided quad emits up only, the two-sided one both
    ways (binomial halves)."""
    a = quad([0, 0, 1.0], [1.0, 0, 0], [0, 0.5, 0])            # 2 m^2
    b = quad([3.0, 0, 1.0], [0.5, 0, 0], [0, 0.25, 0])         # 0.5 m^2
    mats = [Material("white"), Material("one", diffuse=0, exitance=[3.0, 2.0, 1.0], emit_both_sides=False),
            Material("two", diffuse=0, exitance=[1.0, 1.0, 4.0])]
    scene = _plain(extra=(a, b), materials=mats, mids=[0, 0, 1, 1, 2, 2])
    n = 20_000
    em = emit_photons(scene, n, _rng())
    flux = np.array([3.0, 2.0, 1.0]) * 2.0 + np.array([1.0, 1.0, 4.0]) * 0.5 * 2
    assert em.per_light == {"emissive meshes": n}
    on_a = em.origins[:, 0] < 2.0
    # Photons per quad in proportion to its luminance flux (they were once picked by area
    # alone, 2 / 3 here, while carrying the same power: the one-sided quad got 3.66 of its
    # 4.28 units of luminance flux).
    flux_a = (np.array([3.0, 2.0, 1.0]) @ LUMINANCE) * 2.0
    share_a = flux_a / (flux_a + (np.array([1.0, 1.0, 4.0]) @ LUMINANCE) * 0.5 * 2)
    assert abs(on_a.mean() - share_a) < 5 * np.sqrt(share_a * (1 - share_a) / n)
    lum = flux @ LUMINANCE
    for mask, m in ((on_a, np.array([3.0, 2.0, 1.0])), (~on_a, np.array([1.0, 1.0, 4.0]))):
        np.testing.assert_allclose(em.power[mask], np.tile(m / (m @ LUMINANCE) * lum / n, (mask.sum(), 1)),
                                   rtol=1e-9)
    # On the triangles, pushed off along the side they leave by.
    eps = offset_distance(em.origins, scene.extent)
    up = em.directions[:, 2] > 0
    np.testing.assert_allclose(em.origins[:, 2], 1.0 + np.where(up, eps, -eps), rtol=1e-6)
    assert np.all(np.abs(em.origins[on_a, 0]) <= 1.0 + 1e-9) and np.all(np.abs(em.origins[on_a, 1]) <= 0.5 + 1e-9)
    assert np.all(up[on_a])
    assert abs(up[~on_a].mean() - 0.5) < 5 * np.sqrt(0.25 / (~on_a).sum())
    # Area-uniform over each quad, both of its triangles: the mean point is the quad's centre
    # (SD of one coordinate half-width / sqrt(3)).
    for mask, centre, half in ((on_a, [0.0, 0.0], [1.0, 0.5]), (~on_a, [3.0, 0.0], [0.5, 0.25])):
        mean = em.origins[mask, :2].mean(axis=0)
        assert np.all(np.abs(mean - centre) < 5 * np.asarray(half) / np.sqrt(3 * mask.sum()))


def test_photon_passes_share_the_emissive_meshes(monkeypatch):
    """``emissive_meshes`` made once and handed to the passes gives the photons made without
    it, bit for bit; a caustic pass of several chunks makes it once, not once a chunk (a
    textured emission's parts cost 35 ms, 90 chunks at the caustic map's most)."""
    a = quad([0, 0, 1.0], [1.0, 0, 0], [0, 0.5, 0])
    mats = [Material("white"), Material("glow", diffuse=0, exitance=[3.0, 2.0, 1.0]),
            Material("mirror", diffuse=0, specular=0.9)]
    mirror = quad([0, 0, 0.2], [0.3, 0, 0], [0, 0.3, 0])
    scene = _plain(extra=(a, mirror), materials=mats, mids=[0, 0, 1, 1, 2, 2])
    meshes = P.emissive_meshes(scene)
    assert [entry[0] for entry in meshes] == ["emissive meshes"]
    plain = emit_photons(scene, 5000, _rng())
    shared = emit_photons(scene, 5000, _rng(), meshes=meshes)
    assert np.array_equal(plain.origins, shared.origins)
    assert np.array_equal(plain.power, shared.power)
    assert P.emissive_meshes(_plain()) == []
    made = []
    monkeypatch.setattr(P, "emissive_meshes", lambda *args: made.append(1) or meshes)
    monkeypatch.setattr(P, "PHOTON_CHUNK", 1000)
    accel = Accelerator(scene.triangles, threads=1)
    cmap = P.build_caustic_map(scene, accel, 4000, seed=1)
    assert cmap.stats["chunks"] == 4
    assert len(made) == 1


def test_dim_emitters_and_shares_between_kinds():
    """An emitter dimmer than 1 W/m^2 still emits, in its own colour; a point light and an
    emissive mesh of equal luminance flux get equal photon counts; one photon is a count."""
    glow = quad([0, 0, 1.0], [0.5, 0, 0], [0, 0.5, 0])                     # 1 m^2
    mats = [Material("white"), Material("dim", diffuse=0, exitance=[0.5, 0.25, 0.125], emit_both_sides=False)]
    scene = _plain(extra=(glow,), materials=mats, mids=[0, 0, 1, 1])
    em = emit_photons(scene, 1000, _rng())
    m = np.array([0.5, 0.25, 0.125])
    n = len(em.power)
    assert n == 1000
    np.testing.assert_allclose(em.power, np.tile(m / n, (n, 1)), rtol=1e-9)
    lum = float(m @ LUMINANCE)
    point = PointLight("P", [0, 0, 2.0], np.full(3, lum))
    both = emit_photons(_plain([point], extra=(glow,), materials=mats, mids=[0, 0, 1, 1]), 1001, _rng())
    # Equal fluxes: 500.5 each; the odd photon goes to one of them (largest remainders).
    assert sorted(both.per_light.values()) == [500, 501]
    one = emit_photons(_plain([point]), 1, _rng())
    assert one.per_light == {"P": 1} and one.origins.shape == (1, 3)


def test_world_emission():
    """A constant world: directions uniform (travelling inwards), origins on a disc of radius
    R perpendicular to each, 2R out from the centre; flux L 4 pi^2 R^2."""
    scene = _plain(world=World([0.5, 0.25, 0.125]))
    lo, hi = scene.bounds()
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    n = 6000
    em = emit_photons(scene, n, _rng())
    np.testing.assert_allclose(em.power.sum(axis=0), np.array([0.5, 0.25, 0.125]) * 4 * np.pi ** 2 * radius ** 2,
                               rtol=1e-9)
    rel = em.origins - center
    along = np.einsum("ij,ij->i", rel, em.directions)
    np.testing.assert_allclose(along, -2 * radius, rtol=1e-9)
    perp = rel - along[:, None] * em.directions
    assert np.linalg.norm(perp, axis=1).max() <= radius * (1 + 1e-9)
    assert np.linalg.norm(perp, axis=1).max() > 0.95 * radius
    assert em.per_light == {"World": n}
    assert np.all(np.abs(em.directions.mean(axis=0)) < 5 * np.sqrt(1 / 3 / n))


def test_a_single_light_gets_every_photon_requested():
    glow = quad([0, 0, 1.0], [0.5, 0, 0], [0, 0.5, 0])
    mats = [Material("white"), Material("dim", diffuse=0, exitance=[0.5, 0.25, 0.125])]
    em = emit_photons(_plain(extra=(glow,), materials=mats, mids=[0, 0, 1, 1]), 1000, _rng())
    assert len(em.origins) == 1000


def test_photons_shared_by_luminance_flux_at_least_one_each():
    bright = PointLight("Bright", [0, 0, 1.0], [1000.0] * 3)
    dim = PointLight("Dim", [1.0, 0, 1.0], [1e-4] * 3)
    red = PointLight("Red", [-1.0, 0, 1.0], [300.0, 0.0, 0.0])
    em = emit_photons(_plain([bright, dim, red]), 10_000, _rng())
    # Luminance shares of 10 000: 9400.44, 0.0009, 599.56 (Red: 300 x 0.2126). The floors
    # leave one photon over; it goes to the largest remainder (Red's 0.56); Dim, below one,
    # gets its one on top.
    assert em.per_light == {"Bright": 9400, "Dim": 1, "Red": 600}
    np.testing.assert_allclose(em.power.sum(axis=0), [1300.0 + 1e-4, 1000.0 + 1e-4, 1000.0 + 1e-4], rtol=1e-12)
    black = PointLight("Black", [0, 0, 1.0], [0.0] * 3)
    none = emit_photons(_plain([black]), 1000, _rng())
    assert none.origins.shape == none.directions.shape == none.power.shape == (0, 3)
    assert none.per_light == {}
    assert len(emit_photons(_plain([bright]), 0, _rng()).origins) == 0


# -- The photon pass ----------------------------------------------------------------------------

def _room():
    # A spot with a soft edge: every photon carries its own power (the mask's weight).
    spot = SpotLight("P", [0.1, 0.2, 0.5], [0.2, 0.1, -1.0], [10.0, 8.0, 6.0],
                     half_angle=np.radians(70), blend=0.8)
    return _scene(np.concatenate([quad([0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]),
                                  quad([0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0])]),
                  [Material("grey", diffuse=[0.6, 0.5, 0.4])], lights=[spot])


def test_photon_pass_in_chunks_is_the_sum_of_its_chunks(monkeypatch):
    """Chunks of 700 photons, each traced with its own stream (seed, STREAM_PHOTON, i + 1):
    the map holds every chunk's photons and its stats are their sums; two workers give the
    same map; progress is called once a chunk."""
    monkeypatch.setattr(P, "PHOTON_CHUNK", 700)
    scene = _room()
    accel = Accelerator(scene.triangles, threads=1)
    calls = []
    pmap = build_photon_map(scene, accel, 3000, seed=4, progress=calls.append)
    assert calls == pytest.approx([1 / 5, 2 / 5, 3 / 5, 4 / 5, 1.0])
    emitted = emit_photons(scene, 3000, sampling.rng_for(4, sampling.STREAM_PHOTON, 0))
    parts = [trace_photons(scene, accel, EmittedPhotons(emitted.origins[a:a + 700],
                                                        emitted.directions[a:a + 700],
                                                        emitted.power[a:a + 700]),
                           sampling.rng_for(4, sampling.STREAM_PHOTON, i + 1))
             for i, a in enumerate(range(0, 3000, 700))]
    st = pmap.stats
    assert len(pmap) == sum(len(p) for p in parts) == st["stored"] == st["stored_all"]
    for key in ("rays", "capped_paths"):
        assert st[key] == sum(p.stats[key] for p in parts), key
    for key in ("flux_absorbed", "flux_escaped", "flux_capped", "flux_stored_first_hit"):
        np.testing.assert_allclose(st[key], np.sum([p.stats[key] for p in parts], axis=0), rtol=1e-12)
    np.testing.assert_allclose(st["flux_emitted"], emitted.power.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(st["flux_lights"], emitted.power.sum(axis=0), rtol=1e-12)
    assert st["requested"] == 3000 and st["emitted"] == 3000 and st["chunks"] == 5
    assert st["cancelled"] is False and st["kept"] == "all" and st["max_bounces"] == 128
    assert st["photons_per_light"] == {"P": 3000} and st["bytes"] == pmap.nbytes
    assert st["bytes_per_photon"] == 37.0 and st["library"] == "pykdtree"
    ref = np.sort(np.concatenate([p.positions for p in parts]), axis=0)
    assert np.array_equal(np.sort(pmap.positions, axis=0), ref)
    direct = np.concatenate([p.power[p.bounces == 0] for p in parts]).astype(float).sum(axis=0)
    indirect = np.concatenate([p.power[p.bounces > 0] for p in parts]).astype(float).sum(axis=0)
    np.testing.assert_allclose(st["flux_stored_direct"], direct, rtol=1e-12)
    np.testing.assert_allclose(st["flux_stored_indirect"], indirect, rtol=1e-12)
    two = build_photon_map(scene, accel, 3000, seed=4, workers=2)
    assert np.array_equal(two.positions, pmap.positions) and np.array_equal(two.power, pmap.power)
    assert np.array_equal(build_photon_map(scene, accel, 3000).positions,
                          build_photon_map(scene, accel, 3000, seed=0).positions)
    # The cap and the ray log reach every chunk's tracing.
    log = []
    capped = build_photon_map(scene, accel, 3000, seed=4, max_bounces=2, ray_log=log)
    assert capped.bounces.max() == 2 and capped.stats["capped_paths"] > 0
    assert capped.stats["max_bounces"] == 2
    assert len(log) >= 5 and sum(len(entry[1]) for entry in log) == capped.stats["rays"]


def test_photon_pass_cancel_keep_and_errors(monkeypatch):
    monkeypatch.setattr(P, "PHOTON_CHUNK", 700)
    scene = _room()
    accel = Accelerator(scene.triangles, threads=1)
    polls = []

    def cancelled():
        polls.append(1)
        return len(polls) >= 2

    t0 = __import__("time").perf_counter()
    part = build_photon_map(scene, accel, 3000, seed=4, cancelled=cancelled)
    elapsed = __import__("time").perf_counter() - t0
    assert 0 <= part.stats["emit_seconds"] <= elapsed and 0 <= part.stats["trace_seconds"] <= elapsed
    emitted = emit_photons(scene, 3000, sampling.rng_for(4, sampling.STREAM_PHOTON, 0))
    assert part.stats["cancelled"] is True and part.stats["emitted"] == 1400
    np.testing.assert_allclose(part.stats["flux_emitted"], emitted.power[:1400].sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(part.stats["flux_lights"], emitted.power.sum(axis=0), rtol=1e-12)
    full = build_photon_map(scene, accel, 3000, seed=4)
    ind = build_photon_map(scene, accel, 3000, seed=4, keep="indirect", library="scipy")
    assert ind.stats["kept"] == "indirect" and ind.library == "scipy"
    assert len(ind) == np.count_nonzero(full.bounces > 0) == ind.stats["stored"]
    assert ind.stats["stored_all"] == len(full) and np.all(ind.bounces > 0)
    assert ind.stats["flux_stored_direct"] == full.stats["flux_stored_direct"]
    assert ind.stats["bytes"] == ind.nbytes < full.stats["bytes"]
    with pytest.raises(ValueError, match="keep"):
        build_photon_map(scene, accel, 100, keep="direct")
    dark = _scene(FLOOR, [Material("white")])
    empty = build_photon_map(dark, Accelerator(dark.triangles, threads=1), 1000)
    assert len(empty) == 0 and empty.stats["emitted"] == 0 and empty.stats["chunks"] == 0
    for key, dtype, shape in (("positions", np.float32, (0, 3)), ("power", np.float32, (0, 3)),
                              ("incoming", np.float16, (0, 3)), ("normals", np.float16, (0, 3)),
                              ("bounces", np.uint8, (0,))):
        assert getattr(empty, key).dtype == dtype and getattr(empty, key).shape == shape, key
    assert empty.stats["bytes_per_photon"] == 0.0 and empty.stats["bytes"] == 0
    assert empty.stats["flux_emitted"] == [0.0, 0.0, 0.0]
    # One photon stored (a near-black floor under a lamp): 37 bytes for it.
    lamp = SpotLight("S", [0, 0, 1.0], [0, 0, -1.0], [1.0] * 3, half_angle=0.3)
    dim = _scene(FLOOR, [Material("dark", diffuse=1e-9)], lights=[lamp])
    one = build_photon_map(dim, Accelerator(dim.triangles, threads=1), 1)
    assert len(one) == 1 and one.stats["bytes_per_photon"] == 37.0


def test_in_crevice_finds_photons_under_an_occluder_closer_than_a_spacing():
    """Four photons on a 4 x 4 m white floor (spacing sqrt(16 / 4) = 2 m), a black plate
    0.5 m above the first two and another 3 m above the third: the first two lie in a crevice
    (0.5 m < the spacing), the third (3 m > the spacing) and the open fourth do not."""
    near = quad([-1.5, -1.5, 0.5], [0.4, 0, 0], [0, 0.4, 0])          # over (-1.5, -1.5)
    high = quad([1.0, -1.0, 3.0], [0.4, 0, 0], [0, 0.4, 0])           # over (1, -1), 3 m up
    mats = [Material("white"), Material("black", diffuse=0.0)]
    scene = _scene(np.concatenate([FLOOR, near, high]), mats, [0, 0, 1, 1, 1, 1])
    accel = Accelerator(scene.triangles, threads=1)
    pmap = _map([[-1.5, -1.5, 0.0], [-1.4, -1.6, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0]],
                np.ones((4, 3)))
    assert P.photon_spacing(scene, 4) == pytest.approx(2.0)
    assert P.in_crevice(scene, accel, pmap).tolist() == [True, True, False, False]
