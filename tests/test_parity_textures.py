"""Texture parity with Cycles (issue 24): Lanterna's ``final`` preset against the all-bounce
Cycles references of ``tests/data/make_material_refs.py`` for ``tests/texture_scenes.py``.

* ``textured_room`` (image-textured Principled floor and back wall, an emission panel whose
  Emission Color is an image): every bright 4 x 4 region's mean luminance within the issue's
  2 % of Cycles'. Measured 2026-12-08 (``final``; the panel's light samples half by its
  texels' power, ``lights.TexturedTriangleEmitter``; photon estimates over their disc's
  covered part, ``Accelerator.disc_coverage``): worst region 1.04 / 0.92 / 1.48 / 1.03 /
  1.20 / 0.87 % at seeds 1-6, the whole image 0.996-1.000. Before those two (2026-12-07):
  1.36 / 1.63 / 2.15 / 1.11 / 1.69 / 1.57 %, the whole image 0.994-0.995; photons drawn
  uniformly over the panel, before that: 1.61 / 1.15 / 1.04 / 1.96 / 1.65 / 1.45 %.
* ``textured_gallery``, the validation scene (nothing was tuned on it: other images, UV ->
  Mapping with Cubic, Generated coordinates with Extend, a panel with two small bright
  spots, another viewpoint): worst region 1.36 / 0.94 / 0.94 / 1.30 % at seeds 1-4, the
  whole image 0.999-1.000. Before: 2.11 / 1.39 / 1.53 / 1.91 % (whole 0.996-0.998), its
  darkest bright region, by the cube's foot and the right wall, 1.7 % below Cycles on
  average. Two things kept it dark: photon estimates by an edge or a corner divided by the
  whole disc (the indirect light there 2-3 % low; Cycles' direct-only render showed the
  direct light within 0.5 %), and the spots, each 1/16 of the panel, lit through solid-angle
  samples of its two triangles.
* Sharpness: the floor's per-pixel rel-RMSE against Cycles (``FLOOR_ROWS``: the bottom rows,
  floor only) on the textured room is no worse than on ``plain_room``, whose floor is the
  image's mean colour: the cache and the photon map hold irradiance, and each pixel
  multiplies it by the albedo at its own hit. Measured 2026-12-08 (``lanterna bench
  --sharpness --seeds 4``): 2.80 / 2.81 / 2.73 / 2.86 % textured against 2.68 / 2.74 / 2.83
  / 2.94 % plain, the means equal (2.80 %); the per-seed difference scatters by 0.11 points
  (sd), so a one-seed comparison decides nothing. The test takes seeds 1 and 2 and allows
  the textured floor 4 sd of their mean difference (0.31 points) over the plain one: what
  a texture blurred by the cache would add to the textured floor alone. The textured floor's own pixel noise is the larger (2.42 % against 2.05 %: a pixel
  straddling a texel edge multiplies its samples' light noise by their different albedos);
  its mean image the closer (2.01 % against 2.12 %). Before (2026-12-07): 2.79 / 2.73 / 2.72
  / 2.75 % against 3.15 / 2.93 / 3.03 / 2.86 %: the plain floor gained 0.1-0.5 points
  from the changes of 2026-12-08 (estimates over their disc's covered part, the panel's
  light samples by texel power), the textured one none. Before adaptive sampling and light numbers
  stratified over a pixel's samples: 3.86 / 3.49 / 3.41 % against 3.50 / 3.56 / 3.48 %
  (seeds 1-3).

The references' own noise: relative SE at most 0.40 % (textured) and 0.34 % (plain) a region
(their manifest).
"""
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import texture_scenes  # noqa: E402
from test_parity_materials import render_against_reference, worst_bright_ratio  # noqa: E402

pytestmark = pytest.mark.parity

REF_DIR = HERE / "data" / "cycles_materials"
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
FLOOR_ROWS = slice(50, 60)        # of 60, row 0 = top: below the cube, floor only
_RENDERS: dict = {}


def _render(name, seed=1):
    if (name, seed) not in _RENDERS:
        _RENDERS[(name, seed)] = render_against_reference(name, seed, texture_scenes, REF_DIR)
    return _RENDERS[(name, seed)]


def test_textured_room_within_2_percent():
    worst = worst_bright_ratio(*_render("textured_room"))
    assert worst <= 0.02, worst


def test_textured_gallery_a_validation_scene_within_2_percent():
    worst = worst_bright_ratio(*_render("textured_gallery"))
    assert worst <= 0.02, worst


def _floor_rel_rmse(name, seed=1):
    image, ref = _render(name, seed)
    ours, theirs = image[FLOOR_ROWS] @ LUMINANCE, ref["image"][FLOOR_ROWS] @ LUMINANCE
    return float(np.sqrt(np.mean((ours - theirs) ** 2)) / np.sqrt(np.mean(theirs ** 2)))


SHARPNESS_SEEDS = (1, 2)
SHARPNESS_SLACK = 0.0031     # 4 sd of the mean of 2 seeds' differences (sd 0.0011 a seed)


def test_textured_floor_is_as_sharp_as_a_plain_one():
    textured = np.mean([_floor_rel_rmse("textured_room", s) for s in SHARPNESS_SEEDS])
    plain = np.mean([_floor_rel_rmse("plain_room", s) for s in SHARPNESS_SEEDS])
    assert textured <= plain + SHARPNESS_SLACK, (textured, plain)
