"""Estimated cost before rendering (issue 6): every stage's time and memory, before any work.

What it computes
    ``estimate_cost(scene, settings, rates=None, passes=(), reused=False)`` -> ``Estimate``:
    for each stage of ``engine/pipeline.py`` that the plan (``engine/plan.py``) runs, the
    counts it will handle, predicted from the scene and the settings without tracing a ray,
    times the per-unit rates of this machine (``Rates``), and the memory it keeps and needs
    while it runs. Totals: seconds, and the peak of the memory the render allocates (the
    scene's own arrays, already in memory, are not counted). ``preflight`` does this for the
    pipeline and refuses (``SceneError``) a render whose peak exceeds ``available_memory()``.
    ``scene_facts(scene)`` gathers what the estimate needs from a scene (counts, areas,
    albedo, lights); ``estimate_from_facts`` is the rest, pure arithmetic, so the render
    panel can re-estimate on every redraw from facts it keeps.

Parameters
    ``scene``: an ``engine.scene.Scene``; ``settings``: ``RenderSettings`` (default: its
    defaults; the preset is applied); ``rates``: ``Rates`` (default ``load_rates()``);
    ``passes``: pass names as ``render`` takes them (default none); ``reused``: the maps come
    from ``bake`` or a file (default False).

Counts (P window pixels, F full-frame pixels, B pixels of the full-frame blocks the camera
shades for the window (``camera_blocks``; B = P = F for a whole frame), S samples per pixel,
T triangles, W worker threads. As in the pipeline, automatic counts follow the full frame and
the cache is placed over it, so a tile (render border) renders as its part of the frame)
    =====================  =================================================================
    count                  prediction
    =====================  =================================================================
    camera rays            B S (exact; every camera ray is assumed to hit, as in a room);
                           with adaptive sampling (``noise_threshold`` > 0) the bound
                           B S (1 + ``ADAPTIVE_BUDGET``), and the counts of the camera's hits
                           with it (shadow, specular rays, light samples; not the look-ups)
    look-ups               B min(L, S), L = ``photon_lookups`` or ``auto_lookups(F)`` (exact when
                           every camera ray hits a diffuse surface)
    shadow rays            B S (D + K [sampled lights exist]) with D delta lights and K light
                           samples: one per delta light and hit, K per hit for the sampled
                           lights (exact for point lights when every hit faces every light;
                           an upper bound otherwise, and shadow photons save some)
    specular rays          B S sum_{d=1..depth} s^d, s = area share of specular surfaces
    photons emitted        N = ``photons`` or ``auto_photon_count(F)`` (exact)
    photon rays            N (1 + c rho_1 sum_{i=0..n-1} (c rho)^i): a Russian-roulette path
                           (seed 9.2) hits something with probability c and survives a hit
                           with probability rho, the area-weighted mean of the materials'
                           roulette P_d + P_s (``photons.roulette_probabilities``: the
                           reflectances' largest channels; rho_1 at the first hit: the mean over
                           triangles weighted by the solid angle each subtends at the point,
                           spot or area lights, occlusion ignored), for at most n =
                           ``bounces`` bounces. c, the closure, is the share of the faces of
                           the scene's bounds (with the camera) that triangles lying in them
                           cover: 1 for a closed room, 0.28 for a lone floor. Exact in
                           expectation for a closed room of one albedo.
    stored photons         c x photon rays x the area share of surfaces that store (P_d > 0);
                           in ``full`` mode without a final gather the first hits (c N x that
                           share) are dropped. Seed scenes, stored per emitted photon: Scene 1
                           2.69 measured, 2.82 predicted; Scene 2 4.39 measured, 3.87
                           predicted (its lamp's light bounces about a white tube).
    radiance estimates     min(400k, 0.25 stored) (``engine/gather.py``, exact given stored)
    cache records          exp(c0 + c1 ln F + c2 ln a + c3 ln F ln a), clipped to
                           [ceil(w/32) ceil(h/32), F] (w x h the frame): a least-squares fit
                           (``tools/fit_cache_counts.py``) to the records the placement passes
                           made, with the neighbour check, on the seed's two scenes (160x120
                           and 640x480, ``preview`` and ``final``): 0.81-1.23 of the fit
                           (2026-12-02, with the coarse-to-fine refill of the check's gaps;
                           0.71-1.41 before it). The check makes the count depend on the light
                           (Scene 2's indirect shadows add 23-50 %, Scene 1 gains 0-6 %) and the
                           view more so (two rooms at 40-90 degrees lay at 0.05-0.9 of it): a
                           guide, not a forecast. Two pilots before the render (the first passes;
                           the placement on a quarter of the frame: ``tools/fit_cache_counts.py
                           --pilots``) did no better for 10-30 % of the placement's time.
                           (An earlier fit scaled with tan(fov/2), as wider
                           views of the rooms saw more corners per pixel; with the check the
                           narrower Scene 2 has the most records, and the factor is gone.)
    gathered look-ups      cache: look-ups x f, f = exp(u0) F^u1 a^u2 (the share that needs a
                           gather in the camera stage: no placed record covers it (across
                           edges from the pixel centres the passes saw, where the normal
                           turns fast, where the neighbour check shrank the records) and it
                           makes a batch-local record or has none near), fitted to the same
                           renders at the presets' 16 spp (0.33-3.5 of the fit; Scene 2's
                           knot needs 8-11x Scene 1's share at ``final``); ``gather``: every
                           look-up.
    gather rays per point  G = M N (1 + ``gather_guided``)
    shadow photons         ``auto_shadow_photon_count`` (100k-1M, from area and extent)
    image look-ups         per surface hit t = the image look-ups of each material's node-driven
                           reflectance (``textures.lookups_per_hit``: the Image Texture nodes
                           upstream; procedural-only 1) weighted by its share of the area; per
                           photon or light sample e = those of its emission weighted by its
                           share of the lights' luminance flux. photons: (N e + c rays t);
                           cache: (F + records G) t; camera: (camera + specular rays +
                           gathered G) t + light samples e (penumbra samples not counted)
    =====================  =================================================================

Time [s] (rates: seconds per unit, measured with ``rates.workers`` threads)
    validate = T r_validate; accel_build = T r_bvh
    photons = N r_emit + rays r_photon_ray + stored_all (r_photon_store(stored_all) +
              r_shadow_ray)   (the last: the crevice probe, one occlusion ray a stored photon)
    radiance_estimates = estimates r_estimate (k + 10) / 60 (the k-dependence assumed, not
    measured: a query's fixed cost and one per neighbour)
    irradiance_cache = F r_cache_pixel + records (G r_gather_ray + r_gather_point)
    shadow_photons = count r_shadow_photon
    camera = camera rays r_camera_sample + specular rays r_camera_sample + delta shadow rays
             r_shadow_ray + light samples r_light_sample + interpolated r_cache_lookup +
             gathered (G r_gather_ray + r_gather_point) + photon-map look-ups r_photon_lookup
    + image look-ups r_texture_lookup in photons, irradiance_cache and camera (the
    ``textures`` line of the table sums them)
    Threads: the parallel parts (photon rays, estimates, gathers, camera, shadow photons)
    scale by W_rates / W (both at most the cores); the rest runs on one thread.
    Triangles: the share of a ray's cost that is Embree's traversal grows with ln T: the
    rates file holds raw embreex seconds per ray at two triangle counts (the calibration
    scene's and a large mesh); ray rates are shifted by the difference of the raw cost at T
    and at the calibration scene's count (interpolated in ln T, extrapolated above; no
    shift below the calibration scene's count). The k-nearest rates are not shifted with the
    size of the photon map: raw pykdtree queries slow 2.5-6x from 50k to 3M points (k = 4
    to 128), but the renderer asks in Morton order or in batches of nearby points, and its
    estimate rate measured the same (7.5-7.8 us) at 0.75M and at 2.7-4.4M stored photons.
    The map's build is: per stored photon it cost 0.20 us at 0.96M and 0.48 us at 4.8M
    (2026-12-02; the Morton reorder's gathers and the kd-tree leave the caches), so the rates
    file holds the build at both sizes (``STORE_KEYS``, the calibration's cache renders and
    a 1.5M-photon map) and r_photon_store is interpolated in ln(stored_all) between them
    like the ray rates (no shift below the small map, extrapolated above the large one).

A shared machine
    Rates are wall time on the machine as it was while they were measured; other work slows
    a render as a whole (here the same render of Scene 1 at 640x480, final, took 18 s on a
    quiet machine and 120 s beside other jobs; pykdtree's OpenMP queries suffer most: the
    estimates of Scene 1 at 640x480, preview, took 0.8 s and 19.7 s). Scaling by a short
    speed probe before each render was tried and dropped: over renders of 30-120 s the load
    changed more than a 50 ms probe could tell, and the probe's own scatter made the estimate
    worse.

Memory [bytes] (keeps: held until the render ends; working: while the stage runs)
    accel_build        keeps 140 T (Embree's BVH and the float32 corners, measured by RSS at
                       200k and 1M triangles: 122-145 B, with the geometric normals)
    photons            keeps 56 stored (36 B a photon, 12 B of directions for look-ups, the
                       kd-tree); working 72 stored_all + W 131072 x 200 (lists, concatenation,
                       Morton sort; measured by tracemalloc: 113-119 B a photon at the peak)
    radiance_estimates keeps 44 estimates; working 60 estimates + W 16384 k 60
    irradiance_cache   keeps 2 x 304 records (float64 records, capacity doubling) + 100 per
                       record of index, + 3 x 216 per record where the gathered sky has three
                       channels of its own (``SceneFacts.sky_channels``); working 170 F
                       (centre hits) + W 256 G 500 (gather)
    shadow_photons     keeps 53 count (about two stored per photon at 18.25 B, kd-trees);
                       working 100 count
    camera             keeps 12 P per image buffer (Combined and each split pass), 264 P
                       for the light passes' sums (11 float64 images) when any is asked; working
                       min(W, blocks) x 640 B per sample of a block + gathers in flight
                       (W min(524288, gathered per batch x G) x 500) + photon look-ups
                       (W 8192 k 60)
    The peak is the largest (keeps of the stages so far + the stage's working memory).
    Textures: the texels of the distinct images the materials' graphs hold (``nodes.Image``
    as held: uint8, float16 or float32; an image shared between materials once), in
    ``SceneFacts.texture_bytes``, the report's ``texture_bytes`` and the table's ``textures``
    line; like the triangles they are the scene's, in memory before the render, so not in its
    peak (``available_memory`` already leaves them out).
    Checked with tracemalloc (which sees numpy's allocations, not Embree's or the kd-trees')
    on the seed scenes, final preset: peak 502 MB measured against 505 MB predicted (Scene 1,
    640x480), 789 against 741 MB (Scene 2, 160x120); per stage 0.85-1.26 of the measured.

Rates files (JSON, ``RATES_SCHEMA``)
    ``engine/data/rates.json`` ships with Lanterna (measured on the development machine);
    ``lanterna bench --calibrate`` measures this machine's and writes the user file
    ``user_rates_path()``: ``$XDG_CACHE_HOME/lanterna/rates.json`` (or
    ``~/.cache/lanterna/rates.json``; ``%LOCALAPPDATA%\\lanterna`` on Windows,
    ``~/Library/Caches/lanterna`` on macOS), which
    ``load_rates`` prefers. A user file that cannot be read, is not JSON or lacks a rate
    gives a warning (``Rates.warnings``, copied into the estimate and the render report) and
    the shipped defaults are used (missing rates alone are taken from the defaults).

Available memory
    ``available_memory()`` (``engine/memory.py``): ``MemAvailable`` of ``/proc/meminfo``,
    ``GlobalMemoryStatusEx`` on Windows, else ``os.sysconf`` free pages; None where none
    answers (then nothing is refused).
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
import dataclasses
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from . import nodes
from .bsdf import roulette_probabilities
from .passes import LIGHT_PASS_NAMES
from .lights import LUMINANCE, area_light_triangles, solid_angle
from .memory import available_memory
from .passes import parse_passes
from .photons import auto_photon_count
from .plan import make_plan
from .scene import AreaLight, PointLight, SceneError, SpotLight, SunLight
from .settings import ADAPTIVE_BUDGET, RenderSettings, auto_lookups, block_side
from .textures import lookups_per_hit
from .shadow_photons import (AUTO_SPACING, DEFAULT_K, DEFAULT_MARGIN, MAX_AUTO_COUNT,
                             MIN_AUTO_COUNT, neighbours_queried)

RATES_SCHEMA = 1
DEFAULT_RATES_PATH = Path(__file__).resolve().parent / "data" / "rates.json"

# Seconds per unit (wall clock with ``Rates.workers`` threads), what each counts.
RATE_KEYS = {
    "validate_triangle": "validate: per triangle",
    "bvh_triangle": "Embree BVH build: per triangle (one thread)",
    "photon_emit": "photon emission: per photon (one thread)",
    "photon_ray": "photon tracing: per photon ray (roulette, storing)",
    "photon_store": "photon map build: per stored photon (Morton order, kd-tree; one thread)",
    "radiance_estimate": "irradiance at a photon, k = 50: per estimate",
    "cache_pixel": "cache placement passes: per frame pixel (centre rays, coverage; one thread)",
    "gather_ray": "final gather: per ray (trace, look-up of the precomputed estimates)",
    "gather_point": "final gather: per point (photon-guided allocation, sums, gradients)",
    "shadow_photon": "shadow photons: per photon (emit, trace through, index, classify)",
    "camera_sample": "camera: per camera ray (generation, trace, shading, pixel sums)",
    "shadow_ray": "camera: per shadow ray of a delta light (point, spot, sun)",
    "light_sample": "camera: per sample of a sampled light (selection, sample, shadow ray)",
    "cache_lookup": "camera: per look-up interpolated from cache records",
    "photon_lookup": "camera: per photon-map estimate at a hit, k = 50",
    "texture_lookup": "textures: per image look-up at a hit (8-bit, Linear; the material's "
                      "per-hit evaluation included)",
}
RAW_KEYS = ("triangles_small", "triangles_large", "incoherent_small", "incoherent_large",
            "coherent_small", "coherent_large")
# The photon map's build at two sizes: stored photons, seconds per stored photon (optional:
# a rates file without them keeps one store rate for every size).
STORE_KEYS = ("stored_small", "stored_large", "store_small", "store_large")
RAW_GROUPS = (RAW_KEYS, STORE_KEYS)
PARALLEL_RATES = {"photon_ray", "radiance_estimate", "gather_ray", "gather_point",
                  "shadow_photon", "camera_sample", "shadow_ray", "light_sample",
                  "cache_lookup", "photon_lookup", "texture_lookup"}

# Memory per unit [bytes] (module docstring).
BVH_BYTES_PER_TRIANGLE = 140
PHOTON_BYTES = 56
PHOTON_BUILD_BYTES = 72
PHOTON_CHUNK_BYTES = 131072 * 200
ESTIMATE_BYTES = 44
ESTIMATE_WORK_BYTES = 60
NEIGHBOUR_BYTES = 60                 # per (query, neighbour) in a k-nearest chunk
ESTIMATE_CHUNK = 16384               # queries per chunk of RadianceEstimates.build
LOOKUP_CHUNK = 8192                  # queries per chunk of PhotonMap.irradiance
RECORD_BYTES = 2 * 304 + 100
# Each channel more: E and three gradients (rotational, translational, H) at 80 B, capacity
# doubling, and the interpolation's value table (7 float64).
RECORD_CHANNEL_BYTES = 2 * 80 + 56
CACHE_PIXEL_BYTES = 170
GATHER_RAY_BYTES = 500
GATHER_CHUNK_POINTS = 256            # points per placement task (indirect.place_cache)
GATHER_RAYS_PER_CALL = 1 << 19       # engine/gather.py
SHADOW_PHOTON_BYTES = 53
SHADOW_PHOTON_WORK_BYTES = 100
PIXEL_BUFFER_BYTES = 12
SAMPLE_WORK_BYTES = 640
K_OFFSET = 10                        # estimate cost ~ (k + K_OFFSET) / (50 + K_OFFSET)

# Fits (module docstring, tools/fit_cache_counts.py): cache records, uncovered look-ups.
RECORD_FIT = (3.55561, 0.12247, -0.01359, -0.13934)
UNCOVERED_FIT = (-7.73603, -0.02467, -1.02819)

GIB = float(1 << 30)


class RatesError(ValueError):
    """A rates file that cannot be used (unreadable, not JSON, wrong schema or values)."""


# -- Rates ------------------------------------------------------------------------------------
@dataclass
class Rates:
    """Seconds per unit of every ``RATE_KEYS`` entry, measured with ``workers`` threads on
    a machine with ``cores`` cores, raw embreex seconds per ray (``RAW_KEYS``) and the
    photon map's build at two sizes (``STORE_KEYS``); each group is kept whole or not at
    all."""

    seconds: dict
    workers: int = 2
    cores: int = 2
    raw: dict = field(default_factory=dict)
    measured: str = ""
    source: str = ""
    warnings: list = field(default_factory=list)

    def to_json(self) -> dict:
        return {"schema": RATES_SCHEMA, "workers": self.workers, "cores": self.cores,
                "measured": self.measured, "seconds": dict(self.seconds),
                "raw": dict(self.raw),
                "units": {k: f"seconds per unit: {v}" for k, v in RATE_KEYS.items()}}

    @classmethod
    def from_json(cls, data, source: str = "", partial: bool = False) -> "Rates":
        """Rates from parsed JSON; ``RatesError`` names what is wrong. ``partial``: rates
        may be missing (they are left out of ``seconds``)."""
        if not isinstance(data, dict):
            raise RatesError("not a JSON object")
        if data.get("schema") != RATES_SCHEMA:
            raise RatesError(f"schema {data.get('schema')!r}, expected {RATES_SCHEMA}")
        seconds = data.get("seconds")
        if not isinstance(seconds, dict):
            raise RatesError("no 'seconds' table")
        out = {}
        for key in RATE_KEYS:
            if key not in seconds:
                if partial:
                    continue
                raise RatesError(f"rate {key!r} is missing")
            value = seconds[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value < 0:
                raise RatesError(f"rate {key!r} = {value!r} is not a finite number >= 0")
            out[key] = float(value)
        workers, cores = data.get("workers", 1), data.get("cores", data.get("workers", 1))
        for name, value in (("workers", workers), ("cores", cores)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise RatesError(f"{name} = {value!r} is not a positive integer")
        raw = data.get("raw") or {}
        if not isinstance(raw, dict):
            raise RatesError("'raw' is not an object")
        raw_ok = {}
        for group in RAW_GROUPS:
            if all(isinstance(raw.get(k), (int, float)) and not isinstance(raw.get(k), bool)
                   and math.isfinite(raw[k]) and raw[k] > 0 for k in group):
                raw_ok.update({k: float(raw[k]) for k in group})
        return cls(seconds=out, workers=workers, cores=cores, raw=raw_ok,
                   measured=str(data.get("measured", "")), source=source)


def user_rates_path(platform: str | None = None) -> Path:
    """Where ``lanterna bench --calibrate`` writes this machine's rates: the user's cache
    folder as each platform names it."""
    platform = sys.platform if platform is None else platform
    home = Path(os.path.expanduser("~"))
    if platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or home / "AppData" / "Local")
    elif platform == "darwin":
        base = home / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or home / ".cache")
    return base / "lanterna" / "rates.json"


def read_rates(path, partial: bool = False) -> Rates:
    """Rates from a JSON file; ``RatesError`` (with the reason) when it cannot be used."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RatesError(f"cannot be read ({exc.strerror or exc})") from None
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise RatesError(f"is not valid JSON ({exc})") from None
    return Rates.from_json(data, source=str(path), partial=partial)


