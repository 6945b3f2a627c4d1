"""Speed on the material and HDRI-world scenes: Lanterna's ``final`` against Cycles at the same
error (issues 23 and 24).

What it computes (``lanterna bench --materials [--worlds]``)
    For each scene of ``--scenes`` (default all five of ``tests/material_scenes.py``'s
    ``MATERIAL_SCENES``: factory_cube at 192 x 108, principled_room, metal_sphere, mix_floor
    and glass_caustic at 80 x 60; with ``--worlds`` the suite ``SUITES["worlds"]``: the yard
    of ``tests/world_scenes.py`` at 320 x 240 (``yard_320``, the goal scene) and at 80 x 60,
    and window_room at 80 x 60, references in ``tests/data/cycles_world`` from
    ``make_world_refs.py``), in one process:

    1. The reference: the stored ``tests/data/cycles_materials/<scene>.npz``
       (``tests/data/make_material_refs.py``: Cycles CPU, all bounces, 4-8 seeds of 512-12288
       spp); its per-pixel noise variance v is the mean of its ``pixel_var`` (the variance of
       the seeds' mean).
    2. The scene built in bpy by ``material_scenes.build`` and exported once
       (``export_scene`` of the evaluated depsgraph). One untimed ``preview`` render first (a
       process's first render is 20-40 % slower, as in ``bench/sweep.py``), then
       ``pipeline.render(scene, RenderSettings(preset="final", seed=1))``, timed.
    3. Cycles on the same bpy scene with the references' settings
       (``configure_cycles(gi=True)`` of ``tests/data/make_cycles_refs.py``: 64 bounces,
       caustics on, no clamping, no adaptive sampling, light threshold 0, Blackman-Harris
       1.5 px, path guiding off) at each of ``--cycles-samples`` (16, 64, 256, 1024, 4096), seed
       ``CYCLES_SEED`` (not a reference seed), via ``bench_cycles.cycles_curve``: one render
       per sample count with OIDN on gives the noisy image and the denoised one; the noisy
       image's time is the render's less OIDN's own time (``measure_denoise_seconds``).
       The noisy curve is the peer; Cycles + OIDN comes free and is an extra column.
    4. Cycles' time for Lanterna's error, ``sweep.time_for_error`` on the curve in sample
       order (log-log interpolation between the two renders around it), and the ratio
       ours / Cycles' (< 1: Lanterna is faster at its own error; the issue's goal: <= 0.5 on
       principled_room). "below 16 spp" when Cycles' fewest samples already do better (the
       ratio is then at least ours / that render's time), "beyond 1024 spp" when its most
       samples do not get there (the ratio is then below ours / that render's time).

Columns (``materials.csv``: one row per render; ``materials_summary.csv``: one per scene)
    seconds               Lanterna: wall time of ``pipeline.render`` (export excluded) [s];
                          Cycles: see 3 [s].
    cpu_seconds           Lanterna: the process's user + system CPU time over the render [s]
                          (on a loaded machine wall time grows and this does not).
    rel_rmse              sqrt(mean((img - ref)^2)) / mean(ref), all pixels and channels.
    rel_rmse_corrected    sqrt(max(MSE - v, 0)) / mean(ref): the error against the noise-free
                          picture (``sweep.figures``, the sweep's definition).
    error                 rel_rmse_corrected (the figure compared).
    block_rel_rmse        the same over the 4 x 4 block means (each block's mean over its
                          pixels and channels, RMS over the blocks, over mean(ref)): the
                          low-frequency part of the error, a bias that more samples of the
                          same method do not remove (the blocks' own noise is small).
    region_worst_rel_error  max over the 4 x 4 blocks of |mean(img) / mean(ref) - 1|.
    stage_<name>          Lanterna: ``report["stages"][name]["seconds"]`` [s].
    cycles_seconds_for_error, cycles_status, ratio   step 4 for the noisy curve;
    oidn_seconds_for_error, oidn_status, oidn_ratio  the same for Cycles + OIDN.
    goal_met              principled_room only (yard_320 with ``--worlds``): ratio <=
                          ``GOAL_RATIO`` (0.5).
    check_256 (JSON)      issue 24's check: final's error at or below Cycles-256's and its
                          time <= 0.5 x that render's (``check_at_samples``), made on the
                          goal scene (yard_320); the worlds' section gives it for the others
                          too, for comparison.

Outputs
    ``--out`` (default ``out/materials``): ``materials.csv``, ``materials_summary.csv``,
    ``materials.json`` (everything: command, machine with the load average at the start and
    the end, references, every render with its stage seconds, Cycles' settings).
    ``--plot`` (default ``docs/materials/materials_vs_cycles.png``): per scene, log-log error
    against seconds: Cycles' noisy curve (16-1024 spp), Cycles + OIDN, Lanterna's ``final``
    as a star, a dotted line at its error.
    ``--doc`` (default ``docs/performance.md``; ``none`` to skip): its section
    ``SECTION_TITLE`` (with ``--worlds``: "HDRI worlds against Cycles (issue 24)") replaced
    (or appended), the rest of the file kept. With ``--worlds`` the defaults of ``--out`` and
    ``--plot`` are ``out/worlds`` and ``docs/materials/worlds_vs_cycles.png`` (the files keep
    their ``materials*`` names); give ``--worlds`` with ``--from-json`` of such a run.
    ``--from-json out/materials/materials.json``: the table, plot and section again from a
    run's JSON, nothing rendered.

Cost: about 15 min on 2 shared cores (Cycles' 1024-spp renders dominate: 15-70 s each at
80 x 60). A benchmark, not a test: it asserts nothing. Expected failures print one
``lanterna bench: error: ...`` line and exit with status 2.
"""
from __future__ import annotations

