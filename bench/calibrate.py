"""This machine's rates for the cost estimate, and the estimate checked against real renders.

What it computes (``lanterna bench --calibrate`` / ``lanterna bench --check-estimate``)
    ``measure_rates()``: short runs on a calibration scene built in code (no bpy: a 5 x 4 x 3 m
    room with a box and a geodesic sphere, 5,144 triangles, unlike the seed scenes the check
    uses) and on a bumpy grid of 249,218 triangles:
    1. raw embreex seconds per ray, closest hit, with the renderer's worker count: coherent
       rays (pinhole rays through pixel centres) and incoherent rays (cosine directions from
       surface points), on the calibration scene and on the grid (best of three each);
       the grid also gives the BVH build and validate rates per triangle;
    2. pipeline renders of the calibration scene, each stage's time divided by the counts
       its report gives (``engine/estimate.py`` names the rates):
       direct light only with 1 and with 4 point lights at 320x240, 16 spp (camera sample
       and shadow ray rates, non-negative least squares); an area light with 8 light samples and shadow
       photons (light sample and shadow photon rates); final gathers at every pixel with
       6x24 and 12x48 strata at 40x30 and 1x4 at 96x72 (the gather point rate, non-negative
       least squares over rays and points); irradiance-cache renders with the presets' gathers
       (``CACHE_RENDERS``: 6x24 at a = 0.3 at 320x240 and 640x480, 12x48 at a = 0.1 at
       320x240), 1 spp, 300k photons (photon
       emission, tracing and map build; radiance estimates; the placement passes' cost per
       pixel and per gather ray, non-negative least squares; cache look-ups); a photon map
       of ``LARGE_MAP_PHOTONS`` in the same room (the map's build per stored photon at a
       preset's size, about 4M stored, beside the cache renders' 1M: ``STORE_KEYS``; its
       emission is pooled with the cache renders' into the emission rate, measured so at a
       preset's size too); and a photon-map look-up render.
    3. image look-ups: the calibration room with its floor's Base Color an 8-bit sRGB
       256 x 256 image (Linear), read through ``MaterialTable.at`` at 2^20 random floor hits
       in chunks of 65,536 over the worker threads (the per-hit material evaluation
       included): seconds per look-up.
    Writes the rates (JSON) to ``--rates-file`` (default ``$XDG_CACHE_HOME/lanterna/
    rates.json`` or ``~/.cache/lanterna/rates.json``) and prints them.

    ``check_estimates()``: the seed's Scene 1 and Scene 2 (``seed_scenes.py``) at each of
    ``--check-resolutions`` (default 160x120,640x480) with the ``preview`` and ``final``
    presets: the estimate (from the rates just written, or the user's / shipped rates with
    ``--check-estimate``), then the render, and prints predicted and measured pipeline time,
    their ratio and PASS where it lies within [1/1.5, 1.5], with the other processes' busy
    cores during the renders (``LoadMeter``) and the per-stage times. A benchmark, not a
    test: the machine is shared, so this is a printout, never an assertion.

Every measurement and every checked render runs ``--repeat`` times (default 2) and the
fastest run counts, as in ``bench/main.py``: on a shared machine it is the one least disturbed.

Parameters
    ``--rates-file PATH``, ``--threads N`` (0 = all cores), ``--check-resolutions LIST``
    (comma-separated WxH; ``none`` skips the check), ``--repeat N`` (2), ``--json FILE``
    (all figures).
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

import numpy as np

from ..engine import estimate as est

PASS_FACTOR = 1.5
REPEAT = 2                       # runs of each measurement and each check; the fastest counts
LARGE_MAP_PHOTONS = 1_500_000    # the large photon map (store and emission rates; about 4M stored)
# The direct-light renders of the camera and shadow-ray rates: at 160 x 120 their camera stages
# took 0.06 and 0.16 s, and two calibrations four hours apart put the shadow ray at 0.125 and
# 0.075 us; at 320 x 240 they take 0.2 and 0.6 s, and the camera stage's own fixed cost (about
# 14 ms, measured from 40 x 30 to 640 x 480) weighs 4 times less in the two-render fit.
DIRECT_RESOLUTION = (320, 240)
# The cache renders (frame, gather M x N, a): the presets' gathers and errors, preview's at two
# frame sizes (per pixel against per ray) and final's. (With 4 x 12 gathers a record's fixed
# costs, about 0.4 ms, came out as 1.4-5 us a ray and lifted the fitted ray rate by 15-25 %.)
CACHE_RENDERS = (((320, 240), (6, 24), 0.3), ((640, 480), (6, 24), 0.3),
                 ((320, 240), (12, 48), 0.1))


# -- The calibration scene (core, no bpy) ------------------------------------------------------
def _quad(c, du, dv):
    c, du, dv = (np.asarray(v, float) for v in (c, du, dv))
    p = [c - du - dv, c + du - dv, c + du + dv, c - du + dv]
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]])


def _box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    ex, ey, ez = np.diag(h)
    return np.concatenate([_quad(c - ez, ex, ey), _quad(c + ez, ex, ey), _quad(c - ex, ey, ez),
                           _quad(c + ex, ey, ez), _quad(c - ey, ex, ez), _quad(c + ey, ex, ez)])


def _icosphere(radius, subdivisions, center):
    t = (1.0 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    tris = v[f] / np.linalg.norm(v[f], axis=2, keepdims=True)
    for _ in range(subdivisions):
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        ab, bc, ca = [(p + q) / np.linalg.norm(p + q, axis=1, keepdims=True)
                      for p, q in ((a, b), (b, c), (c, a))]
        tris = np.concatenate([np.stack(s, 1) for s in
                               ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return tris * radius + np.asarray(center, float)


def calibration_scene(resolution=(160, 120), lights="point"):
    """The calibration room: ``lights`` = ``point`` (one point light), ``points4`` (four) or
    ``area`` (a 1 m square area light under the ceiling)."""
    from ..engine.scene import AreaLight, Camera, Material, PointLight, Scene

    room = _box((0, 0, 0), (5, 4, 3))
    box = _box((0.6, 2.2, 0.0), (1.6, 3.2, 1.2))
    sphere = _icosphere(0.7, 4, (3.3, 2.3, 0.7))
    tris = np.concatenate([room, box, sphere]).astype(np.float32)
    ids = np.concatenate([np.zeros(2, np.int32), np.ones(10, np.int32),       # floor, walls
                          np.full(len(box), 2, np.int32), np.full(len(sphere), 3, np.int32)])
    materials = [Material("Floor", diffuse=(0.6, 0.5, 0.4)), Material("Walls", diffuse=0.75),
                 Material("Box", diffuse=(0.5, 0.6, 0.7)), Material("Sphere", diffuse=(0.7, 0.2, 0.2))]
    if lights == "area":
        m = np.eye(4)
        m[:3, 3] = (2.5, 2.0, 2.95)
        light_list = [AreaLight("Panel", "SQUARE", m, 1.0, 1.0, power=np.full(3, 60.0))]
    else:
        spots = [(2.5, 1.0, 2.6), (4.2, 3.5, 2.4), (0.5, 0.5, 2.5), (1.0, 3.6, 1.8)]
        light_list = [PointLight(f"Lamp{i}", p, np.full(3, 40.0))
                      for i, p in enumerate(spots[:4 if lights == "points4" else 1])]
    cam = Camera.look_at([0.4, 0.3, 1.7], [3.0, 2.6, 0.8], fov_x_deg=70, resolution=resolution)
    return Scene(triangles=tris, material_ids=ids, materials=materials, camera=cam,
                 lights=light_list)


def _grid(n_triangles):
    rng = np.random.default_rng(0)
    side = int(np.sqrt(n_triangles / 2))
    x, y = np.meshgrid(np.linspace(0, 10, side + 1), np.linspace(0, 10, side + 1))
    p = np.stack([x, y, 0.05 * rng.random(x.shape)], -1).astype(np.float32)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    return np.ascontiguousarray(np.concatenate(
        [np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)]))


# -- Measurements -----------------------------------------------------------------------------
def _busy_seconds():
    """CPU seconds all cores have been busy since boot (/proc/stat), None elsewhere."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            ticks = [int(v) for v in f.readline().split()[1:9]]
        hz = os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = ticks
    return (user + nice + system + irq + softirq + steal) / hz