_RATES_CACHE: dict = {}


def load_rates(user_path=None, default_path=None) -> Rates:
    """The user's calibrated rates (``user_rates_path()``) where usable, else the shipped
    defaults; rates missing from the user file come from the defaults. Problems with the
    user file are in ``Rates.warnings``. Cached while neither file changes."""
    user = Path(user_path) if user_path is not None else user_rates_path()
    default = Path(default_path) if default_path is not None else DEFAULT_RATES_PATH

    def stamp(p):
        try:
            st = p.stat()
            return (st.st_mtime_ns, st.st_size)
        except OSError:
            return None

    key = (str(user), stamp(user), str(default), stamp(default))
    if key in _RATES_CACHE:
        return _RATES_CACHE[key]
    try:
        defaults = read_rates(default)
    except RatesError as exc:
        raise RatesError(f"the rates shipped with Lanterna ({default}) {exc}") from None
    rates = defaults
    if stamp(user) is not None:
        try:
            mine = read_rates(user, partial=True)
        except RatesError as exc:
            rates = Rates(**{**asdict(defaults), "warnings": [
                f"Rates file {user} {exc}; using the rates shipped with Lanterna "
                f"({default}); run 'lanterna bench --calibrate' to measure this machine's"]})
        else:
            missing = [k for k in RATE_KEYS if k not in mine.seconds]
            mine.seconds = {**defaults.seconds, **mine.seconds}
            for group in RAW_GROUPS:            # a group the user's file lacks: shipped
                if not all(k in mine.raw for k in group) and all(k in defaults.raw for k in group):
                    mine.raw.update({k: defaults.raw[k] for k in group})
            if missing:
                mine.warnings.append(f"Rates file {user} lacks {', '.join(missing)}; those "
                                     "come from the rates shipped with Lanterna")
            rates = mine
    if len(_RATES_CACHE) > 8:
        _RATES_CACHE.clear()
    _RATES_CACHE[key] = rates
    return rates