import contextlib
import csv
import datetime
import importlib
import json
import math
import os
import shlex
import sys
import tempfile
import time
from pathlib import Path

from dataclasses import dataclass

import numpy as np

from .sweep import figures, machine_info, time_for_error
from .vs_cycles import REPO, BenchError, Parser, int_list, log, run_command

PROG = "lanterna bench --materials"
SCENES = ("factory_cube", "principled_room", "metal_sphere", "mix_floor", "glass_caustic")
CYCLES_SAMPLES = (16, 64, 256, 1024, 4096)
REFERENCES = REPO / "tests" / "data" / "cycles_materials"
GOAL_SCENE = "principled_room"
GOAL_RATIO = 0.5                    # issue 23: final's time <= 0.5 x Cycles' at its error
DEFAULT_OUT = os.path.join("out", "materials")
DEFAULT_PLOT = REPO / "docs" / "materials" / "materials_vs_cycles.png"
DEFAULT_DOC = REPO / "docs" / "performance.md"
SECTION_TITLE = "## Materials against Cycles (issue 23)"
COMMAND = "lanterna bench --materials"
CHECK_SAMPLES = 256                 # issue 24: final at Cycles-256's error in <= half its time


@dataclass(frozen=True)
class Suite:
    """A set of scenes the benchmark runs: where their builders and references live, the
    goal scene, and the section of docs/performance.md it writes."""

    name: str
    scenes: tuple
    module: str                     # tests/<module>.py: build(name) makes the bpy scene
    references: Path
    goal_scene: str
    section: str
    command: str
    out: str
    plot: Path
    issue: str
    description: str                # the scenes and their references, for the section


SUITES = {
    "materials": Suite(
        "materials", SCENES, "material_scenes", REFERENCES, GOAL_SCENE, SECTION_TITLE, COMMAND,
        DEFAULT_OUT, DEFAULT_PLOT, "issue 23",
        "the same bpy scenes of `tests/material_scenes.py`, with the settings of their stored "
        "references (`tests/data/cycles_materials`, `make_material_refs.py`: 64 bounces, "
        "caustics on, no clamping, Blackman-Harris 1.5 px)"),
    "worlds": Suite(
        "worlds", ("yard_320", "yard", "window_room"), "world_scenes",
        REPO / "tests" / "data" / "cycles_world",
        "yard_320", "## HDRI worlds against Cycles (issue 24)", COMMAND + " --worlds",
        os.path.join("out", "worlds"), REPO / "docs" / "materials" / "worlds_vs_cycles.png",
        "issue 24",
        "the same bpy scenes of `tests/world_scenes.py` (the yard under an HDRI with a small "
        "bright sun, at 320 x 240 (yard_320, the goal scene) and at the parity tests' 80 x 60, "
        "where set-up that every render pays outweighs the rendering; window_room, lit only "
        "through a window with a light portal), with the "
        "settings of their stored references (`tests/data/cycles_world`, `make_world_refs.py`: "
        "64 bounces, no clamping, Blackman-Harris 1.5 px)"),
}


def suite_of(data: dict) -> Suite:
    """The ``Suite`` a run's ``data`` belongs to (``data["suite"]``; materials by default)."""
    return SUITES[data.get("suite", "materials")]


