"""Cycles' directional albedo of the Principled BSDF, measured by rendering (issue 23).

Run from the repository root with the project's virtualenv (bpy 5.2.3, Cycles CPU)::

    .venv/bin/python tests/data/make_principled_albedo.py                  # the table
    .venv/bin/python tests/data/make_principled_albedo.py --samples 64 --out /tmp/a.json  # a trial
    (``--preview PNG`` writes the rendered mosaic, ``--exr-dir DIR`` keeps the EXRs)

Method. A surface lit by a uniform environment of radiance 1 and nothing else reflects, towards
the viewer, exactly its directional albedo for that view direction:
L_o(w_o) = integral f(w_i, w_o) cos(theta_i) dw_i = a(w_o) (Helmholtz reciprocity makes the
"albedo for light arriving from w_o" the same number). So: a World of colour (1, 1, 1),
strength 1; a flat quad ("tile") per (material, view angle) seen by an orthographic camera
looking straight down -z, each tile turned about its x axis by theta so that the camera sees
it at cos(theta) = ``COS_VIEW`` (1, 0.7, 0.5, 0.2), and stretched by 1/cos(theta) along the
turned side so that every tile covers the same ``TILE`` x ``TILE`` pixels. The tiles are
invisible to every ray but the camera's (``visible_diffuse = visible_glossy =
visible_transmission = visible_shadow = visible_volume_scatter = False``), so the light
reflected by a tile comes from the world only: no tile shadows or lights another. A flat tile
cannot see itself. The albedo of a tile is the mean of its inner pixels (``MARGIN`` px away
from its edges, clear of the 1.5 px Blackman-Harris filter that mixes in the white world
between tiles). The pixel filter, the sub-pixel jitter and the orthographic rays leave the
view direction exactly constant over a tile.

Materials: ``POINTS``, one row of tiles each: a Principled BSDF at Blender's defaults (Specular
IOR Level 0.5, coat roughness 0.03, coat IOR 1.5, Diffuse Roughness 0, ...) except Base Color
(white (1, 1, 1) unless given), Roughness, IOR, Metallic, Coat Weight and what a point names.
The white points come out at ~1 (Cycles' layers are energy-conserving, so a white base takes
what the specular layer leaves); black, grey, orange and copper points measure the layers
themselves. Cycles settings: those of ``make_cycles_refs.py --gi`` (all bounces, no clamp, no
denoiser, no adaptive sampling, light threshold 0, path guiding off), ``SAMPLES`` per seed,
``SEEDS`` independent renders; the standard error of a tile's mean comes from the spread of the
seeds' tile means (ddof 1) and, as a cross-check, from the per-pixel variance.

Measured (stored table): 4 seeds x 256 spp, 44 s a render on 2 busy cores, largest relative
SE 0.035 %; the gaps between tiles read the world at 1.000000; a black base at roughness 0
gives the exact Fresnel reflectance of IOR 1.5 (0.0400, 0.0509, 0.0892, 0.3389 at cos 1, 0.7,
0.5, 0.2), a check of the set-up.

Output ``tests/data/cycles_principled_albedo.json``::

    {"blender": ..., "samples_per_seed": ..., "seeds": [...], "cos_view": [...],
     "pixels_per_tile": ..., "render_seconds": [...], "method": ...,
     "points": [{"name": ..., "inputs": {socket: value, ...},
                 "albedo": [[R, G, B] per cos_view], "se": [[R, G, B] per cos_view],
                 "se_pixels": [[...]]}, ...]}

Only bpy, numpy, OpenEXR and ``make_cycles_refs.py``'s Cycles set-up and EXR reader: no
import of Lanterna.
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
import parity_scenes as ps  # noqa: E402

OUT = HERE / "cycles_principled_albedo.json"
COS_VIEW = (1.0, 0.7, 0.5, 0.2)
TILE, GAP, MARGIN = 24, 4, 3        # pixels: tile side, white gap between tiles, unused rim
PIXEL = 0.01                        # metres per pixel (orthographic)
SEEDS = (1, 2, 3, 4)
SAMPLES = 256                       # per seed
WHITE = (1.0, 1.0, 1.0)
COPPER = (0.955, 0.638, 0.538)      # tests/material_scenes.py COPPER

# name -> Principled inputs other than the defaults (Base Color white unless given)
POINTS = {
    "r0.0": {"Roughness": 0.0},
    "r0.1": {"Roughness": 0.1},
    "r0.3": {"Roughness": 0.3},
    "r0.5 (defaults)": {"Roughness": 0.5},
    "r0.8": {"Roughness": 0.8},
    "r1.0": {"Roughness": 1.0},
    "r0.5 ior1.1": {"Roughness": 0.5, "IOR": 1.1},
    "r0.5 ior1.33": {"Roughness": 0.5, "IOR": 1.33},
    "r0.5 ior2.0": {"Roughness": 0.5, "IOR": 2.0},
    "r0.2 ior2.5": {"Roughness": 0.2, "IOR": 2.5},
    "metal r0.1": {"Roughness": 0.1, "Metallic": 1.0},
    "metal r0.5": {"Roughness": 0.5, "Metallic": 1.0},
    "metal r1.0": {"Roughness": 1.0, "Metallic": 1.0},
    "metallic0.5 r0.3": {"Roughness": 0.3, "Metallic": 0.5},
    "coat1 r0.5": {"Roughness": 0.5, "Coat Weight": 1.0},
    "coat0.5 r0.5": {"Roughness": 0.5, "Coat Weight": 0.5},
    "coat1 r0.8 coatr0.3": {"Roughness": 0.8, "Coat Weight": 1.0, "Coat Roughness": 0.3},
    "coat1 metal r0.2": {"Roughness": 0.2, "Metallic": 1.0, "Coat Weight": 1.0},
    "orange r0.4": {"Base Color": (0.8, 0.3, 0.1), "Roughness": 0.4},
    "copper r0.3": {"Base Color": COPPER, "Roughness": 0.3, "Metallic": 1.0},
    # A white base makes Cycles' Principled reflect ~all of the light whatever the rest (its
    # layers are energy-conserving): a black base leaves the dielectric specular layer alone,
    # a grey or coloured one weighs the layers against each other.
    "black r0.0": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.0},
    "black r0.1": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.1},
    "black r0.3": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.3},
    "black r0.5": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.5},
    "black r1.0": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 1.0},
    "black r0.5 ior1.33": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.5, "IOR": 1.33},
    "black r0.3 ior2.5": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.3, "IOR": 2.5},
    "black coat1 r0.5": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.5, "Coat Weight": 1.0},
    "black coat1 r0.5 coatr0.3": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.5,
                                  "Coat Weight": 1.0, "Coat Roughness": 0.3},
    "grey0.5 r0.5": {"Base Color": (0.5, 0.5, 0.5), "Roughness": 0.5},
    "grey0.5 r0.5 spec0": {"Base Color": (0.5, 0.5, 0.5), "Roughness": 0.5,
                           "Specular IOR Level": 0.0},
    "orange coat1 r0.3": {"Base Color": (0.8, 0.3, 0.1), "Roughness": 0.3, "Coat Weight": 1.0},
    "orange metallic0.5 r0.5": {"Base Color": (0.8, 0.3, 0.1), "Roughness": 0.5,
                                "Metallic": 0.5},
    "copper r0.3 coat1": {"Base Color": COPPER, "Roughness": 0.3, "Metallic": 1.0,
                          "Coat Weight": 1.0},
    # Issue 23, part 2: coat tint, sheen and thin film.
    "orange coat1 tint": {"Base Color": (0.8, 0.3, 0.1), "Roughness": 0.3, "Coat Weight": 1.0,
                          "Coat Tint": (0.9, 0.5, 0.3)},
    "black sheen1 sr0.5": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.5, "Sheen Weight": 1.0},
    "orange sheen1 sr0.3": {"Base Color": (0.8, 0.3, 0.1), "Roughness": 0.5, "Sheen Weight": 1.0,
                            "Sheen Roughness": 0.3},
    "grey sheen0.5 tint coat": {"Base Color": (0.5, 0.5, 0.5), "Roughness": 0.5,
                                "Sheen Weight": 0.5, "Sheen Tint": (0.2, 0.6, 1.0),
                                "Sheen Roughness": 0.8, "Coat Weight": 1.0},
    "black film500": {"Base Color": (0.0, 0.0, 0.0), "Roughness": 0.2,
                      "Thin Film Thickness": 500.0, "Thin Film IOR": 1.33},
    "grey film300 ior1.8": {"Base Color": (0.5, 0.5, 0.5), "Roughness": 0.4,
                            "Thin Film Thickness": 300.0, "Thin Film IOR": 1.8},
    "copper film250": {"Base Color": COPPER, "Roughness": 0.3, "Metallic": 1.0,
                       "Thin Film Thickness": 250.0, "Thin Film IOR": 1.5},
}


def _material(name: str, inputs: dict):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    values = {"Base Color": WHITE, **inputs}
    for socket, value in values.items():
        value = tuple(value) if isinstance(value, list) else value
        bsdf.inputs[socket].default_value = (*value, 1.0) if isinstance(value, tuple) else value
    return mat


def build():
    """The mosaic scene: one row of tiles per point of ``POINTS``, one column per
    ``COS_VIEW``. Returns (scene, {(row, col): (y0, y1, x0, x1) inner pixel bounds})."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")
    ps._set_world(scene.world, 1.0)               # uniform radiance 1
    rows, cols = len(POINTS), len(COS_VIEW)
    w, h = cols * (TILE + GAP) + GAP, rows * (TILE + GAP) + GAP
    scene.render.resolution_x, scene.render.resolution_y = w, h
    scene.render.resolution_percentage = 100
    cam_data = bpy.data.cameras.new("Ortho")
    cam_data.type = "ORTHO"
    cam_data.sensor_fit = "AUTO"
    cam_data.ortho_scale = max(w, h) * PIXEL     # spans the longer side
    cam_data.clip_start, cam_data.clip_end = 0.1, 100.0
    cam = bpy.data.objects.new("Ortho", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.0, 0.0, 10.0)               # looking down -z, image up = +y
    scene.camera = cam
    half = TILE * PIXEL / 2
    bounds = {}
    for i, (name, inputs) in enumerate(POINTS.items()):
        mat = _material(name, inputs)
        y0 = GAP + i * (TILE + GAP)                           # pixel rows, row 0 = top
        cy = (h / 2 - (y0 + TILE / 2)) * PIXEL
        for j, cos_v in enumerate(COS_VIEW):
            x0 = GAP + j * (TILE + GAP)
            cx = (x0 + TILE / 2 - w / 2) * PIXEL
            hy = half / cos_v                                 # projects back to ``half``
            obj = ps._mesh_object(f"{name} cos{cos_v}",
                                  [(-half, -hy, 0), (half, -hy, 0), (half, hy, 0), (-half, hy, 0)],
                                  [(0, 1, 2, 3)], mat)        # normal +z, towards the camera
            obj.rotation_euler = (math.acos(cos_v), 0.0, 0.0)
            obj.location = (cx, cy, 0.0)
            for ray in ("diffuse", "glossy", "transmission", "shadow", "volume_scatter"):
                setattr(obj, f"visible_{ray}", False)
            bounds[(i, j)] = (y0 + MARGIN, y0 + TILE - MARGIN, x0 + MARGIN, x0 + TILE - MARGIN)
    bpy.context.view_layer.update()
    return scene, bounds


