"""Render settings, the quality presets and the camera's blocks: the one source every other
part reads (a leaf: imports nothing of Lanterna).

What it holds
    ``RenderSettings``  every setting of a render with its default, range and meaning (the
        table below is ``SETTINGS``, read from the fields' metadata: Blender's properties
        (``ui/properties.py``), the command line (``engine/blender/cli.py``) and
        ``RenderSettings.validate`` all take their defaults and limits from it).
    ``PRESETS``  ``preview`` and ``final``: samples, light samples, photons, gather and cache
        error set together (measured time and error on the seed scenes: docs/performance.md).
    ``auto_lookups(pixels, samples)``  camera samples per pixel that ask for indirect light
        when ``photon_lookups`` is 0: about ``LOOKUP_BUDGET`` look-ups per image.
    ``camera_blocks(camera, samples)``  the square blocks of the full frame that the camera
        stage shades as batches (64 x 64 pixels at 16 spp), numbered so that a block's random
        stream does not depend on the render border (tiles of a still reassemble exactly).

Settings (``RenderSettings``; units in brackets)
    =====================  ========  ===========================================================
    name                   default   meaning
    =====================  ========  ===========================================================
    mode                   full      ``full`` (exact direct + indirect light) or ``photon-map``
                                     (all light from the photon map, seen directly; seed 9.5)
    samples                16        camera samples per pixel (1-65536)
    noise_threshold        0.0       adaptive sampling: a pixel whose noise (Cycles' estimate,
                                     ``integrator.shade_adaptive``) is above it gets 2-16x the
                                     samples (a block at most 1.5x its samples); 0 = off
    light_samples          4         samples per shading point shared by area/mesh/world lights
    bounces                128       most bounces of light; 0 = direct light only. Photon paths
                                     end after this many bounces (counted in the report); 128
                                     keeps a rho = 0.95 enclosure within 0.2 % (0.95^130; 64
                                     left it 3.4 % dark)
    seed                   0         random seed; same seed, same image
    threads                0         worker threads; 0 = all cores
    filter_width           1.5       Blackman-Harris pixel filter width [px]
    max_specular_depth     8         perfect-mirror reflections followed from the camera
    photons                0         photons emitted; 0 = automatic: 2 per pixel, 200k-2M
    photon_k               50        photons per estimate (k nearest, Eq. 9.11)
    photon_radius          0.0       cap on the estimate's radius [m]; 0 = automatic (4x the
                                     radius holding k photons spread evenly over the scene)
    photon_filter          none      ``none`` or ``cone`` (Jensen's cone filter, k = 1.1)
    photon_lookups         0         camera samples per pixel that ask for indirect light;
                                     0 = automatic (``auto_lookups``)
    indirect               cache     ``full`` mode's indirect light: ``cache`` (irradiance cache
                                     over the final gather, seed ch. 10), ``gather`` (a final
                                     gather per look-up, ch. 8) or ``photon-map`` (the estimate
                                     at the hit)
    gather_m, gather_n     8, 32     final gather strata in theta and phi (M x N rays)
    cache_error            0.2       irradiance cache error a: records serve where w > 1/a
    cache_gradients        True      interpolate with the records' gradients (Eq. 10.5)
    cache_refine           True      records that a neighbour's gather contradicts reach less
                                     far, so indirect shadows get records of their own
    gather_guided          1.0       extra gather rays, as a multiple of M x N, steered by the
                                     nearby photons' directions (Jensen 1995); 0 = off
    shadow_photons         True      lit / penumbra / umbra classes from shadow photons (9.6)
    force                  ""        comma-separated stages to run although the plan skips
                                     them (checks that a skip changes nothing)
    preset                 custom    ``preview`` / ``final`` set samples, light samples,
                                     photons, gather and cache error together
    =====================  ========  ===========================================================
"""
from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass, field, fields, replace

import numpy as np

from .scene import SceneError

__all__ = ["Setting", "RenderSettings", "SETTINGS", "PRESETS", "MODES",
           "INDIRECT_METHODS", "PHOTON_FILTERS", "CONE_FILTER_K", "MAX_PHOTONS",
           "LOOKUP_BUDGET", "auto_lookups", "TARGET_BATCH_SAMPLES", "ADAPTIVE_LEVELS",
           "ADAPTIVE_BUDGET", "CameraBlock",
           "block_side", "camera_blocks"]


