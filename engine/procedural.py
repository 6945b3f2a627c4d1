"""Blender's procedural textures as Cycles computes them: Noise, Voronoi and Wave, over arrays.

What it computes
----------------
The value of Blender 5.2's Noise Texture, Voronoi Texture and Wave Texture nodes at N points at
once, to agree with Cycles' CPU kernel to float32 rounding. The functions here follow the
definitions in Blender's ``intern/cycles/kernel/svm/noise.h`` (Perlin gradient noise and its
[-1, 1] scaling), ``fractal_noise.h`` (fBM, multifractal, hybrid and ridged multifractal,
heterogeneous terrain), ``noisetex.h`` (distortion and the colour seeds), ``voronoi.h``
(F1, F2, smooth F1, distance to edge, n-sphere radius, fractal octaves) and ``wave.h``, and the
Jenkins lookup3 hash of ``intern/cycles/util/hash.h`` (Bob Jenkins, lookup3.c, 2006); they are
written anew as numpy over the whole batch: the hash in uint32 arithmetic (wrapping as C's
``uint`` does), the geometry in float32 where Cycles computes in float, so that the lattice
cells, hashes and octaves are the ones Cycles picks. Loops run over lattice neighbours and
octaves, never over points.

Parameters and units
--------------------
Points ``p`` are (N, d) float arrays, d = 1..4, in texture space (the node's Vector times its
Scale; W is the fourth coordinate, or the only one in 1D): unitless, one lattice cell per unit.
Every other parameter (detail, roughness, lacunarity, offset, gain, distortion, randomness,
smoothness, exponent, phase ...) is a scalar or an (N,) array, one value per point, as a linked
socket gives it. Detail counts octaves beyond the first (0..15, fractional parts blend in the
next octave); roughness is the amplitude ratio between octaves and lacunarity their frequency
ratio. Results are float32 arrays.
"""
from __future__ import annotations

import numpy as np

__all__ = ["hash_uint", "hash_uint2", "hash_uint3", "hash_uint4", "hash_floats_to_float",
           "perlin", "snoise", "noise_fractal", "noise_texture", "voronoi_texture",
           "wave_texture", "NOISE_TYPES", "VORONOI_FEATURES", "VORONOI_METRICS"]

F32 = np.float32
U32 = np.uint32
NOISE_TYPES = ("FBM", "MULTIFRACTAL", "HYBRID_MULTIFRACTAL", "RIDGED_MULTIFRACTAL",
               "HETERO_TERRAIN")
VORONOI_FEATURES = ("F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE", "N_SPHERE_RADIUS")
VORONOI_METRICS = ("EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI")
FLT_MAX = F32(3.4028235e38)


# ---------------------------------------------------------------------------------------------
# Jenkins lookup3 ("final" and "mix" rounds), uint32 wrapping arithmetic

def _u32(x):
    x = np.asarray(x)
    if x.dtype == np.uint32:
        return x
    if x.dtype == np.float32:
        return x.view(U32)
    return x.astype(np.int64).astype(U32)


def _rot(x, k):
    return (x << U32(k)) | (x >> U32(32 - k))


def _final(a, b, c):
    c = c ^ b
    c = c - _rot(b, 14)
    a = a ^ c
    a = a - _rot(c, 11)
    b = b ^ a
    b = b - _rot(a, 25)
    c = c ^ b
    c = c - _rot(b, 16)
    a = a ^ c
    a = a - _rot(c, 4)
    b = b ^ a
    b = b - _rot(a, 14)
    c = c ^ b
    c = c - _rot(b, 24)
    return c


def _mix(a, b, c):
    a = a - c
    a = a ^ _rot(c, 4)
    c = c + b
    b = b - a
    b = b ^ _rot(a, 6)
    a = a + c
    c = c - b
    c = c ^ _rot(b, 8)
    b = b + a
    a = a - c
    a = a ^ _rot(c, 16)
    c = c + b
    b = b - a
    b = b ^ _rot(a, 19)
    a = a + c
    c = c - b
    c = c ^ _rot(b, 4)
    b = b + a
    return a, b, c


def _seed(n_keys):
    return U32((0xDEADBEEF + (n_keys << 2) + 13) & 0xFFFFFFFF)


