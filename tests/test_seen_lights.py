"""Lights seen by camera rays, as Cycles shows them (``Object.visible_camera``, off for a new
light in Blender: ``camera_visible``).

With it on, Cycles draws area lights (on their emitting side) and point and spot lights with
a radius where a camera ray meets them, and the ray goes on (a light is not a surface: what lies
behind it adds). The pictures here have closed forms: a square light of power P and area A
filling pixels shows L = P / (pi A) in them, in the Emit pass; behind it, or with Camera
visibility off, the pixel shows what lies behind; a point light of radius R (Soft Falloff:
a disk facing the ray) shows Phi / (4 pi^2 R^2) over a disk of radius R. Cycles' own
pictures of such lights: ``tests/test_parity_cycles.py`` (``lights_in_frame``).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from analytic import quad
from lanterna.engine.passes import LIGHT_PASS_NAMES
from lanterna.engine.pipeline import RenderSettings, render
from lanterna.engine.scene import AreaLight, Camera, Material, PointLight, Scene


def _facing_camera(y, flip=False):
    """A matrix placing a light at (0, y, 0) with local -Z towards -y (the camera) or +y."""
    m = np.eye(4)
    z = np.array([0.0, -1.0, 0.0]) if flip else np.array([0.0, 1.0, 0.0])
    x = np.array([1.0, 0.0, 0.0])
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, [0.0, y, 0.0]
    return m


def _scene(lights, wall_rho=0.0):
    # A wall 4 m behind the lights (grey wall_rho, lit by nothing else) and a camera 3 m in
    # front, looking at them along +y.
    wall = quad([-20, 4, -20], [40, 0, 0], [0, 0, 40])
    cam = Camera.look_at([0.0, -3.0, 0.0], [0.0, 0.0, 0.0], up=(0, 0, 1), fov_x_deg=40.0,
                         resolution=(24, 18))
    return Scene(triangles=wall, material_ids=np.zeros(len(wall), np.int32),
                 materials=[Material("wall", diffuse=(wall_rho,) * 3)], camera=cam,
                 lights=lights).validate()


def _centre(image):
    h, w = image.shape[:2]
    return image[h // 2 - 2: h // 2 + 2, w // 2 - 2: w // 2 + 2].reshape(-1, 3)


SETTINGS = RenderSettings(samples=4, light_samples=1, bounces=0, seed=1)


def test_an_area_light_in_frame_shows_its_radiance_on_its_emitting_side_only():
    power = np.array([40.0, 20.0, 10.0])
    light = AreaLight("Panel", "SQUARE", _facing_camera(0.0), 1.5, 1.5, power,
                      camera_visible=True)
    radiance = power / (math.pi * 1.5 * 1.5)
    res = render(_scene([light]), SETTINGS, passes=LIGHT_PASS_NAMES)
    np.testing.assert_allclose(_centre(res.image), np.broadcast_to(radiance, (16, 3)), rtol=1e-5)
    np.testing.assert_allclose(_centre(res.passes["Emit"]), np.broadcast_to(radiance, (16, 3)),
                               rtol=1e-5)
    # Seen from behind it is not there (the black wall behind shows), as in Cycles.
    back = replace(light, matrix=_facing_camera(0.0, flip=True))
    assert np.abs(_centre(render(_scene([back]), SETTINGS).image)).max() == 0.0
    # Camera visibility off: not drawn.
    hidden = replace(light, camera_visible=False)
    assert np.abs(_centre(render(_scene([hidden]), SETTINGS).image)).max() == 0.0


def test_a_light_in_frame_adds_to_what_lies_behind_it():
    """Cycles' lights are not surfaces: a camera ray goes on past one. A panel facing the
    camera, in front of a wall lit by a second panel: the pixels show both."""
    front = AreaLight("Front", "SQUARE", _facing_camera(0.0), 1.0, 1.0, np.full(3, 10.0),
                      camera_visible=True)
    back = AreaLight("Back", "SQUARE", _facing_camera(2.0, flip=True), 6.0, 6.0, np.full(3, 300.0))
    both = _centre(render(_scene([front, back], wall_rho=0.5), SETTINGS).image)
    wall_only = _centre(render(_scene([replace(front, camera_visible=False), back],
                                      wall_rho=0.5), SETTINGS).image)
    assert wall_only.min() > 0.1
    np.testing.assert_allclose(both, wall_only + 10.0 / math.pi, rtol=1e-6)


def test_a_point_light_with_a_radius_is_a_disk_facing_the_camera():
    flux = np.array([100.0, 100.0, 100.0])
    radius = 0.4
    light = PointLight("Bulb", np.array([0.0, 0.0, 0.0]), flux, radius=radius,
                       camera_visible=True)
    image = render(_scene([light]), RenderSettings(samples=64, light_samples=1, bounces=0,
                                                   seed=1)).image
    expected = flux[0] / (4 * math.pi ** 2 * radius ** 2)
    np.testing.assert_allclose(_centre(image), expected, rtol=1e-5)
    # Its image's total: L x the disk's solid angle, in pixels (pixel solid angle at the
    # centre: (2 tan 20 deg / 24)^2 / 1 sr at unit distance; the disk 3 m away).
    pixel = (2 * math.tan(math.radians(20.0)) / 24) ** 2
    disk = math.pi * radius ** 2 / 3.0 ** 2
    total = image[..., 0].sum() * pixel
    assert abs(total / (expected * disk) - 1) < 0.02


def _sun_scene(material, camera_visible=True):
    """A 40 m plane of ``material`` at z = 0, a camera 3 m above it looking straight down
    (10 degree field), a sun of strength 2 and angle 10 degrees at the zenith, black world."""
    from lanterna.engine.scene import SunLight

    plane = quad([-20, -20, 0], [40, 0, 0], [0, 40, 0])
    sun = SunLight("Sun", direction=(0.0, 0.0, -1.0), irradiance=(2.0, 2.0, 2.0),
                   angle=math.radians(10.0), camera_visible=camera_visible)
    cam = Camera.look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], up=(0, 1, 0), fov_x_deg=10.0,
                         resolution=(16, 12))
    return Scene(triangles=plane, material_ids=np.zeros(len(plane), np.int32),
                 materials=[material], camera=cam, lights=[sun]).validate()


def test_a_sun_disc_shows_in_a_mirror_and_to_the_camera_as_cycles_shows_it():
    """A sun of strength E and angle a is a disc of radiance E / (pi sin^2(a / 2)): measured
    in Cycles 5.2 (strength 3, angle 10 degrees, Visibility > Camera on, seen straight on:
    125.713, the formula 125.713; E / (2 pi (1 - cos)) would be 125.474). A perfect mirror
    (specular 0.9) under a zenith sun, seen from straight above, shows 0.9 x that (no light
    sample reaches the sun through a mirror: before, it showed black)."""
    disc = 2.0 / (math.pi * math.sin(math.radians(5.0)) ** 2)
    mirror = Material("mirror", diffuse=(0.0, 0.0, 0.0), specular=(0.9, 0.9, 0.9))
    image = render(_sun_scene(mirror), SETTINGS).image
    np.testing.assert_allclose(_centre(image), 0.9 * disc, rtol=1e-5)
    # The camera looks away from the sun here; turned to it, it sees the disc where its
    # Visibility > Camera is on, and not otherwise.
    scene = _sun_scene(mirror)
    scene.camera = Camera.look_at([0.0, 0.0, 3.0], [0.0, 0.0, 6.0], up=(0, 1, 0),
                                  fov_x_deg=10.0, resolution=(16, 12))
    np.testing.assert_allclose(_centre(render(scene, SETTINGS).image), disc, rtol=1e-5)
    scene.lights[0].camera_visible = False
    assert np.abs(_centre(render(scene, SETTINGS).image)).max() == 0.0
