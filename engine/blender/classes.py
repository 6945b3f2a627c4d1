"""Registering Blender classes and modules (a leaf of the Blender layer: every module that
adds classes to Blender uses it; ``registration.py`` calls the modules in order).

``register_classes(classes)`` registers in order; ``unregister_classes(classes)`` in reverse,
skipping what is not registered (so an ``unregister`` after a failed ``register`` cleans up
without raising); ``register_modules(modules)`` calls each module's ``register()`` and, if one
fails, unregisters those done, in reverse, and re-raises: nothing is left half-registered.
"""
from __future__ import annotations


def register_classes(classes) -> None:
    """Register ``classes`` in order (the loop every Lanterna module's ``register`` runs)."""
    import bpy

    for cls in classes:
        bpy.utils.register_class(cls)


def unregister_classes(classes) -> None:
    """Unregister ``classes`` in reverse order, skipping those not registered."""
    import bpy

    for cls in reversed(classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)


def register_modules(modules) -> None:
    """``register()`` each module in order; on a failure unregister those done, in reverse,
    and re-raise."""
    done = []
    try:
        for module in modules:
            module.register()
            done.append(module)
    except Exception:
        for module in reversed(done):
            module.unregister()
        raise
