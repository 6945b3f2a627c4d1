"""Light Path in materials (issue 24): camera rays meet one material, every other ray
(photons, gather rays, cache records, light samples of emitters, reflections) another, and a
camera path's refractions read their own flags, as in Cycles.

Four scenes over a grey Diffuse floor with a box, a black world, rendered at ``final``'s
settings (64 samples a pixel) against inline Cycles (1024 spp, 64 bounces), compared per
4 x 4 region (regions over a twentieth of the brightest):

* ``hidden_panel``: the only light is a 1.5 m panel 1.6 m up, facing down, whose material is
  Mix(Emission strength 8, Transparent, Fac = Is Camera Ray): it lights the room and the
  camera sees through it (the classic "invisible light" set-up);
* ``two_faced_wall``: an area light, and a back wall whose Diffuse Color is Mix colour(green,
  red, Fac = Is Camera Ray): the camera sees it red, the floor and box are lit by its green;
* ``mirror_view`` / ``glass_view``: an area light, a second box whose Diffuse Color is Mix
  colour(red, green, Fac = Is Glossy Ray / Is Transmission Ray), and a sharp mirror wall
  (Glossy, Roughness 0) behind both boxes / a smooth glass slab (IOR 1.5) in front of its
  lower half: red seen straight and to diffuse bounces, green in the mirror / through the
  glass. Their Cycles renders are unbiased as the stored references are (Filter Glossy 0, no
  clamping): with Cycles' default Filter Glossy 1 the light the mirror throws onto the floor
  comes out 1-11 % under in Cycles, and the light through the slab up to 17 %.

``hidden_objects`` is ``hidden_panel`` made the way people make it: a plain Emission panel
and a red box with the objects' Visibility > Camera off (``export.hidden_from_camera``).

Measured, worst region's luminance at seeds 1-3: hidden_objects 0.52 / 0.39 / 0.62 % (with
the flag ignored 372 %), hidden_panel 0.57 / 0.35 / 0.46 %,
two_faced_wall 0.82 / 0.53 / 0.56 % (bound 2.5 %). Before (every hit read as a camera ray's):
the panel lit nothing (the whole image black: 100 %), the wall bled red onto the floor (6.9 %,
seed 1). The worst region's red / green ratio (the box's colour as each ray sees it):
mirror_view 1.57 / 1.40 / 1.56 %, glass_view 0.75 / 0.70 / 0.79 % (bound 2.5 %); with
every ray after the first hit read as a camera ray's 215 % and 277 % (seed 1). (Their
luminance: mirror_view 1.9-2.8 %, glass_view 0.6-0.9 %.)
"""
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from inline_cycles import (add_area_light, add_camera, cycles_image, empty_scene,  # noqa: E402
                           lanterna_image, node_material, regions)

CASES = ("hidden_panel", "two_faced_wall", "mirror_view", "glass_view", "hidden_objects")
# The outputs the box's colour follows in the last two: seen straight (and by diffuse
# bounces) it is red; in the mirror (a glossy, singular reflection) or through the glass slab
# (a transmission) green.
PATH_OUTPUT = {"mirror_view": "Is Glossy Ray", "glass_view": "Is Transmission Ray"}
CYCLES_SAMPLES = 1024
SAMPLES = 64
BOUND = 0.025
CHROMA_BOUND = 0.025


