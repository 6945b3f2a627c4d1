"""The seed's two test scenes (thesis section 12.1 and 12.2), built with ``bpy`` from nothing.

Scene 1 (12.1): a closed box with a half-height wall in the middle, a white point light near
the upper right corner, the right wall blue, the floor green, everything else white. The half
wall hides the left part of the box from the light, so the left side is lit only indirectly.

Scene 2 (12.2): a closed white room with a blue right wall; a point light sits at the closed
top of a short round tube that hangs from the ceiling and is open at the bottom, so the light
falls in a cone onto a (2, 3) torus knot and a red cylinder beside it (the knot's underside
picks up red light from the cylinder's top: colour bleeding).

Units are metres, Z up. Materials are Diffuse BSDF nodes (Lambertian, which is what the seed's
surfaces are; Cycles renders them alike) with ``Material.lanterna`` set to the same values when
Lanterna is registered. The world is black (a new Blender world is a grey 0.05 Background that
Cycles would add as light). Lights have radius 0: true point lights, as in the seed. Render
size 640 x 480, view transform Standard, engine LANTERNA when it is registered.

Public: ``build_scene1()``, ``build_scene2()``, ``build(name)``, ``save(name, path)``,
``SCENES``. Each build starts from ``read_factory_settings(use_empty=True)`` and returns the
new ``bpy.types.Scene``. Meshes are made from numpy arrays with ``foreach_set``.
"""
from __future__ import annotations

import os

import bpy
import numpy as np
from mathutils import Vector

from . import compat

__all__ = ["build_scene1", "build_scene2", "build", "save", "SCENES"]

WHITE = (0.8, 0.8, 0.8)
BLUE = (0.1, 0.2, 0.7)
GREEN = (0.2, 0.6, 0.2)
RED = (0.7, 0.08, 0.05)

# Scene 1: box [-2, 2] x [-2, 2] x [0, 3] m; half wall in the plane x = 0.
BOX1 = ((-2.0, -2.0, 0.0), (2.0, 2.0, 3.0))
HALF_WALL1 = ((-0.05, -1.0, 0.0), (0.05, 2.0, 1.5))
LIGHT1_POSITION = (1.5, 0.8, 2.6)
LIGHT1_POWER = 25.0  # W; tuned with Cycles: Standard view, lit walls near white, no large clipping

# Scene 2: room [-2.5, 2.5] x [-2.5, 2.5] x [0, 3] m.
BOX2 = ((-2.5, -2.5, 0.0), (2.5, 2.5, 3.0))
TUBE2 = dict(center=(0.1, 0.1), radius=0.25, length=0.4, segments=32)
LIGHT2_DEPTH = 0.05  # m below the ceiling, inside the tube
LIGHT2_POWER = 40.0  # W; tuned likewise
KNOT2 = dict(center=(0.0, 0.1, 1.0), p=2, q=3, radius=0.45, amplitude=0.2, tube=0.09,
             segments=384, sides=24)
CYLINDER2 = dict(center=(0.8, -0.1), radius=0.3, height=0.62, segments=48)


# -- Helpers ----------------------------------------------------------------------------------
def _reset() -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def _lanterna_registered() -> bool:
    return hasattr(bpy.types.Scene, "lanterna")


