"""Oren-Nayar diffuse at camera hits (issue 23): Principled Diffuse Roughness and Diffuse BSDF
Roughness shade direct light as Cycles' Oren-Nayar does.

A lone 6 m plane under a black world and a sun 60 degrees off its normal, seen from the sun's
side 45 degrees off (where a rough diffuse looks brighter than Lambert's: back-scattering) and
from the far side (darker). Only direct light reaches the camera, so Lanterna's image is f(wo,
wi) E cos for the lobe (``lobes.OrenNayar``, tested against its own albedo and Helmholtz in
``test_lobes.py``) and Cycles' (16 spp, rendered here) the same up to its pixel noise.
Measured: ours / Cycles 1.0000 in every channel of all six cases; Lambert's radiance would be
0.64-0.79 of Cycles' on the sun's side and 2.5-3.1 on the far side (the bound is 1 %).
"""
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")


def _plane_under_sun(shader: str, roughness: float, camera_side: float):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add(size=6.0)
    plane = bpy.context.object
    mat = bpy.data.materials.new("Rough")
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    if shader == "diffuse":
        node = tree.nodes.new("ShaderNodeBsdfDiffuse")
        node.inputs["Color"].default_value = (0.8, 0.6, 0.4, 1.0)
        node.inputs["Roughness"].default_value = roughness
    else:
        node = tree.nodes.new("ShaderNodeBsdfPrincipled")
        node.inputs["Base Color"].default_value = (0.8, 0.6, 0.4, 1.0)
        node.inputs["Specular IOR Level"].default_value = 0.0
        node.inputs["Diffuse Roughness"].default_value = roughness
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    plane.data.materials.append(mat)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.0
    sun_obj = bpy.data.objects.new("Sun", sun)
    sun_obj.rotation_euler = (0.0, math.radians(60.0), 0.0)   # light from +x, 60 deg off
    scene.collection.objects.link(sun_obj)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 100.0
    angle = math.radians(45.0) * camera_side
    cam.location = (4.0 * math.sin(angle), 0.0, 4.0 * math.cos(angle))
    cam.rotation_euler = (0.0, angle, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def _means(scene, tmp_path):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert any("(Oren-Nayar, as Cycles) shapes direct light" in w for w in exported.warnings)
    ours = np.asarray(render(exported, RenderSettings(seed=1, preset="preview")).image)
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(tmp_path / "cycles.exr"))
    theirs = np.array(image.pixels[:], np.float64).reshape(-1, 4)[:, :3]
    return ours.reshape(-1, 3).mean(axis=0), theirs.mean(axis=0)


@pytest.mark.parametrize("shader", ["diffuse", "principled"])
@pytest.mark.parametrize("roughness, camera_side", [(1.0, 1.0), (1.0, -1.0), (0.5, 1.0)])
def test_oren_nayar_direct_light_matches_cycles(shader, roughness, camera_side, tmp_path):
    scene = _plane_under_sun(shader, roughness, camera_side)
    ours, theirs = _means(scene, tmp_path)
    lambert = np.array([0.8, 0.6, 0.4]) / math.pi * 3.0 * 0.5
    assert np.abs(theirs / lambert - 1).max() > 0.05      # the views tell the lobes apart
    np.testing.assert_allclose(ours, theirs, rtol=0.01)
