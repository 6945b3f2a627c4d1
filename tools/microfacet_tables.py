"""Compute the GGX albedo tables of ``engine/microfacet.py`` (multiple-scattering
compensation and directional albedo) by our own numpy quasi-Monte Carlo, and write them to
``engine/data/microfacet_tables.npz``.

What it computes
    For each grid node (roughness r, cosine mu of the view direction v, and for the index
    tables z): the single-scattering albedo of the GGX lobe, the expected value over visible
    normals h (``microfacet.sample_vndf``, Heitz 2018) of the sampling weight f cos / pdf,
    which for GGX with height-correlated masking is G2 / G1 = (1 + L(v)) / (1 + L(v) + L(w)),
    times the Fresnel factor of the table, 0 where the reflected (refracted) direction w
    leaves on the wrong side. The glass tables take both branches' expected values at each h
    (F times the reflected weight plus 1 - F times the refracted one) rather than picking one
    at random, which is the same expectation with less noise. The h are a scrambled Sobol
    sequence (scipy.stats.qmc) of 2^m points, the same at every node.

    Grids follow Cycles' (``intern/cycles/app/cycles_precompute.cpp``): node-centred,
    r = x / (n - 1) and mu = y / (n - 1) clamped to [1e-4, 1], z = w / (n - 1) clamped to
    [1e-4, 0.99] with eta = (1 + z^2) / (1 - z^2) (z^4 = F0); "_inv" tables use 1 / eta.
    Averages (Eavg, Gavg) are 2 int_0^1 E(mu) mu dmu by 24-point Gauss-Legendre in mu.

Parameters
    ==========  =======  ============================================================
    option      default  meaning
    ==========  =======  ============================================================
    --log2      14       2^m Sobol points per node (reflection tables)
    --log2-glass 12      2^m Sobol points per node (index tables: R, G and their _inv)
    --out       engine/data/microfacet_tables.npz
    ==========  =======  ============================================================

Run from a checkout (the package importable as ``lanterna``):
    python tools/microfacet_tables.py            (about 2 minutes on one core)
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from lanterna.engine import fresnel, microfacet

ROOT = Path(__file__).resolve().parents[1]
CHUNK = 1 << 21            # samples per vectorised batch


def _nodes(count, low=1e-4, high=1.0):
    return np.clip(np.arange(count) / (count - 1), low, high)


def _eta_nodes(count):
    z = _nodes(count, 1e-4, 0.99)
    return (1.0 + z * z) / (1.0 - z * z)


def _albedo(r, mu, eta, u):
    """Per node (len(r) nodes, arrays of equal length) the expected weights, (nodes, 5):
    reflection with F = 1, x (1 - c)^5, x c (1 - c)^6, reflection with the dielectric F of
    eta, and glass (F reflected + (1 - F) refracted); eta may be nan (no index)."""
    nodes, k = len(r), len(u)
    alpha = np.repeat(np.maximum(r * r, 0.0), k)
    m = np.repeat(mu, k)
    v = np.stack([np.sqrt(1.0 - m * m), np.zeros_like(m), m], axis=1)
    h = microfacet.sample_vndf(v, alpha, alpha, np.tile(u, (nodes, 1)))
    c = np.einsum("ij,ij->i", v, h)
    lam_v = microfacet.ggx_lambda(v, alpha, alpha)
    wr = 2.0 * c[:, None] * h - v
    w_refl = np.where(wr[:, 2] > 0,
                      (1.0 + lam_v) / (1.0 + lam_v + microfacet.ggx_lambda(wr, alpha, alpha)),
                      0.0)
    one_c = 1.0 - c
    out = [w_refl, w_refl * one_c ** 5, w_refl * c * one_c ** 6]
    e = np.repeat(eta, k)
    if np.all(np.isnan(e)):
        out += [np.zeros_like(c), np.zeros_like(c)]
    else:
        F, cos_t = fresnel.dielectric(c, e)
        wt = -v / e[:, None] + (c / e - cos_t)[:, None] * h
        w_t = np.where((wt[:, 2] < 0) & (F < 1.0),
                       (1.0 + lam_v) / (1.0 + lam_v + microfacet.ggx_lambda(wt, alpha, alpha)),
                       0.0)
        out += [F * w_refl, F * w_refl + (1.0 - F) * w_t]
    return np.stack(out, axis=1).reshape(nodes, k, 5).mean(axis=1)


def _run(r, mu, eta, u):
    """_albedo over many nodes in batches of about CHUNK samples."""
    per = max(1, CHUNK // len(u))
    parts = [_albedo(r[i:i + per], mu[i:i + per], eta[i:i + per], u)
             for i in range(0, len(r), per)]
    return np.concatenate(parts, axis=0)


def build(log2: int = 14, log2_glass: int = 12) -> dict:
    u = qmc.Sobol(d=2, scramble=True, seed=20231).random_base2(log2)
    ug = qmc.Sobol(d=2, scramble=True, seed=20232).random_base2(log2_glass)
    gl_x, gl_w = np.polynomial.legendre.leggauss(24)
    gl_mu, gl_w = 0.5 * (gl_x + 1.0), 0.5 * gl_w
    out = {}
    # Reflection: 32 r x 32 mu.
    r, mu = np.meshgrid(_nodes(32), _nodes(32), indexing="ij")
    res = _run(r.ravel(), mu.ravel(), np.full(r.size, np.nan), u).reshape(32, 32, 5)
    out["E"], out["E5"], out["E6"] = res[..., 0], res[..., 1], res[..., 2]
    r, mu = np.meshgrid(_nodes(32), gl_mu, indexing="ij")
    res = _run(r.ravel(), mu.ravel(), np.full(r.size, np.nan), u).reshape(32, 24, 5)
    out["Eavg"] = (2.0 * gl_mu * gl_w * res[..., 0]).sum(axis=1)
    # Index tables: 16 r x 16 mu x 16 z, for eta and 1 / eta.
    for suffix, invert in (("", False), ("_inv", True)):
        eta_nodes = _eta_nodes(16)
        eta_nodes = 1.0 / eta_nodes if invert else eta_nodes
        r, mu, e = np.meshgrid(_nodes(16), _nodes(16), eta_nodes, indexing="ij")
        res = _run(r.ravel(), mu.ravel(), e.ravel(), ug).reshape(16, 16, 16, 5)
        out["R" + suffix], out["G" + suffix] = res[..., 3], res[..., 4]
        r, mu, e = np.meshgrid(_nodes(16), gl_mu, eta_nodes, indexing="ij")
        res = _run(r.ravel(), mu.ravel(), e.ravel(), ug).reshape(16, 24, 16, 5)
        out["Gavg" + suffix] = (2.0 * gl_mu[None, :, None] * gl_w[None, :, None]
                                * res[..., 4]).sum(axis=1)
    out = {k: np.clip(v, 0.0, 1.0).astype(np.float32) for k, v in out.items()}
    out["note"] = np.array(f"made by tools/microfacet_tables.py --log2 {log2} "
                           f"--log2-glass {log2_glass}")
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--log2", type=int, default=14)
    parser.add_argument("--log2-glass", type=int, default=12)
    parser.add_argument("--out", type=Path, default=ROOT / "engine" / "data" /
                        "microfacet_tables.npz")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    data = build(args.log2, args.log2_glass)
    np.savez_compressed(args.out, **data)
    print(f"wrote {args.out} in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
