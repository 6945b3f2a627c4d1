"""Glass (issue 23, no bpy): a dielectric slab and sphere of IOR 1.5 against closed forms.

Camera paths refract and reflect through Glass BSDF closures (``bsdf.GlassLobe``: a smooth
``SmoothGlass`` or a GGX ``MicrofacetGlass``), with eta = IOR entering the front face and
1 / IOR leaving by the back face.

* **Slab** (0.2 m thick, 100 m wide) seen at angle theta through a 1-degree camera, lit by one
  emissive plane (radiance 1, 2 km wide, black world) either behind the slab (the pixels are
  the slab's total transmittance) or on the camera's side (its total reflectance). Cycles'
  dielectric Fresnel F is the unpolarised mean, the same at both faces of a parallel slab, so
  summing the internal reflections gives T = (1 - F) / (1 + F) and R = 2F / (1 + F).
  Smooth white glass carries weight 1 on every path (F / P and (1 - F) / (1 - P) with P = F),
  so the pixels are the share of paths that reach the plane: binomial noise only. With N =
  16 x 16 x 512 = 131072 paths, the relative SD is sqrt((1 - p) / (p N)): 0.34 % for R and
  0.23 % for T at 75 degrees (R = 0.404), 0.10 % for T at normal incidence; measured over
  seeds 1-4 at 64 samples: R at 0 degrees 0.0769, 0.0808, 0.0828, 0.0798 (binomial, as
  predicted). The issue's 1 % bound is 3 SD of the noisiest case. Planted bugs it catches:
  the refraction weighted by (1 - F) twice (T -4 % at 0 degrees), eta not inverted at the
  back face (the ray leaves bent: T at 75 degrees changes), the emissive plane counted by
  light samples as well as by the refracted rays (T x 2).
* **Sphere** in a uniform white world (radiance 1): no absorption, so every path leaves to the
  world and every pixel on the sphere is 1, for smooth glass and for rough glass (GGX 0.3,
  Multiscatter: albedo 1), up to the paths cut at the specular depth. Smooth: 0 noise; rough:
  measured mean over the sphere's pixels 0.9990-1.0004 over seeds 1-4 (SD 0.06 %).
"""
import numpy as np
import pytest

from analytic import icosphere, quad
from lanterna.engine import pipeline
from lanterna.engine.bsdf import GlassLobe, glossy_material
from lanterna.engine.fresnel import dielectric
from lanterna.engine.scene import Camera, Material, Scene, World
from lanterna.engine.settings import RenderSettings
from lanterna.engine.shaders import Closure, seed_reduction

TOLERANCE = 0.01


def _box(lo, hi):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    return np.concatenate([
        quad([x0, y0, z0], [dx, 0, 0], [0, 0, dz]), quad([x0, y1, z0], [0, 0, dz], [dx, 0, 0]),
        quad([x0, y0, z0], [0, 0, dz], [0, dy, 0]), quad([x1, y0, z0], [0, dy, 0], [0, 0, dz]),
        quad([x0, y0, z0], [0, dy, 0], [dx, 0, 0]), quad([x0, y0, z1], [dx, 0, 0], [0, dy, 0])])


def _glass_material(closures):
    seed = seed_reduction(closures)
    return Material("glass", diffuse=seed.diffuse, specular=np.clip(seed.specular, 0, 1),
                    closures=tuple(closures))


def slab_scene(closures, theta_deg, lamp_side):
    """The slab |y| < 0.1 seen from 1 m away at ``theta_deg`` from its normal; the emissive
    plane at y = 5 ("behind") or y = -2 ("front")."""
    lamp = Material("lamp", diffuse=np.zeros(3), exitance=np.full(3, np.pi))
    slab = _box((-50, -0.1, -50), (50, 0.1, 50))
    y = 5.0 if lamp_side == "behind" else -2.0
    plane = quad([-1000, y, -1000], [2000, 0, 0], [0, 0, 2000])
    theta = np.radians(theta_deg)
    eye = np.array([-np.sin(theta), -np.cos(theta), 0.0])
    tris = np.concatenate([slab, plane])
    ids = np.r_[np.zeros(len(slab), np.int32), np.ones(len(plane), np.int32)]
    return Scene(triangles=tris, material_ids=ids, materials=[_glass_material(closures), lamp],
                 camera=Camera.look_at(eye, [0, 0, 0], fov_x_deg=1.0, resolution=(16, 16)),
                 world=World(radiance=np.zeros(3)))


@pytest.mark.parametrize("theta, lamp_side", [(0, "behind"), (75, "behind"), (75, "front")])
def test_smooth_glass_slab_transmits_and_reflects_the_closed_form(theta, lamp_side):
    closures = [Closure("glass", params={"roughness": 0.0, "ior": 1.5})]
    result = pipeline.render(slab_scene(closures, theta, lamp_side),
                             RenderSettings(samples=512, threads=2, seed=1))
    F = float(dielectric(np.cos(np.radians(theta)), 1.5)[0])
    expected = (1 - F) / (1 + F) if lamp_side == "behind" else 2 * F / (1 + F)
    seen = result.image.reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(seen, expected, rtol=TOLERANCE)


def test_principled_transmission_is_the_same_glass():
    """Principled with Transmission 1, a white base and roughness 0 is smooth glass: the slab
    transmits the same total (Cycles' sqrt(Base Color) tint is 1)."""
    closures = [Closure("principled", params={"transmission": 1.0, "roughness": 0.0,
                                              "base_color": (1, 1, 1)})]
    result = pipeline.render(slab_scene(closures, 0, "behind"),
                             RenderSettings(samples=512, threads=2, seed=1))
    seen = result.image.reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(seen, 0.96 / 1.04, rtol=TOLERANCE)


@pytest.mark.parametrize("roughness", [0.0, 0.3])
def test_glass_sphere_in_a_white_world_is_white(roughness):
    closures = [Closure("glass", params={"roughness": roughness, "ior": 1.5})]
    tris = icosphere(1.0, 4)
    # Sphere of angular radius asin(1/4) = 14.5 deg; the frame (28 deg wide) lies within it
    # but for its corners: keep the pixels whose centre is within 13 deg of the axis.
    size = 32
    scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                  materials=[_glass_material(closures)],
                  camera=Camera.look_at([0, -4, 0], [0, 0, 0], fov_x_deg=28.0,
                                        resolution=(size, size)),
                  world=World(radiance=np.ones(3)))
    result = pipeline.render(scene, RenderSettings(samples=16, threads=2, seed=1))
    image = result.image.reshape(size, size, 3)
    c = (np.arange(size) + 0.5) / size * 2 - 1
    tan = np.tan(np.radians(14.0))
    angle = np.degrees(np.arctan(np.hypot(*np.meshgrid(c * tan, c * tan))))
    on_sphere = image[angle < 13.0]
    np.testing.assert_allclose(on_sphere.mean(axis=0), 1.0, rtol=TOLERANCE)


def test_glass_closures_make_glass_lobes_and_no_unsupported_note():
    for kind in ("glass", "refraction"):
        material = glossy_material([Closure(kind)])
        assert isinstance(material.lobes[0], GlassLobe)
        assert not seed_reduction([Closure(kind)]).notes
    principled = glossy_material([Closure("principled", params={"transmission": 0.5})])
    glass = [lobe for lobe in principled.lobes if isinstance(lobe, GlassLobe)]
    assert len(glass) == 1 and np.allclose(glass[0].weight, 0.5)
    # The layer over the diffuse takes the other half.
    assert np.allclose(principled.layer.weight, 0.5)
