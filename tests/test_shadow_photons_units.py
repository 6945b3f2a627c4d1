"""engine/shadow_photons.py piece by piece, on hand-made inputs (no bpy; milliseconds each).

Added for issue 19 item 4 (mutation testing). test_shadow_photons.py checks the classes of a
whole map against exact visibility; these tests pin the pieces exactly:
* the octahedral code on directions whose codes are known by hand, the side test on it;
* the defaults (neighbours queried, the automatic count) against their formulas;
* emission from a light (on its triangles, by area, pushed off the surface, cosine
  directions about the emitting side), tracing through stacked planes (every crossing, its
  depth, the drop at ``max_crossings``);
* the two classification levels on photons and representatives placed by hand, where each
  rule (k photons, all direct / all shadow, the side, the disc, the radius cap; two
  representatives within radius / margin) decides one point;
* the map's bookkeeping: photons per light ~ flux^(2/3), radius caps, stats, round trip.
Statistical checks: a binomial count or a mean of uniform variables within 5 standard
errors of its known variance (P(|z| > 5) = 6e-7).
"""
import numpy as np
import pytest

from analytic import quad
from lanterna.engine import shadow_photons as S
from lanterna.engine.accel import Accelerator
from lanterna.engine.lights import LightSet, SunCone, TriangleEmitter, WorldLight
from lanterna.engine.scene import AreaLight, Camera, Material, Scene, SunLight, World
from lanterna.engine.shadow_photons import (LIT, PENUMBRA, UMBRA, ShadowPhotonMap,
                                            auto_shadow_photon_count, build_shadow_photon_map,
                                            decode_directions, empty_map, encode_directions,
                                            neighbours_queried, positioned)


def _scene(tris, lights=(), materials=None, mids=None, eye=(0.0, -8.0, 6.0), world=None):
    tris = np.asarray(tris, np.float32)
    return Scene(triangles=tris,
                 material_ids=np.zeros(len(tris), np.int32) if mids is None else np.asarray(mids, np.int32),
                 materials=materials or [Material("white")],
                 camera=Camera.look_at(eye, [0, 0, 0]), lights=list(lights),
                 world=world or World()).validate()


def _area(name="Area", height=3.0, half=0.5, power=100.0, x=0.0, shape="SQUARE"):
    m = np.eye(4)
    m[:3, 3] = [x, 0, height]
    return AreaLight(name, shape, m, 2 * half, 2 * half, [power] * 3)


# -- Octahedral code and the side test ---------------------------------------------------------

def test_octahedral_codes_by_hand():
    d = np.array([[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0],
                  [0.6, 0, -0.8], [-0.6, 0, -0.8], [0, -0.6, -0.8], [0.5, 0.5, 0.0], [0, 0, 0]])
    codes = encode_directions(d)
    assert codes.dtype == np.int8
    # -z folds to a corner; (0.6, 0, -0.8): |x| / s = 3/7, folded (1, 4/7) -> (127, 72.6 -> 73).
    assert codes.tolist() == [[0, 0], [127, 127], [127, 0], [-127, 0], [0, 127], [0, -127],
                              [127, 73], [-127, 73], [73, -127], [64, 64], [0, 0]]
    back = decode_directions(codes)
    assert back.dtype == np.float32 and back.shape == (11, 3)
    np.testing.assert_allclose(back[:6], d[:6], atol=1e-7)
    unit = back[6:9] / np.linalg.norm(back[6:9], axis=1, keepdims=True)
    np.testing.assert_allclose(unit, d[6:9], atol=0.01)
    # Decoding a corner code of the lower half by hand: f = (-1, 73/127).
    f = 73 / 127
    np.testing.assert_allclose(back[7], [-1 + f, 0.0, -f], atol=1e-6)
    assert decode_directions(codes.reshape(1, 11, 2)).shape == (1, 11, 3)


