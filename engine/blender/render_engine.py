"""The Blender RenderEngine: depsgraph -> export -> pipeline -> Render Result.

``LanternaRenderEngine.render(depsgraph)`` (F12 and ``bpy.ops.render.render``):

1. Size: ``self.resolution_x/y`` is the full frame with the resolution percentage applied.
   With a render border Blender hands the engine a result of the border's size only:
   ``begin_result(x, y, w, h)`` takes coordinates relative to the border window's lower-left
   corner and clips ``w, h`` to it. The window's offset in the frame is Blender's own
   ``int(border_min * size)`` in float32 (``export.render_border``); its size is read back
   from the result.
   ``use_crop_to_border`` only changes what Blender keeps afterwards (the window alone, or the
   full frame with the window pasted in and the rest transparent): the engine renders the
   same pixels either way.
2. ``export.export_scene(depsgraph, resolution=(W, H), border=(x0, y0, x1, y1))`` and
   ``export.export_settings(scene)``; every ``Scene.warnings`` item is reported once.
3. ``pipeline.render`` with progress -> ``update_progress``/``update_stats`` and
   cancellation <- ``test_break``. Maps baked (Lanterna > Bake in the 3D viewport's
   sidebar), loaded from a file or kept from the last render are reused when their
   fingerprint matches this scene and these map settings (the picture is the same); the
   render's maps are then kept in ``engine/blender/session.py`` for the viewport overlay.
4. The (H, W, 3) image, row 0 = top, goes into the Combined pass as RGBA with rows bottom-up;
   the passes ticked in ``ViewLayer.lanterna_passes`` and Cycles' light passes whose Blender
   flag is on (``use_pass_diffuse_direct`` ...: DiffDir ... Env; ``ui/render_passes.py``),
   registered in ``update_render_passes``, go into theirs as RGB.

Errors stop at this boundary: ``report({'ERROR'})`` + ``error_set`` with a one-line message,
the traceback (for unexpected errors only) to stderr after a ``lanterna: render failed:``
line. (``bpy.ops.render.render()`` then raises RuntimeError carrying the message, once per
report: that is Blender turning ERROR reports into an exception, not ours escaping.)
``LAST_RENDER`` keeps the last render's report, warnings, error, export time and total time
for the panels (Render properties > Last Render).
"""
from __future__ import annotations

import sys
import time
import traceback

import bpy
import numpy as np

from ...ui.render_passes import enabled_passes
from .. import pipeline
from ..artifacts import scene_fingerprint
from ..scene import SceneError
from . import export, session
from .classes import register_classes, unregister_classes

ENGINE_ID = "LANTERNA"

#: The last render (``session.LAST_RENDER``, the same dict).
LAST_RENDER: dict = session.LAST_RENDER


def image_to_rect(image: np.ndarray, channels: int = 4) -> np.ndarray:
    """(H, W, 3) row-0-top linear image -> flat float32 RGBA (or RGB for a 3-channel pass),
    rows bottom-up (Blender's rect)."""
    h, w = image.shape[:2]
    out = np.empty((h, w, channels), np.float32)
    out[..., :3] = image[::-1, :, :3]
    if channels == 4:
        out[..., 3] = 1.0
    return out.ravel()


