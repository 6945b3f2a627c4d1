"""Saving and loading the maps (engine/artifacts.py; no bpy).

The scene: a 10 x 10 m floor, a red wall, a 1 x 1 m plate at 1.5 m and a square area light at
3 m (so all three maps exist: photons, shadow photons with lit / umbra / penumbra, cache
records), rendered at 24 x 18 with 20k photons. What must hold:
* save -> load gives every array of every map back bit for bit, with its dtype, and the
  stats, settings, report and fingerprint;
* bake -> save -> load -> render(artifacts=loaded) gives exactly the picture of
  render(artifacts=baked), which is exactly the picture of a render that builds its maps;
* a file that does not fit is refused with an ``ArtifactError`` whose message names the file
  and the reason: missing, not an .npz, no Lanterna entries, pickled objects
  (``allow_pickle=False``), another format version, another Lanterna version, another scene
  (naming the part that differs), other map settings (naming each setting);
* settings that do not change the maps (samples, threads, ...) do not refuse a file;
* a failed save leaves the previous file whole and no temporary file.
"""
import dataclasses

import numpy as np
import pytest

from analytic import quad
from lanterna.engine import artifacts as A
from lanterna.engine import pipeline
from lanterna.engine.accel import Accelerator
from lanterna.engine.irradiance_cache import IrradianceCache
from lanterna.engine.photons import PhotonMap, build_photon_map
from lanterna.engine.settings import PRESETS, RenderSettings
from lanterna.engine.scene import AreaLight, Camera, Material, Scene
from lanterna.engine.shadow_photons import ShadowPhotonMap

SETTINGS = dict(samples=1, photons=20_000, gather_m=4, gather_n=12, seed=2)


def make_scene(shift=0.0, power=100.0):
    """``shift`` moves one vertex of the plate [m]; ``power`` is the light's [W]."""
    plate = quad([0, 0, 1.5], [0.5, 0, 0], [0, 0.5, 0])
    plate[0, 0, 0] += shift
    tris = np.concatenate([quad([0, 0, 0], [5, 0, 0], [0, 5, 0]),
                           quad([2.5, 0, 1.5], [0, 2.5, 0], [0, 0, 1.5]), plate])
    ids = np.array([0, 0, 1, 1, 0, 0], np.int32)
    m = np.eye(4)
    m[:3, 3] = [0, 0, 3.0]
    return Scene(triangles=tris, material_ids=ids,
                 materials=[Material("white", diffuse=0.7),
                            Material("red", diffuse=[0.7, 0.15, 0.1])],
                 camera=Camera.look_at([0, -5, 4], [0.5, 0, 0.5], resolution=(24, 18)),
                 lights=[AreaLight("Area", "SQUARE", m, 1.0, 1.0, [power] * 3)]).validate()


@pytest.fixture(scope="module")
def baked():
    return pipeline.bake(make_scene(), RenderSettings(**SETTINGS))


@pytest.fixture(scope="module")
def saved(baked, tmp_path_factory):
    path = tmp_path_factory.mktemp("maps") / "scene_lanterna.npz"
    A.save_artifacts(path, baked, scene_name="Scene")
    return path


def _refused(path, scene=None, **settings):
    with pytest.raises(A.ArtifactError) as info:
        A.load_artifacts(path, scene or make_scene(), RenderSettings(**{**SETTINGS, **settings}))
    return str(info.value)


def _rewrite(src, dst, **replace):
    """A copy of the .npz ``src`` with some entries replaced (or removed with None)."""
    with np.load(src, allow_pickle=False) as data:
        entries = {k: data[k] for k in data.files}
    for key, value in replace.items():
        key = key.replace("__", ".")
        if value is None:
            entries.pop(key, None)
        else:
            entries[key] = value
    np.savez(dst, **entries)
    return dst


# -- Round trip -------------------------------------------------------------------------------
def _assert_same_arrays(a: dict, b: dict):
    """Equal arrays with equal dtypes (``stats``, which holds the kd-tree's build time, is
    compared by the tests themselves)."""
    assert sorted(a) == sorted(b)
    for key in a:
        if key == "stats":
            continue
        x, y = np.asarray(a[key]), np.asarray(b[key])
        assert x.dtype == y.dtype and x.shape == y.shape, key
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), key


