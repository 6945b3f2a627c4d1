"""Scenes for sphere-light parity (point and spot lights with a radius): built in bpy, rendered
by Cycles in ``tests/data/make_sphere_light_refs.py`` and by Lanterna in
``tests/test_sphere_lights.py``.

Every scene is the room of ``tests/parity_scenes.py`` (64 x 48 px, camera at (0, -5, 2.2)
looking at (0, 0.5, 0.6), 50 degrees; Lambertian floor, back wall and a 0.8 m box, black
world) lit by one light with a radius, so the box casts a penumbra:

``point_soft``    POINT 300 W at (-0.9, -0.5, 1.0), radius 0.5 m, Soft Falloff on (Blender's
                  default): Cycles' facing disk.
``point_sphere``  the same with Soft Falloff off: a sphere light.
``spot_soft``     SPOT 600 W at (-1.0, -0.8, 2.0) aimed at (0.3, 0.4, 0), size 90 degrees,
                  blend 0.5, radius 0.3 m, Soft Falloff on.
``spot_sphere``   the same with Soft Falloff off.

The light is hidden from camera rays (``visible_camera`` False): Cycles draws a light with a
radius where the camera sees it, Lanterna draws no lights.
"""
from __future__ import annotations

import math

import bpy

import parity_scenes as _ps

__all__ = ["SCENES", "POINT", "SPOT", "build"]

POINT = dict(location=(-0.9, -0.5, 1.0), energy=300.0, radius=0.5)
SPOT = dict(location=(-1.0, -0.8, 2.0), target=(0.3, 0.4, 0.0), energy=600.0,
            size=math.radians(90.0), blend=0.5, radius=0.3)


def _point(soft: bool):
    scene = _ps._reset()
    _ps._room(scene)
    obj = _ps._light(scene, "Point", "POINT", POINT["location"], energy=POINT["energy"],
                     shadow_soft_size=POINT["radius"], use_soft_falloff=soft)
    obj.visible_camera = False
    return scene


def _spot(soft: bool):
    scene = _ps._reset()
    _ps._room(scene)
    obj = _ps._light(scene, "Spot", "SPOT", SPOT["location"], target=SPOT["target"],
                     energy=SPOT["energy"], spot_size=SPOT["size"], spot_blend=SPOT["blend"],
                     shadow_soft_size=SPOT["radius"], use_soft_falloff=soft)
    obj.visible_camera = False
    return scene


SCENES = {
    "point_soft": lambda: _point(True),
    "point_sphere": lambda: _point(False),
    "spot_soft": lambda: _spot(True),
    "spot_sphere": lambda: _spot(False),
}


def build(name: str):
    """Build scene ``name`` of ``SCENES`` into a fresh file; return the bpy scene."""
    scene = SCENES[name]()
    bpy.context.view_layer.update()
    return scene
