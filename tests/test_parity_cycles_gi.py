"""Global-illumination parity with Cycles: Lanterna's ``full`` mode against all-bounce
Cycles references, in region means (issues 3 and 4).

Scenes (``tests/data/README.md``, section ``cycles_gi/``): the seed's Scene 1 at 160 x 120
(a point light; the left half of the box is lit only by bounced light), the seed's Scene 2
at 160 x 120 (a point light inside a tube: nearly everything in view is lit by bounced
light), and a Cornell box at 80 x 60 (an area light; the ceiling is lit only by bounced
light). References: Cycles 5.0.1 CPU, 64 bounces, no clamping, no denoiser, made by
``tests/data/make_cycles_refs.py --gi``: 4 seeds x 768 spp (Scene 1), 4 x 2560 (Cornell), and
for Scene 2, which Cycles converges on slowly, 2 seeds x 2048 spp at 640 x 480 box-averaged to
160 x 120 (worst bright block SE 0.28 %).

Two checks: issue 3's photon map looked up at the first hit (5 %), and issue 4's ``final``
preset, the seed's whole method (final gather, irradiance cache with gradients; 3 %).

Lanterna renders each scene twice (seeds 1 and 2) in ``full`` mode: exact direct light plus
indirect light from a photon map of ``PHOTONS`` photons (the estimate at the first diffuse
hit, k = 50; at these small sizes the automatic look-up count asks the map at all 16 samples
of a pixel). The rule is that of the direct-light parity (``test_parity_cycles.py``) with a
5 % budget, as the issue asks: a bright block (>= 5 % of the channel's peak) must agree within
``REL_TOL`` = 5 %, a dark block within ``ABS_TOL`` = 2 % of the channel's peak.

Noise: the photon map's blotches are low-frequency, so block means keep some of it. The
pooled relative SE of Lanterna's block means, estimated from the two renders, must be at most
``MAX_NOISE`` = 1.25 %, so that the 5 % bound is at least 4 sigma (false alarm per
block-channel about 6e-5; 2 scenes x 48 block-channels). What is left of the budget covers the
photon map's bias: the k-nearest-neighbour disc reaches past the corners of a room, which
darkens the blocks that hold a corner. Measured at 1M photons over seeds 1-4: a single
render's relative SD per bright block 0.53 % (Scene 1) and 0.66 % (Cornell), pooled; the
worst bright block's mean deviation -2.99 % (Scene 1, a floor corner of the unlit half) and
-2.60 % (Cornell); the worst single render 4.20 % and 3.23 %.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import parity_scenes  # noqa: E402
from test_parity_cycles import (BRIGHT_FRACTION, block_means, compare_regions,  # noqa: E402
                                load_reference, pooled_relative_se)

REF_DIR = HERE / "data" / "cycles_gi"
REL_TOL = 0.05
ABS_TOL = 0.02
MAX_NOISE = 0.0125
MAX_REF_NOISE = 0.003
SEEDS = (1, 2)
SAMPLES = 16
PHOTONS = 1_000_000
GI_SCENES = ("scene1", "cornell", "scene2")   # issue 3's photon-map check; FINAL_SCENES below


def build(name):
    if name in ("scene1", "scene2"):
        from lanterna.engine.blender import seed_scenes

        scene = seed_scenes.build(name)
        scene.render.resolution_x, scene.render.resolution_y = 160, 120
        scene.render.resolution_percentage = 100
        return scene
    return parity_scenes.build(name)


def render_full(name, **settings):
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    build(name)
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    settings = settings or dict(mode="full", indirect="photon-map", samples=SAMPLES,
                                photons=PHOTONS)
    return [render(scene, RenderSettings(seed=seed, **settings)) for seed in SEEDS]


@pytest.mark.parity
@pytest.mark.parametrize("name", GI_SCENES)
def test_full_mode_matches_cycles_with_all_bounces(name):
    results = render_full(name)
    for r in results:
        stage = r.report["stages"]["photons"]
        assert stage["kept"] == "indirect" and stage["emitted"] == PHOTONS
    check_against_cycles(name, results, REL_TOL, ABS_TOL, MAX_NOISE,
                         f"full mode, photon map at the hit ({SAMPLES} spp, {PHOTONS:,} photons)")


# Tuning and validation (bench/validation.py, SCENE_ROLES; docs/validation.md): Scene 2 (and
# Scene 1 for the estimate's fits) tuned the final preset's a = 0.1, the guided gather, the
# cache's neighbour check and the batch-local records; their checks here are regressions of
# what was tuned, and validate none of it. The Cornell boxes were never used to tune anything:
# they are the validation.
#
# Scene 2 is lit almost only by light that bounced once off the inside of the lamp's tube, a
# small patch 1000x brighter than the room, and the knot casts an "indirect shadow" of it on
# the floor that Ward's error metric (geometric distances) does not foresee. It needs the
# photon-guided gather, a = 0.1 and the cache's neighbour check (measured against the quiet
# reference: worst bright block -0.81 % with the check, +4.85 % without).
FINAL_SCENES = ("scene1", "cornell", "scene2")
FINAL_REL_TOL = 0.03          # issue 4: the final preset within 3 %
FINAL_MAX_NOISE = 0.0075      # so that 3 % is at least 4 sigma


@pytest.mark.parity
@pytest.mark.parametrize("name", FINAL_SCENES)
def test_final_preset_matches_cycles_within_3_percent(name):
    """The seed's whole method (final gather over precomputed irradiance, irradiance cache
    with gradients) with the ``final`` preset: bright blocks within 3 % of Cycles with all
    bounces, dark blocks within 2 % of the channel's peak."""
    results = render_full(name, preset="final")
    for r in results:
        assert r.report["plan"]["stages"]["irradiance_cache"].startswith("records")
        assert r.report["stages"]["irradiance_cache"]["records"] > 0
    check_against_cycles(name, results, FINAL_REL_TOL, ABS_TOL, FINAL_MAX_NOISE,
                         "final preset (cache + gather)")


