"""Glass under a thin film, and the Principled transmission's Fresnel, against inline Cycles
(issue 23: "thin film, as Cycles modulates Fresnel with it").

Cycles gives its Glass BSDF and the Principled BSDF's transmission one Fresnel
(``svm/closure.h``: generalised Schlick of the node's IOR, f0 = F0(IOR) x Specular Tint, the
film over it; on a back face the film's index is divided by the bulk index). Specular IOR
Level remaps only the Principled dielectric layer, not the transmission.

The scene: a glass surface seen from above at about 60 degrees, reflecting a white emissive
wall (strength 1) that stands beyond it; a black world, so the glass shows F of the wall and
the light that goes in is lost (or, in the closed box, comes back out where it meets the
wall). The region: the glass's lower 18 rows, per channel. Cycles: 1024 spp, 64 bounces,
Filter Glossy 0 (its default 1.0 blurs the rough box's inner bounces: +10 %).

* ``glass_film``: a Glass BSDF plane (IOR 1.5, smooth) under a 400 nm film of index 1.33;
* ``principled_film``: a Principled BSDF plane, Transmission 1, IOR 1.5, Specular IOR Level
  0.8, Specular Tint (1, 0.8, 0.6), a 300 nm film of index 1.6;
* ``principled_level``: the same without the film (the transmission ignores the Level);
* ``box_film``: a closed smooth glass box (6 x 6 x 2 m) with the film: light crosses back
  faces, where the film's index is 1.33 / 1.5;
* ``box_film_rough``: the box at Roughness 0.25 (Multiscatter GGX).

Measured, the worst channel of ours / Cycles at ``final`` (the rough box at 64 spp), seeds
1-3: glass_film 0.03 %, principled_film 0.01 %, principled_level 0.05 %, box_film 0.04-0.16 %,
box_film_rough 0.44-0.83 % (seeds 1-4; at 16 spp 0.8-2.5 %). Before, the film on glass was
ignored (``glass_film`` 2.88 / 2.84 / 1.04 of Cycles in R / G / B) and the transmission took
the Level's remapped index (``principled_level`` 1.43 / 1.41 / 1.38). Planted: the back
face's film index left undivided, ``box_film`` 2.67 / 1.58 / 1.72 (seed 1).
"""
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from inline_cycles import (add_camera, cycles_image, emissive_wall, empty_scene,  # noqa: E402
                           lanterna_image, node_material)

CYCLES_SAMPLES = 1024
REGION = (slice(30, 48), slice(8, 56))
# kind: bound on |ours / Cycles - 1| per channel (smooth glass: the camera splits it, so its
# region is nearly noise-free; the rough box carries the glossy paths' noise at ``final``)
BOUNDS = {"glass_film": 0.015, "principled_film": 0.015, "principled_level": 0.015,
          "box_film": 0.015, "box_film_rough": 0.02}
# Samples a pixel where ``final``'s 16 leave the region too noisy for its bound.
SAMPLES = {"box_film_rough": 64}


def _glass_material(kind: str):
    mat, tree, out = node_material(bpy, f"Glass {kind}")
    if kind.startswith("principled"):
        node = tree.nodes.new("ShaderNodeBsdfPrincipled")
        node.inputs["Transmission Weight"].default_value = 1.0
        node.inputs["Roughness"].default_value = 0.0
        node.inputs["IOR"].default_value = 1.5
        node.inputs["Specular IOR Level"].default_value = 0.8
        node.inputs["Specular Tint"].default_value = (1.0, 0.8, 0.6, 1.0)
        if kind.endswith("film"):
            node.inputs["Thin Film Thickness"].default_value = 300.0
            node.inputs["Thin Film IOR"].default_value = 1.6
    else:
        node = tree.nodes.new("ShaderNodeBsdfGlass")
        node.inputs["IOR"].default_value = 1.5
        node.inputs["Roughness"].default_value = 0.25 if kind.endswith("rough") else 0.0
        node.inputs["Thin Film Thickness"].default_value = 400.0
        node.inputs["Thin Film IOR"].default_value = 1.33
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def _scene(kind: str):
    scene = empty_scene(bpy)
    scene.cycles.blur_glossy = 0.0
    add_camera(bpy, scene, (0.0, -2.0, 1.2), (math.radians(60), 0.0, 0.0))
    if kind.startswith("box"):
        bpy.ops.mesh.primitive_cube_add(size=2, location=(0, 0, -1))
        bpy.context.object.scale = (3, 3, 1)
    else:
        bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, 0))
    bpy.context.object.data.materials.append(_glass_material(kind))
    emissive_wall(bpy, (0, 3.6, 3.0))
    return scene


def ratio_to_cycles(kind: str, tmp_path, seed: int = 1) -> np.ndarray:
    """Ours / Cycles (3,): the region's mean per channel."""
    scene = _scene(kind)
    _, ours = lanterna_image(bpy, seed, SAMPLES.get(kind))
    theirs = cycles_image(bpy, scene, tmp_path, CYCLES_SAMPLES)
    return ours[REGION].mean(axis=(0, 1)) / theirs[REGION].mean(axis=(0, 1))


@pytest.mark.parity      # whole renders against Cycles: make test-parity
@pytest.mark.parametrize("kind", list(BOUNDS))
def test_glass_fresnel_and_film_as_cycles(kind, tmp_path):
    ratio = ratio_to_cycles(kind, tmp_path)
    assert np.all(np.abs(ratio - 1) <= BOUNDS[kind]), ratio
