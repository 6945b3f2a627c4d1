"""The viewport overlay: its data (engine/overlay.py, no bpy) and the Blender side (draw
handler, settings, operators; skipped without bpy).

Core: positions are exactly rows of the map's positions; colours follow the documented
mappings, recomputed here from their definitions (viridis against matplotlib's table within
0.025, the fixed colours to 1e-6); ``max_points`` bounds the points and the kept ones are the
largest keys log(u) / w recomputed here; equal-power photons give a subset spread over the
whole map; the shadow classes' colours are the classes ``classify_photons`` gives.
Blender: register / unregister leave no handler and no classes (background mode adds no
handler at all); batches are rebuilt only when the maps or the data settings change; the
operators bake, clear, save, load (and refuse), export the report on the seed's Scene 1 at
32 x 24; an F12 render keeps its maps.
"""
import json

import numpy as np
import pytest

from analytic import quad
from lanterna.engine import overlay as O
from lanterna.engine.accel import Accelerator
from lanterna.engine.artifacts import Artifacts
from lanterna.engine.irradiance_cache import IrradianceCache
from lanterna.engine.lights import LightSet
from lanterna.engine.photons import PhotonMap
from lanterna.engine.scene import AreaLight, Camera, Material, Scene
from lanterna.engine.shadow_photons import LIT, PENUMBRA, UMBRA, build_shadow_photon_map

LUMA = np.array([0.2126, 0.7152, 0.0722])       # Rec. 709, as documented


def _photon_map(count=20_000, seed=0, equal_power=False):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-2, 2, (count, 3)).astype(np.float32)
    power = (np.full((count, 3), 1e-3) if equal_power
             else rng.uniform(0, 1e-3, (count, 3)) * rng.uniform(0.1, 3.0, (count, 1)))
    power[:3] = [[1e-3, 0, 0], [0, 0, 0], [2e-4, 5e-4, 1e-4]] if not equal_power else 1e-3
    incoming = np.tile([0, 0, -1], (count, 1)).astype(np.float16)
    normals = np.tile([0, 0, 1], (count, 1)).astype(np.float16)
    bounces = rng.integers(0, 12, count).astype(np.uint8)
    return PhotonMap(positions, power.astype(np.float32), incoming, normals, bounces).build()


def _cache(count=500, seed=1):
    rng = np.random.default_rng(seed)
    cache = IrradianceCache()
    cache.add(rng.uniform(-1, 1, (count, 3)), np.tile([0, 0, 1.0], (count, 1)),
              rng.uniform(0, 4, (count, 3)), np.exp(rng.uniform(np.log(0.01), np.log(1), count)))
    cache._used[:count] = rng.integers(0, 100, count)
    return cache


def _artifacts(photon_map=None, shadow_map=None, cache=None):
    return Artifacts(photon_map, shadow_map, cache, fingerprint="test", settings={})


def _matplotlib_viridis(t):
    cm = pytest.importorskip("matplotlib").colormaps["viridis"]
    return cm(np.clip(t, 0, 1))[:, :3]


def _keys(weights, seed=0):
    u = 1.0 - np.random.default_rng(seed).random(len(weights))
    with np.errstate(divide="ignore"):
        return np.where(weights > 0, np.log(u) / np.where(weights > 0, weights, 1), -np.inf)


@pytest.fixture(scope="module")
def shadow_setup():
    """The floor, a plate at 1.5 m and a square light at 3 m (tests/test_shadow_photons.py)."""
    m = np.eye(4)
    m[:3, 3] = [0, 0, 3.0]
    tris = np.concatenate([quad([0, 0, 0], [5, 0, 0], [0, 5, 0]),
                           quad([0, 0, 1.5], [0.5, 0, 0], [0, 0.5, 0])])
    scene = Scene(triangles=tris, material_ids=np.zeros(4, np.int32),
                  materials=[Material("white")], camera=Camera.look_at([0, -8, 6], [0, 0, 0]),
                  lights=[AreaLight("Area", "SQUARE", m, 1.0, 1.0, [100.0] * 3)]).validate()
    accel = Accelerator(scene.triangles, threads=1)
    smap = build_shadow_photon_map(scene, accel, LightSet(scene), 0, seed=1)
    accel.close()
    return smap


