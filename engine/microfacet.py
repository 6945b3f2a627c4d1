"""The GGX microfacet distribution over arrays of hits: normal distribution, Smith masking,
visible-normal sampling, Cycles' roughness mappings, and the albedo tables of its
multiple-scattering compensation.

What it computes (directions in a hit's local frame (t, b, n), n = +z, all (N, 3))
    ``ggx_d(h, ax, ay)``      D(h) = 1 / (pi ax ay (hx^2/ax^2 + hy^2/ay^2 + hz^2)^2) [1/sr]
                              (Trowbridge-Reitz / GGX, Walter et al. 2007 Eq. 33; the
                              anisotropic form of Heitz 2014 Eq. 85), 0 where hz <= 0.
    ``ggx_lambda(w, ax, ay)`` Smith's Lambda = (sqrt(1 + (ax^2 wx^2 + ay^2 wy^2) / wz^2) - 1)/2
                              (Heitz 2014 Eq. 86), so G1 = 1 / (1 + Lambda).
    ``g2``                    height-correlated masking-shadowing 1 / (1 + Lambda_o + Lambda_i)
                              (Heitz 2014 Eq. 99), which is what Cycles uses for GGX
                              (``bsdf_G`` in ``bsdf_microfacet.h``), for reflection and
                              transmission alike.
    ``sample_vndf(v, ax, ay, u)`` microfacet normals distributed as the visible normals
                              D_v(h) = G1(v) max(0, v.h) D(h) / v.z (Heitz 2018, "Sampling the
                              GGX Distribution of Visible Normals", JCGT 7(4)): stretch v to the
                              hemisphere configuration, sample the projected half disk (polar
                              map, the half behind v's plane squeezed by (1 + v'.z)/2),
                              reproject, unstretch. Cycles samples the same density (it maps
                              the disk concentrically).
    ``vndf_pdf(v, h, ax, ay)`` that density [1/sr] of h.
    ``frame(n, tangent)``     (t, b): the tangent made orthogonal to n (Gram-Schmidt, as
                              Cycles' ``make_orthonormals_tangent``: b = n x t), or
                              ``sampling.orthonormal_basis`` where no tangent is given.

Roughness mappings (``intern/cycles/kernel/svm/closure.h``)
    ``alpha_principled(roughness, anisotropic)``: alpha = roughness^2; with anisotropy a in
        [0, 1] (Principled BSDF and Metallic BSDF), aspect = sqrt(1 - 0.9 a),
        alpha_x = alpha / aspect, alpha_y = alpha * aspect.
    ``alpha_glossy(roughness, anisotropy)``: the Glossy BSDF's mapping, a clamped to
        [-0.99, 0.99]: a < 0 gives (alpha / (1 + a), alpha (1 + a)); a >= 0 gives
        (alpha (1 - a), alpha / (1 - a)).
    Both clip alpha_x, alpha_y to [0, 1] as Cycles' GGX setup does.

Multiple-scattering albedo tables (``tools/microfacet_tables.py``, stored in
``engine/data/microfacet_tables.npz``; ``engine/data/README.md`` says how to regenerate them)
    Computed by our own numpy quasi-Monte Carlo over visible normals, on Cycles' grids
    (``intern/cycles/app/cycles_precompute.cpp``): node-centred, r = roughness =
    (alpha_x alpha_y)^(1/4) and mu = cos theta_o in [0, 1], z = ((eta - 1)/(eta + 1))^(1/2)
    in [0, 1) for the index (eta = ior_from_F0(z^4)); eta < 1 has its own ("inv") tables
    indexed by 1/eta. Read back by multilinear interpolation (``table``).

    =========== ============== ==========================================================
    table       grid           the single-scattering albedo of GGX for F equal to
    =========== ============== ==========================================================
    E           32 r x 32 mu   1 (reflection)
    E5          32 r x 32 mu   (1 - mu_h)^5, mu_h = v.h (Schlick's term)
    E6          32 r x 32 mu   mu_h (1 - mu_h)^6 (the F82 term)
    Eavg        32 r           2 int E(mu) mu dmu
    R           16 x 16 x 16   the exact dielectric of eta (reflection only)
    G           16 x 16 x 16   glass: reflection F plus refraction 1 - F (Cycles' ggx_glass_E)
    Gavg        16 r x 16 z    2 int G mu dmu
    R_inv, G_inv, Gavg_inv     the same for eta < 1, indexed by 1 / eta
    =========== ============== ==========================================================

Parameters (per hit)
    =========  ======  ===========================================================
    name       unit    meaning
    =========  ======  ===========================================================
    alpha_x/y  1       GGX widths along the tangent and bitangent, in [0, 1]
    tangent    unit    the direction alpha_x runs along (None: isotropic frame)
    =========  ======  ===========================================================
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from . import sampling

__all__ = ["alpha_principled", "alpha_glossy", "frame", "to_local", "from_local", "ggx_d",
           "ggx_lambda", "ggx_d_iso", "ggx_lambda_iso", "g1", "g2", "sample_vndf", "vndf_pdf",
           "tables", "table", "table_roughness", "table_z", "TABLE_FILE"]

TABLE_FILE = Path(__file__).resolve().parent / "data" / "microfacet_tables.npz"
ALPHA_MIN = 1e-4          # widths are kept above this in the formulas (no 0/0)


def alpha_principled(roughness, anisotropic=0.0):
    """(alpha_x, alpha_y) of the Principled and Metallic BSDFs (see the module docstring)."""
    r = np.clip(np.asarray(roughness, dtype=float), 0.0, 1.0)
    a = np.clip(np.asarray(anisotropic, dtype=float), 0.0, 1.0)
    alpha = r * r
    aspect = np.sqrt(1.0 - 0.9 * a)
    return np.clip(alpha / aspect, 0.0, 1.0), np.clip(alpha * aspect, 0.0, 1.0)


def alpha_glossy(roughness, anisotropy=0.0):
    """(alpha_x, alpha_y) of the Glossy BSDF node (see the module docstring)."""
    r = np.clip(np.asarray(roughness, dtype=float), 0.0, 1.0)
    a = np.clip(np.asarray(anisotropy, dtype=float), -0.99, 0.99)
    alpha = r * r
    ax = np.where(a < 0, alpha / (1.0 + a), alpha * (1.0 - a))
    ay = np.where(a < 0, alpha * (1.0 + a), alpha / (1.0 - a))
    return np.clip(ax, 0.0, 1.0), np.clip(ay, 0.0, 1.0)


def frame(n: np.ndarray, tangent: np.ndarray | None = None):
    """(t, b) completing unit normals n (N, 3) to a right-handed frame, t along ``tangent``
    made orthogonal to n where one is given and not parallel to n."""
    t0, b0 = sampling.orthonormal_basis(n)
    if tangent is None:
        return t0, b0
    t = tangent - np.einsum("ij,ij->i", tangent, n)[:, None] * n
    length = np.linalg.norm(t, axis=1, keepdims=True)
    ok = length > 1e-9
    t = np.where(ok, t / np.where(ok, length, 1.0), t0)
    return t, np.cross(n, t)


def to_local(v, t, b, n):
    """Components of directions v (N, 3) in the frame (t, b, n)."""
    return np.stack([np.einsum("ij,ij->i", v, t), np.einsum("ij,ij->i", v, b),
                     np.einsum("ij,ij->i", v, n)], axis=1)


def from_local(v, t, b, n):
    return v[:, 0:1] * t + v[:, 1:2] * b + v[:, 2:3] * n


def _width(ax, ay):
    return np.maximum(ax, ALPHA_MIN), np.maximum(ay, ALPHA_MIN)


def ggx_d(h, ax, ay):
    """GGX D(h) [1/sr] for local unit normals h (N, 3); 0 below the surface."""
    ax, ay = _width(ax, ay)
    s = (h[:, 0] / ax) ** 2 + (h[:, 1] / ay) ** 2 + h[:, 2] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        d = 1.0 / (np.pi * ax * ay * s * s)
    return np.where(h[:, 2] > 0, d, 0.0)


def ggx_lambda(w, ax, ay):
    """Smith's Lambda for local directions w (N, 3) (either side: uses |w.z|)."""
    ax, ay = _width(ax, ay)
    z2 = w[:, 2] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((ax * w[:, 0]) ** 2 + (ay * w[:, 1]) ** 2) / z2
        lam = 0.5 * (np.sqrt(1.0 + t) - 1.0)
    return np.where(z2 > 0, lam, np.inf)


