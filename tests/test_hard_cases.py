"""The hard cases (issue 6, item 3; DESIGN.md §6): each one must stay finite and give the right
number or picture, not only run. Core only (no bpy): scenes are built from numpy arrays.

Every tolerance is stated next to its assertion with where it comes from: a closed form, the
round-off of a re-ordered computation, or the spread of the result measured over seeds 1-8
(the seed used here is fixed, so a pass is reproducible; the bound is set a few standard
deviations out, not widened until green).

Defects these cases found, fixed in the core (see the comments at each test):
* ``Scene.validate`` measured "zero area" against the largest coordinate of the whole scene,
  so one far-away triangle made every other triangle "too small" and dropped the room; and
  triangles beyond 1e12 m (where Embree's float32 products overflow and rays miss) were kept.
* A light touching or lying in a surface (an area light flush with the ceiling): photons left
  from the surface at t = 0 and were stored on its far side, and shadow rays under normal
  incidence ended exactly on the light's plane, so the room was black.
* A shading point within the ray offset of an emitting wall (1e-7 m from a glowing box's
  edge) dropped that wall's light: half its direct light was missing. A point on a concave
  edge (the foot of a box on the floor) was black: its shadow rays, pushed off the floor
  along the floor's normal, started in the plane of the box's face (now they also leave
  along the ray).
* The final gather's precomputed irradiance was looked up at any distance: the floor under a
  closed lamp shade took the irradiance of the inside of the shade (light leaked out).
* rho_d + rho_s > 1 was accepted silently (photons gained power at every bounce); now scaled
  down with a warning. Non-finite or negative material values set after construction are
  refused at validation; light powers beyond 1e30 (float32 overflow: 1e38 W rendered 18 %
  off, 1e40 W gave inf and NaN) are refused with the light's name.

An irradiance-cache record placed exactly on an inner edge of a closed box (a camera inside
it, aligned with its edges) took the light of the box's outside through a t = 0 hit of its
gather rays; its gather now starts inside its own triangle.
"""
from __future__ import annotations

import numpy as np
import pytest

from analytic import box_room, icosphere, point_irradiance, polygon_irradiance, quad
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.direct import direct_irradiance
from lanterna.engine.lights import LightSet
from lanterna.engine.photons import PhotonMap
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import (AreaLight, Camera, Material, PointLight, Scene, SceneError,
                                   SunLight)

THREADS = 2
# Tiny renders. Shadow photons off: their automatic count (100k-1M) would dominate these
# renders' time; where a case concerns them they are built and checked directly.
QUICK = dict(samples=4, light_samples=2, threads=THREADS, gather_m=4, gather_n=8,
             shadow_photons=False)


def _room(lights, materials=None, material_ids=None, camera=None, extra=None, extra_mids=None):
    """The closed 4 x 4 x 3 m box of ``analytic.box_room`` (white unless told), the junk
    ``extra`` triangles as a second object."""
    tris = box_room()
    mids = np.zeros(len(tris), np.int32) if material_ids is None else material_ids
    oids = np.zeros(len(tris), np.int32)
    names = ["Room"]
    if extra is not None:
        tris = np.concatenate([tris, extra])
        mids = np.r_[mids, np.zeros(len(extra), np.int32) if extra_mids is None else extra_mids]
        oids = np.r_[oids, np.ones(len(extra), np.int32)]
        names.append("Junk")
    camera = camera or Camera.look_at([2, 0.3, 1.5], [2, 4, 1.0], resolution=(32, 24),
                                      fov_x_deg=80)
    return Scene(triangles=np.asarray(tris, np.float32), material_ids=mids.astype(np.int32),
                 object_ids=oids, object_names=names,
                 materials=materials or [Material("White", diffuse=0.8)], camera=camera,
                 lights=list(lights))


