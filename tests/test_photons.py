"""Photon emission, tracing and the photon-map estimate against closed forms (no bpy).

Tolerances: 3 % as issue 3 asks for the estimates; the emitted flux is exact to 1e-6; the
energy balance (emitted = absorbed + escaped + capped) holds in expectation under Russian
roulette, and its tolerance is 4 standard errors of the absorbed flux, estimated from the
per-photon powers.
"""
import numpy as np
import pytest

from analytic import box_room, plane_scene, point_irradiance, quad
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.photons import emit_photons, trace_photons
from lanterna.engine.scene import AreaLight, Camera, Material, PointLight, Scene


def _furnace(rho, exitance=2.0):
    tris = box_room(size=(2.0, 2.0, 2.0))
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("glow", diffuse=rho, exitance=exitance)],
                 camera=Camera.look_at([1, 0.2, 1], [1, 2, 1]))


def test_emitted_flux_equals_light_flux():
    m = np.eye(4)
    m[:3, 3] = [0, 0, 2]
    scene = plane_scene([PointLight("P", [0, 0, 1], [100.0, 50.0, 20.0]),
                         AreaLight("A", "DISK", m, 1.0, 1.0, [30.0, 30.0, 30.0])])
    # plus an emissive triangle
    scene = Scene(triangles=np.concatenate([scene.triangles, quad([0, 0, 3], [0.2, 0, 0], [0, 0.2, 0])]),
                  material_ids=np.array([0, 0, 1, 1], np.int32),
                  materials=[Material("w"), Material("e", exitance=[5.0, 4.0, 3.0])],
                  camera=scene.camera, lights=scene.lights)
    emitted = emit_photons(scene, 100_000, sampling.rng_for(1, sampling.STREAM_PHOTON))
    mesh_flux = np.array([5.0, 4.0, 3.0]) * 0.4 * 0.4 * 2      # both faces
    expected = np.array([100.0, 50.0, 20.0]) + 30.0 + mesh_flux
    np.testing.assert_allclose(emitted.power.sum(axis=0), expected, rtol=1e-6)


def test_photon_map_irradiance_under_point_light():
    light = PointLight("Lamp", [0.0, 0.0, 1.0], [1000.0] * 3)
    scene = plane_scene([light], size=8.0).validate()
    accel = Accelerator(scene.triangles, threads=1)
    emitted = emit_photons(scene, 1_000_000, sampling.rng_for(2, sampling.STREAM_PHOTON))
    pmap = trace_photons(scene, accel, emitted, sampling.rng_for(2, 5)).build()
    assert pmap.nbytes / len(pmap) <= 40
    # Away from the edges: points within 2 m of the centre of the 8 m plane.
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-2, 2, 200), rng.uniform(-2, 2, 200), np.zeros(200)])
    n = np.tile([0.0, 0.0, 1.0], (200, 1))
    est = pmap.irradiance(pts, n, k=200, max_radius=0.5)
    exact = point_irradiance(pts, n, light.position, light.flux)
    # Each estimate is biased by the curvature of E inside its disc and noisy (k = 200,
    # about 7 %); the mean over the points is the check.
    ratio = est[:, 0] / exact[:, 0]
    assert abs(ratio.mean() - 1.0) < 0.03
    assert np.abs(ratio - 1).max() < 0.3


@pytest.mark.parametrize("rho", [0.5, 0.8])
def test_white_furnace(rho):
    """Closed box of exitance M and reflectance rho: E = M / (1 - rho) on every wall, so the
    photon-map radiance of the seed's direct visualisation is (M/pi) / (1 - rho)."""
    m_exit = 2.0
    scene = _furnace(rho, m_exit).validate()
    accel = Accelerator(scene.triangles, threads=1)
    emitted = emit_photons(scene, 200_000, sampling.rng_for(4, sampling.STREAM_PHOTON))
    pmap = trace_photons(scene, accel, emitted, sampling.rng_for(4, 5)).build()
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.uniform(0.4, 1.6, 300), rng.uniform(0.4, 1.6, 300), np.zeros(300)])
    n = np.tile([0.0, 0.0, 1.0], (300, 1))
    e = pmap.irradiance(pts, n, k=100, max_radius=0.4)[:, 0]
    radiance = m_exit / np.pi + rho / np.pi * e
    assert radiance.mean() == pytest.approx(m_exit / np.pi / (1 - rho), rel=0.03)
    # Energy: every photon's flux ends absorbed, escaped or capped. The walls emit from both
    # faces (as Cycles' emission does), so the outer faces' M x 24 m^2 escapes (each photon
    # picks a face with probability 1/2: SE about 0.2 %).
    stats = pmap.stats
    assert stats["flux_escaped"][0] == pytest.approx(m_exit * 24.0, rel=0.02)
    emitted_flux = stats["flux_emitted"][0]
    ended = stats["flux_absorbed"][0] + stats["flux_capped"][0] + stats["flux_escaped"][0]
    per_photon = emitted_flux / stats["emitted"]
    # Absorbed flux is a sum of Bernoulli-like terms of size per_photon: SE <= sqrt(N) * p.
    assert abs(ended - emitted_flux) <= 4 * np.sqrt(stats["emitted"]) * per_photon
