"""Shader-node evaluation over arrays of hits: the value a node tree delivers to one socket.

What it computes
----------------
A material's node tree, read from Blender by ``engine/blender/node_export.py``, is held here as
a :class:`Graph`: plain :class:`Node` records (Blender's ``bl_idname`` as the type, the node's
name, its properties, its input sockets with their kind and default, its output kinds) and the
links between sockets. :func:`evaluate` returns the value reaching one output socket for N hits
at once: ``(N,)`` for a float socket, ``(N, 3)`` for a vector or a colour (alpha is dropped, as
Cycles' SVM drops it), computed with numpy over the whole batch, each node once per call.

Per-hit inputs (``inputs``, arrays over the N hits, float; all optional until a node asks)
    ``"uv"`` (N, 2) the active UV map; ``"uv:<name>"`` a named UV map; ``"position"`` (N, 3)
    object-space position (Texture Coordinate > Object); ``"normal"`` (N, 3) object-space
    shading normal; ``"generated"`` (N, 3) the Generated coordinate (object space mapped
    through the mesh's texture space, Blender's orco); ``"color:<name>"`` (N, 3) and
    ``"alpha:<name>"`` (N,) vertex colours (``"color"``/``"alpha"`` for the active one), or
    ``"color:<name>"`` (N, 4) RGBA (what export hands over).
    World space (Geometry, Fresnel, Layer Weight, Normal Map, Bump): ``"position_world"``
    (N, 3) [m]; ``"normal_world"`` (N, 3) the unit shading normal, already turned to the side
    the ray came from (Cycles' sd->N); ``"true_normal_world"`` (N, 3) the geometric normal, so
    turned too; ``"incoming"`` (N, 3) the unit vector from the hit towards where the ray came
    from (the viewer for camera rays; Cycles' sd->wi); ``"backfacing"`` (N,) 1 where the ray
    hit the back of the face, else 0. ``"attr:<name>"`` a geometry attribute, (N,), (N, 2),
    (N, 3) or (N, 4) (Attribute also finds ``"uv:<name>"`` and ``"color:<name>"``).
    ``"hair"`` (N, 4) on hair (Curves Info): intercept, curve length [m], thickness (twice
    the radius) [m] and Cycles' random per curve (hash_uint2_to_float(curve, 0)); zeros off hair.
    ``"tangent:<uvmap>"`` (N, 4) (``"tangent"`` for the active UV map): the interpolated,
    unnormalised object-space MikkTSpace tangent and, in the last column, the bitangent sign;
    ``"normal_matrix"`` (N, 3, 3) object-to-world matrix for normals (inverse transpose of the
    object's linear part), for the Normal Map's tangent and object spaces. ``"ray:<output>"``
    (N,) a Light Path output; a missing flag or depth is a camera ray's (Is Camera Ray 1, the
    rest 0, as Cycles' path flags at a camera hit), Ray Length has no default. Lanterna's
    meaning: camera rays and camera paths continuing through glossy/specular lobes give what
    Cycles gives; photons are light paths and should be shaded as Cycles shades the emission
    side of a light path: Is Camera Ray 0, Is Diffuse/Glossy/Transmission Ray from the last
    bounce, Ray Depth the bounce count, Ray Length the segment length; final-gather rays are
    one diffuse reflection bounce (Is Diffuse Ray 1, Is Reflection Ray 1, Ray Depth 1, Diffuse
    Depth 1, Ray Length the gather ray's length). ``"dPdx"``, ``"dPdy"`` (N, 3) [m] the hit's
    footprint (ray differentials) and ``"dx:<key>"``, ``"dy:<key>"`` the change of input <key>
    across it, for Bump. A node that needs an input that is not given raises
    :class:`MissingInput`.

Images (``Graph.images``: name -> :class:`Image`)
    ``pixels`` (H, W, 4), row 0 at the bottom and pixel centres at ((i + 0.5) / W,
    (j + 0.5) / H) in UV, as Blender stores them, held once in the precision they came in
    (:func:`stored_pixels`): uint8 for 8-bit images (texels within ``BYTE_TOLERANCE`` = 1e-6
    of k / 255, 4 B a texel), float16 for float images whose every texel round-trips through
    float16 within ``F16_RELATIVE`` = 1e-4 relative + ``F16_ABSOLUTE`` = 1e-6 (the float bar
    of the Cycles bake tests, so holding them so never costs accuracy; in practice images that
    were half floats, 8 B a texel), float32 for the rest (HDR, 16 B a texel). A look-up widens
    only the texels it reads, to float32 (bytes as k / 255, Cycles' byte texture read), and
    interpolates in float32 as Cycles' CPU kernel does. ``encoding`` is ``"srgb"`` for 8-bit
    sRGB images, whose pixels stay sRGB-encoded bytes (what ``Image.pixels`` gives for such an
    image, bytes / 255, measured on Blender 5.2): as in Cycles, the look-up interpolates the
    encoded values and converts to scene linear afterwards; ``"linear"`` for float images and
    Non-Color data, taken as they are. ``Image.nbytes`` is what the texels take; the export
    shares one ``Image`` between the materials that read it.

Nodes (Blender 5.2 LTS; formulas follow Cycles' SVM kernel, ``intern/cycles/kernel/svm``)
    Value, RGB, Reroute, Math (every operation, Clamp), Vector Math (every operation), Map Range
    (float and vector; linear, stepped, smoothstep, smootherstep; clamp), Clamp (min-max, range),
    Mix (float, vector uniform and non-uniform, colour with all 19 blend modes, clamp factor and
    result), MixRGB (legacy), Invert, Gamma, Bright/Contrast, Hue/Saturation/Value, RGB to BW,
    Separate/Combine Color (RGB, HSV, HSL) and XYZ, Color Ramp (constant, linear, ease,
    cardinal, B-spline; RGB, HSV and HSL blending; through Cycles' 257-entry table), Checker,
    Gradient (all 7 types), Texture Coordinate (Generated, Normal, UV, Object), UV Map, Color
    Attribute, Mapping (point, texture, vector, normal), Image Texture (flat projection; closest,
    linear, cubic B-spline, Smart as cubic; repeat, extend, clip, mirror; alpha straight; UDIM
    images, :class:`TiledImage`, tile by tile as Cycles maps them);
    Noise Texture (1D-4D; fBM, multifractal, hybrid and ridged multifractal, hetero terrain;
    fractional detail, distortion, normalize; Fac and Color), Voronoi Texture (1D-4D; F1, F2,
    smooth F1, distance to edge, n-sphere radius; Euclidean, Manhattan, Chebychev, Minkowski;
    fractal detail; Distance, Color, Position, W, Radius), Wave Texture (bands and rings in
    every direction; sine, saw, triangle; distortion) through ``engine/procedural.py``;
    Fresnel, Layer Weight, Geometry (Position, Normal, True Normal, Incoming, Backfacing),
    Attribute (geometry attributes), Light Path (every output); RGB Curves, Vector Curves and
    Float Curve (Cycles' 257-entry table, which ``node_export.curve_table`` builds with
    Blender's own curve evaluation, and its lookup with extrapolation); Normal Map (tangent,
    object, world and Blender's object/world spaces; strength; OpenGL/DirectX; "base" is
    ignored: there is no displacement); Bump (Strength, Distance, Filter Width, Invert, Height,
    Normal). Bump is Cycles' formula, N' = normalize(fw |det| N - s sign(det) grad) with the
    height evaluated three times, at the hit and with every per-hit input k moved by
    fw * dx:k and fw * dy:k (Cycles moves P by fw dP along its ray differentials); it needs
    "dPdx"/"dPdy". Cycles' compact differentials make its footprint a scalar spread along an
    orthonormal frame around Ng, which this batch version does not reproduce: against Cycles'
    bakes the normals differ by up to 3e-2 on a noise height (tests/test_nodes.py,
    KNOWN_MISSES).
    Any other node raises :class:`UnsupportedNode` ("unsupported node <type> '<name>'"), for
    the caller to turn into a warning naming the material and the node.

Implicit conversions between sockets follow Cycles: colour to float by luminance (Rec.709
weights of Blender's default scene-linear space), vector to float by the mean of x, y, z, float
to vector/colour by repetition.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from . import procedural

__all__ = ["Node", "Graph", "Image", "TiledImage", "UnsupportedNode", "MissingInput", "evaluate",
           "graph_to_dict", "graph_from_dict", "SUPPORTED", "math_op", "vector_math_op",
           "mix_color", "rgb_to_hsv", "hsv_to_rgb", "rgb_to_hsl", "hsl_to_rgb",
           "srgb_to_linear", "ramp_table", "image_lookup", "udim_lookup", "MISSING_RGBA",
           "stored_pixels", "Evaluator", "image_bytes"]

LUMA = np.array([0.21263901, 0.71516867, 0.07219232])  # Blender 5.2 config luminance (measured)
FLT_EPSILON = 1.1920929e-07
VECTOR_KINDS = ("VECTOR", "RGBA")


class UnsupportedNode(ValueError):
    """A node (or a node option) the evaluator does not implement."""

    def __init__(self, node_type: str, name: str, detail: str = ""):
        self.node_type, self.name = node_type, name
        super().__init__(f"unsupported node {node_type} '{name}'" + (f": {detail}" if detail
                                                                       else ""))


class MissingInput(KeyError):
    """A per-hit input a node needs (``"uv"``, ``"position"`` ...) was not given."""


# Texels held as float16 where every one of them round-trips through float16 within the
# evaluator's float bar (``F16_RELATIVE`` relative plus ``F16_ABSOLUTE``, tests/test_nodes.py's
# bar for float results): in practice the images that were half floats already (half EXRs).
F16_RELATIVE = 1e-4
F16_ABSOLUTE = 1e-6
# Float texels held as bytes where each is within this of k / 255 (what Blender hands back for
# an 8-bit image: bytes / 255, measured within 3e-8).
BYTE_TOLERANCE = 1e-6
_INV255 = np.float32(1.0 / 255.0)


def stored_pixels(pixels) -> np.ndarray:
    """(H, W, 4) texels in the most compact of uint8, float16 and float32 that holds them
    within the evaluator's bars (module docstring, "Images"); uint8 and float16 arrays are
    kept as they are."""
    px = np.asarray(pixels)
    if px.dtype in (np.uint8, np.float16):
        return np.ascontiguousarray(px)
    px = np.ascontiguousarray(px, np.float32)
    if px.size == 0:
        return px
    with np.errstate(invalid="ignore", over="ignore"):
        k = np.round(px * np.float32(255.0))
        if np.all((k >= 0) & (k <= 255)
                  & (np.abs(k * _INV255 - px) <= np.float32(BYTE_TOLERANCE))):
            return k.astype(np.uint8)
        half = px.astype(np.float16)
        err = np.abs(half.astype(np.float32) - px)
        if np.all(err <= np.float32(F16_RELATIVE) * np.abs(px) + np.float32(F16_ABSOLUTE)):
            return half
    return px


@dataclass
class Image:
    """Texels (H, W, 4), bottom row first, held once in the precision they came in
    (:func:`stored_pixels`: uint8 for 8-bit images, float16 where lossless, else float32);
    ``encoding`` "srgb" or "linear". ``nbytes``: the memory they take."""
    pixels: np.ndarray
    encoding: str = "linear"

    def __post_init__(self):
        self.pixels = stored_pixels(self.pixels)

    @property
    def nbytes(self) -> int:
        return int(self.pixels.nbytes)

    def texels(self, index) -> np.ndarray:
        """(N, 4) float32 values of the texels at flat indices ``index`` (row * W + column):
        bytes as k / 255, halves widened."""
        px = self.pixels
        t = np.take(px.reshape(-1, px.shape[-1]), index, axis=0)
        if t.dtype == np.uint8:
            return t.astype(np.float32) * _INV255
        return t.astype(np.float32, copy=False)


@dataclass
class TiledImage:
    """A UDIM image: ``tiles`` maps a tile number to its :class:`Image`; tile
    1001 + 10 v + u covers UV [u, u + 1) x [v, v + 1), u in 0..9 (Blender's numbering).
    ``nbytes``: the texels of all tiles."""
    tiles: dict
    encoding: str = "linear"

    @property
    def nbytes(self) -> int:
        return int(sum(tile.nbytes for tile in self.tiles.values()))


@dataclass
class Node:
    """One node: Blender's bl_idname, its name, properties, inputs {identifier: (kind,
    default)} and outputs {identifier: kind}; kinds are Blender's socket types."""
    type: str
    name: str
    props: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)


