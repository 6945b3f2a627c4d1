"""Blender depsgraph -> :class:`lanterna.engine.scene.Scene`: the only place that reads Blender
data for rendering.

What it computes
----------------
:func:`export_scene` walks an evaluated depsgraph (modifiers, geometry nodes, constraints and
animation already applied by Blender) and turns it into the renderer's inert scene:

* **Geometry**: every visible mesh-like object (mesh, curve, surface, text, metaball) and every
  instance (collection instances, vertex/face instancing, particles, geometry-nodes instances),
  triangulated with Blender's loop triangles. Corner ("split") normals become the shading
  normals. Positions are transformed by the instance's world matrix and normals by its cofactor
  matrix (the inverse transpose times the determinant, signed so that normals keep their side),
  in numpy. The triangles of one mesh datablock are read once however often it is instanced,
  and all instances of one mesh are transformed together (one batch of numpy per mesh). Render
  visibility follows Blender: Disable in Renders, Show Instancer for Render, and the original
  of an object instanced on its parent's vertices or faces is hidden. Hair (Curves objects:
  ``_read_curves``; hair particle systems: ``_read_particle_hair``, keys from ``co_hair``)
  becomes closed tubes around its strands (``engine/hair.py``), read as Cycles reads it;
  ``Scene.strands`` flags their triangles. Point clouds, volumes and grease pencil are
  reported and skipped.
  Output: ``triangles`` (T, 3, 3) float32 [m], ``shading_normals`` (T, 3, 3) float32,
  ``material_ids`` (T,) int32 into ``materials``, ``object_ids`` (T,) int32 into
  ``object_names``.
* **Objects hidden from the camera** (Visibility > Camera off): their materials' variants
  (``hidden_from_camera``) let camera rays through and meet every other ray as before.
* **Materials** (one per Blender material, deduplicated; slots without a material and objects
  without slots share ``default_surface``: Cycles' default Principled BSDF from Blender 5.0
  on, a grey diffuse of rho_d = 0.8 before): when the material has a
  ``lanterna`` property group with ``derive_from_nodes`` False, its ``diffuse``, ``specular``
  and ``exitance`` are used as they are. Otherwise they are derived from the node tree feeding
  the active Material Output's Surface (:func:`material_from_nodes`, also what the Material
  panel shows):

  - Principled BSDF: rho_d = Base Color (1 - Metallic)(1 - Transmission Weight),
    rho_s = Base Color x Metallic (a perfect mirror, whatever the Roughness), exitance
    M = pi x Emission Color x Emission Strength, for the seed's reduction; the dielectric
    layer, metal, coat, sheen and transmission render as lobes (``bsdf.glossy_material``).
    Alpha < 1 mixes a Transparent BSDF in, as Cycles does; an Alpha driven by nodes (an
    image's alpha) mixes it per hit, as a node-driven Mix Shader Fac. Blender 5 defaults:
    Emission Color white, Strength 0.
  - Diffuse BSDF: rho_d = Color. Emission: M = pi x Color x Strength, rho_d = 0.
  - Glossy BSDF: rho_s = Color. Metallic BSDF: rho_s = Base Color (F82 mode) or the
    normal-incidence Fresnel reflectance ((n-1)^2 + k^2) / ((n+1)^2 + k^2) per channel.
  - Mix Shader: (1 - Fac) A + Fac B; Add Shader: A + B. A Fac driven by nodes the evaluator
    supports becomes a per-hit factor on the weights below it (``textures.WEIGHT``); Light
    Path among them reads each ray's values (``textures`` module docstring: Is Camera Ray
    for camera rays, the flags and depths of the camera path's reflections and refractions,
    a diffuse bounce's for gather rays and photons); Is Shadow Ray reads 0, with a warning.
  - Glass / Refraction: only the reflected Fresnel part at normal incidence, as a mirror.
  - Translucent, Subsurface, Sheen, Toon, hair and other shaders with a colour: treated as a
    diffuse of that colour. Transparent and Holdout: black. Anything else: default grey.

  Inputs fed by a Color (RGB) or Value node take that node's value. An input driven by nodes
  the evaluator supports (``engine/nodes.py``: textures, maths, colour nodes ...) becomes
  per-hit (``Closure.textures``, the material's ``graph``; ``engine/textures.py`` says what
  follows the texture at each hit and what takes its mean, and each approximation is
  reported); the per-corner coordinates the graphs read (UV maps, object-space position and
  normal, generated coordinates, colour attributes for Color Attribute and geometry attributes
  for Attribute nodes: ``_read_attributes``) go onto ``Scene.corner_attributes``. An input
  driven by a node the evaluator does not support is baked by Cycles into an image read
  through the UVs (``node_bake``), or, where a bake cannot hold it (it reads the ray, no UV
  map, a vector), takes the socket's default; either way the report names the material, the
  socket, the node and which fallback was taken. rho_d and rho_s are clipped to [0, 1] and scaled down per channel where
  rho_d + rho_s > 1, with a warning. Emissive meshes need no light objects: the core builds
  mesh lights from triangles whose material has ``exitance`` > 0 (``emit_both_sides`` True,
  as Cycles emits from both faces).
* **Lights** (also instanced ones), colour = Color x (blackbody colour if Use Temperature)
  x Power x 2^Exposure (x the node tree's Emission Strength x Color):

  - Point: :class:`PointLight`, flux Phi = P x colour [W], radius = Radius
    (``shadow_soft_size``) [m] as set (the object's scale does not change it, as in Cycles),
    ``soft_falloff`` = Soft Falloff (``use_soft_falloff``, Blender's default True): a radius
    > 0 makes a sphere light (Soft Falloff off) or Cycles' facing disk (on), soft shadows.
  - Spot: :class:`SpotLight`, half angle = Spot Size / 2, blend = Spot Blend, flux, radius
    and soft falloff as a point, axis = the light's world -Z. Square spots are reported and
    treated as round.
  - Sun: :class:`SunLight`, irradiance = Strength x colour [W/m^2], direction = world -Z,
    angle = Angle [rad].
  - Area: :class:`AreaLight`, shape, world matrix, size_x = Size, size_y = Size Y [m], power =
    P x colour [W] (x world area [m^2] when Normalize is off); ``collimated`` when Spread
    < 1e-3 rad; other spreads below 180 deg are reported and treated as 180 deg.
  - A light's node tree (always there from Blender 5.1, switched on by Use Nodes before) is
    read as Cycles reads it: the Emission node feeding the Light Output multiplies the power by
    its Strength x Color (Blender's default tree, strength 1 and white, changes nothing); Add
    and Mix shaders of emissions combine; an RGB or Value node feeding Color or Strength gives
    its value; any other node (a texture, Blackbody, Light Falloff, another shader) is reported
    by name, light and node, and its socket's own value (or 1) used. A tree with nothing at
    the Light Output makes the light dark, as in Cycles, with a warning.
  - Zero power is skipped silently; negative power is skipped with a warning.
  - ``Light.lanterna``: ``photon_share`` goes onto every light; ``shadow_photons`` onto area
    lights (the only ones shadow photons leave).
  - The object's Visibility > Camera (``visible_camera``, off for a new light) becomes
    ``camera_visible`` of point, spot, sun and area lights: camera rays see them, as in
    Cycles.
* **World**: Background <- Environment Texture (<- Mapping <- Texture Coordinate) or Sky
  Texture: an image environment (``world_export.environment_of``); area lights with
  Cycles' ``is_portal`` become its portals, not lights. Otherwise a uniform environment of
  radiance = Background Color x Strength
  [W m^-2 sr^-1] (Mix/Add shaders of backgrounds are combined); a linked Color or Strength is
  evaluated when its nodes need no coordinate, else reported and its default used; no world
  is black. A new World in Blender 5 is grey 0.05 and Cycles adds it, so it is kept. A world
  that reads Light Path Is Camera Ray (to be seen in one colour and light in another) is read
  for camera rays and for all others: ``World.camera`` is what camera rays see.
* **Camera**: the scene's active camera, perspective, orthographic or equirectangular
  (Cycles' panoramic projection with its latitude and longitude ranges; its shift and depth
  of field are reported and left out; the other panoramic projections and custom cameras are
  reported and treated as perspective with the same lens and sensor). Blender's
  sensor fit: AUTO fits Sensor Width to the larger side of the frame (in pixels x pixel
  aspect), HORIZONTAL fits Sensor Width to the width, VERTICAL fits Sensor Height to the
  height. tan_half = sensor / (2 lens) on the fitted side (orthographic: a half extent of
  Orthographic Scale / 2 [m]), the other side follows the frame's aspect. Shift X/Y are in
  units of the fitted side (so the plane shift is shift x 2 tan_half of that side). The
  camera matrix's scale is removed (as Cycles and ``world_to_camera_view`` do). Depth of
  field as Cycles reads it: aperture radius = lens [m] / (2 F-Stop) (orthographic: 1 / (2
  F-Stop) m), Blades (fewer than 3: a disk), Rotation and Ratio; the focus distance is Focus
  Distance, or with a Focus Object (and bone) the distance to it along the camera's axis.

Parameters of :func:`export_scene`
----------------------------------
``depsgraph``
    An evaluated ``bpy.types.Depsgraph`` (the RenderEngine's, or
    ``bpy.context.evaluated_depsgraph_get()``).
``resolution``
    (width, height) in pixels of the full frame; default: Render Resolution x Percentage / 100
    (integer division, as Blender).
``border``
    (x0, y0, x1, y1) in pixels, y from the bottom, x1/y1 exclusive; default: when the scene's
    Render Region (``use_border``) is on, (min_x W, min_y H, max_x W, max_y H) truncated to
    integers as Blender does; otherwise the whole frame.

Units (DESIGN.md section 3): metres and radians throughout; point/spot flux and area power in
W; sun irradiance in W/m^2; emission Strength S gives radiance S x colour, i.e. exitance
M = pi S per side; world colour is radiance. Reflectances are linear RGB in [0, 1].

Errors: input that cannot be rendered raises :class:`SceneError` naming the object and the
problem (no camera, a non-finite camera or light transform ...). Meshes whose transform is not
finite are skipped with a warning naming the object; non-finite or degenerate triangles are
dropped by :meth:`Scene.validate`. Warnings are deduplicated and kept in ``Scene.warnings``;
``Scene.stats`` holds the export time and counts.

:func:`export_settings` turns ``Scene.lanterna`` (any nested property groups included) into
:class:`lanterna.engine.settings.RenderSettings`, falling back on that class's defaults.
"""
from __future__ import annotations

import dataclasses
import math
import os
import time

import numpy as np

import bpy

from ..settings import RenderSettings
from . import compat
from .. import hair
from .. import nodes
from .. import procedural
from .. import textures
from .world_export import (CAMERA_RAY, LIGHTING_RAY, constant_for_ray, decided_socket,
                           decided_source, environment_of, graph_maker, light_path_outputs)
from ..shaders import CLOSURE_KINDS, Closure, seed_reduction
from . import node_bake
from .node_export import export_graph
from ..scene import (AREA_SHAPES, AreaLight, Camera, Material, PointLight, Scene, SceneError,
                     SpotLight, SunLight, World)

__all__ = ["export_scene", "export_settings", "material_from_nodes"]

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES"}
UNSUPPORTED_TYPES = {"POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"}
COLLIMATED_SPREAD = 1e-3            # rad: below this an area light's Spread counts as zero
DEFAULT_DIFFUSE = 0.8
_LUMA = np.array([0.2126, 0.7152, 0.0722])   # colour -> float conversion of a linked socket
CURVE_TYPE_POLY = 1                 # Blender's curve_type attribute value of a poly curve
MAX_PARTICLE_KEYS = 2_000_000       # particle hair keys read (co_hair: about 1 us a key)


def _as_colour(v) -> np.ndarray:
    """A socket value (colour or float) as RGB."""
    return np.array(v[:3], float) if hasattr(v, "__len__") else np.full(3, float(v))


def _as_scalar(v) -> float:
    """A socket value (colour or float) as a float (a colour by its luminance)."""
    return float(np.dot(_LUMA, v[:3])) if hasattr(v, "__len__") else float(v)


# ---------------------------------------------------------------------------------------------
# Warnings
# ---------------------------------------------------------------------------------------------
class _Warnings:
    """An ordered, deduplicated list of messages."""

    def __init__(self):
        self.messages: list[str] = []
        self._seen: set[str] = set()

    def __call__(self, message: str) -> None:
        if message not in self._seen:
            self._seen.add(message)
            self.messages.append(message)


def _fmt(v) -> str:
    arr = np.atleast_1d(np.asarray(v, dtype=float))
    if arr.size == 1:
        return f"{arr[0]:.4g}"
    return "(" + ", ".join(f"{x:.4g}" for x in arr) + ")"


def _article(word: str) -> str:
    return "an" if word[:1].lower() in "aeiou" else "a"


