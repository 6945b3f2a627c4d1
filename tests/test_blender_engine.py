"""The Blender side: registration, properties, panels and the RenderEngine (F12) end to end.

Scenes are built in code from factory settings. Render Results are read back through
``Image.save_render`` to a float32 EXR (Blender writes scene-linear values to EXR, no view
transform), which is how a user would save them.
"""
import math
import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from lanterna.engine import imageio, pipeline  # noqa: E402
from lanterna.engine.blender import compat, export, registration, render_engine  # noqa: E402
from lanterna.engine.scene import SceneError  # noqa: E402

ENGINE = "LANTERNA"


# -- Helpers ----------------------------------------------------------------------------------
def engine_available() -> bool:
    scene = bpy.context.scene
    old = scene.render.engine
    try:
        scene.render.engine = ENGINE
    except TypeError:
        return False
    scene.render.engine = old
    return True


def panels_with_lanterna() -> list[str]:
    """Registered panels that show for Lanterna (our own and Blender's opened ones)."""
    return sorted(p.__name__ for p in bpy.types.Panel.__subclasses__()
                  if getattr(p, "is_registered", False)
                  and ENGINE in (getattr(p, "COMPAT_ENGINES", None) or ()))


@pytest.fixture
def registered():
    """Lanterna registered for the test; the previous state restored afterwards."""
    was = registration.is_registered()
    registration.register()
    yield
    if not was:
        registration.unregister()


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    from lanterna.engine.blender import session
    session.clear()                     # no maps kept from an earlier test's render
    return bpy.context.scene


def quad(scene, name, corners, color=(0.8, 0.8, 0.8)):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(c) for c in corners], [], [(0, 1, 2, 3)])
    mat = bpy.data.materials.new(name)
    bsdf = compat.ensure_node_tree(mat).nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    mesh.materials.append(mat)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def upper_wall_scene(width=32, height=24, samples=4, seed=3):
    """Camera at the origin looking along +Y; a lit wall at y = 4 that fills only the TOP half
    of the frame (z from 0 to 3); black world, so the bottom half is exactly black."""
    scene = reset()
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    cam.data.lens = 30.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    quad(scene, "Wall", [(-6, 4, 0), (6, 4, 0), (6, 4, 3), (-6, 4, 3)])
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", 'POINT'))
    light.data.energy = 100.0
    light.data.shadow_soft_size = 0.0
    light.location = (0.5, 1.0, 1.0)
    scene.collection.objects.link(light)
    world = bpy.data.worlds.new("Black")
    for node in compat.ensure_node_tree(world).nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    scene.render.engine = ENGINE
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.lanterna.samples = samples
    scene.lanterna.seed = seed
    settings = scene.render.image_settings
    settings.file_format = 'OPEN_EXR'
    settings.color_depth = '32'
    settings.color_mode = 'RGBA'
    return scene


def render_f12(tmp_path, name="result.exr") -> dict:
    """bpy.ops.render.render(), then the Render Result saved as EXR and read back."""
    bpy.ops.render.render()
    path = tmp_path / name
    bpy.data.images["Render Result"].save_render(str(path))
    return imageio.read_exr(path)


def rgb(channels):
    return np.stack([channels[c] for c in "RGB"], axis=-1)


def pipeline_image(scene, resolution, border=None):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lscene = export.export_scene(depsgraph, resolution=resolution, border=border)
    return pipeline.render(lscene, export.export_settings(scene)).image


# -- Registration -----------------------------------------------------------------------------
def test_unregister_leaves_nothing_registered():
    was = registration.is_registered()
    registration.unregister()
    try:
        for owner in (bpy.types.Scene, bpy.types.Material, bpy.types.Light):
            assert not hasattr(owner, "lanterna")
        assert not engine_available()
        assert not hasattr(bpy.types, "LANTERNA_RENDER_PT_sampling")
        assert not hasattr(bpy.types, "LANTERNA_MATERIAL_PT_radiometry")
        assert panels_with_lanterna() == []

        registration.register()
        registration.register()  # twice is harmless
        for owner in (bpy.types.Scene, bpy.types.Material, bpy.types.Light):
            assert hasattr(owner, "lanterna")
        assert engine_available()
        assert hasattr(bpy.types, "LANTERNA_RENDER_PT_sampling")
        opened = panels_with_lanterna()
        for name in ("RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_color_management",
                     "DATA_PT_camera", "DATA_PT_lens", "DATA_PT_context_light",
                     "WORLD_PT_context_world", "EEVEE_MATERIAL_PT_context_material"):
            assert name in opened
        foreign = ("CYCLES_", "EEVEE_WORLD", "RENDER_PT_eevee")
        assert not [n for n in opened if n.startswith(foreign)]
        assert "DATA_PT_light" not in opened  # replaced by LANTERNA_LIGHT_PT_light

        registration.unregister()
        registration.unregister()  # twice is harmless
        assert not hasattr(bpy.types.Scene, "lanterna")
        assert not engine_available()
        assert panels_with_lanterna() == []
    finally:
        if was:
            registration.register()