def _block_means(image, block):
    h, w = image.shape[:2]
    return image.reshape(h // block, block, w // block, block, 3).mean(axis=(1, 3))


# --- Degenerate, zero-area, sliver and duplicate triangles; NaN and infinite vertices --------
def test_broken_triangles_are_skipped_counted_and_change_nothing():
    """Junk added to a closed room: a point, a line, a triangle with two equal corners, NaN,
    +inf and -inf corners, a finite triangle with corners at 1e30-1e38 m, two walls twice
    (once with the winding reversed) and two slivers outside the room. The first seven are
    skipped and counted by reason, named by object; the rest stay. None of it can change the
    picture: duplicates coincide with the walls, the slivers are outside the closed room."""
    nan, inf = np.nan, np.inf
    broken = np.array([
        [[1, 1, 1], [1, 1, 1], [1, 1, 1]],                    # a point
        [[1, 1, 1], [2, 2, 2], [3, 3, 3]],                    # a line
        [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [2.5, 1.5, 0.5]],  # two equal corners
        [[nan, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[inf, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[1, 1, -inf], [1, 0, 0], [0, 1, 0]],
        [[1e30, 1e30, 1e30], [-1e30, 0, 0], [0, 1e38, 0]],   # finite, beyond float32 products
    ])
    walls = box_room()[4:6]
    duplicates = np.concatenate([walls, walls[:, ::-1]])
    slivers = np.array([[[-5, 0, 0], [-4, 0, 0], [-4.5, 1e-6, 0]],         # 1 m x 1 um
                        [[-5, 0, 0], [-4, 0, 1e-7], [-3, 0, 0]]])          # nearly a line
    junk = np.concatenate([broken, duplicates, slivers]).astype(np.float32)
    light = PointLight("Bulb", [1.0, 3.0, 2.0], [80.0] * 3)
    for indirect in ("photon-map", "cache"):
        settings = RenderSettings(seed=3, photons=30_000, indirect=indirect, **QUICK)
        clean = render(_room([light]), settings)
        dirty_scene = _room([light], extra=junk)
        dirty = render(dirty_scene, settings)
        assert dirty.report["warnings"] == [
            "Junk: skipped 3 triangles with non-finite vertices",
            "Junk: skipped 1 triangles with vertices beyond 1e+12 m (float32 overflow)",
            "Junk: skipped 3 triangles with zero area"]
        assert dirty_scene.stats["skipped_triangles"] == 7
        assert len(dirty_scene.triangles) == 12 + 4 + 2
        assert np.isfinite(dirty.image).all()
        # Same seed, same hits, except where a ray's offset follows the scene's size (1 % of
        # its extent near the origin), which the slivers outside change: 68-72 of 150k
        # photons bounce from a point up to 3e-5 m away. Measured 1.8e-5 of the peak (photon
        # map; the photons now leave a bounce from its hit pulled back along the incoming
        # ray) and 8.7e-7 (cache); a seed changes a pixel by several per cent. Bound: 1e-4.
        np.testing.assert_allclose(dirty.image, clean.image, rtol=0,
                                   atol=1e-4 * clean.image.max())


def test_sliver_emitters_match_lamberts_formula():
    """Emissive slivers 1 m long and 1 mm / 1 um wide above a floor: the first is sampled by
    solid angle (Arvo), the second (below 1e-4 sr) by area. Both must give Lambert's polygon
    formula, finite. Tolerance 3 %, with the measured standard error below a third of it."""
    floor = quad([0, 0, 0], [3, 0, 0], [0, 3, 0])
    pts = np.array([[0.0, 0.0, 0.0], [0.4, 0.3, 0.0], [-1.0, 0.5, 0.0]])
    n = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    for width in (1e-3, 1e-6):
        sliver = np.array([[[-0.5, 0.0, 1.0], [0.5, 0.0, 1.0], [0.0, width, 1.0]]], np.float32)
        scene = Scene(triangles=np.concatenate([floor, sliver]),
                      material_ids=np.array([0, 0, 1], np.int32),
                      materials=[Material("Floor"), Material("Glow", diffuse=0, exitance=1e6)],
                      camera=Camera.look_at([0, -2, 2], [0, 0, 0])).validate()
        assert len(scene.triangles) == 3
        accel = Accelerator(scene.triangles, threads=1)
        repeats = 3000
        e = direct_irradiance(np.repeat(pts, repeats, 0), np.repeat(n, repeats, 0),
                              LightSet(scene), accel, sampling.rng_for(5, 9), 4)
        e = e.reshape(len(pts), repeats, 3)[..., 0]
        assert np.isfinite(e).all()
        exact = np.array([polygon_irradiance(p, n[0], sliver[0].astype(float), 1e6 / np.pi)
                          for p in pts])
        stderr = e.std(axis=1, ddof=1) / np.sqrt(repeats)
        assert np.all(stderr < 0.01 * exact), "too noisy to decide"
        np.testing.assert_allclose(e.mean(axis=1), exact, rtol=0.03)


# --- Scale: the seed's Scene 1 at 1e-4 and 1e4; a 1 mm cube on a 1 km plane ----------------
def _scene1(scale=1.0, resolution=(64, 48)):
    """The seed's Scene 1 (``engine/blender/seed_scenes.py``: box [-2, 2] x [-2, 2] x [0, 3] m,
    half wall (-0.05, -1, 0)-(0.05, 2, 1.5) without its bottom and back faces, 25 W point light
    at (1.5, 0.8, 2.6), 18 mm lens on a 36 mm sensor = 90 degrees, camera at (0, -1.85, 2.1)
    looking at (0, 2, 1.1), clip start 5 cm) rebuilt in numpy, every length times ``scale``.
    The light's flux is times scale^2 so that the irradiance, and the picture, stay the same."""
    x0, y0, z0, x1, y1, z1 = -2, -2, 0, 2, 2, 3
    walls = [  # (material, corners counter-clockwise seen from inside)
        (2, [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)]),      # floor: green
        (0, [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)]),      # ceiling
        (0, [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)]),      # back
        (0, [(x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0)]),      # front
        (0, [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)]),      # left
        (1, [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)]),      # right: blue
    ]
    a0, b0, c0, a1, b1, c1 = -0.05, -1.0, 0.0, 0.05, 2.0, 1.5
    v = [(x, y, z) for z in (c0, c1) for y in (b0, b1) for x in (a0, a1)]
    for face in ((0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (4, 5, 7, 6)):   # -x, +x, -y, +z
        walls.append((0, [v[i] for i in face]))
    tris, mids = [], []
    for mid, c in walls:
        c = np.asarray(c, float)
        tris += [[c[0], c[1], c[2]], [c[0], c[2], c[3]]]
        mids += [mid, mid]
    materials = [Material("White", diffuse=0.8), Material("Blue", diffuse=(0.1, 0.2, 0.7)),
                 Material("Green", diffuse=(0.2, 0.6, 0.2))]
    camera = Camera.look_at(np.array([0, -1.85, 2.1]) * scale, np.array([0, 2, 1.1]) * scale,
                            fov_x_deg=90.0, resolution=resolution, clip_start=0.05 * scale)
    light = PointLight("Light", np.array([1.5, 0.8, 2.6]) * scale, [25.0 * scale ** 2] * 3)
    return Scene(triangles=(np.array(tris) * scale).astype(np.float32),
                 material_ids=np.array(mids, np.int32), materials=materials, camera=camera,
                 lights=[light])


@pytest.mark.parametrize("indirect", ["photon-map", "cache"])
def test_scene1_scaled_up_and_down_by_1e4_gives_the_same_picture(indirect):
    """The issue's bound: the same picture within 2 %, compared in 8 x 8-pixel block means
    (blocks above 5 % of the peak relatively, all blocks against 2 % of the peak). Same seed,
    so the random numbers are the same and only round-off and the offsets (relative to the
    coordinates) differ: measured 0.02 % (photon map, QUICK) at worst, where two seeds differ
    by 2 % in a typical block (SD over seeds 2-4) and 9 % in the worst.
    The cache's records reach as far as their neighbours' gathers allow (``cache_refine``),
    so its placement depends on the records' values, which round-off moves by ~4e-4 (a gather
    ray that grazes an edge): with QUICK's 4 x 8 gather one decision flipped and moved a
    block by 5.7 % (seeds differ by up to 9 % there). The cache case therefore gathers 8 x 32
    rays with 100k photons, where seeds differ by up to 3.4 % and the scaled pictures
    agreed within 0.2 % (measured)."""
    extra = dict(gather_m=8, gather_n=32, photons=100_000) if indirect == "cache" else {}
    settings = RenderSettings(**{**dict(seed=1, photons=40_000, indirect=indirect, **QUICK),
                                 **extra})
    reference = render(_scene1(1.0), settings).image
    ref_blocks = _block_means(reference, 8)
    lit = ref_blocks > 0.05 * ref_blocks.max()
    assert lit.mean() > 0.5          # 70 % of the block-channels (blue is dark on the green floor)
    for scale in (1e-4, 1e4):
        image = render(_scene1(scale), settings).image
        assert np.isfinite(image).all()
        blocks = _block_means(image, 8)
        np.testing.assert_allclose(blocks[lit], ref_blocks[lit], rtol=0.02)
        assert np.abs(blocks - ref_blocks).max() <= 0.02 * ref_blocks.max()


def _cube(size):
    """An axis-aligned cube [0, size]^3 with outward faces, without its bottom (it stands on
    the floor: a bottom face would lie on top of the floor)."""
    v = np.array([(x, y, z) for z in (0, size) for y in (0, size) for x in (0, size)], float)
    out = []
    for face in ((0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (4, 5, 7, 6)):
        q = v[list(face)]
        out += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return np.array(out)


def _slab(o, d, lo, hi):
    """Ray / box intersection (the slab test): entry t, exit t and the entry axis."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    near = np.minimum(t1, t2)
    return np.nanmax(near, axis=1), np.nanmin(np.maximum(t1, t2), axis=1), np.nanargmax(near, axis=1)


def test_millimetre_cube_on_a_kilometre_plane():
    """A 1 mm grey cube (rho 0.5) on a 1 km x 1 km grey plane under a sun at 45 degrees,
    seen from 4 mm away: extent/size = 1.4e6. Every pixel is classified by exact ray casting
    in float64 (the cube's top and lit +x face, its unlit -y face, the lit floor, the floor in
    the cube's shadow), at its centre and four corners; pixels with one class throughout are
    compared. Direct light only: radiance rho/pi * E_sun cos 45 or exactly 0, measured to
    2e-9. With the default indirect light (irradiance cache), the -y face, which sees the lit
    floor over the lower half of its hemisphere (projected solid angle pi/2), has
    L = rho/pi * (rho/pi E_floor) pi/2 exactly; a 1 mm face lit by photons 30 m apart on the
    floor, its look-ups share one estimate: measured 0.990 of it, SD 2.6 % over seeds 1-8
    (photon_k = 400), so the bound is 10 %. Top and floor get no indirect light (the plane
    cannot see itself): equal to the direct light there.

    Limitation, measured and left out of the comparison: the ray offset is 2e-5 of 1 % of the
    scene's extent, 0.28 mm here (hit points of photons and gather rays from 1.4 km away carry
    that much float32 error), so the far 0.28 mm of the 1 mm shadow is lit: the pixels whose
    floor point is in the shadow but lit when raised by the offset (1 pixel here) are not
    compared."""
    size, rho, irradiance = 1e-3, 0.5, 3.0
    tris = np.concatenate([quad([0, 0, 0], [500, 0, 0], [0, 500, 0]), _cube(size)])
    res = (48, 36)
    camera = Camera.look_at([0.6e-3, -3.5e-3, 3.0e-3], [0.0, 0.5e-3, 0.3e-3], fov_x_deg=70,
                            resolution=res, clip_start=1e-5)
    sun_dir = np.array([-1.0, 0.0, -1.0]) / np.sqrt(2)
    scene = Scene(triangles=tris.astype(np.float32), material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("Grey", diffuse=rho)], camera=camera,
                  lights=[SunLight("Sun", sun_dir, [irradiance] * 3)])
    eps = 2e-5 * 1e-2 * np.linalg.norm([1000.0, 1000.0, np.linalg.norm(camera.matrix[:3, 3])])
    e_sun = irradiance * np.cos(np.pi / 4)
    lo, hi = np.zeros(3), np.full(3, size)

    def shadowed(points):
        t0, t1, _ = _slab(points, np.broadcast_to(-sun_dir, points.shape), lo, hi)
        return (t1 >= t0) & (t1 > 0)

    def classify(px, py):
        w, h = res
        m = camera.matrix
        sx, sy = (px + 0.5) / w * 2 - 1, 1 - (py + 0.5) / h * 2
        d = (sx[:, None] * camera.tan_half_x * m[:3, 0] + sy[:, None] * camera.tan_half_y
             * m[:3, 1] - m[:3, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(m[:3, 3], d.shape)
        t0, t1, axis = _slab(o, d, lo, hi)
        on_cube = (t1 >= t0) & (t1 > 0)
        floor = o + (-o[:, 2] / d[:, 2])[:, None] * d
        raised = floor.copy()
        raised[:, 2] = eps
        cls = np.where(~shadowed(floor), 1, np.where(shadowed(raised), 2, 9))  # 9: offset band
        face = np.where(axis == 2, 3, np.where(axis == 0, np.where(d[:, 0] < 0, 4, 5), 6))
        return np.where(on_cube, face, cls)

    yy, xx = np.mgrid[0:res[1], 0:res[0]]
    classes = np.array([classify(xx.ravel() + dx, yy.ravel() + dy) for dx, dy in
                        ((0, 0), (-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5))])
    uniform = np.all(classes == classes[0], axis=0).reshape(res[1], res[0])
    cls = classes[0].reshape(res[1], res[0])
    assert (classes == 9).any(axis=0).sum() <= 0.01 * cls.size
    lit = uniform & np.isin(cls, (1, 3))                    # lit floor, cube top (4: not in view)
    dark = uniform & np.isin(cls, (2, 6))                   # floor in shadow, -y face
    face = uniform & (cls == 6)
    assert lit.sum() > 1000 and (uniform & (cls == 3)).sum() >= 8
    assert (uniform & (cls == 2)).sum() >= 8 and face.sum() >= 30

    direct = render(scene, RenderSettings(samples=16, seed=1, bounces=0, filter_width=0.0,
                                          threads=THREADS)).image
    assert np.isfinite(direct).all()
    np.testing.assert_allclose(direct[lit][:, 0], rho / np.pi * e_sun, rtol=1e-6)
    assert np.all(direct[dark] == 0)

    full = render(scene, RenderSettings(samples=16, seed=1, filter_width=0.0, photons=20_000,
                                        photon_k=400, threads=THREADS, gather_m=4,
                                        gather_n=8)).image
    assert np.isfinite(full).all()
    np.testing.assert_allclose(full[lit], direct[lit], rtol=1e-6)
    floor_radiance = rho / np.pi * e_sun
    expected_face = rho / np.pi * floor_radiance * np.pi / 2
    assert full[face][:, 0].mean() == pytest.approx(expected_face, rel=0.10)


# --- Lights touching or inside surfaces, trapped lights, zero and huge powers ---------------
def test_point_light_lying_on_the_floor():
    """A 100 W point light exactly on the floor of the closed room. Its upper half lights the
    room, its lower half leaves through the floor (geometry within the ray offset of a light
    neither blocks its direct light nor catches its photons: the two must agree). Before the
    fix every photon hit the floor at t = 0: the upward half was stored under the floor and
    escaped, the downward half bounced into the room (escaped 40 %, the room lit by photons
    that were never emitted upwards).

    Checks: direct irradiance on the walls and ceiling by Eq. 7.1 exactly (1e-9) and 0 on the
    floor (cos = 0); escaped flux = half the light's (the sphere is stratified: measured
    50.000 %; bound 1 %, 3.5 binomial SE at 30k photons); the photon-map mode's mean
    brightness equals the full mode's (measured ratio 0.9945, SD 0.6 % over seeds 1-5; bound
    3 %)."""
    flux = 100.0
    light = PointLight("Bulb", [2.0, 2.0, 0.0], [flux] * 3)
    scene = _room([light]).validate()
    x = np.array([[0.0, 1.0, 1.0], [4.0, 3.5, 0.2], [2.5, 4.0, 2.0], [1.0, 2.0, 3.0],
                  [3.0, 3.0, 0.0], [2.0, 2.5, 0.0]])
    n = np.array([[1.0, 0, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1], [0, 0, 1]])
    e = direct_irradiance(x, n, LightSet(scene), Accelerator(scene.triangles, threads=1),
                          sampling.rng_for(1, 9), 1)
    np.testing.assert_allclose(e, point_irradiance(x, n, light.position, light.flux),
                               rtol=1e-9, atol=0)
    assert np.all(e[4:] == 0)

    means = {}
    for mode, indirect in (("full", "cache"), ("photon-map", "cache")):
        result = render(_room([light]), RenderSettings(seed=1, photons=30_000, mode=mode,
                                                       indirect=indirect, **QUICK))
        assert np.isfinite(result.image).all()
        photons = result.report["stages"]["photons"]
        assert photons["flux_escaped"][0] == pytest.approx(flux / 2, rel=0.01)
        means[mode] = result.image.mean()
    assert means["photon-map"] == pytest.approx(means["full"], rel=0.03)


def test_area_light_flush_with_the_ceiling():
    """A 1 m square panel lying in the ceiling's plane, facing down: the same picture as the
    panel 0.1 mm lower (E changes by 1e-4 there). Before the fixes the room was black: the
    photons left from the ceiling at t = 0 onto its outside, shadow photons classed the whole
    room as umbra, and shadow rays under normal incidence ended on the panel's plane.
    Checks: direct light at floor points by Lambert's formula (3 %, SE below a third of it);
    every shadow-photon class under the panel LIT (nothing stands between); 8 x 8 block means
    within 2 % of the lowered panel's with the photon map (measured 0.4-0.7 % over seeds 1-3:
    the 0.1 mm shift re-rolls some photon paths), the mean within 1 % with the irradiance
    cache (measured 0.1-0.3 %; its blocks move 3 % because records land elsewhere); no
    photon escapes the closed room."""
    from lanterna.engine.shadow_photons import LIT, build_shadow_photon_map

    def scene_at(z):
        m = np.eye(4)
        m[:3, 3] = [2.0, 2.0, z]
        return _room([AreaLight("Panel", "SQUARE", m, 1.0, 1.0, [100.0] * 3)])

    flush = scene_at(3.0).validate()
    accel = Accelerator(flush.triangles, threads=1)
    lights = LightSet(flush)
    pts = np.array([[2.0, 2.0, 0.0], [1.0, 1.0, 0.0], [3.5, 3.5, 0.0], [0.0, 2.0, 1.5]])
    nrm = np.array([[0, 0, 1.0], [0, 0, 1], [0, 0, 1], [1, 0, 0]])
    repeats = 1500
    e = direct_irradiance(np.repeat(pts, repeats, 0), np.repeat(nrm, repeats, 0), lights, accel,
                          sampling.rng_for(2, 9), 4).reshape(len(pts), repeats, 3)[..., 0]
    poly = np.array([[1.5, 1.5, 3.0], [2.5, 1.5, 3.0], [2.5, 2.5, 3.0], [1.5, 2.5, 3.0]])
    exact = np.array([polygon_irradiance(p, q, poly, 100.0 / np.pi) for p, q in zip(pts, nrm)])
    assert np.all(e.std(axis=1, ddof=1) / np.sqrt(repeats) < 0.01 * exact)
    np.testing.assert_allclose(e.mean(axis=1), exact, rtol=0.03)

    shadow_map = build_shadow_photon_map(flush, accel, lights, count=40_000, seed=1)
    gx, gy = np.meshgrid(np.linspace(0.5, 3.5, 7), np.linspace(0.5, 3.5, 7))
    floor = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    classes = shadow_map.classify(floor, np.tile([0.0, 0.0, 1.0], (len(floor), 1)), 0)
    assert np.all(classes == LIT)

    for mode, indirect in (("full", "photon-map"), ("photon-map", "cache"), ("full", "cache")):
        settings = RenderSettings(seed=1, photons=30_000, mode=mode, indirect=indirect, **QUICK)
        a = render(scene_at(3.0), settings)
        b = render(scene_at(3.0 - 1e-4), settings)
        assert np.isfinite(a.image).all()
        assert a.report["stages"]["photons"]["flux_escaped"] == [0.0, 0.0, 0.0]
        if indirect == "cache" and mode == "full":
            assert a.image.mean() == pytest.approx(b.image.mean(), rel=0.01)
        else:
            blocks_a, blocks_b = _block_means(a.image, 8), _block_means(b.image, 8)
            np.testing.assert_allclose(blocks_a, blocks_b, rtol=0.02)


@pytest.mark.parametrize("rho", [0.9, 1.0])
def test_light_inside_a_closed_sphere(rho):
    """A 100 W point light at the centre of a closed icosphere (1280 triangles, r = 0.5 m)
    floating 0.2 m above a white floor; camera outside. No photon may escape (exactly 0 W),
    nothing outside may be lit (the image is exactly 0 in every mode), and the work is bounded:
    each photon path ends by roulette or at the bounce limit, so photon rays <= emitted x
    (bounces + 1); with rho = 1 every path reaches the limit and says so in the warnings.
    Before the fix the irradiance cache lit 102 pixels of the floor under the sphere (up to
    39 W m^-2 sr^-1, measured with 20k photons and 64 bounces): a gather ray that landed on
    the photon-less floor took the precomputed irradiance of the sphere's inside 0.2 m away
    (the look-up had no distance bound). (Resting on the floor, the sphere still lets the cache
    light 9 of 384 pixels next to the contact, rho = 0.9: there the inside's estimates lie
    within the floor look-up's disc, a limit of the photon map's locality.)"""
    bounces = 16
    sphere = icosphere(0.5, 3, center=(0, 0, 0.7))
    tris = np.concatenate([quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), sphere])
    mids = np.r_[np.zeros(2), np.ones(len(sphere))].astype(np.int32)
    camera = Camera.look_at([0, -3, 1.5], [0, 0, 0.5], resolution=(24, 16))
    for mode, indirect in (("photon-map", "cache"), ("full", "photon-map"), ("full", "cache")):
        scene = Scene(triangles=tris, material_ids=mids,
                      materials=[Material("Floor", diffuse=0.8), Material("Shell", diffuse=rho)],
                      camera=camera, lights=[PointLight("Trapped", [0, 0, 0.7], [100.0] * 3)])
        result = render(scene, RenderSettings(seed=1, photons=10_000, bounces=bounces, mode=mode,
                                              indirect=indirect, **QUICK))
        photons = result.report["stages"]["photons"]
        assert photons["flux_escaped"] == [0.0, 0.0, 0.0]
        assert photons["photon_rays"] <= photons["emitted"] * (bounces + 1)
        assert np.all(result.image == 0)
        if rho == 1.0:
            assert photons["capped_paths"] == photons["emitted"]
            assert any("reached the bounce limit (16)" in w for w in result.report["warnings"])


@pytest.mark.parametrize("sides", [(1e30, 1e-30), (1e4, 1e-4)])
def test_an_area_light_too_thin_to_sample_is_skipped_with_a_warning(sides):
    """A 1 m^2 area light of 1e30 x 1e-30 m rendered black without a word; one of 1e4 x 1e-4 m
    (aspect 1e8) gave 2e-5 of the closed-form irradiance. Sides further apart than
    ``MAX_AREA_ASPECT`` = 1e6 are skipped, naming the light; at an aspect of 1e6 the light is
    kept and the irradiance 2 m under its middle matches the closed form
    E = L h^2 int int (h^2 + x^2 + y^2)^-2 dx dy within 1 % (measured 0.2 %)."""
    from scipy.integrate import quad as integral

    m = np.eye(4)
    m[:3, 3] = [0.0, 0.0, 2.0]
    floor = quad([0, 0, 0], [3, 0, 0], [0, 3, 0])
    camera = Camera.look_at([0, -3, 2], [0, 0, 0], resolution=(16, 12))

    def scene(sx, sy):
        return Scene(triangles=floor, material_ids=np.zeros(2, np.int32),
                     materials=[Material("White")], camera=camera,
                     lights=[AreaLight("Strip", "RECTANGLE", m, sx, sy, [100.0] * 3)])

    result = render(scene(*sides), RenderSettings(**QUICK))
    assert any(w.startswith("Strip: an area light of") and "cannot be sampled; skipped" in w
               for w in result.report["warnings"]), result.report["warnings"]
    assert np.isfinite(result.image).all()
    kept = scene(1e3, 1e-3).validate()
    assert [light.name for light in kept.lights] == ["Strip"]
    lights = LightSet(kept)
    accel = Accelerator(kept.triangles, threads=1)
    e = direct_irradiance(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), lights, accel,
                          np.random.default_rng(1), 256)[0, 0]
    accel.close()
    h, radiance = 2.0, 100.0 / np.pi
    exact = radiance * integral(lambda y: integral(lambda x: h * h / (h * h + x * x + y * y) ** 2,
                                                    -500, 500, limit=200)[0], -5e-4, 5e-4)[0]
    assert e == pytest.approx(exact, rel=0.01)


def test_an_inverted_clip_range_is_named():
    camera = Camera.look_at([1, 1, 1], [0, 0, 0], resolution=(8, 6), clip_start=5.0,
                            clip_end=1.0)
    result = render(_furnace(camera), RenderSettings(**QUICK))
    warnings = [w for w in result.report["warnings"] if "clip start 5 m" in w]
    assert len(warnings) == 1 and "picture is black" in warnings[0]
    assert result.image.max() == 0.0


def test_zero_watt_light():
    """A 0 W light alone: a black image (exactly), no photons; beside a 80 W light: the
    picture of the 80 W light alone, bit for bit (it adds only zero terms)."""
    dark = PointLight("Off", [2.0, 2.0, 2.5], [0.0] * 3)
    bulb = PointLight("Bulb", [1.0, 3.0, 2.0], [80.0] * 3)
    settings = RenderSettings(seed=4, photons=20_000, indirect="photon-map", **QUICK)
    alone = render(_room([dark]), settings)
    assert np.all(alone.image == 0)
    assert alone.report["stages"]["photons"]["emitted"] == 0
    with_dark = render(_room([bulb, dark]), settings).image
    without = render(_room([bulb]), settings).image
    assert np.array_equal(with_dark, without)


def test_huge_light_powers_are_linear_and_overflow_is_refused():
    """1e12 W (and 1e30 W, the limit) lights render exactly 1e12 (1e30) times the 1 W picture:
    float32 photon powers, sums and pixels stay finite and linear (measured 1e-7 relative,
    the float32 round-off; bound 1e-5). Beyond 1e30 (1e38 W rendered 18 % off, 1e40 W gave
    inf and NaN) the light is refused with its name."""
    def scene(power):
        m = np.eye(4)
        m[:3, 3] = [2, 2, 2.9]
        return _room([PointLight("Bulb", [1, 3, 2], [power] * 3),
                      AreaLight("Panel", "SQUARE", m, 1.0, 1.0, [power] * 3)])

    for mode, indirect in (("full", "cache"), ("photon-map", "cache")):
        settings = RenderSettings(seed=2, photons=10_000, mode=mode, indirect=indirect, **QUICK)
        unit = render(scene(1.0), settings).image.astype(np.float64)
        for power in (1e12, 1e30):
            image = render(scene(power), settings).image.astype(np.float64)
            assert np.isfinite(image).all()
            np.testing.assert_allclose(image / power, unit, rtol=1e-5, atol=1e-5 * unit.max())
    with pytest.raises(SceneError, match=r"Bulb: flux .* is beyond 1e\+30"):
        PointLight("Bulb", [0, 0, 0], [1e31, 0, 0])
    with pytest.raises(SceneError, match=r"Panel: power .* is beyond"):
        AreaLight("Panel", "SQUARE", np.eye(4), 1.0, 1.0, [1e40] * 3)
    with pytest.raises(SceneError, match=r"Lamp shade: radiant exitance .* is beyond"):
        Material("Lamp shade", exitance=1e35)


# --- Materials: negative, NaN, rho_d + rho_s > 1 ---------------------------------------------
def test_bad_material_values_are_refused_with_the_name():
    for kwargs, problem in (({"diffuse": -0.1}, "diffuse reflectance is negative"),
                            ({"specular": [0.1, np.nan, 0]}, "specular reflectance is not finite"),
                            ({"exitance": np.inf}, "radiant exitance is not finite"),
                            ({"diffuse": [0.5, 0.5, -1e-3]}, "diffuse reflectance is negative")):
        with pytest.raises(SceneError, match=f"Brick: {problem}"):
            Material("Brick", **kwargs)
    with pytest.raises(SceneError, match="Bulb: position is not finite"):
        PointLight("Bulb", [0, np.nan, 0], [1.0] * 3)
    # Set after construction: refused when the scene is validated.
    for field, value, problem in (("diffuse", np.array([0.5, np.nan, 0.5]), "not finite"),
                                  ("specular", np.array([-0.2, 0, 0]), "negative")):
        brick = Material("Brick")
        setattr(brick, field, value)
        scene = _room([PointLight("Bulb", [1, 3, 2], [80.0] * 3)], materials=[brick])
        with pytest.raises(SceneError, match=f"Material 'Brick': .* is {problem}"):
            scene.validate()


def test_render_refuses_a_material_made_bad_after_construction():
    """The same through ``render``: a SceneError naming the material, before any work (no
    progress report), not a crash."""
    for field, value, problem in (("diffuse", np.array([0.5, np.nan, 0.5]), "not finite"),
                                  ("specular", np.array([-0.2, 0, 0]), "negative")):
        brick = Material("Brick")
        setattr(brick, field, value)
        calls = []
        with pytest.raises(SceneError, match=f"Material 'Brick': .* is {problem}"):
            render(_room([PointLight("Bulb", [1, 3, 2], [80.0] * 3)], materials=[brick]),
                   RenderSettings(**QUICK), progress=lambda f, text: calls.append(text))
        assert calls == []


def test_reflectance_above_one_is_scaled_down_with_a_warning():
    """rho_d = 0.9, rho_s = 0.5 (sum 1.4 in every channel; the red channel 1.05): scaled per
    channel to sum 1 with a warning naming the material; the render is then the render of the
    scaled material, bit for bit, and the photons' energy balance holds (emitted = absorbed +
    escaped + capped within 4 standard errors, as in test_photons.py). Before the fix the
    roulette (P_d + P_s > 1) kept every photon and scaled its power by rho / P: the green
    channel absorbed 93.9 W of the 80 W emitted (measured, seed 5)."""
    hot = Material("Hot", diffuse=[0.9, 0.9, 0.9], specular=[0.15, 0.5, 0.0])
    cool = Material("Hot", diffuse=[0.9 / 1.05, 0.9 / 1.4, 0.9], specular=[0.15 / 1.05, 0.5 / 1.4, 0.0])
    light = PointLight("Bulb", [1.0, 3.0, 2.0], [80.0] * 3)
    mids = np.zeros(12, np.int32)
    mids[:2] = 1                                     # the floor is the hot material
    settings = RenderSettings(seed=5, photons=20_000, indirect="photon-map", **QUICK)
    result = render(_room([light], materials=[Material("White"), hot], material_ids=mids),
                    settings)
    assert [w for w in result.report["warnings"] if w.startswith("Material")] == [
        "Material 'Hot': diffuse + specular reflectance [1.05, 1.4, 0.9] exceeds 1; scaled down "
        "to conserve energy"]
    np.testing.assert_allclose(hot.diffuse, cool.diffuse, rtol=1e-12)
    np.testing.assert_allclose(hot.specular, cool.specular, rtol=1e-12)
    assert np.all(hot.diffuse + hot.specular <= 1 + 1e-12)
    photons = result.report["stages"]["photons"]
    ended = (np.array(photons["flux_absorbed"]) + photons["flux_escaped"]
             + photons["flux_capped"])
    per_photon = 80.0 / photons["emitted"]
    assert np.all(np.abs(ended - 80.0) <= 4 * np.sqrt(photons["emitted"]) * per_photon)
    again = render(_room([light], materials=[Material("White"), cool], material_ids=mids),
                   settings)
    assert not [w for w in again.report["warnings"] if w.startswith("Material")]
    assert np.array_equal(result.image, again.image)


# --- The photon map: coincident photons, k above the photon count, no photons ---------------
def _photon_map(positions, power):
    """A map of photons on the plane z = 0 that arrived from above (straight down)."""
    count = len(positions)
    return PhotonMap(np.asarray(positions, np.float32),
                     np.broadcast_to(np.asarray(power, np.float32).reshape(-1, 1), (count, 3)).copy(),
                     np.tile(np.array([0, 0, -1], np.float16), (count, 1)),
                     np.tile(np.array([0, 0, 1], np.float16), (count, 1)),
                     np.zeros(count, np.uint8)).build()


def _brute_force_estimate(positions, power, x, k, max_radius):
    """Eq. 9.11 as photons.py states it, by sorting all distances: r = the k-th distance (the
    k-th photon itself left out) when k photons lie within max_radius, else max_radius and
    all of them count."""
    d = np.linalg.norm(positions[None] - x[:, None], axis=2)
    order = np.argsort(d, axis=1, kind="stable")
    d_sorted = np.take_along_axis(d, order, axis=1)
    p_sorted = power[order]
    k = min(k, len(positions))
    out = np.empty(len(x))
    for i in range(len(x)):
        if d_sorted[i, k - 1] <= max_radius:
            out[i] = p_sorted[i, :k - 1].sum() / (np.pi * d_sorted[i, k - 1] ** 2)
        else:
            inside = d_sorted[i] <= max_radius
            out[i] = p_sorted[i, inside].sum() / (np.pi * max_radius ** 2)
    return out


def test_coincident_photons():
    """Every photon stored four times at the same place (1000 places, 4000 photons of 1 mW):
    the estimate equals the brute-force Eq. 9.11 (ties of coincident photons are harmless:
    they carry the same power) to float32 round-off (1e-5). All 200 photons at one point: at a
    distance d from it every estimate is (k - 1) phi / (pi d^2) exactly, and at the point itself
    (r = 0, no area) it stays finite: 0, never inf or NaN."""
    rng = np.random.default_rng(7)
    places = np.column_stack([rng.random((1000, 2)), np.zeros(1000)])
    positions = np.repeat(places, 4, axis=0)
    power = np.full(len(positions), 1e-3)
    pmap = _photon_map(positions, power)
    x = np.column_stack([rng.uniform(0.2, 0.8, (50, 2)), np.zeros(50)])
    n = np.tile([0.0, 0.0, 1.0], (50, 1))
    for k, max_radius in ((40, np.inf), (40, 0.05), (7, np.inf)):
        est = pmap.irradiance(x, n, k=k, max_radius=max_radius)
        assert np.isfinite(est).all()
        exact = _brute_force_estimate(positions.astype(np.float32).astype(float), power, x, k,
                                      max_radius)
        np.testing.assert_allclose(est[:, 0], exact, rtol=1e-5)

    pile = _photon_map(np.zeros((200, 3)), np.full(200, 0.01))
    d = np.array([1e-3, 0.1, 2.0])
    at = np.column_stack([d, np.zeros(3), np.zeros(3)])
    est = pile.irradiance(at, np.tile([0.0, 0.0, 1.0], (3, 1)), k=50)
    np.testing.assert_allclose(est[:, 0], 49 * 0.01 / (np.pi * d ** 2), rtol=1e-5)
    centre = pile.irradiance(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), k=50, max_radius=1.0)
    assert np.isfinite(centre).all() and np.all(centre >= 0)


def test_k_larger_than_the_photon_count():
    """Five photons and k = 50: k is clipped to the map (photons.py: the k nearest, k clipped
    to the map's size), so r is the 5th distance and the 5th photon is left out; with
    max_radius between the 3rd and 4th distance r = max_radius and the three inside count.
    Exact (float32 round-off). A render asking for k = 200 from 20 photons (some 70 stored)
    stays finite and lit."""
    positions = np.array([[0.1, 0, 0], [0, -0.2, 0], [-0.3, 0, 0], [0, 0.4, 0], [0.5, 0.5, 0]])
    power = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    pmap = _photon_map(positions, power)
    x = np.zeros((1, 3))
    n = np.array([[0.0, 0.0, 1.0]])
    r5 = np.linalg.norm([0.5, 0.5])
    assert pmap.irradiance(x, n, k=50)[0, 0] == pytest.approx(10.0 / (np.pi * r5 ** 2), rel=1e-6)
    assert pmap.irradiance(x, n, k=50, max_radius=0.35)[0, 0] == \
        pytest.approx(6.0 / (np.pi * 0.35 ** 2), rel=1e-6)
    np.testing.assert_allclose(
        pmap.irradiance(x, n, k=50, max_radius=0.35)[0, 0],
        _brute_force_estimate(positions, power, x, 50, 0.35)[0], rtol=1e-6)

    light = PointLight("Bulb", [1.0, 3.0, 2.0], [80.0] * 3)
    for mode, indirect in (("photon-map", "cache"), ("full", "photon-map"), ("full", "cache")):
        result = render(_room([light]), RenderSettings(seed=1, photons=20, photon_k=200, mode=mode,
                                                       indirect=indirect, **QUICK))
        assert 0 < result.report["stages"]["photons"]["stored"] < 200
        assert np.isfinite(result.image).all() and result.image.max() > 0


def test_empty_photon_map():
    """A light with photon share 0 sends no photons: the map is empty. The photon estimate,
    the precomputed estimates and the gather give 0 (not NaN); a full render is exactly the
    direct-light render (a point light: no random numbers in its direct light), the photon-map
    mode's picture is black, and the report says why."""
    from lanterna.engine.gather import RadianceEstimates

    empty = _photon_map(np.zeros((0, 3)), np.zeros(0))
    assert len(empty) == 0
    x, n = np.zeros((3, 3)), np.tile([0.0, 0.0, 1.0], (3, 1))
    assert np.all(empty.irradiance(x, n, k=50, max_radius=1.0) == 0)
    estimates = RadianceEstimates.build(empty, k=50, max_radius=1.0)
    assert len(estimates) == 0 and np.all(estimates.lookup(x, n) == 0)

    light = PointLight("Bulb", [1.0, 3.0, 2.0], [80.0] * 3, photon_share=0.0)
    direct = render(_room([light]), RenderSettings(seed=1, bounces=0, **QUICK)).image
    assert direct.max() > 0
    for mode, indirect in (("full", "photon-map"), ("full", "gather"), ("full", "cache"),
                           ("photon-map", "cache")):
        result = render(_room([light]), RenderSettings(seed=1, mode=mode, indirect=indirect,
                                                       photons=10_000, **QUICK))
        assert result.report["stages"]["photons"]["stored"] == 0
        assert any("photon share 0" in w for w in result.report["warnings"])
        if mode == "full":
            np.testing.assert_array_equal(result.image, direct)
        else:
            assert np.all(result.image == 0)


# --- Corners, edges, a thin plate ------------------------------------------------------------
FURNACE_M, FURNACE_RHO = 2.0, 0.5


def _furnace(camera, rho=FURNACE_RHO, exitance=FURNACE_M):
    """A closed 2 m box whose walls glow (exitance M) and reflect rho: the radiance is
    (M / pi) / (1 - rho) everywhere (DESIGN.md §6), in corners and on edges too, and the
    direct irradiance from the walls is M at every point of them."""
    tris = box_room(size=(2.0, 2.0, 2.0))
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("Glow", diffuse=rho, exitance=exitance)], camera=camera)


