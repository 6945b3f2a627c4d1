"""Closed-form answers in every indirect mode at default settings (issue 19; no bpy).

``indirect = "cache"`` is what every user renders with; these cases run it, ``gather`` and
``photon-map`` at ``RenderSettings()`` defaults (seed 0, 16 spp, automatic photon count: the
minimum 200k at 24 x 24 pixels), and compare the image mean per channel with the exact answer:

* coloured furnace: a closed 2 m box whose walls emit radiance S = (1, 0.5, 0.25) (both faces,
  as Cycles' Emission shader) and reflect a = (0.9, 0.6, 0.3): L = S / (1 - a) =
  (10, 1.25, 0.357) everywhere;
* grey furnace, a = 0.95, S = 1: L = 20 (a path of about 20 bounces: the bounce limit matters);
* pbrt's sphere: a 100 W point light at the centre of a closed diffuse icosphere (rho = 0.6,
  1280 faces, A its area): L = rho / pi * Phi / (A (1 - rho)).

Tolerance 2 % per channel (the issue's). Measured over seeds 0-7 (``mean`` and ``SD`` of the
relative error, red channel; the other channels lie closer), 2026-12-07:

=========  ==========  ===============  ===============  ===============
case       channel     photon-map       gather           cache
=========  ==========  ===============  ===============  ===============
coloured   red         -1.03 % (0.35)   -0.06 % (0.21)   -0.02 % (0.21)
grey 0.95  all         -0.92 % (0.38)   -0.15 % (0.32)   -0.06 % (0.32)
sphere     all         -0.15 % (0.13)   -0.01 % (0.09)   -0.01 % (0.14)
=========  ==========  ===============  ===============  ===============

So the bound is at least 2.6 SD from each mean (the worst single value over the 72 renders:
-1.53 %). The photon-map mode's ~1 % deficit in the furnaces is the k-nearest-neighbour disc
cut at the box's edges and corners (a pixel near an edge finds a disc partly outside the
wall); the sphere has no edges and no deficit. The gather and cache modes read estimates that
count only the part of the disc their surface covers (``Accelerator.disc_coverage``): before
that they had the same deficit, -0.74 % / -1.15 % (coloured) and -0.87 % / -1.08 % (grey).
The photon-map mode looks up an estimate at every camera sample, where the coverage's 16
probe rays would cost as much as the look-up itself; it stays the seed's estimate.

What these cases caught (seed 0, red channel): with the seed's channel-averaged Russian
roulette the coloured furnace came out -11.2 % (photon-map), -6.9 % (gather), -8.3 % (cache),
over seeds 0-7 from -14.4 % to +6.1 % (SD 5.4-6.8 %): the red weight grew x1.5 a bounce and
its variance diverged. With the bounce limit at 64 the grey furnace lost 0.95^66 = 3.4 % of its
light: -4.2 %, -3.6 %, -3.9 %.
"""
import numpy as np
import pytest

from analytic import box_room, icosphere, triangle_area_sum
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.bsdf import roulette_probabilities
from lanterna.engine.photons import emit_photons, trace_photons
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.settings import INDIRECT_METHODS
from lanterna.engine.scene import Camera, Material, PointLight, Scene

TOLERANCE = 0.02


def furnace(albedo, radiance):
    """A closed 2 m box of one material that emits ``radiance`` [W m^-2 sr^-1] from both
    faces and reflects ``albedo``, seen from inside (24 x 24 pixels)."""
    tris = box_room(size=(2.0, 2.0, 2.0))
    exitance = np.pi * np.asarray(radiance, float)
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("glow", diffuse=albedo, exitance=exitance)],
                 camera=Camera.look_at([1, 0.2, 1], [1, 2, 1], resolution=(24, 24)))


def sphere(rho=0.6, flux=100.0):
    tris = icosphere(1.0, 4)
    camera = Camera.look_at([0.0, -0.3, 0.0], [0.0, 1.0, 0.0], fov_x_deg=70.0,
                            resolution=(24, 24))
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("white", diffuse=rho)], camera=camera,
                 lights=[PointLight("Lamp", [0.0, 0.0, 0.0], [flux] * 3)])


def _sphere_radiance(rho=0.6, flux=100.0):
    area = triangle_area_sum(icosphere(1.0, 4))
    return np.full(3, rho / np.pi * flux / (area * (1 - rho)))


CASES = {
    "coloured furnace": (lambda: furnace([0.9, 0.6, 0.3], [1.0, 0.5, 0.25]),
                         lambda: np.array([1.0, 0.5, 0.25]) / (1 - np.array([0.9, 0.6, 0.3]))),
    "grey furnace": (lambda: furnace(0.95, 1.0), lambda: np.full(3, 1.0 / 0.05)),
    "sphere": (sphere, _sphere_radiance),
}


@pytest.mark.parametrize("indirect", INDIRECT_METHODS)
@pytest.mark.parametrize("case", list(CASES))
def test_default_settings_meet_the_closed_form(case, indirect):
    make, exact = CASES[case]
    result = render(make(), RenderSettings(indirect=indirect))
    image = result.image.reshape(-1, 3).astype(np.float64)
    assert np.isfinite(image).all()
    assert result.report["stages"]["photons"]["emitted"] == pytest.approx(200_000, abs=8)
    error = image.mean(axis=0) / exact() - 1
    assert np.all(np.abs(error) <= TOLERANCE), f"{case}, {indirect}: {np.round(100 * error, 2)} %"


def test_roulette_never_lets_a_channel_grow():
    """Russian roulette survives with the largest channel of the reflectance, so a photon's
    power in any channel never exceeds what it left the light with (DESIGN.md §4). In the
    coloured furnace every stored photon's red, green and blue are at most the emitted
    photon's; the seed's channel-averaged survival (P = 0.6 for (0.9, 0.6, 0.3)) grew red by
    1.5 a bounce: after 10 bounces 57x."""
    scene = furnace([0.9, 0.6, 0.3], [1.0, 0.5, 0.25]).validate()
    accel = Accelerator(scene.triangles, threads=1)
    emitted = emit_photons(scene, 20_000, sampling.rng_for(3, sampling.STREAM_PHOTON))
    pmap = trace_photons(scene, accel, emitted, sampling.rng_for(3, 5))
    start = emitted.power.max(axis=0)
    assert pmap.bounces.max() >= 10
    assert np.all(pmap.power.max(axis=0) <= start * (1 + 1e-6)), (pmap.power.max(axis=0), start)
    # The probabilities themselves: largest channels, scaled where their sum exceeds 1.
    p_d, p_s = roulette_probabilities(np.array([[0.9, 0.6, 0.3], [0.9, 0.0, 0.0], [0.2] * 3]),
                                      np.array([[0.0, 0.0, 0.0], [0.0, 0.9, 0.0], [0.3] * 3]))
    np.testing.assert_allclose(p_d, [0.9, 0.5, 0.2])
    np.testing.assert_allclose(p_s, [0.0, 0.5, 0.3])
