"""The BSDF seam (engine/bsdf.py; no bpy): lobes against their own densities and closed forms.

* Lambertian: ``pdf`` integrates to 1 over the hemisphere (midpoint rule on 256 x 512 cells,
  error < 1e-4); ``sample``'s directions match ``pdf`` in a chi-square test over 8 x 16 cells
  of equal probability under it (cos^2 theta and phi strata; 200,000 samples;
  the 0.999 quantile of chi^2 with 127 degrees of freedom is 181, so this fails by chance
  once in a thousand seeds, never at the fixed one); ``evaluate`` is reciprocal and
  ``weight = f cos / pdf`` equals the reflectance exactly.
* Perfect mirror: the mirror direction, weight rho_s, no density (a delta).
* The composed material: ``sample``'s weights are unbiased (their mean is the albedo
  rho_d + rho_s within 4 standard errors), its ``pdf`` is the diffuse lobe's share of the
  roulette's probabilities, and roulette's probabilities are the largest channels.
* ``MaterialTable.at``: per-hit parameters equal the table's rows.
"""
import numpy as np
import pytest
from scipy.stats import chi2

from lanterna.engine.bsdf import (Lambertian, MaterialTable, PerfectMirror, SurfaceBSDF,
                                  reflect, roulette_probabilities)
from lanterna.engine.scene import Camera, Material, Scene


