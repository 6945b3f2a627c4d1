"""Small bpy scenes, built by code, for material parity with Cycles (issue 23): all bounces.

Five scenes, each for one material question, rendered by ``tests/data/make_material_refs.py``
into ``tests/data/cycles_materials/``. ``MATERIAL_SCENES`` maps a name to its builder; each
builder starts from a fresh file and returns the ``bpy`` scene, with the engine set to Cycles
(the reference script sets the samples and the rest; a Lanterna test sets its own engine).
Units follow DESIGN.md section 3 (Power in W, Emission Strength = radiance, linear RGB).
Regions are the 4 x 4 blocks of the image (row 0 = top), as for ``tests/parity_scenes.py``.

``factory_cube`` (:func:`factory_cube`)
    ``bpy.ops.wm.read_factory_settings()`` **untouched** (the startup file of the Blender that
    runs it): the 2 m cube at the origin with the default Principled "Material" (base 0.8,
    roughness 0.5, IOR 1.5, Specular IOR Level 0.5), the 1000 W point light "Light" of radius
    0.1 m at (4.08, 1.01, 5.90) (not in the frame, ``visible_camera`` off in the startup file),
    the 50 mm camera at (7.36, -6.93, 4.96), the World's Background grey 0.0509. Only the
    engine is set to Cycles and ``resolution_percentage`` to ``FACTORY_PERCENTAGE`` (10):
    1920 x 1080 -> **192 x 108** (blocks of 27 x 48 px). The world is the only light on the
    background and the cube's shadow side.

The other four share a closed room (:func:`_room`): x, y in [-3, 3], z in [0, 3] m, six
inward-facing quads (floor, ceiling, left wall x = -3, right wall x = 3, back wall y = 3,
front wall y = -3, behind the camera), base colours ``ROOM_COLOURS`` (floor warm grey
(0.55, 0.45, 0.35), ceiling and front wall white 0.8, left red (0.70, 0.15, 0.10), right green
(0.15, 0.50, 0.15), back blue (0.20, 0.30, 0.70)); black world (nothing leaves the room
anyway, except in ``glass_caustic``). Spheres are UV spheres made here (:func:`_uv_sphere`,
``SPHERE_SEGMENTS`` x ``SPHERE_RINGS``, shaded smooth: Blender's corner normals), poles on
the z axis. 80 x 60 pixels (``RESOLUTION``, blocks of 15 x 20 px).

``principled_room`` (:func:`principled_room`)
    The room with every surface a Principled BSDF at Blender's defaults except Base Color
    (the ``ROOM_COLOURS``; roughness 0.5, IOR 1.5, Specular IOR Level 0.5: a diffuse base
    under a GGX dielectric layer). The ceiling has a 1.6 x 1.6 m hole at its centre filled by
    a panel quad in the ceiling's plane (z = 3, adjacent, not overlapping): a Principled BSDF
    with default Base Color 0.8, Emission Color white, Emission Strength
    ``PANEL_STRENGTH`` (10; it emits from both faces, the upper one into the black outside).
    The default cube: 2 m, flat-shaded, the default Principled material (base 0.8), standing
    on the floor at (0.6, 1.0), turned 30 degrees about z. Camera at (-0.2, -2.9, 1.7) looking
    at (0.2, 0.8, 0.8), horizontal FOV 75 degrees; the panel is above the frame (its corners
    project to 1.05-1.41 frame heights), the ceiling it lights is in view at the top. The only light is
    the panel (an emissive mesh, sampled by Cycles' light tree).

``metal_sphere`` (:func:`metal_sphere`)
    The room with Diffuse BSDF walls (roughness 0: Lambertian, the ``ROOM_COLOURS``) and a
    copper sphere of radius 0.75 m at (0, 0.4, 0.75) on the floor: Principled BSDF Metallic
    1, Roughness 0.3, Base Color ``COPPER`` (0.955, 0.638, 0.538), the rest default
    (Specular Tint white: Cycles' F82-tint conductor). Square AREA light 1.0 m, 200 W,
    spread 180 degrees, normalize on, 1 cm under the ceiling at (0, 0), facing down,
    ``visible_camera`` off (and out of the frame). Camera at (0, -2.8, 1.5) looking at
    (0, 0.4, 0.7), horizontal FOV 60 degrees. The sphere shows the coloured walls and the
    light's glossy highlight.

``mix_floor`` (:func:`mix_floor`)
    The room with Diffuse BSDF walls and ceiling (Lambertian) and a floor of Mix Shader
    Factor ``MIX_FACTOR`` (0.3) of Diffuse BSDF (first input, colour (0.55, 0.45, 0.35),
    roughness 0) and Glossy BSDF (second input, distribution GGX, not the node's default
    Multiscatter GGX; roughness 0.2, colour 0.8 (the node's default)): 0.7 diffuse +
    0.3 glossy. A Diffuse box 1 x 1 x 1 m, colour (0.80, 0.30, 0.20), on the floor at
    (0.6, 1.2), turned 20 degrees. Square AREA light 1.2 m, 250 W, 1 cm under the ceiling at
    (0, 1.5), facing down, ``visible_camera`` off, out of the frame; its glossy reflection in
    the floor is in view (the bright bottom-middle blocks). Camera at (0, -2.8, 1.6) looking
    at (0, 0.5, 0), horizontal FOV 60 degrees (floor, the box, the back wall's lower part).

``glass_caustic`` (:func:`glass_caustic`)
    No room: a 12 x 12 m floor at z = 0 (Diffuse BSDF white 0.8, Lambertian), a glass sphere
    of radius 0.5 m at (0, 0, 0.5) (Glass BSDF, IOR 1.5, roughness 0, colour white 1,
    ``SPHERE_SEGMENTS`` x ``SPHERE_RINGS`` smooth), black world. A SPOT light 1000 W, radius
    ``SPOT_RADIUS`` = 0.5 m, spot size 50 degrees, blend 0.3, ``SPOT_DISTANCE`` = 2 m from
    the sphere's centre at ``SPOT_ELEVATION`` = 30 degrees above the horizontal, from -x: at
    (-1.732, 0, 1.5), aimed at the sphere's centre. The large radius is deliberate: with a
    radius of 0 a path tracer cannot find the caustic at all, and Cycles' noise on it falls
    as the light's solid angle grows (radius 0.25 m at 3 m left ~13 x the variance). The
    light refracted by the sphere focuses 1.5 r from its centre, so it lands on the floor
    past the focus, in the sphere's shadow to the +x side: a caustic about 3-15 x brighter
    than the directly lit floor, around (0.9, 0, 0). ``CAUSTIC_REGION`` = (44, 64, 31, 39)
    holds its pixel bounds (x0, x1, y0, y1), half-open, row 0 = top, 20 x 8 px, taken from a
    Cycles render (the floor where the radiance is > ~3, the lit floor being ~1). It lies in
    the umbra: Cycles without caustic paths leaves it at exactly 0 (``image_no_caustics`` of
    the reference), so inside only the caustic lights the floor. Camera at
    (0.4, -3.0, 2.2) looking at (0.4, 0, 0.2), horizontal FOV 40 degrees; the spot's glint is
    reflected in the sphere (part of the picture), and fireflies of the sphere's reflected and
    refracted light cover the floor (the reason this scene needs the most samples).

Only ``bpy`` (and ``tests/parity_scenes.py``'s helpers): no import of Lanterna.
"""
from __future__ import annotations

