"""Small bpy scenes, built by code, for parity with Cycles: direct light, and one GI scene.

Every builder starts from ``bpy.ops.wm.read_factory_settings(use_empty=True)`` and makes the
same set: a floor, a back wall and a rotated box (so that every light casts a shadow on both
floor and wall), a perspective camera at 64 x 48 pixels looking at them, a black world, and
one light. The light is never inside the camera's frame (:func:`lights_out_of_frame` checks
it). ``SCENES`` maps a scene name to its builder; each builder returns the ``bpy`` scene.

Materials are pure Lambertian in Cycles (measured, ``tests/data/README.md``):

- floor and wall: Principled BSDF with ``Specular IOR Level`` = 0 (no dielectric specular
  layer; the default 0.5 is *not* Lambertian), ``Roughness`` 1, ``Diffuse Roughness`` 0;
- box: a Diffuse BSDF with ``Roughness`` 0 (roughness > 0 would be Oren-Nayar).

Diffuse reflectances (linear RGB) are in ``COLOURS``. Units follow DESIGN.md section 3:
point/spot/area Power in W, sun Strength in W/m^2, emission Strength = radiance.

Geometry (metres, Z up): floor 12 x 12 at z = 0 centred on (0, -2); wall in the plane y = 2,
x in [-6, 6], z in [0, 5], facing -y; box 0.8 x 0.8 x 0.8 standing on the floor at
(0.3, 0.2), turned 30 degrees about z. Camera at (0, -5, 2.2) looking at (0, 0.5, 0.6),
horizontal field of view 50 degrees. Floor and wall fill the whole frame.

Global illumination (``GI_SCENES``, for the all-bounce references of ``make_cycles_refs.py
--gi``; kept apart so that ``SCENES`` and the direct-light tests do not see them):

- ``cornell`` (:func:`build_cornell`): a Cornell-box-like room x in [-1, 1], y in [-1, 1],
  z in [0, 2], open at the front (y = -1, where the camera looks in). Floor, ceiling and back
  wall white ``CORNELL_COLOURS["white"]`` = 0.75, left wall (x = -1) red (0.63, 0.065, 0.05),
  right wall (x = 1) green (0.14, 0.45, 0.091); a tall white box 0.6 x 0.6 x 1.2 at
  (-0.33, 0.3) turned 15 degrees and a short one 0.6 x 0.6 x 0.6 at (0.35, -0.3) turned -18
  degrees, both standing on the floor without a bottom face (nothing coplanar, nothing
  overlapping). All Diffuse BSDF, roughness 0 (Lambertian). One square AREA light 0.5 m,
  ``CORNELL_POWER`` W, spread 180 degrees, normalize on, 1 cm below the ceiling at its centre,
  facing down, invisible to the camera (``Object.visible_camera = False``: Lanterna does not
  draw area lights seen directly; it still lights the room). Black world. Camera at
  (0, -3.4, 1) looking at (0, 0, 1), horizontal FOV 60 degrees: the open front fills the
  height of the frame, black margins on both sides. ``CORNELL_RESOLUTION`` = 80 x 60.

- ``cornell_mm`` (:func:`build_cornell_original`): the original Cornell box of the Cornell
  University data page, in millimetres, its light quad an Emission mesh (strength 50) 0.1 mm
  under the ceiling and in view, 64 x 64 (``CORNELL_MM_*`` below).

Cameras (in ``SCENES``): ``sun_ortho`` is ``sun`` through an orthographic camera,
``sun_dof`` is ``sun`` with depth of field (a focus object, six blades) and ``sun_pano``
through an equirectangular camera. ``CAMERA_SCENES``
holds ``bokeh``, two out-of-focus emitters in frame whose images are the lens's shape,
compared through ``bokeh_moments`` rather than block means, and ``lights_in_frame``, lights
the camera sees (one of them with Visibility > Camera off), compared by the block rule.
``GEOMETRY_SCENES`` holds ``hair`` (Curves objects: a tuft of Catmull-Rom strands and a few
poly ones under the sun), compared by the block rule and 4 x 4-pixel blocks; ``fur_ball``
(20,000 strands, 160 x 120) is ``lanterna bench --hair``'s scene, with no stored reference.

Only ``bpy``, ``mathutils`` and numpy: no import of Lanterna, so the reference script can use
it without the add-on.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Vector

RESOLUTION = (64, 48)
COLOURS = {
    "floor": (0.70, 0.65, 0.55),
    "wall": (0.45, 0.55, 0.75),
    "box": (0.80, 0.30, 0.20),
}
WORLD_GREY = 0.25       # radiance of the constant world in the "world" scene [W m^-2 sr^-1]

CORNELL_RESOLUTION = (80, 60)
CORNELL_COLOURS = {
    "white": (0.75, 0.75, 0.75),
    "red": (0.63, 0.065, 0.05),
    "green": (0.14, 0.45, 0.091),
}
CORNELL_POWER = 30.0    # W, area light: lit walls at radiance ~0.1-1 with all bounces

__all__ = ["SCENES", "GI_SCENES", "RESOLUTION", "COLOURS", "WORLD_GREY", "CORNELL_RESOLUTION",
           "CORNELL_COLOURS", "CORNELL_POWER", "CORNELL_MM_RESOLUTION", "CORNELL_MM_COLOURS",
           "CORNELL_MM_STRENGTH", "CORNELL_MM_LIGHT_DROP", "build", "build_cornell",
           "build_cornell_original", "lights_out_of_frame"]


# --- building blocks ----------------------------------------------------------------------
def _reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    world = bpy.data.worlds.new("World")
    scene.world = world
    _set_world(world, 0.0)
    return scene


def _set_world(world, grey: float):
    """A new World in Blender 5 is a Background node of grey 0.05: set the node (what Cycles
    renders) and the viewport colour to ``grey``."""
    world.color = (grey, grey, grey)
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (grey, grey, grey, 1.0)
    bg.inputs["Strength"].default_value = 1.0


def _material_principled(name, colour):
    mat = bpy.data.materials.new(name)
    nodes = mat.node_tree.nodes
    bsdf = nodes.get("Principled BSDF")
    if bsdf is None:  # pragma: no cover - Blender always makes it for a new material
        raise RuntimeError("new material has no Principled BSDF node")
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Diffuse Roughness"].default_value = 0.0
    bsdf.inputs["Metallic"].default_value = 0.0
    return mat


def _empty_material(name):
    """A new material whose node tree holds only its output node: (material, tree, output)."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    return mat, tree, tree.nodes.new("ShaderNodeOutputMaterial")


