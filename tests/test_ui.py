"""The panels (``ui/panels.py``) and their properties (``ui/properties.py``) in Blender.

What is checked
* Registration: register / unregister twice each; afterwards no Lanterna class is registered,
  no ``lanterna`` pointer is left on Scene, Material or Light, and no panel of Blender's keeps
  ``'LANTERNA'`` in its ``COMPAT_ENGINES`` (also a set an earlier registration left behind).
  While registered, the built-in output, colour-management, camera and light-data panels are
  open to Lanterna, Blender's light panel (ours replaces it), its spot sub-panel and depth of
  field are not.
* Poll: every Lanterna panel polls True for LANTERNA and False for Cycles, EEVEE (both of its
  identifiers) and Workbench, with a stand-in context and, for the render panels, with
  ``bpy.context`` itself.
* Draw: background Blender has no window, so no real ``UILayout`` can be made. Each panel's
  ``draw`` / ``draw_header`` is called with ``StubLayout``, which checks every call against
  ``bpy.types.UILayout``'s RNA: the function exists, its keyword arguments exist, icons are
  valid, and each ``prop`` names a property that exists on the data it is given. It records
  the labels and props with whether they are drawn active and alert, so the tests can assert
  what a user would see (greyed values under a preset, the energy alert, the plan and the
  timings of a real F12 render). What the stub cannot check is Blender's own drawing (sizes,
  wrapping on screen).
* The rho check flags exactly the channels whose rho_d + rho_s exceeds 1; the derived values
  shown are the exporter's.
* The per-light shadow-photon switch and the new Scene properties reach the core through
  ``export``.
"""
import math
import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from lanterna.engine.blender import compat, export, registration, render_engine  # noqa: E402
from lanterna.engine.lights import LightSet  # noqa: E402
from lanterna.engine.scene import AreaLight, PointLight  # noqa: E402
from lanterna.ui import panels, properties  # noqa: E402

ENGINE = "LANTERNA"
OTHER_ENGINES = ("CYCLES", "BLENDER_EEVEE", "BLENDER_EEVEE_NEXT", "BLENDER_WORKBENCH")
UILAYOUT = bpy.types.UILayout.bl_rna
ICONS = set(UILAYOUT.functions["label"].parameters["icon"].enum_items.keys())
LAYOUT_ATTRIBUTES = set(UILAYOUT.properties.keys()) - {"rna_type"}
WANTED_BUILTINS = ("RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output",
                   "RENDER_PT_color_management", "DATA_PT_context_camera", "DATA_PT_camera",
                   "DATA_PT_lens", "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture",
                   "DATA_PT_context_light", "WORLD_PT_context_world",
                   "EEVEE_MATERIAL_PT_context_material")
UNWANTED_BUILTINS = ("DATA_PT_light", "DATA_PT_spot", "DATA_PT_preview")


# -- A UILayout stand-in ----------------------------------------------------------------------
class StubLayout:
    """Records what a panel draws; every call is checked against ``bpy.types.UILayout``."""

    def __init__(self, log, parent=None):
        object.__setattr__(self, "_log", log)
        object.__setattr__(self, "_parent", parent)
        object.__setattr__(self, "_state", {})

    def __setattr__(self, name, value):
        assert name in LAYOUT_ATTRIBUTES, f"UILayout has no attribute {name!r}"
        self._state[name] = value

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        if name in LAYOUT_ATTRIBUTES:
            return self._state.get(name, UILAYOUT.properties[name].default)
        function = UILAYOUT.functions.get(name)
        if function is None:
            raise AttributeError(f"UILayout has no function {name!r}")
        return lambda *args, **kwargs: self._call(name, function, args, kwargs)

    def _chain(self):
        layout = self
        while layout is not None:
            yield layout
            layout = layout._parent

    def _call(self, name, function, args, kwargs):
        params = list(function.parameters.keys())
        unknown = set(kwargs) - set(params)
        assert not unknown, f"UILayout.{name} has no parameter(s) {sorted(unknown)}"
        if "icon" in kwargs:
            assert kwargs["icon"] in ICONS, f"unknown icon {kwargs['icon']!r}"
        entry = types.SimpleNamespace(
            kind=name, kwargs=kwargs, text=kwargs.get("text"),
            active=all(layout._state.get("active", True) for layout in self._chain()),
            alert=any(layout._state.get("alert", False) for layout in self._chain()),
            data=None, prop=None)
        if name in ("prop", "prop_enum", "props_enum", "prop_menu_enum", "prop_tabs_enum"):
            data = args[0] if args else kwargs["data"]
            prop = args[1] if len(args) > 1 else kwargs["property"]
            assert prop in data.bl_rna.properties.keys(), \
                f"{data.bl_rna.identifier} has no property {prop!r}"
            entry.data, entry.prop = data, prop
        self._log.append(entry)
        return StubLayout(self._log, self)


