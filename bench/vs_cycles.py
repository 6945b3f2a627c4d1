"""Lanterna's ``final`` preset against Cycles on the seed's scenes (issue 4's benchmark).

What it computes (``lanterna bench --vs-cycles`` or
``python -m lanterna.engine.blender.bench_cycles``)
    For each scene of ``--scenes`` (the seed's Scene 1 and 2, built by
    ``engine/blender/seed_scenes.py`` and resized to ``--resolution``), in one process on the
    same bpy scene:

    1. Lanterna: ``export_scene`` of the evaluated depsgraph, then
       ``pipeline.render(scene, RenderSettings(preset="final", seed=1))``. Its time is the wall
       time of the whole ``render`` call (export excluded, printed apart); the stages' seconds
       come from ``result.report["stages"]``.
    2. Cycles on the CPU with the settings of the GI references (``configure_cycles(...,
       gi=True)`` of ``tests/data/make_cycles_refs.py``, imported from it: 64 bounces, caustics
       on, no clamping, no adaptive sampling, light threshold 0, Blackman-Harris 1.5, no path
       guiding; the benchmark runs from a checkout, and says so if that file is missing) at
       each of ``--cycles-samples`` (64, 256, 1024), without and with the
       OpenImageDenoise denoiser (CPU, albedo + normal passes, prefilter ``ACCURATE``). One
       render per sample count gives both: the denoiser on, its passes stored, written as a
       multilayer EXR and read back with OpenEXR (row 0 = top); "Combined" is the denoised
       image and "Noisy Image" the same samples before denoising (checked bit-identical to a
       render with the denoiser off). The denoised time is the wall time of
       ``bpy.ops.render.render(write_still=True)`` (scene sync, BVH, path tracing, denoising,
       writing the EXR; reading it back excluded); the undenoised time is that less OIDN's
       own time at this resolution, measured per scene as the difference of 1-spp renders
       with and without the denoiser (best of 2 each). Cycles' seed is ``CYCLES_SEED``, not
       one of the references' seeds, so the two are independent. One 1-sample Cycles render
       per process, not timed, loads the kernels first.
    3. The reference: at 160 x 120, the stored ``tests/data/cycles_gi/<scene>.npz`` (Cycles,
       same settings, 4 seeds x 768 spp). At any other resolution Cycles renders one at
       ``--reference-samples`` (4096) split over 2 seeds, each seed's render cached as
       ``out/bench_cache/<scene>_<W>x<H>_seed<seed>_<spp>.npz`` (relative to the working
       directory; the format of ``make_cycles_refs.py --reuse-dir``) and reused when
       present.

Errors (against the reference ``ref``, over all pixels and the three channels)
    relative RMSE = sqrt(mean((img - ref)^2)) / mean(ref).
    The reference's own noise adds its per-pixel variance v to every mean squared error
    (independent seeds), so the table also gives sqrt(max(MSE - v, 0)) / mean(ref), the error
    against the noise-free picture. v is known per 4 x 4 block for the stored references
    (``region_se_pixels`` holds the 4 seeds' per-pixel variance, averaged per block) and from
    the 2 seeds' difference for a rendered one. As a cross-check v is also fitted from Cycles'
    own 64 and 256 spp errors (MSE = V/spp + v; JSON only, fragile: Cycles' QMC error can fall
    faster than 1/spp and fireflies make the MSE noisy). Since v is the same for every method, the
    comparisons below come out the same with or without it; only their ratios change.
    worst block = max over the 4 x 4 blocks of |mean(img) / mean(ref) - 1|, the means taken
    over the block's pixels and channels.

Checks (issue 4)
    Lanterna's relative RMSE <= that of Cycles at 256 spp without denoiser, and Lanterna's
    time <= 1/4 of that Cycles render's time; both printed with their ratios.

Why 160 x 120 by default
    The issue asks for 640 x 480. A reference clearly less noisy than Cycles-1024 at 640 x 480
    takes Cycles hours on the 2 shared cores this was written on (Scene 2 needs about 3 min per
    768 spp even at 160 x 120), whereas the stored 160 x 120 references exist. Pass
    ``--resolution 640x480`` on a bigger machine: the reference is rendered once and cached.
    Scene 2's stored reference is noisy (worst 4 x 4 block SE 2 %, see tests/data/README.md):
    its noise-corrected column is the one to read there.

``--compare-at WxH`` (a proxy for the error at a resolution without a reference)
    Everything is rendered at ``--resolution`` (e.g. 640 x 480) and timed there; then every
    image, Lanterna's and each Cycles render, is box-downsampled by the integer factor k (the
    mean of each k x k block of pixels; 4 for 640x480 -> 160x120) and compared at ``WxH`` with
    the reference of that resolution (the stored one at 160 x 120, else one rendered at WxH and
    cached as above). A non-integer factor, or different factors for width and height, is
    refused. The reference's noise v is that of the WxH reference, so the correction above
    holds unchanged. Both methods go through the same downsampling, so comparing them is fair,
    but the figures are not the per-pixel errors at ``--resolution``: the downsampling averages
    away most of each render's pixel noise (k^2 pixels per compared pixel), and it leaves a
    small floor common to both, as a k x k box of pixels filtered with Blackman-Harris 1.5 px
    is not the same pixel filter as the reference's Blackman-Harris 1.5 px at WxH (edges differ
    slightly); Cycles' own error at high spp shows how high that floor is at most.

This is a benchmark, not a test: it asserts nothing, prints the figures and the two checks,
and ``--json FILE`` saves all of them. Expected failures (a scene that cannot be built or
exported, a failed Cycles render, a bad flag) print one ``lanterna bench: error: ...`` line.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PROG = "lanterna bench --vs-cycles"
DEFAULT_RESOLUTION = (160, 120)
DEFAULT_SCENES = ("scene1", "scene2")
DEFAULT_CYCLES_SAMPLES = (64, 256, 1024)
DEFAULT_REFERENCE_SAMPLES = 4096
CYCLES_SEED = 101                 # the stored references use seeds 1-4
REFERENCE_SEEDS = (201, 202)      # a rendered (cached) reference: 2 seeds, for its noise
GRID = (4, 4)                     # rows, columns of blocks
LANTERNA_SEED = 1
CHECK_SAMPLES = 256               # the Cycles render the checks compare with
TIME_FRACTION = 0.25
REPO = Path(__file__).resolve().parents[1]         # the checkout: bench/ lies in it
STORED_REFERENCES = REPO / "tests" / "data" / "cycles_gi"
STORED_RESOLUTION = (160, 120)
CACHE_DIR = Path("out") / "bench_cache"
SCENE_TITLES = {"scene1": "Scene 1", "scene2": "Scene 2"}


class BenchError(Exception):
    """An expected failure: printed as one line, no traceback."""


def run_command(body, argv) -> int:
    """A bench command's exit status: ``body(argv)`` returns it; a ``BenchError`` is printed
    as one ``lanterna bench: error:`` line (status 2), Ctrl-C as ``interrupted`` (130)."""
    try:
        return body(argv)
    except BenchError as exc:
        print(f"lanterna bench: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lanterna bench: interrupted", file=sys.stderr)
        return 130


class Parser(argparse.ArgumentParser):
    def error(self, message):
        raise BenchError(message)


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


@contextlib.contextmanager
def _blender_output_to(path: str):
    """Send what Blender writes to the process's stdout and stderr ("Saved: ..." lines) to
    ``path`` while a render runs; Python exceptions still carry the error."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with open(path, "ab") as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