def _material_diffuse(name, colour):
    mat, tree, out = _empty_material(name)
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def _material_emission(name, colour, strength):
    mat, tree, out = _empty_material(name)
    em = tree.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*colour, 1.0)
    em.inputs["Strength"].default_value = strength
    tree.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def _mesh_object(name, verts, faces, material):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], faces)
    mesh.update()
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _room(scene):
    """Floor, back wall, box and camera: the set shared by every scene."""
    floor = _material_principled("Floor", COLOURS["floor"])
    wall = _material_principled("Wall", COLOURS["wall"])
    box = _material_diffuse("Box", COLOURS["box"])
    _mesh_object("Floor", [(-6, -8, 0), (6, -8, 0), (6, 2, 0), (-6, 2, 0)], [(0, 1, 2, 3)], floor)
    _mesh_object("Wall", [(-6, 2, 0), (-6, 2, 5), (6, 2, 5), (6, 2, 0)], [(0, 1, 2, 3)], wall)
    h = 0.4
    corners = [(x, y, z) for z in (-h, h) for y in (-h, h) for x in (-h, h)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    obj = _mesh_object("Box", corners, faces, box)
    obj.location = (0.3, 0.2, h)
    obj.rotation_euler = (0.0, 0.0, math.radians(30.0))

    cam_data = bpy.data.cameras.new("Camera")
    cam_data.sensor_fit = "AUTO"
    cam_data.angle = math.radians(50.0)    # horizontal: the wider side with fit AUTO
    cam_data.clip_start = 0.05
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    _look_at(cam, (0.0, -5.0, 2.2), (0.0, 0.5, 0.6))
    scene.camera = cam


def _look_at(obj, eye, target):
    """Place ``obj`` at ``eye`` with its local -Z towards ``target`` and +Y up."""
    obj.location = eye
    direction = Vector(target) - Vector(eye)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def _light(scene, name, kind, location, target=None, rotation=None, **props):
    data = bpy.data.lights.new(name, kind)
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(name, data)
    scene.collection.objects.link(obj)
    if target is not None:
        _look_at(obj, location, target)      # lights emit along their local -Z
    else:
        obj.location = location
        if rotation is not None:
            obj.rotation_euler = rotation
    return obj


# --- the scenes ---------------------------------------------------------------------------
def point():
    """Point light, 300 W, radius 0: hard shadows."""
    scene = _reset()
    _room(scene)
    _light(scene, "Point", "POINT", (-1.2, -1.0, 2.8), energy=300.0, shadow_soft_size=0.0)
    return scene


def sun():
    """Sun, strength 3 W/m^2, angle 0.5 degrees, from the left, in front and above: the box's
    shadow falls on the floor to its right."""
    scene = _reset()
    _room(scene)
    _light(scene, "Sun", "SUN", (-4.0, -2.0, 3.2), target=(0.0, 0.0, 0.0),
           energy=3.0, angle=math.radians(0.5))
    return scene


def spot():
    """Spot, 600 W, size 60 degrees, blend 0.15, radius 0: the cone edge crosses floor and
    wall."""
    scene = _reset()
    _room(scene)
    _light(scene, "Spot", "SPOT", (-1.5, -1.2, 3.0), target=(0.6, 0.9, 0.0),
           energy=600.0, spot_size=math.radians(60.0), spot_blend=0.15, shadow_soft_size=0.0)
    return scene


def _area(shape, size, size_y=None, spread=math.radians(180.0), energy=200.0,
          location=(-1.6, -0.8, 2.7), target=(0.6, 0.6, 0.0)):
    scene = _reset()
    _room(scene)
    props = dict(energy=energy, shape=shape, size=size, spread=spread)
    if size_y is not None:
        props["size_y"] = size_y
    obj = _light(scene, f"Area{shape.title()}", "AREA", location, target=target, **props)
    return scene, obj


def area_square():
    """Square area light 1.2 m, 200 W, spread 180 degrees."""
    return _area("SQUARE", 1.2)[0]


def area_rectangle():
    """Rectangle area light 1.6 x 0.4 m, 200 W, turned about its normal."""
    scene, obj = _area("RECTANGLE", 1.6, 0.4)
    obj.rotation_euler.rotate_axis("Z", math.radians(35.0))
    return scene


def area_disk():
    """Disk area light, diameter 1.0 m, 200 W."""
    return _area("DISK", 1.0)[0]


def area_ellipse():
    """Ellipse area light 1.4 x 0.5 m (diameters), 200 W, turned about its normal."""
    scene, obj = _area("ELLIPSE", 1.4, 0.5)
    obj.rotation_euler.rotate_axis("Z", math.radians(-25.0))
    return scene


def area_disk_collimated():
    """Disk area light, diameter 2.4 m, spread 0: a collimated beam of irradiance P/A at
    normal incidence (the seed's circular directional light), 400 W, from the left: the box
    casts a sharp shadow to its right inside the elliptical footprint."""
    return _area("DISK", 2.4, spread=0.0, energy=400.0,
                 location=(-2.8, -0.3, 2.6), target=(0.0, 0.1, 0.0))[0]


def emission_mesh():
    """A 0.6 x 0.6 m quad with an Emission shader of strength 40 (white), tilted, above
    and in front of the box. Cycles emits from both faces."""
    scene = _reset()
    _room(scene)
    mat = _material_emission("Emitter", (1.0, 1.0, 1.0), 40.0)
    s = 0.3
    obj = _mesh_object("Emitter", [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)],
                       [(0, 1, 2, 3)], mat)
    _look_at(obj, (-0.5, -0.8, 2.9), (0.4, 0.8, 0.0))   # its local -Z faces the box
    return scene