# -- Pure figures (tested on hand-made data) --------------------------------------------------
def reference_from_npz(path) -> dict:
    """A stored material reference: {"image" (H, W, 3) float64, "variance": the mean of
    ``pixel_var`` (the per-pixel variance of the seeds' mean), "source", "samples" (spp x
    seeds)}. A missing or unreadable file is a ``BenchError``."""
    path = Path(path)
    try:
        with np.load(path) as data:
            image = data["image"].astype(np.float64)
            variance = float(np.mean(data["pixel_var"].astype(np.float64)))
            spp, seeds = int(data["spp"]), len(data["seeds"])
    except (OSError, KeyError, ValueError) as exc:
        raise BenchError(f"reference {path}: cannot be read ({exc})") from None
    if image.ndim != 3 or image.shape[2] != 3 or not image.mean() > 0:
        raise BenchError(f"reference {path}: not an (H, W, 3) image with light in it")
    try:
        shown = path.relative_to(REPO)
    except ValueError:
        shown = path
    return {"image": image, "variance": variance, "samples": spp * seeds,
            "source": f"{shown}: Cycles {seeds} seeds x {spp} spp"}


def block_rel_rmse(image, ref, grid=(4, 4)) -> float:
    """RMS over the ``grid`` blocks of (block mean of ``image`` - that of ``ref``), the means
    over each block's pixels and channels, over mean(ref): the low-frequency (bias) part of
    the error."""
    from .vs_cycles import block_means

    a = block_means(np.asarray(image, np.float64), grid)
    b = block_means(np.asarray(ref, np.float64), grid)
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.asarray(ref, np.float64).mean())


def speed_ratio(seconds: float, error: float, curve, samples) -> dict:
    """Cycles' time for Lanterna's ``error`` on ``curve`` [(seconds, error)] in the order of
    ``samples`` (its spp), and ours / it: {"seconds", "status" (``time_for_error``'s),
    "ratio", "bound" ("=", ">=": Cycles is better already at its fewest samples, the ratio is
    at least this; "<": Cycles never gets there, the ratio is below this; None: no curve),
    "text"}."""
    t = time_for_error(curve, error)
    out = dict(t, ratio=None, bound=None)
    if t["status"] == "interpolated":
        out.update(ratio=seconds / t["seconds"], bound="=",
                   text=f"{t['seconds']:.1f} s")
    elif t["status"] == "at_most":
        out.update(ratio=seconds / t["seconds"], bound=">=",
                   text=f"below {samples[0]} spp (<= {t['seconds']:.1f} s)")
    elif t["status"] == "beyond":
        last = curve[-1][0]
        out.update(ratio=seconds / last if last else None, bound="<",
                   text=f"beyond {samples[-1]} spp (> {last:.1f} s)")
    else:
        out["text"] = "n/a"
    return out


def ratio_text(entry: dict) -> str:
    """``speed_ratio``'s ratio as the table prints it: "0.42", ">= 1.3", "< 0.05", "-"."""
    if entry.get("ratio") is None:
        return "-"
    prefix = {"=": "", ">=": ">= ", "<": "< "}.get(entry["bound"], "")
    return f"{prefix}{entry['ratio']:.2f}"


def goal_met(entry: dict, goal: float = GOAL_RATIO) -> bool | None:
    """Whether ours / Cycles' <= ``goal`` for sure: an exact ratio or an upper bound ("<")
    at or below it; False when the ratio (or its lower bound) is above; None when unknown."""
    r, bound = entry.get("ratio"), entry.get("bound")
    if r is None:
        return None
    if bound == "=":
        return r <= goal
    if bound == "<":                # the true ratio is below r
        return True if r <= goal else None
    return False if r > goal else None  # ">=": the true ratio is at least r


def stage_text(stages: dict, seconds: float, least: float = 0.05) -> str:
    """The stages taking at least ``least`` of ``seconds``, largest first: "camera 5.1 s
    (48 %), photons 2.0 s (19 %)"."""
    parts = sorted(((v, k) for k, v in stages.items() if seconds > 0 and v / seconds >= least),
                   reverse=True)
    return ", ".join(f"{k} {v:.1f} s ({100 * v / seconds:.0f} %)" for v, k in parts)


def check_at_samples(s: dict, samples: int = CHECK_SAMPLES) -> dict | None:
    """Issue 24's check on a scene: does final reach the error of Cycles at ``samples`` spp in
    at most half that render's time? {"samples", "cycles_error", "cycles_seconds",
    "error_ok" (ours <= its error), "time_ratio" (ours / its time), "met"}; None when the
    curve has no render at ``samples``."""
    row = next((r for r in s["cycles_rows"] if r["samples"] == samples), None)
    if row is None or not row["seconds"] > 0:
        return None
    lan = s["lanterna"]
    ratio = lan["seconds"] / row["seconds"]
    ok = lan["error"] <= row["error"]
    return {"samples": samples, "cycles_error": row["error"], "cycles_seconds": row["seconds"],
            "error_ok": ok, "time_ratio": ratio, "met": bool(ok and ratio <= GOAL_RATIO)}


