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


# --- at render time: hits on tubes (engine/surfaces.py, engine/indirect.py) ----------------
def tube_scene(turns=12, r=0.1):
    """``turns`` vertical tubes of radius ``r`` (each turned by its own fraction of a side),
    far apart along x, as a validated Scene with the strand flags set."""
    from lanterna.engine.scene import Camera, Material, Scene
    n = turns
    x = np.arange(n) * 1.0
    points = np.stack([np.repeat(x, 2), np.zeros(2 * n), np.tile([-2.0, 2.0], n)], axis=1)
    tubes = hair.tessellate_curves(points, np.full(2 * n, r), np.arange(0, 2 * n + 1, 2))
    tris = tubes.vertices[tubes.triangles]
    scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("hair")],
                  camera=Camera.look_at((0, -5, 0), (0, 0, 0)),
                  shading_normals=tubes.normals[tubes.triangles],
                  strands=np.ones(len(tris), bool)).validate()
    return scene, x


@pytest.mark.parametrize("light_deg", [0, 60])
def test_a_tube_hit_takes_the_round_curves_normal_for_its_ray(light_deg):
    """Parallel rays across tubes: the mean of max(0, n . l) over the silhouette (a pixel
    row's diffuse shading) is the round curve's, within 1.5 %; the corner normals'
    interpolation gives 3.6 % less for a light behind the viewer (a hexagon's faces hold too
    few normals that face it)."""
    from lanterna.engine.accel import Accelerator
    from lanterna.engine.surfaces import SceneSurfaces
    r = 0.1
    scene, centres = tube_scene(r=r)
    accel, surfaces = Accelerator(scene.triangles), SceneSurfaces(scene)
    b = np.linspace(-0.12, 0.12, 4801)
    db = b[1] - b[0]
    a = math.radians(light_deg)
    light = np.array([math.sin(a), -math.cos(a), 0.0])
    # The integral of max(0, cos(theta - a)) cos(theta) over the visible half, closed form.
    round_curve = 0.5 * (math.sin(a) + (math.pi - a) * math.cos(a))
    rounded, interpolated = [], []
    for c in centres:
        o = np.stack([c + b, np.full_like(b, -5.0), np.zeros_like(b)], 1).astype(np.float32)
        d = np.tile(np.float32([0, 1, 0]), (len(b), 1))
        _t, prim, bu, bv = accel.intersect(o, d, np.full(len(b), 1e30, np.float32))
        hit = prim >= 0
        normals = surfaces.strand_normals(prim[hit], bu[hit], bv[hit], d[hit])
        _ng, ns, _front = surfaces.normals(prim[hit], bu[hit], bv[hit], d[hit])
        rounded.append(np.maximum(normals @ light, 0).sum() * db / r)
        interpolated.append(np.maximum(ns @ light, 0).sum() * db / r)
    assert np.mean(rounded) == pytest.approx(round_curve, rel=0.015)
    if light_deg == 0:
        assert np.mean(interpolated) < 0.975 * round_curve


def test_strand_flags_follow_the_triangles_the_scene_keeps():
    from lanterna.engine.scene import Camera, Material, Scene, SceneError
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                     [[0, 0, 0], [1, 0, 0], [2, 0, 0]],          # zero area: dropped
                     [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], np.float32)
    make = lambda flags: Scene(triangles=tris, material_ids=np.zeros(3, np.int32),
                               materials=[Material("m")],
                               camera=Camera.look_at((0, 0, 5), (0, 0, 0)), strands=flags)
    scene = make(np.array([False, True, True])).validate()
    assert scene.strands.tolist() == [False, True]
    assert make(np.array([False, True, False])).validate().strands is None   # none left
    with pytest.raises(SceneError):
        make(np.array([True, False])).validate()