def test_shading_points_in_a_corner_and_on_an_edge():
    """In the glowing box: the direct irradiance at points 1 mm, 10 um and 0.1 um from a
    corner and from two edges is M (5 %, the estimate's SE below a third of it). Before the
    fix the points 0.1 um from an edge got half (0.998 of 2): samples of the wall they nearly
    touch lay within the ray offset and were dropped as "behind the light".
    Exactly on the corner or an edge the point lies in the planes of the walls that meet
    there: they subtend no solid angle from it, and the light comes from the walls that do
    not pass through it: the quarter of the hemisphere inside the box at a corner (M/4), half
    on an edge (M/2). (The limit from inside the box is M: a point of measure zero, which a
    camera ray meets only by float32 coincidence.) Before the fixes both were 0: the shadow
    rays started in the neighbouring wall's plane and Embree reported it at t = 0.
    The rendered corner (full mode, irradiance cache): the 4 x 4 pixels around it average
    0.985 of (M/pi)/(1 - rho), SD 1.8 % over seeds 1-8 (the photon disc is cut by the walls
    there); bound 8 %."""
    scene = _furnace(Camera.look_at([1, 1, 1], [0, 0, 0], resolution=(16, 16), fov_x_deg=30))
    scene.validate()
    accel, lights = Accelerator(scene.triangles, threads=1), LightSet(scene)
    repeats = 2500
    for d in (1e-3, 1e-5, 1e-7):
        x = np.array([[d, d, 0.0], [1.0, d, 0.0], [2.0 - d, 2.0 - d, 2.0], [d, 1.0, 1.0]])
        n = np.array([[0, 0, 1.0], [0, 0, 1], [0, 0, -1], [1, 0, 0]])
        e = direct_irradiance(np.repeat(x, repeats, 0), np.repeat(n, repeats, 0), lights, accel,
                              sampling.rng_for(3, 9), 4).reshape(len(x), repeats, 3)[..., 0]
        assert np.isfinite(e).all()
        assert np.all(e.std(axis=1, ddof=1) / np.sqrt(repeats) < 0.05 / 3 * FURNACE_M)
        np.testing.assert_allclose(e.mean(axis=1), FURNACE_M, rtol=0.05)
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 2.0, 2.0], [0.0, 1.0, 2.0]])
    n = np.array([[0, 0, 1.0], [0, 0, 1], [0, 0, -1], [1, 0, 0]])
    e = direct_irradiance(np.repeat(x, repeats, 0), np.repeat(n, repeats, 0), lights, accel,
                          sampling.rng_for(3, 9), 4).reshape(len(x), repeats, 3)[..., 0]
    assert np.isfinite(e).all()
    assert np.all(e.std(axis=1, ddof=1) / np.sqrt(repeats) < 0.05 / 3 * FURNACE_M / 4)
    np.testing.assert_allclose(e.mean(axis=1), np.array([1 / 4, 1 / 2, 1 / 4, 1 / 2]) * FURNACE_M,
                               rtol=0.05)

    image = render(scene, RenderSettings(seed=1, photons=20_000, **QUICK)).image
    assert np.isfinite(image).all()
    exact = FURNACE_M / np.pi / (1 - FURNACE_RHO)
    assert image[6:10, 6:10, 0].mean() == pytest.approx(exact, rel=0.08)