def _material(name: str, color) -> bpy.types.Material:
    """A Lambertian material: Diffuse BSDF of ``color`` into the Material Output."""
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = (*color, 1.0)
    tree = compat.ensure_node_tree(mat)
    nodes = tree.nodes
    for node in list(nodes):
        if node.bl_idname != "ShaderNodeOutputMaterial":
            nodes.remove(node)
    output = next((n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial"), None)
    if output is None:
        output = nodes.new("ShaderNodeOutputMaterial")
    output.location = (300, 0)
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    tree.links.new(bsdf.outputs["BSDF"], output.inputs["Surface"])
    if hasattr(mat, "lanterna"):
        mat.lanterna.derive_from_nodes = True
        mat.lanterna.diffuse = color
    return mat


def _black_world(scene: bpy.types.Scene) -> None:
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    for node in compat.ensure_node_tree(world).nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
            node.inputs["Strength"].default_value = 0.0
    scene.world = world


def _mesh_object(scene, name: str, verts, faces, material, smooth=False) -> bpy.types.Object:
    """An object from ``verts`` (N, 3) and ``faces``: one (F, k) int ndarray or a list of
    such blocks (faces of different sizes).

    ``smooth``: bool, or a bool array with one entry per face (in the order given).
    """
    verts = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
    if isinstance(faces, np.ndarray):
        faces = [faces]
    blocks = [np.atleast_2d(np.asarray(f, dtype=np.int32)) for f in faces]
    loops = np.concatenate([b.ravel() for b in blocks])
    sizes = np.concatenate([np.full(len(b), b.shape[1], np.int32) for b in blocks])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int32)

    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.ravel())
    mesh.loops.add(len(loops))
    mesh.loops.foreach_set("vertex_index", loops)
    mesh.polygons.add(len(sizes))
    mesh.polygons.foreach_set("loop_start", starts)
    flags = np.broadcast_to(np.asarray(smooth, dtype=bool), (len(sizes),))
    mesh.polygons.foreach_set("use_smooth", np.ascontiguousarray(flags))
    mesh.update(calc_edges=True)
    if mesh.validate():
        raise RuntimeError(f"{name}: generated mesh was invalid")
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def _box_walls(scene, lo, hi, materials: dict) -> list:
    """Six inward-facing quads, one object each: Floor, Ceiling, Wall Back/Front/Left/Right."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    # Corners listed counter-clockwise seen from inside the box (normals point inward).
    quads = {
        "Floor": [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],
        "Ceiling": [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)],
        "Wall Back": [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)],
        "Wall Front": [(x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0)],
        "Wall Left": [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)],
        "Wall Right": [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],
    }
    face = np.array([[0, 1, 2, 3]])
    return [_mesh_object(scene, name, corners, face, materials.get(name, materials["*"]))
            for name, corners in quads.items()]


def _camera(scene, location, target, lens_mm: float, name="Camera") -> bpy.types.Object:
    cam = bpy.data.cameras.new(name)
    cam.lens = lens_mm
    cam.sensor_width = 36.0
    cam.sensor_fit = 'AUTO'
    cam.clip_start = 0.05
    cam.clip_end = 100.0
    obj = bpy.data.objects.new(name, cam)
    obj.location = location
    direction = Vector(target) - Vector(location)
    obj.rotation_euler = direction.to_track_quat('-Z', 'Y').to_euler()
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


def _point_light(scene, location, power: float, name="Light") -> bpy.types.Object:
    light = bpy.data.lights.new(name, 'POINT')
    light.energy = power
    light.color = (1.0, 1.0, 1.0)
    light.shadow_soft_size = 0.0  # a true point light, as in the seed
    obj = bpy.data.objects.new(name, light)
    obj.location = location
    scene.collection.objects.link(obj)
    return obj


def _render_setup(scene, width=640, height=480) -> None:
    render = scene.render
    render.resolution_x, render.resolution_y = width, height
    render.resolution_percentage = 100
    render.pixel_aspect_x = render.pixel_aspect_y = 1.0
    render.use_border = False
    scene.view_settings.view_transform = 'Standard'
    scene.view_settings.look = 'None'
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    if _lanterna_registered():
        render.engine = 'LANTERNA'


# -- Geometry in numpy ------------------------------------------------------------------------
def torus_knot(p=2, q=3, radius=0.45, amplitude=0.2, tube=0.09, segments=384, sides=24):
    """A (p, q) torus knot tube: vertices (segments*sides, 3) and quads (segments*sides, 4).

    Centre line c(t) = ((R + a cos qt) cos pt, (R + a cos qt) sin pt, a sin qt), t in [0, 2pi),
    swept by a circle of radius ``tube`` in the Frenet frame (the curvature never vanishes
    on this curve, so the frame is smooth and closes on itself). Quads face outward.
    """
    t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    R, a = radius, amplitude
    cq, sq, cp, sp = np.cos(q * t), np.sin(q * t), np.cos(p * t), np.sin(p * t)
    r = R + a * cq
    dr = -a * q * sq
    ddr = -a * q * q * cq
    c = np.stack([r * cp, r * sp, a * sq], axis=1)
    d1 = np.stack([dr * cp - p * r * sp, dr * sp + p * r * cp, a * q * cq], axis=1)
    d2 = np.stack([ddr * cp - 2 * p * dr * sp - p * p * r * cp,
                   ddr * sp + 2 * p * dr * cp - p * p * r * sp,
                   -a * q * q * sq], axis=1)
    tangent = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    binormal = np.cross(d1, d2)
    binormal /= np.linalg.norm(binormal, axis=1, keepdims=True)
    normal = np.cross(binormal, tangent)
    phi = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    ring = (np.cos(phi)[None, :, None] * normal[:, None, :]
            + np.sin(phi)[None, :, None] * binormal[:, None, :])
    verts = (c[:, None, :] + tube * ring).reshape(-1, 3)
    i = np.arange(segments)[:, None]
    j = np.arange(sides)[None, :]
    i1, j1 = (i + 1) % segments, (j + 1) % sides
    quads = np.stack([i * sides + j, i * sides + j1, i1 * sides + j1, i1 * sides + j], axis=-1)
    return verts, quads.reshape(-1, 4)


def cylinder(radius=0.3, height=0.6, segments=48):
    """A closed cylinder standing on z = 0: vertices, [side quads (n, 4), caps (2, n)]."""
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    bottom = np.column_stack([ring, np.zeros(segments)])
    top = np.column_stack([ring, np.full(segments, height)])
    verts = np.concatenate([bottom, top])
    k = np.arange(segments)
    k1 = (k + 1) % segments
    sides = np.stack([k, k1, k1 + segments, k + segments], axis=1)  # outward
    caps = np.stack([k[::-1], k + segments])  # bottom faces down, top faces up
    return verts, [sides, caps]


def open_tube(radius=0.25, length=0.4, segments=32):
    """An open round tube from z = 0 down to z = -length (side quads only, no caps)."""
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    verts = np.concatenate([np.column_stack([ring, np.zeros(segments)]),
                            np.column_stack([ring, np.full(segments, -length)])])
    k = np.arange(segments)
    k1 = (k + 1) % segments
    return verts, np.stack([k, k + segments, k1 + segments, k1], axis=1)


def box_faces(lo, hi, skip=()):
    """An axis-aligned box with outward quads; ``skip`` names faces to leave out
    (any of "-x", "+x", "-y", "+y", "-z", "+z")."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    verts = np.array([(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    # vertex index = x + 2 y + 4 z (each 0/1)
    faces = {
        "-x": (0, 4, 6, 2), "+x": (1, 3, 7, 5),
        "-y": (0, 1, 5, 4), "+y": (2, 6, 7, 3),
        "-z": (0, 2, 3, 1), "+z": (4, 5, 7, 6),
    }
    return verts, np.array([f for key, f in faces.items() if key not in skip], np.int32)