def test_hair_gathers_per_sample_instead_of_a_record_at_nearly_every_sample(monkeypatch):
    """A strand's normal turns all the way round within a pixel, so the irradiance cache's
    records serve almost no neighbour on hair: 400 strands over a floor made 2,244 records
    and 2.8 M gather rays in the camera stage. Hair samples gather with M/4 x N/4 rays each:
    a tenth of the rays, the same picture (means within 0.4 %; the other render asks the
    cache for hair samples too, all else alike)."""
    from lanterna.engine import indirect
    from lanterna.engine.pipeline import RenderSettings, render
    from lanterna.engine.scene import Camera, Material, Scene, SunLight
    rng = np.random.default_rng(3)
    n = 400
    roots = np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), np.zeros(n)], 1)
    tips = roots + np.stack([rng.normal(0, 0.1, n), rng.normal(0, 0.1, n), np.full(n, 0.4)], 1)
    points = np.stack([roots, (roots + tips) / 2, tips], 1).reshape(-1, 3)
    tubes = hair.tessellate_curves(points, np.tile([0.01, 0.007, 0.0], n),
                                   np.arange(0, 3 * n + 1, 3))
    floor = np.float32([[[-3, -3, 0], [3, -3, 0], [3, 3, 0]], [[-3, -3, 0], [3, 3, 0], [-3, 3, 0]]])
    count = len(tubes.triangles)
    sun = np.array([0.3, 0.4, -0.8]) / np.linalg.norm([0.3, 0.4, -0.8])
    scene = Scene(triangles=np.concatenate([floor, tubes.vertices[tubes.triangles]]),
                  material_ids=np.r_[np.zeros(2, np.int32), np.ones(count, np.int32)],
                  materials=[Material("floor", diffuse=np.full(3, 0.5)),
                             Material("hair", diffuse=np.array([0.6, 0.4, 0.2]))],
                  camera=Camera.look_at((0, -2.0, 1.0), (0, 0, 0.2), fov_x_deg=50,
                                        resolution=(48, 36)),
                  shading_normals=np.concatenate([np.tile(np.float32([0, 0, 1]), (2, 3, 1)),
                                                  tubes.normals[tubes.triangles]]),
                  strands=np.r_[np.zeros(2, bool), np.ones(count, bool)],
                  lights=[SunLight("Sun", direction=sun, irradiance=np.full(3, 3.0))])
    settings = RenderSettings(samples=16, light_samples=2, photons=50000, gather_m=8,
                              gather_n=32, cache_error=0.1, indirect="cache", seed=1)
    flagged = render(scene, settings)
    monkeypatch.setattr(indirect.CachedIndirect, "_with_strands",
                        lambda self, x, ns, ng, rng, stats, strands:
                        self.irradiance(x, ns, ng, rng, stats))
    plain = render(scene, settings)
    ours, theirs = flagged.report["stages"]["camera"], plain.report["stages"]["camera"]
    assert ours["strand_gathered"] > 1000 and theirs["strand_gathered"] == 0
    assert ours["gather_rays"] < 0.2 * theirs["gather_rays"]
    assert ours["cache_local_records"] < 0.2 * theirs["cache_local_records"]
    np.testing.assert_allclose(np.asarray(flagged.image).mean((0, 1)),
                               np.asarray(plain.image).mean((0, 1)), rtol=0.015)


def random_tufts(count=3000, seed=5, r=0.01):
    """``count`` straight strands of radius ``r`` at random in the unit cube, random
    directions, 0.3 m long: (tubes, triangles (T, 3, 3))."""
    rng = np.random.default_rng(seed)
    start = rng.random((count, 3))
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    points = np.stack([start, start + 0.3 * direction], axis=1).reshape(-1, 3)
    tubes = hair.tessellate_curves(points, np.full(2 * count, r), np.arange(0, 2 * count + 1, 2))
    return tubes, tubes.vertices[tubes.triangles].astype(np.float64)