def test_convex_and_concave_edges_get_exact_direct_light():
    """Points exactly on the edges of a 1 m cube standing on a floor, shaded with the normal
    of either face that meets there (and the floor's at the cube's foot), under a point light
    in front of and above the cube: Eq. 7.1 exactly (1e-9), never self-shadowed by the other
    face; where the light is behind the face (cos < 0): 0. Before the fix the foot of the
    cube (a concave edge) was black: the shadow ray, pushed off the floor along the floor's
    normal, started in the plane of the cube's face, which Embree reported at t = 0."""
    cube = _cube(1.0) + np.array([-0.5, -0.5, 0.0])
    tris = np.concatenate([quad([0, 0, 0], [5, 0, 0], [0, 5, 0]), cube])
    light = PointLight("Bulb", [0.8, -2.0, 2.5], [100.0] * 3)
    scene = Scene(triangles=tris.astype(np.float32), material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("White")], camera=Camera.look_at([2, -3, 2], [0, 0, 0.5]),
                  lights=[light]).validate()
    edges = {  # point on the edge: the normals of the faces meeting there
        (0.1, -0.5, 1.0): ([0, 0, 1], [0, -1, 0]),          # top / front (convex)
        (0.5, 0.2, 1.0): ([0, 0, 1], [1, 0, 0]),            # top / right (convex)
        (0.5, -0.5, 0.4): ([1, 0, 0], [0, -1, 0]),          # right / front (convex)
        (0.5, -0.5, 1.0): ([0, 0, 1], [1, 0, 0]),           # the corner
        (-0.2, -0.5, 0.0): ([0, 0, 1], [0, -1, 0]),         # floor / front (concave)
        (-0.5, 0.0, 1.0): ([0, 0, 1], [-1, 0, 0]),          # top / left: light behind -x
    }
    x = np.array([p for p, normals in edges.items() for _ in normals], float)
    n = np.array([q for normals in edges.values() for q in normals], float)
    e = direct_irradiance(x, n, LightSet(scene), Accelerator(scene.triangles, threads=1),
                          sampling.rng_for(1, 9), 1)
    exact = point_irradiance(x, n, light.position, light.flux)
    assert np.count_nonzero(exact[:, 0]) >= 9
    np.testing.assert_allclose(e, exact, rtol=1e-9, atol=0)


