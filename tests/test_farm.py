"""Batch and farm rendering through the bpy module: what ``blender -b file.blend -E LANTERNA -a``
(every frame), ``-f N`` (one frame) and a render farm's tile split of a still do.

``bpy.ops.render.render(animation=True)`` is the job ``-a`` runs: frames one after another, each
written to ``render.filepath`` with its number. Maps (photon map, shadow photons, irradiance
cache) kept from the previous frame are reused when their fingerprint matches the frame's scene
and map settings, and built afresh otherwise, so a static scene traces its photons once per
process and an animated one every frame; the picture is the same either way.
"""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from lanterna.engine import imageio  # noqa: E402
from lanterna.engine.blender import compat, registration, render_engine, session  # noqa: E402

ENGINE = "LANTERNA"


@pytest.fixture
def registered():
    was = registration.is_registered()
    registration.register()
    yield
    if not was:
        registration.unregister()


def quad(scene, name, corners, color):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(c) for c in corners], [], [(0, 1, 2, 3)])
    mat = bpy.data.materials.new(name)
    bsdf = compat.ensure_node_tree(mat).nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    mesh.materials.append(mat)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)


def room(tmp_path, moving_light: bool):
    """A floor and a back wall seen from the front, a point light; frames 1-2. With
    ``moving_light`` the light is keyframed from the left (frame 1) to the right (frame 2)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    session.clear()
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -6.0, 1.5)
    cam.rotation_euler = (1.45, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    quad(scene, "Floor", [(-4, -3, 0), (4, -3, 0), (4, 3, 0), (-4, 3, 0)], (0.2, 0.6, 0.2))
    quad(scene, "Wall", [(-4, 3, 0), (4, 3, 0), (4, 3, 4), (-4, 3, 4)], (0.8, 0.8, 0.8))
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", 'POINT'))
    light.data.energy = 300.0
    light.data.shadow_soft_size = 0.0
    scene.collection.objects.link(light)
    light.location = (-2.0, 1.0, 2.0)
    if moving_light:
        light.keyframe_insert("location", frame=1)
        light.location = (2.0, 1.0, 2.0)
        light.keyframe_insert("location", frame=2)
    world = bpy.data.worlds.new("Black")
    for node in compat.ensure_node_tree(world).nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    render = scene.render
    render.engine = ENGINE
    render.resolution_x, render.resolution_y, render.resolution_percentage = 32, 24, 100
    scene.lanterna.samples = 2
    scene.lanterna.photons = 20_000
    scene.lanterna.seed = 3
    scene.frame_start, scene.frame_end = 1, 2
    scene.frame_set(1)
    settings = render.image_settings
    settings.file_format, settings.color_depth, settings.color_mode = 'OPEN_EXR', '32', 'RGB'
    render.filepath = str(tmp_path / "frame_")
    render.use_file_extension = True
    return scene


def render_animation(scene) -> list[tuple]:
    """``blender -b file.blend -E LANTERNA -a``: (frame, maps reused, error) per frame."""
    seen = []

    def after_frame(rendered_scene, *_args):
        last = render_engine.LAST_RENDER
        seen.append((rendered_scene.frame_current, last.get("maps_reused"), last.get("error")))

    bpy.app.handlers.render_post.append(after_frame)
    try:
        bpy.ops.render.render(animation=True)
    finally:
        bpy.app.handlers.render_post.remove(after_frame)
    return seen


def render_frame(scene, frame: int, path) -> np.ndarray:
    """``blender -b file.blend -E LANTERNA -f N``, in a fresh process (no maps kept)."""
    session.clear()
    scene.frame_set(frame)
    old = scene.render.filepath
    scene.render.filepath = str(path)
    scene.render.use_file_extension = False
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        scene.render.filepath = old
        scene.render.use_file_extension = True
    return read(path)


def read(path) -> np.ndarray:
    channels = imageio.read_exr(path)
    return np.stack([channels[c] for c in "RGB"], axis=-1)


def frames(tmp_path) -> list[str]:
    return sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("frame_"))


def test_animation_rebuilds_the_maps_of_each_changed_frame(registered, tmp_path):
    scene = room(tmp_path, moving_light=True)
    seen = render_animation(scene)
    assert seen == [(1, False, None), (2, False, None)]       # the light moved: built afresh
    assert frames(tmp_path) == ["frame_0001.exr", "frame_0002.exr"]
    first, second = read(tmp_path / "frame_0001.exr"), read(tmp_path / "frame_0002.exr")
    assert first.shape == second.shape == (24, 32, 3)
    assert first.mean() > 1e-3 and second.mean() > 1e-3
    # The light went from left to right: the left half darkens, the right half brightens.
    assert first[:, :16].mean() > 1.5 * second[:, :16].mean()
    assert second[:, 16:].mean() > 1.5 * first[:, 16:].mean()
    # Each frame is the picture `-f N` gives on its own (a farm task of one frame).
    np.testing.assert_array_equal(render_frame(scene, 2, tmp_path / "f2.exr"), second)
    np.testing.assert_array_equal(render_frame(scene, 1, tmp_path / "f1.exr"), first)


def test_static_animation_traces_its_maps_once(registered, tmp_path):
    scene = room(tmp_path, moving_light=False)
    seen = render_animation(scene)
    assert seen == [(1, False, None), (2, True, None)]        # frame 2 reuses frame 1's maps
    first, second = read(tmp_path / "frame_0001.exr"), read(tmp_path / "frame_0002.exr")
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(render_frame(scene, 2, tmp_path / "f2.exr"), second)
    # Changing a map setting between frames (here by hand, as an animated setting would)
    # builds the maps afresh.
    scene.lanterna.photons = 25_000
    seen = render_animation(scene)
    assert seen == [(1, False, None), (2, True, None)]


_WORKER = textwrap.dedent("""
    import sys
    import bpy
    from lanterna.engine.blender import compat, registration
    registration.register()                         # the add-on enabled on the worker
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1])  # blender -b file.blend
    scene = bpy.context.scene
    scene.render.engine = "LANTERNA"                # -E LANTERNA
    scene.lanterna.threads = 1                      # a worker with another core count
    scene.render.filepath = sys.argv[2]
    bpy.ops.render.render(animation=True)           # -a
    compat.exit_process(0)
