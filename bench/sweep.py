"""Quality sweep: Lanterna's error against its time, knob by knob, beside Cycles (issue 6).

What it computes (``lanterna bench --sweep``)
    For each scene (the seed's Scene 1 and Scene 2 built by ``engine/blender/seed_scenes.py``,
    or the active scene of a ``.blend``), at ``--resolution`` (default 160 x 120, where the
    stored Cycles references exist), in one process:

    1. The reference: ``--reference EXR`` when given; else for a seed scene at 160 x 120 the
       stored ``tests/data/cycles_gi/<scene>.npz`` (Cycles, 4 seeds x 768 spp); else a Cycles
       render at ``--reference-samples`` (4096) split over 2 seeds, made on demand and cached
       in ``out/bench_cache/`` (``bench_cycles.rendered_reference``; a ``.blend``'s cache key
       is its file name, a hash of its absolute path and modification time, the resolution
       and the sample count, so an edited file gets a new reference).
    2. Lanterna at every point of the sweep: ``pipeline.render(scene, RenderSettings(...,
       seed=1))`` on the scene exported once. One untimed ``preview`` render comes first (a
       process's first render is 20-40 % slower: fresh memory). Each point is rendered once
       (``--repeat N``: N times, the fastest run's time and stages kept; a fixed seed gives
       the same picture every time).
    3. Cycles as the peer curve, on the same bpy scene after Lanterna: each of
       ``--cycles-samples`` (16, 64, 256, 1024; ``--quick``: 16, 64) once, with the
       settings of the GI references (``tests/data/make_cycles_refs.py``), via
       ``bench_cycles.cycles_curve``: one render with OIDN on gives the noisy and the
       denoised image; the noisy one's time is the render's less OIDN's own time (a 1-spp
       difference, see ``bench_cycles.measure_denoise_seconds``), and at least a 1-spp
       render's; ``--repeat N``: the whole
       curve N times, the fastest time per render kept.

The sweep (``--knobs``, all five by default; ``samples``, the camera samples, can be added)
    The base point is the ``final`` preset resolved to its values (16 spp, 8 light samples,
    1M photons, k = 50, gather 12 x 48, a = 0.1, irradiance cache); ``--base`` changes it
    (``--base preview`` or ``--base photons=500000,gather=8x32``: the final preset with those
    values). Each knob then varies alone, the others at the base:

    ==============  =====================================  ===============  ===============
    knob            full range                             ``--quick``      RenderSettings
    ==============  =====================================  ===============  ===============
    photons         100k, 250k, 500k, 1M, 2M               250k             photons
    photon_k        20, 50, 100, 200                       20               photon_k
    gather          4x16, 6x24, 8x32, 12x48, 16x64         6x24             gather_m x _n
    cache_error     0.05, 0.1, 0.2, 0.3, 0.4               0.3              cache_error (a)
    light_samples   1, 2, 4, 8, 16                         2                light_samples
    samples         4, 8, 16, 32 (not swept by default)    4                samples
    ==============  =====================================  ===============  ===============

    A value equal to the base's is the base point itself (rendered once, on every knob's
    curve). The presets of ``--presets`` (``preview``, ``final``) are marked points; one whose
    values equal a point already swept (``final`` is the base) is that point. Full sweep:
    1 base + 19 knob points + ``preview`` = 21 Lanterna renders and 4 Cycles renders (plus
    the warm-ups and OIDN's timing): about 5 min for Scene 1 and 7 min for Scene 2 at
    160 x 120 on 2 idle cores (``final`` takes 8 and 13 s there, Cycles 1024 spp about a
    minute); an estimate is printed up front and refined after the base point.
    ``--quick``: 1 + 5 + 1 = 7 Lanterna renders and Cycles at 16 and 64 spp, about 1.5 min
    for Scene 1 on 2 idle cores (3.4 min measured with a load average of 8-10).

Each point's figures
    seconds       wall time of ``pipeline.render`` (export excluded) [s]; Cycles: see 3.
    cpu_seconds   the process's user + system CPU time over the render [s] (Lanterna only): on
                  a loaded machine wall time grows and this does not, so it shows the load.
    stage shares  ``report["stages"][name]["seconds"]`` / seconds, per stage (validate,
                  accel_build, lights, photons, radiance_estimates, irradiance_cache,
                  shadow_photons, camera); ``other`` = 1 - their sum.
    peak memory   the process's peak resident set size during the render [MB], and that peak
                  less the resident size just before it (the render's own working memory).
                  ``report["peak_memory_mb"]`` is ``ru_maxrss``, the process's peak since it
                  started, which only grows over a sweep; instead, before each point, after
                  ``gc.collect()`` and glibc's ``malloc_trim(0)``, the kernel's peak (VmHWM)
                  is reset by writing ``5`` to ``/proc/self/clear_refs`` and read back after
                  the render: exact and free, same process, so timings stay warm (a fresh
                  process per point would pay bpy's import and a cold first render each
                  time). Where that file cannot be written, a thread samples the resident
                  size every 5 ms (``sampled``); without ``/proc``, the process-wide peak
                  of ``engine/memory.py`` (its platform's unit; None where unknown). The method is in the JSON. Not measured for Cycles.
    rel_rmse      sqrt(mean((img - ref)^2)) / mean(ref), all pixels and channels
                  (``bench_cycles.errors``).
    rel_rmse_corrected  sqrt(max(MSE - v, 0)) / mean(ref), v the reference's own per-pixel
                  noise variance (stored references: from their 4 seeds; rendered: from the 2
                  seeds' difference; a given EXR: unknown, so absent and rel_rmse is used).
    region mean / worst  the 4 x 4 blocks' |mean(img) / mean(ref) - 1| (means over each block's
                  pixels and channels): their mean and their maximum.
    error         the figure plotted and compared: rel_rmse_corrected when the reference's
                  noise is known, else rel_rmse.

Analysis
    Pareto front: the Lanterna points (sweep and presets) that no other Lanterna point beats in
    both seconds and error (non-dominated), drawn as a step line (the least error reachable
    within a time). For each preset: the front's error at the preset's time, interpolated
    linearly in log(seconds)-log(error) between the front's points (flat after the last
    one), and the preset's error over it: 1.0 on the front, "on the front" when <= 1.10
    (10 %); also the same ratio against the front of the other points (< 1: it beats every
    other setting at its time). Cycles' time for the same error: where the Cycles curve (in
    sample order) first falls to the preset's error, interpolated in log-log; "<= t" when
    Cycles' fewest samples already do better, "beyond the curve" when its most samples do not
    reach it; for the noisy and the OIDN curve, with the ratio to the preset's time.

Outputs in ``--out`` (default ``out/sweep``), per scene ``<scene>`` (a .blend: its stem)
    ``<scene>_sweep.csv``   one row per point (Lanterna points, then Cycles without and with
                            OIDN per sample count): scene, method, knob, value, preset, label,
                            samples, seconds, cpu_seconds, rel_rmse, rel_rmse_corrected,
                            error,
                            region_mean_rel_error, region_worst_rel_error, peak_rss_mb,
                            peak_above_start_mb, on_front, share_<stage>..., share_other,
                            settings (JSON).
    ``<scene>_sweep.json``  everything: the command, machine, reference, every point with
                            its stage seconds and block ratios, the front, the presets'
                            analysis, Cycles' settings, definitions.
    ``<scene>_sweep.png``   log-log error against seconds (matplotlib, Agg): one line per
                            knob, Cycles without and with OIDN, the presets as large labelled
                            stars, the front as a grey step line; the title names the scene,
                            resolution and machine (CPU count, platform).

Command line
    ``lanterna bench --sweep [SCENE.blend | --scenes scene1,scene2] [--resolution WxH]``
    ``[--reference EXR] [--reference-samples N] [--knobs photons,photon_k,gather,``
    ``cache_error,light_samples] [--base SPEC] [--presets preview,final|none]``
    ``[--cycles-samples 16,64,256,1024|none] [--out DIR] [--repeat N] [--quick]``

This is a benchmark, not a test: it asserts nothing, prints a table, the presets' ratios and
where the files went. Expected failures (a bad flag, a missing or unreadable file, a scene
that cannot be built or exported, a failed Cycles render) print one ``lanterna bench: error:
...`` line; the exit status is then 2.
"""
from __future__ import annotations