def test_facing_and_height():
    """``_facing`` is True where the photon travelled against the normal (arrived on the side
    it faces), from the code alone; ``_height`` the distance to the tangent plane."""
    rng = np.random.default_rng(0)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = rng.normal(size=(1000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    codes = encode_directions(d).reshape(1000, 3, 2)
    facing = S._facing(codes, n.astype(np.float32))
    dot = np.einsum("pkj,pj->pk", d.reshape(1000, 3, 3), n)
    clear = np.abs(dot) > 0.03
    assert facing.shape == (1000, 3)
    assert np.array_equal(facing[clear], dot[clear] < 0)
    q = rng.normal(size=(4, 2, 3))
    p = rng.normal(size=(4, 3))
    nn = n[:4]
    np.testing.assert_allclose(S._height(q, p, nn), np.abs(np.einsum("pkj,pj->pk", q - p[:, None], nn)),
                               rtol=1e-12)


# -- Defaults -----------------------------------------------------------------------------------

def test_neighbours_queried_and_auto_count():
    assert neighbours_queried(32, 1.5) == 72
    assert neighbours_queried(10, 1.0) == 10
    assert neighbours_queried(5, 1.2) == 8
    # Three 10 m floors stacked (300 m^2): N = 72 A / (pi (0.01 extent)^2), inside 100k-1M.
    tris = np.concatenate([quad([0, 0, z], [5, 0, 0], [0, 5, 0]) for z in (0.0, 1.0, 2.0)])
    scene = _scene(tris)
    expected = 72 * 300.0 / (np.pi * (0.01 * scene.extent) ** 2)
    assert 100_000 < expected < 1_000_000
    assert auto_shadow_photon_count(scene) == int(expected)
    assert auto_shadow_photon_count(scene, k=16, margin=1.0) == max(int(16 * 300.0 / (np.pi * (0.01 * scene.extent) ** 2)), 100_000)
    one = _scene(tris[:2])
    assert auto_shadow_photon_count(one) == 100_000                    # 75k clipped up
    assert auto_shadow_photon_count(scene, k=320) == 1_000_000         # clipped down
    # The count depends on the scene's shape, not its size: the same at a millimetre scale.
    tiny = _scene(tris * np.float32(1e-3), eye=(0.0, -8e-3, 6e-3))
    assert auto_shadow_photon_count(tiny) == pytest.approx(int(expected), rel=1e-4)
    single = _scene(tris[:1])                                          # one triangle, 50 m^2
    count = neighbours_queried(96, 1.5) * 50.0 / (np.pi * (0.01 * single.extent) ** 2)
    assert 100_000 < count < 1_000_000
    assert auto_shadow_photon_count(single, k=96) == int(count)
    empty = Scene(triangles=np.zeros((0, 3, 3), np.float32), material_ids=np.zeros(0, np.int32),
                  materials=[Material("m")], camera=Camera.look_at([0, -1, 1], [0, 0, 0]))
    assert auto_shadow_photon_count(empty) == 100_000


def test_positioned_lights_and_luminance_flux():
    scene = _scene(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]),
                   [_area(), _area("Disk", shape="DISK"), SunLight("Sun", [0, 0, -1.0], [1.0] * 3, angle=0.1)],
                   world=World([0.1] * 3))
    lights = LightSet(scene)
    kinds = [positioned(light) for light in lights.sampled]
    assert kinds == [True, True, False, False]
    assert isinstance(lights.sampled[2], SunCone) and isinstance(lights.sampled[3], WorldLight)
    assert S._luminance_flux(lights.sampled[0]) == pytest.approx(100.0, rel=1e-9)
    dim = LightSet(_scene(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), [_area(power=0.25)])).sampled[0]
    assert S._luminance_flux(dim) == pytest.approx(0.25, rel=1e-9)


# -- Emission and tracing -----------------------------------------------------------------------

