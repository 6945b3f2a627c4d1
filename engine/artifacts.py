"""Artifacts: the maps a render builds (photon map, shadow photons, irradiance cache), kept
after the render, saved to one ``.npz`` file and loaded back, refused when they were made for
another scene, other settings or another version of Lanterna.

What it computes
    ``Artifacts``  the photon map as the render used it (``full`` mode with a final gather
        keeps all photons, without one only those that bounced), the shadow photon map, the
        irradiance-cache records (thesis Fig. 12.4 shows such records, Fig. 12.5 a photon
        map), the fingerprint of the scene and settings they were made for, the resolved
        settings and the report's stage entries of the bake. The radiance estimates
        (``engine/gather.py``) derive from the photon map and are rebuilt, not saved.
    ``scene_fingerprint(scene, settings)``  sha256 (hex) over two parts kept apart, so that a
        refusal can say which differs:
        * the scene part: sha256 over the sha256 of each of
          ``geometry``   the triangles' float32 bytes and the shading normals' bytes (or "flat");
          ``materials``  the per-triangle material ids and the material table (rho_d, rho_s,
                         exitance, two-sided emission);
          ``lights``     every light's type and dataclass fields except its name (position,
                         direction, flux / power / irradiance, sizes, matrix, spot angles,
                         photon share, ...) and the world's radiance;
          ``camera``     the camera's fields except its name (matrix, field of view, shift,
                         clip range, resolution, border).
          Names are left out: renaming an object changes no map.
        * the settings part: sha256 over the JSON of the resolved (preset applied) settings
          that change the maps, ``MAP_SETTINGS``: mode, bounces, seed, photons, photon_k,
          photon_radius, indirect, gather_m, gather_n, gather_guided, cache_error,
          cache_refine, shadow_photons and force (forced stages add maps). Samples, light
          samples, threads, filter width, photon filter, look-ups, cache gradients and the
          mirror depth only act when the camera stage uses the maps, so they are left out.
        The fingerprint is sha256("lanterna-fingerprint-v1|<scene part>|<settings part>").
        The scene is validated first (``Scene.validate`` is idempotent: it drops untraceable
        triangles, as the pipeline does), so a scene hashes alike before and after a render.
    ``save_artifacts(path, artifacts, scene_name="")``  one ``np.savez_compressed`` archive,
        written to a temporary file in the target folder and moved over ``path`` with
        ``os.replace`` (never half-written). Entries: ``lanterna.format`` (``FORMAT_VERSION``),
        ``lanterna.version`` (``LANTERNA_VERSION``, read from ``blender_manifest.toml``),
        ``lanterna.fingerprint``, ``lanterna.scene_parts`` (JSON: the part hashes when known),
        ``lanterna.settings`` / ``lanterna.report`` (JSON), ``lanterna.scene_name``,
        ``lanterna.maps`` (JSON list of the maps present) and each map's ``to_arrays()``
        under ``photons.*``, ``shadow_photons.*``, ``cache.*``. No entry is a Python object.
    ``load_artifacts(path, scene, settings)``  ``np.load(path, allow_pickle=False)``; raises
        ``ArtifactError`` (a ``SceneError``, so a ``ValueError``) naming the file and the
        problem when the file is missing, is not an ``.npz`` archive, has no Lanterna entries,
        holds pickled objects, has another format version or Lanterna version, was made for
        another scene (naming the differing parts when the file has them) or with other
        settings (naming each setting: file value and current value). Otherwise returns the
        ``Artifacts`` with kd-trees rebuilt (``PhotonMap.build`` keeping the saved Morton
        order, ``ShadowPhotonMap.build_trees``): the same maps, ready to render with.

Parameters and units
    Positions [m], photon power [W], irradiance [W/m^2] as in the maps' own modules.
    ``save_artifacts(compress=True)``: zlib; measured 13 bytes a stored point on a test box
    (100k photons, 36 bytes each in memory, and 20k shadow photons, 16 bytes each).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tomllib
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .archive import ArchiveError, check_budget, check_schema, entry_headers
from .irradiance_cache import IrradianceCache
from .memory import available_memory
from .npzjson import jsonable, pack_json, unpack_json
from .photons import PhotonMap
from .scene import SceneError
from .settings import RenderSettings
from .shadow_photons import ShadowPhotonMap

__all__ = ["FORMAT_VERSION", "LANTERNA_VERSION", "MAP_SETTINGS", "Artifacts", "ArtifactError",
           "scene_fingerprint", "scene_parts", "settings_part", "map_settings", "save_artifacts",
           "load_artifacts"]

FORMAT_VERSION = 1

#: The resolved ``RenderSettings`` that change the maps (see the module docstring).
MAP_SETTINGS = ("mode", "bounces", "seed", "photons", "photon_k", "photon_radius", "indirect",
                "gather_m", "gather_n", "gather_guided", "cache_error", "cache_refine",
                "shadow_photons", "force")

_FINGERPRINT_TAG = "lanterna-fingerprint-v1"
_MAPS = (("photons", "photon_map", PhotonMap), ("shadow_photons", "shadow_map", ShadowPhotonMap),
         ("cache", "cache", IrradianceCache))
#: The file's own entries (``engine/archive.py`` schema).
HEADER_SCHEMA = {"lanterna.format": (("<i8",), ()), "lanterna.version": (("U",), ()),
                 "lanterna.fingerprint": (("U",), ()), "lanterna.scene_parts": (("U",), ()),
                 "lanterna.settings": (("U",), ()), "lanterna.report": (("U",), ()),
                 "lanterna.scene_name": (("U",), ()), "lanterna.maps": (("U",), ())}
#: The count each map's report entry promises, and the symbol of its schema that counts it.
PROMISED = {"photons": ("photons", "stored", "P"), "cache": ("irradiance_cache", "records", "N"),
            "shadow_photons": ("shadow_photons", "stored", "P")}
MEMORY_SHARE = 0.5                 # of the available memory a maps file may take once read
UNKNOWN_MEMORY_BUDGET = 16 << 30   # when the platform cannot tell [bytes]
SCENE_PART_NAMES = {"geometry": "the geometry (triangles or shading normals)",
                    "materials": "the materials", "lights": "the lights or the world",
                    "camera": "the camera (view, lens, resolution or border)"}


def _read_version() -> str:
    """Lanterna's version: ``blender_manifest.toml``'s ``version``, else pyproject's."""
    root = Path(__file__).resolve().parent.parent
    for name, section in (("blender_manifest.toml", None), ("pyproject.toml", "project")):
        try:
            data = tomllib.loads((root / name).read_text(encoding="utf-8"))
        except (OSError, tomllib.TOMLDecodeError):
            continue
        table = data.get(section, {}) if section else data
        if isinstance(table.get("version"), str):
            return table["version"]
    return "0.0.0"


