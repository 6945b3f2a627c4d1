"""Cycles' bake of a node subtree Lanterna cannot evaluate, as an image read through UVs.

What it computes
----------------
A shader input driven by a node outside ``engine.nodes.SUPPORTED`` (Brick, Magic, White
Noise, Gabor, Wireframe, Blackbody, Object Info ...) falls back to whichever is closer to
what Cycles shows (issue 24): Blender's own bake of that subtree, or the socket's default.

* **Bake** (:meth:`NodeBaker.bake`): a copy of the material whose active output is an
  Emission (Strength 1) fed by the subtree's output, on a copy of the evaluated mesh of one
  object that uses the material (its other materials' faces removed), in a scratch scene;
  ``bpy.ops.object.bake(type='EMIT')`` with Cycles, 1 sample (the emission is evaluated once
  at each texel's centre, as ``tests/data/make_node_bakes.py`` measured), margin
  ``BAKE_MARGIN`` texels extended past the UV islands, into a float image of ``BAKE_SIZE`` x
  ``BAKE_SIZE`` texels (scene linear) through the object's active UV map. Lanterna then
  reads that image with bilinear filtering through the same UV map at every hit (camera,
  photon, gather, records: wherever the material is read). Nothing of the user's data is
  changed; every scratch datablock is removed, also when the bake fails.
* **Default** (the bake is refused, with the reason): the subtree reads something a bake
  cannot hold, a value of the ray or of the rest of the scene (``RAY_NODES``: Light Path,
  Camera Data, Fresnel, Layer Weight, Geometry's Incoming / Backfacing, Ambient Occlusion,
  Bevel ...); no mesh object that uses the material has a UV map; the input is a vector
  (Normal, Tangent); or this is not Blender's main thread and the bake is not cached yet
  (an F12 render runs its engine in a render thread, where operators must not run;
  Lanterna's Bake Maps operator exports on the main thread and so makes the bakes every
  later F12 reuses, and ``blender -b`` / ``lanterna render`` export on the main thread).

A material on several objects is baked through the first one's UVs (by name); the others
read the same image through their own UVs, which is exact when the subtree reads only UV
coordinates and is reported otherwise.

Bakes are cached in memory (``_CACHE``, the last ``CACHE_ENTRIES``) by a hash of the
subtree (every node's settings, input values and links, its images' names, sizes and
files), the object's evaluated UVs and positions, and the bake's size, so a second render
of an unchanged scene bakes nothing.

Parameters: ``BAKE_SIZE`` = 1024 texels a side, ``BAKE_MARGIN`` = 16 texels.
"""
from __future__ import annotations

import hashlib
import threading

import numpy as np

import bpy

from .. import nodes as N

__all__ = ["NodeBaker", "BakeRefused", "BAKE_SIZE", "BAKE_MARGIN", "RAY_NODES",
           "subtree_nodes"]

BAKE_SIZE = 1024
BAKE_MARGIN = 16
CACHE_ENTRIES = 16
# Nodes whose value depends on the ray or on the rest of the scene, which a bake of the
# object alone cannot hold (bl_idname -> the outputs that do; None: all of them).
RAY_NODES = {
    "ShaderNodeLightPath": None, "ShaderNodeCameraData": None, "ShaderNodeFresnel": None,
    "ShaderNodeLayerWeight": None, "ShaderNodeNewGeometry": ("Incoming", "Backfacing"),
    "ShaderNodeAmbientOcclusion": None, "ShaderNodeBevel": None,
    "ShaderNodeLightFalloff": None, "ShaderNodeParticleInfo": None,
    "ShaderNodeHairInfo": None, "ShaderNodePointInfo": None, "ShaderNodeVolumeInfo": None,
}
_UI_PROPS = frozenset({"rna_type", "name", "label", "location", "location_absolute", "width",
                       "height", "dimensions", "select", "parent", "color", "color_tag",
                       "hide", "show_options", "show_preview", "show_texture",
                       "use_custom_color", "bl_idname", "bl_label", "bl_description",
                       "bl_icon", "bl_static_type", "bl_width_default", "bl_width_min",
                       "bl_width_max", "bl_height_default", "bl_height_min",
                       "bl_height_max", "internal_links", "inputs", "outputs", "type",
                       "is_active_output", "warning_propagation"})
_CACHE: dict = {}


class BakeRefused(Exception):
    """Why a subtree is not baked (the socket's default is used); the message completes the
    sentence "... using its default <value> (<message>)"."""


def _source(socket):
    """(node, output socket) feeding ``socket`` through reroutes and muted nodes, or None."""
    for _ in range(256):
        if socket is None or not socket.is_linked:
            return None
        link = socket.links[0]
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            return None
        node, out = link.from_node, link.from_socket
        if node.type == "REROUTE":
            socket = node.inputs[0]
            continue
        if getattr(node, "mute", False):
            socket = next((il.from_socket for il in node.internal_links
                           if il.to_socket == out), None)
            continue
        return node, out
    return None


