"""Shadow photons: lit / umbra / penumbra classes per light, so direct light skips shadow rays.

What it computes (seed 7.2 and 9.6; Jensen and Christensen 1995, "Efficiently rendering
shadows using the photon map")
    ``build_shadow_photon_map(scene, accel, lights, count)`` emits ``count`` photons from the
    sampled lights that have a position (``lights.sampled`` entries that are
    ``TriangleEmitter``: square / rectangle area lights and emissive meshes, or
    ``EllipseEmitter``: disk / ellipse area lights; suns with an angle, point and spot lights
    with a radius (``SphereLight``: their penumbrae are traced, as for an area light whose
    ``shadow_photons`` is off) and the world keep plain shadow rays). A light whose ``shadow_photons`` flag is off (``AreaLight.shadow_photons``,
    Blender's ``Light.lanterna.shadow_photons``, carried onto its emitter by ``LightSet``)
    sends none: the map does not cover it (``covers`` is False), so ``engine/direct.py`` traces
    all of its shadow rays. Emission is that of the photon map for area lights: an
    area-uniform point (triangle by area with ``searchsorted``, the seed's "area line"; the
    concentric map for disks) and a cosine direction about the emitting side (a random side of
    a two-sided emissive mesh). Each photon is traced THROUGH every surface along its line:
    the first hit is stored as "direct", every later hit as "shadow" (the number of surfaces
    crossed is kept), tagged with the index of its light in ``lights.sampled``. Nothing
    bounces: the map holds visibility, not energy.

    ``ShadowPhotonMap.classify(points, normals, light_index)`` -> int8 classes
    ``LIT`` = 0 (the whole light is visible: visibility 1, no shadow ray), ``UMBRA`` = 1
    (none is: no ray, no light) and ``PENUMBRA`` = 2 (unknown: trace). Two levels:
    * At build time every ``rep_stride``-th photon of a light (Morton order, so they spread
      evenly) is a representative and gets a class from the photons themselves
      (``classify_photons``): per light a kd-tree (pykdtree, leafsize 16) gives the
      ``ceil(k margin^2)`` nearest photons within the radius cap; a photon counts if it
      arrived on the side the surface faces (its direction, quantised, tells a thin plate's
      two sides apart) and lies in the disc of the tangent plane (height at most ``disc`` x
      the neighbourhood radius, the photon map's Fig. 9.5 filter). LIT when at least ``k``
      count and all are direct, UMBRA when at least ``k`` count and all are shadow, PENUMBRA
      otherwise (mixed, or too few photons within the cap). The representative keeps the
      radius of that neighbourhood.
    * A shading point asks the ``lookup_k`` nearest representatives of the light; those
      arriving on the side its normal faces, in its disc and within their radius / ``margin``
      count. At least two must count and all must share a class, else PENUMBRA.
    Precomputing at a subset of the photons is Christensen's (1999) device for irradiance: a
    look-up of 4 neighbours instead of 72 (measured here: 350-430k points/s against 42-84k
    for the direct 72-photon test, on a loaded 2-core machine).

Being conservative
    A point of visibility V whose neighbours are all direct is called LIT with probability
    about V^m for m counting photons, so the brightening it causes, (1 - V) V^m, is at most
    1 / (e m) of the unoccluded light, at V = m / (m + 1); the same bound holds for UMBRA.
    The ``margin`` asks the homogeneous neighbourhood to hold ``margin^2`` times more photons
    than ``k`` (it reaches ``margin`` times farther): on an open surface all ``ceil(k margin^2)``
    = 72 photons must agree (bound 0.5 %), and a shading point must lie well inside
    (1/margin of the radius) the homogeneous neighbourhoods of at least two representatives,
    so its own homogeneous neighbourhood reaches about a third of that radius beyond it.
    The error is thus confined to the band of the penumbra next to its edges, where V is
    within a few per cent of 0 or 1. Points in lit and umbra regions are exact: a
    misclassification there needs all of at least ``k`` nearby photons to be of the other
    kind. What no photon sees is not seen: an occluder whose whole shadow falls between
    photons (smaller than their spacing, about 1 % of the scene's extent at the default
    count) can be missed, as in any photon method; the radius cap bounds that spacing.

Parameters and units
    ==================  ==========  =======================================================
    name                default     meaning
    ==================  ==========  =======================================================
    count               0 = auto    photons emitted over all positioned lights;
                                    auto: ``auto_shadow_photon_count``: enough for
                                    ``ceil(k margin^2)`` photons within 1 % of the scene's
                                    extent on a surface of the scene's total area, clipped
                                    to 100k-1M
    k                   32          photons that must count (dimensionless; sets the bias
                                    bound 1 / (e k) above, so it does not depend on the scene)
    margin              1.5         neighbourhood reach over the k-photon radius
    max_radius          0 = auto    cap [m] on the neighbourhood radius, per light: 3 x the
                                    radius holding ``ceil(k margin^2)`` photons if the light's
                                    stored photons spread evenly over the scene's area, at most
                                    3 % of the extent; where fewer photons lie within it the
                                    class is PENUMBRA (too sparse to tell)
    disc                0.25        photons farther than this fraction of the neighbourhood
                                    radius from the tangent plane do not count
    penumbra_factor     2           light samples of a PENUMBRA (point, light) pair are
                                    multiplied by this (``engine/direct.py``)
    rep_stride          4           every rep_stride-th photon is a representative
    lookup_k            4           representatives asked per shading point
    max_crossings       64          surfaces a photon may cross before it is dropped
    ==================  ==========  =======================================================

Photons per light
    In proportion to the light's luminance flux to the power 2/3 (at least 1). Rays to light
    l are drawn in proportion to its contribution (``LightSet.selection_weights``), about its
    flux Phi_l; with N_l photons the band of points left unclassified around shadow edges is
    about as wide as the photon spacing, N_l^(-1/2). Minimising the traced rays
    sum_l Phi_l N_l^(-1/2) with sum_l N_l fixed gives N_l ~ Phi_l^(2/3): bright lights get
    more photons, dim ones still enough to classify most of their points.

Storage: 16 bytes a photon (``stats["bytes_per_photon"]``): float32 position (12), the
incoming direction in an octahedral map quantised to two int8 (2; about 1 degree, enough for
the side test), the light index (1 byte; 2 when a scene has more than 256 sampled lights) and
the number of surfaces crossed before it (1 byte, 0 = direct, at most 254; 255 =
``THROUGH_GLASS``: one of them was transmissive, and a point whose neighbourhood holds such a
photon is PENUMBRA, so points behind glass are traced and never called UMBRA). The seed
used 14 (no direction). Photons are sorted by light, then along a Morton curve inside each
light, so each light's kd-tree covers one contiguous slice. Representatives add 9 bytes each
(int32 photon index, int8 class, float32 radius: 2.25 bytes a photon at stride 4), counted in
``stats["bytes"]`` and ``stats["representative_bytes"]``; the kd-trees are not counted.

The photons' emission numbers come from ``rng_for(seed, STREAM_SHADOW_PHOTON)``; tracing is
deterministic, so a fixed seed gives the same map whatever the thread scheduling.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numpy as np

from . import sampling
from .bsdf import MaterialTable
from .lights import LUMINANCE, EllipseEmitter, TriangleEmitter
from .npzjson import pack_json, unpack_json
from .photons import column_bounds, morton_order

LIT, UMBRA, PENUMBRA = 0, 1, 2
CLASS_NAMES = ("lit", "umbra", "penumbra")
STREAM_SHADOW_PHOTON = 7

DEFAULT_K = 32
DEFAULT_MARGIN = 1.5
DEFAULT_DISC = 0.25
DEFAULT_PENUMBRA_FACTOR = 2
RADIUS_FACTOR = 3.0
MAX_RADIUS_SHARE = 0.03           # ... and at most this share of the scene's extent
AUTO_SPACING = 0.01               # neighbourhood radius aimed at, as a share of the extent
MIN_AUTO_COUNT = 100_000
MAX_AUTO_COUNT = 1_000_000
MAX_CROSSINGS = 64
# ``crossings`` of a photon that crossed a transmissive (glass) surface before it: such a
# photon makes its neighbourhood PENUMBRA, so points behind glass are traced, never UMBRA.
THROUGH_GLASS = 255
CLASSIFY_CHUNK = 8192
REP_STRIDE = 4                    # every 4th photon carries a precomputed class
LOOKUP_K = 4                      # representatives asked per shading point


# Octahedral direction code -----------------------------------------------------------------
def encode_directions(d: np.ndarray) -> np.ndarray:
    """Unit directions (N, 3) -> octahedral codes (N, 2) int8 (Cigolle et al. 2014)."""
    d = np.asarray(d, np.float32)
    s = np.abs(d[:, 0]) + np.abs(d[:, 1]) + np.abs(d[:, 2])
    s = np.where(s > 0, s, 1.0).astype(np.float32)
    px, py = d[:, 0] / s, d[:, 1] / s
    lower = d[:, 2] < 0
    sx = np.where(px >= 0, 1.0, -1.0).astype(np.float32)
    sy = np.where(py >= 0, 1.0, -1.0).astype(np.float32)
    fx = np.where(lower, (1.0 - np.abs(py)) * sx, px)
    fy = np.where(lower, (1.0 - np.abs(px)) * sy, py)
    return np.clip(np.rint(np.stack([fx, fy], 1) * 127.0), -127, 127).astype(np.int8)


def decode_directions(code: np.ndarray) -> np.ndarray:
    """Octahedral codes (..., 2) int8 -> directions (..., 3) float32, NOT normalised (their
    length is between 1/sqrt(3) and 1: enough for sign tests; normalise for anything else)."""
    f = code.astype(np.float32) * np.float32(1.0 / 127.0)
    x, y = f[..., 0], f[..., 1]
    z = 1.0 - np.abs(x) - np.abs(y)
    t = np.maximum(-z, 0.0)
    x = x - np.copysign(t, x)
    y = y - np.copysign(t, y)
    return np.stack([x, y, z], axis=-1)


# Defaults ------------------------------------------------------------------------------------
def neighbours_queried(k: int, margin: float) -> int:
    return int(np.ceil(k * margin * margin))


def auto_shadow_photon_count(scene, k: int = DEFAULT_K, margin: float = DEFAULT_MARGIN) -> int:
    """Default photon count: ``ceil(k margin^2)`` photons within ``AUTO_SPACING`` x extent,
    spread over the scene's total triangle area A: N = K A / (pi (0.01 extent)^2), 100k-1M.
    A / extent^2 is the scene's shape, not its scale, so a scene scaled by 1e-3 or 1e3 gets
    the same count."""
    if len(scene.triangles) == 0:
        return MIN_AUTO_COUNT
    area = float(scene.triangle_areas().sum())
    radius = AUTO_SPACING * max(scene.extent, 1e-30)
    count = neighbours_queried(k, margin) * area / (np.pi * radius * radius)
    return int(np.clip(count, MIN_AUTO_COUNT, MAX_AUTO_COUNT))


def positioned(light) -> bool:
    """Sampled lights that shadow photons can leave from (area lights, emissive meshes)."""
    return isinstance(light, (TriangleEmitter, EllipseEmitter))


def _luminance_flux(light) -> float:
    return max(float(np.asarray(light.power, np.float64) @ LUMINANCE), 0.0)


# Emission ------------------------------------------------------------------------------------
def _emit(light, n: int, rng: np.random.Generator, accel):
    """``n`` photons of one light: origins (n, 3), directions (n, 3), float64."""
    u = sampling.stratified_2d(1, n, rng)[0]
    v = rng.random((n, 2))
    if isinstance(light, EllipseEmitter):
        disk = sampling.square_to_disk(u)
        o = light.center + disk[:, 0:1] * light.du + disk[:, 1:2] * light.dv
        nrm = np.ascontiguousarray(np.broadcast_to(light.normal, (n, 3)), np.float64)
    else:
        cdf = light.cdf
        tri = np.minimum(np.searchsorted(cdf, u[:, 0] * cdf[-1], side="right"), len(cdf) - 1)
        lower = np.where(tri > 0, cdf[np.maximum(tri - 1, 0)], 0.0)
        share = cdf[tri] - lower
        u0 = np.clip((u[:, 0] - lower) / np.where(share > 0, share, 1.0), 0.0, 1.0 - 1e-12)
        bary = sampling.square_to_triangle(np.stack([u0, u[:, 1]], 1))
        tp = light.tris[tri]
        o = tp[:, 0] * (1 - bary[:, 0:1] - bary[:, 1:2]) + tp[:, 1] * bary[:, 0:1] + tp[:, 2] * bary[:, 1:2]
        nrm = light.normals[tri].copy()
        if light.two_sided:
            nrm[rng.random(n) < 0.5] *= -1
    # Leave the emitter's plane as accel.offset_origins does: an emissive mesh is geometry
    # too, and an area light may lie in a surface (a panel flush with the ceiling).
    o = o + nrm * accel.offset_distance(o)[:, None]
    d = sampling.cosine_directions(nrm, v)
    return o, d


# Tracing through surfaces --------------------------------------------------------------------
def _trace_through(accel, normals_geo, origins, directions, max_crossings, transmissive=None):
    """Follow each ray through every surface on its line. Returns, per stored hit, the hit
    point (float32), the ray's index, the number of surfaces crossed before it
    (``THROUGH_GLASS`` once one of them was a triangle marked in ``transmissive``) and the
    triangle hit; then the rays traced and the photons dropped at ``max_crossings``."""
    o = np.ascontiguousarray(origins, np.float32)
    d = np.ascontiguousarray(directions, np.float32)
    ray = np.arange(len(o), dtype=np.int64)
    through = np.zeros(len(o), bool)
    depth = 0
    points, rays, crossed, prims = [], [], [], []
    traced = 0
    while len(o) and depth < max_crossings:
        traced += len(o)
        t, prim, _u, _v = accel.intersect(o, d)
        hit = np.flatnonzero(prim >= 0)
        if len(hit) == 0:
            break
        if len(hit) < len(o):
            o, d, t, prim, ray, through = (np.take(a, hit, axis=0)
                                           for a in (o, d, t, prim, ray, through))
        x = sampling.scale_rows(d, t)
        x += o
        points.append(x)
        rays.append(ray)
        prims.append(prim.astype(np.int32, copy=True))
        crossed.append(np.where(through, THROUGH_GLASS, min(depth, THROUGH_GLASS - 1))
                       .astype(np.uint8))
        if transmissive is not None:
            through = through | transmissive[prim]
        # Restart just past the hit, on the far side of its surface.
        o = accel.offset_origins(x, np.take(normals_geo, prim, axis=0), d)
        depth += 1
    dropped = len(o) if depth >= max_crossings else 0
    if not points:
        return (np.zeros((0, 3), np.float32), np.zeros(0, np.int64), np.zeros(0, np.uint8),
                np.zeros(0, np.int32), traced, dropped)
    return (np.concatenate(points), np.concatenate(rays), np.concatenate(crossed),
            np.concatenate(prims), traced, dropped)


# The map -------------------------------------------------------------------------------------
@dataclass
class ShadowPhotonMap:
    """Shadow photons of the positioned sampled lights, 16 bytes each, one kd-tree per light,
    and the classes precomputed at every ``rep_stride``-th photon (the representatives).

    ``slices[li] = (start, end)``: the photons of light ``li`` (index into ``lights.sampled``)
    are ``positions[start:end]``; ``radius[li]`` is its neighbourhood cap [m]. Representative
    r of light li is photon ``rep_index[r]`` with class ``rep_class[r]`` over its
    neighbourhood of radius ``rep_radius[r]`` [m]; ``rep_slices[li]`` holds li's range."""

    positions: np.ndarray            # (P, 3) float32 [m]
    directions: np.ndarray           # (P, 2) int8 octahedral code of the travel direction
    light: np.ndarray                # (P,) uint8 (uint16 beyond 256 lights) index in lights.sampled
    crossings: np.ndarray            # (P,) uint8 surfaces crossed before; 0 = direct
    slices: dict = field(default_factory=dict)
    radius: dict = field(default_factory=dict)
    rep_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    rep_class: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int8))
    rep_radius: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    rep_slices: dict = field(default_factory=dict)
    k: int = DEFAULT_K
    margin: float = DEFAULT_MARGIN
    disc: float = DEFAULT_DISC
    penumbra_factor: int = DEFAULT_PENUMBRA_FACTOR
    lookup_k: int = LOOKUP_K
    stats: dict = field(default_factory=dict)
    _trees: dict = field(default_factory=dict, repr=False)
    _rep_trees: dict = field(default_factory=dict, repr=False)
    _bounds: dict = field(default_factory=dict, repr=False)
    _lock: object = field(default_factory=threading.Lock, repr=False)

    def __len__(self):
        return len(self.positions)

    @property
    def nbytes(self) -> int:
        """Photons (16 bytes each) and representatives (9 bytes each), without the trees."""
        return sum(a.nbytes for a in (self.positions, self.directions, self.light, self.crossings,
                                      self.rep_index, self.rep_class, self.rep_radius))

    def covers(self, light_index: int) -> bool:
        """True when light ``light_index`` has photons: its points can be classified."""
        return int(light_index) in self._rep_trees

    # Persistence (engine/artifacts.py) ----------------------------------------------------
    ARRAY_FIELDS = ("positions", "directions", "light", "crossings", "rep_index", "rep_class",
                    "rep_radius")
    SCALAR_FIELDS = ("k", "margin", "disc", "penumbra_factor", "lookup_k")
    #: What a saved map must hold (``engine/archive.py``): P photons, R representatives, L
    #: lights with photons, K lights with a radius.
    SCHEMA = {"positions": (("<f4",), ("P", 3)), "directions": (("|i1",), ("P", 2)),
              "light": (("|u1", "<u2"), ("P",)), "crossings": (("|u1",), ("P",)),
              "rep_index": (("<i4", "<i8"), ("R",)), "rep_class": (("|i1",), ("R",)),
              "rep_radius": (("<f4",), ("R",)), "slices.keys": (("<i8",), ("L",)),
              "slices.values": (("<i8",), ("L", 2)), "rep_slices.keys": (("<i8",), ("L",)),
              "rep_slices.values": (("<i8",), ("L", 2)), "radius.keys": (("<i8",), ("K",)),
              "radius.values": (("<f8",), ("K",)), "k": (("<i8",), ()),
              "margin": (("<f8",), ()), "disc": (("<f8",), ()),
              "penumbra_factor": (("<i8",), ()), "lookup_k": (("<i8",), ()),
              "stats": (("U",), ())}

    @staticmethod
    def value_problems(arrays) -> list[str]:
        """What is wrong with a saved map's values (the shapes passed ``SCHEMA``): finite
        positions, representatives that index photons, classes lit / umbra / penumbra, slices
        inside the arrays, radii and options within their ranges."""
        out = []
        positions, count = arrays["positions"], len(arrays["positions"])
        if not np.isfinite(positions).all():
            out.append("shadow photon positions are not finite")
        rep = arrays["rep_index"]
        if rep.size and not (rep.min() >= 0 and rep.max() < count):
            out.append("representatives index photons that do not exist")
        if not np.isin(arrays["rep_class"], (LIT, UMBRA, PENUMBRA)).all():
            out.append("representative classes are not lit, umbra or penumbra")
        radius = arrays["rep_radius"]
        if not (np.isfinite(radius).all() and (radius >= 0).all()):
            out.append("representative radii are not finite and >= 0")
        for name, size in (("slices", count), ("rep_slices", len(rep))):
            v = arrays[name + ".values"]
            if v.size and not ((v[:, 0] >= 0).all() and (v[:, 0] <= v[:, 1]).all()
                               and (v[:, 1] <= size).all()):
                out.append(f"{name} reach outside the arrays")
        lights = arrays["radius.values"]
        if not (np.isfinite(lights).all() and (lights > 0).all()):
            out.append("light radii are not finite and positive")
        for name, low, high in (("k", 1, 10_000), ("penumbra_factor", 1, 1024),
                                ("lookup_k", 1, 10_000), ("margin", 0.0, 1e6),
                                ("disc", 1e-6, 1e6)):
            value = arrays[name].item()
            if not (np.isfinite(value) and low <= value <= high):
                out.append(f"{name} = {value!r} is outside [{low:g}, {high:g}]")
        return out

    def to_arrays(self) -> dict:
        """The map as named numpy arrays (``np.load(allow_pickle=False)`` reads them back):
        the photon and representative arrays with their dtypes, the per-light dicts as key /
        value arrays (``slices.keys`` (L,) int64, ``slices.values`` (L, 2) int64; ``radius``,
        ``rep_slices`` alike), the scalar options as 0-d arrays and ``stats`` as JSON."""
        out = {key: np.ascontiguousarray(getattr(self, key)) for key in self.ARRAY_FIELDS}
        for name in ("slices", "rep_slices"):
            table = getattr(self, name)
            out[name + ".keys"] = np.array(sorted(table), np.int64)
            out[name + ".values"] = np.array([table[li] for li in sorted(table)],
                                             np.int64).reshape(-1, 2)
        out["radius.keys"] = np.array(sorted(self.radius), np.int64)
        out["radius.values"] = np.array([self.radius[li] for li in sorted(self.radius)], np.float64)
        for key in self.SCALAR_FIELDS:
            out[key] = np.array(getattr(self, key))
        out["stats"] = pack_json(self.stats)
        return out

    @classmethod
    def from_arrays(cls, arrays, build: bool = True) -> "ShadowPhotonMap":
        """The inverse of ``to_arrays``; ``build`` makes the kd-trees (``build_trees``)."""
        smap = cls(*(np.asarray(arrays[key]) for key in cls.ARRAY_FIELDS[:4]))
        for key in cls.ARRAY_FIELDS[4:]:
            setattr(smap, key, np.asarray(arrays[key]))
        for name in ("slices", "rep_slices"):
            keys, values = np.asarray(arrays[name + ".keys"]), np.asarray(arrays[name + ".values"])
            setattr(smap, name, {int(li): (int(a), int(b)) for li, (a, b) in zip(keys, values)})
        smap.radius = {int(li): float(r) for li, r in zip(np.asarray(arrays["radius.keys"]),
                                                           np.asarray(arrays["radius.values"]))}
        for key in cls.SCALAR_FIELDS:
            setattr(smap, key, type(getattr(smap, key))(np.asarray(arrays[key]).item()))
        smap.stats = unpack_json(arrays["stats"])
        if build:
            smap.build_trees()
        return smap

    def build_trees(self):
        """A pykdtree (leafsize 16) over each light's photons and one over its representatives."""
        from pykdtree.kdtree import KDTree
        self._trees, self._bounds, self._rep_trees = {}, {}, {}
        for li, (a, b) in self.slices.items():
            if b > a:
                pts = self.positions[a:b]
                self._trees[li] = KDTree(pts, leafsize=16)
                self._bounds[li] = column_bounds(pts)
        for li, (a, b) in self.rep_slices.items():
            if b > a:
                reps = np.ascontiguousarray(self.positions[self.rep_index[a:b]])
                self._rep_trees[li] = KDTree(reps, leafsize=16)
        return self

    # Classification ------------------------------------------------------------------------
    def classify(self, points: np.ndarray, normals: np.ndarray, light_index: int) -> np.ndarray:
        """Classes (N,) int8 of ``points`` on the side ``normals`` face, for light
        ``light_index`` (in ``lights.sampled``): LIT, UMBRA or PENUMBRA (unknown: trace).

        The ``lookup_k`` nearest representatives count when they arrived on the side the
        normal faces, lie in the disc (height <= ``disc`` x their radius) and within their
        radius / ``margin``; at least two must count and all must share a class, else
        PENUMBRA. Each representative's class holds over a ball of its radius (at least
        ``ceil(k margin^2)`` photons), so a LIT or UMBRA point has a homogeneous
        neighbourhood reaching (1 - 1/margin) x that radius beyond it. Lights without photons
        give PENUMBRA everywhere."""
        count = len(points)
        out = np.full(count, PENUMBRA, np.int8)
        li = int(light_index)
        tree = self._rep_trees.get(li)
        if tree is None or count == 0:
            return out
        t0 = time.perf_counter()
        a, b = self.rep_slices[li]
        lo, hi = self._bounds[li]
        order = morton_order(points, lo, hi)
        p32 = np.ascontiguousarray(points, np.float32)[order]
        n32 = np.ascontiguousarray(normals, np.float32)[order]
        k = min(self.lookup_k, b - a)
        cap = float(self.radius.get(li, np.inf))
        rep_pos = self.positions[self.rep_index[a:b]]
        rep_dir = self.directions[self.rep_index[a:b]]
        rep_cls = self.rep_class[a:b]
        rep_rad = self.rep_radius[a:b]
        cls = np.empty(count, np.int8)
        for s in range(0, count, CLASSIFY_CHUNK):
            e = min(s + CLASSIFY_CHUNK, count)
            p, n = p32[s:e], n32[s:e]
            dist, idx = tree.query(p, k=k, distance_upper_bound=cap if np.isfinite(cap) else None)
            dist = np.asarray(dist, np.float32).reshape(len(p), k)
            idx = np.asarray(idx).reshape(len(p), k)
            found = idx < (b - a)
            flat = np.where(found, idx, 0).astype(np.intp).reshape(-1)
            radius = np.take(rep_rad, flat).reshape(len(p), k)
            ok = found & (dist * self.margin <= radius)
            ok &= _facing(np.take(rep_dir, flat, axis=0).reshape(len(p), k, 2), n)
            ok &= _height(np.take(rep_pos, flat, axis=0).reshape(len(p), k, 3), p, n) <= self.disc * radius
            c = np.take(rep_cls, flat).reshape(len(p), k)
            n_ok = ok.sum(axis=1)
            n_lit = (ok & (c == LIT)).sum(axis=1)
            n_umbra = (ok & (c == UMBRA)).sum(axis=1)
            enough = n_ok >= min(2, k)
            part = np.full(len(p), PENUMBRA, np.int8)
            part[enough & (n_lit == n_ok)] = LIT
            part[enough & (n_umbra == n_ok)] = UMBRA
            cls[s:e] = part
        out[order] = cls
        self._tally("", out, time.perf_counter() - t0)
        return out

    def classify_photons(self, points: np.ndarray, normals: np.ndarray, light_index: int,
                         return_radius: bool = False):
        """The classes straight from the photons (slower; what the representatives store):
        among the ``ceil(k margin^2)`` nearest photons within the cap, those arriving on the
        side ``normals`` face and in the disc count; at least ``k`` must count, all direct
        -> LIT, all shadow -> UMBRA, else PENUMBRA. ``return_radius``: also the
        neighbourhood radius (N,) float32 (the farthest neighbour's distance, or the cap)."""
        count = len(points)
        out = np.full(count, PENUMBRA, np.int8)
        rad = np.zeros(count, np.float32)
        li = int(light_index)
        tree = self._trees.get(li)
        if tree is None or count == 0:
            return (out, rad) if return_radius else out
        t0 = time.perf_counter()
        a, b = self.slices[li]
        lo, hi = self._bounds[li]
        order = morton_order(points, lo, hi)
        p32 = np.ascontiguousarray(points, np.float32)[order]
        n32 = np.ascontiguousarray(normals, np.float32)[order]
        k_query = min(neighbours_queried(self.k, self.margin), b - a)
        cap = float(self.radius.get(li, np.inf))
        pos, dirs, shadow = self.positions[a:b], self.directions[a:b], self.crossings[a:b] > 0
        glass = self.crossings[a:b] == THROUGH_GLASS
        cls = np.empty(count, np.int8)
        radius = np.empty(count, np.float32)
        for s in range(0, count, CLASSIFY_CHUNK):
            e = min(s + CLASSIFY_CHUNK, count)
            cls[s:e], radius[s:e] = self._photon_chunk(tree, pos, dirs, shadow, p32[s:e],
                                                       n32[s:e], k_query, cap, glass)
        out[order] = cls
        rad[order] = radius
        self._tally("photons_", out, time.perf_counter() - t0)
        return (out, rad) if return_radius else out

    def _photon_chunk(self, tree, pos, dirs, shadow, p, n, k_query, cap, glass=None):
        dist, idx = tree.query(p, k=k_query, distance_upper_bound=cap if np.isfinite(cap) else None)
        dist = np.asarray(dist, np.float32).reshape(len(p), k_query)
        idx = np.asarray(idx).reshape(len(p), k_query)
        found = idx < len(pos)
        flat = np.where(found, idx, 0).astype(np.intp).reshape(-1)
        radius = np.where(np.isfinite(dist[:, -1]), dist[:, -1], np.float32(min(cap, 3e38)))
        counts = found & _facing(np.take(dirs, flat, axis=0).reshape(len(p), k_query, 2), n)
        counts &= _height(np.take(pos, flat, axis=0).reshape(len(p), k_query, 3), p, n) \
            <= self.disc * radius[:, None]
        n_count = counts.sum(axis=1)
        n_shadow = (counts & np.take(shadow, flat).reshape(len(p), k_query)).sum(axis=1)
        enough = n_count >= min(self.k, k_query)
        cls = np.full(len(p), PENUMBRA, np.int8)
        cls[enough & (n_shadow == 0)] = LIT
        cls[enough & (n_shadow == n_count)] = UMBRA
        if glass is not None:
            # Behind glass: the light's share that reaches the point is not a class (Cycles'
            # shadow rays stop at glass: traced rays give that answer, and its light comes
            # through the caustic map).
            cls[(counts & np.take(glass, flat).reshape(len(p), k_query)).any(axis=1)] = PENUMBRA
        return cls, radius

    def _tally(self, prefix, classes, seconds):
        tally = np.bincount(classes, minlength=3)
        with self._lock:
            st = self.stats
            st[prefix + "classified"] = st.get(prefix + "classified", 0) + len(classes)
            st[prefix + "classify_seconds"] = st.get(prefix + "classify_seconds", 0.0) + seconds
            for name, c in zip(CLASS_NAMES, tally):
                key = f"{prefix}classified_{name}"
                st[key] = st.get(key, 0) + int(c)


