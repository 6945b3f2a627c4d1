"""Sample generation and warps, all vectorised over arrays of samples.

What it computes
    Random streams that depend only on (seed, purpose, batch) so results do not depend on
    thread scheduling; stratified 2-D samples per group (jittered grid when the count is a
    square, Latin hypercube otherwise); numbers stratified over a pixel's samples
    (``pixel_stratified``); the scrambled (0, 2)-sequence (``sobol_02``, Sobol 1967's first
    two dimensions) for adaptive sampling; warps from the unit square to the disk, triangle,
    cosine hemisphere, sphere and cone; orthonormal frames around normals; importance
    sampling of the Blackman-Harris pixel filter.

Parameters and units
    ``seed`` (int, default 0): the render seed. Directions are unit vectors; solid angles in sr.

Seed equations and corrections
    Triangle sampling follows DESIGN.md §4 (the seed's Eq. 9.1-9.3 corrected):
    alpha = 1 - sqrt(xi1), beta = xi2 sqrt(xi1) is uniform over the triangle.
    Cosine hemisphere (Eq. 8.4-8.6, 9.5): Malley's method through the concentric disk map
    (Shirley and Chiu 1997). Orthonormal basis: Duff et al. 2017, "Building an Orthonormal
    Basis, Revisited". Filter: Blackman-Harris with Cycles' meaning of its width (default
    1.5 px: the window spans [-1.5, 1.5] px, measured against Cycles' edge profile), sampled
    separably in x and y through a tabulated inverse CDF (Cycles' filter table).
"""
from __future__ import annotations

import numpy as np

# Stream ids keep the random numbers of different purposes independent.
STREAM_CAMERA = 1
STREAM_LIGHT = 2
STREAM_PHOTON = 3
STREAM_GATHER = 4
STREAM_EDGE = 5          # the camera's extra samples of emitter edges (pipeline.py)
STREAM_CAUSTIC = 6       # the caustic photon map's pilot and photons (photons.py)
# (7: shadow_photons.STREAM_SHADOW_PHOTON)
STREAM_TEXTURE = 8       # the camera's extra texture look-ups per sample (integrator.py)
STREAM_SEQUENCE = 9      # the per-pixel scrambles of adaptive sampling's sequence (integrator.py)


