"""A world seen in one colour and lighting in another (issue 24): Light Path Is Camera Ray.

A Blender user makes the background the camera sees differ from the light the world gives by
mixing on Light Path's Is Camera Ray, a Mix Shader of two Backgrounds or a Mix colour node in
front of one. Cycles evaluates the world for camera rays with Is Camera Ray 1, and with 0
for light samples, reflections and bounces; rays that go straight through a Transparent BSDF
stay camera rays. Before, Lanterna read the mix at its Fac's default 0.5 (a warning), so both
the seen sky and the light were the average of the two.

The scene: a large white Diffuse floor, a mirror ball (Glossy, roughness 0) that reflects the
lighting world, and a Transparent BSDF card of colour 0.9 in front of the sky, through which
the camera still sees the camera world. Three worlds:

* ``flat``: Mix Shader(Is Camera Ray; Background orange lights, Background blue is seen);
* ``image lights``: Background <- Mix colour(Is Camera Ray; Environment Texture, grey 0.5):
  an image lights the scene (with a small bright patch), the camera sees grey;
* ``image seen``: Mix Shader(Is Camera Ray; Background orange, Background <- Environment
  Texture): the camera sees the image, orange lights.

Each renders at ``final`` against inline Cycles (``tests/inline_cycles.py``, 2048 spp) and is
compared per 4 x 4 region and channel. Measured at seeds 1-3 (worst region and channel):
see ``BOUND``. Without ``World.camera`` the seen sky is off by 30-60 % in every case.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from inline_cycles import add_camera, cycles_image, lanterna_image, node_material, regions  # noqa: E402,E501

WORLDS = ("flat", "image lights", "image seen")
LIT = (1.0, 0.5, 0.2)         # the lighting Background's colour where it is flat
SEEN = (0.1, 0.2, 0.9)        # the seen Background's colour (``flat``)
GREY = (0.5, 0.5, 0.5)        # what the camera sees in ``image lights``
CARD = 0.9                    # the Transparent card's colour
CYCLES_SAMPLES = 2048
BOUND = 0.025                 # worst region and channel, relative (measured 0.7-1.4 %)


def _sky_image():
    """A small float equirectangular sky: a vertical gradient and a bright warm patch."""
    w, h = 64, 32
    v, u = np.mgrid[0:h, 0:w]
    elevation = (v + 0.5) / h * np.pi - np.pi / 2          # row 0 at the bottom
    phi = (u + 0.5) / w * 2 * np.pi
    up = np.sin(elevation)
    patch = np.exp(-((phi - 2.0) ** 2 + (elevation - 0.6) ** 2) / 0.08)
    rgb = np.stack([0.3 + 0.2 * up + 4 * patch, 0.4 + 0.2 * up + 3 * patch,
                    0.6 + 0.3 * up + patch], -1)
    image = bpy.data.images.new("Sky", w, h, float_buffer=True)
    image.pixels.foreach_set(np.concatenate([rgb, np.ones((h, w, 1))], -1)
                             .astype(np.float32).ravel())
    image.pack()
    return image


def _background(tree, colour):
    node = tree.nodes.new("ShaderNodeBackground")
    node.inputs["Color"].default_value = (*colour, 1.0)
    return node


def _world(kind: str):
    world = bpy.data.worlds.new("Seen and lit")
    if world.node_tree is None:
        world.use_nodes = True
    tree = world.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputWorld")
    is_camera = tree.nodes.new("ShaderNodeLightPath").outputs["Is Camera Ray"]
    if kind == "image lights":
        sky = tree.nodes.new("ShaderNodeTexEnvironment")
        sky.image = _sky_image()
        mix = tree.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        by_id = {s.identifier: s for s in mix.inputs}
        by_id["B_Color"].default_value = (*GREY, 1.0)
        tree.links.new(is_camera, by_id["Factor_Float"])
        tree.links.new(sky.outputs["Color"], by_id["A_Color"])
        background = _background(tree, (0.8, 0.8, 0.8))
        tree.links.new(mix.outputs[2], background.inputs["Color"])
        tree.links.new(background.outputs[0], out.inputs["Surface"])
        return world
    mix = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(is_camera, mix.inputs[0])
    tree.links.new(_background(tree, LIT).outputs[0], mix.inputs[1])
    seen = _background(tree, SEEN)
    if kind == "image seen":
        sky = tree.nodes.new("ShaderNodeTexEnvironment")
        sky.image = _sky_image()
        tree.links.new(sky.outputs["Color"], seen.inputs["Color"])
    tree.links.new(seen.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    return world


def _surface(name, kind, colour, **inputs):
    mat, tree, out = node_material(bpy, name)
    node = tree.nodes.new(kind)
    node.inputs["Color"].default_value = (*colour, 1.0)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    bpy.context.object.data.materials.append(mat)


def _scene(kind: str):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 48, 32
    bpy.ops.mesh.primitive_plane_add(size=200.0)
    _surface("Floor", "ShaderNodeBsdfDiffuse", (0.8, 0.8, 0.8))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(-1.2, 0.0, 2.2), segments=64,
                                         ring_count=32)
    bpy.ops.object.shade_smooth()
    _surface("Mirror", "ShaderNodeBsdfGlossy", (1.0, 1.0, 1.0), Roughness=0.0)
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(1.0, 0.0, 1.6),
                                     rotation=(np.pi / 2, 0.0, 0.0))
    _surface("Card", "ShaderNodeBsdfTransparent", (CARD,) * 3)
    add_camera(bpy, scene, (0.0, -6.0, 1.4), (np.pi / 2, 0.0, 0.0))
    scene.world = _world(kind)
    return scene


def worst_region_error(kind: str, tmp_path, seed: int = 1) -> float:
    """Worst relative difference of a 4 x 4 region's channel mean, ours against Cycles."""
    scene = _scene(kind)
    exported, ours = lanterna_image(bpy, seed)
    assert not any("World" in w for w in exported.warnings), exported.warnings
    assert exported.world.camera is not None
    cycles = cycles_image(bpy, scene, tmp_path, CYCLES_SAMPLES)
    return float(np.max(np.abs(regions(ours) / regions(cycles) - 1.0)))


