"""Material parity with Cycles (issue 23): Lanterna's ``final`` preset against the all-bounce
Cycles references of ``tests/data/make_material_refs.py`` (scenes: ``tests/material_scenes.py``),
4 x 4 region means of luminance, bright regions (over a tenth of the brightest) within the
issue's bound.

Measured (seed 1, ``final``; worst bright region, then the whole image's ratio):

===============  =====  ===================  ======================  =========================
scene            bound  seed materials       glossy camera paths     glass, caustic map, the
                        (before issue 23)    (d5d7b81)               layer in the transport
===============  =====  ===================  ======================  =========================
factory_cube     2 %    5.9 %  (1.027)       0.3 %  (1.0005)         0.22 % (1.0004)
principled_room  2 %    9.3 %  (0.975)       3.9 %  (0.987)          1.64 % (0.994); seed 2:
                                                                     1.25 %
metal_sphere     3 %    82.1 % (0.70)        4.6 %  (0.980)          3.56 % (1.009); light
                                                                     samples by sharpness:
                                                                     0.62 % (seeds 1-12: max
                                                                     1.33 %)
mix_floor        3 %    80.3 % (0.69)        7.0 %  (1.006)          1.55 % (0.999)
glass_caustic    5 %    99 %   (black ball)  -                       11.1 % (0.980); seed 2:
                                                                     17.6 %; split glass
                                                                     3.7 % (0.983)
===============  =====  ===================  ======================  =========================

What moved the last column: photons and gather rays now carry the Principled layer and the
glossy lobes (``bsdf.MaterialTable.transport_*``; gather rays read a layered wall's diffuse
at their own angle and continue by the layer), glossy lobes where a camera path ends read
their indirect light where their ray lands (``integrator._GlossyHits``), and the caustic map
carries light that mirrors, glossy surfaces and glass send from the lamps onto diffuse ones.

The glass scene's caustic (``material_scenes.CAUSTIC_REGION``, the floor lit only through the
ball) has a mean 6.3 % and 5.3 % below Cycles' at seeds 1 and 2 (the issue's bound: 10 %; it
was +3.0 % and +4.1 % before photons from the spot's Soft Falloff were dimmed at their first
hit as Cycles' facing disk is, which also took the floor around the caustic from 1.05-1.11 to
0.95-1.03). Its worst regions are the far floor behind the ball, 0.89-1.18 between seeds 1
and 2: noise (a larger caustic radius does not change it; gather rays through the ball that
see the bright caustic are the suspect). The copper sphere's worst region is the one holding its
highlight of the area light.

Multiple importance sampling of glossy direct light (``integrator``, issue 23) took the
copper sphere from 3.56 % / 1.77 % (seeds 1 / 2) to 3.07 % / 2.63 %: its worst region (row 1,
column 2, the highlight) is 1.036 / 1.018 of Cycles before and 1.031 / 1.026 after, a mean
of +2.7-2.9 % at both, so what keeps it over the 3 % bound is a bias of that region, not the
highlight's noise. The glass scene is unchanged (11.09 % / 17.60 %): its ball is a delta
lobe, which MIS leaves to its own rays, and its floor is diffuse.

Photons that go through a surface (glass, translucent) now leave from the hit itself: before,
pulled back along their way and pushed through by the same distance, some stayed on the
entry face and crossed it again. The glass scene's worst region went from 11.09 % / 17.60 %
to 7.73 % / 6.05 % (seeds 1 / 2). The copper sphere's highlight region over 14 seeds at
``final`` averages 1.000 of Cycles with a standard deviation of 2.2 % (seeds 1 and 2 are
+3.1 % and +2.6 %; four seeds of 14 fall outside 3 %, two each way): noise, not a bias; at
64 spp its deviation is 1.0 %. It is the glossy direct light's sampling (seeds 1-6 at
``final``, the two highlight regions over Cycles', standard deviation over seeds): 8 light
samples give 0.981-1.040 (1.5 % / 1.6 %), 64 light samples 0.987-1.009 (0.3 % / 0.8 %),
64 spp 0.985-1.008 (0.6 % / 0.9 %, seeds 1-4). Eight area-uniform samples of the 1 m light
put few in the narrow GGX lobe of the 20-pixel highlight. It is not the shadow photons (off:
0.949-1.020, 0.6 % / 2.4 %, seed 6 at 5.1 %) nor the caustic map (8 x its photons: the
same values to 0.001).

Glossy hits now take more light samples the sharper their lobes are (``integrator.
glossy_light_factor``: 8x for the Roughness 0.3 copper, 1x at Blender's default 0.5). The
copper sphere's worst region over seeds 1-12 at ``final``: 0.62, 0.79, 0.68, 1.17, 0.52,
1.33, 0.64, 1.02, 0.81, 0.71, 1.10, 1.25 % (before, seeds 1-6: 1.89, 2.18, 4.01, 1.44, 0.48,
2.17 %); the highlight regions' deviation over seeds 1-12 is 0.40 % / 0.74 % (was 1.5 % /
1.6 %), what 64 light samples everywhere gave, for +36 % render time where those took +90 %
(28.1 s against 20.9 s at seed 1; the Principled room +9 %). Seed 1 passed the bound before
too (1.89 %), so this test alone would not catch the fix undone: ``tests/test_mis.py``
guards the factor and the weights that must count it.

At the camera's first two vertices smooth glass now splits (``integrator.GLASS_SPLIT_DEPTH``):
one ray reflects with weight F, one refracts with 1 - F, where one of them was picked with
probability F. The worst region (row 1, column 0) held the spot's glint in the ball: the
few percent of samples that picked the reflection saw the lamp at 1 / F of its share, a
scatter of fireflies (0.88-1.13 of Cycles over seeds 1-8). Seeds 1-10 now give 2.4-3.8 %
(seed 1: 3.73 %, seed 2: 3.15 %); the worst is the caustic's region, whose mean stays
5.0-6.5 % below Cycles' (the bound there: 10 %), for 1.2-1.4 x the render time.

The references' own noise is at most 0.3 % a region (their manifest).
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


def render_against_reference(name, seed=1, scenes=material_scenes, ref_dir=REF_DIR,
                             check=None):
    """(Lanterna's image, the reference's npz) for scene ``name`` of the builder module
    ``scenes`` (``build(name)``) at ``final``, its reference in ``ref_dir``; ``check``: called
    with the exported scene first (the texture and world parity files share this)."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    scenes.build(name)
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    if check is not None:
        check(scene)
    ref = np.load(ref_dir / f"{name}.npz")
    image = np.asarray(render(scene, RenderSettings(seed=seed, preset="final")).image,
                       np.float64)
    assert np.all(np.isfinite(image))
    return image, ref


