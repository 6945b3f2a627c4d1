#!/usr/bin/env python3
"""Build Lanterna's Blender extension: one installable zip per platform, with Blender's own tool.

    python tools/build_extension.py [--platform linux-x64 ...] [--dist DIR] [--wheels DIR]
                                    [--stage DIR] [--offline] [--blender-ext PATH]

What it does (``make extension`` runs it with the defaults):

1. Reads ``blender_manifest.toml``: its ``wheels`` (the exact wheel files the extension bundles,
   ``./wheels/<file>.whl``), ``platforms`` and Blender version range. Every wheel must be a
   dependency of ``pyproject.toml`` pinned to one version for every Python (``name==version``
   without an environment marker) at that version; every platform must have a wheel of every
   bundled dependency for every Python; and the Pythons must be those of the Blender series
   the range admits (``BLENDER_PYTHON``: 3.11 for 4.2 to 5.0, 3.13 for 5.1 to 5.3), no more,
   no fewer. Anything else is refused with a message saying what to change.
2. Downloads each wheel of the chosen platforms, unmodified, from the package index with
   ``pip download --only-binary=:all: --no-deps`` into ``build/wheels`` (reused when there:
   download once, build offline afterwards). Each wheel's own ``RECORD`` hashes are checked.
3. Stages a copy of the add-on (the repository's tracked and untracked, not ignored files) with
   the wheels in ``build/extension/lanterna``; for a subset of platforms the staged manifest
   lists only those platforms and their wheels (the committed one is never edited).
4. Runs Blender's ``blender_ext.py build --split-platforms`` (it ships inside the ``bpy``
   package; the manifest's ``[build]`` excludes tests, tools and build output) and then
   ``blender_ext.py validate`` on every zip: ``dist/lanterna-<version>-<platform>.zip``.

Exit code 0 on success; 2 with one message on stderr for a bad argument, manifest, download or
a failed build or validation.

One zip per platform, carrying the wheels of every Python (cp311 and cp313), not one zip per
platform and Python: that is what Blender's extension code supports and expects (read in bpy
4.2.23 and 5.2.3, ``addons_core/bl_pkg``):

* ``blender_ext.py build --split-platforms`` splits by platform only: each zip gets "the wheels
  compatible with the platform" (``build_paths_filter_by_platform`` ->
  ``paths_filter_wheels_by_platform``, a test of the wheel's platform tag alone), so both
  Pythons' wheels of a platform go into its zip, and ``[build.generated] wheels`` lists them.
  There is no option to split by Python; a zip per Python would need two manifests and names
  of our own for zips the tool names ``<id>-<version>-<platform>.zip``.
* Installing and enabling, Blender takes the package's Python versions from its wheels
  (``python_versions_from_wheels``: {3.11, 3.13} here) and refuses the package only when its
  own Python is none of them (``repository_filter_skip``); then
  ``_extensions_wheel_filter_for_this_system`` keeps the wheels whose platform tag matches and
  whose Python tag is the running one ("Skipping wheel for other Python version"), and only
  those are extracted into ``extensions/.local/lib/python3.X/site-packages``.

So a user picks a zip by platform alone, as before, and an extension carried over from
Blender 5.0 (3.11) to 5.1+ (3.13) keeps working: Blender extracts the other Python's wheels
from the same package. The price is size: each zip carries two copies of the two wheels.

The Python filter is not in Blender 4.2.0: its ``_extensions_wheel_filter_for_platform``
reads the platform tag only (``_python_tag, _abi_tag, platform_tag = ...``), and
``wheel_list_deduplicate_as_skip_set`` then keeps one wheel per distribution, the same
version broken by the larger file name, i.e. the cp313 wheel, which Python 3.11 cannot
import. bpy 4.2.13 (the next 4.2 on the package index; Blender added the filter with "Support
multiple extensions with different Python versions", ref #128750, and backported it to 4.2
LTS) has it, as have 4.2.23, 4.5, 5.0 and later. So a manifest bundling more than one Python
must say ``blender_version_min >= MULTI_PYTHON_MIN`` (4.2.13). Tried with bpy 4.2.0: a zip
of both Pythons with a minimum of 4.2.0 installs and enables, with the cp313 embreex and
pykdtree extracted into ``python3.11/site-packages`` (``import embreex.rtcore_scene``:
ModuleNotFoundError, so the first render fails); with 4.2.13 Blender 4.2.0 refuses it at once:
"This Blender version (4.2.0) doesn't meet the minimum supported version (4.2.13)".
"""
from __future__ import annotations