import contextlib
import csv
import ctypes
import datetime
import gc
import hashlib
import json
import math
import os
import platform
import shlex
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from .vs_cycles import (CACHE_DIR, CYCLES_SEED, DEFAULT_REFERENCE_SAMPLES, LANTERNA_SEED,
                           SCENE_TITLES, STORED_REFERENCES, STORED_RESOLUTION, BenchError,
                           int_list, log, Parser, parse_resolution, run_command)
from ..engine.memory import peak_memory

PROG = "lanterna bench --sweep"
DEFAULT_SCENES = ("scene1", "scene2")
DEFAULT_CYCLES_SAMPLES = (16, 64, 256, 1024)
QUICK_CYCLES_SAMPLES = (16, 64)
DEFAULT_OUT = os.path.join("out", "sweep")
DEFAULT_PRESETS = ("preview", "final")
BASE_PRESET = "final"
# The settings a point sets (the others stay at RenderSettings' defaults: full mode, 64
# bounces, automatic photon look-ups and radius, guided gather 1, shadow photons on).
SWEEP_FIELDS = ("samples", "light_samples", "photons", "photon_k", "gather_m", "gather_n",
                "cache_error", "indirect")
# knob -> (full range, --quick values); the base's value joins each curve.
KNOBS = {
    "photons": ((100_000, 250_000, 500_000, 1_000_000, 2_000_000), (250_000,)),
    "photon_k": ((20, 50, 100, 200), (20,)),
    "gather": (((4, 16), (6, 24), (8, 32), (12, 48), (16, 64)), ((6, 24),)),
    "cache_error": ((0.05, 0.1, 0.2, 0.3, 0.4), (0.3,)),
    "light_samples": ((1, 2, 4, 8, 16), (2,)),
    "samples": ((4, 8, 16, 32), (4,)),
}
DEFAULT_KNOBS = ("photons", "photon_k", "gather", "cache_error", "light_samples")
STAGE_ORDER = ("validate", "accel_build", "lights", "photons", "radiance_estimates",
               "irradiance_cache", "shadow_photons", "camera", "passes")
ON_FRONT_TOLERANCE = 0.10          # a preset within 10 % of the front's error is "on" it
# Rough costs for the estimate printed up front (2 shared cores, seed scenes, 2026-11):
FINAL_SECONDS_160x120 = 10.0       # Lanterna's final preset: 8-13 s at 160 x 120 ...
FINAL_PIXEL_EXPONENT = 0.2         # ... and 14-17 s at 640 x 480 (16x the pixels)
CYCLES_SECONDS_PER_SAMPLE = 3.5e-6  # Cycles, per sample and pixel (2.5-4.5e-6 measured)
CYCLES_RENDER_OVERHEAD = 0.7       # scene sync, BVH, EXR per Cycles render [s]
DEFINITIONS = {
    "seconds": "Lanterna: wall time of pipeline.render (export excluded); Cycles: "
               "bpy.ops.render.render(write_still=True) with OIDN on, less OIDN's own time for "
               "the noisy image",
    "stage_shares": "report['stages'][name]['seconds'] / seconds; other = 1 - their sum",
    "peak_rss_mb": "the process's peak resident set size during the render [MB]",
    "peak_above_start_mb": "peak_rss_mb less the resident size just before the render",
    "rel_rmse": "sqrt(mean((img - ref)^2)) / mean(ref), all pixels and channels",
    "rel_rmse_corrected": "sqrt(max(MSE - v, 0)) / mean(ref), v = the reference's per-pixel "
                          "noise variance",
    "region_mean_rel_error": "mean over the 4x4 blocks of |mean(img)/mean(ref) - 1|",
    "region_worst_rel_error": "max over the 4x4 blocks of |mean(img)/mean(ref) - 1|",
    "error": "rel_rmse_corrected where the reference's noise is known, else rel_rmse",
    "front": "Lanterna points no other Lanterna point beats in both seconds and error",
    "front_error_ratio": "a preset's error / the front's error at its time (log-log "
                         "interpolation between front points, flat after the last); on the "
                         f"front when <= {1 + ON_FRONT_TOLERANCE:.2f}",
    "cycles_seconds_for_same_error": "the time at which the Cycles curve (sample order) first "
                                     "falls to the preset's error, log-log interpolation",
}


# -- Small numerics (tested on hand-made data) ----------------------------------------------------
def loglog_interp(x: float, xs, ys) -> float | None:
    """y at ``x`` by linear interpolation of log(y) against log(x) between the points
    (``xs`` increasing); None when ``x`` lies outside [xs[0], xs[-1]] or any value used is not
    positive."""
    xs = np.asarray(xs, np.float64)
    ys = np.asarray(ys, np.float64)
    if len(xs) == 0 or not x > 0 or x < xs[0] or x > xs[-1]:
        return None
    if np.any(xs <= 0) or np.any(ys <= 0):
        return None
    if len(xs) == 1:
        return float(ys[0])
    return float(np.exp(np.interp(math.log(x), np.log(xs), np.log(ys))))