def test_emission_from_triangles_by_area_and_cosine():
    """A one-sided emitter of three triangles, 2, 0.5 and 1.5 m^2, facing down: photons start
    on them in proportion to area (binomial), area-uniform inside each (mean barycentric 1/3,
    SD of one 1/sqrt(18)), pushed off along the normal by the accel's offset, and leave
    downwards with mean cos 2/3 (SD of one 1/sqrt(18)). A two-sided emitter sends half each
    way."""
    big = np.array([[-1.0, -1.0, 2.0], [-1.0, 1.0, 2.0], [1.0, -1.0, 2.0]])      # 2 m^2, normal -z
    small = np.array([[3.0, 0.0, 2.0], [3.0, 1.0, 2.0], [4.0, 0.0, 2.0]])        # 0.5 m^2
    mid = np.array([[6.0, 0.0, 2.0], [6.0, 1.0, 2.0], [9.0, 0.0, 2.0]])          # 1.5 m^2
    light = TriangleEmitter("L", np.stack([big, small, mid]), [1.0, 1.0, 1.0], two_sided=False)
    assert np.allclose(light.normals, [0, 0, -1.0])
    accel = Accelerator(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), threads=1)
    n = 20_000
    o, d = S._emit(light, n, np.random.default_rng(1), accel)
    eps = accel.offset_distance(o)
    np.testing.assert_allclose(o[:, 2], 2.0 - eps, rtol=0, atol=1e-9)
    masks = (o[:, 0] < 2.0, (o[:, 0] > 2.0) & (o[:, 0] < 5.0), o[:, 0] > 5.0)
    for tri, mask, share in zip((big, small, mid), masks, (0.5, 0.125, 0.375)):
        assert abs(mask.mean() - share) < 5 * np.sqrt(share * (1 - share) / n)
        e1, e2 = tri[1, :2] - tri[0, :2], tri[2, :2] - tri[0, :2]
        ab = np.linalg.solve(np.column_stack([e1, e2]), (o[mask, :2] - tri[0, :2]).T).T
        bary = np.column_stack([1 - ab.sum(axis=1), ab])
        assert np.all(bary > -1e-9)
        assert np.all(np.abs(bary.mean(axis=0) - 1 / 3) < 5 / np.sqrt(18 * mask.sum()))
    cos = -d[:, 2]
    assert np.all(cos > 0) and abs(cos.mean() - 2 / 3) < 5 / np.sqrt(18 * n)
    two = TriangleEmitter("T", big[None], [1.0] * 3, two_sided=True)
    o2, d2 = S._emit(two, n, np.random.default_rng(2), accel)
    up = d2[:, 2] > 0
    assert abs(up.mean() - 0.5) < 5 * np.sqrt(0.25 / n)
    np.testing.assert_allclose(o2[:, 2], 2.0 + np.where(up, 1, -1) * accel.offset_distance(o2), atol=1e-9)


def test_emission_from_a_disk():
    scene = _scene(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), [_area("Disk", height=2.0, half=0.5, shape="DISK")])
    lights = LightSet(scene)
    accel = Accelerator(scene.triangles, threads=1)
    o, d = S._emit(lights.sampled[0], 5000, np.random.default_rng(3), accel)
    r = np.hypot(o[:, 0], o[:, 1])
    assert r.max() <= 0.5 + 1e-9 and r.max() > 0.49
    assert abs((r ** 2).mean() - 0.125) < 5 * 0.25 / np.sqrt(12 * 5000)
    # Both axes: x and y each have mean 0 and mean square R^2 / 4 over the disc.
    for c in (0, 1):
        assert abs(o[:, c].mean()) < 5 * 0.25 / np.sqrt(5000)
        assert abs((o[:, c] ** 2).mean() - 0.0625) < 5 * 0.0625 / np.sqrt(5000)
    np.testing.assert_allclose(o[:, 2], 2.0 - accel.offset_distance(o), atol=1e-9)
    assert np.all(d[:, 2] < 0) and abs(-d[:, 2].mean() - 2 / 3) < 5 / np.sqrt(18 * 5000)


