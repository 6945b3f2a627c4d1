"""Benchmarks: time per stage, ray throughput against raw Embree, export speed.

What it computes (``lanterna bench`` or ``python -m lanterna.bench.main`` from a checkout)
    1. Renders the seed's Scene 1 (section 12.1, built by ``engine/blender/seed_scenes.py``)
       at ``--resolution`` (default 640x480) and ``--samples`` (default 16) with every traced
       batch of rays logged, and prints the time of each stage and the camera + shadow rays
       traced per second over the whole direct-light stage (ray generation, shading and
       tracing together).
    2. Re-traces exactly the same rays with raw embreex in the same run, with one thread and
       with the renderer's worker count (best of ``--repeat`` each), and prints the
       renderer's throughput as a ratio of each. Target: at least 0.6 of raw embreex.
    3. Exports a mesh of about 1M triangles from Blender and prints the time (target < 2 s).
    4. Photons (issue 3), on the same Scene 1: emits, traces and builds a map of
       ``--photons`` (1M) photons with the renderer's worker count and prints the time of
       each part (target: under 4 s in all) and the photon rays traced per second next to
       raw embreex re-tracing exactly the same rays with as many threads. Then the photon
       map's radiance estimates (k = 50, the seed's filters) at the camera's first hits, one
       per pixel, in queries per second, next to the library (pykdtree) answering the same
       k-nearest queries on a tree over the same photons as the tracer left them, and next
       to scipy's cKDTree. Last, a ``photon-map`` render of Scene 1 at 640 x 480 with the
       same photon count, timed as a whole (target: under 10 s).

This is a benchmark, not a test: the machine is shared and noisy, so it prints ratios
measured within one run rather than asserting absolute times. ``--json FILE`` saves all
figures.

Parameters
    ``--resolution WxH`` (640x480), ``--samples N`` (16), ``--threads N`` (0 = all cores),
    ``--export-triangles N`` (1 000 000; 0 skips), ``--photons N`` (1 000 000; 0 skips the
    photon benchmark), ``--json FILE``. ``--calibrate`` (measure this machine's rates for the
    cost estimate, then check it on the seed scenes) and ``--check-estimate`` (the check
    alone) hand over to ``bench/calibrate.py``, ``--sweep`` to ``bench/sweep.py``,
    ``--materials`` to ``bench/materials.py``, ``--textures`` to ``bench/texture_cost.py``,
    ``--hair`` to ``bench/hair_vs_cycles.py``,
    ``--sharpness`` to ``bench/floor_sharpness.py``,
    ``--vs-cycles`` to ``bench/vs_cycles.py`` and
    ``--cache-index`` to ``bench/cache_index.py``.
"""
from __future__ import annotations

import argparse
import sys