class LanternaRenderEngine(bpy.types.RenderEngine):
    bl_idname = ENGINE_ID
    bl_label = "Lanterna"
    bl_use_preview = False            # material previews would need their own scene export
    bl_use_shading_nodes_custom = False  # the standard shader node editor works
    bl_use_eevee_viewport = True      # Material Preview shading in the viewport uses EEVEE
    bl_use_postprocess = True

    # -- F12 ----------------------------------------------------------------------------------
    def render(self, depsgraph):
        started = time.perf_counter()
        scene = depsgraph.scene
        width, height = self.resolution_x, self.resolution_y
        layer = depsgraph.view_layer.name if depsgraph.view_layer else ""
        result = self.begin_result(0, 0, width, height, layer=layer)
        state = {"report": {}, "warnings": [], "error": None, "size": (width, height)}
        try:
            self._render_into(depsgraph, scene, width, height, result, state)
        except Exception as exc:  # the boundary: nothing escapes to Blender
            self._fail(exc, state)
        finally:
            # A failed render keeps nothing; a cancelled one keeps what it has.
            self.end_result(result, cancel=state["error"] is not None)
            state["total_time"] = time.perf_counter() - started
            LAST_RENDER.clear()
            LAST_RENDER.update(state)

    def _render_into(self, depsgraph, scene, width, height, result, state):
        win_w, win_h = result.resolution_x, result.resolution_y
        border = export.render_border(scene.render, (width, height))  # Blender's truncation
        if border is not None:
            x0, y0 = border[:2]
            border = (x0, y0, x0 + win_w, y0 + win_h)  # the result's size is the truth
        elif (win_w, win_h) != (width, height):
            raise RuntimeError(f"Blender gave a {win_w}x{win_h} result for a "
                               f"{width}x{height} frame without a border")
        state["border"] = border

        self.update_stats("Lanterna", "Exporting scene")
        lscene = export.export_scene(depsgraph, resolution=(width, height), border=border)
        settings = export.export_settings(scene)
        state["export_seconds"] = float(lscene.stats.get("export_seconds", 0.0))
        self._report_warnings(list(lscene.warnings), state)

        def progress(fraction, text=""):
            self.update_progress(float(min(max(fraction, 0.0), 1.0)))
            if text:
                self.update_stats("Lanterna", str(text))

        wanted = enabled_passes(depsgraph.view_layer) if depsgraph.view_layer else []
        # The maps stay in the session for the viewport overlay and the next render.
        reuse = self._reusable_maps(session.get(scene.name), lscene, settings)
        res = pipeline.render(lscene, settings, progress=progress, cancelled=self.test_break,
                              passes=wanted, artifacts=reuse)
        state["report"] = res.report or {}
        state["maps_reused"] = reuse is not None
        if not res.cancelled:
            session.put(scene.name, getattr(res, "artifacts", None), source="render")
        self._report_warnings(list((res.report or {}).get("warnings", ())), state)

        image = np.asarray(res.image, dtype=np.float32)
        if image.shape[:2] != (win_h, win_w) or image.ndim != 3 or image.shape[2] < 3:
            raise RuntimeError(f"pipeline returned an image of shape {image.shape}, "
                               f"expected ({win_h}, {win_w}, 3)")
        layer_passes = result.layers[0].passes
        layer_passes["Combined"].rect.foreach_set(image_to_rect(image))
        for name, pass_image in res.passes.items():
            target = layer_passes.get(name)
            if target is not None:
                target.rect.foreach_set(image_to_rect(pass_image, channels=3))
        self.update_progress(1.0)
        state["cancelled"] = bool(res.cancelled)
        plan = (res.report or {}).get("plan", {}).get("summary", "")
        self.update_stats("Lanterna", ("Cancelled" if res.cancelled else "Done")
                          + (f" | {plan}" if plan else ""))

    @staticmethod
    def _reusable_maps(artifacts, lscene, settings):
        """Maps baked, loaded or kept from the last render, when they were made for exactly
        this scene and these map settings (same fingerprint): the render then skips building
        them and gives the same picture. Anything else: None (build afresh)."""
        if artifacts is None:
            return None
        try:
            same = artifacts.fingerprint == scene_fingerprint(lscene, settings.resolved())
        except Exception:  # noqa: BLE001 - a scene the fingerprint cannot take: build afresh
            return None
        return artifacts if same else None

    # -- Passes --------------------------------------------------------------------------------
    def update_render_passes(self, scene=None, renderlayer=None):
        """Tell Blender which passes the view layer gets (Combined is always there), so they
        show in the Image Editor, the compositor's Render Layers node and multilayer EXRs."""
        for name in enabled_passes(renderlayer):
            self.register_pass(scene, renderlayer, name, 3, "RGB", 'COLOR')

    # -- Reporting ----------------------------------------------------------------------------
    def _report_warnings(self, warnings, state):
        for text in warnings:
            text = str(text)
            if text not in state["warnings"]:
                state["warnings"].append(text)
                self.report({'WARNING'}, text)

    def _fail(self, exc: BaseException, state):
        if isinstance(exc, SceneError):
            message = str(exc) or type(exc).__name__
        else:
            message = f"Lanterna internal error: {type(exc).__name__}: {exc}"
            print("lanterna: render failed:", file=sys.stderr)
            traceback.print_exc(file=sys.stderr)
        message = " ".join(message.split())  # one line
        state["error"] = message
        self.report({'ERROR'}, message)
        self.error_set(message)


classes = (LanternaRenderEngine,)


def register():
    register_classes(classes)


def unregister():
    unregister_classes(classes)
