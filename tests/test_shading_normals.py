"""Normal maps at camera hits (issue 24): a node-driven Normal shades direct light.

A 4 m plane under a sun of 3 W/m^2 whose light comes tilted by ALPHA towards +x, a Diffuse
BSDF of 0.8 whose Normal is a tangent-space Normal Map of a constant colour
(0.5 + 0.5 sin a, 0.5, 0.5 + 0.5 cos a): the map tilts the normal by ``a`` towards the UV
map's u direction. Lambert's radiance is 0.8 / pi x 3 x cos(angle between the mapped normal
and the sun), exactly, with no indirect light (a lone plane under a black world), and so is
Cycles' (16 spp, rendered here). The UV map's u axis along +x puts the tangent along +x; the
same UVs turned by 90 degrees put it along -y, which the tangents must follow (the MikkTSpace
tangents export reads, ``export._read_tangents``).

Without the mapped normal (the smooth normal +z) the radiance is 0.8 / pi x 3 x cos(ALPHA):
13 % below the mapped value at ALPHA = 30 degrees, far outside these bounds (0.5 %).
"""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

ALPHA = math.radians(30.0)
SUN = 3.0
ALBEDO = 0.8


def _build(tilt: float, uv_turn: bool, space: str = "TANGENT", bump: str = ""):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plane = bpy.context.object
    if uv_turn:
        uv = plane.data.uv_layers.active.data
        for loop in uv:
            u, v = loop.uv
            loop.uv = (1.0 - v, u)        # turned by 90 degrees: u now runs along -y
    mat = bpy.data.materials.new("Mapped")
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    if bump:
        # Height h = -tan(tilt) x (x read through ``bump``): Bump's normal z - grad h leans
        # by ``tilt`` towards +x.
        node = tree.nodes.new("ShaderNodeBump")
        node.inputs["Distance"].default_value = 1.0
        if bump == "object":
            coords = tree.nodes.new("ShaderNodeTexCoord")
            position = coords.outputs["Object"]
        else:
            coords = tree.nodes.new("ShaderNodeNewGeometry")
            position = coords.outputs["Position"]
        split = tree.nodes.new("ShaderNodeSeparateXYZ")
        scale = tree.nodes.new("ShaderNodeMath")
        scale.operation = "MULTIPLY"
        scale.inputs[1].default_value = -math.tan(tilt)
        tree.links.new(position, split.inputs[0])
        tree.links.new(split.outputs["X"], scale.inputs[0])
        tree.links.new(scale.outputs[0], node.inputs["Height"])
        tree.links.new(node.outputs["Normal"], diffuse.inputs["Normal"])
    else:
        normal_map = tree.nodes.new("ShaderNodeNormalMap")
        normal_map.space = space
        colour = tree.nodes.new("ShaderNodeRGB")
        colour.outputs[0].default_value = (0.5 + 0.5 * math.sin(tilt), 0.5,
                                           0.5 + 0.5 * math.cos(tilt), 1.0)
        tree.links.new(colour.outputs[0], normal_map.inputs["Color"])
        tree.links.new(normal_map.outputs["Normal"], diffuse.inputs["Normal"])
    tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    plane.data.materials.append(mat)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = SUN
    sun.angle = 0.0
    sun_obj = bpy.data.objects.new("Sun", sun)
    scene.collection.objects.link(sun_obj)
    # The light travels along the sun's -z: turned about y by ALPHA it comes from
    # (sin ALPHA, 0, cos ALPHA).
    sun_obj.rotation_euler = (0.0, ALPHA, 0.0)
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = 50.0
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = (0.0, 0.0, 4.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def _lanterna_mean(scene):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert any("Normal of" in w and "shades camera hits" in w for w in exported.warnings)
    image = np.asarray(render(exported, RenderSettings(seed=1, preset="preview")).image)
    return image.reshape(-1, 3).mean(axis=0)


def _cycles_mean(scene, tmp_path):
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(tmp_path / "cycles.exr"))
    pixels = np.array(image.pixels[:], np.float64).reshape(-1, 4)[:, :3]
    return pixels.mean(axis=0)