from .throughput import bench_photons, bench_scene1, benchmark_export, print_photons


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--sweep" in argv:  # issue 6: quality sweep against a reference and Cycles (sweep.py)
        if "--vs-cycles" in argv:
            print("lanterna bench: error: give either --sweep or --vs-cycles, not both",
                  file=sys.stderr)
            return 2
        from .sweep import main as sweep_main
        return sweep_main([a for a in argv if a != "--sweep"])
    if "--materials" in argv:  # issues 23, 24: final against Cycles (materials, --worlds)
        from .materials import main as materials_main
        return materials_main([a for a in argv if a != "--materials"])
    if "--hair" in argv:  # hair against Cycles (hair.py)
        from .hair_vs_cycles import main as hair_main
        return hair_main([a for a in argv if a != "--hair"])
    if "--textures" in argv:  # issue 24: what textures add to final (textures.py)
        from .texture_cost import main as textures_main
        return textures_main([a for a in argv if a != "--textures"])
    if "--sharpness" in argv:  # issue 24: the textured floor's noise and blur (floor_sharpness.py)
        from .floor_sharpness import main as sharpness_main
        return sharpness_main([a for a in argv if a != "--sharpness"])
    if "--calibrate" in argv or "--check-estimate" in argv:  # issue 6: rates (calibrate.py)
        from .calibrate import main as calibrate_main
        return calibrate_main(argv)
    if "--performance" in argv:  # docs/performance.md (performance.py)
        from .performance import main as performance_main
        return performance_main([a for a in argv if a != "--performance"])
    if "--validation" in argv:  # docs/validation.md (validation.py)
        from .validation import main as validation_main
        return validation_main([a for a in argv if a != "--validation"])
    if "--cache-index" in argv:  # the irradiance cache's grid against its kd-tree
        from .cache_index import main as cache_index_main
        return cache_index_main([a for a in argv if a != "--cache-index"])
    if "--vs-cycles" in argv:  # issue 4: the final preset against Cycles (vs_cycles.py)
        from .vs_cycles import main as vs_cycles_main
        return vs_cycles_main([a for a in argv if a != "--vs-cycles"])
    parser = argparse.ArgumentParser(prog="lanterna bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--vs-cycles", action="store_true",
                        help="Lanterna's final preset against Cycles on the seed's scenes; "
                             "see bench/vs_cycles.py (--vs-cycles --help)")
    parser.add_argument("--sweep", action="store_true",
                        help="a sweep over quality settings against a reference and Cycles; "
                             "see bench/sweep.py (--sweep --help)")
    parser.add_argument("--materials", action="store_true",
                        help="final's time against Cycles' for the same error on the material "
                             "scenes (with --worlds: the HDRI world scenes); see "
                             "bench/materials.py (--materials --help)")
    parser.add_argument("--hair", action="store_true",
                        help="a fur ball's final against Cycles' 3D curves; see bench/hair_vs_cycles.py")
    parser.add_argument("--textures", action="store_true",
                        help="what texture evaluation adds to the textured room's final, "
                             "against the same scene with each texture's mean; see "
                             "bench/texture_cost.py (--textures --help)")
    parser.add_argument("--sharpness", action="store_true",
                        help="the textured room's floor against a plain one: per-seed error, "
                             "the seeds' mean image and per-pixel noise; see "
                             "bench/floor_sharpness.py (--sharpness --help)")
    parser.add_argument("--calibrate", action="store_true",
                        help="measure this machine's rates for the cost estimate, write them "
                             "and check the estimate on the seed scenes; see "
                             "bench/calibrate.py (--calibrate --help)")
    parser.add_argument("--performance", action="store_true",
                        help="measure and write docs/performance.md; see bench/performance.py")
    parser.add_argument("--validation", action="store_true",
                        help="measure and write docs/validation.md; see bench/validation.py")
    parser.add_argument("--cache-index", action="store_true",
                        help="the irradiance cache's grid index against its kd-tree; see "
                             "bench/cache_index.py")
    parser.add_argument("--check-estimate", action="store_true",
                        help="only check the cost estimate against renders of the seed scenes")
    parser.add_argument("--resolution", default="640x480")
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--export-triangles", type=int, default=1_000_000)
    parser.add_argument("--photons", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    try:
        w, h = (int(v) for v in args.resolution.lower().split("x"))
    except ValueError:
        print("lanterna: error: --resolution must look like 640x480", file=sys.stderr)
        return 2
    from ..engine import imageio

    if args.json and (problem := imageio.output_problem(args.json)):
        print(f"lanterna: error: --json {args.json}: {problem}", file=sys.stderr)
        return 2
    out = bench_scene1((w, h), args.samples, args.threads, max(1, args.repeat))
    workers = out["workers"]
    print(f"Scene 1 at {w}x{h}, {args.samples} spp, {out['triangles']} triangles, {workers} workers")
    print("stage times [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in out["stages"].items()))
    print(f"best of {out['repeat']} for the renderer and for raw embreex; direct-light stage runs: "
          + ", ".join(f"{s:.3f}" for s in out["camera_seconds_runs"]) + " s")
    print(f"rays: camera {out['rays']['camera']:,}  shadow {out['rays']['shadow']:,}")
    print(f"renderer (direct-light stage, all work)  {out['renderer_rays_per_second'] / 1e6:7.2f} Mrays/s")
    print(f"raw embreex, same rays, 1 thread        {out['raw_embree_1_thread_rays_per_second'] / 1e6:7.2f} Mrays/s"
          f"   ratio {out['ratio_vs_raw_1_thread']:.2f}")
    key = f"raw_embree_{workers}_threads_rays_per_second"
    print(f"raw embreex, same rays, {workers} threads       {out[key] / 1e6:7.2f} Mrays/s"
          f"   ratio {out[f'ratio_vs_raw_{workers}_threads']:.2f}")
    print(f"render total {out['total_seconds']:.2f} s, peak memory {out['peak_memory_mb']:.0f} MB")
    if args.export_triangles > 0:
        exp = benchmark_export(args.export_triangles)
        out["export_benchmark"] = exp
        print(f"export of {exp['triangles']:,} triangles: {exp['seconds']:.2f} s (target < 2 s)")
    if args.photons > 0:
        out["photons"] = bench_photons(args.photons, (w, h), args.threads)
        print_photons(out["photons"])
    if args.json:
        imageio.write_json(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
