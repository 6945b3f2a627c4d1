"""Hair against Cycles: a fur ball's ``final`` next to Cycles' 3D Curves (``lanterna bench
--hair``).

What it computes
    ``tests/parity_scenes.py``'s ``fur_ball`` (``--strands``, default 20,000 Catmull-Rom
    strands on a sphere, 160 x 120 px, sun and grey world) built in bpy and exported once:
    1. Lanterna ``final``, seed 1, after an untimed ``preview`` (a process's first render is
       slower): wall time and stages.
    2. Cycles at ``--cycles-samples`` (default 256) and a reference at ``--reference-samples``
       (2048), with the settings of the stored references (``tests/data/make_cycles_refs.py``,
       all bounces, no denoiser).
    3. Direct light alone: Lanterna (``bounces`` 0, 64 x 2 samples) against Cycles' direct-only
       references' settings at 512 spp.
    Figures: relative RMSE of the luminance against the reference (whole picture), and the
    ratio of mean luminance Lanterna / reference over ``FUR_REGIONS`` (the fur, its core, the
    open floor), for the full render and for direct light.

Outputs
    Printed; ``--doc`` (default ``docs/performance.md``, ``none`` to skip): its section
    ``SECTION_TITLE`` replaced (or appended). About 3 min on 2 shared cores.

A benchmark, not a test: it asserts nothing.
"""
from __future__ import annotations

import datetime
import os
import platform
import tempfile
import time

import numpy as np

from .materials import material_scenes_module, replace_section
from .vs_cycles import REPO, BenchError, Parser, cycles_functions, log, run_command

PROG = "lanterna bench --hair"
SECTION_TITLE = "## Hair against Cycles"
DEFAULT_DOC = REPO / "docs" / "performance.md"
LUMA = np.array([0.2126, 0.7152, 0.0722])


def region_ratios(image, ref, regions) -> dict:
    """Mean luminance of ``image`` over ``ref``'s in each named (rows, columns) region."""
    return {name: float((image[r] @ LUMA).mean() / max((ref[r] @ LUMA).mean(), 1e-30))
            for name, r in regions.items()}


def rel_rmse(image, ref) -> float:
    """RMS of the luminance difference over the reference's mean luminance."""
    a, b = image @ LUMA, ref @ LUMA
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(b.mean(), 1e-30))


def section_markdown(d: dict) -> str:
    r, c = d["lanterna"], d["cycles"]
    rows = [f"| Lanterna `final` | {r['seconds']:.1f} s | {r['error']:.2%} | "
            + " | ".join(f"{d['ratios'][k]:.3f}" for k in d["regions"]) + " |",
            f"| Cycles {c['samples']} spp | {c['seconds']:.1f} s | {c['error']:.2%} | "
            + " | ".join(f"{d['cycles_ratios'][k]:.3f}" for k in d["regions"]) + " |",
            "| direct light alone, Lanterna / Cycles | | | "
            + " | ".join(f"{d['direct_ratios'][k]:.3f}" for k in d["regions"]) + " |"]
    return "\n".join([
        SECTION_TITLE, "",
        f"Measured {d['date']} on {d['machine']}, Blender {d['blender']}. Regenerate with "
        f"`{PROG}` from a checkout (`bench/hair_vs_cycles.py`, whose docstring defines every figure; it "
        f"rewrites this section only). `tests/parity_scenes.py`'s fur ball ({d['strands']:,} "
        f"strands, {d['triangles']:,} triangles, 160 × 120) against Cycles' 3D Curves at "
        f"{d['reference_samples']} spp; error = relative RMSE of the luminance, region columns "
        "= mean luminance over the reference's.", "",
        "| render | time | error | " + " | ".join(d["regions"]) + " |",
        "|---|---|---|" + "---|" * len(d["regions"]),
        *rows, "",
        f"Lanterna's stages: {', '.join(f'{k} {v:.1f} s' for k, v in r['stages'].items())}. "
        "The bounced light between strands comes out dark in dense hair (the photon map's "
        "estimates assume a surface; docs/usage.md), which the core's ratio shows.", ""])


def run(args) -> dict:
    import bpy
    from ..engine.blender.export import export_scene
    from ..engine.pipeline import RenderSettings, render
    from ..engine.settings import PRESETS

    scenes = material_scenes_module("parity_scenes")
    configure, render_exr, _source = cycles_functions()
    bscene = scenes.fur_ball(args.strands)
    bpy.context.view_layer.update()
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    log(f"fur ball: {len(scene.triangles):,} triangles, export "
        f"{scene.stats['export_seconds']:.1f} s")
    render(scene, RenderSettings(**PRESETS["preview"], seed=1))            # warm-up
    t0 = time.perf_counter()
    result = render(scene, RenderSettings(**PRESETS["final"], seed=1))
    seconds = time.perf_counter() - t0
    ours = np.asarray(result.image, np.float64)
    stages = {k: v.get("seconds", 0.0) for k, v in result.report["stages"].items()
              if v.get("seconds", 0.0) >= 0.05}
    with tempfile.TemporaryDirectory() as tmp:
        configure(bscene, args.cycles_samples, 1, gi=True)
        theirs, cycles_seconds = render_exr(bscene, os.path.join(tmp, "cycles.exr"))
        configure(bscene, args.reference_samples, 2, gi=True)
        ref, _ = render_exr(bscene, os.path.join(tmp, "reference.exr"))
        direct = np.asarray(render(scene, RenderSettings(samples=64, light_samples=2, bounces=0,
                                                         seed=1)).image, np.float64)
        configure(bscene, 512, 3, gi=False)
        direct_ref, _ = render_exr(bscene, os.path.join(tmp, "direct.exr"))
    regions = scenes.FUR_REGIONS
    return {
        "date": datetime.date.today().isoformat(),
        "machine": f"{os.cpu_count()} CPUs ({platform.processor() or platform.machine()}, "
                   f"{platform.system()})",
        "blender": bpy.app.version_string, "strands": args.strands,
        "triangles": int(len(scene.triangles)), "reference_samples": args.reference_samples,
        "regions": list(regions),
        "lanterna": {"seconds": seconds, "error": rel_rmse(ours, ref), "stages": stages},
        "cycles": {"samples": args.cycles_samples, "seconds": float(cycles_seconds),
                   "error": rel_rmse(theirs, ref)},
        "ratios": region_ratios(ours, ref, regions),
        "cycles_ratios": region_ratios(theirs, ref, regions),
        "direct_ratios": region_ratios(direct, direct_ref, regions)}


def body(argv) -> int:
    parser = Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--strands", type=int, default=20000)
    parser.add_argument("--cycles-samples", type=int, default=256)
    parser.add_argument("--reference-samples", type=int, default=2048)
    parser.add_argument("--doc", default=str(DEFAULT_DOC))
    args = parser.parse_args(argv)
    if args.strands < 1:
        raise BenchError("--strands must be at least 1")
    data = run(args)
    section = section_markdown(data)
    print(section)
    if args.doc != "none":
        path = REPO / args.doc if not os.path.isabs(args.doc) else args.doc
        text = open(path, encoding="utf-8").read() if os.path.isfile(path) else ""
        with open(path, "w", encoding="utf-8") as f:
            f.write(replace_section(text, section, SECTION_TITLE))
    return 0


def main(argv=None) -> int:
    return run_command(body, argv)
