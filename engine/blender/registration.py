"""Register and unregister everything Lanterna adds to Blender, in dependency order.

Order: properties (``Scene/Material/Light.lanterna``), the RenderEngine, operators, panels.
``unregister`` undoes it in reverse and leaves nothing behind: no classes, no ``lanterna``
pointers, no ``'LANTERNA'`` in Blender's own panels. Both are safe to call twice.
"""
from __future__ import annotations

_registered = False


def _modules():
    from ... import ops
    from ...ui import panels, properties
    from . import render_engine

    return (properties, render_engine, ops, panels)


def is_registered() -> bool:
    return _registered


def register():
    global _registered
    if _registered:
        return
    done = []
    try:
        for module in _modules():
            module.register()
            done.append(module)
    except Exception:
        for module in reversed(done):
            module.unregister()
        raise
    _registered = True


def unregister():
    global _registered
    if not _registered:
        return
    for module in reversed(_modules()):
        module.unregister()
    _registered = False
