"""A Blender world's image environment: Environment Texture and Sky Texture worlds.

What it computes
    ``environment_of(world, warn)`` -> ``engine.environment.Environment`` or None. It reads
    the tree Cycles renders (World Output <- Background <- Environment Texture [<- Mapping
    <- Texture Coordinate Generated]) or a Sky Texture in place of the Environment Texture;
    the Background's Strength (a constant) scales the image. Anything else in that chain (a
    Math node on the colour, a Mix, an Object coordinate ...) returns None after a warning
    that names the world and the node: the exporter then keeps the flat colour
    (``export._export_world``). A Mix Shader or Mix colour node on the way whose factor is
    exactly 0 or 1 for the ray it is evaluated for passes that input on: a world mixed by
    Light Path Is Camera Ray is read twice, for camera rays (``CAMERA_RAY``) and for the
    rest (``LIGHTING_RAY``), and can be an image for one and a colour for the other.

    * Environment Texture: its image (packed or a file; float EXR/HDR held as float32, 8-bit
      as uint8 sRGB-encoded, decoded after each look-up as Cycles does), its projection
      (equirectangular, mirror ball) and interpolation. Each image is read once per image
      name and modification (``_IMAGES``, by name, file path, size and ``is_dirty``).
    * Mapping: its rotation (Euler XYZ, Cycles' ``euler_to_transform``) as the world ->
      texture rotation; Point, Vector and Normal use R, Texture R^T. A location (Point,
      Texture) or a non-uniform scale changes directions in a way a rotation cannot hold: it is
      reported and left out.
    * Sky Texture: Blender's own sky, baked by Cycles into an equirectangular float image of
      ``SKY_BAKE_SIZE`` (512 x 256) through a panoramic camera in a scratch scene whose world
      is the sky alone (strength 1), then used as an Environment Texture. Bakes are cached in
      memory and in the temporary folder by a hash of the sky node's settings.

Parameters: ``warn`` takes one message. Units: radiance W m^-2 sr^-1.
"""
from __future__ import annotations

import hashlib
import math
import os
import tempfile

import numpy as np

import bpy

from .. import nodes
from ..environment import Environment, euler_rotation
from .node_export import export_graph, image_pixels

# The Light Path values of the two kinds of ray a world is evaluated for (``nodes.evaluate``
# inputs): a camera ray (``nodes.LIGHT_PATH_CAMERA``), and every other ray (Is Camera Ray 0,
# the rest 0 too, as Cycles evaluates a world for its light samples).
CAMERA_RAY: dict = {}
LIGHTING_RAY = {"ray:Is Camera Ray": np.zeros(1)}
SKY_BAKE_SIZE = (512, 256)
SKY_BAKE_SAMPLES = 16
_IMAGES: dict = {}
_SKIES: dict = {}


def _source(socket):
    """(node, output) linked into ``socket`` through reroutes; None when not linked."""
    for _ in range(64):
        if socket is None or not socket.is_linked:
            return None
        link = socket.links[0]
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            return None
        node = link.from_node
        if node.type == "REROUTE":
            socket = node.inputs[0]
            continue
        return node, link.from_socket
    return None


def light_path_outputs(tree) -> set:
    """Names of the Light Path node outputs linked anywhere in ``tree``."""
    return {s.name for n in tree.nodes if n.type == "LIGHT_PATH" for s in n.outputs
            if s.is_linked}


def constant_for_ray(node, output, ray, graph_of):
    """What ``node``'s ``output`` evaluates to for a ray of Light Path values ``ray``: a
    float or an RGB (3,); None when its nodes need more than the ray (a coordinate) or are
    not supported."""
    try:
        v = nodes.evaluate(graph_of(), (node.name, output.identifier), dict(ray), n=1)
    except (nodes.UnsupportedNode, nodes.MissingInput, KeyError):
        return None
    return np.asarray(v, float)[0]


def _factor(socket, ray, graph_of):
    """A mix node's factor as one number for ``ray``: its own value, or what the nodes linked
    to it evaluate to (a colour by its luminance); None where they cannot be evaluated."""
    src = _source(socket)
    if src is None:
        return float(socket.default_value)
    v = constant_for_ray(*src, ray, graph_of)
    if v is None:
        return None
    return float(v @ nodes.LUMA if np.ndim(v) else v)