# ---------------------------------------------------------------------------------------------
# Mesh reading (cached per mesh datablock)
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass
class _MeshData:
    co: np.ndarray          # (V, 3) float32, object space
    tri_verts: np.ndarray   # (T*3,) int32 into co
    tri_loops: np.ndarray   # (T*3,) int32 into corner_normals
    corner_normals: np.ndarray  # (L, 3) float32, object space
    mat_index: np.ndarray   # (T,) int32, material slot per triangle
    corner_loops: np.ndarray | None = None   # (T*3,) int32 into the mesh's corners (UVs)
    uv_maps: dict = dataclasses.field(default_factory=dict)   # name -> (L, 2) float32
    active_uv: str = ""     # the active render UV map's name
    texspace: tuple | None = None   # (location (3,), size (3,)) of the texture space
    # UV map name -> (L, 4) float32 MikkTSpace tangent and bitangent sign per corner (read only
    # for meshes whose materials have a shading normal: ``_read_tangents``)
    tangents: dict | None = None
    # ``"color:<name>"`` / ``"color"`` / ``"attr:<name>"`` -> (T, 3, 4) float32 per triangle
    # corner: the colour and geometry attributes the mesh's materials read
    # (``_read_attributes``; read once per key)
    attributes: dict = dataclasses.field(default_factory=dict)
    strands: bool = False   # hair tubes (``_read_curves``): ``Scene.strands``

    @property
    def count(self) -> int:
        return len(self.mat_index)


def _attribute(mesh, name: str, domain: str, data_type: str, prop: str, dtype, size: int):
    """A mesh attribute read through the attribute API (a raw array copy, fast), or None."""
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != domain or attr.data_type != data_type:
        return None
    width = 3 if prop == "vector" else 1
    out = np.empty(size * width, dtype)
    attr.data.foreach_get(prop, out)
    return out


def _read_mesh(mesh) -> _MeshData | None:
    """Loop triangles, positions and corner normals of ``mesh`` with ``foreach_get``.

    The attribute API (``position``, ``.corner_vert``, ``material_index``) and
    ``loop_triangle_polygons`` copy raw arrays; ``loop_triangles`` is read only for its corner
    indices, the one per-triangle array Blender does not expose raw."""
    calc = getattr(mesh, "calc_loop_triangles", None)   # gone in Blender 5: always up to date
    if calc is not None:
        calc()
    tris = mesh.loop_triangles
    n_tri = len(tris)
    if n_tri == 0:
        return None
    n_vert, n_corner, n_face = len(mesh.vertices), len(mesh.loops), len(mesh.polygons)

    co = _attribute(mesh, "position", "POINT", "FLOAT_VECTOR", "vector", np.float32, n_vert)
    if co is None:
        co = np.empty(n_vert * 3, np.float32)
        mesh.vertices.foreach_get("co", co)

    tri_loops = np.empty(n_tri * 3, np.int32)
    tris.foreach_get("loops", tri_loops)
    corner_vert = _attribute(mesh, ".corner_vert", "CORNER", "INT", "value", np.int32, n_corner)
    if corner_vert is None:
        corner_vert = np.empty(n_corner, np.int32)
        mesh.loops.foreach_get("vertex_index", corner_vert)
    tri_verts = corner_vert[tri_loops]

    face_mat = _attribute(mesh, "material_index", "FACE", "INT", "value", np.int32, n_face)
    tri_face = getattr(mesh, "loop_triangle_polygons", None)
    if face_mat is None:
        mat_index = np.zeros(n_tri, np.int32)
    elif tri_face is not None and len(tri_face) == n_tri:
        faces = np.empty(n_tri, np.int32)
        tri_face.foreach_get("value", faces)
        mat_index = face_mat[faces]
    else:
        mat_index = np.empty(n_tri, np.int32)
        tris.foreach_get("material_index", mat_index)

    corner_loops = tri_loops
    uv_maps, active_uv = _read_uv_maps(mesh, n_corner)
    location = getattr(mesh, "texspace_location", None)
    size = getattr(mesh, "texspace_size", None)
    texspace = None if location is None or size is None else (
        np.array(location[:3], np.float64), np.array(size[:3], np.float64))
    corner = getattr(mesh, "corner_normals", None)
    if corner is not None and len(corner) == n_corner:
        normals = np.empty(n_corner * 3, np.float32)
        corner.foreach_get("vector", normals)
    else:  # older Blender: per-triangle split normals
        normals = np.empty(n_tri * 9, np.float32)
        tris.foreach_get("split_normals", normals)
        tri_loops = np.arange(n_tri * 3, dtype=np.int32)
    return _MeshData(co.reshape(-1, 3), tri_verts, tri_loops, normals.reshape(-1, 3), mat_index,
                     corner_loops, uv_maps, active_uv, texspace)


def curve_shape(scene) -> str:
    """Cycles' Render > Curves > Shape of ``scene``: "RIBBONS", "THICK" or "THICK_LINEAR"."""
    settings = getattr(scene, "cycles_curves", None)
    return str(getattr(settings, "shape", "THICK")) if settings is not None else "THICK"


def _hair_data(tubes, curve_numbers) -> _MeshData:
    """Tubes (``engine/hair.py``) as mesh data: one corner per vertex, every triangle in the
    first slot, flagged as strands, with Curves Info per corner (``attributes["hair"]``:
    intercept, length, thickness = 2 x radius, Cycles' random of the curve's number in
    ``curve_numbers`` (per vertex))."""
    tri_verts = tubes.triangles.reshape(-1).astype(np.int32)
    random = procedural.hash_uint2(np.asarray(curve_numbers, np.int64), 0).astype(np.float64) \
        / float(0xFFFFFFFF)
    info = np.stack([tubes.vertex_intercept, tubes.vertex_length, 2.0 * tubes.vertex_radius,
                     random], axis=1).astype(np.float32)
    data = _MeshData(tubes.vertices, tri_verts, tri_verts, tubes.normals,
                     np.zeros(len(tubes.triangles), np.int32), tri_verts, {}, "", None,
                     strands=True)
    data.attributes["hair"] = info[tri_verts].reshape(-1, 3, 4)
    return data


def _read_curves(curves, shape: str, warn, owner: str) -> _MeshData | None:
    """A Curves object's curves as tubes of triangles (``engine/hair.py``), read as Cycles
    reads them (``sync_hair``): the control points themselves, the ``radius`` attribute or
    0.005 m, a spline through the points unless the first curve is a poly curve or the
    scene's shape is Linear 3D Curves, every curve with the object's first material, and the
    first 2-D curve attribute (the surface UV of hair grown on a mesh) as its UV map."""
    n_points, n_curves = len(curves.points), len(curves.curves)
    if n_points == 0 or n_curves == 0:
        return None
    co = np.empty(n_points * 3, np.float32)
    curves.position_data.foreach_get("vector", co)
    offsets = np.empty(n_curves + 1, np.int32)
    curves.curve_offset_data.foreach_get("value", offsets)
    radius = _attribute(curves, "radius", "POINT", "FLOAT", "value", np.float32, n_points)
    if radius is None:
        radius = np.full(n_points, hair.DEFAULT_RADIUS, np.float32)
    types = _attribute(curves, "curve_type", "CURVE", "INT8", "value", np.int8, n_curves)
    smooth = shape != "THICK_LINEAR" and not (types is not None and types[0] == CURVE_TYPE_POLY)
    try:
        tubes = hair.tessellate_curves(co.reshape(-1, 3), radius, offsets, smooth=smooth)
    except ValueError as exc:
        warn(f"{owner}: its curves cannot be read ({exc}); skipped")
        return None
    if tubes.skipped:
        warn(f"{owner}: skipped {tubes.skipped} curves with fewer than two points or with "
             "non-finite positions or radii")
    for note in tubes.notes:
        warn(f"{owner}: {note}")
    if shape == "RIBBONS":
        warn(f"{owner}: Cycles' Rounded Ribbons are rendered as 3D curves (round tubes)")
    if len(tubes.triangles) == 0:
        return None
    data = _hair_data(tubes, tubes.vertex_curves)
    for attr in curves.attributes:
        if attr.domain == "CURVE" and attr.data_type == "FLOAT2" \
                and not attr.name.startswith("."):
            uv = np.empty(n_curves * 2, np.float32)
            attr.data.foreach_get("vector", uv)
            data.uv_maps[attr.name] = uv.reshape(-1, 2)[tubes.vertex_curves]
            data.active_uv = attr.name
            break
    return data


def _read_tangents(mesh, data: _MeshData, warn, owner: str) -> dict:
    """UV map name -> (L, 4) float32: the MikkTSpace tangent (x, y, z) and bitangent sign per
    corner, as Blender's ``calc_tangents`` gives them (what Cycles interpolates for a
    tangent-space Normal Map). Where Blender cannot (faces of more than four corners), the
    triangles' own UV gradients, orthogonalised to each corner's normal, with a warning."""
    out = {}
    n_corner = len(mesh.loops)
    for name in data.uv_maps:
        try:
            mesh.calc_tangents(uvmap=name)
            t = np.empty(n_corner * 3, np.float32)
            sign = np.empty(n_corner, np.float32)
            mesh.loops.foreach_get("tangent", t)
            mesh.loops.foreach_get("bitangent_sign", sign)
            out[name] = np.concatenate([t.reshape(-1, 3), sign[:, None]], axis=1)
        except (RuntimeError, AttributeError) as error:
            warn(f"{owner}: Blender gives no tangents for UV map '{name}' ({error}); the "
                 "Normal Map uses each triangle's UV gradient instead")
            out[name] = _gradient_tangents(data, data.uv_maps[name], n_corner)
        finally:
            free = getattr(mesh, "free_tangents", None)
            if free is not None:
                free()
    return out


def _gradient_tangents(data: _MeshData, uv: np.ndarray, n_corner: int) -> np.ndarray:
    """(L, 4) float32 tangents from each triangle's UV gradient dP/du, orthogonalised to the
    corner normal, with the bitangent sign of dP/dv (corners of several triangles keep the
    last)."""
    n_tri = data.count
    p = data.co[data.tri_verts].reshape(n_tri, 3, 3).astype(np.float64)
    t_uv = uv[data.corner_loops].reshape(n_tri, 3, 2).astype(np.float64)
    dp1, dp2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    du1, dv1 = t_uv[:, 1, 0] - t_uv[:, 0, 0], t_uv[:, 1, 1] - t_uv[:, 0, 1]
    du2, dv2 = t_uv[:, 2, 0] - t_uv[:, 0, 0], t_uv[:, 2, 1] - t_uv[:, 0, 1]
    det = du1 * dv2 - du2 * dv1
    inv = np.where(np.abs(det) > 1e-20, 1.0 / np.where(det == 0, 1.0, det), 0.0)[:, None]
    tangent = (dp1 * dv2[:, None] - dp2 * dv1[:, None]) * inv
    bitangent = (dp2 * du1[:, None] - dp1 * du2[:, None]) * inv
    out = np.zeros((n_corner, 4), np.float32)
    n = data.corner_normals[data.tri_loops].reshape(n_tri, 3, 3).astype(np.float64)
    corners = data.corner_loops.reshape(n_tri, 3)
    for k in range(3):
        t = tangent - np.einsum("ij,ij->i", tangent, n[:, k])[:, None] * n[:, k]
        t /= np.maximum(np.linalg.norm(t, axis=1), 1e-20)[:, None]
        sign = np.where(np.einsum("ij,ij->i", np.cross(n[:, k], t), bitangent) < 0, -1.0, 1.0)
        out[corners[:, k], :3] = t
        out[corners[:, k], 3] = sign
    return out


# Attribute data types -> (the ``foreach_get`` property, its width); others are not read.
_ATTRIBUTE_TYPES = {"FLOAT": ("value", 1), "INT": ("value", 1), "BOOLEAN": ("value", 1),
                    "INT8": ("value", 1), "FLOAT_VECTOR": ("vector", 3),
                    "FLOAT2": ("vector", 2), "FLOAT_COLOR": ("color", 4),
                    "BYTE_COLOR": ("color", 4)}


def _default_color_name(mesh) -> str:
    """The colour attribute Cycles reads for a Color Attribute node with no name (the mesh's
    default, i.e. render, colour attribute), or ""."""
    attrs = getattr(mesh, "color_attributes", None)
    if attrs is None:
        return ""
    name = getattr(attrs, "default_color_name", "") or ""
    if not name:
        index = getattr(attrs, "render_color_index", -1)
        if 0 <= index < len(attrs):
            name = attrs[index].name
    return name


