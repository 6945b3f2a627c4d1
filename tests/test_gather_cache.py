"""The irradiance cache against the per-pixel final gather it interpolates (issue 4; no bpy).

Both renders share the seed, so the photon map and the precomputed irradiance are the same;
only where the indirect light is computed differs: a final gather at every pixel sample
(``indirect = gather``, 16 x 64 rays) or records placed in passes and interpolated
(``indirect = cache``). Measured on the box below (48 x 36, 2 spp, seed 3): a = 0.2 worst
4 x 4 block 0.6 % off the per-pixel gather; a = 0.5 worst block 2.6 % with gradients and
9.7 % without, pixel RMS 3.3 % against 5.7 %. The bounds: 2 % (the issue's), and gradients
must cut the RMS to at most 0.75 x (measured 0.59 x; the per-pixel gather's own noise, about
1 % RMS, is in both figures).
"""
import numpy as np
import pytest

from analytic import box_room, quad
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import Camera, Material, PointLight, Scene, SpotLight

BASE = dict(samples=2, photons=300_000, seed=3, gather_m=16, gather_n=64)


def _room():
    tris = box_room(size=(4.0, 4.0, 3.0))
    ids = np.zeros(len(tris), np.int32)
    ids[6:8] = 1                                            # a red right wall
    return Scene(triangles=tris, material_ids=ids,
                 materials=[Material("white", diffuse=0.7), Material("red", diffuse=[0.7, 0.2, 0.1])],
                 camera=Camera.look_at([2.0, 0.3, 1.5], [2.0, 4.0, 1.2], resolution=(48, 36),
                                       fov_x_deg=80),
                 lights=[PointLight("P", [3.2, 2.5, 2.6], [60.0] * 3)])


def _blocks(image):
    return image.reshape(4, 9, 4, 12, 3).astype(np.float64).mean(axis=(1, 3))


@pytest.fixture(scope="module")
def per_pixel_gather():
    return render(_room(), RenderSettings(indirect="gather", **BASE))


def test_cache_agrees_with_the_per_pixel_gather(per_pixel_gather):
    cached = render(_room(), RenderSettings(indirect="cache", cache_error=0.2, **BASE))
    assert np.all(np.isfinite(cached.image)) and cached.image.min() >= 0     # corners included
    ratio = _blocks(cached.image) / _blocks(per_pixel_gather.image)
    assert np.abs(ratio - 1).max() <= 0.02, np.round(ratio[..., 0], 4)
    stage = cached.report["stages"]["irradiance_cache"]
    assert stage["records"] > 50 and stage["pixels_per_record_mean"] > 1
    assert [p["stride"] for p in stage["passes"]] == [32, 16, 8, 4, 2, 1]


def test_gradients_lower_the_interpolation_error(per_pixel_gather):
    ref = per_pixel_gather.image.astype(np.float64)

    def rms(gradients):
        image = render(_room(), RenderSettings(indirect="cache", cache_error=0.5,
                                               cache_gradients=gradients, **BASE)).image
        return np.sqrt(((image - ref) ** 2).mean()) / ref.mean()

    with_gradients, without = rms(True), rms(False)
    assert with_gradients <= 0.75 * without, (with_gradients, without)


SHADOW_BLOCKS = (slice(2, 3), slice(1, 3))     # the floor under the plate, in the 4 x 4 blocks


