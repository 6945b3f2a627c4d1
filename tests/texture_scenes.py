"""Small bpy scenes, built by code, for texture parity with Cycles (issue 24): all bounces.

Rendered by ``tests/data/make_material_refs.py`` (which renders these as it renders
``tests/material_scenes.py``'s) into ``tests/data/cycles_materials/``; ``TEXTURE_SCENES``
maps a name to its builder. Both share ``material_scenes``' closed room, camera and default
cube of ``principled_room`` (80 x 60 pixels, 4 x 4 regions of 20 x 15 px, Principled walls
of the ``ROOM_COLOURS``, black world):

``textured_room`` (:func:`textured_room`)
    * the floor's Base Color is an Image Texture (``FLOOR_IMAGE``: 32 x 32 px, 8-bit sRGB,
      packed, a 4 x 4 checker of ``FLOOR_COLOURS`` with a one-texel darker grout) through its
      UV map, which tiles it ``FLOOR_TILES`` = 3 times across each side (Linear
      interpolation, Repeat);
    * the back wall's Base Color is a second image (``WALL_IMAGE``: 16 x 64 px, 8-bit sRGB,
      horizontal bands of ``WALL_COLOURS``) through its UV map (0..1 across the wall), Closest
      interpolation;
    * the ceiling panel (1.6 m, in the ceiling's hole) is a Principled BSDF whose Emission
      Color is a third image (``PANEL_IMAGE``: 16 x 16 px, 8-bit sRGB, a smooth ramp from
      0.25 to 1 along x and a band of 0.5 along y) at Emission Strength ``PANEL_STRENGTH``
      (10), Base Color 0.8.
``textured_gallery`` (:func:`textured_gallery`), a validation scene: nothing was tuned on it
    (``textured_room`` chose the textured emitter's sub-triangles and the texture look-ups per
    camera sample). The same room seen from its other side (camera at (1.8, 2.6, 1.9)
    looking at (-0.6, -1.2, 0.6), 70 deg), the cube elsewhere (at (-0.9, -0.5), turned
    -20 deg):
    * the floor's Base Color is ``GALLERY_FLOOR_IMAGE`` (48 x 48 px, 8-bit sRGB, diagonal
      stripes of ``GALLERY_STRIPES``) through UV -> Mapping (scale 2 x 2, rotation z 30 deg)
      with Cubic interpolation, Repeat;
    * the left wall's Base Color is the back wall's band image of ``textured_room`` through
      Generated coordinates (Linear, Extend);
    * the panel's Emission Color is ``GALLERY_PANEL_IMAGE`` (8 x 8 px, 8-bit sRGB: a dim
      0.15 field with two bright 2 x 2 texel spots, one warm and one cold), Closest
      interpolation, at Emission Strength ``GALLERY_PANEL_STRENGTH`` (14).
``plain_room`` (:func:`plain_room`)
    The same, but the floor's Base Color is one colour: ``floor_mean_albedo()``, the mean of
    the floor image's texels in linear RGB (what the textured floor reflects on average). The
    issue's sharpness test compares the floor's per-pixel error of the two.

Only ``bpy`` and numpy (and the builders of ``tests/material_scenes.py``): no import of
Lanterna.
"""
from __future__ import annotations

import bpy
import numpy as np

import material_scenes as ms
import parity_scenes as _ps

FLOOR_COLOURS = ((0.85, 0.78, 0.62), (0.30, 0.42, 0.55))     # sRGB-encoded texel values
FLOOR_GROUT = 0.6                 # the grout texels are the cell colour x this
FLOOR_TILES = 3.0
WALL_COLOURS = ((0.75, 0.35, 0.25), (0.90, 0.85, 0.70), (0.25, 0.45, 0.70), (0.55, 0.60, 0.30))
FLOOR_IMAGE, WALL_IMAGE, PANEL_IMAGE = "FloorChecker", "WallBands", "PanelRamp"
GALLERY_STRIPES = ((0.80, 0.72, 0.55), (0.35, 0.30, 0.45), (0.60, 0.75, 0.65))
GALLERY_FLOOR_IMAGE, GALLERY_PANEL_IMAGE = "GalleryStripes", "GallerySpots"
GALLERY_PANEL_STRENGTH = 14.0

