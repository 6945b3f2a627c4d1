"""Lanterna: a photon-mapping render engine for Blender (the add-on entry point).

Blender calls ``register()`` and ``unregister()``; everything else lives in ``engine/``
(the renderer, free of ``bpy``), ``engine/blender/`` (export and the RenderEngine),
``ops/`` (operators) and ``ui/`` (properties and panels). ``bpy`` is imported only inside
those two functions so that ``import lanterna.engine`` works without Blender.
"""


def register():
    from .engine.blender import registration
    registration.register()


def unregister():
    from .engine.blender import registration
    registration.unregister()