import math

import bpy

import parity_scenes as _ps

RESOLUTION = (80, 60)
FACTORY_PERCENTAGE = 10            # 1920 x 1080 -> 192 x 108
ROOM = (-3.0, 3.0, -3.0, 3.0, 0.0, 3.0)   # x0, x1, y0, y1, z0, z1 [m]
ROOM_COLOURS = {
    "floor": (0.55, 0.45, 0.35),
    "ceiling": (0.8, 0.8, 0.8),
    "left": (0.70, 0.15, 0.10),
    "right": (0.15, 0.50, 0.15),
    "back": (0.20, 0.30, 0.70),
    "front": (0.8, 0.8, 0.8),
}
PANEL_SIZE = 1.6
PANEL_STRENGTH = 10.0
COPPER = (0.955, 0.638, 0.538)
MIX_FACTOR = 0.3
SPHERE_SEGMENTS, SPHERE_RINGS = 96, 48
SPOT_RADIUS = 0.5
SPOT_DISTANCE = 2.0        # from the sphere's centre [m]
SPOT_ELEVATION = 30.0      # degrees above the horizontal, from -x
# Pixel bounds (x0, x1, y0, y1) of the glass sphere's caustic on the floor in the 80 x 60
# image, half-open, row 0 = top: set from the Cycles reference (make_material_refs.py
# prints the caustic's mean in it; see tests/data/README.md).
CAUSTIC_REGION = (44, 64, 31, 39)

__all__ = ["MATERIAL_SCENES", "RESOLUTION", "FACTORY_PERCENTAGE", "ROOM", "ROOM_COLOURS",
           "PANEL_SIZE", "PANEL_STRENGTH", "COPPER", "MIX_FACTOR", "SPHERE_SEGMENTS",
           "SPHERE_RINGS", "SPOT_RADIUS", "SPOT_DISTANCE", "SPOT_ELEVATION",
           "CAUSTIC_REGION", "build"]