def test_bake_has_every_map(baked):
    counts = baked.counts()
    assert counts["photons"] > 10_000 and counts["shadow_photons"] >= 100_000
    assert counts["cache"] > 20
    assert set(baked.report) >= {"photons", "irradiance_cache", "shadow_photons"}
    classes = np.bincount(baked.shadow_map.rep_class, minlength=3)
    assert np.all(classes > 0), classes                 # lit, umbra and penumbra all present
    assert baked.fingerprint == A.scene_fingerprint(make_scene(), RenderSettings(**SETTINGS))


def test_save_load_round_trip_is_exact(baked, saved):
    loaded = A.load_artifacts(saved, make_scene(), RenderSettings(**SETTINGS))
    for attr in ("photon_map", "shadow_map", "cache"):
        _assert_same_arrays(getattr(baked, attr).to_arrays(), getattr(loaded, attr).to_arrays())
    for key in PhotonMap.ARRAY_FIELDS:            # the dtypes of the issue: float32 / 16, uint8
        assert getattr(loaded.photon_map, key).dtype == getattr(baked.photon_map, key).dtype
    assert loaded.photon_map.power.dtype == np.float32
    assert loaded.photon_map.incoming.dtype == np.float16
    smap, smap0 = loaded.shadow_map, baked.shadow_map
    assert smap.slices == smap0.slices and smap.rep_slices == smap0.rep_slices
    assert smap.radius == smap0.radius
    assert (smap.k, smap.margin, smap.disc, smap.penumbra_factor, smap.lookup_k) == \
        (smap0.k, smap0.margin, smap0.disc, smap0.penumbra_factor, smap0.lookup_k)
    assert smap.stats["lights"] == smap0.stats["lights"]       # int keys come back as ints
    stats0 = {k: v for k, v in baked.photon_map.stats.items() if k != "build_seconds"}
    assert {k: v for k, v in loaded.photon_map.stats.items() if k != "build_seconds"} == stats0
    assert loaded.settings == baked.settings and loaded.report == baked.report
    assert loaded.fingerprint == baked.fingerprint
    # The kd-trees are rebuilt: the loaded maps answer queries as the baked ones.
    pts = np.array([[0.1, 0.2, 0.0], [2.0, -1.0, 0.0], [0.0, 0.0, 1.5]])
    nrm = np.tile([0.0, 0.0, 1.0], (3, 1))
    assert np.array_equal(loaded.photon_map.irradiance(pts, nrm, k=20),
                          baked.photon_map.irradiance(pts, nrm, k=20))
    assert np.array_equal(smap.classify(pts, nrm, 0), smap0.classify(pts, nrm, 0))


def test_bake_save_load_render_gives_the_same_picture(baked, saved):
    settings = RenderSettings(**SETTINGS)
    loaded = A.load_artifacts(saved, make_scene(), settings)
    with_baked = pipeline.render(make_scene(), settings, artifacts=baked)
    with_loaded = pipeline.render(make_scene(), settings, artifacts=loaded)
    fresh = pipeline.render(make_scene(), settings)
    assert with_loaded.image.mean() > 0
    # Tolerance 0: the same maps and the same seed give the same picture bit for bit.
    assert np.array_equal(with_loaded.image, with_baked.image)
    assert np.array_equal(with_baked.image, fresh.image)
    assert with_loaded.report["stages"]["photons"].get("reused") is True


def test_maps_built_directly_round_trip(tmp_path):
    """Without the pipeline: a traced photon map (unbuilt and built), a cache of random records
    with gradients and usage, an empty shadow map."""
    scene = make_scene()
    accel = Accelerator(scene.triangles, threads=1)
    pmap = build_photon_map(scene, accel, 5000, seed=4)
    accel.close()
    rng = np.random.default_rng(1)
    cache = IrradianceCache()
    x = rng.uniform(-1, 1, (300, 3))
    nrm = rng.normal(size=(300, 3))
    cache.add(x, nrm, rng.uniform(0, 5, (300, 3)), rng.uniform(0.05, 0.5, 300),
              rng.normal(size=(300, 3, 3)), rng.normal(size=(300, 3, 3)))
    cache.interpolate(x[:50] + 0.01, cache.normals[:50], 0.3)        # some usage
    assert cache.usage.sum() > 0
    smap = ShadowPhotonMap(np.zeros((0, 3), np.float32), np.zeros((0, 2), np.int8),
                           np.zeros(0, np.uint8), np.zeros(0, np.uint8))
    art = A.Artifacts.create(scene, RenderSettings(**SETTINGS), pmap, smap, cache)
    path = tmp_path / "direct.npz"
    A.save_artifacts(path, art)
    back = A.load_artifacts(path, make_scene(), RenderSettings(**SETTINGS))
    _assert_same_arrays(pmap.to_arrays(), back.photon_map.to_arrays())
    _assert_same_arrays(cache.to_arrays(), back.cache.to_arrays())
    assert len(back.shadow_map) == 0 and back.shadow_map.slices == {}
    q, qn = x[:40] + 0.02, cache.normals[:40]
    e0 = cache.interpolate(q, qn, 0.3, count_usage=False)
    e1 = back.cache.interpolate(q, qn, 0.3, count_usage=False)
    for a, b in zip(e0, e1):
        assert np.array_equal(a, b)
    # An unbuilt map (not in Morton order) is put in order when loaded, like build() does.
    raw = PhotonMap(pmap.positions[::-1].copy(), pmap.power[::-1].copy(),
                    pmap.incoming[::-1].copy(), pmap.normals[::-1].copy(),
                    pmap.bounces[::-1].copy())
    again = PhotonMap.from_arrays(raw.to_arrays())
    assert np.array_equal(np.sort(again.positions, axis=0), np.sort(pmap.positions, axis=0))
    assert again._tree is not None