def test_trace_through_stacked_planes():
    """Rays straight down through planes at z = 2, 1, 0: every crossing is kept with the
    number of surfaces before it; at max_crossings the rays still going are dropped."""
    tris = np.concatenate([quad([0, 0, z], [5, 0, 0], [0, 5, 0]) for z in (0.0, 1.0, 2.0)])
    scene = _scene(tris)
    accel = Accelerator(scene.triangles, threads=1)
    normals = scene.geometric_normals()
    n = 7
    o = np.column_stack([np.linspace(-1, 1, n), np.zeros(n), np.full(n, 3.0)])
    d = np.tile([0.0, 0, -1.0], (n, 1))
    x, ray, crossed, prim, traced, dropped = S._trace_through(accel, normals, o, d, 64)
    assert x.dtype == np.float32 and prim.dtype == np.int32 and crossed.dtype == np.uint8
    assert len(x) == 3 * n and traced == 4 * n and dropped == 0
    np.testing.assert_allclose(np.sort(x[:, 2]), np.repeat([0.0, 1.0, 2.0], n), atol=1e-5)
    np.testing.assert_allclose(x[:, 2], 2.0 - crossed, atol=1e-5)
    assert np.array_equal(np.sort(ray), np.repeat(np.arange(n), 3))
    np.testing.assert_allclose(x[:, 0], o[ray, 0], atol=1e-6)
    assert np.array_equal(prim // 2, 2 - crossed)                  # quads listed z = 0, 1, 2
    x, ray, crossed, prim, traced, dropped = S._trace_through(accel, normals, o, d, 2)
    assert len(x) == 2 * n and traced == 2 * n and dropped == n and crossed.max() == 1
    x, ray, crossed, prim, traced, dropped = S._trace_through(accel, normals, o, -d, 64)
    assert traced == n and dropped == 0 and x.shape == (0, 3) and x.dtype == np.float32
    for a, dtype in ((ray, np.int64), (crossed, np.uint8), (prim, np.int32)):
        assert a.shape == (0,) and a.dtype == dtype


def test_crossings_saturate_at_254():
    """A ray down through 260 stacked planes: the crossing count stops at 254 (one byte; 255
    is ``THROUGH_GLASS``)."""
    tris = np.concatenate([quad([0, 0, 0.01 * z], [1, 0, 0], [0, 1, 0]) for z in range(260)])
    scene = _scene(tris)
    accel = Accelerator(scene.triangles, threads=1)
    x, ray, crossed, prim, traced, dropped = S._trace_through(
        accel, scene.geometric_normals(), np.array([[0.1, 0.2, 3.0]]), np.array([[0.0, 0, -1.0]]), 300)
    assert len(x) == 260 and dropped == 0
    assert crossed.tolist() == list(range(254)) + [254] * 6


def test_hits_after_a_transmissive_surface_are_marked_through_glass():
    """Five stacked planes, the second (from the top) transmissive: the first two hits keep
    their counts, every hit below the glass is ``THROUGH_GLASS``."""
    tris = np.concatenate([quad([0, 0, 0.1 * z], [1, 0, 0], [0, 1, 0]) for z in range(5)])
    scene = _scene(tris)
    accel = Accelerator(scene.triangles, threads=1)
    glass = np.zeros(len(tris), bool)
    glass[[6, 7]] = True                     # the plane at z = 0.3, hit second from above
    _x, _ray, crossed, _prim, _traced, _dropped = S._trace_through(
        accel, scene.geometric_normals(), np.array([[0.1, 0.2, 3.0]]),
        np.array([[0.0, 0, -1.0]]), 10, glass)
    assert crossed.tolist() == [0, 1, S.THROUGH_GLASS, S.THROUGH_GLASS, S.THROUGH_GLASS]


# -- Classification on hand-made photons --------------------------------------------------------

DOWN = encode_directions(np.array([[0.0, 0.0, -1.0]]))[0]
UP = encode_directions(np.array([[0.0, 0.0, 1.0]]))[0]


def _grid_map(shadow, k=4, margin=1.0, spacing=0.1, side=11, lift=None, arrive=None, cap=np.inf,
              light=0):
    """Photons on an side x side grid of the plane z = 0 (spacing 0.1), arriving downwards,
    ``shadow(x, y)`` True where they crossed a surface first."""
    g = (np.arange(side) - side // 2) * spacing
    gx, gy = np.meshgrid(g, g)
    pos = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]).astype(np.float32)
    if lift is not None:
        pos[:, 2] = lift(pos[:, 0], pos[:, 1])
    codes = np.tile(DOWN, (len(pos), 1)) if arrive is None else arrive(pos)
    crossings = shadow(pos[:, 0], pos[:, 1]).astype(np.uint8)
    smap = ShadowPhotonMap(pos, codes.astype(np.int8), np.full(len(pos), light, np.uint8), crossings,
                           slices={light: (0, len(pos))}, k=k, margin=margin)
    if np.isfinite(cap):
        smap.radius[light] = cap
    return smap.build_trees()


