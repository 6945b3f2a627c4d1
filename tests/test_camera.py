"""The camera's rays: orthographic projection and the thin lens (depth of field).

Geometry is checked exactly (orthographic rays are parallel and start on the near plane; a
pixel sample's rays through every lens point meet on the focus plane where its pinhole ray
does), the lens's shape statistically (``aperture_points`` against points drawn by rejection
from the polygon's own definition, two-sample chi-square), and one whole render against its
closed form. Parity with Cycles' pictures is in ``tests/test_parity_cycles.py`` (``sun_ortho``,
``sun_dof``, ``bokeh``).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lanterna.engine.camera import aperture_points, pixel_rays
from lanterna.engine.passes import project_to_window
from lanterna.engine.scene import Camera, Material, Scene, SceneError, SunLight


def ortho_camera(**kwargs):
    base = Camera.look_at([0.5, -4.0, 2.0], [0.0, 0.0, 0.5], resolution=(16, 12), **kwargs)
    # Orthographic: half extents in metres (2.4 m wide, 1.8 m tall).
    return replace(base, orthographic=True, tan_half_x=1.2, tan_half_y=0.9, shift_x=0.1,
                   clip_start=0.3)


def local(camera, points):
    return camera.to_camera_space(points)


def test_orthographic_rays_are_parallel_start_on_the_near_plane_and_project_back():
    cam = ortho_camera()
    o, d, tmax = pixel_rays(cam, 0, 16 * 12, 4, np.random.default_rng(1))
    axis = -cam.matrix[:3, 2] / np.linalg.norm(cam.matrix[:3, 2])
    np.testing.assert_allclose(d, np.broadcast_to(axis, d.shape), atol=1e-6)
    lo = local(cam, o)
    np.testing.assert_allclose(lo[:, 2], -cam.clip_start, atol=1e-5)
    # The frame: 2 x 1.2 m wide, shifted by 0.1 m, with the filter's spread of 1.5 px.
    px = 2.4 / 16
    assert lo[:, 0].min() >= -1.2 + 0.1 - 1.5 * px and lo[:, 0].max() <= 1.2 + 0.1 + 1.5 * px
    np.testing.assert_allclose(tmax, cam.clip_end - cam.clip_start, rtol=1e-6)
    # Pixel centres project back to their own pixel, at any depth.
    o, d, _ = pixel_rays(cam, 0, 16 * 12, 1, np.random.default_rng(1), centres=True)
    far = o.astype(np.float64) + 7.3 * d
    pixel, dist = project_to_window(cam, far)
    np.testing.assert_array_equal(pixel, np.arange(16 * 12))
    np.testing.assert_allclose(dist, 7.3 + cam.clip_start, rtol=1e-5)
    assert cam.footprint(1.0) == cam.footprint(50.0) == pytest.approx(px)


def pinhole_and_lens(cam, samples=64):
    """Each pixel's samples at one position (so one pinhole ray), through many lens points."""
    rng = np.random.default_rng(3)
    pixels = np.arange(cam.resolution[0] * cam.resolution[1])
    positions = np.repeat(rng.random((len(pixels), 1, 2)), samples, axis=1)
    lens = pixel_rays(cam, 0, 0, samples, rng, 1e-6, pixels=pixels, positions=positions)
    pinhole = pixel_rays(replace(cam, aperture_radius=0.0), 0, 0, samples, rng, 1e-6,
                         pixels=pixels, positions=positions)
    return lens, pinhole


