"""UDIM images (issue 24): an Image Texture of a tiled image, tile by tile, as Cycles maps it.

Three 8 x 8 sRGB tiles (1001, 1002, 1011) of random colours are saved as PNGs and loaded as
one UDIM image; a 2 m plane seen from 2.5 m above carries UVs from u = -0.5 to 3 and v = 0 to
2, so the picture shows tile 1001 twice (u in [-0.5, 0) truncates to tile 1001 in Cycles and
repeats inside it), tiles 1002 and 1011, and the tiles the image lacks (1003, 1012), which
Cycles paints in its missing-image magenta. The plane's Emission Color is the texture
(Closest), rendered by Lanterna (``preview``) and Cycles (64 spp), compared in 4 x 4 regions
of a 32 x 32 image.

Emission is seen directly: the only noise is each side's anti-aliasing across texel edges.
Worst region (summed over channels) at seeds 1-3: 0.41 / 0.55 / 0.36 %, from files and packed
alike; ``BOUND`` is 2 %. Without UDIM support export reports the image as unsupported and the
plane renders magenta (the test also asserts that export has nothing to report).

The packed case packs the tiles into the .blend's data and deletes the files: export reads
the packed bytes.
"""
import os
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from inline_cycles import black_world, cycles_image, node_material  # noqa: E402

SIZE = 32
TILES = (1001, 1002, 1011)
BOUND = 0.02      # 3.6x the worst region measured at seeds 1-3 (docstring)


def _build(tmp_path, packed: bool):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    rng = np.random.default_rng(7)
    for number in TILES:
        tile = bpy.data.images.new(f"tile{number}", 8, 8)
        texels = np.concatenate([rng.random((64, 3)), np.ones((64, 1))], axis=1)
        tile.pixels.foreach_set(texels.astype(np.float32).ravel())
        tile.filepath_raw = str(tmp_path / f"paint.{number}.png")
        tile.file_format = "PNG"
        tile.save()
        bpy.data.images.remove(tile)
    image = bpy.data.images.load(str(tmp_path / "paint.1001.png"))
    image.source = "TILED"
    assert sorted(t.number for t in image.tiles) == list(TILES)
    if packed:
        image.pack()
        for number in TILES:
            os.remove(tmp_path / f"paint.{number}.png")
    # A grid with vertices in every tile: Cycles loads a file-based UDIM image's tiles only
    # where some vertex of the mesh has its UV (measured: on a four-corner plane over the
    # same UVs it leaves tile 1002 magenta), Lanterna reads every tile the image has.
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=7, y_subdivisions=4, size=2.0)
    plane = bpy.context.object
    for loop in plane.data.uv_layers.active.data:
        u, v = loop.uv
        loop.uv = (-0.5 + 3.5 * u, 2.0 * v)
    mat, tree, out = node_material(bpy, "Painted")
    emission = tree.nodes.new("ShaderNodeEmission")
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    texture.interpolation = "Closest"
    tree.links.new(texture.outputs["Color"], emission.inputs["Color"])
    tree.links.new(emission.outputs[0], out.inputs[0])
    plane.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.0, 0.0, 2.5))
    scene.camera = bpy.context.object
    black_world(bpy, scene)
    return scene


def _regions(image):
    return image.reshape(4, SIZE // 4, 4, SIZE // 4, 3).mean(axis=(1, 3))


def _cycles(scene, tmp_path):
    return cycles_image(bpy, scene, tmp_path, 64)


def _worst(scene, tmp_path, seed: int = 1) -> float:
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not exported.warnings, exported.warnings
    ours = np.asarray(render(exported, RenderSettings(seed=seed, preset="preview")).image,
                      np.float64).reshape(SIZE, SIZE, 3)
    theirs = _regions(_cycles(scene, tmp_path)).sum(axis=2)
    return float(np.abs(_regions(ours).sum(axis=2) / np.maximum(theirs, 1e-6) - 1.0).max())


@pytest.mark.parametrize("packed", [False, True], ids=["files", "packed"])
def test_udim_tiles_match_cycles(packed, tmp_path):
    scene = _build(tmp_path, packed)
    assert _worst(scene, tmp_path) < BOUND


def test_udim_lookup_maps_tiles_as_cycles():
    """Tile choice by truncation, UVs relative to the tile, missing tiles magenta."""
    from lanterna.engine import nodes

    tiles = {n: nodes.Image(np.full((2, 2, 4), k / 4.0, np.float32), "linear")
             for k, n in enumerate((1001, 1002, 1011), start=1)}
    image = nodes.TiledImage(tiles)
    u = np.array([0.25, 1.25, 0.25, -0.75, 2.5, 10.5, np.nan])
    v = np.array([0.25, 0.25, 1.25, 0.25, 0.5, 0.5, 0.5])
    rgba = nodes.image_lookup(image, u, v)
    assert np.allclose(rgba[:4, 0], [0.25, 0.5, 0.75, 0.25])
    assert np.allclose(rgba[4:], nodes.MISSING_RGBA)