def pareto_front(points) -> list[int]:
    """Indices of the non-dominated points of ``points`` [(seconds, error), ...]: no other
    point has seconds <= and error <= with one of them strictly less (of equal points, the
    first). Sorted by seconds, so the errors fall strictly along it."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1], i))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def front_error_at(front, seconds: float) -> float | None:
    """The front's error at ``seconds``: ``front`` [(seconds, error)] sorted by seconds (as
    ``pareto_front`` orders it); log-log interpolation between its points, the last point's
    error after it (more time can always run that setting), None before its first point."""
    if not front or seconds < front[0][0]:
        return None
    if seconds >= front[-1][0]:
        return float(front[-1][1])
    xs, ys = zip(*front)
    value = loglog_interp(seconds, xs, ys)
    if value is None:           # a zero error on the front: log-log does not apply; step
        i = max(j for j in range(len(front)) if front[j][0] <= seconds)
        value = float(front[i][1])
    return value


def time_for_error(curve, error: float) -> dict:
    """Where a curve [(seconds, error)] in sample order first falls to ``error``:
    {"seconds", "status"}: "interpolated" (log-log between the two renders around it),
    "at_most" (its first render already has less error: seconds = that render's time, an upper
    bound), "beyond" (its last render does not reach it: seconds None), or "n/a" (no curve or
    an error <= 0)."""
    pts = [(float(s), float(e)) for s, e in curve if s is not None and e is not None]
    if not pts or not error > 0:
        return {"seconds": None, "status": "n/a"}
    if pts[0][1] <= error:
        return {"seconds": pts[0][0], "status": "at_most"}
    for (s0, e0), (s1, e1) in zip(pts, pts[1:]):
        if e0 > error >= e1:
            if min(s0, s1, e0, e1) <= 0:
                return {"seconds": s1, "status": "interpolated"}
            f = (math.log(error) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return {"seconds": math.exp(math.log(s0) + f * (math.log(s1) - math.log(s0))),
                    "status": "interpolated"}
    return {"seconds": None, "status": "beyond"}


# -- Peak memory per point ---------------------------------------------------------------------
def _status_kb(field: str) -> int | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process so far (all its threads; ``os.times`` has
    them on every platform, ``resource`` only on POSIX)."""
    times = os.times()
    return times.user + times.system


def _resident_mb() -> float | None:
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return None


def _malloc_trim() -> None:
    with contextlib.suppress(Exception):
        ctypes.CDLL("libc.so.6").malloc_trim(0)


class PeakMemory:
    """The process's peak resident size during a block of work [MB], reset per block (see
    the module's docstring: ``vmhwm``, ``sampled`` or ``ru_maxrss``)."""

    SAMPLE_SECONDS = 0.005

    def __init__(self):
        self.method = "ru_maxrss"
        if self._reset_hwm() and _status_kb("VmHWM") is not None:
            self.method = "vmhwm"
        elif _resident_mb() is not None:
            self.method = "sampled"

    @staticmethod
    def _reset_hwm() -> bool:
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
            return True
        except OSError:
            return False

    @contextlib.contextmanager
    def measure(self):
        gc.collect()
        _malloc_trim()
        out = {"method": self.method, "rss_start_mb": _resident_mb()}
        if self.method == "vmhwm":
            self._reset_hwm()
            yield out
            out["peak_rss_mb"] = _status_kb("VmHWM") / 1024.0
        elif self.method == "sampled":
            stop = threading.Event()
            peak = [out["rss_start_mb"] or 0.0]

            def sample():
                while not stop.wait(self.SAMPLE_SECONDS):
                    peak[0] = max(peak[0], _resident_mb() or 0.0)

            thread = threading.Thread(target=sample, daemon=True)
            thread.start()
            try:
                yield out
            finally:
                stop.set()
                thread.join()
            out["peak_rss_mb"] = max(peak[0], _resident_mb() or 0.0)
        else:
            yield out
            # The process's peak in the platform's own unit (engine/memory.py), None where
            # the platform cannot tell.
            out["peak_rss_mb"] = peak_memory().megabytes
        start = out["rss_start_mb"]
        out["peak_above_start_mb"] = (None if start is None or out["peak_rss_mb"] is None
                                      else max(out["peak_rss_mb"] - start, 0.0))


# -- The sweep's points ------------------------------------------------------------------------
def _parse_knob_value(knob: str, text: str):
    text = text.strip()
    try:
        if knob == "gather":
            m, n = (int(v) for v in text.lower().split("x"))
            if not (1 <= m <= 256 and 1 <= n <= 1024):
                raise ValueError
            return (m, n)
        if knob == "cache_error":
            value = float(text)
            if not (math.isfinite(value) and 0.01 <= value <= 10):
                raise ValueError
            return value
        value = int(float(text)) if knob == "photons" else int(text)
        lowest = {"light_samples": 0}.get(knob, 1)
        if value < lowest or (knob == "photon_k" and value > 10_000):
            raise ValueError
        return value
    except ValueError:
        hint = {"gather": "MxN, e.g. 8x32", "cache_error": "a number in [0.01, 10]",
                "photon_k": "an integer 1-10000"}.get(knob, "a positive integer")
        raise BenchError(f"--base {knob}={text}: expected {hint}") from None


def apply_knob(values: dict, knob: str, value) -> dict:
    out = dict(values)
    if knob == "gather":
        out["gather_m"], out["gather_n"] = value
    else:
        out[knob] = value
    return out


def knob_value_of(values: dict, knob: str):
    return (values["gather_m"], values["gather_n"]) if knob == "gather" else values[knob]


def preset_values(name: str) -> dict:
    from ..engine.settings import RenderSettings

    settings = RenderSettings(preset=name).resolved()
    return {k: getattr(settings, k) for k in SWEEP_FIELDS}


def base_values(spec: str) -> tuple[dict, str]:
    """``--base``: a preset name and/or knob=value items -> (values, description)."""
    from ..engine.settings import PRESETS, RenderSettings
    from ..engine.scene import SceneError

    items = [s.strip() for s in spec.split(",") if s.strip()]
    names = [s for s in items if "=" not in s]
    if len(names) > 1 or any(n not in PRESETS for n in names):
        raise BenchError(f"--base {spec}: at most one preset ({', '.join(PRESETS)}) and "
                         f"knob=value items ({', '.join(KNOBS)})")
    values = preset_values(names[0] if names else BASE_PRESET)
    for item in items:
        if "=" not in item:
            continue
        knob, text = item.split("=", 1)
        knob = knob.strip()
        if knob not in KNOBS:
            raise BenchError(f"--base {item}: unknown knob {knob!r} (one of {', '.join(KNOBS)})")
        values = apply_knob(values, knob, _parse_knob_value(knob, text))
    try:
        RenderSettings(**values).validate()
    except SceneError as exc:
        raise BenchError(f"--base {spec}: {exc}") from None
    return values, ",".join(items) or BASE_PRESET


def fmt_value(knob: str, value) -> str:
    if knob == "gather":
        return f"{value[0]}x{value[1]}"
    if knob == "photons":
        v = int(value)
        if v >= 1_000_000 and v % 100_000 == 0:
            return f"{v / 1_000_000:g}M"
        if v >= 1000 and v % 1000 == 0:
            return f"{v // 1000}k"
        return str(v)
    return f"{value:g}" if isinstance(value, float) else str(value)


