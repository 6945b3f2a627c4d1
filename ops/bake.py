"""Operators for the maps: bake without rendering, clear, save, load, and export the report.

``LANTERNA_OT_bake``           exports the scene as F12 does (render resolution, percentage and
                               border; ``Scene.lanterna`` settings) and runs
                               ``engine.pipeline.bake``: every stage but the camera (photon map,
                               shadow photons, irradiance cache). The maps go to the scene's
                               store (``engine/blender/session.py``) for the viewport overlay.
                               From the UI it runs in a worker thread under a modal operator:
                               progress in the status bar and the window manager's progress
                               cursor, Esc cancels (a cancelled bake keeps nothing). From
                               scripts (``bpy.ops.lanterna.bake()``) and in background mode it
                               runs to the end before returning.
``LANTERNA_OT_clear``          forgets the scene's maps.
``LANTERNA_OT_save_maps``      writes them to ``filepath``, by default
                               ``//<blend name>_lanterna.npz`` next to the .blend
                               (``engine.artifacts.save_artifacts``: one .npz, written whole or
                               not at all). An unsaved .blend with no path given is an error.
``LANTERNA_OT_load_maps``      reads that file (``load_artifacts``, ``allow_pickle=False``)
                               for the scene as it is now: a file made for another scene, with
                               other map settings or by another version is refused with the
                               reason.
``LANTERNA_OT_export_report``  the last render's report (stage timings, plan, counts,
                               warnings; or the report of the bake or load when no render ran)
                               as JSON to a chosen file.

Errors are reported with ``self.report({'ERROR'}, message)`` and the operator returns
``{'CANCELLED'}``; no traceback reaches the user.
"""
from __future__ import annotations

import json
import os
import threading
import time

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ExportHelper

from ..engine.scene import SceneError

DEFAULT_SUFFIX = "_lanterna.npz"


# -- Helpers ----------------------------------------------------------------------------------
def _export(context):
    """The scene as F12 would render it: (core Scene, RenderSettings)."""
    from ..engine.blender import export

    scene = context.scene
    if scene.camera is None:
        raise SceneError(f"Scene '{scene.name}': no active camera (the maps are made for the "
                         "camera's view)")
    resolution = export.render_resolution(scene.render)
    border = export.render_border(scene.render, resolution)
    depsgraph = context.evaluated_depsgraph_get()
    lscene = export.export_scene(depsgraph, resolution=resolution, border=border)
    return lscene, export.export_settings(scene)


def default_maps_path() -> str:
    """``//<blend name>_lanterna.npz`` (Blender-relative); '' when the .blend is unsaved."""
    if not bpy.data.filepath:
        return ""
    stem = os.path.splitext(bpy.path.basename(bpy.data.filepath))[0]
    return "//" + stem + DEFAULT_SUFFIX


def resolve_maps_path(filepath: str) -> str:
    """The absolute file for ``filepath`` ('' = the default next to the .blend); raises
    SceneError when it would be relative to an unsaved .blend."""
    path = filepath or default_maps_path()
    if not path:
        raise SceneError("The .blend file is not saved: save it first (the maps go next to it "
                         f"as <name>{DEFAULT_SUFFIX}) or give a file path")
    if path.startswith("//") and not bpy.data.filepath:
        raise SceneError(f"The path '{path}' is relative to the .blend file, which is not "
                         "saved: save it first or give an absolute path")
    return os.path.abspath(bpy.path.abspath(path))


def _summary(artifacts) -> str:
    c = artifacts.counts()
    return (f"{c['photons']:,} photons, {c['shadow_photons']:,} shadow photons, "
            f"{c['cache']:,} cache records")


def _one_line(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, SceneError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())


def _json_default(obj):
    import numpy as np

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    return str(obj)


def write_json(path: str, data) -> None:
    """``data`` as indented JSON at ``path``: a temporary file, then ``os.replace``."""
    from ..engine.imageio import atomic_output

    with atomic_output(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=2, default=_json_default, allow_nan=True)
        fh.write("\n")


