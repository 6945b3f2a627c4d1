"""Irradiance cache (seed chapter 10) with Ward & Heckbert's irradiance gradients (1992).

What it computes
    ``gather_directions(m, n, rng, count)``  the stratified cosine-distributed gather
        directions of Eq. 8.4-8.6 in the local frame (+z = normal), for many points at once:
        theta_j = asin(sqrt((j + xi1) / M)), phi_k = 2 pi (k + xi2) / N, stratum index
        j * N + k (theta-major, so a (P, M*N, ...) array reshapes to (P, M, N, ...)).
    ``irradiance_and_gradients(radiance, distances, m, n, frames)``  from the gather results
        of P points (radiance L_jk and hit distance r_jk per stratum): irradiance
        E = pi / (M N) sum L (Eq. 8.4), the harmonic-mean distance R = M N / sum 1/r
        (Eq. 10.4, a miss adds 1/inf = 0), the rotational and the translational gradient of
        Ward & Heckbert, (P, C, 3) [channel, xyz] in world space.
    ``IrradianceCache``  records (x_i, n_i, E_i, R_i, grad_r E_i, grad_t E_i) added in batches,
        and vectorised interpolation with the seed's weight (Eq. 10.3)
            w_i(x, n) = 1 / (|x - x_i| / R_i + sqrt(1 - n . n_i)),
        the records with w_i > 1/a that face the same side (n . n_i > 0) (Eq. 10.2), and
        Eq. 10.5 with gradients
            E(x, n) = sum w_i [E_i + (n_i x n) . grad_r E_i + (x - x_i) . grad_t E_i] / sum w_i.
        A per-record counter of the interpolated points each record served.
    ``clamp_radius(R, r_min, r_max)``  R_i between bounds (corners otherwise drive R_i to 0).
    ``consistent_radii(cache, a, variance)``  bounds on R_i from the neighbours' gathers: a
        record whose extrapolation (Eq. 10.5) misses a neighbouring record's E by more than
        a E plus the gathers' noise may not reach that far (indirect shadows, which Ward's
        geometric weight cannot see); ``GatherGradients.variance`` is each gather's estimate
        of its own noise, from two interleaved halves of its strata.

Gradients and their signs (derived here, pinned by tests/test_irradiance_cache.py)
    With u(phi) = cos(phi) t + sin(phi) b and omega = sin(theta) u + cos(theta) n:
    rotational: rotating n by a small angle d about an axis gives
        dE = d axis . (n x U),  U = integral L tan(theta) u cos(theta) d omega
    so with grad_r = n x U the first-order change is E(n') = E(n) + (n x n') . grad_r, which is
    the form of Eq. 10.5 (record normal first). The estimate of U uses, per stratum, the mean
    of tan(theta) over the stratum (cosine measure: M [F(s) ]_{j/M}^{(j+1)/M},
    F(s) = asin(sqrt s) - sqrt(s (1 - s))) and the mean of u over its phi range
    (sin(pi/N) / (pi/N) u(phi_k centre)): exact for a radiance constant per stratum and with
    bounded weights (a jittered sample's own tan(theta) is unbounded near the horizon).
    In Ward & Heckbert's notation this is (pi/(M N)) sum_k v_k sum_j (+tan(theta_j)) L_jk with
    v_k = n x u_k, the base-plane vector at phi_k + pi/2. The form quoted from the paper has
    -tan(theta_j); with this v_k and Eq. 10.5's (n_i x n) the closed-form tests need +tan, as
    Radiance's dirgradient() (ambcomp.c: +tan, phi + pi/2, extrapolation with
    (n_i x n) . grad) has it; the minus belongs with v_k at phi_k - pi/2 or with n x n_i. The
    tests compare with E(n) known in closed form, so the sign here is not a convention.
    translational: moving the point by dx shifts the content of every stratum towards the
    boundaries it approaches; across a boundary between strata the change is the radiance
    difference times the projected solid angle swept, with the nearer of the two distances:
        grad_t = sum_k [ 2 sin(pi/N) u(phi_k centre) sum_{j=1}^{M-1}
                         sin(theta_j-) cos^2(theta_j-) (L_jk - L_{j-1,k}) / min(r_jk, r_{j-1,k})
                       + v(2 pi k / N) sum_{j=0}^{M-1}
                         (sin(theta_j+) - sin(theta_j-)) (L_jk - L_{j,k-1}) / min(r_jk, r_{j,k-1}) ]
    sin(theta_j-) = sqrt(j/M), sin(theta_j+) = sqrt((j+1)/M), v(phi) = du/dphi, k-1 wraps.
    2 sin(pi/N) = integral of u over the cell's phi range (the quoted formula has 2 pi / N:
    the same to O(1/N^2); Radiance's posgradient() puts u at the cell's edge azimuth). A boundary between two misses contributes nothing
    (1 / min(inf, inf) = 0); an occluder edge against the sky uses the occluder's distance.
    The gradient lies in the tangent plane: (x - x_i) . grad_t ignores moves along n_i.

Clamping the extrapolated value
    Each record's extrapolated term E_i + (rotation) + (translation) is clamped per channel to
    at least ``floor`` x E_i (default 0: an irradiance is never negative, so 0 is the tightest
    bound that never alters a valid extrapolation). Far from a record, across an occluder edge
    or at a sharp contact shadow, a linear extrapolation can overshoot below zero; a negative
    record would pull the weighted mean below its neighbours (dark blotches, negative pixels).
    A floor at a fraction of E_i (newer Radiance uses 5 %) also hides overshoot but lifts real
    contact shadows, so it is left to the caller (``floor``).

Parameters and units
    ============== ======== ==========================================================
    name           unit     default / meaning
    ============== ======== ==========================================================
    m, n           -        caller's (Ward & Heckbert suggest N ~ pi M): theta x phi strata
    radiance       W/m2/sr  (P, M, N, C) incoming radiance per stratum (C channels, RGB)
    distances      m        (P, M, N) first-hit distance per stratum, inf for a miss
    min_distance   m        1e-6: distances are raised to this (guards 1/r)
    E              W/m2     irradiance; R: m; grad_r: W/m2 per radian; grad_t: W/m2 per m
    a              -        caller's (Ward: 0.1-0.3): maximum allowed error, w_i > 1/a
    use_gradients  -        True: Eq. 10.5; False: Eq. 10.1
    floor          -        0.0: extrapolated term >= floor x E_i per channel
    e_min          -        1e-6: w_i = 1 / max(e_i, e_min) (a record exactly at x)
    index          -        "grid" (default) or "kdtree": the spatial index (below)
    radius_ratio   -        4.0: records are grouped in classes R in [ratio^c, ratio^(c+1))
    cell_fraction  -        1.0: grid cell side / (a R_max of the class)
    r_min, r_max   m        clamp_radius bounds (the caller ties them to the pixel footprint)
    ============== ======== ==========================================================

Spatial index (the seed used an octree, 10.2; DESIGN.md: measure)
    A record i can only serve points within a R_i of x_i. Records are grouped in radius
    classes (R within a factor ``radius_ratio``); per class, candidates within a R_max(class):
    * "grid": a hashed uniform grid per class with cells of side a R_max(class); each record is
      listed in every cell its sphere of influence's bounding box overlaps (at most 27), so a
      point looks at one cell: a sorted-key CSR table, one ``searchsorted`` per point, pairs
      made with ``repeat``. Rebuilt from scratch when records are added (a sort of ~13 keys
      a record for records on surfaces).
    * "kdtree": pykdtree per class, k nearest within a R_max(class), k doubled for the rows
      that fill it.
    Both give the same records after the exact test (tests/test_irradiance_cache.py checks
    both against brute force). Measured here (2 cores shared with other jobs, load ~5, so CPU
    time is the steadier number; one thread; float64; gradients on): 300k points on the 5
    walls of a 4 x 3 x 5 m room, 17.9k records placed by the cache's own coverage passes,
    a = 0.3, R in [0.05, 1] m (4 radius classes), 4.5 records per point:
        grid    1.06 s wall / 0.70 s CPU for 300k points (280k/s wall, 430k/s per core);
                build 0.09 s (13.5 grid entries a record), 9.4 MB with the records
        kdtree  3.25 s wall / 1.67 s CPU (90k/s wall, 180k/s per core); build 0.01 s
    The grid is the default. Its time goes to gathering the ~18 candidate pairs per point
    (cells of a R_max: ~4x the records that pass); cells of a R_max / 2 halve the candidates
    but build 4x slower and, measured, gain nothing. ``pool`` runs chunks on threads.
    ``test_speed_report`` prints the two speeds again.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sampling

__all__ = ["gather_directions", "directions_to_world", "frames_from_normals",
           "irradiance_and_gradients", "GatherGradients", "IrradianceCache", "clamp_radius",
           "limit_translational_gradient", "consistent_radii"]


# --------------------------------------------------------------------------------------------
# Gather directions
# --------------------------------------------------------------------------------------------

def gather_directions(m: int, n: int, rng: np.random.Generator | None = None,
                      count: int | None = None, xi: np.ndarray | None = None):
    """Stratified cosine-distributed directions about +z (Eq. 8.4-8.6).

    ``xi`` (P, M*N, 2) in [0, 1) if given; otherwise ``rng.random((count, M*N, 2))``; with
    neither, the stratum centres (xi = 0.5). Returns ``(dirs_local, theta_index, phi_index)``:
    dirs (P, M*N, 3) float64 ((M*N, 3) when ``count`` and ``xi`` are None), and the stratum
    indices (M*N,) int64 of each column: j = index // N, k = index % N."""
    m, n = int(m), int(n)
    squeeze = False
    if xi is None:
        if rng is not None:
            xi = rng.random((1 if count is None else int(count), m * n, 2))
            squeeze = count is None
        else:
            xi = np.full((1 if count is None else int(count), m * n, 2), 0.5)
            squeeze = count is None
    xi = np.asarray(xi, np.float64)
    if xi.ndim == 2:
        xi, squeeze = xi[None], True
    cell = np.arange(m * n)
    j, k = cell // n, cell % n
    s = (j + xi[..., 0]) / m                        # sin^2(theta), uniform per ring: cosine pdf
    s = np.clip(s, 0.0, 1.0)
    sin_t = np.sqrt(s)
    phi = (2.0 * np.pi / n) * (k + xi[..., 1])
    out = np.empty(xi.shape[:-1] + (3,))
    out[..., 0] = sin_t * np.cos(phi)
    out[..., 1] = sin_t * np.sin(phi)
    out[..., 2] = np.sqrt(1.0 - s)
    return (out[0] if squeeze else out), j, k


