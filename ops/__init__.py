"""Operators (``LANTERNA_OT_*``). None yet; ``register``/``unregister`` keep the place in
``engine.blender.registration``'s order so that later operators need no other change."""

classes = ()


def register():
    from ..engine.blender.registration import register_classes
    register_classes(classes)


def unregister():
    from ..engine.blender.registration import unregister_classes
    unregister_classes(classes)
