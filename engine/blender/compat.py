"""What differs between the Blender versions Lanterna supports (4.2 LTS, 4.5 LTS, 5.0, 5.1, 5.2 LTS
and 5.3), in one place. Everything else in Lanterna uses an API that is the same in all of them.

``bpy`` is imported lazily, so that this module loads without Blender (and, having no imports of
its own package, also on its own by file path, as the extension test does).

* ``ensure_node_tree(id_block)`` / ``node_tree_in_use(id_block)`` / ``uses_nodes(id_block)``:
  which node tree a material, world or light renders through. Materials and worlds have a node
  tree from 5.0 on and always render through it; lights do so from 5.1 on (5.2 gives every
  light a tree with one Emission node, strength 1, white, and ignores ``use_nodes = False``).
  There ``use_nodes`` is deprecated, to be removed in 6.0, and reading it warns
  (``DeprecationWarning: 'Material.use_nodes' is expected to be removed in Blender 6.0``;
  ``Light.use_nodes`` likewise). Before, nodes are opt-in: ``use_nodes = True`` creates the
  tree, and a block with ``use_nodes`` off renders without it (a material or world with its
  viewport colour, a light with Color x Power). Which case applies is read from Blender's own
  description of the property (``bl_rna``: deprecated or gone means always on), not from
  version numbers, so ``use_nodes`` is read only where it still means something.
* ``light_exposure(light)`` / ``light_normalized(light)``: ``Light.exposure`` (power x
  2^exposure) and ``Light.normalize`` (off: power per square metre of an area light) came after
  4.2; there every light has exposure 0 and is normalized.
* ``eevee_engine_id()``: EEVEE's engine id is ``'BLENDER_EEVEE_NEXT'`` in 4.2 and 4.5 and
  ``'BLENDER_EEVEE'`` again in 5.0.
* ``multilayer_exr(image_settings)``: 5.0 made "multilayer" a media type
  (``ImageFormatSettings.media_type = 'MULTI_LAYER_IMAGE'``) that must be set before
  ``file_format = 'OPEN_EXR_MULTILAYER'`` is accepted; 4.2 and 4.5 have no ``media_type``.
* ``default_surface_is_principled()``: what Cycles renders faces without a material with: a
  Diffuse BSDF of 0.8 in 4.2 and 4.5, the default Principled BSDF (Base Color 0.8, Roughness
  0.5, IOR 1.5, its dielectric layer) from 5.0 on. Measured: a sunlit plane without a
  material renders as one with a Diffuse BSDF of 0.8 in 4.2 and 4.5 and as one with a default
  Principled BSDF in 5.0, 5.2 and 5.3 (0.515-0.544 against 0.573 towards the horizon).
* ``exit_process(code)``: ``bpy`` *as a Python module* before 5.0 cannot end a process once an
  add-on has registered a property with a Python ``update`` callback (Lanterna's properties
  have them): at interpreter exit bpy 4.2 crashes (SIGSEGV: ``SpaceType``'s C++ destructor calls
  ``PyGILState_Ensure`` after Python has been finalised) and bpy 4.5 hangs (a static
  destructor waits on a condition variable forever), unregistering first or not. Blender itself
  exits through its own path and is not affected. So a process that imported ``bpy`` ends
  with ``os._exit`` there (after flushing output and removing Blender's session temp folder);
  on 5.0 and without ``bpy`` it ends normally.
"""
from __future__ import annotations

import os
import shutil
import sys

__all__ = ["blender_version", "nodes_always_on", "ensure_node_tree", "node_tree_in_use",
           "uses_nodes", "light_exposure", "light_normalized", "eevee_engine_id",
           "multilayer_exr", "default_surface_is_principled", "module_exit_is_unsafe",
           "exit_process"]


def blender_version() -> tuple[int, int, int]:
    import bpy

    return tuple(bpy.app.version)


def nodes_always_on(id_block) -> bool:
    """Whether ``id_block`` (a material, world or light) always renders through its node tree:
    its ``use_nodes`` is deprecated (materials and worlds from 5.0, lights from 5.1) or gone
    (6.0). Read from the RNA description, which does not warn as reading ``use_nodes`` does."""
    prop = type(id_block).bl_rna.properties.get("use_nodes")
    return prop is None or bool(getattr(prop, "is_deprecated", False))


def ensure_node_tree(id_block):
    """The node tree of a material, world or light, switched on first where nodes are opt-in."""
    if id_block.node_tree is None and not nodes_always_on(id_block):     # 4.2, 4.5
        id_block.use_nodes = True
    return id_block.node_tree


def node_tree_in_use(id_block):
    """The node tree a material, world or light renders through, or None when it renders
    without one (no tree, or ``use_nodes`` off where nodes are still opt-in)."""
    tree = id_block.node_tree
    if tree is None:
        return None
    if nodes_always_on(id_block):
        return tree
    return tree if id_block.use_nodes else None


def uses_nodes(id_block) -> bool:
    """Whether a material, world or light renders through its node tree."""
    return node_tree_in_use(id_block) is not None


def light_exposure(light) -> float:
    """``Light.exposure`` in stops (0 where Blender has none)."""
    return float(getattr(light, "exposure", 0.0))


def light_normalized(light) -> bool:
    """``Light.normalize`` (always on where Blender has no such switch)."""
    return bool(getattr(light, "normalize", True))


def eevee_engine_id() -> str:
    """EEVEE's id in ``RenderSettings.engine`` of the running Blender."""
    import bpy

    engines = bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items.keys()
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"


def multilayer_exr(image_settings) -> None:
    """Make ``image_settings`` (a ``bpy.types.ImageFormatSettings``) write multilayer EXR."""
    if hasattr(image_settings, "media_type"):          # 5.0 and later
        image_settings.media_type = 'MULTI_LAYER_IMAGE'
    image_settings.file_format = 'OPEN_EXR_MULTILAYER'


def default_surface_is_principled() -> bool:
    """Whether Cycles shades faces without a material with the default Principled BSDF
    (5.0 on) rather than a Diffuse BSDF of 0.8 (4.2, 4.5): module docstring."""
    return blender_version() >= (5, 0, 0)


def module_exit_is_unsafe() -> bool:
    """True in a process that imported bpy < 5.0 as a module (see the module docstring)."""
    bpy = sys.modules.get("bpy")
    if bpy is None or not hasattr(bpy, "app"):
        return False
    return tuple(bpy.app.version) < (5, 0, 0) and not bpy.app.binary_path


def exit_process(code: int = 0):
    """End the process with ``code``; past bpy 4.2/4.5's broken module exit where it applies."""
    code = code if isinstance(code, int) else (0 if code is None else 1)
    if not module_exit_is_unsafe():
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    import bpy

    tempdir = bpy.app.tempdir                  # Blender's per-session folder, removed at exit
    if tempdir and os.path.basename(os.path.normpath(tempdir)).startswith("blender_"):
        shutil.rmtree(tempdir, ignore_errors=True)
    os._exit(code)