def plan_points(knobs, quick: bool, base: dict, presets) -> list[dict]:
    """The Lanterna points: the base, each knob's values other than the base's, then the
    presets not equal to a point already planned (those mark that point)."""
    points = [{"knob": "base", "value": None, "values": base, "presets": []}]
    for knob in knobs:
        full, short = KNOBS[knob]
        seen = {knob_value_of(base, knob)}
        for value in (short if quick else full):
            if value in seen:
                continue
            seen.add(value)
            points.append({"knob": knob, "value": value, "values": apply_knob(base, knob, value),
                           "presets": []})
    for name in presets:
        values = preset_values(name)
        same = next((p for p in points if p["values"] == values), None)
        if same is not None:
            same["presets"].append(name)
        else:
            points.append({"knob": "preset", "value": name, "values": values, "presets": [name]})
    for p in points:
        p["label"] = point_label(p)
    return points


def point_label(p: dict) -> str:
    if p["knob"] == "base":
        text = "base"
    elif p["knob"] == "preset":
        text = f"preset {p['value']}"
    else:
        text = f"{p['knob']}={fmt_value(p['knob'], p['value'])}"
    extra = [n for n in p["presets"] if p["knob"] != "preset"]
    return text + (f" = {'/'.join(extra)}" if extra else "")


# -- Estimates ---------------------------------------------------------------------------------
def estimate_seconds(n_lanterna: int, cycles_samples, resolution, reference_samples=0,
                     repeat=1) -> dict:
    """A rough run time [s] from costs measured on 2 cores, scaled by the core count."""
    w, h = resolution
    pixels = w * h
    scale = 2.0 / max(1, os.cpu_count() or 1)
    per_point = FINAL_SECONDS_160x120 * scale * (pixels / 19200.0) ** FINAL_PIXEL_EXPONENT
    lan = (n_lanterna * repeat + 0.25) * per_point                # + the preview warm-up
    cyc_renders = len(cycles_samples) + (5 if cycles_samples else 0)  # warm-up + OIDN timing
    cyc = repeat * ((sum(cycles_samples) + 5) * pixels * CYCLES_SECONDS_PER_SAMPLE * scale
                    + cyc_renders * CYCLES_RENDER_OVERHEAD) if cycles_samples else 0.0
    ref = (reference_samples * pixels * CYCLES_SECONDS_PER_SAMPLE * scale
           + 2 * CYCLES_RENDER_OVERHEAD) if reference_samples else 0.0
    return {"lanterna": lan, "per_point": per_point, "cycles": cyc, "reference": ref,
            "total": lan + cyc + ref}


def _minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