def test_cache_keeps_an_indirect_shadow_with_the_neighbour_check():
    """An indirect shadow: a spot under the ceiling lights only the ceiling; the floor gets
    that bounced light, less under a plate floating 1 m above it. Ward's weight sees no reason
    for records there (distances and normals are those of an open floor), so without the
    neighbour check (``cache_refine``) the records interpolate across the shadow's edge.

    Measured at a = 0.3 against the per-pixel gather with the same photons, seeds 3-12, on the
    two blocks of the floor under the plate (green, the mean of the two):
    with the check -0.24, 1.88, -0.30, 0.08, -0.46, 1.93, -0.61, -1.57, 2.26, 1.72 %
    (mean 0.47 %, SD 1.35 %); without it 19.8-23.9 % (mean 22.0 %, SD 1.4 %).
    Bounds: |with| <= 6 % (the mean + 4 SD) and without >= 16 % (the mean - 4 SD).

    (This test used to bound the worst of all 48 block-channels: 3 %, then 5 % after the
    photon bounce change. That statistic is the cache's noise, not the shadow: with the check
    every block's mean over the seeds lies within 1.2 % of the gather, its SD is 0.5-2.3 %, and
    the worst of 48 came out 2.0-4.7 % (mean 3.1 %, SD 0.9 %), so 3 % failed on a new photon
    map and 5 % was under 4 SD. The bias the check removes sits in the shadow's blocks.)"""
    scene = _plate_under_a_spot()
    gathered = _blocks(render(scene, RenderSettings(indirect="gather", **BASE)).image)

    def shadow_error(refine):
        result = render(scene, RenderSettings(indirect="cache", cache_error=0.3,
                                              cache_refine=refine, **BASE))
        error = _blocks(result.image) / gathered - 1
        return float(error[SHADOW_BLOCKS][..., 1].mean()), result.report

    with_check, report = shadow_error(True)
    without, _ = shadow_error(False)
    assert abs(with_check) <= 0.06 and without >= 0.16, (with_check, without)
    passes = report["stages"]["irradiance_cache"]["passes"]
    assert sum(p["shrunk"] for p in passes) > 0


def _plate_under_a_spot():
    room = box_room(size=(4.0, 4.0, 3.0))
    plate = quad([2.0, 2.0, 1.0], [0.5, 0, 0], [0, 0.5, 0])
    tris = np.concatenate([room, plate])
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("white", diffuse=0.6)],
                 lights=[SpotLight("Up", [2.0, 2.0, 2.3], [0, 0, 1.0], [100.0] * 3,
                                   np.radians(25))],
                 camera=Camera.look_at([2.0, 0.3, 2.2], [2.0, 2.3, 0.0], resolution=(48, 36),
                                       fov_x_deg=70))


def test_uncovered_samples_share_batch_local_records(monkeypatch):
    """Camera samples no record covers (edges, the gaps the neighbour check leaves) make
    records of their own within their batch (``indirect.LOCAL_STEPS``) instead of a gather
    each. On the indirect-shadow scene (8 spp, a = 0.3), against a gather at every uncovered
    sample (``LOCAL_STEPS = ()``), seeds 3-8 (2026-12-07): 0.13-0.18 of the gathers and the
    worst 4 x 4 block 0.18-0.47 % apart (mean 0.31 %, SD 0.12 %). Since photon estimates
    count only the part of their disc that their surface covers (``Accelerator.
    disc_coverage``), the room's edges are brighter and a record's gather by them noisier:
    with the whole disc, 0.16-0.29 % on the same seeds (0.05-0.25 %, mean 0.13 %, SD 0.08 %
    when this test was written). Bounds: at most 0.6 of the gathers and 0.8 % (mean + 4
    SD); the same picture twice (the local records do not depend on the order batches
    finish)."""
    from lanterna.engine import indirect

    scene = _plate_under_a_spot()
    settings = RenderSettings(indirect="cache", cache_error=0.3,
                              **{**BASE, "samples": 8, "seed": 5})
    local = render(scene, settings)
    again = render(scene, settings)
    monkeypatch.setattr(indirect, "LOCAL_STEPS", ())
    each = render(scene, settings)
    cam, cam_each = local.report["stages"]["camera"], each.report["stages"]["camera"]
    assert cam["cache_local_records"] > 0 and cam_each["cache_local_records"] == 0
    assert cam["cache_gathered"] <= 0.6 * cam_each["cache_gathered"], (cam, cam_each)
    assert cam["cache_interpolated"] == cam_each["cache_interpolated"]
    np.testing.assert_array_equal(local.image, again.image)
    apart = np.abs(_blocks(local.image) / _blocks(each.image) - 1).max()
    assert apart <= 0.008, apart


