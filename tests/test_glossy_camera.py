"""Glossy camera paths (issue 23, first part; no bpy): a plane under a uniform white world.

A surface alone under a world of radiance 1 reflects, towards any view direction wo, its
directional albedo: L(wo) = sum_j w_j E_j(wo) + rho_d (1 - max E_layer(wo)) for glossy lobes j
(``bsdf.glossy_material``: the lobe's own tables, ``MicrofacetReflection.albedo``) and a diffuse
base below a Principled specular layer, which Cycles scales by one minus the layer's albedo.
The camera is far away with a 0.6 degree field, so every pixel sees the plane at one view
cosine mu. The glossy lobes take the world from their sampled rays and from the world's light
samples, weighted by multiple importance sampling (``integrator``), the diffuse part from light
samples alone, so both paths, the weights and the layering are exercised. (The tolerance
below was measured before MIS, when the lobes took the world from their rays alone.)

Cases: the Principled BSDF at Blender's defaults (dielectric layer over a 0.8 base), copper
metal (Metallic 1, Roughness 0.3: a sharp lobe), Mix(Diffuse, Glossy 0.2), a white Glossy
0.5 (Multiscatter GGX: albedo 1), a Principled with sheen, a tinted coat and a thin film (the
RGB layering through the integrator) and the Sheen BSDF node, each at mu = 0.95, 0.5, 0.2.

Tolerance: 5 seeds at 16 spp gave per-case standard deviations of at most 0.64 % (metal at
mu = 0.2) and means within 0.3 % of the closed form; 4 x 0.64 % rounds up to 2.5 %, so a fixed
seed fails by chance about once in 10^4. Planted bugs it catches: the layering factor left out
(Principled +4.7 % at mu = 0.95), world light samples also fed to the glossy lobes (the world
counted twice: +~100 % on the white Glossy), a lobe's weight divided by the wrong pick
probability (Mix: off by the ratio of the lobes' shares).
"""
import numpy as np
import pytest

from analytic import quad
from lanterna.engine import pipeline
from lanterna.engine.bsdf import glossy_material
from lanterna.engine.scene import Camera, Material, Scene, World
from lanterna.engine.settings import RenderSettings
from lanterna.engine.shaders import Closure, seed_reduction

TOLERANCE = 0.025
# The layered case (sheen, tinted coat, thin film over orange): 5 seeds at 16 spp gave standard
# deviations up to 1.23 % (mu = 0.2), means within 1 % of the closed form: 4 x 1.23 % -> 5 %.
# The Sheen BSDF alone has zero variance (every sample's weight is its albedo).
TOLERANCES = {"layered sheen coat film": 0.05}

CASES = {
    "principled default": [Closure("principled")],
    "copper r0.3": [Closure("principled", params={"metallic": 1.0, "roughness": 0.3,
                                                  "base_color": (0.9, 0.6, 0.5)})],
    "mix diffuse glossy": [Closure("diffuse", params={"color": (0.8, 0.2, 0.2)}).scaled(0.5),
                           Closure("glossy", params={"roughness": 0.2}).scaled(0.5)],
    "white glossy r0.5": [Closure("glossy", params={"color": (1, 1, 1), "roughness": 0.5})],
    "layered sheen coat film": [Closure("principled", params={
        "base_color": (0.8, 0.3, 0.1), "roughness": 0.4, "sheen_weight": 0.7,
        "sheen_roughness": 0.4, "sheen_tint": (0.5, 0.8, 1.0), "coat_weight": 0.8,
        "coat_tint": (0.9, 0.6, 0.4), "thin_film_thickness": 400.0})],
    "sheen node": [Closure("sheen", params={"color": (0.9, 0.9, 0.9), "roughness": 0.3})],
}


