"""Mix Shader with a node-driven Fac (issue 24): the mix follows the Fac at every hit.

A 2 m plane seen from 2.5 m above, its material a Mix Shader of two shaders whose Fac is a
Checker texture (Scale 4 over the Generated coordinates: 0.9 and 0.2 squares), rendered by
Lanterna (``preview``) and Cycles (64 spp), compared in 4 x 4 regions of a 32 x 32 image
(summed over channels):

- ``emission``: two Emission shaders (red, and blue of strength 2), the Fac the Checker's Fac
  (0 or 1: a hard switch);
- ``colour``: the same with the Checker's Color as Fac (Cycles takes a colour by its
  luminance: 0.9 and 0.2, a soft mix);
- ``lit``: two Diffuse BSDFs under a sun (a lone plane in a black world: direct light only).

Worst region at seeds 1-3: emission 0.34 %, colour 0.21 %, lit 0.05 % (anti-aliasing across
the squares' edges is the only noise on either side); the bound is 2 %. Before the Fac was read
per hit, export warned and mixed at the socket's value 0.5 everywhere: emission 52.7 %,
colour 25.8 %, lit 4.3 % off (its regions hold both colours of squares).
"""
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from inline_cycles import black_world, cycles_image, node_material  # noqa: E402

BOUND = 0.02
SIZE = 32

def _build(kind):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.object
    mat, tree, out = node_material(bpy, "Mixed")
    mix = tree.nodes.new("ShaderNodeMixShader")
    checker = tree.nodes.new("ShaderNodeTexChecker"); checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (0.9, 0.9, 0.9, 1); checker.inputs["Color2"].default_value = (0.2, 0.2, 0.2, 1)
    tree.links.new(checker.outputs["Fac" if kind != "colour" else "Color"], mix.inputs["Fac"])
    if kind in ("emission", "colour"):
        a = tree.nodes.new("ShaderNodeEmission"); a.inputs["Color"].default_value = (1, 0.2, 0.1, 1)
        b = tree.nodes.new("ShaderNodeEmission"); b.inputs["Color"].default_value = (0.1, 0.3, 1, 1); b.inputs["Strength"].default_value = 2
    else:
        a = tree.nodes.new("ShaderNodeBsdfDiffuse"); a.inputs["Color"].default_value = (0.8, 0.2, 0.1, 1)
        b = tree.nodes.new("ShaderNodeBsdfDiffuse"); b.inputs["Color"].default_value = (0.1, 0.3, 0.8, 1)
    tree.links.new(a.outputs[0], mix.inputs[1]); tree.links.new(b.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs[0])
    plane.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0, 0, 2.5)); scene.camera = bpy.context.object
    if kind == "lit":
        bpy.ops.object.light_add(type="SUN", rotation=(0.4, 0.2, 0.0)); bpy.context.object.data.energy = 3.0; bpy.context.object.data.angle = 0
    black_world(bpy, scene)
    return scene

def _regions(image):
    return image.reshape(4, SIZE // 4, 4, SIZE // 4, 3).mean(axis=(1, 3)).sum(axis=2)


def _worst(kind, tmp_path, seed=1):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    scene = _build(kind)
    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not exported.warnings, exported.warnings
    ours = np.asarray(render(exported, RenderSettings(seed=seed, preset="preview")).image,
                      np.float64).reshape(SIZE, SIZE, 3)
    theirs = cycles_image(bpy, scene, tmp_path, 64)
    return float(np.abs(_regions(ours) / _regions(theirs) - 1.0).max())


@pytest.mark.parametrize("kind", ["emission", "colour", "lit"])
def test_mix_fac_follows_its_texture_as_cycles(kind, tmp_path):
    assert _worst(kind, tmp_path) < BOUND


def test_glossy_lobe_under_a_driven_mix_is_weighed_per_hit():
    """A glossy lobe mixed in by a texture: no warning, and at each hit its weight over the
    surface's mean (``SurfaceParams.lobe_ratio``) is the Checker's Fac there (0 or 1) over
    that Fac's mean, and the diffuse's (1 - Fac) over its mean (its weight is in rho_d)."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.bsdf import MaterialTable

    _build("lit")
    tree = bpy.data.materials["Mixed"].node_tree
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    tree.links.new(glossy.outputs[0], tree.nodes["Mix Shader"].inputs[2])
    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not exported.warnings, exported.warnings
    table = MaterialTable(exported)
    assert table.lobe_weighted.tolist() == [True]
    rng = np.random.default_rng(4)
    prim = rng.integers(0, len(exported.triangles), 2000)
    bu, bv = rng.random(2000) * 0.5, rng.random(2000) * 0.5
    ratio = table.at(np.zeros(2000, np.int64), prim, bu, bv).lobe_inputs.ratio
    kinds = [c.kind for c in exported.materials[0].closures]
    glossy_ratio, diffuse_ratio = ratio[:, kinds.index("glossy")], ratio[:, kinds.index("diffuse")]
    on = glossy_ratio > 0
    assert 0.3 < on.mean() < 0.7
    np.testing.assert_array_equal(diffuse_ratio[on], 0.0)
    assert np.all(diffuse_ratio[~on] > 1.7)
    # The squares with Fac 1 all share one ratio, 1 / mean(Fac), about 2 for a checker.
    np.testing.assert_allclose(glossy_ratio[on], glossy_ratio[on][0])
    assert 1.7 < glossy_ratio[on][0] < 2.3