""")


def test_a_worker_process_renders_the_same_frames(registered, tmp_path):
    """A saved .blend rendered by another process with one thread (a farm worker running
    ``blender -b file.blend -E LANTERNA -a``) gives exactly the frames rendered here."""
    scene = room(tmp_path, moving_light=True)
    render_animation(scene)
    blend = tmp_path / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    worker = tmp_path / "worker"
    worker.mkdir()
    proc = subprocess.run([sys.executable, "-c", _WORKER, str(blend), str(worker / "frame_")],
                          capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert frames(worker) == ["frame_0001.exr", "frame_0002.exr"]
    for name in frames(worker):
        np.testing.assert_array_equal(read(worker / name), read(tmp_path / name))


def test_border_render_window_is_the_region_of_the_full_frame(registered, tmp_path):
    """What a tile render gives today: a border render is the region of the frame (size,
    place, upright) with the same light, up to sampling noise."""
    scene = room(tmp_path, moving_light=False)
    full = render_frame(scene, 1, tmp_path / "full.exr")
    render = scene.render
    render.use_border = render.use_crop_to_border = True
    render.border_min_x, render.border_max_x = 0.5, 1.0      # the right half ...
    render.border_min_y, render.border_max_y = 0.5, 1.0      # ... of the top half
    tile = render_frame(scene, 1, tmp_path / "tile.exr")
    assert tile.shape == (12, 16, 3)
    assert tile.mean() == pytest.approx(full[:12, 16:].mean(), rel=0.05)


def test_tiles_reassemble_the_full_frame_pixel_for_pixel(registered, tmp_path):
    """A farm splitting a still into 2 x 2 border renders gets exactly the full render back:
    the camera works in blocks of the full frame with their own random streams, automatic
    counts follow the full frame and the irradiance cache is placed over the full frame."""
    scene = room(tmp_path, moving_light=False)
    full = render_frame(scene, 1, tmp_path / "full.exr")
    render = scene.render
    render.use_border = render.use_crop_to_border = True
    tiles = np.zeros_like(full)
    for i, (x0, x1) in enumerate(((0.0, 0.5), (0.5, 1.0))):
        for j, (y0, y1) in enumerate(((0.0, 0.5), (0.5, 1.0))):
            render.border_min_x, render.border_max_x = x0, x1
            render.border_min_y, render.border_max_y = y0, y1
            tile = render_frame(scene, 1, tmp_path / f"tile_{i}{j}.exr")
            rows = slice(24 - int(y1 * 24), 24 - int(y0 * 24))
            tiles[rows, int(x0 * 32):int(x1 * 32)] = tile
    np.testing.assert_array_equal(tiles, full)