def hash_uint(kx):
    """lookup3 of one 32-bit key per point (ints wrap to uint32, float32 hash by their bits)."""
    kx = _u32(kx)
    a = b = c = np.full(kx.shape, _seed(1), U32)
    return _final(a + kx, b, c)


def hash_uint2(kx, ky):
    kx, ky = _u32(kx), _u32(ky)
    a = b = c = np.full(np.broadcast(kx, ky).shape, _seed(2), U32)
    return _final(a + kx, b + ky, c)


def hash_uint3(kx, ky, kz):
    kx, ky, kz = _u32(kx), _u32(ky), _u32(kz)
    a = b = c = np.full(np.broadcast(kx, ky, kz).shape, _seed(3), U32)
    return _final(a + kx, b + ky, c + kz)


def hash_uint4(kx, ky, kz, kw):
    kx, ky, kz, kw = _u32(kx), _u32(ky), _u32(kz), _u32(kw)
    a = b = c = np.full(np.broadcast(kx, ky, kz, kw).shape, _seed(4), U32)
    a, b, c = _mix(a + kx, b + ky, c + kz)
    return _final(a + kw, b, c)


_HASHES = {1: hash_uint, 2: hash_uint2, 3: hash_uint3, 4: hash_uint4}


def _to_unit(h):
    """uint32 -> [0, 1] as Cycles' uint_to_float_incl: float(h) * 2^-32 in float32."""
    return h.astype(F32) * F32(2.0 ** -32)


def hash_floats_to_float(*keys):
    """[0, 1] hash of 1-4 float32 keys by their bit patterns (hash_floatN_to_float)."""
    return _to_unit(_HASHES[len(keys)](*(np.asarray(k, F32) for k in keys)))


def _pcg(v):
    """PCG 2D/3D/4D integer hash (Jarzynski and Olano, JCGT 2020) in the signed-int form
    Cycles uses for Voronoi (hash_pcgNd_i: int32 wrapping, arithmetic shift, 31 bits kept);
    ``v`` a list of d int32 arrays."""
    with np.errstate(over="ignore"):
        v = [x.astype(np.int32) * np.int32(1664525) + np.int32(1013904223) for x in v]
        for rnd in range(2):
            if rnd:
                v = [x ^ (x >> np.int32(16)) for x in v]
            if len(v) == 2:
                v[0] = v[0] + v[1] * np.int32(1664525)
                v[1] = v[1] + v[0] * np.int32(1664525)
            elif len(v) == 3:
                v[0] = v[0] + v[1] * v[2]
                v[1] = v[1] + v[2] * v[0]
                v[2] = v[2] + v[0] * v[1]
            else:
                v[0] = v[0] + v[1] * v[3]
                v[1] = v[1] + v[2] * v[0]
                v[2] = v[2] + v[0] * v[1]
                v[3] = v[3] + v[1] * v[2]
    return [x & np.int32(0x7FFFFFFF) for x in v]


def _pcg_unit(v):
    """hash_intN_to_floatN: the PCG hash scaled to [0, 1] (float(h) / 2^31 in float32)."""
    return [h.astype(F32) * F32(2.0 ** -31) for h in _pcg(v)]


def _cell_offset(cell, d: int):
    """Feature-point offsets in [0, 1]^d of lattice cells (N, d): in 1D Cycles hashes the cell's
    float bits (hash_float_to_float), in 2D-4D its integer coordinates (hash_intN_to_floatN)."""
    if d == 1:
        return hash_floats_to_float(np.asarray(cell, F32)[:, 0])[:, None]
    return np.stack(_pcg_unit([cell[:, i] for i in range(d)]), -1)


def _cell_colour(cell, d: int):
    """A cell's colour: hash_float_to_float3 in 1D, hash_int2_to_float3 (PCG 3D of (x, y, 0)),
    hash_int3_to_float3, and the first three components of hash_int4_to_float4."""
    if d == 1:
        c = np.asarray(cell, F32)[:, 0]
        one, two = F32(1.0), F32(2.0)
        return np.stack([hash_floats_to_float(c), hash_floats_to_float(c, one),
                         hash_floats_to_float(c, two)], -1)
    ints = [cell[:, i] for i in range(d)]
    if d == 2:
        ints.append(np.zeros_like(ints[0]))
    return np.stack(_pcg_unit(ints)[:3], -1)


