"""The cost estimate (engine/estimate.py): counts, plan, memory refusal, dry run, rates files.

What is checked (no timings are asserted: the machine is shared; ``lanterna bench
--check-estimate`` prints predicted against measured time)
* Counts the estimate predicts before any tracing equal what a render reports where they are
  deterministic: camera rays, shadow rays of a point light over a plane that faces it, photons
  emitted, look-ups (cache, photon map), radiance estimates given the stored photons, shadow
  photons; the plan equals the pipeline's for scenes that skip and run different stages.
* Predicted counts lie within stated bounds: stored photons in a closed room within 5 % (the
  bounce factor 1 / (1 - rho) is exact in expectation there), also with a bounce cap and
  with first hits dropped; irradiance-cache records within a factor 2 (a fit).
* Memory: with ``available_memory`` patched to 1 MiB, ``render`` and ``bake`` raise
  SceneError naming the GiB needed, the biggest stages and what is available, before any
  work (a spy on the BVH build is never called).
* ``lanterna render --dry-run`` prints the plan and the table, writes nothing, exits 0.
* Rates files: round trip; the user file wins; a partial one is completed from the
  defaults with a warning; the raw groups (rays by triangle count, the photon map's build by
  its size) are kept or dropped whole, and the store rate follows the map's size; a corrupt
  one gives a warning naming it and the defaults are used (also in a render's report); the
  shipped file is complete and packaged.
"""
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from analytic import box_room, plane_scene
from lanterna.engine import estimate, preparation
from lanterna.bench.calibrate import calibration_scene
from lanterna.engine.pipeline import RenderSettings, bake, render
from lanterna.engine.scene import Camera, Material, PointLight, Scene, SceneError

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _own_rates(tmp_path, monkeypatch):
    """No user rates file of this machine leaks in: the cache directory is a fresh one."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    estimate._RATES_CACHE.clear()
    yield
    estimate._RATES_CACHE.clear()


def _room(rho=0.5, resolution=(24, 18), lights=None):
    tris = box_room(size=(4.0, 4.0, 3.0))
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("grey", diffuse=rho)],
                 camera=Camera.look_at([1.0, 1.0, 1.5], [3.0, 3.0, 1.0], resolution=resolution),
                 lights=lights or [PointLight("Lamp", (2.0, 2.0, 2.5), 60.0)])


# -- Counts -----------------------------------------------------------------------------------
def test_deterministic_counts_equal_the_render_report():
    """Camera rays, point-light shadow rays, photons, cache look-ups and radiance estimates."""
    scene = plane_scene([PointLight("Lamp", (0.0, 0.0, 3.0), 100.0)], rho=0.6,
                        resolution=(32, 24))
    settings = RenderSettings(samples=3, photons=20_000, photon_lookups=2, gather_m=4,
                              gather_n=8, seed=2)
    e = estimate.estimate_cost(scene, settings)
    report = render(scene, settings).report
    st, cam = report["stages"], report["stages"]["camera"]
    pixels = 32 * 24
    assert e.stages["camera"].counts["camera_rays"] == cam["camera_rays"] == pixels * 3
    # Every hit faces the lamp, so each gets exactly one shadow ray.
    assert e.stages["camera"].counts["shadow_rays"] == cam["shadow_rays"] == pixels * 3
    assert e.stages["photons"].counts["emitted"] == st["photons"]["emitted"] == 20_000
    assert e.stages["camera"].counts["lookups"] == \
        cam["cache_interpolated"] + cam["cache_gathered"] == pixels * 2
    assert estimate.radiance_estimate_count(st["photons"]["stored"]) == \
        st["radiance_estimates"]["estimates"]
    # The same stages, and the estimate is in the report.
    assert set(e.stages) == set(st)
    assert report["estimate"]["stages"]["camera"]["counts"]["camera_rays"] == pixels * 3
    assert report["estimate"]["seconds"] > 0 and report["estimate"]["peak_bytes"] > 0


def test_a_window_of_a_large_frame_counts_as_its_part_of_the_frame():
    """Automatic counts follow the full frame and the camera shades whole full-frame blocks:
    a 32 x 24 window of a 640 x 480 frame at 3 spp lies in one 144 x 144 block, whose pixels
    each look up one sample (300k look-ups over 307k pixels, as the whole frame would)."""
    scene = plane_scene([PointLight("Lamp", (0.0, 0.0, 3.0), 100.0)], rho=0.6,
                        resolution=(640, 480))
    scene.camera = Camera.look_at([0, 0, 4], [0, 0, 0], up=(0, 1, 0), fov_x_deg=90,
                                  resolution=(640, 480), border=(304, 228, 336, 252))
    settings = RenderSettings(samples=3, photons=20_000, gather_m=2, gather_n=4)
    e = estimate.estimate_cost(scene, settings)
    cam = render(scene, settings).report["stages"]["camera"]
    assert estimate.camera_blocks((640, 480), (304, 228, 336, 252), 3) == (144 ** 2, 1, 144 ** 2)
    assert e.stages["camera"].counts["camera_rays"] == cam["camera_rays"] == 144 ** 2 * 3
    assert e.stages["camera"].counts["lookups"] == \
        cam["cache_interpolated"] + cam["cache_gathered"] == 144 ** 2


@pytest.mark.parametrize("indirect", ["photon-map", "gather"])
def test_photon_map_and_gather_lookups_are_exact(indirect):
    scene = _room(resolution=(16, 12))
    settings = RenderSettings(samples=4, photons=10_000, indirect=indirect, gather_m=2,
                              gather_n=4, gather_guided=0.0)
    e = estimate.estimate_cost(scene, settings)
    cam = render(scene, settings).report["stages"]["camera"]
    lookups = 16 * 12 * 4                      # auto: every sample of a small image
    if indirect == "photon-map":
        assert e.stages["camera"].counts["photon_lookups"] == cam["photon_queries"] == lookups
    else:
        assert e.stages["camera"].counts["gathered"] == cam["gather_points"] == lookups
        # Unguided and no mirrors: exactly M x N rays a point.
        assert cam["gather_rays"] == lookups * 2 * 4


def test_shadow_photon_count_and_plans_equal_the_pipeline():
    cases = [
        (calibration_scene((16, 12), "area"), RenderSettings(samples=1, photons=5_000,
                                                             bounces=0)),
        (_room(), RenderSettings(samples=1, photons=5_000, mode="photon-map")),
        (_room(), RenderSettings(samples=1, bounces=0)),
        (_room(), RenderSettings(samples=1, photons=5_000, indirect="photon-map",
                                 force="shadow_photons")),
    ]
    for scene, settings in cases:
        e = estimate.estimate_cost(scene, settings)
        report = render(scene, settings).report
        assert e.plan == report["plan"]["stages"], settings
        assert set(e.stages) == set(report["stages"]), settings
        if "shadow_photons" in report["stages"]:
            assert e.stages["shadow_photons"].counts["shadow_photons"] == \
                report["stages"]["shadow_photons"]["requested"]


def test_stored_photons_within_5_percent_in_a_closed_room():
    """Closed room of one albedo: expected hits per photon sum_{i<=B} rho^i exactly."""
    cases = [(0.5, 64, "cache", 2.0), (0.5, 1, "cache", 1.5), (0.7, 64, "photon-map", 1 / 0.3 - 1)]
    for rho, bounces, indirect, hits in cases:
        scene = _room(rho)
        settings = RenderSettings(samples=1, photons=40_000, bounces=bounces,
                                  indirect=indirect, gather_m=2, gather_n=4, seed=3)
        e = estimate.estimate_cost(scene, settings)
        predicted = e.stages["photons"].counts["stored"]
        assert predicted == pytest.approx(40_000 * hits, rel=1e-6)   # float32 albedo
        measured = render(scene, settings).report["stages"]["photons"]["stored"]
        assert measured == pytest.approx(predicted, rel=0.05), (rho, bounces, indirect)


def test_open_scene_photons_are_not_counted_as_closed():
    """A lone plane: most photons never hit it and bounced ones escape. The closure c (share
    of the bounds' faces covered: the floor of a 10 x 10 x 4 box) as the chance of a hit
    keeps the prediction within a factor 2 (as a closed scene it would be 65 x too many)."""
    scene = plane_scene([PointLight("Lamp", (0.0, 0.0, 3.0), 100.0)], rho=1.0)
    facts = estimate.scene_facts(scene)
    assert facts.closure == pytest.approx(100 / (2 * 100 + 4 * 40), rel=1e-6)
    settings = RenderSettings(samples=1, photons=20_000, indirect="photon-map", mode="photon-map")
    predicted = estimate.estimate_cost(scene, settings).stages["photons"].counts["stored"]
    measured = render(scene, settings).report["stages"]["photons"]["stored"]
    assert 0.5 < predicted / measured < 2.0, (predicted, measured)


def test_cache_records_within_a_factor_2():
    scene = calibration_scene((128, 96))
    settings = RenderSettings(samples=1, photons=30_000, cache_error=0.25, gather_m=4,
                              gather_n=12)
    predicted = estimate.estimate_cost(scene, settings).stages["irradiance_cache"].counts["records"]
    measured = render(scene, settings).report["stages"]["irradiance_cache"]["records"]
    assert 0.5 < predicted / measured < 2.0, (predicted, measured)


# -- Memory -----------------------------------------------------------------------------------
def _image_graph(image):
    from lanterna.engine import nodes

    graph = nodes.Graph()
    graph.nodes["Image"] = nodes.Node(
        "ShaderNodeTexImage", "Image", {"image": "tex", "interpolation": "Linear"},
        {"Vector": ("VECTOR", [0.0, 0.0, 0.0])}, {"Color": "RGBA", "Alpha": "VALUE"})
    graph.images["tex"] = image
    return graph


def _textured(name, image, param="base_color"):
    from lanterna.engine.shaders import Closure

    closure = Closure("principled")
    closure.textures[param] = [(("Image", "Color"), None)]
    return Material(name, diffuse=0.5, closures=(closure,), graph=_image_graph(image))


def _textured_room():
    """``_room`` whose floor and ceiling read one shared 8-bit image (two graphs, one Image
    object) and whose back wall reads a float32 one; the other walls are plain."""
    from lanterna.engine import nodes

    rng = np.random.default_rng(7)
    byte = nodes.Image(rng.integers(0, 256, (16, 32, 4)).astype(np.uint8), "srgb")
    hdr = nodes.Image(np.exp(rng.normal(0, 2, (4, 8, 4))).astype(np.float32), "linear")
    scene = _room()
    scene.materials = [Material("walls", diffuse=0.5), _textured("floor", byte),
                       _textured("ceiling", byte), _textured("back", hdr)]
    ids = np.zeros(12, np.int32)
    ids[0:2], ids[2:4], ids[8:10] = 1, 2, 3
    scene.material_ids = ids
    scene.corner_attributes = {"uv": np.zeros((12, 3, 2), np.float32)}
    return scene, byte, hdr


def test_texture_memory_counts_each_image_once_and_lookups_follow_the_area():
    """The estimate's texture bytes are the held arrays' nbytes, an image two materials share
    counted once (16 x 32 x 4 bytes, not twice; the float32 image 16 B a texel); image
    look-ups per hit are the textured share of the area (floor 16 + ceiling 16 + back wall
    12 m^2 of 80); the camera's look-ups are its hits times that, at the look-up rate, and
    the dry-run table names the bytes."""
    scene, byte, hdr = _textured_room()
    facts = estimate.scene_facts(scene)
    assert byte.pixels.dtype == np.uint8 and hdr.pixels.dtype == np.float32
    assert facts.texture_bytes == byte.pixels.nbytes + hdr.pixels.nbytes == 2048 + 512
    assert facts.texture_lookups == pytest.approx(44.0 / 80.0, rel=1e-6)
    assert facts.emission_lookups == 0.0
    settings = RenderSettings(samples=2, photons=10_000, gather_m=4, gather_n=8)
    e = estimate.estimate_from_facts(facts, settings)
    plain = estimate.estimate_from_facts(estimate.scene_facts(_room()), settings)
    cam = e.stages["camera"].counts
    assert cam["texture_lookups"] == pytest.approx(
        (cam["camera_rays"] + cam.get("specular_rays", 0)
         + cam.get("gathered", 0) * 4 * 8 * (1 + settings.resolved().gather_guided))
        * 44.0 / 80.0)
    assert "texture_lookups" not in plain.stages["camera"].counts
    rates = estimate.load_rates()
    workers = min(settings.resolved().worker_count, estimate.os.cpu_count() or 1)
    rate = rates.seconds["texture_lookup"] * min(rates.workers, rates.cores) / workers
    looks = sum(s.counts.get("texture_lookups", 0) for s in e.stages.values())
    assert looks > 0 and e.texture_seconds == pytest.approx(looks * rate, rel=1e-6)
    assert e.to_report()["texture_bytes"] == 2560
    assert f"textures {estimate.format_seconds(e.texture_seconds):>21}" \
        f"{estimate.format_bytes(2560):>11}" in " ".join(e.table().split("\n"))
    assert estimate.SceneFacts.from_dict({k: v for k, v in facts.to_dict().items()
                                          if not k.startswith(("texture", "emission"))}
                                         ).texture_bytes == 0      # facts saved before


def test_textured_emitters_count_lookups_per_emitted_flux():
    """Image look-ups per photon or light sample: the textured emitters' share of the
    lights' luminance flux (an emissive ceiling of exitance pi x 2 W/m^2 a side on 16 m^2,
    both sides, against a 60 W point light)."""
    from lanterna.engine import nodes

    scene = _room()
    image = nodes.Image(np.full((2, 2, 4), 255, np.uint8), "srgb")
    ceiling = _textured("ceiling", image, "emission")
    ceiling.exitance = np.full(3, 2.0 * np.pi)
    scene.materials = [Material("walls", diffuse=0.5), ceiling]
    scene.material_ids = np.array([0, 0, 1, 1] + [0] * 8, np.int32)
    scene.corner_attributes = {"uv": np.zeros((12, 3, 2), np.float32)}
    facts = estimate.scene_facts(scene)
    mesh = 2.0 * np.pi * 16.0 * 2.0
    assert facts.emission_lookups == pytest.approx(mesh / (mesh + 60.0), rel=1e-6)
    assert facts.texture_lookups == 0.0


def test_too_little_memory_is_refused_before_any_work(monkeypatch):
    built = []

    def spy(*args, **kwargs):
        built.append(args)
        raise AssertionError("the BVH was built")

    monkeypatch.setattr(estimate, "available_memory", lambda: 1 << 20)
    monkeypatch.setattr(preparation, "Accelerator", spy)
    scene = _room()
    settings = RenderSettings(samples=2, photons=2_000_000)
    for run in (render, bake):
        with pytest.raises(SceneError) as info:
            run(scene, settings)
        message = str(info.value)
        assert "needs about" in message and "GiB" in message and "photons" in message
        assert "only 0.0 GiB is available" in message and "lower" in message
    assert built == []
    # The estimate in the message is the estimate's own peak.
    e = estimate.estimate_cost(scene, settings)
    assert f"{e.peak_bytes / estimate.GIB:.1f} GiB" in message


def test_memory_of_a_big_setting_and_the_peak():
    scene = _room(resolution=(640, 480))
    e = estimate.estimate_cost(scene, RenderSettings(photons=10_000_000, samples=4))
    photons = e.stages["photons"]
    # 10M photons in a closed room of rho 0.5: 20M stored at 56 B kept + 72 B while building.
    assert photons.keeps == pytest.approx(20e6 * estimate.PHOTON_BYTES, rel=1e-6)
    assert e.peak_bytes == max(s.peak for s in e.stages.values())
    assert e.peak_bytes >= photons.keeps + 20e6 * estimate.PHOTON_BUILD_BYTES
    with pytest.raises(SceneError, match="needs about 2.4 GiB"):
        estimate.check_memory(e, available=1 << 30)
    estimate.check_memory(e, available=1 << 40)               # fits: no error


def test_available_memory_is_known_here():
    available = estimate.available_memory()
    assert available is not None and available > 1 << 26


def test_unusable_scene_arrays_are_left_to_the_validate_stage():
    scene = _room()
    scene.material_ids = np.full(len(scene.triangles), 7, np.int32)   # no such material
    with pytest.raises(SceneError, match="material that does not exist"):
        render(scene, RenderSettings(samples=1))


# -- Rates files ------------------------------------------------------------------------------
def _rates(value=1e-6):
    raw = {k: 1e-6 * (i + 1) for i, k in enumerate(estimate.RAW_KEYS)}
    raw.update(triangles_small=1e3, triangles_large=1e6, stored_small=1e6, stored_large=4e6,
               store_small=0.2e-6, store_large=0.4e-6)
    return estimate.Rates(seconds={k: value for k in estimate.RATE_KEYS}, workers=2, cores=2,
                          raw=raw, measured="test")


def test_rates_round_trip_and_the_user_file_wins(tmp_path):
    path = estimate.save_rates(_rates(2.5e-6), tmp_path / "cache" / "lanterna" / "rates.json")
    assert path == estimate.user_rates_path()
    back = estimate.read_rates(path)
    assert back.seconds == _rates(2.5e-6).seconds and back.raw == _rates().raw
    assert (back.workers, back.cores, back.measured) == (2, 2, "test")
    loaded = estimate.load_rates()
    assert loaded.source == str(path) and loaded.warnings == []
    assert loaded.seconds["camera_sample"] == 2.5e-6
    assert [p.name for p in path.parent.iterdir()] == ["rates.json"]     # no temporary left


def test_store_rate_follows_the_size_of_the_map():
    """The per-photon build cost is interpolated in ln(stored) between the two measured maps
    (0.2 us at 1M, 0.4 us at 4M here), held at the small map's below it, extrapolated above;
    a rates file without the pair keeps one rate, and the photon stage's estimate follows."""
    rates = _rates()
    assert estimate._store_shift(rates, 1e6) == 0.0
    assert estimate._store_shift(rates, 2e5) == 0.0
    assert estimate._store_shift(rates, 2e6) == pytest.approx(0.1e-6, rel=1e-12)
    assert estimate._store_shift(rates, 4e6) == pytest.approx(0.2e-6, rel=1e-12)
    assert estimate._store_shift(rates, 16e6) == pytest.approx(0.4e-6, rel=1e-12)
    flat = estimate.Rates(**{**rates.__dict__, "raw": {k: v for k, v in rates.raw.items()
                                                       if k not in estimate.STORE_KEYS}})
    assert estimate._store_shift(flat, 4e6) == 0.0
    settings = RenderSettings(photons=1_000_000, samples=1)
    facts = estimate.scene_facts(_room(0.7))
    with_shift = estimate.estimate_from_facts(facts, settings, rates).stages["photons"]
    without = estimate.estimate_from_facts(facts, settings, flat).stages["photons"]
    stored = with_shift.counts["stored"]
    assert stored > 1e6
    expected = stored * estimate._store_shift(rates, stored)
    assert with_shift.seconds - without.seconds == pytest.approx(expected, rel=1e-9)


