"""Final gather (seed chapter 8) over irradiance precomputed at photons (Christensen 1999).

What it computes
    ``RadianceEstimates.build(photon_map, scene, ...)``  irradiance E [W/m^2, RGB] from the
        global photon map (Eq. 9.11, the estimate of ``PhotonMap.irradiance``) at a subset of
        the photon positions, each with its surface normal; a kd-tree over them. A gather ray
        that lands on a diffuse surface then needs one nearest-neighbour look-up instead of a
        k-photon estimate: reflected radiance L = rho_d / pi * E of the nearest precomputed
        point whose normal agrees (n . n_i > 0.5). The estimates divide by the part of their
        disc that their surface covers (``coverage``: ``Accelerator.disc_coverage``), so
        that gather rays that land by an edge or in a corner do not read it too dark.
        Christensen reports 5-7x faster final gathering; the blur it adds is hidden behind
        the gather's own averaging.
    ``StrandEstimates.build(photon_map, accel, triangles, strands)``  the same on hair
        (``Scene.strands``), where the surface estimate fails: the flux landing on strands
        in a sphere over the strands' own area in it, with the light's direction (its
        docstring); gather rays that meet hair read these.
    ``final_gather(points, normals, ...)``  indirect irradiance at shading points by the
        stratified final gather: M x N cosine-distributed directions per point,
        theta_j = asin(sqrt((j + xi1) / M)), phi_k = 2 pi (k + xi2) / N (Eq. 8.4-8.6), so that
        E = pi / (M N) * sum_jk L_jk. Where a gather ray lands:
        * on a diffuse surface: rho_d / pi * E of the precomputed estimates (direct and
          indirect light of that surface, as the photon map holds both); below a Principled
          specular layer x (1 - E_layer(mu)) at the ray's own angle (Cycles' layering); a
          translucent closure adds rho_t / pi * E of the estimates on the far side;
        * on a specular surface (``MaterialTable.is_transport_specular``: a mirror, glossy
          lobes, glass, a Principled layer) the ray also goes on, up to ``max_specular``
          bounces, by sampling the surface's lobes (``bsdf.sample_glossy``; mirrors reflect),
          with Russian roulette on the weight w: it goes on with probability
          min(1, max w / ``ROULETTE_WEIGHT``), its weight divided by that (mirrors of rho_s
          >= 0.5 and glass always go on, a layer's few per cent rarely); the emission of what it then meets is counted (an emitter seen in a
          mirror lights the gather point indirectly) unless a caustic map holds that light
          (``mirrored_emission`` False);
        * on an emitter, or into the world: nothing. The emission of meshes and the world's
          radiance are direct light, which ``engine/direct.py`` computes exactly for every
          shading point; counting them here would count them twice. Except the smooth part
          of an image world with a sun (``sky``: ``lights.EnvironmentLight.gather_sky``): the
          light samples then count the sun's patches alone, and a first ray that leaves the
          scene counts the image outside them (a gather of M x N rays estimates smooth sky
          light far better than a pixel's few light samples, and the cache interpolates it).
          That sky light is direct light at the gather point: with ``split_sky`` it comes in
          three channels of its own (C = 6), which the light passes file as Cycles does
          (Diffuse Direct, ``engine/passes.py``).
        Returns E (P, C) and, per stratum, the radiance L (P, M, N, C) and hit distance
        r (P, M, N) (inf for a miss), from which the irradiance cache derives R_i and the
        gradients of Ward & Heckbert 1992.

Parameters
    ===================  ========  ==========================================================
    name                 default   meaning
    ===================  ========  ==========================================================
    gather_m, gather_n   8, 32     theta and phi strata: M x N rays per gather point
    fraction             0.25      share of the stored photons that get an estimate (Christensen
                                   used 1/4); at most ``max_estimates``
    max_estimates        400 000   cap on the precomputed estimates (time and memory)
    k                    50        photons per precomputed estimate
    AREA_POINTS          2         hair: points spread over the strands' area per photon on a
                                   strand; AREA_NEIGHBOURS = 64 of them set a sphere, which
                                   may hold MAX_SPHERE_PHOTONS = 256 photons
    max_specular         4         specular bounces a gather ray may take (the plan: 8 with
                                   glass)
    ROULETTE_WEIGHT      0.5       a continuation of smaller weight goes on by roulette
    ===================  ========  ==========================================================
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import sampling
from .bsdf import layer_diffuse_factor, sample_glossy
from .textures import DIFFUSE_RAY, ray_after_bounce

ROULETTE_WEIGHT = 0.5      # continuations of smaller weight go on by Russian roulette

LOOKUP_NEIGHBOURS = 4       # nearest estimates inspected for one with an agreeing normal
DISC_THICKNESS = 0.25       # a look-up's disc, as the photon estimate's (photons.py)
GUIDE_PHOTONS = 128         # nearby photons whose directions steer a guided gather
GATHER_RAYS_PER_CALL = 1 << 19   # rays in flight per chunk of final_gather (~150 B a ray)
LUMA = np.array([0.2126, 0.7152, 0.0722])
PROBE_OFFSETS = 4           # a photon's probe into its own surface, in ray offsets
AREA_POINTS = 2             # points spread over the strands' area per photon on a strand
AREA_NEIGHBOURS = 64        # area points in a strand estimate's sphere
MAX_AREA_POINTS = 4_000_000
MAX_SPHERE_PHOTONS = 256    # photons a strand estimate's sphere may hold
ESTIMATE_CHUNK = 8192       # strand estimates per chunk (bounds the neighbour arrays)


@dataclass
class RadianceEstimates:
    """Irradiance precomputed at photon positions (Christensen 1999)."""

    positions: np.ndarray           # (Q, 3) float32 [m]
    normals: np.ndarray             # (Q, 3) float32
    irradiance: np.ndarray          # (Q, 3) float32 [W/m^2]
    stats: dict = field(default_factory=dict)
    _tree: object = None
    max_radius: float = np.inf      # the photon estimate's radius cap [m]: bounds a look-up
    strands: "StrandEstimates | None" = None    # estimates on hair (``StrandEstimates``)

    def __len__(self):
        return len(self.positions)

    @classmethod
    def build(cls, photon_map, k: int = 50, max_radius: float = np.inf, fraction: float = 0.25,
              max_estimates: int = 400_000, pool=None, seed: int = 0,
              coverage=None) -> "RadianceEstimates":
        """Estimates at every 1/``fraction``-th photon of ``photon_map`` (which must hold all
        photons, direct and indirect: a gather ray's landing point reflects both), in chunks
        on ``pool``. The photons are in Morton order, so a regular stride spreads the
        estimates evenly over the surfaces. ``coverage``: the share of each estimate's disc
        that its surface covers (``PhotonMap.irradiance``; ``Accelerator.disc_coverage``)."""
        t0 = time.perf_counter()
        total = len(photon_map)
        wanted = int(min(max_estimates, max(1, round(total * fraction)))) if total else 0
        if wanted == 0:
            empty = np.zeros((0, 3), np.float32)
            out = cls(empty, empty.copy(), empty.copy())
            out.stats = {"estimates": 0, "seconds": 0.0}
            return out
        pick = np.linspace(0, total - 1, wanted).astype(np.int64)
        positions = photon_map.positions[pick].astype(np.float64)
        normals = photon_map.normals[pick].astype(np.float64)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        chunks = np.array_split(np.arange(wanted), max(1, wanted // 16384))

        def estimate(c):
            counters = {}                    # one per chunk: the pool's threads share none
            e = photon_map.irradiance(positions[c], normals[c], k=k, max_radius=max_radius,
                                      stats=counters, coverage=coverage)
            return e, counters

        parts = list(pool.map(estimate, chunks)) if pool is not None else [estimate(c) for c in chunks]
        irradiance = np.concatenate([e for e, _ in parts]).astype(np.float32)
        queries = sum(c.get("queries", 0) for _, c in parts)
        query_seconds = sum(c.get("query_seconds", 0.0) for _, c in parts)
        out = cls(positions.astype(np.float32), normals.astype(np.float32), irradiance,
                  max_radius=float(max_radius))
        from pykdtree.kdtree import KDTree
        out._tree = KDTree(out.positions, leafsize=16)
        out.stats = {"estimates": wanted, "fraction": wanted / total, "k": k,
                     "seconds": time.perf_counter() - t0, "bytes": int(3 * out.positions.nbytes),
                     "queries": queries, "query_thread_seconds": query_seconds}
        return out

    def lookup(self, points: np.ndarray, normals: np.ndarray, on_strands=None) -> np.ndarray:
        """Irradiance (N, 3) at ``points``: where ``on_strands`` (N,) bool, hits on hair, from
        the ``strands`` estimates when there are any; elsewhere (:meth:`surface_lookup`) of
        the nearest surface estimate whose normal agrees."""
        if on_strands is None or self.strands is None or not len(self.strands) \
                or not np.any(on_strands):
            return self.surface_lookup(points, normals)
        out = np.empty((len(points), 3), np.float32)
        out[on_strands] = self.strands.lookup(points[on_strands], normals[on_strands])
        rest = ~on_strands
        if rest.any():
            out[rest] = self.surface_lookup(points[rest], normals[rest])
        return out

    def surface_lookup(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Irradiance (N, 3) of the nearest estimate whose normal agrees with ``normals``
        (n . n_i > 0.5) among the ``LOOKUP_NEIGHBOURS`` nearest; 0 where none does. With a
        finite ``max_radius`` only estimates within it and within ``DISC_THICKNESS`` x it of
        the point's tangent plane count, as photons in the estimate's disc (Fig. 9.5): a
        surface without photons nearby (the floor under a closed lamp shade) must not take
        the irradiance of the far side of a shell."""
        out = np.zeros((len(points), 3), np.float32)
        if self._tree is None or len(points) == 0:
            return out
        kk = int(min(LOOKUP_NEIGHBOURS, len(self)))
        pts32 = np.ascontiguousarray(points, np.float32)
        bounded = bool(np.isfinite(self.max_radius))

        def nearest(query_points, k):
            if bounded:
                _dist, found = self._tree.query(query_points, k=k,
                                                distance_upper_bound=float(self.max_radius))
            else:
                _dist, found = self._tree.query(query_points, k=k)
            return found.reshape(len(query_points), k).astype(np.int64)

        nrm = normals.astype(np.float32)
        # The nearest estimate agrees for nearly every point: it is found and tested alone
        # first, and only the rest look at their other neighbours (the same choice: the
        # first that agrees, nearest first).
        first_idx = nearest(pts32, 1)[:, 0]
        agree = self._agrees(first_idx, pts32, nrm, bounded)
        out[agree] = np.take(self.irradiance, first_idx[agree], axis=0)
        rest = np.flatnonzero(~agree)
        if len(rest) and kk > 1:
            others = nearest(np.ascontiguousarray(pts32[rest]), kk)[:, 1:]
            cols = others.shape[1]
            ok = self._agrees(others.reshape(-1), np.repeat(pts32[rest], cols, axis=0),
                              np.repeat(nrm[rest], cols, axis=0), bounded).reshape(-1, cols)
            first = np.argmax(ok, axis=1)
            rows = np.arange(len(rest))
            found = ok[rows, first]
            out[rest[found]] = np.take(self.irradiance, others[rows, first][found], axis=0)
        return out

    def _agrees(self, idx, points32, normals32, bounded: bool) -> np.ndarray:
        """(N,) bool: estimate ``idx`` (N,) exists (the tree's misses are ``len(self)``), its
        normal agrees with ``normals32`` (n . n_i > 0.5) and, where ``bounded``, it lies
        within ``DISC_THICKNESS`` x ``max_radius`` of the point's tangent plane."""
        found = idx < len(self)
        safe = np.where(found, idx, 0)
        agree = found & (np.einsum("nj,nj->n", np.take(self.normals, safe, axis=0),
                                   normals32) > 0.5)
        if bounded:
            offset = np.take(self.positions, safe, axis=0) - points32
            agree &= np.abs(np.einsum("nj,nj->n", offset, normals32)) \
                <= DISC_THICKNESS * self.max_radius
        return agree


@dataclass
class StrandEstimates:
    """Irradiance precomputed at photons that landed on hair (``Scene.strands``): where
    strands tangle, photons land on surfaces of every orientation inside the search sphere,
    and the surface estimate (photons within a disc of the tangent plane, from the point's
    side, over pi r^2) sees few of them: a fur ball came out 24 % dark against Cycles. Here
    the flux landing on the strands within a sphere is divided by the strands' own surface
    area in it, counted with points spread evenly over the strands' area (``AREA_POINTS`` per
    strand photon); the sphere is the one that holds ``AREA_NEIGHBOURS`` such points. Photons
    land on strands of every orientation alike, so their directions also give the light's
    direction: with n the look-up's normal, E(n) = (sum Phi + 2 sum Phi (-w) . n) / A, the
    first two spherical-harmonic bands of sum Phi max(0, -w . n) x 4 / A (clamped at 0),
    whose mean over normals is sum Phi / A."""

    positions: np.ndarray           # (H, 3) float32 [m]
    base: np.ndarray                # (H, 3) float32: sum Phi / A [W/m^2]
    slope: np.ndarray               # (H, 3, 3) float32: per channel 2 sum Phi (-w) / A
    stats: dict = field(default_factory=dict)
    _tree: object = None

    def __len__(self):
        return len(self.positions)

    @classmethod
    def build(cls, photon_map, accel, triangles, strands, fraction: float = 0.25,
              seed: int = 0, max_estimates: int = 400_000) -> "StrandEstimates":
        """Estimates at every 1/``fraction``-th photon of ``photon_map`` that lies on a strand
        (a ray of ``PROBE_OFFSETS`` self-intersection offsets back along its normal meets a
        strand triangle; ``accel`` traces the scene's ``triangles``);
        ``triangles`` (T, 3, 3) and ``strands`` (T,) bool are the scene's."""
        from pykdtree.kdtree import KDTree
        t0 = time.perf_counter()
        tri = np.asarray(triangles, np.float64)[np.asarray(strands, bool)]
        empty = cls(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32),
                    np.zeros((0, 3, 3), np.float32))
        empty.stats = {"strand_estimates": 0, "seconds": 0.0}
        if len(tri) == 0 or len(photon_map) == 0:
            return empty
        # Which photons lie on a strand: a short ray back into the surface each arrived on.
        photons = np.ascontiguousarray(photon_map.positions, np.float32)
        normals = np.asarray(photon_map.normals, np.float32)
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        step = (PROBE_OFFSETS * accel.offset_distance(photons)).astype(np.float32)
        _t, prim, _u, _v = accel.intersect(photons + normals * step[:, None], -normals,
                                           2.0 * step)
        on = (prim >= 0) & np.asarray(strands, bool)[np.maximum(prim, 0)]
        if on.sum() < AREA_NEIGHBOURS:
            return empty
        # Points spread evenly over the strands' area, each standing for ``unit`` m^2.
        rng = np.random.default_rng(seed + 0x5752)
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                    axis=1)
        count = int(min(max(AREA_POINTS * on.sum(), 10 * AREA_NEIGHBOURS), MAX_AREA_POINTS))
        pick = rng.choice(len(tri), size=count, p=area / area.sum())
        bary = sampling.square_to_triangle(rng.random((count, 2)))
        alpha, beta = bary[:, :1], bary[:, 1:]
        points = alpha * tri[pick, 0] + (1.0 - alpha - beta) * tri[pick, 1] + beta * tri[pick, 2]
        unit = area.sum() / count
        area_tree = KDTree(points.astype(np.float32), leafsize=16)
        strand_photons = np.flatnonzero(on)
        photon_tree = KDTree(photons[strand_photons], leafsize=16)
        power = np.asarray(photon_map.power, np.float64)[strand_photons]
        towards = -np.asarray(photon_map.incoming, np.float64)[strand_photons]
        towards /= np.maximum(np.linalg.norm(towards, axis=1, keepdims=True), 1e-12)
        wanted = int(min(max_estimates, max(1, round(len(strand_photons) * fraction))))
        at = photons[strand_photons[np.linspace(0, len(strand_photons) - 1, wanted)
                                    .astype(np.int64)]]
        base = np.zeros((wanted, 3))
        slope = np.zeros((wanted, 3, 3))
        full = 0                        # spheres that held MAX_SPHERE_PHOTONS (undercounted)
        for a in range(0, wanted, ESTIMATE_CHUNK):
            b = min(a + ESTIMATE_CHUNK, wanted)
            d_area, _ = area_tree.query(at[a:b], k=AREA_NEIGHBOURS)
            radius = np.asarray(d_area, np.float64)[:, -1]
            d_ph, idx = photon_tree.query(at[a:b], k=MAX_SPHERE_PHOTONS,
                                          distance_upper_bound=float(radius.max()))
            idx = np.asarray(idx).reshape(b - a, -1)
            inside = (idx < len(strand_photons)) & (np.asarray(d_ph).reshape(b - a, -1)
                                                    <= radius[:, None])
            full += int(np.count_nonzero(inside[:, -1]))
            inside[:, 0] = False        # the estimate's own photon: +1/32 on average else
            flat = np.where(inside, idx, 0)
            weight = inside.astype(np.float64)
            phi = power[flat] * weight[..., None]                       # (n, K, 3)
            # The sphere holds AREA_NEIGHBOURS x unit of strand area on average, and the
            # photons in it are independent of the area points that set its radius.
            a_sphere = AREA_NEIGHBOURS * unit
            base[a:b] = phi.sum(axis=1) / a_sphere
            slope[a:b] = 2.0 * np.einsum("nkc,nkj->ncj", phi, towards[flat]) / a_sphere
        out = cls(at.astype(np.float32), base.astype(np.float32), slope.astype(np.float32))
        out._tree = KDTree(out.positions, leafsize=16)
        out.stats = {"strand_estimates": wanted, "strand_photons": int(len(strand_photons)),
                     "area_points": count, "full_spheres": full,
                     "seconds": time.perf_counter() - t0}
        return out

    def lookup(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Irradiance (N, 3) on hair at ``points`` with ``normals``: the nearest estimate's
        E(n) (class docstring)."""
        out = np.zeros((len(points), 3), np.float32)
        if self._tree is None or len(points) == 0:
            return out
        _dist, idx = self._tree.query(np.ascontiguousarray(points, np.float32), k=1)
        idx = np.asarray(idx).reshape(-1).astype(np.int64)
        found = idx < len(self)
        idx = np.where(found, idx, 0)
        e = self.base[idx] + np.einsum("ncj,nj->nc", self.slope[idx],
                                       np.asarray(normals, np.float32))
        out[found] = np.maximum(e[found], 0.0)
        return out


def photon_guided_allocation(points, normals, photon_map, m, n, extra, k=GUIDE_PHOTONS,
                             rng=None):
    """Rays per stratum (P, M*N) int: 1 everywhere plus ``extra`` rays a point shared among its
    strata in proportion to the flux of the nearby photons that arrived through them
    (Jensen 1995, "Importance driven path tracing using the photon map"). Only photons that
    bounced at least once count (direct light is computed exactly elsewhere). The allocation
    is fixed before any ray is traced and each stratum's radiance is the mean of its rays, so
    the estimate stays unbiased; bright small patches (a lamp's lit surroundings) get the
    rays that a uniform gather would spend elsewhere."""
    count, cells = len(points), m * n
    alloc = np.ones((count, cells), np.int64)
    if photon_map is None or len(photon_map) == 0 or extra <= 0 or count == 0:
        return alloc
    kk = int(min(k, len(photon_map)))
    _dist, idx = photon_map.query(np.ascontiguousarray(points, np.float32), kk)
    found = idx < len(photon_map)
    flat = np.where(found, idx, 0).reshape(-1)
    nrm = normals.astype(np.float32)
    inc = np.take(photon_map.incoming, flat, axis=0).astype(np.float32).reshape(count, kk, 3)
    pn = np.take(photon_map.normals, flat, axis=0).astype(np.float32).reshape(count, kk, 3)
    towards = -inc                                                     # to where light came from
    t, b = sampling.orthonormal_basis(normals.astype(np.float64))
    cos_t = np.einsum("pkj,pj->pk", towards, nrm)
    keep = found & (cos_t > 0) & (np.einsum("pkj,pj->pk", pn, nrm) > 0.5)
    keep &= np.take(photon_map.bounces, flat).reshape(count, kk) >= 1
    x = np.einsum("pkj,pj->pk", towards, t.astype(np.float32))
    y = np.einsum("pkj,pj->pk", towards, b.astype(np.float32))
    sin2 = np.clip(1.0 - cos_t * cos_t, 0.0, 1.0 - 1e-9)
    j = np.minimum((sin2 * m).astype(np.int64), m - 1)
    phi = np.mod(np.arctan2(y, x), 2 * np.pi)
    kk_ = np.minimum((phi * (n / (2 * np.pi))).astype(np.int64), n - 1)
    weight = np.take(photon_map.power, flat, axis=0).astype(np.float64).reshape(count, kk, 3) @ LUMA
    weight *= keep
    key = (np.arange(count)[:, None] * cells + j * n + kk_).reshape(-1)
    hist = np.bincount(key, weights=weight.reshape(-1), minlength=count * cells).reshape(count, cells)
    total = hist.sum(axis=1, keepdims=True)
    share = np.divide(hist, total, out=np.zeros_like(hist), where=total > 0) * extra
    u = (rng or np.random.default_rng(0)).random(share.shape)
    alloc += np.floor(share + u).astype(np.int64)                       # randomised rounding
    return alloc


def final_gather(points: np.ndarray, normals: np.ndarray, offset_normals: np.ndarray,
                 estimates: RadianceEstimates, accel, surfaces, rng: np.random.Generator,
                 m: int = 8, n: int = 32, max_specular: int = 4, stats: dict | None = None,
                 guide=None, guide_extra: float = 1.0, mirrored_emission: bool = True,
                 sky=None, split_sky: bool = False):
    """Indirect irradiance at ``points`` (P, 3) with unit ``normals`` (facing the viewer) by the
    stratified final gather. ``offset_normals``: geometric normals for the ray offset.
    ``surfaces``: the scene's ``surfaces.SceneSurfaces`` (normals and materials at hits; a
    landing point's material is read through ``bsdf``). ``guide``: a photon map whose
    nearby photons steer ``guide_extra`` x M x N extra rays into the strata their light came
    through (``photon_guided_allocation``); None: one ray per stratum.
    ``mirrored_emission`` False: emitters met after a specular bounce are not counted (the
    caustic photon map holds that light, light -> specular -> here, when one is built).
    ``sky``: radiance (K, 3) of world directions (K, 3) that the rays leaving the scene count
    (the smooth sky the world light left to the gather, module docstring); None: nothing.
    ``split_sky``: that sky's light in channels of its own (C = 6: the three channels of the
    light the rays met at surfaces, then the three of the sky they saw, which is direct
    light at the gather point: Cycles' Diffuse Direct pass), else added in (C = 3).

    Returns (E (P, C), L (P, M, N, C), r (P, M, N)): irradiance, per-stratum radiance (the
    mean of its rays) and hit distance of its first ray (inf for a miss). Points are taken in
    chunks of at most about ``GATHER_RAYS_PER_CALL`` rays, so memory stays bounded however
    many points a caller passes (75M rays in one call was killed for memory)."""
    extra = guide_extra if guide is not None else 0.0
    step = max(1, int(GATHER_RAYS_PER_CALL // (m * n * (1.0 + extra))))
    if len(points) <= step:
        return _final_gather_chunk(points, normals, offset_normals, estimates, accel, surfaces,
                                   rng, m, n, max_specular, stats, guide, guide_extra,
                                   mirrored_emission, sky, split_sky)
    parts = [_final_gather_chunk(points[a:a + step], normals[a:a + step],
                                 offset_normals[a:a + step], estimates, accel, surfaces, rng, m, n,
                                 max_specular, stats, guide, guide_extra, mirrored_emission, sky,
                                 split_sky)
             for a in range(0, len(points), step)]
    return tuple(np.concatenate(columns) for columns in zip(*parts))


def _final_gather_chunk(points, normals, offset_normals, estimates, accel, surfaces, rng, m, n,
                        max_specular, stats, guide, guide_extra, mirrored_emission=True,
                        sky=None, split_sky=False):
    count = len(points)
    cells = m * n
    alloc = photon_guided_allocation(points, normals, guide, m, n, guide_extra * cells, rng=rng) \
        if guide is not None else np.ones((count, cells), np.int64)
    stratum = np.repeat(np.arange(count * cells), alloc.reshape(-1))      # stratum of each ray
    first = np.concatenate([[0], np.cumsum(alloc.reshape(-1))[:-1]])      # its first ray
    point_of = stratum // cells
    j, k = (stratum % cells) // n, stratum % n
    u = rng.random((len(stratum), 2))
    sin2 = (j + u[:, 0]) / m
    sin_t = np.sqrt(sin2)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2))
    phi = 2.0 * np.pi * (k + u[:, 1]) / n
    lx, ly = sin_t * np.cos(phi), sin_t * np.sin(phi)
    t, b = sampling.orthonormal_basis(normals.astype(np.float64))
    nn = normals.astype(np.float64)
    # Row gathers by np.take (twice the speed of fancy indexing).
    dirs = (lx[:, None] * np.take(t, point_of, axis=0) + ly[:, None] * np.take(b, point_of, axis=0)
            + cos_t[:, None] * np.take(nn, point_of, axis=0))
    origin_points = np.take(points.astype(np.float64), point_of, axis=0)
    origin_normals = np.take(offset_normals.astype(np.float64), point_of, axis=0)
    total_rays = len(stratum)
    radiance = np.zeros((total_rays, 3))
    # The sky the first rays see, in channels of its own when asked (``split_sky``).
    sky_radiance = np.zeros((total_rays, 3)) if split_sky and sky is not None else radiance
    distance = np.full(total_rays, np.inf)
    origins = accel.offset_origins(origin_points, origin_normals, dirs)
    ray_of = np.arange(total_rays)
    throughput = None
    # The rays' Light Path values (``textures``): a diffuse bounce's, then each mirror,
    # glossy or glass bounce's (``ray_after_bounce``).
    path_ray = None
    rays = 0
    t0 = time.perf_counter()
    for bounce in range(max_specular + 1):
        if len(ray_of) == 0:
            break
        tt, prim, bu, bv = accel.intersect(origins, dirs)
        rays += len(ray_of)
        hit = prim >= 0
        if bounce == 0:
            distance[ray_of[hit]] = tt[hit]
            if sky is not None and not hit.all():
                sky_radiance[ray_of[~hit]] += sky(np.asarray(dirs[~hit], np.float64))
        ray_of, origins, dirs, tt, prim = ray_of[hit], origins[hit], dirs[hit], tt[hit], prim[hit]
        bu, bv = bu[hit], bv[hit]
        if throughput is not None:
            throughput = throughput[hit]
        if path_ray is not None:
            path_ray = {k: v[hit] for k, v in path_ray.items()}
        if len(ray_of) == 0:
            break
        x = origins + tt[:, None].astype(np.float64) * dirs
        ng = np.take(surfaces.geometric_normals, prim, axis=0).astype(np.float64)
        facing = np.einsum("ij,ij->i", ng, dirs) > 0
        ng[facing] *= -1                                   # towards the gather ray
        surface = surfaces.params(prim, bu, bv, dirs, ray={
            **(DIFFUSE_RAY if path_ray is None else path_ray), "Ray Length": tt})
        if bounce > 0 and mirrored_emission and surfaces.materials.has_emission:
            # An emitter seen in a mirror is indirect light at the gather point (its direct
            # light is the emitters it sees straight): counted here, or it was lost.
            emitted = surface.emitted_radiance * (~facing | surface.both_sides)[:, None]
            radiance[ray_of] += emitted * throughput
        # The diffuse radiance towards the gather point: rho_d / pi, below a Principled
        # specular layer x (1 - E_layer) at this ray's own angle (Cycles' layering; the
        # layer's own reflection is the continuation below).
        rho = surface.diffuse_over_pi
        if surfaces.materials.has_layer:
            rho = rho * layer_diffuse_factor(surfaces.materials, surface.material,
                                             -dirs.astype(np.float64), ng)
        diffuse = np.any(rho > 0, axis=1)
        if diffuse.any():
            strands = getattr(surfaces, "strands", None)
            if strands is None:
                e = estimates.lookup(x[diffuse], ng[diffuse]).astype(np.float64)
            else:                                  # hair: its own estimates
                e = estimates.lookup(x[diffuse], ng[diffuse],
                                     strands[prim[diffuse]]).astype(np.float64)
            value = e * rho[diffuse]
            if throughput is not None:
                value *= throughput[diffuse]
            radiance[ray_of[diffuse]] += value
        if surfaces.materials.has_translucent:
            # Translucent closures: rho_t / pi x the irradiance on the far side.
            through = np.flatnonzero(np.any(surface.translucent > 0, axis=1))
            if len(through):
                e = estimates.lookup(x[through], -ng[through]).astype(np.float64)
                value = e * surface.translucent[through] / np.pi
                if throughput is not None:
                    value *= throughput[through]
                radiance[ray_of[through]] += value
        mirror = surface.is_transport_specular
        if bounce == max_specular or not mirror.any():
            break
        idx = np.nonzero(mirror)[0]
        nm = ng[idx]
        incoming = dirs[idx]
        dirs, weight, pdf = surface.subset(idx).bsdf(transport=True).mirror.sample(-incoming,
                                                                                    nm)
        pdf = np.broadcast_to(np.asarray(pdf, np.float64), (len(idx),)).copy()
        if surfaces.materials.has_glossy:
            # Materials with glossy lobes (issue 23): sampled (bsdf.sample_glossy), not
            # mirrored.
            glossy = np.flatnonzero(surface.camera_glossy[idx])
            if len(glossy):
                per_hit = surface.lobe_inputs
                g_dirs, g_weight, g_pdf = sample_glossy(
                    surfaces.materials, surface.material[idx[glossy]],
                    -incoming[glossy].astype(np.float64), nm[glossy].astype(np.float64), rng,
                    ~facing[idx[glossy]],
                    per_hit=None if per_hit is None else per_hit[idx[glossy]])
                dirs = dirs.astype(np.float64)
                weight = weight.astype(np.float64)
                dirs[glossy], weight[glossy] = g_dirs, g_weight
                pdf[glossy] = g_pdf
        # Russian roulette on the continuation: it goes on with probability q = the largest
        # channel of its weight / ROULETTE_WEIGHT (at most 1), its weight divided by q. A
        # mirror of rho_s >= 0.5 or glass always goes on; a Principled specular layer (weight
        # ~ F, a few %) rarely, so that walls of Principled BSDFs do not multiply the rays.
        q = np.clip(np.max(weight, axis=1) / ROULETTE_WEIGHT, 0.0, 1.0)
        go = rng.random(len(q)) < q
        weight = np.asarray(weight, np.float64)[go] / q[go, None]
        idx, dirs, nm = idx[go], np.asarray(dirs)[go], nm[go]
        if len(idx) == 0:
            break
        if surfaces.materials.reads_light_path:
            path_ray = ray_after_bounce(
                DIFFUSE_RAY if path_ray is None else {k: v[idx] for k, v in path_ray.items()},
                dirs, incoming[go], nm, np.isinf(pdf[go]))
        origins = accel.offset_origins(x[idx], nm, dirs)
        throughput = weight if throughput is None else throughput[idx] * weight
        ray_of = ray_of[idx]
    if stats is not None:
        stats["gather_rays"] = stats.get("gather_rays", 0) + rays
        stats["gather_points"] = stats.get("gather_points", 0) + count
        stats["gather_seconds"] = stats.get("gather_seconds", 0.0) + time.perf_counter() - t0
    if sky_radiance is not radiance:
        radiance = np.concatenate([radiance, sky_radiance], axis=1)
    channels = radiance.shape[1]
    per_stratum = np.zeros((count * cells, channels))
    for c in range(channels):
        per_stratum[:, c] = np.bincount(stratum, weights=radiance[:, c], minlength=count * cells)
    per_stratum /= alloc.reshape(-1, 1)
    per_stratum = per_stratum.reshape(count, m, n, channels)
    irradiance = np.pi / cells * per_stratum.sum(axis=(1, 2))
    return irradiance, per_stratum, distance[first].reshape(count, m, n)
