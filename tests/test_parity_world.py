"""HDRI-world parity with Cycles (issue 24): Lanterna's ``final`` preset against the Cycles
reference of ``tests/data/make_world_refs.py`` (scenes: ``tests/world_scenes.py``), 4 x 4
region means of luminance, bright regions (over a tenth of the brightest) within the issue's
bounds: 2 % for the yard, 3 % for the portal interior.

Measured 2026-12-06 (``final``, with its adaptive sampling; worst bright region; the whole
image's ratio), yard reference 4 x 512 spp, worst region relative SE 0.028 %; light samples
from the sun's bright patches alone (``environment.Environment.bright``), the rest of the sky
by the final gather on the yard (``lights.EnvironmentLight.gather_sky``) and by cosine
samples in window_room (its portal keeps the sky a light):

===========  =====  ===============  ===============  ===============  ===============
scene        bound  seed 1           seed 2           seed 3           seed 4
===========  =====  ===============  ===============  ===============  ===============
yard         2 %    0.82 % (0.9982)  1.08 % (0.9977)  1.31 % (0.9974)  1.14 % (0.9979)
window_room  3 %    0.62 % (0.9991)  1.37 % (1.0022)  1.15 % (1.0028)  1.09 % (0.9989)
===========  =====  ===============  ===============  ===============  ===============

(Before adaptive sampling, the gathered sky and light numbers stratified over a pixel's
samples: yard 0.95 / 1.02 / 1.11 / 0.91 %, window_room 0.86 / 1.91 / 1.94 / 1.17 %; light
samples from the table of all patches, as photons draw them: yard 0.95 / 1.07 / 0.89 /
0.81 %, window_room 1.91 / 2.06 / 2.54 / 1.47 %; with the row / column CDF sampler before
that: yard 0.75 / 1.20 / 0.71 %, window_room 1.63 / 1.68 / 1.90 / 2.64 % at seeds 1-4.)

``window_room`` (an interior lit only through a window with a light portal): reference
4 x 2048 spp, worst bright region relative SE 0.53 %. With the old sampler, over
seeds 1-4 the bright regions' means are within 1.1 % of Cycles and their spread (SD) is
0.5-1.6 %, largest in the two regions the sun patch's edges cross (its direct light). Before
this test: 3.0 / 3.0 / 4.0 % at seeds 1-3 (whole image 0.983 / 0.990 / 0.986): sky photons
entered through the portals only, so the window's outer reveal (outside the portal, in the
wall's thickness), lit by sun and sky, was dark to the gather; ``photons.EXTERIOR_SHARE`` of
the world's photons now come from its disc outside the portals (whole image 0.989 / 0.998 /
1.000, worst 2.1 / 1.2 / 2.8 %, seed 4 4.8 %), and the portal strategy's share of the light
samples gives way to the CDF's where the CDF sees out through the window (``lights``'
``PORTAL_SHIFT``: the sun patch's direct light, block SD 2.6 -> 1.3 %).

Before issue 24 the same world exported as a flat colour (its Background Color, the image
ignored): the issue measured such an exterior at 0.03 x Cycles' mean.
"""
import sys
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import world_scenes  # noqa: E402
from test_parity_materials import render_against_reference, worst_bright_ratio  # noqa: E402

REF_DIR = HERE / "data" / "cycles_world"


def worst_bright_region(name, seed=1):
    def image_world(scene):
        assert scene.world.environment is not None, scene.warnings

    return worst_bright_ratio(*render_against_reference(name, seed, world_scenes, REF_DIR,
                                                        check=image_world))


@pytest.mark.parity
def test_hdri_yard_matches_cycles_within_2_percent():
    assert worst_bright_region("yard") <= 0.02


@pytest.mark.parity
def test_portal_interior_matches_cycles_within_3_percent():
    assert worst_bright_region("window_room") <= 0.03


@pytest.mark.parity
def test_hdri_court_a_validation_scene_matches_cycles_within_2_percent():
    """``court``: the image turned to put the sun elsewhere, other geometry and albedos; no
    parameter was tuned on it (``world_scenes`` docstring). Measured 2026-12-07 (reference
    4 x 512 spp, worst bright region relative SE 0.10 %): worst region 0.43 / 0.36 % at seeds
    1 and 2 (whole image 0.9987 / 0.9989)."""
    assert worst_bright_region("court") <= 0.02