def subtree_nodes(node, output) -> list:
    """[(node, {its outputs that are read})] upstream of ``output`` of ``node``, ``node``
    first, each once (reroutes and muted nodes passed through)."""
    read: dict = {node.name: (node, {output.identifier})}
    order = [node.name]
    stack = [node]
    while stack:
        current = stack.pop()
        for socket in current.inputs:
            src = _source(socket)
            if src is None:
                continue
            upstream, out = src
            if upstream.name not in read:
                read[upstream.name] = (upstream, set())
                order.append(upstream.name)
                stack.append(upstream)
            read[upstream.name][1].add(out.identifier)
    return [read[name] for name in order]


def ray_dependence(node, output) -> str | None:
    """The first node of the subtree whose read outputs depend on the ray or the scene
    (``RAY_NODES``), as "<label> '<name>'", or None."""
    for upstream, outputs in subtree_nodes(node, output):
        dependent = RAY_NODES.get(upstream.bl_idname, ())
        if dependent is None or any(o in outputs for o in (dependent or ())):
            return f"{upstream.bl_label} '{upstream.name}'"
    return None


def _rna_dump(value, depth: int = 0):
    """A hashable description of an RNA value: numbers, strings, arrays, non-ID structs
    (colour ramps, curves, mappings) walked to depth 3, IDs by name (images also by file,
    size and whether they were edited)."""
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, bpy.types.ID):
        if isinstance(value, bpy.types.Image):
            return ("image", value.name, value.filepath, tuple(value.size),
                    bool(value.is_dirty), value.packed_file is not None, value.source)
        return ("id", type(value).__name__, value.name)
    if depth > 3:
        return None
    if isinstance(value, bpy.types.bpy_struct):
        out = []
        for prop in value.bl_rna.properties:
            key = prop.identifier
            if key in _UI_PROPS:
                continue
            try:
                out.append((key, _rna_dump(getattr(value, key), depth + 1)))
            except (AttributeError, TypeError, RuntimeError):
                continue
        return tuple(out)
    try:
        return tuple(_rna_dump(v, depth + 1) for v in value)
    except TypeError:
        return repr(value)


def subtree_hash(node, output) -> str:
    """A hash of everything the subtree's value depends on in its node tree."""
    h = hashlib.sha256()
    for upstream, outputs in subtree_nodes(node, output):
        h.update(repr((upstream.bl_idname, upstream.name, sorted(outputs),
                       _rna_dump(upstream))).encode())
        for socket in upstream.inputs:
            src = _source(socket)
            default = getattr(socket, "default_value", None)
            h.update(repr((socket.identifier, _rna_dump(default) if src is None else
                           (src[0].name, src[1].identifier))).encode())
    return h.hexdigest()


def _mesh_hash(obj_eval, uv_name: str) -> str:
    """A hash of the evaluated mesh's positions, UVs (``uv_name``), polygons' materials and
    the object's matrix."""
    mesh = obj_eval.data
    h = hashlib.sha256()
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    h.update(co.tobytes())
    layer = mesh.uv_layers[uv_name]
    uv = np.empty(len(mesh.loops) * 2, np.float32)
    layer.data.foreach_get("uv", uv)
    h.update(uv.tobytes())
    index = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("material_index", index)
    h.update(index.tobytes())
    h.update(np.array(obj_eval.matrix_world, np.float64).tobytes())
    return h.hexdigest()


def _material_key(material) -> int:
    return getattr(material, "original", material).as_pointer()