# ---------------------------------------------------------------------------------------------
# Perlin gradient noise (Cycles' perlin_1d..4d and noise_scale1..4)

_NOISE_SCALE = {1: F32(0.25), 2: F32(0.6616), 3: F32(0.982), 4: F32(0.8344)}


def _fade(t):
    return t * t * t * (t * (t * F32(6.0) - F32(15.0)) + F32(10.0))


def _lerp(a, b, t):
    return a + t * (b - a)


def _neg_if(v, cond):
    return np.where(cond, -v, v)


def _grad(h, f, d: int):
    """Gradient dot offset for hash ``h`` (uint32) and offsets ``f`` (list of d arrays)."""
    if d == 1:
        hh = h & U32(15)
        g = F32(1.0) + (hh & U32(7)).astype(F32)
        return _neg_if(g, (hh & U32(8)) != 0) * f[0]
    if d == 2:
        hh = h & U32(7)
        lo = hh < 4
        u = np.where(lo, f[0], f[1])
        v = F32(2.0) * np.where(lo, f[1], f[0])
        return _neg_if(u, (hh & U32(1)) != 0) + _neg_if(v, (hh & U32(2)) != 0)
    if d == 3:
        hh = h & U32(15)
        u = np.where(hh < 8, f[0], f[1])
        vt = np.where((hh == 12) | (hh == 14), f[0], f[2])
        v = np.where(hh < 4, f[1], vt)
        return _neg_if(u, (hh & U32(1)) != 0) + _neg_if(v, (hh & U32(2)) != 0)
    hh = h & U32(31)
    u = np.where(hh < 24, f[0], f[1])
    v = np.where(hh < 16, f[1], f[2])
    s = np.where(hh < 8, f[2], f[3])
    return (_neg_if(u, (hh & U32(1)) != 0) + _neg_if(v, (hh & U32(2)) != 0)
            + _neg_if(s, (hh & U32(4)) != 0))


def perlin(p):
    """Unscaled Perlin noise at (N, d) points (float32), Cycles' perlin_Nd."""
    p = np.asarray(p, F32)
    d = p.shape[1]
    fl = np.floor(p)
    cell = fl.astype(np.int32)
    frac = p - fl
    fades = [_fade(frac[:, i]) for i in range(d)]
    hash_fn = _HASHES[d]
    corners = {}
    for k in range(1 << d):
        bits = [(k >> i) & 1 for i in range(d)]
        h = hash_fn(*(cell[:, i] + np.int32(bits[i]) for i in range(d)))
        corners[k] = _grad(h, [frac[:, i] - F32(bits[i]) for i in range(d)], d)
    # interpolate along x first, then y, z, w (a + t (b - a), as Cycles' SIMD mix)
    vals = corners
    for axis in range(d):
        step = 1 << axis
        vals = {k: _lerp(vals[k], vals[k + step], fades[axis])
                for k in vals if not (k >> axis) & 1}
    return vals[0]


def snoise(p):
    """Signed noise in about [-1, 1] (Cycles' snoise_Nd: coordinates wrapped at 1e5)."""
    p = np.fmod(np.asarray(p, F32), F32(100000.0))
    return _NOISE_SCALE[p.shape[1]] * perlin(p)


# ---------------------------------------------------------------------------------------------
# Fractal noise (Cycles' fractal_noise.h), per-point parameters through masks

def _arr(x, n):
    return np.broadcast_to(np.asarray(x, F32), (n,)).copy()


def _fbm(p, detail, rough, lac, normalize):
    n = p.shape[0]
    fscale, amp = np.ones(n, F32), np.ones(n, F32)
    maxamp, total = np.zeros(n, F32), np.zeros(n, F32)
    octaves = np.floor(detail).astype(np.int64)
    for i in range(int(octaves.max(initial=0)) + 1):
        on = i <= octaves
        t = snoise(fscale[:, None] * p)
        total = np.where(on, total + t * amp, total)
        maxamp = np.where(on, maxamp + amp, maxamp)
        amp = np.where(on, amp * rough, amp)
        fscale = np.where(on, fscale * lac, fscale)
    rmd = detail - np.floor(detail)
    frac = rmd != 0
    t = snoise(fscale[:, None] * p) if frac.any() else np.zeros(n, F32)
    total2 = total + t * amp
    with np.errstate(divide="ignore", invalid="ignore"):
        if normalize:
            a = F32(0.5) * total / maxamp + F32(0.5)
            b = F32(0.5) * total2 / (maxamp + amp) + F32(0.5)
            return np.where(frac, _lerp(a, b, rmd), a)
    return np.where(frac, _lerp(total, total2, rmd), total)