@pytest.mark.parametrize("orthographic", [False, True])
def test_rays_through_the_lens_meet_the_pinhole_ray_on_the_focus_plane(orthographic):
    cam = Camera.look_at([0.5, -4.0, 2.0], [0.0, 0.0, 0.5], resolution=(8, 6),
                         aperture_radius=0.2, focus_distance=3.5, aperture_blades=6,
                         aperture_rotation=0.3, aperture_ratio=1.3, clip_start=0.25)
    if orthographic:
        cam = replace(cam, orthographic=True, tan_half_x=1.2, tan_half_y=0.9)
    (o, d, tmax), (po, pd, ptmax) = pinhole_and_lens(cam)
    lo, ld = local(cam, o), cam.to_camera_space(d + cam.matrix[:3, 3])
    plo, pld = local(cam, po), cam.to_camera_space(pd + cam.matrix[:3, 3])

    def on_focus_plane(origin, direction):
        t = (-cam.focus_distance - origin[:, 2]) / direction[:, 2]
        return origin + t[:, None] * direction

    np.testing.assert_allclose(on_focus_plane(lo, ld), on_focus_plane(plo, pld), atol=2e-5)
    # The rays leave the lens: back along each ray to z = 0 lies within the aperture, and
    # the lens points of one pixel spread over it (not one point).
    back = on_focus_plane(lo, ld) - (cam.focus_distance / -ld[:, 2])[:, None] * ld
    offset = back[:, :2] - (plo[:, :2] if orthographic else 0.0)
    assert np.all(np.hypot(offset[:, 0] * cam.aperture_ratio, offset[:, 1]) <= 0.2 + 1e-5)
    assert np.ptp(offset[:64, 0]) > 0.2 and np.ptp(offset[:64, 1]) > 0.2
    # They start at the near clip as Cycles' do: the pinhole ray's clip start / cos along
    # the lens ray (perspective), the plane z = -clip start (orthographic).
    start = np.linalg.norm(lo - back, axis=1)
    if orthographic:
        np.testing.assert_allclose(lo[:, 2], -cam.clip_start, atol=1e-5)
        np.testing.assert_allclose(tmax, cam.clip_end - cam.clip_start, rtol=1e-6)
    else:
        stretch = 1.0 / -pld[:, 2]
        np.testing.assert_allclose(start, cam.clip_start * stretch, rtol=1e-4)
        np.testing.assert_allclose(tmax, ptmax, rtol=1e-5)


def polygon_by_rejection(n, blades, rotation, radius, rng):
    """Uniform points in the regular polygon with circumradius ``radius``, its first edge's
    middle at angle ``rotation`` (vertices at rotation + pi/blades + 2 pi k / blades)."""
    apothem = radius * math.cos(math.pi / blades)
    normals = rotation + 2 * math.pi * np.arange(blades) / blades
    out = []
    while sum(len(p) for p in out) < n:
        p = rng.uniform(-radius, radius, (4 * n, 2))
        inside = np.all(p[:, :1] * np.cos(normals) + p[:, 1:] * np.sin(normals) <= apothem, axis=1)
        out.append(p[inside])
    return np.concatenate(out)[:n]


def two_sample_chi2(a, b, edges):
    ha = np.histogram2d(a[:, 0], a[:, 1], bins=edges)[0].ravel()
    hb = np.histogram2d(b[:, 0], b[:, 1], bins=edges)[0].ravel()
    keep = ha + hb > 20
    stat = float(((ha[keep] - hb[keep]) ** 2 / (ha[keep] + hb[keep])).sum())
    return stat, int(keep.sum()) - 1


@pytest.mark.parametrize("blades, rotation", [(5, math.radians(20.0)), (6, 0.0), (3, -1.0)])
def test_polygonal_aperture_is_uniform_over_cycles_polygon(blades, rotation):
    from scipy.stats import chi2

    rng = np.random.default_rng(blades)
    cam = Camera.look_at([0, -4, 2], [0, 0, 0], aperture_radius=2.0, focus_distance=3.0,
                         aperture_blades=blades, aperture_rotation=rotation,
                         aperture_ratio=1.4)
    n = 200_000
    ours = aperture_points(rng.random((n, 2)), cam)
    ours[:, 0] *= 1.4                                   # undo the squeeze
    ref = polygon_by_rejection(n, blades, rotation, 2.0, rng)
    edges = [np.linspace(-2.0, 2.0, 17)] * 2
    stat, dof = two_sample_chi2(ours, ref, edges)
    assert stat < chi2.ppf(1 - 1e-4, dof), (stat, dof)
    # The polygon turned the other way (or its vertices where its edges are) fails.
    wrong = polygon_by_rejection(n, blades, rotation + math.pi / blades, 2.0, rng)
    assert two_sample_chi2(ours, wrong, edges)[0] > chi2.ppf(1 - 1e-4, dof)


def test_round_aperture_and_its_squeeze():
    rng = np.random.default_rng(4)
    cam = Camera.look_at([0, -4, 2], [0, 0, 0], aperture_radius=0.5, focus_distance=3.0,
                         aperture_blades=0, aperture_ratio=2.0)
    p = aperture_points(rng.random((100_000, 2)), cam)
    assert np.abs(p[:, 0]).max() <= 0.25 + 1e-9 and np.abs(p[:, 1]).max() <= 0.5 + 1e-9
    r = np.hypot(2.0 * p[:, 0], p[:, 1]) / 0.5
    # Uniform over the disk: P(r < 0.5) = 1/4, E[r^2] = 1/2.
    assert np.mean(r < 0.5) == pytest.approx(0.25, abs=0.005)
    assert np.mean(r ** 2) == pytest.approx(0.5, abs=0.005)
    # Blades 1 and 2 are no polygon: a disk, as in Cycles.
    q = aperture_points(rng.random((1000, 2)), replace(cam, aperture_blades=2))
    assert np.hypot(2.0 * q[:, 0], q[:, 1]).max() > 0.49