def test_properties_defaults_limits_and_descriptions(registered):
    scene = reset()
    s = scene.lanterna
    assert (s.samples, s.light_samples, s.bounces, s.seed, s.threads) == (16, 4, 128, 0, 0)
    assert (s.mode, s.photons, s.photon_k, s.photon_radius, s.photon_filter, s.photon_lookups) \
        == ('FULL', 0, 50, 0.0, 'NONE', 0)
    mat = bpy.data.materials.new("M")
    assert mat.lanterna.derive_from_nodes is True
    assert tuple(mat.lanterna.diffuse) == pytest.approx((0.8, 0.8, 0.8))
    assert tuple(mat.lanterna.specular) == (0.0, 0.0, 0.0)
    assert tuple(mat.lanterna.exitance) == (0.0, 0.0, 0.0)
    light = bpy.data.lights.new("L", 'POINT')
    assert light.lanterna.photon_share == 1.0

    # Hard limits clamp assignments.
    s.samples = 0
    assert s.samples == 1
    s.bounces = 1000
    assert s.bounces == 255
    s.photon_k = 0
    assert s.photon_k == 1
    mat.lanterna.diffuse = (2.0, -1.0, 0.5)
    assert tuple(mat.lanterna.diffuse) == pytest.approx((1.0, 0.0, 0.5))
    mat.lanterna.exitance = (500.0, -1.0, 0.0)
    assert tuple(mat.lanterna.exitance) == pytest.approx((500.0, 0.0, 0.0))
    assert mat.lanterna.bl_rna.properties["diffuse"].subtype == 'COLOR'

    for group in (s, mat.lanterna, light.lanterna):
        for prop in group.bl_rna.properties:
            if prop.identifier in ("rna_type", "name"):
                continue
            assert prop.description, f"{group.bl_rna.identifier}.{prop.identifier}"


def test_panels_poll_only_for_lanterna(registered):
    from lanterna.ui import panels

    scene = reset()
    mat = bpy.data.materials.new("M")
    light = bpy.data.lights.new("L", 'POINT')
    world = bpy.data.worlds.new("W")
    cam = bpy.data.cameras.new("C")
    cam.type = 'PANO'                      # the Panorama panel's data
    for panel in panels.classes:
        assert panel.COMPAT_ENGINES == {ENGINE}
        for engine, expected in ((ENGINE, True), ("CYCLES", False), ("BLENDER_EEVEE", False),
                                 ("BLENDER_WORKBENCH", False)):
            ctx = types.SimpleNamespace(engine=engine, scene=scene, material=mat, light=light,
                                        world=world, object=None, camera=cam)
            assert bool(panel.poll(ctx)) is expected, (panel.__name__, engine)
    # Context panels also need their data.
    none = types.SimpleNamespace(engine=ENGINE, scene=scene, material=None, light=None,
                                 world=None, object=None)
    assert not panels.LANTERNA_MATERIAL_PT_radiometry.poll(none)
    assert not panels.LANTERNA_LIGHT_PT_light.poll(none)
    assert not panels.LANTERNA_WORLD_PT_surface.poll(none)
    assert panels.LANTERNA_RENDER_PT_sampling.poll(none)
    # A built-in panel opened to Lanterna polls for it, a Cycles one does not.
    cam_ctx = types.SimpleNamespace(engine=ENGINE, camera=cam)
    assert bpy.types.DATA_PT_lens.poll(cam_ctx)
    assert not bpy.types.DATA_PT_lens.poll(types.SimpleNamespace(engine="NOPE", camera=cam))


def test_energy_warning_channels():
    from lanterna.ui.panels import energy_message

    assert energy_message((0.8, 0.5, 0.2), (0.3, 0.5, 0.9)) == (
        "ρd + ρs > 1 in R (1.100), B (1.100): creates energy; the render scales it down")
    assert energy_message((0.8, 0.8, 0.8), (0.2, 0.0, 0.1)) == ""