def _frame(count, rng):
    n = rng.normal(size=(count, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    wo = rng.normal(size=(count, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wo = np.where((np.einsum("ij,ij->i", wo, n) < 0)[:, None], -wo, wo)
    return n, wo


def _local(wi, n):
    """(cos theta, phi) of directions ``wi`` about normals ``n`` in an arbitrary frame."""
    t = np.cross(n, np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    cos = np.einsum("ij,ij->i", wi, n)
    phi = np.mod(np.arctan2(np.einsum("ij,ij->i", wi, b), np.einsum("ij,ij->i", wi, t)),
                 2 * np.pi)
    return cos, phi


def test_lambertian_pdf_integrates_to_one_and_sample_matches_it():
    rng = np.random.default_rng(5)
    lobe = Lambertian(np.full((1, 3), 0.7))
    # The pdf over the hemisphere, midpoint rule in (cos theta, phi).
    m, k = 256, 512
    cos = (np.arange(m) + 0.5) / m
    phi = (np.arange(k) + 0.5) / k * 2 * np.pi
    c, p = np.meshgrid(cos, phi, indexing="ij")
    s = np.sqrt(1 - c ** 2)
    wi = np.stack([s * np.cos(p), s * np.sin(p), c], -1).reshape(-1, 3)
    n = np.tile([0.0, 0.0, 1.0], (len(wi), 1))
    total = (lobe.pdf(n, wi, n) * (1.0 / m) * (2 * np.pi / k)).sum()
    assert abs(total - 1.0) < 1e-4
    # sample against pdf: chi-square over cells of equal probability (cos^2 and phi strata).
    count = 200_000
    n, wo = _frame(count, rng)
    lobe = Lambertian(np.full((count, 3), 0.7))
    wi, weight, pdf = lobe.sample(wo, n, rng.random((count, 2)))
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-9)
    c, ph = _local(wi, n)
    assert np.all(c >= -1e-12)
    rows, cols = 8, 16
    cell = np.minimum((c ** 2 * rows).astype(int), rows - 1) * cols + \
        np.minimum((ph / (2 * np.pi) * cols).astype(int), cols - 1)
    counts = np.bincount(cell, minlength=rows * cols)
    expected = count / (rows * cols)
    statistic = ((counts - expected) ** 2 / expected).sum()
    assert statistic < chi2.ppf(0.999, rows * cols - 1), statistic
    # A uniform hemisphere sampler fails the same test by far (the test can fail).
    uniform_c = rng.random(count)
    cell_u = np.minimum((uniform_c ** 2 * rows).astype(int), rows - 1) * cols + \
        np.minimum((ph / (2 * np.pi) * cols).astype(int), cols - 1)
    counts_u = np.bincount(cell_u, minlength=rows * cols)
    assert ((counts_u - expected) ** 2 / expected).sum() > 10 * chi2.ppf(0.999, rows * cols - 1)
    # weight = f cos / pdf = rho, and f is reciprocal.
    np.testing.assert_allclose(weight, 0.7)
    np.testing.assert_allclose(pdf, np.maximum(c, 0) / np.pi, rtol=1e-9)
    f_io, f_oi = lobe.evaluate(wo, wi, n), lobe.evaluate(wi, wo, n)
    np.testing.assert_array_equal(f_io, f_oi)
    np.testing.assert_allclose(f_io, 0.7 / np.pi)
    assert np.all(lobe.evaluate(wo, -wi, n) == 0)          # below the surface: nothing


def test_perfect_mirror_is_a_delta():
    rng = np.random.default_rng(6)
    n, wo = _frame(1000, rng)
    mirror = PerfectMirror(np.tile([0.9, 0.5, 0.1], (1000, 1)))
    wi, weight, pdf = mirror.sample(wo, n)
    np.testing.assert_allclose(wi, 2 * np.einsum("ij,ij->i", wo, n)[:, None] * n - wo,
                               atol=1e-12)
    np.testing.assert_allclose(reflect(-wo, n), wi)
    np.testing.assert_array_equal(weight, mirror.reflectance)
    assert np.all(np.isinf(pdf))
    assert np.all(mirror.evaluate(wo, wi, n) == 0) and np.all(mirror.pdf(wo, wi, n) == 0)
    np.testing.assert_array_equal(mirror.albedo(), mirror.reflectance)


def _table(*materials):
    tris = np.zeros((len(materials), 3, 3), np.float32)
    tris[:, 1, 0] = tris[:, 2, 1] = 1.0
    scene = Scene(triangles=tris, material_ids=np.arange(len(materials), dtype=np.int32),
                  materials=list(materials), camera=Camera.look_at([0, 0, 1], [0, 0, 0]))
    return MaterialTable(scene)


def test_composed_material_samples_its_albedo_and_reads_per_hit():
    table = _table(Material("plaster", diffuse=[0.7, 0.5, 0.3]),
                   Material("varnish", diffuse=[0.4, 0.1, 0.1], specular=[0.2, 0.3, 0.5]),
                   Material("black", diffuse=0.0))
    ids = np.repeat(np.arange(3), 40_000)
    params = table.at(ids)
    np.testing.assert_array_equal(params.diffuse, table.diffuse[ids])
    np.testing.assert_array_equal(params.specular, table.specular[ids])
    np.testing.assert_array_equal(params.is_diffuse, [True] * 80_000 + [False] * 40_000)
    np.testing.assert_array_equal(params.subset(slice(0, 5)).material, ids[:5])
    rng = np.random.default_rng(7)
    n, wo = _frame(len(ids), rng)
    bsdf = SurfaceBSDF(params)
    wi, weight, pdf, mirrored = bsdf.sample(wo, n, rng.random(len(ids)), rng.random((len(ids), 2)))
    for m in range(3):
        w = weight[ids == m]
        mean, se = w.mean(axis=0), w.std(axis=0) / np.sqrt(len(w))
        albedo = table.diffuse[m] + table.specular[m]
        assert np.all(np.abs(mean - albedo) <= 4 * se + 1e-12), (m, mean, albedo)
    assert not mirrored[ids == 0].any() and not mirrored[ids == 2].any()
    share = mirrored[ids == 1].mean()                 # P_s / (P_d + P_s) = 0.5 / 0.9
    assert abs(share - 0.5 / 0.9) < 4 * np.sqrt(0.25 / 40_000)
    p_d, p_s = bsdf.lobe_probabilities()
    np.testing.assert_allclose(p_d[ids == 1], 0.4)
    np.testing.assert_allclose(p_s[ids == 1], 0.5)
    diffuse = ~mirrored & (ids == 1)
    np.testing.assert_allclose(bsdf.pdf(wo, wi, n)[diffuse], pdf[diffuse], rtol=1e-12)
    np.testing.assert_allclose(bsdf.albedo(), table.diffuse[ids] + table.specular[ids])
    np.testing.assert_allclose(bsdf.absorption()[0], [0.3, 0.5, 0.7], rtol=1e-6)


@pytest.mark.parametrize("rho_d, rho_s, expected", [
    ([0.9, 0.6, 0.3], [0.0, 0.0, 0.0], (0.9, 0.0)),
    ([0.9, 0.0, 0.0], [0.0, 0.9, 0.0], (0.5, 0.5)),       # peaks apart: scaled to sum 1
    ([0.2, 0.2, 0.2], [0.3, 0.3, 0.3], (0.2, 0.3)),
])
def test_roulette_takes_the_largest_channels(rho_d, rho_s, expected):
    p_d, p_s = roulette_probabilities(np.array([rho_d]), np.array([rho_s]))
    np.testing.assert_allclose((p_d[0], p_s[0]), expected)
    # A survivor's weight rho / P never exceeds 1, nor the sum of the largest channels where
    # the lobes peak in different channels (DESIGN.md §4).
    bound = max(1.0, max(rho_d) + max(rho_s))
    for rho, p in ((rho_d, p_d[0]), (rho_s, p_s[0])):
        if p > 0:
            assert np.all(np.array(rho) / p <= bound + 1e-12)
