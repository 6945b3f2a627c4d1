"""Lanterna on Windows and macOS, checked from Linux (issue 19).

* The peak-memory figure of the report in each platform's unit (``engine/memory.py``):
  ``ru_maxrss`` is KiB on Linux, bytes on macOS; Windows has no ``resource`` module and answers
  through ``K32GetProcessMemoryInfo``; where nothing can tell, the report says ``null`` and why.
* A render in a process that has no ``resource``, ``fcntl`` or ``termios`` (what Windows lacks)
  and starts its workers with ``spawn`` (the only start method on Windows, the default on
  macOS): the add-on imports, registers with bpy and renders a small scene to a finite EXR.
  Before the fix ``engine/pipeline.py`` imported ``resource`` at module level and the first
  render of the Windows zip failed.
"""
import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

if __name__ != "__main__":          # the SESSION process must import Lanterna itself, later
    from lanterna.engine import memory

ROOT = Path(__file__).resolve().parents[1]
BLOCKED = ("resource", "fcntl", "termios")


# -- The memory figure's units, branch by branch -------------------------------------------------
def _fake_resource(maxrss):
    usage = types.SimpleNamespace(ru_maxrss=maxrss)
    return types.SimpleNamespace(RUSAGE_SELF=0, getrusage=lambda _who: usage)


@pytest.mark.parametrize("platform, maxrss, megabytes", [
    ("linux", 2 * 1024 * 1024, 2048.0),          # KiB: 2 GiB
    ("freebsd14", 3 * 1024, 3.0),               # KiB too
    ("darwin", 5 * 1024 * 1024, 5.0),            # bytes: 5 MiB (read as KiB: 5 GiB, 1024x off)
])
def test_maxrss_is_read_in_the_platforms_unit(monkeypatch, platform, maxrss, megabytes):
    monkeypatch.setitem(sys.modules, "resource", _fake_resource(maxrss))
    peak = memory.peak_memory(platform)
    assert peak.megabytes == pytest.approx(megabytes) and peak.source == "getrusage"
    assert peak.to_report() == {"peak_memory_mb": round(megabytes, 1)}


def test_windows_reads_the_peak_working_set(monkeypatch):
    monkeypatch.setitem(sys.modules, "resource", None)          # as on Windows: no module
    monkeypatch.setattr(memory, "windows_peak_bytes", lambda: 7.5 * 1024 * 1024)
    peak = memory.peak_memory("win32")
    assert peak.megabytes == pytest.approx(7.5) and peak.source == "K32GetProcessMemoryInfo"


def test_unknown_peak_memory_is_null_with_the_reason(monkeypatch):
    monkeypatch.setitem(sys.modules, "resource", None)
    peak = memory.peak_memory("linux")
    assert peak.megabytes is None and "linux" in peak.reason
    assert peak.to_report() == {"peak_memory_mb": None, "peak_memory_note": peak.reason}

    def refuse():
        raise OSError(5, "access denied")

    monkeypatch.setattr(memory, "windows_peak_bytes", refuse)
    peak = memory.peak_memory("win32")
    assert peak.megabytes is None and "access denied" in peak.reason


def test_this_platforms_figure_is_plausible():
    peak = memory.peak_memory()
    # numpy, embreex and the tests are loaded: more than 20 MiB, less than the machine.
    assert peak.megabytes is not None and 20 < peak.megabytes < 1 << 20, peak


# -- A render without the POSIX-only modules, workers started by spawn ---------------------------
def _has_bpy() -> bool:
    import importlib.util
    return importlib.util.find_spec("bpy") is not None