def frames_from_normals(normals: np.ndarray):
    """(t, b, n) orthonormal frames about unit normals (P, 3) (``sampling.orthonormal_basis``)."""
    nn = np.asarray(normals, np.float64)
    t, b = sampling.orthonormal_basis(nn)
    return t, b, nn


def directions_to_world(dirs_local: np.ndarray, frames) -> np.ndarray:
    """Local directions (P, K, 3) -> world (P, K, 3) in the frames (t, b, n), each (P, 3)."""
    t, b, nn = (np.asarray(f, np.float64) for f in frames)
    d = np.asarray(dirs_local, np.float64)
    if d.ndim == 2:
        d = np.broadcast_to(d, (len(t),) + d.shape)
    out = np.empty(d.shape[:2] + (3,))
    for c in range(3):
        out[..., c] = (d[..., 0] * t[:, None, c] + d[..., 1] * b[:, None, c]
                       + d[..., 2] * nn[:, None, c])
    return out


# --------------------------------------------------------------------------------------------
# Irradiance, R and gradients from one gather
# --------------------------------------------------------------------------------------------

@dataclass
class GatherGradients:
    irradiance: np.ndarray      # (P, C) [W/m^2]
    radius: np.ndarray          # (P,) harmonic-mean distance [m], inf if every ray missed
    rot_grad: np.ndarray        # (P, C, 3) [W/m^2 per radian], world space
    trans_grad: np.ndarray      # (P, C, 3) [W/m^2 per m], world space, in the tangent plane

    variance: np.ndarray | None = None   # (P,) noise of the channel sum of E [(W/m^2)^2]

    def __iter__(self):
        return iter((self.irradiance, self.radius, self.rot_grad, self.trans_grad))