def check_text(check: dict | None) -> str:
    """``check_at_samples`` in words."""
    if check is None:
        return f"no Cycles render at {CHECK_SAMPLES} spp to check against"
    n = check["samples"]
    return (("meets" if check["met"] else "misses") + f" issue 24's check (final at Cycles-{n}'s "
            f"error, {100 * check['cycles_error']:.2f} %, in <= {GOAL_RATIO} x its "
            f"{check['cycles_seconds']:.1f} s): final's error is "
            + ("at or below it" if check["error_ok"] else "above it")
            + f", its time {check['time_ratio']:.2f} x Cycles-{n}'s")


def scene_sentence(s: dict, suite: Suite | None = None) -> str:
    """One sentence on a scene: the ratio, the suite's goal scene's goal met or not, and
    why: where Lanterna's time goes and how much of its error is low-frequency bias."""
    suite = suite or SUITES["materials"]
    lan, c = s["lanterna"], s["cycles"]
    ratio = ratio_text(c)
    where = stage_text(lan["stages"], lan["seconds"])
    if s["scene"] == suite.goal_scene:
        met = goal_met(c)
        head = ("meets the goal" if met else "misses the goal" if met is False
                else "cannot tell whether it meets the goal")
        head += f" (ratio {ratio}, goal <= {GOAL_RATIO})"
    else:
        head = f"ratio {ratio} (no goal set; {GOAL_RATIO} would be " + (
            "met)" if goal_met(c) else "missed)" if goal_met(c) is False else "undecided)")
    why = (f"final takes {lan['seconds']:.1f} s ({where}); its error is "
           f"{100 * lan['error']:.2f} %, its 4 x 4 block means are off by "
           f"{100 * lan['block_rel_rmse']:.2f} % RMS (worst block "
           f"{100 * lan['region_worst']:.1f} %)" + (
               ": most of it low-frequency, a bias more samples of final would not remove"
               if lan["block_rel_rmse"] >= 0.5 * lan["error"] else
               ": most of it pixel noise, not low-frequency bias"))
    first = s["cycles_rows"][0] if s["cycles_rows"] else {"error": 0.0, "seconds": 0.0}
    if c["status"] == "at_most":
        why += (f"; Cycles is below it already at {s['samples'][0]} spp "
                f"({100 * first['error']:.2f} % in {first['seconds']:.1f} s)")
    elif c["status"] == "interpolated":
        why += f"; Cycles reaches that error in {c['seconds']:.1f} s"
        if s["scene"] == suite.goal_scene and not goal_met(c):
            budget = GOAL_RATIO * c["seconds"]
            rest = lan["seconds"] - lan["stages"].get("camera", 0.0)
            why += (f", so the goal needs final at this error in <= {budget:.1f} s; "
                    f"everything but the camera stage takes {rest:.1f} s" + (
                        ", more than that budget on its own" if rest >= budget else
                        f", which leaves the camera {budget - rest:.1f} s (it takes "
                        f"{lan['seconds'] - rest:.1f} s)"))
    elif c["status"] == "beyond":
        last = s["cycles_rows"][-1]
        why += (f"; Cycles is still at {100 * last['error']:.2f} % after "
                f"{s['samples'][-1]} spp ({last['seconds']:.1f} s)")
    if suite.name == "worlds":
        why += ("; it " if s["scene"] == suite.goal_scene else
                f"; for comparison only (the check is made on {suite.goal_scene}), it ")
        why += check_text(check_at_samples(s))
    return f"**{s['scene']}**: {head}. {why}."


