"""Cycles bakes of single shader nodes, the reference for ``tests/test_nodes.py`` (issue 24).

Each case builds a material on a 2 x 2 plane (UVs 0..1, object at the origin) in which a node,
fed by texture coordinates through a few Math / Vector Math nodes, drives an Emission shader
(Strength 1); Cycles bakes the emission (``bpy.ops.object.bake(type='EMIT')``, 1 sample, margin
0) into a SIZE x SIZE float image through the UVs. The node tree is exported with
``engine/blender/node_export.py`` and stored as JSON next to the bake, so the test evaluates
exactly what was baked without Blender.

The coordinates the bake saw are baked too (UV, Object, Generated, Normal): Cycles' bake
rasteriser does not sample at exact texel centres (measured on Blender 5.2.3: u is
(i + 0.5 + 0.001) / SIZE, v is (j + 0.5 + 0.002) / SIZE), so the test evaluates at the baked
coordinates, not at ideal ones.

The plane also carries three point attributes linear in the vertex position (``ATTRIBUTES``),
and the bake stores the Geometry node's outputs at the texels (world position, normal, true
normal, incoming direction, backfacing), the plane's MikkTSpace tangent for "UVMap" and the
object matrix (identity), so that the test has every per-hit input the nodes read.

Run: ``PYTHONPATH=<dir holding lanterna> nice .venv/bin/python tests/data/make_node_bakes.py``
(about a minute); writes ``tests/data/node_bakes/node_bakes.npz``.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np

from lanterna.engine.blender import node_export
from lanterna.engine import nodes as N

SIZE = 32
OUT = Path(__file__).resolve().parent / "node_bakes" / "node_bakes.npz"

# Geometry attributes on the plane's vertices, each component a + b x + c y of the vertex
# position: barycentric interpolation reproduces a linear function exactly, so the test computes
# the per-hit "attr:<name>" from the baked position instead of trusting another bake.
ATTRIBUTES = {
    "f_attr": ("FLOAT", [[0.3, 0.5, -0.2]]),
    "v_attr": ("FLOAT_VECTOR", [[0.1, 1.2, 0.0], [-0.4, 0.0, 0.9], [0.5, 0.3, 0.3]]),
    "c_attr": ("FLOAT_COLOR", [[0.5, 0.4, 0.0], [0.5, 0.0, 0.45], [0.3, 0.2, 0.2],
                               [0.6, -0.3, 0.1]]),
}
# Per-hit inputs baked through a Geometry node (the Emission shows the vector; Backfacing as
# grey): world position, shading and true normals, the incoming direction (towards the viewer,
# Cycles' sd->wi) and the backfacing flag.
GEOMETRY = ("Position", "Normal", "True Normal", "Incoming", "Backfacing")
LIGHT_PATH = ("Is Camera Ray", "Is Shadow Ray", "Is Diffuse Ray", "Is Glossy Ray",
              "Is Singular Ray", "Is Reflection Ray", "Is Transmission Ray",
              "Is Volume Scatter Ray", "Ray Length", "Ray Depth", "Diffuse Depth",
              "Glossy Depth", "Transparent Depth", "Transmission Depth", "Portal Depth")


def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 1
    sc.render.bake.margin = 0
    bpy.ops.mesh.primitive_plane_add(size=2)
    ob = bpy.context.active_object
    mat = bpy.data.materials.new("bake")
    ob.data.materials.append(mat)
    target = bpy.data.images.new("target", SIZE, SIZE, float_buffer=True)
    me = ob.data
    xy = np.array([v.co[:2] for v in me.vertices])
    for name, (kind, coeffs) in ATTRIBUTES.items():
        c = np.asarray(coeffs, float)
        vals = c[:, 0] + xy @ c[:, 1:].T                  # (V, components)
        at = me.attributes.new(name, kind, "POINT")
        key = "value" if kind == "FLOAT" else "color" if kind == "FLOAT_COLOR" else "vector"
        at.data.foreach_set(key, (vals[:, 0] if kind == "FLOAT" else vals).ravel())
    return ob, mat, target


class Ctx:
    """Node-building helpers on a material tree emptied for one case."""

    def __init__(self, mat, target):
        nt = mat.node_tree
        nt.nodes.clear()
        self.nt = nt
        self.out = nt.nodes.new("ShaderNodeOutputMaterial")
        self.em = nt.nodes.new("ShaderNodeEmission")
        nt.links.new(self.em.outputs[0], self.out.inputs[0])
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = target
        nt.nodes.active = tex
        self.tc = nt.nodes.new("ShaderNodeTexCoord")

    def node(self, kind, name=None, **props):
        n = self.nt.nodes.new(kind)
        if name:
            n.name = name
        for k, v in props.items():
            setattr(n, k, v)
        return n

    def link(self, src, dst):
        self.nt.links.new(src, dst)

    def sep(self, vec):
        s = self.node("ShaderNodeSeparateXYZ")
        self.link(vec, s.inputs[0])
        return s.outputs

    def affine(self, value, m, a):
        """Math MULTIPLY_ADD value * m + a."""
        n = self.node("ShaderNodeMath", operation="MULTIPLY_ADD")
        self.link(value, n.inputs[0])
        n.inputs[1].default_value, n.inputs[2].default_value = m, a
        return n.outputs[0]

    def vaffine(self, vec, m, a):
        n = self.node("ShaderNodeVectorMath", operation="MULTIPLY_ADD")
        self.link(vec, n.inputs[0])
        n.inputs[1].default_value, n.inputs[2].default_value = m, a
        return n.outputs[0]

    def colour_a(self):
        """A colour varying over the plane, in [0, 1]: (u, v, 0.3 + 0.4 u v) via UV."""
        return self.vaffine(self.tc.outputs["UV"], (0.9, 0.85, 0.0), (0.05, 0.1, 0.35))

    def colour_b(self):
        return self.vaffine(self.tc.outputs["Object"], (-0.4, 0.45, 0.0), (0.5, 0.5, 0.8))


def cases():
    """name -> builder(ctx) returning the socket that feeds Emission Color."""
    out = {}
    for op in [e.identifier for e in bpy.types.ShaderNodeMath.bl_rna.properties["operation"]
               .enum_items]:
        def b(c, op=op):
            u, v, _ = c.sep(c.tc.outputs["UV"])
            n = c.node("ShaderNodeMath", "op", operation=op)
            c.link(c.affine(u, 4.0, -2.0), n.inputs[0])
            c.link(c.affine(v, 3.0, -1.2), n.inputs[1])
            n.inputs[2].default_value = 0.35
            return n.outputs[0]
        out[f"math_{op}"] = b

    def math_clamp(c):
        u, v, _ = c.sep(c.tc.outputs["UV"])
        n = c.node("ShaderNodeMath", "op", operation="MULTIPLY", use_clamp=True)
        c.link(c.affine(u, 4.0, -2.0), n.inputs[0])
        c.link(c.affine(v, 3.0, -1.2), n.inputs[1])
        return n.outputs[0]
    out["math_clamp"] = math_clamp

    for op in [e.identifier for e in bpy.types.ShaderNodeVectorMath.bl_rna
               .properties["operation"].enum_items]:
        def b(c, op=op):
            n = c.node("ShaderNodeVectorMath", "op", operation=op)
            c.link(c.vaffine(c.tc.outputs["UV"], (4.0, 3.0, 1.0), (-2.0, -1.5, 0.5)),
                   n.inputs[0])
            c.link(c.vaffine(c.tc.outputs["Object"], (-1.3, 2.1, 1.0), (0.4, -0.2, 0.7)),
                   n.inputs[1])
            n.inputs[2].default_value = (0.5, 1.5, -0.5)
            n.inputs[3].default_value = 0.7
            scalar = op in ("DOT_PRODUCT", "DISTANCE", "LENGTH")
            return n.outputs["Value" if scalar else "Vector"]
        out[f"vmath_{op}"] = b

    for blend in [e.identifier for e in bpy.types.ShaderNodeMix.bl_rna.properties["blend_type"]
                  .enum_items]:
        def b(c, blend=blend, cf=True, cr=False):
            n = c.node("ShaderNodeMix", "op", data_type="RGBA", blend_type=blend,
                       clamp_factor=cf, clamp_result=cr)
            u, v, _ = c.sep(c.tc.outputs["UV"])
            c.link(c.affine(u, 1.4, -0.2), n.inputs["Factor"])
            c.link(c.colour_a(), n.inputs[6])
            c.link(c.colour_b(), n.inputs[7])
            return n.outputs[2]
        out[f"mix_{blend}"] = b
    out["mix_ADD_clamp_result"] = lambda c: out["mix_ADD"](c, "ADD", True, True)
    out["mix_LINEAR_LIGHT_noclamp"] = lambda c: out["mix_MIX"](c, "LINEAR_LIGHT", False, False)

    def mix_float(c):
        n = c.node("ShaderNodeMix", "op", data_type="FLOAT", clamp_factor=False)
        u, v, _ = c.sep(c.tc.outputs["UV"])
        c.link(c.affine(u, 1.4, -0.2), n.inputs["Factor"])
        c.link(v, n.inputs[2])
        n.inputs[3].default_value = 0.8
        return n.outputs[0]
    out["mix_float"] = mix_float

    def mix_vector(c):
        n = c.node("ShaderNodeMix", "op", data_type="VECTOR", factor_mode="NON_UNIFORM")
        c.link(c.vaffine(c.tc.outputs["UV"], (1.4, 1.2, 0), (-0.2, -0.1, 0.5)), n.inputs[1])
        c.link(c.tc.outputs["Object"], n.inputs[4])
        n.inputs[5].default_value = (0.3, 0.6, 0.9)
        return n.outputs[1]
    out["mix_vector"] = mix_vector

    for interp in ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP"):
        def b(c, interp=interp):
            n = c.node("ShaderNodeMapRange", "op", interpolation_type=interp, clamp=True)
            u, v, _ = c.sep(c.tc.outputs["UV"])
            c.link(c.affine(u, 1.4, -0.2), n.inputs[0])
            n.inputs[1].default_value, n.inputs[2].default_value = 0.1, 0.9
            n.inputs[3].default_value, n.inputs[4].default_value = 0.2, 1.5
            n.inputs[5].default_value = 4.0
            return n.outputs[0]
        out[f"maprange_{interp}"] = b

        def bv(c, interp=interp):
            n = c.node("ShaderNodeMapRange", "op", data_type="FLOAT_VECTOR",
                       interpolation_type=interp, clamp=True)
            c.link(c.vaffine(c.tc.outputs["UV"], (1.4, -1.2, 0), (-0.2, 1.1, 0.5)),
                   n.inputs["Vector"])
            n.inputs[7].default_value = (0.1, 0.2, 0.0)
            n.inputs[8].default_value = (0.9, 0.7, 1.0)
            n.inputs[9].default_value = (0.2, 1.0, 0.0)
            n.inputs[10].default_value = (1.5, 0.1, 1.0)
            n.inputs[11].default_value = (4.0, 3.0, 2.0)
            return n.outputs[1]
        out[f"maprange_vec_{interp}"] = bv

    for ct in ("MINMAX", "RANGE"):
        def b(c, ct=ct):
            n = c.node("ShaderNodeClamp", "op", clamp_type=ct)
            u, v, _ = c.sep(c.tc.outputs["UV"])
            c.link(c.affine(u, 1.4, -0.2), n.inputs[0])
            n.inputs[1].default_value, n.inputs[2].default_value = 0.7, 0.3
            return n.outputs[0]
        out[f"clamp_{ct}"] = b

    def invert(c):
        n = c.node("ShaderNodeInvert", "op")
        n.inputs[0].default_value = 0.7
        c.link(c.colour_a(), n.inputs[1])
        return n.outputs[0]
    out["invert"] = invert

    def gamma(c):
        n = c.node("ShaderNodeGamma", "op")
        c.link(c.colour_a(), n.inputs[0])
        u, v, _ = c.sep(c.tc.outputs["UV"])
        c.link(c.affine(v, 2.0, 0.2), n.inputs[1])
        return n.outputs[0]
    out["gamma"] = gamma

    def bright(c):
        n = c.node("ShaderNodeBrightContrast", "op")
        c.link(c.colour_a(), n.inputs[0])
        n.inputs[1].default_value, n.inputs[2].default_value = 0.1, 0.6
        return n.outputs[0]
    out["bright_contrast"] = bright

    def huesat(c):
        n = c.node("ShaderNodeHueSaturation", "op")
        n.inputs[0].default_value, n.inputs[1].default_value = 0.3, 1.4
        n.inputs[2].default_value, n.inputs[3].default_value = 0.9, 0.8
        c.link(c.colour_a(), n.inputs[4])
        return n.outputs[0]
    out["hue_saturation"] = huesat

    def bw(c):
        n = c.node("ShaderNodeRGBToBW", "op")
        c.link(c.colour_a(), n.inputs[0])
        return n.outputs[0]
    out["rgb_to_bw"] = bw

    def colour_to_float(c):                               # implicit colour -> float
        n = c.node("ShaderNodeMath", "op", operation="MULTIPLY")
        c.link(c.colour_b(), n.inputs[0])
        n.inputs[1].default_value = 1.0
        return n.outputs[0]
    out["implicit_colour_to_float"] = colour_to_float

    for mode in ("RGB", "HSV", "HSL"):
        def b(c, mode=mode):
            s = c.node("ShaderNodeSeparateColor", "op", mode=mode)
            c.link(c.colour_a(), s.inputs[0])
            comb = c.node("ShaderNodeCombineXYZ")
            for i in range(3):
                c.link(s.outputs[i], comb.inputs[i])
            return comb.outputs[0]
        out[f"separate_{mode}"] = b

        def bc(c, mode=mode):
            s = c.node("ShaderNodeCombineColor", "op", mode=mode)
            u, v, _ = c.sep(c.tc.outputs["UV"])
            c.link(u, s.inputs[0])
            c.link(v, s.inputs[1])
            s.inputs[2].default_value = 0.6
            return s.outputs[0]
        out[f"combine_{mode}"] = bc

    for interp in ("CONSTANT", "LINEAR", "EASE", "CARDINAL", "B_SPLINE"):
        for cmode in (("RGB", "HSV") if interp == "LINEAR" else ("RGB",)):
            def b(c, interp=interp, cmode=cmode):
                n = c.node("ShaderNodeValToRGB", "op")
                r = n.color_ramp
                r.interpolation, r.color_mode = interp, cmode
                r.elements[0].position, r.elements[0].color = 0.15, (0.9, 0.1, 0.2, 1.0)
                r.elements[1].position, r.elements[1].color = 0.8, (0.1, 0.3, 0.95, 0.5)
                e = r.elements.new(0.45)
                e.color = (0.2, 0.85, 0.3, 0.8)
                u, v, _ = c.sep(c.tc.outputs["UV"])
                c.link(c.affine(u, 1.2, -0.1), n.inputs[0])
                return n.outputs[0]
            out[f"ramp_{interp}_{cmode}"] = b

    def ramp_alpha(c):
        return out["ramp_LINEAR_RGB"](c).node.outputs[1]
    out["ramp_alpha"] = ramp_alpha

    def checker(c):
        n = c.node("ShaderNodeTexChecker", "op")
        c.link(c.tc.outputs["UV"], n.inputs[0])
        n.inputs[3].default_value = 5.0
        return n.outputs[0]
    out["checker_uv"] = checker

    def checker_gen(c):
        n = c.node("ShaderNodeTexChecker", "op")
        n.inputs[3].default_value = 3.0
        return n.outputs[1]
    out["checker_generated_default"] = checker_gen

    for gt in [e.identifier for e in bpy.types.ShaderNodeTexGradient.bl_rna
               .properties["gradient_type"].enum_items]:
        def b(c, gt=gt):
            n = c.node("ShaderNodeTexGradient", "op", gradient_type=gt)
            c.link(c.tc.outputs["Object"], n.inputs[0])
            return n.outputs[1]
        out[f"gradient_{gt}"] = b
    out["gradient_generated_default"] = lambda c: c.node(
        "ShaderNodeTexGradient", "op", gradient_type="DIAGONAL").outputs[0]

    for sock in ("UV", "Generated", "Object", "Normal"):
        out[f"texcoord_{sock}"] = lambda c, sock=sock: c.tc.outputs[sock]
    out["uvmap"] = lambda c: c.node("ShaderNodeUVMap", "op").outputs[0]

    for vt in ("POINT", "TEXTURE", "VECTOR", "NORMAL"):
        def b(c, vt=vt):
            n = c.node("ShaderNodeMapping", "op", vector_type=vt)
            c.link(c.tc.outputs["Object"], n.inputs[0])
            if vt in ("POINT", "TEXTURE"):
                n.inputs["Location"].default_value = (0.3, -0.2, 0.1)
            n.inputs["Rotation"].default_value = (0.4, -0.7, 1.1)
            n.inputs["Scale"].default_value = (1.5, 0.8, 1.2)
            return n.outputs[0]
        out[f"mapping_{vt}"] = b

    for img in ("srgb8", "noncolor8", "float"):
        for interp in ("Closest", "Linear", "Cubic"):
            for ext in ("REPEAT", "EXTEND", "CLIP", "MIRROR"):
                if img != "srgb8" and ext != "REPEAT":
                    continue
                def b(c, img=img, interp=interp, ext=ext):
                    n = c.node("ShaderNodeTexImage", "op", interpolation=interp, extension=ext)
                    n.image = bpy.data.images[img]
                    m = c.node("ShaderNodeMapping", vector_type="POINT")
                    c.link(c.tc.outputs["UV"], m.inputs[0])
                    m.inputs["Location"].default_value = (-0.3, -0.25, 0.0)
                    m.inputs["Scale"].default_value = (1.6, 1.5, 1.0)
                    c.link(m.outputs[0], n.inputs[0])
                    return n.outputs[0]
                out[f"image_{img}_{interp}_{ext}"] = b

    def image_alpha(c):
        n = c.node("ShaderNodeTexImage", "op", interpolation="Linear")
        n.image = bpy.data.images["srgb8"]
        c.link(c.tc.outputs["UV"], n.inputs[0])
        return n.outputs[1]
    out["image_srgb8_alpha"] = image_alpha
    out.update(procedural_cases())
    out.update(input_cases())
    out.update(curve_cases())
    out.update(normal_cases())
    return out


def _rotated_object(c):
    """Object coordinates through a rotation, so x, y and z all vary over the plane."""
    m = c.node("ShaderNodeMapping", vector_type="POINT")
    c.link(c.tc.outputs["Object"], m.inputs[0])
    m.inputs["Rotation"].default_value = (0.4, -0.7, 1.1)
    m.inputs["Location"].default_value = (0.35, -0.15, 0.6)
    return m.outputs[0]


def _socket(n, ident):
    """Input ``ident`` of node ``n`` (by identifier, whether or not it is shown)."""
    return next(s for s in n.inputs if s.identifier == ident)


def set_inputs(n, values):
    for k, v in values:
        _socket(n, k).default_value = v


def link_coords(c, n, dims):
    if dims != "1D":
        c.link(_rotated_object(c), _socket(n, "Vector"))
    if dims in ("1D", "4D"):
        c.link(_w(c), _socket(n, "W"))


def _w(c):
    u, v, _ = c.sep(c.tc.outputs["UV"])
    return c.affine(u, 1.7, -0.4)


def procedural_cases():
    """Noise (4 dimensions x 5 types, colour, distortion, no normalisation), Voronoi (4
    dimensions x 5 features, metrics, fractal octaves, every output) and Wave cases."""
    out = {}
    params = {"FBM": (3.4, 0.55, 2.2, 0.0, 1.0), "MULTIFRACTAL": (2.6, 0.6, 2.1, 0.0, 1.0),
              "HYBRID_MULTIFRACTAL": (3.3, 0.5, 2.3, 0.8, 1.6),
              "RIDGED_MULTIFRACTAL": (2.0, 0.55, 2.0, 1.0, 2.2),
              "HETERO_TERRAIN": (2.7, 0.45, 2.05, 0.6, 1.0)}

    def noise(c, dims, kind, sock="Fac", distortion=0.0, normalize=True, scale=2.5):
        n = c.node("ShaderNodeTexNoise", "op", noise_dimensions=dims, noise_type=kind,
                   normalize=normalize)
        link_coords(c, n, dims)
        d, r, lac, off, gain = params[kind]
        set_inputs(n, (("Scale", scale), ("Detail", d), ("Roughness", r), ("Lacunarity", lac),
                       ("Offset", off), ("Gain", gain), ("Distortion", distortion)))
        return n.outputs[sock]
    for dims in ("1D", "2D", "3D", "4D"):
        for kind in params:
            out[f"noise_{dims}_{kind}"] = lambda c, dims=dims, kind=kind: noise(c, dims, kind)
        out[f"noise_{dims}_color"] = lambda c, dims=dims: noise(c, dims, "FBM", "Color")
    out["noise_3D_distortion"] = lambda c: noise(c, "3D", "FBM", "Color", distortion=0.7)
    out["noise_1D_distortion"] = lambda c: noise(c, "1D", "FBM", distortion=1.3)
    out["noise_4D_distortion"] = lambda c: noise(c, "4D", "HETERO_TERRAIN", distortion=0.5)
    out["noise_3D_FBM_raw"] = lambda c: noise(c, "3D", "FBM", normalize=False)

    def noise_linked_detail(c):                            # per-hit Detail, Roughness
        n = c.node("ShaderNodeTexNoise", "op", noise_dimensions="3D", noise_type="FBM")
        u, v, _ = c.sep(c.tc.outputs["UV"])
        c.link(c.affine(u, 4.0, 0.3), n.inputs["Detail"])
        c.link(c.affine(v, 0.6, 0.2), n.inputs["Roughness"])
        c.link(_rotated_object(c), n.inputs["Vector"])
        return n.outputs["Fac"]
    out["noise_3D_linked_detail"] = noise_linked_detail
    out["noise_generated_default"] = lambda c: c.node(
        "ShaderNodeTexNoise", "op", noise_dimensions="3D", noise_type="FBM").outputs["Fac"]

    def voronoi(c, dims, feature, sock=None, metric="EUCLIDEAN", detail=0.0, normalize=False,
                scale=3.0):
        n = c.node("ShaderNodeTexVoronoi", "op", voronoi_dimensions=dims, feature=feature,
                   distance=metric, normalize=normalize)
        link_coords(c, n, dims)
        set_inputs(n, (("Scale", scale), ("Detail", detail), ("Roughness", 0.6),
                       ("Lacunarity", 2.2), ("Smoothness", 0.8), ("Exponent", 1.5),
                       ("Randomness", 0.85)))
        sock = sock or ("Radius" if feature == "N_SPHERE_RADIUS" else "Distance")
        return n.outputs[sock]
    for dims in ("1D", "2D", "3D", "4D"):
        for feature in ("F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE", "N_SPHERE_RADIUS"):
            out[f"voronoi_{dims}_{feature}"] = (lambda c, dims=dims, feature=feature:
                                               voronoi(c, dims, feature))
        out[f"voronoi_{dims}_F1_color"] = lambda c, dims=dims: voronoi(c, dims, "F1", "Color")
        out[f"voronoi_{dims}_smooth_color"] = (lambda c, dims=dims:
                                              voronoi(c, dims, "SMOOTH_F1", "Color"))
        sock = "W" if dims == "1D" else "Position"
        out[f"voronoi_{dims}_F1_{sock}"] = (lambda c, dims=dims, sock=sock:
                                           voronoi(c, dims, "F1", sock))
    out["voronoi_4D_F2_W"] = lambda c: voronoi(c, "4D", "F2", "W")
    for metric in ("MANHATTAN", "CHEBYCHEV", "MINKOWSKI"):
        for dims in ("2D", "3D"):
            out[f"voronoi_{dims}_F1_{metric}"] = (lambda c, dims=dims, metric=metric:
                                                 voronoi(c, dims, "F1", metric=metric))
        out[f"voronoi_3D_F2_{metric}"] = lambda c, metric=metric: voronoi(
            c, "3D", "F2", metric=metric, normalize=True)
        out[f"voronoi_2D_smooth_{metric}"] = lambda c, metric=metric: voronoi(
            c, "2D", "SMOOTH_F1", metric=metric)
    for feature in ("F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE"):
        for dims, norm in (("3D", True), ("2D", False)):
            out[f"voronoi_{dims}_{feature}_fractal_n{int(norm)}"] = (
                lambda c, dims=dims, feature=feature, norm=norm:
                voronoi(c, dims, feature, detail=2.5, normalize=norm))
    out["voronoi_3D_F1_fractal_color"] = lambda c: voronoi(c, "3D", "F1", "Color", detail=2.5,
                                                           normalize=True)
    out["voronoi_3D_F1_fractal_position"] = lambda c: voronoi(c, "3D", "F1", "Position",
                                                              detail=2.5)
    out["voronoi_1D_F1_fractal_n1"] = lambda c: voronoi(c, "1D", "F1", detail=1.5,
                                                        normalize=True)
    out["voronoi_4D_F1_fractal_n1"] = lambda c: voronoi(c, "4D", "F1", detail=1.5,
                                                        normalize=True)

    def wave(c, kind="BANDS", bands="X", rings="X", profile="SIN", distortion=0.0):
        n = c.node("ShaderNodeTexWave", "op", wave_type=kind, bands_direction=bands,
                   rings_direction=rings, wave_profile=profile)
        c.link(_rotated_object(c), n.inputs["Vector"])
        for k, v in (("Scale", 1.3), ("Distortion", distortion), ("Detail", 3.5),
                     ("Detail Scale", 1.7), ("Detail Roughness", 0.6), ("Phase Offset", 0.4)):
            n.inputs[k].default_value = v
        return n.outputs["Fac"]
    for d in ("X", "Y", "Z", "DIAGONAL"):
        out[f"wave_bands_{d}"] = lambda c, d=d: wave(c, bands=d)
    for d in ("X", "Y", "Z", "SPHERICAL"):
        out[f"wave_rings_{d}"] = lambda c, d=d: wave(c, "RINGS", rings=d, profile="SAW")
    out["wave_tri"] = lambda c: wave(c, profile="TRI", bands="DIAGONAL")
    out["wave_distortion"] = lambda c: wave(c, "RINGS", rings="SPHERICAL", distortion=2.5)
    out["wave_bands_distortion_saw"] = lambda c: wave(c, profile="SAW", distortion=4.0)
    return out


def _tilted_normal(c):
    """A unit normal leaning over the plane: normalize(1.5 (u - 0.5), 1.5 (v - 0.5), 1)."""
    n = c.node("ShaderNodeVectorMath", operation="NORMALIZE")
    c.link(c.vaffine(c.tc.outputs["UV"], (2.4, 1.8, 0.0), (-1.2, -0.9, 0.6)), n.inputs[0])
    return n.outputs[0]


def input_cases():
    """Fresnel, Layer Weight (normals tilted through their Normal input, since the bake looks
    along the plane's normal), Attribute, Light Path."""
    out = {}
    for ior in (1.45, 0.7):
        def fres(c, ior=ior):
            n = c.node("ShaderNodeFresnel", "op")
            n.inputs["IOR"].default_value = ior
            c.link(_tilted_normal(c), n.inputs["Normal"])
            return n.outputs[0]
        out[f"fresnel_ior{ior}"] = fres
    out["fresnel_unlinked_normal"] = lambda c: c.node("ShaderNodeFresnel", "op").outputs[0]
    for blend in (0.3, 0.5, 0.8):
        for sock in ("Fresnel", "Facing"):
            def lw(c, blend=blend, sock=sock):
                n = c.node("ShaderNodeLayerWeight", "op")
                n.inputs["Blend"].default_value = blend
                c.link(_tilted_normal(c), n.inputs["Normal"])
                return n.outputs[sock]
            out[f"layer_weight_{sock}_{blend}"] = lw
    for name, socks in (("f_attr", ("Fac", "Color")), ("v_attr", ("Vector", "Fac")),
                        ("c_attr", ("Color", "Fac", "Alpha"))):
        for sock in socks:
            def at(c, name=name, sock=sock):
                n = c.node("ShaderNodeAttribute", "op", attribute_name=name)
                return n.outputs[sock]
            out[f"attribute_{name}_{sock}"] = at
    for sock in LIGHT_PATH:
        out[f"light_path_{sock.replace(' ', '_')}"] = (
            lambda c, sock=sock: c.node("ShaderNodeLightPath", "op").outputs[sock])
    return out


def curve_cases():
    """RGB Curves (combined and per-channel curves, both extend modes, inputs outside the
    curves' range), Vector Curves, Float Curve."""
    out = {}

    def rgb(c, extend):
        n = c.node("ShaderNodeRGBCurve", "op")
        m = n.mapping
        m.extend = extend
        cc = m.curves[3]                                   # the combined curve
        cc.points[0].location = (0.1, 0.05)
        cc.points.new(0.45, 0.7)
        m.curves[0].points.new(0.3, 0.15)
        m.curves[1].points[1].location = (0.9, 0.8)
        p = m.curves[2].points.new(0.6, 0.35)
        p.handle_type = "VECTOR"
        m.update()
        n.inputs["Fac"].default_value = 0.85
        c.link(c.vaffine(c.tc.outputs["UV"], (1.4, 1.3, 0.0), (-0.2, -0.15, 0.5)),
               n.inputs["Color"])
        return n.outputs[0]
    out["rgb_curves_extrapolated"] = lambda c: rgb(c, "EXTRAPOLATED")
    out["rgb_curves_horizontal"] = lambda c: rgb(c, "HORIZONTAL")

    def vec(c):
        n = c.node("ShaderNodeVectorCurve", "op")
        m = n.mapping
        m.extend = "EXTRAPOLATED"
        m.curves[0].points.new(0.2, 0.6)
        m.curves[1].points[0].location = (-0.8, -0.3)
        m.curves[2].points.new(-0.1, 0.4)
        m.update()
        c.link(c.vaffine(c.tc.outputs["Object"], (1.2, 1.1, 0.0), (0.0, 0.1, 0.3)),
               n.inputs["Vector"])
        return n.outputs[0]
    out["vector_curves"] = vec

    def flt(c):
        n = c.node("ShaderNodeFloatCurve", "op")
        m = n.mapping
        m.curves[0].points.new(0.35, 0.8)
        m.curves[0].points[0].location = (0.05, 0.1)
        m.update()
        u, v, _ = c.sep(c.tc.outputs["UV"])
        c.link(c.affine(u, 1.2, -0.1), n.inputs["Value"])
        n.inputs["Factor"].default_value = 0.9
        return n.outputs[0]
    out["float_curve"] = flt
    return out


def _shown(c, normal):
    """A normal as Cycles renders it through an Emission: normal * 0.5 + 0.5."""
    return c.vaffine(normal, (0.5, 0.5, 0.5), (0.5, 0.5, 0.5))


def normal_cases():
    """Normal Map (tangent, object, world and Blender's spaces; strength; DirectX) and Bump
    (height from noise and from Math nodes; strength, distance, invert, filter width)."""
    out = {}
    for space, strength, conv in (("TANGENT", 1.0, "OPENGL"), ("TANGENT", 0.6, "OPENGL"),
                                  ("TANGENT", 1.7, "DIRECTX"), ("OBJECT", 1.0, "OPENGL"),
                                  ("WORLD", 0.5, "OPENGL"), ("BLENDER_WORLD", 1.0, "OPENGL"),
                                  ("BLENDER_OBJECT", 1.3, "OPENGL")):
        def nm(c, space=space, strength=strength, conv=conv):
            n = c.node("ShaderNodeNormalMap", "op", space=space, convention=conv)
            if space == "TANGENT":
                n.uv_map = "UVMap"
            n.inputs["Strength"].default_value = strength
            c.link(c.vaffine(c.tc.outputs["UV"], (0.4, -0.4, 0.0), (0.3, 0.7, 0.9)),
                   n.inputs["Color"])
            return _shown(c, n.outputs[0])
        out[f"normal_map_{space}_{strength}_{conv}"] = nm

    def bump(c, height, strength=1.0, distance=0.1, invert=False, fw=None):
        n = c.node("ShaderNodeBump", "op", invert=invert)
        n.inputs["Strength"].default_value = strength
        n.inputs["Distance"].default_value = distance
        if fw is not None:
            n.inputs["Filter Width"].default_value = fw
        c.link(height(c), n.inputs["Height"])
        return _shown(c, n.outputs[0])

    def noise_height(c):
        t = c.node("ShaderNodeTexNoise", noise_dimensions="3D", noise_type="FBM")
        t.inputs["Scale"].default_value = 3.0
        t.inputs["Detail"].default_value = 1.5
        c.link(c.tc.outputs["Object"], t.inputs["Vector"])
        return t.outputs["Fac"]

    def math_height(c):
        u, v, _ = c.sep(c.tc.outputs["UV"])
        s = c.node("ShaderNodeMath", operation="SINE")
        c.link(c.affine(u, 7.0, 0.3), s.inputs[0])
        m = c.node("ShaderNodeMath", operation="MULTIPLY_ADD")
        c.link(s.outputs[0], m.inputs[0])
        c.link(v, m.inputs[1])
        c.link(v, m.inputs[2])
        return m.outputs[0]
    out["bump_noise"] = lambda c: bump(c, noise_height)
    out["bump_noise_invert_strength"] = lambda c: bump(c, noise_height, 0.6, 0.3, True)
    out["bump_math"] = lambda c: bump(c, math_height, 1.0, 0.05)
    out["bump_math_filter_width"] = lambda c: bump(c, math_height, 0.8, 0.05, fw=1.0)
    return out


def make_images(tmp):
    rng = np.random.default_rng(24)
    arrays = {}
    for name, space in (("srgb8", "sRGB"), ("noncolor8", "Non-Color")):
        im = bpy.data.images.new(name, 7, 5, alpha=True)
        px = rng.integers(0, 256, (5, 7, 4)).astype(np.float32) / 255.0
        px[..., 3] = 1.0
        im.pixels.foreach_set(px.ravel())
        path = os.path.join(tmp, name + ".png")
        im.filepath_raw = path
        im.file_format = "PNG"
        im.save()
        bpy.data.images.remove(im)
        im = bpy.data.images.load(path)
        im.name = name
        im.colorspace_settings.name = space
        arrays[name] = px
    im = bpy.data.images.new("float", 6, 4, alpha=True, float_buffer=True)
    px = rng.uniform(0.0, 3.0, (4, 6, 4)).astype(np.float32)
    px[..., 3] = 1.0
    im.pixels.foreach_set(px.ravel())
    im.pack()
    arrays["float"] = px
    return arrays


def plane_tangent(ob):
    """The plane's MikkTSpace tangent and bitangent sign for "UVMap" (what Cycles interpolates
    for a tangent-space Normal Map): one (x, y, z, sign) for all loops of the flat plane,
    checked to be the same everywhere."""
    me = ob.data
    me.calc_tangents(uvmap="UVMap")
    t = np.array([list(lp.tangent) + [lp.bitangent_sign] for lp in me.loops])
    assert np.allclose(t, t[0], atol=1e-6), t
    return t[0]


def bake(ob, target):
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.bake(type="EMIT")
    px = np.empty(SIZE * SIZE * 4, np.float32)
    target.pixels.foreach_get(px)
    return px.reshape(SIZE, SIZE, 4)[..., :3].copy()


def main():
    ob, mat, target = scene()
    data = {"size": np.array(SIZE), "blender": np.array(bpy.app.version_string)}
    with tempfile.TemporaryDirectory() as tmp:
        written = make_images(tmp)
        for name in ("srgb8", "noncolor8", "float"):
            image = node_export.image_pixels(bpy.data.images[name])
            data[f"image/{name}"] = image.pixels
            data[f"image_encoding/{name}"] = np.array(image.encoding)
            data[f"image_written/{name}"] = written[name]
        for coord in ("UV", "Object", "Generated", "Normal"):
            c = Ctx(mat, target)
            c.link(c.tc.outputs[coord], c.em.inputs["Color"])
            data[f"coord/{coord}"] = bake(ob, target)
        for sock in GEOMETRY:
            c = Ctx(mat, target)
            c.link(c.node("ShaderNodeNewGeometry").outputs[sock], c.em.inputs["Color"])
            data[f"coord/Geometry/{sock}"] = bake(ob, target)
        for name, (kind, coeffs) in ATTRIBUTES.items():
            data[f"attribute/{name}"] = np.array(coeffs, float)
        data["tangent/UVMap"] = plane_tangent(ob)
        data["object_matrix"] = np.array(ob.matrix_world, float)
        for name, build in cases().items():
            c = Ctx(mat, target)
            sock = build(c)
            c.link(sock, c.em.inputs["Color"])
            warnings = []
            graph = node_export.export_graph(c.nt, warnings.append)
            src = graph.links[(c.em.name, "Color")]
            data[f"case/{name}/graph"] = np.array(json.dumps(N.graph_to_dict(graph)))
            data[f"case/{name}/socket"] = np.array(list(src))
            data[f"case/{name}/bake"] = bake(ob, target)
            print(name, flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **data)
    print(f"{OUT}: {OUT.stat().st_size} bytes, {sum(k.endswith('/bake') for k in data)} cases")


if __name__ == "__main__":
    main()
    sys.exit(0)