def _mix_choice(node, ray, graph_of):
    """The input a mix node passes on unchanged for ``ray``: a Mix Shader's or a Mix colour
    node's first input where its factor is exactly 0, its second where the factor is exactly
    1 and it blends by Mix (Light Path outputs are 0 or 1); None for other nodes and factors."""
    if node.type == "MIX_SHADER":
        fac, first, second, blend = node.inputs[0], node.inputs[1], node.inputs[2], "MIX"
    elif node.type == "MIX" and getattr(node, "data_type", "") == "RGBA" \
            and getattr(node, "factor_mode", "UNIFORM") == "UNIFORM":
        by_id = {s.identifier: s for s in node.inputs}
        fac, first, second = by_id.get("Factor_Float"), by_id.get("A_Color"), by_id.get("B_Color")
        blend = node.blend_type
    elif node.type == "MIX_RGB":
        fac, first, second = node.inputs.get("Fac"), node.inputs.get("Color1"), \
            node.inputs.get("Color2")
        blend = node.blend_type
    else:
        return None
    if fac is None or first is None or second is None:
        return None
    f = _factor(fac, ray, graph_of)
    if f == 0.0:
        return first
    if f == 1.0 and blend == "MIX":
        return second
    return None


def graph_maker(tree, warn):
    """A function that returns ``tree`` as a ``nodes.Graph``, read once when first asked."""
    graph = []

    def graph_of():
        if not graph:
            graph.append(export_graph(tree, warn))
        return graph[0]
    return graph_of


def decided_socket(socket, ray, graph_of):
    """The input socket whose value reaches ``socket`` once the mix nodes that ``ray``
    decides (``_mix_choice``) are passed through: ``socket`` itself, or a mix node's input
    (its own value when nothing is linked to it)."""
    for _ in range(64):
        src = _source(socket)
        choice = None if src is None else _mix_choice(src[0], ray, graph_of)
        if choice is None:
            return socket
        socket = choice
    return socket


def decided_source(socket, ray, graph_of):
    """(node, output) feeding ``socket`` once the mix nodes that ``ray`` decides are passed
    through (``decided_socket``); None when nothing feeds it."""
    return _source(decided_socket(socket, ray, graph_of))


def _output(tree):
    outs = [n for n in tree.nodes if n.type == "OUTPUT_WORLD"]
    for n in outs:
        if getattr(n, "is_active_output", False) and getattr(n, "target", "ALL") in ("ALL", "CYCLES"):
            return n
    return outs[0] if outs else None


def environment_of(world, warn, ray=LIGHTING_RAY):
    """The image environment of ``world`` (module docstring) for a ray of Light Path values
    ``ray`` (``CAMERA_RAY`` or ``LIGHTING_RAY``): mix nodes whose factor that ray decides (a
    Light Path output, or a constant 0 or 1) are passed through. None where the world is no
    image for that ray."""
    tree = getattr(world, "node_tree", None)
    if tree is None:
        return None
    graph_of = graph_maker(tree, warn)

    def follow(socket):
        return decided_source(socket, ray, graph_of)

    out = _output(tree)
    src = follow(out.inputs.get("Surface")) if out is not None else None
    if src is None or src[0].type != "BACKGROUND":
        return None
    background = src[0]
    colour = follow(background.inputs.get("Color"))
    if colour is None or colour[0].type not in ("TEX_ENVIRONMENT", "TEX_SKY"):
        return None
    tex = colour[0]
    who = f"World '{world.name}'"
    strength_socket = background.inputs.get("Strength")
    if _source(strength_socket) is not None:
        warn(f"{who}: Strength of '{background.name}' is driven by a "
             f"{_source(strength_socket)[0].bl_label} node; using its value "
             f"{float(strength_socket.default_value):g}")
    strength = float(strength_socket.default_value) if strength_socket is not None else 1.0
    rotation = _mapping_rotation(tex, who, warn)
    if rotation is None:
        return None
    if tex.type == "TEX_SKY":
        pixels = _sky_pixels(tex, who, warn)
        if pixels is None:
            return None
        return Environment(pixels, "linear", strength, rotation, "EQUIRECTANGULAR", "Linear",
                           name=world.name)
    image = tex.image
    if image is None:
        warn(f"{who}: Environment Texture '{tex.name}' has no image; the world is the flat "
             "colour")
        return None
    pixels, encoding = _image(image, warn)
    if pixels is None:
        return None
    projection = getattr(tex, "projection", "EQUIRECTANGULAR")
    if projection not in ("EQUIRECTANGULAR", "MIRROR_BALL"):
        warn(f"{who}: Environment Texture '{tex.name}' projection {projection} is not "
             "supported; read as equirectangular")
        projection = "EQUIRECTANGULAR"
    return Environment(pixels, encoding, strength, rotation, projection,
                       getattr(tex, "interpolation", "Linear"), name=world.name)