LANTERNA_VERSION = _read_version()


class ArtifactError(SceneError):
    """A maps file that cannot be used: the message names the file and the reason."""


@dataclass
class Artifacts:
    photon_map: PhotonMap | None          # as used by the render (may hold only indirect photons)
    shadow_map: ShadowPhotonMap | None
    cache: IrradianceCache | None
    fingerprint: str                      # scene_fingerprint(scene, settings)
    settings: dict                        # dataclasses.asdict of the resolved RenderSettings
    report: dict = field(default_factory=dict)   # the report's stage entries of the bake
    scene_parts: dict = field(default_factory=dict)  # {part: sha256}; lets a refusal say which

    def __post_init__(self):
        if not self.scene_parts:
            # Made from a fingerprint computed just before: its parts are remembered.
            self.scene_parts = dict(_RECENT_PARTS.get(self.fingerprint, {}))

    @classmethod
    def create(cls, scene, settings, photon_map=None, shadow_map=None, cache=None,
               report=None) -> "Artifacts":
        """Artifacts with the fingerprint, its scene parts and the resolved settings filled."""
        resolved = _resolved(settings)
        return cls(photon_map, shadow_map, cache, scene_fingerprint(scene, resolved),
                   dataclasses.asdict(resolved), dict(report or {}))

    def counts(self) -> dict:
        """Points of each kind: photons, shadow photons, cache records (0 when absent)."""
        return {"photons": len(self.photon_map) if self.photon_map is not None else 0,
                "shadow_photons": len(self.shadow_map) if self.shadow_map is not None else 0,
                "cache": len(self.cache) if self.cache is not None else 0}


# --- Fingerprint -------------------------------------------------------------------------------
def _resolved(settings):
    """Resolved ``RenderSettings`` from settings, a dict of them, or None (the defaults)."""
    if settings is None:
        settings = RenderSettings()
    elif isinstance(settings, dict):
        names = {f.name for f in dataclasses.fields(RenderSettings)}
        settings = RenderSettings(**{k: v for k, v in settings.items() if k in names})
    return settings.resolved()


