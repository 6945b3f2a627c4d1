"""The planner (engine/plan.py): stages run only where the scene calls for them, each skip has
a reason in the report, and forcing a skipped stage on does not change the picture (no bpy)."""
import numpy as np
import pytest

from analytic import box_room, plane_scene, quad
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import AreaLight, Camera, Material, PointLight, Scene, SceneError


def _room(materials, lights, ids=None):
    tris = box_room(size=(2.0, 2.0, 2.0))
    ids = np.zeros(len(tris), np.int32) if ids is None else ids
    return Scene(triangles=tris, material_ids=ids, materials=materials,
                 camera=Camera.look_at([1.0, 0.3, 1.0], [1.0, 2.0, 0.8], resolution=(16, 12)),
                 lights=lights)


def _stages(result):
    return result.report["plan"]["stages"]


def test_point_lights_need_no_shadow_photons_and_diffuse_rooms_no_specular():
    scene = _room([Material("white", diffuse=0.7)], [PointLight("P", [1, 1, 1.8], [50.0] * 3)])
    stages = _stages(render(scene, RenderSettings(samples=1, photons=20_000, indirect="gather",
                                                  gather_m=2, gather_n=4)))
    assert stages["shadow_photons"].startswith("skipped: no area light")
    assert stages["specular"] == "skipped: no specular materials"
    assert not stages["photons"].startswith("skipped")
    assert not stages["final_gather"].startswith("skipped")
    assert stages["irradiance_cache"].startswith("skipped: indirect = gather")


def test_area_light_plans_shadow_photons_and_a_mirror_plans_specular():
    m = np.eye(4)
    m[:3, 3] = [1.0, 1.0, 1.9]
    ids = np.zeros(12, np.int32)
    ids[:2] = 1                                              # a mirror floor
    scene = _room([Material("white", diffuse=0.7), Material("mirror", specular=0.9)],
                  [AreaLight("Panel", "SQUARE", m, 0.5, 0.5, [40.0] * 3)], ids)
    result = render(scene, RenderSettings(samples=1, photons=20_000, indirect="photon-map"))
    stages = _stages(result)
    assert stages["shadow_photons"].startswith("1 area/mesh light")
    assert stages["specular"].startswith("specular materials")
    assert stages["final_gather"].startswith("skipped: indirect = photon-map")
    assert "shadow photons" in result.report["plan"]["summary"]


def test_black_materials_run_no_photons_and_forcing_them_changes_nothing():
    """Only black materials: no light can bounce, so no photon stage. Forced on, the photons
    are all absorbed and the picture (the emitter seen directly) is the same."""
    tris = np.concatenate([quad([0, 0, 0], [2, 0, 0], [0, 2, 0]),
                           quad([0, 0, 1.0], [0.3, 0, 0], [0, 0.3, 0])])
    scene = Scene(triangles=tris, material_ids=np.array([0, 0, 1, 1], np.int32),
                  materials=[Material("black", diffuse=0.0),
                             Material("glow", diffuse=0.0, exitance=[3.0, 2.0, 1.0])],
                  camera=Camera.look_at([0, -3, 2], [0, 0, 0.5], resolution=(16, 12)),
                  lights=[PointLight("P", [0, 0, 2], [10.0] * 3)])
    plain = render(scene, RenderSettings(samples=4, photons=20_000))
    assert _stages(plain)["photons"] == "skipped: all materials are black: no light bounces"
    assert "photons" not in plain.report["stages"]
    forced = render(scene, RenderSettings(samples=4, photons=20_000, force="photons"))
    assert _stages(forced)["photons"].startswith("forced on")
    assert forced.report["stages"]["photons"]["emitted"] > 0
    assert plain.image.max() > 0.1                                  # the emitter is seen
    np.testing.assert_allclose(forced.image, plain.image, rtol=1e-6, atol=1e-7)


def test_no_lights_and_bounces_zero_skip_with_reasons():
    dark = _room([Material("white", diffuse=0.7)], [])
    stages = _stages(render(dark, RenderSettings(samples=1)))
    assert stages["photons"] == "skipped: nothing emits light"
    assert stages["direct"] == "skipped: no lights, emitters or world light"
    lit = _room([Material("white", diffuse=0.7)], [PointLight("P", [1, 1, 1.8], [50.0] * 3)])
    stages = _stages(render(lit, RenderSettings(samples=1, bounces=0)))
    assert stages["photons"] == "skipped: bounces = 0 (direct light only)"
    assert stages["final_gather"] == "skipped: no photon map"


def test_unknown_forced_stage_is_refused():
    scene = plane_scene([PointLight("P", [0, 0, 1], [1.0] * 3)])
    with pytest.raises(SceneError, match="force names unknown stages"):
        render(scene, RenderSettings(samples=1, force="photons,sparkles"))


def test_presets_set_their_values():
    s = RenderSettings(preset="preview", samples=99).resolved()
    assert (s.samples, s.photons, s.gather_m, s.gather_n, s.indirect) == (4, 200_000, 6, 24, "cache")
    assert RenderSettings(samples=99).resolved().samples == 99              # custom keeps them
    with pytest.raises(SceneError, match="preset"):
        RenderSettings(preset="ultra").resolved()


def test_forcing_shadow_photons_without_area_lights_changes_nothing():
    """Only a point light: the planner skips shadow photons. Forced on, the map is built but
    covers no light (points need none), so every shadow ray is traced as before and the
    picture is the same sample for sample."""
    scene = _room([Material("white", diffuse=0.7)], [PointLight("P", [1, 1, 1.8], [50.0] * 3)])
    settings = dict(samples=2, bounces=0)
    plain = render(scene, RenderSettings(**settings))
    forced = render(scene, RenderSettings(force="shadow_photons", **settings))
    assert _stages(plain)["shadow_photons"].startswith("skipped")
    assert _stages(forced)["shadow_photons"].startswith("forced on")
    assert "shadow_photons" in forced.report["stages"]
    np.testing.assert_array_equal(forced.image, plain.image)
