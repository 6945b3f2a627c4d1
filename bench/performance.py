"""``docs/performance.md``: what accuracy costs in time and memory, measured and dated.

What it measures (``lanterna bench --performance [--out docs/performance.md]`` from a checkout;
about 20 minutes on 2 cores)
    1. The quality sweep of the seed's two scenes against their Cycles references, with Cycles
       itself at 16-1024 spp with and without OIDN (``bench/sweep.py``; CSV, JSON and plots in
       ``docs/sweep/``): each preset's time, error, peak memory and whether it lies on the
       time-error front, and Cycles' time for the same error.
    2. Throughput against the libraries underneath, each ratio against a baseline measured in
       the same run (``bench/main.py``): the direct-light camera stage against raw embreex
       tracing the same rays; photon tracing against raw embreex; photon-map estimates against
       raw pykdtree answering the same k-nearest queries; the irradiance cache's grid against
       its kd-tree (``bench/cache_index.py``).
    3. Not rerun here: the sections "Materials against Cycles (issue 23)" and the HDRI
       worlds' written by ``lanterna bench --materials [--worlds]`` (``bench/materials.py``)
       and "Texture cost (issue 24)" written by ``lanterna bench --textures``
       (``bench/texture_cost.py``) are kept as they are.
These are benchmarks on a shared machine, never tests: they print and record, and assert
nothing.
"""
from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SWEEP_COMMAND = ["--scenes", "scene1,scene2", "--cycles-samples", "16,64,256,1024"]


def _sweep(out_dir: Path) -> dict:
    from .sweep import main as sweep_main

    status = sweep_main(SWEEP_COMMAND + ["--out", str(out_dir)])
    if status:
        raise SystemExit(f"the sweep failed (status {status})")
    return {name: json.loads((out_dir / f"{name}_sweep.json").read_text())
            for name in ("scene1", "scene2")}


def _throughput(threads: int) -> dict:
    from .cache_index import measure as cache_index
    from .throughput import bench_photons, bench_scene1

    return {"scene1": bench_scene1((640, 480), 16, threads, 3),
            "photons": bench_photons(1_000_000, (640, 480), threads),
            "cache_index": cache_index()}


def write(path: Path, sweeps: dict, throughput: dict, minutes: float) -> None:
    today = datetime.date.today().isoformat()
    loads = [round(v, 1) for s in sweeps.values()
             for v in (s["machine"].get("load_average_start") or [])[:1]
             + (s["machine"].get("load_average_end") or [])[:1]]
    load = f", load average {min(loads)}-{max(loads)} during the sweep" if loads else ""
    lines = ["# Performance", "",
             f"Measured {today} on {platform.machine()} ({platform.system()}, "
             f"{throughput['scene1']['workers']} worker threads{load}), {minutes:.0f} min. "
             "Regenerate "
             "with `lanterna bench --performance` from a checkout (`bench/performance.py`). "
             "Benchmarks on a shared machine: each ratio is against a baseline measured in the "
             "same run.", "",
             "## What accuracy costs: the presets against Cycles", "",
             "The seed's scenes at 160 × 120 against their stored all-bounce Cycles references "
             "(`tests/data/cycles_gi`); error = relative RMSE less the reference's own noise; "
             "Cycles' time for the same error interpolated on its curve (`bench/sweep.py`, "
             "whose module docstring defines every column).", "",
             "| scene | preset | time | error | worst 4 × 4 block | peak memory | on the front "
             "| Cycles for that error | Cycles + OIDN |", "|---|---|---|---|---|---|---|---|---|"]

    def cyc(entry):
        if entry["seconds"] is None:
            return "beyond 1024 spp"
        ratio = entry.get("time_ratio")
        return f"{entry['seconds']:.1f} s" + (f" ({ratio:.2f}× ours)" if ratio else "")

    for name, sweep in sweeps.items():
        for preset, p in sweep["presets"].items():
            lines.append(f"| {sweep['title']} | {preset} | {p['seconds']:.2f} s | "
                         f"{100 * p['error']:.2f} % | {100 * p['region_worst_rel_error']:.2f} % | "
                         f"{p['peak_rss_mb']:.0f} MB | {'yes' if p['on_front'] else 'no'} | "
                         f"{cyc(p['cycles'])} | {cyc(p['cycles_oidn'])} |")
    lines += [""]
    for name in sweeps:
        lines.append(f"![{name} sweep](sweep/{name}_sweep.png)")
    s1, ph, ci = throughput["scene1"], throughput["photons"], throughput["cache_index"]
    w = s1["workers"]
    raw_photons = f"raw_embree_{ph['workers']}_threads_rays_per_second"
    lines += ["", "## Throughput against the libraries underneath", "",
              "| what | Lanterna | baseline, same work | ratio |", "|---|---|---|---|",
              f"| Scene 1 direct light, 640 × 480, 16 spp (camera + shadow rays, all work) | "
              f"{s1['renderer_rays_per_second'] / 1e6:.2f} Mrays/s | raw embreex, {w} threads: "
              f"{s1[f'raw_embree_{w}_threads_rays_per_second'] / 1e6:.2f} Mrays/s | "
              f"{s1[f'ratio_vs_raw_{w}_threads']:.2f} |",
              f"| photon tracing, 1M photons on Scene 1 | "
              f"{ph['photon_rays_per_second'] / 1e6:.2f} Mrays/s | raw embreex: "
              f"{ph[raw_photons] / 1e6:.2f} Mrays/s | "
              f"{ph['trace_ratio_vs_raw']:.2f} |",
              f"| photon-map estimates, k = {ph['k']} (with the seed's filters) | "
              f"{ph['estimates_per_second'] / 1e3:.0f}k/s | raw pykdtree queries: "
              f"{ph['raw_pykdtree_queries_per_second'] / 1e3:.0f}k/s | "
              f"{ph['estimate_ratio_vs_raw_pykdtree']:.2f} |",
              f"| irradiance cache look-ups, {ci['records']:,} records (grid) | "
              f"{ci['grid_points_per_second'] / 1e3:.0f}k points/s | its kd-tree: "
              f"{ci['kdtree_points_per_second'] / 1e3:.0f}k points/s | "
              f"{ci['grid_over_kdtree']:.2f} |", "",
              f"Photon map of 1M photons on Scene 1: emit {ph['emit_seconds']:.2f} s, trace "
              f"{ph['trace_seconds']:.2f} s, kd-tree {ph['build_seconds']:.2f} s; a "
              f"`photon-map` render at 640 × 480 takes "
              f"{ph['photon_map_render']['total_seconds']:.1f} s."]
    from .hair_vs_cycles import SECTION_TITLE as HAIR_TITLE
    from .materials import SUITES, section_of
    from .texture_cost import SECTION_TITLE as TEXTURES_TITLE

    text = path.read_text(encoding="utf-8") if path.is_file() else ""
    # bench/materials.py's and bench/texture_cost.py's sections: rewritten only by them
    for title in [suite.section for suite in SUITES.values()] + [TEXTURES_TITLE, HAIR_TITLE]:
        kept = section_of(text, title)
        if kept:
            lines += ["", kept.rstrip("\n")]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="lanterna bench --performance",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(REPO / "docs" / "performance.md"))
    parser.add_argument("--threads", type=int, default=0)
    args = parser.parse_args(argv)
    out = Path(args.out)
    t0 = time.perf_counter()
    sweeps = _sweep(out.parent / "sweep")
    throughput = _throughput(args.threads)
    write(out, sweeps, throughput, (time.perf_counter() - t0) / 60)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