def test_a_map_may_be_absent(tmp_path):
    art = A.Artifacts.create(make_scene(), RenderSettings(**SETTINGS))
    A.save_artifacts(tmp_path / "none.npz", art)
    back = A.load_artifacts(tmp_path / "none.npz", make_scene(), RenderSettings(**SETTINGS))
    assert back.photon_map is None and back.shadow_map is None and back.cache is None


# -- Refusals ---------------------------------------------------------------------------------
def test_missing_file_is_refused(tmp_path):
    message = _refused(tmp_path / "nothing.npz")
    assert "nothing.npz" in message and "does not exist" in message


def test_a_file_that_is_not_npz_is_refused(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("photons? no.\n")
    message = _refused(text)
    assert "notes.npz" in message and "not a Lanterna maps file" in message \
        and "not a numpy .npz archive" in message
    single = tmp_path / "single.npz"
    with open(single, "wb") as fh:
        np.save(fh, np.arange(3))
    assert "not an .npz archive" in _refused(single)


def test_an_npz_without_lanterna_entries_is_refused(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, positions=np.zeros((4, 3)))
    message = _refused(path)
    assert "other.npz" in message and "not a Lanterna maps file" in message \
        and "'lanterna.format'" in message


def test_another_format_version_is_refused(saved, tmp_path):
    path = _rewrite(saved, tmp_path / "v2.npz", lanterna__format=np.array(A.FORMAT_VERSION + 1))
    message = _refused(path)
    assert f"format version {A.FORMAT_VERSION + 1}" in message
    assert f"reads version {A.FORMAT_VERSION}" in message


def test_another_lanterna_version_is_refused(saved, monkeypatch):
    monkeypatch.setattr(A, "LANTERNA_VERSION", "99.0.0")
    message = _refused(saved)
    assert f"written by Lanterna {A._read_version()}" in message and "99.0.0" in message


def test_version_is_read_from_the_manifest():
    import tomllib
    from pathlib import Path
    manifest = Path(A.__file__).resolve().parent.parent / "blender_manifest.toml"
    assert A.LANTERNA_VERSION == tomllib.loads(manifest.read_text())["version"]


def test_a_file_made_for_another_scene_is_refused(saved):
    message = _refused(saved, scene=make_scene(shift=0.01))       # one vertex moved 1 cm
    assert "another scene 'Scene'" in message and "the geometry" in message
    assert "lights" not in message and "stale" not in message
    message = _refused(saved, scene=make_scene(power=120.0))
    assert "another scene" in message and "the lights" in message and "geometry" not in message
    scene = make_scene()
    scene.camera = Camera.look_at([0, -5, 4], [0.5, 0, 0.5], resolution=(32, 18))
    assert "the camera" in _refused(saved, scene=scene)
    both = _refused(saved, scene=make_scene(shift=0.01), photons=30_000)
    assert "another scene" in both and "photons = 20000 in the file, 30000 now" in both


def test_stale_settings_are_refused_by_name(saved):
    message = _refused(saved, photons=30_000)
    assert "stale" in message and "photons = 20000 in the file, 30000 now" in message
    assert "seed" not in message
    message = _refused(saved, seed=5, cache_error=0.3)
    assert "seed = 2 in the file, 5 now" in message
    assert "cache_error = 0.2 in the file, 0.3 now" in message


def test_settings_that_do_not_change_the_maps_are_accepted(saved):
    other = dict(SETTINGS, samples=8, threads=1, light_samples=2, filter_width=2.0,
                 photon_lookups=3, cache_gradients=False, photon_filter="cone")
    loaded = A.load_artifacts(saved, make_scene(), RenderSettings(**other))
    assert loaded.photon_map is not None


def test_fingerprint_contents():
    scene = make_scene()
    base = RenderSettings(**SETTINGS)
    fp = A.scene_fingerprint(scene, base)
    assert len(fp) == 64 and int(fp, 16) >= 0
    for name in ("samples", "threads", "light_samples", "filter_width", "max_specular_depth"):
        value = getattr(base, name)
        changed = dataclasses.replace(base, **{name: value * 2 if value else 1})
        assert A.scene_fingerprint(scene, changed) == fp, name
    for name, value in (("mode", "photon-map"), ("bounces", 3), ("seed", 9), ("photons", 1000),
                        ("photon_k", 20), ("photon_radius", 0.5), ("indirect", "gather"),
                        ("gather_m", 6), ("gather_n", 20), ("gather_guided", 0.0),
                        ("cache_error", 0.4), ("shadow_photons", False),
                        ("force", "shadow_photons")):
        changed = dataclasses.replace(base, **{name: value})
        assert A.scene_fingerprint(scene, changed) != fp, name
    # Presets are resolved: the preset and its values spelled out are the same maps.
    assert A.scene_fingerprint(scene, RenderSettings(preset="preview")) == \
        A.scene_fingerprint(scene, RenderSettings(**PRESETS["preview"]))
    # Names do not count; a renamed light is the same scene.
    renamed = make_scene()
    renamed.lights[0].name = "Other name"
    assert A.scene_fingerprint(renamed, base) == fp


def test_pickled_objects_are_refused(saved, tmp_path, monkeypatch):
    # An entry holding a pickled object: np.load(allow_pickle=False) must not unpickle it.
    evil = np.empty(1, object)
    evil[0] = {"not": "an array"}
    path = _rewrite(saved, tmp_path / "pickled.npz", photons__positions=evil)
    message = _refused(path)
    assert "pickled.npz" in message and "pickled Python objects" in message
    # And the call itself says allow_pickle=False.
    calls = []
    real = np.load

    def spy(*args, **kwargs):
        calls.append(kwargs.get("allow_pickle", "default"))
        return real(*args, **kwargs)

    monkeypatch.setattr(A.np, "load", spy)
    A.load_artifacts(saved, make_scene(), RenderSettings(**SETTINGS))
    assert calls == [False]


def test_damaged_file_is_refused(saved, tmp_path):
    path = _rewrite(saved, tmp_path / "damaged.npz", photons__power=None)
    message = _refused(path)
    assert "damaged" in message and "photons" in message


def test_a_failed_save_leaves_the_old_file_whole(baked, saved, tmp_path, monkeypatch):
    path = tmp_path / "maps.npz"
    path.write_bytes(saved.read_bytes())
    before = path.read_bytes()

    def broken(fh, **entries):
        fh.write(b"PK half a file")
        raise OSError("disk full")

    monkeypatch.setattr(A.np, "savez_compressed", broken)
    with pytest.raises(OSError, match="disk full"):
        A.save_artifacts(path, baked)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps.npz"]
    with pytest.raises(A.ArtifactError, match="does not exist"):
        A.save_artifacts(tmp_path / "no" / "such" / "dir.npz", baked)


# -- What the arrays hold: checked on load, before any use (issue 22) ---------------------------
def _entry(path, key):
    with np.load(path, allow_pickle=False) as data:
        return data[key].copy()


def _changed(saved, key, change):
    value = _entry(saved, key)
    return change(value)


def _set(value, index, x):
    value = value.copy()
    value[index] = x
    return value


DAMAGES = {
    # entry, how it is damaged, what the refusal must say
    "photon power NaN": ("photons.power", lambda v: _set(v, (0, 0), np.nan),
                         "photon power is not finite"),
    "photon power inf": ("photons.power", lambda v: _set(v, (3, 1), np.inf),
                         "photon power is not finite"),
    "photon power 3e38": ("photons.power", lambda v: _set(v, (0, 2), 3e38),
                          "photon power lies outside [0, 1e+30] W"),
    "photon power -1e30": ("photons.power", lambda v: _set(v, (5, 0), -1e30),
                           "photon power lies outside [0, 1e+30] W"),
    "photon positions NaN": ("photons.positions", lambda v: _set(v, (1, 1), np.nan),
                             "photon positions are not finite"),
    "photon normals not unit": ("photons.normals", lambda v: v * np.float16(2),
                                "photon normals are not unit vectors"),
    "photon rows mismatched": ("photons.power", lambda v: v[:-1],
                               "'photons.power' has"),
    "photon positions as integers": ("photons.positions", lambda v: v.astype(np.int64),
                                     "'photons.positions' is int64, not float32"),
    "cache irradiance NaN": ("cache.irradiance", lambda v: _set(v, (0, 0), np.nan),
                             "record irradiance is not finite"),
    "cache gradients NaN": ("cache.trans_grad", lambda v: _set(v, (0, 0, 0), np.nan),
                            "record trans grad are not finite"),
    "cache negative radius": ("cache.radius", lambda v: _set(v, 0, -1.0),
                              "record radii are not finite and positive"),
    "cache cell fraction 0": ("cache.cell_fraction", lambda v: np.array(0.0),
                              "cell_fraction = 0.0 is outside"),
    "cache cell fraction 1e-300": ("cache.cell_fraction", lambda v: np.array(1e-300),
                                   "cell_fraction = 1e-300 is outside"),
    "cache channels": ("cache.channels", lambda v: np.array(4),
                       "channel count disagrees"),
    "shadow representative beyond": ("shadow_photons.rep_index",
                                     lambda v: _set(v, 0, np.int32(2 ** 30)),
                                     "representatives index photons that do not exist"),
    "shadow class 7": ("shadow_photons.rep_class", lambda v: _set(v, 0, 7),
                       "representative classes are not lit, umbra or penumbra"),
    "shadow slice beyond": ("shadow_photons.slices.values", lambda v: v + 10 ** 9,
                            "slices reach outside the arrays"),
}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_damaged_arrays_are_refused_with_the_entry_and_the_problem(saved, tmp_path, damage):
    """Each rule of the load's checks against one damage it exists for: without the rule the
    file loads (and renders NaN, negative radiance, hangs in the cache's grid, or fails deep
    in the renderer with a traceback), so each case fails if its rule is removed."""
    key, change, said = DAMAGES[damage]
    path = _rewrite(saved, tmp_path / "damaged.npz",
                    **{key.replace(".", "__", 1): _changed(saved, key, change)})
    message = _refused(path)
    assert "damaged.npz" in message and said in message, message


def test_the_report_s_counts_must_match_the_arrays(saved, tmp_path):
    from lanterna.engine.npzjson import pack_json, unpack_json

    report = unpack_json(_entry(saved, "lanterna.report"))
    report["photons"]["stored"] += 1
    path = _rewrite(saved, tmp_path / "counts.npz", lanterna__report=pack_json(report))
    assert "but the file's report says" in _refused(path)


def _write_npz_member(path, name, header_shape, payload: bytes, dtype="<f4"):
    """An .npz with one member whose .npy header promises ``header_shape`` but holds
    ``payload``: the size the zip declares and the header then disagree."""
    import io
    import zipfile

    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, {"descr": dtype, "fortran_order": False,
                                                  "shape": header_shape})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr(name + ".npy", buffer.getvalue() + payload)


def test_declared_sizes_are_checked_before_anything_is_decompressed(saved, tmp_path,
                                                                    monkeypatch):
    """An entry whose header promises 4e9 x 3 floats (45 GiB) is refused from its header and
    the zip's directory: the arrays are never read (np.load is not even called)."""
    import zipfile

    with zipfile.ZipFile(saved) as src:
        members = {i.filename: src.read(i) for i in src.infolist()}
    path = tmp_path / "huge.npz"
    import io
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False,
                                                  "shape": (4_000_000_000, 3)})
    members["photons.power.npy"] = header.getvalue() + b"\0" * 64
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as dst:
        for name, blob in members.items():
            dst.writestr(name, blob)
    loads = []
    monkeypatch.setattr(np, "load", lambda *a, **k: loads.append(a) or (_ for _ in ()).throw(
        AssertionError("np.load was called")))
    message = _refused(path)
    assert "'photons.power' declares" in message and "its header promises" in message
    assert loads == []
    # A consistent but huge file is refused against the memory budget, still unread.
    monkeypatch.setattr(A, "available_memory", lambda: 1 << 20)
    message = _refused(saved)
    assert "is refused: its arrays would need" in message and loads == []