# -- Cycles --------------------------------------------------------------------------------------
GI_BOUNCES = 64


def cycles_functions():
    """(configure_cycles, render_exr, source) from tests/data/make_cycles_refs.py: the Cycles
    settings of the references, so the peers render exactly as the references were made. The
    benchmark runs from a checkout of the repository (it needs tests/data anyway)."""
    path = REPO / "tests" / "data" / "make_cycles_refs.py"
    try:
        spec = importlib.util.spec_from_file_location("make_cycles_refs", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    except Exception as exc:  # noqa: BLE001 - reported as one line
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise BenchError(f"cannot load the Cycles reference settings from {path}: {reason} "
                         "(run from a checkout of the repository)") from None
    return module.configure_cycles, module.render_exr, "settings of tests/data/make_cycles_refs.py"


def set_denoiser(scene) -> dict:
    """OpenImageDenoise on the CPU, with albedo and normal passes."""
    c = scene.cycles
    c.use_denoising = True
    c.denoiser = "OPENIMAGEDENOISE"
    c.denoising_use_gpu = False
    c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
    c.denoising_prefilter = "ACCURATE"
    return {k: getattr(c, k) for k in ("denoiser", "denoising_input_passes",
                                        "denoising_prefilter", "denoising_quality")}


def oidn_available() -> bool:
    try:
        import _cycles
    except ImportError:
        return False
    return bool(getattr(_cycles, "with_openimagedenoise", False))


def render_with_noisy_pass(scene, path: str):
    """One Cycles render with the denoiser on and its passes stored, written as a multilayer
    EXR and read back: ({"Combined": denoised, "Noisy Image": the same samples undenoised},
    seconds of ``bpy.ops.render.render(write_still=True)``). One render gives both images, so
    a sample count costs one render, not two."""
    import bpy

    from ..engine import imageio

    layer = scene.view_layers[0]
    layer.cycles.denoising_store_passes = True
    fmt = scene.render.image_settings
    old_media = getattr(fmt, "media_type", None)
    try:
        if old_media is not None:                   # Blender 5.0: multilayer is a media type
            fmt.media_type = 'MULTI_LAYER_IMAGE'
        fmt.file_format = 'OPEN_EXR_MULTILAYER'
        fmt.color_depth = "32"
        fmt.exr_codec = "ZIP"
        scene.render.filepath = path
        scene.render.use_file_extension = False
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True, scene=scene.name)
        seconds = time.perf_counter() - t0
    finally:
        layer.cycles.denoising_store_passes = False
        if old_media is not None:
            fmt.media_type = old_media
        fmt.file_format = "OPEN_EXR"
    channels = imageio.read_exr(path)
    out = {}
    for pass_name in ("Combined", "Noisy Image"):
        key = f"{layer.name}.{pass_name}."
        out[pass_name] = np.stack([channels[key + c] for c in "RGB"], axis=-1).astype(np.float64)
    return out, seconds