def test_rates_groups_are_kept_whole(tmp_path):
    """A raw group with a missing or bad entry is dropped whole; the other group stays; a
    user file lacking a group takes the shipped one's."""
    data = _rates().to_json()
    del data["raw"]["store_large"]
    back = estimate.Rates.from_json(data)
    assert set(back.raw) == set(estimate.RAW_KEYS)
    data = _rates().to_json()
    data["raw"]["coherent_small"] = float("nan")
    assert set(estimate.Rates.from_json(data).raw) == set(estimate.STORE_KEYS)
    data = _rates(3e-6).to_json()
    for key in estimate.STORE_KEYS:
        del data["raw"][key]
    path = estimate.user_rates_path()
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(data))
    loaded = estimate.load_rates()
    defaults = estimate.read_rates(estimate.DEFAULT_RATES_PATH)
    assert loaded.raw["coherent_small"] == _rates().raw["coherent_small"]
    assert {k: loaded.raw[k] for k in estimate.STORE_KEYS} == \
        {k: defaults.raw[k] for k in estimate.STORE_KEYS}


def test_partial_user_file_is_completed_from_the_defaults(tmp_path):
    data = _rates(3e-6).to_json()
    del data["seconds"]["gather_ray"]
    path = estimate.user_rates_path()
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(data))
    rates = estimate.load_rates()
    defaults = estimate.read_rates(estimate.DEFAULT_RATES_PATH)
    assert rates.seconds["gather_ray"] == defaults.seconds["gather_ray"]
    assert rates.seconds["camera_sample"] == 3e-6
    assert len(rates.warnings) == 1 and "gather_ray" in rates.warnings[0]