class PanelSelf:
    """``self`` for a panel method: the class's attributes and a stub ``layout``."""

    def __init__(self, cls, layout):
        self.cls = cls
        self.layout = layout

    def __getattr__(self, name):
        return getattr(self.cls, name)


def draw(panel, context, header=False) -> list:
    """Run ``panel.draw`` (or ``draw_header``) with a stub layout; the recorded calls."""
    log = []
    method = panel.draw_header if header else panel.draw
    method(PanelSelf(panel, StubLayout(log)), context)
    return log


def labels(log) -> list[str]:
    return [e.text for e in log if e.kind == "label" and e.text]


def props(log) -> dict:
    """prop name -> its recorded call (the last one with that name)."""
    return {e.prop: e for e in log if e.prop is not None}


# -- Helpers ----------------------------------------------------------------------------------
@pytest.fixture
def registered():
    was = registration.is_registered()
    registration.register()
    yield
    if not was:
        registration.unregister()


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def all_panels():
    return panels._all_panels()


def panels_with_lanterna() -> list[str]:
    """Panels whose own COMPAT_ENGINES set lists Lanterna (Blender's, opened to it)."""
    return sorted(p.__name__ for p in all_panels()
                  if ENGINE in (p.__dict__.get("COMPAT_ENGINES") or ()))


def lanterna_classes():
    return (*properties.classes, *render_engine.classes, *panels.classes)


def context_for(scene, engine=ENGINE, **data):
    base = dict(engine=engine, scene=scene, material=None, light=None, world=None,
                object=None, camera=None, region=None,
                view_layer=scene.view_layers[0] if scene is not None else None)
    base.update(data)
    return types.SimpleNamespace(**base)


def build_scene(light_type='AREA'):
    """A floor with a Principled material, an occluder, a light, a camera, a black world."""
    scene = reset()
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -4.0, 3.0)
    cam.rotation_euler = (math.radians(55), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    mesh = bpy.data.meshes.new("Floor")
    mesh.from_pydata([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0),
                      (-0.5, -0.5, 1), (0.5, -0.5, 1), (0.5, 0.5, 1), (-0.5, 0.5, 1)],
                     [], [(0, 1, 2, 3), (4, 5, 6, 7)])
    mat = bpy.data.materials.new("Floor")
    mesh.materials.append(mat)
    obj = bpy.data.objects.new("Floor", mesh)
    scene.collection.objects.link(obj)
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", light_type))
    light.location = (0.0, 0.0, 2.5)
    light.data.energy = 200.0
    scene.collection.objects.link(light)
    world = bpy.data.worlds.new("Black")
    for node in compat.ensure_node_tree(world).nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    scene.render.engine = ENGINE
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    scene.render.resolution_percentage = 100
    s = scene.lanterna
    s.samples, s.light_samples, s.photons, s.gather_m, s.gather_n = 1, 1, 5000, 2, 4
    return scene, obj, mat, light.data, world, cam.data


