"""Benchmarks: time per stage, ray throughput against raw Embree, export speed.

What it computes (``lanterna bench`` or ``python -m lanterna.engine.blender.bench``)
    1. Renders the seed's Scene 1 (section 12.1, built by ``engine/blender/seed_scenes.py``)
       at ``--resolution`` (default 640x480) and ``--samples`` (default 16) with every traced
       batch of rays logged, and prints the time of each stage and the camera + shadow rays
       traced per second over the whole direct-light stage (ray generation, shading and
       tracing together).
    2. Re-traces exactly the same rays with raw embreex in the same run, with one thread and
       with the renderer's worker count, and prints the renderer's throughput as a ratio of
       each. Target: at least 0.6 of raw embreex.
    3. Exports a mesh of about 1M triangles from Blender and prints the time (target < 2 s).

This is a benchmark, not a test: the machine is shared and noisy, so it prints ratios
measured within one run rather than asserting absolute times. ``--json FILE`` saves all
figures.

Parameters
    ``--resolution WxH`` (640x480), ``--samples N`` (16), ``--threads N`` (0 = all cores),
    ``--export-triangles N`` (1 000 000; 0 skips), ``--json FILE``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def raw_embree_seconds(triangles: np.ndarray, ray_log: list, threads: int) -> float:
    """Wall time for raw embreex to trace the logged rays (same batches, same queries)."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(triangles, np.float32))
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")
    jobs = []
    for kind, org, dirs, far in ray_log:
        org = np.ascontiguousarray(org, np.float32)
        dirs = np.ascontiguousarray(dirs, np.float32)
        far = (np.full(len(org), 1e37, np.float32) if far is None
               else np.ascontiguousarray(np.broadcast_to(far, (len(org),)), np.float32))
        jobs.append((kind, org, dirs, far))

    def trace(job):
        kind, org, dirs, far = job
        if kind == "shadow":
            scene.run(org, dirs, far.copy(), query="OCCLUDED")
        else:
            scene.run(org, dirs, far.copy(), output=1)

    start = time.perf_counter()
    if threads <= 1:
        for job in jobs:
            trace(job)
    else:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(trace, jobs))
    return time.perf_counter() - start


def bench_scene1(resolution=(640, 480), samples=16, threads=0) -> dict:
    import bpy  # noqa: F401  (Blender builds the seed scene)

    from . import seed_scenes
    from .export import export_scene
    from ..pipeline import RenderSettings, render

    seed_scenes.build("scene1")
    bscene = bpy.context.scene
    bscene.render.resolution_x, bscene.render.resolution_y = resolution
    bscene.render.resolution_percentage = 100
    t0 = time.perf_counter()
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    export_seconds = time.perf_counter() - t0
    settings = RenderSettings(samples=samples, light_samples=4, bounces=0, threads=threads)
    ray_log: list = []
    result = render(scene, settings, ray_log=ray_log)
    rep = result.report
    cam = rep["stages"]["camera"]
    rays = rep["rays"]["camera"] + rep["rays"]["shadow"] + rep["rays"]["specular"]
    renderer_rate = rays / cam["seconds"]
    logged = sum(len(entry[1]) for entry in ray_log)
    workers = settings.worker_count
    raw_1 = raw_embree_seconds(scene.triangles, ray_log, 1)
    raw_n = raw_embree_seconds(scene.triangles, ray_log, workers)
    return {
        "scene": "seed Scene 1", "resolution": list(resolution), "samples": samples,
        "triangles": int(len(scene.triangles)), "export_seconds": export_seconds,
        "stages": {k: v["seconds"] for k, v in rep["stages"].items()},
        "rays": rep["rays"], "logged_rays": logged, "workers": workers,
        "renderer_rays_per_second": renderer_rate,
        "raw_embree_1_thread_rays_per_second": logged / raw_1,
        f"raw_embree_{workers}_threads_rays_per_second": logged / raw_n,
        "ratio_vs_raw_1_thread": renderer_rate / (logged / raw_1),
        f"ratio_vs_raw_{workers}_threads": renderer_rate / (logged / raw_n),
        "total_seconds": rep["total_seconds"], "peak_memory_mb": rep["peak_memory_mb"],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="lanterna bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", default="640x480")
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--export-triangles", type=int, default=1_000_000)
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    try:
        w, h = (int(v) for v in args.resolution.lower().split("x"))
    except ValueError:
        print("lanterna: error: --resolution must look like 640x480", file=sys.stderr)
        return 2
    out = bench_scene1((w, h), args.samples, args.threads)
    workers = out["workers"]
    print(f"Scene 1 at {w}x{h}, {args.samples} spp, {out['triangles']} triangles, {workers} workers")
    print("stage times [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in out["stages"].items()))
    print(f"rays: camera {out['rays']['camera']:,}  shadow {out['rays']['shadow']:,}")
    print(f"renderer (direct-light stage, all work)  {out['renderer_rays_per_second'] / 1e6:7.2f} Mrays/s")
    print(f"raw embreex, same rays, 1 thread        {out['raw_embree_1_thread_rays_per_second'] / 1e6:7.2f} Mrays/s"
          f"   ratio {out['ratio_vs_raw_1_thread']:.2f}")
    key = f"raw_embree_{workers}_threads_rays_per_second"
    print(f"raw embreex, same rays, {workers} threads       {out[key] / 1e6:7.2f} Mrays/s"
          f"   ratio {out[f'ratio_vs_raw_{workers}_threads']:.2f}")
    print(f"render total {out['total_seconds']:.2f} s, peak memory {out['peak_memory_mb']:.0f} MB")
    if args.export_triangles > 0:
        from .export import benchmark_export
        exp = benchmark_export(args.export_triangles)
        out["export_benchmark"] = exp
        print(f"export of {exp['triangles']:,} triangles: {exp['seconds']:.2f} s (target < 2 s)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
