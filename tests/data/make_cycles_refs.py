"""Cycles reference data for direct-light and all-bounce (GI) parity; measured Cycles conventions.

Run from the repository root with the project's virtualenv (bpy 5.0.1, Cycles CPU)::

    .venv/bin/python tests/data/make_cycles_refs.py                 # all references
    .venv/bin/python tests/data/make_cycles_refs.py point spot      # some of them
    .venv/bin/python tests/data/make_cycles_refs.py --conventions   # the conventions table
    .venv/bin/python tests/data/make_cycles_refs.py --gi            # all-bounce references
    .venv/bin/python tests/data/make_cycles_refs.py --gi cornell    # one of them
    (``--samples N`` overrides the samples per seed, for trials)

References: every scene of ``tests/parity_scenes.py`` is rendered by Cycles on the CPU with
direct light only (``max_bounces = 0``: measured to leave an indirectly lit wall at exactly 0
while direct light from every light type matches the analytic formulas), no denoiser, no
adaptive sampling, no clamping, light threshold 0, default pixel filter (Blackman-Harris,
1.5 px), ``SEEDS`` independent renders of ``SAMPLES[name]`` samples each. The float render
result is written by Blender as a 32-bit EXR (linear scene radiance: the view transform is
not applied to EXR; checked in ``--conventions``) and read back with OpenEXR (row 0 = top
of the image). Written to ``tests/data/cycles_direct/``:

``<scene>.npz``
    ``image``            (H, W, 3) float32, the mean of the seeds, row 0 = top, W m^-2 sr^-1
    ``region_mean``      (GY, GX, 3) float64, block means of ``image`` (row 0 = top blocks)
    ``region_se``        (GY, GX, 3) standard error of ``region_mean``, from the spread of
                         the per-seed block means (ddof 1, divided by sqrt(SEEDS))
    ``region_se_pixels`` (GY, GX, 3) the same from the per-pixel variance over seeds
                         (assumes independent pixels; a cross-check)
    ``seed_region_means`` (SEEDS, GY, GX, 3) the block means of each seed's render
    ``grid``             (GY, GX) blocks; block (i, j) covers rows i*H/GY..(i+1)*H/GY
    ``settings``         JSON string: every Cycles setting used, seeds, time, Blender version
``manifest.json``
    per scene: settings, render time, brightest block mean, worst relative SE.
``conventions.json``
    the measured Cycles conventions (``--conventions``), see ``tests/data/README.md``.

The camera scene ``bokeh`` (``parity_scenes.CAMERA_SCENES``: emitters in frame on purpose) is
made the same way and also stores ``seed_moments`` (JSON: per seed, per emitter,
``parity_scenes.bokeh_moments``).

Global illumination (``--gi``): the same, with all bounces, into ``tests/data/cycles_gi/``
(``<scene>.npz`` with the same fields and ``manifest.json``, which adds each scene's
resolution and builder). Scenes ``GI_SCENES``: ``scene1``, the seed's Scene 1
(``lanterna.engine.blender.seed_scenes.build("scene1")``: closed box, radius-0 point light,
Diffuse BSDF, black world) rendered at 160 x 120 with its own camera; ``cornell``,
``tests/parity_scenes.py:build_cornell`` (80 x 60, square area light hidden from the camera);
``scene2``, the seed's Scene 2 (``seed_scenes.build("scene2")``: closed room, radius-0 point
light inside a ceiling tube, torus knot, red cylinder, Diffuse BSDF, black world) at 160 x 120
with its own camera; ``cornell_mm``, ``tests/parity_scenes.py:build_cornell_original`` (the
original Cornell box in millimetres, 64 x 64, its light quad an Emission mesh in view).
Settings as above except ``max_bounces = diffuse_bounces = glossy_bounces =
transmission_bounces = GI_BOUNCES`` (64), volume 0, transparent 8, caustics reflective and
refractive on, ``blur_glossy = 0``, path guiding off; ``GI_SAMPLES[name]`` samples per seed,
chosen so that every bright block's relative SE is < 0.3 % (measured 0.16 %, 0.11 % and
0.077 %) for ``scene1``, ``cornell`` and ``cornell_mm``; ``scene2`` (lit almost only indirectly, from the light pool and the
tube's inside) is far noisier and got what fits in ~8 min (see ``tests/data/README.md``).
Lights inside the frame are allowed only if Cycles does not draw them (radius-0 point/spot
lights, ``visible_camera = False``), and emissive meshes, which both renderers draw.

The core of Lanterna is not imported: only bpy, numpy, OpenEXR and ``tests/parity_scenes``
(and, for ``--gi scene1`` / ``scene2``, Lanterna's bpy scene builder
``engine/blender/seed_scenes.py``).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "cycles_direct"
sys.path.insert(0, str(HERE.parent))

import bpy  # noqa: E402
import OpenEXR  # noqa: E402

import parity_scenes  # noqa: E402

GRID = (4, 4)        # (rows, columns) of blocks: 12 x 16 pixels each at 64 x 48
SEEDS = (1, 2, 3, 4)
DEFAULT_SAMPLES = 1024
SAMPLES = {          # per seed; every bright block's relative SE comes out < 0.1 %
    "world": 4096,
    "bokeh": 4096,   # its moments' seed-to-seed spread: 0.3 % at 1024
}

# --gi: all bounces, written to cycles_gi/
OUT_GI = HERE / "cycles_gi"
GI_BOUNCES = 64
GI_SCENES = ("scene1", "cornell", "scene2", "cornell_mm")
GI_SAMPLES = {       # per seed; every bright block's relative SE comes out < 0.3 %
    "scene1": 768,
    "cornell": 2560,
    "scene2": 2048,    # at 4x the resolution (GI_SUPERSAMPLE): see below and the README
    "cornell_mm": 4096,
}
GI_RESOLUTION = {"scene1": (160, 120), "scene2": (160, 120)}   # others: the builder's own
# Scene 2 is lit almost only by bounced light and Cycles converges slowly on it: it is
# rendered at 4 x 4 times the pixels (640 x 480) and box-averaged down to 160 x 120, so each
# stored pixel holds 16 x 2048 samples per seed. Two seeds (the benchmark's 640 x 480
# reference seeds, so `lanterna bench --vs-cycles --resolution 640x480` and this reference
# share the renders: ``--reuse-dir``); with 2 seeds the blocks' SE comes from the per-pixel
# variance (``region_se_pixels``), not from the spread of 2 block means.
GI_SUPERSAMPLE = {"scene2": 4}
GI_SEEDS = {"scene2": (201, 202)}
SEED_SCENES = ("scene1", "scene2")   # built by Lanterna's engine/blender/seed_scenes.py


def _build_gi(name: str):
    """(scene, builder label) of GI scene ``name``: the seed's Scene 1 or 2 (Lanterna's own
    builder, imported here only: bpy scene code, not the renderer) or a GI scene of
    ``tests/parity_scenes.py``, at ``GI_RESOLUTION`` where given."""
    if name in SEED_SCENES:
        from lanterna.engine.blender import seed_scenes
        scene = seed_scenes.build(name)
        label = f"engine/blender/seed_scenes.py:build_{name}"
    else:
        scene = parity_scenes.build(name)
        label = f"tests/parity_scenes.py:{parity_scenes.GI_SCENES[name].__name__}"
    if name in GI_RESOLUTION:
        scene.render.resolution_x, scene.render.resolution_y = GI_RESOLUTION[name]
        scene.render.resolution_percentage = 100
        label += " at {}x{}".format(*GI_RESOLUTION[name])
    bpy.context.view_layer.update()
    # Lights Cycles does not draw may sit in the frame: radius-0 point/spot lights and lights
    # hidden from the camera; and emissive meshes, which both renderers draw (``cornell_mm``'s
    # ceiling quad is in view on purpose).
    inside = [n for n in parity_scenes.lights_out_of_frame(scene)
              if scene.objects[n].visible_camera and scene.objects[n].type != "MESH"
              and not (scene.objects[n].type == "LIGHT" and scene.objects[n].data.type in
                       ("POINT", "SPOT") and scene.objects[n].data.shadow_soft_size == 0.0)]
    if inside:
        raise RuntimeError(f"{name}: visible lights inside the camera frame: {inside}")
    return scene, label


# --- Cycles set-up and reading the render ---------------------------------------------------
def configure_cycles(scene, samples: int, seed: int, gi: bool = False) -> dict:
    """Direct light only (``gi`` False) or all bounces (``gi`` True: ``GI_BOUNCES`` diffuse,
    glossy and transmission bounces, caustics on, no glossy blur), unbiased, deterministic.
    Returns the settings as a dict."""
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = samples
    c.seed = seed
    c.use_animated_seed = False
    c.max_bounces = 0                 # direct light only (camera hit + light / BSDF-hit emission)
    c.diffuse_bounces = 0
    c.glossy_bounces = 0
    c.transmission_bounces = 0
    c.volume_bounces = 0
    c.transparent_max_bounces = 8
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = 1.5
    c.caustics_reflective = False
    c.caustics_refractive = False
    if gi:
        c.max_bounces = GI_BOUNCES
        c.diffuse_bounces = GI_BOUNCES
        c.glossy_bounces = GI_BOUNCES
        c.transmission_bounces = GI_BOUNCES
        c.caustics_reflective = True
        c.caustics_refractive = True
        c.blur_glossy = 0.0
    c.use_guiding = False
    scene.render.film_transparent = False
    scene.render.use_persistent_data = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    settings = {k: getattr(c, k) for k in (
        "device", "samples", "seed", "max_bounces", "diffuse_bounces", "use_denoising",
        "use_adaptive_sampling", "sample_clamp_direct", "sample_clamp_indirect",
        "light_sampling_threshold", "pixel_filter_type", "filter_width", "sampling_pattern",
        "use_light_tree", "direct_light_sampling_type")}
    if gi:
        settings.update({k: getattr(c, k) for k in (
            "glossy_bounces", "transmission_bounces", "volume_bounces", "transparent_max_bounces",
            "caustics_reflective", "caustics_refractive", "blur_glossy", "use_guiding")})
    settings["resolution"] = [scene.render.resolution_x, scene.render.resolution_y]
    return settings


def render_exr(scene, path: str) -> tuple[np.ndarray, float]:
    """Render ``scene`` with Cycles, write a float EXR, read it back: (H, W, 3) float64, row 0
    = top (EXR scanlines run top-down; Blender's own pixel buffers run bottom-up)."""
    fmt = scene.render.image_settings
    fmt.file_format = "OPEN_EXR"
    fmt.color_depth = "32"
    fmt.exr_codec = "ZIP"
    fmt.color_mode = "RGBA"
    scene.render.filepath = path
    scene.render.use_file_extension = False
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True, scene=scene.name)
    seconds = time.perf_counter() - t0
    channels = OpenEXR.File(path).channels()
    if "RGBA" in channels:
        pixels = channels["RGBA"].pixels[..., :3]
    elif "RGB" in channels:
        pixels = channels["RGB"].pixels
    else:
        pixels = np.dstack([channels[k].pixels for k in "RGB"])
    return np.asarray(pixels, dtype=np.float64), seconds