@dataclass(frozen=True)
class Setting:
    """One setting's contract: its label and description (Blender's tooltip, the CLI's help),
    limits, and for a choice its values as (core name, label, description)."""

    label: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    soft_max: float | None = None       # Blender's slider end (the hard limit stays maximum)
    choices: tuple = ()
    unit: str = "NONE"                  # Blender subtype: 'NONE' or 'DISTANCE' [m]
    precision: int | None = None        # decimals Blender shows for a float
    exposed: bool = True                # a property in Blender and a flag of the CLI

    def allowed(self) -> str:
        """What the setting allows, for messages: '(one of a, b)', '(1-65,536)', ..."""
        if self.choices:
            return f"(one of {', '.join(c[0] for c in self.choices)})"
        if self.minimum is not None and self.maximum is not None:
            return f"({_number(self.minimum)}-{_number(self.maximum)})"
        return ""


def _number(value) -> str:
    return f"{int(value):,}" if float(value).is_integer() else f"{value:g}"


def _setting(default, label, description, minimum=None, maximum=None, **more):
    return field(default=default, metadata={"setting": Setting(label, description, minimum,
                                                               maximum, **more)})


MODE_CHOICES = (
    ("full", "Full", "Exact direct light plus indirect light from the photon map"),
    ("photon-map", "Photon Map",
     "All light from the photon map, seen directly (fast, noisy; seed section 9.5)"),
)
INDIRECT_CHOICES = (
    ("cache", "Irradiance Cache",
     "Final gather at cached records, interpolated with gradients (seed chapter 10)"),
    ("gather", "Final Gather", "A final gather at every looked-up sample (slow, reference "
                               "quality)"),
    ("photon-map", "Photon Map", "The photon map's estimate at the hit (fast, blotchy)"),
)
FILTER_CHOICES = (
    ("none", "None", "Every photon in the disc counts fully"),
    ("cone", "Cone", "Nearer photons count more (Jensen's cone filter, k = 1.1): sharper "
                     "edges, a little more noise"),
)
PRESET_CHOICES = (
    ("custom", "Custom", "Use the settings below"),
    ("preview", "Preview", "Fast: 4 spp, 200k photons, gather 6x24, cache error 0.3"),
    ("final", "Final", "16 spp (adaptive, noise threshold 0.01), 1M photons, gather 12x48, "
                       "cache error 0.1"),
)
MODES = tuple(c[0] for c in MODE_CHOICES)
INDIRECT_METHODS = tuple(c[0] for c in INDIRECT_CHOICES)
PHOTON_FILTERS = tuple(c[0] for c in FILTER_CHOICES)
CONE_FILTER_K = 1.1
MAX_PHOTONS = 50_000_000
INT_MAX = 2 ** 31 - 1

# Quality presets (issue 4): photons, gather M x N, cache error a, samples. Measured time and
# error on the seed's scenes: docs/performance.md. Final's noise threshold is Cycles' default
# (0.01), not fitted to any scene of ours.
PRESETS = {
    "preview": dict(samples=4, light_samples=2, photons=200_000, gather_m=6, gather_n=24,
                    cache_error=0.3, indirect="cache"),
    "final": dict(samples=16, light_samples=8, photons=1_000_000, gather_m=12, gather_n=48,
                  cache_error=0.1, indirect="cache", noise_threshold=0.01),
}