def save_rates(rates: Rates, path=None) -> Path:
    """Write ``rates`` as JSON to ``path`` (default ``user_rates_path()``), atomically (a
    temporary file in the same directory, renamed)."""
    path = Path(path) if path is not None else user_rates_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(rates.to_json(), f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


# -- What the estimate needs from a scene ------------------------------------------------------
@dataclass
class SceneFacts:
    """Counts and shares of a scene: everything ``estimate_from_facts`` reads from it."""

    triangles: int
    window: tuple                     # (width, height) of the render window [px]
    frame: tuple                      # (width, height) of the full frame [px]
    border: tuple                     # the window (x0, y0, x1, y1) in the frame [px]
    extent: float                     # diagonal of the bounds [m]
    area: float                       # total triangle area [m^2]
    survival: float                   # area-weighted mean of the materials' P_d + P_s
    first_survival: float             # the same at photons' first hits (solid-angle weighted)
    store_share: float                # area share of surfaces that store photons (P_d > 0)
    specular_share: float             # area share of surfaces with rho_s > 0
    closure: float                    # share of the bounds' faces covered by geometry
    delta_lights: int                 # point, spot, hard sun, collimated area lights
    sampled_lights: list              # (kind, shadow_photons switch, size [m]) per light
    diffuse: list                     # per material: rho_d (RGB)
    specular: list                    # per material: rho_s (RGB)
    has_emission: bool
    texture_bytes: int = 0            # the images' texels, each image once [bytes]
    texture_lookups: float = 0.0      # image look-ups per surface hit (area-weighted)
    emission_lookups: float = 0.0     # image look-ups per photon / light sample of the lights
    sky_channels: int = 0             # 3 where an image world's smooth sky goes to the gather
                                      # (its bright patches, no portals): the cache's records
                                      # then hold it apart (``indirect.FinalGather.channels``)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "SceneFacts":
        fields_ = cls.__dataclass_fields__
        out = cls(**{k: data[k] for k in fields_ if k in data or fields_[k].default is
                     dataclasses.MISSING})
        out.window = tuple(int(v) for v in out.window)
        out.frame = tuple(int(v) for v in out.frame)
        out.border = tuple(int(v) for v in out.border)
        out.sampled_lights = [tuple(v) for v in out.sampled_lights]
        return out

    @property
    def pixels(self) -> int:
        return int(self.window[0]) * int(self.window[1])

    @property
    def frame_pixels(self) -> int:
        return int(self.frame[0]) * int(self.frame[1])


def _bbox_size(points) -> float:
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))) if len(pts) else 0.0