def rng_for(seed: int, stream: int, batch: int = 0) -> np.random.Generator:
    """A generator that depends only on (seed, stream, batch)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed) & 0xFFFFFFFF,
                                                                         int(stream), int(batch)])))


def stratified_2d(groups: int, count: int, rng: np.random.Generator,
                  shuffle: bool = True) -> np.ndarray:
    """``count`` stratified points in [0, 1)^2 for each of ``groups`` groups: (groups, count, 2).

    A jittered sqrt(count) x sqrt(count) grid when ``count`` is a square, visited in a random
    order per group when ``shuffle`` (needed when the sample index pairs these numbers with
    other dimensions); otherwise a Latin hypercube (stratified in each axis).
    """
    u = rng.random((groups, count, 2), dtype=np.float32).astype(np.float64, copy=False) \
        if shuffle else rng.random((groups, count, 2), dtype=np.float32)
    side = int(round(np.sqrt(count)))
    if side * side == count and count > 1 and not shuffle:
        # Same grid for every group: add the cell corners as one flat row per group.
        cells = np.arange(count)
        corner = np.stack([cells % side, cells // side], axis=1).astype(u.dtype).reshape(1, -1)
        flat = u.reshape(groups, -1)
        flat += corner
        flat /= side
    elif side * side == count and count > 1:
        cells = np.argsort(rng.random((groups, count)), axis=1)
        u[..., 0] = (cells % side + u[..., 0]) / side
        u[..., 1] = (cells // side + u[..., 1]) / side
    elif count > 1:
        for axis in (0, 1):
            perm = np.argsort(rng.random((groups, count)), axis=1)
            u[..., axis] = (perm + u[..., axis]) / count
    return u


def jittered_2d(groups: int, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points in [0, 1)^2 for each of ``groups`` groups, (groups, count, 2): one in
    each cell of an a x b grid (a b = count, a the largest divisor of count up to its square
    root: 8 x 14 for 112), visited in a random order per group, so that any chunk of them is
    a random subset and all of them together are stratified in two dimensions (a Latin
    hypercube stratifies each axis alone)."""
    a = max(d for d in range(1, int(np.sqrt(count)) + 1) if count % d == 0) if count else 1
    b = count // a if count else 0
    u = rng.random((groups, count, 2))
    cells = np.argsort(rng.random((groups, count)), axis=1)
    u[..., 0] = (cells % b + u[..., 0]) / max(b, 1)
    u[..., 1] = (cells // b + u[..., 1]) / a
    return u


def sobol_02(index: np.ndarray, scramble: np.ndarray) -> np.ndarray:
    """Points (N, 2) in [0, 1)^2 of the (0, 2)-sequence at integer ``index`` (N,): Sobol's
    first two dimensions (van der Corput's radical inverse, and the one whose generator is
    Pascal's triangle mod 2), each XOR-ed with ``scramble`` (N, 2) uint32 (a random digit
    scramble, which keeps the sequence's stratification: every run of 2^k points starting
    at a multiple of 2^k has one point in each of the 2^k boxes of every shape 2^-a x 2^-b,
    a + b = k). A pixel's samples 0..2^k - 1 are thus as well spread as a jittered grid, and
    samples added later (adaptive sampling) keep the whole set so."""
    i = np.asarray(index, np.uint64).astype(np.uint32)
    x = np.zeros(len(i), np.uint32)
    y = np.zeros(len(i), np.uint32)
    v = np.uint32(1 << 31)
    bits = int(i.max()).bit_length() if len(i) else 0
    for bit in range(bits):
        on = ((i >> np.uint32(bit)) & np.uint32(1)).astype(bool)
        x[on] ^= np.uint32(1 << (31 - bit))
        y[on] ^= v
        v ^= v >> np.uint32(1)
    scramble = np.asarray(scramble, np.uint32).reshape(-1, 2)
    x ^= scramble[:, 0]
    y ^= scramble[:, 1]
    out = np.stack([x, y], axis=1).astype(np.float64) * (1.0 / 4294967296.0)
    return np.minimum(out, 1.0 - 2.0 ** -53)


def pixel_stratified(rays: np.ndarray, spp: int, count: int, rng: np.random.Generator
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Light-sample numbers stratified over each pixel's samples instead of each point's.

    ``rays`` (N,): primary-ray indices (pixel x ``spp`` + sample), each at most once; each
    point takes ``count`` numbers. A pixel's ``spp`` x ``count`` slots share one set: 2-D
    numbers from a jittered grid over them (``jittered_2d``) and a 1-D number from a
    stratified line, each in its own random order per pixel, so any one point's numbers are
    uniform (unbiased) while the pixel's sum sees every stratum once. Returns (u2 (N, count,
    2), u1 (N, count)). Costs numbers for every slot of the pixels present: for the primary
    hits of a block, where most slots are."""
    rays = np.asarray(rays, np.int64)
    pixel, sample = np.divmod(rays, int(spp))
    present, row = np.unique(pixel, return_inverse=True)
    slots = int(spp) * int(count)
    grid = jittered_2d(len(present), slots, rng)                          # (P, slots, 2)
    line = (np.argsort(rng.random((len(present), slots)), axis=1)
            + rng.random((len(present), slots))) / slots                   # (P, slots)
    col = sample[:, None] * int(count) + np.arange(int(count))[None, :]   # (N, count)
    return grid[row[:, None], col], line[row[:, None], col]


# Row-wise helpers for (N, 3) vectors. numpy broadcasts over a last axis of 3 slowly (one
# inner loop per row), so these work on the three columns instead (one loop over N each).
def dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (N, 3) arrays: (N,)."""
    out = a[:, 0] * b[:, 0]
    tmp = a[:, 1] * b[:, 1]
    out += tmp
    np.multiply(a[:, 2], b[:, 2], out=tmp)
    out += tmp
    return out