def section_markdown(data: dict, plot_rel: str) -> str:
    """The suite's section of docs/performance.md (``SECTION_TITLE`` for the materials) from
    a run's ``data`` (as ``materials.json`` holds it), the plot linked at ``plot_rel``
    (relative to the doc)."""
    suite = suite_of(data)
    m = data["machine"]
    loads = ((m.get("load_average_start") or [])[:1]
             + (m.get("load_average_end") or [])[:1])
    load = (f", 1-min load average {min(loads):.1f}-{max(loads):.1f} at the start and end"
            if loads else "")
    goal = (f"goal: <= {GOAL_RATIO} on the Principled room" if suite.name == "materials" else
            f"goal: <= {GOAL_RATIO} on the yard at 320 x 240, {suite.goal_scene}, the scene issue "
            f"24's check is made on too: final at Cycles-{CHECK_SAMPLES}'s error in at most "
            f"{GOAL_RATIO} x its time. At the parity tests' 80 x 60 the set-up that both "
            "renderers pay whatever the image's size (Cycles' 16 spp take most of its "
            f"{CHECK_SAMPLES} spp's time there) outweighs the rendering, so the check is given "
            "there for comparison only")
    lines = [suite.section, "",
             f"Measured {m['date']} on {m['cpu_count']} CPUs ({m['cpu']}, {m['platform']}{load}), "
             f"Blender {m.get('blender', '?')}, {data['minutes']:.0f} min. Regenerate with "
             f"`{suite.command}` from a checkout (`bench/materials.py`, whose docstring defines every "
             "column; it rewrites this section only). Lanterna's `final` (seed 1, after an "
             "untimed warm-up) and Cycles without denoiser at "
             f"{', '.join(map(str, data['cycles_samples']))} spp on {suite.description}. "
             "Error = relative RMSE less the reference's "
             "own noise (as in the sweep); Cycles' time for our error interpolated log-log on "
             f"its curve; ratio = our time / Cycles' ({goal}).", "",
             "| scene | px | final time | final error | its bias (4 × 4 blocks) | Cycles for that "
             "error | ratio ours / Cycles | Cycles + OIDN for it | ratio | Cycles "
             f"{' / '.join(map(str, data['cycles_samples']))} spp: error (time) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for s in data["scenes"].values():
        lan, c, o = s["lanterna"], s["cycles"], s["cycles_oidn"]
        w, h = s["resolution"]
        curve = " / ".join(f"{100 * r['error']:.2f} % ({r['seconds']:.1f} s)"
                           for r in s["cycles_rows"])
        lines.append(f"| {s['scene']} | {w}×{h} | {lan['seconds']:.1f} s | "
                     f"{100 * lan['error']:.2f} % | {100 * lan['block_rel_rmse']:.2f} % | "
                     f"{c['text']} | **{ratio_text(c)}** | {o['text']} | {ratio_text(o)} | "
                     f"{curve} |")
    lines += ["", f"![error against time, per scene]({plot_rel})", ""]
    for s in data["scenes"].values():
        lines += [f"- {scene_sentence(s, suite)}"]
    return "\n".join(lines) + "\n"


def replace_section(text: str, section: str, title: str = SECTION_TITLE) -> str:
    """``text`` (a markdown file) with its section ``title`` (from that heading line to the
    next ``## `` heading or the end) replaced by ``section``; appended when absent."""
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if line.rstrip() == title), None)
    if not section.endswith("\n"):
        section += "\n"
    if start is None:
        body = text if text.endswith("\n") or not text else text + "\n"
        return body + ("\n" if body else "") + section
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")),
               len(lines))
    tail = "".join(lines[end:])
    return "".join(lines[:start]) + section + ("\n" + tail if tail else "")


def section_of(text: str, title: str = SECTION_TITLE) -> str | None:
    """The section ``title`` of ``text`` (heading to the next ``## `` heading or the end),
    or None: what ``bench/performance.py`` keeps when it rewrites the file."""
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if line.rstrip() == title), None)
    if start is None:
        return None
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")),
               len(lines))
    return "".join(lines[start:end]).rstrip("\n") + "\n"


