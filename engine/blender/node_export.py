"""A Blender material's node tree as ``engine.nodes.Graph``: nodes, links, defaults, images.

What it computes
----------------
:func:`export_graph` reads every node of a ``bpy.types.NodeTree`` into a plain
``nodes.Node`` (bl_idname, name, the properties the evaluator uses, each input socket's type and
``default_value``, each output's type) and every enabled link into ``Graph.links``, keyed by
socket *identifiers* (Math's three inputs are "Value", "Value_001", "Value_002"). A Value or RGB
node's constant is read from its output socket; a Color Ramp's stops from ``color_ramp``.
Muted nodes and links are not followed through (the evaluator sees them as absent).

Images (:func:`image_pixels`): ``Image.pixels.foreach_get`` into a preallocated float32
(H, W, 4) array, row 0 at the bottom. What Blender 5.2 hands back, measured: for an 8-bit image
the bytes / 255 as stored, *not* converted to linear whatever its colour space (an sRGB byte of
128 reads 0.50196); for a float image the float buffer, which Blender holds in scene linear. So
an 8-bit image tagged "sRGB" is exported with encoding "srgb" (the evaluator interpolates the
encoded values and converts afterwards, as Cycles does with its byte textures); "Non-Color"
and the linear spaces as "linear"; any other colour space on a byte image is reported through
``warn`` and read as sRGB. An 8-bit image is then held as its bytes (uint8, 4 B a texel), a
float image as float16 where that is lossless and float32 otherwise (``nodes.stored_pixels``);
the float32 read is let go once the image is made. Packed and file images read the same way
(``pixels`` loads them). A UDIM (tiled) image becomes a ``nodes.TiledImage``: each tile is
read from its packed data or from its file (the ``<UDIM>`` / ``<UVTILE>`` token replaced),
through a temporary image of the same colour space, since ``Image.pixels`` gives only the
first tile. Sequences and movies are reported and left out (the Image Texture node then gives
Cycles' missing-image magenta).

Parameters: ``warn`` (callable taking one message; default: ignore), ``images`` (a dict cache
name -> ``nodes.Image``, shared between materials so each image is read once).
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

from .. import nodes as N

__all__ = ["export_graph", "image_pixels", "output_socket", "curve_table"]

# bl_idname -> properties read as they are (enums as their identifier strings, bools, numbers)
_PROPS = {
    "ShaderNodeMath": ("operation", "use_clamp"),
    "ShaderNodeVectorMath": ("operation",),
    "ShaderNodeMapRange": ("data_type", "interpolation_type", "clamp"),
    "ShaderNodeClamp": ("clamp_type",),
    "ShaderNodeMix": ("data_type", "factor_mode", "blend_type", "clamp_factor", "clamp_result"),
    "ShaderNodeMixRGB": ("blend_type", "use_clamp"),
    "ShaderNodeSeparateColor": ("mode",),
    "ShaderNodeCombineColor": ("mode",),
    "ShaderNodeTexGradient": ("gradient_type",),
    "ShaderNodeUVMap": ("uv_map",),
    "ShaderNodeVertexColor": ("layer_name",),
    "ShaderNodeMapping": ("vector_type",),
    "ShaderNodeTexImage": ("interpolation", "projection", "extension"),
    "ShaderNodeTexNoise": ("noise_dimensions", "noise_type", "normalize"),
    "ShaderNodeTexVoronoi": ("voronoi_dimensions", "feature", "distance", "normalize"),
    "ShaderNodeTexWave": ("wave_type", "bands_direction", "rings_direction", "wave_profile"),
    "ShaderNodeAttribute": ("attribute_type", "attribute_name"),
    "ShaderNodeNormalMap": ("space", "uv_map", "convention", "base"),
    "ShaderNodeBump": ("invert",),
}
_CURVES = {"ShaderNodeRGBCurve": 4, "ShaderNodeVectorCurve": 3, "ShaderNodeFloatCurve": 1}
_CURVE_TABLE = 256                     # Cycles' RAMP_TABLE_SIZE: the table has 257 entries
_COLOUR_SPACES_LINEAR = ("Non-Color", "Linear Rec.709", "Linear CIE-XYZ E", "Linear Rec.2020",
                         "Linear CIE-XYZ D65", "Linear FilmLight E-Gamut", "ACEScg",
                         "ACES2065-1")


def _value(v):
    if hasattr(v, "__len__") and not isinstance(v, str):
        return [float(x) for x in v]
    if isinstance(v, bool):
        return v
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def image_pixels(image, warn=lambda m: None):
    """``nodes.Image`` for a bpy image (``nodes.TiledImage`` for a UDIM image), or None
    (reported) when it cannot be read."""
    if image.source == "TILED":
        return _tiled_image(image, warn)
    if image.source in ("SEQUENCE", "MOVIE"):
        warn(f"image '{image.name}': {image.source.lower()} images are not supported yet")
        return None
    w, h = image.size
    if w == 0 or h == 0:
        warn(f"image '{image.name}' has no pixels (missing file?)")
        return None
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, image.channels)
    if image.channels != 4:
        full = np.ones((h, w, 4), np.float32)
        full[..., :min(3, image.channels)] = px[..., :3]
        if image.channels == 1:
            full[..., 1] = full[..., 2] = px[..., 0]
        px = full
    space = image.colorspace_settings.name
    if image.is_float:
        encoding = "linear"
    elif space == "sRGB":
        encoding = "srgb"
    elif space in _COLOUR_SPACES_LINEAR:
        encoding = "linear"
    else:
        warn(f"image '{image.name}': colour space '{space}' read as sRGB")
        encoding = "srgb"
    if not image.is_float:            # the bytes Blender holds: bytes / 255 -> bytes
        px = np.round(px * np.float32(255.0)).clip(0, 255).astype(np.uint8)
    return N.Image(px, encoding)


def curve_table(mapping, n_curves: int) -> dict:
    """A curve node's table as Cycles builds it when it syncs the node (blender/util.h,
    curvemapping_color_to_array / curvemapping_float_to_array): ``min_x``/``max_x`` the
    smallest first and largest last point x over the curves used (R, G, B and the combined C
    for RGB Curves; X, Y, Z for Vector Curves; the one curve of Float Curve), and 257 entries
    at x = min_x + i / 256 (max_x - min_x), each Blender's own curve evaluation
    (``CurveMapping.evaluate``: handles, clipping, extension): R(C(x)), G(C(x)), B(C(x)) for
    RGB Curves, X(x), Y(x), Z(x) for Vector Curves. ``extrapolate`` is the Extend mode."""
    curves = list(mapping.curves)[:n_curves]
    lo = min(float(c.points[0].location[0]) for c in curves)
    hi = max(float(c.points[-1].location[0]) for c in curves)
    mapping.update()
    if hasattr(mapping, "initialize"):
        mapping.initialize()
    xs = (np.float32(lo) + np.arange(_CURVE_TABLE + 1, dtype=np.float32)
          / np.float32(_CURVE_TABLE) * (np.float32(hi) - np.float32(lo)))
    ev = mapping.evaluate
    if n_curves == 1:
        table = [float(ev(curves[0], float(x))) for x in xs]
    elif n_curves == 4:
        table = [[float(ev(c, ev(curves[3], float(x)))) for c in curves[:3]] for x in xs]
    else:
        table = [[float(ev(c, float(x))) for c in curves] for x in xs]
    return {"table": table, "min_x": lo, "max_x": hi,
            "extrapolate": mapping.extend == "EXTRAPOLATED"}


def _tile_path(path: str, number: int) -> str:
    """A UDIM tile's file: Blender's ``<UDIM>`` (1001 ...) or ``<UVTILE>`` (u1_v1 ...) token
    replaced by the tile's number."""
    u, v = (number - 1001) % 10, (number - 1001) // 10
    return path.replace("<UDIM>", str(number)).replace("<UVTILE>", f"u{u + 1}_v{v + 1}")