def test_thin_plate_lit_from_both_sides():
    """A red light above and a blue light below a 1 m plate, as one two-sided quad and as a
    1 mm thick box. Seen from above not a trace of blue (exactly 0), from below not a trace
    of red, in the photon-map mode (photons of the other side lie 0-1 mm away, inside the
    estimate's disc, and must be rejected by their direction) and in the full mode. The lit
    side: the full mode's radiance is the direct light (an isolated plate receives no
    indirect light) = rho/pi Phi cos/(4 pi r^2) at the pixel centres' hits (1 %: the pixel
    footprint's curvature of E is below 0.2 %); the photon-map mode's mean over the plate
    (200k photons, some 6 % of them land on the plate) within 5 % of it: measured over seeds
    1-6 at worst -0.4 % +- 0.9 % (mean +- SD, the side lit from 0.9 m below)."""
    red = PointLight("Red", [0.1, 0.0, 2.0], [100.0, 0.0, 0.0])
    blue = PointLight("Blue", [-0.1, 0.0, 0.0], [0.0, 0.0, 100.0])
    single = quad([0, 0, 1], [0.5, 0, 0], [0, 0.5, 0])
    box = _cube(1.0)
    box = np.concatenate([box, box[8:10][:, ::-1] * [1, 1, 0]])   # the bottom face too
    box = box * [1.0, 1.0, 1e-3] + [-0.5, -0.5, 1.0 - 1e-3]
    for plate, top_z, bottom_z in ((single, 1.0, 1.0), (box, 1.0, 1.0 - 1e-3)):
        for side, eye in (("top", [0.3, 0.2, 2.6]), ("bottom", [0.3, 0.2, -0.6])):
            camera = Camera.look_at(eye, [0, 0, top_z if side == "top" else bottom_z],
                                    up=(0, 1, 0), fov_x_deg=40, resolution=(24, 24))
            scene = Scene(triangles=np.asarray(plate, np.float32),
                          material_ids=np.zeros(len(plate), np.int32),
                          materials=[Material("White", diffuse=0.8)], camera=camera,
                          lights=[red, blue])
            lit, unlit = (0, 2) if side == "top" else (2, 0)
            images = {}
            for mode, photons in (("full", 10_000), ("photon-map", 200_000)):
                result = render(scene, RenderSettings(seed=1, photons=photons, mode=mode,
                                                      filter_width=0.0, samples=16,
                                                      threads=THREADS, shadow_photons=False))
                assert np.isfinite(result.image).all()
                assert np.all(result.image[..., unlit] == 0), (side, mode)
                images[mode] = result.image[..., lit]
            # The hits of the pixel centres on the plate's face.
            w, h = camera.resolution
            yy, xx = np.mgrid[0:h, 0:w]
            sx, sy = (xx + 0.5) / w * 2 - 1, 1 - (yy + 0.5) / h * 2
            m = camera.matrix
            d = (sx[..., None] * camera.tan_half_x * m[:3, 0]
                 + sy[..., None] * camera.tan_half_y * m[:3, 1] - m[:3, 2])
            z = top_z if side == "top" else bottom_z
            hit = m[:3, 3] + ((z - m[2, 3]) / d[..., 2])[..., None] * d
            inside = np.all(np.abs(hit[..., :2]) < 0.5 - 0.05, axis=-1)   # a pixel from the rim
            normal = np.array([0, 0, 1.0 if side == "top" else -1.0])
            source = red if side == "top" else blue
            exact = 0.8 / np.pi * point_irradiance(hit[inside], np.tile(normal, (inside.sum(), 1)),
                                                   source.position, source.flux)[:, lit]
            assert inside.sum() > 200
            np.testing.assert_allclose(images["full"][inside], exact, rtol=0.01)
            assert images["photon-map"][inside].mean() == pytest.approx(exact.mean(), rel=0.05)


