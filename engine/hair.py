"""Hair curves as closed tubes of triangles: what Cycles renders as 3D curves.

What it computes
    :func:`tessellate_curves` turns curves (a Blender Curves object's points, radii and curve
    offsets, in object space) into triangles the rest of the renderer traces like any mesh:
    each curve becomes a tube whose rings follow the curve, with a flat cap at each end, and
    per-vertex shading normals around the tube. Cycles intersects the curves themselves
    (Embree's round curves); a tube of ``sides`` faces reproduces them to within its
    polygonal cross-section, and nothing downstream (photons, shadow photons, the cache,
    textures) needs a second kind of primitive.

Parameters and units
    ``points``  (P, 3) float [m], the control points of all curves, curve after curve.
    ``radii``   (P,) float [m], each point's radius (Blender's ``radius`` attribute; Cycles
                reads 0.005 m where there is none: :data:`DEFAULT_RADIUS`). Negative radii
                count as 0; a ring of radius 0 (a tapered tip) closes the tube.
    ``offsets`` (C + 1,) int, curve c spans points ``offsets[c]:offsets[c + 1]``.
    ``smooth``  (bool, default True): the curve passes through its points as a uniform
                Catmull-Rom spline whose end points are repeated (Cycles' 3D curves, Embree's
                round Catmull-Rom curves), the radius interpolated by the same spline;
                False: straight pieces between the points (Cycles' linear 3D curves, which
                it uses for poly curves).
    ``sides``   (int, default :data:`SIDES` = 6): faces around the tube. The ring's radius
                is the curve's times (pi / n) / sin(pi / n), so the tube's perimeter, and by
                Cauchy's formula its mean projected width (the shadow and the pixels it
                covers), equal the round curve's.
    ``max_turn`` (rad, default :data:`MAX_TURN` = 10 degrees): a spline piece between two
                points is cut into up to :data:`MAX_PIECES` = 8 parts, as many as keep each
                part's turn (between the spline's tangents at its ends and its chord) under
                this; straight pieces are not cut.
    ``max_triangles`` (default :data:`MAX_TRIANGLES` = 16 million): where the tubes would
                need more, pieces are not cut and then fewer sides are used (at least 3);
                beyond that, one curve in k is drawn; :attr:`Tubes.notes` says so.

    Rings are framed by parallel transport (Bishop 1975: each ring's frame is the last one's
    with the new tangent's component removed), so tubes do not twist where a fixed reference
    axis would flip; each curve's first frame is turned by its own fraction of a side, so a
    polygon's width seen from one direction averages to the round curve's over many curves
    instead of being the same for all of them. A ring's normal leans against the tangent by the radius' slope, the
    true normal of a cone. Curves with fewer than two points or with a non-finite position or
    radius are skipped and counted (:attr:`Tubes.skipped`); curves whose radius is 0 at
    every point draw nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import sampling

DEFAULT_RADIUS = 0.005        # m: Cycles' radius for curves without a radius attribute
SIDES = 6
MAX_TURN = math.radians(5.0)
MAX_PIECES = 8
MAX_TRIANGLES = 16_000_000
MIN_SIDES = 3
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass
class Tubes:
    """Triangles of tessellated curves (object space, float32)."""

    vertices: np.ndarray        # (V, 3) float32 [m]
    normals: np.ndarray         # (V, 3) float32, unit, outwards
    triangles: np.ndarray       # (T, 3) int32 into ``vertices``, counter-clockwise from outside
    vertex_curves: np.ndarray   # (V,) int32: the input curve each vertex belongs to
    skipped: int = 0            # curves skipped (fewer than two points, non-finite values)
    notes: list = field(default_factory=list)
    # Cycles' Curves Info per vertex: the intercept (0 at the root, 1 at the tip, by the
    # length along the points, linear within a piece), the curve's length through its points
    # [m], and the radius [m] (the round curve's, not the widened polygon's).
    vertex_intercept: np.ndarray | None = None   # (V,) float32
    vertex_length: np.ndarray | None = None      # (V,) float32
    vertex_radius: np.ndarray | None = None      # (V,) float32


def _empty(skipped: int, notes: list) -> Tubes:
    return Tubes(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32),
                 np.zeros((0, 3), np.int32), np.zeros(0, np.int32), skipped, notes)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``v`` normalised, and their lengths (rows of length 0 stay 0)."""
    length = np.sqrt(np.einsum("ij,ij->i", v, v))
    return v / np.where(length > 0, length, 1.0)[:, None], length