@pytest.mark.parametrize("text, reason", [
    ("{not json", "is not valid JSON"),
    (json.dumps({"schema": 1, "seconds": {"camera_sample": -1}, "workers": 2}), "'camera_sample'"),
    (json.dumps({"schema": 99, "seconds": {}}), "schema 99"),
    (json.dumps([1, 2]), "not a JSON object"),
])
def test_corrupt_user_rates_warn_and_fall_back_to_the_defaults(text, reason):
    path = estimate.user_rates_path()
    path.parent.mkdir(parents=True)
    path.write_text(text)
    rates = estimate.load_rates()
    defaults = estimate.read_rates(estimate.DEFAULT_RATES_PATH)
    assert rates.source == str(estimate.DEFAULT_RATES_PATH)
    assert rates.seconds == defaults.seconds
    assert len(rates.warnings) == 1
    assert str(path) in rates.warnings[0] and reason in rates.warnings[0]
    assert "shipped with Lanterna" in rates.warnings[0]


def test_a_render_reports_the_rates_warning():
    path = estimate.user_rates_path()
    path.parent.mkdir(parents=True)
    path.write_text("garbage")
    report = render(_room(resolution=(8, 6)), RenderSettings(samples=1, bounces=0)).report
    assert any(str(path) in w and "not valid JSON" in w for w in report["warnings"])
    assert report["estimate"]["rates"] == str(estimate.DEFAULT_RATES_PATH)