def _ring_weights(m: int):
    """Per theta ring: the cosine-measure mean of tan(theta) over ring j (M,), and for the
    boundaries j = 1..M-1 sin(theta_j-) cos^2(theta_j-) (M-1,), and sin(theta_j+) - sin(theta_j-)
    (M,)."""
    s = np.arange(m + 1) / m
    f = np.arcsin(np.sqrt(s)) - np.sqrt(s * (1.0 - s))
    mean_tan = m * np.diff(f)
    sin_b = np.sqrt(s)
    wall_theta = sin_b[1:m] * (1.0 - s[1:m])
    wall_phi = np.diff(sin_b)
    return mean_tan, wall_theta, wall_phi


def irradiance_and_gradients(radiance: np.ndarray, distances: np.ndarray, m: int, n: int,
                             frames, min_distance: float = 1e-6,
                             misses_count: bool = True) -> GatherGradients:
    """E, R, rotational and translational gradients of P gathers (see the module docstring).

    ``radiance`` (P, M, N, C) or (P, M*N, C) incoming radiance per stratum, theta-major;
    ``distances`` (P, M, N) or (P, M*N) hit distances (inf or nan for a miss); ``frames``
    (t, b, n) each (P, 3): the frame the gather directions were built in. ``misses_count``
    False: R is the harmonic mean over the rays that hit something (the pipeline's choice:
    with misses as infinitely far, R grows without bound where half the rays leave through an
    opening although nearby surfaces still shape E; a Cornell box's open side came out 3.5 %
    dark). Returns a ``GatherGradients`` (unpacks as E, R, rot_grad, trans_grad)."""
    m, n = int(m), int(n)
    L = np.asarray(radiance, np.float64)
    p = L.shape[0]
    L = L.reshape(p, m, n, -1)
    r = np.asarray(distances, np.float64).reshape(p, m, n)
    t, b, nn = (np.asarray(f, np.float64).reshape(p, 3) for f in frames)
    mn = m * n
    E = (np.pi / mn) * L.sum(axis=(1, 2))
    hit = np.isfinite(r)
    inv_r = np.zeros_like(r)
    inv_r[hit] = 1.0 / np.maximum(r[hit], min_distance)
    s_inv = inv_r.sum(axis=(1, 2))
    with np.errstate(divide="ignore"):
        # Ward's R counts a miss as infinitely far (MN in the numerator); misses_count=False
        # takes the harmonic mean over the rays that hit only.
        hits = mn if misses_count else hit.sum(axis=(1, 2))
        R = np.where(s_inv > 0, hits / np.where(s_inv > 0, s_inv, 1.0), np.inf)

    mean_tan, wall_theta, wall_phi = _ring_weights(m)
    centre = (2.0 * np.pi / n) * (np.arange(n) + 0.5)
    edge = (2.0 * np.pi / n) * np.arange(n)
    sinc = np.sinc(1.0 / n)                          # sin(pi/N) / (pi/N)

    # Rotational: U = pi/(MN) sinc sum_k u_k sum_j tanbar_j L_jk; grad_r = n x U.
    col = np.einsum("pjkc,j->pkc", L, mean_tan)      # (P, N, C)
    ux = (np.pi / mn) * sinc * np.einsum("pkc,k->pc", col, np.cos(centre))
    uy = (np.pi / mn) * sinc * np.einsum("pkc,k->pc", col, np.sin(centre))
    U = ux[..., None] * t[:, None, :] + uy[..., None] * b[:, None, :]      # (P, C, 3)
    rot = np.cross(nn[:, None, :], U)

    # Translational: walls between theta rings (along u at the cell) and between phi columns
    # (along v at the boundary azimuth), each with the nearer distance of the two strata.
    if m > 1:
        w1 = np.maximum(inv_r[:, 1:], inv_r[:, :-1])                    # (P, M-1, N)
        d1 = L[:, 1:] - L[:, :-1]                                       # (P, M-1, N, C)
        t1 = np.einsum("pjk,pjkc,j->pkc", w1, d1, wall_theta)          # (P, N, C)
    else:
        t1 = np.zeros((p, n, L.shape[3]))
    w2 = np.maximum(inv_r, np.roll(inv_r, 1, axis=2))
    d2 = L - np.roll(L, 1, axis=2)                                      # L_jk - L_j,k-1
    t2 = np.einsum("pjk,pjkc,j->pkc", w2, d2, wall_phi)                # (P, N, C)
    chord = 2.0 * np.sin(np.pi / n)
    gx = chord * np.einsum("pkc,k->pc", t1, np.cos(centre)) - np.einsum("pkc,k->pc", t2, np.sin(edge))
    gy = chord * np.einsum("pkc,k->pc", t1, np.sin(centre)) + np.einsum("pkc,k->pc", t2, np.cos(edge))
    trans = gx[..., None] * t[:, None, :] + gy[..., None] * b[:, None, :]
    return GatherGradients(E, R, rot, trans, _stratified_variance(L))


