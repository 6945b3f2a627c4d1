"""The per-light shadow-photon switch (``AreaLight.shadow_photons``, Blender's
``Light.lanterna.shadow_photons``; seed 7.2, 9.6) in the core (no bpy).

The scene: a 10 m floor, a 1 m square occluder 1.5 m up, and two 1 m square area lights 3 m
up facing down: "On" above the occluder, "Off" 2.5 m beside it (so both cast a penumbra).

What is checked
* A light with the switch off sends no shadow photons: the map holds none of its photons,
  does not cover it, and names it in ``stats["lights_switched_off"]``; the other light is
  covered as before (a control with both switches on covers both).
* The plan: with every eligible light off the stage is skipped with the reason "every
  eligible light has shadow photons off"; with one of two off it runs and counts the other.
* The picture: a light that is the only one and is switched off, with the stage forced on,
  gives the plain picture sample for sample (the map covers nothing, so ``direct.py`` traces
  every shadow ray as without a map). With one of two lights off the picture equals the one
  with both on within noise: block means of 4 x 4 pixels agree within 5 combined standard
  errors (measured from the spread over seeds) plus 2 % of the block, the bias bound the
  shadow-photon classes have in penumbrae (tests/test_shadow_photons.py).
"""
import numpy as np

from analytic import quad
from lanterna.engine.accel import Accelerator
from lanterna.engine.lights import LightSet
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import AreaLight, Camera, Material, Scene
from lanterna.engine.shadow_photons import build_shadow_photon_map


def _area(name, x, shadow_photons=True, power=100.0):
    m = np.eye(4)
    m[:3, 3] = [x, 0.0, 3.0]
    return AreaLight(name, "SQUARE", m, 1.0, 1.0, [power] * 3, shadow_photons=shadow_photons)


def _scene(on=True, off=False, only_off=False, resolution=(24, 18)):
    tris = np.concatenate([quad([0, 0, 0], [5, 0, 0], [0, 5, 0]),
                           quad([0, 0, 1.5], [0.5, 0, 0], [0, 0.5, 0])])
    lights = ([_area("Off", 2.5, shadow_photons=off)] if only_off
              else [_area("On", 0.0, shadow_photons=on), _area("Off", 2.5, shadow_photons=off)])
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("white", diffuse=0.7)],
                 camera=Camera.look_at([1.2, -4.0, 5.0], [1.2, 0.0, 0.0], resolution=resolution),
                 lights=lights).validate()


def test_the_flag_is_a_light_field_and_reaches_the_emitter():
    light = _area("L", 0.0)
    assert light.shadow_photons is True
    assert _area("L", 0.0, shadow_photons=0).shadow_photons is False
    lights = LightSet(_scene())
    assert [(e.name, e.shadow_photons) for e in lights.sampled] == [("On", True), ("Off", False)]


def test_a_light_switched_off_gets_no_shadow_photons():
    scene = _scene()
    accel = Accelerator(scene.triangles, threads=1)
    lights = LightSet(scene)
    on, off = (next(i for i, e in enumerate(lights.sampled) if e.name == n) for n in ("On", "Off"))
    smap = build_shadow_photon_map(scene, accel, lights, 40_000, seed=1)
    assert smap.covers(on) and not smap.covers(off)
    assert np.count_nonzero(smap.light == off) == 0
    assert np.count_nonzero(smap.light == on) == len(smap) > 0
    assert list(smap.stats["lights"]) == [on]
    assert smap.stats["photons_per_light"] == {"On": 40_000}
    assert smap.stats["lights_switched_off"] == ["Off"]

    # Control: with both switches on both lights get photons.
    both = _scene(off=True)
    lights_both = LightSet(both)
    full = build_shadow_photon_map(both, accel, lights_both, 40_000, seed=1)
    assert full.covers(on) and full.covers(off)
    assert sorted(full.stats["photons_per_light"]) == ["Off", "On"]
    assert full.stats["lights_switched_off"] == []
    accel.close()


def test_plan_reasons():
    settings = RenderSettings(samples=1, bounces=0)
    alone = render(_scene(only_off=True, resolution=(8, 6)), settings).report
    assert alone["plan"]["stages"]["shadow_photons"] == \
        "skipped: every eligible light has shadow photons off"
    assert "shadow_photons" not in alone["stages"]
    mixed = render(_scene(resolution=(8, 6)), settings).report
    assert mixed["plan"]["stages"]["shadow_photons"] == \
        "1 area/mesh light(s) with penumbrae; 1 with shadow photons off"
    assert mixed["stages"]["shadow_photons"]["lights_switched_off"] == ["Off"]


def test_sole_light_switched_off_gives_the_plain_picture():
    scene = _scene(only_off=True)
    settings = dict(samples=4, bounces=0, seed=2)
    plain = render(scene, RenderSettings(shadow_photons=False, **settings))
    forced = render(scene, RenderSettings(force="shadow_photons", **settings))
    assert forced.report["plan"]["stages"]["shadow_photons"].startswith("forced on")
    assert forced.report["stages"]["shadow_photons"]["emitted"] == 0
    assert forced.report["stages"]["camera"]["shadow_rays_saved"] == 0
    np.testing.assert_array_equal(forced.image, plain.image)
    assert plain.image.max() > 0


def test_one_light_off_leaves_the_picture_within_noise():
    block = 4
    seeds = range(4)
    settings = dict(samples=8, light_samples=2, bounces=0)
    off = [render(_scene(off=False), RenderSettings(seed=s, **settings)) for s in seeds]
    on = [render(_scene(off=True), RenderSettings(seed=s, **settings)) for s in seeds]
    # The switch did what it says: fewer shadow rays saved with one light off.
    saved_off = sum(r.report["stages"]["camera"]["shadow_rays_saved"] for r in off)
    saved_on = sum(r.report["stages"]["camera"]["shadow_rays_saved"] for r in on)
    assert saved_on > saved_off

    def blocks(results):
        img = np.stack([r.image.mean(axis=2) for r in results])        # (seeds, H, W)
        s, h, w = img.shape
        img = img[:, :h - h % block, :w - w % block]
        return img.reshape(s, h // block, block, w // block, block).mean(axis=(2, 4))

    a, b = blocks(off), blocks(on)
    n = len(seeds)
    se = np.sqrt(a.var(axis=0, ddof=1) / n + b.var(axis=0, ddof=1) / n)
    diff = np.abs(a.mean(axis=0) - b.mean(axis=0))
    allowed = 5 * se + 0.02 * b.mean(axis=0) + 1e-9
    assert b.mean() > 0
    assert np.all(diff <= allowed), float(np.max(diff - allowed))
