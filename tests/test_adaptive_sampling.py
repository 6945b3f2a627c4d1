"""Adaptive sampling (``integrator.shade_adaptive``, ``RenderSettings.noise_threshold``; no
bpy, about 15 s).

* The (0, 2)-sequence (``sampling.sobol_02``): every run of 2^k points starting at a multiple
  of 2^k has one point in each elementary box of area 2^-k (all shapes), with or without a
  scramble; so a pixel's first samples and the extra ones added later are one stratified set.
* A box on a plane under a uniform sky (24 x 24 px, 8 spp, 2 light samples; the box's edges,
  its sky shadow and the cache make the noise): at threshold 0.01 the extra samples use the
  block's budget (at most half its own samples again) and the image's squared error against
  a 512-spp render of the same seed (its photons, so that what is left is the pixels' noise,
  which adaptive sampling acts on) falls to 0.76 x the plain render's (seeds 1-12:
  0.60-0.87, sd 0.087; the test takes the mean of seeds 1-4, bound 0.93 = mean + 4 sd of a
  4-seed mean; measured 2026-12-07). Against one 512-spp render of seed 9, as this test first
  did, the photon maps' differences count too: 0.73 then, 0.79 (sd 0.14) since photon
  estimates count only their disc's covered part (``Accelerator.disc_coverage``: the box's
  foot is brighter and its estimates' noise with it), where 4 sd no longer stays below 1.
  Measured then: the mean of 12 seeds +0.19 % off that render's against the plain renders'
  +0.11 % (se 0.10 %); with
  each pixel's noise judged by its own estimate alone (Cycles' way) it was +0.35 % (at twice
  the budget), the pixels whose samples came out dark getting the extra ones (measured, not
  asserted: 12 seeds of both would be needed).

Checked to fail: extra samples shaded at the wrong pixels (the subset reversed: ratio 3.4) and
no adaptive pass at all (ratio 1).
"""
import numpy as np

from lanterna.engine.pipeline import render
from lanterna.engine.sampling import sobol_02
from lanterna.engine.scene import World
from lanterna.engine.settings import RenderSettings
from test_environment import _box_yard


def test_the_sequence_fills_every_elementary_box_once():
    rng = np.random.default_rng(5)
    for scramble in (np.zeros(2, np.uint32), rng.integers(0, 1 << 32, 2, dtype=np.uint32)):
        for k in (4, 6):
            for start in (0, 1 << k, 3 << k):
                index = np.arange(start, start + (1 << k))
                p = sobol_02(index, np.tile(scramble, (len(index), 1)))
                assert p.min() >= 0.0 and p.max() < 1.0
                for a in range(k + 1):
                    cell = (np.floor(p[:, 0] * 2 ** a) * 2 ** (k - a)
                            + np.floor(p[:, 1] * 2 ** (k - a)))
                    assert len(np.unique(cell)) == 1 << k, (scramble, k, start, a)


def _render(scene, seed, **settings):
    base = dict(samples=8, light_samples=2, photons=20_000, gather_m=4, gather_n=16,
                cache_error=0.3, seed=seed)
    result = render(scene, RenderSettings(**{**base, **settings}))
    return np.asarray(result.image, np.float64), result.report["stages"]["camera"]


def test_extra_samples_within_the_budget_lower_the_error():
    scene = _box_yard(World(radiance=np.array([0.6, 0.5, 0.4])))
    ratios = []
    for seed in (1, 2, 3, 4):
        reference, _ = _render(scene, seed, samples=512)     # the same seed's photons
        plain, _ = _render(scene, seed)
        image, camera = _render(scene, seed, noise_threshold=0.01)
        assert 0 < camera["adaptive_samples"] <= 0.5 * 8 * 24 * 24, camera["adaptive_samples"]
        assert camera["camera_rays"] == 8 * 24 * 24 + camera["adaptive_samples"]
        ratios.append(np.mean((image - reference) ** 2) / np.mean((plain - reference) ** 2))
    assert np.mean(ratios) < 0.93, ratios