def _multifractal(p, detail, rough, lac):
    n = p.shape[0]
    value, pwr = np.ones(n, F32), np.ones(n, F32)
    octaves = np.floor(detail).astype(np.int64)
    p = p.copy()
    for i in range(int(octaves.max(initial=0)) + 1):
        on = i <= octaves
        value = np.where(on, value * (pwr * snoise(p) + F32(1.0)), value)
        pwr = np.where(on, pwr * rough, pwr)
        p = np.where(on[:, None], p * lac[:, None], p)
    rmd = detail - np.floor(detail)
    return np.where(rmd != 0, value * (rmd * pwr * snoise(p) + F32(1.0)), value)


def _hetero_terrain(p, detail, rough, lac, offset):
    pwr = rough.copy()
    value = offset + snoise(p)
    p = p * lac[:, None]
    octaves = np.floor(detail).astype(np.int64)
    for i in range(1, int(octaves.max(initial=0)) + 1):
        on = i <= octaves
        inc = (snoise(p) + offset) * pwr * value
        value = np.where(on, value + inc, value)
        pwr = np.where(on, pwr * rough, pwr)
        p = np.where(on[:, None], p * lac[:, None], p)
    rmd = detail - np.floor(detail)
    inc = (snoise(p) + offset) * pwr * value
    return np.where(rmd != 0, value + rmd * inc, value)


def _hybrid_multifractal(p, detail, rough, lac, offset, gain):
    n = p.shape[0]
    pwr, weight = np.ones(n, F32), np.ones(n, F32)
    value = np.zeros(n, F32)
    octaves = np.floor(detail).astype(np.int64)
    running = np.ones(n, bool)
    p = p.copy()
    for i in range(int(octaves.max(initial=0)) + 1):
        running &= (weight > F32(0.001)) & (i <= octaves)
        if not running.any():
            break
        weight = np.where(running, np.minimum(weight, F32(1.0)), weight)
        signal = (snoise(p) + offset) * pwr
        pwr = np.where(running, pwr * rough, pwr)
        value = np.where(running, value + weight * signal, value)
        weight = np.where(running, weight * gain * signal, weight)
        p = np.where(running[:, None], p * lac[:, None], p)
    rmd = detail - np.floor(detail)
    last = (rmd != 0) & (weight > F32(0.001))
    w = np.minimum(weight, F32(1.0))
    signal = (snoise(p) + offset) * pwr
    return np.where(last, value + rmd * w * signal, value)


def _ridged_multifractal(p, detail, rough, lac, offset, gain):
    pwr = rough.copy()
    signal = offset - np.abs(snoise(p))
    signal = signal * signal
    value = signal.copy()
    octaves = np.floor(detail).astype(np.int64)
    p = p.copy()
    for i in range(1, int(octaves.max(initial=0)) + 1):
        on = i <= octaves
        p = np.where(on[:, None], p * lac[:, None], p)
        weight = np.clip(signal * gain, F32(0.0), F32(1.0))
        s = offset - np.abs(snoise(p))
        s = s * s * weight
        signal = np.where(on, s, signal)
        value = np.where(on, value + s * pwr, value)
        pwr = np.where(on, pwr * rough, pwr)
    return value


