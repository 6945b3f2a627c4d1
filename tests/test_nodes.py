"""The shader-node evaluator (``engine/nodes.py``) against Cycles' own bakes, and its formulas
at edge values (issue 24; no bpy, no Cycles at test time).

``tests/data/node_bakes/node_bakes.npz`` holds, per case, an Emission-only plane's Cycles bake
(32 x 32 texels, made by ``tests/data/make_node_bakes.py``) and the node tree as
``engine/blender/node_export.py`` exported it; the evaluator, fed the coordinates Cycles baked
at the same texels, must agree within the issue's bounds: 1/255 for cases reading 8-bit images,
1e-4 relative (plus 1e-6 absolute, float32 noise near zero) for everything else. A planted bug
(two blend modes swapped) must make the comparison fail, so a comparison that cannot fail does
not pass for agreement.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lanterna.engine import nodes as N

BAKES = Path(__file__).resolve().parent / "data" / "node_bakes" / "node_bakes.npz"


@pytest.fixture(scope="module")
def bakes():
    d = np.load(BAKES)
    data = {k: d[k] for k in d.files}
    images = {k.split("/", 1)[1]: v for k, v in data.items() if k.startswith("image/")}
    inputs = {"uv": data["coord/UV"].reshape(-1, 3)[:, :2],
              "position": data["coord/Object"].reshape(-1, 3),
              "generated": data["coord/Generated"].reshape(-1, 3),
              "normal": data["coord/Normal"].reshape(-1, 3)}
    return data, images, inputs


def _names():
    with np.load(BAKES) as d:
        return sorted(k.split("/")[1] for k in d.files if k.endswith("/bake"))


def _compare(data, images, inputs, name):
    graph = N.graph_from_dict(json.loads(str(data[f"case/{name}/graph"])), images)
    value = N.evaluate(graph, tuple(str(s) for s in data[f"case/{name}/socket"]), inputs)
    if value.ndim == 1:
        value = np.repeat(value[:, None], 3, 1)
    ref = data[f"case/{name}/bake"].reshape(-1, 3).astype(float)
    both_nan = np.isnan(ref) & np.isnan(value)
    err = np.where(both_nan, 0.0, np.abs(value - ref))
    err = np.where(np.isnan(err), np.inf, err)
    eight_bit = name.startswith(("image_srgb8", "image_noncolor8"))
    bound = np.full(ref.shape, 1.0 / 255.0) if eight_bit else 1e-4 * np.abs(ref) + 1e-6
    return err, bound


@pytest.mark.parametrize("name", _names())
def test_node_matches_cycles_bake(bakes, name):
    err, bound = _compare(*bakes, name)
    worst = np.unravel_index(np.argmax(err - bound), err.shape)
    assert np.all(err <= bound), (f"{name}: {np.sum(err > bound)} texels out of bound, worst "
                                  f"error {err[worst]:.3g} (bound {bound[worst]:.3g})")


def test_planted_bug_is_caught(bakes, monkeypatch):
    """Swapping SCREEN and MULTIPLY must break both cases' agreement."""
    real = N.mix_color
    swap = {"SCREEN": "MULTIPLY", "MULTIPLY": "SCREEN"}
    monkeypatch.setattr(N, "mix_color", lambda b, *a: real(swap.get(b, b), *a))
    for name in ("mix_SCREEN", "mix_MULTIPLY"):
        err, bound = _compare(*bakes, name)
        assert np.any(err > bound), name


def test_bake_coordinates_are_near_texel_centres(bakes):
    """The bake samples ~0.001 texel off the centres (measured); the test uses its coords."""
    data, _, inputs = bakes
    s = int(data["size"])
    u = inputs["uv"][:s, 0] * s - (np.arange(s) + 0.5)
    v = inputs["uv"][::s, 1] * s - (np.arange(s) + 0.5)
    assert np.all(np.abs(u) < 0.01) and np.all(np.abs(v) < 0.01)