# -- Registration -----------------------------------------------------------------------------
def assert_nothing_left():
    for cls in lanterna_classes():
        assert not getattr(cls, "is_registered", False), cls.__name__
        assert not hasattr(bpy.types, cls.__name__), cls.__name__
    for owner in (bpy.types.Scene, bpy.types.Material, bpy.types.Light):
        assert not hasattr(owner, "lanterna"), owner
        assert "lanterna" not in owner.bl_rna.properties.keys()
    assert panels_with_lanterna() == []
    with pytest.raises(TypeError):                   # the engine is gone from the enum
        bpy.context.scene.render.engine = ENGINE


def test_register_and_unregister_twice_leave_nothing_behind():
    was = registration.is_registered()
    registration.unregister()
    try:
        assert_nothing_left()
        for _ in range(2):
            registration.register()
            registration.register()            # a second register is harmless
            for cls in lanterna_classes():
                assert cls.is_registered, cls.__name__
            for owner in (bpy.types.Scene, bpy.types.Material, bpy.types.Light):
                assert hasattr(owner, "lanterna")
            opened = panels_with_lanterna()          # Blender's panels opened to Lanterna
            for name in WANTED_BUILTINS:
                assert name in opened, name
            for name in UNWANTED_BUILTINS:
                assert name not in opened, name
            assert not [n for n in opened if n.startswith(("CYCLES_", "EEVEE_WORLD",
                                                           "RENDER_PT_eevee"))]
            registration.unregister()
            registration.unregister()          # so is a second unregister
            assert_nothing_left()
    finally:
        if was:
            registration.register()


def test_unregister_removes_lanterna_from_sets_an_earlier_registration_left():
    was = registration.is_registered()
    registration.unregister()
    stale = bpy.types.RENDER_PT_format.COMPAT_ENGINES
    try:
        stale.add(ENGINE)                      # as a reloaded copy of the module would leave it
        registration.register()
        assert ENGINE in stale
        registration.unregister()
        assert ENGINE not in stale
        assert_nothing_left()
    finally:
        stale.discard(ENGINE)
        if was:
            registration.register()


def test_panel_conventions(registered):
    names = {cls.__name__ for cls in panels.classes}
    for cls in panels.classes:
        assert cls.COMPAT_ENGINES == {ENGINE}
        assert cls.__name__.startswith("LANTERNA_") and "_PT_" in cls.__name__
        assert cls.bl_space_type == 'PROPERTIES' and cls.bl_region_type == 'WINDOW'
        parent = getattr(cls, "bl_parent_id", "")
        if parent:
            # A Lanterna panel registered before it, or a built-in panel opened to Lanterna.
            assert parent in names or parent in panels._EXTRA_BUILTINS, cls.__name__
            parent_cls = getattr(bpy.types, parent)
            assert parent_cls.bl_context == cls.bl_context, cls.__name__
            if parent in names:
                assert panels.classes.index(parent_cls) < panels.classes.index(cls)
    # The switches live in the headers.
    for cls, prop in ((panels.LANTERNA_RENDER_PT_shadow_photons, "shadow_photons"),
                      (panels.LANTERNA_RENDER_PT_irradiance_cache, "use_irradiance_cache")):
        scene = reset()
        log = draw(cls, context_for(scene), header=True)
        assert [(e.prop, e.text) for e in log if e.prop] == [(prop, "")]
    assert panels.LANTERNA_RENDER_PT_final_gather.bl_parent_id == "LANTERNA_RENDER_PT_indirect"
    assert panels.LANTERNA_RENDER_PT_irradiance_cache.bl_parent_id == "LANTERNA_RENDER_PT_indirect"
    assert panels.LANTERNA_LIGHT_PT_photons.bl_parent_id == "LANTERNA_LIGHT_PT_light"


