"""engine/direct.py piece by piece (no bpy; milliseconds to a second each).

Added for issue 19 item 4 (mutation testing). test_direct_analytic.py checks one light at a
time against closed forms; these tests pin what it averages away:
* delta lights where only some points face the light, several lights at once, and the
  shadow-ray bookkeeping (rays counted per call, accumulated over calls);
* two sampled lights at once: the light-selection probabilities must cancel (Lambert's
  formula summed over both, within 5 standard errors measured from the repeats);
* the shadow-photon path with a stand-in map whose classes are chosen by hand: LIT traces no
  ray (light through an occluder, equal bit for bit to the unoccluded scene with the same
  random numbers), UMBRA gives exactly 0, PENUMBRA with M = 1 is the plain call, M = 2
  traces twice the rays and stays unbiased (5 standard errors), samples below the geometric
  surface are traced even when LIT; next to delta lights, the ray counts (saved, traced,
  summed over calls) are exact; an emissive mesh in penumbra with M = 1 traces the plain
  call's rays bit for bit; a single penumbra sample becomes M;
* a hard sun on points partly facing away (the index path of delta lights), samples of a
  light behind the surface (no ray).
"""
import numpy as np
import pytest

from analytic import point_irradiance, polygon_irradiance, quad
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.direct import (LIT, PENUMBRA, UMBRA, direct_irradiance, direct_terms,
                                    irradiance_from_terms)
from lanterna.engine.lights import LightSet
from lanterna.engine.scene import AreaLight, Camera, Material, PointLight, Scene, SpotLight

UP = np.array([0.0, 0.0, 1.0])


def _scene(lights, extra=()):
    tris = np.concatenate([quad([0, 0, 0], [5.0, 0, 0], [0, 5.0, 0]), *extra]).astype(np.float32)
    scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("white")], camera=Camera.look_at([0, -6, 4], [0, 0, 0]),
                  lights=list(lights)).validate()
    return scene, Accelerator(scene.triangles, threads=1), LightSet(scene)


def _square(name, center, half, power):
    m = np.eye(4)
    m[:3, 3] = center
    return AreaLight(name, "SQUARE", m, 2 * half, 2 * half, [power] * 3)


def _square_polygon(center, half):
    c = np.asarray(center, float)
    return np.array([c + [-half, -half, 0], c + [half, -half, 0], c + [half, half, 0], c + [-half, half, 0]])


PLATE = quad([0, 0, 1.5], [1.0, 0, 0], [0, 1.0, 0])          # over |x|, |y| < 1 at 1.5 m


def test_point_lights_some_points_facing_away_and_occluded():
    """Two point lights; points facing up, down and sideways; a plate shadows the first light
    from the points under it. Each point gets Eq. 7.1 of every light it faces and sees,
    exactly; one shadow ray per lit (point, light) pair."""
    a = PointLight("A", [0.0, 0.0, 3.0], [100.0, 50.0, 20.0])
    b = PointLight("B", [3.0, 0.0, 1.0], [10.0, 10.0, 40.0])
    scene, accel, lights = _scene([a, b], [PLATE])
    x = np.array([[0.2, 0.1, 0.0], [2.0, 1.5, 0.0], [2.0, 1.5, 0.0], [-2.5, 0.0, 0.0]])
    n = np.array([UP, UP, -UP, [1.0, 0, 0]])
    st = {}
    e = direct_irradiance(x, n, lights, accel, np.random.default_rng(0), stats=st)
    expect = point_irradiance(x, n, b.position, b.flux)
    expect[1:] += point_irradiance(x[1:], n[1:], a.position, a.flux)        # not under the plate
    np.testing.assert_allclose(e, expect, rtol=1e-9)
    # Pairs facing their light: A faces points 0, 1, 3 (3 sideways at x = -2.5 faces +x: A at
    # x = 0 is in front); B faces 0, 1, 3.
    facing = sum(int(np.sum(point_irradiance(x, n, l.position, l.flux)[:, 2] > 0)) for l in (a, b))
    assert st["shadow_rays"] == facing and st["trace_seconds"] >= 0
    direct_irradiance(x, n, lights, accel, np.random.default_rng(0), stats=st)
    assert st["shadow_rays"] == 2 * facing
    # A single light facing every point: one group, no index arrays.
    scene1, accel1, lights1 = _scene([a])
    e1 = direct_irradiance(x[:2], n[:2], lights1, accel1, np.random.default_rng(0))
    np.testing.assert_allclose(e1, point_irradiance(x[:2], n[:2], a.position, a.flux), rtol=1e-9)
    # Offset normals: the shadow rays leave along them (here the same surface).
    e2 = direct_irradiance(x, n, lights, accel, np.random.default_rng(0), offset_normals=n.copy())
    np.testing.assert_array_equal(e2, e)