def measure_denoise_seconds(scene, configure, render_exr, tmpdir, name) -> tuple:
    """OIDN's time at this resolution: a 1-spp render with the denoiser minus one without
    (best of 2 each, after a warm-up); subtracted from a denoised render's time to give the
    time of the same render without the denoiser. Returns (that difference, the 1-spp render's
    time without the denoiser): the least a render of this size takes, so that the
    subtraction, noisy where both are tiny, never gives a render of no time."""
    times = {False: [], True: []}
    for _ in range(2):
        for den in (False, True):
            configure(scene, 1, CYCLES_SEED, gi=True)
            with _blender_output_to(os.path.join(tmpdir, "blender.log")):
                if den:
                    set_denoiser(scene)
                _img, dt = render_exr(scene, os.path.join(tmpdir, f"{name}_den{int(den)}.exr"))
            times[den].append(dt)
    return max(min(times[True]) - min(times[False]), 0.0), min(times[False])


def warm_up_cycles(bscene, configure, render_exr, tmpdir, warm: dict) -> None:
    """One 1-sample Cycles render per process, not timed, to load the kernels first; ``warm``
    (a dict kept across scenes) remembers that it ran."""
    if warm.get("done"):
        return
    configure(bscene, 1, CYCLES_SEED, gi=True)
    try:
        with _blender_output_to(os.path.join(tmpdir, "blender.log")):
            render_exr(bscene, os.path.join(tmpdir, "warm.exr"))
    except Exception:  # noqa: BLE001 - the real renders after it report the failure
        pass
    warm["done"] = True