def scale_rows(a: np.ndarray, s: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """a * s[:, None] for a (N, 3) and s (N,); ``out`` may be ``a``."""
    if out is None:
        out = np.empty(a.shape, np.result_type(a, s))
    for c in range(3):
        np.multiply(a[:, c], s, out=out[:, c])
    return out


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent vectors (t, b) with (t, b, n) orthonormal, for unit normals n (N, 3)."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def cosine_directions(n: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Cosine-distributed directions (N, 3) about unit normals ``n`` (N, 3) (pdf cos/pi,
    Eq. 9.5) from ``u`` (N, 2) in [0, 1): polar map r = sqrt(u0), phi = 2 pi u1, in the
    frame of :func:`orthonormal_basis`, computed a column at a time (no (N, 3) temporaries
    per term). For unstratified numbers (photon bounces) the polar map is as good as the
    concentric one and cheaper."""
    dtype = n.dtype
    nx, ny, nz = n[:, 0], n[:, 1], n[:, 2]
    r = np.sqrt(u[:, 0]).astype(dtype, copy=False)
    phi = (2.0 * np.pi * u[:, 1]).astype(dtype, copy=False)
    lx = r * np.cos(phi)
    ly = r * np.sin(phi)
    lz = np.sqrt(np.maximum(0.0, 1.0 - r * r)).astype(dtype, copy=False)
    sign = np.where(nz >= 0, dtype.type(1), dtype.type(-1))
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    out = np.empty(n.shape, dtype)
    # t = (1 + sign nx^2 a, sign b, -sign nx), bt = (b, sign + ny^2 a, -ny)
    out[:, 0] = lx * (1.0 + sign * nx * nx * a) + ly * b + lz * nx
    out[:, 1] = lx * (sign * b) + ly * (sign + ny * ny * a) + lz * ny
    out[:, 2] = -lx * (sign * nx) - ly * ny + lz * nz
    return out


def square_to_disk(u: np.ndarray) -> np.ndarray:
    """Concentric map of [0,1)^2 onto the unit disk (Shirley and Chiu); returns (..., 2)."""
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    use_a = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    r = np.where(use_a, a, b)
    phi = np.where(use_a, (np.pi / 4) * (b / safe_a), (np.pi / 2) - (np.pi / 4) * (a / safe_b))
    r = np.where((a == 0) & (b == 0), 0.0, r)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def square_to_triangle(u: np.ndarray) -> np.ndarray:
    """Uniform barycentrics (alpha, beta) over a triangle (DESIGN.md §4 correction)."""
    s = np.sqrt(u[..., 0])
    return np.stack([1.0 - s, u[..., 1] * s], axis=-1)


def square_to_cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Local directions (..., 3) about +z with pdf cos(theta)/pi (Eq. 8.4-8.6, 9.5)."""
    d = square_to_disk(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - d[..., 0] ** 2 - d[..., 1] ** 2))
    return np.concatenate([d, z[..., None]], axis=-1)