@pytest.mark.parity      # whole renders against Cycles: make test-parity
@pytest.mark.parametrize("kind", WORLDS)
def test_world_seen_and_lit_apart_as_cycles(kind, tmp_path):
    assert worst_region_error(kind, tmp_path) <= BOUND


def test_the_camera_sees_its_own_world_and_the_mirror_the_other():
    """The exported Worlds: flat colours where flat, the camera's through the card."""
    _scene("flat")
    from lanterna.engine.blender.export import export_scene

    world = export_scene(bpy.context.evaluated_depsgraph_get()).world
    np.testing.assert_allclose(world.radiance, LIT)
    np.testing.assert_allclose(world.camera.radiance, SEEN)
    assert world.seen_by_camera is world.camera


def test_a_world_without_light_path_has_no_camera_world():
    _scene("flat")
    bpy.context.scene.world = bpy.data.worlds.new("Plain")
    from lanterna.engine.blender.export import export_scene

    assert export_scene(bpy.context.evaluated_depsgraph_get()).world.camera is None


def test_other_light_path_outputs_are_reported():
    _scene("flat")
    tree = bpy.context.scene.world.node_tree
    path = next(n for n in tree.nodes if n.type == "LIGHT_PATH")
    mix = next(n for n in tree.nodes if n.type == "MIX_SHADER")
    tree.links.new(path.outputs["Is Glossy Ray"], mix.inputs[0])
    from lanterna.engine.blender.export import export_scene

    warnings = export_scene(bpy.context.evaluated_depsgraph_get()).warnings
    assert any("Light Path Is Glossy Ray is read as 0" in w for w in warnings), warnings
