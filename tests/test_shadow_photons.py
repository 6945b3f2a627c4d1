"""Shadow photons (seed 7.2, 9.6): classes against exact visibility, and direct light with and
without the map (no bpy).

The scene: a 10 m floor, a 1 m square area light 3 m above it facing down, and a 1 m square
occluder (one quad) half way between. From a floor point p the occluder's shadow on the light's
plane is a square, so the occluded share of the light's area is a product of two interval
overlaps (``occluded_share``): 0 lit, 1 umbra, penumbra in between.

Tolerances
* Lit and umbra points: the two estimates have the same expectation there (visibility is
  exactly 1 or 0), so they must agree within noise: every point within 5 combined standard
  errors (measured from the spread of the repeats: P(|z| > 5) = 6e-7 a point, so 1600 points
  fail by chance about once in a thousand runs), region means within 4.
* Penumbra: the classes are a decision from neighbouring photons, biased where a point of
  visibility near 0 or 1 is called UMBRA or LIT; the region mean must be within 2 %, and the
  test first checks that its standard error is below a third of that.
* At least 80 % of the shadow rays a plain call traces are saved on this scene (printed).
"""
import numpy as np
import pytest

from analytic import quad
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.direct import direct_irradiance
from lanterna.engine.lights import LightSet
from lanterna.engine.scene import AreaLight, Camera, Material, Scene, SunLight, World
from lanterna.engine.shadow_photons import (LIT, PENUMBRA, UMBRA, build_shadow_photon_map,
                                            decode_directions, encode_directions)

H, A, OCC_H, B = 3.0, 0.5, 1.5, 0.5        # light height, half size; occluder height, half size


def _light(height=H, half=A, power=100.0):
    m = np.eye(4)
    m[:3, 3] = [0, 0, height]
    return AreaLight("Area", "SQUARE", m, 2 * half, 2 * half, [power] * 3)


def _scene(extra_tris=(), lights=None, materials=None, material_ids=None, world=None):
    floor = quad([0, 0, 0], [5, 0, 0], [0, 5, 0])
    tris = np.concatenate([floor, *extra_tris]) if len(extra_tris) else floor
    mats = materials or [Material("white")]
    mids = np.zeros(len(tris), np.int32) if material_ids is None else material_ids
    return Scene(triangles=tris, material_ids=mids, materials=mats,
                 camera=Camera.look_at([0, -8, 6], [0, 0, 0]),
                 lights=[_light()] if lights is None else lights,
                 world=world or World()).validate()


def _occluder():
    return quad([0, 0, OCC_H], [B, 0, 0], [0, B, 0])


def occluded_share(px, py):
    """Share of the light's area hidden by the occluder from floor points (px, py, 0)."""
    s = H / OCC_H

    def overlap(p):
        lo, hi = p + (-B - p) * s, p + (B - p) * s
        return np.clip(np.minimum(hi, A) - np.maximum(lo, -A), 0, None) / (2 * A)
    return overlap(px) * overlap(py)


def _floor_grid(side, half=4.9):
    g = np.linspace(-half, half, side)
    gx, gy = np.meshgrid(g, g)
    x = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    return x, np.tile([0.0, 0.0, 1.0], (len(x), 1))


@pytest.fixture(scope="module")
def occluder_setup():
    scene = _scene([_occluder()])
    accel = Accelerator(scene.triangles, threads=2)
    lights = LightSet(scene)
    smap = build_shadow_photon_map(scene, accel, lights, 0, seed=1)
    return scene, accel, lights, smap