def square_to_sphere(u: np.ndarray) -> np.ndarray:
    """Uniform directions on the unit sphere (..., 3), pdf 1/(4 pi)."""
    z = 1.0 - 2.0 * u[..., 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def square_to_cone(u: np.ndarray, cos_max: float | np.ndarray) -> np.ndarray:
    """Uniform directions (..., 3) in the cone about +z with cos(theta) >= cos_max."""
    z = 1.0 - u[..., 0] * (1.0 - cos_max)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def to_world(local: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotate local (N, 3) directions about +z into the frame (t, b, n)."""
    return local[:, 0:1] * t + local[:, 1:2] * b + local[:, 2:3] * n


# Pixel filter -------------------------------------------------------------------------------
FILTER_TABLE_SIZE = 1024      # entries of Cycles' filter table
FILTER_LOOKUP_BINS = 65536    # equal bins of u in which that table's reading is stored here


def _blackman_harris(x: np.ndarray) -> np.ndarray:
    """The Blackman-Harris window on [0, 1]."""
    a = 2.0 * np.pi * x
    return 0.35875 - 0.48829 * np.cos(a) + 0.14128 * np.cos(2 * a) - 0.01168 * np.cos(3 * a)


def cycles_filter_table(width: float, size: int = FILTER_TABLE_SIZE) -> np.ndarray:
    """Pixel offsets [px] about the centre at ``size`` evenly spaced u in [0, 1]: the table
    through which Cycles samples its Blackman-Harris filter of width w (spanning [-w, w]),
    which it reads with linear interpolation in u (``filter_offsets``).

    Built as Cycles builds it (measured against Cycles 5.0.1, ``tests/data/README.md``): the
    half window on [0, w] summed at size - 1 evenly spaced points into a running CDF (left
    sums), inverted at (size - 1) / 2 + 1 evenly spaced probabilities q by the first CDF entry
    above q and the slope of the step after it, the offset (index + t) / (size - 1) w mirrored
    about the centre, and the last entry, which that inversion never writes, left at the
    pixel's corner (offset -1/2). Read with linear interpolation, the outermost step on each
    side spreads its 1/1023 of the samples evenly over [1.19 w / 1.5, w], where the window
    itself has almost nothing; the unwritten entry sends another 1/1023 evenly over
    [-1/2, w]. So Cycles' filter puts 6.5e-4 of the weight beyond 1.32 px at w = 1.5, not the
    window's 1.5e-4: next to an emitter 100 x brighter than the wall beside it, a pixel row
    1.3 px off the emitter's edge gets 0.03 (about 8 % of the ceiling there, measured on the
    original Cornell box) that an exact Blackman-Harris does not give it."""
    n = size - 1
    x = width * np.arange(n) / (n - 1)
    cdf = np.concatenate([[0.0], np.cumsum(np.abs(_blackman_harris(x / (2.0 * width) + 0.5)))])
    cdf /= cdf[-1]
    half = (size - 1) // 2
    q = np.arange(half + 1) / half
    k = np.searchsorted(cdf, q, side="right")            # first entry above q
    last = k >= len(cdf) - 1
    k0 = np.minimum(k, len(cdf) - 2)
    t = np.where(last, 0.0, (q - cdf[k0]) / (cdf[k0 + 1] - cdf[k0]))
    k = np.where(last, len(cdf) - 1, k)
    r = (k + t) / (size - 1) * width
    table = np.full(size, -0.5)
    table[half + np.arange(half + 1)] = r
    table[half - np.arange(half + 1)] = -r
    return table


def _blackman_harris_inverse_cdf(width: float, bins: int = FILTER_LOOKUP_BINS) -> np.ndarray:
    """``cycles_filter_table`` read with linear interpolation at the centres of ``bins``
    equal bins of u (float32): one ``np.take`` a sample, within 1/65536 of a step of the
    interpolation."""
    table = cycles_filter_table(width)
    p = (np.arange(bins) + 0.5) / bins * (len(table) - 1)
    i = p.astype(np.int64)
    t = p - i
    return ((1.0 - t) * table[i] + t * table[np.minimum(i + 1, len(table) - 1)]).astype(np.float32)


_FILTER_TABLES: dict[float, np.ndarray] = {}


def filter_offsets(u: np.ndarray, width: float = 1.5, out: np.ndarray | None = None) -> np.ndarray:
    """Map uniform [0,1) numbers to pixel offsets distributed like Cycles' Blackman-Harris
    filter: separable in x and y, through Cycles' own table read with linear interpolation
    (``cycles_filter_table``); a width of 0 gives a box filter of one pixel. Offsets are in
    pixels about the pixel centre, float32.
    ``out`` (float32, may be ``u``) receives the offsets.
    """
    if width <= 0:
        return (u - 0.5).astype(np.float32)
    table = _FILTER_TABLES.get(width)
    if table is None:
        table = _FILTER_TABLES[width] = _blackman_harris_inverse_cdf(width)
    # Bin index, truncated straight into int32; mode="clip" maps u = 1 to the last bin.
    index = np.multiply(u, np.float32(len(table)), out=np.empty(u.shape, np.int32), casting="unsafe")
    return np.take(table, index, mode="clip", out=out)
