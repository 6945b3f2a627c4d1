"""File > Import > ASCII Scene Export (.ase): the seed's scenes (3ds Max ASE + the companion
material file, thesis section 3) as Blender objects.

What it does
------------
:func:`import_ase` reads the ``.ase`` file and its companion ``.mat`` with
:func:`lanterna.engine.ase.load` (which checks everything and raises
:class:`~lanterna.engine.ase.AseError` naming the file, line, object and what was expected),
and only when both were read entirely does it create Blender data, all in a new collection
named after the file (``room.ase`` -> collection ``room``) linked to the scene:

* one mesh object per ``*GEOMOBJECT`` (``from_pydata``), with the ``*NODE_TM`` as its world
  matrix and the vertices in its object space, so that the world positions are the ASE's;
  material slots in ASE order, a material index per face;
* one material per ASE material used, with ``Material.lanterna`` set from the companion file:
  ``derive_from_nodes`` off, ``diffuse`` = rho_d, ``specular`` = rho_s, ``exitance`` = M
  [W/m^2]. For the viewport and other engines the Principled BSDF gets Base Color = rho_d +
  rho_s, Metallic = mean(rho_s) / mean(rho_d + rho_s), Roughness 0 when there is a mirror part,
  and Emission Color x Strength = M / pi (the exporter's reading of these nodes gives back rho_d,
  rho_s and M when rho_s is grey-proportional to rho_d + rho_s; Lanterna uses the exact values
  anyway, since nodes are not derived);
* cameras (horizontal field of view, sensor fit Horizontal); the first becomes the scene's
  camera when the scene has none;
* lights: Omni -> Point of radius 0 (``shadow_soft_size`` 0, the seed's point light), Target /
  Free spots -> Spot (radius 0, cone = falloff), Directional -> Sun (angle 0); Power [W] or
  Strength [W/m^2] from the companion file's ``light "<name>" power P`` or from
  ``*LIGHT_INTENS`` (see the conversion in ``engine/ase.py``), colour ``*LIGHT_COLOR``.

Nothing is half-imported: a file that does not parse creates nothing, and if creating the
Blender data fails midway, everything created so far is removed again before the error is
reported. Warnings (materials missing from the companion file, degenerate faces, ...) are
returned in the summary and reported as WARNING by the operator.

Parameters of :func:`import_ase`: ``filepath`` (the ``.ase``), ``context`` (``bpy.context``),
``material_path`` (the companion file; default: same folder and stem with ``.mat``, optional).
Returns a dict: ``collection`` (name), ``objects``, ``meshes``, ``materials``, ``cameras``,
``lights`` (lists of the created names), ``warnings``.
"""
from __future__ import annotations

import os

import bpy
import numpy as np
from bpy.props import StringProperty
from bpy_extras.io_utils import ImportHelper
from mathutils import Matrix

from ..engine import ase
from ..engine.blender import compat

__all__ = ["LANTERNA_OT_import_ase", "import_ase", "register", "unregister"]

# -- Creation helpers ---------------------------------------------------------------------------
def _matrix(m: np.ndarray) -> Matrix:
    return Matrix([[float(v) for v in row] for row in m])


def _make_material(spec: ase.MaterialSpec):
    mat = bpy.data.materials.new(spec.name)
    d, s, e = (np.asarray(x, float) for x in (spec.diffuse, spec.specular, spec.exitance))
    settings = getattr(mat, "lanterna", None)
    if settings is not None:              # Lanterna's properties are registered
        settings.derive_from_nodes = False
        settings.diffuse = d.tolist()
        settings.specular = s.tolist()
        settings.exitance = e.tolist()
    mat.diffuse_color = (*d.tolist(), 1.0)
    tree = compat.ensure_node_tree(mat)
    bsdf = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"), None)
    if bsdf is not None:
        base = np.clip(d + s, 0.0, 1.0)
        metallic = float(s.mean() / base.mean()) if base.mean() > 0 else 0.0
        bsdf.inputs["Base Color"].default_value = (*base.tolist(), 1.0)
        bsdf.inputs["Metallic"].default_value = min(metallic, 1.0)
        if metallic > 0:
            bsdf.inputs["Roughness"].default_value = 0.0
        peak = float(e.max())
        if peak > 0:
            bsdf.inputs["Emission Color"].default_value = (*(e / peak).tolist(), 1.0)
            bsdf.inputs["Emission Strength"].default_value = peak / np.pi
    return mat


def _make_mesh(spec: ase.MeshSpec, materials: dict):
    mesh = bpy.data.meshes.new(spec.name)
    mesh.from_pydata(spec.local_vertices.tolist(), [], spec.faces.tolist())
    for name in spec.slots:
        mesh.materials.append(materials[name])
    if len(spec.faces):
        mesh.polygons.foreach_set("material_index", spec.face_slots.astype(np.int32))
    mesh.validate(clean_customdata=False)       # e.g. drops faces listed twice
    mesh.update()
    return mesh


def _make_camera(spec: ase.CameraSpec):
    cam = bpy.data.cameras.new(spec.name)
    cam.sensor_fit = 'HORIZONTAL'
    cam.angle = float(spec.fov)
    return cam