@dataclass
class RenderSettings:
    """A render's settings (module docstring); ``SETTINGS`` holds each one's contract."""

    mode: str = _setting("full", "Mode", "How light is computed", choices=MODE_CHOICES)
    samples: int = _setting(16, "Samples", "Camera samples per pixel", 1, 65536,
                            soft_max=4096)
    noise_threshold: float = _setting(0.0, "Noise Threshold",
                                      "Adaptive sampling: pixels whose noise (Cycles' "
                                      "estimate) is above this get 2-16x the samples, within "
                                      "1.5x a block's samples in all; 0 = off", 0.0, 1.0,
                                      soft_max=0.1, precision=4)
    light_samples: int = _setting(4, "Light Samples",
                                  "Samples per area/mesh/world light per camera hit",
                                  1, 65536, soft_max=256)
    bounces: int = _setting(128, "Max Bounces",
                            "Most bounces of light between surfaces (0 = direct light only); "
                            "photon paths end after this many", 0, 255, soft_max=128)
    seed: int = _setting(0, "Seed", "Seed of the random sequences; the same seed gives the "
                                    "same image", 0, INT_MAX)
    threads: int = _setting(0, "Threads", "Worker threads (0 = automatic: one per CPU core)",
                            0, 1024, soft_max=64)
    filter_width: float = _setting(1.5, "Filter Width",
                                   "Blackman-Harris pixel filter width in pixels", 0.0, 10.0,
                                   exposed=False)
    max_specular_depth: int = _setting(8, "Mirror Depth", "Perfect-mirror reflections "
                                       "followed from the camera", 0, 255, exposed=False)
    photons: int = _setting(0, "Photons", "Photons emitted from the lights (0 = automatic: "
                                          "two per pixel, 200k-2M)", 0, MAX_PHOTONS,
                            soft_max=10_000_000)
    photon_k: int = _setting(50, "Photons per Estimate",
                             "Nearest photons in each radiance estimate (Eq. 9.11)", 1, 10_000,
                             soft_max=500)
    photon_radius: float = _setting(0.0, "Max Radius",
                                    "Largest radius of a photon estimate in metres (0 = "
                                    "automatic, from the scene's area and the photon count)",
                                    0.0, 1.0e6, soft_max=10.0, unit="DISTANCE", precision=4)
    photon_filter: str = _setting("none", "Filter", "Weighting of the photons in an estimate",
                                  choices=FILTER_CHOICES)
    photon_lookups: int = _setting(0, "Lookups per Pixel",
                                   "Camera samples per pixel that ask the photon map; their "
                                   "estimate stands for the pixel's other samples (0 = "
                                   "automatic: about 300k look-ups per image)", 0, 65536,
                                   soft_max=64)
    indirect: str = _setting("cache", "Indirect", "How the full mode computes indirect light",
                             choices=INDIRECT_CHOICES)
    gather_m: int = _setting(8, "Gather Theta",
                             "Final gather: strata in the polar angle (M of M x N rays)", 1, 256,
                             soft_max=64)
    gather_n: int = _setting(32, "Gather Phi",
                             "Final gather: strata in the azimuth (N of M x N rays)", 1, 1024,
                             soft_max=256)
    cache_error: float = _setting(0.2, "Cache Error", "Irradiance cache: largest error a; "
                                  "records are used where w > 1/a (Eq. 10.3)", 0.01, 10.0,
                                  soft_max=1.0, precision=3)
    cache_gradients: bool = _setting(True, "Gradients",
                                     "Irradiance cache: extrapolate each record with its "
                                     "rotation and translation gradients (Ward and Heckbert "
                                     "1992, Eq. 10.5); off: plain weighted average of the "
                                     "records")
    cache_refine: bool = _setting(True, "Refine at Contrasts",
                                  "Irradiance cache: records whose extrapolation a "
                                  "neighbouring record's gather contradicts reach less far, so "
                                  "indirect shadows and sharp changes get records of their "
                                  "own; off: records placed by Ward's geometric weight only")
    gather_guided: float = _setting(1.0, "Guided Rays",
                                    "Final gather: extra rays, as a multiple of M x N, steered "
                                    "into the directions nearby photons came from (Jensen "
                                    "1995); 0 = off", 0.0, 64.0, soft_max=8.0, precision=2)
    shadow_photons: bool = _setting(True, "Shadow Photons",
                                    "Classify lit, penumbra and umbra with shadow photons to "
                                    "save shadow rays")
    force: str = _setting("", "Force Stages", "Comma-separated stages to run although the "
                                              "plan skips them", exposed=False)
    preset: str = _setting("custom", "Preset", "Quality preset: sets photons, gather, cache "
                                               "error and samples together",
                           choices=PRESET_CHOICES)

    def resolved(self) -> "RenderSettings":
        """A copy with the preset's values in place of the individual settings (``custom``:
        the settings as they are)."""
        if self.preset not in PRESETS and self.preset != "custom":
            raise SceneError(f"Render settings: preset = {self.preset!r} is not one of "
                                f"{', '.join(('custom',) + tuple(PRESETS))}")
        return replace(self, **PRESETS.get(self.preset, {}))

    def validate(self) -> "RenderSettings":
        """Every setting within its ``SETTINGS`` limits (numbers finite), else
        ``SceneError`` naming the first that is not, its value and what is allowed."""
        for name, spec in SETTINGS.items():
            value = getattr(self, name)
            if spec.choices:
                ok = value in tuple(c[0] for c in spec.choices)
            elif isinstance(value, bool) or isinstance(value, str):
                ok = True
            else:
                ok = (isinstance(value, numbers.Real) and math.isfinite(value)
                      and (spec.minimum is None or value >= spec.minimum)
                      and (spec.maximum is None or value <= spec.maximum))
            if not ok:
                extra = {"photons": " (0 = automatic)"}.get(name, "")
                raise SceneError(f"Render settings: {name} = {value!r} is out of range "
                                    f"{spec.allowed()}{extra}")
        return self

    @property
    def worker_count(self) -> int:
        return self.threads or os.cpu_count() or 1


