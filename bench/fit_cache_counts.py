"""Refit the cost estimate's irradiance-cache counts (``engine/estimate.py``: ``RECORD_FIT`` and
``UNCOVERED_FIT``) from real renders.

What it computes
    Renders the seed's Scene 1 and Scene 2 (``engine/blender/seed_scenes.py``) at 160 x 120 and
    640 x 480 with the ``preview`` and ``final`` presets (a = 0.3 and 0.1; 16 spp, the presets'
    samples: the automatic look-up count asks the cache at all 16 samples of a pixel at
    160 x 120 and at one at 640 x 480, and the camera's batch-local records serve a pixel's
    uncovered samples from one gather, so the gathered share depends on it), and two closed rooms
    (``tests/test_gather_cache.py``'s box with a point light, and the same box with a plate
    floating over the floor under a spot that lights the ceiling) at fields of view of 40,
    60 and 90 degrees (160 x 120, a = 0.2, gather 8 x 32), and for each the records the
    placement passes made (with the neighbour check, ``cache_refine``) and the share of the
    cache look-ups that needed a gather in the camera stage (no placed record covered them,
    and they made a batch-local record or had no local record near: gathered afresh). Then
    the least-squares fits
        ln(records)              = c0 + c1 ln F + c2 ln a + c3 ln F ln a
        ln(uncovered share)      = u0 + u1 ln F + u2 ln a
    (F the frame's pixels) over the seed scenes' eight renders, and how far each render, the
    rooms' too, lies from them. The rooms scatter far more than F and a can explain (a view
    of one flat wall needs 55 records, a room at 90 degrees 978 at the same size and a): what
    the camera sees and how the light falls decide, which counts known before the render
    cannot tell, so the fit is the seed scenes'. Each case is also placed without the
    neighbour check (``cache_refine`` off) to show what the check adds: measured 2026-12-02,
    with the passes refilling the check's gaps coarse to fine, x1.04-1.06 on Scene 1 at
    a = 0.3 and x1.00 at a = 0.1, x1.23-1.30 and x1.35-1.50 on Scene 2, x1.00-1.01 in the room
    and x1.01-2.26 for the plate with the view; the seed renders lie at 0.81-1.23 of the fit,
    the rooms at 0.05-0.89. (Before the refill, 2026-12-01: x1.56-2.05, x1.01-1.04, x1.29-1.47,
    x1.76-2.01, x1.00-1.11 and x1.04-23.7; the seed renders at 0.71-1.41.) No one number
    of a scene foresees it: the concentration of the light's first hits (the flux-weighted
    mean irradiance over the mean, from 50k photons' first hits in voxels of 1/48 of the
    scene) is 39 for Scene 1, 304 for Scene 2, 29 for the room and 1049 for the plate.
    Counts do not depend on the machine's speed, so the fit can run on a busy machine.

Pilots (``--pilots``): can a cheap run before the render foresee the records? For every case,
on a map of ``PILOT_PHOTONS`` photons (the first passes' counts come out within a few records
of the full map's), two pilots:
    passes   the first three placement passes (strides 32, 16, 8) with the render's gather,
             plus the count of stride-4 points they leave uncovered (pass 4's records, known
             without its gathers): K records known; then the least-squares fit
             ln(records) = p0 + p1 ln K + p2 ln a over the seed scenes, with leave-one-out.
    windows  the whole placement restricted to ``WINDOW_SHARE`` of the frame (a centred window
             in each cell of a 4 x 4 grid, 2 x 2 below 240 pixels), each record weighed by
             the share of its reach's disc inside the windows, over that share.
Measured 2026-12-02, before the refill (``--pilots``, this tool's eight seed renders and six
rooms):
    passes   0.73-1.44 of the records (0.59-1.81 left out; the F, a fit: 0.71-1.41), rooms
             0.22-1.17; Scene 1 and Scene 2 at 640 x 480, ``final``: 0.88 and 1.09 (the F, a
             fit 0.74 and 1.35), but at 160 x 120, ``final``: 0.73 and 1.43, as the F, a fit;
             2.6-3.2 s at 640 x 480, ``final``, on top of a 100k-photon map (0.5-1 s).
    windows  0.52-1.54 (640 x 480, ``final``: 1.09 and 1.04), rooms 0.01-1.78 (the plate under
             the spot falls outside the windows); 3.5-6.1 s at 640 x 480, ``final``: 25-30 %
             of the placement itself.
Neither is worth its cost as a forecast: the check's growth happens in the last passes
(Scene 2 at 320 x 240, ``preview``: 291 records at stride 2, then 4,027 at stride 1), which
only placing them shows.

Usage (from the repository root, with the project's virtualenv)::

    .venv/bin/python tools/fit_cache_counts.py [--json FILE] [--pilots]

Prints one line per render and the fitted constants to paste into ``engine/estimate.py``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))


def seed_scene(name, resolution):
    import bpy

    from lanterna.engine.blender import seed_scenes
    from lanterna.engine.blender.export import export_scene

    scene = seed_scenes.build(name)
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()
    return export_scene(bpy.context.evaluated_depsgraph_get())


def rooms(fov):
    from analytic import box_room, quad
    from lanterna.engine.scene import Camera, Material, PointLight, Scene, SpotLight

    room = box_room(size=(4.0, 4.0, 3.0))
    plate = np.concatenate([room, quad([2.0, 2.0, 1.0], [0.5, 0, 0], [0, 0.5, 0])])
    white = [Material("white", diffuse=0.7)]
    yield f"room {fov}", Scene(
        triangles=room, material_ids=np.zeros(len(room), np.int32), materials=white,
        lights=[PointLight("P", [3.2, 2.5, 2.6], [60.0] * 3)],
        camera=Camera.look_at([2.0, 0.3, 1.5], [2.0, 4.0, 1.2], resolution=(160, 120),
                              fov_x_deg=fov))
    yield f"plate {fov}", Scene(
        triangles=plate, material_ids=np.zeros(len(plate), np.int32), materials=white,
        lights=[SpotLight("Up", [2.0, 2.0, 2.3], [0, 0, 1.0], [100.0] * 3, np.radians(25))],
        camera=Camera.look_at([2.0, 0.3, 2.2], [2.0, 2.3, 0.0], resolution=(160, 120),
                              fov_x_deg=fov))


def cases():
    from lanterna.engine.pipeline import PRESETS

    for name in ("scene1", "scene2"):
        for res in ((160, 120), (640, 480)):
            scene = seed_scene(name, res)
            for preset in ("preview", "final"):
                p = PRESETS[preset]
                yield (f"{name} {res[0]}x{res[1]} {preset}", scene,
                       dict(photons=p["photons"], gather_m=p["gather_m"], gather_n=p["gather_n"],
                            cache_error=p["cache_error"]))
    for fov in (40, 60, 90):
        for label, scene in rooms(fov):
            yield label, scene, dict(photons=300_000, gather_m=8, gather_n=32, cache_error=0.2)


def measure(with_pilots=False):
    from lanterna.engine.pipeline import RenderSettings, render

    rows = []
    for label, scene, settings in cases():
        result = render(scene, RenderSettings(samples=16, seed=1, light_samples=1, **settings))
        cam = result.report["stages"]["camera"]
        lookups = (cam["cache_interpolated"] + cam["cache_local_interpolated"]
                   + cam["cache_gathered"])
        w, h = scene.camera.resolution
        plain = render(scene, RenderSettings(samples=1, seed=1, light_samples=1,
                                             cache_refine=False, **settings))
        row = {"case": label, "pixels": w * h, "a": settings["cache_error"],
               "records": result.report["stages"]["irradiance_cache"]["records"],
               "records_without_check": plain.report["stages"]["irradiance_cache"]["records"],
               "uncovered": cam["cache_gathered"] / max(lookups, 1)}
        if with_pilots:
            row.update(pilots(scene, settings))
        rows.append(row)
        print(f"  {label:<26} records {row['records']:>6} ({row['records_without_check']:>6} "
              f"without the check, x{row['records'] / max(row['records_without_check'], 1):.2f})"
              f"  uncovered {row['uncovered']:.4f}", flush=True)
    return rows


PILOT_PHOTONS = 100_000
WINDOW_SHARE = 0.25


def pilots(scene, settings_dict) -> dict:
    """The two pilots of the module docstring for one case: known records K (passes pilot),
    and the windows pilot's weighted record count over the whole frame."""
    import time
    from dataclasses import replace

    from lanterna.engine import pipeline as P

    settings = P.RenderSettings(samples=16, seed=1, light_samples=1, **settings_dict).resolved()
    # The pipeline's own stages 1-6 on a small map: with indirect="gather" they end at the
    # final gather the placement passes use, and place no cache.
    prep = P._prepare(scene, replace(settings, photons=PILOT_PHOTONS, indirect="gather"),
                      None, None, None)
    accel, arrays, pool, gather = prep.accel, prep.arrays, prep.pool, prep.photon
    a = settings.cache_error
    quiet = lambda *args: None                                     # noqa: E731
    t0 = time.perf_counter()
    cache, _stats = P._cache_prepass(scene, accel, arrays, gather, settings, pool, quiet, None,
                                     strides=(32, 16, 8))
    cam = scene.camera
    w, h = cam.window_size
    hits = P._centre_hits(scene, accel, arrays)
    row, col = np.divmod(hits.pixel[hits.diffuse], w)
    on4 = (row % 4 == 0) & (col % 4 == 0)
    _e, covered, _w, _c = cache.interpolate(hits.x[hits.diffuse][on4],
                                            hits.ns[hits.diffuse][on4], a, count_usage=False)
    known = len(cache) + int((~covered).sum())
    passes_seconds = time.perf_counter() - t0

    cells = 4 if min(w, h) >= 240 else 2
    cw, ch = w / cells, h / cells
    ww, wh = (max(1, int(round(v * np.sqrt(WINDOW_SHARE)))) for v in (cw, ch))
    mask = np.zeros((h, w), bool)
    for i in range(cells):
        for j in range(cells):
            x0, y0 = int(round(j * cw + (cw - ww) / 2)), int(round(i * ch + (ch - wh) / 2))
            mask[y0:y0 + wh, x0:x0 + ww] = True
    t0 = time.perf_counter()
    cache, stats = P._cache_prepass(scene, accel, arrays, gather, settings, pool, quiet, None,
                                    pixel_mask=mask)
    window_seconds = time.perf_counter() - t0
    reach = a * cache.radius / stats["record_footprint"]       # pixels
    py, px = np.divmod(stats["record_pixels"], w)
    ring = np.sqrt((np.arange(4) + 0.5) / 4)
    turn = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    disc = np.array([(r * np.cos(q), r * np.sin(q)) for r in ring for q in turn])
    sx = px[:, None] + 0.5 + reach[:, None] * disc[None, :, 0]
    sy = py[:, None] + 0.5 + reach[:, None] * disc[None, :, 1]
    # a disc sample counts where it falls on a window pixel of the mask
    in_frame = (sx >= 0) & (sx < w) & (sy >= 0) & (sy < h)
    inside = np.zeros(sx.shape, bool)
    inside[in_frame] = mask[sy[in_frame].astype(np.int64), sx[in_frame].astype(np.int64)]
    prep.close()
    return {"pilot_known": known, "pilot_passes_seconds": passes_seconds,
            "pilot_windows": float(inside.mean(axis=1).sum() / (mask.sum() / (w * h))),
            "pilot_windows_seconds": window_seconds}


