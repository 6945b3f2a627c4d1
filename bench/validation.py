"""``docs/validation.md``: what Lanterna's pictures are checked against, measured and dated.

What it measures (``lanterna bench --validation [--out docs/validation.md]`` from a checkout;
about 10 minutes on 2 cores)
    1. Closed forms in every indirect mode (``tests/test_analytic_modes.py``'s cases: the
       coloured and grey furnaces, pbrt's sphere) at default settings over ``--seeds`` seeds:
       mean, SD and worst relative error per case and mode (the worst channel).
    2. Direct light against Cycles (``tests/test_parity_cycles.py``: ten scenes, one light type
       each, two Lanterna seeds): the worst bright 4 x 4 block and the whole image's luminance.
    3. All bounces against Cycles (``tests/test_parity_cycles_gi.py``): the ``final`` preset
       and the photon map at the hit, two seeds, on every scene with a stored reference.
    4. Textures and HDRI worlds against Cycles (``TEXTURE_WORLD_SCENES``: issue 24's three
       scenes and a validation scene of each kind, ``final`` at ``TEXTURE_WORLD_SEEDS``): the
       worst bright 4 x 4 region (``tests/test_parity_materials.worst_bright_ratio``) and the
       whole image's luminance ratio, per seed (needs bpy: the scenes are built in it).
    5. Which scenes tuned which parameters, and which only validate (``SCENE_ROLES``): a
       parameter tuned on a scene is not validated by that scene.
The tests assert the rules; this writes down how far inside them each figure lies.
"""
from __future__ import annotations

import argparse
import datetime
import platform
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TESTS = REPO / "tests"
LUMA = np.array([0.2126, 0.7152, 0.0722])

# scene -> (role, what was tuned on it). Tuning scenes keep regression tests (a change must
# not undo what was tuned), but their agreement validates nothing that was tuned on them.
SCENE_ROLES = {
    "Scene 2 (seed, 12.1)": ("tuning", "the `final` preset's cache error a = 0.1 and the "
                             "photon-guided gather (1 x M x N extra rays); the cache's "
                             "neighbour check (one pooled noise sigma, a linear bound); the "
                             "camera's batch-local records (steps 16, 4); with Scene 1, the "
                             "estimate's cache-count fit (`bench/fit_cache_counts.py`)"),
    "Scene 1 (seed, 12.1)": ("tuning", "the estimate's cache-count fit (with Scene 2); the "
                             "presets' place on the quality sweep"),
    "plate under a spot (`tests/test_gather_cache.py`)": ("tuning", "the neighbour check's "
                                                          "indirect shadow"),
    "calibration room (`bench/calibrate.py`)": ("tuning", "the cost estimate's rates"),
    "Cornell box, 80 x 60 (`tests/parity_scenes.py`)": ("validation", "nothing"),
    "Cornell box, original data in mm (`tests/parity_scenes.py`)": ("validation", "nothing"),
    "furnaces and pbrt's sphere (`tests/test_analytic_modes.py`)": ("validation", "nothing"),
    "ten direct-light scenes (`tests/parity_scenes.py`)": ("validation", "nothing"),
    "textured room (`tests/texture_scenes.py`)": ("tuning", "the textured emitter's "
                                                  "sub-triangles for light samples "
                                                  "(`lights.TEXTURED_EMITTER_TRIANGLES`); the "
                                                  "texture look-ups per camera sample "
                                                  "(`integrator.TEXTURE_SUPERSAMPLES`, on its "
                                                  "floor's sharpness)"),
    "textured gallery (`tests/texture_scenes.py`)": ("validation", "nothing"),
    "HDRI yard (`tests/world_scenes.py`)": ("tuning", "leaving the sky outside the sun's "
                                            "patches to the final gather "
                                            "(`lights.EnvironmentLight.gather_sky`, chosen "
                                            "on its error)"),
    "window room with a portal (`tests/world_scenes.py`)": ("tuning", "the world's photons "
                                                            "outside the portals "
                                                            "(`photons.EXTERIOR_SHARE`) and "
                                                            "the portals' share of light "
                                                            "samples (`lights.PORTAL_SHIFT`)"),
    "HDRI court (`tests/world_scenes.py`)": ("validation", "nothing"),
}

# Section 4 (issue 24): (builder module in tests/, scene, reference folder in tests/data/,
# the bound on the worst bright region, role).
TEXTURE_WORLD_SCENES = (
    ("texture_scenes", "textured_room", "cycles_materials", 0.02, "issue 24's scene"),
    ("texture_scenes", "textured_gallery", "cycles_materials", 0.02, "validation"),
    ("world_scenes", "yard", "cycles_world", 0.02, "issue 24's scene"),
    ("world_scenes", "court", "cycles_world", 0.02, "validation"),
    ("world_scenes", "window_room", "cycles_world", 0.03, "issue 24's scene"),
)
TEXTURE_WORLD_SEEDS = (1, 2)