FIRST_HIT_LIGHTS = 8                 # brightest lights whose first hits are weighed


def _first_hit_survival(scene, tris, mids, survival, chunks):
    """P_d + P_s at the photons' first hits: per point, spot and area light (the
    ``FIRST_HIT_LIGHTS`` brightest), the mean over triangles weighted by the solid angle each
    subtends at the light (Van Oosterom and Strackee; occlusion ignored: the nearest surfaces
    dominate), on the emitting side of an area light; lights weighted by their luminance flux.
    None when no such light exists (suns, the world and emissive meshes use the area mean)."""

    lights = []
    for light in scene.lights:
        if isinstance(light, (PointLight, SpotLight)):
            lights.append((float(LUMINANCE @ light.flux), light.position, None))
        elif isinstance(light, AreaLight):
            lights.append((float(LUMINANCE @ light.power), light.center, light.normal))
    lights = sorted(lights, key=lambda item: -item[0])[:FIRST_HIT_LIGHTS]
    if not lights or not len(tris) or not sum(w for w, _, _ in lights) > 0:
        return None
    total = weight = 0.0
    for flux, position, normal in lights:
        num = den = 0.0
        for a, b in chunks:
            t = tris[a:b].astype(np.float64) - np.asarray(position, np.float64)
            with np.errstate(invalid="ignore", divide="ignore"):
                t /= np.linalg.norm(t, axis=2, keepdims=True)
                omega = solid_angle(t[:, 0], t[:, 1], t[:, 2])
            if normal is not None:
                omega = omega * (t.mean(axis=1) @ np.asarray(normal, np.float64) > 0)
            omega[~np.isfinite(omega)] = 0.0
            num += float(omega @ survival[mids[a:b]])
            den += float(omega.sum())
        if den > 0:
            total += flux * num / den
            weight += flux
    return float(np.clip(total / weight, 0.0, 1.0)) if weight > 0 else None