def test_shipped_rates_are_complete_and_packaged():
    rates = estimate.read_rates(estimate.DEFAULT_RATES_PATH)
    assert set(rates.seconds) == set(estimate.RATE_KEYS)
    assert all(v > 0 for v in rates.seconds.values())
    assert set(rates.raw) == set(estimate.RAW_KEYS) | set(estimate.STORE_KEYS)
    with open(ROOT / "pyproject.toml", "rb") as f:
        setuptools = tomllib.load(f)["tool"]["setuptools"]
    assert "data/*.json" in setuptools["package-data"]["lanterna.engine"]
    with pytest.raises(estimate.RatesError, match="cannot be read"):
        estimate.read_rates(ROOT / "no-such-rates.json")


# -- The command line and the panel (Blender) -------------------------------------------------
def test_dry_run_prints_the_plan_and_table_and_writes_nothing(tmp_path, capfd):
    pytest.importorskip("bpy")
    from lanterna.engine.blender import cli, registration

    was = registration.is_registered()
    folder = tmp_path / "out"
    folder.mkdir()
    try:
        out = folder / "never.exr"
        for extra in ([], ["-o", str(out), "--report", str(folder / "never.json")]):
            capfd.readouterr()
            code = cli.main(["render", "--scene", "scene1", "--resolution", "40x30",
                             "--preset", "preview", "--dry-run", *extra])
            captured = capfd.readouterr()
            assert code == 0, captured.err
            text = captured.out
            for word in ("plan:", "photons", "irradiance_cache", "camera", "total",
                         "peak memory", "nothing rendered, nothing written"):
                assert word in text, word
            assert "40x30 px, 4 spp, preset preview" in text
        assert list(folder.iterdir()) == []
        assert not estimate.user_rates_path().exists()
        # Without --dry-run the output is still required.
        assert cli.main(["render", "--scene", "scene1"]) == 2
        assert "required: -o/--output" in capfd.readouterr().err
    finally:
        if not was:
            registration.unregister()