def _read_attributes(mesh, data: _MeshData, keys, warn, owner: str) -> None:
    """Fill ``data.attributes`` for the attribute keys ``keys`` (``"color"``,
    ``"color:<name>"``, ``"attr:<name>"``) not yet read: (T, 3, 4) float32 per triangle corner,
    as Cycles interpolates them. Colours are Blender's scene-linear values (a byte colour's
    ``color``, as Cycles linearises it before interpolating); numbers fill (f, f, f, 1),
    vectors (x, y, z, 1), 2-D vectors (x, y, 0, 1) (with a warning: Cycles' Fac of such an
    attribute is x, the evaluator gives the mean of the three components). Point attributes
    are taken at each corner's vertex, face attributes on the whole triangle. A mesh that
    lacks the attribute gets zeros (alpha 0 too), as Cycles reads a missing attribute; an
    edge-domain or unsupported type is reported and read as missing. UV maps named by an
    Attribute node come from ``data.uv_maps``."""
    n_tri = data.count

    def two_d(name: str) -> str:
        return (f"{owner}: an Attribute node reads the 2-D attribute '{name}'; its Fac is the "
                "mean of (x, y, 0) here, Cycles gives x")

    for key in keys:
        if key in data.attributes or not key.startswith(("color", "attr:")):
            continue
        out = np.zeros((n_tri, 3, 4), np.float32)
        data.attributes[key] = out
        name = key.split(":", 1)[1] if ":" in key else _default_color_name(mesh)
        if not name:
            continue
        if key.startswith("attr:") and name in data.uv_maps:
            uv = data.uv_maps[name][data.corner_loops].reshape(n_tri, 3, 2)
            out[..., :2], out[..., 3] = uv, 1.0
            warn(two_d(name))
            continue
        attr = mesh.attributes.get(name)
        if attr is None:
            continue
        kind = _ATTRIBUTE_TYPES.get(attr.data_type)
        sizes = {"POINT": len(mesh.vertices), "CORNER": len(mesh.loops),
                 "FACE": len(mesh.polygons)}
        if kind is None or attr.domain not in sizes:
            warn(f"{owner}: attribute '{name}' ({attr.data_type.lower()} on the "
                 f"{attr.domain.lower()} domain) cannot be read by shader nodes; it reads 0")
            continue
        prop, width = kind
        size = sizes[attr.domain]
        values = np.empty(size * width, np.float64 if prop == "value" else np.float32)
        attr.data.foreach_get(prop, values)
        values = values.reshape(size, width).astype(np.float32)
        if attr.domain == "POINT":
            per_corner = values[data.tri_verts]
        elif attr.domain == "CORNER":
            per_corner = values[data.corner_loops]
        else:
            per_corner = np.repeat(values[_triangle_faces(mesh, n_tri)], 3, axis=0)
        per_corner = per_corner.reshape(n_tri, 3, width)
        if width == 1:
            out[..., :3], out[..., 3] = per_corner, 1.0
        elif width == 4:
            out[:] = per_corner
        else:
            out[..., :width], out[..., 3] = per_corner, 1.0
            if width == 2:
                warn(two_d(name))
        if not np.all(np.isfinite(out)):
            warn(f"{owner}: attribute '{name}' holds NaN or infinite values; they read 0")
            np.nan_to_num(out, copy=False, nan=0.0, posinf=0.0, neginf=0.0)


def _triangle_faces(mesh, n_tri: int) -> np.ndarray:
    """(T,) int32: the face each loop triangle belongs to."""
    faces = np.empty(n_tri, np.int32)
    tri_face = getattr(mesh, "loop_triangle_polygons", None)
    if tri_face is not None and len(tri_face) == n_tri:
        tri_face.foreach_get("value", faces)
    else:
        mesh.loop_triangles.foreach_get("polygon_index", faces)
    return faces


def _read_uv_maps(mesh, n_corner: int):
    """({name: (L, 2) float32}, the active render map's name) of ``mesh``'s UV maps."""
    maps, active = {}, ""
    layers = getattr(mesh, "uv_layers", None)
    if layers is None or n_corner == 0:
        return maps, active
    for layer in layers:
        out = np.empty(n_corner * 2, np.float32)
        data = getattr(layer, "uv", None)
        if data is not None and len(data) == n_corner:
            data.foreach_get("vector", out)
        else:
            layer.data.foreach_get("uv", out)
        maps[layer.name] = out.reshape(-1, 2)
        if getattr(layer, "active_render", False):
            active = layer.name
    if not active and maps:
        current = getattr(layers, "active", None)
        active = current.name if current is not None else next(iter(maps))
    return maps, active


def _corner_attribute(data: _MeshData, key: str) -> np.ndarray:
    """(T, 3, k) float32: one per-corner coordinate of a mesh's triangles (object space;
    ``Scene.corner_attributes``); zeros where the mesh lacks it (a UV map it has not)."""
    n_tri = data.count
    if key == "position":
        return data.co[data.tri_verts].reshape(n_tri, 3, 3)
    if key == "normal":
        return data.corner_normals[data.tri_loops].reshape(n_tri, 3, 3)
    if key == "generated":
        co = data.co.astype(np.float64)
        if data.texspace is not None:
            location, size = data.texspace
        else:
            low, high = co.min(axis=0), co.max(axis=0)
            location, size = (low + high) / 2, (high - low) / 2
        size = np.where(np.abs(size) > 1e-12, size, 1.0)
        generated = (co - (location - size)) / (2.0 * size)
        return generated[data.tri_verts].astype(np.float32).reshape(n_tri, 3, 3)
    if key.startswith(("color", "attr:")) or key == "hair":
        attribute = data.attributes.get(key)
        return attribute if attribute is not None else np.zeros((n_tri, 3, 4), np.float32)
    if key.startswith("tangent"):
        name = data.active_uv if key == "tangent" else key[8:]
        tangent = (data.tangents or {}).get(name)
        if tangent is None:
            return np.zeros((n_tri, 3, 4), np.float32)
        return tangent[data.corner_loops].reshape(n_tri, 3, 4)
    name = data.active_uv if key == "uv" else key[3:]
    uv = data.uv_maps.get(name)
    if uv is None:
        return np.zeros((n_tri, 3, 2), np.float32)
    return uv[data.corner_loops].reshape(n_tri, 3, 2)


def _gather_rows(src: np.ndarray, index: np.ndarray, out: np.ndarray) -> None:
    """out[i] = src[index[i]] for (N, 3) float32 rows, as one 12-byte item per row (faster than
    ``np.take(axis=0)``)."""
    row = np.dtype((np.void, 12))
    src = np.ascontiguousarray(src, dtype=np.float32)
    np.take(src.view(row).reshape(-1), index, out=out.view(row).reshape(-1))


def _normal_matrices(m3: np.ndarray) -> np.ndarray:
    """Cofactor matrices of (N, 3, 3) ``m3`` times sign(det): they transform normals like the
    inverse transpose (up to a positive scale) and stay defined for singular matrices."""
    a, b, c = m3[:, :, 0], m3[:, :, 1], m3[:, :, 2]
    bc = np.cross(b, c)
    cof = np.stack([bc, np.cross(c, a), np.cross(a, b)], axis=2)
    det = np.einsum("ij,ij->i", a, bc)
    return cof * np.where(det < 0, -1.0, 1.0)[:, None, None]


@dataclasses.dataclass
class _Group:
    """Instances of one mesh with one material mapping."""
    data: _MeshData
    lut: np.ndarray                     # material slot -> global material id
    matrices: list = dataclasses.field(default_factory=list)     # 4x4 world matrices
    names: list = dataclasses.field(default_factory=list)       # object name per instance
    object_ids: np.ndarray | None = None


# ---------------------------------------------------------------------------------------------
# Materials
# ---------------------------------------------------------------------------------------------
# The sockets each closure parameter is read from (the names ``_NodeReader.colour`` /
# ``scalar`` are asked for), in order: a parameter of two sockets is their product.
_PARAM_SOCKETS = {
    "principled": {
        "base_color": [("Base Color",)], "metallic": [("Metallic",)],
        "roughness": [("Roughness",)], "ior": [("IOR",)], "alpha": [("Alpha",)],
        "diffuse_roughness": [("Diffuse Roughness",)],
        "subsurface_weight": [("Subsurface Weight",)],
        "specular_ior_level": [("Specular IOR Level",)], "specular_tint": [("Specular Tint",)],
        "anisotropic": [("Anisotropic",)], "anisotropic_rotation": [("Anisotropic Rotation",)],
        "transmission": [("Transmission Weight", "Transmission")],
        "coat_weight": [("Coat Weight",)], "coat_roughness": [("Coat Roughness",)],
        "coat_ior": [("Coat IOR",)], "coat_tint": [("Coat Tint",)],
        "sheen_weight": [("Sheen Weight",)], "sheen_roughness": [("Sheen Roughness",)],
        "sheen_tint": [("Sheen Tint",)],
        "emission": [("Emission Color", "Emission"), ("Emission Strength",)],
        "thin_film_thickness": [("Thin Film Thickness",)], "thin_film_ior": [("Thin Film IOR",)],
    },
    "diffuse": {"color": [("Color",)], "roughness": [("Roughness",)]},
    "emission": {"radiance": [("Color",), ("Strength",)]},
    "glossy": {"color": [("Color",)], "roughness": [("Roughness",)],
               "anisotropy": [("Anisotropy",)], "rotation": [("Rotation",)]},
    "metallic": {"base_color": [("Base Color",)], "edge_tint": [("Edge Tint",)],
                 "roughness": [("Roughness",)], "anisotropy": [("Anisotropy",)],
                 "rotation": [("Rotation",)], "thin_film_thickness": [("Thin Film Thickness",)],
                 "thin_film_ior": [("Thin Film IOR",)]},
    "glass": {"color": [("Color",)], "roughness": [("Roughness",)], "ior": [("IOR",)],
              "thin_film_thickness": [("Thin Film Thickness",)],
              "thin_film_ior": [("Thin Film IOR",)]},
    "refraction": {"color": [("Color",)], "roughness": [("Roughness",)], "ior": [("IOR",)]},
    "transparent": {"color": [("Color",)]},
    "translucent": {"color": [("Color",)]},
    "sheen": {"color": [("Color",)], "roughness": [("Roughness",)]},
}
_COORDINATE_KEYS = ("uv", "position", "normal", "generated", "color", "attr", "hair")
# What a shading normal's nodes (Normal Map) may read besides those: the per-corner MikkTSpace
# tangents, the per-triangle normal matrix, and the camera hit's own world-space values
# (``nodes`` module docstring), which the integrator hands over (``bsdf.MaterialTable``).
_NORMAL_KEYS = ("tangent", "normal_matrix")
_HIT_KEYS = ("normal_world", "true_normal_world", "incoming", "backfacing", "position_world",
             "dPdx", "dPdy")
_DIFFERENTIAL_KEYS = ("dx", "dy")     # "dx:<key>": the change of <key> across the footprint
_VIEW_KEYS = _HIT_KEYS[:5]            # what every hit's view gives (no footprint)


class _CoordinateRecorder(dict):
    """Per-hit inputs for a trial evaluation of a node graph at one point: answers every
    coordinate ``Scene.corner_attributes`` can hold with zeros and records which were read;
    with ``shading_normal`` also what a Normal Map reads (``_NORMAL_KEYS``, ``_HIT_KEYS``)."""

    def __init__(self, shading_normal: bool = False):
        super().__init__()
        self.asked: set = set()
        # A closure input may read the hit's view and world-space values too (Fresnel, Layer
        # Weight, Geometry: ``textures.VIEW_NODES``), which every hit hands over.
        self.keys = _COORDINATE_KEYS + (_NORMAL_KEYS + _HIT_KEYS + _DIFFERENTIAL_KEYS
                                        if shading_normal else _VIEW_KEYS)

    def __contains__(self, key) -> bool:
        return isinstance(key, str) and key.split(":", 1)[0] in self.keys

    def __getitem__(self, key):
        if key not in self:
            raise KeyError(key)
        base = key.split(":", 1)[1] if key.split(":", 1)[0] in _DIFFERENTIAL_KEYS else key
        if base in _HIT_KEYS:
            return np.zeros(1) if base == "backfacing" else np.zeros((1, 3))
        if base != key and base.split(":", 1)[0] not in self.keys:
            raise KeyError(key)
        self.asked.add(base)
        key = base
        if key == "normal_matrix":
            return np.eye(3)[None]
        if key.startswith("tangent"):
            return np.array([[1.0, 0.0, 0.0, 1.0]])
        if key.startswith(("color", "attr", "hair")):
            return np.zeros((1, 4))
        return np.zeros((1, 2) if key.startswith("uv") else (1, 3))

    def get(self, key, default=None):
        return self[key] if key in self else default