def ggx_d_iso(cos_h, alpha):
    """Isotropic GGX D from the cosine of h with the normal (sign ignored: D(h) = D(-h), as
    Cycles evaluates the refraction half vector)."""
    a2 = np.maximum(alpha, ALPHA_MIN) ** 2
    c2 = np.minimum(cos_h * cos_h, 1.0)
    return a2 / (np.pi * (1.0 - c2 + a2 * c2) ** 2)


def ggx_lambda_iso(cos, alpha):
    """Isotropic Smith Lambda from a direction's cosine with the normal (either side)."""
    a2 = np.maximum(alpha, ALPHA_MIN) ** 2
    c2 = cos * cos
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = 0.5 * (np.sqrt(1.0 + a2 * np.maximum(1.0 / c2 - 1.0, 0.0)) - 1.0)
    return np.where(c2 > 0, lam, np.inf)


def g1(w, ax, ay):
    return 1.0 / (1.0 + ggx_lambda(w, ax, ay))


def g2(wo, wi, ax, ay):
    """Height-correlated masking-shadowing 1 / (1 + Lambda(wo) + Lambda(wi))."""
    return 1.0 / (1.0 + ggx_lambda(wo, ax, ay) + ggx_lambda(wi, ax, ay))


def sample_vndf(v, ax, ay, u):
    """Visible normals (N, 3) for local view directions v (v.z > 0) from u (N, 2)."""
    ax, ay = _width(ax, ay)
    vh = np.stack([ax * v[:, 0], ay * v[:, 1], v[:, 2]], axis=1)
    vh /= np.linalg.norm(vh, axis=1, keepdims=True)
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    tilted = lensq > 1e-14
    inv = 1.0 / np.sqrt(np.where(tilted, lensq, 1.0))
    t1 = np.where(tilted[:, None], np.stack([-vh[:, 1] * inv, vh[:, 0] * inv,
                                             np.zeros(len(v))], axis=1), [[1.0, 0.0, 0.0]])
    t2 = np.cross(vh, t1)
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * vh
    ne = np.stack([ax * nh[:, 0], ay * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return ne / np.linalg.norm(ne, axis=1, keepdims=True)


def vndf_pdf(v, h, ax, ay):
    """Density [1/sr] of ``sample_vndf``'s normals h for view v: G1(v) max(0, v.h) D(h) / v.z."""
    vdoth = np.einsum("ij,ij->i", v, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = g1(v, ax, ay) * np.maximum(vdoth, 0.0) * ggx_d(h, ax, ay) / v[:, 2]
    return np.where(v[:, 2] > 0, p, 0.0)


# -- Albedo tables -------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def tables() -> dict:
    """The albedo tables as {name: float64 array}, read once."""
    with np.load(TABLE_FILE, allow_pickle=False) as data:
        return {name: data[name].astype(np.float64) for name in data.files
                if data[name].dtype.kind == "f"}


def table_roughness(ax, ay):
    """The tables' roughness coordinate r = (alpha_x alpha_y)^(1/4) (Cycles' ``rough``)."""
    return np.sqrt(np.sqrt(np.asarray(ax, dtype=float) * np.asarray(ay, dtype=float)))


def table_z(eta):
    """(z, inverse): the tables' index coordinate sqrt(|eta' - 1| / (eta' + 1)) with
    eta' = max(eta, 1 / eta), and whether the "_inv" tables apply (eta < 1)."""
    eta = np.asarray(eta, dtype=float)
    inverse = eta < 1.0
    e = np.where(inverse, 1.0 / np.maximum(eta, 1e-6), eta)
    return np.sqrt(np.abs((e - 1.0) / (e + 1.0))), inverse


def _interp_axis(x, size):
    f = np.clip(np.asarray(x, dtype=float), 0.0, 1.0) * (size - 1)
    i = np.minimum(f.astype(int), size - 2)
    return i, f - i


def table(name: str, r, mu=None, eta=None) -> np.ndarray:
    """Multilinear look-up of table ``name`` at roughness r (N,), cosine mu (N,) and, for the
    index tables (R, G, Gavg), relative index eta (N,) (the "_inv" table where eta < 1)."""
    data = tables()
    coords = [r] + ([mu] if mu is not None else [])
    if eta is None:
        return _lookup(data[name], coords)
    z, inverse = table_z(eta)
    out = _lookup(data[name], coords + [z])
    if inverse.any():
        out = np.where(inverse, _lookup(data[name + "_inv"], coords + [z]), out)
    return out


def _lookup(grid: np.ndarray, coords) -> np.ndarray:
    axes = [_interp_axis(c, grid.shape[k]) for k, c in enumerate(coords)]
    out = 0.0
    dims = len(axes)
    for corner in range(1 << dims):
        index, weight = [], 1.0
        for k, (i, f) in enumerate(axes):
            bit = (corner >> k) & 1
            index.append(i + bit)
            weight = weight * (f if bit else 1.0 - f)
        out = out + weight * grid[tuple(index)]
    return out