def test_render_panel_shows_the_estimate_of_the_current_settings():
    pytest.importorskip("bpy")
    import test_ui as ui
    from lanterna.engine.blender import export, live_estimate, registration
    from lanterna.ui import panels

    was = registration.is_registered()
    registration.register()
    try:
        import bpy

        scene, *_ = ui.build_scene('POINT')
        ctx = ui.context_for(scene)
        panel = panels.LANTERNA_RENDER_PT_estimate
        assert panel.bl_parent_id == "LANTERNA_RENDER_PT_sampling"
        shown = ui.labels(ui.draw(panel, ctx))
        assert "Total" in shown
        expected = estimate.estimate_cost(
            export.export_scene(bpy.context.evaluated_depsgraph_get()),
            export.export_settings(scene))
        assert estimate.format_seconds(expected.seconds) in shown
        assert f"peak {estimate.format_bytes(expected.peak_bytes)}" in shown
        # A settings change shows at once (the facts are cached, the estimate recomputed).
        before = live_estimate.panel_estimate(ctx)[0].stages["camera"].counts["camera_rays"]
        scene.lanterna.samples *= 4
        after = live_estimate.panel_estimate(ctx)[0].stages["camera"].counts["camera_rays"]
        assert after == 4 * before
    finally:
        if not was:
            registration.unregister()