def test_exported_pixels_are_what_was_written(bakes):
    """Image.pixels of an 8-bit sRGB PNG gives bytes / 255, not linearised (measured)."""
    data, images, _ = bakes
    for name in ("srgb8", "noncolor8", "float"):
        assert np.allclose(images[name], data[f"image_written/{name}"], atol=1e-6), name
    assert str(data["image_encoding/srgb8"]) == "srgb"
    assert str(data["image_encoding/noncolor8"]) == "linear"
    assert str(data["image_encoding/float"]) == "linear"


# ---------------------------------------------------------------------------------------------
# Formulas at edge values

def _m(op, a, b=0.0, c=0.0, clamp=False):
    return N.math_op(op, np.atleast_1d(np.asarray(a, float)), b, c, clamp)


def test_math_safe_operations():
    assert _m("DIVIDE", 1.0, 0.0)[0] == 0.0
    assert _m("MODULO", 5.0, 0.0)[0] == 0.0
    assert _m("MODULO", -5.5, 2.0)[0] == pytest.approx(-1.5)          # fmod keeps the sign
    assert _m("FLOORED_MODULO", -5.5, 2.0)[0] == pytest.approx(0.5)
    assert _m("POWER", -2.0, 0.5)[0] == 0.0 and _m("POWER", -2.0, 3.0)[0] == -8.0
    assert _m("LOGARITHM", -1.0, 2.0)[0] == 0.0 and _m("LOGARITHM", 8.0, 2.0)[0] == 3.0
    assert _m("SQRT", -4.0)[0] == 0.0
    assert _m("ARCSINE", 2.0)[0] == pytest.approx(np.pi / 2)
    assert _m("SNAP", 1.0, 0.0)[0] == 0.0
    assert _m("SIGN", [-3.0, 0.0, 2.0]).tolist() == [-1.0, 0.0, 1.0]
    assert _m("ROUND", [-0.5, 0.5, 1.49]).tolist() == [0.0, 1.0, 1.0]
    assert _m("TRUNC", [-1.7, 1.7]).tolist() == [-1.0, 1.0]
    assert _m("MULTIPLY", 3.0, 2.0, clamp=True)[0] == 1.0


def test_math_wrap_pingpong_compare_smooth():
    assert _m("WRAP", 1.25, 1.0, 0.0)[0] == pytest.approx(0.25)
    assert _m("WRAP", -0.25, 1.0, 0.0)[0] == pytest.approx(0.75)
    assert _m("WRAP", 3.0, 2.0, 2.0)[0] == 2.0                        # empty range: min
    assert _m("PINGPONG", [0.5, 1.5, 2.5], 1.0).tolist() == pytest.approx([0.5, 0.5, 0.5])
    assert _m("PINGPONG", 3.0, 0.0)[0] == 0.0
    assert _m("COMPARE", 1.0, 1.0 + 1e-8, 0.0)[0] == 1.0              # FLT_EPSILON floor
    assert _m("COMPARE", 1.0, 1.2, 0.1)[0] == 0.0
    assert _m("SMOOTH_MIN", 1.0, 1.0, 0.0)[0] == 1.0
    assert _m("SMOOTH_MIN", 1.0, 1.0, 0.6)[0] == pytest.approx(1.0 - 0.1)
    assert _m("SMOOTH_MAX", 1.0, 1.0, 0.6)[0] == pytest.approx(1.0 + 0.1)


def test_vector_math_edges():
    z, one = np.zeros((1, 3)), np.ones((1, 3))
    s = np.ones(1)
    assert np.all(N.vector_math_op("NORMALIZE", z, z, z, s)[0] == 0)
    assert np.all(N.vector_math_op("DIVIDE", one, z, z, s)[0] == 0)
    assert np.all(N.vector_math_op("PROJECT", one, z, z, s)[0] == 0)
    r = N.vector_math_op("REFRACT", np.array([[1.0, 0, -0.1]]), np.array([[0, 0, 1.0]]), z,
                         np.array([1.5]))[0]
    assert np.all(r == 0)                                             # total internal reflection
    assert N.vector_math_op("LENGTH", np.array([[3.0, 4.0, 0]]), z, z, s)[1][0] == 5.0


