"""The ``lanterna`` command (engine/blender/cli.py) and the seed scenes it builds.

``main([...])`` is called in-process and returns the exit status. Bad input must give exactly
one stderr line ``lanterna: error: ...``, status 2, and leave no file behind.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from lanterna.engine import imageio, pipeline  # noqa: E402
from lanterna.engine.blender import cli, export, registration, seed_scenes  # noqa: E402


@pytest.fixture(autouse=True)
def _restore_registration():
    was = registration.is_registered()
    yield
    if not was:
        registration.unregister()


def run_error(capfd, argv):
    """Run ``main(argv)`` expecting a usage error; return the one stderr line."""
    capfd.readouterr()
    code = cli.main(argv)
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (argv, err)
    assert len(lines) == 1, (argv, err)
    assert lines[0].startswith("lanterna: error: "), lines[0]
    assert "Traceback" not in err
    return lines[0]


# -- Bad input --------------------------------------------------------------------------------
def test_bad_arguments_give_one_line_and_status_2(tmp_path, capfd):
    out = str(tmp_path / "out.exr")
    cases = {
        ("render", "-o", out, "--resolution", "0x5"): "width and height must be 1 to 65536",
        ("render", "-o", out, "--resolution", "640by480"): "WIDTHxHEIGHT",
        ("render", "-o", out, "--samples", "-1"): "--samples",
        ("render", "-o", out, "--samples", "many"): "expected an integer",
        ("render", "-o", out, "--light-samples", "0"): "--light-samples",
        ("render", "-o", out, "--bounces", "-2"): "--bounces",
        ("render", "-o", out, "--mode", "path"): "--mode",
        ("render", "-o", out, "--photon-radius", "nan"): "--photon-radius",
        ("render", "-o", out, "--photon-k", "0"): "--photon-k",
        ("render", "-o", out, "--seed", "-3"): "--seed",
        ("render",): "required",
        ("render", "-o", out, "--scene", "scene9"): "invalid choice",
        ("render", str(tmp_path / "a.blend"), "--scene", "scene1", "-o", out): "not both",
        ("scene", "scene3", "-o", str(tmp_path / "x.blend")): "invalid choice",
        ("frobnicate",): "invalid choice",
    }
    for argv, expected in cases.items():
        line = run_error(capfd, list(argv))
        assert expected in line, (argv, line)
    assert list(tmp_path.iterdir()) == []


def test_unwritable_outputs_are_refused_before_rendering(tmp_path, capfd):
    missing_dir = tmp_path / "no" / "such"
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    a_dir = tmp_path / "dir.exr"
    a_dir.mkdir()
    good = str(tmp_path / "good.exr")
    cases = [
        (["render", "-o", str(missing_dir / "out.exr")], "does not exist"),
        (["render", "-o", str(a_file / "out.exr")], "does not exist"),
        (["render", "-o", str(a_dir)], "is a directory"),
        (["render", "-o", str(tmp_path / "out.png")], "must end in .exr"),
        (["render", "-o", good, "--png", str(missing_dir / "a.png")], "does not exist"),
        (["render", "-o", good, "--report", str(missing_dir / "r.json")], "does not exist"),
        (["scene", "scene1", "-o", str(missing_dir / "s.blend")], "does not exist"),
    ]
    for argv, expected in cases:
        assert expected in run_error(capfd, argv)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.exr", "file.txt"]


def test_missing_and_corrupt_blend_files(tmp_path, capfd):
    out = str(tmp_path / "out.exr")
    assert "no such file" in run_error(capfd, ["render", str(tmp_path / "none.blend"), "-o", out])

    garbage = tmp_path / "garbage.blend"
    garbage.write_bytes(np.random.default_rng(1).integers(0, 256, 4096, np.uint8).tobytes())
    assert "not a .blend file" in run_error(capfd, ["render", str(garbage), "-o", out])

    truncated = tmp_path / "truncated.blend"  # right magic, nothing after it
    truncated.write_bytes(b"BLENDER-v500REND" + bytes(64))
    assert "cannot be opened" in run_error(capfd, ["render", str(truncated), "-o", out])
    assert not os.path.exists(out)


def test_scene_error_is_a_usage_error(tmp_path, capfd):
    """A .blend without a camera: the exporter's SceneError becomes one line, status 2."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mesh = bpy.data.meshes.new("Tri")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Tri", mesh))
    blend = tmp_path / "nocamera.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    out = tmp_path / "out.exr"
    line = run_error(capfd, ["render", str(blend), "-o", str(out)])
    assert "no active camera" in line
    assert not out.exists()