SETTINGS: dict[str, Setting] = {f.name: f.metadata["setting"] for f in fields(RenderSettings)}


# -- Look-ups per pixel --------------------------------------------------------------------------
LOOKUP_BUDGET = 300_000      # photon-map look-ups per image when photon_lookups = 0


def auto_lookups(pixels: int, samples: int) -> int:
    """Camera samples per pixel that ask the photon map by default: about ``LOOKUP_BUDGET``
    look-ups per image (a small preview gets every sample looked up, a 640 x 480 render one
    per pixel), between 1 and ``samples``."""
    return int(min(samples, max(1, -(-LOOKUP_BUDGET // max(int(pixels), 1)))))


# -- The camera's blocks ---------------------------------------------------------------------------
TARGET_BATCH_SAMPLES = 1 << 16
# Adaptive sampling (``integrator.shade_adaptive``): a noisy pixel's extra samples, in
# multiples of the samples (it ends with 2, 4, 8 or 16 x as many: whole runs of the (0, 2)-
# sequence), and the most extra samples a block may take, in multiples of its samples (a
# block of noise everywhere costs at most 1.5x its time).
ADAPTIVE_LEVELS = (1, 3, 7, 15)
ADAPTIVE_BUDGET = 0.5


@dataclass
class CameraBlock:
    """One camera batch: a square block of the full frame (``camera``: the frame's camera
    with its border set to the block). ``index`` numbers the block in the full frame and
    seeds its random stream, so a block's pixels come out the same whatever render border
    (tile) it is rendered for; ``source`` picks the block's pixels inside the window and
    ``target`` says where they go in the window image (flat, row-major, top row first)."""

    index: int
    camera: object
    pixels: int
    source: object
    target: object


def block_side(samples: int) -> int:
    """A camera block's side B [px]: sqrt(TARGET_BATCH_SAMPLES / samples) rounded down to a
    multiple of 8, at least 8 (64 at 16 spp)."""
    return max(8, int(np.sqrt(TARGET_BATCH_SAMPLES / max(1, samples))) // 8 * 8)


def camera_blocks(camera, samples: int) -> list[CameraBlock]:
    """The full-frame blocks that meet ``camera``'s render window, in window order. A block
    is B x B pixels (``block_side``), clipped to the frame; blocks are numbered row by row
    from the frame's bottom-left, as Blender counts border coordinates."""
    side = block_side(samples)
    full_w, full_h = camera.resolution
    wx0, wy0, wx1, wy1 = camera.border
    win_w = wx1 - wx0
    columns = -(-full_w // side)
    out = []
    for by in range(wy0 // side, -(-wy1 // side)):
        for bx in range(wx0 // side, -(-wx1 // side)):
            x0, y0 = bx * side, by * side
            x1, y1 = min(x0 + side, full_w), min(y0 + side, full_h)
            bw = x1 - x0
            # the block's pixels inside the window: block rows run top-down from y1 - 1
            ys = np.arange(max(y0, wy0), min(y1, wy1))
            xs = np.arange(max(x0, wx0), min(x1, wx1))
            yy, xx = np.meshgrid(ys, xs, indexing="ij")
            source = ((y1 - 1 - yy) * bw + (xx - x0)).ravel()
            target = ((wy1 - 1 - yy) * win_w + (xx - wx0)).ravel()
            out.append(CameraBlock(index=by * columns + bx,
                                   camera=replace(camera, border=(x0, y0, x1, y1)),
                                   pixels=bw * (y1 - y0), source=source, target=target))
    # window order (top rows first), so progress sweeps down the picture
    out.sort(key=lambda b: (-b.camera.border[1], b.camera.border[0]))
    return out