def map_settings(settings) -> dict:
    """The resolved settings that change the maps (``MAP_SETTINGS``), as a dict."""
    resolved = _resolved(settings)
    return {name: getattr(resolved, name) for name in MAP_SETTINGS}


def settings_part(settings) -> str:
    """sha256 hex of the JSON of ``map_settings(settings)``."""
    text = json.dumps(jsonable(map_settings(settings)), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _feed(h, value):
    """Add one value to hash ``h`` with its type, so that 1, 1.0 and "1" differ."""
    if isinstance(value, (bool, np.bool_)):
        h.update(b"b1" if value else b"b0")
    elif isinstance(value, (str,)):
        h.update(b"s" + value.encode() + b"\0")
    elif value is None:
        h.update(b"n")
    elif isinstance(value, (tuple, list)) or isinstance(value, np.ndarray) \
            or isinstance(value, (int, float, np.number)):
        arr = np.asarray(value)
        if arr.dtype.kind in "biuf":
            arr = arr.astype(np.float64)
        arr = np.ascontiguousarray(arr)
        h.update(f"a{arr.dtype.str}{arr.shape}".encode())
        h.update(arr.tobytes())
    elif dataclasses.is_dataclass(value):
        _feed_fields(h, value)
    else:
        h.update(b"r" + repr(value).encode())


def _feed_world(h, world) -> None:
    h.update(b"world")
    _feed(h, np.asarray(world.radiance, np.float64))
    env = world.environment
    if env is not None:             # an image world: its pixels and how they are mapped
        h.update(f"{env.projection}|{env.interpolation}|{env.encoding}".encode())
        for arr in (env.pixels, env.strength, env.rotation):
            _feed(h, np.ascontiguousarray(arr))


def _feed_fields(h, obj):
    h.update(type(obj).__name__.encode() + b"{")
    for f in dataclasses.fields(obj):
        if f.name == "name":
            continue
        h.update(f.name.encode() + b"=")
        _feed(h, getattr(obj, f.name))
    h.update(b"}")


def scene_parts(scene) -> dict:
    """{part: sha256 hex} for ``geometry``, ``materials``, ``lights`` and ``camera`` (the
    scene is validated first; see the module docstring)."""
    scene.validate()
    parts = {}
    h = hashlib.sha256()
    tris = np.ascontiguousarray(scene.triangles, np.float32)
    h.update(f"{tris.shape}".encode())
    h.update(tris.tobytes())
    if scene.shading_normals is None:
        h.update(b"flat")
    else:
        h.update(np.ascontiguousarray(scene.shading_normals, np.float32).tobytes())
    if scene.strands is not None:           # hair changes the photons kept and their estimates
        h.update(b"strands")
        h.update(np.packbits(np.asarray(scene.strands, bool)).tobytes())
    parts["geometry"] = h.hexdigest()
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(scene.material_ids, np.int32).tobytes())
    for key, arr in sorted(scene.material_table().items()):
        h.update(key.encode())
        h.update(np.ascontiguousarray(arr).tobytes())
    parts["materials"] = h.hexdigest()
    h = hashlib.sha256()
    for light in scene.lights:
        _feed_fields(h, light)
    _feed_world(h, scene.world)
    for portal in scene.world.portals:
        _feed_fields(h, portal)
    parts["lights"] = h.hexdigest()
    h = hashlib.sha256()
    _feed_fields(h, scene.camera)
    if scene.world.camera is not None:      # what camera rays see of the world, apart
        _feed_world(h, scene.world.camera)
    parts["camera"] = h.hexdigest()
    return parts


def _scene_part(parts: dict) -> str:
    text = "|".join(f"{k}:{parts[k]}" for k in sorted(parts))
    return hashlib.sha256(text.encode()).hexdigest()


def _combine(scene_hash: str, settings_hash: str) -> str:
    return hashlib.sha256(f"{_FINGERPRINT_TAG}|{scene_hash}|{settings_hash}".encode()).hexdigest()


# The scene parts of the last few fingerprints computed, so that ``Artifacts`` made with just
# ``fingerprint=scene_fingerprint(...)`` still carry them (a refusal can then name the part).
_RECENT_PARTS: dict = {}
_RECENT_LIMIT = 16