class LoadMeter:
    """Busy cores of other processes since it was made: the machine's busy CPU time
    (/proc/stat) minus this process's (``os.times``), over the wall time (printed beside the
    check, to show how shared the machine was)."""

    def __init__(self):
        self.start = (time.perf_counter(), _busy_seconds(), self._own())

    @staticmethod
    def _own() -> float:
        t = os.times()
        return t.user + t.system

    def cores(self):
        t0, busy0, own0 = self.start
        busy1, wall = _busy_seconds(), time.perf_counter() - t0
        if busy0 is None or busy1 is None or wall <= 0:
            return None
        return max(0.0, ((busy1 - busy0) - (self._own() - own0)) / wall)


def _raw_seconds_per_ray(triangles, origins, directions, workers, repeat=3):
    from .raw_embree import raw_embree_seconds

    step = 1 << 16
    log = [("camera", origins[a:a + step], directions[a:a + step], None)
           for a in range(0, len(origins), step)]
    best = min(raw_embree_seconds(triangles, log, workers) for _ in range(repeat))
    return best / len(origins)


def _raw_rays(workers, tell):
    """Raw embreex seconds per ray (coherent, incoherent) on the calibration scene and the
    250k grid; BVH build and validate rates from the grid."""
    from ..engine import sampling
    from ..engine.accel import Accelerator
    from ..engine.camera import pixel_rays
    from ..engine.scene import Camera, Material, Scene

    out = {}
    rng = np.random.default_rng(1)
    for size, scene in (("small", calibration_scene((320, 240))), ("large", None)):
        if scene is None:
            tris = _grid(250_000)
            cam = Camera.look_at([5, 5, 6], [5, 5, 0], up=(0, 1, 0), fov_x_deg=60,
                                 resolution=(320, 240))
            scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                          materials=[Material("Grid")], camera=cam)
            t0 = time.perf_counter()
            scene.validate()
            out["validate_triangle"] = (time.perf_counter() - t0) / len(tris)
            accel = Accelerator(scene.triangles, threads=1)
            out["bvh_triangle"] = accel.build_seconds / len(tris)
        else:
            accel = Accelerator(scene.triangles, threads=1)
        tell(f"raw embreex rays on {len(scene.triangles):,} triangles")
        o, d, _t = pixel_rays(scene.camera, 0, 320 * 240, 4, rng)
        t, prim, _u, _v = accel.intersect(o, d)
        hit = prim >= 0
        x = (o[hit] + t[hit, None] * d[hit]).astype(np.float64)
        n = scene.geometric_normals()[prim[hit]].astype(np.float64)
        n[np.einsum("ij,ij->i", n, d[hit]) > 0] *= -1
        dirs = sampling.cosine_directions(n, rng.random((len(n), 2)))
        org = accel.offset_origins(x, n, dirs).astype(np.float32)
        accel.close()
        out[f"triangles_{size}"] = float(len(scene.triangles))
        out[f"coherent_{size}"] = _raw_seconds_per_ray(scene.triangles, o, d, workers)
        out[f"incoherent_{size}"] = _raw_seconds_per_ray(scene.triangles, org,
                                                         dirs.astype(np.float32), workers)
    return out


