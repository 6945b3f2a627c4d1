"""Operators (``LANTERNA_OT_*``), one module per family: ``bake`` (bake, save, load and clear
the maps) and ``import_ase`` (File > Import > ASE). Each has ``register()`` / ``unregister()``;
``engine.blender.registration`` registers them after the RenderEngine, before the panels."""
