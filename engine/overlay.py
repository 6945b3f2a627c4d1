"""Viewport overlay data: the points and colours that show a render's maps in the 3D viewport.

What it computes
    ``overlay_points(artifacts, kind, color_by, max_points)`` -> ``OverlayPoints``: positions
    (N, 3) float32 (rows of the map's own positions, cast to float32), colours (N, 4) float32
    RGBA in [0, 1], ``sizes`` (N,) float32 or None, ``indices`` (N,) int64 (the rows taken,
    most important first; for the shadow ``class`` colouring rows of the representative
    arrays, whose photons are ``rep_index[indices]``) and ``total`` (points of that kind in
    the map). The thesis shows the same pictures: cache
    record positions (Fig. 12.4) and the photon map (Fig. 12.5). Pure numpy, deterministic;
    ``engine/blender/overlay_draw.py`` turns the result into a GPU batch.

Kinds and colourings (``COLOR_BY``; the first is the default)
    ``photons`` (``Artifacts.photon_map``; in ``full`` mode without a final gather it holds the
    photons that bounced at least once)
        ``power``     viridis(t), t = L / L99 clipped to [0, 1], L the luminance
                      (Rec. 709: 0.2126 R + 0.7152 G + 0.0722 B) of the photon's power [W] and
                      L99 the 99th percentile of L over the whole map (not the drawn subset,
                      so a colour does not change with ``max_points``)
        ``rgb``       the photon's RGB power over its largest channel: its colour at full
                      brightness (colour bleeding shows as tinted photons); black for zero power
        ``bounces``   ``CATEGORY_COLORS[min(bounces, 7)]``
    ``shadow_photons`` (``Artifacts.shadow_map``)
        ``crossings`` direct photons (crossings = 0) ``DIRECT_COLOR`` yellow (1, 0.85, 0.1);
                      shadow photons (crossings > 0) ``SHADOW_COLOR`` blue (0.15, 0.35, 1)
        ``class``     only the representatives (``rep_index``), by the class precomputed from
                      their neighbours: LIT yellow (1, 0.85, 0.1), UMBRA blue (0.15, 0.35, 1),
                      PENUMBRA magenta (1, 0.2, 0.6) (``CLASS_COLORS``, indexed by
                      ``shadow_photons.LIT/UMBRA/PENUMBRA``); ``total`` counts representatives
        ``light``     ``CATEGORY_COLORS[light index mod 8]``
    ``cache`` (``Artifacts.cache``; ``sizes`` = the record's radius R_i [m])
        ``radius``    viridis of log R: t = (ln R - ln R_min) / (ln R_max - ln R_min) over all
                      records (t = 0.5 when all radii are equal)
        ``irradiance`` viridis(t), t = L / L99 of the luminance of E_i [W/m^2], as ``power``
        ``usage``     viridis(t), t = ln(1 + u) / ln(1 + u_max), u the points a record served

    viridis is matplotlib's, sampled at 17 evenly spaced knots (``VIRIDIS``) and interpolated
    linearly per channel (within 0.021 of matplotlib's 256-entry table).

The first N by importance (``importance_order``)
    ``max_points`` (default 100 000) bounds the draw, so millions of photons stay interactive.
    Each point gets the key log(u) / w with u uniform in (0, 1] (``numpy.random.default_rng(
    seed)``, one number per point in map order) and weight w: the photon's power luminance
    for ``photons``, 1 for shadow photons and cache records; the N largest keys are kept, in
    descending key order. This is Efraimidis and Spirakis' (2006) weighted random sampling
    without replacement: photons of equal power give a uniform random subset spread over the
    whole scene (not the first N of the map's Morton order, which would cover one corner),
    brighter photons are kept more often, and the points kept for N are the first N of those
    kept for any larger N (raising ``max_points`` only adds points). Weight 0 keys are -inf
    (kept last, in map order).

Parameters
    ``alpha`` (default 1) fills the fourth colour channel; ``seed`` (default 0) the keys.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["KINDS", "COLOR_BY", "OverlayPoints", "overlay_points", "overlay_count",
           "importance_order", "viridis", "VIRIDIS", "CATEGORY_COLORS", "CLASS_COLORS",
           "DIRECT_COLOR", "SHADOW_COLOR", "LUMINANCE"]

KINDS = ("photons", "shadow_photons", "cache")
COLOR_BY = {
    "photons": ("power", "rgb", "bounces"),
    "shadow_photons": ("crossings", "class", "light"),
    "cache": ("radius", "irradiance", "usage"),
}
DEFAULT_MAX_POINTS = 100_000
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

VIRIDIS = np.array([
    (0.2670, 0.0049, 0.3294), (0.2823, 0.0950, 0.4173), (0.2788, 0.1755, 0.4834),
    (0.2590, 0.2515, 0.5247), (0.2297, 0.3224, 0.5457), (0.1994, 0.3876, 0.5546),
    (0.1727, 0.4488, 0.5579), (0.1490, 0.5081, 0.5573), (0.1276, 0.5669, 0.5506),
    (0.1206, 0.6258, 0.5335), (0.1579, 0.6838, 0.5017), (0.2461, 0.7389, 0.4520),
    (0.3692, 0.7889, 0.3829), (0.5160, 0.8312, 0.2943), (0.6785, 0.8637, 0.1895),
    (0.8456, 0.8873, 0.0997), (0.9932, 0.9062, 0.1439)])
_KNOTS = np.linspace(0.0, 1.0, len(VIRIDIS))

DIRECT_COLOR = (1.0, 0.85, 0.1)
SHADOW_COLOR = (0.15, 0.35, 1.0)
# Indexed by shadow_photons.LIT (0), UMBRA (1), PENUMBRA (2).
CLASS_COLORS = np.array([DIRECT_COLOR, SHADOW_COLOR, (1.0, 0.2, 0.6)])
CATEGORY_COLORS = np.array([
    (1.0, 1.0, 1.0), (1.0, 0.85, 0.1), (1.0, 0.45, 0.1), (0.9, 0.15, 0.3),
    (0.6, 0.2, 0.8), (0.25, 0.4, 1.0), (0.1, 0.75, 0.9), (0.3, 0.85, 0.4)])


@dataclass
class OverlayPoints:
    positions: np.ndarray          # (N, 3) float32 [m]
    colors: np.ndarray             # (N, 4) float32 RGBA in [0, 1]
    sizes: np.ndarray | None       # (N,) float32 (cache: record radius [m]) or None
    total: int                     # points of this kind in the map
    indices: np.ndarray | None = None   # (N,) int64 rows taken (representatives for "class")

    def __len__(self):
        return len(self.positions)


def viridis(t: np.ndarray) -> np.ndarray:
    """(N,) values in [0, 1] (clipped; nan -> 0) -> (N, 3) float64 colours."""
    t = np.nan_to_num(np.clip(np.asarray(t, np.float64), 0.0, 1.0), nan=0.0)
    return np.stack([np.interp(t, _KNOTS, VIRIDIS[:, c]) for c in range(3)], axis=1)


def importance_order(weights: np.ndarray, max_points: int, seed: int = 0) -> np.ndarray:
    """Indices (min(N, P),) int64 of the ``max_points`` largest keys log(u) / w, in
    descending key order, ties by index (see the module docstring)."""
    w = np.asarray(weights, np.float64).reshape(-1)
    n = len(w)
    count = int(max(0, min(int(max_points), n)))
    if count == 0:
        return np.zeros(0, np.int64)
    u = 1.0 - np.random.default_rng(seed).random(n)          # (0, 1]
    positive = w > 0
    key = np.full(n, -np.inf)
    key[positive] = np.log(u[positive]) / w[positive]
    if count < n:
        top = np.argpartition(-key, count - 1)[:count]
    else:
        top = np.arange(n)
    return top[np.lexsort((top, -key[top]))].astype(np.int64)


def _normalised(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """values / (99th percentile of ``reference``), 0 where that is not > 0."""
    if len(reference) == 0:
        return np.zeros(len(values))
    top = float(np.percentile(reference, 99.0))
    return values / top if top > 0 else np.zeros(len(values))


def _rgba(rgb: np.ndarray, alpha: float) -> np.ndarray:
    out = np.empty((len(rgb), 4), np.float32)
    out[:, :3] = np.clip(rgb, 0.0, 1.0)
    out[:, 3] = float(alpha)
    return out


def _source(artifacts, kind):
    if kind not in KINDS:
        raise ValueError(f"Overlay: unknown kind {kind!r} (one of {', '.join(KINDS)})")
    if artifacts is None:
        return None
    return {"photons": artifacts.photon_map, "shadow_photons": artifacts.shadow_map,
            "cache": artifacts.cache}[kind]


def _color_by(kind, color_by):
    if color_by is None:
        return COLOR_BY[kind][0]
    if color_by not in COLOR_BY[kind]:
        raise ValueError(f"Overlay: {kind} cannot be coloured by {color_by!r} (one of "
                         f"{', '.join(COLOR_BY[kind])})")
    return color_by


def overlay_count(artifacts, kind: str, color_by: str | None = None,
                  max_points: int = DEFAULT_MAX_POINTS) -> tuple[int, int]:
    """(drawn, total) of ``overlay_points`` with these arguments, without building them."""
    source, color_by = _source(artifacts, kind), _color_by(kind, color_by)
    if source is None:
        return 0, 0
    total = len(source.rep_index) if kind == "shadow_photons" and color_by == "class" else len(source)
    return int(min(max(int(max_points), 0), total)), int(total)


def overlay_points(artifacts, kind: str, color_by: str | None = None,
                   max_points: int = DEFAULT_MAX_POINTS, *, alpha: float = 1.0,
                   seed: int = 0) -> OverlayPoints:
    """The first ``max_points`` points of ``kind`` by importance, coloured by ``color_by``
    (see the module docstring). An absent map gives no points and ``total`` 0."""
    source, color_by = _source(artifacts, kind), _color_by(kind, color_by)
    if source is None or len(source) == 0:
        return OverlayPoints(np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32),
                             None, 0, np.zeros(0, np.int64))
    sizes = None
    if kind == "photons":
        power = np.asarray(source.power, np.float64)
        lum = power @ LUMINANCE
        idx = importance_order(lum, max_points, seed)
        positions = source.positions[idx]
        if color_by == "power":
            rgb = viridis(_normalised(lum[idx], lum))
        elif color_by == "rgb":
            p = power[idx]
            peak = p.max(axis=1, initial=0.0) if len(p) else np.zeros(0)
            rgb = np.where(peak[:, None] > 0, p / np.where(peak > 0, peak, 1.0)[:, None], 0.0)
        else:
            rgb = CATEGORY_COLORS[np.minimum(source.bounces[idx], len(CATEGORY_COLORS) - 1)]
        total = len(source)
    elif kind == "shadow_photons":
        if color_by == "class":
            reps = np.asarray(source.rep_index, np.int64)
            idx = importance_order(np.ones(len(reps)), max_points, seed)
            positions = source.positions[reps[idx]]
            rgb = CLASS_COLORS[np.asarray(source.rep_class, np.int64)[idx]]
            total = len(reps)
        else:
            idx = importance_order(np.ones(len(source)), max_points, seed)
            positions = source.positions[idx]
            if color_by == "crossings":
                rgb = np.where((source.crossings[idx] > 0)[:, None], SHADOW_COLOR, DIRECT_COLOR)
            else:
                rgb = CATEGORY_COLORS[np.asarray(source.light[idx], np.int64) % len(CATEGORY_COLORS)]
            total = len(source)
    else:
        idx = importance_order(np.ones(len(source)), max_points, seed)
        positions = source.positions[idx]
        radius = np.asarray(source.radius, np.float64)
        sizes = radius[idx].astype(np.float32)
        if color_by == "radius":
            log_r = np.log(radius)
            lo, hi = float(log_r.min()), float(log_r.max())
            t = (log_r[idx] - lo) / (hi - lo) if hi > lo else np.full(len(idx), 0.5)
        elif color_by == "irradiance":
            e = np.asarray(source.irradiance, np.float64)
            # RGB, or RGB of indirect light then of a gathered sky (6 channels): their sum.
            lum = (e.reshape(len(e), -1, 3).sum(axis=1) @ LUMINANCE if e.shape[1] % 3 == 0
                   else e[:, 0])
            t = _normalised(lum[idx], lum)
        else:
            usage = np.log1p(np.asarray(source.usage, np.float64))
            top = float(usage.max())
            t = usage[idx] / top if top > 0 else np.zeros(len(idx))
        rgb = viridis(t)
        total = len(source)
    return OverlayPoints(np.ascontiguousarray(positions, np.float32), _rgba(rgb, alpha), sizes,
                         int(total), idx)