def _tiled_image(image, warn):
    """``nodes.TiledImage`` of a UDIM image: each tile read from its packed data or its file
    (Blender's ``Image.pixels`` gives the first tile only), loaded as a temporary image with
    the UDIM image's colour space and alpha mode and read as any image; a tile that cannot be
    read is reported and left out (Cycles' missing-image colour there)."""
    import bpy

    packed = {int(getattr(p, "tile_number", 0)): p for p in getattr(image, "packed_files", ())}
    path = bpy.path.abspath(image.filepath_raw or image.filepath, library=image.library)
    tiles = {}
    for tile in image.tiles:
        number = int(tile.number)
        source, temporary = None, None
        if number in packed and packed[number].packed_file is not None:
            suffix = os.path.splitext(packed[number].filepath)[1] or ".png"
            handle, temporary = tempfile.mkstemp(suffix=suffix)
            with os.fdopen(handle, "wb") as out:
                out.write(packed[number].packed_file.data)
            source = temporary
        elif path:
            candidate = _tile_path(path, number)
            if os.path.isfile(candidate):
                source = candidate
        if source is None:
            warn(f"image '{image.name}': UDIM tile {number} has no file or packed data "
                 "(a generated tile that was never saved?); it reads as missing (magenta)")
            continue
        loaded = None
        try:
            loaded = bpy.data.images.load(source, check_existing=False)
            loaded.colorspace_settings.name = image.colorspace_settings.name
            loaded.alpha_mode = image.alpha_mode
            tiles[number] = image_pixels(loaded, lambda m, n=number: warn(
                m.replace(f"image '{loaded.name}'", f"image '{image.name}' tile {n}")))
        except (RuntimeError, TypeError, ValueError) as error:
            warn(f"image '{image.name}': UDIM tile {number} cannot be read ({error}); it "
                 "reads as missing (magenta)")
        finally:
            if loaded is not None:
                bpy.data.images.remove(loaded)
            if temporary is not None:
                try:
                    os.remove(temporary)
                except OSError:
                    pass
    tiles = {n: t for n, t in tiles.items() if t is not None}
    if not tiles:
        warn(f"image '{image.name}': no UDIM tile could be read")
        return None
    encodings = {t.encoding for t in tiles.values()}
    return N.TiledImage(tiles, encodings.pop() if len(encodings) == 1 else "linear")