# -- Renders ----------------------------------------------------------------------------------
def material_scenes_module(module: str = "material_scenes"):
    """``tests/<module>.py`` (``material_scenes``, ``world_scenes``, and the
    ``parity_scenes`` they import), from the checkout's tests/ folder."""
    tests = str(REPO / "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)
    try:
        return importlib.import_module(module)
    except Exception as exc:  # noqa: BLE001 - reported as one line
        raise BenchError(f"cannot import tests/{module}.py: "
                         f"{' '.join(str(exc).split())} (run from a checkout)") from None


def bench_scene(name: str, samples, cycles, tmpdir, warm: dict,
                suite: Suite = SUITES["materials"]) -> dict:
    """One scene: reference, Lanterna ``final`` (after a warm-up), the Cycles curve, and the
    speed ratios (module docstring, steps 1-4)."""
    import bpy

    from .vs_cycles import CYCLES_SEED, LANTERNA_SEED, cycles_curve
    from ..engine.blender.export import export_scene
    from ..engine.pipeline import RenderSettings, render
    from ..engine.scene import SceneError

    ref = reference_from_npz(suite.references / f"{name}.npz")
    h, w = ref["image"].shape[:2]
    ms = material_scenes_module(suite.module)
    try:
        bscene = ms.build(name)
        lscene = export_scene(bpy.context.evaluated_depsgraph_get())
    except Exception as exc:  # noqa: BLE001
        raise BenchError(f"{name}: cannot be built or exported: "
                         f"{' '.join(str(exc).split())}") from None
    log(f"{name}: Lanterna warm-up (preview, not timed) ...")
    try:
        render(lscene, RenderSettings(preset="preview", seed=LANTERNA_SEED))
        log(f"{name}: Lanterna final ...")
        times0 = os.times()
        t0 = time.perf_counter()
        result = render(lscene, RenderSettings(preset="final", seed=LANTERNA_SEED))
        seconds = time.perf_counter() - t0
        times1 = os.times()
    except SceneError as exc:
        raise BenchError(f"{name}: Lanterna cannot render it: "
                         f"{' '.join(str(exc).split())}") from None
    image = np.asarray(result.image, np.float64)
    if image.shape[:2] != (h, w):
        raise BenchError(f"{name}: Lanterna's image is {image.shape[1]}x{image.shape[0]}, the "
                         f"reference {w}x{h}")
    rep = result.report
    fig = figures(image, ref)
    lan = {"seconds": seconds,
           "cpu_seconds": (times1.user + times1.system) - (times0.user + times0.system),
           "stages": {k: float(v["seconds"]) for k, v in rep["stages"].items()},
           "error": fig["error"], "rel_rmse": fig["rel_rmse"],
           "rel_rmse_corrected": fig["rel_rmse_corrected"],
           "region_worst": fig["region_worst_rel_error"],
           "block_rel_rmse": block_rel_rmse(image, ref["image"]),
           "settings": rep.get("settings"), "warnings": rep.get("warnings", [])}
    del result
    try:
        curve = cycles_curve(bscene, name, (w, h), samples, cycles, tmpdir, warm)
    except Exception as exc:  # noqa: BLE001 - the warm-up or OIDN's timing failed
        raise BenchError(f"{name}: Cycles failed: {' '.join(str(exc).split())}") from None
    rows = {False: [], True: []}
    for crow in curve["rows"]:
        img = curve["images"][("cycles", crow["samples"], crow["denoiser"])]
        f = figures(img, ref)
        rows[crow["denoiser"]].append({
            "samples": crow["samples"], "seconds": crow["seconds"], "error": f["error"],
            "rel_rmse": f["rel_rmse"], "rel_rmse_corrected": f["rel_rmse_corrected"],
            "region_worst": f["region_worst_rel_error"],
            "block_rel_rmse": block_rel_rmse(img, ref["image"]),
            "render_seconds_with_oidn": crow["render_seconds_with_oidn"]})
    used = cycles[0](bscene, 1, CYCLES_SEED, gi=True)
    out = {"scene": name, "resolution": [w, h], "samples": list(samples),
           "reference": {k: ref[k] for k in ("source", "samples", "variance")},
           "lanterna": lan, "cycles_rows": rows[False], "oidn_rows": rows[True],
           "denoise_seconds": curve["denoise_seconds"], "failures": curve["failures"],
           "cycles_settings": {k: v for k, v in used.items() if k not in ("samples", "seed")}}
    out["reference"]["rel_rms_noise"] = math.sqrt(ref["variance"]) / float(ref["image"].mean())
    for key, rs in (("cycles", rows[False]), ("cycles_oidn", rows[True])):
        out[key] = speed_ratio(seconds, lan["error"], [(r["seconds"], r["error"]) for r in rs],
                               [r["samples"] for r in rs] or list(samples))
    if name == suite.goal_scene:
        out["goal_met"] = goal_met(out["cycles"])
    out["check_256"] = check_at_samples(out)
    return out


# -- Outputs ----------------------------------------------------------------------------------
def _cell(v):
    return "" if v is None else f"{v:.6g}" if isinstance(v, float) else v


def write_csvs(data: dict, out_dir: str) -> None:
    stages = sorted({k for s in data["scenes"].values() for k in s["lanterna"]["stages"]})
    with open(os.path.join(out_dir, "materials.csv"), "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["scene", "method", "samples", "seconds", "cpu_seconds", "rel_rmse",
                     "rel_rmse_corrected", "error", "block_rel_rmse", "region_worst_rel_error"]
                    + [f"stage_{k}" for k in stages])
        for s in data["scenes"].values():
            lan = s["lanterna"]
            wr.writerow([_cell(v) for v in (
                s["scene"], "Lanterna final", lan["settings"].get("samples") if lan["settings"]
                else None, lan["seconds"], lan["cpu_seconds"], lan["rel_rmse"],
                lan["rel_rmse_corrected"], lan["error"], lan["block_rel_rmse"],
                lan["region_worst"])] + [_cell(lan["stages"].get(k)) for k in stages])
            for method, rs in (("Cycles", s["cycles_rows"]), ("Cycles+OIDN", s["oidn_rows"])):
                for r in rs:
                    wr.writerow([_cell(v) for v in (
                        s["scene"], method, r["samples"], r["seconds"], None, r["rel_rmse"],
                        r["rel_rmse_corrected"], r["error"], r["block_rel_rmse"],
                        r["region_worst"])] + [""] * len(stages))
    with open(os.path.join(out_dir, "materials_summary.csv"), "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["scene", "seconds", "error", "block_rel_rmse", "cycles_seconds_for_error",
                     "cycles_status", "ratio", "ratio_bound", "oidn_seconds_for_error",
                     "oidn_status", "oidn_ratio", "oidn_ratio_bound", "goal_met"])
        for s in data["scenes"].values():
            c, o = s["cycles"], s["cycles_oidn"]
            wr.writerow([_cell(v) for v in (
                s["scene"], s["lanterna"]["seconds"], s["lanterna"]["error"],
                s["lanterna"]["block_rel_rmse"], c["seconds"], c["status"], c["ratio"],
                c["bound"], o["seconds"], o["status"], o["ratio"], o["bound"],
                s.get("goal_met"))])