def block_means(image: np.ndarray, grid=GRID) -> np.ndarray:
    """(H, W, C) -> (GY, GX, C) means over equal blocks; H, W must divide by the grid."""
    h, w, c = image.shape
    gy, gx = grid
    if h % gy or w % gx:
        raise ValueError(f"image {w}x{h} does not divide into a {gx}x{gy} grid")
    return image.reshape(gy, h // gy, gx, w // gx, c).mean(axis=(1, 3))


# --- references -----------------------------------------------------------------------------
def _supersampled_render(scene, name, samples, seed, factor, tmpdir, reuse_dir):
    """Render at ``factor`` x the resolution and box-average back; a render of that size,
    samples and seed found in ``reuse_dir`` (``<scene>_<W>x<H>_seed<seed>_<spp>.npz`` with
    ``image`` and ``seconds``) is used instead of rendering, and a new one is saved there."""
    w, h = scene.render.resolution_x, scene.render.resolution_y
    big = (w * factor, h * factor)
    path = Path(reuse_dir) / f"{name}_{big[0]}x{big[1]}_seed{seed}_{samples}.npz" if reuse_dir else None
    if path is not None and path.is_file():
        with np.load(path) as data:
            img, dt = data["image"].astype(np.float64), float(data["seconds"])
        print(f"  {name} seed {seed}: reusing {path}", flush=True)
    else:
        scene.render.resolution_x, scene.render.resolution_y = big
        try:
            img, dt = render_exr(scene, os.path.join(tmpdir, f"{name}_{seed}_big.exr"))
        finally:
            scene.render.resolution_x, scene.render.resolution_y = w, h
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(path, image=img.astype(np.float32), seconds=dt)
    if img.shape[:2] != (big[1], big[0]):
        raise RuntimeError(f"{name}: render of {img.shape[1]}x{img.shape[0]}, expected {big}")
    return img.reshape(h, factor, w, factor, 3).mean(axis=(1, 3)), dt


def make_reference(name: str, tmpdir: str, gi: bool = False, reuse_dir=None) -> dict:
    """Render scene ``name`` with every seed and write ``<scene>.npz`` into ``cycles_direct/``
    (``gi`` False: a scene of ``parity_scenes.SCENES``, direct light) or ``cycles_gi/`` (``gi``
    True: a name of ``GI_SCENES``, all bounces). Returns the manifest entry."""
    samples = GI_SAMPLES[name] if gi else SAMPLES.get(name, DEFAULT_SAMPLES)
    out = OUT_GI if gi else OUT
    factor = GI_SUPERSAMPLE.get(name, 1) if gi else 1
    seeds = GI_SEEDS.get(name, SEEDS) if gi else SEEDS
    renders, seconds, settings = [], [], None
    for seed in seeds:
        if gi:
            scene, builder = _build_gi(name)
        elif name in parity_scenes.CAMERA_SCENES:     # emitters in frame on purpose
            scene = parity_scenes.build(name)
            builder = f"tests/parity_scenes.py:{parity_scenes.CAMERA_SCENES[name].__name__}"
        elif name in parity_scenes.GEOMETRY_SCENES:
            scene = parity_scenes.build(name)
            builder = f"tests/parity_scenes.py:{parity_scenes.GEOMETRY_SCENES[name].__name__}"
        else:
            scene = parity_scenes.build(name)
            builder = f"tests/parity_scenes.py:{parity_scenes.SCENES[name].__name__}"
            inside = parity_scenes.lights_out_of_frame(scene)
            if inside:
                raise RuntimeError(f"{name}: lights inside the camera frame: {inside}")
        settings = configure_cycles(scene, samples, seed, gi=gi)
        if factor > 1:
            img, dt = _supersampled_render(scene, name, samples, seed, factor, tmpdir, reuse_dir)
        else:
            img, dt = render_exr(scene, os.path.join(tmpdir, f"{name}_{seed}.exr"))
        renders.append(img)
        seconds.append(dt)
    stack = np.stack(renders)                              # (K, H, W, 3)
    k = len(seeds)
    image = stack.mean(axis=0)
    seed_blocks = np.stack([block_means(r) for r in renders])
    region_mean = block_means(image)
    region_se = seed_blocks.std(axis=0, ddof=1) / math.sqrt(k)
    h, w = image.shape[:2]
    npix = (h // GRID[0]) * (w // GRID[1])
    pixel_var = stack.var(axis=0, ddof=1) / k              # variance of each mean pixel
    region_se_pixels = np.sqrt(block_means(pixel_var)) / math.sqrt(npix)
    if k < 4:     # 2 block means give a poor spread: the per-pixel estimate (1200+ pixels)
        region_se = region_se_pixels
    settings = dict(settings, seeds=list(seeds), seed="see seeds", blender=bpy.app.version_string,
                    render_seconds=[round(s, 2) for s in seconds], grid=list(GRID),
                    scene=name, builder=builder, supersample=factor,
                    rendered_at=[w * factor, h * factor],
                    region_se_from="per-pixel variance" if k < 4 else "spread of the seeds")
    out.mkdir(parents=True, exist_ok=True)
    extra = {}
    if name == "bokeh":          # per seed, per emitter: parity_scenes.bokeh_moments
        extra["seed_moments"] = json.dumps(
            [{part: parity_scenes.bokeh_moments(r, cols)
              for part, cols in parity_scenes.BOKEH_REGIONS.items()} for r in renders])
    np.savez_compressed(
        out / f"{name}.npz", image=image.astype(np.float32), region_mean=region_mean,
        region_se=region_se, region_se_pixels=region_se_pixels, seed_region_means=seed_blocks,
        grid=np.array(GRID), settings=json.dumps(settings), **extra)
    peak = float(region_mean.max())
    bright = region_mean >= 0.05 * peak
    rel_se = np.where(bright, region_se / np.maximum(region_mean, 1e-30), 0.0)
    # seed-to-seed: largest difference between two seeds' block means, relative to the peak
    spread = float((seed_blocks.max(axis=0) - seed_blocks.min(axis=0)).max() / peak)
    summary = {
        "samples_per_seed": samples, "seeds": list(seeds), "supersample": factor,
        "seconds_per_render": round(float(np.mean(seconds)), 2),
        "brightest_region_mean": round(peak, 5),
        "max_rel_se_bright_regions": float(f"{rel_se.max():.3g}"),
        "median_rel_se_bright_regions": float(f"{np.median(rel_se[bright]):.3g}"),
        "max_rel_se_pixels_estimate": float(
            f"{np.where(bright, region_se_pixels / np.maximum(region_mean, 1e-30), 0).max():.3g}"),
        "max_abs_se_dark_regions_over_peak": float(
            f"{(np.where(bright, 0, region_se).max() / peak):.3g}"),
        "max_seed_to_seed_block_spread_over_peak": float(f"{spread:.3g}"),
        "blender": bpy.app.version_string,
    }
    if gi:
        summary["resolution"] = [w, h]
        summary["builder"] = builder
    print(f"{name:22s} {samples:5d} spp x {k} seeds, {summary['seconds_per_render']:.2f} s/render,"
          f" rel SE max {summary['max_rel_se_bright_regions']:.2e}"
          f" (pixel est. {summary['max_rel_se_pixels_estimate']:.2e})", flush=True)
    return summary


# --- conventions ----------------------------------------------------------------------------
def _reset_lab():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    scene.world = world
    parity_scenes._set_world(world, 0.0)
    return scene


def _white(kind="DIFFUSE", rho=1.0, spec=0.0):
    if kind == "DIFFUSE":
        return parity_scenes._material_diffuse("White", (rho, rho, rho))
    mat = parity_scenes._material_principled("White", (rho, rho, rho))
    mat.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = spec
    return mat


def _floor(mat, size=200.0, z=0.0):
    s = size / 2
    return parity_scenes._mesh_object("Floor", [(-s, -s, z), (s, -s, z), (s, s, z), (-s, s, z)],
                                      [(0, 1, 2, 3)], mat)


def _ortho(scene, scale, res, location=(0, 0, 5), rotation=(0, 0, 0)):
    cam_data = bpy.data.cameras.new("Ortho")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = scale
    cam = bpy.data.objects.new("Ortho", cam_data)
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = location, rotation
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()
    return cam


def _pixel_points(cam, res, plane_z=0.0):
    """World points where each pixel centre's (orthographic) ray meets the plane z=plane_z,
    (H, W, 3), row 0 = top."""
    w, h = res
    sx = cam.data.ortho_scale if w >= h else cam.data.ortho_scale * w / h
    sy = sx * h / w
    u = ((np.arange(w) + 0.5) / w - 0.5) * sx
    v = (0.5 - (np.arange(h) + 0.5) / h) * sy
    uu, vv = np.meshgrid(u, v)
    m = np.array(cam.matrix_world)
    origin = (m[:3, :3] @ np.stack([uu.ravel(), vv.ravel(), np.zeros(uu.size)])).T + m[:3, 3]
    d = -m[:3, 2]
    t = (plane_z - origin[:, 2]) / d[2]
    return (origin + t[:, None] * d).reshape(h, w, 3)


def _lambert_polygon(points, verts):
    """Irradiance per unit radiance, E/L, at ``points`` (..., 3) with normal +Z from a planar
    polygon ``verts`` (N, 3): Lambert's formula E = L/2 sum_k Theta_k (gamma_k . n)."""
    shape = points.shape[:-1]
    p = points.reshape(-1, 3)
    acc = np.zeros(len(p))
    for k in range(len(verts)):
        a = verts[k] - p
        b = verts[(k + 1) % len(verts)] - p
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        c = np.cross(a, b)
        cn = np.linalg.norm(c, axis=1)
        theta = np.arctan2(cn, np.sum(a * b, axis=1))
        acc += theta * c[:, 2] / np.maximum(cn, 1e-30)
    return np.abs(0.5 * acc).reshape(shape)


def _shape_polygon(shape, sx, sy, matrix, n=2048):
    if shape in ("SQUARE", "RECTANGLE"):
        loc = np.array([[-sx / 2, -sy / 2, 0], [sx / 2, -sy / 2, 0],
                        [sx / 2, sy / 2, 0], [-sx / 2, sy / 2, 0]])
    else:  # an area-preserving inscribed polygon
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        k = math.sqrt((2 * np.pi / n) / math.sin(2 * np.pi / n))
        loc = np.stack([sx / 2 * k * np.cos(t), sy / 2 * k * np.sin(t), 0 * t], 1)
    m = np.asarray(matrix)
    return (m[:3, :3] @ loc.T).T + m[:3, 3]


def _add_light(scene, kind, location=(0, 0, 0), rotation=(0, 0, 0), **props):
    data = bpy.data.lights.new(kind.title(), kind)
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(kind.title(), data)
    scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.view_layer.update()
    return obj


def _lab_render(scene, samples, tmpdir, tag):
    configure_cycles(scene, samples, seed=1)
    img, _ = render_exr(scene, os.path.join(tmpdir, f"conv_{tag}.exr"))
    return img[..., 0]


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def measure_conventions(tmpdir: str) -> dict:
    """Small renders of a white Lambertian plane compared with formulas. Each entry gives
    the measured / model ratio (mean over the pixels used, and its spread)."""
    res_all = {}

    def record(key, ratio, note, **extra):
        ratio = np.asarray(ratio, dtype=np.float64)
        entry = {"ratio_mean": float(f"{ratio.mean():.5f}"), "note": note}
        if ratio.size > 1:
            entry["ratio_sd"] = float(f"{ratio.std():.2g}")
        entry.update(extra)
        res_all[key] = entry
        print(f"  {key:44s} {entry['ratio_mean']:.4f}  {note}", flush=True)

    # EXR holds linear radiance whatever the view transform
    scene = _reset_lab()
    _floor(_white())
    cam = _ortho(scene, 4.0, (64, 64))
    light = _add_light(scene, "POINT", (0.8, 1.2, 1.0), energy=1000.0, shadow_soft_size=0.0)
    img = _lab_render(scene, 256, tmpdir, "point")
    configure_cycles(scene, 256, 1)
    scene.view_settings.view_transform = "AgX"
    img_agx, _ = render_exr(scene, os.path.join(tmpdir, "conv_agx.exr"))
    record("exr_linear_view_transform_independent", img_agx[..., 0] / img,
           "EXR with view transform AgX / with Standard, pixel by pixel")

    # 1. point light: L = rho/pi * P cos(theta) / (4 pi r^2)
    p = _pixel_points(cam, (64, 64))
    d = np.array(light.location) - p
    r2 = (d ** 2).sum(-1)
    model = 1000.0 * d[..., 2] / np.sqrt(r2) / (4 * np.pi * r2) / np.pi
    record("point_P1000_h1", img / model, "L = rho/pi * P cos / (4 pi r^2); rho = 1, 64x64 px "
           "over 4 m, light 1 m above (peak pixels ~0.998: filter over the peak)",
           orientation_row0_is_top=bool(np.unravel_index(img.argmax(), img.shape)[0] < 32))

    # Lambertian check: grazing light, oblique views, Principled (IOR level 0) and Diffuse
    for kind, spec in (("DIFFUSE", 0.0), ("PRINCIPLED", 0.0), ("PRINCIPLED", 0.5)):
        ratios = []
        for view_deg in (0, 45, 75):
            scene = _reset_lab()
            _floor(_white(kind, 0.8, spec))
            a = math.radians(view_deg)
            cam = _ortho(scene, 3.0, (32, 32), (0, -10 * math.sin(a), 10 * math.cos(a)), (a, 0, 0))
            light = _add_light(scene, "POINT", (-2.0, 1.0, 1.0), energy=1000.0, shadow_soft_size=0.0)
            img = _lab_render(scene, 128, tmpdir, "lambert")
            p = _pixel_points(cam, (32, 32))
            d = np.array(light.location) - p
            r2 = (d ** 2).sum(-1)
            model = 0.8 / np.pi * 1000.0 * d[..., 2] / np.sqrt(r2) / (4 * np.pi * r2)
            ratios.append((img / model).mean())
        label = "diffuse_bsdf" if kind == "DIFFUSE" else f"principled_spec_ior_level_{spec}"
        record(f"lambertian_{label}", ratios,
               "L / (rho/pi E) for views 0, 45, 75 deg from the normal, light incidence 27-80 deg",
               per_view=[round(float(x), 4) for x in ratios])

    # 2. spot: on-axis intensity P/(4 pi); attenuation smoothstep((cos t - cos h)/((1-cos h) blend))
    for size_deg, blend in ((60.0, 0.15), (90.0, 0.5), (120.0, 1.0), (60.0, 0.0)):
        scene = _reset_lab()
        _floor(_white())
        h = 1.0
        res = (96, 96)
        cam = _ortho(scene, 2.6 * h * math.tan(math.radians(size_deg / 2)), res)
        _add_light(scene, "SPOT", (0, 0, h), energy=1000.0, spot_size=math.radians(size_deg),
                   spot_blend=blend, shadow_soft_size=0.0)
        img = _lab_render(scene, 256, tmpdir, "spot")
        p = _pixel_points(cam, res)
        d = np.array([0, 0, h]) - p
        r2 = (d ** 2).sum(-1)
        cos = d[..., 2] / np.sqrt(r2)
        intensity = img * np.pi / (cos / r2) / (1000.0 / (4 * np.pi))
        cos_h = math.cos(math.radians(size_deg / 2))
        att = (_smoothstep((cos - cos_h) / ((1 - cos_h) * blend)) if blend > 0
               else (cos > cos_h).astype(float))
        theta = np.degrees(np.arccos(cos))
        pixel_deg = math.degrees(cam.data.ortho_scale / res[0] / h)
        away = np.abs(theta - size_deg / 2) > 2 * pixel_deg     # off the hard outer edge
        bins = np.linspace(0.0, size_deg / 2 + 2.0, 9)
        profile = [[round(float((a + b) / 2), 1),
                    round(float(intensity[(theta >= a) & (theta < b)].mean()), 4),
                    round(float(att[(theta >= a) & (theta < b)].mean()), 4)]
                   for a, b in zip(bins[:-1], bins[1:])]
        record(f"spot_{int(size_deg)}deg_blend{blend}_on_axis", intensity[theta < 3.0],
               "I(0) / (P / 4 pi)",
               max_abs_dev_from_smoothstep_model=round(float(np.abs(intensity - att)[away].max()), 4),
               rms_dev_from_smoothstep_model=round(float(np.sqrt(((intensity - att)[away] ** 2).mean())), 4),
               profile_theta_measured_model=profile)

    # 3. sun: E = S cos(theta), whatever the angle
    for angle_deg, tilt_deg in ((0.0, 0.0), (0.0, 45.0), (0.0, 70.0), (0.5, 45.0), (10.0, 45.0)):
        scene = _reset_lab()
        _floor(_white())
        _ortho(scene, 1.0, (16, 16))
        _add_light(scene, "SUN", rotation=(math.radians(tilt_deg), 0, 0), energy=3.0,
                   angle=math.radians(angle_deg))
        img = _lab_render(scene, 64, tmpdir, "sun")
        record(f"sun_S3_angle{angle_deg}_incidence{int(tilt_deg)}",
               img * np.pi / (3.0 * math.cos(math.radians(tilt_deg))), "E / (S cos theta)")

    # 4. area lights: L = P / (pi A), one-sided towards local -Z; on-axis and full images
    def area_scene(shape, sx, sy, h, energy=100.0, normalize=True, spread=None, rotation=(0, 0, 0),
                   location=None, res=(8, 8), scale=0.02):
        scene = _reset_lab()
        _floor(_white())
        cam = _ortho(scene, scale, res)
        props = dict(energy=energy, shape=shape, size=sx, size_y=sy, normalize=normalize)
        if spread is not None:
            props["spread"] = spread
        light = _add_light(scene, "AREA", location or (0, 0, h), rotation, **props)
        return scene, cam, light

    for shape, sx, sy, h in (("SQUARE", 1, 1, 1.0), ("SQUARE", 1, 1, 0.25), ("RECTANGLE", 1, 0.5, 0.5),
                             ("DISK", 1, 1, 1.0), ("DISK", 1, 1, 0.25), ("ELLIPSE", 1, 0.5, 0.5)):
        scene, cam, light = area_scene(shape, sx, sy, h)
        img = _lab_render(scene, 1024, tmpdir, "area")
        area = sx * sy * (math.pi / 4 if shape in ("DISK", "ELLIPSE") else 1.0)
        radiance = 100.0 / (math.pi * area)
        if shape == "DISK":
            r = sx / 2
            e_model = math.pi * radiance * r * r / (h * h + r * r)
            formula = "E = pi L r^2/(d^2+r^2), L = P/(pi A)"
        else:
            e_model = radiance * _lambert_polygon(np.zeros((1, 3)), _shape_polygon(
                shape, sx, sy, light.matrix_world))[0]
            formula = "E = L * Lambert polygon, L = P/(pi A)" + (", A = pi a b" if shape == "ELLIPSE" else "")
        record(f"area_{shape.lower()}_{sx}x{sy}_d{h}_on_axis", img * np.pi / e_model, formula)
    # whole-image check for a tilted, offset light
    for shape, sx, sy, h in (("SQUARE", 1.0, 1.0, 1.0), ("ELLIPSE", 1.0, 0.4, 0.5)):
        scene, cam, light = area_scene(shape, sx, sy, h, rotation=(0.2, 0, 0.3),
                                       location=(0.2, 0.1, h), res=(48, 48), scale=3.0)
        img = _lab_render(scene, 256, tmpdir, "area_img")
        area = sx * sy * (math.pi / 4 if shape in ("DISK", "ELLIPSE") else 1.0)
        e = 100.0 / (math.pi * area) * _lambert_polygon(
            _pixel_points(cam, (48, 48)), _shape_polygon(shape, sx, sy, light.matrix_world))
        ok = e > 0.05 * e.max()
        record(f"area_{shape.lower()}_tilted_whole_image", (img * np.pi / e)[ok],
               "pixels with E > 5 % of max; light tilted 11 deg, turned 17 deg")
    scene, cam, light = area_scene("SQUARE", 1, 1, 1.0, rotation=(math.pi, 0, 0))
    img = _lab_render(scene, 64, tmpdir, "area_up")
    res_all["area_facing_away_floor_radiance"] = {"value": float(img.mean()),
                                                  "note": "square light turned to emit +Z: 0 = one-sided"}
    print(f"  area_facing_away_floor_radiance             {img.mean():.4g}")
    for shape, sx in (("SQUARE", 2.0), ("DISK", 2.0)):
        scene, cam, light = area_scene(shape, sx, sx, 1.0, normalize=False)
        img = _lab_render(scene, 1024, tmpdir, "area_nonorm")
        if shape == "DISK":
            g = math.pi * (sx / 2) ** 2 / (1.0 + (sx / 2) ** 2)
        else:
            g = _lambert_polygon(np.zeros((1, 3)), _shape_polygon(shape, sx, sx, light.matrix_world))[0]
        record(f"area_{shape.lower()}_{sx}m_normalize_off", img * np.pi / (g * 100.0 / math.pi),
               "Light.normalize = False: L = P / pi (power per m^2), not P/(pi A)")

    # 5. spread: 0 -> collimated, E = P/A cos inside the beam; general spread profile
    for spread_deg, tilt_deg in ((0.0, 0.0), (0.0, 30.0), (1.0, 0.0), (5.0, 0.0)):
        scene, cam, light = area_scene("DISK", 1.0, 1.0, 1.5, spread=math.radians(spread_deg),
                                       rotation=(math.radians(tilt_deg), 0, 0), res=(32, 32), scale=1.6)
        img = _lab_render(scene, 256, tmpdir, "spread")
        p = _pixel_points(cam, (32, 32))
        m = np.array(light.matrix_world)
        n = -m[:3, 2]
        q = p - ((p - m[:3, 3]) @ n)[..., None] * n
        loc = (np.linalg.inv(m[:3, :3]) @ (q - m[:3, 3]).reshape(-1, 3).T).T.reshape(p.shape)
        rho = np.hypot(loc[..., 0], loc[..., 1])
        inside, outside = rho < 0.35, rho > 0.65
        e_model = 100.0 / (math.pi / 4) * math.cos(math.radians(tilt_deg))
        record(f"area_disk_spread{spread_deg}_incidence{int(tilt_deg)}", img[inside] * np.pi / e_model,
               "E / (P/A cos theta) inside the beam (footprint radius < 0.35 m of 0.5 m)",
               outside_max_over_P_A=float(f"{(img[outside].max() * np.pi / e_model):.3g}"))
    scene, cam, light = area_scene("DISK", 1.0, 1.0, 1.0, spread=math.radians(30.0), res=(48, 48), scale=2.4)
    img = _lab_render(scene, 1024, tmpdir, "spread30")
    half = math.radians(15.0)
    k = 1.0 / (math.tan(half) - half)
    n = 300
    g = (np.arange(n) + 0.5) / n - 0.5
    gx, gy = np.meshgrid(g, g)
    on = gx ** 2 + gy ** 2 < 0.25
    q = np.stack([gx[on], gy[on], np.full(on.sum(), 1.0)], 1)
    p = _pixel_points(cam, (48, 48)).reshape(-1, 3)
    e = np.zeros(len(p))
    for i in range(0, len(p), 256):
        d = q[None] - p[i:i + 256, None]
        r2 = (d ** 2).sum(-1)
        c = d[..., 2] / np.sqrt(r2)
        f = np.maximum((math.tan(half) - np.sqrt(np.maximum(1 - c * c, 0)) / c) * k, 0)
        e[i:i + 256] = (100.0 / (math.pi * math.pi / 4) * f * c * c / r2).sum(1) / n ** 2
    e = e.reshape(48, 48)
    centre = e > 0.9 * e.max()
    record("area_disk_spread30_profile", (img * np.pi)[centre] / e[centre],
           "L(theta) = P/(pi A) * max(0, (tan(s/2) - tan theta) / (tan(s/2) - s/2)): pixels with "
           "E > 90 % of max (edges within 3 % of max, pixel-filter blur)",
           max_abs_dev_over_max=round(float(np.abs(img * np.pi - e).max() / e.max()), 4))

    # 6. emission shader on a mesh: L = S * colour from both faces
    h = 0.5
    g = _lambert_polygon(np.zeros((1, 3)), np.array(
        [[-0.5, -0.5, h], [0.5, -0.5, h], [0.5, 0.5, h], [-0.5, 0.5, h]]))[0]
    for flip in (False, True):
        scene = _reset_lab()
        _floor(_white())
        _ortho(scene, 0.02, (8, 8), location=(0, 0, 0.25))
        mat = parity_scenes._material_emission("Emit", (1, 1, 1), 5.0)
        verts = [(-0.5, -0.5, h), (0.5, -0.5, h), (0.5, 0.5, h), (-0.5, 0.5, h)]
        parity_scenes._mesh_object("Emitter", verts, [(3, 2, 1, 0)] if flip else [(0, 1, 2, 3)], mat)
        img = _lab_render(scene, 1024, tmpdir, "emit")
        record(f"emission_S5_floor_{'front' if flip else 'back'}_face_towards_floor",
               img * np.pi / (5.0 * g), "E / (S * Lambert polygon): L = S")
    scene = _reset_lab()
    _floor(_white())
    _ortho(scene, 0.02, (8, 8), location=(0, 0, 0.25))
    mat = parity_scenes._material_emission("Emit", (1, 1, 1), 5.0)
    mat.cycles.emission_sampling = "NONE"
    parity_scenes._mesh_object("Emitter", [(-0.5, -0.5, h), (0.5, -0.5, h), (0.5, 0.5, h),
                                           (-0.5, 0.5, h)], [(0, 1, 2, 3)], mat)
    img = _lab_render(scene, 1024, tmpdir, "emit_none")
    record("emission_S5_floor_emission_sampling_NONE", img * np.pi / (5.0 * g),
           "no light sampling of the mesh: at max_bounces = 0 the BSDF-sampled ray still "
           "collects the emitter (direct light is complete, only noisier)")
    for z, rot in ((5.0, (0, 0, 0)), (-5.0, (math.pi, 0, 0))):
        scene = _reset_lab()
        mat = parity_scenes._material_emission("Emit", (1.0, 0.5, 0.25), 5.0)
        parity_scenes._mesh_object("Emitter", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)],
                                   [(0, 1, 2, 3)], mat)
        _ortho(scene, 0.2, (8, 8), location=(0, 0, z), rotation=rot)
        configure_cycles(scene, 16, 1)
        rgb, _ = render_exr(scene, os.path.join(tmpdir, "conv_emit_view.exr"))
        record(f"emission_seen_from_{'front' if z > 0 else 'back'}", rgb.reshape(-1, 3).mean(0)
               / (5.0 * np.array([1.0, 0.5, 0.25])), "pixel / (S * colour), per channel")

    # 7. world colour C: E = pi C on an open upward plane
    scene = _reset_lab()
    parity_scenes._set_world(scene.world, 0.5)
    _floor(_white("DIFFUSE", 0.8), size=2000.0)
    _ortho(scene, 0.2, (8, 8))
    img = _lab_render(scene, 1024, tmpdir, "world")
    record("world_C0.5_upward_plane", img / (0.8 * 0.5), "L / (rho C): E = pi C")
    scene.camera.location = (0, 0, -1)
    img = _lab_render(scene, 16, tmpdir, "world_direct")
    record("world_C0.5_seen_directly", img / 0.5, "pixel / C")

    # 8. pixel filter: edge spread of an emissive half-plane whose edge lies on a pixel border
    scene = _reset_lab()
    mat = parity_scenes._material_emission("Emit", (1, 1, 1), 1.0)
    parity_scenes._mesh_object("Half", [(-100, -100, 0), (0, -100, 0), (0, 100, 0), (-100, 100, 0)],
                               [(0, 1, 2, 3)], mat)
    _ortho(scene, 32.0, (32, 8))
    centres = np.arange(12, 20) + 0.5 - 16.0            # pixel centres [px] from the edge

    def bh_edge(support):
        t = np.linspace(-support / 2, support / 2, 200001)
        x = 2 * np.pi * (t / support + 0.5)
        f = 0.35875 - 0.48829 * np.cos(x) + 0.14128 * np.cos(2 * x) - 0.01168 * np.cos(3 * x)
        return np.array([f[c + t < 0].sum() / f.sum() for c in centres])

    for width in (1.5, 1.0):
        configure_cycles(scene, 4096, 1)
        scene.cycles.filter_width = width
        img, _ = render_exr(scene, os.path.join(tmpdir, "conv_filter.exr"))
        esf = img[..., 0].mean(axis=0)[12:20]
        fit = {f"support_{k:g}w": float(f"{np.abs(esf - bh_edge(k * width)).max():.2g}")
               for k in (1.0, 2.0)}
        res_all[f"pixel_filter_blackman_harris_width{width}"] = {
            "edge_profile_cols_12_19": [round(float(v), 4) for v in esf],
            "max_abs_dev_if_support_is": fit,
            "note": "Cycles' Blackman-Harris of filter_width w spans [-w, w] (support 2 w), "
                    "not [-w/2, w/2]: compare the two max deviations"}
        print(f"  pixel_filter_blackman_harris_width{width}       max dev: {fit}")

    # 9. max_bounces = 0 is direct light only: a wall outside a narrow spot cone stays black
    for bounces in (0, 1):
        scene = _reset_lab()
        white = _white("DIFFUSE", 0.8)
        _floor(white, size=4.0)
        parity_scenes._mesh_object("Wall", [(-2, 1, 0), (2, 1, 0), (2, 1, 2), (-2, 1, 2)],
                                   [(0, 1, 2, 3)], white)
        _ortho(scene, 1.0, (16, 16), location=(0, -3, 1), rotation=(math.pi / 2, 0, 0))
        _add_light(scene, "SPOT", (0, 0, 2), energy=1000.0, spot_size=math.radians(20.0),
                   spot_blend=0.0, shadow_soft_size=0.0)
        configure_cycles(scene, 256, 1)
        scene.cycles.max_bounces = scene.cycles.diffuse_bounces = bounces
        img, _ = render_exr(scene, os.path.join(tmpdir, "conv_bounce.exr"))
        res_all[f"indirect_only_wall_max_bounces_{bounces}"] = {
            "value": float(img.mean()), "note": "wall lit only by light bounced off the floor"}
        print(f"  indirect_only_wall_max_bounces_{bounces}             {img.mean():.4g}")
    return res_all