def scene_facts(scene) -> SceneFacts:
    """The facts of ``scene`` (an ``engine.scene.Scene``, validated or not: non-finite
    triangles count as zero area). Works on the triangles in chunks of a million, so it
    needs little memory beside the scene's."""

    tris = np.asarray(scene.triangles).reshape(-1, 3, 3)
    count = len(tris)
    table = scene.material_table()
    materials = max(len(table["diffuse"]), 1)
    mids = np.clip(np.asarray(scene.material_ids).reshape(-1)[:count], 0, materials - 1)
    area_m = np.zeros(materials)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    step = 1 << 20
    chunks = [(a, min(a + step, count)) for a in range(0, count, step)]
    for a, b in chunks:
        t = tris[a:b].astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            areas = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        areas[~np.isfinite(areas)] = 0.0
        area_m += np.bincount(mids[a:b], weights=areas, minlength=materials)
        pts = t.reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    cam = np.asarray(scene.camera.matrix, np.float64)[:3, 3]
    lo, hi = np.minimum(lo, cam), np.maximum(hi, cam)
    extent = float(max(np.linalg.norm(hi - lo), 1e-30))
    # Closure: the area of triangles lying in a face of the bounds over the faces' area.
    covered = np.zeros((3, 2))
    eps = 1e-3 * extent
    for a, b in chunks:
        t = tris[a:b].astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            areas = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        areas[~np.isfinite(areas)] = 0.0
        for axis in range(3):
            for side, plane in enumerate((lo[axis], hi[axis])):
                on = np.all(np.abs(t[:, :, axis] - plane) <= eps, axis=1)
                covered[axis, side] += areas[on].sum()
    size = np.maximum(hi - lo, 0.0)
    face = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]])
    faces = float(2 * face.sum())
    closure = (float(sum(min(covered[i, j], face[i]) for i in range(3) for j in range(2)))
               / faces if faces > 0 else 0.0)
    total = float(area_m.sum())
    # (Bad values are the validate stage's to name: here they only must not poison counts.)
    diffuse = np.clip(np.nan_to_num(table["diffuse"].astype(np.float64)), 0, 1).reshape(-1, 3)
    specular = np.clip(np.nan_to_num(table["specular"].astype(np.float64)), 0, 1).reshape(-1, 3)
    p_d, p_s = roulette_probabilities(diffuse, specular)
    if total > 0 and len(p_d):
        share = area_m[:len(p_d)] / total
        survival = float(np.clip((share * (p_d + p_s)).sum(), 0.0, 1.0))
        store = float(share[p_d > 0].sum())
        spec = float(share[np.any(specular > 0, axis=1)].sum())
    else:
        survival = store = spec = 0.0

    first = _first_hit_survival(scene, tris, mids, p_d + p_s, chunks)
    delta, sampled = 0, []
    for light in scene.lights:
        if isinstance(light, (PointLight, SpotLight)):
            if light.radius > 0:           # a sphere light: sampled, no shadow photons
                sampled.append(("sphere", False, 2.0 * light.radius))
            else:
                delta += 1
        elif isinstance(light, SunLight):
            if light.angle > 1e-6:
                sampled.append(("sun", True, 0.0))
            else:
                delta += 1
        elif isinstance(light, AreaLight):
            if light.collimated:
                delta += 1
            elif light.shape in ("SQUARE", "RECTANGLE"):
                sampled.append(("area", bool(light.shadow_photons),
                                _bbox_size(area_light_triangles(light))))
            else:
                size = 2 * max(np.linalg.norm(light.axis_u), np.linalg.norm(light.axis_v))
                sampled.append(("area", bool(light.shadow_photons), float(size)))
    exitance = np.nan_to_num(table["exitance"].astype(np.float64)).reshape(-1, 3)
    emissive_materials = np.any(exitance > 0, axis=1)
    if count and emissive_materials.any():
        idx = np.nonzero(emissive_materials[mids])[0]
        oids = (np.zeros(count, np.int64) if scene.object_ids is None
                else np.asarray(scene.object_ids).reshape(-1)[:count].astype(np.int64))
        keys = oids[idx] * 65536 + mids[idx]
        for key in np.unique(keys):
            sampled.append(("mesh", True, _bbox_size(tris[idx[keys == key]])))
    if not scene.world.is_black:
        sampled.append(("world", True, 0.0))
    texture_bytes, texture_lookups, emission_lookups = _texture_facts(
        scene, area_m, exitance, extent)
    sky_channels = 3 if scene.world.has_sky_to_gather else 0
    w, h = scene.camera.window_size
    fw, fh = scene.camera.resolution
    return SceneFacts(triangles=int(count), window=(int(w), int(h)), frame=(int(fw), int(fh)),
                      border=tuple(int(v) for v in scene.camera.border),
                      extent=extent, area=total,
                      survival=survival, store_share=store, specular_share=spec,
                      first_survival=survival if first is None else first,
                      closure=float(np.clip(closure, 0.0, 1.0)),
                      delta_lights=int(delta), sampled_lights=sampled,
                      diffuse=diffuse.tolist(), specular=specular.tolist(),
                      has_emission=bool(emissive_materials.any()),
                      texture_bytes=texture_bytes, texture_lookups=texture_lookups,
                      emission_lookups=emission_lookups, sky_channels=sky_channels)


def _texture_facts(scene, area_m, exitance, extent) -> tuple[int, float, float]:
    """(texture bytes, image look-ups per surface hit, per photon or light sample): the
    texels of the distinct images the materials' graphs hold (``nodes.image_bytes``: an image
    shared between materials once); the look-ups of each material's reflectance
    (``textures.lookups_per_hit``) weighted by its share of the area; those of its emission
    weighted by its share of the lights' luminance flux (emissive meshes: pi M A per side;
    point and spot lights their flux, area lights their power, suns their irradiance over
    the bounds' disc; the world left out)."""
    materials = scene.materials
    graphs = [getattr(m, "graph", None) for m in materials]
    if not any(g is not None for g in graphs):
        return 0, 0.0, 0.0
    looks = np.array([lookups_per_hit(m) for m in materials], np.float64).reshape(-1, 2)
    total = float(area_m.sum())
    per_hit = float(area_m[:len(looks)] @ looks[:, 0]) / total if total > 0 else 0.0
    both = np.array([2.0 if m.emit_both_sides else 1.0 for m in materials])
    mesh = (exitance[:len(materials)] @ LUMINANCE) * area_m[:len(materials)] * both
    flux = float(mesh.sum())
    for light in scene.lights:
        if isinstance(light, (PointLight, SpotLight)):
            flux += float(LUMINANCE @ light.flux)
        elif isinstance(light, AreaLight):
            flux += float(LUMINANCE @ light.power)
        elif isinstance(light, SunLight):
            flux += float(LUMINANCE @ light.irradiance) * np.pi * (extent / 2) ** 2
    per_emitted = float(mesh @ looks[:, 1]) / flux if flux > 0 else 0.0
    return nodes.image_bytes(graphs), per_hit, per_emitted


def plan_for(facts: SceneFacts, settings):
    """``engine.plan.make_plan`` on the facts (stand-ins for the scene, lights and material
    table it reads), so the estimate plans exactly as the pipeline will."""
    diffuse = np.asarray(facts.diffuse, np.float64).reshape(-1, 3)
    specular = np.asarray(facts.specular, np.float64).reshape(-1, 3)
    sampled = [SimpleNamespace(kind=kind, shadow_photons=on,
                               tris=np.array([[0.0, 0.0, 0.0], [size, 0.0, 0.0]]))
               for kind, on, size in facts.sampled_lights]
    lights = SimpleNamespace(empty=facts.delta_lights == 0 and not sampled, sampled=sampled)
    materials = SimpleNamespace(diffuse=diffuse, specular=specular,
                                is_diffuse=np.any(diffuse > 0, axis=1), count=len(diffuse),
                                has_emission=facts.has_emission,
                                has_specular=bool(np.any(specular > 0)))
    return make_plan(SimpleNamespace(extent=facts.extent), settings, lights, materials)