def _perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit row of ``t`` (``sampling``'s basis)."""
    return sampling.orthonormal_basis(t)[0]


def _spline(p0, p1, p2, p3, t):
    """Uniform Catmull-Rom between p1 (t = 0) and p2 (t = 1); t broadcasts over rows."""
    t2 = t * t
    return 0.5 * (2.0 * p1 + (p2 - p0) * t + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
                  + (3.0 * (p1 - p2) + p3 - p0) * t2 * t)


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between rows of ``u`` and ``v`` (0 where either is zero)."""
    u, lu = _unit(u)
    v, lv = _unit(v)
    cos = np.clip(np.einsum("ij,ij->i", u, v), -1.0, 1.0)
    return np.where((lu > 0) & (lv > 0), np.arccos(cos), 0.0)


def tessellate_curves(points, radii, offsets, *, smooth: bool = True, sides: int = SIDES,
                      max_turn: float = MAX_TURN,
                      max_triangles: int = MAX_TRIANGLES) -> Tubes:
    """Tubes around the curves (module docstring)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    radii = np.asarray(radii, np.float64).reshape(-1)
    offsets = np.asarray(offsets, np.int64).reshape(-1)
    notes: list = []
    if len(offsets) < 2:
        return _empty(0, notes)
    if len(radii) != len(points) or offsets[0] != 0 or offsets[-1] != len(points) \
            or np.any(np.diff(offsets) < 0):
        raise ValueError("curves: points, radii and offsets do not describe the same curves")
    counts = np.diff(offsets)
    n_curves = len(counts)

    # Curves that can be drawn: two points or more, all finite.
    bad_point = ~(np.all(np.isfinite(points), axis=1) & np.isfinite(radii))
    bad_sum = np.concatenate([[0], np.cumsum(bad_point)])
    bad_curve = bad_sum[offsets[1:]] - bad_sum[offsets[:-1]] > 0
    radii = np.maximum(np.where(bad_point, 0.0, radii), 0.0)
    r_sum = np.concatenate([[0.0], np.cumsum(radii)])
    drawn = (counts >= 2) & ~bad_curve
    skipped = int(np.sum(~drawn & ((counts < 2) | bad_curve)))
    drawn &= (r_sum[offsets[1:]] - r_sum[offsets[:-1]]) > 0
    curve_ids = np.flatnonzero(drawn)
    if len(curve_ids) == 0:
        return _empty(skipped, notes)
    # Beyond the budget even with MIN_SIDES and no cuts: every k-th curve alone, said.
    least = int(np.sum(2 * MIN_SIDES * (counts[curve_ids] - 1) + 2 * (MIN_SIDES - 2)))
    if least > max_triangles:
        step = -(-least // max(int(max_triangles), 1))
        notes.append(f"{len(curve_ids[::step]):,} of {len(curve_ids):,} curves drawn (one in "
                     f"{step}): too many triangles")
        curve_ids = curve_ids[::step]
    counts = counts[curve_ids]
    first = offsets[:-1][curve_ids]
    last = first + counts - 1

    # Spline pieces: one per pair of consecutive points.
    n_pieces = counts - 1
    piece_curve = np.repeat(np.arange(len(curve_ids)), n_pieces)
    piece_start = np.arange(int(n_pieces.sum())) - np.repeat(np.cumsum(n_pieces) - n_pieces,
                                                             n_pieces) + first[piece_curve]
    p1, p2 = points[piece_start], points[piece_start + 1]
    r1, r2 = radii[piece_start], radii[piece_start + 1]
    if smooth:
        before = np.maximum(piece_start - 1, first[piece_curve])
        after = np.minimum(piece_start + 2, last[piece_curve])
        p0, p3 = points[before], points[after]
        r0, r3 = radii[before], radii[after]
        chord = p2 - p1
        turn = _angle(p2 - p0, chord) + _angle(chord, p3 - p1)
        cuts = np.clip(np.ceil(turn / max(max_turn, 1e-6)), 1, MAX_PIECES).astype(np.int64)
    else:
        cuts = np.ones(len(piece_start), np.int64)

    sides = max(int(sides), MIN_SIDES)

    def triangle_count(cut):
        rings = int(cut.sum()) + len(curve_ids)
        return 2 * sides * (rings - len(curve_ids)) + 2 * (sides - 2) * len(curve_ids), rings

    if triangle_count(cuts)[0] > max_triangles and np.any(cuts > 1):
        cuts = np.ones_like(cuts)
        notes.append("spline pieces are not subdivided (too many triangles)")
    if triangle_count(cuts)[0] > max_triangles:
        rings = int(cuts.sum()) + len(curve_ids)
        per_side = 2 * (rings - len(curve_ids)) + 2 * len(curve_ids)
        new_sides = max(MIN_SIDES, int(max_triangles // max(per_side, 1)))
        if new_sides < sides:
            notes.append(f"tubes have {new_sides} sides instead of {sides} (too many triangles)")
            sides = new_sides

    # Rings: each piece's cuts at t = j / cut, then the curve's last point.
    ring_count = np.bincount(piece_curve, weights=cuts, minlength=len(curve_ids)).astype(
        np.int64) + 1
    ring_start = np.concatenate([[0], np.cumsum(ring_count)[:-1]])
    n_rings = int(ring_count.sum())
    piece_ring = (np.cumsum(cuts) - cuts) + piece_curve       # each curve adds its last ring
    sample_piece = np.repeat(np.arange(len(cuts)), cuts)
    sample_j = np.arange(int(cuts.sum())) - np.repeat(np.cumsum(cuts) - cuts, cuts)
    t = (sample_j / cuts[sample_piece])[:, None]
    centre = np.empty((n_rings, 3))
    radius = np.empty(n_rings)
    ring_of_sample = piece_ring[sample_piece] + sample_j
    if smooth:
        centre[ring_of_sample] = _spline(p0[sample_piece], p1[sample_piece], p2[sample_piece],
                                         p3[sample_piece], t)
        radius[ring_of_sample] = _spline(r0[sample_piece], r1[sample_piece], r2[sample_piece],
                                         r3[sample_piece], t[:, 0])
    else:
        centre[ring_of_sample] = p1[sample_piece] + (p2 - p1)[sample_piece] * t
        radius[ring_of_sample] = r1[sample_piece] + (r2 - r1)[sample_piece] * t[:, 0]
    end_ring = ring_start + ring_count - 1
    centre[end_ring] = points[last]
    radius[end_ring] = radii[last]
    radius = np.maximum(radius, 0.0)
    ring_curve = np.repeat(np.arange(len(curve_ids)), ring_count)

    # Cycles' intercept: the length along the points, normalised, linear within a piece.
    seg = np.linalg.norm(p2 - p1, axis=1)
    run = np.cumsum(seg) - seg                     # length before each piece, from the root
    run -= np.repeat(run[np.cumsum(n_pieces) - n_pieces], n_pieces)
    curve_length = np.bincount(piece_curve, weights=seg, minlength=len(curve_ids))
    whole = np.where(curve_length > 0, curve_length, 1.0)
    intercept = np.empty(n_rings)
    intercept[ring_of_sample] = ((run[sample_piece] + seg[sample_piece] * t[:, 0])
                                 / whole[piece_curve[sample_piece]])
    intercept[end_ring] = np.where(curve_length > 0, 1.0, 0.0)

    # Tangents by differences along the rings; the radius' slope along the arc.
    index = np.arange(n_rings)
    nxt = np.minimum(index + 1, end_ring[ring_curve])
    prv = np.maximum(index - 1, ring_start[ring_curve])
    tangent, span = _unit(centre[nxt] - centre[prv])
    overall, _ = _unit(points[last] - points[first])
    fallback = np.where(np.linalg.norm(overall, axis=1)[:, None] > 0, overall,
                        np.array([0.0, 0.0, 1.0]))
    flat = span <= 0
    tangent[flat] = fallback[ring_curve[flat]]
    slope = np.where(span > 0, (radius[nxt] - radius[prv]) / np.where(span > 0, span, 1.0), 0.0)
    slope = np.clip(slope, -10.0, 10.0)

    # Parallel transport of a normal along each curve's rings, curves longest first.
    # The first ring's frame is turned by a different fraction of a side per curve (golden
    # ratio steps), so that a polygon's width seen from one direction is not the same for every
    # curve: over many curves it is the round curve's (the perimeter matches).
    normal = np.empty((n_rings, 3))
    start_t = tangent[ring_start]
    start_n = _perpendicular(start_t)
    turn0 = (2.0 * math.pi / sides) * ((curve_ids * GOLDEN) % 1.0)[:, None]
    normal[ring_start] = np.cos(turn0) * start_n + np.sin(turn0) * np.cross(start_t, start_n)
    order = np.argsort(-ring_count, kind="stable")
    starts_sorted, counts_sorted = ring_start[order], ring_count[order]
    for j in range(1, int(counts_sorted[0])):
        active = int(np.searchsorted(-counts_sorted, -j, side="left"))
        cur = starts_sorted[:active] + j
        prev = normal[cur - 1]
        tan = tangent[cur]
        v = prev - np.einsum("ij,ij->i", prev, tan)[:, None] * tan
        v, length = _unit(v)
        weak = length < 1e-6
        if np.any(weak):
            v[weak] = _perpendicular(tan[weak])
        normal[cur] = v
    binormal = np.cross(tangent, normal)

    # Ring vertices and normals.
    phi = 2.0 * math.pi * np.arange(sides) / sides
    radial = (np.cos(phi)[None, :, None] * normal[:, None, :]
              + np.sin(phi)[None, :, None] * binormal[:, None, :])          # (R, S, 3)
    widen = (math.pi / sides) / math.sin(math.pi / sides)
    ring_vertices = centre[:, None, :] + (widen * radius)[:, None, None] * radial
    ring_normals, _ = _unit((radial - slope[:, None, None] * tangent[:, None, :]).reshape(-1, 3))

    # Side quads between consecutive rings of a curve, two triangles each.
    lower = np.flatnonzero(index != end_ring[ring_curve])
    k = np.arange(sides)
    a = lower[:, None] * sides + k[None, :]
    a1 = lower[:, None] * sides + (k[None, :] + 1) % sides
    b, b1 = a + sides, a1 + sides
    side_tris = np.concatenate([np.stack([a, a1, b1], -1).reshape(-1, 3),
                                np.stack([a, b1, b], -1).reshape(-1, 3)])

    # Flat caps at both ends (where the ring is open), facing -tangent and +tangent.
    n_ring_vertices = n_rings * sides
    cap_rings = np.concatenate([ring_start, end_ring])
    cap_sign = np.concatenate([-np.ones(len(ring_start)), np.ones(len(end_ring))])
    open_cap = radius[cap_rings] > 0
    cap_rings, cap_sign = cap_rings[open_cap], cap_sign[open_cap]
    n_caps = len(cap_rings)
    cap_base = n_ring_vertices + np.arange(n_caps) * sides       # each cap's own ring copy
    cap_vertices = ring_vertices[cap_rings].reshape(-1, 3)
    cap_normals = np.repeat(cap_sign[:, None] * tangent[cap_rings], sides, axis=0)
    first_corner = np.repeat(cap_base, sides - 2)
    u = first_corner + np.tile(np.arange(1, sides - 1), n_caps)
    back = np.repeat(cap_sign < 0, sides - 2)
    cap_tris = np.stack([first_corner, np.where(back, u + 1, u), np.where(back, u, u + 1)],
                        axis=1)

    vertices = np.concatenate([ring_vertices.reshape(-1, 3), cap_vertices])
    normals = np.concatenate([ring_normals, cap_normals])
    triangles = np.concatenate([side_tris, cap_tris]).astype(np.int64)
    vertex_curves = np.concatenate([np.repeat(ring_curve, sides),
                                    np.repeat(ring_curve[cap_rings], sides)])

    # Drop the sliver triangles of closed (radius 0) rings.
    corners = vertices[triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    edge = np.max(np.abs(corners - corners[:, :1]), axis=(1, 2))
    keep = np.einsum("ij,ij->i", cross, cross) > (1e-6 * edge ** 2) ** 2
    triangles = triangles[keep]

    vertex_rings = np.concatenate([np.repeat(np.arange(n_rings), sides),
                                   np.repeat(cap_rings, sides)])
    return Tubes(vertices.astype(np.float32), normals.astype(np.float32),
                 triangles.astype(np.int32), curve_ids[vertex_curves].astype(np.int32),
                 skipped, notes, intercept[vertex_rings].astype(np.float32),
                 curve_length[vertex_curves].astype(np.float32),
                 radius[vertex_rings].astype(np.float32))
