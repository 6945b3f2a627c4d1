"""Draws the kept maps (``session``) in the 3D viewport as points, with the ``gpu`` module.

What it does
    ``register()`` adds one draw handler, ``bpy.types.SpaceView3D.draw_handler_add(draw, (),
    'WINDOW', 'POST_VIEW')``, and ``unregister()`` removes it; in background mode
    (``bpy.app.background``) neither touches the GPU nor adds anything. ``draw()`` reads the
    scene's ``Scene.lanterna_overlay`` settings (``ui/viewport.py``): for each kind switched
    on (photons, shadow photons, cache records) the points of ``engine.overlay.overlay_points``
    (the first ``max_points`` by importance, coloured as chosen) become a ``'POINTS'`` batch
    of the builtin ``'POINT_FLAT_COLOR'`` shader (round points, one colour each; attributes
    ``pos`` vec3 and ``color`` vec4), drawn with ``gpu.state.point_size_set(point_size)``.

Batches are cached per kind with a signature: (``session.version()``, the artifacts' id,
scene name, colouring, max points, opacity). A batch is rebuilt only when its signature
changes, that is when a render, bake, load or clear changed the maps or an overlay setting
that shapes the data changed; point size, "in front" and the per-kind switches act at draw
time without a rebuild. ``requests(settings)`` and ``entry(scene_name, request,
make_batch)`` are the GPU-free parts (the tests drive them with a stand-in batch maker).

Parameters: point size [px] (default 3), max points per kind (default 100 000), opacity
(default 1), in front (default on: points are drawn over the surfaces they lie on; off: the
depth test hides those behind geometry).
"""
from __future__ import annotations

import sys
import traceback

import bpy

from .. import overlay
from . import session

_handle = None
_entries: dict = {}          # kind -> {"signature", "batch", "drawn", "total"}
_shader = None
_failed = False              # print a failing draw's traceback once, not every frame
builds = 0                   # batches built since register (for tests and the panel)

#: (kind, its switch, its colouring) in ``Scene.lanterna_overlay``.
KIND_PROPS = (("photons", "show_photons", "photons_color"),
              ("shadow_photons", "show_shadow_photons", "shadow_color"),
              ("cache", "show_cache", "cache_color"))


def requests(settings) -> list[tuple]:
    """(kind, color_by, max_points, alpha) for every kind the settings switch on."""
    if settings is None or not settings.show:
        return []
    out = []
    for kind, switch, color in KIND_PROPS:
        if getattr(settings, switch):
            out.append((kind, str(getattr(settings, color)).lower(), int(settings.max_points),
                        round(float(settings.opacity), 4)))
    return out


def entry(scene_name: str, request: tuple, make_batch) -> dict:
    """The cached entry of ``request`` (see ``requests``) for ``scene_name``; rebuilt with
    ``make_batch(OverlayPoints)`` (-> batch or None) only when the signature changed."""
    global builds
    kind, color_by, max_points, alpha = request
    artifacts = session.get(scene_name)
    signature = (session.version(), id(artifacts), scene_name, color_by, max_points, alpha)
    cached = _entries.get(kind)
    if cached is not None and cached["signature"] == signature:
        return cached
    points = overlay.overlay_points(artifacts, kind, color_by, max_points, alpha=alpha)
    batch = make_batch(points) if len(points) else None
    builds += 1
    cached = {"signature": signature, "batch": batch, "drawn": len(points),
              "total": points.total}
    _entries[kind] = cached
    return cached


def _gpu_batch(points):
    global _shader
    import gpu
    from gpu_extras.batch import batch_for_shader

    if _shader is None:
        try:
            _shader = gpu.shader.from_builtin('POINT_FLAT_COLOR')
        except (ValueError, SystemError):
            _shader = gpu.shader.from_builtin('FLAT_COLOR')
    return batch_for_shader(_shader, 'POINTS', {"pos": points.positions, "color": points.colors})


def draw():
    """The POST_VIEW callback: the scene's switched-on kinds as points."""
    global _failed
    try:
        _draw(bpy.context)
    except Exception:        # a draw callback must never raise into Blender's redraw loop
        if not _failed:
            _failed = True
            print("lanterna: viewport overlay failed:", file=sys.stderr)
            traceback.print_exc(file=sys.stderr)


def _draw(context):
    import gpu

    scene = context.scene
    space = context.space_data
    if scene is None or getattr(space, "type", "") != 'VIEW_3D':
        return
    if not getattr(getattr(space, "overlay", None), "show_overlays", True):
        return
    settings = getattr(scene, "lanterna_overlay", None)
    wanted = requests(settings)
    if not wanted or session.get(scene.name) is None:
        return
    items = [entry(scene.name, request, _gpu_batch) for request in wanted]
    gpu.state.point_size_set(float(settings.point_size))
    gpu.state.blend_set('ALPHA')
    gpu.state.depth_test_set('NONE' if settings.in_front else 'LESS_EQUAL')
    try:
        for item in items:
            if item["batch"] is not None:
                item["batch"].draw(_shader)
    finally:
        gpu.state.point_size_set(1.0)
        gpu.state.blend_set('NONE')
        gpu.state.depth_test_set('NONE')


def counts(scene_name: str, settings) -> dict:
    """{kind: (drawn, total)} of every kind with the settings' colouring and max points, on
    or off (computed, not drawn: also in background mode)."""
    artifacts = session.get(scene_name)
    return {kind: overlay.overlay_count(artifacts, kind, str(getattr(settings, color)).lower(),
                                        int(settings.max_points))
            for kind, _switch, color in KIND_PROPS}


def is_registered() -> bool:
    return _handle is not None


def _background() -> bool:
    return bool(bpy.app.background)


def register():
    global _handle, _failed
    if _background() or _handle is not None:
        return
    _failed = False
    _handle = bpy.types.SpaceView3D.draw_handler_add(draw, (), 'WINDOW', 'POST_VIEW')


def unregister():
    global _handle, _shader
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, 'WINDOW')
        _handle = None
    _entries.clear()
    _shader = None