def write_plot(data: dict, path) -> None:
    """Per scene, log-log error against seconds: Cycles without and with OIDN, Lanterna's
    final as a star and a dotted line at its error (matplotlib, Agg)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, NullFormatter

    from ..engine import imageio

    scenes = list(data["scenes"].values())
    cols = min(3, len(scenes))
    rows = math.ceil(len(scenes) / cols)
    fig = Figure(figsize=(5 * cols, 4 * rows))
    FigureCanvasAgg(fig)
    for i, s in enumerate(scenes):
        ax = fig.add_subplot(rows, cols, i + 1)
        for key, style, colour, label in (("cycles_rows", "-s", "black", "Cycles, no denoiser"),
                                          ("oidn_rows", "--^", "gray", "Cycles + OIDN")):
            rs = [r for r in s[key] if r["seconds"] > 0 and r["error"] > 0]
            if rs:
                ax.plot([r["seconds"] for r in rs], [100 * r["error"] for r in rs], style,
                        color=colour, ms=4, lw=1.2, label=label)
                for r in rs:
                    ax.annotate(str(r["samples"]), (r["seconds"], 100 * r["error"]),
                                textcoords="offset points", xytext=(3, 3), fontsize=7,
                                color=colour)
        lan = s["lanterna"]
        if lan["error"] > 0:
            ax.axhline(100 * lan["error"], color="tab:orange", ls=":", lw=1)
            ax.scatter([lan["seconds"]], [100 * lan["error"]], s=220, marker="*",
                       color="gold", edgecolors="black", zorder=5, label="Lanterna final")
        if s["cycles"]["status"] == "interpolated":
            ax.axvline(s["cycles"]["seconds"], color="tab:orange", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
            axis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
        w, h = s["resolution"]
        ax.set_title(f"{s['scene']} ({w}x{h}): ratio {ratio_text(s['cycles'])}", fontsize=10)
        ax.set_xlabel("seconds")
        ax.set_ylabel("rel. RMSE less reference noise [%]")
        ax.legend(fontsize=7)
    m = data["machine"]
    fig.suptitle(f"Lanterna final against Cycles at the same error: {m['cpu_count']} CPUs, "
                 f"{m['platform']}, {m['date']}", fontsize=11)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with imageio.atomic_output(str(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=90)


def print_table(data: dict) -> None:
    print(f"\n{'scene':16s} {'final s':>8s} {'error':>8s} {'bias':>7s}  {'Cycles for it':>28s} "
          f"{'ratio':>7s}  {'OIDN for it':>28s} {'ratio':>7s}")
    for s in data["scenes"].values():
        lan, c, o = s["lanterna"], s["cycles"], s["cycles_oidn"]
        print(f"{s['scene']:16s} {lan['seconds']:8.2f} {100 * lan['error']:7.2f}% "
              f"{100 * lan['block_rel_rmse']:6.2f}%  {c['text']:>28s} {ratio_text(c):>7s}  "
              f"{o['text']:>28s} {ratio_text(o):>7s}")
        print("    Cycles " + ", ".join(f"{r['samples']} spp {r['seconds']:.1f} s "
                                        f"{100 * r['error']:.2f}%" for r in s["cycles_rows"]))
        print(f"    stages: {stage_text(lan['stages'], lan['seconds'])}")
    for s in data["scenes"].values():
        print(f"  {scene_sentence(s, suite_of(data))}")


# -- Command line -----------------------------------------------------------------------------
def parse_args(argv):
    parser = Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--worlds", action="store_true")
    parser.add_argument("--scenes", default=None)
    parser.add_argument("--cycles-samples", default=",".join(map(str, CYCLES_SAMPLES)))
    parser.add_argument("--out", default=None)
    parser.add_argument("--plot", default=None)
    parser.add_argument("--doc", default=str(DEFAULT_DOC))
    parser.add_argument("--from-json", default=None, metavar="FILE")
    args = parser.parse_args(argv)
    args.suite = SUITES["worlds" if args.worlds else "materials"]
    suite = args.suite
    args.scenes = args.scenes or ",".join(suite.scenes)
    args.out = args.out or suite.out
    args.plot = args.plot or str(suite.plot)
    names = [n.strip() for n in args.scenes.split(",") if n.strip()]
    bad = [n for n in names if n not in suite.scenes]
    if bad or not names:
        raise BenchError(f"--scenes: unknown scene {bad[0]!r} (of {', '.join(suite.scenes)})"
                         if bad else "--scenes is empty")
    args.scenes = list(dict.fromkeys(names))
    args.cycles_samples = sorted(set(int_list(args.cycles_samples, "--cycles-samples")))
    if not args.cycles_samples:
        raise BenchError("--cycles-samples is empty")
    args.out = os.path.abspath(os.path.expanduser(args.out))
    args.doc = None if args.doc.strip().lower() == "none" else Path(args.doc).resolve()
    args.plot = Path(args.plot).resolve()
    return args


def write_doc(data: dict, doc: Path, plot: Path) -> None:
    """Replace (or append) the suite's section of ``doc``, the rest kept."""
    from ..engine import imageio

    title = suite_of(data).section
    text = doc.read_text(encoding="utf-8") if doc.is_file() else ""
    new = replace_section(text, section_markdown(data, os.path.relpath(plot, doc.parent)),
                          title)
    with imageio.atomic_output(str(doc)) as tmp:
        Path(tmp).write_text(new, encoding="utf-8")
    print(f"wrote the section {title[3:]!r} of {doc}")