def export_graph(tree, warn=lambda m: None, images: dict | None = None) -> N.Graph:
    """The graph of a bpy node tree (see the module docstring)."""
    images = {} if images is None else images
    graph = N.Graph()
    for node in tree.nodes:
        if node.bl_idname in ("NodeFrame",):
            continue
        props = {k: (v if isinstance(v, str) else _value(v))
                 for k in _PROPS.get(node.bl_idname, ()) if (v := getattr(node, k, None))
                 is not None}
        if node.bl_idname in ("ShaderNodeValue", "ShaderNodeRGB"):
            props["value" if node.bl_idname == "ShaderNodeValue" else "color"] = _value(
                node.outputs[0].default_value)
        if node.bl_idname == "ShaderNodeValToRGB":
            ramp = node.color_ramp
            props.update(elements=[[float(e.position), [float(c) for c in e.color]]
                                   for e in ramp.elements],
                         interpolation=ramp.interpolation, color_mode=ramp.color_mode,
                         hue_interpolation=ramp.hue_interpolation)
        if node.bl_idname in _CURVES:
            props.update(curve_table(node.mapping, _CURVES[node.bl_idname]))
        if node.bl_idname == "ShaderNodeTexImage" and node.image is not None:
            name = node.image.name
            if name not in images:
                images[name] = image_pixels(node.image, warn)
            if images[name] is not None:
                props["image"] = name
                graph.images[name] = images[name]
        inputs = {}
        for s in node.inputs:
            dv = getattr(s, "default_value", None)
            inputs[s.identifier] = (s.type, _value(dv) if dv is not None else None)
        outputs = {s.identifier: s.type for s in node.outputs}
        graph.nodes[node.name] = N.Node(node.bl_idname, node.name, props, inputs, outputs)
    for link in tree.links:
        if link.is_muted or not link.is_valid or link.from_node.mute:
            continue
        graph.links[(link.to_node.name, link.to_socket.identifier)] = (
            link.from_node.name, link.from_socket.identifier)
    return graph


def output_socket(graph: N.Graph, to_node: str, to_input: str):
    """(node, output identifier) linked into input ``to_input`` of ``to_node``, or None."""
    return graph.links.get((to_node, to_input))