# --- A white enclosure, a camera inside an object, tiny and huge images ---------------------
def test_white_enclosure_with_rho_one_is_bounded():
    """A closed box of rho = 1 whose walls glow with M = 2 W/m^2 on both faces: without the
    bounce limit the radiance is infinite. Each inward photon is stored at bounces 0..B and
    then counted as capped; nothing is absorbed. So the irradiance is M (B + 1) from the
    photons and the radiance (M/pi)(B + 2) (the emission plus the reflected light), in the
    photon-map mode and in the full mode with the photon map at the hit (exact direct M plus
    the photons that bounced, M B). Measured at B = 8 over seeds 1-8: the image mean 1.5 %
    low (the disc of the estimate is cut at the box's edges in view), SD 1.1 %; bound 5 %.
    Time and memory are bounded, checked as counts: photon rays = emitted + inward x B exactly
    (the outward half escape at once), stored = inward x (B + 1), at most 40 bytes a
    stored photon, every inward path capped and reported; with B = 64 too."""
    m_exit = 2.0
    camera = Camera.look_at([1, 0.2, 1], [1, 2, 1], resolution=(16, 12))
    for bounces, modes in ((8, (("photon-map", "cache"), ("full", "photon-map"))),
                           (64, (("photon-map", "cache"),))):
        for mode, indirect in modes:
            scene = _furnace(camera, rho=1.0, exitance=m_exit)
            result = render(scene, RenderSettings(seed=1, photons=20_000, bounces=bounces,
                                                  mode=mode, indirect=indirect, **QUICK))
            photons = result.report["stages"]["photons"]
            inward = photons["capped_paths"]
            assert inward == pytest.approx(photons["emitted"] / 2, rel=0.02)
            assert photons["photon_rays"] == photons["emitted"] + inward * bounces
            assert photons["stored_all"] == inward * (bounces + 1)
            assert photons["flux_absorbed"] == [0.0, 0.0, 0.0]
            assert photons["map_bytes"] <= 40 * photons["stored"]
            assert any(f"{inward:,} photon paths reached the bounce limit ({bounces})" in w
                       for w in result.report["warnings"])
            assert np.isfinite(result.image).all()
            expected = m_exit / np.pi * (bounces + 2)
            assert result.image[..., 0].mean() == pytest.approx(expected, rel=0.05)


