"""Ray tracing through Embree (the ``embreex`` binding): batched closest-hit and occlusion.

What it computes
    For arrays of rays (origins (N, 3), unit directions (N, 3), optional maximum distances),
    the closest hit (distance, triangle index, barycentrics) or whether anything blocks the
    segment. Rays are split into chunks traced on a thread pool: embreex releases the GIL
    while it traces, so both cores work.
    ``disc_coverage(points, normals, radius)``: the share of each point's tangent disc that
    its surface covers, probed by rays parallel to it (the photon estimate's edge correction,
    ``PhotonMap.irradiance``).

Parameters
    ``triangles``  (T, 3, 3) float32 world-space corners [m].
    ``threads``    worker threads (default: all cores).
    ``chunk``      rays per Embree call (default 65 536).
    ``COVERAGE_DIRECTIONS`` (8) directions a disc is probed in; ``COVERAGE_PROBE_OFFSETS``
    (4) the probes' height over and under the surface, in self-intersection offsets;
    ``COVERAGE_EDGE_COS`` (0.7071) a surface met that turns more than 45 deg from the disc
    ends it; ``COVERAGE_MIN`` (0.25) the least share reported (a right-angled corner).

Self-intersection
    embreex starts every ray at t = 0, so a secondary ray's origin is pushed off its surface
    with :meth:`Accelerator.offset_origins` by ``offset_scale * max(|p|_inf, 1e-2 * extent)``
    along the normal on the side the ray leaves. The offset is relative to the coordinates'
    magnitude (float32 round-off grows with it) and to the scene's size, so a scene scaled
    by 1e-3 or 1e3 renders the same picture. The seed's octree (4.1) is replaced by Embree's
    BVH (DESIGN.md §4).
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .sampling import dot_rows, scale_rows

MISS = -1
OFFSET_SCALE = 2e-5
# ``Accelerator.disc_coverage``: directions probed per disc, the height of its probes in
# offsets, how far from the disc's plane a surface must turn to end it (cos 45 deg), and the
# least share it reports (a disc centred on a right-angled corner).
COVERAGE_DIRECTIONS = 8
COVERAGE_PROBE_OFFSETS = 4
COVERAGE_EDGE_COS = 0.7071
COVERAGE_MIN = 0.25


def offset_distance(points: np.ndarray, extent: float) -> np.ndarray:
    """Self-intersection offset [m] for each point (N,): ``OFFSET_SCALE`` times the larger of
    its largest |coordinate| and 1 % of the scene's ``extent``."""
    mag = np.abs(points[:, 0])                 # max |coordinate|, a column at a time
    tmp = np.abs(points[:, 1])
    np.maximum(mag, tmp, out=mag)
    np.maximum(mag, np.abs(points[:, 2], out=tmp), out=mag)
    np.maximum(mag, 1e-2 * extent, out=mag)
    mag *= OFFSET_SCALE
    return mag