@dataclass
class Graph:
    """Nodes by name; links {(to node, to input identifier): (from node, from output
    identifier)}; images by name."""
    nodes: dict = field(default_factory=dict)
    links: dict = field(default_factory=dict)
    images: dict = field(default_factory=dict)


def graph_to_dict(graph: Graph) -> dict:
    """A JSON-able description (images by name only; their pixels travel separately)."""
    return {"nodes": [{"type": n.type, "name": n.name, "props": n.props,
                       "inputs": {k: [kind, _plain(v)] for k, (kind, v) in n.inputs.items()},
                       "outputs": n.outputs} for n in graph.nodes.values()],
            "links": [[a, b, c, d] for (a, b), (c, d) in graph.links.items()],
            "images": {k: im.encoding for k, im in graph.images.items()}}


def graph_from_dict(d: dict, pixels: dict | None = None) -> Graph:
    """Inverse of :func:`graph_to_dict`; ``pixels`` maps image names to (H, W, 4) arrays, or
    for a UDIM image to {tile number: (H, W, 4)} (an image without pixels is left out: its
    Image Texture nodes give the missing-image colour)."""
    nodes = {n["name"]: Node(n["type"], n["name"], dict(n["props"]),
                             {k: (kind, v) for k, (kind, v) in n["inputs"].items()},
                             dict(n["outputs"])) for n in d["nodes"]}
    links = {(a, b): (c, e) for a, b, c, e in d["links"]}
    pixels = pixels or {}
    images = {k: (TiledImage({int(n): Image(a, enc) for n, a in pixels[k].items()}, enc)
                  if isinstance(pixels[k], dict) else Image(pixels[k], enc))
              for k, enc in d.get("images", {}).items() if k in pixels}
    return Graph(nodes, links, images)


def _plain(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, tuple):
        return list(v)
    return v


# ---------------------------------------------------------------------------------------------
# Helpers as Cycles defines them (util/math_*.h, util/color.h)

def _safe_div(a, b):
    b = np.asarray(b, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(b != 0, np.asarray(a, float) / np.where(b != 0, b, 1), 0.0)


def _safe_mod(a, b):
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(b != 0, np.fmod(a, np.where(b != 0, b, 1)), 0.0)


def _floored_mod(a, b):
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(b != 0, a - np.floor(a / np.where(b != 0, b, 1)) * b, 0.0)


def _wrap(v, hi, lo):
    rng = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(rng != 0, v - rng * np.floor((v - lo) / np.where(rng != 0, rng, 1)),
                        lo)


def _pingpong(a, b):
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (a - b) / np.where(b != 0, b * 2, 1)
        return np.where(b != 0, np.abs((x - np.floor(x)) * b * 2 - b), 0.0)


def _smoothmin(a, b, k):
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.maximum(k - np.abs(a - b), 0.0) / np.where(k != 0, k, 1)
        return np.where(k != 0, np.minimum(a, b) - h * h * h * k * (1.0 / 6.0), np.minimum(a, b))


def _safe_pow(a, b):
    bad = (a < 0) & (b != np.floor(b))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return np.where(bad, 0.0, np.power(np.where(bad, 1.0, a), b))


def _safe_log(a, b):
    ok = (a > 0) & (b > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, _safe_div(np.log(np.where(ok, a, 1)), np.log(np.where(ok, b, 2))),
                        0.0)


def _sign(a):
    return np.where(a == 0, 0.0, np.where(a > 0, 1.0, -1.0))


_ERR = {"divide": "ignore", "invalid": "ignore", "over": "ignore"}
_MATH = {
    "ADD": lambda a, b, c: a + b, "SUBTRACT": lambda a, b, c: a - b,
    "MULTIPLY": lambda a, b, c: a * b, "DIVIDE": lambda a, b, c: _safe_div(a, b),
    "MULTIPLY_ADD": lambda a, b, c: a * b + c, "POWER": lambda a, b, c: _safe_pow(a, b),
    "LOGARITHM": lambda a, b, c: _safe_log(a, b),
    "SQRT": lambda a, b, c: np.sqrt(np.maximum(a, 0.0)),
    # Cycles computes 1/sqrt(a), non-finite for a <= 0, which its bake shows as 0 (measured)
    "INVERSE_SQRT": lambda a, b, c: np.where(a > 0, 1.0 / np.sqrt(np.maximum(a, 1e-300)), 0.0),
    "ABSOLUTE": lambda a, b, c: np.abs(a), "EXPONENT": lambda a, b, c: np.exp(a),
    "MINIMUM": lambda a, b, c: np.fmin(a, b), "MAXIMUM": lambda a, b, c: np.fmax(a, b),
    "LESS_THAN": lambda a, b, c: (a < b).astype(float),
    "GREATER_THAN": lambda a, b, c: (a > b).astype(float),
    "SIGN": lambda a, b, c: _sign(a),
    "COMPARE": lambda a, b, c: ((a == b) | (np.abs(a - b) <= np.maximum(c, FLT_EPSILON))
                                ).astype(float),
    "SMOOTH_MIN": lambda a, b, c: _smoothmin(a, b, c),
    "SMOOTH_MAX": lambda a, b, c: -_smoothmin(-a, -b, c),
    "ROUND": lambda a, b, c: np.floor(a + 0.5), "FLOOR": lambda a, b, c: np.floor(a),
    "CEIL": lambda a, b, c: np.ceil(a), "TRUNC": lambda a, b, c: np.trunc(a),
    "FRACT": lambda a, b, c: a - np.floor(a), "MODULO": lambda a, b, c: _safe_mod(a, b),
    "FLOORED_MODULO": lambda a, b, c: _floored_mod(a, b),
    "WRAP": lambda a, b, c: _wrap(a, b, c),
    "SNAP": lambda a, b, c: np.floor(_safe_div(a, b)) * b,
    "PINGPONG": lambda a, b, c: _pingpong(a, b),
    "SINE": lambda a, b, c: np.sin(a), "COSINE": lambda a, b, c: np.cos(a),
    "TANGENT": lambda a, b, c: np.tan(a),
    "ARCSINE": lambda a, b, c: np.arcsin(np.clip(a, -1, 1)),
    "ARCCOSINE": lambda a, b, c: np.arccos(np.clip(a, -1, 1)),
    "ARCTANGENT": lambda a, b, c: np.arctan(a),
    "ARCTAN2": lambda a, b, c: np.arctan2(a, b),
    "SINH": lambda a, b, c: np.sinh(a), "COSH": lambda a, b, c: np.cosh(a),
    "TANH": lambda a, b, c: np.tanh(a),
    "RADIANS": lambda a, b, c: a * (np.pi / 180.0),
    "DEGREES": lambda a, b, c: a * (180.0 / np.pi),
}


def math_op(op: str, a, b, c, clamp: bool = False):
    """Blender's Math node: ``op`` one of its operations on arrays ``a, b, c``."""
    a, b, c = (np.asarray(x, float) for x in (a, b, c))
    with np.errstate(**_ERR):
        r = _MATH[op](a, b, c)
    return np.clip(r, 0.0, 1.0) if clamp else r


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _normalize(a):
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    return _safe_div(a, n)


def vector_math_op(op: str, a, b, c, scale):
    """Blender's Vector Math node on (N, 3) arrays; returns (vector (N, 3), value (N,))."""
    n = a.shape[0]
    zero_v, zero_s = np.zeros((n, 3)), np.zeros(n)
    with np.errstate(**_ERR):
        if op in ("DOT_PRODUCT", "DISTANCE", "LENGTH"):
            v = {"DOT_PRODUCT": lambda: _dot(a, b),
                 "DISTANCE": lambda: np.linalg.norm(a - b, axis=-1),
                 "LENGTH": lambda: np.linalg.norm(a, axis=-1)}[op]()
            return zero_v, v
        if op == "PROJECT":
            ll = _dot(b, b)[:, None]
            r = _safe_div(_dot(a, b)[:, None], ll) * b
        elif op == "REFLECT":
            nb = _normalize(b)
            r = a - 2.0 * nb * _dot(a, nb)[:, None]
        elif op == "REFRACT":
            nb = _normalize(b)
            eta = scale[:, None]
            d = _dot(nb, a)[:, None]
            k = 1.0 - eta * eta * (1.0 - d * d)
            r = np.where(k < 0, 0.0, eta * a - (eta * d + np.sqrt(np.maximum(k, 0))) * nb)
        elif op == "FACEFORWARD":
            r = np.where((_dot(c, b) < 0)[:, None], a, -a)
        else:
            f = {"ADD": lambda: a + b, "SUBTRACT": lambda: a - b, "MULTIPLY": lambda: a * b,
                 "DIVIDE": lambda: _safe_div(a, b), "CROSS_PRODUCT": lambda: np.cross(a, b),
                 "MULTIPLY_ADD": lambda: a * b + c, "SCALE": lambda: a * scale[:, None],
                 "NORMALIZE": lambda: _normalize(a), "ABSOLUTE": lambda: np.abs(a),
                 "POWER": lambda: _safe_pow(a, b), "SIGN": lambda: _sign(a),
                 "MINIMUM": lambda: np.minimum(a, b), "MAXIMUM": lambda: np.maximum(a, b),
                 "ROUND": lambda: np.floor(a + 0.5), "FLOOR": lambda: np.floor(a),
                 "CEIL": lambda: np.ceil(a), "FRACTION": lambda: a - np.floor(a),
                 "MODULO": lambda: _safe_mod(a, b), "WRAP": lambda: _wrap(a, b, c),
                 "SNAP": lambda: np.floor(_safe_div(a, b)) * b,
                 "SINE": lambda: np.sin(a), "COSINE": lambda: np.cos(a),
                 "TANGENT": lambda: np.tan(a)}.get(op)
            if f is None:
                raise KeyError(op)
            r = f()
    return r, zero_s


# ---------------------------------------------------------------------------------------------
# Colour

def srgb_to_linear(c):
    """sRGB-encoded -> scene linear (Cycles' color_srgb_to_linear; negatives to 0)."""
    c = np.asarray(c, float)
    with np.errstate(invalid="ignore"):
        return np.where(c < 0.04045, np.where(c < 0, 0.0, c / 12.92),
                        np.power((np.maximum(c, 0.04045) + 0.055) / 1.055, 2.4))


def rgb_to_hsv(rgb):
    rgb = np.asarray(rgb, float)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    cmax, cmin = rgb.max(-1), rgb.min(-1)
    d = cmax - cmin
    s = _safe_div(d, cmax)
    s = np.where(cmax != 0, s, 0.0)
    with np.errstate(**_ERR):
        dd = np.where(d != 0, d, 1.0)
        cr, cg, cb = (cmax - r) / dd, (cmax - g) / dd, (cmax - b) / dd
    h = np.where(r == cmax, cb - cg, np.where(g == cmax, 2.0 + cr - cb, 4.0 + cg - cr)) / 6.0
    h = np.where(h < 0, h + 1.0, h)
    h = np.where(s != 0, h, 0.0)
    return np.stack([h, s, cmax], -1)


def hsv_to_rgb(hsv):
    hsv = np.asarray(hsv, float)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    h = np.where(h == 1.0, 0.0, h) * 6.0
    i = np.floor(h)
    f = h - i
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    cases = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v)]
    out = np.stack([v, p, q], -1)
    for k in range(4, -1, -1):
        out = np.where((i == k)[..., None], np.stack(cases[k], -1), out)
    return np.where((s != 0)[..., None], out, np.stack([v, v, v], -1))


