"""The textured floor's sharpness against a plain one (issue 24): blur or noise?

What it computes (``lanterna bench --sharpness``)
    ``tests/texture_scenes.py``'s ``textured_room`` (an image checker on the Principled floor)
    and ``plain_room`` (the same floor at the image's mean colour), each rendered at ``final``
    for seeds 1..``--seeds`` (default 3) and compared with its stored Cycles reference
    (``tests/data/cycles_materials``) on the floor rows of ``tests/test_parity_textures.py``
    (``FLOOR_ROWS``), in luminance:

    ``rel-RMSE``      sqrt(mean((ours - Cycles)^2)) / sqrt(mean(Cycles^2)) per seed: the
                      issue's figure (its test renders seed 1);
    ``mean image``    the same figure for the mean of the seeds' images: what is left when
                      the noise is averaged down (blur or bias stays; noise falls as
                      1 / sqrt(seeds));
    ``pixel noise``   RMS over the floor pixels of (seed 1 - seed 2) / (sqrt 2 x Cycles): the
                      per-pixel relative noise, also split into the pixels at texture edges
                      (contrast to a 4-neighbour above the floor's median) and the others.

    A texture blurred by the irradiance cache or the photon map would show in ``mean image``
    (and at the edges); noise shows in ``pixel noise``. About 2 min for 3 seeds on 2 cores.

A benchmark, not a test: it asserts nothing and writes nothing. Expected failures print one
``lanterna bench: error: ...`` line and exit with status 2.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from .materials import material_scenes_module
from .vs_cycles import REPO, BenchError

PROG = "lanterna bench --sharpness"
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
SCENES = ("textured_room", "plain_room")


def render_floor(name: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(Lanterna's final, Cycles' reference) luminance images (H, W) of scene ``name``."""
    import bpy

    from ..engine.blender.export import export_scene
    from ..engine.pipeline import RenderSettings, render

    scenes = material_scenes_module("texture_scenes")
    ref_path = REPO / "tests" / "data" / "cycles_materials" / f"{name}.npz"
    if not ref_path.exists():
        raise BenchError(f"no reference {ref_path} (tests/data/make_material_refs.py)")
    scenes.build(name)
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    image = np.asarray(render(scene, RenderSettings(seed=seed, preset="final")).image,
                       np.float64)
    ref = np.load(ref_path)["image"].astype(np.float64)
    return image @ LUMINANCE, ref @ LUMINANCE


def rel_rmse(ours: np.ndarray, theirs: np.ndarray) -> float:
    return float(np.sqrt(np.mean((ours - theirs) ** 2)) / np.sqrt(np.mean(theirs ** 2)))


def floor_figures(name: str, seeds: int, rows: slice) -> dict:
    """The module docstring's figures for scene ``name``."""
    images, ref = [], None
    for seed in range(1, seeds + 1):
        image, ref = render_floor(name, seed)
        images.append(image[rows])
        print(f"  {name} seed {seed}: rel-RMSE {100 * rel_rmse(images[-1], ref[rows]):.2f} %",
              flush=True)
    theirs = ref[rows]
    padded = np.pad(ref, 1, mode="edge")
    neighbours = np.stack([padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2],
                           padded[1:-1, 2:]])
    contrast = (np.abs(neighbours - ref[None]).max(axis=0) / np.maximum(ref, 1e-30))[rows]
    edge = contrast > np.median(contrast)
    figures = dict(per_seed=[rel_rmse(i, theirs) for i in images],
                   mean_image=rel_rmse(np.mean(images, axis=0), theirs))
    if seeds >= 2:
        noise = (images[0] - images[1]) / (np.sqrt(2.0) * np.maximum(theirs, 1e-30))
        figures.update(noise=float(np.sqrt(np.mean(noise ** 2))),
                       noise_edge=float(np.sqrt(np.mean(noise[edge] ** 2))),
                       noise_inside=float(np.sqrt(np.mean(noise[~edge] ** 2))))
    return figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        if args.seeds < 1:
            raise BenchError("--seeds must be at least 1")
        rows = material_scenes_module("test_parity_textures").FLOOR_ROWS
        print(f"{PROG} --seeds {args.seeds}: floor rows {rows.start}-{rows.stop - 1}", flush=True)
        for name in SCENES:
            f = floor_figures(name, args.seeds, rows)
            line = (f"{name}: rel-RMSE per seed "
                    + " / ".join(f"{100 * v:.2f}" for v in f["per_seed"])
                    + f" % (mean {100 * np.mean(f['per_seed']):.2f} %); mean image "
                    f"{100 * f['mean_image']:.2f} %")
            if "noise" in f:
                line += (f"; pixel noise {100 * f['noise']:.2f} % (edges "
                         f"{100 * f['noise_edge']:.2f} %, inside {100 * f['noise_inside']:.2f} %)")
            print(line, flush=True)
    except BenchError as exc:
        print(f"lanterna bench: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