# -- Poll -------------------------------------------------------------------------------------
def test_every_panel_polls_only_for_lanterna(registered):
    scene, obj, mat, light, world, cam = build_scene()
    cam.type = 'PANO'              # the Panorama panel shows for panoramic cameras only
    data = dict(material=mat, light=light, world=world, object=obj, camera=cam)
    for cls in panels.classes:
        assert cls.poll(context_for(scene, **data)), cls.__name__
        for engine in OTHER_ENGINES:
            assert not cls.poll(context_for(scene, engine, **data)), (cls.__name__, engine)
    # Data panels need their data block.
    for cls in (panels.LANTERNA_MATERIAL_PT_surface, panels.LANTERNA_MATERIAL_PT_radiometry,
                panels.LANTERNA_LIGHT_PT_light, panels.LANTERNA_LIGHT_PT_photons,
                panels.LANTERNA_WORLD_PT_surface, panels.LANTERNA_CAMERA_PT_panorama):
        assert not cls.poll(context_for(scene)), cls.__name__
    cam.type = 'PERSP'
    assert not panels.LANTERNA_CAMERA_PT_panorama.poll(context_for(scene, **data))

    # bpy.context itself (background mode has engine and scene, no material or light).
    render_panels = [cls for cls in panels.classes if cls.bl_context == "render"]
    assert len(render_panels) >= 10
    scene.render.engine = ENGINE
    assert bpy.context.engine == ENGINE
    assert all(cls.poll(bpy.context) for cls in render_panels)
    for engine in ("CYCLES", compat.eevee_engine_id(), "BLENDER_WORKBENCH"):
        scene.render.engine = engine
        assert bpy.context.engine == engine
        assert not any(cls.poll(bpy.context) for cls in render_panels), engine
    scene.render.engine = ENGINE


# -- Draw -------------------------------------------------------------------------------------
def test_every_panel_draws(registered, tmp_path):
    """All panels and headers draw on a scene with a mesh, a material, lights of every type
    and a real last render; every prop they draw exists on its property group."""
    scene, obj, mat, light, world, cam = build_scene()
    cam.type = 'PANO'
    cam.panorama_type = 'EQUIRECTANGULAR'
    bpy.ops.render.render()
    last = render_engine.LAST_RENDER
    assert last.get("error") is None and last["report"]["plan"]["stages"]
    for light_type in ('AREA', 'POINT', 'SPOT', 'SUN'):
        light.type = light_type
        light = bpy.data.lights[light.name]              # its RNA type changed with the type
        ctx = context_for(scene, material=mat, light=light, world=world, object=obj, camera=cam)
        for cls in panels.classes:
            log = draw(cls, ctx)
            assert log, cls.__name__
            if hasattr(cls, "draw_header"):
                draw(cls, ctx, header=True)
        for derive in (True, False):
            mat.lanterna.derive_from_nodes = derive
            draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)
    # The property groups' props that the render panels draw cover the settings.
    drawn = set()
    for cls in panels.classes:
        if cls.bl_context == "render":
            log = draw(cls, ctx) + (draw(cls, ctx, header=True)
                                    if hasattr(cls, "draw_header") else [])
            drawn |= {e.prop for e in log if e.data == scene.lanterna}
    settings = set(scene.lanterna.bl_rna.properties.keys()) - {"rna_type", "name"}
    assert settings - drawn == set(), "render settings no panel draws"