class _NodeReader:
    """Evaluates a material's (or world's) shader nodes into constant radiometric values; with
    a material's ``tree``, inputs driven by nodes the evaluator supports are kept per-hit
    (``driven``; :meth:`attach_textures`)."""

    def __init__(self, owner: str, warn: _Warnings, tree=None, images: dict | None = None,
                 constants=None, baker=None, material=None):
        self.owner = owner      # e.g. "Material 'Wood'"
        self.warn = warn
        self.tree = tree
        # A material's: ``node_bake.NodeBaker`` for inputs driven by unsupported nodes, and
        # the bpy material it bakes (None: such inputs take their sockets' defaults).
        self.baker, self.material = baker, material
        # A world's: (Light Path inputs, graph maker): linked inputs whose nodes need nothing
        # per hit are evaluated to one constant for that ray (``world_export.CAMERA_RAY``).
        self.constants = constants
        self.images = {} if images is None else images
        self.graph = None       # the tree as ``nodes.Graph``, read when first needed
        # (node name, socket names) -> (graph socket, the socket's own value, label) for
        # inputs driven by supported nodes; ``values``: every constant read, same keys.
        self.driven: dict = {}
        self.values: dict = {}
        self.coordinates: set = set()     # per-corner coordinates the graphs read
        self.normals: list = []           # (shader node, graph socket) of driven Normals

    def _graph_socket(self, src_node, out, shading_normal: bool = False):
        """(node name, output identifier) when the evaluator supports the nodes feeding this
        output (a trial evaluation; ``shading_normal``: as a Normal input, which may read
        tangents and the hit's world-space values), else None with the reason."""
        if self.graph is None:
            self.graph = export_graph(self.tree, self.warn, self.images)
        socket = (src_node.name, out.identifier)
        recorder = _CoordinateRecorder(shading_normal)
        try:
            nodes.evaluate(self.graph, socket, recorder, n=1)
        except nodes.UnsupportedNode as error:
            return None, str(error)
        except (nodes.MissingInput, KeyError) as error:
            return None, f"a coordinate that is not exported ({error})"
        self.coordinates |= recorder.asked
        return socket, ""

    def _baked_socket(self, src_node, out, fallback: str):
        """(graph socket of a Cycles bake of the subtree feeding ``out``, the report's words
        for it), or (None, ``fallback`` with the reason no bake was made): the bake's image
        (``node_bake``) read by an Image Texture (Linear, Extend) through the UV map it was
        baked through, added to the graph."""
        try:
            image, uv_name, note = self.baker.bake(self.material, src_node, out)
        except node_bake.BakeRefused as refused:
            return None, f"{fallback} ({refused})"
        except (RuntimeError, ValueError, KeyError) as error:
            return None, (f"{fallback} (Blender's bake failed: "
                          f"{' '.join(str(error).split())})")
        name = f"lanterna bake: {src_node.name} {out.identifier}"
        uv_node, texture = f"{name} (UV)", f"{name} (image)"
        self.graph.images[name] = image
        self.graph.nodes[uv_node] = nodes.Node("ShaderNodeUVMap", uv_node, {"uv_map": uv_name},
                                               {}, {"UV": "VECTOR"})
        self.graph.nodes[texture] = nodes.Node(
            "ShaderNodeTexImage", texture,
            {"interpolation": "Linear", "projection": "FLAT", "extension": "EXTEND",
             "image": name}, {"Vector": ("VECTOR", [0.0, 0.0, 0.0])},
            {"Color": "RGBA", "Alpha": "VALUE"})
        self.graph.links[(texture, "Vector")] = (uv_node, "UV")
        socket = (texture, "Color")
        recorder = _CoordinateRecorder()
        nodes.evaluate(self.graph, socket, recorder, n=1)
        self.coordinates |= recorder.asked
        size = image.pixels.shape[1]
        return socket, f"baked by Cycles into a {size}x{size} image {note}"

    def attach_textures(self, closure: Closure, node) -> Closure:
        """``closure`` with ``textures`` for each of its parameters whose sockets are driven
        (``_PARAM_SOCKETS``); those entries leave ``driven``."""
        for param, sockets in _PARAM_SOCKETS.get(closure.kind, {}).items():
            keys = [(node.name, names) for names in sockets]
            if not any(k in self.driven for k in keys):
                continue
            factors = []
            for k in keys:
                if k in self.driven:
                    factors.append((self.driven.pop(k)[0], None))
                else:
                    factors.append((None, self.values.get(k, 1.0)))
            closure.textures[param] = factors
        return closure

    # Links ---------------------------------------------------------------------------------
    def source(self, socket):
        """(node, output socket) feeding input ``socket``, through reroutes and muted nodes;
        None when nothing (or a muted link) feeds it. A link Blender marks invalid (one that
        closes a loop of nodes, which Blender and Cycles ignore) feeds nothing, with a warning
        naming the nodes."""
        for _ in range(256):
            if socket is None or not socket.is_linked:
                return None
            link = socket.links[0]
            if getattr(link, "is_muted", False):
                return None
            if not getattr(link, "is_valid", True):
                self.warn(f"{self.owner}: the link from '{link.from_node.name}' to "
                          f"'{link.to_node.name}' closes a loop of nodes, which Blender and "
                          f"Cycles ignore; {link.to_socket.name} of '{link.to_node.name}' gets "
                          "nothing")
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

    @staticmethod
    def input(node, *names):
        for name in names:
            sock = node.inputs.get(name)
            if sock is not None:
                return sock
        return None

    def _linked_warning(self, node, sock, src_node, what: str, value) -> None:
        label = src_node.bl_label
        named = "" if src_node.name == label else f" ('{src_node.name}')"
        self.warn(f"{self.owner}: {sock.name} of '{node.name}' is driven by {_article(label)} "
                  f"{label} node{named}; using its default {what} {_fmt(value)}")

    def _constant(self, node, names, default, convert, what):
        """The input's value: its own default, or a constant RGB / Value node linked to it;
        anything else linked is warned about (naming ``what``) and the default is used.
        ``convert`` turns a socket value (a float or a sequence) into the wanted type."""
        sock = self.input(node, *names)
        if sock is None:
            return convert(default)
        if self.constants is not None:     # a world: past the mixes its ray decides
            sock = decided_socket(sock, *self.constants)
        value = convert(sock.default_value) if hasattr(sock, "default_value") else convert(default)
        self.values[(node.name, tuple(names))] = value
        src = self.source(sock)
        if src is None:
            return value
        src_node, out = src
        if src_node.type in ("RGB", "VALUE") and hasattr(out, "default_value"):
            return convert(out.default_value)
        if self.constants is not None:
            evaluated = constant_for_ray(src_node, out, *self.constants)
            if evaluated is not None:
                return convert(evaluated)
        if self.tree is not None:
            socket, reason = self._graph_socket(src_node, out)
            fallback = f"using its default {what} {_fmt(value)}"
            if socket is None and reason.startswith("unsupported node") and \
                    self.baker is not None:
                socket, fallback = self._baked_socket(src_node, out, fallback)
                if socket is not None:
                    self.driven[(node.name, tuple(names))] = (socket, value, sock.name)
            elif socket is not None:
                self.driven[(node.name, tuple(names))] = (socket, value, sock.name)
                self.values[(node.name, tuple(names))] = value
                return value
            self.warn(f"{self.owner}: {sock.name} of '{node.name}' is driven by nodes Lanterna "
                      f"cannot evaluate ({reason}); {fallback}")
            return value
        self._linked_warning(node, sock, src_node, what, value)
        return value

    def colour(self, node, *names, default=(0.0, 0.0, 0.0)) -> np.ndarray:
        return self._constant(node, names, default, _as_colour, "colour")

    def scalar(self, node, *names, default=0.0) -> float:
        return self._constant(node, names, default, _as_scalar, "value")

    def check_normal(self, node, socket_name: str = "Normal") -> None:
        """A linked vector input (Normal, Coat Normal, Tangent). A shader's Normal driven by
        nodes the evaluator supports (Normal Map, vector maths ...) becomes the material's
        shading normal (``normals``: (shader node, graph socket)); anything else (Bump, Coat
        Normal, custom tangents) is ignored with a warning."""
        sock = node.inputs.get(socket_name)
        src = self.source(sock) if sock is not None else None
        if src is None:
            return
        label = src[0].bl_label
        reason = ""
        if socket_name == "Normal" and self.tree is not None:
            socket, reason = self._graph_socket(*src, shading_normal=True)
            if socket is not None:
                self.normals.append((node.name, socket))
                return
        what = ("custom tangents are ignored" if socket_name == "Tangent"
                else "bump and normal mapping are ignored")
        why = f" ({reason})" if reason else ""
        self.warn(f"{self.owner}: {socket_name} of '{node.name}' is driven by "
                  f"{_article(label)} {label} node; {what}{why}")

    # Shaders -------------------------------------------------------------------------------
    def _principled(self, node) -> Closure:
        c, x = self.colour, self.scalar
        emission = (c(node, "Emission Color", "Emission", default=(1, 1, 1))
                    * x(node, "Emission Strength", default=0.0))
        params = {
            "base_color": c(node, "Base Color", default=(0.8, 0.8, 0.8)),
            "metallic": float(np.clip(x(node, "Metallic"), 0, 1)),
            "roughness": float(np.clip(x(node, "Roughness", default=0.5), 0, 1)),
            "ior": x(node, "IOR", default=1.5),
            "alpha": float(np.clip(x(node, "Alpha", default=1.0), 0, 1)),
            "thin_wall": float(bool(x(node, "Thin Wall", default=0.0))),
            "diffuse_roughness": float(np.clip(x(node, "Diffuse Roughness"), 0, 1)),
            "subsurface_weight": float(np.clip(x(node, "Subsurface Weight"), 0, 1)),
            "specular_ior_level": max(x(node, "Specular IOR Level", default=0.5), 0.0),
            "specular_tint": c(node, "Specular Tint", default=(1, 1, 1)),
            "anisotropic": float(np.clip(x(node, "Anisotropic"), 0, 1)),
            "anisotropic_rotation": x(node, "Anisotropic Rotation"),
            "transmission": float(np.clip(x(node, "Transmission Weight", "Transmission"), 0, 1)),
            "coat_weight": max(x(node, "Coat Weight"), 0.0),
            "coat_roughness": float(np.clip(x(node, "Coat Roughness", default=0.03), 0, 1)),
            "coat_ior": x(node, "Coat IOR", default=1.5),
            "coat_tint": c(node, "Coat Tint", default=(1, 1, 1)),
            "sheen_weight": max(x(node, "Sheen Weight"), 0.0),
            "sheen_roughness": float(np.clip(x(node, "Sheen Roughness", default=0.5), 0, 1)),
            "sheen_tint": c(node, "Sheen Tint", default=(1, 1, 1)),
            "emission": emission,
            "thin_film_thickness": max(x(node, "Thin Film Thickness"), 0.0),
            "thin_film_ior": x(node, "Thin Film IOR", default=1.33),
        }
        for vector in ("Normal", "Coat Normal", "Tangent"):
            self.check_normal(node, vector)
        return self.attach_textures(Closure("principled", params=params, node=node.name,
                                            distribution=getattr(node, "distribution", "")), node)

    def _microfacet(self, node, kind: str) -> Closure:
        c, x = self.colour, self.scalar
        params = {"roughness": float(np.clip(x(node, "Roughness", default=0.5), 0, 1))}
        if kind == "metallic":
            params.update(base_color=c(node, "Base Color", default=(0.617, 0.577, 0.540)),
                          edge_tint=c(node, "Edge Tint", default=(0.695, 0.726, 0.770)),
                          physical=float(getattr(node, "fresnel_type", "F82") != "F82"))
            for key, sock_name in (("ior", "IOR"), ("extinction", "Extinction")):
                sock = self.input(node, sock_name)
                if sock is not None:
                    params[key] = np.array(sock.default_value[:3], float)
        else:
            params["color"] = c(node, "Color", default=(0.8, 0.8, 0.8))
        if kind in ("glossy", "metallic"):
            params["anisotropy"] = float(np.clip(x(node, "Anisotropy"), -1, 1))
            params["rotation"] = x(node, "Rotation")
        if kind in ("glass", "refraction"):
            params["ior"] = x(node, "IOR", default=1.5 if kind == "glass" else 1.45)
        if kind in ("glass", "metallic"):
            params["thin_film_thickness"] = max(x(node, "Thin Film Thickness"), 0.0)
            params["thin_film_ior"] = x(node, "Thin Film IOR", default=1.33)
        for vector in ("Normal", "Tangent"):
            self.check_normal(node, vector)
        return self.attach_textures(Closure(kind, params=params, node=node.name,
                                            distribution=getattr(node, "distribution", "")), node)

    def closures(self, src, depth: int = 0) -> list:
        """The weighted closures of the shader feeding a socket, as Cycles flattens a shader
        tree (Mix Shader: (1 - Fac) and Fac times its inputs' closures; Add Shader: both
        lists); empty when unlinked."""
        if src is None:
            return []
        node, out = src
        t = node.type
        name = f"'{node.name}'"
        grey = [Closure("diffuse", params={"color": np.full(3, DEFAULT_DIFFUSE)}, node=node.name)]
        if depth > 64:
            self.warn(f"{self.owner}: shader nodes nested too deep at {name}; using grey")
            return grey
        if out.type != "SHADER":
            self.warn(f"{self.owner}: {node.bl_label} node {name} (not a shader) feeds a shader "
                      f"input; using grey diffuse {DEFAULT_DIFFUSE}")
            return grey
        if t == "BSDF_PRINCIPLED":
            principled = self._principled(node)
            alpha = principled.params["alpha"]
            factors = principled.textures.get("alpha", ())
            if len(factors) == 1 and factors[0][0] is not None:
                # An Alpha driven by nodes (an image's alpha): Cycles mixes the Transparent
                # BSDF in per hit, as a Mix Shader whose Fac is the Alpha (clamped to [0, 1]).
                socket = tuple(principled.textures.pop("alpha")[0][0])
                principled.params["alpha"] = 1.0
                clear = Closure("transparent", params={"color": np.ones(3)}, node=node.name)
                return [_weighted(principled, socket, alpha),
                        _weighted(clear, socket + (textures.COMPLEMENT,), 1.0 - alpha)]
            if alpha < 1 and "alpha" not in principled.textures:
                # Cycles: Alpha mixes a Transparent BSDF in, (1 - Alpha) of the light.
                principled.params["alpha"] = 1.0
                return [principled.scaled(alpha),
                        Closure("transparent", params={"color": np.ones(3)},
                                node=node.name).scaled(1.0 - alpha)]
            return [principled]
        if t == "BSDF_DIFFUSE":
            self.check_normal(node)
            return [self.attach_textures(Closure("diffuse", params={
                "color": self.colour(node, "Color", default=(0.8, 0.8, 0.8)),
                "roughness": float(np.clip(self.scalar(node, "Roughness"), 0, 1))},
                node=node.name), node)]
        if t == "EMISSION":
            return [self.attach_textures(Closure("emission", params={
                "radiance": (self.colour(node, "Color", default=(1, 1, 1))
                             * self.scalar(node, "Strength", default=1.0))}, node=node.name),
                node)]
        kinds = {"BSDF_GLOSSY": "glossy", "BSDF_ANISOTROPIC": "glossy",
                 "BSDF_METALLIC": "metallic", "BSDF_GLASS": "glass",
                 "BSDF_REFRACTION": "refraction"}
        if t in kinds:
            return [self._microfacet(node, kinds[t])]
        if t in ("MIX_SHADER", "ADD_SHADER"):
            shaders = [s for s in node.inputs if s.type == "SHADER"]
            a = self.closures(self.source(shaders[0]), depth + 1)
            b = self.closures(self.source(shaders[1]), depth + 1)
            if t == "ADD_SHADER":
                return a + b
            fac = float(np.clip(self.scalar(node, "Fac", "Factor", default=0.5), 0, 1))
            driven = next((self.driven.pop(k) for k in ((node.name, ("Fac", "Factor")),)
                           if k in self.driven), None)
            if driven is not None:
                # A Fac driven by nodes the evaluator supports: each closure's weight takes
                # (1 - Fac) or Fac per hit (``textures.WEIGHT``; Cycles clamps it to [0, 1]).
                socket = tuple(driven[0])
                return ([_weighted(c, socket + (textures.COMPLEMENT,), 1.0 - fac) for c in a]
                        + [_weighted(c, socket, fac) for c in b])
            return [c.scaled(1 - fac) for c in a] + [c.scaled(fac) for c in b]
        if t in ("BSDF_TRANSPARENT", "BSDF_TRANSLUCENT", "BSDF_SHEEN"):
            kind = {"BSDF_TRANSPARENT": "transparent", "BSDF_TRANSLUCENT": "translucent",
                    "BSDF_SHEEN": "sheen"}[t]
            params = {"color": self.colour(node, "Color", default=CLOSURE_KINDS[kind]["color"])}
            if kind == "sheen":
                params["roughness"] = float(np.clip(self.scalar(node, "Roughness", default=0.5),
                                                    0, 1))
            if kind != "transparent":
                self.check_normal(node)
            return [self.attach_textures(Closure(kind, params=params, node=node.name), node)]
        if t == "HOLDOUT":
            return [Closure("holdout", node=node.name)]

        colour_sock = self.input(node, "Color", "Base Color")
        if colour_sock is not None:
            colour = self.colour(node, "Color", "Base Color", default=(0.8, 0.8, 0.8))
            self.warn(f"{self.owner}: {node.bl_label} {name} is not supported; treated as a "
                      f"diffuse of colour {_fmt(colour)}")
            return [Closure("diffuse", params={"color": colour}, node=node.name)]
        self.warn(f"{self.owner}: {node.bl_label} {name} is not supported; using grey diffuse "
                  f"{DEFAULT_DIFFUSE}")
        return grey


