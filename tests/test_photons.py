"""Photon emission, tracing and the photon-map estimate against closed forms (no bpy).

Tolerances: 3 % as issue 3 asks for the estimates; the emitted flux is exact to 1e-6; the
energy balance (emitted = absorbed + escaped + capped) holds in expectation under Russian
roulette, and its tolerance is 4 standard errors of the absorbed flux, estimated from the
per-photon powers.
"""
import numpy as np
import pytest

from analytic import box_room, icosphere, plane_scene, point_irradiance, quad, triangle_area_sum
from lanterna.engine import sampling
from lanterna.engine.accel import Accelerator
from lanterna.engine.photons import build_photon_map, emit_photons, trace_photons
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import AreaLight, Camera, Material, PointLight, Scene, SceneError


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


# --- Sampling, leaks, and the render modes against closed forms ----------------------------
def test_triangle_sampling_is_area_uniform_chi_square():
    """Points of ``square_to_triangle`` (DESIGN.md §4: alpha = 1 - sqrt(u0), beta = u1 sqrt(u0))
    fall into the 16 congruent sub-triangles of a twice-subdivided triangle equally often.
    Chi-square with 15 degrees of freedom; the 0.999 quantile is 37.70, so this fails by
    chance once in a thousand runs (fixed seed: never), while the seed's original mapping
    (beta = (1 - alpha) u1) gives chi^2 in the thousands."""
    from scipy.stats import chi2

    rng = np.random.default_rng(11)
    n = 160_000
    bary = sampling.square_to_triangle(rng.random((n, 2)))
    a, b = bary[:, 0], bary[:, 1]
    assert np.all(a >= 0) and np.all(b >= 0) and np.all(a + b <= 1 + 1e-12)

    def cells(a, b):
        # Sub-triangle index on a 4 x 4 grid of the barycentric triangle: (i, j, upper).
        i, j = np.floor(a * 4).astype(int), np.floor(b * 4).astype(int)
        upper = (a * 4 - i) + (b * 4 - j) > 1
        return np.clip(i, 0, 3) * 8 + np.clip(j, 0, 3) * 2 + upper

    valid = [i * 8 + j * 2 + u for i in range(4) for j in range(4) for u in range(2)
             if i + j + u <= 3]
    assert len(valid) == 16

    def statistic(a, b):
        counts = np.bincount(cells(a, b), minlength=32)[valid]
        expected = len(a) / 16
        return ((counts - expected) ** 2 / expected).sum()

    limit = chi2.ppf(0.999, 15)
    assert statistic(a, b) < limit
    u = rng.random((n, 2))
    seed_alpha = u[:, 0]
    assert statistic(seed_alpha, (1 - seed_alpha) * u[:, 1]) > 10 * limit


def test_thin_plate_lit_from_both_sides_does_not_leak():
    """A single two-sided plate with a red light above and a blue light below: the top's
    estimate holds no blue and the bottom's no red (the seed's first filter, 9.4), and each
    side matches its light (Eq. 7.1) to 3 % on average."""
    red = PointLight("Red", [0.0, 0.0, 1.0], [400.0, 0.0, 0.0])
    blue = PointLight("Blue", [0.0, 0.0, -1.0], [0.0, 0.0, 400.0])
    scene = plane_scene([red, blue], size=6.0).validate()
    accel = Accelerator(scene.triangles, threads=1)
    pmap = build_photon_map(scene, accel, 400_000, seed=6)
    rng = np.random.default_rng(8)
    pts = np.column_stack([rng.uniform(-1.5, 1.5, 300), rng.uniform(-1.5, 1.5, 300), np.zeros(300)])
    up = np.tile([0.0, 0.0, 1.0], (300, 1))
    top = pmap.irradiance(pts, up, k=100)
    bottom = pmap.irradiance(pts, -up, k=100)
    assert top[:, 2].max() == 0.0 and bottom[:, 0].max() == 0.0
    assert top[:, 0].mean() == pytest.approx(point_irradiance(pts, up, red.position, red.flux)[:, 0].mean(), rel=0.03)
    assert bottom[:, 2].mean() == pytest.approx(point_irradiance(pts, -up, blue.position, blue.flux)[:, 2].mean(), rel=0.03)


def _sphere_scene(rho, radius=1.0, flux=100.0):
    tris = icosphere(radius, 4)
    light = PointLight("Lamp", [0.0, 0.0, 0.0], [flux] * 3)
    cam = Camera.look_at([0.0, -0.3 * radius, 0.0], [0.0, radius, 0.0], fov_x_deg=70.0,
                         resolution=(24, 24))
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("white", diffuse=rho)], camera=cam, lights=[light])


@pytest.mark.parametrize("mode, indirect", [("full", "photon-map"), ("full", "gather"),
                                            ("photon-map", "photon-map")])
