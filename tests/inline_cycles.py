"""Helpers for tests that render a small bpy scene with Cycles inline and compare: a black or
grey world, a camera and an area light, Cycles' image of the scene as an (H, W, 3) float64
array (row 0 at the top, as Lanterna's images), read back from an EXR written under
``tmp_path``, Lanterna's image at ``final``'s settings, and 4 x 4 region means."""
import math
import pathlib

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722])


def empty_scene(bpy, resolution=(64, 48), bounces: int = 64):
    """Blender's empty factory scene at ``resolution`` [px], Cycles' bounce limits all at
    ``bounces`` (the references' all-bounce settings), a black world; returns the scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    c = scene.cycles
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = bounces
    c.transmission_bounces = c.transparent_max_bounces = bounces
    black_world(bpy, scene)
    return scene


def emissive_wall(bpy, location, size=(12.0, 8.0), strength: float = 1.0):
    """An upright white Emission quad of ``size`` (width, height) [m] centred at ``location``,
    facing -y, of ``strength``; returns the object."""
    bpy.ops.mesh.primitive_plane_add(size=1, location=location, rotation=(math.pi / 2, 0, 0))
    wall = bpy.context.object
    wall.scale = (size[0], size[1], 1)
    mat, tree, out = node_material(bpy, "Wall")
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = strength
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    wall.data.materials.append(mat)
    return wall


def black_world(bpy, scene) -> None:
    """A World whose Background has strength 0: no light but the scene's own."""
    world = bpy.data.worlds.new("Black")
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world


def grey_world(bpy, scene, value: float) -> None:
    """A World whose Background is grey ``value`` at strength 1."""
    world = bpy.data.worlds.new("Grey")
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (value, value, value, 1)
    scene.world = world


def add_camera(bpy, scene, location, rotation) -> None:
    """A perspective camera at ``location`` with Euler ``rotation`` [rad], made active."""
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = location
    cam.rotation_euler = rotation
    scene.collection.objects.link(cam)
    scene.camera = cam


def add_area_light(bpy, scene, energy: float, size: float, location, rotation) -> None:
    """A square area light of ``energy`` [W] and ``size`` [m]."""
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", "AREA"))
    light.data.energy = energy
    light.data.size = size
    light.location = location
    light.rotation_euler = rotation
    scene.collection.objects.link(light)


def regions(image, luminance: bool = False) -> np.ndarray:
    """Means of a 4 x 4 grid of regions: (4, 4, 3), or (4, 4) of luminance."""
    h, w = image.shape[:2]
    means = image.reshape(4, h // 4, 4, w // 4, 3).mean(axis=(1, 3))
    return means @ LUMA if luminance else means


def lanterna_image(bpy, seed: int, samples: int | None = None):
    """(exported scene, image (H, W, 3)) of the current scene by Lanterna at ``final``'s
    settings (``samples`` a pixel where given, then that many everywhere: no adaptive
    sampling on top of a count chosen for the test), checked finite."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render
    from lanterna.engine.settings import PRESETS

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    # (``RenderSettings(preset="final", samples=...)`` would keep the preset's 16 samples.)
    settings = RenderSettings(seed=seed, preset="final") if samples is None else \
        RenderSettings(**{**PRESETS["final"], "samples": samples, "seed": seed,
                          "noise_threshold": 0.0})
    image = np.asarray(render(exported, settings).image)
    assert np.all(np.isfinite(image))
    return exported, image


def cycles_image(bpy, scene, tmp_path, samples: int, adaptive: bool = True,
                 unbiased: bool = False) -> np.ndarray:
    """Cycles' render of ``scene`` at ``samples`` spp, no denoising (``adaptive`` False: no
    adaptive sampling either), (H, W, 3) float64 with row 0 at the top. ``unbiased``: as the
    stored references (``tests/data``): Filter Glossy 0 and no clamping (Cycles' defaults,
    Filter Glossy 1 and indirect clamp 10, take light off caustic paths: a mirror wall's
    light on the floor 1-11 % under)."""
    scene.render.engine = "CYCLES"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    if unbiased:
        scene.cycles.blur_glossy = 0.0
        scene.cycles.sample_clamp_direct = scene.cycles.sample_clamp_indirect = 0.0
    if not adaptive:
        scene.cycles.use_adaptive_sampling = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(pathlib.Path(tmp_path) / "cycles.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath)
    w, h = scene.render.resolution_x, scene.render.resolution_y
    return np.array(image.pixels[:], np.float64).reshape(h, w, 4)[::-1, :, :3]


def node_material(bpy, name: str):
    """A new material with an empty node tree but its Material Output: (material, tree,
    output node)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    return mat, tree, tree.nodes.new("ShaderNodeOutputMaterial")