def world():
    """No light: a constant grey world of radiance WORLD_GREY (floor shadowed by the wall
    and the box)."""
    scene = _reset()
    _room(scene)
    _set_world(scene.world, WORLD_GREY)
    return scene


def sun_ortho():
    """``sun`` seen through an orthographic camera: Orthographic Scale 6 m on the wider side,
    Shift X 0.08 and Y -0.05 (in units of that side), from the same place and direction."""
    scene = sun()
    cam = scene.camera.data
    cam.type = "ORTHO"
    cam.ortho_scale = 6.0
    cam.shift_x, cam.shift_y = 0.08, -0.05
    return scene


def sun_pano():
    """``sun`` seen through an equirectangular (panoramic) camera at (3, -2.5, 1.2) looking
    at (-1, 1.5, 0.6), over longitudes -120..150 degrees and latitudes -80..70 degrees (an
    off-centre camera and ranges, so that a swapped or mirrored axis shows)."""
    scene = sun()
    _look_at(scene.camera, (3.0, -2.5, 1.2), (-1.0, 1.5, 0.6))
    cam = scene.camera.data
    cam.type = "PANO"
    cam.panorama_type = "EQUIRECTANGULAR"
    cam.longitude_min, cam.longitude_max = math.radians(-120.0), math.radians(150.0)
    cam.latitude_min, cam.latitude_max = math.radians(-80.0), math.radians(70.0)
    return scene