def rgb_to_hsl(rgb):
    rgb = np.asarray(rgb, float)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    cmax, cmin = rgb.max(-1), rgb.min(-1)
    l = np.minimum(1.0, (cmax + cmin) / 2.0)
    d = cmax - cmin
    same = cmax == cmin
    with np.errstate(**_ERR):
        dd = np.where(same, 1.0, d)
        s = np.where(l > 0.5, dd / (2.0 - cmax - cmin), dd / (cmax + cmin))
        h = np.where(cmax == r, (g - b) / dd + np.where(g < b, 6.0, 0.0),
                     np.where(cmax == g, (b - r) / dd + 2.0, (r - g) / dd + 4.0))
    return np.stack([np.where(same, 0.0, h / 6.0), np.where(same, 0.0, s), l], -1)


def hsl_to_rgb(hsl):
    hsl = np.asarray(hsl, float)
    h, s, l = hsl[..., 0], hsl[..., 1], hsl[..., 2]
    nr = np.clip(np.abs(h * 6.0 - 3.0) - 1.0, 0, 1)
    ng = np.clip(2.0 - np.abs(h * 6.0 - 2.0), 0, 1)
    nb = np.clip(2.0 - np.abs(h * 6.0 - 4.0), 0, 1)
    chroma = ((1.0 - np.abs(2.0 * l - 1.0)) * s)[..., None]
    return (np.stack([nr, ng, nb], -1) - 0.5) * chroma + l[..., None]


def _lerp(a, b, t):
    return (1.0 - t) * a + t * b


def mix_color(blend: str, t, c1, c2):
    """Blender's Mix Color blend modes (Cycles' svm_mix_*): ``t`` (N,) factor already clamped
    when the node clamps it, ``c1, c2`` (N, 3)."""
    t = np.asarray(t, float)[..., None]
    c1, c2 = np.asarray(c1, float), np.asarray(c2, float)
    tm = 1.0 - t
    with np.errstate(**_ERR):
        if blend == "MIX":
            return _lerp(c1, c2, t)
        if blend == "ADD":
            return _lerp(c1, c1 + c2, t)
        if blend == "MULTIPLY":
            return _lerp(c1, c1 * c2, t)
        if blend == "SCREEN":
            return 1.0 - (tm + t * (1.0 - c2)) * (1.0 - c1)
        if blend == "OVERLAY":
            return np.where(c1 < 0.5, c1 * (tm + 2.0 * t * c2),
                            1.0 - (tm + 2.0 * t * (1.0 - c2)) * (1.0 - c1))
        if blend == "SUBTRACT":
            return _lerp(c1, c1 - c2, t)
        if blend == "DIVIDE":
            return np.where(c2 != 0, tm * c1 + t * c1 / np.where(c2 != 0, c2, 1), c1)
        if blend == "DIFFERENCE":
            return _lerp(c1, np.abs(c1 - c2), t)
        if blend == "EXCLUSION":
            return np.maximum(_lerp(c1, c1 + c2 - 2.0 * c1 * c2, t), 0.0)
        if blend == "DARKEN":
            return _lerp(c1, np.minimum(c1, c2), t)
        if blend == "LIGHTEN":
            return _lerp(c1, np.maximum(c1, c2), t)
        if blend == "DODGE":
            tmp = 1.0 - t * c2
            q = c1 / np.where(tmp <= 0, 1.0, tmp)
            out = np.where(tmp <= 0, 1.0, np.minimum(q, 1.0))
            return np.where(c1 != 0, out, c1)
        if blend == "BURN":
            tmp = tm + t * c2
            q = 1.0 - (1.0 - c1) / np.where(tmp <= 0, 1.0, tmp)
            return np.where(tmp <= 0, 0.0, np.clip(q, 0.0, 1.0))
        if blend == "HUE":
            hsv2 = rgb_to_hsv(c2)
            hsv = rgb_to_hsv(c1)
            hsv[..., 0] = hsv2[..., 0]
            return np.where((hsv2[..., 1] != 0)[..., None], _lerp(c1, hsv_to_rgb(hsv), t), c1)
        if blend == "SATURATION":
            hsv, hsv2 = rgb_to_hsv(c1), rgb_to_hsv(c2)
            keep = hsv[..., 1] == 0
            hsv[..., 1] = tm[..., 0] * hsv[..., 1] + t[..., 0] * hsv2[..., 1]
            return np.where(keep[..., None], c1, hsv_to_rgb(hsv))
        if blend == "VALUE":
            hsv, hsv2 = rgb_to_hsv(c1), rgb_to_hsv(c2)
            hsv[..., 2] = tm[..., 0] * hsv[..., 2] + t[..., 0] * hsv2[..., 2]
            return hsv_to_rgb(hsv)
        if blend == "COLOR":
            hsv2, hsv = rgb_to_hsv(c2), rgb_to_hsv(c1)
            hsv[..., 0], hsv[..., 1] = hsv2[..., 0], hsv2[..., 1]
            return np.where((hsv2[..., 1] != 0)[..., None], _lerp(c1, hsv_to_rgb(hsv), t), c1)
        if blend == "SOFT_LIGHT":
            scr = 1.0 - (1.0 - c2) * (1.0 - c1)
            return tm * c1 + t * ((1.0 - c1) * c2 * c1 + c1 * scr)
        if blend == "LINEAR_LIGHT":
            return c1 + t * (2.0 * c2 - 1.0)
    raise KeyError(blend)