def from_json(args) -> int:
    """``--from-json FILE``: the table, plot and section again from a run's
    ``materials.json``, without rendering (e.g. after a change of wording)."""
    try:
        data = json.loads(Path(args.from_json).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise BenchError(f"--from-json {args.from_json}: cannot be read ({exc})") from None
    write_plot(data, args.plot)
    print_table(data)
    if args.doc is not None:
        write_doc(data, args.doc, args.plot)
    return 0


def run(args, argv) -> tuple[dict, int]:
    try:
        import bpy  # noqa: F401
        import OpenEXR  # noqa: F401
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise BenchError(f"needs bpy, OpenEXR and matplotlib: {exc}") from None
    from .vs_cycles import cycles_functions

    os.makedirs(args.out, exist_ok=True)
    cycles = cycles_functions()
    machine = machine_info()
    suite = args.suite
    command = " ".join([COMMAND] + [shlex.quote(a) for a in argv])
    print(f"{command}\n{machine['cpu_count']} CPUs ({machine['cpu']}), load average "
          f"{machine.get('load_average_start')}; scenes {', '.join(args.scenes)}; Cycles at "
          f"{', '.join(map(str, args.cycles_samples))} spp", flush=True)
    t0 = time.perf_counter()
    data = {"command": command, "suite": suite.name, "machine": machine,
            "cycles_samples": args.cycles_samples,
            "goal": {"scene": suite.goal_scene, "ratio": GOAL_RATIO}, "scenes": {}, "errors": []}
    status = 0
    with tempfile.TemporaryDirectory(prefix="lanterna_materials_") as tmpdir:
        warm: dict = {}
        for name in args.scenes:
            try:
                s = bench_scene(name, args.cycles_samples, cycles, tmpdir, warm, suite)
            except BenchError as exc:
                print(f"lanterna bench: error: {' '.join(str(exc).split())}", file=sys.stderr)
                data["errors"].append(str(exc))
                status = 2
                continue
            status = 2 if s["failures"] else status
            data["scenes"][name] = s
            lan, c = s["lanterna"], s["cycles"]
            log(f"{name}: final {lan['seconds']:.1f} s, error {100 * lan['error']:.2f} %; "
                f"Cycles for it {c['text']}, ratio {ratio_text(c)}")
    with contextlib.suppress(OSError, AttributeError):
        machine["load_average_end"] = list(os.getloadavg())
    data["minutes"] = (time.perf_counter() - t0) / 60
    data["date_time"] = datetime.datetime.now().isoformat(timespec="seconds")
    if not data["scenes"]:
        return data, 2
    from .sweep import write_json

    write_json(data, os.path.join(args.out, "materials.json"))
    write_csvs(data, args.out)
    write_plot(data, args.plot)
    print_table(data)
    print(f"wrote {args.out}/materials.csv, materials_summary.csv, materials.json; {args.plot}")
    if args.doc is not None:
        write_doc(data, args.doc, args.plot)
    return data, status


def main(argv=None) -> int:
    def body(argv):
        args = parse_args(argv)
        return from_json(args) if args.from_json else run(args, argv)[1]
    return run_command(body, list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