def _tests_on_path():
    if str(TESTS) not in sys.path:
        sys.path.insert(0, str(TESTS))


def analytic(seeds: int) -> list[dict]:
    """Section 1: relative error of the image mean per case, mode and seed."""
    _tests_on_path()
    import test_analytic_modes as A
    from ..engine.pipeline import RenderSettings, render
    from ..engine.settings import INDIRECT_METHODS

    rows = []
    for case, (make, exact) in A.CASES.items():
        for mode in INDIRECT_METHODS:
            errors = []
            for seed in range(seeds):
                image = render(make(), RenderSettings(indirect=mode, seed=seed)).image
                errors.append(image.reshape(-1, 3).astype(np.float64).mean(0) / exact() - 1)
            errors = np.array(errors)
            worst_channel = int(np.abs(errors).max(axis=0).argmax())
            e = errors[:, worst_channel]
            rows.append({"case": case, "mode": mode, "channel": "RGB"[worst_channel],
                         "mean": float(e.mean()), "sd": float(e.std(ddof=1)) if seeds > 1 else 0.0,
                         "worst": float(e[np.abs(e).argmax()])})
            print(f"  {case:18s} {mode:10s} {100 * e.mean():+.2f} %", file=sys.stderr, flush=True)
    return rows


def _blocks_against(name, images, ref) -> dict:
    _tests_on_path()
    from test_parity_cycles import BRIGHT_FRACTION, block_means

    grid = tuple(int(v) for v in ref["grid"])
    lan = np.mean([block_means(np.asarray(i, np.float64), grid) for i in images], axis=0)
    mean = ref["region_mean"]
    peak = mean.reshape(-1, 3).max(axis=0)
    bright = mean >= BRIGHT_FRACTION * np.maximum(peak, 1e-30)
    rel = np.where(bright, lan / np.where(bright, mean, 1.0) - 1, 0.0)
    worst = float(rel.flat[np.abs(rel).argmax()])
    image = np.mean(images, axis=0).reshape(-1, 3) @ LUMA
    whole = float(image.sum() / (ref["image"].reshape(-1, 3) @ LUMA).sum() - 1)
    return {"scene": name, "worst": worst, "whole": whole}


def direct_parity() -> list[dict]:
    """Section 2: the direct-light scenes against their Cycles references."""
    _tests_on_path()
    import parity_scenes
    import test_parity_cycles as D

    rows = []
    for name in parity_scenes.SCENES:
        t0 = time.perf_counter()
        images, _sampling = D.render_lanterna(name)
        row = _blocks_against(name, images, D.load_reference(name))
        row["seconds"] = (time.perf_counter() - t0) / len(images)
        rows.append(row)
        print(f"  direct {name}: {100 * row['worst']:+.2f} %", file=sys.stderr, flush=True)
    return rows


def gi_parity() -> list[dict]:
    """Section 3: every scene with an all-bounce reference, ``final`` and the photon map."""
    _tests_on_path()
    import test_parity_cycles_gi as G
    from test_parity_cycles import load_reference

    rows = []
    names = sorted(p.stem for p in G.REF_DIR.glob("*.npz"))
    for name in names:
        ref = load_reference(name, G.REF_DIR)
        for label, settings in (("final", dict(preset="final")),
                                ("photon map at the hit", None)):
            t0 = time.perf_counter()
            results = G.render_full(name, **(settings or {}))
            row = _blocks_against(name, [r.image for r in results], ref)
            row.update(method=label, seconds=(time.perf_counter() - t0) / len(results))
            rows.append(row)
            print(f"  gi {name} {label}: {100 * row['worst']:+.2f} %", file=sys.stderr,
                  flush=True)
    return rows


def texture_world_parity() -> list[dict]:
    """Section 4: issue 24's scenes and their validation scenes against their references."""
    _tests_on_path()
    import importlib

    from test_parity_materials import render_against_reference, worst_bright_ratio

    rows = []
    for module, name, folder, bound, role in TEXTURE_WORLD_SCENES:
        builders = importlib.import_module(module)
        worst, whole, seconds = [], [], []
        for seed in TEXTURE_WORLD_SEEDS:
            t0 = time.perf_counter()
            image, ref = render_against_reference(name, seed, builders,
                                                  TESTS / "data" / folder)
            seconds.append(time.perf_counter() - t0)
            worst.append(worst_bright_ratio(image, ref))
            whole.append(float((image.reshape(-1, 3) @ LUMA).sum()
                               / (ref["image"].reshape(-1, 3) @ LUMA).sum()))
            print(f"  {name} seed {seed}: worst {100 * worst[-1]:.2f} %", file=sys.stderr,
                  flush=True)
        rows.append({"scene": name, "role": role, "bound": bound, "worst": worst,
                     "whole": whole, "seconds": float(np.mean(seconds))})
    return rows