def test_spot_partly_outside_its_cone_and_ray_log():
    spot = SpotLight("S", [0.0, 0.0, 2.0], [0.0, 0.0, -1.0], [120.0] * 3, half_angle=np.radians(30))
    scene, accel, lights = _scene([spot])
    x = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [3.0, 0.0, 0.0]])
    log, st = [], {}
    e = direct_irradiance(x, np.tile(UP, (3, 1)), lights, accel, np.random.default_rng(0),
                          stats=st, ray_log=log)
    exact = point_irradiance(x, np.tile(UP, (3, 1)), spot.position, spot.flux)
    np.testing.assert_allclose(e[:2], exact[:2], rtol=1e-9)
    assert np.all(e[2] == 0) and st["shadow_rays"] == 2
    assert len(log) == 1 and log[0][0] == "shadow" and len(log[0][1]) == 2
    np.testing.assert_allclose(log[0][3], np.linalg.norm(spot.position - x[:2], axis=1), rtol=1e-3)


def test_nothing_to_do():
    scene, accel, lights = _scene([PointLight("A", [0, 0, 1.0], [1.0] * 3)])
    assert direct_terms(np.zeros((0, 3)), np.zeros((0, 3)), lights, accel, np.random.default_rng(0)) == []
    dark, accel_d, lights_d = _scene([])
    assert direct_terms(np.zeros((2, 3)), np.tile(UP, (2, 1)), lights_d, accel_d, np.random.default_rng(0)) == []
    st = {}
    e = direct_irradiance(np.zeros((2, 3)), np.tile(-UP, (2, 1)), lights, accel,
                          np.random.default_rng(0), stats=st)
    assert np.all(e == 0) and st == {}
    area, accel_a, lights_a = _scene([_square("Q", [0, 0, 2.0], 0.5, 10.0)])
    assert direct_terms(np.zeros((2, 3)), np.tile(UP, (2, 1)), lights_a, accel_a,
                        np.random.default_rng(0), light_samples=0) == []


def test_irradiance_from_terms():
    terms = [(None, np.array([1.0, 2.0]), [1.0, 0.0, 0.0]),
             (np.array([1, 1, 0]), np.array([0.5, 0.25, 2.0]), [0.0, 1.0, 2.0])]
    np.testing.assert_allclose(irradiance_from_terms(terms, 2), [[1.0, 2.0, 4.0], [2.0, 0.75, 1.5]])
    assert irradiance_from_terms([], 3).shape == (3, 3)


def test_two_sampled_lights_share_the_samples_without_bias():
    """A bright and a dim square light at different places: each sample picks one light by the
    estimated contribution and divides by that probability, so the mean is Lambert's formula
    summed over both lights (5 standard errors of the mean over 2000 repeats, measured)."""
    bright = _square("Bright", [0.5, 0.0, 1.0], 0.25, 80.0)
    dim = _square("Dim", [-1.0, 0.5, 0.7], 0.4, 15.0)
    scene, accel, lights = _scene([bright, dim])
    pts = np.array([[0.0, 0.0, 0.0], [0.6, 0.1, 0.0], [-1.2, 0.4, 0.0]])
    reps = 2000
    xs = np.repeat(pts[None], reps, 0).reshape(-1, 3)
    e = direct_irradiance(xs, np.tile(UP, (len(xs), 1)), lights, accel, sampling.rng_for(1, 9),
                          light_samples=3)[:, 0].reshape(reps, -1)
    exact = sum(np.array([polygon_irradiance(p, UP, _square_polygon(l.center, 0.25 if l is bright else 0.4),
                                             l.radiance) for p in pts])[:, 0] for l in (bright, dim))
    se = e.std(axis=0, ddof=1) / np.sqrt(reps)
    assert np.all(se < 0.01 * exact)
    assert np.all(np.abs(e.mean(axis=0) - exact) < 5 * se)


class _Classes:
    """A stand-in shadow-photon map: classes chosen by hand, per point."""

    def __init__(self, rule, factor=2, covered=(0,)):
        self.rule, self.penumbra_factor, self.covered = rule, factor, covered
        self.asked = []

    def covers(self, li):
        return li in self.covered

    def classify(self, x, n, li):
        self.asked.append((x.copy(), n.copy(), li))
        return self.rule(x).astype(np.int8)