def test_sampling_greys_what_the_preset_sets(registered):
    scene = reset()
    ctx = context_for(scene)
    scene.lanterna.preset = 'CUSTOM'
    drawn = props(draw(panels.LANTERNA_RENDER_PT_sampling, ctx))
    assert drawn["samples"].active and drawn["light_samples"].active and drawn["preset"].active
    scene.lanterna.preset = 'FINAL'
    log = draw(panels.LANTERNA_RENDER_PT_sampling, ctx)
    drawn = props(log)
    assert not drawn["samples"].active and not drawn["light_samples"].active
    assert drawn["bounces"].active and drawn["preset"].active
    assert any("Final preset" in text for text in labels(log))
    fg = props(draw(panels.LANTERNA_RENDER_PT_final_gather, ctx))
    assert not fg["gather_m"].active and not fg["gather_n"].active
    cache = props(draw(panels.LANTERNA_RENDER_PT_irradiance_cache, ctx))
    assert not cache["cache_error"].active and cache["cache_gradients"].active
    # Photon Map indirect: the final gather and the cache are unused, hence greyed.
    scene.lanterna.preset = 'CUSTOM'
    scene.lanterna.indirect = 'PHOTON_MAP'
    assert not props(draw(panels.LANTERNA_RENDER_PT_final_gather, ctx))["gather_m"].active
    assert not props(draw(panels.LANTERNA_RENDER_PT_irradiance_cache, ctx))["cache_error"].active
    scene.lanterna.indirect = 'CACHE'
    assert props(draw(panels.LANTERNA_RENDER_PT_irradiance_cache, ctx))["cache_error"].active


def test_last_render_panels_show_the_plan_and_the_timings(registered):
    scene, obj, mat, light, world, cam = build_scene()
    ctx = context_for(scene)
    render_engine.LAST_RENDER.clear()
    assert "No render yet" in labels(draw(panels.LANTERNA_RENDER_PT_last_render, ctx))
    draw(panels.LANTERNA_RENDER_PT_last_render_plan, ctx)
    draw(panels.LANTERNA_RENDER_PT_last_render_timings, ctx)

    bpy.ops.render.render()
    report = render_engine.LAST_RENDER["report"]
    stages = report["plan"]["stages"]
    assert any(r.startswith("skipped") for r in stages.values())
    assert any(not r.startswith("skipped") for r in stages.values())
    log = draw(panels.LANTERNA_RENDER_PT_last_render_plan, ctx)
    shown = labels(log)
    text = " ".join(shown)
    for stage, reason in stages.items():
        title = panels.stage_title(stage)
        icon = [e.kwargs.get("icon") for e in log if e.text == title]
        skipped = reason.startswith("skipped")
        assert icon == ['X' if skipped else 'CHECKMARK'], stage
        assert (reason[len("skipped: "):] if skipped else reason) in text, stage
    assert shown.count("Skipped") == sum(r.startswith("skipped") for r in stages.values())
    assert shown.count("Runs") == sum(not r.startswith("skipped") for r in stages.values())

    shown = labels(draw(panels.LANTERNA_RENDER_PT_last_render_timings, ctx))
    for name, entry in report["stages"].items():
        i = shown.index(panels.stage_title(name))
        assert shown[i + 1] == f"{entry['seconds']:.3f} s", name
    assert "Export" in shown and "Total" in shown
    assert f"{render_engine.LAST_RENDER['total_time']:.3f} s" in shown
    assert "Done" in labels(draw(panels.LANTERNA_RENDER_PT_last_render, ctx))

    # A failed render: its one-line error, in red.
    render_engine.LAST_RENDER.clear()
    render_engine.LAST_RENDER.update(error="Scene has no camera", warnings=["W1", "W2"])
    log = draw(panels.LANTERNA_RENDER_PT_last_render, ctx)
    assert [e.alert for e in log if e.text == "Scene has no camera"] == [True]
    assert labels(draw(panels.LANTERNA_RENDER_PT_last_render_warnings, ctx)) == ["W1", "W2"]
    assert labels(draw(panels.LANTERNA_RENDER_PT_last_render_warnings, ctx, header=True)) == ["2"]
    render_engine.LAST_RENDER.clear()