def test_strand_estimates_divide_the_flux_on_strands_by_their_area_and_keep_its_direction():
    """Photons spread evenly over a tangle's strand area, each of power P, all falling
    straight down: the flux density is F = N P / A whatever the strands' orientations, and
    the estimate of E(n) = F + 2F z . n (the light's direction, up). Measured: the mean
    base within 2 % of F (1.001 F), the mean slope within 5 % of 2F along +z (the surface
    estimate at the same photons, k = 50 in its disc: 0.75 F; counting the estimate's own
    photon and the k-th area point's share: 1.049 F)."""
    from lanterna.engine.gather import StrandEstimates
    from lanterna.engine.photons import PhotonMap
    tubes, tris = random_tufts()
    rng = np.random.default_rng(6)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    n = 60000
    pick = rng.choice(len(tris), n, p=area / area.sum())
    u = rng.random((n, 2))
    root = np.sqrt(u[:, 0])
    positions = (tris[pick, 0] * (1 - root)[:, None] + tris[pick, 1] * (root * (1 - u[:, 1]))[:, None]
                 + tris[pick, 2] * (root * u[:, 1])[:, None])
    power = np.full((n, 3), 1e-3)
    flux_density = n * 1e-3 / area.sum()
    face = np.cross(tris[pick, 1] - tris[pick, 0], tris[pick, 2] - tris[pick, 0])
    face /= np.linalg.norm(face, axis=1)[:, None]
    face *= np.where(face[:, 2] > 0, 1.0, -1.0)[:, None]         # the side facing the light
    pmap = PhotonMap(positions.astype(np.float32), power.astype(np.float32),
                     np.tile(np.float16([0, 0, -1]), (n, 1)), face.astype(np.float16),
                     np.zeros(n, np.uint8))
    from lanterna.engine.accel import Accelerator
    est = StrandEstimates.build(pmap, Accelerator(tris.astype(np.float32)), tris,
                                np.ones(len(tris), bool))
    assert len(est) == n // 4 and est.stats["strand_photons"] == n
    assert est.stats["full_spheres"] == 0
    np.testing.assert_allclose(est.base.mean(axis=0), flux_density, rtol=0.02)
    np.testing.assert_allclose(est.slope.mean(axis=0)[:, 2], 2 * flux_density, rtol=0.05)
    assert np.abs(est.slope.mean(axis=0)[:, :2]).max() < 0.05 * flux_density
    up = est.lookup(positions[:500], np.tile([0.0, 0.0, 1.0], (500, 1)))
    down = est.lookup(positions[:500], np.tile([0.0, 0.0, -1.0], (500, 1)))
    assert up.mean() == pytest.approx(3 * flux_density, rel=0.05) and down.mean() < 0.1 * up.mean()


def test_photons_between_strands_are_no_crevice():
    """A floor under a tube 5 mm above it: without the strand flag the floor's photons under
    the tube are in a crevice (an occluder closer than the photons' spacing) and dropped;
    flagged as hair, they are kept."""
    import dataclasses
    from lanterna.engine.accel import Accelerator
    from lanterna.engine.photons import PhotonMap, in_crevice
    from lanterna.engine.scene import Camera, Material, Scene
    tubes = hair.tessellate_curves([[-1, 0, 0.015], [1, 0, 0.015]], [0.01, 0.01], [0, 2])
    floor = np.float32([[[-2, -2, 0], [2, -2, 0], [2, 2, 0]], [[-2, -2, 0], [2, 2, 0], [-2, 2, 0]]])
    tris = np.concatenate([floor, tubes.vertices[tubes.triangles]])
    strands = np.r_[np.zeros(2, bool), np.ones(len(tubes.triangles), bool)]
    scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("m")], camera=Camera.look_at((0, -3, 1), (0, 0, 0)),
                  strands=strands).validate()
    under = np.float32([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 1.0, 0.0]])
    pmap = PhotonMap(under, np.ones((3, 3), np.float32), np.tile(np.float16([0, 0, -1]), (3, 1)),
                     np.tile(np.float16([0, 0, 1]), (3, 1)), np.zeros(3, np.uint8))
    accel = Accelerator(scene.triangles)
    assert in_crevice(dataclasses.replace(scene, strands=None), accel, pmap).tolist() \
        == [True, True, False]
    assert in_crevice(scene, accel, pmap).tolist() == [False, False, False]


def test_a_saved_map_of_the_same_triangles_without_hair_is_not_reused():
    """Hair changes which photons are kept and how they are estimated: the artifacts'
    geometry fingerprint takes the strand flags (and is unchanged without hair)."""
    import dataclasses
    from lanterna.engine.artifacts import scene_parts
    scene, _ = tube_scene(turns=2)
    plain = dataclasses.replace(scene, strands=None)
    assert scene_parts(scene)["geometry"] != scene_parts(plain)["geometry"]
    assert scene_parts(scene)["materials"] == scene_parts(plain)["materials"]


def test_beyond_the_budget_one_curve_in_k_is_drawn_and_said():
    points = np.stack([np.repeat(np.arange(100.0), 2), np.zeros(200), np.tile([0.0, 1.0], 100)], 1)
    least = 100 * (2 * 3 + 2 * 1)                  # three sides, one piece, two caps each
    tubes = hair.tessellate_curves(points, np.full(200, 0.01), np.arange(0, 201, 2),
                                   max_triangles=least // 4)
    assert len(tubes.triangles) <= least // 4
    assert np.unique(tubes.vertex_curves).tolist() == list(range(0, 100, 4))
    assert any("25 of 100 curves drawn (one in 4)" in n for n in tubes.notes)