def noise_fractal(kind: str, p, detail, roughness, lacunarity, offset=0.0, gain=1.0,
                  normalize: bool = True):
    """Cycles' noise_select: fractal noise of type ``kind`` (one of NOISE_TYPES) at (N, d)
    points; ``normalize`` applies to fBM only."""
    p = np.asarray(p, F32)
    n = p.shape[0]
    detail, rough, lac, off, gain = (_arr(x, n) for x in (detail, roughness, lacunarity,
                                                          offset, gain))
    with np.errstate(over="ignore", invalid="ignore"):
        if kind == "FBM":
            return _fbm(p, detail, rough, lac, normalize)
        if kind == "MULTIFRACTAL":
            return _multifractal(p, detail, rough, lac)
        if kind == "HETERO_TERRAIN":
            return _hetero_terrain(p, detail, rough, lac, off)
        if kind == "HYBRID_MULTIFRACTAL":
            return _hybrid_multifractal(p, detail, rough, lac, off, gain)
        if kind == "RIDGED_MULTIFRACTAL":
            return _ridged_multifractal(p, detail, rough, lac, off, gain)
    raise KeyError(kind)


def _random_offset(seed: float, d: int):
    """noisetex.h's per-seed coordinate offsets in [100, 200] (d components)."""
    s = np.array([seed], F32)

    def fma(h):                      # 100 + h 100 rounded once, as a fused multiply-add
        return (100.0 + h.astype(np.float64) * 100.0).astype(F32)
    if d == 1:
        return fma(hash_floats_to_float(s))
    return np.concatenate([fma(hash_floats_to_float(s, np.array([F32(i)])))
                           for i in range(d)])


def noise_texture(p, kind="FBM", detail=2.0, roughness=0.5, lacunarity=2.0, offset=0.0,
                  gain=1.0, distortion=0.0, normalize=True, want_color=True):
    """Blender's Noise Texture at (N, d) points already multiplied by Scale: returns
    (Fac (N,), Color (N, 3) or None). Detail is clamped to [0, 15] and roughness to >= 0,
    as svm_node_tex_noise does."""
    p = np.asarray(p, F32)
    n, d = p.shape
    detail = np.clip(_arr(detail, n), F32(0.0), F32(15.0))
    roughness = np.maximum(_arr(roughness, n), F32(0.0))
    distortion = _arr(distortion, n)
    if np.any(distortion != 0):
        warp = np.stack([snoise(p + _random_offset(float(i), d)) for i in range(d)], -1)
        p = np.where((distortion != 0)[:, None], p + warp * distortion[:, None], p)
    args = (detail, roughness, lacunarity, offset, gain, normalize)
    fac = noise_fractal(kind, p, *args)
    if not want_color:
        return fac, None
    seeds = (1.0, 2.0) if d == 1 else (float(d), float(d + 1))
    g = noise_fractal(kind, p + _random_offset(seeds[0], d), *args)
    b = noise_fractal(kind, p + _random_offset(seeds[1], d), *args)
    return fac, np.stack([fac, g, b], -1)


# ---------------------------------------------------------------------------------------------
# Voronoi (Cycles' voronoi.h)

def _offsets(d: int, r: int):
    """All integer offsets in [-r, r]^d, x fastest (Cycles' loop order), as float32 rows."""
    g = np.stack(np.meshgrid(*([np.arange(-r, r + 1)] * d), indexing="ij"), -1)
    g = g.reshape(-1, d)[:, ::-1]                      # last loop variable (x) fastest
    return g.astype(F32)


def _distance(a, b, metric: str, exponent):
    diff = np.abs(a - b)
    if diff.shape[1] == 1:
        return diff[:, 0]
    if metric == "EUCLIDEAN":
        return np.sqrt(np.sum(diff * diff, axis=1, dtype=F32))
    if metric == "MANHATTAN":
        return np.sum(diff, axis=1, dtype=F32)
    if metric == "CHEBYCHEV":
        return diff.max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        e = exponent[:, None]
        return np.power(np.sum(np.power(diff, e), axis=1, dtype=F32), F32(1.0) / exponent)


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), F32(0.0), F32(1.0))
    return t * t * (F32(3.0) - F32(2.0) * t)


def _distance_bound(a, b, metric: str, exponent):
    """voronoi_distance_bound: a monotone stand-in for the distance (squared for Euclidean,
    Minkowski without its root) that Cycles compares in F1 searches."""
    if a.shape[1] == 1 or metric in ("MANHATTAN", "CHEBYCHEV"):
        return _distance(a, b, metric, exponent)
    diff = np.abs(a - b)
    if metric == "EUCLIDEAN":
        return np.sum(diff * diff, axis=1, dtype=F32)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.sum(np.power(diff, exponent[:, None]), axis=1, dtype=F32)