# -- Reference ---------------------------------------------------------------------------------
def read_reference_exr(path: str, resolution) -> dict:
    """A given reference EXR: channels R, G, B (or a layer's ``*.Combined.R``...), (H, W)
    matching ``resolution``; its noise is unknown."""
    from ..engine import imageio

    try:
        channels = imageio.read_exr(path)
    except Exception as exc:  # noqa: BLE001 - reported as one line
        raise BenchError(f"--reference {path}: cannot be read as OpenEXR: "
                         f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
    prefix = ""
    if not all(c in channels for c in "RGB"):
        layers = sorted(k[:-1] for k in channels if k.endswith("Combined.R"))
        if not layers or not all(layers[0] + c in channels for c in "RGB"):
            raise BenchError(f"--reference {path}: no R, G, B channels (has "
                             f"{', '.join(sorted(channels)[:8])})")
        prefix = layers[0]
    image = np.stack([channels[prefix + c] for c in "RGB"], axis=-1).astype(np.float64)
    w, h = resolution
    if image.shape[:2] != (h, w):
        raise BenchError(f"--reference {path}: {image.shape[1]}x{image.shape[0]} pixels, the "
                         f"sweep renders {w}x{h} (--resolution)")
    if not np.all(np.isfinite(image)) or not image.mean() > 0:
        raise BenchError(f"--reference {path}: not finite, or black")
    return {"image": image, "variance": None, "samples": None, "seconds": None,
            "source": f"given {path} (its noise unknown: errors not corrected for it)"}


def blend_cache_key(path: str) -> str:
    """The cache name of a .blend's reference: its stem and a hash of its absolute path and
    modification time (``rendered_reference`` adds the resolution and sample count)."""
    path = os.path.abspath(path)
    stamp = f"{path}|{os.stat(path).st_mtime_ns}"
    return f"{Path(path).stem}-{hashlib.sha1(stamp.encode()).hexdigest()[:12]}"


# -- One scene ---------------------------------------------------------------------------------
def _load_scene(spec: dict, resolution):
    """The bpy scene of ``spec`` (a seed scene or a .blend) at ``resolution``, no border."""
    import bpy

    from .vs_cycles import build_seed_scene

    if spec["blend"] is None:
        bscene = build_seed_scene(spec["name"], resolution)
    else:
        from ..engine.blender.cli import UsageError, open_blend

        try:
            bscene = open_blend(spec["blend"])
        except UsageError as exc:
            raise BenchError(str(exc)) from None
        bscene.render.resolution_x, bscene.render.resolution_y = resolution
        bscene.render.resolution_percentage = 100
    bscene.render.use_border = False
    bpy.context.view_layer.update()
    return bscene


def _reference(spec, args, bscene, cycles, tmpdir) -> dict:
    from .vs_cycles import rendered_reference, stored_reference

    if args.reference:
        return read_reference_exr(args.reference, args.resolution)
    if spec["blend"] is None:
        ref = stored_reference(spec["name"], args.resolution)
        if ref is not None:
            return ref
        key = spec["name"]
    else:
        key = blend_cache_key(spec["blend"])
    configure, render_exr, _source = cycles
    try:
        return rendered_reference(key, bscene, args.resolution, args.reference_samples,
                                  configure, render_exr, tmpdir)
    except BenchError:
        raise
    except Exception as exc:  # noqa: BLE001 - a failed Cycles render, one line
        raise BenchError(f"{spec['name']}: the Cycles reference failed: "
                         f"{' '.join(str(exc).split())}") from None


def _reference_ready(spec, args) -> bool:
    """Whether the reference exists (stored or cached), for the estimate."""
    w, h = args.resolution
    if spec["blend"] is None and tuple(args.resolution) == STORED_RESOLUTION:
        return (STORED_REFERENCES / f"{spec['name']}.npz").is_file()
    key = spec["name"] if spec["blend"] is None else blend_cache_key(spec["blend"])
    return (CACHE_DIR / f"{key}_{w}x{h}_{args.reference_samples}.npz").is_file()


def figures(image, ref: dict) -> dict:
    """An image's errors against ``ref`` ({"image": (H, W, 3), "variance": the reference's
    per-pixel noise variance or None}): rel_rmse, rel_rmse_corrected (None without the
    variance), region_mean_rel_error and region_worst_rel_error (the 4 x 4 blocks'
    |mean(img) / mean(ref) - 1|: mean and max), block_ratios, mse, and ``error``: the corrected
    figure where the variance is known, else rel_rmse (the module docstring's columns)."""
    from .vs_cycles import errors

    e = errors(image, ref["image"], ref["variance"])
    dev = np.abs(np.asarray(e["block_ratios"], np.float64) - 1.0)
    out = {"rel_rmse": e["rel_rmse"], "rel_rmse_corrected": e.get("rel_rmse_corrected"),
           "region_mean_rel_error": float(dev.mean()),
           "region_worst_rel_error": float(dev.max()), "block_ratios": e["block_ratios"],
           "mse": e["mse"]}
    out["error"] = (out["rel_rmse_corrected"] if out["rel_rmse_corrected"] is not None
                    else out["rel_rmse"])
    return out


def sweep_scene(spec: dict, args, cycles, tmpdir, warm: dict, memory: PeakMemory) -> dict:
    import bpy

    from .vs_cycles import cycles_curve
    from ..engine.blender.export import export_scene
    from ..engine.pipeline import RenderSettings, render
    from ..engine.scene import SceneError

    name = spec["name"]
    w, h = args.resolution
    started = time.perf_counter()
    bscene = _load_scene(spec, args.resolution)
    points = plan_points(args.knobs, args.quick, args.base, args.presets)
    reference_pending = not args.reference and not _reference_ready(spec, args)
    est = estimate_seconds(len(points), args.cycles_samples, args.resolution,
                           args.reference_samples if reference_pending else 0, args.repeat)
    print(f"\n{spec['title']} ({name}) at {w}x{h}: {len(points)} Lanterna points, Cycles at "
          f"{', '.join(map(str, args.cycles_samples)) or 'none'} spp; estimated run time about "
          f"{_minutes(est['total'])} (Lanterna {_minutes(est['lanterna'])}, Cycles "
          f"{_minutes(est['cycles'])}"
          + (f", reference {_minutes(est['reference'])} unless cached" if est["reference"] else "")
          + f"; rough: from 2-core timings, scaled by {os.cpu_count()} cores)", flush=True)

    ref = _reference(spec, args, bscene, cycles, tmpdir)
    mean_ref = float(ref["image"].mean())
    try:
        lscene = export_scene(bpy.context.evaluated_depsgraph_get())
    except SceneError as exc:
        raise BenchError(f"{name}: Lanterna cannot export it: "
                         f"{' '.join(str(exc).split())}") from None

    out = {"scene": name, "title": spec["title"], "blend": spec["blend"],
           "resolution": [w, h], "base": args.base, "base_spec": args.base_spec,
           "knobs": {k: [knob_value_of(args.base, k)] + [p["value"] for p in points
                                                         if p["knob"] == k] for k in args.knobs},
           "quick": args.quick, "presets_marked": list(args.presets),
           "estimate_seconds": est, "peak_memory_method": memory.method,
           "reference": {"source": ref["source"], "samples": ref["samples"],
                         "seconds": ref["seconds"], "mean": mean_ref,
                         "pixel_variance": ref["variance"],
                         "rel_rms_noise": (None if ref["variance"] is None
                                           else math.sqrt(ref["variance"]) / mean_ref)},
           "points": [], "failures": []}

    # Lanterna: one untimed warm-up, then every point (--repeat times, the fastest kept).
    log(f"{name}: Lanterna warm-up (preview, not timed) ...")
    try:
        render(lscene, RenderSettings(preset="preview", seed=LANTERNA_SEED))
    except SceneError as exc:
        raise BenchError(f"{name}: Lanterna cannot render it: "
                         f"{' '.join(str(exc).split())}") from None
    for index, p in enumerate(points):
        settings = RenderSettings(seed=LANTERNA_SEED, **p["values"])
        log(f"{name}: [{index + 1}/{len(points)}] {p['label']} ...")
        runs = []                   # (seconds, cpu seconds, report) of each repeat
        try:
            for repeat in range(args.repeat):
                with memory.measure() if repeat == 0 else contextlib.nullcontext() as measured:
                    cpu0 = _cpu_seconds()
                    t0 = time.perf_counter()
                    result = render(lscene, settings)
                    runs.append((time.perf_counter() - t0, _cpu_seconds() - cpu0, result.report))
                if repeat == 0:     # same seed, same picture: the first run's image is kept
                    mem, image = measured, np.asarray(result.image, np.float64)
                del result
        except SceneError as exc:
            raise BenchError(f"{name}: {p['label']}: {' '.join(str(exc).split())}") from None
        seconds, cpu_seconds, rep = min(runs, key=lambda run: run[0])
        stages = {k: float(v["seconds"]) for k, v in rep["stages"].items()}
        shares = {k: v / seconds for k, v in stages.items()}
        shares["other"] = max(1.0 - sum(shares.values()), 0.0)
        row = {"method": "Lanterna", "knob": p["knob"],
               "value": (fmt_value(p["knob"], p["value"]) if p["knob"] not in ("base", "preset")
                         else p["value"]),
               "preset": "/".join(p["presets"]) or None, "label": p["label"],
               "samples": settings.samples, "denoiser": False, "seconds": seconds,
               "seconds_runs": [run[0] for run in runs], "cpu_seconds": cpu_seconds,
               "stages": stages, "shares": shares,
               "report_total_seconds": rep.get("total_seconds"),
               "settings": dict(p["values"], seed=LANTERNA_SEED),
               "peak_rss_mb": mem["peak_rss_mb"], "peak_above_start_mb": mem["peak_above_start_mb"],
               "rss_start_mb": mem["rss_start_mb"],
               "process_peak_memory_mb": rep.get("peak_memory_mb"),
               "warnings": rep.get("warnings", [])}
        row.update(figures(image, ref))
        out["points"].append(row)
        if index == 0 and len(points) > 1:
            left = (len(points) - 1) * sum(run[0] for run in runs) + est["cycles"]
            log(f"{name}: the base took {seconds:.1f} s; about {_minutes(left)} left "
                 f"({len(points) - 1} Lanterna points at about its time, then Cycles)")

    # Cycles: the peer curve, same bpy scene, same run.
    if args.cycles_samples:
        try:
            curves = [cycles_curve(bscene, name, (w, h), args.cycles_samples, cycles, tmpdir,
                                   warm) for _ in range(args.repeat)]
        except Exception as exc:  # noqa: BLE001 - the warm-up or OIDN's timing failed
            raise BenchError(f"{name}: Cycles failed: {' '.join(str(exc).split())}") from None
        curve = curves[0]           # same seed, same pictures; the fastest of the repeats
        for crow in curve["rows"]:
            times = [r["seconds"] for c in curves for r in c["rows"]
                     if (r["samples"], r["denoiser"]) == (crow["samples"], crow["denoiser"])]
            crow["seconds_runs"] = times
            crow["seconds"] = min(times)
        out["denoise_seconds"] = curve["denoise_seconds"]
        out["failures"].extend(curve["failures"])
        configure = cycles[0]
        used = configure(bscene, 1, CYCLES_SEED, gi=True)
        out["cycles_settings"] = {k: v for k, v in used.items() if k not in ("samples", "seed")}
        for crow in curve["rows"]:
            spp, den = crow["samples"], crow["denoiser"]
            row = {"method": "Cycles+OIDN" if den else "Cycles", "knob": "cycles_samples",
                   "value": str(spp), "preset": None,
                   "label": f"Cycles {spp} spp" + (" + OIDN" if den else ""),
                   "samples": spp, "denoiser": den, "seconds": crow["seconds"],
                   "seconds_runs": crow["seconds_runs"], "stages": {}, "shares": {},
                   "settings": {"samples": spp, "seed": crow["seed"], "denoiser": den,
                                "threads": crow["threads"]},
                   "render_seconds_with_oidn": crow["render_seconds_with_oidn"],
                   "peak_rss_mb": None, "peak_above_start_mb": None}
            if den:
                row["denoiser_changed_image"] = crow.get("denoiser_changed_image")
            row.update(figures(curve["images"][("cycles", spp, den)], ref))
            out["points"].append(row)
    analyse(out)
    out["seconds_total"] = time.perf_counter() - started
    return out


def _ratio(error: float, front: float | None) -> float | None:
    """error / front error; None without a front there; a zero front error gives 1 for a zero
    error and infinity otherwise."""
    if front is None:
        return None
    if front <= 0:
        return 1.0 if error <= 0 else math.inf
    return error / front


def analyse(out: dict) -> None:
    """The front over the Lanterna points, each preset's place against it and Cycles' time
    for the same error (fills ``out["front"]``, ``out["presets"]``, rows' ``on_front``)."""
    lan = [r for r in out["points"] if r["method"] == "Lanterna"]
    pts = [(r["seconds"], r["error"]) for r in lan]
    front_idx = pareto_front(pts)
    for i, r in enumerate(lan):
        r["on_front"] = i in front_idx
    front = [pts[i] for i in front_idx]
    out["front"] = [{"label": lan[i]["label"], "seconds": pts[i][0], "error": pts[i][1]}
                    for i in front_idx]
    curves = {m: sorted(((r["samples"], r["seconds"], r["error"]) for r in out["points"]
                         if r["method"] == m)) for m in ("Cycles", "Cycles+OIDN")}
    out["presets"] = {}
    for i, r in enumerate(lan):
        for name in (r["preset"] or "").split("/"):
            if not name:
                continue
            s, e = pts[i]
            at = front_error_at(front, s)
            others = [pts[j] for j in range(len(pts)) if j != i]
            others_front = [others[j] for j in pareto_front(others)]
            at_others = front_error_at(others_front, s)
            ratio = _ratio(e, at)
            entry = {"label": r["label"], "seconds": s, "error": e,
                     "rel_rmse": r["rel_rmse"], "rel_rmse_corrected": r["rel_rmse_corrected"],
                     "region_worst_rel_error": r["region_worst_rel_error"],
                     "peak_rss_mb": r["peak_rss_mb"],
                     "peak_above_start_mb": r["peak_above_start_mb"],
                     "front_error": at, "front_error_ratio": ratio,
                     "on_front": ratio is not None and ratio <= 1.0 + ON_FRONT_TOLERANCE,
                     "front_error_others": at_others,
                     "front_error_ratio_others": _ratio(e, at_others)}
            for m, key in (("Cycles", "cycles"), ("Cycles+OIDN", "cycles_oidn")):
                t = time_for_error([(c[1], c[2]) for c in curves[m]], e)
                t["time_ratio"] = t["seconds"] / s if t["seconds"] is not None and s > 0 else None
                entry[key] = t
            out["presets"][name] = entry


# -- Outputs -----------------------------------------------------------------------------------
def stage_columns(points) -> list[str]:
    names = {k for r in points for k in r.get("stages", {})}
    return [k for k in STAGE_ORDER if k in names] + sorted(names - set(STAGE_ORDER))


CSV_HEAD = ("scene", "method", "knob", "value", "preset", "label", "samples", "seconds",
            "cpu_seconds", "rel_rmse", "rel_rmse_corrected", "error", "region_mean_rel_error",
            "region_worst_rel_error", "peak_rss_mb", "peak_above_start_mb", "on_front")


def _cell(value):
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


def write_csv(out: dict, path: str) -> None:
    from ..engine import imageio

    stages = stage_columns(out["points"])
    header = list(CSV_HEAD) + [f"share_{s}" for s in stages] + ["share_other", "settings"]
    with imageio.atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for r in out["points"]:
            row = [out["scene"]] + [_cell(r.get(k)) for k in CSV_HEAD[1:]]
            shares = r.get("shares", {})
            row += [_cell(shares.get(s)) for s in stages] + [_cell(shares.get("other"))]
            row.append(json.dumps(r.get("settings", {}), sort_keys=True))
            writer.writerow(row)


def write_json(data: dict, path: str) -> None:
    from ..engine import imageio

    imageio.write_json(path, _plain(data), allow_nan=False)


def _plain(obj):
    """JSON-ready: numpy values as Python ones, tuples as lists, inf / nan as strings."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    if obj is None or isinstance(obj, (str, int, float, bool)):
        return obj
    return str(obj)


def _leading_digit(v: float) -> int:
    return int(round(v / 10 ** math.floor(math.log10(v) + 1e-9))) if v > 0 else 0


def _positive(rows):
    return [r for r in rows if r["seconds"] and r["seconds"] > 0 and r["error"] and r["error"] > 0]


def write_plot(out: dict, path: str, machine: dict) -> None:
    """Log-log error against seconds (see the module's docstring), with matplotlib's Agg."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    from ..engine import imageio

    fig = Figure(figsize=(10, 7))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    lan = [r for r in out["points"] if r["method"] == "Lanterna"]
    base = next(r for r in lan if r["knob"] == "base")
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"]
    for colour, knob in zip(colours, out["knobs"]):
        rows = [base] + [r for r in lan if r["knob"] == knob]

        def key(r, knob=knob):
            v = knob_value_of(r["settings"], knob)
            return v[0] * v[1] if knob == "gather" else v

        rows = _positive(sorted(rows, key=key))
        if not rows:
            continue
        values = [fmt_value(knob, knob_value_of(r["settings"], knob)) for r in rows]
        ax.plot([r["seconds"] for r in rows], [r["error"] for r in rows], "-o", color=colour,
                ms=5, lw=1.4, label=f"{knob}: {', '.join(values)}")
        for r, text in zip(rows, values):
            if r is not base:               # the base is labelled once, below
                ax.annotate(text, (r["seconds"], r["error"]), textcoords="offset points",
                            xytext=(4, 3), fontsize=7, color=colour)
    if not base["preset"] and _positive([base]):
        ax.annotate("base", (base["seconds"], base["error"]), textcoords="offset points",
                    xytext=(6, -12), fontsize=9, fontweight="bold")
    for method, style, colour in (("Cycles", "-s", "black"), ("Cycles+OIDN", "--^", "dimgray")):
        rows = _positive(sorted((r for r in out["points"] if r["method"] == method),
                                key=lambda r: r["samples"]))
        if rows:
            ax.plot([r["seconds"] for r in rows], [r["error"] for r in rows], style,
                    color=colour, ms=5, lw=1.4,
                    label=("Cycles, no denoiser" if method == "Cycles" else "Cycles + OIDN")
                    + f" ({', '.join(str(r['samples']) for r in rows)} spp)")
            for r in rows:
                ax.annotate(str(r["samples"]), (r["seconds"], r["error"]),
                            textcoords="offset points", xytext=(4, -9), fontsize=7, color=colour)
    front = [f for f in out["front"] if f["seconds"] > 0 and f["error"] > 0]
    if front:
        xs = [f["seconds"] for f in front]
        ys = [f["error"] for f in front]
        right = max([r["seconds"] for r in _positive(out["points"])] + xs)
        ax.step(xs + [right], ys + [ys[-1]], where="post", color="gray", lw=7, alpha=0.25,
                solid_capstyle="butt", label="Pareto front of Lanterna's points", zorder=0)
    for name, entry in out["presets"].items():
        if entry["seconds"] > 0 and entry["error"] and entry["error"] > 0:
            ax.scatter([entry["seconds"]], [entry["error"]], s=320, marker="*", color="gold",
                       edgecolors="black", linewidths=1.0, zorder=5)
            ax.annotate(name, (entry["seconds"], entry["error"]), textcoords="offset points",
                        xytext=(8, 8), fontsize=11, fontweight="bold", zorder=6)
    ax.set_xscale("log")
    ax.set_yscale("log")
    for axis, form in ((ax.xaxis, "{:g}"), (ax.yaxis, "{:g} %")):
        scale = 100.0 if axis is ax.yaxis else 1.0
        axis.set_major_formatter(FuncFormatter(lambda v, _pos, f=form, k=scale: f.format(
            float(f"{v * k:.3g}"))))
        axis.set_minor_formatter(FuncFormatter(lambda v, _pos, f=form, k=scale: f.format(
            float(f"{v * k:.3g}")) if _leading_digit(v) in (2, 3, 5) else ""))
    ax.grid(True, which="both", alpha=0.3)
    corrected = out["reference"]["pixel_variance"] is not None
    ax.set_ylabel("relative RMSE" + (" (reference noise removed)" if corrected else ""))
    ax.set_xlabel("seconds (Lanterna: pipeline.render; Cycles: render, less OIDN when off)")
    w, h = out["resolution"]
    ax.set_title(f"{out['title']} at {w}x{h}: error against time, Lanterna knob by knob and "
                 f"Cycles\n{machine['cpu_count']} CPUs, {machine['platform']}, "
                 f"{machine['date']}", fontsize=10)
    ax.legend(fontsize=7.5, loc="best")
    fig.tight_layout()
    with imageio.atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)


# -- Printing ----------------------------------------------------------------------------------
def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2f} %"