# -- The scenes -------------------------------------------------------------------------------
def build_scene1() -> bpy.types.Scene:
    """Seed Scene 1: the box with a half wall, a point light near the upper right corner."""
    scene = _reset()
    scene.name = "Scene 1"
    white, blue = _material("White", WHITE), _material("Blue", BLUE)
    green = _material("Green", GREEN)
    _box_walls(scene, *BOX1, {"*": white, "Wall Right": blue, "Floor": green})
    # The half wall stands on the floor against the back wall: its bottom and back faces are
    # hidden, and left out so that no face lies on top of the floor or the back wall.
    verts, faces = box_faces(*HALF_WALL1, skip=("-z", "+y"))
    _mesh_object(scene, "Half Wall", verts, faces, white)
    _point_light(scene, LIGHT1_POSITION, LIGHT1_POWER)
    _camera(scene, location=(0.0, -1.85, 2.1), target=(0.0, 2.0, 1.1), lens_mm=18.0)
    _black_world(scene)
    _render_setup(scene)
    return scene


def build_scene2() -> bpy.types.Scene:
    """Seed Scene 2: white room, blue right wall, light in a ceiling tube, knot and cylinder."""
    scene = _reset()
    scene.name = "Scene 2"
    white, blue, red = _material("White", WHITE), _material("Blue", BLUE), _material("Red", RED)
    _box_walls(scene, *BOX2, {"*": white, "Wall Right": blue})
    ceiling = BOX2[1][2]

    tx, ty = TUBE2["center"]
    verts, faces = open_tube(TUBE2["radius"], TUBE2["length"], TUBE2["segments"])
    tube = _mesh_object(scene, "Tube", verts, faces, white)
    tube.location = (tx, ty, ceiling)
    _point_light(scene, (tx, ty, ceiling - LIGHT2_DEPTH), LIGHT2_POWER)

    knot = dict(KNOT2)
    center = knot.pop("center")
    verts, quads = torus_knot(**knot)
    obj = _mesh_object(scene, "Torus Knot", verts, quads, white, smooth=True)
    obj.location = center

    cx, cy = CYLINDER2["center"]
    verts, faces = cylinder(CYLINDER2["radius"], CYLINDER2["height"], CYLINDER2["segments"])
    smooth = np.concatenate([np.ones(len(faces[0]), bool), np.zeros(len(faces[1]), bool)])
    obj = _mesh_object(scene, "Cylinder", verts, faces, red, smooth=smooth)
    obj.location = (cx, cy, 0.0)

    _camera(scene, location=(0.8, -2.4, 1.7), target=(0.15, 0.1, 0.85), lens_mm=24.0)
    _black_world(scene)
    _render_setup(scene)
    return scene


SCENES = {"scene1": build_scene1, "scene2": build_scene2}


def build(name: str) -> bpy.types.Scene:
    """Build the seed scene ``name`` ("scene1" or "scene2") and return it."""
    try:
        builder = SCENES[name]
    except KeyError:
        raise ValueError(f"unknown seed scene {name!r}; choose from {', '.join(SCENES)}") from None
    return builder()


def save(name: str, path) -> str:
    """Build the seed scene ``name`` and save it as a .blend at ``path`` (returned, absolute)."""
    build(name)
    path = os.path.abspath(os.fspath(path))
    bpy.ops.wm.save_as_mainfile(filepath=path, check_existing=False, compress=True)
    return path