def _make_light(spec: ase.LightSpec):
    light = bpy.data.lights.new(spec.name, spec.kind)      # POINT, SPOT or SUN
    light.color = [float(c) for c in spec.color]
    light.energy = float(spec.power)
    if spec.kind == "SUN":
        light.angle = 0.0
    else:
        light.shadow_soft_size = 0.0
    if spec.kind == "SPOT":
        light.spot_size = float(spec.spot_size)
        light.spot_blend = float(spec.spot_blend)
    return light


def _remove(created: list, scene, set_camera: bool):
    """Undo a failed import: unlink and delete everything in ``created``, newest first."""
    if set_camera:
        scene.camera = None
    collections = {
        "OBJECT": bpy.data.objects, "MESH": bpy.data.meshes, "MATERIAL": bpy.data.materials,
        "CAMERA": bpy.data.cameras, "LIGHT": bpy.data.lights,
        "COLLECTION": bpy.data.collections,
    }
    for kind, block in reversed(created):
        try:
            collections[kind].remove(block)
        except (ReferenceError, RuntimeError):
            pass                            # already gone with its owner


# -- The import --------------------------------------------------------------------------------
def import_ase(filepath: str, context, material_path: str | None = None) -> dict:
    """Import ``filepath`` (see the module docstring). Raises
    :class:`lanterna.engine.ase.AseError` for a bad file (nothing created), or the Blender
    error when creating the data failed (whatever was created is removed first)."""
    data = ase.load(filepath, material_path or None)     # everything is checked here

    scene = context.scene
    created: list = []
    set_camera = False
    summary = {"collection": "", "objects": [], "meshes": [], "materials": [], "cameras": [],
               "lights": [], "warnings": list(data.warnings)}

    def keep(kind, block):
        created.append((kind, block))
        return block

    try:
        stem = os.path.splitext(os.path.basename(filepath))[0] or "ASE"
        coll = keep("COLLECTION", bpy.data.collections.new(stem))
        summary["collection"] = coll.name

        materials = {}
        for spec in data.materials:
            mat = keep("MATERIAL", _make_material(spec))
            materials[spec.name] = mat
            summary["materials"].append(mat.name)

        def add_object(name, obj_data, matrix):
            obj = keep("OBJECT", bpy.data.objects.new(name, obj_data))
            obj.matrix_world = _matrix(matrix)
            coll.objects.link(obj)
            summary["objects"].append(obj.name)
            return obj

        for spec in data.meshes:
            mesh = keep("MESH", _make_mesh(spec, materials))
            if len(mesh.polygons) != len(spec.faces):
                summary["warnings"].append(
                    f"{filepath}:{spec.line}: GEOMOBJECT '{spec.name}': Blender kept "
                    f"{len(mesh.polygons)} of its {len(spec.faces)} faces")
            add_object(spec.name, mesh, spec.matrix)
            summary["meshes"].append(mesh.name)

        cameras = []
        for spec in data.cameras:
            obj = add_object(spec.name, keep("CAMERA", _make_camera(spec)), spec.matrix)
            cameras.append(obj)
            summary["cameras"].append(obj.name)

        for spec in data.lights:
            obj = add_object(spec.name, keep("LIGHT", _make_light(spec)), spec.matrix)
            obj.hide_render = not spec.enabled
            summary["lights"].append(obj.name)

        scene.collection.children.link(coll)
        if scene.camera is None and cameras:
            scene.camera = cameras[0]
            set_camera = True
    except Exception:
        _remove(created, scene, set_camera)
        raise
    return summary


# -- The operator ------------------------------------------------------------------------------
class LANTERNA_OT_import_ase(bpy.types.Operator, ImportHelper):
    """Import a 3ds Max ASCII Scene Export file (.ase) with its Lanterna material file (.mat)"""

    bl_idname = "import_scene.lanterna_ase"
    bl_label = "ASCII Scene Export (.ase)"
    bl_options = {'REGISTER', 'UNDO'}

    filename_ext = ".ase"
    filter_glob: StringProperty(default="*.ase", options={'HIDDEN'}, maxlen=255)
    material_file: StringProperty(
        name="Material File",
        description=("Companion material file (diffuse, specular reflectance and exitance per "
                     "material); empty: the .mat file of the same name next to the .ase"),
        default="", subtype='FILE_PATH',
    )

    def execute(self, context):
        try:
            material = bpy.path.abspath(self.material_file) if self.material_file else None
            summary = import_ase(self.filepath, context, material)
        except ase.AseError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        except Exception as exc:              # Blender refused to create something
            self.report({'ERROR'}, f"{self.filepath}: import failed and was undone: {exc}")
            return {'CANCELLED'}
        for text in summary["warnings"]:
            self.report({'WARNING'}, text)
        self.report({'INFO'}, (f"Imported {len(summary['meshes'])} meshes, "
                               f"{len(summary['cameras'])} cameras, {len(summary['lights'])} "
                               f"lights and {len(summary['materials'])} materials into "
                               f"collection '{summary['collection']}'"))
        return {'FINISHED'}


def _menu(self, context):
    self.layout.operator(LANTERNA_OT_import_ase.bl_idname, text="ASCII Scene Export (.ase)")


classes = (LANTERNA_OT_import_ase,)


def register():
    from ..engine.blender.classes import register_classes
    register_classes(classes)
    bpy.types.TOPBAR_MT_file_import.append(_menu)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    from ..engine.blender.classes import unregister_classes
    unregister_classes(classes)