def _mb(x) -> str:
    return "-" if x is None else f"{x:.0f}"


def print_scene(out: dict) -> None:
    w, h = out["resolution"]
    ref = out["reference"]
    noise = ("unknown" if ref["rel_rms_noise"] is None
             else f"RMS {_pct(ref['rel_rms_noise'])} of the mean")
    print(f"\n{out['title']} ({out['scene']}) at {w}x{h}; reference: {ref['source']}; its "
          f"per-pixel noise: {noise}")
    print(f"  {'point':26s} {'seconds':>8s} {'rel RMSE':>9s} {'corrected':>9s} {'region':>8s}"
          f" {'worst':>8s} {'peak MB':>8s} {'(+render)':>9s}  front  stage shares")
    for r in out["points"]:
        shares = ", ".join(f"{k} {100 * v:.0f}%" for k, v in
                           sorted(r["shares"].items(), key=lambda kv: -kv[1]) if v >= 0.05)
        front = ("*" if r.get("on_front") else "") if r["method"] == "Lanterna" else ""
        above = "-" if r["peak_above_start_mb"] is None else f"+{r['peak_above_start_mb']:.0f}"
        print(f"  {r['label'][:26]:26s} {r['seconds']:8.2f} {_pct(r['rel_rmse']):>9s} "
              f"{_pct(r['rel_rmse_corrected']):>9s} {_pct(r['region_mean_rel_error']):>8s} "
              f"{_pct(r['region_worst_rel_error']):>8s} {_mb(r['peak_rss_mb']):>8s} "
              f"{above:>9s}  {front:^5s}  {shares}")
        if r.get("denoiser") and r.get("denoiser_changed_image") is False:
            print("    ^ the denoiser left the image unchanged: OIDN did not run")
    print("  region = mean over the 4x4 blocks of |block mean / reference - 1|, worst = their "
          "max; * = on the Pareto front; errors compared: "
          + ("corrected" if ref["pixel_variance"] is not None else "rel RMSE"))
    zero = [r["label"] for r in out["points"] if r["method"] == "Lanterna" and r["error"] == 0]
    if zero:
        print(f"  note: the reference's own noise exceeds the difference for {len(zero)} "
              f"point(s) ({', '.join(zero[:3])}{', ...' if len(zero) > 3 else ''}): their "
              "corrected error is 0; a quieter reference (--reference-samples) separates them")
    print("  front: " + " -> ".join(f"{f['label']} ({f['seconds']:.1f} s, {_pct(f['error'])})"
                                   for f in out["front"]))
    for name, p in out["presets"].items():
        ratio = p["front_error_ratio"]
        where = ("-" if ratio is None else
                 f"on the Pareto front (error {ratio:.2f}x the front's at its time)"
                 if p["on_front"] else f"off the front: error {ratio:.2f}x the front's at its time")
        others = p["front_error_ratio_others"]
        other_text = ("faster than every other point" if others is None
                      else f"{others:.2f}x the front of the other points")
        print(f"  preset {name}: {p['seconds']:.2f} s, error {_pct(p['error'])}, peak "
              f"{_mb(p['peak_rss_mb'])} MB (+{_mb(p['peak_above_start_mb'])}): {where}; "
              f"{other_text}")
        parts = []
        for key, text in (("cycles", "without denoiser"), ("cycles_oidn", "with OIDN")):
            t = p[key]
            if t["status"] == "interpolated":
                parts.append(f"{t['seconds']:.1f} s {text} ({t['time_ratio']:.2f}x its time)")
            elif t["status"] == "at_most":
                parts.append(f"<= {t['seconds']:.1f} s {text} (its fewest samples already do "
                             f"better; <= {t['time_ratio']:.2f}x)")
            elif t["status"] == "beyond":
                parts.append(f"beyond the curve {text}")
            else:
                parts.append(f"n/a {text}")
        print(f"    Cycles' time for the same error: {'; '.join(parts)}")
    print(f"  total {out['seconds_total']:.0f} s for this scene (estimated "
          f"{out['estimate_seconds']['total']:.0f} s)")