__all__ = ["TEXTURE_SCENES", "FLOOR_COLOURS", "FLOOR_TILES", "WALL_COLOURS", "floor_texels",
           "floor_mean_albedo", "build"]


def _srgb_to_linear(c):
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def floor_texels() -> np.ndarray:
    """(32, 32, 4) sRGB-encoded floor texels, row 0 at the bottom (Blender's order)."""
    size, cells = 32, 4
    cell = size // cells
    j, i = np.mgrid[0:size, 0:size]
    pick = ((i // cell) + (j // cell)) % 2
    rgb = np.asarray(FLOOR_COLOURS)[pick]
    grout = (i % cell == 0) | (j % cell == 0)
    rgb = np.where(grout[..., None], rgb * FLOOR_GROUT, rgb)
    return np.concatenate([rgb, np.ones((size, size, 1))], axis=2)


def _wall_texels() -> np.ndarray:
    height, width = 64, 16
    band = (np.arange(height) * len(WALL_COLOURS)) // height
    rgb = np.asarray(WALL_COLOURS)[band][:, None, :].repeat(width, axis=1)
    return np.concatenate([rgb, np.ones((height, width, 1))], axis=2)


def _panel_texels() -> np.ndarray:
    size = 16
    x = (np.arange(size) + 0.5) / size
    ramp = 0.25 + 0.75 * x                                  # along u
    rgb = np.repeat(ramp[None, :, None], size, axis=0).repeat(3, axis=2)
    rgb[size // 2 - 2:size // 2 + 2, :, 1] *= 0.5           # a band of half green along v
    return np.concatenate([rgb, np.ones((size, size, 1))], axis=2)


def floor_mean_albedo() -> tuple:
    """The floor image's mean texel in linear RGB."""
    return tuple(float(v) for v in _srgb_to_linear(floor_texels()[..., :3]).mean(axis=(0, 1)))


def _image(name, texels):
    """A packed 8-bit sRGB image of ``texels`` (H, W, 4), row 0 at the bottom."""
    height, width = texels.shape[:2]
    image = bpy.data.images.new(name, width, height, alpha=False)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(np.ascontiguousarray(texels, np.float32).ravel())
    image.pack()
    return image


def _uv(obj, uvs):
    """Set the object's first UV map to ``uvs``, one (u, v) per face corner, in loop order."""
    mesh = obj.data
    layer = mesh.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", np.asarray(uvs, np.float32).ravel())
    return layer


def _textured_principled(name, image, interpolation="Linear", socket="Base Color",
                         **inputs):
    mat = ms._principled(name, (0.8, 0.8, 0.8), **inputs)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = interpolation
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs[socket])
    return mat


def _build(textured_floor: bool):
    scene = ms._reset()
    mats = {k: ms._principled(k.title(), c) for k, c in ms.ROOM_COLOURS.items()
            if k not in ("floor", "back")}
    if textured_floor:
        mats["floor"] = _textured_principled("Floor", _image(FLOOR_IMAGE, floor_texels()))
    else:
        mats["floor"] = ms._principled("Floor", floor_mean_albedo())
    mats["back"] = _textured_principled("Back", _image(WALL_IMAGE, _wall_texels()), "Closest")
    panel = _textured_principled("Panel", _image(PANEL_IMAGE, _panel_texels()),
                                 socket="Emission Color", Emission_Strength=ms.PANEL_STRENGTH)
    ms._room(mats, hole=(ms.PANEL_SIZE / 2, panel))
    t = FLOOR_TILES
    _uv(bpy.data.objects["Floor"], [(0, 0), (t, 0), (t, t), (0, t)])
    _uv(bpy.data.objects["Back"], [(0, 0), (1, 0), (1, 1), (0, 1)])
    _uv(bpy.data.objects["Panel"], [(0, 0), (0, 1), (1, 1), (1, 0)])
    cube = bpy.data.materials.new("Material")
    ms._box("Cube", 2.0, (0.6, 1.0), 30.0, cube)
    ms._camera(scene, (-0.2, -2.9, 1.7), (0.2, 0.8, 0.8), 75.0)
    return scene


def textured_room():
    """The Principled room with an image-textured floor, back wall and emission panel."""
    return _build(True)


def _gallery_floor_texels() -> np.ndarray:
    size = 48
    j, i = np.mgrid[0:size, 0:size]
    band = ((i + j) // 8) % len(GALLERY_STRIPES)
    rgb = np.asarray(GALLERY_STRIPES)[band]
    return np.concatenate([rgb, np.ones((size, size, 1))], axis=2)


def _gallery_panel_texels() -> np.ndarray:
    size = 8
    rgb = np.full((size, size, 3), 0.15)
    rgb[1:3, 1:3] = (1.0, 0.85, 0.6)                        # a warm spot
    rgb[5:7, 4:6] = (0.6, 0.8, 1.0)                         # a cold one
    return np.concatenate([rgb, np.ones((size, size, 1))], axis=2)


def _mapped_image(mat, coordinate, image, interpolation, extension="REPEAT", scale=None,
                  rot_z_deg=0.0):
    """Feed ``mat``'s Base Color from ``image`` through Texture Coordinate ``coordinate``
    (and a Mapping of ``scale`` and rotation about z where given)."""
    tree = mat.node_tree
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = image, interpolation, extension
    vector = coords.outputs[coordinate]
    if scale is not None:
        mapping = tree.nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (*scale, 1.0)
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, np.radians(rot_z_deg))
        tree.links.new(vector, mapping.inputs["Vector"])
        vector = mapping.outputs["Vector"]
    tree.links.new(vector, tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def textured_gallery():
    """The validation scene of the module docstring: other images, mappings, interpolations
    and emission spots, from another viewpoint."""
    scene = ms._reset()
    mats = {k: ms._principled(k.title(), c) for k, c in ms.ROOM_COLOURS.items()}
    _mapped_image(mats["floor"], "UV", _image(GALLERY_FLOOR_IMAGE, _gallery_floor_texels()),
                  "Cubic", scale=(2.0, 2.0), rot_z_deg=30.0)
    _mapped_image(mats["left"], "Generated", _image(WALL_IMAGE, _wall_texels()), "Linear",
                  extension="EXTEND")
    panel = _textured_principled("Panel", _image(GALLERY_PANEL_IMAGE, _gallery_panel_texels()),
                                 "Closest", socket="Emission Color",
                                 Emission_Strength=GALLERY_PANEL_STRENGTH)
    ms._room(mats, hole=(ms.PANEL_SIZE / 2, panel))
    _uv(bpy.data.objects["Floor"], [(0, 0), (1, 0), (1, 1), (0, 1)])
    _uv(bpy.data.objects["Panel"], [(0, 0), (0, 1), (1, 1), (1, 0)])
    cube = bpy.data.materials.new("Material")
    ms._box("Cube", 1.6, (-0.9, -0.5), -20.0, cube)
    ms._camera(scene, (1.8, 2.6, 1.9), (-0.6, -1.2, 0.6), 70.0)
    return scene


def plain_room():
    """``textured_room`` with the floor's image replaced by its mean colour."""
    return _build(False)


TEXTURE_SCENES = {"textured_room": textured_room, "plain_room": plain_room,
                  "textured_gallery": textured_gallery}


def build(name: str):
    """Build scene ``name`` of ``TEXTURE_SCENES`` into a fresh file; return the bpy scene."""
    scene = TEXTURE_SCENES[name]()
    bpy.context.view_layer.update()
    return scene