def _preview(image: np.ndarray, path: Path):
    x = np.clip(image, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    h, w = x.shape[:2]
    img = bpy.data.images.new("preview", w, h, float_buffer=False)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = x[::-1]
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = str(path)
    img.file_format = "PNG"
    img.save()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=SAMPLES, help="samples per seed")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS))
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--preview", type=Path, help="PNG of the mean mosaic (clipped at 1)")
    args = parser.parse_args()
    renders, seconds, settings, bounds = [], [], None, None
    with tempfile.TemporaryDirectory() as tmpdir:
        for seed in args.seeds:
            scene, bounds = build()
            settings = mcr.configure_cycles(scene, args.samples, seed, gi=True)
            img, dt = mcr.render_exr(scene, str(Path(tmpdir) / f"albedo_{seed}.exr"))
            print(f"  seed {seed}: {args.samples} spp, {dt:.1f} s", flush=True)
            renders.append(img)
            seconds.append(dt)
    stack = np.stack(renders)                                 # (K, H, W, 3)
    k = len(renders)
    if args.preview:
        _preview(stack.mean(axis=0), args.preview)
    # the gaps show the world: a check of its radiance and of the read-back
    gap = stack[:, :GAP - 2, :, :].mean()
    points, worst = [], 0.0
    for i, (name, inputs) in enumerate(POINTS.items()):
        alb, se, se_pix = [], [], []
        for j in range(len(COS_VIEW)):
            y0, y1, x0, x1 = bounds[(i, j)]
            tile = stack[:, y0:y1, x0:x1]                     # (K, n, n, 3)
            per_seed = tile.mean(axis=(1, 2))                 # (K, 3)
            mean = per_seed.mean(axis=0)
            s = per_seed.std(axis=0, ddof=1) / math.sqrt(k)
            npix = tile.shape[1] * tile.shape[2]
            s_pix = np.sqrt(tile.var(axis=0, ddof=1).mean(axis=(0, 1)) / k / npix)
            alb.append([round(float(v), 6) for v in mean])
            se.append([float(f"{v:.3g}") for v in s])
            se_pix.append([float(f"{v:.3g}") for v in s_pix])
            worst = max(worst, float((np.maximum(s, s_pix) / mean).max()))
        inputs_out = {"Base Color": list(WHITE), **{
            key: list(v) if isinstance(v, tuple) else v for key, v in inputs.items()}}
        points.append({"name": name, "inputs": inputs_out, "albedo": alb, "se": se,
                       "se_pixels": se_pix})
        print(f"{name:22s} " + "  ".join(
            f"{c:.1f}: {a[0]:.4f} {a[1]:.4f} {a[2]:.4f}" for c, a in zip(COS_VIEW, alb)),
            flush=True)
    table = {
        "blender": bpy.app.version_string, "samples_per_seed": args.samples, "seeds": args.seeds,
        "cos_view": list(COS_VIEW), "pixels_per_tile": (TILE - 2 * MARGIN) ** 2,
        "render_seconds": [round(s, 2) for s in seconds],
        "max_rel_se": float(f"{worst:.3g}"), "world_radiance_seen": round(float(gap), 6),
        "settings": settings,
        "method": ("flat Principled tiles seen by an orthographic camera at fixed cos(theta), "
                   "lit only by a uniform white world of radiance 1, invisible to all but "
                   "camera rays; albedo = mean radiance of a tile's inner pixels; "
                   "tests/data/make_principled_albedo.py"),
        "points": points,
    }
    args.out.write_text(json.dumps(table, indent=1) + "\n")
    print(f"max relative SE {worst:.2e}; world seen in the gaps {gap:.6f}; "
          f"{np.mean(seconds):.1f} s per render; -> {args.out}")


if __name__ == "__main__":
    main()