@pytest.mark.skipif(not _has_bpy(), reason="needs the bpy module")
def test_addon_renders_without_posix_modules_under_spawn(tmp_path):
    out = tmp_path / "render.exr"
    proc = subprocess.run([sys.executable, __file__, "SESSION", str(out)], capture_output=True,
                          text=True, cwd=tmp_path, timeout=600,
                          env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert "Traceback" not in log, log
    r = json.loads((tmp_path / "session.json").read_text())
    assert r["start_method"] == "spawn"
    assert r["blocked_still_loaded"] == []
    assert r["render"] == ["FINISHED"] and r["error"] is None, r
    assert r["lanterna_modules"] > 10
    from lanterna.engine import imageio

    channels = imageio.read_exr(out)
    image = np.stack([channels[c] for c in "RGB"], axis=-1)
    assert image.shape == (24, 32, 3)
    assert np.isfinite(image).all() and image.mean() > 1e-3
    # The report's memory figure: a number here, through the same code as on any platform.
    assert r["peak_memory_mb"] is None or r["peak_memory_mb"] > 10


def _session(exr_path: str) -> None:
    import importlib.abc
    import multiprocessing

    multiprocessing.set_start_method("spawn", force=True)
    import bpy                       # Blender's own modules first: they may use what we block

    attempts = []

    class NoPosixOnly(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name in BLOCKED:
                attempts.append(name)
                raise ModuleNotFoundError(f"No module named {name!r} (blocked: not on Windows)",
                                          name=name)
            return None

    for name in BLOCKED:
        sys.modules.pop(name, None)
    sys.meta_path.insert(0, NoPosixOnly())
    assert not [m for m in sys.modules if m.startswith("lanterna")]

    from lanterna.engine.blender import compat, registration, render_engine

    registration.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -6.0, 1.5)
    cam.rotation_euler = (1.45, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    for name, corners in (("Floor", [(-4, -3, 0), (4, -3, 0), (4, 3, 0), (-4, 3, 0)]),
                          ("Wall", [(-4, 3, 0), (4, 3, 0), (4, 3, 4), (-4, 3, 4)])):
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata(corners, [], [(0, 1, 2, 3)])
        obj = bpy.data.objects.new(name, mesh)
        scene.collection.objects.link(obj)
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", 'POINT'))
    light.data.energy = 300.0
    light.location = (0.0, 1.0, 2.0)
    scene.collection.objects.link(light)
    render = scene.render
    render.engine = "LANTERNA"
    render.resolution_x, render.resolution_y, render.resolution_percentage = 32, 24, 100
    scene.lanterna.samples, scene.lanterna.photons, scene.lanterna.seed = 2, 20_000, 1
    image_settings = render.image_settings
    image_settings.file_format, image_settings.color_depth = 'OPEN_EXR', '32'
    image_settings.color_mode = 'RGB'
    render.filepath = exr_path
    render.use_file_extension = False
    result = sorted(bpy.ops.render.render(write_still=True))
    last = render_engine.LAST_RENDER
    r = {"start_method": multiprocessing.get_start_method(), "render": result,
         "error": last.get("error"),
         "peak_memory_mb": (last.get("report") or {}).get("peak_memory_mb"),
         "blocked_still_loaded": sorted(m for m in BLOCKED if sys.modules.get(m) is not None),
         "blocked_attempts": sorted(set(attempts)),
         "lanterna_modules": len([m for m in sys.modules if m.startswith("lanterna")])}
    Path(exr_path).with_name("session.json").write_text(json.dumps(r))
    registration.unregister()
    compat.exit_process(0)


if __name__ == "__main__" and sys.argv[1:2] == ["SESSION"]:
    _session(sys.argv[2])


# -- Available memory and the user's cache folder, branch by branch ------------------------------
def test_available_memory_on_windows_and_where_unknown(monkeypatch):
    monkeypatch.setattr(memory, "windows_available_bytes", lambda: 3 << 30)
    assert memory.available_memory("win32") == 3 << 30

    def refuse():
        raise OSError(5, "access denied")

    monkeypatch.setattr(memory, "windows_available_bytes", refuse)
    assert memory.available_memory("win32") is None
    here = memory.available_memory()
    assert here is not None and here > 1 << 20


@pytest.mark.parametrize("platform, parts", [
    ("win32", ("Local", "lanterna", "rates.json")),
    ("darwin", ("Library", "Caches", "lanterna", "rates.json")),
    ("linux", ("cache", "lanterna", "rates.json")),
])
def test_calibrated_rates_go_to_the_platforms_cache_folder(monkeypatch, tmp_path, platform, parts):
    from lanterna.engine import estimate

    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "AppData" / "Local"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    path = estimate.user_rates_path(platform)
    assert path.parts[-len(parts):] == parts and str(path).startswith(str(tmp_path))
