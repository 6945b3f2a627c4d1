"""Cycles references for the HDRI-world parity (issue 24): ``tests/world_scenes.py``.

Run from the repository root with the project's virtualenv (bpy 5.2.3, Cycles CPU)::

    .venv/bin/python tests/data/make_world_refs.py                 # both scenes
    .venv/bin/python tests/data/make_world_refs.py yard --samples 64 --seeds 1 --out /tmp/x

Writes ``tests/data/cycles_world/sky.exr`` (the synthetic HDRI, ``world_scenes.make_hdri``)
when it is missing, then renders each scene with ``make_cycles_refs.configure_cycles(gi=True)``
(64 bounces, no clamping, no denoiser, no adaptive sampling, Blackman-Harris 1.5 px), one
render per seed, and stores ``<scene>.npz`` in ``tests/data/cycles_world/`` with the keys of
``make_material_refs.py`` (``image``, ``pixel_var``, ``region_mean``, ``region_se``,
``seed_region_means``, ``grid``, ``spp``, ``seeds``, ``render_seconds``, ``settings``).
Only bpy, numpy, OpenEXR and the test scene builders: no import of Lanterna.
"""
from __future__ import annotations

import argparse
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
import world_scenes as ws  # noqa: E402

OUT = HERE / "cycles_world"
GRID = (4, 4)
SEEDS = (1, 2, 3, 4)
SAMPLES = {"yard": 512, "window_room": 2048, "yard_320": 1024, "court": 512}


def make_reference(name, tmpdir, out, samples=None, seeds=SEEDS):
    spp = samples or SAMPLES[name]
    renders, seconds, settings = [], [], None
    for seed in seeds:
        scene = ws.build(name)
        settings = mcr.configure_cycles(scene, spp, seed, gi=True)
        img, dt = mcr.render_exr(scene, str(Path(tmpdir) / f"{name}_{seed}.exr"))
        print(f"  {name} seed {seed}: {spp} spp, {dt:.1f} s", flush=True)
        renders.append(img)
        seconds.append(dt)
    stack = np.stack(renders)
    k = len(seeds)
    image = stack.mean(axis=0)
    pixel_var = stack.var(axis=0, ddof=1) / k if k > 1 else np.zeros_like(image)
    seed_blocks = np.stack([mcr.block_means(r, GRID) for r in renders])
    region_mean = mcr.block_means(image, GRID)
    region_se = seed_blocks.std(axis=0, ddof=1) / math.sqrt(k) if k > 1 else 0 * region_mean
    settings = dict(settings, seeds=list(seeds), blender=bpy.app.version_string, grid=list(GRID),
                    scene=name, builder=f"tests/world_scenes.py:{name}",
                    render_seconds=[round(s, 2) for s in seconds])
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / f"{name}.npz", image=image.astype(np.float32),
                        pixel_var=pixel_var.astype(np.float32), region_mean=region_mean,
                        region_se=region_se, seed_region_means=seed_blocks, grid=np.array(GRID),
                        spp=spp, seeds=np.array(seeds), render_seconds=np.array(seconds),
                        settings=json.dumps(settings, default=str))
    lum = region_mean @ np.array([0.2126, 0.7152, 0.0722])
    se = region_se @ np.array([0.2126, 0.7152, 0.0722])
    bright = lum > 0.1 * lum.max()
    rel = float((se[bright] / lum[bright]).max()) if k > 1 else float("nan")
    print(f"{name}: worst bright-region relative SE {rel:.4%}, {np.mean(seconds):.1f} s/seed")
    return {"samples_per_seed": spp, "seeds": list(seeds), "max_rel_se_bright_regions": rel,
            "seconds_per_render": round(float(np.mean(seconds)), 2)}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scenes", nargs="*", default=list(ws.WORLD_SCENES))
    p.add_argument("--samples", type=int)
    p.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS))
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    if not ws.HDRI_PATH.exists():
        ws.write_hdri()
    manifest_path = args.out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            manifest[name] = make_reference(name, tmp, args.out, args.samples, tuple(args.seeds))
    args.out.mkdir(parents=True, exist_ok=True)
    manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