def scene_fingerprint(scene, settings) -> str:
    """sha256 hex over the scene part and the settings part (see the module docstring)."""
    parts = scene_parts(scene)
    fingerprint = _combine(_scene_part(parts), settings_part(settings))
    _RECENT_PARTS.pop(fingerprint, None)
    _RECENT_PARTS[fingerprint] = parts
    while len(_RECENT_PARTS) > _RECENT_LIMIT:
        _RECENT_PARTS.pop(next(iter(_RECENT_PARTS)))
    return fingerprint


# --- Save --------------------------------------------------------------------------------------
def save_artifacts(path, artifacts: Artifacts, *, scene_name: str = "",
                   compress: bool = True) -> None:
    """Write ``artifacts`` to ``path`` (one ``.npz``; see the module docstring). The folder
    must exist; the file appears whole or not at all."""
    path = Path(os.fspath(path))
    entries = {
        "lanterna.format": np.array(FORMAT_VERSION, np.int64),
        "lanterna.version": np.array(LANTERNA_VERSION),
        "lanterna.fingerprint": np.array(str(artifacts.fingerprint)),
        "lanterna.scene_parts": pack_json(artifacts.scene_parts or {}),
        "lanterna.settings": pack_json(artifacts.settings),
        "lanterna.report": pack_json(artifacts.report or {}),
        "lanterna.scene_name": np.array(str(scene_name)),
    }
    present = []
    for prefix, attr, _cls in _MAPS:
        value = getattr(artifacts, attr)
        if value is None:
            continue
        present.append(prefix)
        for key, arr in value.to_arrays().items():
            entries[f"{prefix}.{key}"] = arr
    entries["lanterna.maps"] = pack_json(present)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ArtifactError(f"Cannot save the maps to '{path}': the folder '{folder}' does not exist")
    from .imageio import atomic_output

    with atomic_output(path) as tmp, open(tmp, "wb") as fh:
        (np.savez_compressed if compress else np.savez)(fh, **entries)
        fh.flush()
        os.fsync(fh.fileno())


# --- Load --------------------------------------------------------------------------------------
def _differences(saved: dict, current: dict) -> list[str]:
    out = []
    for name in MAP_SETTINGS:
        a, b = saved.get(name, "<missing>"), current.get(name)
        if a != b:
            out.append(f"{name} = {a!r} in the file, {b!r} now")
    return out