import argparse
import base64
import csv
import hashlib
import importlib.util
import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = "blender_manifest.toml"
PLATFORMS = ("linux-x64", "windows-x64", "macos-arm64", "macos-x64")
DEFAULT_DIST = ROOT / "dist"
DEFAULT_WHEELS = ROOT / "build" / "wheels"
DEFAULT_STAGE = ROOT / "build" / "extension"
# Folders never copied into the staging tree (build output and environments); the manifest's
# [build] section then decides what of the rest goes into the zip.
_SKIP_DIRS = {"build", "dist", "out", "__pycache__", "wheels"}

# The Python of each Blender series (the Python that series' bpy wheel is built for), from 4.2,
# the first with extensions. Bundled wheels must cover exactly the Pythons of the series that
# the manifest's [blender_version_min, blender_version_max) admits.
BLENDER_PYTHON = {
    (4, 2): "3.11", (4, 3): "3.11", (4, 4): "3.11", (4, 5): "3.11", (5, 0): "3.11",
    (5, 1): "3.13", (5, 2): "3.13", (5, 3): "3.13",
}

# The first Blender known to install only its own Python's wheels of a package that bundles
# several (see the module docstring): bpy 4.2.13 has the filter, 4.2.0 does not, and no 4.2
# between them is on the package index.
MULTI_PYTHON_MIN = (4, 2, 13)

_WHEEL_RE = re.compile(r"^(?P<name>[^-]+)-(?P<version>[^-]+)(?:-(?P<build>\d[^-]*))?"
                       r"-(?P<python>[^-]+)-(?P<abi>[^-]+)-(?P<platform>[^-]+)\.whl$")


class BuildError(Exception):
    """A build that cannot go on; the message says why and what to do."""


@dataclass(frozen=True)
class Wheel:
    path: str            # as listed in the manifest: ./wheels/<file>.whl
    filename: str
    name: str            # normalised distribution name (lower case, '-' and '.' as '_')
    version: str
    python: str          # python tag, e.g. cp311
    abi: str
    platform_tags: tuple[str, ...]
    platform: str        # Blender's name: linux-x64, windows-x64, macos-arm64, macos-x64

    @property
    def python_version(self) -> str:
        m = re.fullmatch(r"cp(\d)(\d+)", self.python)
        if not m:
            raise BuildError(f"{self.filename}: python tag {self.python!r} is not CPython "
                             "(cpXY); bundle CPython wheels only")
        return f"{m.group(1)}.{m.group(2)}"


def normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def blender_platform(tag: str) -> str | None:
    """Blender's platform name for one wheel platform tag (None when it has none)."""
    if tag == "win_amd64":
        return "windows-x64"
    if re.fullmatch(r"manylinux(?:1|2010|2014|_\d+_\d+)_x86_64", tag):
        return "linux-x64"
    m = re.fullmatch(r"macosx_\d+_\d+_(arm64|x86_64)", tag)
    if m:
        return "macos-arm64" if m.group(1) == "arm64" else "macos-x64"
    return None


def parse_wheel(path: str) -> Wheel:
    if not isinstance(path, str) or not path.startswith("./wheels/"):
        raise BuildError(f"{MANIFEST}: wheel {path!r} must be a path of the form "
                         "./wheels/<file>.whl")
    filename = path[len("./wheels/"):]
    m = _WHEEL_RE.match(filename)
    if not m or "/" in filename:
        raise BuildError(f"{MANIFEST}: {filename!r} is not a wheel file name "
                         "(name-version-python-abi-platform.whl)")
    tags = tuple(m.group("platform").split("."))
    platforms = {blender_platform(t) for t in tags}
    if None in platforms or len(platforms) != 1:
        raise BuildError(f"{MANIFEST}: {filename}: platform tag {m.group('platform')!r} is not "
                         f"one of Blender's platforms ({', '.join(PLATFORMS)})")
    return Wheel(path, filename, normalise(m.group("name")), m.group("version"),
                 m.group("python"), m.group("abi"), tags, platforms.pop())


def pinned_versions(pyproject: Path) -> dict[str, str]:
    """``{normalised name: version}`` for the ``name==version`` pins of ``[project]`` that hold
    for every Python. A pin with an environment marker (``numpy==2.5.5; python_version >=
    '3.13'``) differs between Pythons and is left out: a bundled wheel's dependency must be one
    version everywhere, so that every Blender runs the same code."""
    data = tomllib.loads(pyproject.read_text(encoding="utf-8"))
    pins = {}
    for req in data.get("project", {}).get("dependencies", []):
        m = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)\s*==\s*([^\s;,]+)\s*(;.*)?", req)
        if m and not m.group(3):
            pins[normalise(m.group(1))] = m.group(2)
    return pins


