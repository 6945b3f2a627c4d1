"""Register and unregister everything Lanterna adds to Blender, in dependency order.

Order: properties (``Scene/Material/Light.lanterna``), the RenderEngine, operators, panels.
``unregister`` undoes it in reverse and leaves nothing behind: no classes, no ``lanterna``
pointers, no ``'LANTERNA'`` in Blender's own panels. Both are safe to call twice.
"""
from __future__ import annotations

_registered = False


def register_classes(classes) -> None:
    """Register ``classes`` in order (the loop every Lanterna module's ``register`` runs)."""
    import bpy

    for cls in classes:
        bpy.utils.register_class(cls)


def unregister_classes(classes) -> None:
    """Unregister ``classes`` in reverse order, skipping those not registered (so that
    ``unregister`` after a failed ``register`` cleans up without raising)."""
    import bpy

    for cls in reversed(classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)


def _modules():
    from ... import ops
    from ...ui import panels, properties, render_passes, viewport
    from . import render_engine

    return (properties, render_passes, render_engine, ops, panels, viewport)


def is_registered() -> bool:
    return _registered


def register_modules(modules) -> None:
    """``register()`` each module in order; if one fails, unregister those done, in reverse,
    and re-raise (nothing is left half-registered)."""
    done = []
    try:
        for module in modules:
            module.register()
            done.append(module)
    except Exception:
        for module in reversed(done):
            module.unregister()
        raise


def register():
    global _registered
    if _registered:
        return
    register_modules(_modules())
    _registered = True


def unregister():
    global _registered
    if not _registered:
        return
    for module in reversed(_modules()):
        module.unregister()
    _registered = False