# -- Command line ------------------------------------------------------------------------------
def machine_info() -> dict:
    """The machine a benchmark ran on: cpu_count, cpu (model name), platform, python, numpy,
    date (ISO), load_average_start (1, 5, 15 min, where the OS tells) and blender (bpy's
    version, when bpy imports)."""
    model = platform.processor()
    with contextlib.suppress(OSError):
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    out = {"cpu_count": os.cpu_count(), "cpu": model, "platform": platform.platform(terse=True),
           "python": platform.python_version(), "numpy": np.__version__,
           "date": datetime.date.today().isoformat()}
    with contextlib.suppress(OSError, AttributeError):
        out["load_average_start"] = list(os.getloadavg())
    with contextlib.suppress(ImportError):
        import bpy
        out["blender"] = bpy.app.version_string
    return out


def parse_args(argv):
    parser = Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("blend", nargs="?", default=None, metavar="SCENE.blend")
    parser.add_argument("--scenes", default=None)
    parser.add_argument("--resolution", default="160x120")
    parser.add_argument("--reference", default=None, metavar="EXR")
    parser.add_argument("--reference-samples", default=str(DEFAULT_REFERENCE_SAMPLES))
    parser.add_argument("--knobs", default=",".join(DEFAULT_KNOBS))
    parser.add_argument("--base", default=BASE_PRESET)
    parser.add_argument("--presets", default=",".join(DEFAULT_PRESETS))
    parser.add_argument("--cycles-samples", default=None)
    parser.add_argument("--out", default=DEFAULT_OUT)
    parser.add_argument("--repeat", default="1")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    args.resolution = parse_resolution(args.resolution)
    if args.blend and args.scenes:
        raise BenchError("give either SCENE.blend or --scenes, not both")
    if args.blend:
        from ..engine.blender.cli import UsageError, check_blend

        try:
            args.blend = check_blend(args.blend)
        except UsageError as exc:
            raise BenchError(str(exc)) from None
        args.specs = [{"name": Path(args.blend).stem, "title": Path(args.blend).name,
                       "blend": args.blend}]
    else:
        names = [s.strip() for s in (args.scenes or ",".join(DEFAULT_SCENES)).split(",")
                 if s.strip()]
        if not names:
            raise BenchError("--scenes is empty")
        unknown = [n for n in names if n not in SCENE_TITLES]
        if unknown:
            raise BenchError(f"--scenes: unknown seed scene {unknown[0]!r} (one of "
                             f"{', '.join(SCENE_TITLES)}; a .blend is given as SCENE.blend)")
        args.specs = [{"name": n, "title": SCENE_TITLES[n], "blend": None}
                      for n in dict.fromkeys(names)]
    knobs = [k.strip() for k in args.knobs.split(",") if k.strip()]
    bad = [k for k in knobs if k not in KNOBS]
    if bad or not knobs:
        raise BenchError(f"--knobs: unknown knob {bad[0]!r} (one of {', '.join(KNOBS)})" if bad
                         else "--knobs is empty")
    args.knobs = list(dict.fromkeys(knobs))
    from ..engine.settings import PRESETS
    presets = [] if args.presets.strip().lower() == "none" else [
        p.strip() for p in args.presets.split(",") if p.strip()]
    bad = [p for p in presets if p not in PRESETS]
    if bad:
        raise BenchError(f"--presets: unknown preset {bad[0]!r} (one of {', '.join(PRESETS)}, "
                         "or none)")
    args.presets = list(dict.fromkeys(presets))
    args.base, args.base_spec = base_values(args.base)
    if args.cycles_samples is None:
        args.cycles_samples = list(QUICK_CYCLES_SAMPLES if args.quick else DEFAULT_CYCLES_SAMPLES)
    elif args.cycles_samples.strip().lower() == "none":
        args.cycles_samples = []
    else:
        args.cycles_samples = sorted(set(int_list(args.cycles_samples, "--cycles-samples")))
    ref = int_list(args.reference_samples, "--reference-samples")
    if len(ref) != 1 or ref[0] < 2:
        raise BenchError("--reference-samples must be one integer >= 2")
    args.reference_samples = ref[0]
    repeat = int_list(args.repeat, "--repeat")
    if len(repeat) != 1:
        raise BenchError("--repeat must be one integer >= 1")
    args.repeat = repeat[0]
    if args.reference:
        if len(args.specs) != 1:
            raise BenchError("--reference EXR needs one scene (SCENE.blend or one of --scenes)")
        path = os.path.abspath(os.path.expanduser(args.reference))
        if not os.path.isfile(path):
            raise BenchError(f"--reference {path}: no such file")
        args.reference = path
    out_dir = os.path.abspath(os.path.expanduser(args.out))
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise BenchError(f"--out {out_dir}: exists and is not a directory")
    args.out = out_dir
    return args