def _look_at(eye, target):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, [0, 0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, u, -f, eye
    return m


def plane_under_white_world(closures, mu):
    seed = seed_reduction(closures)
    material = Material("plane", diffuse=np.clip(seed.diffuse, 0, 1),
                        specular=np.clip(seed.specular, 0, 1), closures=tuple(closures))
    tris = quad([0, 0, 0], [500, 0, 0], [0, 500, 0])
    eye = [0, -10 * np.sqrt(1 - mu * mu), 10 * mu]
    camera = Camera(_look_at(eye, [0, 0, 0]), 0.005, 0.005, (8, 8))
    return Scene(triangles=tris, shading_normals=None,
                 material_ids=np.zeros(len(tris), np.int32), materials=[material],
                 camera=camera, world=World(radiance=np.ones(3)))


def directional_albedo(closures, mu):
    glossy = glossy_material(closures)
    wo = np.array([[0.0, -np.sqrt(1 - mu * mu), mu]])
    n = np.array([[0.0, 0.0, 1.0]])
    total = sum(w[0] * lobe.at(1).albedo(wo, n)[0]
                for lobe, w in zip(glossy.lobes, glossy.lobe_weights(wo, n)))
    return total + seed_reduction(closures).diffuse * glossy.diffuse_factor(wo, n)[0]


@pytest.mark.parametrize("mu", [0.95, 0.5, 0.2])
@pytest.mark.parametrize("name", list(CASES))
def test_plane_under_a_white_world_reflects_its_albedo(name, mu):
    closures = CASES[name]
    result = pipeline.render(plane_under_white_world(closures, mu),
                             RenderSettings(samples=16, threads=1, seed=3))
    seen = result.image.reshape(-1, 3).mean(axis=0)
    expected = directional_albedo(closures, mu)
    np.testing.assert_allclose(seen, expected, rtol=TOLERANCES.get(name, TOLERANCE),
                               err_msg=f"{name} at mu={mu}")


def test_materials_without_glossy_lobes_keep_the_seed_path():
    """Diffuse-only closures (and materials built without closures) make no glossy lobes, so
    the seed scenes' pictures cannot change."""
    assert glossy_material([Closure("diffuse")]) is None
    assert glossy_material([Closure("principled", params={"specular_ior_level": 0.0})]) is None
    assert glossy_material([]) is None


def test_glossy_furnace_in_the_default_mode():
    """A closed 2 m box whose walls emit S = (1, 0.5, 0.25) and reflect by 0.7 Diffuse(0.6) +
    0.3 Glossy(white, roughness 0.4, Multiscatter GGX: albedo 1 at every angle): the albedo
    is 0.72 whatever the direction, so L = S / (1 - 0.72) everywhere, in the default mode
    (cache + gather over the photon map) at default settings. This exercises the photons'
    glossy scattering (``bsdf.sample_glossy``), the gather's mirror-followed rays and the
    camera's glossy lobes at hits where the path ends (irradiance x albedo / pi).

    Measured over seeds 0-4: -1.34, -0.71, -1.11, -0.81, -1.30 % (mean -1.05, SD 0.28; the
    diffuse furnaces' ~1 % edge deficit, test_analytic_modes.py); the issue's 2 % bound is
    3.4 SD from the mean. Before the gather counted emitters seen in mirrors it was -9.6 %
    (SD 0.28) over the same seeds: the light the glossy walls reflect from the glowing walls
    never reached the cache."""
    from analytic import box_room

    S = np.array([1.0, 0.5, 0.25])
    closures = [Closure("diffuse", params={"color": (0.6, 0.6, 0.6)}).scaled(0.7),
                Closure("glossy", params={"color": (1, 1, 1), "roughness": 0.4}).scaled(0.3),
                Closure("emission", params={"radiance": S})]
    seed = seed_reduction(closures)
    tris = box_room(size=(2.0, 2.0, 2.0))
    scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("glow", diffuse=seed.diffuse, specular=seed.specular,
                                      exitance=seed.exitance, closures=tuple(closures))],
                  camera=Camera.look_at([1, 0.2, 1], [1, 2, 1], resolution=(24, 24)))
    result = pipeline.render(scene, RenderSettings(seed=0))
    np.testing.assert_allclose(result.image.reshape(-1, 3).mean(axis=0), S / (1 - 0.72),
                               rtol=0.02)