def _diffuse(name: str, colour):
    mat, tree, out = node_material(bpy, name)
    node = tree.nodes.new("ShaderNodeBsdfDiffuse")
    node.inputs["Color"].default_value = (*colour, 1.0)
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def _hidden_panel_material():
    mat, tree, out = node_material(bpy, "Hidden panel")
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 8.0
    clear = tree.nodes.new("ShaderNodeBsdfTransparent")
    path = tree.nodes.new("ShaderNodeLightPath")
    mix = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    tree.links.new(emission.outputs[0], mix.inputs[1])
    tree.links.new(clear.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    return mat


def _two_faced_material():
    mat, tree, out = node_material(bpy, "Two-faced")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    path = tree.nodes.new("ShaderNodeLightPath")
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["A"].default_value = (0.1, 0.7, 0.1, 1.0)       # what light meets
    mix.inputs["B"].default_value = (0.8, 0.1, 0.1, 1.0)       # what the camera sees
    tree.links.new(path.outputs["Is Camera Ray"], mix.inputs["Factor"])
    tree.links.new(mix.outputs["Result"], diffuse.inputs["Color"])
    tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    return mat


def _path_box_material(output: str):
    """A Diffuse box red to camera rays and diffuse bounces, green where ``output`` is 1."""
    mat, tree, out = node_material(bpy, "Box")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    path = tree.nodes.new("ShaderNodeLightPath")
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["A"].default_value = (0.8, 0.1, 0.1, 1.0)
    mix.inputs["B"].default_value = (0.1, 0.7, 0.1, 1.0)
    tree.links.new(path.outputs[output], mix.inputs["Factor"])
    tree.links.new(mix.outputs["Result"], diffuse.inputs["Color"])
    tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    return mat


def _pane_material(kind: str):
    """A sharp mirror (Glossy, Roughness 0, Color 0.9) or smooth glass (IOR 1.5)."""
    mat, tree, out = node_material(bpy, "Pane")
    if kind == "mirror_view":
        node = tree.nodes.new("ShaderNodeBsdfGlossy")
        node.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1.0)
    else:
        node = tree.nodes.new("ShaderNodeBsdfGlass")
        node.inputs["IOR"].default_value = 1.5
    node.inputs["Roughness"].default_value = 0.0
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def _scene(kind: str):
    scene = empty_scene(bpy)
    add_camera(bpy, scene, (0.0, -4.0, 2.5), (math.radians(62), 0.0, 0.0))
    grey = _diffuse("Grey", (0.8, 0.8, 0.8))
    bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, 0))
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0.8, 0.5, 0.5))
    bpy.context.object.data.materials.append(grey)
    if kind in PATH_OUTPUT:
        add_area_light(bpy, scene, 300.0, 1.0, (-0.5, -0.5, 2.5), (0.0, 0.0, 0.0))
        bpy.ops.mesh.primitive_cube_add(size=0.8, location=(-0.9, -0.2, 0.4))
        bpy.context.object.data.materials.append(_path_box_material(PATH_OUTPUT[kind]))
        if kind == "mirror_view":       # a mirror wall behind both boxes
            bpy.ops.mesh.primitive_plane_add(size=3, location=(-0.3, 1.6, 1.5),
                                             rotation=(math.radians(90), 0, 0))
        else:                           # a glass slab in front of the box's lower half
            bpy.ops.mesh.primitive_cube_add(size=1, location=(-0.9, -1.2, 0.6))
            bpy.context.object.scale = (0.6, 0.05, 0.6)
        bpy.context.object.data.materials.append(_pane_material(kind))
    elif kind == "hidden_panel":
        bpy.ops.mesh.primitive_plane_add(size=1.5, location=(0, 0, 1.6), rotation=(math.pi, 0, 0))
        bpy.context.object.data.materials.append(_hidden_panel_material())
    elif kind == "hidden_objects":
        # The same panel, a plain Emission, and a second box, both with Visibility > Camera
        # off: the camera sees the light and the box's shadow but neither object.
        bpy.ops.mesh.primitive_plane_add(size=1.5, location=(0, 0, 1.6), rotation=(math.pi, 0, 0))
        panel = bpy.context.object
        mat, tree, out = node_material(bpy, "Panel")
        emission = tree.nodes.new("ShaderNodeEmission")
        emission.inputs["Strength"].default_value = 8.0
        tree.links.new(emission.outputs[0], out.inputs["Surface"])
        panel.data.materials.append(mat)
        bpy.ops.mesh.primitive_cube_add(size=0.8, location=(-0.9, -0.2, 0.4))
        box = bpy.context.object
        box.data.materials.append(_diffuse("Red", (0.8, 0.1, 0.1)))
        panel.visible_camera = box.visible_camera = False
    else:
        add_area_light(bpy, scene, 300.0, 1.0, (-0.5, -0.5, 2.5), (0.0, 0.0, 0.0))
        bpy.ops.mesh.primitive_plane_add(size=3, location=(-0.3, 1.6, 1.5),
                                         rotation=(math.radians(90), 0, 0))
        bpy.context.object.data.materials.append(_two_faced_material())
    return scene


def worst_region_error(kind: str, tmp_path, seed: int = 1) -> float:
    scene = _scene(kind)
    _, ours = lanterna_image(bpy, seed, SAMPLES)
    theirs = cycles_image(bpy, scene, tmp_path, CYCLES_SAMPLES, unbiased=kind in PATH_OUTPUT)
    a, b = regions(ours, luminance=True), regions(theirs, luminance=True)
    bright = b > 0.05 * b.max()
    return float(np.abs(a[bright] / b[bright] - 1).max())