def _stratified_variance(L: np.ndarray) -> np.ndarray:
    """The noise of E's channel sum from one gather (P, M, N, C): the strata split into two
    interleaved halves (a checkerboard in (j, k)), each half's mean an estimate of E/pi, and
    var(E) = pi^2 (m_A - m_B)^2 n_A n_B / (n_A + n_B)^2 (the variance of the whole mean, from
    E[(m_A - m_B)^2] = s^2 (1/n_A + 1/n_B)). One gather's estimate of its own noise: unbiased
    but itself noisy; it overstates the noise where a bright patch's edge runs between strata
    (stratification removes part of that)."""
    p, m, n = L.shape[:3]
    if m * n < 2:
        return np.zeros(p)
    total = L.sum(axis=3).reshape(p, m * n)
    half = ((np.arange(m)[:, None] + np.arange(n)[None, :]) % 2 == 0).reshape(-1)
    na, nb = int(half.sum()), int((~half).sum())
    diff = total[:, half].mean(axis=1) - total[:, ~half].mean(axis=1)
    return np.pi ** 2 * diff * diff * (na * nb) / (na + nb) ** 2


def limit_translational_gradient(grad, irradiance, radius_raw, radius):
    """Translational gradients (P, C, 3) made safe to extrapolate with (Krivanek et al. 2008,
    Tabellion and Lamorlette 2004): where R_i was clamped up from R_raw, the gradient (whose
    1/min(r) terms R_raw came from) is scaled by R_raw / R_i; and no channel may change by
    more than its own E_i over the distance R_i (|grad| <= E_i / R_i). Without this a record
    near a corner (gather distances of a millimetre) extrapolated to 100x its value."""
    raw = np.where(np.isfinite(radius_raw), radius_raw, radius)
    grad = grad * np.minimum(1.0, raw / radius)[:, None, None]
    norm = np.linalg.norm(grad, axis=2)                                   # (P, C)
    limit = irradiance / radius[:, None]
    scale = np.where(norm > limit, limit / np.maximum(norm, 1e-300), 1.0)
    return grad * scale[..., None]


def consistent_radii(cache: "IrradianceCache", a: float, variance, r_min=0.0,
                     tolerance: float | None = None, z: float = 4.0,
                     reach: float = 2.0, pool=None) -> np.ndarray:
    """Upper bounds on the records' R_i from what their neighbours measured: a check of the
    first-order extrapolation (Eq. 10.5) against gathers actually made nearby.

    Ward's weight places records by geometry (distances, normals) only; an indirect shadow
    (a bright patch occluded from part of an open floor) is invisible to it, and records
    interpolate straight across it. Here every record j within ``reach`` times another record
    i's reach (w_i(x_j, n_j) > 1 / (reach a)) is a test point: i's extrapolation to x_j
    against the E_j gathered there. An excess e = |E_i(x_j) - E_j| beyond ``tolerance`` x E at
    distance d means that neither record may reach across: R_i and R_j <= (d / a) tolerance E
    / e (an error growing linearly with distance, as across a shadow's edge, reaches
    tolerance x E at d tolerance E / e; the reach of a record is a R). Both shrink, so that
    neither side of an edge dominates the other. Channel sums throughout; E is the mean of
    E_i and E_j.

    Noise is not structure: e counts only beyond ``z`` standard deviations of the difference
    of two gathers, sigma sqrt(E_i^2 + E_j^2), with one relative noise sigma for all records:
    the median of sqrt(variance) / E (``variance``, (n,) per record, from
    ``GatherGradients.variance``). Each record's own variance would be a worse guide: it is
    largest where a gather saw a bright patch's edge, so the bright records would escape the
    test and the dark ones shrink alone, which biased Scene 2's indirect shadows 15-20 %
    bright (measured); with one sigma the result hardly moved between z = 1 and 4. z = 4, as a
    gather's noise is heavy-tailed (a few rays catch a small bright patch): on Scene 2 at
    640 x 480 z = 2 made 21k records and z = 4 15k, with the same block error at 160 x 120.

    ``tolerance`` defaults to a (Ward's a is the allowed relative error). ``r_min``: the
    smallest R a record may get (scalar or (n,)). ``pool``: an executor for the neighbour
    search (``IrradianceCache.neighbour_predictions``; the bounds do not depend on it).
    Returns (n,) bounds, inf where nothing disagreed; ``cache.limit_radius`` applies them."""
    n = len(cache)
    bound = np.full(n, np.inf)
    if n < 2:
        return bound
    tol = float(a if tolerance is None else tolerance)
    j, i, d, predicted = cache.neighbour_predictions(reach * a, pool=pool)
    if len(j) == 0:
        return bound
    e_sum = cache.irradiance.sum(axis=1)
    sd = np.sqrt(np.maximum(np.asarray(variance, np.float64).reshape(n), 0.0))
    lit = e_sum > 0
    sigma = float(np.median(sd[lit] / e_sum[lit])) if lit.any() else 0.0
    excess = np.abs(predicted.sum(axis=1) - e_sum[j])
    excess -= z * sigma * np.sqrt(e_sum[i] ** 2 + e_sum[j] ** 2)
    scale = 0.5 * (e_sum[i] + e_sum[j])
    bad = np.nonzero(excess > tol * scale)[0]
    if len(bad):
        reach_ok = d[bad] * (tol * scale[bad] / excess[bad]) / a
        np.minimum.at(bound, i[bad], reach_ok)
        np.minimum.at(bound, j[bad], reach_ok)
    return np.maximum(bound, np.broadcast_to(np.asarray(r_min, np.float64), (n,)))


def clamp_radius(R, r_min, r_max) -> np.ndarray:
    """R clipped to [r_min, r_max] (scalars or per-record arrays); nan and inf become r_max."""
    R = np.asarray(R, np.float64)
    r_max = np.broadcast_to(np.asarray(r_max, np.float64), R.shape)
    R = np.where(np.isfinite(R), R, r_max)
    return np.clip(R, r_min, r_max)