@pytest.mark.parametrize("tilt, uv_turn, cos_expected", [
    (ALPHA, False, 1.0),                                   # tangent +x: normal onto the sun
    (-ALPHA, False, math.cos(2 * ALPHA)),                  # away from it
    (ALPHA, True, math.cos(ALPHA) ** 2),                   # tangent -y: tilted sideways
])
def test_normal_map_shades_direct_light_as_cycles(tilt, uv_turn, cos_expected, tmp_path):
    scene = _build(tilt, uv_turn)
    expected = ALBEDO / math.pi * SUN * cos_expected
    ours = _lanterna_mean(scene)
    cycles = _cycles_mean(scene, tmp_path)
    assert np.allclose(cycles, expected, rtol=5e-3), (cycles, expected)
    assert np.allclose(ours, expected, rtol=5e-3), (ours, expected)


@pytest.mark.parametrize("bump", ["object", "position"])
@pytest.mark.parametrize("tilt, cos_expected", [(ALPHA, 1.0), (-ALPHA, math.cos(2 * ALPHA))])
def test_bump_shades_direct_light_as_cycles(bump, tilt, cos_expected, tmp_path):
    """A Bump of a height linear in x (Texture Coordinate > Object, or Geometry > Position):
    the normal leans by ``tilt``; its finite differences step across the pixel's footprint,
    through the corner attributes' barycentric derivatives or the hit's position."""
    scene = _build(tilt, False, bump=bump)
    expected = ALBEDO / math.pi * SUN * cos_expected
    ours = _lanterna_mean(scene)
    cycles = _cycles_mean(scene, tmp_path)
    assert np.allclose(cycles, expected, rtol=5e-3), (cycles, expected)
    assert np.allclose(ours, expected, rtol=5e-3), (ours, expected)


def _wavy_plane():
    """A 4 m plane whose Principled BSDF (Roughness 0.5, so the specular layer shows the
    normals too) reads a tangent-space normal map image: ridges along v, the normal leaning
    +-0.5 rad towards u as sin(2 pi 3 u); under a 1 m area light, tilted, and a black world."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 48, 32
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plane = bpy.context.object
    size = 64
    u = (np.arange(size) + 0.5) / size
    lean = 0.5 * np.sin(2 * np.pi * 3 * u)
    texel = np.zeros((size, size, 4), np.float32)
    texel[..., 0] = 0.5 + 0.5 * np.sin(lean)[None, :]
    texel[..., 1] = 0.5
    texel[..., 2] = 0.5 + 0.5 * np.cos(lean)[None, :]
    texel[..., 3] = 1.0
    image = bpy.data.images.new("Ridges", size, size, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(texel.ravel())
    image.pack()
    mat = bpy.data.materials.new("Ridged")
    mat.use_nodes = True
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.7, 0.5, 0.3, 1.0)
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    plane.data.materials.append(mat)
    light = bpy.data.lights.new("Area", "AREA")
    light.energy = 200.0
    light.size = 1.0
    light_obj = bpy.data.objects.new("Area", light)
    light_obj.location = (2.0, 0.5, 2.0)
    light_obj.rotation_euler = (0.0, math.radians(45.0), 0.0)
    scene.collection.objects.link(light_obj)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -3.0, 3.0)
    cam.rotation_euler = (math.radians(45.0), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def test_image_normal_map_regions_match_cycles(tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    """The ridged plane's 4 x 4 region means against Cycles (256 spp, rendered here): within
    3 %. Measured against Cycles at 1024 spp: worst region 1.65 / 1.69 / 1.73 % at seeds
    1 / 2 / 3 (the left column 1-2 % bright at every seed); with the smooth normal instead
    87.5 % (regions from 0.65 to 2.07 of Cycles)."""
    from test_parity_cycles import block_means

    scene = _wavy_plane()
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    ours = np.asarray(render(exported, RenderSettings(seed=1, preset="final")).image,
                      np.float64)
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 256
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    cycles_image = bpy.data.images.load(str(tmp_path / "cycles.exr"))
    theirs = np.array(cycles_image.pixels[:], np.float64).reshape(32, 48, 4)[::-1, :, :3]
    luminance = np.array([0.2126, 0.7152, 0.0722])
    a = block_means(ours, (4, 4)) @ luminance
    b = block_means(theirs, (4, 4)) @ luminance
    bright = b > 0.1 * b.max()
    worst = float(np.abs(a[bright] / b[bright] - 1).max())
    print("worst region", worst)
    assert worst <= 0.03