def cycles_curve(bscene, name, resolution, cycles_samples, cycles, tmpdir, warm: dict) -> dict:
    """Cycles on ``bscene`` (already at ``resolution`` (W, H)) at each of ``cycles_samples``:
    one render per sample count with OIDN on (``render_with_noisy_pass``), after the warm-up
    and the denoiser's own time (``measure_denoise_seconds``). Returns {"denoise_seconds",
    "rows": two per sample count (denoiser False: the render's time less the denoiser's;
    True: the render's time), "images": {("cycles", spp, denoiser): (H, W, 3) float64},
    "failures": [text]}; a failed render prints one ``lanterna bench: error:`` line."""
    configure, render_exr, _source = cycles
    w, h = resolution
    warm_up_cycles(bscene, configure, render_exr, tmpdir, warm)
    # The denoiser's own time: a 1-spp render with and without it (warm), the difference.
    denoise_seconds, least_seconds = measure_denoise_seconds(bscene, configure, render_exr,
                                                             tmpdir, name)
    rows, images, failures = [], {}, []
    for spp in cycles_samples:
        label = f"Cycles {spp} spp (+ OIDN)"
        log(f"{name}: {label} ...")
        configure(bscene, spp, CYCLES_SEED, gi=True)
        try:
            with _blender_output_to(os.path.join(tmpdir, "blender.log")):
                den_settings = set_denoiser(bscene)
                passes, dt = render_with_noisy_pass(bscene, os.path.join(tmpdir, f"{name}_{spp}.exr"))
        except Exception as exc:  # noqa: BLE001
            msg = f"{name}: {label} failed: {' '.join(str(exc).split())}"
            print(f"lanterna bench: error: {msg}", file=sys.stderr)
            failures.append(msg)
            continue
        noisy, denoised = passes["Noisy Image"], passes["Combined"]
        if noisy.shape[:2] != (h, w):
            failures.append(f"{name}: {label}: image {noisy.shape[1]}x{noisy.shape[0]}")
            continue
        images[("cycles", spp, False)] = noisy
        images[("cycles", spp, True)] = denoised
        common = {"method": "Cycles", "samples": spp, "seed": CYCLES_SEED,
                  "threads": bscene.render.threads, "render_seconds_with_oidn": dt}
        rows.append({**common, "denoiser": False,
                     "seconds": max(dt - denoise_seconds, least_seconds),
                     "seconds_note": "the render's time less the denoiser's (at least a "
                                     "1-spp render's)"})
        rows.append({**common, "denoiser": True, "seconds": dt,
                     "denoiser_settings": den_settings,
                     "denoiser_changed_image": bool(np.abs(denoised - noisy).max() > 0)})
    return {"denoise_seconds": denoise_seconds, "rows": rows, "images": images,
            "failures": failures}