# -- Rendering --------------------------------------------------------------------------------
def test_tiny_render_writes_exr_png_and_report(tmp_path, capfd):
    exr, png, report = tmp_path / "r.exr", tmp_path / "r.png", tmp_path / "r.json"
    code = cli.main(["render", "--resolution", "32x24", "--samples", "2", "--seed", "5",
                     "--light-samples", "2", "-o", str(exr), "--png", str(png),
                     "--report", str(report), "--quiet"])
    assert code == 0, capfd.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.exr", "r.json", "r.png"]

    channels = imageio.read_exr(exr)
    assert sorted(channels) == ["B", "G", "R"]
    image = imageio.read_exr_rgb(exr)
    assert image.shape == (24, 32, 3) and image.dtype == np.float32
    assert np.isfinite(image).all()
    assert image.max() > 0.01, "the seed's Scene 1 is lit"

    from PIL import Image
    with Image.open(png) as p:
        assert p.size == (32, 24)
        assert np.array_equal(np.asarray(p.convert("RGB")),
                              np.round(imageio.linear_to_srgb(image) * 255).astype(np.uint8))

    data = json.loads(report.read_text())
    assert data["settings"]["samples"] == 2
    assert data["settings"]["seed"] == 5
    assert data["settings"]["light_samples"] == 2
    assert data["resolution"] == [32, 24]
    assert data["image_size"] == [32, 24]
    assert data["scene"] == "seed:scene1"
    assert "stages" in data["pipeline"]
    assert data["export"]["triangles"] >= 12
    assert isinstance(data["warnings"], list)
    assert data["peak_memory_mb"] > 10
    assert data["time"]["total_seconds"] >= data["time"]["render_seconds"] > 0

    # The file holds exactly what the pipeline renders for the same scene and settings.
    scene = seed_scenes.build_scene1()
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.lanterna.samples, scene.lanterna.seed, scene.lanterna.light_samples = 2, 5, 2
    lscene = export.export_scene(bpy.context.evaluated_depsgraph_get())
    expected = pipeline.render(lscene, export.export_settings(scene)).image
    np.testing.assert_allclose(image, expected, rtol=1e-6, atol=0)


def test_photon_flags_reach_the_pipeline(tmp_path, capfd):
    exr, report = tmp_path / "p.exr", tmp_path / "p.json"
    code = cli.main(["render", "--resolution", "32x24", "--samples", "2", "--mode", "photon-map",
                     "--photons", "20000", "--photon-k", "30", "--photon-radius", "0.5",
                     "--photon-filter", "cone", "--photon-lookups", "2", "--bounces", "5",
                     "-o", str(exr), "--report", str(report), "--quiet"])
    assert code == 0, capfd.readouterr().err
    data = json.loads(report.read_text())
    s = data["settings"]
    assert (s["mode"], s["photons"], s["photon_k"], s["photon_radius"], s["photon_filter"],
            s["photon_lookups"], s["bounces"]) == ("photon-map", 20000, 30, 0.5, "cone", 2, 5)
    photons = data["pipeline"]["stages"]["photons"]
    assert photons["emitted"] == 20000 and photons["kept"] == "all"
    assert photons["max_radius_m"] == 0.5 and photons["max_bounces"] == 5
    # Scene 1 is closed: every photon's flux is absorbed or dropped at the bounce limit.
    ended = np.add(photons["flux_absorbed"], photons["flux_capped"])
    np.testing.assert_allclose(ended, photons["flux_emitted"], rtol=0.05)
    assert data["pipeline"]["stages"]["camera"]["photon_queries"] == 32 * 24 * 2
    assert imageio.read_exr_rgb(exr).max() > 0.01