def _mapping_rotation(tex, who, warn):
    """World -> texture rotation (3, 3) from the texture's Vector input, or None after a
    warning when that input is something other than Mapping / Texture Coordinate Generated."""
    vec = _source(tex.inputs.get("Vector"))
    rotation = np.eye(3)
    if vec is None:
        return rotation
    node, socket = vec
    if node.type == "MAPPING":
        kind = getattr(node, "vector_type", "POINT")
        loc = np.array(node.inputs["Location"].default_value[:], float) \
            if "Location" in node.inputs else np.zeros(3)
        rot = np.array(node.inputs["Rotation"].default_value[:], float)
        scale = np.array(node.inputs["Scale"].default_value[:], float) \
            if "Scale" in node.inputs else np.ones(3)
        for name in ("Location", "Rotation", "Scale"):
            sock = node.inputs.get(name)
            if sock is not None and _source(sock) is not None:
                warn(f"{who}: {name} of Mapping '{node.name}' is linked; its own value is used")
        if kind in ("POINT", "TEXTURE") and np.any(loc != 0):
            warn(f"{who}: Mapping '{node.name}' Location {loc.tolist()} does not move a "
                 "direction the way Cycles' does with a far world; left out")
        if not (np.allclose(scale, scale[0]) and scale[0] > 0):
            warn(f"{who}: Mapping '{node.name}' non-uniform or negative scale "
                 f"{scale.tolist()} is left out")
        r = euler_rotation(rot)
        rotation = r.T if kind == "TEXTURE" else r
        inner = _source(node.inputs.get("Vector"))
        if inner is None:
            return rotation
        node, socket = inner
    if node.type == "TEX_COORD" and socket.name in ("Generated", "Normal", "Object"):
        return rotation
    warn(f"{who}: {node.bl_label} node '{node.name}' feeding the Environment Texture's vector "
         "is not supported; the world is the flat colour")
    return None


def _image(image, warn):
    """(pixels, encoding) of a bpy image, read once per image and modification."""
    key = (image.name, image.filepath, tuple(image.size), bool(image.is_dirty),
           getattr(image.packed_file, "size", 0) if image.packed_file else 0)
    if key not in _IMAGES:
        img = image_pixels(image, warn)
        if img is None:
            _IMAGES[key] = (None, "")
        elif img.encoding == "srgb":
            _IMAGES[key] = (np.round(np.clip(img.pixels[..., :3], 0, 1) * 255).astype(np.uint8),
                            "srgb")
        else:
            _IMAGES[key] = (np.ascontiguousarray(img.pixels[..., :3], np.float32), "linear")
    return _IMAGES[key]


def _sky_key(tex) -> str:
    h = hashlib.sha256()
    for prop in tex.bl_rna.properties:
        if prop.identifier in ("rna_type", "name", "label", "location", "width", "height",
                               "select", "dimensions", "parent", "color", "use_custom_color",
                               "show_options", "show_preview", "hide", "mute",
                               "show_texture", "internal_links", "inputs", "outputs",
                               "width_hidden", "bl_idname", "bl_label", "bl_description",
                               "bl_icon", "bl_static_type", "bl_width_default",
                               "bl_width_min", "bl_width_max", "bl_height_default",
                               "bl_height_min", "bl_height_max", "type", "texture_mapping",
                               "color_mapping", "location_absolute", "warning_propagation",
                               "color_tag"):
            continue
        try:
            value = getattr(tex, prop.identifier)
        except AttributeError:
            continue
        if hasattr(value, "__len__") and not isinstance(value, str):
            value = tuple(value)
        h.update(f"{prop.identifier}={value!r};".encode())
    for sock in tex.inputs:
        if hasattr(sock, "default_value"):
            v = sock.default_value
            h.update(f"{sock.identifier}={tuple(v) if hasattr(v, '__len__') else v!r};".encode())
    return h.hexdigest()[:24]


