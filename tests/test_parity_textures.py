"""Texture parity with Cycles (issue 24): Lanterna's ``final`` preset against the all-bounce
Cycles references of ``tests/data/make_material_refs.py`` for ``tests/texture_scenes.py``.

* ``textured_room`` (image-textured Principled floor and back wall, an emission panel whose
  Emission Color is an image): every bright 4 x 4 region's mean luminance within the issue's
  2 % of Cycles'. Measured, seed 1: worst region 1.91 % (1.45 % before the emitter kept
  its own triangles and lookups went float32, a different realisation of the same
  estimator: seeds 2 and 3 give 1.13 % and 0.99 %, against 1.30 % and 1.42 % before).
* Sharpness (open, a strict xfail: 3.86 % / 3.49 % / 3.41 % textured against 3.50 % / 3.56 % /
  3.48 % plain at seeds 1 / 2 / 3, measured 2026-12-06 by ``lanterna bench --sharpness``;
  the test renders seed 1; what is known of the gap is in the xfail's reason): the
  floor's per-pixel rel-RMSE against Cycles (``FLOOR_ROWS``: the bottom rows,
  floor only) on the textured room is no worse than on ``plain_room``, whose floor is the
  image's mean colour: the cache and the photon map hold irradiance, and each pixel
  multiplies it by the albedo at its own hit.

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


def _floor_rel_rmse(name):
    image, ref = _render(name)
    ours, theirs = image[FLOOR_ROWS] @ LUMINANCE, ref["image"][FLOOR_ROWS] @ LUMINANCE
    return float(np.sqrt(np.mean((ours - theirs) ** 2)) / np.sqrt(np.mean(theirs ** 2)))


@pytest.mark.xfail(strict=True, reason="issue 24 open: the textured floor's rel-RMSE is 3.86 % "
                   "/ 3.49 % / 3.41 % against the plain floor's 3.50 % / 3.56 % / 3.48 % (seeds "
                   "1 / 2 / 3). Its detail is as sharp (the 3-seed mean images: 2.42 % against "
                   "2.48 %); the excess is noise (seed 1 minus seed 2, in this metric: 3.39 % "
                   "against 3.03 %), nearly all in Diffuse Direct (3.17 % against 2.89 %): the "
                   "albedo's own anti-aliasing noise adds 0.33 %, the direct irradiance 3.13 % "
                   "against 2.89 %, of which its per-pixel noise is 4.97 % against 4.84 % under "
                   "the same brightness weights and the rest the metric's (the bright texels' "
                   "noise counts more, while the glossy layer's light, alike on every texel, "
                   "dilutes it less); Diffuse Indirect 0.80 % against 0.60 %, cause not found")
def test_textured_floor_is_as_sharp_as_a_plain_one():
    textured, plain = _floor_rel_rmse("textured_room"), _floor_rel_rmse("plain_room")
    assert textured <= plain, (textured, plain)