def _version(text, what: str) -> tuple[int, ...]:
    if not isinstance(text, str) or not re.fullmatch(r"\d+(\.\d+){1,2}", text):
        raise BuildError(f"{MANIFEST}: {what} must be a version like \"4.2.0\", found {text!r}")
    return tuple(int(x) for x in text.split("."))


def pythons_of_range(manifest: dict) -> dict[str, list[str]]:
    """``{python: [Blender series]}`` for the known series the manifest's version range admits
    (``blender_version_max`` excluded, as Blender excludes it)."""
    low = _version(manifest.get("blender_version_min"), "blender_version_min")
    high = manifest.get("blender_version_max")
    high = _version(high, "blender_version_max") if high is not None else None
    pythons: dict[str, list[str]] = {}
    for series, python in BLENDER_PYTHON.items():
        if (series + (99,)) < low or (high is not None and series + (0,) >= high):
            continue
        pythons.setdefault(python, []).append("%d.%d" % series)
    return pythons


def load_manifest(root: Path = ROOT) -> tuple[dict, str]:
    path = root / MANIFEST
    try:
        text = path.read_text(encoding="utf-8")
        return tomllib.loads(text), text
    except OSError as exc:
        raise BuildError(f"cannot read {path}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise BuildError(f"{path}: not valid TOML: {exc}") from None


def manifest_wheels(manifest: dict, pins: dict[str, str]) -> list[Wheel]:
    """The manifest's wheels, checked against the pins and the declared platforms."""
    listed = manifest.get("wheels")
    platforms = manifest.get("platforms")
    if not isinstance(listed, list) or not listed:
        raise BuildError(f"{MANIFEST}: 'wheels' must list the bundled wheels")
    if not isinstance(platforms, list) or not platforms:
        raise BuildError(f"{MANIFEST}: 'platforms' must list the platforms to build")
    unknown = [p for p in platforms if p not in PLATFORMS]
    if unknown:
        raise BuildError(f"{MANIFEST}: unknown platform(s) {', '.join(map(repr, unknown))} "
                         f"(known: {', '.join(PLATFORMS)})")
    wheels = [parse_wheel(p) for p in listed]
    seen = {}
    for w in wheels:
        pin = pins.get(w.name)
        if pin is None:
            raise BuildError(f"{MANIFEST}: {w.filename}: {w.name} is not a pinned dependency "
                             "(name==version, without an environment marker) in pyproject.toml")
        if pin != w.version:
            raise BuildError(f"{MANIFEST}: {w.filename} is {w.name} {w.version} but "
                             f"pyproject.toml pins {pin}; list the {pin} wheels or change the pin")
        key = (w.name, w.platform, w.python)
        if key in seen:
            raise BuildError(f"{MANIFEST}: {seen[key]} and {w.filename} are both {w.name} for "
                             f"{w.platform}, {w.python}")
        seen[key] = w.filename
        if w.platform not in platforms:
            raise BuildError(f"{MANIFEST}: {w.filename} is for {w.platform}, which 'platforms' "
                             "does not list")
    names = sorted({w.name for w in wheels})
    pythons = sorted({w.python for w in wheels})
    needed = pythons_of_range(manifest)
    have = {w.python_version for w in wheels}
    for python, series in needed.items():
        if python not in have:
            raise BuildError(f"{MANIFEST}: no cp{python.replace('.', '')} wheels, but the "
                             f"version range admits Blender {', '.join(series)} (Python "
                             f"{python}); add them or narrow the range")
    low = _version(manifest.get("blender_version_min"), "blender_version_min")
    if len(have) > 1 and low < MULTI_PYTHON_MIN:
        least = ".".join(map(str, MULTI_PYTHON_MIN))
        raise BuildError(f"{MANIFEST}: wheels for Python {' and '.join(sorted(have))} in one zip "
                         f"need blender_version_min >= {least}: older Blender extracts wheels "
                         "of every Python (the cp313 one wins and does not import on 3.11)")
    for python in sorted(have - set(needed)):
        raise BuildError(f"{MANIFEST}: cp{python.replace('.', '')} wheels, but no Blender the "
                         f"version range admits runs Python {python}; drop them")
    for platform in platforms:
        for name in names:
            for python in pythons:
                if (name, platform, python) not in seen:
                    raise BuildError(f"{MANIFEST}: no {python} wheel of {name} for {platform}; "
                                     "add it or drop the platform")
    return wheels


# -- Wheels -----------------------------------------------------------------------------------
def verify_wheel(path: Path) -> None:
    """Check a wheel is a readable zip whose files match the sha256 sums of its RECORD."""
    try:
        with zipfile.ZipFile(path) as zf:
            records = [n for n in zf.namelist() if n.endswith(".dist-info/RECORD")]
            if len(records) != 1:
                raise BuildError(f"{path}: not a wheel (no single .dist-info/RECORD)")
            rows = csv.reader(io.TextIOWrapper(zf.open(records[0]), encoding="utf-8"))
            for row in rows:
                if len(row) < 2 or not row[1]:
                    continue
                algo, _, digest = row[1].partition("=")
                data = zf.read(row[0])
                got = base64.urlsafe_b64encode(hashlib.new(algo, data).digest()).rstrip(b"=")
                if got.decode() != digest:
                    raise BuildError(f"{path}: {row[0]} does not match the wheel's RECORD "
                                     "(a modified or damaged wheel); delete it to download again")
    except (zipfile.BadZipFile, KeyError, OSError, ValueError) as exc:
        raise BuildError(f"{path}: damaged wheel ({exc}); delete it to download again") from None


def fetch_wheel(wheel: Wheel, cache: Path, offline: bool = False) -> Path:
    """The wheel from ``cache``, downloaded unmodified from the package index when missing."""
    target = cache / wheel.filename
    if target.is_file():
        verify_wheel(target)
        return target
    if offline:
        raise BuildError(f"{wheel.filename} is not in {cache} and --offline was given; "
                         "run once with network access to download it")
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=cache, prefix=".download-") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
               "--only-binary=:all:", "--no-deps", "--dest", tmp,
               "--python-version", wheel.python_version, "--implementation", "cp",
               "--abi", wheel.abi]
        for tag in wheel.platform_tags:
            cmd += ["--platform", tag]
        cmd.append(f"{wheel.name}=={wheel.version}")
        print(f"downloading {wheel.filename}", flush=True)
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            tail = " ".join((proc.stderr or proc.stdout).strip().splitlines()[-2:])
            raise BuildError(f"pip could not download {wheel.name}=={wheel.version} for "
                             f"{wheel.platform} ({', '.join(wheel.platform_tags)}): {tail}")
        got = sorted(os.listdir(tmp))
        if got != [wheel.filename]:
            raise BuildError(f"the package index gave {got} for {wheel.name}=={wheel.version} "
                             f"on {wheel.platform}, not {wheel.filename}; update the manifest")
        verify_wheel(Path(tmp) / wheel.filename)
        os.replace(Path(tmp) / wheel.filename, target)
    return target