def _focus_on(scene, location):
    """An empty at ``location`` as the camera's Focus Object; depth of field on."""
    target = bpy.data.objects.new("Focus", None)
    scene.collection.objects.link(target)
    target.location = location
    dof = scene.camera.data.dof
    dof.use_dof = True
    dof.focus_object = target
    return dof


def sun_dof():
    """``sun`` with depth of field: focused on the box's centre (an empty as Focus Object,
    5.5 m along the camera's axis), F-Stop 0.04 (a lens of radius 0.48 m: the near floor blurs
    by about 5 pixels, the wall by 1), six blades turned by 15 degrees."""
    scene = sun()
    dof = _focus_on(scene, (0.3, 0.2, 0.4))
    dof.aperture_fstop = 0.04
    dof.aperture_blades = 6
    dof.aperture_rotation = math.radians(15.0)
    return scene


def bokeh():
    """Two out-of-focus emitters on a black world: their images are the lens's shape (five
    blades turned by 20 degrees, Ratio 1.4: squeezed horizontally), scaled by how far each is
    from the focus plane, and turned over for the near one. Camera at the origin looking
    along +y (Focal Length 50 mm, Sensor Width 36 mm), focused by an empty 3 m ahead, F-Stop
    0.05 (lens radius 0.5 m). Emission strength 20, colour (1, 0.8, 0.6): a 0.4 m square 9 m
    away on the left (``BOKEH_REGIONS["far"]``, about 4 px across, blurred to about 20 px
    tall) and a 0.05 m square 1.5 m away on the right (``"near"``, about 3 px, blurred to
    about 30 px)."""
    scene = _reset()
    data = bpy.data.cameras.new("Camera")
    data.lens, data.sensor_width, data.sensor_fit = 50.0, 36.0, "AUTO"
    cam = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(cam)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)             # -Z towards +y, +Y up
    scene.camera = cam
    dof = _focus_on(scene, (0.5, 3.0, 0.2))
    dof.aperture_fstop = 0.05
    dof.aperture_blades = 5
    dof.aperture_rotation = math.radians(20.0)
    dof.aperture_ratio = 1.4
    mat = _material_emission("Emitter", (1.0, 0.8, 0.6), 20.0)
    for name, half, location in (("Far", 0.2, (-0.9, 9.0, 0.0)), ("Near", 0.025, (0.25, 1.5, 0.0))):
        quad = [(-half, 0, -half), (half, 0, -half), (half, 0, half), (-half, 0, half)]
        _mesh_object(name, quad, [(0, 1, 2, 3)], mat).location = location
    return scene


def lights_in_frame():
    """Lights the camera sees, as Cycles draws them: a disk area light (0.7 m, 150 W) and a
    point light of radius 0.2 m (Soft Falloff, 200 W) in frame, turned towards the camera,
    with Visibility > Camera on, and a square area light (0.5 m, 50 W) in frame with it off,
    as Blender makes a new light (it lights the room but is not drawn). The box and the room as in the other scenes."""
    scene = _reset()
    _room(scene)
    eye = (0.0, -5.0, 2.2)
    disk = _light(scene, "Disk", "AREA", (-1.6, 0.5, 2.2), target=eye, shape="DISK", size=0.7,
                  energy=150.0)
    bulb = _light(scene, "Bulb", "POINT", (1.2, 0.8, 1.9), energy=200.0, shadow_soft_size=0.2)
    hidden = _light(scene, "Hidden", "AREA", (0.0, 1.0, 2.6), target=eye, shape="SQUARE",
                    size=0.5, energy=50.0)
    disk.visible_camera = bulb.visible_camera = True     # a new light's is off
    hidden.visible_camera = False
    return scene


HAIR_COLOUR = (0.7, 0.35, 0.15)