def _fastest(reports) -> dict:
    """The stages of ``reports`` (same scene, settings and seed: same counts) with every
    ``*seconds`` entry the smallest of the runs: on a shared machine the fastest run is the
    one least disturbed by other work (as ``bench.py`` does)."""
    stages = {k: dict(v) for k, v in reports[0]["stages"].items()}
    for report in reports[1:]:
        for name, entry in report["stages"].items():
            for key, value in entry.items():
                if key.endswith("seconds") and isinstance(value, (int, float)):
                    stages[name][key] = min(stages[name][key], value)
    return stages


def _render(scene, tell, label, repeat=REPEAT, **settings):
    from ..engine.pipeline import RenderSettings, render

    tell(label)
    s = RenderSettings(**{"seed": 1, **settings})
    return _fastest([render(scene, s).report for _ in range(max(1, repeat))]), s


def _nonnegative_fit(rows, values, floor=0.0):
    """Per-unit costs >= ``floor`` from equations rows[i] . costs = values[i] (least squares
    with non-negative costs, scipy's NNLS; rows scaled so each equation weighs alike)."""
    from scipy.optimize import nnls

    m, y = np.asarray(rows, float), np.asarray(values, float)
    scale = np.maximum(np.abs(y), 1e-9)
    costs, _ = nnls(m / scale[:, None], y / scale)
    return tuple(float(max(c, floor)) for c in costs)