def test_photon_classes_need_k_agreeing_photons():
    """k = 4 nearest (margin 1): at a grid photon's position its 4 nearest are itself and 3
    of its neighbours at 0.1 m. Left half direct, right half shadow: LIT far left, UMBRA far
    right, PENUMBRA where the 4 mix; the radius is the 4th neighbour's distance."""
    smap = _grid_map(lambda x, y: x > 0.05)
    pts = np.array([[-0.3, 0.0, 0], [0.3, 0.0, 0], [0.05, 0.0, 0], [-0.3, 0.02, 0]])
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    cls, rad = smap.classify_photons(pts, up, 0, return_radius=True)
    assert cls.tolist() == [LIT, UMBRA, PENUMBRA, LIT]
    assert rad.dtype == np.float32
    np.testing.assert_allclose(rad[:2], 0.1, rtol=1e-6)
    np.testing.assert_allclose(rad[3], np.hypot(0.1, 0.02), rtol=1e-6)
    # Seen from below nothing arrives on that side: PENUMBRA.
    assert np.all(smap.classify_photons(pts, -up, 0) == PENUMBRA)
    # A light without photons, and no points: PENUMBRA / empty.
    assert np.all(smap.classify_photons(pts, up, 3) == PENUMBRA)
    out, r = smap.classify_photons(np.zeros((0, 3)), np.zeros((0, 3)), 0, return_radius=True)
    assert len(out) == 0 and len(r) == 0
    st = smap.stats
    assert st["photons_classified"] == 8 and st["photons_classified_lit"] == 2
    assert st["photons_classified_umbra"] == 1 and st["photons_classified_penumbra"] == 5
    assert st["photons_classify_seconds"] >= 0


def test_photon_classes_within_the_cap_and_the_disc():
    """A radius cap below the grid spacing leaves one photon within reach (fewer than k):
    PENUMBRA, radius = the cap. Photons lifted out of the disc (height > disc x radius) do not
    count, so a point among lifted shadow photons and flat direct ones is LIT when the lifted
    ones are high, PENUMBRA when they lie inside the disc."""
    smap = _grid_map(lambda x, y: np.zeros_like(x, bool), cap=0.05)
    cls, rad = smap.classify_photons(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]), 0,
                                     return_radius=True)
    assert cls.tolist() == [PENUMBRA] and rad[0] == pytest.approx(0.05)
    # Shadow photons at (+-0.1, 0), lifted by h; k = 4 of the 8 nearest (margin sqrt(2)): the
    # point sits on a direct photon; the 8th neighbour, a diagonal one, sets r = 0.1414 and
    # the disc 0.25 r = 0.035. Lifted 0.06 the shadow photons are out of it (6 direct ones
    # count: LIT), lifted 0.02 they count (mixed: PENUMBRA).
    pair = lambda x, y: (np.abs(y) < 1e-6) & (np.abs(np.abs(x) - 0.1) < 1e-6)   # noqa: E731
    q, up = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]])
    for h, expect in ((0.06, LIT), (0.02, PENUMBRA)):
        smap = _grid_map(pair, k=4, margin=np.sqrt(2.0), lift=lambda x, y, h=h: np.where(pair(x, y), h, 0.0))
        cls, rad = smap.classify_photons(q, up, 0, return_radius=True)
        assert cls.tolist() == [expect], h
        assert rad[0] == pytest.approx(np.sqrt(0.02), rel=1e-5)
    # Direct photons that arrived upwards do not count for an upward normal.
    smap = _grid_map(lambda x, y: np.zeros_like(x, bool),
                     arrive=lambda p: np.where((p[:, :1] > 0.05), UP, DOWN))
    pts = np.array([[-0.02, 0.0, 0.0], [-0.3, 0.0, 0.0], [0.03, 0.0, 0.0], [0.3, 0.0, 0.0]])
    assert smap.classify_photons(pts, np.tile([0.0, 0.0, 1.0], (4, 1)), 0).tolist() == \
        [LIT, LIT, PENUMBRA, PENUMBRA]


def _with_reps(smap, rep_index, rep_class, rep_radius, light=0, lookup_k=4, margin=None):
    smap.rep_index = np.asarray(rep_index, np.int32)
    smap.rep_class = np.asarray(rep_class, np.int8)
    smap.rep_radius = np.asarray(rep_radius, np.float32)
    smap.rep_slices = {light: (0, len(rep_index))}
    smap.lookup_k = lookup_k
    if margin is not None:
        smap.margin = margin
    return smap.build_trees()