# --- building blocks ----------------------------------------------------------------------
def _reset():
    scene = _ps._reset()
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    return scene


def _principled(name, colour, **inputs):
    """A new material: Principled BSDF at Blender's defaults except Base Color and ``inputs``
    (socket name with spaces as underscores -> value)."""
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    for key, value in inputs.items():
        socket = bsdf.inputs[key.replace("_", " ")]
        socket.default_value = (*value, 1.0) if isinstance(value, tuple) else value
    return mat


def _camera(scene, eye, target, hfov_deg):
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.sensor_fit = "AUTO"
    cam_data.angle = math.radians(hfov_deg)   # horizontal: the wider side with fit AUTO
    cam_data.clip_start = 0.05
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    _ps._look_at(cam, eye, target)
    scene.camera = cam
    return cam


def _room(materials, hole=None):
    """The closed room ``ROOM``, quads facing inwards. ``materials``: name -> material for
    floor, ceiling, left, right, back, front. ``hole`` = (half size, material): the ceiling
    gets a square hole of that half size at its centre, filled by a panel quad ("Panel") in
    the ceiling's plane."""
    x0, x1, y0, y1, z0, z1 = ROOM
    quads = {
        "floor": [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)],
        "left": [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)],
        "right": [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)],
        "back": [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)],
        "front": [(x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0)],
    }
    for name, verts in quads.items():
        _ps._mesh_object(name.title(), verts, [(0, 1, 2, 3)], materials[name])
    if hole is None:
        _ps._mesh_object("Ceiling", [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)],
                         [(0, 1, 2, 3)], materials["ceiling"])
        return
    h, panel_mat = hole
    # outer square x0..x1, inner square -h..h; four quads around the hole, facing down
    outer = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    inner = [(-h, -h), (h, -h), (h, h), (-h, h)]
    verts = [(x, y, z1) for x, y in outer + inner]
    faces = [(0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)]
    _ps._mesh_object("Ceiling", verts, faces, materials["ceiling"])
    _ps._mesh_object("Panel", [(-h, -h, z1), (-h, h, z1), (h, h, z1), (h, -h, z1)],
                     [(0, 1, 2, 3)], panel_mat)


def _box(name, size, location, angle_deg, material):
    """An axis box of edge ``size`` standing on z = 0 at ``location`` (x, y), turned about z;
    six outward quads, flat shaded."""
    h = size / 2
    corners = [(x, y, z) for z in (-h, h) for y in (-h, h) for x in (-h, h)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    obj = _ps._mesh_object(name, corners, faces, material)
    obj.location = (*location, h)
    obj.rotation_euler = (0.0, 0.0, math.radians(angle_deg))
    return obj


def _uv_sphere(name, radius, centre, material, segments=None, rings=None):
    """A UV sphere (poles on z, triangle fans at the poles, quads between), shaded smooth."""
    segments = segments or SPHERE_SEGMENTS
    rings = rings or SPHERE_RINGS
    verts = [(0.0, 0.0, radius)]
    for i in range(1, rings):
        theta = math.pi * i / rings
        for j in range(segments):
            phi = 2 * math.pi * j / segments
            verts.append((radius * math.sin(theta) * math.cos(phi),
                          radius * math.sin(theta) * math.sin(phi), radius * math.cos(theta)))
    verts.append((0.0, 0.0, -radius))
    south = len(verts) - 1

    def ring(i, j):
        return 1 + (i - 1) * segments + j % segments

    faces = [(0, ring(1, j), ring(1, j + 1)) for j in range(segments)]
    for i in range(1, rings - 1):
        faces += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1))
                  for j in range(segments)]
    faces += [(ring(rings - 1, j + 1), ring(rings - 1, j), south) for j in range(segments)]
    obj = _ps._mesh_object(name, verts, faces, material)
    obj.data.shade_smooth()
    obj.location = centre
    return obj


def _diffuse_room(floor=None):
    mats = {k: _ps._material_diffuse(k.title(), c) for k, c in ROOM_COLOURS.items()}
    if floor is not None:
        mats["floor"] = floor
    _room(mats)


def _ceiling_area(scene, size, power, location_xy=(0.0, 0.0)):
    light = _ps._light(scene, "Area", "AREA", (*location_xy, ROOM[5] - 0.01),
                       rotation=(0.0, 0.0, 0.0), energy=power, shape="SQUARE", size=size,
                       spread=math.radians(180.0), normalize=True)    # local -Z = down
    light.visible_camera = False
    return light