# -- The estimate -----------------------------------------------------------------------------
@dataclass
class StageEstimate:
    name: str
    seconds: float
    keeps: int                         # bytes held from this stage to the end of the render
    working: int                       # bytes needed while it runs, freed after
    peak: int = 0                      # keeps of the stages so far + working of this one
    counts: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"seconds": round(self.seconds, 4), "keeps_bytes": int(self.keeps),
                "working_bytes": int(self.working), "peak_bytes": int(self.peak),
                "counts": {k: (round(v, 6) if isinstance(v, float) else v)
                           for k, v in self.counts.items()}}


@dataclass
class Estimate:
    stages: dict                       # name -> StageEstimate, in pipeline order
    seconds: float
    peak_bytes: int
    peak_stage: str
    plan: dict                         # stage -> reason (the plan's report)
    facts: SceneFacts
    settings: dict
    rates_source: str
    workers: int
    available_bytes: int | None = None
    warnings: list = field(default_factory=list)
    texture_seconds: float = 0.0       # the image look-ups' share of ``seconds``

    def biggest(self, n: int = 2) -> list:
        """The ``n`` stages whose memory (keeps + working) is largest: (name, bytes)."""
        sizes = [(s.name, s.keeps + s.working) for s in self.stages.values()]
        return sorted(sizes, key=lambda item: -item[1])[:n]

    def to_report(self) -> dict:
        """Plain JSON data (lists, not tuples: the same after a JSON round trip, as the
        reports that ``engine/artifacts.py`` saves must be)."""
        return json.loads(json.dumps(self._report()))

    def _report(self) -> dict:
        return {"seconds": round(self.seconds, 4), "peak_bytes": int(self.peak_bytes),
                "peak_stage": self.peak_stage, "available_bytes": self.available_bytes,
                "workers": self.workers, "rates": self.rates_source,
                "stages": {k: v.to_dict() for k, v in self.stages.items()},
                "facts": self.facts.to_dict(), "warnings": list(self.warnings),
                "texture_bytes": int(self.facts.texture_bytes),
                "texture_seconds": round(self.texture_seconds, 4)}


    def table(self) -> str:
        """The per-stage table (time, memory kept and working memory, counts) and totals."""
        lines = [f"{'stage':<20}{'time':>10}{'keeps':>11}{'working':>11}  counts"]
        for s in self.stages.values():
            counts = ", ".join(f"{_short(v)} {k.replace('_', ' ')}" for k, v in s.counts.items()
                               if not isinstance(v, str))
            lines.append(f"{s.name:<20}{format_seconds(s.seconds):>10}{format_bytes(s.keeps):>11}"
                         f"{format_bytes(s.working):>11}  {counts}")
        avail = (f", {self.available_bytes / GIB:.1f} GiB available"
                 if self.available_bytes is not None else "")
        lines.append(f"{'total':<20}{format_seconds(self.seconds):>10}  peak memory "
                     f"{format_bytes(self.peak_bytes)} (during {self.peak_stage}){avail}")
        if self.facts.texture_bytes or self.texture_seconds:
            looks = sum(float(v.counts.get("texture_lookups", 0.0))
                        for v in self.stages.values())
            lines.append(f"{'textures':<20}{format_seconds(self.texture_seconds):>10}"
                         f"{format_bytes(self.facts.texture_bytes):>11}  {_short(looks)} image "
                         "look-ups (their time is in the stages above; the texels are the "
                         "scene's, held before the render and not in its peak)")

        return "\n".join(lines)


def _short(value) -> str:
    value = float(value)
    if value >= 1e9:
        return f"{value / 1e9:.3g}G"
    if value >= 1e6:
        return f"{value / 1e6:.3g}M"
    if value >= 1e4:
        return f"{value / 1e3:.3g}k"
    return f"{value:.0f}" if value >= 10 or value == int(value) else f"{value:.2g}"


def format_seconds(s: float) -> str:
    if s < 0.01:
        return "<0.01 s"
    if s < 100:
        return f"{s:.2f} s"
    if s < 3600:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


def format_bytes(b: float) -> str:
    if b < 1 << 20:
        return f"{b / 1024:.0f} KiB" if b else "0"
    if b < 1 << 30:
        return f"{b / (1 << 20):.0f} MiB"
    return f"{b / GIB:.1f} GiB"


def record_count(pixels: int, a: float, window=None) -> float:
    """Predicted irradiance-cache records for ``pixels`` frame pixels and error ``a`` (module
    docstring)."""
    c0, c1, c2, c3 = RECORD_FIT
    lp, la = math.log(max(pixels, 1)), math.log(max(a, 1e-3))
    records = math.exp(c0 + c1 * lp + c2 * la + c3 * lp * la)
    w, h = window if window is not None else (math.sqrt(pixels),) * 2
    low = math.ceil(w / 32) * math.ceil(h / 32)
    return float(min(max(records, low), pixels))


