"""Render passes (engine/passes.py, pipeline.render(passes=...)): every pass exists with the
right name and size, the passes agree with each other and with the maps (no bpy)."""
import numpy as np
import pytest

from analytic import box_room, quad
from lanterna.engine import passes as P
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import AreaLight, Camera, Material, Scene

RES = (40, 30)


def _room():
    """A 2 m box, white walls, a 0.5 m square area light under the ceiling, a plate 0.5 m
    above the floor casting a shadow, and a glowing patch on the back wall."""
    room = box_room(size=(2.0, 2.0, 2.0))
    plate = quad([1.0, 1.3, 0.5], [0.3, 0, 0], [0, 0.3, 0])
    plate = np.concatenate([plate, plate[:, ::-1]])                 # both sides
    glow = quad([1.5, 1.99, 1.2], [0.15, 0, 0], [0, 0, 0.15])[:, ::-1]
    tris = np.concatenate([room, plate, glow])
    ids = np.r_[np.zeros(len(room)), np.ones(len(plate)), np.full(len(glow), 2)].astype(np.int32)
    m = np.eye(4)
    m[:3, 3] = [1.0, 1.2, 1.95]
    return Scene(triangles=tris, material_ids=ids,
                 materials=[Material("white", diffuse=0.7), Material("plate", diffuse=0.5),
                            Material("glow", diffuse=0.0, exitance=[2.0, 1.0, 0.5])],
                 camera=Camera.look_at([1.0, 0.05, 1.3], [1.0, 1.5, 0.6], fov_x_deg=80,
                                       resolution=RES),
                 lights=[AreaLight("Panel", "SQUARE", m, 0.5, 0.5, [30.0] * 3)])


@pytest.fixture(scope="module")
def cached():
    settings = RenderSettings(samples=4, photons=40_000, gather_m=4, gather_n=8, seed=3)
    return render(_room(), settings, passes="all")


def test_every_pass_has_its_name_size_and_type(cached):
    assert set(cached.passes) == set(P.PASS_NAMES)
    for name, image in cached.passes.items():
        assert image.shape == (RES[1], RES[0], 3), name
        assert image.dtype == np.float32, name
        assert np.isfinite(image).all(), name
    assert cached.report["passes"] == list(P.PASS_NAMES)


def test_combined_is_direct_plus_indirect_plus_emission(cached):
    p = cached.passes
    total = p["Direct"] + p["Indirect"] + p["Emission"]
    np.testing.assert_allclose(total, cached.image, rtol=0, atol=1e-4)
    # each part carries light: the glow is seen, the room is lit directly and indirectly
    assert p["Emission"].max() == pytest.approx(2.0 / np.pi, rel=1e-5)   # M / pi, seen head-on
    assert p["Direct"].mean() > 0.01 and p["Indirect"].mean() > 0.01
    assert np.all(p["Direct"] >= 0) and np.all(p["Indirect"] >= 0)


def test_direct_pass_is_the_direct_only_render_sample_for_sample():
    """With the photon map at the hit looked up by every sample, the indirect term draws no
    random numbers, so the Direct pass equals a bounces = 0 render exactly (same seed)."""
    scene = _room()
    common = dict(samples=2, seed=5)
    full = render(scene, RenderSettings(photons=20_000, indirect="photon-map", photon_lookups=2,
                                        **common), passes="direct,emission")
    direct_only = render(scene, RenderSettings(bounces=0, **common))
    np.testing.assert_allclose(full.passes["Direct"] + full.passes["Emission"],
                               direct_only.image, rtol=1e-6, atol=1e-7)
    assert set(full.passes) == {"Direct", "Emission"}