# ---------------------------------------------------------------------------------------------
# Color Ramp: Blender's colorband, sampled into Cycles' 256-entry table

_RAMP_TABLE = 257                      # Blender's CM_TABLE + 1, as Cycles samples it


def _key_weights(t: float, kind: str):
    t2, t3 = t * t, t * t * t
    if kind == "CARDINAL":
        fc = 0.71
        return (-fc * t3 + 2.0 * fc * t2 - fc * t, (2.0 - fc) * t3 + (fc - 3.0) * t2 + 1.0,
                (fc - 2.0) * t3 + (3.0 - 2.0 * fc) * t2 + fc * t, fc * t3 - fc * t2)
    return (-0.16666666 * t3 + 0.5 * t2 - 0.5 * t + 0.16666666, 0.5 * t3 - t2 + 0.66666666,
            -0.5 * t3 + 0.5 * t2 + 0.5 * t + 0.16666666, 0.16666666 * t3)


def _hue_interp(mode: str, mfac: float, fac: float, h1: float, h2: float) -> float:
    h1 = h1 if h1 < 1.0 else h1 - 1.0
    h2 = h2 if h2 < 1.0 else h2 - 1.0
    m = 0
    if mode == "NEAR":
        m = 1 if (h1 < h2 and h2 - h1 > 0.5) else 2 if (h1 > h2 and h2 - h1 < -0.5) else 0
    elif mode == "FAR":
        m = (1 if h1 == h2 else 1 if (h1 < h2 and h2 - h1 < 0.5)
             else 2 if (h1 > h2 and h2 - h1 > -0.5) else 0)
    elif mode == "CCW":
        m = 2 if h1 > h2 else 0
    elif mode == "CW":
        m = 1 if h1 < h2 else 0
    if m == 0:
        return mfac * h1 + fac * h2
    h = mfac * (h1 + 1.0) + fac * h2 if m == 1 else mfac * h1 + fac * (h2 + 1.0)
    return h if h < 1.0 else h - 1.0


def _colorband(stops, x: float, interp: str, mode: str, hue: str) -> np.ndarray:
    """Blender's BKE_colorband_evaluate at one position; stops [(pos, (r, g, b, a))] sorted."""
    ipo = interp if mode == "RGB" else "LINEAR"
    simple = ipo in ("LINEAR", "EASE", "CONSTANT")
    if len(stops) == 1 or (x <= stops[0][0] and simple):
        return np.array(stops[0][1], float)
    tot = len(stops)
    a = next((i for i, (p, _) in enumerate(stops) if p > x), tot)
    if a == tot:
        left = stops[a - 1]
        right = (1.0, left[1])
    elif a == 0:
        right = stops[0]
        left = (0.0, right[1])
    else:
        left, right = stops[a - 1], stops[a]
    if a == tot and simple:
        return np.array(left[1], float)
    if ipo == "CONSTANT":
        return np.array(left[1], float)
    fac = ((x - right[0]) / (left[0] - right[0]) if left[0] != right[0]
           else (0.0 if a != tot else 1.0))
    if ipo in ("B_SPLINE", "CARDINAL"):
        c0 = right if a >= tot - 1 else stops[a + 1]
        c3 = left if a < 2 else stops[a - 2]
        w = _key_weights(min(max(fac, 0.0), 1.0), ipo)
        out = (w[3] * np.array(c3[1]) + w[2] * np.array(left[1]) + w[1] * np.array(right[1])
               + w[0] * np.array(c0[1]))
        return np.clip(out, 0.0, 1.0)
    if ipo == "EASE":
        fac = 3.0 * fac * fac - 2.0 * fac * fac * fac
    mfac = 1.0 - fac
    c1, c2 = np.array(right[1], float), np.array(left[1], float)
    if mode in ("HSV", "HSL"):
        to, back = (rgb_to_hsv, hsv_to_rgb) if mode == "HSV" else (rgb_to_hsl, hsl_to_rgb)
        h1, h2 = to(c1[:3]), to(c2[:3])
        out = np.array([_hue_interp(hue, mfac, fac, h1[0], h2[0]), mfac * h1[1] + fac * h2[1],
                        mfac * h1[2] + fac * h2[2]])
        return np.concatenate([back(out), [mfac * c1[3] + fac * c2[3]]])
    return mfac * c1 + fac * c2


def ramp_table(stops, interpolation="LINEAR", color_mode="RGB", hue="NEAR") -> np.ndarray:
    """The (257, 4) table Cycles samples a Color Ramp into (positions i / 256); measured:
    against Cycles' bakes this table agrees to 1.3e-7, the exact colorband to only 1e-4."""
    stops = sorted(((float(p), tuple(float(v) for v in c)) for p, c in stops),
                   key=lambda s: s[0])
    return np.array([_colorband(stops, i / (_RAMP_TABLE - 1), interpolation, color_mode, hue)
                     for i in range(_RAMP_TABLE)])


def _ramp_lookup(table, f, interpolate: bool):
    n = table.shape[0]
    f = np.clip(np.nan_to_num(f), 0.0, 1.0) * (n - 1)
    i = np.clip(f.astype(int), 0, n - 1)
    t = f - i
    a = table[i]
    if interpolate:
        b = table[np.minimum(i + 1, n - 1)]
        a = np.where((t > 0)[:, None], (1.0 - t)[:, None] * a + t[:, None] * b, a)
    return a


# ---------------------------------------------------------------------------------------------
# Image look-up (Cycles' kernel/device/cpu/image.h)

def _cubic_weights(t):
    return ((((-1.0 / 6.0) * t + 0.5) * t - 0.5) * t + (1.0 / 6.0),
            ((0.5 * t - 1.0) * t) * t + (2.0 / 3.0),
            ((-0.5 * t + 0.5) * t + 0.5) * t + (1.0 / 6.0),
            (1.0 / 6.0) * t * t * t)


def _wrap_index(i, n, extension):
    if extension == "REPEAT":
        return np.mod(i, n), np.ones(i.shape, bool)
    if extension == "EXTEND":
        return np.clip(i, 0, n - 1), np.ones(i.shape, bool)
    if extension == "MIRROR":
        m = np.abs(i + (i < 0)) % (2 * n)
        return np.where(m >= n, 2 * n - m - 1, m), np.ones(i.shape, bool)
    inside = (i >= 0) & (i < n)                             # CLIP
    return np.clip(i, 0, n - 1), inside


# Cycles' missing-image colour (TEX_IMAGE_MISSING_R/G/B/A: magenta, alpha 1)
MISSING_RGBA = (1.0, 0.0, 1.0, 1.0)


def udim_lookup(image: TiledImage, x, y, interpolation="Linear", extension="REPEAT"):
    """RGBA (N, 4) of a UDIM image at UV (x, y), as Cycles maps UDIMs: the tile is
    1001 + 10 trunc(y) + trunc(x) (truncated towards zero, in float32, so -0.5 falls in tile
    1001), UVs are taken relative to it and the extension applies inside the tile; points
    with trunc(x) < 0, trunc(y) < 0, trunc(x) > 9 or in a tile the image lacks get the
    missing-image colour."""
    x, y = np.asarray(x, np.float32), np.asarray(y, np.float32)
    out = np.broadcast_to(np.asarray(MISSING_RGBA, np.float64), (x.shape[0], 4)).copy()
    finite = np.isfinite(x) & np.isfinite(y)
    tx = np.trunc(np.where(finite, x, -1.0)).clip(-1, 1e6).astype(np.int64)
    ty = np.trunc(np.where(finite, y, -1.0)).clip(-1, 1e6).astype(np.int64)
    valid = finite & (tx >= 0) & (ty >= 0) & (tx < 10)
    number = 1001 + 10 * ty + tx
    for tile_number, tile in image.tiles.items():
        hit = np.flatnonzero(valid & (number == tile_number))
        if hit.size:
            out[hit] = image_lookup(tile, x[hit] - tx[hit].astype(np.float32),
                                    y[hit] - ty[hit].astype(np.float32), interpolation,
                                    extension)
    return out


def image_lookup(image: Image, x, y, interpolation="Linear", extension="REPEAT"):
    """RGBA (N, 4) of ``image`` at UV (x, y), as Cycles' image look-up and svm_image_texture
    give it (interpolating the stored encoding in float32, bytes as k / 255, then sRGB ->
    linear for "srgb" images); a :class:`TiledImage` by :func:`udim_lookup`."""
    if isinstance(image, TiledImage):
        return udim_lookup(image, x, y, interpolation, extension)
    px = image.pixels
    h, w = px.shape[:2]
    flat = px.reshape(h * w, px.shape[-1])
    x, y = np.asarray(x, np.float32), np.asarray(y, np.float32)
    if interpolation == "Closest":
        fx, fy = np.floor(x * np.float32(w)), np.floor(y * np.float32(h))
        ix, okx = _wrap_index(fx.astype(np.int64), w, extension)
        iy, oky = _wrap_index(fy.astype(np.int64), h, extension)
        out = np.take(flat, iy * w + ix, axis=0).astype(np.float32)
        if extension == "CLIP":
            out *= (okx & oky)[:, None]
    else:
        sx, sy = x * np.float32(w) - np.float32(0.5), y * np.float32(h) - np.float32(0.5)
        fx, fy = np.floor(sx), np.floor(sy)
        tx, ty = sx - fx, sy - fy
        ix0, iy0 = fx.astype(np.int64), fy.astype(np.int64)
        if interpolation == "Linear":
            offs, wx, wy = (0, 1), (1.0 - tx, tx), (1.0 - ty, ty)
        else:                                               # Cubic, Smart: B-spline
            offs, wx, wy = (-1, 0, 1, 2), _cubic_weights(tx), _cubic_weights(ty)
        cols = [_wrap_index(ix0 + o, w, extension) for o in offs]
        out = np.zeros((x.shape[0], 4), np.float32)
        for j, oy in enumerate(offs):
            iy, oky = _wrap_index(iy0 + oy, h, extension)
            row = iy * w
            for i, (ix, okx) in enumerate(cols):
                weight = wx[i] * wy[j]
                if extension == "CLIP":
                    weight = weight * (okx & oky)
                # float32 x the stored texel (uint8 or float16 widened by numpy): float32
                out += weight[:, None] * np.take(flat, row + ix, axis=0)
    if px.dtype == np.uint8:
        out *= _INV255                                      # bytes as k / 255
    if image.encoding == "srgb":
        out[:, :3] = _srgb_to_linear32(out[:, :3])
    return out.astype(np.float64)