def test_preset_and_indirect_flags(tmp_path, capfd):
    exr, report = tmp_path / "q.exr", tmp_path / "q.json"
    code = cli.main(["render", "--resolution", "32x24", "--preset", "preview", "--gather", "3x7",
                     "--cache-error", "0.4", "--gather-guided", "2.5", "--no-shadow-photons",
                     "-o", str(exr),
                     "--report", str(report), "--quiet"])
    err = capfd.readouterr().err
    assert code == 0, err
    assert "the preview preset sets --gather, --cache-error; those flags are ignored" in err
    data = json.loads(report.read_text())
    s = data["settings"]                         # as rendered: the preset's values
    assert s["preset"] == "preview" and (s["gather_m"], s["gather_n"]) == (6, 24)
    assert s["cache_error"] == pytest.approx(0.3) and s["shadow_photons"] is False
    assert s["samples"] == 4 and s["gather_guided"] == 2.5      # not a preset value: kept
    stages = data["pipeline"]["stages"]
    assert "irradiance_cache" in stages and stages["irradiance_cache"]["records"] > 0
    # The preset's values are what rendered: 4 spp and a 6 x 24 gather (not --gather 3x7).
    assert stages["irradiance_cache"]["gather"] == "6x24"
    assert stages["camera"]["camera_rays"] == 32 * 24 * 4
    line = run_error(capfd, ["render", "-o", str(exr), "--gather", "0x8"])
    assert "--gather" in line


def test_render_a_saved_blend_with_border(tmp_path, capfd):
    blend = tmp_path / "s2.blend"
    assert cli.main(["scene", "scene2", "-o", str(blend)]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    render = bpy.context.scene.render
    render.use_border, render.use_crop_to_border = True, True
    render.border_min_x, render.border_max_x = 0.0, 0.5
    render.border_min_y, render.border_max_y = 0.0, 0.5
    bpy.ops.wm.save_mainfile()
    exr = tmp_path / "b.exr"
    assert cli.main(["render", str(blend), "--resolution", "40x30", "--samples", "1",
                     "-o", str(exr), "--quiet"]) == 0
    assert imageio.read_exr_rgb(exr).shape == (15, 20, 3)   # cropped: the region only

    bpy.ops.wm.open_mainfile(filepath=str(blend))  # the command reloaded the file: fresh data
    bpy.context.scene.render.use_crop_to_border = False
    bpy.ops.wm.save_mainfile()
    assert cli.main(["render", str(blend), "--resolution", "40x30", "--samples", "1",
                     "-o", str(exr), "--quiet"]) == 0
    full = imageio.read_exr_rgb(exr)
    assert full.shape == (30, 40, 3)                        # full frame, zeros outside
    assert full[:15].max() == 0.0 and full[:, 20:].max() == 0.0
    assert full[15:, :20].max() > 0.0


# -- Seed scenes ------------------------------------------------------------------------------
def test_scene_command_round_trips(tmp_path):
    blend = tmp_path / "scene1.blend"
    assert cli.main(["scene", "scene1", "-o", str(blend)]) == 0
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    names = {o.name for o in scene.objects}
    assert names == {"Floor", "Ceiling", "Wall Back", "Wall Front", "Wall Left", "Wall Right",
                     "Half Wall", "Light", "Camera"}
    light = scene.objects["Light"]
    assert light.type == "LIGHT" and light.data.type == "POINT"
    assert light.data.shadow_soft_size == 0.0
    assert light.data.energy == pytest.approx(seed_scenes.LIGHT1_POWER)
    assert light.location.x > 1.0 and light.location.z > 2.0       # upper right
    assert scene.camera.name == "Camera"
    assert (scene.render.resolution_x, scene.render.resolution_y) == (640, 480)
    assert scene.render.engine == "LANTERNA"
    assert scene.view_settings.view_transform == "Standard"

    def colour(obj_name):
        mat = scene.objects[obj_name].material_slots[0].material
        node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfDiffuse")
        return tuple(round(v, 3) for v in node.inputs["Color"].default_value[:3])

    assert colour("Wall Right") == seed_scenes.BLUE
    assert colour("Floor") == seed_scenes.GREEN
    assert colour("Wall Left") == colour("Ceiling") == colour("Half Wall") == seed_scenes.WHITE
    background = next(n for n in scene.world.node_tree.nodes
                      if n.bl_idname == "ShaderNodeBackground")
    assert tuple(background.inputs["Color"].default_value[:3]) == (0.0, 0.0, 0.0)


def world_triangles(scene) -> np.ndarray:
    """All mesh triangles of the evaluated scene in world space, (T, 3, 3) float32."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    out = []
    for obj in scene.objects:
        if obj.type != "MESH":
            continue
        ev = obj.evaluated_get(depsgraph)
        mesh = ev.to_mesh()
        mesh.calc_loop_triangles()
        co = np.empty(len(mesh.vertices) * 3, np.float64)
        mesh.vertices.foreach_get("co", co)
        tri = np.empty(len(mesh.loop_triangles) * 3, np.int64)
        mesh.loop_triangles.foreach_get("vertices", tri)
        m = np.array(ev.matrix_world)
        world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        out.append(world[tri.reshape(-1, 3)])
        ev.to_mesh_clear()
    return np.concatenate(out).astype(np.float32)


def sphere_directions(n: int) -> np.ndarray:
    """n nearly uniform unit vectors (Fibonacci sphere)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def trace(triangles, origin, directions):
    """Closest-hit distance per ray (inf for a miss), with raw embreex."""
    rtcore_scene = pytest.importorskip("embreex.rtcore_scene")
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(triangles))
    origins = np.repeat(np.asarray(origin, np.float32)[None], len(directions), axis=0)
    res = scene.run(origins, directions.astype(np.float32), output=1)
    dist = np.asarray(res["tfar"], np.float64)
    return np.where(np.asarray(res["geomID"]) >= 0, dist, np.inf)