# -- Material ---------------------------------------------------------------------------------
def test_rho_check_flags_exactly_the_channels_over_one():
    over = lambda d, s: [c for c, _total in panels.channel_sums_over_one(d, s)]  # noqa: E731
    assert over((0.8, 0.5, 0.2), (0.3, 0.5, 0.9)) == ["R", "B"]
    assert over((0.8, 0.8, 0.8), (0.2, 0.0, 0.1)) == []
    assert over((0.5, 0.5, 0.5), (0.5, 0.501, 0.4)) == ["G"]
    message = panels.energy_message((0.8, 0.5, 0.2), (0.3, 0.5, 0.9))
    assert "R (1.100)" in message and "B (1.100)" in message and "G (" not in message
    assert panels.energy_message((1.0, 0.0, 0.3), (0.0, 1.0, 0.7)) == ""


def test_radiometry_panel_alerts_on_the_channels_over_one(registered):
    scene, obj, mat, light, world, cam = build_scene()
    ctx = context_for(scene, material=mat)
    mat.lanterna.derive_from_nodes = False
    mat.lanterna.diffuse = (0.8, 0.5, 0.2)
    mat.lanterna.specular = (0.3, 0.5, 0.9)
    log = draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)
    assert {"derive_from_nodes", "diffuse", "specular", "exitance"} <= set(props(log))
    alerts = [e.text for e in log if e.kind == "label" and e.alert]
    assert alerts and all(e.kwargs.get("icon") in ('ERROR', 'BLANK1')
                          for e in log if e.kind == "label" and e.alert)
    alert = " ".join(alerts)
    assert "R (1.100)" in alert and "B (1.100)" in alert and "G (" not in alert
    mat.lanterna.specular = (0.2, 0.5, 0.8)              # sums 1.0, 1.0, 1.0: allowed
    log = draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)
    assert not [e for e in log if e.alert]


def test_radiometry_panel_shows_the_exporters_derived_values(registered):
    scene, obj, mat, light, world, cam = build_scene()
    ctx = context_for(scene, material=mat)
    bsdf = compat.ensure_node_tree(mat).nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.2, 0.4, 0.6, 1.0)
    bsdf.inputs["Metallic"].default_value = 0.5
    bsdf.inputs["Roughness"].default_value = 0.0
    bsdf.inputs["Emission Strength"].default_value = 2.0
    mat.lanterna.derive_from_nodes = True
    mat.lanterna.diffuse = (0.9, 0.9, 0.9)               # unused while derived
    log = draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)
    assert set(props(log)) == {"derive_from_nodes"}     # the derived values are read only
    shown = labels(log)
    lscene = export.export_scene(bpy.context.evaluated_depsgraph_get())
    core = next(m for m in lscene.materials if m.name == "Floor")
    np.testing.assert_allclose(core.diffuse, [0.1, 0.2, 0.3])
    np.testing.assert_allclose(core.specular, [0.1, 0.2, 0.3])
    for values in (core.diffuse, core.specular, core.exitance):
        assert panels._rgb_text(values) in shown
    assert "0.100  0.200  0.300" in shown and "6.283  6.283  6.283" in shown

    # What the derivation approximates is shown with the values.
    # A node the evaluator lacks is named; a supported texture on Base Color is followed per
    # hit (no note), by the diffuse, the metal and the transmission's tint alike.
    tex = mat.node_tree.nodes.new("ShaderNodeTexBrick")
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    text = " ".join(labels(draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)))
    assert "Brick" in text and "Base Color" in text
    tex = mat.node_tree.nodes.new("ShaderNodeTexChecker")
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    text = " ".join(labels(draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)))
    assert "driven by nodes" not in text
    bsdf.inputs["Transmission Weight"].default_value = 0.5
    text = " ".join(labels(draw(panels.LANTERNA_MATERIAL_PT_radiometry, ctx)))
    assert "driven by nodes" not in text