def _box_in_room(camera):
    box = _cube(0.2)
    box = np.concatenate([box, box[8:10][:, ::-1] * [1, 1, 0]]) + [1.9, 1.9, 1.0]
    return _room([PointLight("Bulb", [1.0, 3.0, 2.0], [80.0] * 3)], camera=camera, extra=box)


def test_camera_inside_a_closed_object():
    """The camera inside a closed box (12 triangles, 20 cm) standing in the lit room: it sees
    the box's inner faces, which no light reaches. Every mode gives exactly 0 (the photons on
    the outer faces, 0 m away through the wall, face the other way). Measured 0 for seeds 1-3
    in the four modes."""
    camera = Camera.look_at([2.013, 1.947, 1.083], [2.05, 4.0, 1.13], resolution=(16, 12),
                            fov_x_deg=90)
    for mode, indirect in (("full", "cache"), ("full", "gather"), ("full", "photon-map"),
                           ("photon-map", "cache")):
        result = render(_box_in_room(camera), RenderSettings(seed=1, photons=20_000, mode=mode,
                                                             indirect=indirect, **QUICK))
        assert result.report["stages"]["photons"]["stored"] > 10_000
        assert np.all(result.image == 0), (mode, indirect)


def test_camera_inside_a_closed_object_aligned_with_its_edges():
    """The same with the camera centred in the box (2.0, 1.95, 1.1), looking along +y: pixel
    centres of the cache's placement passes land exactly (in float32) on the box's inner
    edges. A gather ray from such a record started in the plane of the neighbouring face;
    Embree reported that face at t = 0, and rays that left it into the box saw it from its
    outer side, whose photons (lit by the room) the look-up then took: 2 of 58 records lit,
    15-24 pixels up to 0.09-0.17 W m^-2 sr^-1 (seeds 1-3). A record's gather now starts
    inside its own triangle (``indirect.into_own_triangle``): 0 at seeds 1-3, as the gather
    and photon-map modes give."""
    camera = Camera.look_at([2.0, 1.95, 1.1], [2.0, 4.0, 1.1], resolution=(16, 12), fov_x_deg=90)
    for seed in (1, 2, 3):
        result = render(_box_in_room(camera), RenderSettings(seed=seed, photons=20_000, **QUICK))
        assert np.all(result.image == 0), seed