def worst_chroma_error(kind: str, tmp_path, seed: int = 1) -> float:
    """The largest |ours / Cycles - 1| of the 4 x 4 regions' red / green ratio (regions over
    a twentieth of the brightest): the box's colour as each kind of ray sees it."""
    scene = _scene(kind)
    _, ours = lanterna_image(bpy, seed, SAMPLES)
    theirs = cycles_image(bpy, scene, tmp_path, CYCLES_SAMPLES, unbiased=True)
    a, b = regions(ours), regions(theirs)
    bright = regions(theirs, luminance=True) > 0.05 * regions(theirs, luminance=True).max()
    ratio = (a[..., 0] / a[..., 1]) / (b[..., 0] / b[..., 1])
    return float(np.abs(ratio[bright] - 1).max())


@pytest.mark.parity      # whole renders against Cycles: make test-parity
@pytest.mark.parametrize("kind", CASES[:2] + CASES[4:])
def test_is_camera_ray_tells_camera_rays_apart(kind, tmp_path):
    assert worst_region_error(kind, tmp_path) <= BOUND


@pytest.mark.parity
@pytest.mark.parametrize("kind", list(PATH_OUTPUT))
def test_reflections_and_refractions_read_their_rays(kind, tmp_path):
    assert worst_chroma_error(kind, tmp_path) <= CHROMA_BOUND


def test_light_path_reads_each_rays_values():
    """Export names nothing for the outputs Lanterna follows (Is Diffuse Ray here); a hit
    reads the camera's colour for a camera ray, the lighting colour for a diffuse bounce's
    ray (gather rays, photons: ``textures.DIFFUSE_RAY``), and Is Shadow Ray is named."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.surfaces import SceneSurfaces
    from lanterna.engine.textures import DIFFUSE_RAY

    _scene("two_faced_wall")
    tree = bpy.data.materials["Two-faced"].node_tree
    path = next(n for n in tree.nodes if n.type == "LIGHT_PATH")
    mix = next(n for n in tree.nodes if n.type == "MIX")
    mix.inputs["A"].default_value = (0.8, 0.1, 0.1, 1.0)       # Is Diffuse Ray 0
    mix.inputs["B"].default_value = (0.1, 0.7, 0.1, 1.0)       # Is Diffuse Ray 1
    tree.links.new(path.outputs["Is Diffuse Ray"], mix.inputs["Factor"])
    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    assert not any("Light Path" in w for w in exported.warnings), exported.warnings
    surfaces = SceneSurfaces(exported)
    wall = next(i for i, m in enumerate(exported.materials) if m.name == "Two-faced")
    prim = np.flatnonzero(exported.material_ids == wall)[:4]
    half = np.full(len(prim), 0.3)
    seen = surfaces.params(prim, half, half, camera=True).diffuse
    lit = surfaces.params(prim, half, half, ray=DIFFUSE_RAY).diffuse
    np.testing.assert_allclose(seen, np.tile([0.8, 0.1, 0.1], (len(prim), 1)), atol=1e-6)
    np.testing.assert_allclose(lit, np.tile([0.1, 0.7, 0.1], (len(prim), 1)), atol=1e-6)
    tree.links.new(path.outputs["Is Shadow Ray"], mix.inputs["Factor"])
    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    named = [w for w in exported.warnings if "Light Path" in w]
    assert len(named) == 1 and "Material 'Two-faced'" in named[0] \
        and "Is Shadow Ray reads 0" in named[0], named


def test_rays_after_a_bounce_carry_cycles_flags_and_depths():
    """A diffuse bounce's ray (a gather ray), then a mirror reflection, a refraction and a
    transparent pass (straight on): the flags of the last bounce, the depths counted per kind
    (``textures.ray_after_bounce``)."""
    from lanterna.engine.textures import DIFFUSE_RAY, ray_after_bounce

    n = np.array([[0.0, 0.0, 1.0]])
    down = np.array([[0.0, 0.6, -0.8]])
    up = np.array([[0.0, 0.6, 0.8]])

    def values(ray):
        return {k: float(np.asarray(v).reshape(-1)[0]) for k, v in ray.items()}

    mirrored = ray_after_bounce(DIFFUSE_RAY, up, down, n, np.array([True]))
    assert values(mirrored) == {
        "Is Diffuse Ray": 0, "Is Glossy Ray": 1, "Is Singular Ray": 1,
        "Is Reflection Ray": 1, "Is Transmission Ray": 0, "Ray Depth": 2,
        "Diffuse Depth": 1, "Glossy Depth": 1, "Transmission Depth": 0,
        "Transparent Depth": 0}
    refracted = ray_after_bounce(mirrored, np.array([[0.0, 0.3, -0.95]]), down, n,
                                 np.array([False]))
    assert values(refracted) == {
        "Is Diffuse Ray": 0, "Is Glossy Ray": 1, "Is Singular Ray": 0,
        "Is Reflection Ray": 0, "Is Transmission Ray": 1, "Ray Depth": 3,
        "Diffuse Depth": 1, "Glossy Depth": 1, "Transmission Depth": 1,
        "Transparent Depth": 0}
    passed = ray_after_bounce(refracted, down, down, n, np.array([True]))
    assert values(passed) == {**values(refracted), "Transparent Depth": 1}
    # From a camera ray (no values: all 0) a mirror gives Ray Depth 1.
    assert values(ray_after_bounce(None, up, down, n, np.array([True])))["Ray Depth"] == 1


def test_light_path_with_view_nodes_in_one_material():
    """A Fac that reads Light Path and Fresnel together: the surface means (made for camera
    rays too) hand the Fresnel its view along the normal, and camera hits and other hits
    mix differently (before: the camera means asked for a view they were not given)."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.surfaces import SceneSurfaces

    _scene("two_faced_wall")
    tree = bpy.data.materials["Two-faced"].node_tree
    path = next(n for n in tree.nodes if n.type == "LIGHT_PATH")
    mix = next(n for n in tree.nodes if n.type == "MIX")
    fresnel = tree.nodes.new("ShaderNodeFresnel")
    times = tree.nodes.new("ShaderNodeMath")
    times.operation = "MULTIPLY"
    tree.links.new(path.outputs["Is Camera Ray"], times.inputs[0])
    tree.links.new(fresnel.outputs["Fac"], times.inputs[1])
    tree.links.new(times.outputs["Value"], mix.inputs["Factor"])
    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    surfaces = SceneSurfaces(exported)
    wall = next(i for i, m in enumerate(exported.materials) if m.name == "Two-faced")
    prim = np.flatnonzero(exported.material_ids == wall)[:2]
    half = np.full(len(prim), 0.3)
    down = np.tile([0.0, 1.0, 0.0], (len(prim), 1))          # head-on into the wall
    seen = surfaces.params(prim, half, half, down, camera=True).diffuse
    lit = surfaces.params(prim, half, half, down).diffuse
    np.testing.assert_allclose(lit, np.tile([0.1, 0.7, 0.1], (len(prim), 1)), atol=1e-6)
    assert np.all(seen[:, 0] > lit[:, 0]) and np.all(seen[:, 1] < lit[:, 1])


