"""Cycles' light passes (issue 23, item 5; no bpy): Diffuse, Glossy and Transmission, each
Direct, Indirect and Color, with Emit and Env (``engine/passes.py``).

* **Combined is their sum**: a diffuse floor under an emissive quad (black world), with a
  copper sphere (Principled metal, roughness 0.3) beside a smooth glass sphere:
  sum over kinds of (Dir + Ind) x Col + Emit + Env equals Combined to float rounding (each
  part is (light / Col) x Col in float32). Asking for the passes leaves Combined bit for bit
  as it was. Planted bugs it catches: the label taken from the last bounce instead of the
  first (the copper reflects the glass: the light of paths through it went to Transmission,
  where the copper's TransCol is 0, and fell out of the sum: off by 0.25 at the worst pixel);
  light at later hits filed by the kind of the surface it lights (the floor seen through
  glass or in the copper filed as Diffuse, whose Col is 0 there: off by 0.56); Direct taken
  one bounce late (GlossDir empty).
* **Pure diffuse**: a floor and the sky: Glossy and Transmission passes are exactly 0,
  DiffCol = rho_d on the floor, Env = the world's radiance in the sky, and Combined =
  (DiffDir + DiffInd) DiffCol + Env, DiffDir x DiffCol = Lanterna's Direct.
* **Glass slab** (``test_glass.slab_scene``), smooth, IOR 1.5, seen through a 1-degree camera.
  At 75 degrees with the emissive plane on the camera's side: GlossCol = F and TransCol =
  1 - F exactly (smooth glass: F and 1 - F, white tints); the plane seen in the front face's
  reflection is Glossy Direct, GlossDir x GlossCol = F (+0.036 % at seeds 1-4: the camera
  splits smooth glass at its first two vertices, ``integrator.GLASS_SPLIT_DEPTH``, so each
  sample sends one ray down each branch; bound 0.2 %), the light that went in and came back
  is Transmission Indirect, summing with it to the closed form 2F / (1 + F) (seeds 1-4: within
  0.17 %, bound 0.5 %). Head-on with the plane behind: all light is Transmission Indirect,
  (1 - F) / (1 + F) (within 0.01 %, bound 3 %). Planted bugs (each fails here): the glass's
  albedo all in TransCol (TransCol = 1, not 0.96); Direct taken one bounce late (the
  reflection in GlossInd); no split (a branch picked by its Fresnel share, as Cycles does:
  the reflection 0.7-3.4 % off at seeds 1-4, the sum 0.6-2.0 %).
"""
import numpy as np
import pytest

from analytic import icosphere, quad
from lanterna.engine import pipeline
from lanterna.engine.fresnel import dielectric
from lanterna.engine.passes import LIGHT_PASS_NAMES
from lanterna.engine.passes import parse_passes
from lanterna.engine.scene import Camera, Material, Scene, World
from lanterna.engine.settings import RenderSettings
from lanterna.engine.shaders import Closure, seed_reduction
from test_glass import slab_scene


def _material(name, closures):
    seed = seed_reduction(closures)
    return Material(name, diffuse=np.clip(seed.diffuse, 0, 1),
                    specular=np.clip(seed.specular, 0, 1), closures=tuple(closures))


def _sum_of_kinds(p):
    total = p["Emit"] + p["Env"]
    for kind in ("Diff", "Gloss", "Trans"):
        total = total + (p[kind + "Dir"] + p[kind + "Ind"]) * p[kind + "Col"]
    return total


def spheres_scene():
    floor = quad([-5, -5, 0], [10, 0, 0], [0, 10, 0])
    copper = icosphere(0.5, 2, (-0.55, 0, 0.5))
    glass = icosphere(0.5, 2, (0.55, 0, 0.5))
    lamp = quad([-0.5, -0.5, 3], [0, 1, 0], [1, 0, 0])
    tris = np.concatenate([floor, copper, glass, lamp])
    ids = np.concatenate([np.full(len(t), i) for i, t in
                          enumerate((floor, copper, glass, lamp))]).astype(np.int32)
    materials = [
        _material("floor", [Closure("diffuse", params={"color": (0.8, 0.7, 0.6)})]),
        _material("copper", [Closure("principled", params={
            "metallic": 1.0, "roughness": 0.3, "base_color": (0.9, 0.6, 0.5)})]),
        _material("glass", [Closure("glass", params={"roughness": 0.0, "ior": 1.5})]),
        Material("lamp", diffuse=np.zeros(3), exitance=np.full(3, 20.0))]
    return Scene(triangles=tris, material_ids=ids, materials=materials,
                 camera=Camera.look_at([0, -4, 1.6], [0, 0, 0.5], fov_x_deg=32,
                                       resolution=(32, 20)),
                 world=World(radiance=np.zeros(3)))


def test_pass_names_are_cycles_names():
    assert LIGHT_PASS_NAMES == ("DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd",
                                "GlossCol", "TransDir", "TransInd", "TransCol", "Emit", "Env")
    assert parse_passes("diffuse-direct,transmission-color,environment") == \
        ("DiffDir", "TransCol", "Env")
    assert set(LIGHT_PASS_NAMES) <= set(parse_passes("all"))