def run(args, argv) -> tuple[dict, int]:
    try:
        import bpy  # noqa: F401
        import OpenEXR  # noqa: F401
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise BenchError(f"needs bpy, OpenEXR and matplotlib: {exc}") from None
    from .vs_cycles import cycles_functions

    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as exc:
        raise BenchError(f"--out {args.out}: cannot be created ({exc.strerror})") from None
    if not os.access(args.out, os.W_OK | os.X_OK):
        raise BenchError(f"--out {args.out}: not writable")
    cycles = cycles_functions()
    memory = PeakMemory()
    machine = machine_info()
    command = "lanterna bench --sweep " + " ".join(shlex.quote(a) for a in argv)
    print(f"{command}\nLanterna quality sweep: knobs {', '.join(args.knobs)} around the base "
          f"({args.base_spec}), presets {', '.join(args.presets) or 'none'}; "
          f"{'--quick; ' if args.quick else ''}{machine['cpu_count']} CPUs "
          f"({machine['cpu']}), {machine['platform']}; peak memory per point by "
          f"{memory.method}")
    results = {"command": command, "machine": machine, "scenes": {}, "errors": []}
    status = 0
    with tempfile.TemporaryDirectory(prefix="lanterna_sweep_") as tmpdir:
        warm: dict = {}
        for spec in args.specs:
            try:
                out = sweep_scene(spec, args, cycles, tmpdir, warm, memory)
            except BenchError as exc:
                print(f"lanterna bench: error: {' '.join(str(exc).split())}", file=sys.stderr)
                results["errors"].append(str(exc))
                status = 2
                continue
            if out["failures"]:
                status = 2
            with contextlib.suppress(OSError, AttributeError):
                machine["load_average_end"] = list(os.getloadavg())
            data = {"command": command, "machine": machine, "definitions": DEFINITIONS, **out}
            stem = os.path.join(args.out, f"{spec['name']}_sweep")
            write_csv(out, stem + ".csv")
            write_json(data, stem + ".json")
            write_plot(out, stem + ".png", machine)
            results["scenes"][spec["name"]] = out
            print_scene(out)
            print(f"  wrote {stem}.csv, .json, .png")
    return results, status


def main(argv=None) -> int:
    return run_command(lambda a: run(parse_args(a), a)[1],
                       list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