# -- Staging and Blender's tool ---------------------------------------------------------------
def source_files(root: Path) -> list[Path]:
    """The repository's tracked and untracked, not ignored files (relative paths); without git,
    every file outside dot-folders and build output."""
    try:
        out = subprocess.run(["git", "-C", str(root), "ls-files", "-z", "--cached", "--others",
                              "--exclude-standard"], capture_output=True, check=True).stdout
        files = sorted({Path(p) for p in out.decode().split("\0") if p})
        return [p for p in files if (root / p).is_file()]
    except (OSError, subprocess.CalledProcessError):
        pass
    files = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and d not in _SKIP_DIRS
                             and not d.endswith(".egg-info"))
        rel = Path(dirpath).relative_to(root)
        files += [rel / f for f in sorted(filenames) if not f.startswith(".")]
    return files


def _replace_array(text: str, key: str, values: list[str]) -> str:
    pattern = re.compile(rf"^{key}\s*=\s*\[[^\]]*\]", re.M)
    if len(pattern.findall(text)) != 1:
        raise BuildError(f"{MANIFEST}: expected one top-level '{key} = [...]' array")
    body = "".join(f'\n  "{v}",' for v in values)
    return pattern.sub(lambda _m: f"{key} = [{body}\n]", text)


def stage(root: Path, stage_dir: Path, manifest_text: str, platforms: list[str],
          wheels: list[Wheel], wheel_files: dict[str, Path], all_platforms: list[str]) -> Path:
    """A fresh copy of the add-on with its wheels in ``stage_dir/lanterna``."""
    dest = stage_dir / "lanterna"
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    for rel in source_files(root):
        if rel.parts[0] in _SKIP_DIRS or rel.name == MANIFEST and len(rel.parts) == 1:
            continue
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, dest / rel)
    if platforms != all_platforms:
        manifest_text = _replace_array(manifest_text, "platforms", platforms)
        manifest_text = _replace_array(manifest_text, "wheels", [w.path for w in wheels])
    (dest / MANIFEST).write_text(manifest_text, encoding="utf-8")
    (dest / "wheels").mkdir()
    for w in wheels:
        shutil.copy2(wheel_files[w.filename], dest / "wheels" / w.filename)
    return dest