@pytest.mark.parametrize("name", ["scene1", "scene2"])
def test_seed_scenes_are_closed(name):
    scene = seed_scenes.build(name)
    triangles = world_triangles(scene)
    dirs = sphere_directions(20000)
    for viewpoint in ("Light", "Camera"):
        origin = np.array(scene.objects[viewpoint].location)
        dist = trace(triangles, origin, dirs)
        assert np.isfinite(dist).all(), f"{name}: rays from the {viewpoint} escape"
        assert dist.min() > 0.01


def test_scene2_light_falls_in_a_cone():
    """The tube lets light out only downwards: steep rays travel far, shallow ones stop in
    the tube or at the ceiling right beside the light."""
    scene = seed_scenes.build_scene2()
    triangles = world_triangles(scene)
    dirs = sphere_directions(20000)
    dist = trace(triangles, np.array(scene.objects["Light"].location), dirs)
    angle_from_down = np.degrees(np.arccos(np.clip(-dirs[:, 2], -1, 1)))
    tube = seed_scenes.TUBE2
    half_angle = np.degrees(np.arctan(tube["radius"] / (tube["length"] - seed_scenes.LIGHT2_DEPTH)))
    inside = angle_from_down < half_angle - 5
    outside = angle_from_down > half_angle + 5
    assert dist[inside].min() > 1.0
    assert dist[outside].max() < tube["length"] + 0.1