def test_hsv_hsl_round_trip_and_edges():
    rgb = np.array([[0.2, 0.5, 0.9], [0.3, 0.3, 0.3], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                    [0.9, 0.2, 0.6]])
    assert np.allclose(N.hsv_to_rgb(N.rgb_to_hsv(rgb)), rgb)
    assert np.allclose(N.hsl_to_rgb(N.rgb_to_hsl(rgb)), rgb)
    assert np.all(N.rgb_to_hsv(rgb[1:3])[:, :2] == 0)                 # greys: no hue
    assert np.allclose(N.hsv_to_rgb(np.array([[1.0, 1.0, 1.0]])), [[1.0, 0.0, 0.0]])  # h=1 as 0


def _mix(blend, t, a, b):
    return N.mix_color(blend, np.array([t]), np.array([a], float), np.array([b], float))[0]


def test_blend_modes_at_edges():
    a, b = [0.2, 0.6, 0.0], [0.5, 0.0, 1.0]
    assert np.allclose(_mix("MIX", 0.0, a, b), a) and np.allclose(_mix("MIX", 1.0, a, b), b)
    assert np.allclose(_mix("MULTIPLY", 1.0, a, b), [0.1, 0.0, 0.0])
    assert np.allclose(_mix("SCREEN", 1.0, a, b), [0.6, 0.6, 1.0])
    assert np.allclose(_mix("DIVIDE", 1.0, a, b), [0.4, 0.6, 0.0])   # /0 keeps the channel
    assert np.allclose(_mix("DODGE", 1.0, a, b), [0.4, 0.6, 0.0])    # 0 stays 0, 1-t*b=0 -> 1
    assert np.allclose(_mix("DODGE", 1.0, [0.5, 0.5, 0.5], [1.0, 0.8, 0.0]), [1.0, 1.0, 0.5])
    assert np.allclose(_mix("BURN", 1.0, [0.5, 0.5, 0.5], [0.0, 0.8, 1.0]), [0.0, 0.375, 0.5])
    assert np.allclose(_mix("EXCLUSION", 1.0, [2.0, 0.5, 0], [1.0, 0.5, 0]), [0.0, 0.5, 0.0])
    assert np.allclose(_mix("OVERLAY", 1.0, [0.25, 0.75, 0.5], [1.0, 0.0, 0.5]),
                       [0.5, 0.5, 0.5])
    assert np.allclose(_mix("LINEAR_LIGHT", 1.0, a, b), [0.2, -0.4, 1.0])
    assert np.allclose(_mix("SOFT_LIGHT", 0.0, a, b), a)
    assert np.allclose(_mix("HUE", 1.0, a, [0.5, 0.5, 0.5]), a)      # grey B: no hue to take
    assert np.allclose(_mix("SATURATION", 1.0, [0.4, 0.4, 0.4], b), [0.4, 0.4, 0.4])
    assert np.allclose(_mix("VALUE", 1.0, [0.5, 0.25, 0.0], [0.0, 0.0, 1.0]), [1.0, 0.5, 0.0])
    assert np.allclose(_mix("COLOR", 1.0, [0.5, 0.5, 0.5], [1.0, 0.0, 0.0]), [0.5, 0.0, 0.0])