def check_against_cycles(name, results, rel_tol, abs_tol, max_noise, what):
    ref = load_reference(name, REF_DIR)
    grid = tuple(int(v) for v in ref["grid"])
    images = [np.asarray(r.image, np.float64) for r in results]
    h, w = ref["image"].shape[:2]
    for image in images:
        assert image.shape == (h, w, 3) and np.all(np.isfinite(image))

    blocks = [block_means(image, grid) for image in images]
    lan = np.mean(blocks, axis=0)
    lan_se = np.abs(blocks[0] - blocks[1]) / 2.0
    ref_mean, ref_se = ref["region_mean"], ref["region_se"]
    pooled_lan, pooled_ref, noise = pooled_relative_se(lan_se, ref_mean, ref_se)

    failures, table = compare_regions(lan, ref_mean, ref_se, lan_se, (h, w), rel_tol, abs_tol)
    ratio = np.mean(images, axis=0).reshape(-1, 3).sum(0) / ref["image"].reshape(-1, 3).sum(0)
    header = (f"{name}: Lanterna {what}, seeds {SEEDS}, vs Cycles all bounces; whole-image "
              f"ratio R,G,B = {np.round(ratio, 4).tolist()}; pooled relative SE Lanterna "
              f"{pooled_lan:.3%}, Cycles {pooled_ref:.3%}")
    messages = list(failures)
    if noise > max_noise:
        messages.append(f"noise: pooled relative SE {noise:.3%} > {max_noise:.2%}: the "
                        f"{rel_tol:.0%} bound is not 4 sigma")
    assert not messages, (header + f"\n{len(failures)} of {ref_mean.size} block-channels outside "
                          "the rule:\n  " + "\n  ".join(messages)
                          + "\nLanterna / Cycles luminance per block:\n" + table)


def test_gi_references_are_all_bounce_and_quiet():
    problems = []
    for name in GI_SCENES + ("cornell_mm",):
        ref = load_reference(name, REF_DIR)
        s = ref["settings"]
        if s["max_bounces"] < 16 or s["diffuse_bounces"] < 16 or s["use_denoising"] \
                or s["use_adaptive_sampling"] or s["sample_clamp_direct"] or s["sample_clamp_indirect"]:
            problems.append(f"{name}: reference settings are not all-bounce/unbiased: {s}")
        mean, se = ref["region_mean"], ref["region_se"]
        peak = mean.reshape(-1, 3).max(axis=0)
        bright = mean >= BRIGHT_FRACTION * np.maximum(peak, 1e-30)
        rel = (se / np.maximum(mean, 1e-30))[bright]
        if rel.max() > MAX_REF_NOISE:
            problems.append(f"{name}: reference relative SE up to {rel.max():.3%}")
        if not np.allclose(block_means(ref["image"], ref["grid"]), mean, rtol=1e-5, atol=1e-7):
            problems.append(f"{name}: region_mean does not match the stored image")
    assert not problems, "\n".join(problems)