def _large_map(workers, tell, repeat=REPEAT) -> tuple[dict, float]:
    """A photon map at a preset's size: ``LARGE_MAP_PHOTONS`` photons in the calibration room
    (about 4M stored), ``repeat`` passes. Returns (``STORE_KEYS``' large pair: the build, i.e.
    concatenation, Morton reorder and kd-tree, per stored photon; the emission's seconds),
    each the fastest pass's."""
    from concurrent.futures import ThreadPoolExecutor

    from ..engine.accel import Accelerator
    from ..engine.photons import build_photon_map

    scene = calibration_scene((160, 120))
    accel = Accelerator(scene.triangles, threads=1)
    tell(f"photon map of {LARGE_MAP_PHOTONS:,} photons")
    best = emit = None
    try:
        with ThreadPoolExecutor(workers) as pool:
            for _ in range(max(1, repeat)):
                t0 = time.perf_counter()
                stats = build_photon_map(scene, accel, LARGE_MAP_PHOTONS, seed=1, pool=pool).stats
                store = (time.perf_counter() - t0 - stats["emit_seconds"]
                         - stats["trace_seconds"])
                best = store if best is None else min(best, store)
                emit = stats["emit_seconds"] if emit is None else min(emit, stats["emit_seconds"])
    finally:
        accel.close()
    stored = stats["stored_all"]
    return ({"stored_large": float(stored), "store_large": max(best, 1e-12) / max(stored, 1)},
            float(emit))


TEXTURE_SIZE = 256               # the calibration floor's image: 256 x 256 texels, 8-bit sRGB
TEXTURE_HITS = 1 << 20           # hits at which it is read, in chunks of TEXTURE_CHUNK
TEXTURE_CHUNK = 1 << 16


def textured_calibration_scene(resolution=(160, 120)):
    """The calibration room whose floor is a Principled BSDF with its Base Color an 8-bit
    sRGB image (``TEXTURE_SIZE`` square, random texels, Linear, Repeat) tiled 4 times through
    its UV map: one image look-up per hit on the floor."""
    from ..engine import nodes
    from ..engine.shaders import Closure

    scene = calibration_scene(resolution)
    rng = np.random.default_rng(2)
    graph = nodes.Graph()
    graph.nodes["Image"] = nodes.Node(
        "ShaderNodeTexImage", "Image", {"image": "calibration", "interpolation": "Linear",
                                        "extension": "REPEAT"},
        {"Vector": ("VECTOR", [0.0, 0.0, 0.0])}, {"Color": "RGBA", "Alpha": "VALUE"})
    graph.images["calibration"] = nodes.Image(
        rng.integers(0, 256, (TEXTURE_SIZE, TEXTURE_SIZE, 4)).astype(np.uint8), "srgb")
    closure = Closure("principled")
    closure.textures["base_color"] = [(("Image", "Color"), None)]
    floor = scene.materials[0]
    floor.closures, floor.graph = (closure,), graph
    uv = np.zeros((len(scene.triangles), 3, 2), np.float32)
    uv[:2] = scene.triangles[:2, :, :2] * (4.0 / 5.0)             # the floor: x, y in metres
    scene.corner_attributes = {"uv": uv}
    return scene


def _texture_rate(workers, tell, repeat=REPEAT) -> float:
    """Seconds per image look-up: ``MaterialTable.at(...).diffuse`` at ``TEXTURE_HITS``
    random hits on the textured floor (``textured_calibration_scene``), in chunks over
    ``workers`` threads as the stages read materials; the fastest of ``repeat`` runs."""
    from concurrent.futures import ThreadPoolExecutor

    from ..engine.bsdf import MaterialTable

    scene = textured_calibration_scene()
    table = MaterialTable(scene)
    rng = np.random.default_rng(3)
    prim = rng.integers(0, 2, TEXTURE_HITS)
    su, v = np.sqrt(rng.random(TEXTURE_HITS)), rng.random(TEXTURE_HITS)
    bu, bv = su * (1 - v), su * v
    mids = scene.material_ids[prim]
    chunks = [slice(a, a + TEXTURE_CHUNK) for a in range(0, TEXTURE_HITS, TEXTURE_CHUNK)]

    def read(c):
        return table.at(mids[c], prim[c], bu[c], bv[c]).diffuse

    tell(f"texture look-ups at {TEXTURE_HITS:,} hits")
    best = None
    with ThreadPoolExecutor(workers) as pool:
        for _ in range(max(1, repeat)):
            t0 = time.perf_counter()
            list(pool.map(read, chunks))
            seconds = time.perf_counter() - t0
            best = seconds if best is None else min(best, seconds)
    return best / TEXTURE_HITS