def _srgb_to_linear32(c):
    """:func:`srgb_to_linear` in float32 (Cycles' precision; within 4e-7 of it)."""
    out = np.maximum(c, np.float32(0.04045))
    out += np.float32(0.055)
    out *= np.float32(1.0 / 1.055)
    np.power(out, np.float32(2.4), out=out)
    low = c < np.float32(0.04045)
    out[low] = np.maximum(c[low], np.float32(0.0)) * np.float32(1.0 / 12.92)
    return out


# ---------------------------------------------------------------------------------------------
# Evaluation

def _euler_matrix(rot):
    """(N, 3, 3) rotation matrices for XYZ Euler angles (N, 3), Cycles' euler_to_transform."""
    cx, cy, cz = np.cos(rot[:, 0]), np.cos(rot[:, 1]), np.cos(rot[:, 2])
    sx, sy, sz = np.sin(rot[:, 0]), np.sin(rot[:, 1]), np.sin(rot[:, 2])
    return np.stack([np.stack([cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz], -1),
                     np.stack([cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz], -1),
                     np.stack([-sy, cy * sx, cy * cx], -1)], 1)


def _gradient(p, kind):
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    if kind == "LINEAR":
        f = x
    elif kind == "QUADRATIC":
        f = np.maximum(x, 0.0) ** 2
    elif kind == "EASING":
        r = np.clip(x, 0.0, 1.0)
        f = 3.0 * r * r - 2.0 * r * r * r
    elif kind == "DIAGONAL":
        f = (x + y) * 0.5
    elif kind == "RADIAL":
        f = np.arctan2(y, x) / (2.0 * np.pi) + 0.5
    else:
        r = np.maximum(0.999999 - np.sqrt(x * x + y * y + z * z), 0.0)
        f = r * r if kind == "QUADRATIC_SPHERE" else r
    return np.clip(f, 0.0, 1.0)


def _checker(p):
    p = ((p.astype(np.float32) + np.float32(1e-6)) * np.float32(0.999999))
    i = np.abs(np.floor(p).astype(np.int64)) % 2
    return ((i[:, 0] == i[:, 1]) == i[:, 2]).astype(float)


SUPPORTED = frozenset({
    "ShaderNodeValue", "ShaderNodeRGB", "NodeReroute", "ShaderNodeMath",
    "ShaderNodeVectorMath", "ShaderNodeMapRange", "ShaderNodeClamp", "ShaderNodeMix",
    "ShaderNodeMixRGB", "ShaderNodeInvert", "ShaderNodeGamma", "ShaderNodeBrightContrast",
    "ShaderNodeHueSaturation", "ShaderNodeRGBToBW", "ShaderNodeSeparateColor",
    "ShaderNodeCombineColor", "ShaderNodeSeparateXYZ", "ShaderNodeCombineXYZ",
    "ShaderNodeValToRGB", "ShaderNodeTexChecker", "ShaderNodeTexGradient",
    "ShaderNodeTexCoord", "ShaderNodeUVMap", "ShaderNodeVertexColor", "ShaderNodeMapping",
    "ShaderNodeTexImage", "ShaderNodeTexNoise", "ShaderNodeTexVoronoi", "ShaderNodeTexWave",
    "ShaderNodeFresnel", "ShaderNodeLayerWeight", "ShaderNodeNewGeometry",
    "ShaderNodeAttribute", "ShaderNodeLightPath", "ShaderNodeRGBCurve",
    "ShaderNodeVectorCurve", "ShaderNodeFloatCurve", "ShaderNodeNormalMap", "ShaderNodeBump",
    "ShaderNodeHairInfo"})


class ShiftedInputs(Mapping):
    """Per-hit inputs moved along one axis of the hits' footprint (``_Eval.shifted``): key k
    reads k + width x "d<axis>:k" (for "position_world" without its own differential,
    "dPd<axis>"); differentials themselves and keys without one are read unchanged."""

    def __init__(self, inputs, axis: str, width):
        self.base, self.axis, self.width = inputs, axis, np.asarray(width, float)

    def __getitem__(self, key):
        v = self.base[key]
        if key.startswith(("dx:", "dy:")) or key in ("dPdx", "dPdy"):
            return v
        d = self.base.get(f"d{self.axis}:{key}")
        if d is None and key == "position_world":
            d = self.base.get(f"dPd{self.axis}")
        if d is None:
            return v
        v = np.asarray(v, float)
        w = self.width
        return v + (w.reshape(-1, *([1] * (v.ndim - 1))) if w.ndim else w) * d

    def __contains__(self, key):
        return key in self.base

    def __iter__(self):
        return iter(self.base)

    def __len__(self):
        return len(self.base)


class _Eval:
    def __init__(self, graph: Graph, inputs: dict, n: int):
        self.g, self.inputs, self.n = graph, inputs, n
        self.memo: dict = {}

    def hit(self, key: str, node: Node) -> np.ndarray:
        if key not in self.inputs:
            raise MissingInput(f"node {node.type} '{node.name}' needs the per-hit input "
                               f"'{key}'")
        a = np.asarray(self.inputs[key], float)
        if a.ndim == 2 and a.shape[1] == 2:
            a = np.concatenate([a, np.zeros((a.shape[0], 1))], 1)
        return a

    def output(self, name: str, socket: str) -> np.ndarray:
        key = (name, socket)
        if key not in self.memo:
            node = self.g.nodes[name]
            if node.type not in SUPPORTED:
                raise UnsupportedNode(node.type, node.name)
            outs = _NODE_FUNCS[node.type](self, node)
            for k, v in outs.items():
                self.memo[(name, k)] = v
            if key not in self.memo and node.type == "ShaderNodeTexCoord":
                self.hit(_TEXCO_KEYS.get(socket, socket.lower()), node)
            if key not in self.memo and node.type == "ShaderNodeNewGeometry" \
                    and socket in _GEOMETRY_KEYS:
                self.hit(_GEOMETRY_KEYS[socket], node)
            if key not in self.memo and node.type == "ShaderNodeLightPath":
                self.hit(f"ray:{socket}", node)
            if key not in self.memo:
                raise UnsupportedNode(node.type, node.name, f"output '{socket}'")
        return self.memo[key]

    def kind_of(self, name: str, socket: str) -> str:
        return self.g.nodes[name].outputs.get(socket, "VALUE")

    def input(self, node: Node, ident: str, want: str | None = None):
        """The value at an input socket, as ``want`` ("VALUE" or "VECTOR"; default the
        socket's own kind), (N,) or (N, 3)."""
        kind, default = node.inputs[ident]
        want = want or kind
        src = self.g.links.get((node.name, ident))
        if src is None:
            v = np.asarray(default, float)
            have = "VALUE" if v.ndim == 0 else "VECTOR"
            v = np.broadcast_to(v[:3] if v.ndim else v, (self.n, 3) if v.ndim else (self.n,))
        else:
            v = self.output(*src)
            have = self.kind_of(*src)
            if have == "RGBA" and want == "VALUE":
                return v @ LUMA
        if want in VECTOR_KINDS and v.ndim == 1:
            return np.repeat(v[:, None], 3, 1)
        if want == "VALUE" and v.ndim == 2:
            return v @ LUMA if have == "RGBA" else v.mean(1)
        return np.array(v, float)

    def shifted(self, axis: str, width) -> "_Eval":
        """An evaluator at the hits moved by ``width`` times the footprint along ``axis``
        ("x" or "y"): each per-hit input k with a differential "d<axis>:k" becomes
        k + width * d<axis>:k ("position_world" moves by dPd<axis> unless given its own);
        the others stay (Cycles' bump evaluation at P + dP * filter width). The moved inputs
        are computed when a node reads them (:class:`ShiftedInputs`)."""
        return _Eval(self.g, ShiftedInputs(self.inputs, axis, width), self.n)

    def vector_or(self, node: Node, ident: str, default_key: str):
        """A texture's Vector input, or the per-hit coordinate used when it is unlinked."""
        if (node.name, ident) in self.g.links:
            return self.input(node, ident, "VECTOR")
        return self.hit(default_key, node)


def _value(ev, node):
    return {"Value": np.full(ev.n, float(node.props["value"]))}


def _rgb(ev, node):
    return {"Color": np.broadcast_to(np.asarray(node.props["color"], float)[:3],
                                     (ev.n, 3)).copy()}


def _reroute(ev, node):
    ident = next(iter(node.inputs))
    kind = node.inputs[ident][0]
    return {next(iter(node.outputs)): ev.input(node, ident,
                                               "VECTOR" if kind in VECTOR_KINDS else "VALUE")}


def _math(ev, node):
    a, b, c = (ev.input(node, k, "VALUE") for k in ("Value", "Value_001", "Value_002"))
    op = node.props["operation"]
    if op not in _MATH:
        raise UnsupportedNode(node.type, node.name, f"operation {op}")
    return {"Value": math_op(op, a, b, c, bool(node.props.get("use_clamp", False)))}


def _vector_math(ev, node):
    a, b, c = (ev.input(node, k, "VECTOR") for k in ("Vector", "Vector_001", "Vector_002"))
    s = ev.input(node, "Scale", "VALUE")
    try:
        v, f = vector_math_op(node.props["operation"], a, b, c, s)
    except KeyError:
        raise UnsupportedNode(node.type, node.name, f"operation {node.props['operation']}")
    return {"Vector": v, "Value": f}