class Accelerator:
    """An Embree BVH over the scene's triangles with batched, threaded queries."""

    def __init__(self, triangles: np.ndarray, threads: int | None = None, chunk: int = 1 << 16):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.triangles = np.ascontiguousarray(triangles, dtype=np.float32).reshape(-1, 3, 3)
        self.threads = max(1, int(threads or os.cpu_count() or 1))
        self.chunk = int(chunk)
        self.rays_traced = 0
        self.trace_seconds = 0.0
        start = time.perf_counter()
        self._embree = None
        if len(self.triangles):
            self._embree = rtcore_scene.EmbreeScene()
            self._mesh = TriangleMesh(self._embree, self.triangles)
            # The first query commits the scene (builds the BVH); do it now so that build
            # time is not charged to the first batch of rays.
            probe = np.zeros((1, 3), np.float32)
            self._embree.run(probe, np.array([[0, 0, 1]], np.float32), query="OCCLUDED")
            pts = self.triangles.reshape(-1, 3)
            lo, hi = pts.min(axis=0).astype(np.float64), pts.max(axis=0).astype(np.float64)
            self.extent = float(max(np.linalg.norm(hi - lo), 1e-30))
        else:
            self.extent = 1.0
        self.build_seconds = time.perf_counter() - start
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    # Queries --------------------------------------------------------------------------------
    def _map_chunks(self, fn, n: int):
        bounds = [(s, min(s + self.chunk, n)) for s in range(0, n, self.chunk)]
        if self._pool is None or len(bounds) == 1:
            for b in bounds:
                fn(*b)
        else:
            list(self._pool.map(lambda b: fn(*b), bounds))

    def intersect(self, origins: np.ndarray, directions: np.ndarray,
                  tmax: np.ndarray | float | None = None):
        """Closest hits. Returns (t float32 (N,), prim int32 (N,) with -1 for a miss,
        u float32, v float32): hit point = (1-u-v) p0 + u p1 + v p2."""
        n = len(origins)
        if n == 0 or self._embree is None:
            return (np.full(n, np.inf, np.float32), np.full(n, MISS, np.int32),
                    np.zeros(n, np.float32), np.zeros(n, np.float32))
        org = np.ascontiguousarray(origins, dtype=np.float32)
        dirs = np.ascontiguousarray(directions, dtype=np.float32)
        far = None if tmax is None else np.broadcast_to(np.asarray(tmax, np.float32), (n,))
        start = time.perf_counter()
        if n <= self.chunk:
            # One Embree call: return its arrays as they are, without copies.
            dists = np.full(n, 1e37, np.float32) if far is None else np.array(far, np.float32)
            out = self._embree.run(org, dirs, dists, output=1)
            self.trace_seconds += time.perf_counter() - start
            self.rays_traced += n
            return out["tfar"], out["primID"], out["u"], out["v"]
        t = np.empty(n, np.float32)
        prim = np.empty(n, np.int32)
        u = np.empty(n, np.float32)
        v = np.empty(n, np.float32)

        def run(a, b):
            dists = np.full(b - a, 1e37, np.float32) if far is None else np.array(far[a:b], np.float32)
            out = self._embree.run(org[a:b], dirs[a:b], dists, output=1)
            prim[a:b] = out["primID"]
            t[a:b] = out["tfar"]
            u[a:b] = out["u"]
            v[a:b] = out["v"]

        self._map_chunks(run, n)
        self.trace_seconds += time.perf_counter() - start
        self.rays_traced += n
        return t, prim, u, v

    def occluded(self, origins: np.ndarray, directions: np.ndarray,
                 tmax: np.ndarray | float) -> np.ndarray:
        """True where something lies on the segment [0, tmax) of each ray."""
        n = len(origins)
        blocked = np.zeros(n, bool)
        if n == 0 or self._embree is None:
            return blocked
        org = np.ascontiguousarray(origins, dtype=np.float32)
        dirs = np.ascontiguousarray(directions, dtype=np.float32)
        far = np.broadcast_to(np.asarray(tmax, np.float32), (n,))
        start = time.perf_counter()

        def run(a, b):
            ids = self._embree.run(org[a:b], dirs[a:b], np.array(far[a:b], np.float32),
                                   query="OCCLUDED")
            blocked[a:b] = ids >= 0

        self._map_chunks(run, n)
        self.trace_seconds += time.perf_counter() - start
        self.rays_traced += n
        return blocked

    def disc_coverage(self, points: np.ndarray, normals: np.ndarray, radius: np.ndarray,
                      directions: int = COVERAGE_DIRECTIONS) -> np.ndarray:
        """The share (N,) of the disc of ``radius`` [m] about each point, in its tangent plane
        (unit ``normals``), that its own surface covers: 1 inside a face, about 1/2 on an
        edge, 1/4 in a right-angled corner (at least ``COVERAGE_MIN``). In ``directions``
        directions d_j (a per-point rotation from the point's coordinates, so the answer
        does not depend on batching) two rays run parallel to the plane, just above and just
        below it (``COVERAGE_PROBE_OFFSETS`` offsets): the first surface they meet within the
        radius that turns more than 45 deg from the plane ends the disc there (above: a wall
        rising from a floor; below: the inside of a solid past its convex edge); the share is
        the polar area sum_j min(t_j, r)^2 / (D r^2). Coplanar neighbours and gently curved
        surfaces do not end it; an open edge (a sheet ending in air) is not seen."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        n = np.asarray(normals, np.float64).reshape(-1, 3)
        r = np.asarray(radius, np.float64).reshape(-1)
        count, d = len(x), int(directions)
        share = np.ones(count)
        if count == 0 or self._embree is None:
            return share
        # A tangent frame per point, turned by a hash of its coordinates.
        helper = np.where(np.abs(n[:, 0:1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(n, helper)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-300)
        t2 = np.cross(n, t1)
        turn = np.modf(np.abs(np.sin(x @ np.array([12.9898, 78.233, 37.719])) * 43758.5453))[0]
        phi = 2.0 * np.pi * (np.arange(d)[None, :] + turn[:, None]) / d            # (N, D)
        ways = (np.cos(phi)[..., None] * t1[:, None, :]
                + np.sin(phi)[..., None] * t2[:, None, :]).reshape(-1, 3)          # (N D, 3)
        lift = (COVERAGE_PROBE_OFFSETS * self.offset_distance(x))[:, None] * n     # (N, 3)
        reach = np.repeat(r, d)
        ends = np.repeat(r, d)
        for side in (1.0, -1.0):
            origins = np.repeat(x + side * lift, d, axis=0)
            t, prim, _u, _v = self.intersect(origins, ways, reach)
            hit = np.flatnonzero((prim >= 0) & (t < reach))
            if len(hit) == 0:
                continue
            corners = self.triangles[prim[hit]].astype(np.float64)    # the hit ones only
            face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300)
            turned = np.abs(dot_rows(face, np.repeat(n, d, axis=0)[hit])) < COVERAGE_EDGE_COS
            hit = hit[turned]
            ends[hit] = np.minimum(ends[hit], t[hit])
        safe_r = np.where(r > 0, r, 1.0)
        share = ((ends.reshape(count, d) / safe_r[:, None]) ** 2).mean(axis=1)
        return np.where(r > 0, np.clip(share, COVERAGE_MIN, 1.0), 1.0)

    # Geometry helpers -----------------------------------------------------------------------
    def offset_distance(self, points: np.ndarray) -> np.ndarray:
        """Self-intersection offset [m] for each point (N,): see :func:`offset_distance`."""
        return offset_distance(points, self.extent)

    def offset_origins(self, points: np.ndarray, normals: np.ndarray,
                       directions: np.ndarray, eps: np.ndarray | None = None) -> np.ndarray:
        """Push points off their surface along the normal, on the side ``directions`` leave.
        ``eps``: ``offset_distance(points)`` when the caller has it already."""
        if eps is None:
            eps = self.offset_distance(points)
        eps = np.where(dot_rows(normals, directions) >= 0, eps, -eps).astype(points.dtype, copy=False)
        out = scale_rows(normals, eps)
        out += points
        return out