def test_impossible_lens_settings_are_refused_with_the_camera_named():
    with pytest.raises(SceneError, match="Cam.*aperture radius"):
        Camera.look_at([0, -4, 2], [0, 0, 0], aperture_radius=-0.1, name="Cam")
    with pytest.raises(SceneError, match="Cam.*focus distance"):
        Camera.look_at([0, -4, 2], [0, 0, 0], aperture_radius=0.1, focus_distance=0.0,
                       name="Cam")
    with pytest.raises(SceneError, match="Cam.*aperture ratio"):
        Camera.look_at([0, -4, 2], [0, 0, 0], aperture_radius=0.1, aperture_ratio=0.0,
                       name="Cam")


def test_orthographic_render_of_a_sunlit_plane_is_its_closed_form():
    """A plane lit by a sun at 40 degrees, seen through an orthographic camera at an angle,
    with the irradiance cache (whose record reach and camera-time records read the
    footprint): every pixel is rho / pi x E cos(theta), with no indirect light."""
    from lanterna.engine.pipeline import RenderSettings, render

    rho, e, theta = 0.6, 2.0, math.radians(40.0)
    tris = np.array([[[-20, -20, 0], [20, -20, 0], [20, 20, 0]],
                     [[-20, -20, 0], [20, 20, 0], [-20, 20, 0]]], np.float32)
    sun = SunLight(name="Sun", direction=(math.sin(theta), 0.0, -math.cos(theta)), irradiance=(e, e, e))
    cam = Camera.look_at([0.0, -3.0, 3.0], [0.0, 0.0, 0.0], resolution=(16, 12))
    cam = replace(cam, orthographic=True, tan_half_x=1.5, tan_half_y=1.125)
    scene = Scene(triangles=tris, material_ids=np.zeros(2, np.int32),
                  materials=[Material("plane", diffuse=(rho, rho, rho))], camera=cam,
                  lights=[sun]).validate()
    image = render(scene, RenderSettings(samples=4, light_samples=1, photons=20_000,
                                         seed=1)).image
    expected = rho / math.pi * e * math.cos(theta)
    np.testing.assert_allclose(image, expected, rtol=1e-4)


def test_equirectangular_rays_cover_the_sphere_and_project_back():
    cam = replace(Camera.look_at([0.5, -4.0, 2.0], [0.0, 0.0, 0.5], resolution=(32, 16)),
                  panorama="EQUIRECTANGULAR", tan_half_x=0.5, tan_half_y=0.5)
    o, d, tmax = pixel_rays(cam, 0, 32 * 16, 1, np.random.default_rng(1), centres=True)
    local_d = cam.to_camera_space(d + cam.matrix[:3, 3])
    grid = local_d.reshape(16, 32, 3)               # row 0 = top
    # The centre of the frame looks along the view axis, the top row up, the bottom row
    # down, the right half to the camera's right (Cycles' equirectangular frame).
    np.testing.assert_allclose(grid[7:9, 15:17].mean(axis=(0, 1)), [0, 0, -1], atol=0.05)
    assert grid[0, :, 1].min() > 0.99 and grid[-1, :, 1].max() < -0.99
    assert grid[8, 20:28, 0].min() > 0.3 and grid[8, 4:12, 0].max() < -0.3
    # Pixel solid angles sum to the sphere's 4 pi (cos(latitude) weights).
    lat = np.arcsin(np.clip(grid[..., 1], -1, 1))
    assert (np.cos(lat).sum() * (2 * np.pi / 32) * (np.pi / 16)) == pytest.approx(4 * np.pi,
                                                                                rel=0.01)
    np.testing.assert_allclose(np.linalg.norm(o - cam.matrix[:3, 3], axis=1), cam.clip_start,
                               atol=1e-6)           # float32 origins 4 m out
    pixel, dist = project_to_window(cam, o.astype(np.float64) + 5.0 * d)
    np.testing.assert_array_equal(pixel, np.arange(32 * 16))
    np.testing.assert_allclose(dist, 5.0 + cam.clip_start, rtol=1e-5)