def measure_rates(threads=0, tell=print, repeat=REPEAT) -> est.Rates:
    """Measure every rate of ``estimate.RATE_KEYS`` on this machine (module docstring), each
    render ``repeat`` times, the fastest counting."""
    from functools import partial

    from ..engine.settings import RenderSettings

    workers = RenderSettings(threads=threads).worker_count
    run = partial(_render, repeat=repeat)

    r = {}
    raw = _raw_rays(workers, tell)
    r["validate_triangle"] = raw.pop("validate_triangle")
    r["bvh_triangle"] = raw.pop("bvh_triangle")
    tiny = 1e-9

    # camera samples and delta shadow rays: 1 and 4 point lights, direct light only
    direct = dict(bounces=0, samples=16, threads=threads)
    rows, ys = [], []
    for lights in ("point", "points4"):
        stages, _ = run(calibration_scene(DIRECT_RESOLUTION, lights), tell,
                        f"direct light, {lights}", **direct)
        cam = stages["camera"]
        rows.append((cam["camera_rays"], cam["shadow_rays"]))
        ys.append(cam["seconds"])
    r["camera_sample"], r["shadow_ray"] = _nonnegative_fit(rows, ys, tiny)

    # light samples of an area light, shadow photons
    stages, s = run(calibration_scene((160, 120), "area"), tell,
                    "area light, 8 light samples, shadow photons",
                    bounces=0, samples=16, light_samples=8, threads=threads)
    cam = stages["camera"]
    samples = cam["camera_rays"] * s.light_samples
    r["light_sample"] = max(tiny, (cam["seconds"] - cam["camera_rays"] * r["camera_sample"])
                            / samples)
    sp = stages.get("shadow_photons", {})
    r["shadow_photon"] = sp.get("seconds", 0.0) / max(sp.get("emitted", sp.get("requested", 1)), 1)

    def direct_part(cam):
        return cam["camera_rays"] * r["camera_sample"] + cam["shadow_rays"] * r["shadow_ray"]

    # final gather at every look-up: three gather sizes (many rays a point, and few)
    rows, ys = [], []
    for (m, n), res in (((6, 24), (40, 30)), ((12, 48), (40, 30)), ((1, 4), (96, 72))):
        stages, _ = run(calibration_scene(res), tell, f"final gather {m}x{n}, {res[0]}x{res[1]}",
                        samples=1, photons=100_000, indirect="gather", gather_m=m,
                        gather_n=n, threads=threads)
        cam = stages["camera"]
        rows.append((cam["gather_rays"], cam["gather_points"]))
        ys.append(cam["seconds"] - direct_part(cam))
    # (the gather-mode renders give the per-point cost; the per-ray cost comes from the cache
    # renders below, whose placement passes are what the presets spend their time in)
    _, r["gather_point"] = _nonnegative_fit(rows, ys, tiny)

    # photons, estimates, cache passes (per pixel and per gather ray), cache look-ups: three
    # cache renders, two sizes of image and two of gather
    sums = dict.fromkeys(("emit", "emitted", "trace", "rays", "store", "stored", "est",
                          "estimates", "lookup", "interpolated"), 0.0)
    cache_rows, cache_ys, cameras = [], [], []
    for res, (m, n), a in CACHE_RENDERS:
        stages, s = run(calibration_scene(res), tell, f"irradiance cache {res[0]}x{res[1]}",
                        samples=1, photons=300_000, gather_m=m, gather_n=n, cache_error=a,
                        threads=threads)
        ph, cam, ic = stages["photons"], stages["camera"], stages["irradiance_cache"]
        sums["emit"] += ph["emit_seconds"]
        sums["emitted"] += ph["emitted"]
        sums["trace"] += ph["trace_seconds"]
        sums["rays"] += ph["photon_rays"]
        sums["store"] += max(ph["seconds"] - ph["emit_seconds"] - ph["trace_seconds"], 0.0)
        sums["stored"] += ph["stored_all"]
        sums["est"] += stages["radiance_estimates"]["seconds"]
        sums["estimates"] += stages["radiance_estimates"]["estimates"]
        gather = m * n * (1 + s.gather_guided)
        cache_rows.append((res[0] * res[1], ic["records"] * gather))
        cache_ys.append(ic["seconds"] - ic["records"] * r["gather_point"])
        cameras.append(cam)
    r["cache_pixel"], r["gather_ray"] = _nonnegative_fit(cache_rows, cache_ys, tiny)
    for cam in cameras:
        sums["lookup"] += max(cam["seconds"] - direct_part(cam) - cam["gather_rays"]
                              * r["gather_ray"] - cam["gather_points"] * r["gather_point"], 0.0)
        sums["interpolated"] += cam["cache_interpolated"] + cam["cache_local_interpolated"]
    large, large_emit = _large_map(workers, tell, repeat)
    # Emission pooled over the cache renders and the large map (its fastest pass), so that it
    # is measured at a preset's size too (1M photons at ``final``; 300k-photon runs alone gave
    # 0.19 and 0.34 us a photon in two calibrations).
    r["photon_emit"] = max(tiny, (sums["emit"] + large_emit)
                           / (sums["emitted"] + LARGE_MAP_PHOTONS))
    r["photon_ray"] = max(tiny, sums["trace"] / sums["rays"])
    r["photon_store"] = max(tiny, sums["store"] / sums["stored"])
    store = {"stored_small": sums["stored"] / len(cameras), "store_small": r["photon_store"],
             **large}
    r["radiance_estimate"] = max(tiny, sums["est"] / sums["estimates"])
    r["cache_lookup"] = max(tiny, sums["lookup"] / max(sums["interpolated"], 1))

    # photon-map look-ups at the hits
    stages, _ = run(calibration_scene((160, 120)), tell, "photon-map look-ups",
                    samples=4, photons=300_000, indirect="photon-map", threads=threads)
    cam = stages["camera"]
    r["photon_lookup"] = max(tiny, (cam["seconds"] - direct_part(cam))
                             / max(cam["photon_queries"], 1))
    r["texture_lookup"] = max(tiny, _texture_rate(workers, tell, repeat))
    return est.Rates(seconds={k: float(r[k]) for k in est.RATE_KEYS}, workers=workers,
                     cores=os.cpu_count() or 1,
                     raw={**{k: raw[k] for k in est.RAW_KEYS}, **store},
                     measured=datetime.datetime.now().isoformat(timespec="seconds"))