def _active_output(tree, node_type: str):
    outputs = [n for n in tree.nodes if n.type == node_type]
    for n in outputs:
        if getattr(n, "is_active_output", False) and getattr(n, "target", "ALL") in ("ALL", "CYCLES"):
            return n
    for n in outputs:
        if getattr(n, "target", "ALL") in ("ALL", "CYCLES"):
            return n
    return outputs[0] if outputs else None


def _clamp_reflectances(name: str, diffuse, specular, exitance, warn: _Warnings):
    diffuse, specular, exitance = (np.asarray(x, float) for x in (diffuse, specular, exitance))
    for what, arr in (("diffuse reflectance", diffuse), ("specular reflectance", specular),
                      ("exitance", exitance)):
        if not np.all(np.isfinite(arr)):
            raise SceneError(f"Material '{name}': {what} is not finite ({_fmt(arr)})")
        if np.any(arr < 0):
            warn(f"Material '{name}': negative {what} {_fmt(arr)} clipped to 0")
    diffuse, specular, exitance = (np.maximum(x, 0.0) for x in (diffuse, specular, exitance))
    total = diffuse + specular
    if np.any(total > 1.0):
        warn(f"Material '{name}': diffuse + specular reflectance {_fmt(total)} exceeds 1; "
             f"scaled down to conserve energy")
        scale = 1.0 / np.maximum(total, 1.0)
        diffuse, specular = diffuse * scale, specular * scale
    return diffuse, specular, exitance


def _coordinates_read(materials) -> set:
    """The per-corner coordinates (``Scene.corner_attributes`` keys) the node-driven inputs of
    ``materials`` read, by a trial evaluation of each at one point."""
    keys: set = set()
    for material in materials:
        keys |= _material_coordinates(material)
    return keys


def _weighted(closure: Closure, socket: tuple, default: float) -> Closure:
    """``closure`` with one more per-hit factor on its weight (a Mix Shader's node-driven Fac,
    or its complement, ``default`` the socket's own value so taken):
    ``Closure.textures[textures.WEIGHT]``."""
    out = closure.scaled(1.0)
    out.textures[textures.WEIGHT] = (list(out.textures.get(textures.WEIGHT, []))
                                     + [(socket, default)])
    return out


def _material_coordinates(material) -> set:
    """The per-corner coordinates one material's node-driven inputs and normal read."""
    keys: set = set()
    if getattr(material, "shading_normal", None) is not None:
        recorder = _CoordinateRecorder(shading_normal=True)
        nodes.evaluate(material.graph, tuple(material.shading_normal), recorder, n=1)
        keys |= recorder.asked
    for closure in material.closures:
        for factors in closure.textures.values():
            for socket, _constant in factors:
                if socket is not None:
                    recorder = _CoordinateRecorder()
                    nodes.evaluate(material.graph, tuple(socket[:2]), recorder, n=1)
                    keys |= recorder.asked
    return keys


def _convert_material(mat, warn: _Warnings, images: dict | None = None,
                      baker=None) -> Material:
    """A Blender material -> :class:`Material` (see the module docstring)."""
    name = mat.name
    props = getattr(mat, "lanterna", None)
    if props is not None and not getattr(props, "derive_from_nodes", True):
        d = getattr(props, "diffuse", (DEFAULT_DIFFUSE,) * 3)
        s = getattr(props, "specular", (0.0, 0.0, 0.0))
        e = getattr(props, "exitance", (0.0, 0.0, 0.0))
        d, s, e = _clamp_reflectances(name, d[:3], s[:3], e[:3], warn)
        return Material(name, diffuse=d, specular=s, exitance=e)
    return material_from_nodes(mat, warn, images, baker)


def material_from_nodes(mat, warn=None, images: dict | None = None,
                        baker=None) -> Material:
    """The :class:`Material` derived from ``mat``'s node tree (or its viewport colour when it
    has none), whatever its ``derive_from_nodes`` says: the rules of the module docstring,
    clamped as the render clamps them. ``warn`` (a callable taking a message; default: the
    messages are dropped) receives what the derivation had to approximate; ``images`` (name
    -> ``nodes.Image``) is shared between materials so each image is read once. The Material
    panel shows these values read-only (node-driven inputs at their sockets' own values).
    ``baker`` (``node_bake.NodeBaker``; default None: sockets' defaults) bakes inputs driven
    by nodes the evaluator does not support."""
    warn = warn if warn is not None else _Warnings()
    name = mat.name
    tree = mat.node_tree
    if not compat.uses_nodes(mat):
        # Cycles renders a node-less material as a Diffuse BSDF of the viewport colour.
        d, s, e = _clamp_reflectances(name, mat.diffuse_color[:3], (0, 0, 0), (0, 0, 0), warn)
        return Material(name, diffuse=d, specular=s, exitance=e)

    reader = _NodeReader(f"Material '{name}'", warn, tree, images, baker=baker, material=mat)
    out = _active_output(tree, "OUTPUT_MATERIAL")
    if out is None:
        warn(f"Material '{name}' has no Material Output node; rendered black")
        return Material(name, diffuse=np.zeros(3))
    src = reader.source(out.inputs.get("Surface"))
    if src is None:
        warn(f"Material '{name}': nothing is connected to the Material Output's Surface; "
             f"rendered black")
        return Material(name, diffuse=np.zeros(3))
    closures = reader.closures(src)
    if "Is Shadow Ray" in light_path_outputs(tree):
        warn(f"{reader.owner}: Light Path Is Shadow Ray reads 0 at every hit: Lanterna's "
             "shadow rays stop at every surface and read no material (light through "
             "transparent and glass surfaces comes from photons)")
    # Driven inputs no closure parameter took (a Mix Shader's Fac ...): their defaults.
    for (node_name, _names), (_socket, value, socket_name) in reader.driven.items():
        warn(f"{reader.owner}: {socket_name} of '{node_name}' is driven by nodes; Lanterna "
             f"takes no per-hit value there and uses its default {_fmt(value)}")
    # The static material (the planner's first guess; textured materials are replaced by
    # their means at render time) with each node-driven Mix Fac at its socket's value.
    seed = seed_reduction([c.scaled(textures.default_weight(c)) for c in closures])
    for note in seed.notes:
        warn(f"{reader.owner}: {note}")
    for note in textures.approximations(closures):
        warn(f"{reader.owner}: {note}")
    d, s, e = _clamp_reflectances(name, seed.diffuse, seed.specular, seed.exitance, warn)
    textured = any(c.textures for c in closures)
    shading_normal = _shading_normal(reader, closures, warn)
    return Material(name, diffuse=d, specular=s, exitance=e, closures=tuple(closures),
                    graph=reader.graph if textured or shading_normal else None,
                    shading_normal=shading_normal)


def camera_hidden(obj) -> bool:
    """Whether a geometry object's Visibility > Camera is off (its materials then render as
    ``hidden_from_camera`` makes them)."""
    return not getattr(obj, "visible_camera", True)


# The Light Path node that a camera-hidden object's materials read (``hidden_from_camera``).
HIDDEN_NODE = "Lanterna: Visibility > Camera off"


def hidden_from_camera(material: Material) -> Material:
    """``material`` as an object whose Visibility > Camera is off shows it: camera rays go
    straight on through it (Cycles leaves such an object out of their intersections), every
    other ray meets it as before. Made as Cycles would render Mix(the material, Transparent
    white, Fac = Light Path Is Camera Ray): its closures take the factor 1 - Is Camera Ray and
    a white Transparent closure the factor Is Camera Ray, read from a Light Path node added to
    a copy of its graph. A material without closures (its radiometric values set by hand, or
    no nodes) gets the closures those values stand for (diffuse, sharp glossy, emission)."""
    closures = list(material.closures)
    if not closures:
        closures = [Closure("diffuse", params={"color": material.diffuse, "roughness": 0.0})]
        if np.any(material.specular > 0):
            closures.append(Closure("glossy", params={"color": material.specular,
                                                      "roughness": 0.0}))
        if np.any(material.exitance > 0):
            closures.append(Closure("emission", params={"radiance": material.exitance / math.pi}))
    graph = material.graph
    graph = nodes.Graph(dict(graph.nodes), dict(graph.links), dict(graph.images)) \
        if graph is not None else nodes.Graph()
    graph.nodes[HIDDEN_NODE] = nodes.Node("ShaderNodeLightPath", HIDDEN_NODE, {}, {},
                                          {k: "VALUE" for k in nodes.LIGHT_PATH_CAMERA})
    socket = (HIDDEN_NODE, "Is Camera Ray")
    clear = Closure("transparent", params={"color": np.ones(3)}, node=HIDDEN_NODE)
    closures = ([_weighted(c, socket + (textures.COMPLEMENT,), 1.0) for c in closures]
                + [_weighted(clear, socket, 0.0)])
    return dataclasses.replace(material, closures=tuple(closures), graph=graph)


class _UnsetPrincipled:
    """A Principled BSDF node with no sockets: every input reads its default."""

    name = "Principled BSDF"
    type = "BSDF_PRINCIPLED"
    distribution = "MULTI_GGX"
    inputs: dict = {}