def _cells(coord):
    """(cell floats, local position, cell keys): the keys are float32 cells in 1D and int32
    cells in 2D-4D, as Cycles hashes them; offsets are added to the keys."""
    cell = np.floor(coord)
    key = cell if coord.shape[1] == 1 else cell.astype(np.int32)
    return cell, coord - cell, key


def _voronoi_octave(coord, feature, metric, exponent, randomness, smoothness):
    """One octave of F1 / F2 / smooth F1: (distance (N,), colour (N, 3), position (N, d))."""
    n, d = coord.shape
    cell, local, key = _cells(coord)
    rnd = randomness[:, None]
    kt = key.dtype
    if feature == "SMOOTH_F1":
        sm = smoothness
        dist = np.zeros(n, F32)
        col = np.zeros((n, 3), F32)
        pos = np.zeros((n, d), F32)
        first = True
        for o in _offsets(d, 2):
            k = key + o.astype(kt)
            off, ccol = _cell_offset(k, d), _cell_colour(k, d)
            point = o + off * rnd
            dp = _distance(point, local, metric, exponent)
            if first:
                h = np.ones(n, F32)
                first = False
            else:
                with np.errstate(divide="ignore", invalid="ignore"):
                    h = _smoothstep(F32(0.0), F32(1.0),
                                    F32(0.5) + F32(0.5) * (dist - dp) / sm)
            corr = sm * h * (F32(1.0) - h)
            dist = _lerp(dist, dp, h) - corr
            corr = corr / (F32(1.0) + F32(3.0) * sm)
            col = _lerp(col, ccol, h[:, None]) - corr[:, None]
            pos = _lerp(pos, point, h[:, None]) - corr[:, None]
        return dist, col, cell + pos
    d1 = np.full(n, FLT_MAX, F32)
    d2 = np.full(n, FLT_MAX, F32)
    o1 = np.zeros((n, d), F32)
    o2 = np.zeros((n, d), F32)
    p1 = np.zeros((n, d), F32)
    p2 = np.zeros((n, d), F32)
    for o in _offsets(d, 1):
        point = o + _cell_offset(key + o.astype(kt), d) * rnd
        if feature == "F1":
            dp = _distance_bound(point, local, metric, exponent)
            closer = dp < d1
            d1 = np.where(closer, dp, d1)
            o1 = np.where(closer[:, None], o, o1)
            p1 = np.where(closer[:, None], point, p1)
            continue
        dp = _distance(point, local, metric, exponent)
        closer = dp < d1
        second = ~closer & (dp < d2)
        d2 = np.where(closer, d1, np.where(second, dp, d2))
        o2 = np.where(closer[:, None], o1, np.where(second[:, None], o, o2))
        p2 = np.where(closer[:, None], p1, np.where(second[:, None], point, p2))
        d1 = np.where(closer, dp, d1)
        o1 = np.where(closer[:, None], o, o1)
        p1 = np.where(closer[:, None], point, p1)
    if feature == "F1":
        return (_distance(p1, local, metric, exponent), _cell_colour(key + o1.astype(kt), d),
                p1 + cell)
    return d2, _cell_colour(key + o2.astype(kt), d), p2 + cell


def _voronoi_edge(coord, randomness):
    n, d = coord.shape
    cell, local, key = _cells(coord)
    rnd = randomness[:, None]
    if d == 1:
        mid = _cell_offset(cell, 1)[:, 0] * rnd[:, 0]
        left = F32(-1.0) + _cell_offset(cell - F32(1.0), 1)[:, 0] * rnd[:, 0]
        right = F32(1.0) + _cell_offset(cell + F32(1.0), 1)[:, 0] * rnd[:, 0]
        lp = local[:, 0]
        return np.minimum(np.abs((mid + left) / F32(2.0) - lp),
                          np.abs((mid + right) / F32(2.0) - lp))
    offs = _offsets(d, 1)
    vecs = [o + _cell_offset(key + o.astype(key.dtype), d) * rnd - local for o in offs]
    best = np.full(n, FLT_MAX, F32)
    closest = np.zeros((n, d), F32)
    for v in vecs:
        dd = np.sum(v * v, axis=1, dtype=F32)
        c = dd < best
        best = np.where(c, dd, best)
        closest = np.where(c[:, None], v, closest)
    out = np.full(n, FLT_MAX, F32)
    for v in vecs:
        perp = v - closest
        pp = np.sum(perp * perp, axis=1, dtype=F32)
        ok = pp > F32(0.0001)
        with np.errstate(divide="ignore", invalid="ignore"):
            unit = perp / np.sqrt(pp)[:, None]
        e = np.sum((closest + v) / F32(2.0) * unit, axis=1, dtype=F32)
        out = np.where(ok, np.minimum(out, e), out)
    return out