def _smoothstep01(t):
    t = np.clip(t, 0.0, 1.0)
    return (3.0 - 2.0 * t) * t * t


def _smootherstep01(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _map_range(ev, node):
    p = node.props
    kind = p.get("interpolation_type", "LINEAR")
    clamp = bool(p.get("clamp", True))
    if p.get("data_type", "FLOAT") == "FLOAT_VECTOR":
        v, f0, f1, t0, t1, st = (ev.input(node, k, "VECTOR") for k in (
            "Vector", "From_Min_FLOAT3", "From_Max_FLOAT3", "To_Min_FLOAT3", "To_Max_FLOAT3",
            "Steps_FLOAT3"))
        fac = _safe_div(v - f0, f1 - f0)
        if kind == "STEPPED":
            with np.errstate(**_ERR):
                fac = np.where(st > 0, np.floor(fac * (st + 1.0)) / np.where(st > 0, st, 1), 0.0)
        elif kind == "SMOOTHSTEP":
            fac = _smoothstep01(fac)
        elif kind == "SMOOTHERSTEP":
            fac = _smootherstep01(fac)
        r = t0 + fac * (t1 - t0)
        if clamp and kind in ("LINEAR", "STEPPED"):
            r = np.clip(r, np.minimum(t0, t1), np.maximum(t0, t1))
        return {"Vector": r, "Result": np.zeros(ev.n)}
    v, f0, f1, t0, t1, st = (ev.input(node, k, "VALUE") for k in (
        "Value", "From Min", "From Max", "To Min", "To Max", "Steps"))
    same = f1 == f0
    with np.errstate(**_ERR):
        d = np.where(same, 1.0, f1 - f0)
        if kind in ("LINEAR", "STEPPED"):
            fac = (v - f0) / d
            if kind == "STEPPED":
                fac = np.where(st > 0, np.floor(fac * (st + 1.0)) / np.where(st > 0, st, 1), 0.0)
        else:
            lo, hi = np.minimum(f0, f1), np.maximum(f0, f1)
            t = _safe_div(v - lo, hi - lo)
            s = _smoothstep01(t) if kind == "SMOOTHSTEP" else _smootherstep01(t)
            fac = np.where(f0 > f1, 1.0 - s, s)
        r = np.where(same, 0.0, t0 + fac * (t1 - t0))
    if clamp and kind in ("LINEAR", "STEPPED"):
        r = np.clip(r, np.minimum(t0, t1), np.maximum(t0, t1))
    return {"Result": r, "Vector": np.zeros((ev.n, 3))}


def _clamp(ev, node):
    v, lo, hi = (ev.input(node, k, "VALUE") for k in ("Value", "Min", "Max"))
    if node.props.get("clamp_type", "MINMAX") == "RANGE":
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    return {"Result": np.minimum(np.maximum(v, lo), hi)}


def _mix(ev, node):
    p = node.props
    dt = p.get("data_type", "FLOAT")
    if dt == "RGBA":
        t = ev.input(node, "Factor_Float", "VALUE")
        if p.get("clamp_factor", True):
            t = np.clip(t, 0.0, 1.0)
        r = mix_color(p.get("blend_type", "MIX"), t, ev.input(node, "A_Color", "VECTOR"),
                      ev.input(node, "B_Color", "VECTOR"))
        if p.get("clamp_result", False):
            r = np.clip(r, 0.0, 1.0)
        return {"Result_Color": r}
    if dt == "FLOAT":
        t = ev.input(node, "Factor_Float", "VALUE")
        if p.get("clamp_factor", True):
            t = np.clip(t, 0.0, 1.0)
        a, b = ev.input(node, "A_Float", "VALUE"), ev.input(node, "B_Float", "VALUE")
        return {"Result_Float": a * (1.0 - t) + b * t}
    if dt == "VECTOR":
        if p.get("factor_mode", "UNIFORM") == "NON_UNIFORM":
            t = ev.input(node, "Factor_Vector", "VECTOR")
        else:
            t = ev.input(node, "Factor_Float", "VALUE")[:, None]
        if p.get("clamp_factor", True):
            t = np.clip(t, 0.0, 1.0)
        a, b = ev.input(node, "A_Vector", "VECTOR"), ev.input(node, "B_Vector", "VECTOR")
        return {"Result_Vector": a * (1.0 - t) + b * t}
    raise UnsupportedNode(node.type, node.name, f"data type {dt}")


def _mix_rgb(ev, node):
    t = np.clip(ev.input(node, "Fac", "VALUE"), 0.0, 1.0)
    r = mix_color(node.props.get("blend_type", "MIX"), t, ev.input(node, "Color1", "VECTOR"),
                  ev.input(node, "Color2", "VECTOR"))
    if node.props.get("use_clamp", False):
        r = np.clip(r, 0.0, 1.0)
    return {"Color": r}


def _invert(ev, node):
    f = ev.input(node, "Fac", "VALUE")[:, None]
    c = ev.input(node, "Color", "VECTOR")
    return {"Color": f * (1.0 - c) + (1.0 - f) * c}


def _gamma(ev, node):
    c = ev.input(node, "Color", "VECTOR")
    g = ev.input(node, "Gamma", "VALUE")[:, None]
    with np.errstate(**_ERR):
        r = np.where(c > 0, np.power(np.where(c > 0, c, 1.0), g), c)
    return {"Color": np.where(g == 0, 1.0, r)}


def _bright_contrast(ev, node):
    c = ev.input(node, "Color", "VECTOR")
    br = ev.input(node, "Bright", "VALUE")[:, None]
    co = ev.input(node, "Contrast", "VALUE")[:, None]
    return {"Color": np.maximum((1.0 + co) * c + (br - co * 0.5), 0.0)}


def _hue_sat(ev, node):
    hue, sat, val, fac = (ev.input(node, k, "VALUE") for k in ("Hue", "Saturation", "Value",
                                                                  "Fac"))
    c = ev.input(node, "Color", "VECTOR")
    hsv = rgb_to_hsv(c)
    h = hsv[:, 0] + hue + 0.5
    hsv = np.stack([h - np.floor(h), np.clip(hsv[:, 1] * sat, 0.0, 1.0), hsv[:, 2] * val], -1)
    r = hsv_to_rgb(hsv)
    return {"Color": np.maximum(fac[:, None] * r + (1.0 - fac[:, None]) * c, 0.0)}


def _rgb_to_bw(ev, node):
    return {"Val": ev.input(node, "Color", "VECTOR") @ LUMA}


def _separate_color(ev, node):
    c = ev.input(node, "Color", "VECTOR")
    mode = node.props.get("mode", "RGB")
    c = rgb_to_hsv(c) if mode == "HSV" else rgb_to_hsl(c) if mode == "HSL" else c
    return {"Red": c[:, 0], "Green": c[:, 1], "Blue": c[:, 2]}


def _combine_color(ev, node):
    c = np.stack([ev.input(node, k, "VALUE") for k in ("Red", "Green", "Blue")], -1)
    mode = node.props.get("mode", "RGB")
    return {"Color": hsv_to_rgb(c) if mode == "HSV" else hsl_to_rgb(c) if mode == "HSL"
            else c}


def _separate_xyz(ev, node):
    v = ev.input(node, "Vector", "VECTOR")
    return {"X": v[:, 0], "Y": v[:, 1], "Z": v[:, 2]}


def _combine_xyz(ev, node):
    return {"Vector": np.stack([ev.input(node, k, "VALUE") for k in ("X", "Y", "Z")], -1)}


def _color_ramp(ev, node):
    p = node.props
    table = p.get("_table")
    if table is None:
        table = ramp_table(p["elements"], p.get("interpolation", "LINEAR"),
                           p.get("color_mode", "RGB"), p.get("hue_interpolation", "NEAR"))
        p["_table"] = table
    rgba = _ramp_lookup(table, ev.input(node, "Fac", "VALUE"),
                        p.get("interpolation", "LINEAR") != "CONSTANT")
    return {"Color": rgba[:, :3], "Alpha": rgba[:, 3]}


def _tex_checker(ev, node):
    p = ev.vector_or(node, "Vector", "generated")
    f = _checker(p * ev.input(node, "Scale", "VALUE")[:, None])
    c1, c2 = ev.input(node, "Color1", "VECTOR"), ev.input(node, "Color2", "VECTOR")
    return {"Color": np.where((f == 1.0)[:, None], c1, c2), "Fac": f}


def _tex_gradient(ev, node):
    f = _gradient(ev.vector_or(node, "Vector", "generated"),
                  node.props.get("gradient_type", "LINEAR"))
    return {"Color": np.repeat(f[:, None], 3, 1), "Fac": f}


_TEXCO_KEYS = {"Generated": "generated", "Normal": "normal", "UV": "uv", "Object": "position"}


def _tex_coord(ev, node):
    out = {}
    for sock, key in _TEXCO_KEYS.items():
        if key in ev.inputs:
            out[sock] = ev.hit(key, node)
    return out


def _uv_map(ev, node):
    name = node.props.get("uv_map", "")
    return {"UV": ev.hit(f"uv:{name}" if name and f"uv:{name}" in ev.inputs else "uv", node)}


def _vertex_color(ev, node):
    name = node.props.get("layer_name", "")
    ck = f"color:{name}" if name else "color"
    ak = f"alpha:{name}" if name else "alpha"
    color = ev.hit(ck, node)
    if color.shape[1] == 4:       # RGBA, as export stores colour attributes
        return {"Color": color[:, :3], "Alpha": color[:, 3]}
    out = {"Color": color}
    out["Alpha"] = (np.asarray(ev.inputs[ak], float) if ak in ev.inputs else np.ones(ev.n))
    return out


def _mapping(ev, node):
    kind = node.props.get("vector_type", "POINT")
    v = ev.input(node, "Vector", "VECTOR")
    rot = ev.input(node, "Rotation", "VECTOR")
    scale = ev.input(node, "Scale", "VECTOR")
    m = _euler_matrix(rot)
    if kind == "POINT":
        r = np.einsum("nij,nj->ni", m, v * scale) + ev.input(node, "Location", "VECTOR")
    elif kind == "TEXTURE":
        r = _safe_div(np.einsum("nji,nj->ni", m, v - ev.input(node, "Location", "VECTOR")),
                      scale)
    elif kind == "VECTOR":
        r = np.einsum("nij,nj->ni", m, v * scale)
    else:
        r = _normalize(np.einsum("nij,nj->ni", m, _safe_div(v, scale)))
    return {"Vector": r}


def _tex_image(ev, node):
    p = node.props
    name = p.get("image")
    if name is None or name not in ev.g.images:
        return {"Color": np.broadcast_to(MISSING_RGBA[:3], (ev.n, 3)).copy(),
                "Alpha": np.ones(ev.n)}
    if p.get("projection", "FLAT") != "FLAT":
        raise UnsupportedNode(node.type, node.name, f"projection {p['projection']}")
    co = ev.vector_or(node, "Vector", "uv")
    rgba = image_lookup(ev.g.images[name], co[:, 0], co[:, 1],
                        p.get("interpolation", "Linear"), p.get("extension", "REPEAT"))
    return {"Color": rgba[:, :3], "Alpha": rgba[:, 3]}


# ---------------------------------------------------------------------------------------------
# Procedural textures (engine/procedural.py), input nodes, curves, normal map, bump

_F32 = np.float32


def _tex_points(ev, node, dims: str):
    """(N, d) float32 texture-space points: Vector and W times Scale, as Cycles forms them."""
    vec = ev.vector_or(node, "Vector", "generated").astype(_F32)
    scale = ev.input(node, "Scale", "VALUE").astype(_F32)
    vec = vec * scale[:, None]
    if dims == "1D" or dims == "4D":
        w = ev.input(node, "W", "VALUE").astype(_F32) * scale
        return w[:, None] if dims == "1D" else np.concatenate([vec, w[:, None]], 1)
    return vec[:, :2] if dims == "2D" else vec


def _tex_noise(ev, node):
    p = node.props
    dims = p.get("noise_dimensions", "3D")
    kind = p.get("noise_type", "FBM")
    if kind not in procedural.NOISE_TYPES:
        raise UnsupportedNode(node.type, node.name, f"noise type {kind}")
    pts = _tex_points(ev, node, dims)
    args = {k.lower(): ev.input(node, k, "VALUE") for k in ("Detail", "Roughness", "Lacunarity",
                                                           "Offset", "Gain", "Distortion")}
    fac, col = procedural.noise_texture(pts, kind, normalize=bool(p.get("normalize", True)),
                                        **args)
    return {"Fac": fac.astype(float), "Color": col.astype(float)}


def _tex_voronoi(ev, node):
    p = node.props
    dims = p.get("voronoi_dimensions", "3D")
    feature = p.get("feature", "F1")
    if feature not in procedural.VORONOI_FEATURES:
        raise UnsupportedNode(node.type, node.name, f"feature {feature}")
    pts = _tex_points(ev, node, dims)
    args = {k.lower(): ev.input(node, k, "VALUE") for k in (
        "Scale", "Detail", "Roughness", "Lacunarity", "Smoothness", "Exponent", "Randomness")}
    r = procedural.voronoi_texture(pts, feature, p.get("distance", "EUCLIDEAN"),
                                   normalize=bool(p.get("normalize", False)), **args)
    n = ev.n
    out = {"Distance": np.zeros(n), "Color": np.zeros((n, 3)), "Position": np.zeros((n, 3)),
           "W": np.zeros(n), "Radius": np.zeros(n)}
    for k in ("Distance", "Radius", "Color"):
        if k in r:
            out[k] = r[k].astype(float)
    if "Position" in r:
        pos = r["Position"].astype(float)
        if dims == "1D":
            out["W"] = pos[:, 0]
        else:
            out["Position"][:, :min(3, pos.shape[1])] = pos[:, :3]
            if dims == "4D":
                out["W"] = pos[:, 3]
    return out


def _tex_wave(ev, node):
    p = node.props
    pts = _tex_points(ev, node, "3D")
    f = procedural.wave_texture(
        pts, p.get("wave_type", "BANDS"), p.get("bands_direction", "X"),
        p.get("rings_direction", "X"), p.get("wave_profile", "SIN"),
        *(ev.input(node, k, "VALUE") for k in ("Distortion", "Detail", "Detail Scale",
                                                "Detail Roughness", "Phase Offset")))
    f = f.astype(float)
    return {"Fac": f, "Color": np.repeat(f[:, None], 3, 1)}


def fresnel_dielectric_cos(cosi, eta):
    """Unpolarised dielectric Fresnel reflectance for cos(incidence) and relative IOR eta
    (Cycles' fresnel_dielectric_cos: 1 under total internal reflection)."""
    c = np.abs(cosi)
    g = eta * eta - 1.0 + c * c
    ok = g > 0
    g = np.sqrt(np.where(ok, g, 1.0))
    with np.errstate(**_ERR):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(ok, f, 1.0)


def _normal_in(ev, node):
    """A Normal input when linked, else the shading normal (Cycles' sd->N)."""
    if (node.name, "Normal") in ev.g.links:
        return ev.input(node, "Normal", "VECTOR")
    return ev.hit("normal_world", node)


def _backfacing(ev, node):
    return np.asarray(ev.hit("backfacing", node), float).reshape(ev.n) > 0.5


def _fresnel(ev, node):
    n = _normal_in(ev, node)
    eta = np.maximum(ev.input(node, "IOR", "VALUE"), 1e-5)
    eta = np.where(_backfacing(ev, node), 1.0 / eta, eta)
    return {"Fac": fresnel_dielectric_cos(_dot(ev.hit("incoming", node), n), eta)}


def _layer_weight(ev, node):
    n = _normal_in(ev, node)
    blend = ev.input(node, "Blend", "VALUE")
    cos = _dot(ev.hit("incoming", node), n)
    eta = np.maximum(1.0 - blend, 1e-5)
    eta = np.where(_backfacing(ev, node), eta, 1.0 / eta)
    fres = fresnel_dielectric_cos(cos, eta)
    b = np.clip(blend, 0.0, 1.0 - 1e-5)
    b = np.where(b < 0.5, 2.0 * b, 0.5 / (1.0 - b))
    f = np.abs(cos)
    with np.errstate(**_ERR):
        facing = 1.0 - np.where(blend != 0.5, np.power(f, b), f)
    return {"Fresnel": fres, "Facing": facing}


_GEOMETRY_KEYS = {"Position": "position_world", "Normal": "normal_world",
                  "True Normal": "true_normal_world", "Incoming": "incoming",
                  "Backfacing": "backfacing"}


def _geometry(ev, node):
    out = {}
    for sock, key in _GEOMETRY_KEYS.items():
        if key in ev.inputs:
            v = ev.hit(key, node)
            out[sock] = v.reshape(ev.n) if sock == "Backfacing" else v
    return out


def _hair_info(ev, node):
    """Cycles' Curves Info (``ShaderNodeHairInfo``) from the per-hit ``"hair"`` input
    (intercept, length [m], thickness [m], random; zeros off hair: Is Strand 0, as Cycles on
    a mesh). Tangent Normal is not given (reported as an unsupported output)."""
    a = ev.hit("hair", node)
    return {"Is Strand": (a[:, 1] > 0).astype(float), "Intercept": a[:, 0],
            "Length": a[:, 1], "Thickness": a[:, 2], "Random": a[:, 3]}


def _attribute(ev, node):
    p = node.props
    if p.get("attribute_type", "GEOMETRY") != "GEOMETRY":
        raise UnsupportedNode(node.type, node.name,
                              f"attribute type {p.get('attribute_type')}")
    name = p.get("attribute_name", "")
    for key in (f"attr:{name}", f"uv:{name}", f"color:{name}"):
        if key in ev.inputs:
            break
    else:
        raise MissingInput(f"node {node.type} '{node.name}' needs the per-hit input "
                           f"'attr:{name}'")
    a = np.asarray(ev.inputs[key], float)
    if a.ndim == 1:
        vec, fac, alpha = np.repeat(a[:, None], 3, 1), a, np.ones(ev.n)
    elif a.shape[1] == 2:
        vec = np.concatenate([a, np.zeros((ev.n, 1))], 1)
        fac, alpha = a[:, 0], np.ones(ev.n)
    else:
        vec = a[:, :3]
        fac = vec.mean(1)
        alpha = a[:, 3] if a.shape[1] == 4 else np.asarray(
            ev.inputs.get(f"alpha:{name}", np.ones(ev.n)), float)
    return {"Color": vec, "Vector": vec, "Fac": fac, "Alpha": alpha}


# What a camera ray gives (Cycles' path flags at the first hit: PATH_RAY_CAMERA only)
LIGHT_PATH_CAMERA = {"Is Camera Ray": 1.0, "Is Shadow Ray": 0.0, "Is Diffuse Ray": 0.0,
                     "Is Glossy Ray": 0.0, "Is Singular Ray": 0.0, "Is Reflection Ray": 0.0,
                     "Is Transmission Ray": 0.0, "Is Volume Scatter Ray": 0.0,
                     "Ray Depth": 0.0, "Diffuse Depth": 0.0, "Glossy Depth": 0.0,
                     "Transparent Depth": 0.0, "Transmission Depth": 0.0, "Portal Depth": 0.0}


def _light_path(ev, node):
    out = {}
    for sock in node.outputs:
        key = f"ray:{sock}"
        if key in ev.inputs:
            out[sock] = np.broadcast_to(np.asarray(ev.inputs[key], float), (ev.n,)).copy()
        elif sock in LIGHT_PATH_CAMERA:
            out[sock] = np.full(ev.n, LIGHT_PATH_CAMERA[sock])
    return out


def curve_lookup(table, x, extrapolate: bool):
    """Cycles' float_ramp_lookup of a curve table (M,) at x (N,): linear between entries at
    positions i / (M - 1); outside [0, 1] clamped, or extended along the end segments."""
    table = np.asarray(table, float)
    m = table.shape[0]
    x = np.asarray(x, float)
    f = np.clip(np.nan_to_num(x), 0.0, 1.0) * (m - 1)
    i = np.clip(f.astype(int), 0, m - 1)
    t = f - i
    a = table[i]
    a = np.where(t > 0, (1.0 - t) * a + t * table[np.minimum(i + 1, m - 1)], a)
    if extrapolate:
        lo = table[0] + (table[0] - table[1]) * (-x) * (m - 1)
        hi = table[-1] + (table[-1] - table[-2]) * (x - 1.0) * (m - 1)
        a = np.where(x < 0, lo, np.where(x > 1, hi, a))
    return a


def _curve_pos(node, v):
    lo, hi = float(node.props["min_x"]), float(node.props["max_x"])
    with np.errstate(**_ERR):
        return (v - lo) / (hi - lo)


def _rgb_curves(ev, node, vec_in="Color", out="Color"):
    p = node.props
    if "table" not in p:
        raise UnsupportedNode(node.type, node.name, "no curve table (export it with bpy)")
    table = np.asarray(p["table"], float)
    c = ev.input(node, vec_in, "VECTOR")
    fac = ev.input(node, "Fac", "VALUE")[:, None]
    rel = _curve_pos(node, c)
    ext = bool(p.get("extrapolate", False))
    mapped = np.stack([curve_lookup(table[:, k], rel[:, k], ext) for k in range(3)], -1)
    return {out: (1.0 - fac) * c + fac * mapped}


def _vector_curves(ev, node):
    return _rgb_curves(ev, node, "Vector", "Vector")


def _float_curve(ev, node):
    p = node.props
    if "table" not in p:
        raise UnsupportedNode(node.type, node.name, "no curve table (export it with bpy)")
    v = ev.input(node, "Value", "VALUE")
    fac = ev.input(node, "Factor", "VALUE")
    m = curve_lookup(np.asarray(p["table"], float).reshape(-1), _curve_pos(node, v),
                     bool(p.get("extrapolate", False)))
    return {"Value": (1.0 - fac) * v + fac * m}


def _transform_normals(ev, node, n):
    """Object-space normals to world space (Cycles' object_normal_transform: normalised)."""
    m = ev.inputs.get("normal_matrix")
    if m is None:
        raise MissingInput(f"node {node.type} '{node.name}' needs the per-hit input "
                           "'normal_matrix'")
    return _normalize(np.einsum("nij,nj->ni", np.broadcast_to(np.asarray(m, float),
                                                               (ev.n, 3, 3)), n))


def _normal_map(ev, node):
    p = node.props
    space = p.get("space", "TANGENT")
    c = 2.0 * (ev.input(node, "Color", "VECTOR") - 0.5)
    if p.get("convention", "OPENGL") == "DIRECTX":
        c[:, 1] = -c[:, 1]
    strength = ev.input(node, "Strength", "VALUE")
    back = _backfacing(ev, node)
    sd_n = ev.hit("normal_world", node)
    if space == "TANGENT":
        name = p.get("uv_map", "")
        key = f"tangent:{name}" if name else "tangent"
        t4 = np.asarray(ev.hit(key, node) if key in ev.inputs else ev.hit("tangent", node),
                        float)
        tangent, sign = t4[:, :3], t4[:, 3]
        normal = ev.hit("normal", node) * np.where(back, -1.0, 1.0)[:, None]
        c[:, 0] *= strength
        c[:, 1] *= strength
        c[:, 2] = 1.0 + np.clip(strength, 0.0, 1.0) * (c[:, 2] - 1.0)
        b = sign[:, None] * np.cross(normal, tangent)
        n = _normalize(c[:, :1] * tangent + c[:, 1:2] * b + c[:, 2:] * normal)
        n = _transform_normals(ev, node, n)
    else:
        if space in ("BLENDER_OBJECT", "BLENDER_WORLD"):
            c[:, 1:] = -c[:, 1:]
        n = (_transform_normals(ev, node, c) if space in ("OBJECT", "BLENDER_OBJECT")
             else _normalize(c))
        s = np.maximum(strength, 0.0)[:, None]
        n = np.where(strength[:, None] != 1.0, _normalize(sd_n + (n - sd_n) * s), n)
    n = np.where(back[:, None], -n, n)
    return {"Normal": np.where(np.all(n == 0, axis=1)[:, None], sd_n, n)}


def _bump(ev, node):
    n_in = _normal_in(ev, node)
    fw = ev.input(node, "Filter Width", "VALUE")
    dpdx, dpdy = ev.hit("dPdx", node), ev.hit("dPdy", node)
    h_c = ev.input(node, "Height", "VALUE")
    if (node.name, "Height") in ev.g.links:
        h_x = ev.shifted("x", fw).input(node, "Height", "VALUE")
        h_y = ev.shifted("y", fw).input(node, "Height", "VALUE")
    else:
        h_x = h_y = h_c
    rx = np.cross(dpdy, n_in)
    ry = np.cross(n_in, dpdx)
    det = _dot(dpdx, rx)
    surfgrad = (h_x - h_c)[:, None] * rx + (h_y - h_c)[:, None] * ry
    strength = np.maximum(ev.input(node, "Strength", "VALUE"), 0.0)[:, None]
    scale = ev.input(node, "Distance", "VALUE") * (-1.0 if node.props.get("invert") else 1.0)
    out = _normalize((fw * np.abs(det))[:, None] * n_in
                     - (scale * np.sign(det))[:, None] * surfgrad)
    zero = np.all(out == 0, axis=1)[:, None]
    return {"Normal": np.where(zero, n_in,
                               _normalize(strength * out + (1.0 - strength) * n_in))}


_NODE_FUNCS = {
    "ShaderNodeValue": _value, "ShaderNodeRGB": _rgb, "NodeReroute": _reroute,
    "ShaderNodeMath": _math, "ShaderNodeVectorMath": _vector_math,
    "ShaderNodeMapRange": _map_range, "ShaderNodeClamp": _clamp, "ShaderNodeMix": _mix,
    "ShaderNodeMixRGB": _mix_rgb, "ShaderNodeInvert": _invert, "ShaderNodeGamma": _gamma,
    "ShaderNodeBrightContrast": _bright_contrast, "ShaderNodeHueSaturation": _hue_sat,
    "ShaderNodeRGBToBW": _rgb_to_bw, "ShaderNodeSeparateColor": _separate_color,
    "ShaderNodeCombineColor": _combine_color, "ShaderNodeSeparateXYZ": _separate_xyz,
    "ShaderNodeCombineXYZ": _combine_xyz, "ShaderNodeValToRGB": _color_ramp,
    "ShaderNodeTexChecker": _tex_checker, "ShaderNodeTexGradient": _tex_gradient,
    "ShaderNodeTexCoord": _tex_coord, "ShaderNodeUVMap": _uv_map,
    "ShaderNodeVertexColor": _vertex_color, "ShaderNodeMapping": _mapping,
    "ShaderNodeTexImage": _tex_image, "ShaderNodeTexNoise": _tex_noise,
    "ShaderNodeTexVoronoi": _tex_voronoi, "ShaderNodeTexWave": _tex_wave,
    "ShaderNodeFresnel": _fresnel, "ShaderNodeLayerWeight": _layer_weight,
    "ShaderNodeNewGeometry": _geometry, "ShaderNodeAttribute": _attribute,
    "ShaderNodeHairInfo": _hair_info,
    "ShaderNodeLightPath": _light_path, "ShaderNodeRGBCurve": _rgb_curves,
    "ShaderNodeVectorCurve": _vector_curves, "ShaderNodeFloatCurve": _float_curve,
    "ShaderNodeNormalMap": _normal_map, "ShaderNodeBump": _bump,
}


class Evaluator:
    """The values of a graph's sockets for one batch of N hits, each node computed once
    however many sockets ask for it (the closure inputs of one material read one graph)."""

    def __init__(self, graph: Graph, inputs, n: int | None = None):
        if n is None:
            n = next((len(v) for v in inputs.values()), 1)
        self.n = n
        self._ev = _Eval(graph, inputs, n)

    def value(self, socket: tuple) -> np.ndarray:
        """As :func:`evaluate` (a fresh array the caller may change)."""
        out = self._ev.output(*socket)
        if out is None:
            raise MissingInput(f"output {socket} has no value")
        return np.array(out, float)


def evaluate(graph: Graph, socket: tuple, inputs: dict, n: int | None = None) -> np.ndarray:
    """The value reaching output ``socket`` = (node name, output identifier) for N hits:
    (N,) for a float socket, (N, 3) for a vector or colour. ``inputs`` holds the per-hit
    coordinates (module docstring); ``n`` is taken from them when not given. Raises
    :class:`UnsupportedNode` for a node outside ``SUPPORTED`` on the path, and
    :class:`MissingInput` when a needed coordinate is absent."""
    return Evaluator(graph, inputs, n).value(socket)


def image_bytes(graphs) -> int:
    """Bytes of the texels of the distinct images the ``graphs`` (None entries skipped) hold,
    each image counted once however many graphs share it."""
    seen = {}
    for graph in graphs:
        for image in (graph.images.values() if graph is not None else ()):
            seen[id(image)] = image.nbytes
    return int(sum(seen.values()))