def default_surface(warn=None) -> Material:
    """The material of faces without one, as Cycles renders them
    (``compat.default_surface_is_principled``): a Diffuse BSDF of ``DEFAULT_DIFFUSE`` in
    Blender 4.2 and 4.5, the default Principled BSDF from 5.0 on (its dielectric layer
    darkens a sunlit plane towards the horizon by up to 10 %: the plain diffuse made it that
    much too bright)."""
    if not compat.default_surface_is_principled():
        return Material("Default", diffuse=np.full(3, DEFAULT_DIFFUSE))
    warn = warn if warn is not None else _Warnings()
    closure = _NodeReader("Default surface", warn)._principled(_UnsetPrincipled())
    seed = seed_reduction([closure])
    d, s, e = _clamp_reflectances("Default", seed.diffuse, seed.specular, seed.exitance, warn)
    return Material("Default", diffuse=d, specular=s, exitance=e, closures=(closure,))


def _shading_normal(reader: _NodeReader, closures, warn) -> tuple | None:
    """The graph socket of the material's node-driven Normal (``Material.shading_normal``),
    with a warning saying what it shapes; a second, different one is named and ignored."""
    used = {c.node for c in closures}
    found = [(node, socket) for node, socket in reader.normals if node in used]
    if not found:
        return None
    node, socket = found[0]
    label = reader.graph.nodes[socket[0]].type.removeprefix("ShaderNode")
    warn(f"{reader.owner}: Normal of '{node}' ({label} '{socket[0]}') shades camera hits "
         "(direct light, glossy and glass reflections); indirect diffuse light, photons and "
         "the irradiance cache use the smooth normal")
    for other, other_socket in found[1:]:
        if tuple(other_socket) != tuple(socket):
            warn(f"{reader.owner}: Normal of '{other}' differs from that of '{node}'; one "
                 f"shading normal per material: '{node}''s is used for all its shaders")
    return tuple(socket)


# ---------------------------------------------------------------------------------------------
# Lights
# ---------------------------------------------------------------------------------------------
def _light_emission(reader: _NodeReader, src, depth: int = 0) -> np.ndarray:
    """The colour factor of the shader feeding a Light Output, as Cycles reads it: an Emission
    node's Color x Strength; Add and Mix shaders of emissions combined; anything else warned
    about (naming the node) and taken as 1, i.e. Color x Power."""
    node, out = src
    t = node.type
    if t == "EMISSION":
        return (reader.colour(node, "Color", default=(1.0, 1.0, 1.0))
                * reader.scalar(node, "Strength", default=1.0))
    if t in ("MIX_SHADER", "ADD_SHADER") and depth < 64:
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        parts = []
        for sock in shaders[:2]:
            sub = reader.source(sock)
            parts.append(np.zeros(3) if sub is None else _light_emission(reader, sub, depth + 1))
        if t == "ADD_SHADER":
            return parts[0] + parts[1]
        fac = float(np.clip(reader.scalar(node, "Fac", "Factor", default=0.5), 0, 1))
        return (1 - fac) * parts[0] + fac * parts[1]
    reader.warn(f"{reader.owner}: {node.bl_label} node '{node.name}' feeding the Light Output "
                f"is not supported; using Color x Power")
    return np.ones(3)


def _light_node_factor(name: str, tree, warn: _Warnings) -> np.ndarray | None:
    """What a light's node tree multiplies its Color x Power by (Cycles: the Emission node's
    Strength and Color), or None when nothing reaches the Light Output's Surface: Cycles then
    gives the light no emission, so it is dark (with a warning). Blender 5.2's default tree
    (one Emission node, strength 1, white) gives 1 and no warning."""
    reader = _NodeReader(f"Light '{name}'", warn)
    out = _active_output(tree, "OUTPUT_LIGHT")
    src = None if out is None else reader.source(out.inputs.get("Surface"))
    if src is None:
        what = "has no Light Output node" if out is None else \
            "has nothing connected to the Light Output's Surface"
        warn(f"Light '{name}': its node tree {what}; the light is dark (as in Cycles)")
        return None
    return _light_emission(reader, src)


def _convert_light(name: str, light, matrix: np.ndarray, warn: _Warnings):
    """A Blender light with its 4x4 world matrix -> a core light, or None (zero power)."""
    colour = np.array(light.color[:3], float)
    if getattr(light, "use_temperature", False):
        colour = colour * np.array(light.temperature_color[:3], float)
    power = colour * float(light.energy) * 2.0 ** compat.light_exposure(light)
    tree = compat.node_tree_in_use(light)
    if tree is not None:
        factor = _light_node_factor(name, tree, warn)
        if factor is None:
            return None
        power = power * factor
    if not np.all(np.isfinite(power)):
        raise SceneError(f"Light '{name}': power {_fmt(power)} is not finite")
    if np.all(power == 0):
        return None
    if np.any(power < 0):
        warn(f"Light '{name}': negative power {_fmt(power)} is not supported; light skipped")
        return None
    if not np.all(np.isfinite(matrix)):
        raise SceneError(f"Light '{name}': world matrix is not finite (NaN or infinite "
                         f"location, rotation or scale)")
    normalize = compat.light_normalized(light)
    position = matrix[:3, 3]
    down = -matrix[:3, 2]          # the light's local -Z in world space
    kind = light.type

    if kind in ("POINT", "SPOT"):
        radius = float(getattr(light, "shadow_soft_size", 0.0))
        soft = bool(getattr(light, "use_soft_falloff", True))
        if not normalize:
            warn(f"Light '{name}': Normalize off is not supported; treated as normalized")
        if kind == "POINT":
            return PointLight(name, position=position, flux=power, radius=radius,
                              soft_falloff=soft)
        if getattr(light, "use_square", False):
            warn(f"Light '{name}': square spot cone is treated as round")
        if np.linalg.norm(down) == 0:
            raise SceneError(f"Light '{name}': zero scale, the spot has no direction")
        return SpotLight(name, position=position, direction=down, flux=power,
                         half_angle=0.5 * float(light.spot_size), blend=float(light.spot_blend),
                         radius=radius, soft_falloff=soft)

    if kind == "SUN":
        if not normalize:
            warn(f"Light '{name}': Normalize off is not supported; treated as normalized")
        if np.linalg.norm(down) == 0:
            raise SceneError(f"Light '{name}': zero scale, the sun has no direction")
        return SunLight(name, direction=down, irradiance=power, angle=float(light.angle))

    if kind == "AREA":
        shape = light.shape
        if shape not in AREA_SHAPES:
            raise SceneError(f"Light '{name}': unknown area light shape {shape!r}")
        size_x = float(light.size)
        size_y = float(light.size_y) if shape in ("RECTANGLE", "ELLIPSE") else size_x
        spread = float(getattr(light, "spread", math.pi))
        collimated = spread < COLLIMATED_SPREAD
        if not collimated and spread < math.pi - 1e-4:
            warn(f"Light '{name}': Spread {math.degrees(spread):.4g} deg is treated as 180 deg")
        area = AreaLight(name, shape=shape, matrix=matrix, size_x=size_x, size_y=size_y,
                         power=power, collimated=collimated)
        if not normalize:       # Cycles: power is then per square metre of the light
            area.power = area.power * area.area
        return area

    warn(f"Light '{name}': light type {kind} is not supported; skipped")
    return None


# ---------------------------------------------------------------------------------------------
# World
# ---------------------------------------------------------------------------------------------
def _world_radiance(reader: _NodeReader, src, depth: int = 0) -> np.ndarray:
    if src is None:
        return np.zeros(3)
    node, out = src
    t = node.type
    if t in ("BACKGROUND", "EMISSION"):
        return (reader.colour(node, "Color", default=(0.05, 0.05, 0.05))
                * reader.scalar(node, "Strength", default=1.0))
    if t in ("MIX_SHADER", "ADD_SHADER") and depth < 64:
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        a = _world_radiance(reader, decided_source(shaders[0], *reader.constants), depth + 1)
        b = _world_radiance(reader, decided_source(shaders[1], *reader.constants), depth + 1)
        if t == "ADD_SHADER":
            return a + b
        fac = float(np.clip(reader.scalar(node, "Fac", "Factor", default=0.5), 0, 1))
        return (1 - fac) * a + fac * b
    reader.warn(f"{reader.owner}: {node.bl_label} node '{node.name}' feeding the World Output "
                f"is not supported; the world is black")
    return np.zeros(3)


def _world_for(world, warn: _Warnings, ray) -> World:
    """The World a ray of Light Path values ``ray`` meets (``world_export.CAMERA_RAY`` or
    ``LIGHTING_RAY``): an image environment, or one colour."""
    if not compat.uses_nodes(world):
        radiance = np.array(world.color[:3], float)
    else:
        environment = environment_of(world, warn, ray)
        if environment is not None:
            return World(environment=environment)
        tree = world.node_tree
        constants = (ray, graph_maker(tree, warn))
        reader = _NodeReader(f"World '{world.name}'", warn, constants=constants)
        out = _active_output(tree, "OUTPUT_WORLD")
        radiance = np.zeros(3) if out is None else \
            _world_radiance(reader, decided_source(out.inputs.get("Surface"), *constants))
    if not np.all(np.isfinite(radiance)):
        raise SceneError(f"World '{world.name}': colour {_fmt(radiance)} is not finite")
    if np.any(radiance < 0):
        warn(f"World '{world.name}': negative colour {_fmt(radiance)} clipped to 0")
    return World(radiance=np.maximum(radiance, 0.0))


def _export_world(world, warn: _Warnings, portals=()) -> World:
    """The scene's World. A world whose nodes read Light Path (Is Camera Ray) is read for
    camera rays and for the rest: ``World.camera`` holds the first where they differ."""
    if world is None:
        return World(portals=list(portals))
    lighting = _world_for(world, warn, LIGHTING_RAY)
    camera = None
    read = light_path_outputs(world.node_tree) if compat.uses_nodes(world) else set()
    if read:
        others = sorted(read - {"Is Camera Ray"})
        if others:
            warn(f"World '{world.name}': Light Path {', '.join(others)} "
                 f"{'is' if len(others) == 1 else 'are'} read as 0 for every ray (as for "
                 "Cycles' light samples); only Is Camera Ray tells rays apart")
        camera = _world_for(world, warn, CAMERA_RAY)
        if camera.environment is None and lighting.environment is None \
                and np.array_equal(camera.radiance, lighting.radiance):
            camera = None
    return World(radiance=lighting.radiance, environment=lighting.environment,
                 portals=list(portals), camera=camera)