# --------------------------------------------------------------------------------------------
# The cache
# --------------------------------------------------------------------------------------------

def _pairs_from_ranges(start: np.ndarray, count: np.ndarray):
    """For rows with [start, start + count): (row of each pair, position of each pair)."""
    total = int(count.sum())
    row = np.repeat(np.arange(len(count)), count)
    first = np.cumsum(count) - count
    pos = np.arange(total) - np.repeat(first - start, count)
    return row, pos


class _GridClass:
    """Hashed uniform grid over one radius class, cells of side ``cell_fraction`` x a R_max;
    each record listed in every cell its influence box (x_i +- a R_i) overlaps."""

    def __init__(self, positions, radii, members, a, cell_fraction=1.0):
        self.members = members
        reach = a * radii[members]
        self.cell = float(reach.max()) * cell_fraction
        x = positions[members]
        self.lo = x.min(axis=0) - 2 * reach.max()
        extent = x.max(axis=0) + 2 * reach.max() - self.lo
        self.cell = max(self.cell, float(extent.max()) * 1e-15, 1e-300)
        while float(np.prod(np.ceil(extent / self.cell) + 1)) > 2.0 ** 62:
            self.cell *= 2.0                        # 64-bit keys: coarsen (tiny R, huge scene)
        self.dims = np.maximum(np.ceil(extent / self.cell).astype(np.int64) + 1, 1)
        first = np.floor((x - reach[:, None] - self.lo) / self.cell).astype(np.int64)
        last = np.floor((x + reach[:, None] - self.lo) / self.cell).astype(np.int64)
        span = int((last - first).max()) + 1
        keys, recs = [], []
        local = np.arange(len(members))
        for ox in range(span):
            okx = first[:, 0] + ox <= last[:, 0]
            for oy in range(span):
                oky = okx & (first[:, 1] + oy <= last[:, 1])
                for oz in range(span):
                    ok = np.nonzero(oky & (first[:, 2] + oz <= last[:, 2]))[0]
                    if len(ok) == 0:
                        continue
                    keys.append(self._key(first[ok] + np.array([ox, oy, oz])))
                    recs.append(local[ok])
        keys = np.concatenate(keys)
        recs = np.concatenate(recs)
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        self.records = members[recs[order]]
        self.keys, self.start, self.count = np.unique(keys, return_index=True, return_counts=True)
        self.nbytes = self.keys.nbytes + self.start.nbytes + self.count.nbytes + self.records.nbytes

    def _key(self, c):
        return (c[:, 0] * self.dims[1] + c[:, 1]) * self.dims[2] + c[:, 2]

    def candidates(self, points):
        c = np.floor((points - self.lo) / self.cell).astype(np.int64)
        inside = np.all((c >= 0) & (c < self.dims), axis=1)
        q = np.nonzero(inside)[0]
        key = self._key(c[q])
        at = np.searchsorted(self.keys, key)
        at = np.minimum(at, len(self.keys) - 1)
        found = self.keys[at] == key
        q, at = q[found], at[found]
        row, pos = _pairs_from_ranges(self.start[at], self.count[at])
        return q[row], self.records[pos]


class _TreeClass:
    """pykdtree over one radius class; k nearest within a R_max, k doubled where full."""

    def __init__(self, positions, radii, members):
        from pykdtree.kdtree import KDTree
        self.members = members
        self.rmax = float(radii[members].max())
        self.tree = KDTree(np.ascontiguousarray(positions[members]), leafsize=16)
        self.nbytes = positions[members].nbytes * 2

    def candidates(self, points, a, k0=16):
        bound = a * self.rmax * (1 + 1e-9)
        size = len(self.members)
        rows = np.arange(len(points))
        qs, rs = [], []
        k = min(k0, size)
        pts = np.ascontiguousarray(points)
        while len(rows):
            _d, idx = self.tree.query(pts[rows] if len(rows) < len(points) else pts, k=k,
                                      distance_upper_bound=bound)
            idx = idx.reshape(len(rows), k)
            full = idx[:, -1] < size
            if k >= size:
                full[:] = False
            done = ~full
            sel = idx[done]
            ok = sel < size
            qs.append(np.repeat(rows[done], k)[ok.reshape(-1)])
            rs.append(self.members[sel[ok].astype(np.int64)])
            rows = rows[full]
            k = min(2 * k, size)
        if not qs:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(qs), np.concatenate(rs)


