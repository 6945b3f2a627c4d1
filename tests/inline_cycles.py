"""Helpers for tests that render a small bpy scene with Cycles inline and compare: a black
world, and Cycles' image of the scene as an (H, W, 3) float64 array (row 0 at the top, as
Lanterna's images), read back from an EXR written under ``tmp_path``."""
import pathlib

import numpy as np


def black_world(bpy, scene) -> None:
    """A World whose Background has strength 0: no light but the scene's own."""
    world = bpy.data.worlds.new("Black")
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world


def cycles_image(bpy, scene, tmp_path, samples: int, adaptive: bool = True) -> np.ndarray:
    """Cycles' render of ``scene`` at ``samples`` spp, no denoising (``adaptive`` False: no
    adaptive sampling either), (H, W, 3) float64 with row 0 at the top."""
    scene.render.engine = "CYCLES"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
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