# ---------------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------------
def render_resolution(render) -> tuple[int, int]:
    """Blender's full-frame size in pixels: Resolution x Percentage / 100 (integer division)."""
    pct = int(render.resolution_percentage)
    return (int(render.resolution_x) * pct // 100, int(render.resolution_y) * pct // 100)


def render_border(render, resolution) -> tuple[int, int, int, int] | None:
    """The Render Region in pixels (x0, y0, x1, y1), y from the bottom, truncated like Blender
    (float32 fraction x size, converted to int); None when the region is off."""
    if not render.use_border:
        return None
    w, h = (np.float32(v) for v in resolution)
    return (int(np.float32(render.border_min_x) * w), int(np.float32(render.border_min_y) * h),
            int(np.float32(render.border_max_x) * w), int(np.float32(render.border_max_y) * h))


def _export_camera(depsgraph, scene, resolution, border, warn: _Warnings) -> Camera:
    cam_obj = scene.camera
    if cam_obj is None:
        raise SceneError(f"Scene '{scene.name}' has no active camera: set one in the Scene "
                         f"properties (Scene > Camera)")
    if cam_obj.type != "CAMERA":
        raise SceneError(f"Active camera '{cam_obj.name}' is {_article(cam_obj.type)} "
                         f"{cam_obj.type.lower()} object, not a camera")
    cam_eval = cam_obj.evaluated_get(depsgraph)
    data = cam_eval.data
    name = cam_obj.name
    matrix = np.array(cam_eval.matrix_world, dtype=np.float64)
    if not np.all(np.isfinite(matrix)):
        raise SceneError(f"Camera '{name}': world matrix is not finite (NaN or infinite "
                         f"location, rotation or scale)")
    lengths = np.linalg.norm(matrix[:3, :3], axis=0)
    if np.any(lengths < 1e-12):
        raise SceneError(f"Camera '{name}': zero scale on an axis")
    matrix[:3, :3] /= lengths          # as Matrix.normalized(): drop the scale

    render = scene.render
    if resolution is None:
        resolution = render_resolution(render)
    w, h = (int(v) for v in resolution)
    if w < 1 or h < 1:
        raise SceneError(f"Scene '{scene.name}': resolution {w}x{h} must be at least 1x1")
    if border is None:
        border = render_border(render, (w, h))

    orthographic = data.type == "ORTHO"
    panorama = _panorama(data, name) if data.type == "PANO" else None
    if data.type not in ("PERSP", "ORTHO") and panorama is None:
        kind = f"{data.type.lower()} cameras are" if data.type != "PANO" else \
            f"panoramic cameras of type {data.panorama_type} are"
        warn(f"Camera '{name}': {kind} not supported; rendered as perspective with the same "
             f"lens and sensor")
    lens = float(data.lens)
    if not (lens > 0 and math.isfinite(lens)):
        raise SceneError(f"Camera '{name}': focal length {lens} mm must be positive")
    ortho_scale = float(data.ortho_scale)
    if orthographic and not (ortho_scale > 0 and math.isfinite(ortho_scale)):
        raise SceneError(f"Camera '{name}': orthographic scale {ortho_scale} m must be positive")
    lens_params = _camera_lens(depsgraph, cam_obj, data, matrix, orthographic, lens, warn)
    if panorama is not None:
        if lens_params:
            warn(f"Camera '{name}': depth of field of a panoramic camera is not supported; "
                 f"rendered sharp")
        if data.shift_x or data.shift_y:
            warn(f"Camera '{name}': shift of a panoramic camera is not supported; ignored")
        return Camera(matrix=matrix, tan_half_x=0.5, tan_half_y=0.5, resolution=(w, h),
                      clip_start=float(data.clip_start), clip_end=float(data.clip_end),
                      border=None if border is None else tuple(int(v) for v in border),
                      name=name, panorama="EQUIRECTANGULAR", **panorama)

    # Sensor fit (BKE_camera_params_compute_viewplane): frame size in pixels x pixel aspect.
    fx = w * float(render.pixel_aspect_x)
    fy = h * float(render.pixel_aspect_y)
    fit = data.sensor_fit
    if fit == "AUTO":
        horizontal, sensor = fx >= fy, float(data.sensor_width)
    elif fit == "HORIZONTAL":
        horizontal, sensor = True, float(data.sensor_width)
    else:
        horizontal, sensor = False, float(data.sensor_height)
    half = 0.5 * ortho_scale if orthographic else sensor / (2.0 * lens)
    if horizontal:
        tan_x, tan_y = half, half * fy / fx
        unit = 2.0 * tan_x
    else:
        tan_x, tan_y = half * fx / fy, half
        unit = 2.0 * tan_y
    return Camera(matrix=matrix, tan_half_x=tan_x, tan_half_y=tan_y, resolution=(w, h),
                  shift_x=float(data.shift_x) * unit, shift_y=float(data.shift_y) * unit,
                  clip_start=float(data.clip_start), clip_end=float(data.clip_end),
                  border=None if border is None else tuple(int(v) for v in border), name=name,
                  orthographic=orthographic, **lens_params)


# Object > Visibility flags Lanterna does not follow: (property, label).
_RAY_FLAGS = (("visible_diffuse", "Diffuse"), ("visible_glossy", "Glossy"),
              ("visible_transmission", "Transmission"))
_SHADOW_FLAG = ("visible_shadow", "Shadow")


def _report_visibility(obj, warn) -> None:
    """Warn, naming the object, of the visibility settings that Cycles follows and Lanterna
    does not (it renders the object as if they were at their defaults): Ray Visibility
    Diffuse, Glossy, Transmission (and Shadow for geometry) off, Shadow Catcher, Holdout, and a
    light's Cast Shadow off. Camera visibility is followed (``hidden_from_camera``, lights'
    ``camera_visible``)."""
    name = obj.name
    flags = _RAY_FLAGS if obj.type == "LIGHT" else _RAY_FLAGS + (_SHADOW_FLAG,)
    off = [label for attr, label in flags if not getattr(obj, attr, True)]
    if off:
        warn(f"Object '{name}': Ray Visibility {', '.join(off)} off is not supported; "
             f"rendered as if on")
    if obj.type == "LIGHT":       # (a light's own is_shadow_catcher reads True: not used)
        if not getattr(obj.data, "use_shadow", True):
            warn(f"Light '{name}': Cast Shadow off is not supported; it casts shadows")
        return
    for attr, label in (("is_shadow_catcher", "Shadow Catcher"), ("is_holdout", "Holdout")):
        if getattr(obj, attr, False):
            warn(f"Object '{name}': {label} is not supported; rendered as an ordinary object")


def _particle_hair(obj, depsgraph) -> list:
    """The indices of the hair particle systems of ``obj`` that Cycles draws (Hair, rendered
    as Path, its modifier on for this depsgraph)."""
    render = getattr(depsgraph, "mode", "RENDER") == "RENDER"
    out = []
    for index, system in enumerate(getattr(obj, "particle_systems", ())):
        settings = system.settings
        if settings.type != "HAIR" or settings.render_type != "PATH":
            continue
        modifier = next((m for m in obj.modifiers if m.type == "PARTICLE_SYSTEM"
                         and m.particle_system == system), None)
        if modifier is not None and not (modifier.show_render if render
                                         else modifier.show_viewport):
            continue
        out.append(index)
    return out


def _read_particle_hair(obj, index: int, render: bool, warn) -> tuple:
    """One hair particle system of the evaluated ``obj`` as Cycles reads it
    (``ObtainCacheParticleData``): the children where there are any, else the parents; 2^steps
    + 1 keys per strand (Render Steps, or Viewport Display Steps outside a final render;
    Spiral kink adds its extra steps) from ``co_hair`` (world space); radius
    Radius Scale / 2 x (Root ... Tip, bent by Shape along the strand's length), 0 at the last
    key with Close Tip. Returns (tubes' _MeshData in world space or None, material slot)."""
    system = obj.particle_systems[index]
    settings = system.settings
    parents, children = len(system.particles), len(system.child_particles)
    has_children = settings.child_type != "NONE" and children > 0
    first = parents if has_children else 0
    count = parents + children - first if has_children else parents
    keys = 2 ** (settings.render_step if render else settings.display_step) + 1
    if settings.kink == "SPIRAL":
        keys += settings.kink_extra_steps
    slot = max(int(settings.material) - 1, 0)
    if count == 0:
        return None, slot
    owner = f"Object '{obj.name}', particle hair '{system.name}'"
    step = -(-count * keys // MAX_PARTICLE_KEYS)    # one strand in ``step`` beyond the cap
    if step > 1:
        warn(f"{owner}: {count:,} strands of {keys} keys are more than Lanterna reads "
             f"({MAX_PARTICLE_KEYS:,} keys); one strand in {step} is drawn")
    numbers = np.arange(0, count, step)
    points = np.empty((len(numbers), keys, 3))
    co_hair = system.co_hair
    for row, i in zip(points, numbers):        # one call per key: Blender has no bulk read
        for k in range(keys):
            row[k] = co_hair(obj, particle_no=first + int(i), step=k)
    count = len(numbers)
    length = np.concatenate([np.zeros((count, 1)), np.cumsum(
        np.linalg.norm(np.diff(points, axis=1), axis=2), axis=1)], axis=1)
    time_ = np.divide(length, length[:, -1:], out=np.zeros_like(length),
                      where=length[:, -1:] > 0)
    scale = 0.5 * float(settings.radius_scale)
    root, tip, shape = scale * float(settings.root_radius), scale * float(settings.tip_radius), \
        float(settings.shape)
    falloff = 1.0 - time_
    if shape < 0:
        falloff = falloff ** (1.0 + shape)
    elif shape > 0:
        falloff = falloff ** (1.0 / (1.0 - shape))
    radius = falloff * (root - tip) + tip
    if settings.use_close_tip:
        radius[:, -1] = 0.0
    tubes = hair.tessellate_curves(points.reshape(-1, 3), radius.reshape(-1),
                                   np.arange(0, count * keys + 1, keys))
    for note in tubes.notes:
        warn(f"{owner}: {note}")
    if len(tubes.triangles) == 0:
        return None, slot
    return _hair_data(tubes, numbers[tubes.vertex_curves]), slot


def _panorama(data, name: str) -> dict | None:
    """The ``scene.Camera`` fields of an equirectangular camera (its latitude and longitude
    ranges, on the Camera from Blender 4.0 on), or None for the other panoramic projections
    (reported by the caller)."""
    if data.panorama_type != "EQUIRECTANGULAR":
        return None
    out = {key: float(getattr(data, key)) for key in
           ("longitude_min", "longitude_max", "latitude_min", "latitude_max")}
    for key, value in out.items():
        if not math.isfinite(value):
            raise SceneError(f"Camera '{name}': {key.replace('_', ' ')} is not finite")
    return out


def _camera_lens(depsgraph, cam_obj, data, matrix, orthographic, lens, warn) -> dict:
    """The thin lens's ``scene.Camera`` fields from Blender's Depth of Field panel, as Cycles'
    ``blender_camera_from_object`` and ``blender_camera_focal_distance`` read it; {} when
    depth of field is off."""
    dof = getattr(data, "dof", None)
    name = cam_obj.name
    if dof is None or not dof.use_dof:
        return {}
    fstop = max(float(dof.aperture_fstop), 1e-5)
    radius = (1.0 if orthographic else lens * 1e-3) / (2.0 * fstop)
    focus = float(dof.focus_distance)
    target = dof.focus_object
    if target is not None:
        target_matrix = np.array(target.evaluated_get(depsgraph).matrix_world, np.float64)
        bone_name = getattr(dof, "focus_subtarget", "")
        pose = getattr(target, "pose", None)
        if bone_name and pose is not None and bone_name in pose.bones:
            target_matrix = target_matrix @ np.array(pose.bones[bone_name].matrix, np.float64)
        focus = abs(float(np.dot(matrix[:3, 2], matrix[:3, 3] - target_matrix[:3, 3])))
    ratio = float(dof.aperture_ratio)
    if not (focus > 0 and math.isfinite(focus)):
        where = f"its focus object '{target.name}' lies in its plane" if target is not None \
            else f"focus distance {focus:g} m"
        warn(f"Camera '{name}': depth of field is off: {where}, so nothing could be in focus "
             f"(Cycles' picture is undefined)")
        return {}
    if not (ratio > 0 and math.isfinite(ratio)):
        warn(f"Camera '{name}': aperture ratio {ratio:g} is not positive; 1 is used")
        ratio = 1.0
    blades = int(dof.aperture_blades)
    return dict(aperture_radius=radius, focus_distance=focus,
                aperture_blades=blades if blades >= 3 else 0,
                aperture_rotation=float(dof.aperture_rotation), aperture_ratio=ratio)


# ---------------------------------------------------------------------------------------------
# The scene
# ---------------------------------------------------------------------------------------------
def _visible(inst, obj) -> bool:
    """Render visibility of one depsgraph instance.

    The depsgraph's iterator already drops what it does not show in its mode (viewport or
    render). A viewport depsgraph (tests, previews) still lists what a final render hides, so
    the render rules are applied here too: Disable in Renders (hide_render), an instancer's
    Show Instancer for Render, and the original of an object instanced on its parent's
    vertices or faces (Blender hides it in renders)."""
    if not inst.show_self:
        return False
    if inst.is_instance:
        parent = inst.parent
        return parent is None or not parent.original.hide_render
    original = obj.original
    if original.hide_render:
        return False
    if getattr(obj, "is_instancer", False) and not original.show_instancer_for_render:
        return False
    parent = original.parent
    if parent is not None and parent.instance_type in ("VERTS", "FACES"):
        return False
    return True


def export_scene(depsgraph, *, resolution=None, border=None) -> Scene:
    """Export the evaluated ``depsgraph`` into a validated :class:`Scene` (see module doc)."""
    t_start = time.perf_counter()
    warn = _Warnings()
    scene = depsgraph.scene
    scene_eval = getattr(depsgraph, "scene_eval", scene)

    camera = _export_camera(depsgraph, scene, resolution, border, warn)

    materials: list[Material] = []
    images: dict = {}                       # image name -> nodes.Image, read once
    converted: dict = {}        # Blender material pointer (None: no material) -> Material
    material_index: dict = {}   # (that key, hidden from the camera) -> index in ``materials``
    baker = node_bake.NodeBaker(depsgraph)  # Cycles bakes of unsupported node subtrees

    def material_id(mat, hidden: bool = False) -> int:
        """The index in ``materials`` of ``mat`` (None: the default surface), converted once,
        or with ``hidden`` of its variant for objects hidden from the camera
        (``hidden_from_camera``); each is listed when an object first uses it."""
        key = None if mat is None else getattr(mat, "original", mat).as_pointer()
        if key not in converted:
            converted[key] = default_surface(warn) if mat is None else \
                _convert_material(mat, warn, images, baker)
        if (key, hidden) not in material_index:
            material_index[key, hidden] = len(materials)
            materials.append(hidden_from_camera(converted[key]) if hidden else converted[key])
        return material_index[key, hidden]

    object_names: list[str] = []
    object_index: dict[str, int] = {}
    mesh_cache: dict = {}
    groups: dict = {}        # (object, mesh) -> _Group of instances
    lights = []
    portals = []           # Cycles light portals: windows of the world, not lights

    mesh_parents: set = set()    # objects whose geometry arrived as MESH instances
    shape = curve_shape(scene)   # how Cycles draws curves
    hair_objects: dict = {}      # names of the objects whose hair is drawn, in order
    curve_like = []              # non-mesh geometry objects, converted if no mesh arrived

    def add_instance(obj, key, name, matrix, slot=None):
        """Queue one instance of the cached mesh ``key``; instances sharing a mesh and a
        material mapping form one group, transformed together. ``slot``: every triangle takes
        that material slot's material (Cycles' curves and particle hair)."""
        if mesh_cache[key] is None:
            return
        group_key = (obj.original.as_pointer(), key)
        group = groups.get(group_key)
        if group is None:
            slots = obj.material_slots
            if slot is not None:
                slots = slots[slot:slot + 1] if slot < len(slots) else slots[:1]
            hidden = camera_hidden(obj)
            lut = np.array([material_id(s.material, hidden) for s in slots] if len(slots)
                           else [material_id(None, hidden)], dtype=np.int32)
            group = groups[group_key] = _Group(mesh_cache[key], lut)
        group.matrices.append(matrix)
        group.names.append(name)

    material_keys: dict = {}     # material id -> the corner attributes it reads

    def hair_reads(obj, slot, missing, owner) -> None:
        """Warn when the material in ``slot`` of a hair object reads coordinates its strands
        do not carry (``missing`` key prefixes): they read 0 there."""
        slots = obj.material_slots
        mat = slots[slot].material if slot < len(slots) else (slots[0].material if len(slots)
                                                               else None)
        i = material_id(mat, camera_hidden(obj))
        if i not in material_keys:
            material_keys[i] = _material_coordinates(materials[i])
        unread = sorted(k for k in material_keys[i] if k.startswith(missing))
        if unread:
            warn(f"{owner}: its material '{materials[i].name}' reads {', '.join(unread)}, "
                 "which hair does not carry here; they read 0 on the strands")

    def read_tangents(obj, mesh, data) -> None:
        """The mesh's tangents, once, when a material of ``obj`` has a shading normal; the
        colour and geometry attributes its materials read."""
        if data is None:
            return
        hidden = camera_hidden(obj)
        slots = [material_id(s.material, hidden) for s in obj.material_slots]
        keys: set = set()
        for i in slots:
            if i not in material_keys:
                material_keys[i] = _material_coordinates(materials[i])
            keys |= material_keys[i]
        _read_attributes(mesh, data, sorted(keys), warn, f"Object '{obj.name}'")
        if data.tangents is not None or not data.uv_maps:
            return
        if any(materials[i].shading_normal is not None for i in slots):
            data.tangents = _read_tangents(mesh, data, warn, f"Object '{obj.name}'")

    # Walk the instances: one Python step per object or instance, never per triangle.
    for inst in depsgraph.object_instances:
        obj = inst.object
        otype = obj.type
        if otype not in GEOMETRY_TYPES and otype != "LIGHT":
            if otype in UNSUPPORTED_TYPES:
                warn(f"Object '{obj.name}': {otype.lower()} objects are not supported; skipped")
            continue
        if not _visible(inst, obj):
            continue
        name = obj.name
        parent = inst.parent if inst.is_instance else None
        if parent is not None and parent.name != obj.name:
            name = f"{parent.name}/{obj.name}"
        matrix = np.array(inst.matrix_world, np.float64)

        if otype == "LIGHT" and obj.data.type == "AREA" and \
                getattr(getattr(obj.data, "cycles", None), "is_portal", False):
            # A light portal (Cycles): a window for the world's light, not a light.
            data = obj.data
            shape = data.shape if data.shape in AREA_SHAPES else "SQUARE"
            size_y = float(data.size_y) if shape in ("RECTANGLE", "ELLIPSE") else float(data.size)
            if np.all(np.isfinite(matrix)):
                portals.append(AreaLight(name, shape=shape, matrix=matrix,
                                         size_x=float(data.size), size_y=size_y,
                                         power=np.zeros(3)))
        elif otype == "LIGHT":
            _report_visibility(obj, warn)
            light = _convert_light(name, obj.data, matrix, warn)
            if light is not None:
                settings = getattr(obj.data, "lanterna", None)
                if settings is not None:
                    light.photon_share = float(settings.photon_share)
                    if isinstance(light, AreaLight):   # the only lights shadow photons leave
                        light.shadow_photons = bool(getattr(settings, "shadow_photons", True))
                if hasattr(light, "camera_visible"):     # Object > Visibility > Camera
                    light.camera_visible = bool(getattr(obj, "visible_camera", False))
                lights.append(light)
        elif otype == "CURVES":
            _report_visibility(obj, warn)
            key = ("curves", obj.data.as_pointer())
            if key not in mesh_cache:
                mesh_cache[key] = _read_curves(obj.data, shape, warn, f"Object '{obj.name}'")
            add_instance(obj, key, name, matrix, slot=0)
            if mesh_cache[key] is not None:
                hair_objects.setdefault(obj.name)
                lacks = ("color", "attr:", "tangent") + (() if mesh_cache[key].uv_maps
                                                         else ("uv",))
                hair_reads(obj, 0, lacks, f"Object '{obj.name}'")
        elif otype == "MESH":
            _report_visibility(obj, warn)
            if not inst.is_instance:
                for index in _particle_hair(obj, depsgraph):
                    key = ("particles", obj.original.as_pointer(), index)
                    if key not in mesh_cache:
                        mesh_cache[key], slot = _read_particle_hair(
                            obj, index, getattr(depsgraph, "mode", "RENDER") == "RENDER", warn)
                    add_instance(obj, key, name, np.eye(4), slot=slot)
                    if mesh_cache[key] is not None:
                        hair_objects.setdefault(obj.name)
                        hair_reads(obj, slot, ("uv", "color", "attr:", "tangent"),
                                   f"Object '{obj.name}', particle hair")
            if parent is not None:
                mesh_parents.add(parent.original.as_pointer())
            key = ("mesh", obj.data.as_pointer())
            if key not in mesh_cache:              # read once per mesh datablock
                mesh_cache[key] = _read_mesh(obj.data)
            read_tangents(obj, obj.data, mesh_cache[key])
            add_instance(obj, key, name, matrix)
        elif not inst.is_instance:
            # Curves, surfaces, text and metaballs: Blender 3+ hands their evaluated mesh over
            # as a MESH instance whose parent is the object itself; to_mesh() is the fallback.
            curve_like.append((obj, name, matrix))

    for obj, name, matrix in curve_like:
        if obj.original.as_pointer() in mesh_parents:
            continue
        key = ("to_mesh", obj.original.as_pointer())
        try:
            mesh = obj.to_mesh()
        except RuntimeError:
            mesh = None
        try:
            mesh_cache[key] = _read_mesh(mesh) if mesh is not None else None
            read_tangents(obj, mesh, mesh_cache[key])
        finally:
            obj.to_mesh_clear()
        add_instance(obj, key, name, matrix)

    # Drop instances whose transform is not finite, naming them; number the objects.
    for group in groups.values():
        mats = np.array(group.matrices, np.float64).reshape(-1, 4, 4)
        finite = np.all(np.isfinite(mats), axis=(1, 2))
        for i in np.flatnonzero(~finite):
            warn(f"Object '{group.names[i].rsplit('/', 1)[-1]}': world matrix is not finite "
                 f"(NaN or infinite location, rotation or scale); its {group.data.count} "
                 f"triangles are skipped")
        ids = []
        for name in (n for n, ok in zip(group.names, finite) if ok):
            if name not in object_index:
                object_index[name] = len(object_names)
                object_names.append(name)
            ids.append(object_index[name])
        group.matrices = mats[finite]
        group.object_ids = np.asarray(ids, np.int32)
    n_instances = sum(len(g.matrices) for g in groups.values())

    # Fill preallocated output arrays, one block of numpy work per group of instances.
    total = sum(len(g.matrices) * g.data.count for g in groups.values())
    triangles = np.empty((total, 3, 3), np.float32)
    normals = np.empty((total, 3, 3), np.float32)
    material_ids = np.empty(total, np.int32)
    object_ids = np.empty(total, np.int32)
    strands = np.zeros(total, bool)
    flat_tris = triangles.reshape(-1, 3)
    flat_normals = normals.reshape(-1, 3)
    start = 0
    for group in groups.values():
        data, n_tri = group.data, group.data.count
        tri_mats = group.lut[np.clip(data.mat_index, 0, len(group.lut) - 1)]
        # Chunks keep the temporary per-instance copies of the mesh near 4M rows.
        rows = max(len(data.co), len(data.corner_normals), 1)
        step = max(1, 4_000_000 // rows)
        for c0 in range(0, len(group.matrices), step):
            mats = group.matrices[c0:c0 + step]
            n = len(mats)
            end = start + n * n_tri
            if n == 1 and np.array_equal(mats[0], np.eye(4)):
                co, cn = data.co, data.corner_normals
                vert_index, loop_index = data.tri_verts, data.tri_loops
            else:
                rot = mats[:, :3, :3]
                co = np.matmul(data.co, rot.transpose(0, 2, 1).astype(np.float32))
                co += mats[:, None, :3, 3].astype(np.float32)
                cn = np.matmul(data.corner_normals,
                               _normal_matrices(rot).transpose(0, 2, 1).astype(np.float32))
                vert_index = (data.tri_verts[None, :]
                              + (np.arange(n) * len(data.co))[:, None]).ravel()
                loop_index = (data.tri_loops[None, :]
                              + (np.arange(n) * len(data.corner_normals))[:, None]).ravel()
            _gather_rows(co.reshape(-1, 3), vert_index, flat_tris[3 * start:3 * end])
            _gather_rows(cn.reshape(-1, 3), loop_index, flat_normals[3 * start:3 * end])
            material_ids[start:end].reshape(n, n_tri)[:] = tri_mats
            object_ids[start:end] = np.repeat(group.object_ids[c0:c0 + step], n_tri)
            strands[start:end] = data.strands
            start = end

    width = {"uv": 2, "tangent": 4, "color": 4, "attr": 4, "hair": 4}
    corner_attributes = {key: np.zeros((total, 3, width.get(key.split(":")[0], 3)), np.float32)
                         for key in sorted(_coordinates_read(materials))}
    start = 0
    for group in groups.values():
        n_tri, n = group.data.count, len(group.matrices)
        for key, out_array in corner_attributes.items():
            block = out_array[start:start + n * n_tri].reshape(n, n_tri, 3, -1)
            if key == "normal_matrix":
                # Per triangle, not per corner: the instance's object-to-world normal matrix.
                block[:] = _normal_matrices(group.matrices[:, :3, :3])[:, None, :, :]
            else:
                block[:] = _corner_attribute(group.data, key)
        start += n * n_tri

    if hair_objects:
        warn(f"Hair ({', '.join(repr(n) for n in hair_objects)}): the light bounced between "
             "strands comes out dark where hair is dense (a fur ball's core: 12 % below "
             "Cycles, its direct light alone 7 %; docs/usage.md)")
    world = _export_world(scene_eval.world, warn, portals)
    out = Scene(triangles=triangles, material_ids=material_ids, materials=materials,
                camera=camera, shading_normals=normals, object_ids=object_ids,
                object_names=object_names, lights=lights, world=world,
                warnings=list(warn.messages), corner_attributes=corner_attributes,
                strands=strands if strands.any() else None)
    out.validate()
    out.warnings = list(dict.fromkeys(out.warnings))
    out.stats.update({
        "export_seconds": time.perf_counter() - t_start,
        "triangles": int(len(out.triangles)),
        "instances": n_instances,
        "meshes_read": sum(1 for v in mesh_cache.values() if v is not None),
        "lights": len(lights),
        "materials": len(materials),
    })
    return out


# ---------------------------------------------------------------------------------------------
# Settings
# ---------------------------------------------------------------------------------------------
def _find_setting(props, name: str, depth: int = 0):
    """Look ``name`` up on ``props`` and then on its nested property groups."""
    if props is None or depth > 3:
        return None
    rna = getattr(props, "bl_rna", None)
    if rna is not None and name in rna.properties.keys():
        return getattr(props, name)
    if rna is None:
        return getattr(props, name, None)
    for prop in rna.properties:
        if prop.type == "POINTER" and prop.identifier != "rna_type":
            found = _find_setting(getattr(props, prop.identifier, None), name, depth + 1)
            if found is not None:
                return found
    return None


def export_settings(blender_scene) -> RenderSettings:
    """``Scene.lanterna`` -> :class:`RenderSettings`; missing fields keep the class defaults,
    except ``threads`` whose 0 (or absence) means ``os.cpu_count()``."""
    props = getattr(blender_scene, "lanterna", None)
    values = {}
    for f in dataclasses.fields(RenderSettings):
        value = _find_setting(props, f.name)
        if value is None:
            continue
        default = getattr(RenderSettings(), f.name)
        try:
            values[f.name] = type(default)(value) if isinstance(default, (int, float, bool)) \
                else value
        except (TypeError, ValueError):
            raise SceneError(f"Render setting '{f.name}' has an invalid value {value!r}")
    # Enum identifiers ('PHOTON_MAP') -> core names ('photon-map').
    for key in ("mode", "photon_filter", "indirect", "preset"):
        if key in values:
            values[key] = str(values[key]).lower().replace("_", "-")
    threads = int(values.get("threads", 0))
    values["threads"] = threads if threads > 0 else (os.cpu_count() or 1)
    if "samples" in values:
        values["samples"] = max(1, values["samples"])
    for key in ("light_samples", "bounces"):
        if key in values:
            values[key] = max(0, values[key])
    return RenderSettings(**values)
