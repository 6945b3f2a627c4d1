"""Lanterna as a Blender extension: the zip Blender's own tool builds, installed, enabled,
rendering, disabled and removed again.

The linux-x64 zip is built by ``tools/build_extension.py`` (what ``make extension`` runs; wheels
come from the package index once and are reused from ``build/wheels``). The install test runs in
a separate Python process with its own ``BLENDER_USER_RESOURCES``, so the user's real Blender
configuration is never touched, and with every package that Blender does not ship hidden (the
development copy of ``lanterna`` among them): the add-on must run as
``bl_ext.user_default.lanterna`` on the bundled wheels alone. The same file is that process's
script (``python tests/test_extension.py SESSION ...``).
"""
from __future__ import annotations

import ast
import importlib.util
import json
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "bl_ext.user_default.lanterna"
# Distributions Blender itself ships besides bpy's own requirements (pip comes with Blender's
# Python); everything else installed in this environment is hidden from the session.
SHIPPED_WITH_BLENDER = {"pip", "setuptools"}


def _load_build_tool():
    spec = importlib.util.spec_from_file_location("build_extension",
                                                  ROOT / "tools" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("build_extension", module)
    spec.loader.exec_module(module)
    return module


be = _load_build_tool()


def _bpy_installed() -> bool:
    return importlib.util.find_spec("bpy") is not None


needs_bpy = pytest.mark.skipif(not _bpy_installed(), reason="bpy is not installed")


@pytest.fixture(scope="module")
def linux_zip(tmp_path_factory):
    """The linux-x64 extension zip, built and validated by Blender's blender_ext.py."""
    if not _bpy_installed():
        pytest.skip("bpy is not installed (blender_ext.py ships inside it)")
    work = tmp_path_factory.mktemp("extension")
    lines = []
    try:
        result = be.build(["linux-x64"], dist=work / "dist", stage_dir=work / "stage",
                          log=lines.append)
    except be.BuildError as exc:
        pytest.fail(f"building the extension failed: {exc}")
    info = result["linux-x64"]
    info["log"] = "\n".join(lines)
    return info


@pytest.fixture(scope="module")
def scene1_blend(tmp_path_factory):
    """The seed's Scene 1 saved as a .blend by the development copy (``lanterna scene``)."""
    path = tmp_path_factory.mktemp("scenes") / "scene1.blend"
    proc = subprocess.run([sys.executable, "-m", "lanterna.engine.blender.cli", "scene",
                           "scene1", "-o", str(path)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return path


# -- The manifest and the build tool ------------------------------------------------------------
def test_manifest_follows_the_strict_rules():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text(encoding="utf-8"))
    tagline = manifest["tagline"]
    assert len(tagline) <= 64 and tagline[-1].isalnum()
    assert manifest["license"] == ["SPDX:GPL-3.0-or-later"]
    # 4.2.13 to 5.3: the versions tested; 4.2.0 would install the cp313 wheels (see
    # tools/build_extension.py, MULTI_PYTHON_MIN).
    assert manifest["blender_version_min"] == "4.2.13"
    assert manifest["blender_version_max"] == "5.4.0"
    assert manifest["permissions"], "permissions must say why"
    for reason in manifest["permissions"].values():
        assert 0 < len(reason) <= 64 and reason[-1].isalnum()
    excluded = manifest["build"]["paths_exclude_pattern"]
    for pattern in ("/tests/", "/tools/", "/build/", "/dist/", "/out/", "__pycache__/"):
        assert pattern in excluded
    assert manifest["platforms"] == ["linux-x64", "windows-x64", "macos-arm64", "macos-x64"]
    pins = be.pinned_versions(ROOT / "pyproject.toml")
    assert pins["embreex"] == "4.4.0.post1" and pins["pykdtree"] == "1.4.3"
    assert "numpy" not in pins                            # one pin per Python: markers
    wheels = be.manifest_wheels(manifest, pins)           # raises on any inconsistency
    assert {w.name for w in wheels} == {"embreex", "pykdtree"}
    # Both Pythons in every platform's zip: 3.11 (Blender 4.2 to 5.0), 3.13 (5.1 to 5.3).
    assert {w.python for w in wheels} == {"cp311", "cp313"}
    assert be.pythons_of_range(manifest) == {"3.11": ["4.2", "4.3", "4.4", "4.5", "5.0"],
                                             "3.13": ["5.1", "5.2", "5.3"]}
    assert sorted(w.platform for w in wheels) == sorted(4 * manifest["platforms"])
    assert "numpy" not in {w.name for w in wheels}         # Blender ships numpy


def _manifest(**changes):
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text(encoding="utf-8"))
    manifest.update(changes)
    return manifest


def test_build_tool_refuses_bad_manifests_with_a_message():
    pins = be.pinned_versions(ROOT / "pyproject.toml")
    wheels = _manifest()["wheels"]
    cases = [
        (_manifest(wheels=[w.replace("pykdtree-1.4.3", "pykdtree-1.4.2") for w in wheels]),
         "pyproject.toml pins 1.4.3"),
        (_manifest(wheels=[w for w in wheels if "win_amd64" not in w or "pykdtree" in w]),
         "no cp311 wheel of embreex for windows-x64"),
        (_manifest(wheels=wheels + ["./wheels/scipy-1.17.1-cp311-cp311-win_amd64.whl"]),
         "no cp311 wheel of scipy for linux-x64"),
        (_manifest(wheels=wheels + [wheels[0]]), "are both embreex for linux-x64"),
        (_manifest(wheels=wheels + ["./wheels/Pillow-9.0.0-cp311-cp311-win_amd64.whl"]),
         "pyproject.toml pins 13.0.0"),
        (_manifest(wheels=wheels + ["./wheels/requests-2.0-py3-none-any.whl"]),
         "not one of Blender's platforms"),
        (_manifest(wheels=wheels + ["wheels/x.whl"]), "./wheels/<file>.whl"),
        (_manifest(platforms=["linux-x64", "amiga-68k"]), "unknown platform(s) 'amiga-68k'"),
        (_manifest(platforms=["linux-x64"]), "which 'platforms' does not list"),
        # The Pythons follow the version range: each admitted Blender's, and no other.
        (_manifest(wheels=[w for w in wheels if "cp313" not in w]),
         "no cp313 wheels, but the version range admits Blender 5.1, 5.2, 5.3"),
        (_manifest(blender_version_max="5.1.0"),
         "cp313 wheels, but no Blender the version range admits runs Python 3.13"),
        (_manifest(blender_version_min="5.1.0"),
         "cp311 wheels, but no Blender the version range admits runs Python 3.11"),
        (_manifest(blender_version_max="five"), "blender_version_max must be a version"),
        (_manifest(blender_version_min="4.2.0"),
         "wheels for Python 3.11 and 3.13 in one zip need blender_version_min >= 4.2.13"),
        # numpy is pinned per Python (an environment marker): never bundled.
        (_manifest(wheels=wheels + ["./wheels/numpy-2.5.5-cp313-cp313-win_amd64.whl"]),
         "numpy is not a pinned dependency (name==version, without an environment marker)"),
    ]
    for manifest, expected in cases:
        with pytest.raises(be.BuildError) as info:
            be.manifest_wheels(manifest, pins)
        assert expected in str(info.value), str(info.value)


def test_build_tool_bad_arguments_and_missing_or_damaged_wheels(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        be.main(["--platform", "amiga-68k"])
    assert info.value.code == 2
    assert "invalid choice: 'amiga-68k'" in capsys.readouterr().err

    wheel = be.parse_wheel(_manifest()["wheels"][0])
    with pytest.raises(be.BuildError, match="not in .* and --offline was given"):
        be.fetch_wheel(wheel, tmp_path, offline=True)
    (tmp_path / wheel.filename).write_bytes(b"not a zip")
    with pytest.raises(be.BuildError, match="damaged wheel"):
        be.fetch_wheel(wheel, tmp_path, offline=True)


def test_wheel_platform_tags():
    assert be.blender_platform("manylinux_2_28_x86_64") == "linux-x64"
    assert be.blender_platform("manylinux2014_x86_64") == "linux-x64"
    assert be.blender_platform("win_amd64") == "windows-x64"
    assert be.blender_platform("macosx_14_0_arm64") == "macos-arm64"
    assert be.blender_platform("macosx_10_9_x86_64") == "macos-x64"
    assert be.blender_platform("manylinux_2_28_aarch64") is None
    assert be.blender_platform("win32") is None


# -- The zip ----------------------------------------------------------------------------------
def test_linux_zip_is_valid_and_holds_the_addon_and_its_wheels(linux_zip):
    path = linux_zip["zip"]
    assert path.name == "lanterna-0.1.0-linux_x64.zip"
    assert linux_zip["validate"].startswith("Success parsing TOML")
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        for required in ("blender_manifest.toml", "__init__.py", "engine/pipeline.py",
                         "engine/blender/render_engine.py", "ui/panels.py", "ops/bake.py"):
            assert required in names
        top = {n.split("/")[0] for n in names}
        assert not top & {"tests", "tools", "docs", "bench", "out", "build", "dist", "Makefile",
                          "pyproject.toml", ".gitignore", ".ci"}, sorted(top)
        # No benchmark or calibration module rides along anywhere (issue 20): the zip's
        # Python files are the add-on's, none of bench/'s names.
        bench_names = {p.name for p in (ROOT / "bench").glob("*.py")} - {"__init__.py"}
        benchmarks = [n for n in names if n.endswith(".py") and (
            n.split("/")[-1] in bench_names or "bench" in n.split("/")[-1]
            or "calibrat" in n)]
        assert benchmarks == [], benchmarks
        assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
        wheels = sorted(n for n in names if n.startswith("wheels/"))
        assert wheels == sorted(f"wheels/{w}" for w in linux_zip["wheels"])
        assert [tuple(w.split("-")[i] for i in (0, 2)) for w in wheels] == [
            ("wheels/embreex", "cp311"), ("wheels/embreex", "cp313"),
            ("wheels/pykdtree", "cp311"), ("wheels/pykdtree", "cp313")]
        for name in wheels:                   # unmodified: byte for byte the downloaded file
            assert zf.read(name) == (be.DEFAULT_WHEELS / name.split("/", 1)[1]).read_bytes()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    assert manifest["build"]["generated"]["platforms"] == ["linux-x64"]
    assert sorted(manifest["build"]["generated"]["wheels"]) == [f"./{w}" for w in wheels]


def _absolute_lanterna_imports(source: str, filename: str) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Import):
            found += [f"{filename}:{node.lineno}: import {a.name}" for a in node.names
                      if a.name.split(".")[0] == "lanterna"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "lanterna":
            found.append(f"{filename}:{node.lineno}: from {node.module} import ...")
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str) \
                and node.args[0].value.split(".")[0] == "lanterna" \
                and getattr(node.func, "id", getattr(node.func, "attr", "")) in (
                    "__import__", "import_module"):
            found.append(f"{filename}:{node.lineno}: imports {node.args[0].value!r} by name")
    return found


def test_addon_code_imports_itself_only_relatively(linux_zip):
    with zipfile.ZipFile(linux_zip["zip"]) as zf:
        sources = {n: zf.read(n).decode("utf-8") for n in zf.namelist() if n.endswith(".py")}
    assert len(sources) > 20
    bad = [hit for name, text in sorted(sources.items())
           for hit in _absolute_lanterna_imports(text, name)]
    assert bad == []
    # The check itself sees each form.
    probe = "import lanterna\nfrom lanterna.engine import x\n__import__('lanterna.engine')\n"
    assert len(_absolute_lanterna_imports(probe, "probe.py")) == 3


# -- Install, enable, render, disable, remove -------------------------------------------------
@needs_bpy
def test_install_enable_render_disable_remove(linux_zip, scene1_blend, tmp_path):
    user = tmp_path / "blender-user"
    out = tmp_path / "out"
    out.mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user), PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([sys.executable, __file__, "SESSION", str(linux_zip["zip"]),
                           str(scene1_blend), str(out)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=600)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert "Traceback" not in log and "Python script error" not in log, log
    r = json.loads((out / "session.json").read_text())

    assert r["install"] == ["FINISHED"] and r["enabled_after_install"] is True
    assert r["package_dir"].startswith(str(user)) and r["engine_available"] is True
    # Wheels went into the user extension site-packages, and the add-on used them.
    assert r["ext_site_packages"].startswith(str(user))
    for module in ("embreex", "pykdtree"):
        assert r["modules_from"][module].startswith(r["ext_site_packages"]), r["modules_from"]
    assert r["bundled_modules_used"] == ["embreex", "pykdtree"]
    # One zip for every Python: Blender extracted only its own Python's wheels of the two.
    tag = "cp%d%d" % sys.version_info[:2]
    assert sum(tag in w for w in linux_zip["wheels"]) == 2 < len(linux_zip["wheels"])
    assert sorted(r["wheels_extracted"]) == ["embreex-4.4.0.post1", "pykdtree-1.4.3"]
    assert all(t.startswith(f"{tag}-{tag}-") for tags in r["wheels_extracted"].values()
               for t in tags), r["wheels_extracted"]
    ext_modules = [f for f in r["extension_modules_extracted"] if "cpython-" in f]
    assert ext_modules and all(f"cpython-{tag[2:]}" in f for f in ext_modules), ext_modules
    # The add-on's own modules touched no deprecated Blender API (Light/World/Material.use_nodes
    # in 5.x ...): every DeprecationWarning attributed to them, through install and render.
    assert r["deprecations_from_addon"] == []
    assert r["hidden_imports_attempted"] == []     # no OpenEXR, Pillow, scipy, dev lanterna
    assert r["modules_of_addon"] and all(m.startswith(PACKAGE) for m in r["modules_of_addon"])

    # The render: Scene 1 through bpy.ops.render.render(), as F12 does.
    assert r["engine"] == "LANTERNA" and r["render"] == ["FINISHED"]
    assert r["last_render_error"] is None
    assert r["plan"].startswith("Plan: direct, photons")
    from lanterna.engine import imageio

    channels = imageio.read_exr(out / "f12.exr")
    image = np.stack([channels[c] for c in "RGB"], axis=-1)
    expected = np.load(out / "pipeline.npy")
    assert image.shape == expected.shape == (120, 160, 3)
    np.testing.assert_allclose(image, expected, rtol=1e-5, atol=1e-7)
    assert np.isfinite(image).all() and image.mean() > 1e-3
    # The left of the half wall is lit only by bounced light: indirect light was rendered.
    assert image[60:, :40].mean() > 1e-4

    # Nothing written into the add-on's own folder (Python's bytecode cache is off here).
    assert r["package_files_changed"] == []
    # Disabled: nothing of Lanterna stays registered; removed: files and wheels gone. (While
    # enabled, the same check finds the engine, the properties, panels and the import menu.)
    enabled = r["registered_while_enabled"]
    for item in ("render engine LANTERNA", "Scene.lanterna", "Material.lanterna",
                 "ViewLayer.lanterna_passes", "bpy.types.LANTERNA_RENDER_PT_sampling",
                 "COMPAT_ENGINES of RENDER_PT_format"):
        assert item in enabled, enabled
    assert [e for e in enabled if e.startswith("File > Import entry")], enabled
    assert r["disable"] == ["FINISHED"]
    assert r["left_registered_after_disable"] == []
    assert r["uninstall"] == ["FINISHED"]
    assert r["left_registered_after_uninstall"] == []
    assert r["package_dir_exists_after_uninstall"] is False
    assert r["addon_in_preferences_after_uninstall"] is False
    assert r["wheels_left_after_uninstall"] == []


# -- The session (runs in its own process) ------------------------------------------------------
def _not_shipped_by_blender() -> set[str]:
    """Top-level import names of every installed distribution that is neither bpy, nor one of
    bpy's requirements (what Blender's own Python ships), nor pip/setuptools."""
    import importlib.metadata as md
    import re

    def norm(name):
        return re.sub(r"[-_.]+", "-", name).lower()

    allowed, todo = set(), ["bpy", *SHIPPED_WITH_BLENDER]
    while todo:
        name = norm(todo.pop())
        if name in allowed:
            continue
        allowed.add(name)
        try:
            requires = md.requires(name) or []
        except md.PackageNotFoundError:
            continue
        todo += [re.match(r"[A-Za-z0-9_.\-]+", r).group(0) for r in requires if "extra ==" not in r]
    hidden = {"lanterna"}
    for dist in md.distributions():
        if norm(dist.metadata["Name"] or "") in allowed:
            continue
        top = (dist.read_text("top_level.txt") or "").split()
        for f in dist.files or ():
            head = f.parts[0]
            if head.endswith((".dist-info", ".egg-info", ".libs", ".pth", ".data")) \
                    or head in ("..", "__pycache__") or head.startswith("__editable__"):
                continue
            top.append(head.split(".")[0])
        hidden.update(t for t in top if t)
    return hidden


def _registered_leftovers(bpy) -> list[str]:
    """Everything Lanterna could leave behind in Blender after being disabled."""
    left = [f"bpy.types.{n}" for n in dir(bpy.types) if "lanterna" in n.lower()]
    for owner in ("Scene", "Material", "Light", "World", "ViewLayer", "Object"):
        left += [f"{owner}.{a}" for a in dir(getattr(bpy.types, owner)) if "lanterna" in a]
    if _engine_available(bpy):
        left.append("render engine LANTERNA")
    left += [f"RenderEngine {e.__name__}" for e in bpy.types.RenderEngine.__subclasses__()
             if getattr(e, "bl_idname", "") == "LANTERNA" and getattr(e, "is_registered", False)]
    for panel in bpy.types.Panel.__subclasses__():
        if getattr(panel, "is_registered", False) and "LANTERNA" in (
                getattr(panel, "COMPAT_ENGINES", None) or ()):
            left.append(f"COMPAT_ENGINES of {panel.__name__}")
    menu = bpy.types.TOPBAR_MT_file_import
    for fn in getattr(menu.draw, "_draw_funcs", ()):
        if getattr(fn, "__module__", "").startswith(PACKAGE):
            left.append(f"File > Import entry {fn.__module__}.{fn.__name__}")
    for name in dir(bpy.app.handlers):
        handlers = getattr(bpy.app.handlers, name)
        if isinstance(handlers, list):
            left += [f"bpy.app.handlers.{name}: {h}" for h in handlers
                     if getattr(h, "__module__", "").startswith(PACKAGE)]
    return left


def _engine_available(bpy) -> bool:
    render = bpy.context.scene.render
    old = render.engine
    try:
        render.engine = "LANTERNA"
    except TypeError:
        return False
    render.engine = old
    return True


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*"))}


def _session(zip_path: str, blend: str, out: str) -> None:
    import importlib.abc
    import importlib.machinery

    user = os.environ["BLENDER_USER_RESOURCES"]
    ext_site = os.path.join(user, "extensions", ".local", "lib",
                            "python{}.{}".format(*sys.version_info[:2]), "site-packages")
    hidden = _not_shipped_by_blender()
    attempted = []

    class OnlyBundled(importlib.abc.MetaPathFinder):
        """Hidden packages resolve only from the extensions' wheel site-packages."""

        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] not in hidden or "." in name:
                return None
            spec = importlib.machinery.PathFinder.find_spec(name, [ext_site])
            if spec is None:
                attempted.append(name)
                raise ModuleNotFoundError(f"No module named {name!r} (not shipped by Blender, "
                                          "not bundled)", name=name)
            return spec

    sys.meta_path.insert(0, OnlyBundled())

    # Every DeprecationWarning attributed to the add-on's own modules, recorded (Blender's own
    # warnings pass as usual).
    import warnings

    deprecations = []
    show = warnings.showwarning

    def record(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, DeprecationWarning) and "lanterna" in filename:
            deprecations.append(f"{filename}:{lineno}: {message}")
        return show(message, category, filename, lineno, file, line)

    warnings.showwarning = record
    warnings.filterwarnings("always", category=DeprecationWarning,
                            module=PACKAGE.replace(".", r"\."))

    import bpy

    r = {"blender": bpy.app.version_string}
    r["install"] = sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))
    prefs = bpy.context.preferences
    r["enabled_after_install"] = PACKAGE in prefs.addons
    repo = next(repo for repo in prefs.extensions.repos if repo.module == "user_default")
    package_dir = Path(repo.directory) / "lanterna"
    r["package_dir"] = str(package_dir)
    r["ext_site_packages"] = ext_site
    r["registered_while_enabled"] = _registered_leftovers(bpy)
    before = _snapshot(package_dir)

    bpy.ops.wm.open_mainfile(filepath=blend)          # keeps the preferences and add-ons
    scene = bpy.context.scene
    r["engine_available"] = _engine_available(bpy)
    r["engine"] = scene.render.engine
    scene.render.resolution_percentage = 25                       # 160 x 120
    scene.lanterna.samples = 4
    scene.lanterna.photons = 20_000
    scene.lanterna.seed = 7
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGB"
    scene.render.filepath = os.path.join(out, "f12.exr")
    scene.render.use_file_extension = False
    r["render"] = sorted(bpy.ops.render.render(write_still=True))
    engine_mod = sys.modules[PACKAGE + ".engine.blender.render_engine"]
    last = engine_mod.LAST_RENDER
    r["last_render_error"] = last["error"]
    r["plan"] = last["report"]["plan"]["summary"]
    export = sys.modules[PACKAGE + ".engine.blender.export"]
    pipeline = sys.modules[PACKAGE + ".engine.pipeline"]
    lscene = export.export_scene(bpy.context.evaluated_depsgraph_get(), resolution=(160, 120))
    np.save(os.path.join(out, "pipeline.npy"),
            pipeline.render(lscene, export.export_settings(scene)).image)
    r["wheels_extracted"] = {      # each extracted wheel's tags, from its .dist-info/WHEEL
        p.name[:-len(".dist-info")]: [line.split(":", 1)[1].strip() for line in
                                      (p / "WHEEL").read_text().splitlines()
                                      if line.startswith("Tag:")]
        for p in Path(ext_site).glob("*.dist-info")}
    r["extension_modules_extracted"] = sorted(
        str(p.relative_to(ext_site)) for p in Path(ext_site).rglob("*")
        if p.suffix in (".so", ".pyd"))
    r["modules_from"] = {m: getattr(sys.modules.get(m), "__file__", None)
                         for m in ("embreex", "pykdtree")}
    r["bundled_modules_used"] = sorted({m.split(".")[0] for m, mod in list(sys.modules.items())
                                        if (getattr(mod, "__file__", None) or "").startswith(
                                            ext_site)})
    r["modules_of_addon"] = sorted(m for m in sys.modules if "lanterna" in m
                                   and not m.startswith("__editable__"))
    after = _snapshot(package_dir)
    r["package_files_changed"] = sorted(k for k in before.keys() | after.keys()
                                        if before.get(k) != after.get(k))

    r["disable"] = sorted(bpy.ops.preferences.addon_disable(module=PACKAGE))
    r["left_registered_after_disable"] = _registered_leftovers(bpy)
    r["uninstall"] = sorted(bpy.ops.extensions.package_uninstall(
        repo_directory=repo.directory, pkg_id="lanterna"))
    r["left_registered_after_uninstall"] = _registered_leftovers(bpy)
    r["package_dir_exists_after_uninstall"] = package_dir.exists()
    r["addon_in_preferences_after_uninstall"] = PACKAGE in prefs.addons
    r["wheels_left_after_uninstall"] = sorted(
        p.name for p in Path(ext_site).glob("*") if p.name.split("-")[0].split(".")[0]
        in ("embreex", "pykdtree")) if os.path.isdir(ext_site) else []
    r["hidden_imports_attempted"] = sorted(set(attempted))
    r["deprecations_from_addon"] = deprecations
    Path(out, "session.json").write_text(json.dumps(r, indent=1))


if __name__ == "__main__" and sys.argv[1:2] == ["SESSION"]:
    _session(*sys.argv[2:5])
    # bpy 4.2/4.5 as a module cannot exit normally after an add-on registered properties with
    # update callbacks; compat.exit_process ends the process past that (no bpy import needed).
    spec = importlib.util.spec_from_file_location("lanterna_compat",
                                                  ROOT / "engine" / "blender" / "compat.py")
    compat = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(compat)
    compat.exit_process(0)
