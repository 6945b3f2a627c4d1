"""Material parity with Cycles (issue 23): Lanterna's ``final`` preset against the all-bounce
Cycles references of ``tests/data/make_material_refs.py`` (scenes: ``tests/material_scenes.py``),
4 x 4 region means of luminance, bright regions (over a tenth of the brightest) within the
issue's bound.

Measured (seed 1, ``final``; worst bright region, then the whole image's ratio):

===============  =====  ==========================  ==========================  ============
scene            bound  seed materials (before)     glossy camera paths (now)   status
===============  =====  ==========================  ==========================  ============
factory_cube     2 %    5.9 %  (1.027)              0.3 %  (1.0005)             passes
principled_room  2 %    9.3 %  (0.975, 0.955 blue)  3.9 %  (0.987, 0.974 blue)  open
metal_sphere     3 %    82.1 % (0.70)               4.6 %  (0.980)              open
mix_floor        3 %    80.3 % (0.69)               7.0 %  (1.006, 0.955 blue)  open
===============  =====  ==========================  ==========================  ============

What is left (issue 23): photons and the final gather still see a Principled specular layer as
part of the diffuse base, and rough metal and glossy as mirrors (their camera-visible lobes are
right, their light onto other surfaces is not); the glass scene needs refraction. Those cases
are strict xfails: they fail this file the day they start to pass, so their bound becomes a
test. The references' own noise is at most 0.3 % a region (their manifest).
"""
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import material_scenes  # noqa: E402
from test_parity_cycles import block_means  # noqa: E402

REF_DIR = HERE / "data" / "cycles_materials"
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def worst_bright_region(name, seed=1):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    material_scenes.build(name)
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    ref = np.load(REF_DIR / f"{name}.npz")
    grid = tuple(int(v) for v in ref["grid"])
    image = np.asarray(render(scene, RenderSettings(seed=seed, preset="final")).image,
                       np.float64)
    assert np.all(np.isfinite(image))
    ours = block_means(image, grid) @ LUMINANCE
    theirs = ref["region_mean"] @ LUMINANCE
    bright = theirs > 0.1 * theirs.max()
    return float(np.abs(ours[bright] / theirs[bright] - 1).max())


def test_factory_cube_matches_cycles_within_2_percent():
    """Blender's startup file untouched: the default Principled cube (a GGX dielectric layer
    over a 0.8 base) under the 1000 W point light and the grey world."""
    assert worst_bright_region("factory_cube") <= 0.02


# name: (the issue's bound, today's guard, what is left). The guard is today's figure plus a
# margin for one seed's noise (region noise at ``final`` about 1 %): it catches regressions
# while the issue's bound is still open (a strict xfail: it fails the day the bound is met,
# so that the bound then becomes the test).
OPEN = {
    "principled_room": (0.02, 0.06, "photons and the gather leave the walls' specular layers "
                                    "out of the indirect light"),
    "metal_sphere": (0.03, 0.07, "photons and the gather see the rough copper as a mirror"),
    "mix_floor": (0.03, 0.09, "photons and the gather see the rough glossy floor as a mirror"),
}


@pytest.mark.parity
@pytest.mark.parametrize("name", list(OPEN))
def test_open_material_scenes_do_not_regress(name):
    assert worst_bright_region(name) <= OPEN[name][1]


@pytest.mark.parity
@pytest.mark.xfail(strict=True, reason="issue 23 open: the indirect light of glossy materials")
@pytest.mark.parametrize("name", list(OPEN))
def test_open_material_scenes_meet_the_issue_bound(name):
    assert worst_bright_region(name) <= OPEN[name][0]