def test_help_is_fast_and_does_not_import_bpy():
    code = ("import sys; from lanterna.engine.blender import cli; "
            "rc = cli.main(['--help']); print('bpy' in sys.modules, rc)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False 0"
    assert "render" in done.stdout and "scene" in done.stdout


def test_bench_is_dispatched(capfd, monkeypatch):
    """From a checkout ``lanterna bench`` reaches bench/main.py; where bench/ is absent (an
    installed add-on: the zips leave it out) it says so in one line, exit status 2."""
    assert cli.main(["bench", "--help"]) == 0
    assert "lanterna bench" in capfd.readouterr().out
    monkeypatch.setattr(cli, "BENCH_PACKAGE", "lanterna.no_bench_here")
    assert cli.main(["bench"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lanterna: error: the benchmarks are not part")


def test_passes_are_written_as_exr_layers(tmp_path, capfd):
    exr = tmp_path / "p.exr"
    code = cli.main(["render", "--resolution", "32x24", "--samples", "2", "--seed", "5",
                     "--preset", "preview", "--photons", "20000", "-o", str(exr), "--quiet",
                     "--passes", "direct,indirect,emission,cache-points,cache-usage"])
    assert code == 0, capfd.readouterr().err
    channels = imageio.read_exr(exr)
    layers = ("Direct", "Indirect", "Emission", "CachePoints", "CacheUsage")
    assert sorted(channels) == sorted(["R", "G", "B"] + [f"{n}.{c}" for n in layers for c in "RGB"])
    for c in "RGB":
        total = channels[f"Direct.{c}"] + channels[f"Indirect.{c}"] + channels[f"Emission.{c}"]
        np.testing.assert_allclose(total, channels[c], rtol=0, atol=1e-4)
        assert channels[f"Indirect.{c}"].mean() > 0.01
    assert set(np.unique(channels["CachePoints.R"])) <= {0.0, 1.0}


def test_unknown_pass_is_refused(tmp_path, capfd):
    code = cli.main(["render", "-o", str(tmp_path / "x.exr"), "--passes", "direct,albedo"])
    err = capfd.readouterr().err
    assert code == 2 and "unknown pass 'albedo'" in err
    assert list(tmp_path.iterdir()) == []


# -- Every input a user has (issue 22): .ase, baked maps, and a .blend that crashes the reader --
ASE = os.path.join(os.path.dirname(__file__), "data", "ase", "room.ase")


def test_an_ase_scene_renders_with_its_material_file(tmp_path, capfd):
    exr = tmp_path / "ase.exr"
    argv = ["render", ASE, "--materials", ASE[:-4] + ".mat", "--resolution", "32x24",
            "--samples", "2", "--photons", "20000", "-o", str(exr), "--quiet"]
    assert cli.main(argv) == 0, capfd.readouterr().err
    image = imageio.read_exr_rgb(exr)
    assert image.shape == (24, 32, 3) and np.isfinite(image).all() and image.mean() > 0
    missing = tmp_path / "none.mat"
    line = run_error(capfd, argv[:2] + ["--materials", str(missing)] + argv[4:])
    assert "none.mat" in line and "no such file" in line
    line = run_error(capfd, ["render", "--scene", "scene1", "--materials", str(missing),
                             "-o", str(exr)])
    assert "--materials goes with an .ase scene" in line


def test_bake_then_render_with_the_maps_gives_the_render_s_picture(tmp_path, capfd):
    """``lanterna bake`` then ``render --maps``: the same EXR as a render that builds its maps;
    maps made with other map settings are refused by name, status 2, nothing written."""
    maps = tmp_path / "maps.npz"
    flags = ["--scene", "scene1", "--resolution", "32x24", "--samples", "2", "--photons",
             "20000", "--seed", "3", "--quiet"]
    assert cli.main(["bake", *flags, "-o", str(maps)]) == 0
    assert "wrote" in capfd.readouterr().out and maps.exists()
    plain, baked = tmp_path / "plain.exr", tmp_path / "baked.exr"
    assert cli.main(["render", *flags, "-o", str(plain)]) == 0
    assert cli.main(["render", *flags, "--maps", str(maps), "-o", str(baked)]) == 0
    np.testing.assert_array_equal(imageio.read_exr_rgb(plain), imageio.read_exr_rgb(baked))
    stale = tmp_path / "stale.exr"
    line = run_error(capfd, ["render", *flags[:6], "--photons", "30000", "--seed", "3",
                             "--maps", str(maps), "-o", str(stale)])
    assert "maps.npz" in line and "photons = 20000 in the file, 30000 now" in line
    assert not stale.exists()


def _blend(tmp_path):
    blend = tmp_path / "s1.blend"
    assert cli.main(["scene", "scene1", "-o", str(blend)]) == 0
    return blend


@pytest.mark.parametrize("stage, code, said", [
    ("open", 2, "Blender could not read it (damaged file?)"),
    ("render", 1, "internal error: Blender crashed"),
])
def test_a_crash_in_blender_is_a_message_not_a_signal(tmp_path, stage, code, said):
    """A .blend is rendered in a child process, because Blender's reader can crash on a
    damaged file (a segmentation fault, no Python exception: 7 of 200 one-bit flips did).
    Here the child aborts on purpose at a stage (``LANTERNA_TEST_CRASH_AT``): while reading
    the file it is a damaged file, exit 2; after it an internal error, exit 1; one line either
    way and nothing written. ``tests/fuzz.py`` meets the real crashes."""
    blend, exr = _blend(tmp_path), tmp_path / "out.exr"
    done = subprocess.run([sys.executable, "-m", "lanterna.engine.blender.cli", "render",
                           str(blend), "--resolution", "16x12", "--samples", "1", "-o",
                           str(exr), "--quiet"], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, LANTERNA_TEST_CRASH_AT=stage))
    lines = [line for line in done.stderr.splitlines() if line.startswith("lanterna:")]
    assert done.returncode == code, done.stderr
    assert len(lines) == 1 and said in lines[0] and str(blend) in lines[0], done.stderr
    assert not exr.exists()