def print_rates(rates: est.Rates, path=None) -> None:
    where = f" -> {path}" if path else ""
    print(f"Rates of this machine ({rates.workers} workers, {rates.cores} cores, "
          f"{rates.measured}){where}")
    for key, what in est.RATE_KEYS.items():
        print(f"  {key:<18} {rates.seconds[key] * 1e6:10.3f} us   {what}")
    raw = rates.raw
    if "stored_small" in raw:
        print("  photon map build: " + ", ".join(
            f"{raw[f'store_{size}'] * 1e6:.3f} us per photon at {raw[f'stored_{size}'] / 1e6:.2f}M"
            for size in ("small", "large")))
    if "triangles_small" in raw:
        for size in ("small", "large"):
            print(f"  raw embreex, {int(raw[f'triangles_{size}']):>9,} triangles: coherent "
                  f"{1e-6 / raw[f'coherent_{size}']:6.2f} Mrays/s, incoherent "
                  f"{1e-6 / raw[f'incoherent_{size}']:6.2f} Mrays/s")



# -- The check: estimate against measured time -----------------------------------------------
def check_estimates(resolutions=((160, 120), (640, 480)), scenes=("scene1", "scene2"),
                    presets=("preview", "final"), rates=None, threads=0, tell=print,
                    repeat=REPEAT) -> list:
    """Estimate, then render ``repeat`` times, every (scene, resolution, preset); rows of
    predicted and measured seconds (the fastest run; per stage the fastest) in total and per
    stage."""
    import bpy

    from ..engine.blender import seed_scenes
    from ..engine.blender.export import export_scene
    from ..engine.pipeline import RenderSettings, render

    rows = []
    for name in scenes:
        for w, h in resolutions:
            seed_scenes.build(name)
            b = bpy.context.scene
            b.render.resolution_x, b.render.resolution_y = w, h
            b.render.resolution_percentage = 100
            scene = export_scene(bpy.context.evaluated_depsgraph_get())
            for preset in presets:
                settings = RenderSettings(preset=preset, threads=threads)
                e = est.estimate_cost(scene, settings, rates)
                tell(f"{name} {w}x{h} {preset}: predicted {e.seconds:.1f} s, rendering")
                meter = LoadMeter()
                reports = [render(scene, settings).report for _ in range(max(1, repeat))]
                during = meter.cores()
                measured = min(r["total_seconds"] for r in reports)
                fastest = _fastest(reports)
                stages = {k: (v.seconds, fastest.get(k, {}).get("seconds"))
                          for k, v in e.stages.items()}
                rows.append({"scene": name, "resolution": [w, h], "preset": preset,
                             "predicted_seconds": e.seconds, "measured_seconds": measured,
                             "measured_runs": [r["total_seconds"] for r in reports],
                             "load_during": during,
                             "ratio": e.seconds / measured if measured > 0 else float("inf"),
                             "predicted_peak_bytes": e.peak_bytes, "stages": stages,
                             "estimate": e.to_report()})
    return rows