def test_gi_rule_catches_a_missing_bounce():
    """Not vacuous: direct light alone (bounces = 0) must fail against the GI reference."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    ref = load_reference("scene1", REF_DIR)
    build("scene1")
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    direct = render(scene, RenderSettings(bounces=0, samples=4, seed=1)).image.astype(np.float64)
    lan = block_means(direct, ref["grid"])
    zeros = np.zeros_like(lan)
    failures, _ = compare_regions(lan, ref["region_mean"], ref["region_se"], zeros,
                                  direct.shape[:2], REL_TOL, ABS_TOL)
    assert len(failures) >= 8


# --- Issue 19, item 5: the original Cornell box, its light quad in view ---------------------
CORNELL_MM_SEEDS = (1, 2, 3, 4)
CORNELL_MM_TOL = 0.02            # every region, every channel: |Lanterna / Cycles - 1|
CORNELL_MM_EMITTER_MAX_SE = 0.005    # regions that hold an emitter: SE of the 4-seed mean
CORNELL_MM_MAX_NOISE = 0.005     # pooled SE of the 4-seed means: 2 % is >= 4 sigma


@pytest.mark.parity      # four whole renders against Cycles (40 s): make test-parity
def test_original_cornell_box_every_region_within_2_percent():
    """The original Cornell box (``tests/parity_scenes.py:build_cornell_original``: the data
    page's geometry in millimetres, its light quad an Emission mesh of strength 50 0.1 mm under
    the ceiling, in view; 64 x 64) at ``final`` against Cycles with all bounces (4 x 4096 spp,
    worst bright block SE 0.077 %: none of the budget). Every one of the 16 regions, in every
    channel, including the region holding the light, within ``CORNELL_MM_TOL`` = 2 %, over the
    mean of seeds 1-4.

    Why 2 % holds, and why 4 seeds (measured with the fixes over seeds 1-8, per block-channel:
    mean deviation b and SD s of one render): |b| <= 1.07 % (a wall's blue; the regions are
    -0.05 to -0.91 % in luminance), s <= 0.80 % (the short box's regions; median 0.26 %), the
    light's regions b = -0.11 / -0.05 %, s = 0.30-0.35 %. With those normal laws the chance
    that any of the 48 block-channels of a 4-seed mean (SD s / 2 <= 0.40 %) falls outside 2 %
    is 0.08 %; for 2 seeds (SD s / sqrt 2) it is 2.2 %, hence 4 seeds (81 s). Seeds 1-4 give
    a worst block-channel of 1.27 %. Noise is checked too: the pooled SE of the 4-seed means
    must be <= ``CORNELL_MM_MAX_NOISE`` = 0.5 % (measured 0.19 %), and in every region that
    holds an emitter (emission over half its mean) the SE must be <= 0.5 % (measured 0.18 %;
    an estimate from 4 renders exceeds 0.5 % with probability ~1e-5 when the truth is 0.18 %).

    Without the fixes of issue 19 item 5 this fails, seeds 1-4: the light's region has an SE
    of 0.78 % (its edge pixels decided by 16 samples each: one render's SD 1.3-2.1 %; seeds 1
    and 2 alone put it -2.80 % off, the issue's "3.3 % dark"), so 2 % is not a 4-sigma bound
    there. The photon halo around the light (every other region +0.9-1.1 %) and the filter's
    tail (the ceiling row past the light's far edge 8 % dark) are below this rule's
    resolution; ``test_no_photon_halo_around_a_light_under_the_ceiling`` and
    ``test_parity_cycles.py::test_pixel_filter_tail_is_cycles`` catch them."""
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.pipeline import RenderSettings, render

    build("cornell_mm")
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    results = [render(scene, RenderSettings(seed=seed, preset="final"), passes=("Emission",))
               for seed in CORNELL_MM_SEEDS]
    ref = load_reference("cornell_mm", REF_DIR)
    grid = tuple(int(v) for v in ref["grid"])
    ref_mean = ref["region_mean"]
    images = [np.asarray(r.image, np.float64) for r in results]
    for image in images:
        assert image.shape == ref["image"].shape and np.all(np.isfinite(image))
    dev = np.array([block_means(image, grid) / ref_mean - 1.0 for image in images])
    mean = dev.mean(axis=0)
    se = dev.std(axis=0, ddof=1) / np.sqrt(len(images))
    emission = np.mean([block_means(np.asarray(r.passes["Emission"], np.float64), grid)
                        for r in results], axis=0)
    lum = np.mean([block_means(image, grid) for image in images], axis=0).sum(axis=-1)
    emitter = emission.sum(axis=-1) > 0.5 * lum
    assert emitter.any(), "no region holds the light: the test would not see it"

    problems = [f"region {tuple(int(v) for v in i[:2])} channel {'RGB'[i[2]]}: "
                f"{mean[tuple(i)]:+.2%} (SE {se[tuple(i)]:.2%})"
                for i in np.argwhere(np.abs(mean) > CORNELL_MM_TOL)]
    problems += [f"region {tuple(int(v) for v in i)} (holds the light): SE {se[tuple(i)].max():.2%} "
                 f"> {CORNELL_MM_EMITTER_MAX_SE:.1%}, 2 % is not 4 sigma there"
                 for i in np.argwhere(emitter) if se[tuple(i)].max() > CORNELL_MM_EMITTER_MAX_SE]
    pooled = float(np.sqrt(np.mean(se ** 2)))
    if pooled > CORNELL_MM_MAX_NOISE:
        problems.append(f"pooled SE {pooled:.2%} > {CORNELL_MM_MAX_NOISE:.1%}")
    table = "\n".join(" ".join(f"{v:+6.2%}" for v in row) for row in mean.mean(axis=-1))
    assert not problems, ("original Cornell box, final, seeds 1-4 vs Cycles:\n  "
                          + "\n  ".join(problems) + "\nmean deviation per region (RGB mean):\n"
                          + table)


def test_no_photon_halo_around_a_light_under_the_ceiling():
    """The original Cornell box's light quad hangs 0.1 mm under the ceiling and emits from
    both faces (as Cycles' Emission shader does): half its flux goes up into that gap, where
    the ceiling's irradiance is pi L = 157 W/m^2 (L = 50), ~100 x the room's ceiling. Those
    photons are hidden behind the quad; estimates on the visible ceiling beside it must not
    take them in. Measured, 1M photons (the ``final`` count), seed 1, at the middle of each
    edge, 0.5-4 mm outside: before the crevice rule (``photons.in_crevice``) the photon
    estimate was 3.2-43 W/m^2 and the precomputed estimates' look-up 5-115 W/m^2 against
    1.0-2.2 W/m^2 16-32 mm away (the true irradiance there: the ceiling's ~1.5-1.9 plus the
    direct glow out of the gap, pi L / 2 (1 - d / sqrt(d^2 + h^2)) = 1.5 W/m^2 at 0.5 mm and
    0.1 at 2 mm); after it 1.2-2.5 W/m^2. Bound: within 2 x the mean at 16-32 mm of the same
    edge plus the glow (k = 50 estimates scatter by ~15 %, and the ceiling's own irradiance
    varies by up to 1.6 x along these 32 mm)."""
    from concurrent.futures import ThreadPoolExecutor

    from lanterna.engine.accel import Accelerator
    from lanterna.engine.blender.export import export_scene
    from lanterna.engine.gather import RadianceEstimates
    from lanterna.engine.photons import auto_max_radius, build_photon_map

    build("cornell_mm")
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    accel = Accelerator(scene.triangles, threads=1)
    with ThreadPoolExecutor(2) as pool:
        pmap = build_photon_map(scene, accel, 1_000_000, seed=1, keep="all", pool=pool)
        radius = auto_max_radius(scene, len(pmap), 50)
        estimates = RadianceEstimates.build(pmap, k=50, max_radius=radius, pool=pool)
    accel.close()
    drop = parity_scenes.CORNELL_MM_LIGHT_DROP
    strength = parity_scenes.CORNELL_MM_STRENGTH
    z = 548.8 - 0.01                        # on the ceiling (Blender z = the data's y), mm
    near = np.array([0.5, 1.0, 2.0, 4.0])
    far = np.array([16.0, 24.0, 32.0])
    glow = np.pi * strength / 2 * (1 - near / np.sqrt(near ** 2 + drop ** 2))
    # Edge midpoints and the outward direction (Blender x, y; the quad spans x 213..343 and
    # y -332..-227).
    edges = {"far": ((278.0, -332.0), (0, -1)), "near": ((278.0, -227.0), (0, 1)),
             "left": ((343.0, -279.5), (1, 0)), "right": ((213.0, -279.5), (-1, 0))}
    problems = []
    for name, ((x0, y0), (dx, dy)) in edges.items():
        def at(d):
            p = np.column_stack([x0 + dx * d, y0 + dy * d, np.full(len(d), z)])
            n = np.tile([0.0, 0.0, -1.0], (len(d), 1))
            return (pmap.irradiance(p, n, k=50, max_radius=radius).mean(axis=1),
                    estimates.lookup(p, n).mean(axis=1))
        (e_near, l_near), (e_far, l_far) = at(near), at(far)
        for what, e, ref in (("photon estimate", e_near, e_far), ("look-up", l_near, l_far)):
            bound = 2.0 * ref.mean() + glow
            if np.any(e > bound):
                problems.append(f"{name} edge, {what} at {near.tolist()} mm: "
                                f"{np.round(e, 2).tolist()} > {np.round(bound, 2).tolist()}")
    assert not problems, "photon halo beside the light:\n  " + "\n  ".join(problems)
