"""Transparent BSDF and Principled Alpha (issue 23): straight through, as Cycles.

A 4 m plane fills the camera's view in front of a larger emitting plane (radiance 1) under a
black world, so that what the plane reflects is black and only what it lets through is seen. Its
material is a Transparent BSDF of colour C, or a Principled BSDF of Base Color 0 and Specular
IOR Level 0 (it reflects nothing) with Alpha a: Cycles mixes a Transparent BSDF in with weight
1 - a. The camera then sees the emitter through the plane, C x 1 or (1 - a) x 1 exactly
(what the plane does not transmit it absorbs). Before, both rendered black (0); rendered as a
mirror of colour C they would be black too.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")


def _plane_in_white_world(make_material):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plane = bpy.context.object
    mat = bpy.data.materials.new("Seen through")
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(make_material(tree).outputs[0], out.inputs["Surface"])
    plane.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, 0.0, 4.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.ops.mesh.primitive_plane_add(size=40.0, location=(0.0, 0.0, -1.0))
    glow = bpy.data.materials.new("Glow")
    glow.use_nodes = True
    glow.node_tree.nodes.clear()
    emission = glow.node_tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    glow_out = glow.node_tree.nodes.new("ShaderNodeOutputMaterial")
    glow.node_tree.links.new(emission.outputs[0], glow_out.inputs["Surface"])
    bpy.context.object.data.materials.append(glow)
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def _transparent(colour):
    def make(tree):
        node = tree.nodes.new("ShaderNodeBsdfTransparent")
        node.inputs["Color"].default_value = (*colour, 1.0)
        return node
    return make


def _principled_alpha(alpha):
    def make(tree):
        node = tree.nodes.new("ShaderNodeBsdfPrincipled")
        node.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        node.inputs["Specular IOR Level"].default_value = 0.0
        node.inputs["Alpha"].default_value = alpha
        return node
    return make


def _render_mean(scene):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert any("Transparent BSDF" in w and "not through shadow rays" in w
               for w in exported.warnings), exported.warnings
    image = np.asarray(render(exported, RenderSettings(seed=1, preset="preview")).image)
    assert np.all(np.isfinite(image))
    return image.reshape(-1, 3).mean(axis=0)


def _cycles_mean(scene, tmp_path):
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(tmp_path / "cycles.exr"))
    return np.array(image.pixels[:], np.float64).reshape(-1, 4)[:, :3].mean(axis=0)


@pytest.mark.parametrize("make, expected", [
    (_transparent((0.2, 0.5, 0.8)), (0.2, 0.5, 0.8)),
    (_principled_alpha(0.25), (0.75, 0.75, 0.75)),
])
def test_seen_through_as_cycles(make, expected, tmp_path):
    scene = _plane_in_white_world(make)
    ours = _render_mean(scene)
    cycles = _cycles_mean(scene, tmp_path)
    assert np.allclose(cycles, expected, rtol=1e-3), cycles
    assert np.allclose(ours, expected, rtol=1e-3), ours


def test_material_panel_names_the_transparent_lobe():
    from lanterna.engine.shaders import Closure, lobe_names

    assert lobe_names([Closure("transparent"), Closure("diffuse")]) == ["transparent", "diffuse"]


def test_half_transparent_card_shadow_matches_cycles(tmp_path):
    """A red Principled card of Alpha 0.5 hovering 1 m over a white floor under a sun: the
    light it lets through reaches the floor by caustic photons (not by shadow rays, as in
    Cycles), its half-shadow and the card itself within 3 % of Cycles (256 spp, rendered
    here) in every 4 x 4 region. Measured against Cycles at 1024 spp, ``final``: worst region
    0.59 / 1.18 / 0.51 % at seeds 1 / 2 / 3 (3.5 s each, 64 x 48); before, the card rendered
    opaque and the floor under it without the sun (its shadow regions 0.41-0.48 of the lit
    floor's luminance in Cycles)."""
    import math
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_parity_cycles import block_means
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    for size, z, colour, alpha in ((8.0, 0.0, (0.8, 0.8, 0.8), 1.0),
                                   (2.0, 1.0, (0.8, 0.2, 0.2), 0.5)):
        bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, z))
        mat = bpy.data.materials.new(f"Alpha {alpha}")
        mat.use_nodes = True
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
        bsdf.inputs["Specular IOR Level"].default_value = 0.0
        bsdf.inputs["Alpha"].default_value = alpha
        bpy.context.object.data.materials.append(mat)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.0
    sun_obj = bpy.data.objects.new("Sun", sun)
    sun_obj.rotation_euler = (0.0, math.radians(20.0), 0.0)
    scene.collection.objects.link(sun_obj)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location, cam.rotation_euler = (0.0, -5.0, 5.0), (math.radians(45.0), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    ours = np.asarray(render(exported, RenderSettings(seed=1, preset="final")).image, float)
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 256
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    theirs = np.array(bpy.data.images.load(str(tmp_path / "cycles.exr")).pixels[:],
                      float).reshape(48, 64, 4)[::-1, :, :3]
    luminance = np.array([0.2126, 0.7152, 0.0722])
    a = block_means(ours, (4, 4)) @ luminance
    b = block_means(theirs, (4, 4)) @ luminance
    assert float(np.abs(a / b - 1).max()) <= 0.03
