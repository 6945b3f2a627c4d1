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

Run: ``PYTHONPATH=<dir holding lanterna> .venv/bin/python tests/data/make_node_bakes.py``
(about 5 s); writes ``tests/data/node_bakes/node_bakes.npz``.
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
