"""Cycles all-bounce references for material parity (issue 23): ``tests/material_scenes.py``.

Run from the repository root with the project's virtualenv (bpy 5.2.3, Cycles CPU)::

    .venv/bin/python tests/data/make_material_refs.py                    # all five scenes
    .venv/bin/python tests/data/make_material_refs.py mix_floor          # some of them
    .venv/bin/python tests/data/make_material_refs.py --samples 32 --out /tmp/trial   # a trial
    (``--preview DIR`` also writes a PNG of each mean image, clipped and sRGB-encoded)
    .venv/bin/python tests/data/make_material_refs.py metal_sphere --seeds 5 6 7 8 --add-seeds
    (renders seeds 5-8 at the stored spp and merges them into the stored reference: the
    per-pixel sums come back exactly from ``image`` and ``pixel_var``)

Every scene of ``MATERIAL_SCENES`` (and of ``tests/texture_scenes.py``'s ``TEXTURE_SCENES``:
``textured_room``, ``plain_room``) is rendered by Cycles on the CPU with the settings of
``make_cycles_refs.py --gi`` (its ``configure_cycles(gi=True)``): 64 diffuse, glossy and
transmission bounces, caustics reflective and refractive on, no glossy blur, no denoiser, no
adaptive sampling, no clamping, light threshold 0, Blackman-Harris 1.5 px, path guiding off,
read back through a 32-bit EXR (row 0 = top). ``SEEDS`` (or ``SCENE_SEEDS[name]``)
independent renders of ``SAMPLES[name]`` samples each, chosen so that every bright 4 x 4
block (>= 5 % of the brightest) has a relative standard error < 0.3 % (measured: 0.004 %,
0.30 %, 0.20 %, 0.19 %, 0.26 %; tests/data/README.md). Written to ``tests/data/cycles_materials/``:

``<scene>.npz``
    ``image``             (H, W, 3) float32, the mean of the seeds, row 0 = top, W m^-2 sr^-1
    ``pixel_var``         (H, W, 3) float32, variance of ``image`` (per-pixel variance over
                          the seeds, ddof 1, divided by the number of seeds)
    ``region_mean``       (4, 4, 3) block means of ``image``
    ``region_se``         (4, 4, 3) their standard error from the spread of the seeds'
                          block means (ddof 1, / sqrt(seeds))
    ``region_se_pixels``  (4, 4, 3) the same from ``pixel_var`` (independent pixels assumed)
    ``seed_region_means`` (seeds, 4, 4, 3)
    ``grid``, ``spp``, ``seeds``, ``blender`` (version string), ``render_seconds`` (per seed)
    ``settings``          JSON: every Cycles setting, builder, resolution
    ``glass_caustic`` only: ``caustic_region`` (x0, x1, y0, y1) = ``CAUSTIC_REGION``,
    ``caustic_mean`` (RGB mean radiance inside it), ``caustic_se`` (its SE, from the seeds);
    ``image_no_caustics`` (float32, one seed of ``NO_CAUSTICS_SAMPLES``, the same settings
    with ``caustics_reflective = caustics_refractive = False``: Cycles drops every path
    that meets a glossy or refractive surface after a diffuse one, so what is left is the
    direct light, its penumbra included, and plain interreflection), ``no_caustics_spp``,
    ``caustic_region_no_caustics_mean``: the caustic proper is ``caustic_mean`` minus it
``manifest.json``: per scene the spp, seeds, seconds per render, worst relative SE.

Only bpy, numpy, OpenEXR, ``tests/material_scenes.py`` and ``make_cycles_refs.py``'s Cycles
set-up and EXR reader: no import of Lanterna.
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
import material_scenes as ms  # noqa: E402
import texture_scenes as ts  # noqa: E402

# Every scene this script renders: the material scenes (issue 23) and the texture scenes
# (issue 24, ``tests/texture_scenes.py``), name -> (builder module, builder).
SCENES = {**{n: (ms, f) for n, f in ms.MATERIAL_SCENES.items()},
          **{n: (ts, f) for n, f in ts.TEXTURE_SCENES.items()}}

OUT = HERE / "cycles_materials"
GRID = (4, 4)
SEEDS = (1, 2, 3, 4)
SAMPLES = {              # per seed: every bright block's relative SE < 0.3 % (README)
    "factory_cube": 512,
    "principled_room": 1024,
    "metal_sphere": 1536,
    "mix_floor": 1024,
    "glass_caustic": 12288,
    "textured_room": 1024,
    "plain_room": 1024,
    "textured_gallery": 2048,
}
SCENE_SEEDS = {          # where 4 seeds left a block at >= 0.3 % (the stored references)
    "metal_sphere": (1, 2, 3, 4, 5, 6, 7, 8),      # 0.33 % with 4
    "glass_caustic": (1, 2, 3, 4, 5, 6),           # 0.31 % with 4
}
NO_CAUSTICS_SAMPLES = 1024    # glass_caustic's render without caustic paths (one seed)


def _srgb_png(image: np.ndarray, path: Path, scale: float | None = None):
    """Write a preview: linear radiance scaled so the 99th percentile is 1, sRGB-encoded."""
    scale = scale or 1.0 / max(float(np.percentile(image, 99)), 1e-12)
    x = np.clip(image * scale, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    h, w = x.shape[:2]
    img = bpy.data.images.new("preview", w, h, float_buffer=False)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = x[::-1]                  # Blender's pixel rows run bottom-up
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = str(path)
    img.file_format = "PNG"
    img.alpha_mode = "NONE"
    img.save()


def _previous(path: Path, spp: int, seeds) -> dict | None:
    """What ``--add-seeds`` merges: the per-pixel sum and sum of squares over the seeds of
    the reference at ``path`` (rebuilt from its mean and ``pixel_var``), its seeds' block
    means, seeds and times; None if there is no file. Same spp, new seeds only."""
    if not path.exists():
        return None
    with np.load(path) as d:
        old = {key: d[key] for key in d.files}
    k = len(old["seeds"])
    if int(old["spp"]) != spp or set(old["seeds"].tolist()) & set(seeds):
        raise SystemExit(f"{path}: {int(old['spp'])} spp, seeds {old['seeds'].tolist()}: "
                         f"--add-seeds needs the same spp ({spp}) and new seeds ({list(seeds)})")
    mean = old["image"].astype(np.float64)
    var = old["pixel_var"].astype(np.float64) * k                 # ddof 1 over the seeds
    prev = {"k": k, "sum": k * mean, "sumsq": (k - 1) * var + k * mean ** 2,
            "seed_blocks": old["seed_region_means"], "seeds": old["seeds"].tolist(),
            "seconds": old["render_seconds"].tolist()}
    if "caustic_mean" in old:             # the seeds' caustic means: their sum, sum of squares
        cm, cv = old["caustic_mean"], old["caustic_se"] ** 2 * k
        prev["caustic"] = (k * cm, (k - 1) * cv + k * cm ** 2)
    return prev


def make_reference(name: str, tmpdir: str, out: Path, samples: int | None = None,
                   seeds=SEEDS, preview: Path | None = None, add: bool = False) -> dict:
    """Render scene ``name`` once per seed, write ``<out>/<name>.npz``, return a summary.
    ``add``: merge these seeds into the reference already there (same spp)."""
    spp = samples or SAMPLES[name]
    prev = _previous(out / f"{name}.npz", spp, seeds) if add else None
    renders, seconds, settings = [], [], None
    for seed in seeds:
        scene = SCENES[name][0].build(name)
        inside = [n for n in ms._ps.lights_out_of_frame(scene) if scene.objects[n].visible_camera]
        if inside:
            raise RuntimeError(f"{name}: visible lights inside the camera frame: {inside}")
        settings = mcr.configure_cycles(scene, spp, seed, gi=True)
        img, dt = mcr.render_exr(scene, str(Path(tmpdir) / f"{name}_{seed}.exr"))
        print(f"  {name} seed {seed}: {spp} spp, {dt:.1f} s", flush=True)
        renders.append(img)
        seconds.append(dt)
    stack = np.stack(renders)                               # (K, H, W, 3)
    seed_blocks = np.stack([mcr.block_means(r, GRID) for r in renders])
    total, total_sq = stack.sum(axis=0), (stack ** 2).sum(axis=0)
    caustic = None                        # (sum, sum of squares) of the seeds' caustic means
    if name == "glass_caustic":
        x0, x1, y0, y1 = ms.CAUSTIC_REGION
        c = stack[:, y0:y1, x0:x1].mean(axis=(1, 2))                # (K, 3)
        caustic = (c.sum(axis=0), (c ** 2).sum(axis=0))
    if prev is not None:
        total, total_sq = total + prev["sum"], total_sq + prev["sumsq"]
        seed_blocks = np.concatenate([prev["seed_blocks"], seed_blocks])
        seeds, seconds = tuple(prev["seeds"]) + tuple(seeds), prev["seconds"] + seconds
        if caustic is not None:
            caustic = (caustic[0] + prev["caustic"][0], caustic[1] + prev["caustic"][1])
    k = len(seeds)
    image = total / k
    pixel_var = np.maximum(total_sq - k * image ** 2, 0.0) / (k - 1) / k
    region_mean = mcr.block_means(image, GRID)
    region_se = seed_blocks.std(axis=0, ddof=1) / math.sqrt(k)
    h, w = image.shape[:2]
    npix = (h // GRID[0]) * (w // GRID[1])
    region_se_pixels = np.sqrt(mcr.block_means(pixel_var, GRID)) / math.sqrt(npix)
    settings = dict(settings, seeds=list(seeds), seed="see seeds", blender=bpy.app.version_string,
                    render_seconds=[round(s, 2) for s in seconds], grid=list(GRID), scene=name,
                    builder=f"tests/{SCENES[name][0].__name__}.py:{SCENES[name][1].__name__}")
    extra = {}
    if caustic is not None:
        x0, x1, y0, y1 = ms.CAUSTIC_REGION
        if x1 > x0 and y1 > y0:
            c_mean = caustic[0] / k
            c_se = np.sqrt(np.maximum(caustic[1] - k * c_mean ** 2, 0.0) / (k - 1) / k)
            scene = ms.build(name)
            nc = mcr.configure_cycles(scene, NO_CAUSTICS_SAMPLES, seeds[0], gi=True)
            scene.cycles.caustics_reflective = scene.cycles.caustics_refractive = False
            img_nc, dt = mcr.render_exr(scene, str(Path(tmpdir) / f"{name}_nc.exr"))
            print(f"  {name} without caustics: {NO_CAUSTICS_SAMPLES} spp, {dt:.1f} s", flush=True)
            extra = dict(caustic_region=np.array(ms.CAUSTIC_REGION),
                         caustic_mean=c_mean, caustic_se=c_se,
                         image_no_caustics=img_nc.astype(np.float32),
                         no_caustics_spp=NO_CAUSTICS_SAMPLES,
                         caustic_region_no_caustics_mean=img_nc[y0:y1, x0:x1].mean(axis=(0, 1)))
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out / f"{name}.npz", image=image.astype(np.float32), pixel_var=pixel_var.astype(np.float32),
        region_mean=region_mean, region_se=region_se, region_se_pixels=region_se_pixels,
        seed_region_means=seed_blocks, grid=np.array(GRID), spp=spp, seeds=np.array(seeds),
        blender=bpy.app.version_string, render_seconds=np.array(seconds),
        settings=json.dumps(settings), **extra)
    if preview is not None:
        preview.mkdir(parents=True, exist_ok=True)
        _srgb_png(image, preview / f"{name}.png")
    peak = float(region_mean.max())
    bright = region_mean >= 0.05 * peak
    rel = np.where(bright, region_se / np.maximum(region_mean, 1e-30), 0.0)
    rel_pix = np.where(bright, region_se_pixels / np.maximum(region_mean, 1e-30), 0.0)
    summary = {
        "samples_per_seed": spp, "seeds": list(seeds), "resolution": [w, h],
        "seconds_per_render": round(float(np.mean(seconds)), 2),
        "brightest_region_mean": round(peak, 5),
        "max_rel_se_bright_regions": float(f"{rel.max():.3g}"),
        "median_rel_se_bright_regions": float(f"{np.median(rel[bright]):.3g}"),
        "max_rel_se_pixels_estimate": float(f"{rel_pix.max():.3g}"),
        "max_abs_se_dark_regions_over_peak": float(
            f"{(np.where(bright, 0, np.maximum(region_se, region_se_pixels)).max() / peak):.3g}"),
    }
    if extra:
        summary["caustic_region"] = list(ms.CAUSTIC_REGION)
        summary["caustic_mean"] = [round(float(v), 5) for v in extra["caustic_mean"]]
        c_rel = (extra["caustic_se"] / extra["caustic_mean"]).max()
        summary["caustic_rel_se"] = float(f"{c_rel:.3g}")
        summary["caustic_region_no_caustics_mean"] = [
            round(float(v), 5) for v in extra["caustic_region_no_caustics_mean"]]
    print(f"{name:16s} {spp:5d} spp x {k}, {summary['seconds_per_render']:.1f} s/render, "
          f"rel SE max "
          f"{summary['max_rel_se_bright_regions']:.2e} (pixel est. "
          f"{summary['max_rel_se_pixels_estimate']:.2e})", flush=True)
    np.set_printoptions(precision=4, suppress=True, linewidth=120)
    print("  region means, luminance-ish (mean of RGB), row 0 = top:")
    print(region_mean.mean(axis=2))
    if extra:
        print(f"  caustic {ms.CAUSTIC_REGION}: mean {extra['caustic_mean']}, "
              f"rel SE {summary['caustic_rel_se']:.2e}; without caustic paths "
              f"{extra['caustic_region_no_caustics_mean']}")
    return summary


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", nargs="*", help=f"of {list(SCENES)}")
    parser.add_argument("--samples", type=int, help="samples per seed (trials)")
    parser.add_argument("--seeds", type=int, nargs="+",
                        help="seeds (default: SCENE_SEEDS or SEEDS)")
    parser.add_argument("--out", type=Path, default=OUT, help="output folder")
    parser.add_argument("--preview", type=Path, help="write PNG previews there")
    parser.add_argument("--add-seeds", action="store_true",
                        help="merge the renders of --seeds into the references already there")
    args = parser.parse_args()
    names = args.scenes or list(SCENES)
    unknown = [n for n in names if n not in SCENES]
    if unknown:
        parser.error(f"unknown scenes {unknown}; known: {list(SCENES)}")
    args.out.mkdir(parents=True, exist_ok=True)
    manifest_path = args.out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    with tempfile.TemporaryDirectory() as tmpdir:
        for name in names:
            seeds = tuple(args.seeds) if args.seeds else SCENE_SEEDS.get(name, SEEDS)
            manifest[name] = make_reference(name, tmpdir, args.out, args.samples, seeds,
                                            args.preview, args.add_seeds)
            manifest["_meta"] = {
                "blender": bpy.app.version_string, "grid": list(GRID),
                "bounces": mcr.GI_BOUNCES, "made_by": "tests/data/make_material_refs.py"}
            manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