def _facing(codes: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(N, K) True where the photon with octahedral code ``codes`` (N, K, 2) travelled against
    the normal n (N, 3): it arrived on the side n faces. Column-wise (no (N, K, 3) arrays)."""
    f = codes.astype(np.float32)
    x, y = f[..., 0], f[..., 1]
    z = 127.0 - np.abs(x) - np.abs(y)           # codes are 127 x the octahedral coordinates
    t = np.maximum(-z, 0.0)
    x -= np.copysign(t, x)
    y -= np.copysign(t, y)
    dot = x * n[:, 0:1]
    dot += y * n[:, 1:2]
    dot += z * n[:, 2:3]
    return dot < 0


def _height(q: np.ndarray, p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """|(q - p) . n| (N, K) for points q (N, K, 3), p (N, 3), unit normals n (N, 3)."""
    h = q[..., 0] * n[:, 0:1]
    h += q[..., 1] * n[:, 1:2]
    h += q[..., 2] * n[:, 2:3]
    h -= sampling.dot_rows(p, n)[:, None]
    return np.abs(h)


def empty_map(**kwargs) -> ShadowPhotonMap:
    return ShadowPhotonMap(np.zeros((0, 3), np.float32), np.zeros((0, 2), np.int8),
                           np.zeros(0, np.uint8), np.zeros(0, np.uint8), **kwargs)


def build_shadow_photon_map(scene, accel, lights, count: int = 0, seed: int = 0, pool=None, *,
                            k: int = DEFAULT_K, margin: float = DEFAULT_MARGIN,
                            max_radius: float = 0.0, disc: float = DEFAULT_DISC,
                            penumbra_factor: int = DEFAULT_PENUMBRA_FACTOR,
                            rep_stride: int = REP_STRIDE, lookup_k: int = LOOKUP_K,
                            max_crossings: int = MAX_CROSSINGS) -> ShadowPhotonMap:
    """Emit ``count`` shadow photons (0: ``auto_shadow_photon_count``) from the positioned
    lights of ``lights.sampled`` (a ``LightSet``), trace them through ``accel`` (on ``pool``
    in chunks when given), store and index them, and classify every ``rep_stride``-th photon
    from its neighbours. ``max_radius`` [m] caps every light's neighbourhood (0: automatic).

    ``stats``: photons per light (by index and name), the names of the positioned lights whose
    ``shadow_photons`` is off (``lights_switched_off``), stored direct / shadow counts, rays,
    dropped photons, bytes and bytes per photon, representatives per class, emit / trace /
    index / build seconds; ``classify`` adds classified counts per class and seconds."""
    t_start = time.perf_counter()
    k = int(max(1, k))
    margin = float(max(1.0, margin))
    rep_stride = int(max(1, rep_stride))
    options = dict(k=k, margin=margin, disc=float(disc), penumbra_factor=int(max(1, penumbra_factor)),
                   lookup_k=int(max(1, lookup_k)))
    if not count:
        count = auto_shadow_photon_count(scene, k, margin)
    count = int(count)
    chosen = [(li, light) for li, light in enumerate(lights.sampled)
              if positioned(light) and getattr(light, "shadow_photons", True)
              and _luminance_flux(light) > 0]
    switched_off = [light.name for light in lights.sampled
                    if positioned(light) and not getattr(light, "shadow_photons", True)]
    smap = empty_map(**options)
    smap.stats.update({"requested": count, "emitted": 0, "stored": 0, "stored_direct": 0,
                       "stored_shadow": 0, "photons_per_light": {}, "lights": {},
                       "lights_switched_off": switched_off,
                       "rays": 0, "dropped": 0, "bytes": 0, "bytes_per_photon": 16.0,
                       "representatives": 0, "k": k, "margin": margin,
                       "neighbours": neighbours_queried(k, margin), "rep_stride": rep_stride})
    if not chosen or count <= 0 or len(scene.triangles) == 0:
        smap.stats["build_seconds"] = time.perf_counter() - t_start
        return smap

    # 1. Emission: photons per light ~ luminance flux^(2/3) (module docstring).
    weight = np.array([_luminance_flux(light) ** (2.0 / 3.0) for _, light in chosen])
    share = np.maximum(np.floor(count * weight / weight.sum()).astype(np.int64), 1)
    rng = sampling.rng_for(seed, STREAM_SHADOW_PHOTON, 0)
    origins, directions, light_of = [], [], []
    for (li, light), n in zip(chosen, share):
        o, d = _emit(light, int(n), rng, accel)
        origins.append(o); directions.append(d)
        light_of.append(np.full(int(n), li, np.int64))
    origins = np.concatenate(origins)
    directions = np.concatenate(directions)
    light_of = np.concatenate(light_of)
    emit_seconds = time.perf_counter() - t_start

    # 2. Tracing through every surface, in chunks (deterministic: no random numbers).
    t0 = time.perf_counter()
    normals_geo = scene.geometric_normals()
    materials = MaterialTable(scene)
    transmissive = materials.transmissive[scene.material_ids] if materials.has_transmission \
        else None
    total = len(origins)
    step = int(getattr(accel, "chunk", 1 << 16)) if pool is not None else max(total, 1)
    bounds = [(a, min(a + step, total)) for a in range(0, total, step)]

    def trace(bound):
        a, b = bound
        x, ray, crossed, prim, rays, dropped = _trace_through(
            accel, normals_geo, origins[a:b], directions[a:b], max_crossings, transmissive)
        return x, ray + a, crossed, prim, rays, dropped

    parts = list(pool.map(trace, bounds)) if pool is not None else [trace(b) for b in bounds]
    x = np.concatenate([p[0] for p in parts])
    ray = np.concatenate([p[1] for p in parts])
    crossed = np.concatenate([p[2] for p in parts])
    prim = np.concatenate([p[3] for p in parts])
    trace_seconds = time.perf_counter() - t0

    # 3. Storage: sorted by light, then along a Morton curve inside each light.
    t0 = time.perf_counter()
    light_dtype = np.uint8 if len(lights.sampled) <= 256 else np.uint16
    codes = encode_directions(directions)
    photon_light = light_of[ray]
    order = np.argsort(photon_light, kind="stable")
    x, ray, crossed, prim, photon_light = (a[order] for a in (x, ray, crossed, prim, photon_light))
    keys = [li for li, _ in chosen]
    starts = np.searchsorted(photon_light, keys, side="left")
    ends = np.searchsorted(photon_light, keys, side="right")
    for a, b in zip(starts, ends):
        if b > a:
            sub = morton_order(x[a:b]) + a
            x[a:b], ray[a:b], crossed[a:b], prim[a:b] = x[sub], ray[sub], crossed[sub], prim[sub]
    smap.positions = np.ascontiguousarray(x, np.float32)
    smap.directions = np.ascontiguousarray(codes[ray])
    smap.light = photon_light.astype(light_dtype)
    smap.crossings = crossed
    smap.slices = {li: (int(a), int(b)) for li, a, b in zip(keys, starts, ends)}

    # 4. Radius caps and kd-trees over the photons.
    area = float(scene.triangle_areas().sum())
    k_query = neighbours_queried(k, margin)
    for li, (a, b) in smap.slices.items():
        if max_radius and max_radius > 0:
            smap.radius[li] = float(max_radius)
        elif b > a:
            smap.radius[li] = float(min(RADIUS_FACTOR * np.sqrt(k_query * area / (np.pi * (b - a))),
                                        MAX_RADIUS_SHARE * scene.extent))
    smap.build_trees()
    index_seconds = time.perf_counter() - t0

    # 5. Representatives: every rep_stride-th photon (Morton order: spread evenly), classified
    # from its neighbours on the side it arrived (its triangle's normal turned towards it).
    t0 = time.perf_counter()
    rep_index, rep_class, rep_radius, rep_slices = [], [], [], {}
    offset = 0
    for li, (a, b) in smap.slices.items():
        idx = np.arange(a, b, rep_stride, dtype=np.int64)
        nrm = normals_geo[prim[idx]].astype(np.float32)
        back = sampling.dot_rows(nrm, directions[ray[idx]].astype(np.float32)) > 0
        nrm[back] *= -1
        cls, rad = smap.classify_photons(smap.positions[idx], nrm, li, return_radius=True)
        rep_index.append(idx.astype(np.int32)); rep_class.append(cls); rep_radius.append(rad)
        rep_slices[li] = (offset, offset + len(idx))
        offset += len(idx)
    smap.rep_index = np.concatenate(rep_index) if rep_index else np.zeros(0, np.int32)
    smap.rep_class = np.concatenate(rep_class) if rep_class else np.zeros(0, np.int8)
    smap.rep_radius = np.concatenate(rep_radius).astype(np.float32) if rep_radius else np.zeros(0, np.float32)
    smap.rep_slices = rep_slices
    smap.build_trees()
    for key in [key for key in smap.stats if key.startswith("photons_classif")]:
        del smap.stats[key]
    rep_seconds = time.perf_counter() - t0

    per_light, per_name = {}, {}
    for (li, light), n in zip(chosen, share):
        a, b = smap.slices[li]
        ra, rb = smap.rep_slices[li]
        direct = int(np.count_nonzero(smap.crossings[a:b] == 0))
        per_light[li] = {"name": light.name, "emitted": int(n), "stored_direct": direct,
                         "stored_shadow": int(b - a - direct), "radius": smap.radius.get(li),
                         "representatives": dict(zip(CLASS_NAMES, np.bincount(
                             smap.rep_class[ra:rb], minlength=3).tolist()))}
        per_name[light.name] = per_name.get(light.name, 0) + int(n)
    direct = int(np.count_nonzero(smap.crossings == 0))
    photon_bytes = sum(a.nbytes for a in (smap.positions, smap.directions, smap.light, smap.crossings))
    smap.stats.update({
        "emitted": int(total), "stored": len(smap), "stored_direct": direct,
        "stored_shadow": len(smap) - direct, "photons_per_light": per_name, "lights": per_light,
        "representatives": int(len(smap.rep_index)),
        "rays": int(sum(p[4] for p in parts)), "dropped": int(sum(p[5] for p in parts)),
        "bytes": int(smap.nbytes), "bytes_per_photon": round(photon_bytes / max(len(smap), 1), 2),
        "representative_bytes": int(smap.nbytes - photon_bytes),
        "emit_seconds": emit_seconds, "trace_seconds": trace_seconds,
        "index_seconds": index_seconds, "representative_seconds": rep_seconds,
        "build_seconds": time.perf_counter() - t_start,
    })
    return smap
