"""Translucent BSDF (issue 23): light from the far side, f = rho_t / pi, as Cycles has it.

1. **Seen lit from behind**: a 4 m plane whose material is a Translucent BSDF of colour
   rho_t = (0.6, 0.8, 0.3), a sun of 3 W/m^2 under it tilted by 0.5 rad, the camera above: its
   radiance is rho_t / pi x 3 cos 0.5 exactly (a lone plane in a black world), in Cycles too
   (64 spp, rendered here). A Mix (0.5) with a Diffuse BSDF lit by a second sun from above is
   compared with Cycles alone. Measured: within 0.08 % (0.06 % mixed) of both at seeds 1-3;
   rendered as a diffuse of its colour (as before) the plane was black (the sun is behind
   it).
2. **The shade under a translucent sheet**: a 2 m sheet (rho_t = (0.7, 0.5, 0.3)) 1 m over a
   white (0.8) floor under a zenith sun of 3 W/m^2, the camera 0.9 m over the floor looking
   down at the centre of the shade: the floor there sees only the sheet's underside, a
   Lambertian emitter of radiance rho_t / pi x 3, so its radiance is
   0.8 / pi x L x (pi x the square's form factor, 1.7408), exactly (nothing else lights it:
   a black world, and the sheet reflects nothing). The light reaches it by photons through
   the sheet and by gather rays that read the sheet's far side. Measured at ``preview``,
   seeds 1-3: +1.1 %, -0.6 %, -2.3 % (the cache's noise; ``SHADE_BOUND`` 5 %). Before
   photons went through from the hit itself, a photon pulled back along its way and pushed
   through by the same distance stayed on the sheet under the zenith sun and crossed it
   twice (x rho_t^2): +33-74 % per channel.
3. **A side view against Cycles**: the same sheet and floor seen from the side (the sheet's
   edge, the lit floor and the shade under it), ``final`` against Cycles at 2048 spp (no
   adaptive sampling, rendered here), 4 x 4 regions of luminance brighter than a tenth of the
   brightest: worst 0.9 % / 1.5 % / 2.1 % at seeds 1-3 (the bound: 3 %, the issue's bound
   for material scenes).
"""
import math
import pathlib
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from inline_cycles import black_world, cycles_image, node_material  # noqa: E402

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
SHADE_BOUND = 0.05
SIDE_BOUND = 0.03


def _material(name: str, node: str, colour):
    mat, tree, out = node_material(bpy, name)
    shader = tree.nodes.new(node)
    shader.inputs["Color"].default_value = (*colour, 1.0)
    tree.links.new(shader.outputs[0], out.inputs[0])
    return mat


def _sun(rotation, energy):
    bpy.ops.object.light_add(type="SUN", rotation=rotation)
    bpy.context.object.data.energy = energy
    bpy.context.object.data.angle = 0.0


def _cycles(scene, tmp_path, samples):
    return cycles_image(bpy, scene, tmp_path, samples, adaptive=False)


def _lanterna(scene, seed, preset):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not exported.warnings, exported.warnings
    w, h = scene.render.resolution_x, scene.render.resolution_y
    result = render(exported, RenderSettings(seed=seed, preset=preset))
    return np.asarray(result.image, np.float64).reshape(h, w, 3)


def _lit_from_behind(mixed: bool):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    mat = _material("Leaf", "ShaderNodeBsdfTranslucent", (0.6, 0.8, 0.3))
    if mixed:
        tree = mat.node_tree
        translucent = tree.nodes["Translucent BSDF"]
        mix = tree.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = 0.5
        diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.3, 0.6, 0.2, 1.0)
        tree.links.new(diffuse.outputs[0], mix.inputs[1])
        tree.links.new(translucent.outputs[0], mix.inputs[2])
        tree.links.new(mix.outputs[0], tree.nodes["Material Output"].inputs[0])
    bpy.context.object.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.0, 0.0, 3.0))
    scene.camera = bpy.context.object
    _sun((math.pi - 0.5, 0.0, 0.0), 3.0)                 # from below, 0.5 rad off the axis
    if mixed:
        _sun((0.3, 0.2, 0.0), 2.0)                       # from above
    black_world(bpy, scene)
    return scene


@pytest.mark.parametrize("mixed", [False, True], ids=["translucent", "mix"])
def test_lit_from_behind_matches_cycles(mixed, tmp_path):
    scene = _lit_from_behind(mixed)
    ours = _lanterna(scene, 1, "preview").reshape(-1, 3).mean(axis=0)
    theirs = _cycles(scene, tmp_path, 64).reshape(-1, 3).mean(axis=0)
    assert np.allclose(ours, theirs, rtol=2e-3), (ours, theirs)
    if not mixed:
        exact = np.array([0.6, 0.8, 0.3]) / math.pi * 3.0 * math.cos(0.5)
        assert np.allclose(ours, exact, rtol=2e-3), (ours, exact)


def _sheet_over_floor(side_view: bool):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if side_view:
        scene.render.resolution_x, scene.render.resolution_y = 48, 32
    else:
        scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.context.object.data.materials.append(
        _material("Floor", "ShaderNodeBsdfDiffuse", (0.8, 0.8, 0.8)))
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.0, 0.0, 1.0))
    bpy.context.object.data.materials.append(
        _material("Sheet", "ShaderNodeBsdfTranslucent", (0.7, 0.5, 0.3)))
    if side_view:
        bpy.ops.object.camera_add(location=(3.2, -2.2, 0.9))
        camera = bpy.context.object
        d = np.array([0.0, 0.0, 0.45]) - np.array(camera.location)
        camera.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0.0,
                                 math.atan2(-d[0], d[1]))
    else:
        bpy.ops.object.camera_add(location=(0.0, 0.0, 0.9))
    scene.camera = bpy.context.object
    _sun((0.0, 0.0, 0.0), 3.0)
    black_world(bpy, scene)
    return scene


def _form_factor_term() -> float:
    """pi x the form factor from the floor's point under the centre of a 2 m square 1 m above
    it (a 400 x 400 midpoint sum of cos cos / r^2)."""
    g = (np.arange(400) + 0.5) / 400 * 2.0 - 1.0
    x, y = np.meshgrid(g, g)
    r2 = x * x + y * y + 1.0
    return float((1.0 / r2 ** 2).sum() * (2.0 / 400) ** 2)


def test_shade_under_a_translucent_sheet_is_lit_through_it():
    scene = _sheet_over_floor(side_view=False)
    image = _lanterna(scene, 1, "preview")
    ours = image[6:10, 6:10].reshape(-1, 3).mean(axis=0)
    exact = 0.8 / math.pi * np.array([0.7, 0.5, 0.3]) / math.pi * 3.0 * _form_factor_term()
    assert np.all(np.abs(ours / exact - 1.0) < SHADE_BOUND), (ours, exact)


def test_side_view_matches_cycles(tmp_path):
    scene = _sheet_over_floor(side_view=True)
    ours = _lanterna(scene, 1, "final") @ LUMINANCE
    theirs = _cycles(scene, tmp_path, 2048) @ LUMINANCE

    def regions(a):
        return a.reshape(4, 8, 4, 12).mean(axis=(1, 3))

    ours, theirs = regions(ours), regions(theirs)
    bright = theirs > 0.1 * theirs.max()
    assert np.abs(ours[bright] / theirs[bright] - 1.0).max() < SIDE_BOUND, ours / theirs