# --- the scenes ---------------------------------------------------------------------------
def factory_cube():
    """The factory startup scene, untouched, at ``FACTORY_PERCENTAGE`` % (192 x 108)."""
    bpy.ops.wm.read_factory_settings()
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.render.resolution_percentage = FACTORY_PERCENTAGE
    return scene


def principled_room():
    """Closed room of default Principled walls (coloured), the default cube, a Principled
    emission panel in the ceiling."""
    scene = _reset()
    mats = {k: _principled(k.title(), c) for k, c in ROOM_COLOURS.items()}
    panel = _principled("Panel", (0.8, 0.8, 0.8), Emission_Color=(1.0, 1.0, 1.0),
                        Emission_Strength=PANEL_STRENGTH)
    _room(mats, hole=(PANEL_SIZE / 2, panel))
    cube = bpy.data.materials.new("Material")          # a new material: default Principled
    _box("Cube", 2.0, (0.6, 1.0), 30.0, cube)
    _camera(scene, (-0.2, -2.9, 1.7), (0.2, 0.8, 0.8), 75.0)
    return scene


def metal_sphere():
    """Rough copper sphere (Principled Metallic 1, Roughness 0.3) in a Lambertian room lit by
    a square area light under the ceiling."""
    scene = _reset()
    _diffuse_room()
    copper = _principled("Copper", COPPER, Metallic=1.0, Roughness=0.3)
    _uv_sphere("Sphere", 0.75, (0.0, 0.4, 0.75), copper)
    _ceiling_area(scene, 1.0, 200.0)
    _camera(scene, (0.0, -2.8, 1.5), (0.0, 0.4, 0.7), 60.0)
    return scene


def mix_floor():
    """Floor of Mix(Diffuse, Glossy GGX 0.2), factor 0.3, in a Lambertian room with a box."""
    scene = _reset()
    mat, tree, out = _ps._empty_material("MixFloor")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*ROOM_COLOURS["floor"], 1.0)
    diffuse.inputs["Roughness"].default_value = 0.0
    glossy = tree.nodes.new("ShaderNodeBsdfAnisotropic")          # the "Glossy BSDF" node
    glossy.distribution = "GGX"
    glossy.inputs["Roughness"].default_value = 0.2
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = MIX_FACTOR        # "Factor"
    tree.links.new(diffuse.outputs["BSDF"], mix.inputs[1])
    tree.links.new(glossy.outputs["BSDF"], mix.inputs[2])
    tree.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    _diffuse_room(floor=mat)
    _box("Box", 1.0, (0.6, 1.2), 20.0, _ps._material_diffuse("Box", (0.80, 0.30, 0.20)))
    _ceiling_area(scene, 1.2, 250.0, (0.0, 1.5))
    _camera(scene, (0.0, -2.8, 1.6), (0.0, 0.5, 0.0), 60.0)
    return scene


def glass_caustic():
    """Smooth glass sphere (IOR 1.5) on a white floor under a spot light of radius 0.25 m:
    a caustic in the sphere's shadow, ``CAUSTIC_REGION``."""
    scene = _reset()
    floor = _ps._material_diffuse("Floor", (0.8, 0.8, 0.8))
    _ps._mesh_object("Floor", [(-6, -6, 0), (6, -6, 0), (6, 6, 0), (-6, 6, 0)],
                     [(0, 1, 2, 3)], floor)
    mat, tree, out = _ps._empty_material("Glass")
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    glass.inputs["Roughness"].default_value = 0.0
    glass.inputs["IOR"].default_value = 1.5
    tree.links.new(glass.outputs["BSDF"], out.inputs["Surface"])
    _uv_sphere("Sphere", 0.5, (0.0, 0.0, 0.5), mat)
    elev, dist = math.radians(SPOT_ELEVATION), SPOT_DISTANCE
    _ps._light(scene, "Spot", "SPOT", (-dist * math.cos(elev), 0.0, 0.5 + dist * math.sin(elev)),
               target=(0.0, 0.0, 0.5), energy=1000.0, spot_size=math.radians(50.0),
               spot_blend=0.3, shadow_soft_size=SPOT_RADIUS)
    _camera(scene, (0.4, -3.0, 2.2), (0.4, 0.0, 0.2), 40.0)
    return scene


MATERIAL_SCENES = {
    "factory_cube": factory_cube,
    "principled_room": principled_room,
    "metal_sphere": metal_sphere,
    "mix_floor": mix_floor,
    "glass_caustic": glass_caustic,
}


def build(name: str):
    """Build scene ``name`` of ``MATERIAL_SCENES`` into a fresh file; return the bpy scene."""
    scene = MATERIAL_SCENES[name]()
    bpy.context.view_layer.update()
    return scene