# -- Rendering --------------------------------------------------------------------------------
def test_f12_equals_pipeline_and_is_upright(registered, tmp_path, capfd):
    scene = upper_wall_scene()
    channels = render_f12(tmp_path)
    out = capfd.readouterr()
    assert "Python script error" not in out.err + out.out
    image = rgb(channels)
    assert image.shape == (24, 32, 3)
    assert np.all(channels["A"] == 1.0)
    assert render_engine.LAST_RENDER["error"] is None
    assert "camera" in render_engine.LAST_RENDER["report"]["stages"]
    plan = render_engine.LAST_RENDER["report"]["plan"]
    assert plan["stages"]["shadow_photons"].startswith("skipped: no area light")   # a point light
    assert plan["summary"].startswith("Plan: direct, photons")

    expected = pipeline_image(scene, (32, 24))
    assert expected.shape == image.shape
    np.testing.assert_allclose(image, expected, rtol=1e-5, atol=1e-7)
    # The wall is in the upper half of the frame: bright at the top, black at the bottom.
    luminance = image.mean(axis=2)
    assert luminance[:9].min() > 1e-3, "top rows should see the lit wall"
    assert luminance[15:].max() == 0.0, "bottom rows look into the black world"


def test_resolution_percentage_is_applied(registered, tmp_path):
    scene = upper_wall_scene(width=64, height=48)
    scene.render.resolution_percentage = 50
    image = rgb(render_f12(tmp_path))
    assert image.shape == (24, 32, 3)
    np.testing.assert_allclose(image, pipeline_image(scene, (32, 24)), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("crop", [True, False])
def test_border_render(registered, tmp_path, crop):
    scene = upper_wall_scene()
    full = pipeline_image(scene, (32, 24))
    render = scene.render
    render.use_border = True
    render.use_crop_to_border = crop
    render.border_min_x, render.border_max_x = 0.25, 0.75   # pixels 8..24
    render.border_min_y, render.border_max_y = 0.5, 1.0     # pixels 12..24 from the bottom
    channels = render_f12(tmp_path)
    window = pipeline_image(scene, (32, 24), border=(8, 12, 24, 24))
    assert window.shape == (12, 16, 3)
    assert render_engine.LAST_RENDER["border"] == (8, 12, 24, 24)
    image = rgb(channels)
    if crop:
        assert image.shape == (12, 16, 3)
        inside = image
    else:
        # Blender pastes the window into the full frame; the rest stays transparent.
        assert image.shape == (24, 32, 3)
        alpha = channels["A"]
        assert np.all(alpha[:12, 8:24] == 1.0)
        outside = np.ones_like(alpha, bool)
        outside[:12, 8:24] = False
        assert np.all(alpha[outside] == 0.0)
        inside = image[:12, 8:24]
    np.testing.assert_allclose(inside, window, rtol=1e-5, atol=1e-7)
    # The window is the top middle of the frame (row 0 = top): same picture as the full
    # render up to sampling noise.
    crop_of_full = full[:12, 8:24]
    assert inside.mean() > 1e-3
    assert inside.mean() == pytest.approx(crop_of_full.mean(), rel=0.05)


def test_border_with_uneven_fractions(registered, tmp_path):
    """Border edges that fall inside pixels: the window is truncated as Blender does it and
    the EXR Blender saves has exactly the window's size."""
    scene = upper_wall_scene(width=33, height=25)
    render = scene.render
    render.use_border = render.use_crop_to_border = True
    render.border_min_x, render.border_max_x = 0.3, 0.71
    render.border_min_y, render.border_max_y = 0.45, 0.93
    image = rgb(render_f12(tmp_path))
    x0, y0, x1, y1 = render_engine.LAST_RENDER["border"]
    assert (x0, y0) == (int(np.float32(0.3) * np.float32(33)), int(np.float32(0.45) * 25))
    assert image.shape == (y1 - y0, x1 - x0, 3)
    assert (x1 - x0, y1 - y0) == (23 - 9, 23 - 11)  # int(9.9), int(23.43); int(11.25), int(23.25)
    window = pipeline_image(scene, (33, 25), border=(x0, y0, x1, y1))
    np.testing.assert_allclose(image, window, rtol=1e-5, atol=1e-7)


def test_warnings_are_reported_once(registered, tmp_path, capfd):
    scene = upper_wall_scene()
    data = scene.objects["Light"].data
    if not hasattr(data, "normalize"):
        pytest.skip("Light.normalize is Blender 4.3+")
    data.normalize = False                              # exporter: Normalize off unsupported
    render_f12(tmp_path)
    out = capfd.readouterr()
    warnings = render_engine.LAST_RENDER["warnings"]
    assert len([w for w in warnings if "Normalize off" in w]) == 1
    assert (out.out + out.err).count("Normalize off is not supported") == 1


def test_scene_error_ends_in_a_message_not_a_traceback(registered, tmp_path, capfd):
    scene = upper_wall_scene()
    empty = bpy.data.objects.new("Not A Camera", None)
    scene.collection.objects.link(empty)
    scene.camera = empty
    with pytest.raises(RuntimeError) as info:
        bpy.ops.render.render()
    out = capfd.readouterr()
    message = "Active camera 'Not A Camera' is an empty object, not a camera"
    assert render_engine.LAST_RENDER["error"] == message
    lines = [line for line in str(info.value).splitlines() if line]
    assert lines and all(line == f"Error: {message}" for line in lines)
    assert "Traceback" not in out.err + out.out
    assert "Python script error" not in out.err + out.out


def test_unexpected_error_is_caught_and_logged(registered, tmp_path, capfd, monkeypatch):
    upper_wall_scene()

    def broken(*args, **kwargs):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(export, "export_scene", broken)
    with pytest.raises(RuntimeError) as info:
        bpy.ops.render.render()
    out = capfd.readouterr()
    expected = "Lanterna internal error: ZeroDivisionError: boom"
    assert render_engine.LAST_RENDER["error"] == expected
    assert expected in str(info.value)
    assert "Python script error" not in out.err + out.out   # nothing escaped to Blender
    assert "lanterna: render failed:" in out.err             # the traceback is logged
    assert "ZeroDivisionError: boom" in out.err


def test_scene_error_from_export_is_reported(registered, capfd, monkeypatch):
    upper_wall_scene()

    def rejects(*args, **kwargs):
        raise SceneError("Object 'Wall': 3 triangles have\nNaN vertices")

    monkeypatch.setattr(export, "export_scene", rejects)
    with pytest.raises(RuntimeError) as info:
        bpy.ops.render.render()
    out = capfd.readouterr()
    assert render_engine.LAST_RENDER["error"] == "Object 'Wall': 3 triangles have NaN vertices"
    assert "NaN vertices" in str(info.value)
    assert "Traceback" not in out.err + out.out


@pytest.mark.parametrize("bounces", [0, 64])
def test_progress_and_cancel_are_wired(registered, tmp_path, monkeypatch, bounces):
    """The engine passes update_progress and test_break to the pipeline; a cancelled render
    keeps the pixels it has and is no error. (RNA methods such as test_break cannot be
    monkeypatched on the class, so the pipeline is wrapped instead.) With bounces = 0 the
    cancel lands in the camera stage after the first batch (its pixels are kept); with
    bounces the photon stage stops after its first chunk and no camera batch runs."""
    upper_wall_scene().lanterna.bounces = bounces
    real_render = pipeline.render
    seen = {}

    def wrapped(scene, settings, progress=None, cancelled=None, **kwargs):
        seen["test_break"] = cancelled()          # Blender's answer: nobody pressed Esc
        progress(0.5, "halfway")                  # must not raise
        return real_render(scene, settings, progress=progress, cancelled=lambda: True, **kwargs)

    monkeypatch.setattr(pipeline, "render", wrapped)
    image = rgb(render_f12(tmp_path))
    assert seen["test_break"] is False
    assert render_engine.LAST_RENDER["error"] is None
    assert render_engine.LAST_RENDER["cancelled"] is True
    assert image.shape == (24, 32, 3)
    if bounces == 0:
        assert image[:9].mean() > 1e-3
    else:
        report = render_engine.LAST_RENDER["report"]
        assert report["stages"]["photons"]["emitted"] < report["stages"]["photons"]["requested"]
        assert report["stages"]["camera"]["batches_done"] == 0 and image.max() == 0.0


def test_light_photon_share_is_exported(registered):
    scene = upper_wall_scene()
    light = scene.objects["Light"].data
    assert light.lanterna.photon_share == 1.0
    light.lanterna.photon_share = 2.5
    lscene = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert [(l.name, l.photon_share) for l in lscene.lights] == [("Light", 2.5)]


def test_passes_reach_the_render_result(registered, tmp_path):
    """Ticked passes are registered for the view layer and filled: a multilayer EXR of the
    Render Result holds them, and Combined = Direct + Indirect + Emission."""
    scene = upper_wall_scene()
    layer = bpy.context.view_layer
    for prop in ("direct", "indirect", "emission", "cache_points"):
        setattr(layer.lanterna_passes, prop, True)
    fmt = scene.render.image_settings
    if hasattr(fmt, "media_type"):                   # Blender 5.0: multilayer is a media type
        fmt.media_type = 'MULTI_LAYER_IMAGE'
    fmt.file_format = 'OPEN_EXR_MULTILAYER'
    scene.render.filepath = str(tmp_path / "passes.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)          # as a user's F12 + save or a batch render
    channels = imageio.read_exr(tmp_path / "passes.exr")
    name = layer.name
    for pass_name in ("Direct", "Indirect", "Emission", "CachePoints"):
        for c in "RGB":
            assert f"{name}.{pass_name}.{c}" in channels, sorted(channels)
    combined = np.stack([channels[f"{name}.Combined.{c}"] for c in "RGB"], axis=-1)
    parts = sum(np.stack([channels[f"{name}.{p}.{c}"] for c in "RGB"], axis=-1)
                for p in ("Direct", "Indirect", "Emission"))
    np.testing.assert_allclose(parts, combined, rtol=0, atol=1e-4)
    direct = channels[f"{name}.Direct.R"]
    assert direct[:9].min() > 1e-3 and direct[15:].max() == 0.0      # upright, like Combined
    assert set(np.unique(channels[f"{name}.CachePoints.R"])) <= {0.0, 1.0}
    layer.lanterna_passes.cache_points = False
    assert render_engine.LAST_RENDER["report"]["passes"] == [
        "Direct", "Indirect", "Emission", "CachePoints"]


def test_cycles_light_passes_reach_the_render_result(registered, tmp_path):
    """Blender's own view-layer flags (use_pass_diffuse_direct ... use_pass_environment) make
    Cycles' light passes under Cycles' names, and they sum to Combined."""
    from lanterna.engine.passes import LIGHT_PASS_NAMES
    from lanterna.ui.render_passes import LIGHT_PASS_FLAGS
    scene = upper_wall_scene(samples=2)
    layer = bpy.context.view_layer
    for flag in LIGHT_PASS_FLAGS.values():
        setattr(layer, flag, True)
    fmt = scene.render.image_settings
    if hasattr(fmt, "media_type"):
        fmt.media_type = 'MULTI_LAYER_IMAGE'
    fmt.file_format = 'OPEN_EXR_MULTILAYER'
    scene.render.filepath = str(tmp_path / "light.exr")
    scene.render.use_file_extension = False
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        for flag in LIGHT_PASS_FLAGS.values():
            setattr(layer, flag, False)
    channels = imageio.read_exr(tmp_path / "light.exr")
    name = layer.name

    def image(pass_name):
        return np.stack([channels[f"{name}.{pass_name}.{c}"] for c in "RGB"], axis=-1)

    for pass_name in LIGHT_PASS_NAMES:
        for c in "RGB":
            assert f"{name}.{pass_name}.{c}" in channels, sorted(channels)
    total = image("Emit") + image("Env")
    for kind in ("Diff", "Gloss", "Trans"):
        total = total + (image(kind + "Dir") + image(kind + "Ind")) * image(kind + "Col")
    np.testing.assert_allclose(total, image("Combined"), rtol=1e-4, atol=1e-4)
    assert image("DiffDir").max() > 0 and image("DiffCol").max() > 0
    assert render_engine.LAST_RENDER["report"]["passes"] == list(LIGHT_PASS_NAMES)


def test_f12_reuses_kept_maps_only_for_the_same_scene(registered, tmp_path):
    """A second F12 with only the samples changed reuses the first render's maps (same
    fingerprint) and equals a fresh render; moving the light builds them afresh."""
    scene = upper_wall_scene(samples=2)
    scene.lanterna.photons = 20_000
    render_f12(tmp_path, "first.exr")
    assert render_engine.LAST_RENDER["maps_reused"] is False
    scene.lanterna.samples = 4
    second = rgb(render_f12(tmp_path, "second.exr"))
    assert render_engine.LAST_RENDER["maps_reused"] is True
    assert render_engine.LAST_RENDER["report"]["stages"]["photons"]["reused"] is True
    from lanterna.engine.blender import session
    session.clear()
    fresh = rgb(render_f12(tmp_path, "fresh.exr"))
    assert render_engine.LAST_RENDER["maps_reused"] is False
    np.testing.assert_array_equal(second, fresh)
    bpy.data.objects["Light"].location.x += 0.3
    render_f12(tmp_path, "moved.exr")
    assert render_engine.LAST_RENDER["maps_reused"] is False