# -- Core: photons ----------------------------------------------------------------------------
def test_photon_positions_are_rows_of_the_map():
    pmap = _photon_map()
    pts = O.overlay_points(_artifacts(pmap), "photons", "power", 5000)
    assert pts.positions.dtype == np.float32 and pts.positions.shape == (5000, 3)
    assert pts.colors.dtype == np.float32 and pts.colors.shape == (5000, 4)
    assert pts.total == len(pmap) and pts.sizes is None
    assert np.array_equal(pts.positions, pmap.positions[pts.indices])
    assert len(np.unique(pts.indices)) == 5000
    # Every drawn position is a photon's position (by value, not only by index).
    rows = np.ascontiguousarray(pmap.positions).view([("", np.float32)] * 3).ravel()
    drawn = np.ascontiguousarray(pts.positions).view([("", np.float32)] * 3).ravel()
    assert np.isin(drawn, rows).all()


def test_power_colours_follow_viridis_of_normalised_luminance():
    pmap = _photon_map()
    pts = O.overlay_points(_artifacts(pmap), "photons", "power", len(pmap))
    lum = pmap.power.astype(np.float64) @ LUMA
    t = lum / np.percentile(lum, 99)
    rows = pts.indices[:: len(pts) // 40]
    at = {int(i): k for k, i in enumerate(pts.indices)}
    got = np.array([pts.colors[at[int(i)], :3] for i in rows])
    assert np.abs(got - _matplotlib_viridis(t[rows])).max() < 0.025
    # The ends of the map: t <= 0 is viridis(0), t >= 1 is viridis(1) (to 1e-4).
    brightest = int(np.argmax(lum))
    assert np.allclose(pts.colors[at[brightest], :3], [0.9932, 0.9062, 0.1439], atol=1e-4)
    assert np.all(pts.colors[:, 3] == 1.0)


def test_rgb_and_bounce_colours():
    pmap = _photon_map()
    art = _artifacts(pmap)
    pts = O.overlay_points(art, "photons", "rgb", len(pmap), alpha=0.5)
    p = pmap.power[pts.indices].astype(np.float64)
    peak = p.max(axis=1)
    ok = peak > 0
    assert np.allclose(pts.colors[ok, :3], p[ok] / peak[ok, None], atol=1e-6)
    assert np.all(pts.colors[~ok, :3] == 0) and np.all(pts.colors[:, 3] == 0.5)
    pure_red = int(np.nonzero((pmap.power[:, 1] == 0) & (pmap.power[:, 0] > 0))[0][0])
    k = int(np.nonzero(pts.indices == pure_red)[0][0])
    assert np.allclose(pts.colors[k], [1, 0, 0, 0.5])
    pts = O.overlay_points(art, "photons", "bounces", len(pmap))
    b = pmap.bounces[pts.indices]
    assert np.allclose(pts.colors[b == 0, :3], [1, 1, 1])          # documented: white first
    assert np.allclose(pts.colors[b == 1, :3], [1.0, 0.85, 0.1], atol=1e-6)
    many = pts.colors[b >= 7, :3]                                 # 7 and more share a colour
    assert len(many) and np.allclose(many, many[0])


def test_max_points_keeps_the_most_important_photons():
    pmap = _photon_map()
    lum = pmap.power.astype(np.float64) @ LUMA
    keys = _keys(lum)
    for n in (1, 100, 4000):
        pts = O.overlay_points(_artifacts(pmap), "photons", "power", n)
        assert len(pts) == n and pts.total == len(pmap)
        assert set(pts.indices.tolist()) == set(np.argsort(-keys, kind="stable")[:n].tolist())
        assert np.all(np.diff(keys[pts.indices]) <= 0)            # most important first
        rest = np.setdiff1d(np.arange(len(pmap)), pts.indices)
        assert keys[pts.indices].min() >= keys[rest].max()
    # Raising max_points only adds points; brighter photons are kept more often.
    small = O.overlay_points(_artifacts(pmap), "photons", "power", 2000).indices
    large = O.overlay_points(_artifacts(pmap), "photons", "power", 8000).indices
    assert np.array_equal(large[:2000], small)
    assert lum[small].mean() > 1.3 * lum.mean()
    # The zero-power photon comes last of all.
    everything = O.overlay_points(_artifacts(pmap), "photons", "power", 10 ** 9)
    zero = np.nonzero(lum == 0)[0]
    assert len(zero) == 1 and len(everything) == len(pmap) and everything.indices[-1] == zero[0]
    assert O.overlay_count(_artifacts(pmap), "photons", "power", 4000) == (4000, len(pmap))


def test_equal_power_gives_a_subset_spread_over_the_map():
    pmap = _photon_map(count=40_000, equal_power=True)      # Morton order after build()
    pts = O.overlay_points(_artifacts(pmap), "photons", "power", 4000)
    # Per octant of the cube: 500 expected, a uniform random subset within 20 %.
    octant = ((pts.positions > 0) * [1, 2, 4]).sum(axis=1)
    counts = np.bincount(octant, minlength=8)
    assert np.all(np.abs(counts - 500) < 100), counts
    # The same call gives the same points (deterministic).
    again = O.overlay_points(_artifacts(pmap), "photons", "power", 4000)
    assert np.array_equal(again.indices, pts.indices)
    assert np.array_equal(again.colors, pts.colors)


# -- Core: shadow photons and cache records ---------------------------------------------------
def test_shadow_photon_colours(shadow_setup):
    smap = shadow_setup
    art = _artifacts(shadow_map=smap)
    pts = O.overlay_points(art, "shadow_photons", "crossings", 20_000)
    assert pts.total == len(smap) and len(pts) == 20_000
    assert np.array_equal(pts.positions, smap.positions[pts.indices])
    shadow = smap.crossings[pts.indices] > 0
    assert shadow.any() and (~shadow).any()
    assert np.allclose(pts.colors[~shadow, :3], [1.0, 0.85, 0.1], atol=1e-6)   # direct: yellow
    assert np.allclose(pts.colors[shadow, :3], [0.15, 0.35, 1.0], atol=1e-6)   # shadow: blue
    pts = O.overlay_points(art, "shadow_photons", "light", 100)
    assert np.allclose(pts.colors[:, :3], O.CATEGORY_COLORS[0])                  # one light


def test_class_colours_are_the_classes_of_the_representatives(shadow_setup):
    smap = shadow_setup
    pts = O.overlay_points(_artifacts(shadow_map=smap), "shadow_photons", "class", 6000)
    assert pts.total == len(smap.rep_index) and len(pts) == 6000
    photon_rows = smap.rep_index[pts.indices]
    assert np.array_equal(pts.positions, smap.positions[photon_rows])
    # Classes from the photons at those points (every surface here faces +z, the light above).
    classes = smap.classify_photons(pts.positions.astype(np.float64),
                                    np.tile([0.0, 0.0, 1.0], (len(pts), 1)), 0)
    assert np.array_equal(classes, smap.rep_class[pts.indices])
    expected = {LIT: [1.0, 0.85, 0.1], UMBRA: [0.15, 0.35, 1.0], PENUMBRA: [1.0, 0.2, 0.6]}
    for cls, colour in expected.items():
        assert (classes == cls).sum() > 50, cls
        assert np.allclose(pts.colors[classes == cls, :3], colour, atol=1e-6)


def test_cache_colours_and_sizes():
    cache = _cache()
    art = _artifacts(cache=cache)
    pts = O.overlay_points(art, "cache", "radius", 10_000)
    assert len(pts) == len(cache) == pts.total
    assert np.array_equal(pts.positions, cache.positions[pts.indices].astype(np.float32))
    assert np.array_equal(pts.sizes, cache.radius[pts.indices].astype(np.float32))
    log_r = np.log(cache.radius)
    t = (log_r - log_r.min()) / (log_r.max() - log_r.min())
    assert np.abs(pts.colors[:, :3] - _matplotlib_viridis(t[pts.indices])).max() < 0.025
    smallest = int(np.nonzero(pts.indices == np.argmin(cache.radius))[0][0])
    assert np.allclose(pts.colors[smallest, :3], [0.2670, 0.0049, 0.3294], atol=1e-4)
    pts = O.overlay_points(art, "cache", "irradiance", 100)
    lum = cache.irradiance @ LUMA
    t = lum[pts.indices] / np.percentile(lum, 99)
    assert np.abs(pts.colors[:, :3] - _matplotlib_viridis(t)).max() < 0.025
    pts = O.overlay_points(art, "cache", "usage", 100)
    t = np.log1p(cache.usage[pts.indices]) / np.log1p(cache.usage.max())
    assert np.abs(pts.colors[:, :3] - _matplotlib_viridis(t)).max() < 0.025
    # Uniform importance: the kept records are the largest keys log(u) / 1.
    assert set(pts.indices.tolist()) == set(np.argsort(-_keys(np.ones(len(cache))))[:100].tolist())


def test_absent_maps_and_bad_arguments():
    empty = O.overlay_points(None, "photons")
    assert len(empty) == 0 and empty.total == 0 and empty.colors.shape == (0, 4)
    art = _artifacts(photon_map=_photon_map(100))
    assert O.overlay_points(art, "cache").total == 0
    assert O.overlay_count(art, "shadow_photons") == (0, 0)
    with pytest.raises(ValueError, match="unknown kind 'voxels'"):
        O.overlay_points(art, "voxels")
    with pytest.raises(ValueError, match="photons cannot be coloured by 'radius'"):
        O.overlay_points(art, "photons", "radius")


# -- Blender ----------------------------------------------------------------------------------
@pytest.fixture
def blender():
    bpy = pytest.importorskip("bpy")
    from lanterna.engine.blender import registration, session
    was = registration.is_registered()
    registration.register()
    yield bpy
    session.clear()
    if not was:
        registration.unregister()


def _scene1(bpy):
    from lanterna.engine.blender import seed_scenes
    scene = seed_scenes.build_scene1()
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.lanterna.samples = 1
    scene.lanterna.photons = 20_000
    return scene


def test_register_unregister_leaves_nothing(monkeypatch):
    bpy = pytest.importorskip("bpy")
    from lanterna.engine.blender import overlay_draw, registration
    names = ("LANTERNA_OT_bake", "LANTERNA_OT_clear", "LANTERNA_OT_save_maps",
             "LANTERNA_OT_load_maps", "LANTERNA_OT_export_report", "LANTERNA_VIEW3D_PT_maps")
    was = registration.is_registered()
    if was:
        registration.unregister()
    try:
        assert bpy.app.background
        registration.register()
        # Background mode: classes and settings, but no draw handler at all.
        assert not overlay_draw.is_registered()
        assert all(getattr(bpy.types, n, None) is not None for n in names)
        assert hasattr(bpy.types.Scene, "lanterna_overlay")
        registration.unregister()
        assert not any(hasattr(bpy.types, n) for n in names)
        assert not hasattr(bpy.types.Scene, "lanterna_overlay")
        # With a window (simulated): one POST_VIEW handler, removed by unregister.
        added, removed = [], []
        real_add = bpy.types.SpaceView3D.draw_handler_add
        real_remove = bpy.types.SpaceView3D.draw_handler_remove
        monkeypatch.setattr(overlay_draw, "_background", lambda: False)

        def add(*args):
            added.append(args[2:])
            return real_add(*args)

        def remove(handle, region):
            removed.append(region)
            return real_remove(handle, region)

        monkeypatch.setattr(bpy.types.SpaceView3D, "draw_handler_add", add, raising=False)
        monkeypatch.setattr(bpy.types.SpaceView3D, "draw_handler_remove", remove, raising=False)
        registration.register()
        assert overlay_draw.is_registered() and added == [('WINDOW', 'POST_VIEW')]
        registration.unregister()
        assert not overlay_draw.is_registered() and removed == ['WINDOW']
        assert not any(hasattr(bpy.types, n) for n in names)
    finally:
        if was:
            registration.register()


def test_batches_are_rebuilt_only_when_the_data_changes(blender):
    from lanterna.engine.blender import overlay_draw, session
    bpy = blender
    scene = bpy.context.scene
    settings = scene.lanterna_overlay
    settings.show, settings.show_photons, settings.show_cache = True, True, False
    settings.show_shadow_photons = False
    session.put(scene.name, _artifacts(photon_map=_photon_map(3000), cache=_cache()))
    made = []

    def fake_batch(points):
        made.append(len(points))
        return object()

    def frame():
        return [overlay_draw.entry(scene.name, r, fake_batch) for r in overlay_draw.requests(settings)]

    first = frame()
    assert made == [3000] and first[0]["drawn"] == 3000 and first[0]["total"] == 3000
    frame(); frame()
    assert made == [3000]                                   # redraws reuse the batch
    settings.point_size = 7.0
    settings.in_front = False
    frame()
    assert made == [3000]                                   # draw-time settings: no rebuild
    settings.max_points = 1000
    frame()
    assert made == [3000, 1000]
    settings.photons_color = 'RGB'
    frame()
    assert made == [3000, 1000, 1000]
    session.put(scene.name, _artifacts(photon_map=_photon_map(500), cache=_cache()))  # new maps
    frame()
    assert made[-1] == 500
    settings.show_cache = True
    frame()
    assert len(made) == 5 and made[-1] == len(_cache())
    counts = overlay_draw.counts(scene.name, settings)
    assert counts == {"photons": (500, 500), "shadow_photons": (0, 0), "cache": (500, 500)}
    settings.show = False
    assert overlay_draw.requests(settings) == []


def test_operators_bake_clear_save_load(blender, tmp_path):
    from lanterna.engine.artifacts import load_artifacts
    from lanterna.engine.blender import export, session
    bpy = blender
    scene = _scene1(bpy)
    assert bpy.ops.lanterna.bake() == {'FINISHED'}
    baked = session.get(scene.name)
    assert baked is not None and session.info(scene.name)["source"] == "bake"
    counts = baked.counts()
    assert counts["photons"] > 10_000 and counts["cache"] > 10
    assert baked.shadow_map is None or len(baked.shadow_map) == 0     # a point light only

    assert bpy.ops.lanterna.clear() == {'FINISHED'}
    assert session.get(scene.name) is None
    with pytest.raises(RuntimeError, match="has no maps to save: render or bake first"):
        bpy.ops.lanterna.save_maps()
    bpy.ops.lanterna.bake()
    baked = session.get(scene.name)
    # The .blend is not saved: the default path next to it does not exist yet.
    with pytest.raises(RuntimeError, match="The .blend file is not saved"):
        bpy.ops.lanterna.save_maps()
    with pytest.raises(RuntimeError, match="The .blend file is not saved"):
        bpy.ops.lanterna.load_maps()
    blend = tmp_path / "seed scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    assert bpy.ops.lanterna.save_maps() == {'FINISHED'}
    path = tmp_path / "seed scene_lanterna.npz"
    assert path.is_file() and session.info(scene.name)["path"] == str(path)

    bpy.ops.lanterna.clear()
    assert bpy.ops.lanterna.load_maps() == {'FINISHED'}
    loaded = session.get(scene.name)
    assert session.info(scene.name) == {"source": "load", "path": str(path)}
    for attr in ("photon_map", "cache"):
        a, b = getattr(baked, attr).to_arrays(), getattr(loaded, attr).to_arrays()
        for key in a:
            if key != "stats":
                assert np.array_equal(a[key], b[key]), (attr, key)
    # The loaded maps render the same picture as the baked ones.
    from lanterna.engine import pipeline
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lscene = export.export_scene(depsgraph, resolution=(32, 24))
    settings = export.export_settings(scene)
    assert np.array_equal(pipeline.render(lscene, settings, artifacts=loaded).image,
                          pipeline.render(lscene, settings, artifacts=baked).image)

    # Stale settings and another scene are refused, naming the reason; nothing is replaced.
    scene.lanterna.photons = 30_000
    with pytest.raises(RuntimeError, match="stale.*photons = 20000 in the file, 30000 now"):
        bpy.ops.lanterna.load_maps()
    assert session.get(scene.name) is loaded
    scene.lanterna.photons = 20_000
    bpy.data.objects["Half Wall"].location.x += 0.05          # the half wall moves 5 cm
    bpy.context.view_layer.update()
    with pytest.raises(RuntimeError, match="another scene.*the geometry"):
        bpy.ops.lanterna.load_maps()
    # An explicit path works as well, and a foreign file is refused.
    other = tmp_path / "other.npz"
    np.savez(other, positions=np.zeros((2, 3)))
    with pytest.raises(RuntimeError, match="not a Lanterna maps file"):
        bpy.ops.lanterna.load_maps(filepath=str(other))
    with pytest.raises(Exception, match="another scene"):
        load_artifacts(path, export.export_scene(bpy.context.evaluated_depsgraph_get(),
                                                 resolution=(32, 24)), settings)


def test_render_keeps_its_maps_and_the_report_exports(blender, tmp_path):
    from lanterna.engine.blender import render_engine, session
    bpy = blender
    scene = _scene1(bpy)
    render_engine.LAST_RENDER.clear()
    with pytest.raises(RuntimeError, match="No report to export"):
        bpy.ops.lanterna.export_report(filepath=str(tmp_path / "none.json"))
    bpy.ops.render.render()
    kept = session.get(scene.name)
    assert kept is not None and session.info(scene.name)["source"] == "render"
    assert kept.photon_map is not None and len(kept.photon_map) > 10_000
    out = tmp_path / "report.json"
    assert bpy.ops.lanterna.export_report(filepath=str(out)) == {'FINISHED'}
    data = json.loads(out.read_text())
    assert data["source"] == "render" and data["scene"] == scene.name
    assert data["report"]["stages"]["photons"]["requested"] == 20_000
    assert "camera" in data["report"]["stages"] and data["error"] is None
    assert [p.name for p in tmp_path.iterdir()] == ["report.json"]      # no temp file left


class _Layout:
    """A stand-in for ``UILayout`` that checks what a panel draws: every property exists on
    its data and every operator is registered."""

    def __init__(self, bpy, log):
        self.bpy, self.log = bpy, log
        self.active = True
        self.use_property_split = False

    def row(self, **_kw):
        return _Layout(self.bpy, self.log)

    column = box = row

    def prop(self, data, name, **_kw):
        assert name in data.bl_rna.properties.keys(), name
        self.log.append(("prop", name))

    def operator(self, idname, **_kw):
        family, name = idname.split(".")
        assert hasattr(getattr(self.bpy.ops, family), name), idname
        self.log.append(("operator", idname))

    def label(self, text="", **_kw):
        self.log.append(("label", text))


def test_sidebar_panel_draws_the_switches_counts_and_buttons(blender):
    from lanterna.engine.blender import session
    bpy = blender
    scene = bpy.context.scene
    panel_cls = bpy.types.LANTERNA_VIEW3D_PT_maps
    assert (panel_cls.bl_space_type, panel_cls.bl_region_type, panel_cls.bl_category) == \
        ('VIEW_3D', 'UI', 'Lanterna')
    session.put(scene.name, _artifacts(photon_map=_photon_map(1500)), source="bake")
    assert panel_cls.poll(bpy.context)
    log = []
    # The draw functions called with a stand-in ``self`` whose layout checks every item.
    fake = type("FakePanel", (), {"layout": _Layout(bpy, log)})()
    panel_cls.draw_header(fake, bpy.context)
    panel_cls.draw(fake, bpy.context)
    operators = {x[1] for x in log if x[0] == "operator"}
    assert operators == {"lanterna.bake", "lanterna.clear", "lanterna.save_maps",
                         "lanterna.load_maps", "lanterna.export_report"}
    props = {x[1] for x in log if x[0] == "prop"}
    assert {"show", "show_photons", "show_shadow_photons", "show_cache", "photons_color",
            "shadow_color", "cache_color", "point_size", "max_points"} <= props
    labels = [x[1] for x in log if x[0] == "label"]
    assert "1,500 / 1,500" in labels and "0 / 0" in labels and "Baked" in labels


def test_draw_callback_with_a_stand_in_gpu(blender, monkeypatch):
    """The draw path without a GPU (background mode has none): a stand-in ``gpu`` module
    records the shader, the batch's attributes and the state, which must be restored."""
    import sys
    import types
    from lanterna.engine.blender import overlay_draw, session
    bpy = blender
    calls = []

    class Batch:
        def draw(self, shader):
            calls.append(("draw", shader))

    def batch_for_shader(shader, kind, content):
        calls.append(("batch", shader, kind, {k: (v.dtype, v.shape) for k, v in content.items()}))
        return Batch()

    state = types.SimpleNamespace(
        point_size_set=lambda v: calls.append(("point_size", v)),
        blend_set=lambda v: calls.append(("blend", v)),
        depth_test_set=lambda v: calls.append(("depth", v)))
    fake_gpu = types.SimpleNamespace(
        state=state, shader=types.SimpleNamespace(from_builtin=lambda name: f"shader:{name}"))
    monkeypatch.setitem(sys.modules, "gpu", fake_gpu)
    monkeypatch.setitem(sys.modules, "gpu_extras.batch",
                        types.SimpleNamespace(batch_for_shader=batch_for_shader))
    monkeypatch.setattr(overlay_draw, "_shader", None)
    monkeypatch.setattr(overlay_draw, "_entries", {})
    scene = bpy.context.scene
    settings = scene.lanterna_overlay
    settings.show, settings.show_photons, settings.show_cache = True, True, True
    settings.point_size, settings.max_points, settings.in_front = 5.0, 700, True
    session.put(scene.name, _artifacts(photon_map=_photon_map(2000), cache=_cache(300)))
    space = types.SimpleNamespace(type='VIEW_3D', overlay=types.SimpleNamespace(show_overlays=True))
    context = types.SimpleNamespace(scene=scene, space_data=space)
    overlay_draw._draw(context)
    batches = [c for c in calls if c[0] == "batch"]
    assert [b[1:3] for b in batches] == [("shader:POINT_FLAT_COLOR", 'POINTS')] * 2
    assert batches[0][3] == {"pos": (np.float32, (700, 3)), "color": (np.float32, (700, 4))}
    assert batches[1][3] == {"pos": (np.float32, (300, 3)), "color": (np.float32, (300, 4))}
    assert ("point_size", 5.0) in calls and ("depth", 'NONE') in calls
    assert calls[-3:] == [("point_size", 1.0), ("blend", 'NONE'), ("depth", 'NONE')]
    assert sum(c[0] == "draw" for c in calls) == 2
    calls.clear()
    overlay_draw._draw(context)                          # the next frame: no new batch
    assert not any(c[0] == "batch" for c in calls) and sum(c[0] == "draw" for c in calls) == 2
    calls.clear()
    space.overlay.show_overlays = False                  # the viewport's overlays are off
    overlay_draw._draw(context)
    assert calls == []