def _occluded_setup():
    light = _square("Q", [0.0, 0.0, 3.0], 0.5, 100.0)
    return _scene([light], [PLATE]), _scene([light])


def test_lit_traces_nothing_and_umbra_is_dark():
    """Classes from the stand-in map: LIT points get the light without a ray (under the plate
    too: the same as the scene without the plate, with the same random numbers), UMBRA points
    exactly nothing; one class per (point, light), asked once per point."""
    (scene, accel, lights), (_open, accel_open, lights_open) = _occluded_setup()
    x = np.array([[0.1, 0.2, 0.0], [0.3, -0.2, 0.0], [2.5, 0.0, 0.0], [3.0, 1.0, 0.0]])
    n = np.tile(UP, (4, 1))
    lit = _Classes(lambda p: np.full(len(p), LIT))
    st = {}
    e = direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4, stats=st, shadow_map=lit)
    e_open = direct_irradiance(x, n, lights_open, accel_open, sampling.rng_for(2, 9), 4)
    np.testing.assert_array_equal(e, e_open)
    assert np.all(e > 0)
    assert st["shadow_rays"] == 0 and st["shadow_rays_saved"] == 16
    assert (st["shadow_lit"], st["shadow_umbra"], st["shadow_penumbra"]) == (4, 0, 0)
    assert len(lit.asked) == 1 and len(lit.asked[0][0]) == 4
    umbra = _Classes(lambda p: np.where(p[:, 0] < 1.0, UMBRA, LIT))
    st = {}
    e = direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4, stats=st, shadow_map=umbra)
    assert np.all(e[:2] == 0)
    np.testing.assert_array_equal(e[2:], e_open[2:])
    assert (st["shadow_lit"], st["shadow_umbra"], st["shadow_penumbra"]) == (2, 2, 0)
    assert st["shadow_rays"] == 0 and st["shadow_rays_saved"] == 16
    # Repeated points: one class each, the same class for every sample of the pair.
    xs = np.repeat(x, 3, axis=0)
    st = {}
    e3 = direct_irradiance(xs, np.tile(UP, (12, 1)), lights, accel, sampling.rng_for(2, 9), 4,
                           stats=st, shadow_map=umbra)
    assert np.all(e3[:6] == 0) and np.all(e3[6:] > 0) and st["shadow_umbra"] == 6
    # A light the map does not cover is traced as without a map.
    none = _Classes(lambda p: np.full(len(p), LIT), covered=())
    st = {}
    e = direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4, stats=st, shadow_map=none)
    np.testing.assert_array_equal(e, direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4))
    assert st["shadow_rays"] == 16 and st["shadow_rays_saved"] == 0 and st["shadow_lit"] == 0


def test_lit_samples_below_the_geometric_surface_are_traced():
    """Shading normal up, geometric normal down (a smooth-shaded surface seen from the back):
    the light lies below the geometric surface, so even LIT samples go through a shadow ray,
    and the plate blocks them: exactly the plain call."""
    (scene, accel, lights), _ = _occluded_setup()
    x = np.array([[0.1, 0.2, 0.0], [2.5, 0.0, 0.0]])
    n, geo = np.tile(UP, (2, 1)), np.tile(-UP, (2, 1))
    lit = _Classes(lambda p: np.full(len(p), LIT))
    st = {}
    e = direct_irradiance(x, n, lights, accel, sampling.rng_for(3, 9), 4, stats=st,
                          offset_normals=geo, shadow_map=lit)
    plain = direct_irradiance(x, n, lights, accel, sampling.rng_for(3, 9), 4, offset_normals=geo)
    np.testing.assert_array_equal(e, plain)
    assert st["shadow_rays"] == 8 and st["shadow_rays_saved"] == 0
    np.testing.assert_array_equal(lit.asked[0][1], geo)            # classified with geo normals