def test_srgb_and_image_lookup():
    assert N.srgb_to_linear(np.array([0.0, 1.0, -0.5]))[[0, 1, 2]].tolist() == [0.0, 1.0, 0.0]
    lo, hi = N.srgb_to_linear(np.array([0.04045 - 1e-9, 0.04045]))
    assert hi == pytest.approx(lo, rel=1e-5)                          # continuous at the knee
    px = np.zeros((2, 4, 4), np.float32)
    px[0, :, 0] = [0.0, 1.0, 2.0, 3.0]                               # bottom row
    px[1, :, 0] = 10.0
    im = N.Image(px, "linear")
    x, y = np.array([0.125, 0.375, 1.125, -0.1]), np.array([0.25, 0.25, 0.25, 0.25])
    assert N.image_lookup(im, x, y, "Closest")[:, 0].tolist() == [0.0, 1.0, 0.0, 3.0]
    assert N.image_lookup(im, x, y, "Closest", "CLIP")[:, 0].tolist() == [0.0, 1.0, 0.0, 0.0]
    assert N.image_lookup(im, x, y, "Closest", "EXTEND")[:, 0].tolist() == [0.0, 1.0, 3.0, 0.0]
    mid = N.image_lookup(im, np.array([0.25]), np.array([0.25]), "Linear")[0, 0]
    assert mid == pytest.approx(0.5)                                  # between centres 0 and 1
    flat = N.Image(np.full((3, 3, 4), 0.5, np.float32), "linear")
    assert np.allclose(N.image_lookup(flat, np.array([0.3]), np.array([0.7]), "Cubic"), 0.5)


def test_checker_gradient_ramp_maprange_edges():
    p = np.array([[1.0, 0.0, 0.0], [0.999, 0.0, 0.0], [-0.5, 0.0, 0.0]])
    assert N._checker(p).tolist() == [0.0, 0.0, 1.0]    # x = 1 is nudged into cell 0, as Cycles
    assert N._gradient(np.array([[1.0, 0.0, 0.0]]), "SPHERICAL")[0] == 0.0
    table = N.ramp_table([(0.5, (1, 0, 0, 1)), (0.0, (0, 0, 1, 1))], "CONSTANT")
    assert np.allclose(table[0], [0, 0, 1, 1]) and np.allclose(table[-1], [1, 0, 0, 1])
    g = N.Graph({"v": N.Node("ShaderNodeValue", "v", {"value": 0.5}, {}, {"Value": "VALUE"}),
                 "m": N.Node("ShaderNodeMapRange", "m", {"interpolation_type": "LINEAR"},
                             {k: ("VALUE", d) for k, d in (("Value", 0.5), ("From Min", 1.0),
                                                           ("From Max", 1.0), ("To Min", 0.0),
                                                           ("To Max", 1.0), ("Steps", 4.0))},
                             {"Result": "VALUE", "Vector": "VECTOR"})})
    g.links[("m", "Value")] = ("v", "Value")
    assert N.evaluate(g, ("m", "Result"), {}, n=2).tolist() == [0.0, 0.0]  # empty from-range


def test_unsupported_and_missing_are_named():
    g = N.Graph({"n": N.Node("ShaderNodeTexNoise", "Noise.001", {}, {}, {"Fac": "VALUE"}),
                 "c": N.Node("ShaderNodeTexCoord", "tc", {}, {}, {"UV": "VECTOR"})})
    with pytest.raises(N.UnsupportedNode, match="unsupported node ShaderNodeTexNoise "
                                                "'Noise.001'"):
        N.evaluate(g, ("n", "Fac"), {}, n=1)
    with pytest.raises(N.MissingInput, match="uv"):
        N.evaluate(g, ("c", "UV"), {"position": np.zeros((1, 3))})


def test_graph_dict_round_trip(bakes):
    data, images, inputs = bakes
    d = json.loads(str(data["case/image_srgb8_Cubic_MIRROR/graph"]))
    again = json.loads(json.dumps(N.graph_to_dict(N.graph_from_dict(d, images))))
    assert again["nodes"] == d["nodes"] and again["links"] == d["links"]
    assert again["images"] == {"srgb8": "srgb"}             # the bake target had no pixels
