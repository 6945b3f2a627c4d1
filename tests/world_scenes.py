"""Scenes lit by an HDRI world (issue 24), built in bpy, for ``tests/data/make_world_refs.py``
and ``tests/test_parity_world.py``.

The HDRI is synthetic and made here (``make_hdri``): an equirectangular float image of
``HDRI_SIZE`` (256 x 128), in the Environment Texture's convention (column u: azimuth
phi = pi - 2 pi u, row v from the bottom: elevation 90 - 180 (1 - v) deg): a sky gradient
from ``HORIZON`` at the horizon to ``ZENITH`` overhead, a ground of ``GROUND`` below the
horizon, and a sun disk of angular radius ``SUN_RADIUS_DEG`` and radiance ``SUN_RADIANCE``
at ``SUN_ELEVATION_DEG`` / ``SUN_AZIMUTH_DEG`` (before the Mapping's rotation). The world:
Texture Coordinate Generated -> Mapping (Point, rotation z = ``MAPPING_Z_DEG``) ->
Environment Texture (Linear) -> Background (Strength ``STRENGTH``); the room turns the
image by ``ROOM_MAPPING_Z_DEG`` so that the sun shines through its window.

``yard``: a 16 x 16 m grey ground plane (0.5), two boxes (0.7 and 0.4) and an overhang (a
2.4 x 1.6 m slab 1.2 m up on two posts, 0.6) casting a sky-only shadow; camera at
(6, -7, 4.5) looking at (0, 0, 0.5), 60 deg, 80 x 60 px. ``yard_320``: the same at 320 x 240.
``court``, a validation scene (nothing was tuned on it; the yard chose how the sky is shared
between light samples and the final gather, the window room the share of sky photons outside
the portals): the image turned by ``COURT_MAPPING_Z_DEG`` (the sun from another side), a
12 x 12 m ground of (0.35, 0.40, 0.30), an L of two walls 2 m high (0.75), a pillar (0.5)
and a low bench (0.3, 0.3, 0.6) in the walls' shadow; camera at (-6, 5, 3.5) looking at
(0.5, -0.5, 0.8), 65 deg, 80 x 60 px.
``window_room``: a closed 4 x 4 x 2.6 m room (walls 0.7), a 1.2 x 1.0 m window in the wall
at y = -2, lit only by the HDRI through it; a portal area light fills the window; the camera
inside looks at the floor patch the sun reaches.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import bpy

import parity_scenes as _ps

HDRI_SIZE = (256, 128)
HORIZON = np.array([0.9, 1.0, 1.1])
ZENITH = np.array([0.25, 0.4, 0.8])
GROUND = np.array([0.12, 0.1, 0.08])
SUN_RADIANCE = np.array([2600.0, 2400.0, 2100.0])
SUN_RADIUS_DEG = 2.0
SUN_ELEVATION_DEG = 40.0
SUN_AZIMUTH_DEG = 20.0
MAPPING_Z_DEG = 35.0
ROOM_MAPPING_Z_DEG = 90.0   # the room's sun: azimuth -70 deg, through its south window
COURT_MAPPING_Z_DEG = 160.0
STRENGTH = 1.0
RESOLUTION = (80, 60)
BENCH_RESOLUTION = (320, 240)
HDRI_PATH = Path(__file__).resolve().parent / "data" / "cycles_world" / "sky.exr"


def make_hdri() -> np.ndarray:
    """The synthetic HDRI (H, W, 3) float32, row 0 at the bottom (module docstring)."""
    w, h = HDRI_SIZE
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    vv, uu = np.meshgrid(v, u, indexing="ij")
    phi = np.pi - 2 * np.pi * uu
    elev = np.pi * (vv - 0.5)
    t = np.clip(np.sin(elev), 0, 1)[..., None]
    img = np.where(elev[..., None] > 0, HORIZON * (1 - t) + ZENITH * t, GROUND)
    se, sa = math.radians(SUN_ELEVATION_DEG), math.radians(SUN_AZIMUTH_DEG)
    sun = np.array([math.cos(se) * math.cos(sa), math.cos(se) * math.sin(sa), math.sin(se)])
    d = np.stack([np.cos(elev) * np.cos(phi), np.cos(elev) * np.sin(phi), np.sin(elev)], -1)
    inside = d @ sun > math.cos(math.radians(SUN_RADIUS_DEG))
    img[inside] = SUN_RADIANCE
    return img.astype(np.float32)


def write_hdri(path: Path = HDRI_PATH) -> Path:
    """Write ``make_hdri`` as a half-float, ZIP-compressed EXR (top row first, as EXR
    stores scanlines; Blender reads it as a float image)."""
    import OpenEXR
    img = make_hdri()[::-1].astype(np.float16)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    path.parent.mkdir(parents=True, exist_ok=True)
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(img)}) as f:
        f.write(str(path))
    return path


def _hdri_world(scene, rot_z_deg=MAPPING_Z_DEG):
    world = scene.world
    tree = world.node_tree
    tree.nodes.clear()
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rot_z_deg))
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    if not HDRI_PATH.exists():
        write_hdri()
    env.image = bpy.data.images.load(str(HDRI_PATH), check_existing=True)
    env.interpolation = "Linear"
    bg = tree.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = STRENGTH
    out = tree.nodes.new("ShaderNodeOutputWorld")
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    tree.links.new(env.outputs["Color"], bg.inputs["Color"])
    tree.links.new(bg.outputs["Background"], out.inputs["Surface"])
    return world


def _block(name, lo, hi, material):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    verts = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return _ps._mesh_object(name, verts, faces, material)


def _camera(scene, eye, target, hfov_deg):
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.sensor_fit = "AUTO"
    cam_data.angle = math.radians(hfov_deg)
    cam_data.clip_start = 0.05
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    _ps._look_at(cam, eye, target)
    scene.camera = cam


def yard():
    scene = _ps._reset()
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    _hdri_world(scene)
    grey = _ps._material_diffuse("Ground", (0.5, 0.5, 0.5))
    _ps._mesh_object("Ground", [(-8, -8, 0), (8, -8, 0), (8, 8, 0), (-8, 8, 0)],
                     [(0, 1, 2, 3)], grey)
    _block("BoxA", (-2.2, 0.6, 0.0), (-1.2, 1.6, 1.0), _ps._material_diffuse("BoxA", (0.7, 0.7, 0.7)))
    _block("BoxB", (1.0, 1.2, 0.0), (1.8, 2.0, 0.6), _ps._material_diffuse("BoxB", (0.4, 0.5, 0.6)))
    slab = _ps._material_diffuse("Slab", (0.6, 0.6, 0.6))
    _block("Slab", (-0.8, -1.6, 1.2), (1.6, 0.0, 1.35), slab)
    _block("PostA", (-0.8, -1.6, 0.0), (-0.65, -1.45, 1.2), slab)
    _block("PostB", (1.45, -1.6, 0.0), (1.6, -1.45, 1.2), slab)
    _camera(scene, (6.0, -7.0, 4.5), (0.0, 0.0, 0.5), 60.0)
    return scene


def window_room():
    scene = _ps._reset()
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    _hdri_world(scene, ROOM_MAPPING_Z_DEG)
    wall = _ps._material_diffuse("Wall", (0.7, 0.7, 0.7))
    t = 0.1
    # floor, ceiling, walls as slabs; the wall at y = -2 has a window 1.2 x 1.0 (x -0.6..0.6,
    # z 0.9..1.9)
    _block("Floor", (-2 - t, -2 - t, -t), (2 + t, 2 + t, 0.0), wall)
    _block("Ceiling", (-2 - t, -2 - t, 2.6), (2 + t, 2 + t, 2.6 + t), wall)
    _block("West", (-2 - t, -2, 0), (-2, 2, 2.6), wall)
    _block("East", (2, -2, 0), (2 + t, 2, 2.6), wall)
    _block("North", (-2, 2, 0), (2, 2 + t, 2.6), wall)
    _block("SouthL", (-2, -2 - t, 0), (-0.6, -2, 2.6), wall)
    _block("SouthR", (0.6, -2 - t, 0), (2, -2, 2.6), wall)
    _block("SouthB", (-0.6, -2 - t, 0), (0.6, -2, 0.9), wall)
    _block("SouthT", (-0.6, -2 - t, 1.9), (0.6, -2, 2.6), wall)
    portal = _ps._light(scene, "Portal", "AREA", (0.0, -2.0 - t / 2, 1.4),
                        rotation=(math.radians(90.0), 0.0, 0.0), energy=1.0,
                        shape="RECTANGLE", size=1.2, size_y=1.0)
    portal.data.cycles.is_portal = True
    _camera(scene, (1.7, 1.7, 1.7), (-0.3, -1.0, 0.4), 75.0)
    return scene


def court():
    scene = _ps._reset()
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    _hdri_world(scene, COURT_MAPPING_Z_DEG)
    _ps._mesh_object("Ground", [(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)],
                     [(0, 1, 2, 3)], _ps._material_diffuse("Ground", (0.35, 0.40, 0.30)))
    wall = _ps._material_diffuse("Wall", (0.75, 0.75, 0.75))
    _block("WallX", (-1.5, 1.0, 0.0), (2.5, 1.25, 2.0), wall)
    _block("WallY", (2.25, -2.0, 0.0), (2.5, 1.0, 2.0), wall)
    _block("Pillar", (-0.9, -1.6, 0.0), (-0.5, -1.2, 2.4),
           _ps._material_diffuse("Pillar", (0.5, 0.5, 0.5)))
    _block("Bench", (0.6, 0.1, 0.0), (1.9, 0.6, 0.45),
           _ps._material_diffuse("Bench", (0.3, 0.3, 0.6)))
    _camera(scene, (-6.0, 5.0, 3.5), (0.5, -0.5, 0.8), 65.0)
    return scene


def yard_320():
    """The yard at ``BENCH_RESOLUTION``: the benchmark's picture (``lanterna bench --materials
    --worlds``), where the set-up that every render pays (the scene, the photon map) no longer
    outweighs the rendering, as it does at 80 x 60."""
    scene = yard()
    scene.render.resolution_x, scene.render.resolution_y = BENCH_RESOLUTION
    return scene


WORLD_SCENES = {"yard": yard, "window_room": window_room, "yard_320": yard_320,
                "court": court}


def build(name: str):
    scene = WORLD_SCENES[name]()
    bpy.context.view_layer.update()
    return scene