def test_an_object_hidden_from_the_camera_is_its_material_mixed_by_is_camera_ray():
    """Visibility > Camera off (``export.hidden_from_camera``) renders as Cycles renders
    Mix(material, Transparent, Is Camera Ray), the set-up ``hidden_panel`` checks against
    Cycles: the two scenes give the same picture, sample for sample; with the panel seen (the
    flag on) the picture differs; the hidden box's material lights the floor red (its
    Diffuse colour reaches gather rays) yet the camera never sees red on it."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render
    from lanterna.engine.surfaces import SceneSurfaces
    from lanterna.engine.textures import DIFFUSE_RAY

    settings = RenderSettings(samples=4, light_samples=2, photons=20_000, gather_m=4,
                              gather_n=8, seed=3)

    def picture():
        return np.asarray(render(export_scene(bpy.context.evaluated_depsgraph_get()),
                                 settings).image)

    _scene("hidden_panel")
    mixed = picture()
    panel = bpy.data.objects["Plane.001"]
    mat, tree, out = node_material(bpy, "Plain panel")
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 8.0
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    panel.data.materials[0] = mat
    panel.visible_camera = False
    assert np.array_equal(picture(), mixed)
    panel.visible_camera = True
    assert not np.allclose(picture(), mixed)
    _scene("hidden_objects")
    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    red = next(i for i, m in enumerate(exported.materials) if m.name == "Red")
    assert sum(m.name == "Red" for m in exported.materials) == 1     # only the variant
    prim = np.flatnonzero(exported.material_ids == red)[:4]
    assert len(prim) and exported.materials[red].closures[-1].kind == "transparent"
    surfaces = SceneSurfaces(exported)
    half = np.full(len(prim), 0.3)
    seen = surfaces.params(prim, half, half, camera=True)
    lit = surfaces.params(prim, half, half, ray=DIFFUSE_RAY)
    np.testing.assert_allclose(seen.diffuse, 0.0, atol=1e-12)
    np.testing.assert_allclose(lit.diffuse, np.tile([0.8, 0.1, 0.1], (len(prim), 1)), atol=1e-6)