def load_artifacts(path, scene, settings) -> Artifacts:
    """Read the maps in ``path`` for ``scene`` rendered with ``settings`` (see the module
    docstring); raises ``ArtifactError`` with the reason when the file does not fit."""
    path = Path(os.fspath(path))
    where = f"Lanterna maps file '{path}'"
    if not path.is_file():
        raise ArtifactError(f"{where} does not exist")
    try:
        headers = entry_headers(path)
    except ArchiveError as exc:
        if exc.whole:
            raise ArtifactError(f"{where} is not a Lanterna maps file ({exc})") from None
        raise ArtifactError(f"{where} is damaged: {exc}") from None
    if "lanterna.format" not in headers:
        raise ArtifactError(f"{where} is not a Lanterna maps file (an .npz archive without "
                            "the 'lanterna.format' entry)")
    problems = check_schema(headers, HEADER_SCHEMA)
    if problems:
        raise ArtifactError(f"{where} is damaged: {problems[0]}")
    available = available_memory()
    try:
        check_budget(headers, UNKNOWN_MEMORY_BUDGET if available is None
                     else int(available * MEMORY_SHARE))
    except ArchiveError as exc:
        raise ArtifactError(f"{where} is refused: {exc}") from None
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ArtifactError(f"{where} is not a Lanterna maps file (not a numpy .npz archive: "
                            f"{exc})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ArtifactError(f"{where} is not a Lanterna maps file (a single numpy array, not "
                            "an .npz archive)")
    with data:
        return _load_open(data, headers, where, scene, settings)


def _check_map(prefix, cls, headers, report, where):
    """The map ``prefix``'s entries against ``cls.SCHEMA`` and the count its report entry
    promises, from the headers alone (nothing decompressed yet)."""
    problems = check_schema(headers, cls.SCHEMA, prefix + ".")
    if not problems and prefix in PROMISED:
        stage, key, symbol = PROMISED[prefix]
        promised = (report.get(stage) or {}).get(key) if isinstance(report, dict) else None
        rows = next(headers[prefix + "." + name].shape[0]
                    for name, (_d, shape) in cls.SCHEMA.items()
                    if shape and shape[0] == symbol)
        if isinstance(promised, int) and promised != rows:
            problems.append(f"the entry '{prefix}.positions' has {rows:,} rows, but the file's "
                            f"report says {promised:,}")
    if problems:
        raise ArtifactError(f"{where} is damaged: {problems[0]}")


def _load_open(data, headers, where, scene, settings) -> Artifacts:
    def entry(key):
        try:
            return data[key]
        except KeyError:
            raise ArtifactError(f"{where} is damaged: the entry '{key}' is missing") from None
        except ValueError as exc:       # object arrays: refused by allow_pickle=False
            raise ArtifactError(f"{where}: the entry '{key}' holds pickled Python objects, "
                                f"which Lanterna does not load ({exc})") from None
        except (OSError, EOFError, zipfile.BadZipFile, zipfile.LargeZipFile) as exc:
            raise ArtifactError(f"{where} is damaged: the entry '{key}' cannot be read "
                                f"({exc})") from None

    if "lanterna.format" not in data.files:
        raise ArtifactError(f"{where} is not a Lanterna maps file (an .npz archive without "
                            "the 'lanterna.format' entry)")
    try:
        fmt = int(entry("lanterna.format"))
        version = str(entry("lanterna.version"))
        fingerprint = str(entry("lanterna.fingerprint"))
        saved_settings = unpack_json(entry("lanterna.settings"))
        saved_parts = unpack_json(entry("lanterna.scene_parts"))
        report = unpack_json(entry("lanterna.report"))
        scene_name = str(entry("lanterna.scene_name"))
        present = unpack_json(entry("lanterna.maps"))
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ArtifactError):
            raise
        raise ArtifactError(f"{where} is damaged: its header cannot be read ({exc})") from None
    if fmt != FORMAT_VERSION:
        raise ArtifactError(f"{where} has format version {fmt}; this Lanterna ({LANTERNA_VERSION}) "
                            f"reads version {FORMAT_VERSION}. Bake the maps again")
    if version != LANTERNA_VERSION:
        raise ArtifactError(f"{where} was written by Lanterna {version}; this is Lanterna "
                            f"{LANTERNA_VERSION}. Bake the maps again")

    # Scene and settings: the scene part from the saved settings tells which one differs.
    parts_now = scene_parts(scene)
    scene_now = _scene_part(parts_now)
    settings_now = map_settings(settings)
    try:
        saved_map = map_settings(saved_settings)
        settings_saved_hash = settings_part(saved_settings)
    except (TypeError, ValueError, AttributeError):
        saved_map, settings_saved_hash = {}, ""
    changed = _differences(saved_map, settings_now)
    if fingerprint != _combine(scene_now, settings_part(settings)):
        named = f" '{scene_name}'" if scene_name else ""
        if fingerprint != _combine(scene_now, settings_saved_hash):
            which = [SCENE_PART_NAMES.get(k, k) for k in sorted(parts_now)
                     if isinstance(saved_parts, dict) and k in saved_parts
                     and saved_parts[k] != parts_now[k]]
            detail = f": {', '.join(which)} differ" if which else \
                " (its geometry, materials, lights or camera differ)"
            extra = f"; its settings differ too ({'; '.join(changed)})" if changed else ""
            raise ArtifactError(f"{where} was made for another scene{named}{detail}{extra}. "
                                "Bake the maps again")
        raise ArtifactError(f"{where} is stale: made with other settings ("
                            f"{'; '.join(changed) or 'unknown'}). Bake the maps again or "
                            "restore those settings")

    if not (isinstance(present, list) and all(isinstance(p, str) for p in present)):
        raise ArtifactError(f"{where} is damaged: its list of maps cannot be read")
    maps = {}
    for prefix, attr, cls in _MAPS:
        if prefix not in present:
            maps[attr] = None
            continue
        _check_map(prefix, cls, headers, report, where)
        head = prefix + "."
        sub = {key[len(head):]: entry(key) for key in data.files if key.startswith(head)}
        problems = cls.value_problems(sub)
        if problems:
            raise ArtifactError(f"{where} is damaged: {problems[0]} (entries '{head}*')")
        try:
            maps[attr] = cls.from_arrays(sub)
        except (KeyError, ValueError, TypeError, IndexError) as exc:
            raise ArtifactError(f"{where} is damaged: its {prefix.replace('_', ' ')} cannot be "
                                f"read ({type(exc).__name__}: {exc})") from None
    return Artifacts(maps["photon_map"], maps["shadow_map"], maps["cache"], fingerprint,
                     saved_settings, report if isinstance(report, dict) else {},
                     saved_parts if isinstance(saved_parts, dict) else {})