def test_octahedral_code_keeps_the_side():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    back = decode_directions(encode_directions(d))
    back /= np.linalg.norm(back, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d, back), -1, 1)))
    assert angle.max() < 1.5
    n = rng.normal(size=(20000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", d, n)
    clear = np.abs(cos) > 0.03                    # farther than ~1.7 degrees from grazing
    assert np.array_equal(np.einsum("ij,ij->i", back, n)[clear] < 0, cos[clear] < 0)


def test_map_contents_and_stats(occluder_setup):
    scene, accel, lights, smap = occluder_setup
    st = smap.stats
    assert st["bytes_per_photon"] == 16.0
    assert smap.covers(0) and st["photons_per_light"] == {"Area": st["emitted"]}
    assert st["stored"] == st["stored_direct"] + st["stored_shadow"] == len(smap)
    assert st["stored_shadow"] > 0 and st["dropped"] == 0
    # Shadow photons lie on the floor inside the occluder's penumbra (|x|, |y| < 1.5 m).
    shadow = smap.positions[smap.crossings > 0]
    assert np.all(np.abs(shadow[:, 2]) < 1e-3) and np.all(np.abs(shadow[:, :2]) < 1.5 + 1e-3)
    # Direct photons on the occluder: the share of the cosine emission it intercepts.
    on_occ = np.abs(smap.positions[:, 2] - OCC_H) < 1e-3
    assert np.all(smap.crossings[on_occ] == 0)
    assert abs(on_occ.sum() - st["stored_shadow"]) <= 3 * np.sqrt(st["stored_shadow"])


def test_classes_against_exact_visibility(occluder_setup):
    scene, accel, lights, smap = occluder_setup
    x, n = _floor_grid(300)
    f = occluded_share(x[:, 0], x[:, 1])
    cls = smap.classify(x, n, 0)
    lit, umbra, pen = f == 0, f == 1, (f > 0) & (f < 1)
    # Never the opposite class; the undecided band stays narrow.
    assert not np.any(cls[lit] == UMBRA) and not np.any(cls[umbra] == LIT)
    assert np.mean(cls[lit] == LIT) > 0.97
    assert np.mean(cls[umbra] == UMBRA) > 0.7
    # Penumbra points given a class are close to its visibility.
    assert np.all(f[pen & (cls == LIT)] < 0.1)
    assert np.all(f[pen & (cls == UMBRA)] > 0.9)
    # The representatives never decide where the photons themselves do not.
    direct = smap.classify_photons(x, n, 0)
    assert not np.any((cls == LIT) & (direct == UMBRA)) and not np.any((cls == UMBRA) & (direct == LIT))
    # Points facing away from the light see no photons arriving: unknown, traced.
    assert np.all(smap.classify(x, -n, 0) == PENUMBRA)


def test_direct_light_with_and_without_shadow_map(occluder_setup):
    scene, accel, lights, smap = occluder_setup
    x, n = _floor_grid(40)
    f = occluded_share(x[:, 0], x[:, 1])
    repeats, k = 32, 4
    xs = np.repeat(x[None], repeats, 0).reshape(-1, 3)
    ns = np.repeat(n[None], repeats, 0).reshape(-1, 3)
    plain_stats, map_stats = {}, {}
    plain = direct_irradiance(xs, ns, lights, accel, sampling.rng_for(3, 9), k,
                              stats=plain_stats)[:, 0].reshape(repeats, -1)
    fast = direct_irradiance(xs, ns, lights, accel, sampling.rng_for(4, 9), k, stats=map_stats,
                             shadow_map=smap)[:, 0].reshape(repeats, -1)
    var = plain.var(axis=0, ddof=1) / repeats + fast.var(axis=0, ddof=1) / repeats
    diff = fast.mean(axis=0) - plain.mean(axis=0)
    lit, umbra, pen = f == 0, f == 1, (f > 0) & (f < 1)
    assert lit.sum() > 1000 and umbra.sum() >= 16 and pen.sum() >= 64
    for name, mask in (("lit", lit), ("umbra", umbra)):
        se = np.sqrt(var[mask])
        assert np.all(np.abs(diff[mask]) <= 5 * se + 1e-12), name
        region_se = np.sqrt(var[mask].sum()) / mask.sum()
        assert abs(diff[mask].mean()) <= 4 * region_se + 1e-12, name
    assert np.all(fast[:, umbra] == 0) and np.all(plain[:, umbra] == 0)
    pen_mean = plain[:, pen].mean()
    region_se = np.sqrt(var[pen].sum()) / pen.sum()
    assert region_se < 0.02 / 3 * pen_mean, "too noisy to decide"
    assert abs(fast[:, pen].mean() / pen_mean - 1) < 0.02

    # Rays: the same light samples, counted against the plain call.
    assert plain_stats["shadow_rays"] == repeats * len(x) * k
    saved = map_stats["shadow_rays_saved"] / plain_stats["shadow_rays"]
    assert map_stats["shadow_rays"] + map_stats["shadow_rays_saved"] == plain_stats["shadow_rays"]
    assert map_stats["shadow_lit"] + map_stats["shadow_umbra"] + map_stats["shadow_penumbra"] \
        == repeats * len(x)
    print(f"\nshadow rays saved: {100 * saved:.1f} % (penumbra factor {smap.penumbra_factor}); "
          f"classes lit/umbra/penumbra {map_stats['shadow_lit']}/{map_stats['shadow_umbra']}/"
          f"{map_stats['shadow_penumbra']}")
    assert saved >= 0.80


def test_penumbra_factor_one_traces_the_same_samples(occluder_setup):
    """With M = 1 penumbra pairs keep their own samples: the traced rays are exactly the
    plain call's rays of PENUMBRA pairs, and the random numbers are those of a plain call."""
    scene, accel, lights, smap = occluder_setup
    x, n = _floor_grid(30)
    saved_factor = smap.penumbra_factor
    smap.penumbra_factor = 1
    try:
        st = {}
        e1 = direct_irradiance(x, n, lights, accel, sampling.rng_for(5, 9), 4, stats=st, shadow_map=smap)
    finally:
        smap.penumbra_factor = saved_factor
    e0 = direct_irradiance(x, n, lights, accel, sampling.rng_for(5, 9), 4)
    cls = smap.classify(x, n, 0)
    # Where the pair is PENUMBRA, the same samples are traced: identical results.
    np.testing.assert_allclose(e1[cls == PENUMBRA], e0[cls == PENUMBRA], rtol=1e-12)
    assert np.all(e1[cls == UMBRA] == 0)
    assert st["shadow_rays"] == 4 * np.count_nonzero(cls == PENUMBRA)


def test_thin_plate_is_umbra_below_never_lit():
    """A single quad 1 m above the floor, 2 m wide, under the light: the floor below it is
    UMBRA; the plate's underside (normal down) receives no photon from the side it faces,
    so it is never LIT although the plate's top, a float's width away, is."""
    plate = quad([0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0])
    scene = _scene([plate])
    accel = Accelerator(scene.triangles, threads=1)
    lights = LightSet(scene)
    smap = build_shadow_photon_map(scene, accel, lights, 0, seed=2)
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.9, 0.9, (2000, 2))
    up = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    floor = np.column_stack([xy, np.zeros(len(xy))])
    top = np.column_stack([xy, np.ones(len(xy))])
    floor_cls = smap.classify(floor, up, 0)
    assert np.all(floor_cls == UMBRA)
    assert np.mean(smap.classify(top, up, 0) == LIT) > 0.95
    below = smap.classify(top, -up, 0)
    assert not np.any(below == LIT)

    # A sheet 1 mm above the floor: the floor under it is never LIT (its own shadow photons
    # mix with the sheet's direct ones, so it is traced), and the floor around it still is.
    sheet = quad([0, 0, 1e-3], [1.0, 0, 0], [0, 1.0, 0])
    scene = _scene([sheet])
    accel = Accelerator(scene.triangles, threads=1)
    smap = build_shadow_photon_map(scene, accel, LightSet(scene), 0, seed=2)
    assert not np.any(smap.classify(floor, up, 0) == LIT)
    around = np.column_stack([rng.uniform(1.5, 3.0, 500), rng.uniform(-1, 1, 500), np.zeros(500)])
    assert np.mean(smap.classify(around, up[:500], 0) == LIT) > 0.95


def test_emissive_mesh_light():
    """A two-sided emissive quad 3 m up lights the floor past the occluder."""
    emitter = quad([0, 0, H], [A, 0, 0], [0, A, 0])
    mats = [Material("white"), Material("glow", diffuse=0.0, exitance=[40.0] * 3)]
    tris = [_occluder(), emitter]
    mids = np.array([0, 0, 0, 0, 1, 1], np.int32)
    scene = _scene(tris, lights=[], materials=mats, material_ids=mids)
    accel = Accelerator(scene.triangles, threads=2)
    lights = LightSet(scene)
    index = [i for i, s in enumerate(lights.sampled) if getattr(s, "in_bvh", False)]
    assert index == [0]
    smap = build_shadow_photon_map(scene, accel, lights, 100_000, seed=3)
    assert smap.covers(0) and np.all(smap.light == 0)
    x, n = _floor_grid(60)
    f = occluded_share(x[:, 0], x[:, 1])
    cls = smap.classify(x, n, 0)
    assert not np.any(cls[f == 0] == UMBRA) and not np.any(cls[f == 1] == LIT)
    assert np.mean(cls[f == 0] == LIT) > 0.9 and np.mean(cls[f == 1] == UMBRA) > 0.5
    # Direct light: the same within noise at lit points, zero in the umbra.
    repeats = 16
    xs = np.repeat(x[None], repeats, 0).reshape(-1, 3)
    ns = np.repeat(n[None], repeats, 0).reshape(-1, 3)
    st = {}
    plain = direct_irradiance(xs, ns, lights, accel, sampling.rng_for(6, 9), 4)[:, 0].reshape(repeats, -1)
    fast = direct_irradiance(xs, ns, lights, accel, sampling.rng_for(7, 9), 4, stats=st,
                             shadow_map=smap)[:, 0].reshape(repeats, -1)
    var = plain.var(axis=0, ddof=1) / repeats + fast.var(axis=0, ddof=1) / repeats
    lit = f == 0
    diff = fast.mean(axis=0) - plain.mean(axis=0)
    assert np.all(np.abs(diff[lit]) <= 5 * np.sqrt(var[lit]) + 1e-12)
    assert np.all(fast[:, f == 1] == 0)
    assert st["shadow_rays_saved"] > 0.5 * (st["shadow_rays"] + st["shadow_rays_saved"])


def test_scene_without_positioned_lights():
    """A soft sun and the world keep plain shadow rays: the map is empty, every class is
    PENUMBRA and direct light is the plain call's, bit for bit."""
    sun = SunLight("Sun", [0.3, 0.2, -1.0], [3.0] * 3, angle=0.05)
    scene = _scene([_occluder()], lights=[sun], world=World([0.2] * 3))
    accel = Accelerator(scene.triangles, threads=1)
    lights = LightSet(scene)
    smap = build_shadow_photon_map(scene, accel, lights, 50_000)
    assert len(smap) == 0 and smap.stats["emitted"] == 0
    x, n = _floor_grid(20)
    for li in range(len(lights.sampled)):
        assert not smap.covers(li)
        assert np.all(smap.classify(x, n, li) == PENUMBRA)
    st = {}
    e1 = direct_irradiance(x, n, lights, accel, sampling.rng_for(8, 9), 4, stats=st, shadow_map=smap)
    e0 = direct_irradiance(x, n, lights, accel, sampling.rng_for(8, 9), 4)
    assert np.array_equal(e0, e1) and st["shadow_rays_saved"] == 0


def test_deterministic_for_a_fixed_seed():
    scene = _scene([_occluder()])
    accel = Accelerator(scene.triangles, threads=2)
    lights = LightSet(scene)
    a = build_shadow_photon_map(scene, accel, lights, 30_000, seed=5)
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(2) as pool:
        b = build_shadow_photon_map(scene, accel, lights, 30_000, seed=5, pool=pool)
    c = build_shadow_photon_map(scene, accel, lights, 30_000, seed=6)
    for key in ("positions", "directions", "light", "crossings", "rep_index", "rep_class"):
        assert np.array_equal(getattr(a, key), getattr(b, key)), key
    assert not np.array_equal(a.positions, c.positions)
    x, n = _floor_grid(50)
    assert np.array_equal(a.classify(x, n, 0), b.classify(x, n, 0))


def test_same_classes_at_any_scale():
    """The scene scaled by 1e-3 and 1e3: the default count, the radius caps and the classes
    scale with it (DESIGN.md §6)."""
    x, n = _floor_grid(120)
    results = []
    for s in (1e-3, 1.0, 1e3):
        floor = quad([0, 0, 0], [5, 0, 0], [0, 5, 0]) * np.float32(s)
        m = np.eye(4)
        m[:3, :3] *= s
        m[:3, 3] = [0, 0, H * s]
        scene = Scene(triangles=np.concatenate([floor, _occluder() * np.float32(s)]),
                      material_ids=np.zeros(4, np.int32), materials=[Material("white")],
                      camera=Camera.look_at(np.array([0, -8, 6]) * s, [0, 0, 0]),
                      lights=[AreaLight("Area", "SQUARE", m, 2 * A, 2 * A, [100.0] * 3)]).validate()
        accel = Accelerator(scene.triangles, threads=1)
        smap = build_shadow_photon_map(scene, accel, LightSet(scene), 0, seed=1)
        results.append((smap.stats["emitted"], smap.radius[0] / s, smap.classify(x * s, n, 0)))
    for emitted, radius, cls in results[::2]:
        assert emitted == results[1][0]
        assert radius == pytest.approx(results[1][1], rel=1e-5)
        assert np.mean(cls == results[1][2]) > 0.995


def test_points_behind_glass_are_traced_never_umbra():
    """The occluder of the classes test made of glass (a Glass BSDF closure): no floor point
    in its shadow is UMBRA (they are PENUMBRA: traced, and Cycles' shadow rays stop at glass,
    so the traced answer is the same, while the light through it comes from the caustic map).
    The same quad opaque gives UMBRA under its middle (the contrast: the test fails if glass
    is treated as any occluder)."""
    from lanterna.engine.shaders import Closure, seed_reduction

    closures = (Closure("glass"),)
    seed = seed_reduction(closures)
    glass = Material("glass", diffuse=seed.diffuse, specular=np.clip(seed.specular, 0, 1),
                     closures=closures)
    occluder = _occluder()
    floor_ids = np.zeros(2, np.int32)
    under = np.column_stack([np.random.default_rng(3).uniform(-0.1, 0.1, (400, 2)),
                             np.zeros(400)])
    up = np.tile([0.0, 0.0, 1.0], (len(under), 1))
    classes = {}
    for name, mats in (("glass", [Material("white"), glass]), ("opaque", None)):
        ids = np.r_[floor_ids, np.ones(len(occluder), np.int32)] if mats else None
        scene = _scene([occluder], materials=mats, material_ids=ids)
        accel = Accelerator(scene.triangles, threads=1)
        smap = build_shadow_photon_map(scene, accel, LightSet(scene), 0, seed=1)
        classes[name] = smap.classify(under, up, 0)
    assert np.mean(classes["opaque"] == UMBRA) > 0.9
    assert not np.any(classes["glass"] == UMBRA)
    assert np.all(classes["glass"] == PENUMBRA)