def test_penumbra_samples():
    """PENUMBRA with M = 1: the pair's own samples, traced: the plain call. With M = 3: three
    fresh samples per original, weighted by 1/3, traced (3 x the rays); the mean over repeats
    equals the plain call's within 5 standard errors (both measured)."""
    (scene, accel, lights), _ = _occluded_setup()
    x = np.array([[1.8, 0.0, 0.0], [2.2, 0.2, 0.0], [2.8, 0.0, 0.0]])     # penumbra x 2, lit
    n = np.tile(UP, (3, 1))
    one = _Classes(lambda p: np.full(len(p), PENUMBRA), factor=1)
    st = {}
    e1 = direct_irradiance(x, n, lights, accel, sampling.rng_for(4, 9), 4, stats=st, shadow_map=one)
    np.testing.assert_array_equal(e1, direct_irradiance(x, n, lights, accel, sampling.rng_for(4, 9), 4))
    assert st["shadow_rays"] == 12 and st["shadow_penumbra"] == 3
    reps = 3000
    xs = np.repeat(x[None], reps, 0).reshape(-1, 3)
    ns = np.tile(UP, (len(xs), 1))
    three = _Classes(lambda p: np.full(len(p), PENUMBRA), factor=3)
    st = {}
    e3 = direct_irradiance(xs, ns, lights, accel, sampling.rng_for(5, 9), 4, stats=st,
                           shadow_map=three)[:, 0].reshape(reps, -1)
    plain = direct_irradiance(xs, ns, lights, accel, sampling.rng_for(6, 9), 4)[:, 0].reshape(reps, -1)
    assert st["shadow_rays"] == 3 * 4 * len(xs) and st["shadow_rays_saved"] == -2 * 4 * len(xs)
    se = np.sqrt(e3.var(axis=0, ddof=1) / reps + plain.var(axis=0, ddof=1) / reps)
    assert np.all(np.abs(e3.mean(axis=0) - plain.mean(axis=0)) <= 5 * se)
    assert np.all(e3.var(axis=0) < plain.var(axis=0))          # three samples for one: less noise
    assert np.all(plain.mean(axis=0) > 0)


def test_emitter_that_is_geometry_is_not_its_own_shadow():
    """An emissive quad (in the BVH) 1 m above the floor, lighting it: shadow rays aim at the
    sampled point and stop short of it, so the emitter does not shadow itself; a plate
    between them blocks it."""
    tris = np.concatenate([quad([0, 0, 0], [5.0, 0, 0], [0, 5.0, 0]), quad([0, 0, 1.0], [0.3, 0, 0], [0, 0.3, 0]),
                           quad([1.5, 0, 0.5], [0.7, 0, 0], [0, 0.7, 0])]).astype(np.float32)
    scene = Scene(triangles=tris, material_ids=np.array([0, 0, 1, 1, 0, 0], np.int32),
                  materials=[Material("white"), Material("glow", diffuse=0.0, exitance=20.0)],
                  camera=Camera.look_at([0, -6, 4], [0, 0, 0])).validate()
    accel, lights = Accelerator(scene.triangles, threads=1), LightSet(scene)
    assert lights.sampled[0].in_bvh
    pts = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.0]])
    reps = 400
    xs = np.repeat(pts[None], reps, 0).reshape(-1, 3)
    e = direct_irradiance(xs, np.tile(UP, (len(xs), 1)), lights, accel, sampling.rng_for(7, 9),
                          8)[:, 0].reshape(reps, -1)
    square = np.array([[-0.3, -0.3, 1.0], [0.3, -0.3, 1.0], [0.3, 0.3, 1.0], [-0.3, 0.3, 1.0]])
    exact = np.array([polygon_irradiance(p, UP, square, 20.0 / np.pi) for p in pts])
    se = e.std(axis=0, ddof=1) / np.sqrt(reps)
    assert np.all(np.abs(e.mean(axis=0) - exact) < 5 * se + 1e-3 * exact)
    hidden = direct_irradiance(np.array([[3.0, 0.0, 0.0]]), UP[None], lights, accel,
                               sampling.rng_for(7, 9), 8)
    assert np.all(hidden == 0)


def test_shadow_map_next_to_delta_lights_counts_every_ray():
    """Two point lights (traced: one ray per lit point each) and a square light the map calls
    LIT (no ray): rays saved = the square's samples exactly, rays traced = the point lights'
    pairs; the irradiance is the plain call's (no occluder), to rounding."""
    a = PointLight("A", [0.0, 0.0, 3.0], [100.0, 50.0, 20.0])
    b = PointLight("B", [3.0, 0.0, 1.0], [10.0, 10.0, 40.0])
    q = _square("Q", [0.0, 0.0, 3.0], 0.5, 100.0)
    scene, accel, lights = _scene([a, b, q])
    x = np.array([[0.1, 0.2, 0.0], [0.3, -0.2, 0.0], [2.5, 0.0, 0.0], [-1.0, 1.0, 0.0]])
    n = np.tile(UP, (4, 1))
    st = {}
    lit = _Classes(lambda p: np.full(len(p), LIT))
    e = direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4, stats=st, shadow_map=lit)
    plain = direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4)
    np.testing.assert_allclose(e, plain, rtol=1e-12)
    assert st["shadow_rays"] == 8 and st["shadow_rays_saved"] == 16
    assert (st["shadow_lit"], st["shadow_umbra"], st["shadow_penumbra"]) == (4, 0, 0)
    direct_irradiance(x, n, lights, accel, sampling.rng_for(2, 9), 4, stats=st, shadow_map=lit)
    assert st["shadow_rays"] == 16 and st["shadow_rays_saved"] == 32     # summed over calls
    assert (st["shadow_lit"], st["shadow_umbra"], st["shadow_penumbra"]) == (8, 0, 0)