class NodeBaker:
    """Bakes for one export: ``depsgraph`` (evaluated), ``size`` texels a side (default
    ``BAKE_SIZE``), ``margin`` texels (default ``BAKE_MARGIN``). ``baked``
    lists (material, node, output, object, UV map, seconds, cached) of each bake used."""

    def __init__(self, depsgraph, size: int | None = None, margin: int | None = None):
        self.depsgraph = depsgraph
        self.size = int(BAKE_SIZE if size is None else size)
        self.margin = int(BAKE_MARGIN if margin is None else margin)
        self.baked: list = []
        self._users: dict | None = None

    def users(self, material) -> list:
        """The evaluated mesh objects that use ``material``, by name."""
        if self._users is None:
            self._users = {}
            for obj in self.depsgraph.objects:
                if obj.type != "MESH":
                    continue
                for slot in obj.material_slots:
                    if slot.material is not None:
                        self._users.setdefault(_material_key(slot.material), {})[obj.name] = obj
        found = self._users.get(_material_key(material), {})
        return [found[name] for name in sorted(found)]

    def bake(self, material, node, output, what: str = "colour"):
        """(``nodes.Image`` of the bake, the UV map's name, a note for the report: which
        object's UVs and whether other objects share it) for the subtree feeding
        ``output`` of ``node`` in ``material``'s tree; raises :class:`BakeRefused`."""
        if output.type in ("VECTOR", "SHADER"):
            raise BakeRefused(f"a {output.type.lower()} output cannot be baked into a colour")
        dependent = ray_dependence(node, output)
        if dependent is not None:
            raise BakeRefused(f"it reads {dependent}, which depends on the ray or the rest "
                              "of the scene, so a bake cannot hold it")
        objects = [o for o in self.users(material) if len(o.data.uv_layers)]
        if not objects:
            raise BakeRefused("no mesh object that uses the material has a UV map to bake "
                              "through")
        obj = objects[0]
        uv_name = obj.data.uv_layers.active.name
        key = (subtree_hash(node, output), _mesh_hash(obj, uv_name), self.size, self.margin,
               material.name)
        cached = key in _CACHE
        if not cached:
            if threading.current_thread() is not threading.main_thread():
                raise BakeRefused("Blender's bake cannot run in the render thread; Bake "
                                  "Maps (the Lanterna menu of the 3D viewport) bakes it once "
                                  "for every later F12, and blender -b bakes as it renders")
            _CACHE[key] = self._bake(material, node, output, obj, uv_name)
            while len(_CACHE) > CACHE_ENTRIES:
                _CACHE.pop(next(iter(_CACHE)))
        pixels, seconds = _CACHE[key]
        note = (f"through UV map '{uv_name}' of '{obj.name}' "
                f"({'reused from an earlier bake' if cached else f'{seconds:.1f} s'})")
        others = [o.name for o in self.users(material) if o.name != obj.name]
        if others:
            note += (f"; {', '.join(repr(n) for n in others[:3])}"
                     f"{' ...' if len(others) > 3 else ''} read the same image through "
                     "their own UVs (exact only where the nodes read nothing but UVs)")
        self.baked.append((material.name, node.name, output.identifier, obj.name, uv_name,
                           seconds, cached))
        return N.Image(pixels, "linear"), uv_name, note

    def _bake(self, material, node, output, obj, uv_name):
        """((size, size, 4) float32 row 0 at the bottom, seconds): the bake itself."""
        import time

        import bmesh

        t0 = time.perf_counter()
        original = getattr(material, "original", material)
        scratch = {"material": original.copy(), "image": None, "mesh": None,
                   "object": None, "scene": None}
        try:
            mat = scratch["material"]
            mat.name = "lanterna_bake"
            tree = mat.node_tree
            for n in tree.nodes:
                if n.bl_idname == "ShaderNodeOutputMaterial":
                    n.is_active_output = False
            source = tree.nodes[node.name]
            out = next(o for o in source.outputs if o.identifier == output.identifier)
            emission = tree.nodes.new("ShaderNodeEmission")
            emission.inputs["Strength"].default_value = 1.0
            tree.links.new(out, emission.inputs["Color"])
            result = tree.nodes.new("ShaderNodeOutputMaterial")
            result.target = "ALL"
            tree.links.new(emission.outputs[0], result.inputs["Surface"])
            result.is_active_output = True
            image = scratch["image"] = bpy.data.images.new("lanterna_bake", self.size,
                                                           self.size, alpha=True,
                                                           float_buffer=True)
            target = tree.nodes.new("ShaderNodeTexImage")
            target.image = image
            tree.nodes.active = target

            mesh = scratch["mesh"] = bpy.data.meshes.new_from_object(
                obj, preserve_all_data_layers=True, depsgraph=self.depsgraph)
            slots = [s.material for s in obj.material_slots]
            wanted = _material_key(material)
            bm = bmesh.new()
            try:
                bm.from_mesh(mesh)
                drop = [f for f in bm.faces
                        if not (f.material_index < len(slots)
                                and slots[f.material_index] is not None
                                and _material_key(slots[f.material_index]) == wanted)]
                bmesh.ops.delete(bm, geom=drop, context="FACES")
                for f in bm.faces:
                    f.material_index = 0
                bm.to_mesh(mesh)
            finally:
                bm.free()
            mesh.materials.clear()
            mesh.materials.append(mat)
            mesh.uv_layers.active = mesh.uv_layers[uv_name]
            ob = scratch["object"] = bpy.data.objects.new("lanterna_bake", mesh)
            ob.matrix_world = obj.matrix_world.copy()
            scene = scratch["scene"] = bpy.data.scenes.new("lanterna_bake")
            scene.collection.objects.link(ob)
            scene.render.engine = "CYCLES"
            scene.cycles.device = "CPU"
            scene.cycles.samples = 1
            scene.render.bake.margin = self.margin
            layer = scene.view_layers[0]
            layer.objects.active = ob
            ob.select_set(True, view_layer=layer)
            with bpy.context.temp_override(scene=scene, view_layer=layer, active_object=ob,
                                           object=ob, selected_objects=[ob],
                                           selected_editable_objects=[ob]):
                bpy.ops.object.bake(type="EMIT", margin=self.margin, use_clear=True,
                                    target="IMAGE_TEXTURES", use_selected_to_active=False)
            pixels = np.empty(self.size * self.size * 4, np.float32)
            image.pixels.foreach_get(pixels)
            pixels = pixels.reshape(self.size, self.size, 4)
            pixels[..., 3] = 1.0
            return pixels, time.perf_counter() - t0
        finally:
            for kind, collection in (("scene", bpy.data.scenes), ("object", bpy.data.objects),
                                     ("mesh", bpy.data.meshes), ("image", bpy.data.images),
                                     ("material", bpy.data.materials)):
                if scratch[kind] is not None:
                    collection.remove(scratch[kind])