def test_point_light_in_a_diffuse_sphere(mode, indirect):
    """pbrt's test: a point light of flux Phi at the centre of a closed diffuse sphere of
    reflectance rho. Every point receives E_direct = Phi / A (A: the polyhedron's area) and in
    all E = Phi / (A (1 - rho)) (energy balance), so L = rho / pi * Phi / (A (1 - rho)).
    Both modes, and the full mode with the photon map looked up at the hit or through the
    final gather, must give it within 3 % on the mean over the image. Spread of the pixel
    values (k = 50 estimates, about 14 % each) averages down to < 1 % over 576 pixels; the
    gather's pixels spread by 0.3 %."""
    rho, flux = 0.6, 100.0
    scene = _sphere_scene(rho, flux=flux)
    area = triangle_area_sum(scene.triangles)
    expected = rho / np.pi * flux / (area * (1 - rho))
    result = render(scene, RenderSettings(mode=mode, indirect=indirect, samples=4,
                                          photons=300_000, seed=4))
    img = result.image.reshape(-1, 3)
    assert np.isfinite(img).all()
    assert img[:, 0].mean() == pytest.approx(expected, rel=0.03)
    np.testing.assert_allclose(img.mean(axis=0), img[:, 0].mean(), rtol=1e-5)   # grey stays grey
    stage = result.report["stages"]["photons"]
    assert stage["kept"] == ("indirect" if mode == "full" and indirect == "photon-map" else "all")
    # Closed sphere: nothing escapes; every photon's first hit is stored, so the flux stored
    # at first hits is the emitted flux; emitted = absorbed + capped within the RR noise.
    assert stage["flux_escaped"] == [0.0, 0.0, 0.0]
    assert stage["flux_stored_direct"][0] == pytest.approx(flux, rel=1e-5)
    ended = stage["flux_absorbed"][0] + stage["flux_capped"][0]
    assert ended == pytest.approx(flux, rel=0.01)


@pytest.mark.parametrize("rho", [0.5, 0.8])
def test_white_furnace_renders_in_photon_map_mode(rho):
    """The furnace through the whole pipeline in ``photon-map`` mode: every pixel sees a wall
    of radiance (M / pi) / (1 - rho); the image mean must be within 3 %."""
    m_exit = 2.0
    scene = _furnace(rho, m_exit)
    result = render(scene, RenderSettings(mode="photon-map", samples=2, photons=200_000, seed=2))
    expected = m_exit / np.pi / (1 - rho)
    assert result.image[..., 0].mean() == pytest.approx(expected, rel=0.03)
    full = render(scene, RenderSettings(mode="full", indirect="photon-map", samples=2,
                                        photons=200_000, seed=2, light_samples=8))
    assert full.image[..., 0].mean() == pytest.approx(expected, rel=0.03)


def test_bounces_zero_and_empty_cases():
    """bounces = 0 in full mode runs no photon stage (direct light only); a photon-map render
    with bounces = 0 sees only first-hit photons, i.e. direct light; a scene without lights
    plans no photons."""
    rho = 0.6
    scene = _sphere_scene(rho)
    area = triangle_area_sum(scene.triangles)
    direct = render(scene, RenderSettings(bounces=0, samples=2))
    assert "photons" not in direct.report["stages"]
    assert direct.report["plan"]["stages"]["photons"].startswith("skipped: bounces = 0")
    first_hits = render(scene, RenderSettings(mode="photon-map", bounces=0, samples=2,
                                              photons=200_000))
    expected_direct = rho / np.pi * 100.0 / area
    assert direct.image[..., 0].mean() == pytest.approx(expected_direct, rel=0.01)
    assert first_hits.image[..., 0].mean() == pytest.approx(expected_direct, rel=0.03)
    assert first_hits.report["stages"]["photons"]["capped_paths"] > 0
    dark = Scene(triangles=scene.triangles, material_ids=scene.material_ids,
                 materials=scene.materials, camera=scene.camera, lights=[])
    result = render(dark, RenderSettings(samples=1))
    assert result.report["plan"]["stages"]["photons"] == "skipped: nothing emits light"
    assert result.image.max() == 0.0


def test_photon_share_moves_photons_not_energy():
    """Light.lanterna.photon_share: photons split in proportion to flux x share; each light's
    photons still carry exactly its flux; share 0 sends none (and the render warns)."""
    a = PointLight("A", [0.0, 0.0, 1.0], [100.0] * 3, photon_share=3.0)
    b = PointLight("B", [1.0, 0.0, 1.0], [100.0] * 3)
    scene = plane_scene([a, b])
    emitted = emit_photons(scene, 40_000, sampling.rng_for(1, sampling.STREAM_PHOTON))
    assert emitted.per_light == {"A": 30_000, "B": 10_000}
    np.testing.assert_allclose(emitted.power.sum(axis=0), [200.0] * 3, rtol=1e-9)
    np.testing.assert_allclose(emitted.power[:30_000].sum(axis=0), [100.0] * 3, rtol=1e-9)
    b.photon_share = 0.0
    assert emit_photons(scene, 1000, sampling.rng_for(1, 3)).per_light == {"A": 1000}
    result = render(scene, RenderSettings(samples=1, photons=1000))
    assert any("'B': photon share 0" in w for w in result.report["warnings"])
    with pytest.raises(SceneError, match="photon share"):
        PointLight("C", [0, 0, 1], [1.0] * 3, photon_share=float("nan"))


def test_cone_filter_keeps_the_irradiance():
    """Jensen's cone filter (k_c = 1.1) is normalised by 1 - 2/(3 k_c): on a plane under a
    point light its mean estimate stays within 3 % of Eq. 7.1, as the plain disc's does."""
    light = PointLight("Lamp", [0.0, 0.0, 1.0], [1000.0] * 3)
    scene = plane_scene([light], size=8.0).validate()
    accel = Accelerator(scene.triangles, threads=1)
    pmap = build_photon_map(scene, accel, 400_000, seed=9)
    rng = np.random.default_rng(10)
    pts = np.column_stack([rng.uniform(-2, 2, 300), rng.uniform(-2, 2, 300), np.zeros(300)])
    n = np.tile([0.0, 0.0, 1.0], (300, 1))
    exact = point_irradiance(pts, n, light.position, light.flux)[:, 0]
    cone = pmap.irradiance(pts, n, k=100, cone_filter=1.1)[:, 0]
    assert (cone / exact).mean() == pytest.approx(1.0, abs=0.03)
    unnormalised = cone * (1 - 2 / 3.3)
    assert (unnormalised / exact).mean() < 0.5