def camera_blocks(frame, border, samples: int) -> tuple[int, int, int]:
    """(pixels, blocks, pixels of the largest block) the camera stage shades for the window
    ``border`` of a ``frame``: the square full-frame blocks of ``settings.camera_blocks``
    (side ``settings.block_side``, clipped to the frame) that meet the window; each is shaded
    whole (so tiles of a still agree)."""
    side = block_side(samples)
    (full_w, full_h), (x0, y0, x1, y1) = frame, border
    widths = [min(b * side + side, full_w) - b * side for b in range(x0 // side, -(-x1 // side))]
    heights = [min(b * side + side, full_h) - b * side for b in range(y0 // side, -(-y1 // side))]
    return (sum(widths) * sum(heights), len(widths) * len(heights),
            max(widths, default=0) * max(heights, default=0))


def radiance_estimate_count(stored: float) -> int:
    """Estimates precomputed at ``stored`` photons (``RadianceEstimates.build``'s defaults:
    a quarter of them, at most 400k)."""
    return int(min(400_000, max(1, round(0.25 * stored)))) if stored >= 0.5 else 0


def uncovered_share(pixels: int, a: float) -> float:
    """Predicted share of cache look-ups that no record covers (gathered afresh)."""
    u0, u1, u2 = UNCOVERED_FIT
    return float(min(1.0, math.exp(u0) * max(pixels, 1) ** u1 * max(a, 1e-3) ** u2))


def _log_shift(raw: dict, size_key: str, cost_key: str, size: float) -> float:
    """Cost at ``size`` minus at the small measured size (two measured sizes ``{size_key}_small
    / _large`` with costs ``{cost_key}_small / _large``, interpolated in ln size, extrapolated
    above them; sizes below the small one count as the small one, where fixed costs
    dominate). 0 when ``raw`` lacks the four entries."""
    keys = [f"{k}_{end}" for k in (size_key, cost_key) for end in ("small", "large")]
    if not all(k in raw for k in keys):
        return 0.0
    t0, t1 = raw[f"{size_key}_small"], raw[f"{size_key}_large"]
    c0, c1 = raw[f"{cost_key}_small"], raw[f"{cost_key}_large"]
    if t1 <= t0:
        return 0.0
    slope = (c1 - c0) / math.log(t1 / t0)
    return slope * (math.log(max(size, t0)) - math.log(t0))


def _trace_shift(rates: Rates, triangles: int, kind: str) -> float:
    """Raw Embree seconds per ray at ``triangles`` minus at the calibration scene's count."""
    return _log_shift(rates.raw, "triangles", kind, triangles)


def _store_shift(rates: Rates, stored: float) -> float:
    """Seconds per stored photon at a map of ``stored`` photons minus at the calibration's
    small map (``STORE_KEYS``; the Morton reorder and the kd-tree reach further out of the
    caches as the map grows)."""
    return _log_shift(rates.raw, "stored", "store", stored)


def estimate_from_facts(facts: SceneFacts, settings, rates: Rates | None = None, passes=(),
                        reused: bool = False, available: int | None = None,
                        camera: bool = True) -> Estimate:
    """The estimate for ``facts`` and ``settings`` (``RenderSettings``; the preset is applied
    here). ``reused``: the maps come from ``bake`` or a file (no photon, cache or
    shadow-photon work and no new memory for them). ``available``: bytes, for the report.
    ``camera`` False: the stages of ``bake`` only (no camera, no passes)."""

    rates = rates or load_rates()
    s = settings.resolved()
    plan = plan_for(facts, s)
    P, spp, T = facts.pixels, int(s.samples), facts.triangles
    W = min(s.worker_count, os.cpu_count() or 1)
    scale = min(rates.workers, rates.cores) / max(W, 1)
    F = facts.frame_pixels            # automatic counts follow the full frame (pipeline.py)
    shaded, batches, block = camera_blocks(facts.frame, facts.border, spp)
    pc = _photon_counts(facts, s, plan, F) if plan["photons"] else {}
    r = dict(rates.seconds)
    shifts = {key: _trace_shift(rates, T, "incoherent")
              for key in ("photon_ray", "gather_ray", "shadow_ray", "light_sample")}
    shifts["camera_sample"] = _trace_shift(rates, T, "coherent")
    if pc:
        shifts["photon_store"] = _store_shift(rates, pc["stored_all"])
    for key, shift in shifts.items():
        r[key] = max(0.3 * r[key], r[key] + shift)
    for key in PARALLEL_RATES:
        r[key] *= scale
    k_factor = (s.photon_k + K_OFFSET) / (50 + K_OFFSET)
    stages = {}

    def add(name, seconds, keeps=0, working=0, **counts):
        stages[name] = StageEstimate(name, float(seconds), int(keeps), int(working),
                                     counts=counts)

    add("validate", T * r["validate_triangle"], triangles=T)
    add("accel_build", T * r["bvh_triangle"], T * BVH_BYTES_PER_TRIANGLE, triangles=T)
    add("lights", 0.0, lights=facts.delta_lights + len(facts.sampled_lights))

    # photons, estimates, cache
    stored = 0.0
    gather_rays = s.gather_m * s.gather_n * (1.0 + s.gather_guided)
    per_gather = gather_rays * r["gather_ray"] + r["gather_point"]
    lookups = 0
    if plan["photons"]:
        lookups = shaded * min(s.photon_lookups or auto_lookups(F, spp), spp)
        emitted, rays, stored_all, stored = (pc[k] for k in ("emitted", "rays", "stored_all",
                                                             "stored"))
        if reused:
            add("photons", 0.0, emitted=0, reused=1)
        else:
            looks = emitted * facts.emission_lookups + rays * facts.closure * facts.texture_lookups
            add("photons", emitted * r["photon_emit"] + rays * r["photon_ray"]
                + stored_all * (r["photon_store"] + r["shadow_ray"])
                + looks * r["texture_lookup"], stored * PHOTON_BYTES,
                stored_all * PHOTON_BUILD_BYTES + min(W, 1 + emitted // 131072)
                * PHOTON_CHUNK_BYTES, emitted=int(emitted), photon_rays=rays, stored=stored,
                **_nonzero(texture_lookups=looks))
        if plan["radiance_estimates"]:
            n_est = pc["estimates"]
            add("radiance_estimates", n_est * r["radiance_estimate"] * k_factor,
                n_est * ESTIMATE_BYTES,
                n_est * ESTIMATE_WORK_BYTES + W * ESTIMATE_CHUNK * s.photon_k * NEIGHBOUR_BYTES,
                estimates=n_est)
        if plan["irradiance_cache"]:
            # Placed over the full frame whatever the window (a tile agrees with the frame).
            records = record_count(F, s.cache_error, facts.frame)
            if reused:
                add("irradiance_cache", 0.0, records=records, reused=1)
            else:
                looks = (F + records * gather_rays) * facts.texture_lookups
                add("irradiance_cache", F * r["cache_pixel"] + records * per_gather
                    + looks * r["texture_lookup"],
                    records * (RECORD_BYTES + (facts.sky_channels if s.mode == "full" else 0)
                               * RECORD_CHANNEL_BYTES),
                    F * CACHE_PIXEL_BYTES + W * GATHER_CHUNK_POINTS * gather_rays
                    * GATHER_RAY_BYTES, records=records, gather_rays=records * gather_rays,
                    **_nonzero(texture_lookups=looks))
    if plan["shadow_photons"]:
        radius = AUTO_SPACING * max(facts.extent, 1e-30)
        count = int(np.clip(neighbours_queried(DEFAULT_K, DEFAULT_MARGIN) * facts.area
                            / (np.pi * radius * radius), MIN_AUTO_COUNT, MAX_AUTO_COUNT))
        if reused:
            add("shadow_photons", 0.0, shadow_photons=count, reused=1)
        else:
            add("shadow_photons", count * r["shadow_photon"], count * SHADOW_PHOTON_BYTES,
                count * SHADOW_PHOTON_WORK_BYTES, shadow_photons=count)

    # camera
    wanted = parse_passes(passes)
    if not camera:
        return _finish(stages, plan, facts, s, rates, W, available, r["texture_lookup"])
    camera_rays = shaded * spp
    if s.noise_threshold > 0 and spp >= 2:
        camera_rays *= 1.0 + ADAPTIVE_BUDGET      # adaptive sampling: at most this many more
    depth = s.max_specular_depth if plan["specular"] else 0
    spec = min(facts.specular_share, 0.999)
    specular_rays = camera_rays * sum(spec ** d for d in range(1, depth + 1))
    hits = camera_rays * facts.store_share
    delta_rays = hits * facts.delta_lights if plan["direct"] else 0
    light_samples = (hits * s.light_samples
                     if plan["direct"] and facts.sampled_lights else 0)
    interpolated = gathered = photon_lookups = 0.0
    if plan["photons"]:
        if plan["irradiance_cache"]:
            gathered = lookups * uncovered_share(F, s.cache_error)
            interpolated = lookups - gathered
        elif plan["final_gather"]:
            gathered = lookups
        else:
            photon_lookups = lookups
    running = min(W, batches)
    batch_samples = block * spp
    gather_work = 0.0
    if gathered:
        per_batch = gathered / batches * gather_rays
        gather_work = running * min(GATHER_RAYS_PER_CALL, per_batch) * GATHER_RAY_BYTES
    lookup_work = running * LOOKUP_CHUNK * s.photon_k * NEIGHBOUR_BYTES if photon_lookups else 0
    split = sum(name in wanted for name in ("Emission", "Direct", "Indirect"))
    usage = 16 * P if "CacheUsage" in wanted and plan["irradiance_cache"] else 0
    if set(wanted) & set(LIGHT_PASS_NAMES):
        usage += len(LIGHT_PASS_NAMES) * 24 * P
    texture_lookups = ((camera_rays + specular_rays + gathered * gather_rays)
                       * facts.texture_lookups + light_samples * facts.emission_lookups)
    counts = dict(camera_rays=camera_rays)
    for name, value in (("specular_rays", specular_rays), ("shadow_rays", delta_rays),
                        ("light_samples", light_samples), ("lookups", lookups),
                        ("interpolated", interpolated), ("gathered", gathered),
                        ("photon_lookups", photon_lookups),
                        ("texture_lookups", texture_lookups)):
        if value:
            counts[name] = value
    add("camera", (camera_rays + specular_rays) * r["camera_sample"]
        + delta_rays * r["shadow_ray"] + light_samples * r["light_sample"]
        + interpolated * r["cache_lookup"] + gathered * per_gather
        + photon_lookups * r["photon_lookup"] * k_factor
        + texture_lookups * r["texture_lookup"],
        (1 + split) * P * PIXEL_BUFFER_BYTES + usage,
        running * batch_samples * SAMPLE_WORK_BYTES + gather_work + lookup_work, **counts)
    diagnostic = set(wanted) - {"Emission", "Direct", "Indirect"}
    if diagnostic:
        seconds = P * r["camera_sample"] if {"PhotonMap", "ShadowClasses"} & diagnostic else 0.0
        if "PhotonMap" in diagnostic:
            seconds += P * r["photon_lookup"] * k_factor
        add("passes", seconds, len(diagnostic) * P * PIXEL_BUFFER_BYTES, P * CACHE_PIXEL_BYTES,
            passes=len(diagnostic))

    return _finish(stages, plan, facts, s, rates, W, available, r["texture_lookup"])


def _nonzero(**counts) -> dict:
    """The counts that are not zero (a stage lists texture look-ups only where there are)."""
    return {k: v for k, v in counts.items() if v}


def _photon_counts(facts: SceneFacts, s, plan, pixels: int) -> dict:
    """Photons emitted (automatic: from the full frame's ``pixels``), photon rays, stored
    (all, and kept) and radiance estimates (module docstring)."""
    emitted = s.photons or auto_photon_count(pixels)
    c = facts.closure
    rho = min(facts.survival * c, 0.999)
    later = (1.0 - rho ** s.bounces) / (1.0 - rho)          # sum_{i<B} (c rho)^i
    rays = emitted * (1.0 + facts.first_survival * c * later)
    stored_all = rays * c * facts.store_share
    keep_all = not (s.mode == "full" and not plan["final_gather"])
    stored = stored_all if keep_all else stored_all - emitted * c * facts.store_share
    estimates = radiance_estimate_count(stored) if plan["radiance_estimates"] else 0
    return dict(emitted=emitted, rays=rays, stored_all=stored_all, stored=stored,
                estimates=estimates)


def _finish(stages, plan, facts, settings, rates, workers, available,
            texture_rate: float = 0.0) -> Estimate:
    """Totals; the peak is the largest keeps of the stages so far + a stage's working
    memory; ``texture_rate`` [s] per image look-up, for the look-ups' share of the time."""
    kept, peak, peak_stage = 0, 0, "validate"
    for stage in stages.values():
        stage.peak = kept + stage.keeps + stage.working
        kept += stage.keeps
        if stage.peak > peak:
            peak, peak_stage = stage.peak, stage.name
    return Estimate(stages=stages, seconds=sum(v.seconds for v in stages.values()),
                    peak_bytes=int(peak), peak_stage=peak_stage, plan=plan.to_report(),
                    facts=facts, settings=asdict(settings), rates_source=rates.source,
                    workers=workers, available_bytes=available, warnings=list(rates.warnings),
                    texture_seconds=texture_rate * sum(float(v.counts.get("texture_lookups", 0))
                                                       for v in stages.values()))


def estimate_cost(scene, settings=None, rates: Rates | None = None, passes=(),
                  reused: bool = False) -> Estimate:
    """The estimate of rendering ``scene`` with ``settings`` (module docstring)."""
    settings = settings or RenderSettings()
    return estimate_from_facts(scene_facts(scene), settings, rates, passes, reused,
                               available_memory())


def check_memory(estimate: Estimate, available: int | None = None) -> None:
    """``SceneError`` when the estimate's peak memory exceeds ``available`` bytes (default
    ``available_memory()``); the message gives the estimate, its biggest stages and what
    to lower."""
    if available is None:
        available = available_memory()
    if available is None or estimate.peak_bytes <= available:
        return
    biggest = ", ".join(f"{name.replace('_', ' ')} {b / GIB:.1f} GiB"
                        for name, b in estimate.biggest(2) if b > 0)
    hints = {"photons": "the photon count", "radiance_estimates": "the photon count",
             "irradiance_cache": "the resolution or the gather size",
             "camera": "the resolution or the samples", "accel_build": "the geometry",
             "shadow_photons": "the shadow photons (switch them off)",
             "passes": "the passes"}
    lower = []
    for name, _ in estimate.biggest(2):
        hint = hints.get(name)
        if hint and hint not in lower:
            lower.append(hint)
    raise SceneError(f"Render settings: this render needs about {estimate.peak_bytes / GIB:.1f} "
                     f"GiB ({biggest}) but only {available / GIB:.1f} GiB is available; lower "
                     f"{' or '.join(lower) or 'the resolution'}")


def preflight(scene, settings, passes=(), reused: bool = False, camera: bool = True) -> dict:
    """For ``pipeline.render`` and ``pipeline.bake`` (``camera`` False), before any work: the
    estimate as a report entry; ``SceneError`` (from ``check_memory``) when it cannot fit. A
    scene whose arrays cannot even be counted gets ``{"error": ...}`` and is left to the
    validate stage, which names the problem."""
    t0 = time.perf_counter()
    available = available_memory()
    try:
        facts = scene_facts(scene)
        rates = load_rates()
        estimate = estimate_from_facts(facts, settings, rates, passes, reused, available, camera)
    except SceneError:
        raise
    except (ValueError, IndexError, TypeError, AttributeError, ArithmeticError,
            RatesError) as exc:
        return {"error": f"{type(exc).__name__}: {exc}"}
    check_memory(estimate, available)
    out = estimate.to_report()
    out["estimate_seconds"] = round(time.perf_counter() - t0, 6)
    return out