def test_thin_plate_lit_from_both_sides_keeps_its_sides_apart():
    """A plate in the middle of a room, a red lamp above and a blue lamp below. Records on one
    side must never serve the other (n . n_i < 0): looking at either side, the cache agrees
    with the per-pixel gather within 3 % per channel on the plate, and the top stays red."""
    room = box_room(size=(4.0, 4.0, 3.0))
    plate = quad([2.0, 2.0, 1.5], [1.2, 0, 0], [0, 1.2, 0])
    tris = np.concatenate([room, plate])
    lights = [PointLight("Red", [2.0, 2.0, 2.6], [40.0, 0.0, 0.0]),
              PointLight("Blue", [2.0, 2.0, 0.4], [0.0, 0.0, 40.0])]
    materials = [Material("white", diffuse=0.7)]
    for eye, target in (([2.0, 0.6, 2.8], [2.0, 2.0, 1.5]), ([2.0, 0.6, 0.2], [2.0, 2.0, 1.5])):
        scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                      materials=materials, lights=lights,
                      camera=Camera.look_at(eye, target, resolution=(24, 18), fov_x_deg=30))
        cached = render(scene, RenderSettings(indirect="cache", **BASE)).image
        gathered = render(scene, RenderSettings(indirect="gather", **BASE)).image
        assert np.all(np.isfinite(cached))
        centre = (slice(6, 12), slice(8, 16))                 # on the plate from both views
        c, g = cached[centre].reshape(-1, 3).mean(0), gathered[centre].reshape(-1, 3).mean(0)
        np.testing.assert_allclose(c, g, rtol=0.03)
        top = eye[2] > 1.5
        assert (c[0] > 5 * c[2]) if top else (c[2] > 5 * c[0])


def test_photon_guided_gather_is_unbiased_and_less_noisy():
    """Steering extra rays by the photons' directions (Jensen 1995) keeps the estimate's mean
    (it only changes how many rays each stratum gets) and spreads less than a plain gather
    with as many rays: per-point indirect irradiance on the room's back wall, 64 points x 40
    repeats; guided 4 x 16 + 64 extra rays against plain 4 x 16 and 4 x 32. Measured spread
    (mean per-point SD): plain 4 x 16 0.117, plain 4 x 32 0.075, guided 0.065."""
    from lanterna.engine.accel import Accelerator
    from lanterna.engine.gather import RadianceEstimates, final_gather
    from lanterna.engine.photons import auto_max_radius, build_photon_map
    from lanterna.engine.surfaces import SceneSurfaces

    scene = _room().validate()
    accel = Accelerator(scene.triangles, threads=1)
    pmap = build_photon_map(scene, accel, 200_000, seed=5)
    estimates = RadianceEstimates.build(pmap, k=50, max_radius=auto_max_radius(scene, len(pmap), 50))
    arrays = SceneSurfaces(scene)
    points = np.column_stack([np.linspace(0.5, 3.5, 64), np.full(64, 3.99), np.linspace(0.3, 2.7, 64)])
    normals = np.tile([0.0, -1.0, 0.0], (64, 1))                # the back wall, facing the room

    def repeat(guide, extra, n=16):
        rng = np.random.default_rng(7)
        return np.stack([final_gather(points, normals, normals, estimates, accel, arrays, rng, 4, n,
                                      guide=guide, guide_extra=extra)[0][:, 1] for _ in range(40)])

    plain, guided, same_rays = repeat(None, 0.0), repeat(pmap, 1.0), repeat(None, 0.0, 32)
    se = np.sqrt(plain.var(axis=0, ddof=1) / 40 + guided.var(axis=0, ddof=1) / 40).mean()
    assert abs(guided.mean() - plain.mean()) <= 4 * se / np.sqrt(64)
    assert guided.std(axis=0).mean() < same_rays.std(axis=0).mean() < plain.std(axis=0).mean()
