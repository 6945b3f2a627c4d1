"""The irradiance cache's spatial index: the hashed grid against the kd-tree it can use instead.

What it measures (``lanterna bench --cache-index`` or ``python -m lanterna.bench.cache_index``)
    Records placed as the cache's coverage passes place them in a 4 m room (floor and two
    walls; R clamped to [0.05, 1] m, up to 1,500 new records a pass at the points nothing
    covers, until fewer than 20 are left), then ``--points`` (100,000) look-ups on the same
    surfaces at a = 0.3, timed for both indexes after a warm-up on 10 points (which builds
    the index). Prints points per second for each and the grid's ratio to the kd-tree
    measured in the same run (the baseline). The two indexes answer alike: that is a test
    (``tests/test_irradiance_cache.py``); this is the speed, a benchmark, never asserted.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ..engine.irradiance_cache import IrradianceCache, clamp_radius


def _room(rng, count):
    face = rng.integers(0, 3, count)
    u = rng.uniform(0, 4, (count, 2))
    p = np.where(face[:, None] == 0, np.c_[u, np.zeros(count)],
                 np.where(face[:, None] == 1, np.c_[np.zeros(count), u],
                          np.c_[u[:, 0], np.zeros(count), u[:, 1]]))
    return p, np.eye(3)[[2, 0, 1]][face]


def measure(points: int = 100_000, seed: int = 13) -> dict:
    rng = np.random.default_rng(seed)
    placed = IrradianceCache()
    for _ in range(30):
        p, n = _room(rng, 10000)
        _, cov, _, _ = placed.interpolate(p, n, 0.3, count_usage=False)
        unc = np.nonzero(~cov)[0][:1500]
        if len(unc) < 20:
            break
        radius = clamp_radius(0.05 + 0.3 * np.sort(p[unc], axis=1)[:, 1], 0.05, 1.0)
        placed.add(p[unc], n[unc], np.ones((len(unc), 3)), radius, None,
                   rng.normal(size=(len(unc), 3, 3)))
    p, n = _room(rng, points)
    out = {"records": len(placed), "points": points}
    for index in ("grid", "kdtree"):
        cache = IrradianceCache(index=index)
        cache.add(placed.positions, placed.normals, placed.irradiance, placed.radius,
                  placed.rot_grad, placed.trans_grad)
        cache.interpolate(p[:10], n[:10], 0.3)
        t0 = time.perf_counter()
        cache.interpolate(p, n, 0.3)
        out[f"{index}_points_per_second"] = points / (time.perf_counter() - t0)
    out["grid_over_kdtree"] = out["grid_points_per_second"] / out["kdtree_points_per_second"]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="lanterna bench --cache-index",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=100_000)
    args = parser.parse_args(argv)
    out = measure(max(1, args.points))
    print(f"irradiance cache, {out['records']:,} records, {out['points']:,} look-ups at a = 0.3:")
    print(f"  grid    {out['grid_points_per_second'] / 1e3:8.0f}k points/s")
    print(f"  kd-tree {out['kdtree_points_per_second'] / 1e3:8.0f}k points/s (baseline)")
    print(f"  grid / kd-tree: {out['grid_over_kdtree']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