class IrradianceCache:
    """Irradiance records and their interpolation (Eq. 10.2, 10.3, 10.5); see the module
    docstring. Records are float64: position (3), normal (3), E (C), R, grad_r (C, 3),
    grad_t (C, 3), and a usage counter."""

    def __init__(self, channels: int = 3, index: str = "grid", radius_ratio: float = 4.0,
                 e_min: float = 1e-6, cell_fraction: float = 1.0):
        if index not in ("grid", "kdtree"):
            raise ValueError(f"unknown index {index!r}: 'grid' or 'kdtree'")
        # Limits that keep the index finite: a cell of 1e-300 R made the grid's loop over the
        # cells a record reaches run for ever; a radius ratio at 1 puts every record in a class
        # of its own.
        for name, value, low, high in (("channels", channels, 1, 64),
                                       ("radius_ratio", radius_ratio, 1.0 + 1e-9, 1e3),
                                       ("e_min", e_min, 1e-300, 1.0),
                                       ("cell_fraction", cell_fraction, 0.05, 20.0)):
            if not (np.isfinite(value) and low <= value <= high):
                raise ValueError(f"{name} = {value!r} is outside [{low:g}, {high:g}]")
        self.channels = int(channels)
        self.index = index
        self.radius_ratio = float(radius_ratio)
        self.e_min = float(e_min)
        self.cell_fraction = float(cell_fraction)
        self._n = 0
        self._alloc(0)
        self._classes = None      # [record indices of each radius class]
        self._indexes = {}        # a -> list of per-class structures (grid) / None -> trees
        self._geo = self._val = None
        self.build_seconds = 0.0

    # storage ----------------------------------------------------------------------------
    def _alloc(self, cap):
        c = self.channels
        old = getattr(self, "_pos", None)
        fields = {"_pos": (3,), "_nrm": (3,), "_E": (c,), "_R": (), "_grot": (c, 3),
                  "_gtr": (c, 3), "_H": (c, 3)}
        for name, shape in fields.items():
            arr = np.zeros((cap,) + shape)
            if old is not None:
                arr[:self._n] = getattr(self, name)[:self._n]
            setattr(self, name, arr)
        used = np.zeros(cap, np.int64)
        if old is not None:
            used[:self._n] = self._used[:self._n]
        self._used = used

    def __len__(self):
        return self._n

    positions = property(lambda self: self._pos[:self._n])
    normals = property(lambda self: self._nrm[:self._n])
    irradiance = property(lambda self: self._E[:self._n])
    radius = property(lambda self: self._R[:self._n])
    rot_grad = property(lambda self: self._grot[:self._n])
    trans_grad = property(lambda self: self._gtr[:self._n])
    usage = property(lambda self: self._used[:self._n])

    def add(self, positions, normals, irradiance, radius, rot_grad=None, trans_grad=None):
        """Append a batch of records; returns their indices. ``radius`` must be finite and > 0
        (pass it through ``clamp_radius``); missing gradients are zero. Normals are
        normalised."""
        x = np.asarray(positions, np.float64).reshape(-1, 3)
        k = len(x)
        nrm = np.asarray(normals, np.float64).reshape(k, 3)
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        E = np.asarray(irradiance, np.float64).reshape(k, self.channels)
        R = np.asarray(radius, np.float64).reshape(k)
        if not np.all(np.isfinite(R) & (R > 0)):
            raise ValueError("record radii must be finite and > 0 (use clamp_radius)")
        zero = np.zeros((k, self.channels, 3))
        gr = zero if rot_grad is None else np.asarray(rot_grad, np.float64).reshape(k, self.channels, 3)
        gt = zero if trans_grad is None else np.asarray(trans_grad, np.float64).reshape(k, self.channels, 3)
        if self._n + k > len(self._R):
            self._alloc(max(2 * len(self._R), self._n + k, 1024))
        sl = slice(self._n, self._n + k)
        self._pos[sl], self._nrm[sl], self._E[sl], self._R[sl] = x, nrm, E, R
        self._grot[sl], self._gtr[sl] = gr, gt
        # (n_i x n) . g = n . (g x n_i): per record once, so a pair needs one dot product.
        self._H[sl] = np.cross(gr, nrm[:, None, :])
        self._used[sl] = 0
        self._n += k
        self._classes = None
        self._indexes = {}
        self._geo = self._val = None
        return np.arange(sl.start, sl.stop)

    # persistence (engine/artifacts.py) -------------------------------------------------
    ARRAY_FIELDS = ("positions", "normals", "irradiance", "radius", "rot_grad", "trans_grad",
                    "usage")
    #: What saved records must hold (``engine/archive.py``): N records of C channels.
    SCHEMA = {"positions": (("<f8",), ("N", 3)), "normals": (("<f8",), ("N", 3)),
              "irradiance": (("<f8",), ("N", "C")), "radius": (("<f8",), ("N",)),
              "rot_grad": (("<f8",), ("N", "C", 3)), "trans_grad": (("<f8",), ("N", "C", 3)),
              "usage": (("<i8",), ("N",)), "channels": (("<i8",), ()), "index": (("U",), ()),
              "radius_ratio": (("<f8",), ()), "e_min": (("<f8",), ()),
              "cell_fraction": (("<f8",), ())}

    @staticmethod
    def value_problems(arrays) -> list[str]:
        """What is wrong with saved records' values (the shapes passed ``SCHEMA``): finite
        positions, unit normals, irradiance finite in [0, 1e30] W/m^2, radii finite and
        positive, finite gradients, the options within ``__init__``'s ranges."""
        out = []
        for key in ("positions", "rot_grad", "trans_grad"):
            if not np.isfinite(arrays[key]).all():
                out.append(f"record {key.replace('_', ' ')} are not finite")
        normals = arrays["normals"]
        length = np.sqrt(np.einsum("ij,ij->i", normals, normals))
        if not (np.isfinite(length).all() and np.all(np.abs(length - 1) <= 1e-6)):
            out.append("record normals are not unit vectors")
        e = arrays["irradiance"]
        if not (np.isfinite(e).all() and (e >= 0).all() and (e <= 1e30).all()):
            out.append("record irradiance is not finite in [0, 1e30] W/m^2")
        radius = arrays["radius"]
        if not (np.isfinite(radius).all() and (radius > 0).all()):
            out.append("record radii are not finite and positive")
        if (arrays["usage"] < 0).any():
            out.append("record usage counts are negative")
        if arrays["channels"].item() != arrays["irradiance"].shape[1]:
            out.append("the channel count disagrees with the irradiance's columns")
        try:
            IrradianceCache(channels=int(arrays["channels"]), index=str(arrays["index"]),
                            radius_ratio=float(arrays["radius_ratio"]),
                            e_min=float(arrays["e_min"]),
                            cell_fraction=float(arrays["cell_fraction"]))
        except ValueError as exc:
            out.append(str(exc))
        return out

    def to_arrays(self) -> dict:
        """The records as named numpy arrays (float64, usage int64) and the options as 0-d
        arrays; ``np.load(allow_pickle=False)`` reads them back."""
        out = {key: np.ascontiguousarray(getattr(self, key)) for key in self.ARRAY_FIELDS}
        out.update(channels=np.array(self.channels), index=np.array(self.index),
                   radius_ratio=np.array(self.radius_ratio), e_min=np.array(self.e_min),
                   cell_fraction=np.array(self.cell_fraction))
        return out

    @classmethod
    def from_arrays(cls, arrays) -> "IrradianceCache":
        """The inverse of ``to_arrays``: the same records bit for bit (normals are not
        normalised again, as ``add`` would), usage counters included."""
        cache = cls(channels=int(arrays["channels"]), index=str(arrays["index"]),
                    radius_ratio=float(arrays["radius_ratio"]), e_min=float(arrays["e_min"]),
                    cell_fraction=float(arrays["cell_fraction"]))
        n = len(np.asarray(arrays["radius"]))
        cache._alloc(n)
        for name, key in (("_pos", "positions"), ("_nrm", "normals"), ("_E", "irradiance"),
                          ("_R", "radius"), ("_grot", "rot_grad"), ("_gtr", "trans_grad")):
            getattr(cache, name)[:] = np.asarray(arrays[key], np.float64).reshape(
                getattr(cache, name).shape)
        cache._used[:] = np.asarray(arrays["usage"], np.int64)
        cache._H[:] = np.cross(cache._grot, cache._nrm[:, None, :])
        cache._n = n
        return cache

    # index ------------------------------------------------------------------------------
    def _radius_classes(self):
        if self._classes is None:
            R = self._R[:self._n]
            cls = np.floor(np.log(R) / np.log(self.radius_ratio)).astype(np.int64)
            order = np.argsort(cls, kind="stable")
            ids, first = np.unique(cls[order], return_index=True)
            self._classes = np.split(order, first[1:]) if len(order) else []
        return self._classes

    def _structures(self, a):
        key = float(a) if self.index == "grid" else None
        if key not in self._indexes:
            if len(self._indexes) >= 4:             # a few values of a at most
                self._indexes.pop(next(iter(self._indexes)))
            import time
            t0 = time.perf_counter()
            pos, R = self._pos[:self._n], self._R[:self._n]
            if self.index == "grid":
                structs = [_GridClass(pos, R, mem, a, self.cell_fraction) for mem in self._radius_classes()]
            else:
                structs = [_TreeClass(pos, R, mem) for mem in self._radius_classes()]
            self._indexes[key] = structs
            self.build_seconds = time.perf_counter() - t0
        return self._indexes[key]

    def candidates(self, points, a):
        """(point index, record index) pairs with |x - x_i| possibly < a R_i (a superset)."""
        qs, rs = [], []
        for s in self._structures(a):
            q, r = s.candidates(points) if self.index == "grid" else s.candidates(points, a)
            qs.append(q)
            rs.append(r)
        if not qs:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(qs), np.concatenate(rs)

    # interpolation ----------------------------------------------------------------------
    def interpolate(self, points, normals, a, use_gradients: bool = True, floor: float = 0.0,
                    chunk: int = 32768, count_usage: bool = True, pool=None):
        """Interpolated irradiance at ``points`` (P, 3) with unit ``normals`` (P, 3).

        Returns (E (P, C), covered (P,) bool, weight_sum (P,), count (P,) int64): E is 0 where
        no record has w_i > 1/a (not covered); covered points have weight_sum > 1/a.
        ``count_usage`` adds one to the usage counter of every record for every point it
        served. ``pool`` (an executor with ``map``) runs the chunks of ``chunk`` points
        concurrently (numpy releases the GIL in the gathers and arithmetic)."""
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        nq = np.asarray(normals, np.float64).reshape(-1, 3)
        p, c = len(pts), self.channels
        E = np.zeros((p, c))
        wsum = np.zeros(p)
        cnt = np.zeros(p, np.int64)
        a = float(a)
        if self._n == 0 or p == 0 or not a > 0:
            return E, np.zeros(p, bool), wsum, cnt
        self._tables()
        self._structures(a)                   # build once, before any concurrent chunk
        bounds = [(lo, min(p, lo + chunk)) for lo in range(0, p, chunk)]

        def run(b):
            lo, hi = b
            return self._interpolate_chunk(pts[lo:hi], nq[lo:hi], a, use_gradients, floor)

        parts = pool.map(run, bounds) if pool is not None else map(run, bounds)
        used = np.zeros(self._n, np.int64)
        for (lo, hi), (e_, w_, n_, u_) in zip(bounds, parts):
            E[lo:hi], wsum[lo:hi], cnt[lo:hi] = e_, w_, n_
            used += u_
        if count_usage:
            self._used[:self._n] += used
        return E, cnt > 0, wsum, cnt

    def _tables(self):
        """Column tables for the pair loop, one contiguous row per quantity (``np.take`` of a
        contiguous row, then arithmetic on contiguous arrays: 2-3x faster here than gathering
        rows of an (n, k) array): geometry (7, n) = x, n, R; values (7C, n) = E, grad_t, H."""
        if self._geo is None:
            n = self._n
            self._geo = np.ascontiguousarray(np.concatenate(
                [self._pos[:n], self._nrm[:n], self._R[:n, None]], axis=1).T)
            self._val = np.ascontiguousarray(np.concatenate(
                [self._E[:n], self._gtr[:n].reshape(n, -1), self._H[:n].reshape(n, -1)], axis=1).T)
        return self._geo, self._val

    def _interpolate_chunk(self, pts, nq, a, use_gradients, floor):
        p, c = len(pts), self.channels
        qi, ri, w, ext, _d2 = self._pair_terms(pts, nq, a, use_gradients, floor)
        wsum = np.bincount(qi, w, minlength=p)
        cnt = np.bincount(qi, minlength=p)
        E = np.zeros((p, c))
        for ch in range(c):
            E[:, ch] = np.bincount(qi, ext[ch] * w, minlength=p)
        ok = wsum > 0
        E[ok] /= wsum[ok, None]
        return E, wsum, cnt, np.bincount(ri, minlength=self._n)

    def _pair_terms(self, pts, nq, a, use_gradients, floor):
        """The (point, record) pairs with w_i > 1/a facing the same side: point and record
        indices, weights w_i, each record's extrapolated value at the point per channel
        (C, K) (Eq. 10.5's bracket, at least ``floor`` x E_i), and the squared distances."""
        c = self.channels
        geo, val = self._tables()
        qi, ri = self.candidates(pts, a)
        qcols = np.ascontiguousarray(np.concatenate([pts, nq], axis=1).T)    # (6, p)
        dx = [np.take(qcols[k], qi) - np.take(geo[k], ri) for k in range(3)]
        d2 = dx[0] * dx[0]
        d2 += dx[1] * dx[1]
        d2 += dx[2] * dx[2]
        cosn = np.take(qcols[3], qi) * np.take(geo[3], ri)
        cosn += np.take(qcols[4], qi) * np.take(geo[4], ri)
        cosn += np.take(qcols[5], qi) * np.take(geo[5], ri)
        np.clip(cosn, -1.0, 1.0, out=cosn)            # before the root: n . n_i = 1 + eps
        err = np.sqrt(d2)
        err /= np.take(geo[6], ri)
        err += np.sqrt(1.0 - cosn)
        keep = np.nonzero((err < a) & (cosn > 0))[0]
        qi, ri, err, d2 = qi[keep], ri[keep], err[keep], d2[keep]
        w = 1.0 / np.maximum(err, self.e_min)
        if use_gradients:
            dx = [np.take(d, keep) for d in dx]
            nk = [np.take(qcols[3 + k], qi) for k in range(3)]
        ext = np.empty((c, len(qi)))
        for ch in range(c):
            e_i = np.take(val[ch], ri)
            ext[ch] = e_i
            if use_gradients:
                for k in range(3):
                    ext[ch] += dx[k] * np.take(val[c + 3 * ch + k], ri)
                    ext[ch] += nk[k] * np.take(val[4 * c + 3 * ch + k], ri)
                np.maximum(ext[ch], floor * e_i, out=ext[ch])
        return qi, ri, w, ext, d2

    def neighbour_predictions(self, a, use_gradients: bool = True, floor: float = 0.0,
                              chunk: int = 2048, pool=None):
        """For every record j, the other records i whose reach covers it (w_i(x_j, n_j) > 1/a,
        same side): (j, i, |x_j - x_i|, E_i extrapolated to x_j by Eq. 10.5's bracket (K, C)).
        What a record's neighbours predict where a gather was actually made.

        The records are asked in blocks of ``chunk``, on ``pool`` (an executor with ``map``)
        when given: the pairs are the same, block by block in record order. (Asked at once,
        Scene 2's 15.5k records at 640 x 480, ``final``, made 1.5M pairs from one call's
        temporaries, 4.0 s on one thread; in blocks on two threads, measured in the README.)"""
        if self._n == 0:
            return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0),
                    np.zeros((0, self.channels)))
        self._tables()
        self._structures(a)                   # build once, before any concurrent block
        pos, nrm, a = self.positions, self.normals, float(a)

        def run(lo):
            qi, ri, _w, ext, d2 = self._pair_terms(pos[lo:lo + chunk], nrm[lo:lo + chunk], a,
                                                   use_gradients, floor)
            qi += lo
            other = np.nonzero(qi != ri)[0]
            return qi[other], ri[other], np.sqrt(d2[other]), ext[:, other].T

        starts = range(0, self._n, chunk)
        parts = list(pool.map(run, starts) if pool is not None else map(run, starts))
        return tuple(np.concatenate([part[k] for part in parts]) for k in range(4))

    def limit_radius(self, radius) -> int:
        """R_i = min(R_i, radius_i) for every record ((n,) array; inf leaves a record as it
        is); the index is rebuilt on the next look-up. Returns how many radii shrank."""
        radius = np.asarray(radius, np.float64).reshape(self._n)
        smaller = radius < self._R[:self._n]
        if not smaller.any():
            return 0
        if not np.all(radius[smaller] > 0):
            raise ValueError("record radii must stay > 0")
        self._R[:self._n] = np.where(smaller, radius, self._R[:self._n])
        self._classes = None
        self._indexes = {}
        self._geo = self._val = None
        return int(smaller.sum())

    # reporting --------------------------------------------------------------------------
    def stats(self) -> dict:
        """Record count, memory [bytes] (records and built indexes), and the usage counter:
        ``usage`` (per record, the interpolated points it served), with its summary."""
        n = self._n
        index_bytes = sum(getattr(s, "nbytes", 0) for v in self._indexes.values() for s in v)
        tables = 0 if self._geo is None else self._geo.nbytes + self._val.nbytes
        live = sum(getattr(self, f)[:n].nbytes for f in
                   ("_pos", "_nrm", "_E", "_R", "_grot", "_gtr", "_H", "_used"))
        used = self._used[:n].copy()
        return {
            "records": n,
            "memory_bytes": int(live + tables + index_bytes),
            "allocated_bytes": int(sum(getattr(self, f).nbytes for f in
                                       ("_pos", "_nrm", "_E", "_R", "_grot", "_gtr", "_H", "_used"))
                                   + tables + index_bytes),
            "usage": used,
            "usage_mean": float(used.mean()) if n else 0.0,
            "usage_max": int(used.max()) if n else 0,
            "unused_records": int((used == 0).sum()),
            "radius_classes": len(self._radius_classes()) if n else 0,
            "index": self.index,
            "index_build_seconds": self.build_seconds,
        }

    def reset_usage(self):
        """Zero every record's usage counter (a render that reuses baked records counts its
        own use)."""
        self._used[:] = 0
