"""Operators (``LANTERNA_OT_*``). None yet; ``register``/``unregister`` keep the place in
``engine.blender.registration``'s order so that later operators need no other change."""

classes = ()


def register():
    import bpy

    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    import bpy

    for cls in reversed(classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
