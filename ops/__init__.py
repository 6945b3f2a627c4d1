"""Operators (``LANTERNA_OT_*``), one module per family, registered in ``MODULES`` order by
``engine.blender.registration`` (after the RenderEngine, before the panels). Each module has
``register()`` / ``unregister()``; ``unregister`` runs in reverse order."""
import importlib

# Module names under ops/, in registration order.
MODULES = ("bake", "import_ase")


def _modules():
    return [importlib.import_module(f"{__name__}.{name}") for name in MODULES]


def register():
    from ..engine.blender.registration import register_modules
    register_modules(_modules())


def unregister():
    for module in reversed(_modules()):
        module.unregister()