def test_combined_is_the_sum_over_kinds():
    scene = spheres_scene()
    settings = RenderSettings(samples=2, threads=2, seed=3, photons=5000)
    plain = pipeline.render(scene, settings)
    res = pipeline.render(scene, settings, passes=LIGHT_PASS_NAMES)
    assert np.array_equal(plain.image, res.image)          # the passes change nothing
    p = res.passes
    assert set(p) == set(LIGHT_PASS_NAMES)
    for name in LIGHT_PASS_NAMES:
        assert p[name].shape == (20, 32, 3) and p[name].dtype == np.float32
        assert np.all(np.isfinite(p[name])) and np.all(p[name] >= 0)
    np.testing.assert_allclose(_sum_of_kinds(p), res.image, rtol=1e-5, atol=1e-6)
    # Every kind takes part: the floor, the copper and the glass are all in view.
    for name in ("DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol",
                 "TransInd", "TransCol"):
        assert p[name].max() > 0.01, name
    assert p["Emit"].max() == 0.0 and p["Env"].max() == 0.0   # lamp faces away; black world


def test_pure_diffuse_scene_has_only_diffuse_passes():
    """A floor under a lamp, the sky above the horizon: no Glossy or Transmission light,
    DiffCol = rho_d on the floor, Env = the world in the sky."""
    rho, sky = np.array([0.7, 0.5, 0.3]), 0.1
    floor = quad([-500, -500, 0], [1000, 0, 0], [0, 1000, 0])
    lamp = quad([-0.5, -0.5, 2], [0, 1, 0], [1, 0, 0])
    scene = Scene(triangles=np.concatenate([floor, lamp]),
                  material_ids=np.r_[np.zeros(len(floor)), np.ones(len(lamp))].astype(np.int32),
                  materials=[_material("floor", [Closure("diffuse", params={"color": rho})]),
                             Material("lamp", diffuse=np.zeros(3), exitance=np.full(3, 10.0))],
                  camera=Camera.look_at([0, -1, 0.5], [0, 0, 0.3], fov_x_deg=40,
                                        resolution=(16, 12)),
                  world=World(radiance=np.full(3, sky)))
    res = pipeline.render(scene, RenderSettings(samples=2, threads=2, seed=1, photons=5000),
                          passes="all")
    p = res.passes
    for name in ("GlossDir", "GlossInd", "GlossCol", "TransDir", "TransInd", "TransCol",
                 "Emit"):
        assert p[name].max() == 0.0, name
    on_floor = np.all(p["DiffCol"] > 0, axis=2)
    full = np.all(np.abs(p["DiffCol"] - rho) < 1e-6, axis=2)
    assert full.sum() > 50 and (~on_floor).sum() >= 16         # floor and sky both in view
    assert p["DiffCol"][~full].max() < rho.max()                # the horizon's pixels mix
    # (pixels at the horizon take their seen emission from more samples: emitter_edges)
    assert np.all(p["Env"][0] == np.float32(sky)) and np.all(p["Env"][-1] == 0)
    assert p["DiffDir"][full].min() > 0
    np.testing.assert_allclose(_sum_of_kinds(p), res.image, rtol=1e-5, atol=1e-7)
    # Lanterna's own split agrees here: Direct, Indirect and the world seen (Emission).
    np.testing.assert_allclose(p["DiffDir"] * p["DiffCol"], p["Direct"], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(p["DiffInd"] * p["DiffCol"], p["Indirect"], rtol=1e-5,
                               atol=1e-7)
    np.testing.assert_allclose(p["Env"], p["Emission"], rtol=1e-6)


@pytest.mark.parametrize("theta, lamp_side", [(75, "front"), (0, "behind")])
def test_glass_slab_light_is_glossy_and_transmission(theta, lamp_side):
    closures = [Closure("glass", params={"roughness": 0.0, "ior": 1.5})]
    res = pipeline.render(slab_scene(closures, theta, lamp_side),
                          RenderSettings(samples=64, threads=2, seed=1),
                          passes=LIGHT_PASS_NAMES)
    p = {name: image.reshape(-1, 3).mean(axis=0) for name, image in res.passes.items()}
    F = float(dielectric(np.cos(np.radians(theta)), 1.5)[0])
    np.testing.assert_allclose(p["GlossCol"], F, rtol=2e-3)
    np.testing.assert_allclose(p["TransCol"], 1 - F, rtol=2e-3)
    assert np.all(p["DiffCol"] == 0) and np.all(p["DiffDir"] == 0) and np.all(p["DiffInd"] == 0)
    through = p["TransInd"] * p["TransCol"]
    assert np.all(p["TransDir"] == 0)           # the plane is two crossings away
    if lamp_side == "front":
        reflected = p["GlossDir"] * p["GlossCol"]
        np.testing.assert_allclose(reflected, F, rtol=2e-3)
        assert np.all(p["GlossInd"] == 0)
        np.testing.assert_allclose(reflected + through, 2 * F / (1 + F), rtol=5e-3)
    else:
        assert np.all(p["GlossDir"] == 0) and np.all(p["GlossInd"] == 0)
        np.testing.assert_allclose(through, (1 - F) / (1 + F), rtol=0.03)
