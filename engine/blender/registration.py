"""Register and unregister everything Lanterna adds to Blender, in dependency order: the top of
the Blender layer (``__init__.py`` and the ``lanterna`` command call it).

Order (``MODULES``): properties (``Scene/Material/Light.lanterna``, the view layers' passes),
the RenderEngine, the operators (bake and load maps; import ASE), panels, the viewport
overlay. ``unregister`` undoes it in reverse and
leaves nothing behind: no classes, no ``lanterna`` pointers, no ``'LANTERNA'`` in Blender's own
panels. Both are safe to call twice.
"""
from __future__ import annotations

from ...ops import bake, import_ase
from ...ui import panels, properties, render_passes, viewport
from . import render_engine
from .classes import register_modules

MODULES = (properties, render_passes, render_engine, bake, import_ase, panels, viewport)
_registered = False


def is_registered() -> bool:
    return _registered


def register():
    global _registered
    if _registered:
        return
    register_modules(MODULES)
    _registered = True


def unregister():
    global _registered
    if not _registered:
        return
    for module in reversed(MODULES):
        module.unregister()
    _registered = False