def test_representative_lookup_rules():
    """Four representatives at the corners of a 0.2 m square around the origin (0.1414 m
    away), each with radius 0.3: a point at the origin counts those within radius / margin;
    at least two must count, all of one class."""
    smap = _grid_map(lambda x, y: np.zeros_like(x, bool), margin=1.5)
    g = smap.positions
    corners = [int(np.flatnonzero(np.all(np.abs(g[:, :2] - c) < 1e-6, axis=1))[0])
               for c in ([-0.1, -0.1], [0.1, -0.1], [-0.1, 0.1], [0.1, 0.1])]
    q, up = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]])

    def cls(classes, radii, margin=1.5, normal=up, lookup_k=4):
        _with_reps(smap, corners, classes, radii, margin=margin, lookup_k=lookup_k)
        return int(smap.classify(q, normal, 0)[0])

    assert cls([LIT] * 4, [0.3] * 4) == LIT
    assert cls([UMBRA] * 4, [0.3] * 4) == UMBRA
    assert cls([LIT, LIT, LIT, UMBRA], [0.3] * 4) == PENUMBRA
    assert cls([LIT, LIT, LIT, PENUMBRA], [0.3] * 4) == PENUMBRA
    # Radius / margin: 0.3 / 1.5 = 0.2 > 0.1414 counts; 0.2 / 1.5 = 0.133 does not.
    assert cls([LIT, LIT, UMBRA, UMBRA], [0.3, 0.3, 0.2, 0.2]) == LIT
    assert cls([LIT, LIT, UMBRA, UMBRA], [0.3, 0.2, 0.2, 0.2]) == PENUMBRA       # only one
    assert cls([LIT] * 4, [0.3] * 4, margin=2.2) == PENUMBRA                      # 0.136 < 0.141
    assert cls([LIT] * 4, [0.3] * 4, normal=-up) == PENUMBRA                      # wrong side
    assert cls([LIT] * 4, [0.3] * 4, lookup_k=1) == LIT                           # min(2, k) = 1
    # The disc: the point 0.08 above the plane is out of the disc of 0.25 x 0.3 = 0.075.
    _with_reps(smap, corners, [LIT] * 4, [0.3] * 4, margin=1.0)
    assert smap.classify(np.array([[0.0, 0.0, 0.07]]), up, 0).tolist() == [LIT]
    assert smap.classify(np.array([[0.0, 0.0, 0.08]]), up, 0).tolist() == [PENUMBRA]
    # Many points (more than one chunk of 8192), out of order: each gets its own class.
    _with_reps(smap, corners, [LIT, UMBRA, LIT, UMBRA], [0.15] * 4, margin=1.0)
    xs = np.tile([[-0.1, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.0]], (3000, 1))
    out = smap.classify(xs, np.tile(up, (9000, 1)), 0)
    assert out.tolist() == [LIT, UMBRA, PENUMBRA] * 3000
    st = smap.stats
    assert st["classified"] >= 9000 and st["classified_lit"] >= 3000 and st["classify_seconds"] >= 0
    assert not smap.covers(1) and smap.covers(0)
    assert np.all(smap.classify(xs[:5], np.tile(up, (5, 1)), 1) == PENUMBRA)
    assert len(smap.classify(np.zeros((0, 3)), np.zeros((0, 3)), 0)) == 0


def test_map_round_trip_and_bytes():
    smap = _grid_map(lambda x, y: x > 0, cap=0.5)
    _with_reps(smap, [0, 5, 9], [LIT, UMBRA, PENUMBRA], [0.1, 0.2, 0.3], lookup_k=3)
    smap.penumbra_factor, smap.disc = 3, 0.2
    smap.stats["x"] = 1
    assert smap.nbytes == 121 * 16 + 3 * 9 and len(smap) == 121
    arrays = smap.to_arrays()
    back = ShadowPhotonMap.from_arrays(arrays)
    for key in ShadowPhotonMap.ARRAY_FIELDS:
        assert np.array_equal(getattr(back, key), getattr(smap, key))
        assert getattr(back, key).dtype == getattr(smap, key).dtype
    assert back.slices == smap.slices and back.rep_slices == smap.rep_slices
    assert back.radius == {0: 0.5} and back.stats == smap.stats
    for key in ShadowPhotonMap.SCALAR_FIELDS:
        assert getattr(back, key) == getattr(smap, key) and type(getattr(back, key)) is type(getattr(smap, key))
    assert back.covers(0)
    q = np.array([[0.0, 0.0, 0.0], [0.4, 0.1, 0.0]])
    np.testing.assert_array_equal(back.classify(q, np.tile([0, 0, 1.0], (2, 1)), 0),
                                  smap.classify(q, np.tile([0, 0, 1.0], (2, 1)), 0))
    assert not ShadowPhotonMap.from_arrays(arrays, build=False).covers(0)
    e = empty_map(k=7)
    assert len(e) == 0 and e.k == 7 and e.nbytes == 0
    for key, dtype, shape in (("positions", np.float32, (0, 3)), ("directions", np.int8, (0, 2)),
                              ("light", np.uint8, (0,)), ("crossings", np.uint8, (0,))):
        assert getattr(e, key).dtype == dtype and getattr(e, key).shape == shape, key
    # A light whose slice is empty gets no tree: it is not covered.
    smap.slices[1], smap.rep_slices[1] = (5, 5), (2, 2)
    smap.build_trees()
    assert smap.covers(0) and not smap.covers(1) and 1 not in smap._trees