# -- Bake -------------------------------------------------------------------------------------
class LANTERNA_OT_bake(bpy.types.Operator):
    bl_idname = "lanterna.bake"
    bl_label = "Bake Maps"
    bl_description = ("Build the photon map, shadow photons and irradiance cache of this scene "
                      "without rendering the image (to inspect them in the viewport or save "
                      "them next to the .blend); Esc cancels")
    bl_options = {'REGISTER'}

    _running = False            # one bake at a time (class-wide)

    @classmethod
    def poll(cls, context):
        return context.scene is not None and not LANTERNA_OT_bake._running

    # Scripts and background mode: to the end, then return.
    def execute(self, context):
        from ..engine import pipeline
        from ..engine.blender import session

        scene_name = context.scene.name
        wm = context.window_manager
        started = time.perf_counter()
        try:
            lscene, settings = _export(context)
            wm.progress_begin(0, 100)
            try:
                artifacts = pipeline.bake(
                    lscene, settings,
                    progress=lambda fraction, text="": wm.progress_update(100 * float(fraction)))
            finally:
                wm.progress_end()
        except Exception as exc:        # the boundary: a message, not a traceback
            self.report({'ERROR'}, f"Bake failed: {_one_line(exc)}")
            return {'CANCELLED'}
        session.put(scene_name, artifacts, source="bake")
        self.report({'INFO'}, f"Baked {_summary(artifacts)} in "
                              f"{time.perf_counter() - started:.1f} s")
        return {'FINISHED'}

    # The UI: a worker thread, progress in the status bar, Esc to cancel.
    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        from ..engine import pipeline

        try:
            lscene, settings = _export(context)
        except Exception as exc:
            self.report({'ERROR'}, f"Bake failed: {_one_line(exc)}")
            return {'CANCELLED'}
        state = {"fraction": 0.0, "text": "Baking", "cancel": False, "result": None,
                 "error": None, "started": time.perf_counter()}
        self._state, self._scene_name = state, context.scene.name

        def progress(fraction, text=""):
            state["fraction"] = float(fraction)
            if text:
                state["text"] = str(text)

        def work():
            try:
                state["result"] = pipeline.bake(lscene, settings, progress=progress,
                                                cancelled=lambda: state["cancel"])
            except Exception as exc:
                state["error"] = exc

        self._thread = threading.Thread(target=work, name="lanterna-bake", daemon=True)
        LANTERNA_OT_bake._running = True
        self._thread.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        state = self._state
        if event.type == 'ESC' and event.value == 'PRESS':
            state["cancel"] = True
            state["text"] = "Cancelling"
            return {'RUNNING_MODAL'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        context.window_manager.progress_update(100 * min(max(state["fraction"], 0.0), 1.0))
        if context.workspace is not None:
            context.workspace.status_text_set(f"Lanterna: {state['text']} (Esc to cancel)")
        if self._thread.is_alive():
            return {'PASS_THROUGH'}
        return self._finish(context)

    def _finish(self, context):
        from ..engine.blender import session

        self._end(context)
        state = self._state
        if state["error"] is not None:
            self.report({'ERROR'}, f"Bake failed: {_one_line(state['error'])}")
            return {'CANCELLED'}
        artifacts = state["result"]
        if state["cancel"] or artifacts is None or (artifacts.report or {}).get("cancelled"):
            self.report({'WARNING'}, "Bake cancelled: nothing kept")
            return {'CANCELLED'}
        session.put(self._scene_name, artifacts, source="bake")
        self.report({'INFO'}, f"Baked {_summary(artifacts)} in "
                              f"{time.perf_counter() - state['started']:.1f} s")
        return {'FINISHED'}

    def _end(self, context):
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        LANTERNA_OT_bake._running = False

    def cancel(self, context):           # Blender ends the modal (window closed, file loaded)
        self._state["cancel"] = True
        self._thread.join()
        self._end(context)


class LANTERNA_OT_clear(bpy.types.Operator):
    bl_idname = "lanterna.clear"
    bl_label = "Clear Maps"
    bl_description = "Forget the photon map, shadow photons and cache records kept for this scene"
    bl_options = {'REGISTER'}

    def execute(self, context):
        from ..engine.blender import session

        session.clear(context.scene.name)
        return {'FINISHED'}


# -- Save / load ------------------------------------------------------------------------------
_PATH_DESCRIPTION = ("Maps file (.npz); empty: <blend name>" + DEFAULT_SUFFIX + " next to the "
                     ".blend file")


class LANTERNA_OT_save_maps(bpy.types.Operator):
    bl_idname = "lanterna.save_maps"
    bl_label = "Save Maps"
    bl_description = ("Save the kept maps of this scene to a file next to the .blend "
                      "(<blend name>" + DEFAULT_SUFFIX + ")")
    bl_options = {'REGISTER'}

    filepath: StringProperty(name="File Path", subtype='FILE_PATH', default="",
                             description=_PATH_DESCRIPTION)

    def execute(self, context):
        from ..engine.artifacts import save_artifacts
        from ..engine.blender import session

        scene_name = context.scene.name
        artifacts = session.get(scene_name)
        if artifacts is None:
            self.report({'ERROR'}, f"Scene '{scene_name}' has no maps to save: render or bake "
                                   "first")
            return {'CANCELLED'}
        try:
            path = resolve_maps_path(self.filepath)
            save_artifacts(path, artifacts, scene_name=scene_name)
        except (SceneError, OSError) as exc:
            self.report({'ERROR'}, f"Saving the maps failed: {_one_line(exc)}")
            return {'CANCELLED'}
        session.set_path(scene_name, path)
        self.report({'INFO'}, f"Saved {_summary(artifacts)} to {path}")
        return {'FINISHED'}


class LANTERNA_OT_load_maps(bpy.types.Operator):
    bl_idname = "lanterna.load_maps"
    bl_label = "Load Maps"
    bl_description = ("Load maps saved for this scene (<blend name>" + DEFAULT_SUFFIX + " next "
                      "to the .blend); a file made for another scene or other settings is refused")
    bl_options = {'REGISTER'}

    filepath: StringProperty(name="File Path", subtype='FILE_PATH', default="",
                             description=_PATH_DESCRIPTION)

    def execute(self, context):
        from ..engine.artifacts import load_artifacts
        from ..engine.blender import session

        scene_name = context.scene.name
        try:
            path = resolve_maps_path(self.filepath)
            if not os.path.isfile(path):
                raise SceneError(f"No maps file at '{path}': save the maps first")
            lscene, settings = _export(context)
            artifacts = load_artifacts(path, lscene, settings)
        except Exception as exc:
            self.report({'ERROR'}, f"Loading the maps failed: {_one_line(exc)}")
            return {'CANCELLED'}
        session.put(scene_name, artifacts, source="load", path=path)
        self.report({'INFO'}, f"Loaded {_summary(artifacts)} from {path}")
        return {'FINISHED'}


# -- Report -----------------------------------------------------------------------------------
def last_report(scene_name: str) -> dict | None:
    """What ``export_report`` writes: the last render's state (report, warnings, error, times)
    or, when no render ran, the report of the scene's baked or loaded maps; None if neither."""
    from ..engine.artifacts import LANTERNA_VERSION
    from ..engine.blender import session

    last = dict(session.LAST_RENDER)
    if last.get("report"):
        out = {"source": "render"}
        out.update(last)
    else:
        artifacts = session.get(scene_name)
        if artifacts is None or not artifacts.report:
            return None
        out = {"source": session.info(scene_name).get("source", "bake"),
               "report": artifacts.report, "settings": artifacts.settings}
    out["scene"] = scene_name
    out["lanterna_version"] = LANTERNA_VERSION
    return out


class LANTERNA_OT_export_report(bpy.types.Operator, ExportHelper):
    bl_idname = "lanterna.export_report"
    bl_label = "Export Report"
    bl_description = ("Write the last render's report (stage timings, plan, counts, warnings) "
                      "as JSON")
    bl_options = {'REGISTER'}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})

    def execute(self, context):
        data = last_report(context.scene.name)
        if data is None:
            self.report({'ERROR'}, "No report to export: render or bake first")
            return {'CANCELLED'}
        if not self.filepath:
            self.report({'ERROR'}, "Export Report: no file path given")
            return {'CANCELLED'}
        path = os.path.abspath(bpy.path.abspath(self.filepath))
        try:
            write_json(path, data)
        except OSError as exc:
            self.report({'ERROR'}, f"Exporting the report failed: {_one_line(exc)}")
            return {'CANCELLED'}
        self.report({'INFO'}, f"Report written to {path}")
        return {'FINISHED'}


classes = (LANTERNA_OT_bake, LANTERNA_OT_clear, LANTERNA_OT_save_maps, LANTERNA_OT_load_maps,
           LANTERNA_OT_export_report)


def register():
    from ..engine.blender.classes import register_classes
    register_classes(classes)


def unregister():
    from ..engine.blender.classes import unregister_classes
    unregister_classes(classes)