def write(path: Path, analytic_rows, direct_rows, gi_rows, seeds: int, minutes: float,
          texture_world_rows=()) -> None:
    today = datetime.date.today().isoformat()
    pct = lambda v: f"{100 * v:+.2f} %"                                    # noqa: E731
    lines = [
        "# Validation", "",
        f"Measured {today} on {platform.machine()} ({platform.system()}), {minutes:.0f} min. "
        "Regenerate with `lanterna bench --validation` from a checkout "
        "(`bench/validation.py`). The tests (`make test`) assert the rules; this page says "
        "how far inside them each figure lies.", "",
        "## Closed forms in every indirect mode", "",
        f"Default settings (16 spp, 200k photons at 24 × 24), seeds 0-{seeds - 1}; the image "
        "mean against the exact radiance, the channel that lies farthest off "
        "(`tests/test_analytic_modes.py`, rule 2 %).", "",
        "| case | mode | channel | mean error | SD | worst |", "|---|---|---|---|---|---|"]
    for r in analytic_rows:
        lines.append(f"| {r['case']} | {r['mode']} | {r['channel']} | {pct(r['mean'])} | "
                     f"{100 * r['sd']:.2f} % | {pct(r['worst'])} |")
    lines += ["", "## Direct light against Cycles", "",
              "Ten scenes, one light type each, over diffuse surfaces with an occluder, 64 × 48; "
              "Cycles 4 × 1024 spp (`tests/test_parity_cycles.py`, rule 2 % on bright blocks). "
              "Lanterna: mean of two seeds.", "",
              "| scene | worst bright 4 × 4 block | whole image (luminance) |", "|---|---|---|"]
    for r in direct_rows:
        lines.append(f"| {r['scene']} | {pct(r['worst'])} | {pct(r['whole'])} |")
    lines += ["", "## All bounces against Cycles", "",
              "Cycles with 64 bounces, no clamping, no denoiser (`tests/data/README.md`); "
              "Lanterna `full` mode, mean of seeds 1 and 2 (`tests/test_parity_cycles_gi.py`: "
              "rule 3 % for `final`, 5 % for the photon map at the hit). Scene 2 is a tuning "
              "scene (below): its row guards against regressions, it validates nothing tuned "
              "on it.", "",
              "| scene | method | worst bright block | whole image | seconds per render |",
              "|---|---|---|---|---|"]
    for r in gi_rows:
        lines.append(f"| {r['scene']} | {r['method']} | {pct(r['worst'])} | {pct(r['whole'])} "
                     f"| {r['seconds']:.1f} |")
    if texture_world_rows:
        seeds_text = " / ".join(str(v) for v in TEXTURE_WORLD_SEEDS)
        lines += ["", "## Textures and HDRI worlds against Cycles (issue 24)", "",
                  "`final` against the all-bounce Cycles references of "
                  "`tests/data/make_material_refs.py` and `make_world_refs.py` (64 bounces, no "
                  "clamping, no denoiser): the worst bright 4 × 4 region's mean luminance "
                  "(regions over a tenth of the brightest) and the whole image's, per seed. "
                  "Issue 24's scenes are asserted by `tests/test_parity_textures.py` and "
                  "`tests/test_parity_world.py` at seed 1; the validation scenes shaped "
                  "nothing (below).", "",
                  f"| scene | role | bound | worst bright region, seeds {seeds_text} | "
                  "whole image | seconds per render |", "|---|---|---|---|---|---|"]
        for r in texture_world_rows:
            worst = " / ".join(f"{100 * v:.2f} %" for v in r["worst"])
            whole = " / ".join(f"{v:.4f}" for v in r["whole"])
            lines.append(f"| {r['scene']} | {r['role']} | {100 * r['bound']:.0f} % | {worst} "
                         f"| {whole} | {r['seconds']:.1f} |")
    lines += ["", "## Tuning scenes and validation scenes", "",
              "A parameter tuned on a scene is not validated by that scene.", "",
              "| scene | role | tuned on it |", "|---|---|---|"]
    for scene, (role, what) in SCENE_ROLES.items():
        lines.append(f"| {scene} | {role} | {what} |")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="lanterna bench --validation",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(REPO / "docs" / "validation.md"))
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    rows_a = analytic(max(1, args.seeds))
    rows_d = direct_parity()
    rows_g = gi_parity()
    rows_t = texture_world_parity()
    write(Path(args.out), rows_a, rows_d, rows_g, max(1, args.seeds),
          (time.perf_counter() - t0) / 60, rows_t)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
