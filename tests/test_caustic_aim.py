"""The caustic map aims the sun's and the world's photons at the specular surfaces (issue 23;
``photons.specular_bounds``, Jensen's projection maps in their simplest form).

A 0.5 m square mirror, tilted 45 degrees, hangs 1 m over a 200 m ground under a zenith sun
of irradiance E; it turns the sun's beam sideways onto a wall 2 m away, which the sun itself
meets edge-on. The beam's cross-section is the mirror's shadow, 0.5 x 0.5 x cos 45 = 0.177
m^2, and where it meets the wall square on its irradiance is exactly E (a mirror of
reflectance 1). Aimed at the whole 200 m scene, 1 photon in 355,000 would meet the mirror:
the 20,000-photon pilot saw nothing, and no caustic map was made (so the floor by a mirror
ball under an HDRI came out 11 % dark). Aimed at the mirror's bounding sphere, 45 % meet it
(the beam's area over that sphere's disc), and the caustic on the wall is E.
"""
import numpy as np

from analytic import quad
from lanterna.engine import photons as P
from lanterna.engine.accel import Accelerator
from lanterna.engine.scene import Camera, Material, Scene, SunLight

E = np.array([3.0, 2.0, 1.0])
BEAM_AREA = 0.5 * 0.5 * np.cos(np.pi / 4)


def _mirror_scene():
    tilt = 0.25 * np.array([0.0, 1.0, 1.0]) / np.sqrt(2)
    tris = np.concatenate([quad([0, 0, 0], [100.0, 0, 0], [0, 100.0, 0]),       # ground
                           quad([0, 0, 1.0], [0.25, 0, 0], tilt),                  # mirror
                           quad([0, -2.0, 1.0], [0, 0, 1.0], [1.0, 0, 0])])       # wall, +y
    mats = [Material("ground", diffuse=0.5), Material("mirror", diffuse=0.0, specular=1.0),
            Material("wall", diffuse=0.5)]
    return Scene(triangles=tris, material_ids=np.array([0, 0, 1, 1, 2, 2], np.int32),
                 materials=mats, camera=Camera.look_at([3.0, -6.0, 2.0], [0, -1.0, 1.0]),
                 lights=[SunLight("Sun", [0.0, 0.0, -1.0], E)]).validate()


def test_the_specular_bounds_are_the_mirrors_sphere():
    scene = _mirror_scene()
    center, radius = P.specular_bounds(scene, P.SceneSurfaces(scene))
    np.testing.assert_allclose(center, [0.0, 0.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(radius, np.sqrt(2) * 0.25, rtol=1e-5)


def test_the_pilot_meets_the_mirror_in_the_share_of_its_beam():
    """Share = beam area / the sphere's disc (binomial, 5 sigma); the flux share is against
    the sun's flux over the whole scene's disc; the mirror passes all of what it meets."""
    scene = _mirror_scene()
    accel = Accelerator(scene.triangles, threads=1)
    share, flux_share, passed = P.specular_share(scene, accel, seed=3)
    expected = BEAM_AREA / (np.pi * 0.125)
    sigma = np.sqrt(expected * (1 - expected) / P.CAUSTIC_PILOT)
    assert abs(share - expected) < 5 * sigma, (share, expected)
    lo, hi = scene.bounds()
    whole = np.pi * (np.linalg.norm(hi - lo) / 2) ** 2
    np.testing.assert_allclose(flux_share, BEAM_AREA / whole, rtol=5 * sigma / expected)
    assert flux_share < P.MIN_CAUSTIC_FLUX and passed == 1.0


def test_the_aimed_caustic_on_the_wall_is_the_suns_irradiance():
    """The caustic map's irradiance over the middle of the beam's patch on the wall (x in
    [-0.2, 0.2], z in [0.88, 1.12]) is E: measured 0.992-1.008 E at seeds 1-6 (SD 0.55 %)."""
    scene = _mirror_scene()
    accel = Accelerator(scene.triangles, threads=1)
    rng = np.random.default_rng(0)
    points = np.stack([rng.uniform(-0.2, 0.2, 400), np.full(400, -2.0),
                       rng.uniform(0.88, 1.12, 400)], 1)
    normals = np.tile([0.0, 1.0, 0.0], (400, 1))
    for seed in (1, 2):
        cmap = P.build_caustic_map(scene, accel, 200_000, seed=seed)
        assert cmap.stats["stored"] > 0.9 * 200_000 * BEAM_AREA / (np.pi * 0.125)
        mean = cmap.irradiance(points, normals).mean(axis=0)
        np.testing.assert_allclose(mean / E, 1.0, atol=0.02)