def test_hard_sun_on_points_partly_facing_away():
    """A hard sun straight down (3 W/m^2): a point under the plate gets 0, an open point facing
    up 3 exactly, a point facing down nothing and no ray (two rays in all)."""
    from lanterna.engine.scene import SunLight
    sun = SunLight("Sun", [0.0, 0.0, -1.0], [3.0, 3.0, 3.0])
    scene, accel, lights = _scene([sun], [PLATE])
    x = np.array([[0.2, 0.1, 0.0], [3.0, 1.0, 0.0], [2.0, 2.0, 0.0]])
    n = np.array([UP, UP, -UP])
    st = {}
    e = direct_irradiance(x, n, lights, accel, np.random.default_rng(0), stats=st)
    np.testing.assert_allclose(e, [[0.0] * 3, [3.0] * 3, [0.0] * 3], rtol=1e-12, atol=0)
    assert st["shadow_rays"] == 2


def test_samples_of_a_light_behind_the_surface_trace_no_ray():
    """Points facing away from a square light: every sample weighs 0, nothing is traced."""
    scene, accel, lights = _scene([_square("Q", [0.0, 0.0, 3.0], 0.5, 100.0)])
    st = {}
    e = direct_irradiance(np.zeros((3, 3)), np.tile(-UP, (3, 1)), lights, accel,
                          sampling.rng_for(1, 9), 4, stats=st)
    assert np.all(e == 0) and st.get("shadow_rays", 0) == 0


def test_penumbra_of_an_emissive_mesh_traces_the_plain_rays():
    """PENUMBRA with M = 1 on a light that is geometry (an emissive quad in the BVH): the
    shadow rays are the plain call's, aimed at the sampled points, bit for bit."""
    tris = np.concatenate([quad([0, 0, 0], [5.0, 0, 0], [0, 5.0, 0]),
                           quad([0, 0, 1.0], [0.3, 0, 0], [0, 0.3, 0])]).astype(np.float32)
    scene = Scene(triangles=tris, material_ids=np.array([0, 0, 1, 1], np.int32),
                  materials=[Material("white"), Material("glow", diffuse=0.0, exitance=20.0)],
                  camera=Camera.look_at([0, -6, 4], [0, 0, 0])).validate()
    accel, lights = Accelerator(scene.triangles, threads=1), LightSet(scene)
    x = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.0], [1.5, -0.5, 0.0]])
    n = np.tile(UP, (3, 1))
    log, plain_log = [], []
    one = _Classes(lambda p: np.full(len(p), PENUMBRA), factor=1)
    e = direct_irradiance(x, n, lights, accel, sampling.rng_for(3, 9), 4, ray_log=log, shadow_map=one)
    plain = direct_irradiance(x, n, lights, accel, sampling.rng_for(3, 9), 4, ray_log=plain_log)
    np.testing.assert_array_equal(e, plain)
    for got, want in zip(log[0][1:], plain_log[0][1:]):
        np.testing.assert_array_equal(got, want)


def test_a_single_penumbra_sample_becomes_m_samples():
    """One point, one light sample, PENUMBRA with M = 3: three rays, and the open point gets
    light."""
    scene, accel, lights = _scene([_square("Q", [0.0, 0.0, 3.0], 0.5, 100.0)])
    three = _Classes(lambda p: np.full(len(p), PENUMBRA), factor=3)
    st = {}
    e = direct_irradiance(np.zeros((1, 3)), UP[None], lights, accel, sampling.rng_for(4, 9), 1,
                          stats=st, shadow_map=three)
    assert st["shadow_rays"] == 3 and st["shadow_penumbra"] == 1 and np.all(e > 0)