def _sky_pixels(tex, who, warn):
    """Cycles' render of the Sky Texture alone as an equirectangular (H, W, 3) float32."""
    key = _sky_key(tex)
    if key in _SKIES:
        return _SKIES[key]
    path = os.path.join(tempfile.gettempdir(), "lanterna_sky", key + ".npy")
    if os.path.exists(path):
        try:
            _SKIES[key] = np.load(path)
            return _SKIES[key]
        except (OSError, ValueError):
            pass
    try:
        pixels = _bake_sky(tex)
    except Exception as exc:            # a bake that fails leaves the flat colour
        warn(f"{who}: the Sky Texture '{tex.name}' could not be baked ({exc}); the world is "
             "the flat colour")
        return None
    _SKIES[key] = pixels
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        np.save(path, pixels)
    except OSError:
        pass
    return pixels


def bake_world(world, size=SKY_BAKE_SIZE, samples=SKY_BAKE_SAMPLES) -> np.ndarray:
    """Cycles' render of ``world`` (its own node tree) through an equirectangular panoramic
    camera at the origin: (H, W, 3) float32, row 0 at the bottom, in the Environment
    Texture's convention (column u: azimuth 1/2 - atan2(y, x) / 2 pi)."""
    scene = bpy.data.scenes.new("lanterna_world_bake")
    cam_data = bpy.data.cameras.new("lanterna_world_bake")
    cam = bpy.data.objects.new("lanterna_world_bake", cam_data)
    out = os.path.join(tempfile.mkdtemp(prefix="lanterna_bake_"), "world.exr")
    try:
        scene.collection.objects.link(cam)
        scene.camera = cam
        cam_data.type = "PANO"
        if hasattr(cam_data, "panorama_type"):
            cam_data.panorama_type = "EQUIRECTANGULAR"
        else:
            cam_data.cycles.panorama_type = "EQUIRECTANGULAR"
        # Cycles' panoramic camera looks along its local -Z with +X as u's centre; turned so
        # that its image is the Environment Texture's (u = 0.5 at +X, up is +Z).
        cam.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
        scene.world = world
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = samples
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.use_denoising = False
        scene.render.resolution_x, scene.render.resolution_y = size
        scene.render.resolution_percentage = 100
        if hasattr(scene.render, "filter_size"):
            scene.render.filter_size = 0.01      # no pixel filter: texel-sharp
        else:
            scene.cycles.filter_width = 0.01
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = out
        _render(scene)
        img = bpy.data.images.load(out)
        try:
            w, h = img.size
            px = np.empty(w * h * img.channels, np.float32)
            img.pixels.foreach_get(px)
            px = px.reshape(h, w, img.channels)[..., :3].copy()
        finally:
            bpy.data.images.remove(img)
        return px
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(scene)
        try:
            os.remove(out)
            os.rmdir(os.path.dirname(out))
        except OSError:
            pass


def _render(scene):
    """Render ``scene`` to its file path (Cycles, in the foreground)."""
    with bpy.context.temp_override(scene=scene):
        bpy.ops.render.render(write_still=True, scene=scene.name)


def _bake_sky(tex) -> np.ndarray:
    """The Sky Texture node ``tex`` alone (Background strength 1) baked by ``bake_world``."""
    world = bpy.data.worlds.new("lanterna_sky_bake")
    try:
        tree = world.node_tree if world.node_tree is not None else None
        if tree is None:
            world.use_nodes = True
            tree = world.node_tree
        tree.nodes.clear()
        sky = tree.nodes.new("ShaderNodeTexSky")
        for prop in tex.bl_rna.properties:
            if prop.is_readonly or prop.identifier in ("name", "label", "location", "width",
                                                       "height", "select", "parent", "color",
                                                       "hide", "mute", "show_options",
                                                       "show_preview", "show_texture",
                                                       "use_custom_color", "location_absolute",
                                                       "color_tag"):
                continue
            try:
                setattr(sky, prop.identifier, getattr(tex, prop.identifier))
            except (AttributeError, TypeError, ValueError):
                pass
        for sock in tex.inputs:
            if hasattr(sock, "default_value") and sock.identifier in sky.inputs:
                sky.inputs[sock.identifier].default_value = sock.default_value
        bg = tree.nodes.new("ShaderNodeBackground")
        bg.inputs["Strength"].default_value = 1.0
        out = tree.nodes.new("ShaderNodeOutputWorld")
        tree.links.new(sky.outputs["Color"], bg.inputs["Color"])
        tree.links.new(bg.outputs["Background"], out.inputs["Surface"])
        return bake_world(world)
    finally:
        bpy.data.worlds.remove(world)
