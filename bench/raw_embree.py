"""The baseline of the ray benchmarks: raw embreex tracing exactly the rays a render logged.

``raw_embree_seconds(triangles, ray_log, threads)``: wall time [s] for embreex alone (its own
scene over the same triangles, no Lanterna code in between) to trace every batch of
``ray_log`` (``pipeline.render(..., ray_log=[])`` fills it: (kind, origins, directions, far)
per batch; ``shadow`` batches as occlusion queries, the rest as closest hits), on one thread
or on a pool of ``threads``. The renderer's throughput is printed as a ratio of it.
"""
from __future__ import annotations

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
