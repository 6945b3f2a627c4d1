"""Cycles direct-light references for point and spot lights with a radius
(``tests/sphere_light_scenes.py``), used by ``tests/test_sphere_lights.py``.

Run from the repository root with the project's virtualenv (bpy 5.2.3, Cycles CPU)::

    .venv/bin/python tests/data/make_sphere_light_refs.py                # all four scenes
    .venv/bin/python tests/data/make_sphere_light_refs.py spot_sphere    # some of them

Settings: ``make_cycles_refs.configure_cycles(gi=False)``: direct light only (max bounces 0),
no denoiser, no adaptive sampling, no clamping, light threshold 0, Blackman-Harris 1.5 px,
read back through a 32-bit EXR (row 0 = top). ``SEEDS`` independent renders of ``SAMPLES``
samples each. Written to ``tests/data/cycles_sphere_lights/<scene>.npz``: ``region_mean``
(4, 4, 3) block means of the seeds' mean image, ``region_se`` (their standard error from
the seeds' block means, ddof 1), ``seed_region_means``, ``grid``, ``spp``, ``seeds``,
``blender``, ``settings`` (JSON); and ``manifest.json`` (noise and time per scene). Only
block means are stored (the test compares regions), so the files stay small.

Only bpy, numpy, OpenEXR and ``make_cycles_refs.py``'s Cycles set-up: no import of Lanterna.
"""
from __future__ import annotations

import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bpy  # noqa: E402

import make_cycles_refs as mcr  # noqa: E402
import sphere_light_scenes as sls  # noqa: E402

OUT = HERE / "cycles_sphere_lights"
GRID = (4, 4)
SEEDS = (1, 2, 3, 4)
SAMPLES = 1024


def make_reference(name: str, tmpdir: str) -> dict:
    blocks, seconds, settings = [], [], None
    for seed in SEEDS:
        scene = sls.build(name)
        settings = mcr.configure_cycles(scene, SAMPLES, seed, gi=False)
        img, dt = mcr.render_exr(scene, str(Path(tmpdir) / f"{name}_{seed}.exr"))
        blocks.append(mcr.block_means(img, GRID))
        seconds.append(dt)
        print(f"  {name} seed {seed}: {SAMPLES} spp, {dt:.1f} s", flush=True)
    seed_blocks = np.stack(blocks)
    region_mean = seed_blocks.mean(axis=0)
    region_se = seed_blocks.std(axis=0, ddof=1) / math.sqrt(len(SEEDS))
    settings = dict(settings, seeds=list(SEEDS), seed="see seeds", blender=bpy.app.version_string,
                    grid=list(GRID), scene=name, builder=f"tests/sphere_light_scenes.py:{name}")
    OUT.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT / f"{name}.npz", region_mean=region_mean, region_se=region_se,
                        seed_region_means=seed_blocks, grid=np.array(GRID), spp=SAMPLES,
                        seeds=np.array(SEEDS), blender=bpy.app.version_string,
                        settings=json.dumps(settings))
    peak = region_mean.max(axis=(0, 1))
    bright = region_mean >= 0.05 * peak
    rel = np.where(bright, region_se / np.maximum(region_mean, 1e-30), 0.0)
    return {"spp": SAMPLES, "seeds": list(SEEDS), "seconds_per_render": round(float(np.mean(seconds)), 2),
            "max_rel_se_bright_regions": float(f"{rel.max():.3g}"),
            "max_abs_se_over_peak": float(f"{(region_se / peak).max():.3g}")}


def main(argv=None):
    names = (argv if argv is not None else sys.argv[1:]) or list(sls.SCENES)
    manifest_path = OUT / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    with tempfile.TemporaryDirectory() as tmpdir:
        for name in names:
            manifest[name] = make_reference(name, tmpdir)
            print(name, manifest[name], flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