def print_check(rows) -> bool:
    print(f"Estimate against measured pipeline time (PASS: ratio within "
          f"[1/{PASS_FACTOR:g}, {PASS_FACTOR:g}]); load: other processes' busy cores during "
          "the renders")
    print(f"  {'scene':<8}{'size':>9}  {'preset':<8}{'predicted':>11}{'measured':>10}"
          f"{'ratio':>7}  result  load   per stage (predicted/measured s)")
    ok = True
    for row in rows:
        good = 1 / PASS_FACTOR <= row["ratio"] <= PASS_FACTOR
        ok &= good
        parts = ", ".join(f"{k} {p:.2f}/{m:.2f}" for k, (p, m) in row["stages"].items()
                          if m is not None and max(p, m) >= 0.05)
        w, h = row["resolution"]
        print(f"  {row['scene']:<8}{f'{w}x{h}':>9}  {row['preset']:<8}"
              f"{row['predicted_seconds']:>9.2f} s{row['measured_seconds']:>8.2f} s"
              f"{row['ratio']:>7.2f}  {'PASS' if good else 'FAIL':<6}  {_load(row)}   {parts}")
    return ok


def _load(row) -> str:
    during = row.get("load_during")
    return f"{'?' if during is None else f'{during:.1f}':>4}"


def _resolutions(text: str):
    if text.strip().lower() in ("none", ""):
        return ()
    out = []
    for part in text.split(","):
        w, h = (int(v) for v in part.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError(part)
        out.append((w, h))
    return tuple(out)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(
        prog="lanterna bench --calibrate",
        description="Measure this machine's rates for the cost estimate and check the "
                    "estimate against real renders of the seed scenes.")
    parser.add_argument("--calibrate", action="store_true",
                        help="measure the rates and write them (then check)")
    parser.add_argument("--check-estimate", action="store_true",
                        help="only check the estimate against measured renders")
    parser.add_argument("--rates-file", default=None,
                        help=f"where to write the rates (default {est.user_rates_path()})")
    parser.add_argument("--check-resolutions", default="160x120,640x480",
                        help="comma-separated WxH for the check, or 'none'")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=REPEAT,
                        help=f"runs of every measurement and check; the fastest counts "
                             f"(default {REPEAT})")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    from ..engine import imageio

    if args.json and (problem := imageio.output_problem(args.json)):
        print(f"lanterna: error: --json {args.json}: {problem}", file=sys.stderr)
        return 2
    try:
        resolutions = _resolutions(args.check_resolutions)
    except ValueError:
        print("lanterna: error: --check-resolutions must look like 160x120,640x480 or none",
              file=sys.stderr)
        return 2
    out = {}

    def tell(text):
        print(f"  ... {text}", flush=True)

    if args.calibrate:
        t0 = time.perf_counter()
        rates = measure_rates(args.threads, tell, max(1, args.repeat))
        path = est.save_rates(rates, args.rates_file)
        rates.source = str(path)
        print_rates(rates, path)
        print(f"calibration took {time.perf_counter() - t0:.1f} s")
        out["rates"] = rates.to_json()
    else:
        user = args.rates_file or est.user_rates_path()
        rates = est.load_rates(user_path=user)
        for text in rates.warnings:
            print(f"lanterna: warning: {text}", file=sys.stderr)
        print(f"Rates from {rates.source} ({rates.measured})")
    ok = True
    if resolutions:
        rows = check_estimates(resolutions, rates=rates, threads=args.threads, tell=tell,
                               repeat=max(1, args.repeat))
        ok = print_check(rows)
        out["check"] = rows
    if args.json:
        imageio.write_json(args.json, out, default=str)
    if not ok:
        print("(a benchmark on a shared machine: a FAIL is a finding to look into, not an error)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