def test_projection_inverts_the_camera_rays():
    """A pixel centre's first hit projects back to that pixel (with a render border too)."""
    from lanterna.engine.accel import Accelerator
    from lanterna.engine.passes import centre_hits
    from lanterna.engine.surfaces import SceneSurfaces

    scene = _room()
    scene.camera.border = (5, 4, 31, 22)
    scene.camera.__post_init__()
    accel = Accelerator(scene.triangles, threads=1)
    hits = centre_hits(scene, accel, SceneSurfaces(scene))
    pixel, visible = P.visible_points(scene.camera, accel, hits.x)
    accel.close()
    np.testing.assert_array_equal(pixel, hits.pixel)
    assert visible.mean() > 0.99
    assert hits.shape == (18, 26)


def test_photons_and_cache_points_show_the_maps(cached):
    art = cached.artifacts
    photons = cached.passes["Photons"]
    lit = photons.reshape(-1, 3)
    lit = lit[lit.max(axis=1) > 0]
    power = art.photon_map.power / art.photon_map.power.max(axis=1, keepdims=True)
    # every dot is the colour of a stored photon
    keys = {tuple(np.round(c, 6)) for c in power}
    assert all(tuple(np.round(c, 6)) in keys for c in lit)
    assert 0.3 * RES[0] * RES[1] < len(lit) <= len(art.photon_map)
    points = cached.passes["CachePoints"].reshape(-1, 3)
    white = np.all(points == 1.0, axis=1)
    assert np.all(white | np.all(points == 0.0, axis=1))
    records = len(art.cache)
    assert 0 < white.sum() <= records
    # records are placed at pixel centres: nearly every record shows up as a dot
    assert white.sum() >= 0.9 * records - 2


def test_cache_usage_matches_the_counts(cached):
    usage = cached.passes["CacheUsage"]
    asked = usage.sum(axis=2) > 0
    np.testing.assert_allclose(usage[asked].sum(axis=1), 1.0, atol=1e-6)
    cam = cached.report["stages"]["camera"]
    share = cam["cache_interpolated"] / (cam["cache_interpolated"] + cam["cache_gathered"])
    # pixels ask equally many samples except those straddling the glow (a few of 1200), so
    # the mean over pixels is the share over samples to within those few pixels' weight
    assert usage[asked][:, 1].mean() == pytest.approx(share, abs=2e-3)
    assert share > 0.5


def test_shadow_classes_see_the_plate_shadow(cached):
    cls = cached.passes["ShadowClasses"]
    on = cls.sum(axis=2) > 0
    np.testing.assert_allclose(cls[on].sum(axis=1), 1.0, atol=1e-6)
    green, red, blue = (cls[..., i][on] for i in (1, 0, 2))
    assert green.mean() > 0.3 and blue.sum() > 0 and red.sum() > 0
    # two shadow-photon lights (the panel and the glowing patch), each half of a pixel's
    # colour: the floor in front (bottom corners) is lit by the panel, the middle of the
    # plate's shadow on the floor is its umbra
    assert cls[-1, 0, 1] >= 0.5 and cls[-1, -1, 1] >= 0.5
    assert cls[24, 20, 2] >= 0.5


def test_photon_map_pass_is_the_photon_map_view():
    """The PhotonMap pass of a full render and the Combined of a photon-map mode render are
    the same estimator (one at pixel centres, one filtered): region means within 4 %."""
    scene = _room()
    common = dict(samples=4, photons=100_000, seed=2)
    full = render(scene, RenderSettings(**common, indirect="gather", gather_m=2, gather_n=4),
                  passes="photon-map,emission")
    view = render(scene, RenderSettings(mode="photon-map", **common), passes="emission")
    a = full.passes["PhotonMap"] + full.passes["Emission"]
    b = view.image
    blocks = lambda im: im.reshape(3, 10, 4, 10, 3).mean(axis=(1, 3, 4))
    ratio = blocks(a) / blocks(b)
    assert np.abs(ratio - 1).max() < 0.04, ratio


def test_pass_names_are_checked():
    assert P.parse_passes("direct, Indirect,CacheUsage") == ("Direct", "Indirect", "CacheUsage")
    assert P.parse_passes("") == ()
    with pytest.raises(ValueError, match="unknown pass 'diffuse'"):
        P.parse_passes("direct,diffuse")
