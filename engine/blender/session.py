"""Where a render's maps live in Blender between renders: a store keyed by scene name.

What it holds
    For each scene name the last ``engine.artifacts.Artifacts`` (photon map, shadow photons,
    irradiance cache) that a render (``render_engine.py``), a bake or a load
    (``ops/bake.py``) produced, with where it came from (``"render"``, ``"bake"`` or
    ``"load"``) and, for loaded or saved maps, the file. ``version()`` is a counter that
    grows with every change; the viewport overlay (``overlay_draw.py``) rebuilds its GPU
    batches only when it moved. The maps stay in memory (about 36 bytes a photon plus the
    kd-trees) until ``clear``, a new render of the scene, or Blender's exit; nothing is
    written into the .blend.

``LAST_RENDER``: the last F12 render's report, warnings, error, export and total time, size,
border and whether it was cancelled (``render_engine.py`` fills it; the Last Render panels and
the panel's estimate read it).

Functions
    ``put(scene_name, artifacts, source="render", path="")``  store (None clears);
    ``get(scene_name)`` -> Artifacts or None; ``info(scene_name)`` -> {"source", "path"};
    ``clear(scene_name=None)`` (None: every scene); ``version()``; ``names()``.
    Each change asks the 3D viewports to redraw (``redraw_viewports``; skipped in background
    mode).
"""
from __future__ import annotations

import threading

_lock = threading.Lock()
_store: dict = {}          # scene name -> {"artifacts", "source", "path"}
_version = 0

#: The last render: {"report", "warnings", "error", "export_seconds", "total_time", "size",
#: "border", "cancelled"}.
LAST_RENDER: dict = {}


def _changed():
    global _version
    _version += 1
    redraw_viewports()


def redraw_viewports():
    """Ask every 3D viewport to redraw (the overlay follows the maps); nothing in background
    mode."""
    try:
        import bpy
    except ImportError:
        return
    if bpy.app.background:
        return
    wm = getattr(bpy.context, "window_manager", None)
    for window in getattr(wm, "windows", ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def put(scene_name: str, artifacts, source: str = "render", path: str = "") -> None:
    """Keep ``artifacts`` for ``scene_name`` (replacing what it had); None clears it."""
    with _lock:
        if artifacts is None:
            _store.pop(str(scene_name), None)
        else:
            _store[str(scene_name)] = {"artifacts": artifacts, "source": source, "path": str(path)}
    _changed()


def get(scene_name: str):
    """The scene's artifacts, or None."""
    entry = _store.get(str(scene_name))
    return None if entry is None else entry["artifacts"]


def info(scene_name: str) -> dict:
    """{"source": "render" | "bake" | "load", "path": file or ""}; {} when nothing is kept."""
    entry = _store.get(str(scene_name))
    return {} if entry is None else {"source": entry["source"], "path": entry["path"]}


def set_path(scene_name: str, path: str) -> None:
    """Record the file the scene's maps were saved to."""
    with _lock:
        entry = _store.get(str(scene_name))
        if entry is not None:
            entry["path"] = str(path)


def clear(scene_name: str | None = None) -> None:
    """Forget the maps of ``scene_name`` (None: of every scene)."""
    with _lock:
        if scene_name is None:
            _store.clear()
        else:
            _store.pop(str(scene_name), None)
    _changed()


def names() -> list[str]:
    return sorted(_store)


def version() -> int:
    """Grows with every ``put`` / ``clear``."""
    return _version