# -- Errors --------------------------------------------------------------------------------------
def block_means(image: np.ndarray, grid=GRID) -> np.ndarray:
    """(H, W, C) -> (GY, GX) means over equal blocks and the channels."""
    h, w, c = image.shape
    gy, gx = grid
    return image.reshape(gy, h // gy, gx, w // gx, c).mean(axis=(1, 3, 4))


def box_downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """(H, W, C) -> (H / factor, W / factor, C): the mean of each factor x factor block."""
    image = np.asarray(image, np.float64)
    if factor == 1:
        return image
    h, w, c = image.shape
    return image.reshape(h // factor, factor, w // factor, factor, c).mean(axis=(1, 3))


def errors(image: np.ndarray, ref: np.ndarray, ref_var: float | None) -> dict:
    diff = np.asarray(image, np.float64) - ref
    mse = float(np.mean(diff * diff))
    mean_ref = float(ref.mean())
    out = {"mse": mse, "rel_rmse": math.sqrt(mse) / mean_ref}
    if ref_var is not None:
        out["rel_rmse_corrected"] = math.sqrt(max(mse - ref_var, 0.0)) / mean_ref
    ratio = block_means(np.asarray(image, np.float64)) / block_means(ref)
    out["block_ratios"] = ratio.round(5).tolist()
    out["worst_block"] = float(np.abs(ratio - 1.0).max())
    return out


# -- Reference -----------------------------------------------------------------------------------
def stored_reference(name: str, resolution) -> dict | None:
    path = STORED_REFERENCES / f"{name}.npz"
    if tuple(resolution) != STORED_RESOLUTION or not path.is_file():
        return None
    data = np.load(path)
    image = data["image"].astype(np.float64)
    if image.shape[:2] != (resolution[1], resolution[0]):
        return None
    settings = json.loads(str(data["settings"]))
    grid = tuple(int(v) for v in data["grid"])
    npix = (image.shape[0] // grid[0]) * (image.shape[1] // grid[1])
    # region_se_pixels = sqrt(block mean of the mean pixel's variance) / sqrt(npix)
    ref_var = float(np.mean(data["region_se_pixels"] ** 2 * npix))
    seeds = settings.get("seeds", [])
    return {"image": image, "variance": ref_var,
            "source": f"stored {path.relative_to(REPO)}: Cycles {len(seeds)} seeds x "
                      f"{settings.get('samples')} spp",
            "samples": int(settings.get("samples", 0)) * max(1, len(seeds)),
            "seconds": None}


def seed_render_path(name: str, resolution, seed: int, samples: int) -> Path:
    """Where one seed's Cycles render is cached: ``<scene>_<W>x<H>_seed<seed>_<spp>.npz`` with
    ``image`` (float32, row 0 = top) and ``seconds``, the format ``tests/data/
    make_cycles_refs.py --reuse-dir`` reads, so the stored Scene 2 reference and this benchmark
    share the renders."""
    w, h = resolution
    return CACHE_DIR / f"{name}_{w}x{h}_seed{seed}_{samples}.npz"


def rendered_reference(name, bscene, resolution, samples, configure, render_exr, tmpdir) -> dict:
    """The mean of ``REFERENCE_SEEDS`` Cycles renders of ``samples`` / 2 spp each, every one
    rendered once and cached (``seed_render_path``), and the per-pixel variance of the mean
    from the seeds' difference."""
    per_seed = max(1, samples // len(REFERENCE_SEEDS))
    renders, seconds, fresh = [], 0.0, False
    for seed in REFERENCE_SEEDS:
        path = seed_render_path(name, resolution, seed, per_seed)
        if path.is_file():
            with np.load(path) as data:
                img, dt = data["image"].astype(np.float64), float(data["seconds"])
        else:
            log(f"  reference: Cycles {per_seed} spp, seed {seed} ...")
            configure(bscene, per_seed, seed, gi=True)
            with _blender_output_to(os.path.join(tmpdir, "blender.log")):
                img, dt = render_exr(bscene, os.path.join(tmpdir, f"ref_{name}_{seed}.exr"))
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(path.stem + ".tmp.npz")
            np.savez_compressed(tmp, image=img.astype(np.float32), seconds=dt)
            os.replace(tmp, path)
            fresh = True
        renders.append(img)
        seconds += dt
    a, b = renders
    image = (a + b) / 2
    ref_var = float(np.mean((a - b) ** 2) / 4)     # variance of the 2-seed mean, per pixel
    how = "rendered now, cached" if fresh else "cached"
    return {"image": image, "variance": ref_var,
            "source": f"{how} as {CACHE_DIR}/{name}_{resolution[0]}x{resolution[1]}_seed"
                      f"<{'|'.join(map(str, REFERENCE_SEEDS))}>_{per_seed}.npz: Cycles "
                      f"{len(REFERENCE_SEEDS)} seeds x {per_seed} spp", "samples": samples,
            "seconds": seconds}


# -- One scene -----------------------------------------------------------------------------------
def build_seed_scene(name: str, resolution):
    """The seed scene ``name`` built in bpy (``seed_scenes.build``) at ``resolution`` (W, H),
    100 %; a scene that cannot be built is a ``BenchError``."""
    import bpy

    from ..engine.blender import seed_scenes

    w, h = resolution
    try:
        bscene = seed_scenes.build(name)
        bscene.render.resolution_x, bscene.render.resolution_y = w, h
        bscene.render.resolution_percentage = 100
        bpy.context.view_layer.update()
    except Exception as exc:  # noqa: BLE001 - reported as one line
        raise BenchError(f"scene {name!r} cannot be built: {' '.join(str(exc).split())}") from None
    return bscene


def bench_scene(name, resolution, cycles_samples, reference_samples, cycles, tmpdir,
                warm: dict, compare=None) -> dict:
    import bpy

    from ..engine.blender.export import export_scene
    from ..engine.pipeline import RenderSettings, render
    from ..engine.scene import SceneError

    configure, render_exr, _source = cycles
    w, h = resolution
    compare = tuple(compare or resolution)
    factor = w // compare[0]
    bscene = build_seed_scene(name, (w, h))

    out = {"scene": name, "resolution": [w, h], "compare_at": list(compare),
           "downsample_factor": factor, "rows": [], "failures": []}
    # Lanterna
    log(f"{name}: Lanterna, preset final ...")
    try:
        t0 = time.perf_counter()
        scene = export_scene(bpy.context.evaluated_depsgraph_get())
        export_seconds = time.perf_counter() - t0
        settings = RenderSettings(preset="final", seed=LANTERNA_SEED)
        t0 = time.perf_counter()
        result = render(scene, settings)
        seconds = time.perf_counter() - t0
    except SceneError as exc:
        raise BenchError(f"scene {name!r}: Lanterna cannot render it: "
                         f"{' '.join(str(exc).split())}") from None
    rep = result.report
    images = {("lanterna", None, False): np.asarray(result.image, np.float64)}
    out["rows"].append({
        "method": "Lanterna", "preset": "final", "samples": rep["settings"]["samples"],
        "denoiser": False, "seconds": seconds, "export_seconds": export_seconds,
        "stages": {k: v["seconds"] for k, v in rep["stages"].items()},
        "settings": rep["settings"], "warnings": rep.get("warnings", []),
        "peak_memory_mb": rep.get("peak_memory_mb")})

    # Cycles
    curve = cycles_curve(bscene, name, (w, h), cycles_samples, cycles, tmpdir, warm)
    out["denoise_seconds"] = curve["denoise_seconds"]
    out["rows"].extend(curve["rows"])
    out["failures"].extend(curve["failures"])
    images.update(curve["images"])
    out["cycles_settings"] = {k: v for k, v in configure(bscene, 1, CYCLES_SEED, gi=True).items()
                              if k not in ("samples", "seed")}

    # Reference and errors, at the comparison resolution
    ref = stored_reference(name, compare)
    if ref is None:
        bscene.render.resolution_x, bscene.render.resolution_y = compare
        try:
            ref = rendered_reference(name, bscene, compare, reference_samples, configure,
                                     render_exr, tmpdir)
        finally:
            bscene.render.resolution_x, bscene.render.resolution_y = w, h
    ref_image = ref["image"]
    mean_ref = float(ref_image.mean())
    out["reference"] = {"source": ref["source"], "samples": ref["samples"],
                        "seconds": ref["seconds"], "mean": mean_ref,
                        "pixel_variance": ref["variance"],
                        "rel_rms_noise": math.sqrt(ref["variance"]) / mean_ref}
    for row in out["rows"]:
        key = (("lanterna", None, False) if row["method"] == "Lanterna"
               else ("cycles", row["samples"], row["denoiser"]))
        row.update(errors(box_downsample(images[key], factor), ref_image, ref["variance"]))
    # Cross-check of the reference noise: Cycles' MSE = V / spp + v at 64 and 256 spp. JSON
    # only: fragile (Cycles' QMC error can fall faster than 1/spp, fireflies make MSE noisy).
    by = {(r["samples"], r["denoiser"]): r for r in out["rows"] if r["method"] == "Cycles"}
    if (64, False) in by and (256, False) in by:
        m64, m256 = by[(64, False)]["mse"], by[(256, False)]["mse"]
        v_fit = (m256 * 256 - m64 * 64) / (256 - 64)
        out["reference"]["pixel_variance_fit_from_cycles"] = v_fit
        out["reference"]["rel_rms_noise_fit_from_cycles"] = (
            math.sqrt(v_fit) / mean_ref if v_fit > 0 else 0.0)

    # The checks
    lan = out["rows"][0]
    c256 = by.get((CHECK_SAMPLES, False))
    if c256 is None:
        out["checks"] = {"skipped": f"no Cycles {CHECK_SAMPLES} spp render without denoiser"}
    else:
        checks = {
            "rmse_ratio": lan["rel_rmse"] / c256["rel_rmse"],
            "rmse_ok": lan["rel_rmse"] <= c256["rel_rmse"],
            "time_ratio": lan["seconds"] / c256["seconds"],
        }
        checks["time_ok"] = checks["time_ratio"] <= TIME_FRACTION
        if c256.get("rel_rmse_corrected"):
            checks["rmse_ratio_corrected"] = lan["rel_rmse_corrected"] / c256["rel_rmse_corrected"]
        out["checks"] = checks
    return out


# -- Printing ------------------------------------------------------------------------------------
def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:6.2f} %"


def print_scene(out: dict) -> None:
    w, h = out["resolution"]
    ref = out["reference"]
    k = out.get("downsample_factor", 1)
    where = f"at {w}x{h}"
    if k > 1:
        cw, ch = out["compare_at"]
        where = (f"rendered and timed at {w}x{h}; errors at {cw}x{ch} after {k}x{k} box "
                 f"downsampling of every image")
    print(f"\n{SCENE_TITLES.get(out['scene'], out['scene'])} ({out['scene']}) {where}")
    print(f"  reference: {ref['source']}; its per-pixel noise: RMS "
          f"{_pct(ref['rel_rms_noise']).strip()} of the mean")
    if out["scene"] == "scene2" and ref["source"].startswith("stored"):
        print("  note: Scene 2's stored reference is noisy (worst 4x4 block SE 2 %, "
              "tests/data/README.md); read the corrected column")
    print(f"  {'method':9s} {'samples':>8s} {'denoiser':>8s} {'seconds':>8s} {'rel RMSE':>9s}"
          f" {'corrected':>9s} {'worst block':>11s}")
    for r in out["rows"]:
        samples = f"final/{r['samples']}" if r["method"] == "Lanterna" else str(r["samples"])
        den = "OIDN" if r["denoiser"] else "off"
        if r["method"] == "Lanterna":
            den = "-"
        print(f"  {r['method']:9s} {samples:>8s} {den:>8s} {r['seconds']:8.2f} "
              f"{_pct(r.get('rel_rmse')):>9s} {_pct(r.get('rel_rmse_corrected')):>9s} "
              f"{_pct(r.get('worst_block')):>11s}")
        if r.get("denoiser") and r.get("denoiser_changed_image") is False:
            print("    ^ the denoiser left the image unchanged: OIDN did not run")
    lan = out["rows"][0]
    print("  Lanterna stages [s]: " + ", ".join(
        f"{k} {v:.2f}" for k, v in lan["stages"].items() if v >= 0.005)
        + f"; export {lan['export_seconds']:.2f} s (not counted)")
    c = out["checks"]
    if "skipped" in c:
        print(f"  checks skipped: {c['skipped']}")
        return
    corr = (f", corrected {c['rmse_ratio_corrected']:.2f}" if "rmse_ratio_corrected" in c else "")
    print(f"  check 1: Lanterna RMSE <= Cycles-{CHECK_SAMPLES} RMSE: ratio {c['rmse_ratio']:.2f}"
          f"{corr} -> {'PASS' if c['rmse_ok'] else 'FAIL'}")
    print(f"  check 2: Lanterna time <= 1/4 of Cycles-{CHECK_SAMPLES}'s: ratio {c['time_ratio']:.3f}"
          f" (need <= {TIME_FRACTION}) -> {'PASS' if c['time_ok'] else 'FAIL'}")


# -- Command line --------------------------------------------------------------------------------
def parse_resolution(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise BenchError(f"--resolution must look like 160x120, got {text!r}") from None
    if w < GRID[1] or h < GRID[0] or w % GRID[1] or h % GRID[0]:
        raise BenchError(f"--resolution {w}x{h}: width and height must be multiples of "
                         f"{GRID[1]} and {GRID[0]} (the 4 x 4 block grid)")
    return w, h


def _compare_at(text, resolution):
    """``--compare-at`` -> (resolution, integer factor); refuses a non-integer factor."""
    if text is None:
        return tuple(resolution), 1
    try:
        cw, ch = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise BenchError(f"--compare-at must look like 160x120, got {text!r}") from None
    w, h = resolution
    if cw < 1 or ch < 1 or w % cw or h % ch or w // cw != h // ch:
        raise BenchError(f"--compare-at {cw}x{ch}: needs one integer downsampling factor from "
                         f"--resolution {w}x{h}, got {w}/{cw} = {w / cw:g} and "
                         f"{h}/{ch} = {h / ch:g}")
    if cw < GRID[1] or ch < GRID[0] or cw % GRID[1] or ch % GRID[0]:
        raise BenchError(f"--compare-at {cw}x{ch}: width and height must be multiples of "
                         f"{GRID[1]} and {GRID[0]} (the 4 x 4 block grid)")
    return (cw, ch), w // cw


def int_list(text: str, flag: str):
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise BenchError(f"{flag} must be a comma-separated list of integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise BenchError(f"{flag} must list integers >= 1, got {text!r}")
    return values


def parse_args(argv):
    parser = Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", default="x".join(map(str, DEFAULT_RESOLUTION)))
    parser.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    parser.add_argument("--cycles-samples", default=",".join(map(str, DEFAULT_CYCLES_SAMPLES)))
    parser.add_argument("--reference-samples", default=str(DEFAULT_REFERENCE_SAMPLES))
    parser.add_argument("--compare-at", default=None, metavar="WxH",
                        help="box-downsample every image by the integer factor to WxH and "
                             "compare there (e.g. --resolution 640x480 --compare-at 160x120)")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    args.resolution = parse_resolution(args.resolution)
    args.compare_at, args.factor = _compare_at(args.compare_at, args.resolution)
    args.scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    if not args.scenes:
        raise BenchError("--scenes is empty")
    args.cycles_samples = int_list(args.cycles_samples, "--cycles-samples")
    ref = int_list(args.reference_samples, "--reference-samples")
    if len(ref) != 1 or ref[0] < 2:
        raise BenchError("--reference-samples must be one integer >= 2")
    args.reference_samples = ref[0]
    return args


def run(args) -> tuple[dict, int]:
    try:
        import bpy  # noqa: F401
        import OpenEXR  # noqa: F401
    except ImportError as exc:
        raise BenchError(f"needs bpy and OpenEXR: {exc}") from None
    from ..engine import imageio

    if args.json and (problem := imageio.output_problem(args.json)):
        raise BenchError(f"--json {args.json}: {problem}")
    cycles = cycles_functions()
    results = {"resolution": list(args.resolution), "compare_at": list(args.compare_at),
               "downsample_factor": args.factor, "cycles_samples": args.cycles_samples,
               "cycles_settings_source": cycles[2], "oidn_in_build": oidn_available(),
               "definitions": {
                   "rel_rmse": "sqrt(mean((img - ref)^2)) / mean(ref), all pixels and channels",
                   "rel_rmse_corrected": "sqrt(max(MSE - v, 0)) / mean(ref), v = reference's "
                                         "per-pixel noise variance",
                   "worst_block": "max over 4x4 blocks of |mean(img)/mean(ref) - 1|, means over "
                                  "the block's pixels and channels",
                   "seconds": "wall time of pipeline.render (Lanterna) / "
                              "bpy.ops.render.render(write_still=True) (Cycles), at "
                              "'resolution'",
                   "compare_at": "errors computed at this resolution, every image (Lanterna's "
                                 "and Cycles') box-downsampled by 'downsample_factor' first: a "
                                 "proxy, not the per-pixel error at 'resolution'"},
               "scenes": {}, "errors": []}
    print(f"Lanterna (preset final) vs Cycles (CPU, {cycles[2]}) at "
          f"{args.resolution[0]}x{args.resolution[1]}; OIDN in this bpy: "
          f"{'yes' if results['oidn_in_build'] else 'NO'}")
    if args.factor > 1:
        cw, ch = args.compare_at
        k = args.factor
        print(f"errors at {cw}x{ch} after {k}x{k} box downsampling: every image (Lanterna's and "
              f"Cycles') rendered and timed at {args.resolution[0]}x{args.resolution[1]}, then "
              f"averaged over {k}x{k} pixel blocks and compared with the {cw}x{ch} reference; "
              f"fair between the methods, but a proxy, not the per-pixel error at "
              f"{args.resolution[0]}x{args.resolution[1]}")
    print("rel RMSE = sqrt(mean((img - ref)^2)) / mean(ref) over all pixels and channels;"
          " corrected = with the reference's own noise variance taken out;"
          " worst block = max |block mean / reference - 1| over 4x4 blocks")
    status = 0
    with tempfile.TemporaryDirectory(prefix="lanterna_vs_cycles_") as tmpdir:
        warm: dict = {}
        for name in args.scenes:
            try:
                out = bench_scene(name, args.resolution, args.cycles_samples,
                                  args.reference_samples, cycles, tmpdir, warm,
                                  compare=args.compare_at)
            except BenchError as exc:
                print(f"lanterna bench: error: {exc}", file=sys.stderr)
                results["errors"].append(str(exc))
                status = 2
                continue
            results["scenes"][name] = out
            results["errors"].extend(out["failures"])
            if out["failures"]:
                status = 2
            print_scene(out)
    if args.json:
        imageio.write_json(args.json, results)
        print(f"\nwrote {args.json}")
    return results, status


def main(argv=None) -> int:
    return run_command(lambda a: run(parse_args(a))[1],
                       list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