def test_one_pixel_image():
    """A 1 x 1 image of the glowing box's wall (64 samples): the closed form (M/pi)/(1 - rho).
    Measured over seeds 1-8: photon-map mode -0.1 % +- 1.5 %, full mode (irradiance cache)
    -1.7 % +- 1.6 % (one record serves the pixel); bound 7 %."""
    camera = Camera.look_at([1, 0.5, 1], [1, 2, 1], resolution=(1, 1), fov_x_deg=20)
    exact = FURNACE_M / np.pi / (1 - FURNACE_RHO)
    for mode in ("photon-map", "full"):
        result = render(_furnace(camera), RenderSettings(seed=1, photons=20_000, mode=mode,
                                                         samples=64, threads=THREADS,
                                                         shadow_photons=False))
        assert result.image.shape == (1, 1, 3)
        np.testing.assert_allclose(result.image[0, 0], exact, rtol=0.07)


_BORDER_RENDER = r"""
import json, resource, sys
sys.path.insert(0, sys.argv[1])
import numpy as np
from test_hard_cases import _scene1
from lanterna.engine.estimate import estimate_cost
from lanterna.engine.pipeline import RenderSettings, render

def peak():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

scene = _scene1(1.0, (8000, 8000))
scene.camera.border = (3968, 3976, 4032, 4024)
scene.camera.__post_init__()
settings = RenderSettings(threads=2, bounces=0)
estimate = estimate_cost(scene, settings)
before = peak()
result = render(scene, settings)
print(json.dumps({"before": before, "after": peak(), "estimate": estimate.peak_bytes,
                  "shape": list(result.image.shape),
                  "finite": bool(np.isfinite(result.image).all()),
                  "lit": float(result.image.mean())}))
"""


def test_8000_by_8000_image(monkeypatch):
    """An 8000 x 8000 frame of the seed's Scene 1 with the default settings (16 samples, 2M
    photons, irradiance cache). engine/estimate.py predicts it before any work: here 10.6 GiB
    at the peak and 36 minutes (of 22.8 GiB available), so it is accepted, and rendering it
    whole is not a test. Checked instead:
    * the estimate holds at least the frame's Combined buffer (8000 x 8000 x 12 B = 768 MB)
      and more than a minute of work (why the whole frame is not rendered here); where it
      exceeds the available memory the render is refused before any work;
    * refusal, forced by pretending 1 GiB is available: SceneError naming the estimate and the
      available memory, raised before the first progress report (no work done);
    * acceptance: a 64 x 48 window of the same 8000 x 8000 frame (the camera's border), direct
      light only, in a fresh process: finite, lit, and the peak resident memory it added stays
      within the estimate for that window. (Direct light only because a border render with
      indirect light places the whole frame's irradiance-cache records, so that tiles
      reassemble exactly: for 64M pixels that is minutes of work, not a test.)"""
    import json
    import os
    import subprocess
    import sys

    from lanterna.engine import estimate as estimate_module
    from lanterna.engine.estimate import estimate_cost

    scene = _scene1(1.0, (8000, 8000))
    settings = RenderSettings(threads=THREADS)
    estimate = estimate_cost(scene, settings)
    assert estimate.peak_bytes >= 8000 * 8000 * 12
    assert estimate.seconds > 60
    calls = []
    available = estimate_module.available_memory()
    if available is not None and estimate.peak_bytes > available:
        with pytest.raises(SceneError, match="available"):
            render(scene, settings, progress=lambda f, text: calls.append(text))
        assert calls == []

    monkeypatch.setattr(estimate_module, "available_memory", lambda: 1 << 30)
    with pytest.raises(SceneError, match=r"GiB.*1\.0 GiB is available"):
        render(scene, settings, progress=lambda f, text: calls.append(text))
    assert calls == []
    monkeypatch.undo()

    here = os.path.dirname(os.path.abspath(__file__))
    done = subprocess.run([sys.executable, "-c", _BORDER_RENDER, here], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["shape"] == [48, 64, 3] and out["finite"] and out["lit"] > 0.01
    assert out["after"] - out["before"] <= out["estimate"]