# --- main -----------------------------------------------------------------------------------
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", help="scene names (default: all)")
    parser.add_argument("--conventions", action="store_true",
                        help="measure the Cycles conventions into conventions.json instead")
    parser.add_argument("--gi", action="store_true",
                        help=f"all-bounce references of {list(GI_SCENES)} into cycles_gi/")
    parser.add_argument("--samples", type=int, default=None,
                        help="override the samples per seed (trials)")
    parser.add_argument("--reuse-dir", default=None,
                        help="supersampled GI renders (scene2) are looked for and kept here, "
                             "e.g. out/bench_cache (the 640x480 benchmark's renders)")
    args = parser.parse_args(argv)
    if args.samples is not None:
        for table in (SAMPLES, GI_SAMPLES):
            for key in set(table) | set(args.scenes):
                table[key] = args.samples
        global DEFAULT_SAMPLES
        DEFAULT_SAMPLES = args.samples
    if args.gi:
        return main_gi(parser, args)
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmpdir:
        if args.conventions:
            t0 = time.perf_counter()
            table = measure_conventions(tmpdir)
            table["_meta"] = {"blender": bpy.app.version_string,
                              "seconds": round(time.perf_counter() - t0, 1),
                              "made_by": "tests/data/make_cycles_refs.py --conventions"}
            (OUT / "conventions.json").write_text(json.dumps(table, indent=1) + "\n")
            return
        known = list(parity_scenes.SCENES) + list(parity_scenes.CAMERA_SCENES) \
            + list(parity_scenes.GEOMETRY_SCENES)
        names = args.scenes or known
        unknown = [n for n in names if n not in known]
        if unknown:
            parser.error(f"unknown scenes {unknown}; known: {known}")
        manifest_path = OUT / "manifest.json"
        manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
        for name in names:
            manifest[name] = make_reference(name, tmpdir)
        versions = {entry.get("blender", "5.0.1") for key, entry in manifest.items()
                    if not key.startswith("_")}
        manifest["_meta"] = {
            "blender": ", ".join(sorted(versions)), "grid": list(GRID), "seeds": list(SEEDS),
            "resolution": list(parity_scenes.RESOLUTION),
            "made_by": "tests/data/make_cycles_refs.py"}
        manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def main_gi(parser, args):
    names = args.scenes or list(GI_SCENES)
    unknown = [n for n in names if n not in GI_SCENES]
    if unknown:
        parser.error(f"unknown GI scenes {unknown}; known: {list(GI_SCENES)}")
    OUT_GI.mkdir(parents=True, exist_ok=True)
    manifest_path = OUT_GI / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    with tempfile.TemporaryDirectory() as tmpdir:
        for name in names:
            manifest[name] = make_reference(name, tmpdir, gi=True, reuse_dir=args.reuse_dir)
    manifest["_meta"] = {
        "blender": bpy.app.version_string, "grid": list(GRID), "seeds": list(SEEDS),
        "bounces": GI_BOUNCES, "made_by": "tests/data/make_cycles_refs.py --gi"}
    manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