def _voronoi_radius(coord, randomness):
    n, d = coord.shape
    cell, local, key = _cells(coord)
    kt = key.dtype
    rnd = randomness[:, None]
    best = np.full(n, FLT_MAX, F32)
    cp = np.zeros((n, d), F32)
    co = np.zeros((n, d), F32)
    for o in _offsets(d, 1):
        point = o + _cell_offset(key + o.astype(kt), d) * rnd
        dp = _distance_bound(point, local, "EUCLIDEAN", None)
        c = dp < best
        best = np.where(c, dp, best)
        cp = np.where(c[:, None], point, cp)
        co = np.where(c[:, None], o, co)
    best = np.full(n, FLT_MAX, F32)
    other = np.zeros((n, d), F32)
    for o in _offsets(d, 1):
        if not o.any():
            continue
        off = o + co
        point = off + _cell_offset(key + off.astype(kt), d) * rnd
        dp = _distance_bound(cp, point, "EUCLIDEAN", None)
        c = dp < best
        best = np.where(c, dp, best)
        other = np.where(c[:, None], point, other)
    return _distance(other, cp, "EUCLIDEAN", None) / F32(2.0)


def voronoi_texture(p, feature="F1", metric="EUCLIDEAN", detail=0.0, roughness=0.5,
                    lacunarity=2.0, smoothness=1.0, exponent=0.5, randomness=1.0,
                    normalize=False, scale=1.0):
    """Blender's Voronoi Texture at (N, d) points already multiplied by Scale (``scale`` is
    still needed: Position is divided by it). Returns a dict of Distance (N,), Color (N, 3),
    Position (N, d) and Radius (N,), those the feature defines (svm_node_tex_voronoi)."""
    coord = np.asarray(p, F32)
    n, d = coord.shape
    detail = np.clip(_arr(detail, n), F32(0.0), F32(15.0))
    rough = np.clip(_arr(roughness, n), F32(0.0), F32(1.0))
    lac = _arr(lacunarity, n)
    rnd = np.clip(_arr(randomness, n), F32(0.0), F32(1.0))
    smooth = np.clip(_arr(smoothness, n) / F32(2.0), F32(0.0), F32(0.5))
    expo = _arr(exponent, n)
    scale = _arr(scale, n)
    if feature == "N_SPHERE_RADIUS":
        return {"Radius": _voronoi_radius(coord, rnd)}
    zero_input = (detail == 0) | (rough == 0)
    amp = np.ones(n, F32)
    octave_scale = np.ones(n, F32)
    rmd = detail - np.floor(detail)
    n_oct = int(np.ceil(detail.max(initial=0)))
    if feature == "DISTANCE_TO_EDGE":
        max_dist = F32(0.5) + F32(0.5) * rnd
        max_amp = max_dist.copy()
        dist = np.full(n, F32(8.0))
        first = None
        for i in range(n_oct + 1):
            od = _voronoi_edge(coord * octave_scale[:, None], rnd)
            if i == 0:
                first = od
            full = i <= detail
            lerp_amp = _lerp(max_amp, max_dist / octave_scale, amp)
            lerp_dist = _lerp(dist, np.minimum(dist, od / octave_scale), amp)
            part = ~full & (rmd != 0)
            max_amp = np.where(full, lerp_amp, np.where(part, _lerp(max_amp, lerp_amp, rmd),
                                                         max_amp))
            dist = np.where(full, lerp_dist,
                            np.where(part, _lerp(dist, np.minimum(dist, lerp_dist), rmd), dist))
            octave_scale = np.where(full, octave_scale * lac, octave_scale)
            amp = np.where(full, amp * rough, amp)
        dist = np.where(zero_input, first, dist)
        if normalize:
            dist = np.where(zero_input, dist / max_dist, dist / max_amp)
        return {"Distance": dist}
    feat = "F1" if feature == "SMOOTH_F1" and not np.any(smooth != 0) else feature
    if d == 1:
        max_dist = F32(0.5) + F32(0.5) * rnd
    else:
        half = np.repeat((F32(0.5) + F32(0.5) * rnd)[:, None], d, 1)
        max_dist = _distance(np.zeros_like(half), half, metric, expo)
    if feature == "F2":
        max_dist = max_dist * F32(2.0)
    max_amp = np.zeros(n, F32)
    dist = np.zeros(n, F32)
    col = np.zeros((n, 3), F32)
    pos = np.zeros((n, d), F32)
    first = None
    for i in range(n_oct + 1):
        od, oc, op = _voronoi_octave(coord * octave_scale[:, None], feat, metric, expo, rnd,
                                     smooth)
        if i == 0:
            first = (od, oc, op)
        full = (i <= detail)
        part = ~full & (rmd != 0)
        a = amp[:, None]
        new_pos = _lerp(pos, op / octave_scale[:, None], a)
        max_amp = np.where(full, max_amp + amp,
                           np.where(part, _lerp(max_amp, max_amp + amp, rmd), max_amp))
        dist = np.where(full, dist + od * amp,
                        np.where(part, _lerp(dist, dist + od * amp, rmd), dist))
        col = np.where(full[:, None], col + oc * a,
                       np.where(part[:, None], _lerp(col, col + oc * a, rmd[:, None]), col))
        pos = np.where(full[:, None], new_pos,
                       np.where(part[:, None], _lerp(pos, new_pos, rmd[:, None]), pos))
        octave_scale = np.where(full, octave_scale * lac, octave_scale)
        amp = np.where(full, amp * rough, amp)
    z = zero_input
    dist = np.where(z, first[0], dist)
    col = np.where(z[:, None], first[1], col)
    pos = np.where(z[:, None], first[2], pos)
    max_amp = np.where(z, F32(1.0), max_amp)
    if normalize:
        with np.errstate(divide="ignore", invalid="ignore"):
            dist = dist / (max_amp * max_dist)
            col = col / max_amp[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = np.where(scale[:, None] != 0, pos / scale[:, None], F32(0.0))
    return {"Distance": dist, "Color": col, "Position": pos}


# ---------------------------------------------------------------------------------------------
# Wave (Cycles' wave.h)

def wave_texture(p, wave_type="BANDS", bands_direction="X", rings_direction="X",
                 profile="SIN", distortion=0.0, detail=2.0, detail_scale=1.0,
                 detail_roughness=0.5, phase=0.0):
    """Blender's Wave Texture at (N, 3) points already multiplied by Scale: Fac (N,)."""
    p = np.asarray(p, F32)
    n = p.shape[0]
    p = (p + F32(0.000001)) * F32(0.999999)
    if wave_type == "BANDS":
        if bands_direction == "DIAGONAL":
            w = (p[:, 0] + p[:, 1] + p[:, 2]) * F32(10.0)
        else:
            w = p[:, "XYZ".index(bands_direction)] * F32(20.0)
    else:
        rp = p.copy()
        if rings_direction != "SPHERICAL":
            rp[:, "XYZ".index(rings_direction)] = F32(0.0)
        w = np.sqrt(np.sum(rp * rp, axis=1, dtype=F32)) * F32(20.0)
    w = w + _arr(phase, n)
    dist = _arr(distortion, n)
    if np.any(dist != 0):
        fb = noise_fractal("FBM", p * _arr(detail_scale, n)[:, None], _arr(detail, n),
                           _arr(detail_roughness, n), _arr(2.0, n), normalize=True)
        w = np.where(dist != 0, w + dist * (fb * F32(2.0) - F32(1.0)), w)
    if profile == "SIN":
        return F32(0.5) + F32(0.5) * np.sin(w - F32(np.pi / 2)).astype(F32)
    w = w / F32(2.0 * np.pi)
    if profile == "SAW":
        return w - np.floor(w)
    return np.abs(w - np.floor(w + F32(0.5))) * F32(2.0)