def worst_bright_region(name, seed=1):
    return worst_bright_ratio(*render_against_reference(name, seed))


def worst_bright_ratio(image, ref) -> float:
    """The largest |ours / Cycles - 1| of the 4 x 4 regions' mean luminance, over the regions
    brighter than a tenth of the brightest."""
    grid = tuple(int(v) for v in ref["grid"])
    ours = block_means(image, grid) @ LUMINANCE
    theirs = ref["region_mean"] @ LUMINANCE
    bright = theirs > 0.1 * theirs.max()
    return float(np.abs(ours[bright] / theirs[bright] - 1).max())


def test_factory_cube_matches_cycles_within_2_percent():
    """Blender's startup file untouched: the default Principled cube (a GGX dielectric layer
    over a 0.8 base) under the 1000 W point light and the grey world."""
    assert worst_bright_region("factory_cube") <= 0.02


# Scenes that meet the issue's bound (parity suite: 15-25 s each at ``final``).
MET = {"principled_room": 0.02, "metal_sphere": 0.03, "mix_floor": 0.03, "glass_caustic": 0.05}


@pytest.mark.parity
@pytest.mark.parametrize("name", list(MET))
def test_material_scenes_meet_the_issue_bound(name):
    assert worst_bright_region(name) <= MET[name]


@pytest.mark.parity
def test_glass_caustic_mean_within_10_percent():
    """The floor lit only through the glass ball (``material_scenes.CAUSTIC_REGION``, where
    Cycles without caustic paths gives exactly 0): its mean luminance within the issue's 10 %
    of Cycles'. Measured: -6.3 % (seed 1), -5.3 % (seed 2); without the caustic map the
    region is the umbra's indirect light alone (0.002 of Cycles), and before the sphere
    lights (the spot's 0.5 m radius rendered as a point) +35 %."""
    image, ref = render_against_reference("glass_caustic")
    x0, x1, y0, y1 = material_scenes.CAUSTIC_REGION
    ours = float((image[y0:y1, x0:x1] @ LUMINANCE).mean())
    theirs = float((ref["image"][y0:y1, x0:x1] @ LUMINANCE).mean())
    assert abs(ours / theirs - 1) <= 0.10