# -- The whole build ----------------------------------------------------------------------------

def test_build_shares_caps_and_stats():
    """Two square lights of 100 W and 800 W over a floor: photons in proportion to flux^(2/3)
    (1 : 4), every photon stored on the floor as direct; radius cap per light
    min(3 sqrt(K A / (pi N_l)), 3 % of the extent); every rep_stride-th photon a
    representative; the stats add up."""
    scene = _scene(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]),
                   [_area("Dim", power=100.0, x=-2.0), _area("Bright", power=800.0, x=2.0)])
    lights = LightSet(scene)
    accel = Accelerator(scene.triangles, threads=1)
    smap = build_shadow_photon_map(scene, accel, lights, 10_000, seed=1, rep_stride=3, k=8, margin=1.0)
    st = smap.stats
    assert st["photons_per_light"] == {"Dim": 2000, "Bright": 8000}
    assert st["requested"] == 10_000 and st["emitted"] == 10_000 and st["k"] == 8
    assert st["neighbours"] == 8 and st["rep_stride"] == 3 and st["margin"] == 1.0
    assert st["stored"] == len(smap) == st["stored_direct"] + st["stored_shadow"]
    assert st["stored_shadow"] == 0 and st["dropped"] == 0 and st["lights_switched_off"] == []
    assert st["rays"] >= st["emitted"]
    for li, (name, count) in enumerate((("Dim", 2000), ("Bright", 8000))):
        a, b = smap.slices[li]
        per = st["lights"][li]
        assert per["name"] == name and per["emitted"] == count
        assert per["stored_direct"] == b - a and per["stored_shadow"] == 0
        assert np.all(smap.light[a:b] == li)
        expect = min(3.0 * np.sqrt(8 * 100.0 / (np.pi * (b - a))), 0.03 * scene.extent)
        assert smap.radius[li] == pytest.approx(expect, rel=1e-12) and per["radius"] == smap.radius[li]
        ra, rb = smap.rep_slices[li]
        assert rb - ra == len(range(a, b, 3))
        assert np.array_equal(smap.rep_index[ra:rb], np.arange(a, b, 3))
        assert sum(per["representatives"].values()) == rb - ra
        assert set(per["representatives"]) == {"lit", "umbra", "penumbra"}
    assert st["representatives"] == len(smap.rep_index)
    assert st["bytes"] == smap.nbytes and st["bytes_per_photon"] == 16.0
    assert st["representative_bytes"] == 9 * len(smap.rep_index)
    assert not any(key.startswith("photons_classif") for key in st)
    for key in ("emit_seconds", "trace_seconds", "index_seconds", "representative_seconds", "build_seconds"):
        assert st[key] >= 0
    # Open floor, nothing in the way: every representative with its k photons is LIT.
    assert np.count_nonzero(smap.rep_class == UMBRA) == 0 and np.mean(smap.rep_class == LIT) > 0.9
    # A given cap replaces the automatic one.
    capped = build_shadow_photon_map(scene, accel, lights, 2000, seed=1, max_radius=0.07)
    assert capped.radius == {0: 0.07, 1: 0.07}