def find_blender_ext() -> Path:
    """``blender_ext.py`` from the installed ``bpy`` package (not imported: only located)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.origin:
        raise BuildError("the bpy package is not installed in this Python "
                         f"({sys.executable}); run `make` first, or pass --blender-ext")
    hits = sorted(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not hits:
        raise BuildError(f"no blender_ext.py under {Path(spec.origin).parent}; pass --blender-ext")
    return hits[-1]


def run_blender_ext(blender_ext: Path, *args: str) -> str:
    proc = subprocess.run([sys.executable, str(blender_ext), *args], capture_output=True,
                          text=True)
    output = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0:
        raise BuildError(f"blender_ext.py {args[0]} failed (exit {proc.returncode}): {output}")
    return output


def build(platforms: list[str] | None = None, dist: Path = DEFAULT_DIST,
          wheel_cache: Path = DEFAULT_WHEELS, stage_dir: Path = DEFAULT_STAGE,
          offline: bool = False, blender_ext: Path | None = None, root: Path = ROOT,
          log=print) -> dict[str, dict]:
    """Build (and validate) one zip per platform; ``{platform: {"zip", "wheels", "validate"}}``."""
    manifest, text = load_manifest(root)
    wheels = manifest_wheels(manifest, pinned_versions(root / "pyproject.toml"))
    declared = list(manifest["platforms"])
    chosen = declared if not platforms else list(dict.fromkeys(platforms))
    bad = [p for p in chosen if p not in declared]
    if bad:
        raise BuildError(f"unknown platform {bad[0]!r}: {MANIFEST} declares "
                         f"{', '.join(declared)}")
    chosen = [p for p in declared if p in chosen]          # the manifest's order
    wheels = [w for w in wheels if w.platform in chosen]
    blender_ext = Path(blender_ext) if blender_ext else find_blender_ext()
    files = {w.filename: fetch_wheel(w, Path(wheel_cache), offline) for w in wheels}
    src = stage(root, Path(stage_dir), text, chosen, wheels, files, declared)
    dist = Path(dist)
    dist.mkdir(parents=True, exist_ok=True)
    log(run_blender_ext(blender_ext, "build", "--source-dir", str(src), "--output-dir",
                        str(dist), "--split-platforms"))
    result = {}
    for platform in chosen:
        zip_path = dist / f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"
        if not zip_path.is_file():
            raise BuildError(f"blender_ext.py build made no {zip_path.name} in {dist}")
        report = run_blender_ext(blender_ext, "validate", str(zip_path))
        log(f"validate {zip_path.name}: {report}")
        result[platform] = {"zip": zip_path, "validate": report,
                            "wheels": [w.filename for w in wheels if w.platform == platform]}
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="build_extension.py", description=__doc__.split("\n")[0])
    parser.add_argument("--platform", action="append", choices=PLATFORMS,
                        help="build only this platform (repeatable; default: every platform "
                             "the manifest declares)")
    parser.add_argument("--dist", type=Path, default=DEFAULT_DIST, help="where the zips go")
    parser.add_argument("--wheels", type=Path, default=DEFAULT_WHEELS,
                        help="download cache of the wheels (reused)")
    parser.add_argument("--stage", type=Path, default=DEFAULT_STAGE,
                        help="staging folder (emptied)")
    parser.add_argument("--offline", action="store_true",
                        help="use only wheels already in the cache")
    parser.add_argument("--blender-ext", type=Path, help="path to Blender's blender_ext.py")
    args = parser.parse_args(argv)
    try:
        result = build(args.platform, args.dist, args.wheels, args.stage, args.offline,
                       args.blender_ext)
    except BuildError as exc:
        print(f"build_extension: {exc}", file=sys.stderr)
        return 2
    for platform, info in result.items():
        size = info["zip"].stat().st_size
        print(f"{info['zip']}  {size / 2**20:.1f} MiB  ({platform}: {', '.join(info['wheels'])})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