def _curves_object(scene, name, strands, material, poly=False):
    """A Curves object of ``strands`` [(points (n, 3), radii (n,)), ...] with ``material``."""
    data = bpy.data.hair_curves.new(name)
    data.add_curves([len(p) for p, _ in strands])
    points = np.concatenate([p for p, _ in strands]).astype(np.float32)
    radii = np.concatenate([r for _, r in strands]).astype(np.float32)
    data.position_data.foreach_set("vector", points.reshape(-1))
    if "radius" not in data.attributes:
        data.attributes.new("radius", "FLOAT", "POINT")
    data.attributes["radius"].data.foreach_set("value", radii)
    if poly:
        data.set_types(type="POLY")
    data.materials.append(material)
    obj = bpy.data.objects.new(name, data)
    scene.collection.objects.link(obj)
    return obj


def hair():
    """Hair curves under ``sun``'s light: a tuft of 12 Catmull-Rom strands of three points
    each on an arc of 2 radians (radius 0.8 m, turned to random azimuths; the spline departs
    from the points' straight pieces by about 2 px), radius 0.09, 0.06 and 0 m (a closed
    tip), left of the box, and 5
    straight-piece (poly) strands of radius 0.05 m on its right, Principled ``HAIR_COLOUR``,
    Cycles' default Curves shape (Rounded Ribbons) turned to 3D Curves, the shape Lanterna
    draws. Strands are about 2-3 px wide at 64 x 48 and cast shadows on the floor and wall."""
    scene = sun()
    scene.cycles_curves.shape = "THICK"
    mat = _material_principled("Hair", HAIR_COLOUR)
    rng = np.random.default_rng(7)
    strands = []
    for i in range(12):
        root = np.array([-2.1 + 0.35 * (i % 4), -1.2 + 0.45 * (i // 4), -0.05])
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        bend = 2.0 * np.linspace(0.0, 1.0, 3)          # an arc of 2 rad, radius 0.8 m
        out, up = 0.8 * (1.0 - np.cos(bend)), 0.8 * np.sin(bend)
        points = root + np.stack([out * math.cos(azimuth), out * math.sin(azimuth), up], axis=1)
        strands.append((points, np.array([0.09, 0.06, 0.0])))
    _curves_object(scene, "Tuft", strands, mat)
    poly = []
    for i in range(5):
        root = np.array([0.9 + 0.2 * i, -1.9 + 0.25 * i, 0.0])
        points = root + np.array([[0, 0, 0], [0.1, 0.0, 0.5], [0.35, -0.1, 0.9], [0.5, 0.0, 1.1]])
        poly.append((points, np.full(4, 0.05)))
    _curves_object(scene, "Stubble", poly, mat, poly=True)
    return scene


FUR_REGIONS = {"fur": (slice(70, 115), slice(15, 75)), "core": (slice(80, 105), slice(25, 65)),
               "floor": (slice(100, 120), slice(110, 160))}     # rows, columns at 160 x 120


def fur_ball(strands: int = 20000):
    """``sun``'s room at 160 x 120 with a fur ball left of the box: a UV sphere (radius 0.5 m,
    centre (-1, -1, 0)) with ``strands`` Catmull-Rom strands on its upper half (6 points,
    0.25 m long along the normal, slightly bent, radius 4 mm at the root tapering to 0),
    Principled (0.6, 0.4, 0.2), 3D Curves; ``FUR_REGIONS`` name the fur, its core and the open
    floor. For ``lanterna bench --hair``, not a stored reference."""
    scene = sun()
    scene.cycles_curves.shape = "THICK"
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    rng = np.random.default_rng(1)
    normal = rng.normal(size=(strands, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    normal[:, 2] = np.abs(normal[:, 2])
    centre, radius, s = np.array([-1.0, -1.0, 0.0]), 0.5, np.linspace(0.0, 1.0, 6)
    bend = rng.normal(size=(strands, 3)) * 0.05
    points = (centre + radius * normal[:, None, :] + 0.25 * s[None, :, None] * normal[:, None, :]
              + bend[:, None, :] * s[None, :, None] ** 2)
    mat = _material_principled("Fur", (0.6, 0.4, 0.2))
    _curves_object(scene, "Fur", [(p, 0.004 * (1.0 - s)) for p in points], mat)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=tuple(centre))
    bpy.context.object.data.materials.append(mat)
    return scene


# Window columns holding each emitter's image in ``bokeh`` (at 64 x 48).
BOKEH_REGIONS = {"far": (0, 32), "near": (32, 64)}
BOKEH_BLADES, BOKEH_RATIO = 5, 1.4


def bokeh_moments(image, columns, blades=BOKEH_BLADES, ratio=BOKEH_RATIO) -> dict:
    """Moments of the red channel of an (H, W, 3) image (row 0 = top) over ``columns``
    [start, stop): ``flux`` (the sum), centroid ``cx``, ``cy`` [px], central second moments
    ``xx``, ``yy`` [px^2], and ``turn`` [degrees]: the phase of the blades-fold angular moment
    sum(I z^blades) / blades, z = (ratio dx, -dy) (the squeeze undone, y up), which tells the
    polygon's orientation (360 / blades degrees apart are the same)."""
    im = np.asarray(image, np.float64)[:, columns[0]:columns[1], 0]
    y, x = np.mgrid[:im.shape[0], :im.shape[1]]
    flux = im.sum()
    cx, cy = (im * x).sum() / flux, (im * y).sum() / flux
    dx, dy = x - cx, y - cy
    z = ratio * dx - 1j * dy
    turn = np.degrees(np.angle((im * z ** blades).sum())) / blades
    return {"flux": float(flux), "cx": float(cx + columns[0]), "cy": float(cy),
            "xx": float((im * dx * dx).sum() / flux), "yy": float((im * dy * dy).sum() / flux),
            "turn": float(turn)}


SCENES = {
    "point": point,
    "sun": sun,
    "spot": spot,
    "area_square": area_square,
    "area_rectangle": area_rectangle,
    "area_disk": area_disk,
    "area_ellipse": area_ellipse,
    "area_disk_collimated": area_disk_collimated,
    "emission_mesh": emission_mesh,
    "world": world,
    "sun_ortho": sun_ortho,
    "sun_dof": sun_dof,
    "sun_pano": sun_pano,
}
# Scenes for the camera's lens alone (their emitters are in frame on purpose).
CAMERA_SCENES = {"bokeh": bokeh, "lights_in_frame": lights_in_frame}
# Geometry beyond meshes, compared by the block rule like ``SCENES``.
GEOMETRY_SCENES = {"hair": hair}


# --- global illumination ------------------------------------------------------------------
def _cornell_box(name, size, location, angle_deg, material):
    """A box ``size`` = (sx, sy, sz) standing on z = 0 at ``location`` (x, y), turned about z;
    five outward quads (no bottom face: it would lie on the floor)."""
    hx, hy, hz = (s / 2 for s in size)
    corners = [(x, y, z) for z in (0.0, 2 * hz) for y in (-hy, hy) for x in (-hx, hx)]
    faces = [(4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    obj = _mesh_object(name, corners, faces, material)
    obj.location = (*location, 0.0)
    obj.rotation_euler = (0.0, 0.0, math.radians(angle_deg))
    return obj


def build_cornell():
    """Cornell-box-like room with a square area light under the ceiling (see the module
    docstring); all bounces matter: the ceiling is lit only indirectly."""
    scene = _reset()
    scene.render.resolution_x, scene.render.resolution_y = CORNELL_RESOLUTION
    white = _material_diffuse("White", CORNELL_COLOURS["white"])
    red = _material_diffuse("Red", CORNELL_COLOURS["red"])
    green = _material_diffuse("Green", CORNELL_COLOURS["green"])
    x0, x1, y0, y1, z0, z1 = -1.0, 1.0, -1.0, 1.0, 0.0, 2.0
    face = [(0, 1, 2, 3)]                  # quads listed with their normals pointing inwards
    _mesh_object("Floor", [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)], face, white)
    _mesh_object("Ceiling", [(x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1)], face, white)
    _mesh_object("Wall Back", [(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)], face, white)
    _mesh_object("Wall Left", [(x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)], face, red)
    _mesh_object("Wall Right", [(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)], face,
                 green)
    _cornell_box("Tall Box", (0.6, 0.6, 1.2), (-0.33, 0.3), 15.0, white)
    _cornell_box("Short Box", (0.6, 0.6, 0.6), (0.35, -0.3), -18.0, white)

    light = _light(scene, "Area", "AREA", (0.0, 0.0, z1 - 0.01), rotation=(0.0, 0.0, 0.0),
                   energy=CORNELL_POWER, shape="SQUARE", size=0.5, spread=math.radians(180.0),
                   normalize=True)                    # local -Z = down
    light.visible_camera = False

    cam_data = bpy.data.cameras.new("Camera")
    cam_data.sensor_fit = "AUTO"
    cam_data.angle = math.radians(60.0)    # horizontal (the wider side with fit AUTO)
    cam_data.clip_start = 0.05
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    _look_at(cam, (0.0, -3.4, 1.0), (0.0, 0.0, 1.0))
    scene.camera = cam
    return scene


# --- the original Cornell box, in millimetres ----------------------------------------------
# The Cornell University "Cornell Box data" page (graphics.cornell.edu/online/box/data.html):
# y-up, millimetres, the camera at (278, 273, -800) looking +z. Converted to Blender's z-up by
# the rotation of +90 degrees about x: (x, y, z)_data -> (x, -z, y) (a proper rotation, so red
# stays on the left as seen from the camera and no winding flips); the numbers stay the data's
# millimetres as Blender units (unit scale 1: neither Cycles nor Lanterna reads
# ``unit_settings.scale_length``, and radiance is independent of the scale).
CORNELL_MM_RESOLUTION = (64, 64)
CORNELL_MM_COLOURS = {
    "white": (0.73, 0.73, 0.73),
    "red": (0.63, 0.065, 0.05),
    "green": (0.14, 0.45, 0.09),
}
CORNELL_MM_STRENGTH = 50.0     # Emission strength = radiance of the light quad (white)
# The data put the light quad in the ceiling's plane (y = 548.8, the ceiling has no hole):
# coplanar, it z-fights with the ceiling in both renderers. Like most renditions (548.7) it is
# lowered by CORNELL_MM_LIGHT_DROP [mm].
CORNELL_MM_LIGHT_DROP = 0.1
CORNELL_MM_DATA = {     # quads of the data page, [mm], y up
    "Floor": ("white", [(552.8, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 559.2),
                        (549.6, 0.0, 559.2)]),
    "Ceiling": ("white", [(556.0, 548.8, 0.0), (556.0, 548.8, 559.2), (0.0, 548.8, 559.2),
                          (0.0, 548.8, 0.0)]),
    "Back Wall": ("white", [(549.6, 0.0, 559.2), (0.0, 0.0, 559.2), (0.0, 548.8, 559.2),
                            (556.0, 548.8, 559.2)]),
    "Right Wall": ("green", [(0.0, 0.0, 559.2), (0.0, 0.0, 0.0), (0.0, 548.8, 0.0),
                             (0.0, 548.8, 559.2)]),
    "Left Wall": ("red", [(552.8, 0.0, 0.0), (549.6, 0.0, 559.2), (556.0, 548.8, 559.2),
                          (556.0, 548.8, 0.0)]),
    "Short Block": ("white", [
        (130.0, 165.0, 65.0), (82.0, 165.0, 225.0), (240.0, 165.0, 272.0), (290.0, 165.0, 114.0),
        (290.0, 0.0, 114.0), (290.0, 165.0, 114.0), (240.0, 165.0, 272.0), (240.0, 0.0, 272.0),
        (130.0, 0.0, 65.0), (130.0, 165.0, 65.0), (290.0, 165.0, 114.0), (290.0, 0.0, 114.0),
        (82.0, 0.0, 225.0), (82.0, 165.0, 225.0), (130.0, 165.0, 65.0), (130.0, 0.0, 65.0),
        (240.0, 0.0, 272.0), (240.0, 165.0, 272.0), (82.0, 165.0, 225.0), (82.0, 0.0, 225.0)]),
    "Tall Block": ("white", [
        (423.0, 330.0, 247.0), (265.0, 330.0, 296.0), (314.0, 330.0, 456.0), (472.0, 330.0, 406.0),
        (423.0, 0.0, 247.0), (423.0, 330.0, 247.0), (472.0, 330.0, 406.0), (472.0, 0.0, 406.0),
        (472.0, 0.0, 406.0), (472.0, 330.0, 406.0), (314.0, 330.0, 456.0), (314.0, 0.0, 456.0),
        (314.0, 0.0, 456.0), (314.0, 330.0, 456.0), (265.0, 330.0, 296.0), (265.0, 0.0, 296.0),
        (265.0, 0.0, 296.0), (265.0, 330.0, 296.0), (423.0, 330.0, 247.0), (423.0, 0.0, 247.0)]),
}
CORNELL_MM_LIGHT = [(343.0, 548.8, 227.0), (343.0, 548.8, 332.0), (213.0, 548.8, 332.0),
                    (213.0, 548.8, 227.0)]
CORNELL_MM_CAMERA = dict(position=(278.0, 273.0, -800.0), direction=(0.0, 0.0, 1.0),
                         up=(0.0, 1.0, 0.0), lens_mm=35.0, film_mm=25.0)


def _cornell_mm_to_blender(p):
    """Data (x, y, z), y up -> Blender (x, -z, y), z up: +90 degrees about x."""
    x, y, z = p
    return (x, -z, y)


def build_cornell_original(light_drop=None, strength=None):
    """The original Cornell box (the data page's geometry, millimetres as Blender units, see
    ``CORNELL_MM_DATA``), lit by its ceiling quad: an Emission-shader mesh of strength
    ``CORNELL_MM_STRENGTH`` (both faces emit, as in Cycles), ``light_drop`` (default
    ``CORNELL_MM_LIGHT_DROP``) mm under the ceiling. Diffuse BSDF (roughness 0) white 0.73,
    red (0.63, 0.065, 0.05), green (0.14, 0.45, 0.09). The data's camera: 35 mm lens on a
    25 mm film (39.3 degrees), 64 x 64 pixels, clip 10-10000 mm. Black world. The light is in
    the frame, on purpose: both renderers draw an emissive mesh."""
    drop = CORNELL_MM_LIGHT_DROP if light_drop is None else light_drop
    scene = _reset()
    scene.render.resolution_x, scene.render.resolution_y = CORNELL_MM_RESOLUTION
    mats = {name: _material_diffuse(name.title(), colour)
            for name, colour in CORNELL_MM_COLOURS.items()}
    for name, (colour, points) in CORNELL_MM_DATA.items():
        verts = [_cornell_mm_to_blender(p) for p in points]
        faces = [tuple(range(i, i + 4)) for i in range(0, len(verts), 4)]
        _mesh_object(name, verts, faces, mats[colour])
    light = _material_emission("Light", (1.0, 1.0, 1.0),
                               CORNELL_MM_STRENGTH if strength is None else strength)
    verts = [_cornell_mm_to_blender((x, y - drop, z)) for x, y, z in CORNELL_MM_LIGHT]
    _mesh_object("Emitter", verts, [(0, 1, 2, 3)], light)

    c = CORNELL_MM_CAMERA
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.sensor_fit = "AUTO"
    cam_data.sensor_width = c["film_mm"]
    cam_data.lens = c["lens_mm"]
    cam_data.clip_start = 10.0
    cam_data.clip_end = 10000.0
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    eye = _cornell_mm_to_blender(c["position"])
    target = _cornell_mm_to_blender(tuple(p + d for p, d in zip(c["position"], c["direction"])))
    _look_at(cam, eye, target)          # world up +z: the data's up (0, 1, 0)
    scene.camera = cam
    return scene


GI_SCENES = {
    "cornell": build_cornell,
    "cornell_mm": build_cornell_original,
}


def build(name: str):
    """Build scene ``name`` (of ``SCENES``, ``CAMERA_SCENES``, ``GEOMETRY_SCENES`` or
    ``GI_SCENES``) into a fresh file and return the bpy scene."""
    scene = {**SCENES, **CAMERA_SCENES, **GEOMETRY_SCENES, **GI_SCENES}[name]()
    bpy.context.view_layer.update()
    return scene


def lights_out_of_frame(scene) -> list[str]:
    """Names of lights (and emissive meshes) that fall inside the camera frame; [] is good.

    Point-like lights are checked at their position; area lights and meshes at every corner
    (an area light is inside if any corner is in front of the camera and inside the frame).
    """
    from bpy_extras.object_utils import world_to_camera_view

    cam = scene.camera
    inside = []
    for obj in scene.objects:
        points = []
        if obj.type == "LIGHT":
            if obj.data.type == "SUN":
                continue
            points = [obj.matrix_world.translation]
            if obj.data.type == "AREA":
                sx = obj.data.size / 2
                sy = (obj.data.size_y if obj.data.shape in ("RECTANGLE", "ELLIPSE")
                      else obj.data.size) / 2
                points += [obj.matrix_world @ Vector((x, y, 0)) for x in (-sx, sx) for y in (-sy, sy)]
        elif obj.type == "MESH" and obj.name == "Emitter":
            points = [obj.matrix_world @ v.co for v in obj.data.vertices]
        for p in points:
            ndc = world_to_camera_view(scene, cam, p)
            if ndc.z > 0 and 0 <= ndc.x <= 1 and 0 <= ndc.y <= 1:
                inside.append(obj.name)
                break
    return inside