def test_build_options_are_clamped_and_kept():
    scene = _scene(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), [_area()])
    lights = LightSet(scene)
    accel = Accelerator(scene.triangles, threads=1)
    smap = build_shadow_photon_map(scene, accel, lights, 500, k=0, margin=0.5, rep_stride=0,
                                   penumbra_factor=0, lookup_k=0, disc=0.3)
    assert (smap.k, smap.margin, smap.penumbra_factor, smap.lookup_k, smap.disc) == (1, 1.0, 1, 1, 0.3)
    assert smap.stats["rep_stride"] == 1 and len(smap.rep_index) == len(smap)
    smap = build_shadow_photon_map(scene, accel, lights, 500, k=5, margin=2.0, penumbra_factor=3,
                                   lookup_k=6)
    assert (smap.k, smap.margin, smap.penumbra_factor, smap.lookup_k) == (5, 2.0, 3, 6)
    assert smap.stats["rep_stride"] == S.REP_STRIDE
    auto = build_shadow_photon_map(scene, accel, lights, 0, k=4, margin=1.0)
    assert auto.stats["requested"] == auto_shadow_photon_count(scene, 4, 1.0)
    dark = build_shadow_photon_map(scene, accel, lights, -5)
    assert len(dark) == 0 and dark.stats["emitted"] == 0 and "build_seconds" in dark.stats


def test_emitted_photons_cross_an_occluder():
    """A plate between the light and the floor: photons that hit it go on to the floor as
    shadow photons (crossings 1); those on the plate are direct; a second plate under the
    first makes floor photons under both cross 2 surfaces."""
    plate = quad([0, 0, 1.5], [0.5, 0, 0], [0, 0.5, 0])
    low = quad([0, 0, 0.5], [0.25, 0, 0], [0, 0.25, 0])
    scene = _scene(np.concatenate([quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), plate, low]), [_area()])
    smap = build_shadow_photon_map(scene, Accelerator(scene.triangles, threads=1), LightSet(scene),
                                   20_000, seed=2)
    z = smap.positions[:, 2]
    assert np.all(smap.crossings[np.abs(z - 1.5) < 1e-3] == 0)
    on_low = np.abs(z - 0.5) < 1e-3
    assert set(np.unique(smap.crossings[on_low]).tolist()) <= {0, 1} and smap.crossings[on_low].max() == 1
    floor = np.abs(z) < 1e-3
    assert smap.crossings[floor].max() == 2
    inside = floor & (np.abs(smap.positions[:, 0]) < 0.2) & (np.abs(smap.positions[:, 1]) < 0.2)
    assert np.all(smap.crossings[inside] >= 1)
    assert smap.stats["stored_shadow"] == np.count_nonzero(smap.crossings > 0)
    # Directions kept per photon: every photon travelled downwards.
    assert np.all(decode_directions(smap.directions)[:, 2] < 0)


def test_value_problems_name_options_out_of_range():
    """A sound saved map has no problem; options outside their ranges (or not finite) are
    each named; the classification's seconds lie within the wall time measured around it."""
    import time
    smap = _grid_map(lambda x, y: x > 0, cap=0.5)
    _with_reps(smap, [0, 5, 9], [LIT, UMBRA, PENUMBRA], [0.1, 0.2, 0.3], lookup_k=3)
    t0 = time.perf_counter()
    smap.classify(np.zeros((50, 3)), np.tile([0, 0, 1.0], (50, 1)), 0)
    wall = time.perf_counter() - t0
    assert 0 <= smap.stats["classify_seconds"] <= wall
    arrays = smap.to_arrays()
    assert ShadowPhotonMap.value_problems(arrays) == []
    bad = dict(arrays, k=np.array(0), penumbra_factor=np.array(1025), margin=np.array(np.nan),
               disc=np.array(np.inf))
    assert ShadowPhotonMap.value_problems(bad) == [
        "k = 0 is outside [1, 10000]", "penumbra_factor = 1025 is outside [1, 1024]",
        "margin = nan is outside [0, 1e+06]", "disc = inf is outside [1e-06, 1e+06]"]


def test_a_dim_light_gets_shadow_photons_and_the_build_times_add_up():
    """A 0.5 W square light (luminance flux 0.5: dim, not dark) gets every photon and is
    covered; each phase's seconds lie within the wall time measured around the build."""
    import time
    scene = _scene(quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), [_area("Dim", power=0.5)])
    lights = LightSet(scene)
    accel = Accelerator(scene.triangles, threads=1)
    t0 = time.perf_counter()
    smap = build_shadow_photon_map(scene, accel, lights, 2000, seed=2)
    wall = time.perf_counter() - t0
    assert smap.covers(0) and smap.stats["photons_per_light"] == {"Dim": 2000}
    for key in ("emit_seconds", "trace_seconds", "index_seconds", "representative_seconds",
                "build_seconds"):
        assert 0 <= smap.stats[key] <= wall, key