def pilot_fit(rows):
    """ln(records) = p0 + p1 ln K + p2 ln a over the seed scenes' rows: the constants, each
    row's measured / fitted ratio, and each seed row's ratio left out of its own fit."""
    y = np.log([r["records"] for r in rows])
    X = np.column_stack([np.ones(len(rows)), np.log([r["pilot_known"] for r in rows]),
                         np.log([r["a"] for r in rows])])
    seed = np.array([r["case"].startswith("scene") for r in rows])
    p = np.linalg.lstsq(X[seed], y[seed], rcond=None)[0]
    loo = {}
    for i in np.nonzero(seed)[0]:
        keep = seed.copy()
        keep[i] = False
        q = np.linalg.lstsq(X[keep], y[keep], rcond=None)[0]
        loo[i] = float(np.exp(y[i] - X[i] @ q))
    return p, np.exp(y - X @ p), loo


def fit(rows):
    """The two fits over the seed scenes' rows (the rooms are checked against them, not fitted:
    what a camera sees matters more than F and a, see the module docstring), and every row's
    measured / fitted ratio."""
    lp = np.log([r["pixels"] for r in rows])
    la = np.log([r["a"] for r in rows])
    seed = np.array([r["case"].startswith("scene") for r in rows])
    y = np.log([r["records"] for r in rows])
    X = np.column_stack([np.ones_like(lp), lp, la, lp * la])
    c = np.linalg.lstsq(X[seed], y[seed], rcond=None)[0]
    record_ratio = np.exp(y - X @ c)
    share = np.array([max(r["uncovered"], 1e-6) for r in rows])
    Xu = np.column_stack([np.ones_like(lp), lp, la])
    u = np.linalg.lstsq(Xu[seed], np.log(share[seed]), rcond=None)[0]
    uncovered_ratio = share / np.exp(Xu @ u)
    return c, u, record_ratio, uncovered_ratio, seed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", default=None, help="also write every point and the fit")
    parser.add_argument("--pilots", action="store_true",
                        help="also run the two pilots of the module docstring on every case")
    args = parser.parse_args(argv)
    rows = measure(args.pilots)
    c, u, rr, ur, seed = fit(rows)
    print("\nmeasured / fitted:")
    for row, a, b in zip(rows, rr, ur):
        print(f"  {row['case']:<26} records {a:5.2f}  uncovered {b:5.2f}")
    print(f"\nRECORD_FIT = ({', '.join(f'{v:.5f}' for v in c)})")
    print(f"UNCOVERED_FIT = ({', '.join(f'{v:.5f}' for v in u)})")
    print(f"records: seed scenes {min(rr[seed]):.2f}-{max(rr[seed]):.2f} of the fit, rooms "
          f"{min(rr[~seed]):.2f}-{max(rr[~seed]):.2f}; uncovered share: seed scenes "
          f"{min(ur[seed]):.2f}-{max(ur[seed]):.2f}, rooms {min(ur[~seed]):.2f}-"
          f"{max(ur[~seed]):.2f}")
    if args.pilots:
        p, ratio, loo = pilot_fit(rows)
        print(f"\npilots (ln records = {p[0]:.3f} + {p[1]:.3f} ln K + {p[2]:.3f} ln a):")
        for i, row in enumerate(rows):
            left = f" (left out {loo[i]:.2f})" if i in loo else ""
            print(f"  {row['case']:<26} K {row['pilot_known']:>6}  passes pilot {ratio[i]:5.2f}"
                  f"{left} in {row['pilot_passes_seconds']:.1f} s;  windows pilot "
                  f"{row['pilot_windows'] / row['records']:5.2f} in "
                  f"{row['pilot_windows_seconds']:.1f} s")
    if args.json:
        out = {"rows": rows, "record_fit": c.tolist(), "uncovered_fit": u.tolist()}
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