# -- Light ------------------------------------------------------------------------------------
def test_light_panel_switches(registered):
    scene, obj, mat, light, world, cam = build_scene('AREA')
    ctx = context_for(scene, light=light)
    drawn = props(draw(panels.LANTERNA_LIGHT_PT_photons, ctx))
    assert set(drawn) == {"photon_share", "shadow_photons"}
    assert drawn["shadow_photons"].active and drawn["shadow_photons"].data == light.lanterna
    # Listed, with its switch, in the render panel.
    listed = [e for e in draw(panels.LANTERNA_RENDER_PT_shadow_photons, ctx) if e.prop]
    assert [(e.data, e.text) for e in listed] == [(light.lanterna, "Lamp")]
    scene.lanterna.shadow_photons = False                # off for the whole scene
    drawn = props(draw(panels.LANTERNA_LIGHT_PT_photons, ctx))
    assert not drawn["shadow_photons"].active
    scene.lanterna.shadow_photons = True
    light.type = 'POINT'                                 # points need no shadow photons
    light = bpy.data.lights[light.name]
    ctx.light = light
    log = draw(panels.LANTERNA_LIGHT_PT_photons, ctx)
    assert not props(log)["shadow_photons"].active
    assert any("one ray" in text for text in labels(log))
    assert not [e for e in draw(panels.LANTERNA_RENDER_PT_shadow_photons, ctx) if e.prop]
    # Blender's own light panel is not opened: ours draws the same.
    assert ENGINE not in bpy.types.DATA_PT_light.COMPAT_ENGINES


# -- Export -----------------------------------------------------------------------------------
def test_light_shadow_photon_switch_reaches_the_core(registered):
    scene, obj, mat, light, world, cam = build_scene('AREA')
    assert light.lanterna.shadow_photons is True
    point = bpy.data.objects.new("Bulb", bpy.data.lights.new("Bulb", 'POINT'))
    point.data.energy = 10.0
    point.data.lanterna.shadow_photons = False           # meaningless for a point: ignored
    scene.collection.objects.link(point)

    def exported():
        return {l.name: l for l in export.export_scene(bpy.context.evaluated_depsgraph_get(),
                                                       resolution=(8, 6)).lights}

    lights = exported()
    assert isinstance(lights["Lamp"], AreaLight) and lights["Lamp"].shadow_photons is True
    assert isinstance(lights["Bulb"], PointLight) and not hasattr(lights["Bulb"], "shadow_photons")
    light.lanterna.shadow_photons = False    # tags the light: the evaluated copy follows
    lscene = export.export_scene(bpy.context.evaluated_depsgraph_get(), resolution=(8, 6))
    area = next(l for l in lscene.lights if l.name == "Lamp")
    assert area.shadow_photons is False
    assert [e.shadow_photons for e in LightSet(lscene).sampled if e.name == "Lamp"] == [False]


def test_scene_settings_reach_the_core(registered):
    scene = reset()
    s = scene.lanterna
    assert s.cache_gradients is True and export.export_settings(scene).cache_gradients is True
    s.cache_gradients = False
    assert export.export_settings(scene).cache_gradients is False
    # The cache's header switch is the Indirect method.
    assert s.indirect == 'CACHE' and s.use_irradiance_cache
    s.use_irradiance_cache = False
    assert s.indirect == 'GATHER' and export.export_settings(scene).indirect == "gather"
    s.use_irradiance_cache = True
    assert s.indirect == 'CACHE' and export.export_settings(scene).indirect == "cache"
    s.indirect = 'PHOTON_MAP'
    assert not s.use_irradiance_cache
    s.use_irradiance_cache = False                     # already off: the method stays
    assert s.indirect == 'PHOTON_MAP'
    s.shadow_photons = False
    assert export.export_settings(scene).shadow_photons is False
    for group, names in ((s, ("cache_gradients", "use_irradiance_cache")),
                         (bpy.data.lights.new("L", 'AREA').lanterna, ("shadow_photons",))):
        for name in names:
            assert group.bl_rna.properties[name].description, name
