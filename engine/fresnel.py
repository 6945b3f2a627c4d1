"""Fresnel reflectance at a hit, over arrays of hits: dielectric, Cycles' F82-tint metal, the
physical conductor (complex IOR), the Principled BSDF's remapped dielectric and a constant.

What it computes
    ``dielectric(cos_i, eta)`` -> (F, cos_t): the exact unpolarised reflectance of a smooth
        interface (the mean of the s- and p-polarised squared amplitudes), with ``eta`` the
        relative index eta_t / eta_i (the far side over the side the light arrives from;
        ``eta < 1`` when leaving a denser medium) and total internal reflection (F = 1,
        cos_t = 0) where sin^2 theta_t = (1 - cos_i^2) / eta^2 >= 1. cos_t >= 0 is the cosine
        of the refracted ray with the normal, for building the refracted direction.
    ``conductor(cos_i, n, k)``: the exact reflectance of a conductor of complex index
        n + i k (per RGB channel) seen from a medium of index 1, through complex arithmetic
        (Born and Wolf §14.4; the same two amplitudes as the dielectric with a complex eta).
    ``f82_tint_b(f0, tint)`` and ``f82(cos_i, f0, b)``: Cycles' metal (Kutz et al. 2021,
        "Novel aspects of the Adobe Standard Material"): Schlick's curve
        S = F0 + (1 - F0)(1 - mu)^5 less b mu (1 - mu)^6, clipped to [0, 1], with b chosen so
        that at mu = 1/7 (about 82 degrees) the curve is ``tint`` times Schlick's:
        b = S(1/7) (1 - tint) / ((1/7)(6/7)^6).
    ``*.average()``: Fss, the cosine-weighted hemispherical mean 2 int_0^1 F(mu) mu dmu that
        Cycles' multiple-scattering compensation uses (Kulla and Conty 2017, appendix).
        For F82 it is closed: 2 int (1 - mu)^5 mu = 1/21 and 2 int mu^2 (1 - mu)^6 = 1/126, so
        Fss = F0 + (1 - F0)/21 - b/126. For the dielectric it is a 128-point Gauss-Legendre sum
        over mu (split at the critical angle when eta < 1); Cycles uses Kulla and Conty's
        rational fit there (within about 1e-3 of the sum). For the physical conductor it is,
        as in Cycles, the F82 closed form of the F82 curve through F(1) and F(1/7).

Fresnel objects hold per-hit parameters and offer ``reflectance(cos)`` (N, 3) for the cosine of
the view direction with the microfacet normal, ``average()`` (N, 3), ``subset(index)`` and
``table_terms()``: F written as a sum of coefficients times functions whose microfacet albedo
is tabulated (``engine/microfacet.py``): "E" (F = 1), "E5" ((1 - mu)^5), "E6"
(mu (1 - mu)^6) and "R" (the exact dielectric of index eta), so a lobe's directional albedo is a
sum of table look-ups.

Parameters (per hit)
    =================  ==========  =======================================================
    name               unit        meaning
    =================  ==========  =======================================================
    eta                1           relative IOR eta_t / eta_i (Glass/Principled: IOR, or
                                   1 / IOR on a back face, as Cycles flips it)
    f0                 [0, 1] RGB  reflectance at normal incidence (Principled metal: base
                                   colour; Metallic BSDF F82 mode: Base Color)
    tint               [0, 1] RGB  F82 tint (Principled: Specular Tint; default white, b = 0)
    n, k               RGB         complex IOR (Metallic BSDF "Physical Conductor")
    color              RGB         constant F (Glossy BSDF's colour)
    =================  ==========  =======================================================

Where Cycles is followed (``intern/cycles/kernel/closure/bsdf_util.h``, ``bsdf_microfacet.h``
``microfacet_fresnel``): the F82-tint curve and its b, the clip of F82 to [0, 1], Fss of the
physical conductor through its F82 fit, and the Principled/Glass "generalized Schlick" remap
F = mix(f0, 1, s) with s = (F_real - F0_real) / (1 - F0_real) clipped to [0, 1]
(``TintedDielectricFresnel``; with f0 = F0_real it is the real Fresnel, which is how the Glass
BSDF uses it).

Thin film (``iridescence``; Belcour and Barla 2017, "A Practical Extension to Microfacet
Theory for the Modeling of Varying Iridescence"): a film of index ``film_ior`` and thickness
[nm] over the dielectric or conductor; the Airy summation of the reflected orders m <= 3 with
per-order phase (optical path difference 2 n_film d cos_t plus the interfaces' phase shifts),
integrated against the linear Rec.709 colour matching functions in Fourier space
(``tools/thin_film_table.py`` -> ``engine/data/thin_film_table.npz``), per channel, the two
polarisations averaged, as Cycles does (``bsdf_util.h`` ``fresnel_iridescence_channel``). The
F82 metal becomes the conductor of Gulbrandsen's (r, g) mapping; the multiple-scattering Fss
stays the film-free one. The film Fresnels have no ``table_terms`` (their albedo is integrated
numerically by the lobe) and ``smooth_estimate``: a layer's share of the light below it is read,
as Cycles reads it, from F(mu_o) of the smooth surface.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["dielectric", "conductor", "f82_tint_b", "f82", "f0_from_ior",
           "dielectric_average", "DielectricFresnel", "TintedDielectricFresnel",
           "F82TintFresnel", "ConductorFresnel", "ConstantFresnel", "rgb_per_hit",
           "iridescence", "gulbrandsen_nk", "thin_film_table", "ThinFilmDielectricFresnel",
           "ThinFilmF82Fresnel", "ThinFilmConductorFresnel", "THIN_FILM_CUTOFF"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(128)


def dielectric(cos_i, eta):
    """(F, cos_t) of a smooth dielectric interface for |cos_i| and relative index ``eta``
    (arrays broadcast together); F = 1 and cos_t = 0 under total internal reflection."""
    c = np.minimum(np.abs(cos_i), 1.0)
    eta = np.asarray(eta, dtype=float)
    sin_t2 = (1.0 - c * c) / (eta * eta)
    tir = sin_t2 >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r_s = (c - eta * cos_t) / (c + eta * cos_t)
        r_p = (eta * c - cos_t) / (eta * c + cos_t)
        F = 0.5 * (r_s * r_s + r_p * r_p)
    F = np.where(tir, 1.0, np.nan_to_num(F, nan=1.0))
    return np.clip(F, 0.0, 1.0), np.where(tir, 0.0, cos_t)


def f0_from_ior(eta):
    """Reflectance at normal incidence ((eta - 1) / (eta + 1))^2."""
    eta = np.asarray(eta, dtype=float)
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def conductor(cos_i, n, k):
    """Exact conductor reflectance (N, 3) for cosines (N,) and complex IOR n + i k (N, 3)."""
    c = np.minimum(np.abs(np.asarray(cos_i, dtype=float)), 1.0)[..., None]
    eta = np.asarray(n, dtype=float) + 1j * np.asarray(k, dtype=float)
    cos_t = np.sqrt(1.0 - (1.0 - c * c) / (eta * eta))
    with np.errstate(invalid="ignore", divide="ignore"):
        r_s = (c - eta * cos_t) / (c + eta * cos_t)
        r_p = (eta * c - cos_t) / (eta * c + cos_t)
        F = 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)
    return np.clip(np.nan_to_num(F, nan=1.0), 0.0, 1.0)


def f82_tint_b(f0, tint):
    """b of the F82-tint curve: F(1/7) = tint * Schlick(1/7)."""
    s = 6.0 / 7.0
    schlick = f0 + (1.0 - f0) * s ** 5
    return schlick * (1.0 - tint) * 7.0 / s ** 6


def f82_b_from_value(f0, f82_value):
    """b of the F82 curve through a given value at mu = 1/7."""
    s = 6.0 / 7.0
    return (f0 + (1.0 - f0) * s ** 5 - f82_value) * 7.0 / s ** 6


def f82(cos_i, f0, b):
    """The F82 curve (N, 3) at cosines (N,), clipped to [0, 1]."""
    mu = np.clip(np.asarray(cos_i, dtype=float), 0.0, 1.0)[..., None]
    m = 1.0 - mu
    m5 = m ** 5
    return np.clip(f0 + (1.0 - f0) * m5 - b * mu * m5 * m, 0.0, 1.0)


def _dielectric_average_unique(eta: float) -> float:
    """2 int_0^1 F(mu) mu dmu, split at the critical cosine where eta < 1."""
    edges = [0.0, 1.0]
    if eta < 1.0:
        edges = [0.0, np.sqrt(1.0 - eta * eta), 1.0]
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        mu = 0.5 * (b - a) * _GL_X + 0.5 * (a + b)
        total += 0.5 * (b - a) * np.sum(_GL_W * 2.0 * mu * dielectric(mu, eta)[0])
    return float(total)


def dielectric_average(eta):
    """Fss of the exact dielectric per hit (N,), computed once per distinct eta."""
    eta = np.asarray(eta, dtype=float)
    values, inverse = np.unique(eta, return_inverse=True)
    return np.array([_dielectric_average_unique(v) for v in values])[inverse].reshape(eta.shape)


def rgb_per_hit(x, count):
    """(count, 3) from a scalar, one RGB colour (3,), a per-hit (count,) array (count != 3)
    or a (count, 3) array."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 0:
        return np.full((count, 3), float(x))
    if x.shape == (3,):
        return np.broadcast_to(x, (count, 3)).copy()
    if x.ndim == 1:
        return np.repeat(x[:, None], 3, axis=1)
    return x


class DielectricFresnel:
    """The exact dielectric of relative index ``eta`` (N,)."""

    def __init__(self, eta):
        self.eta = np.asarray(eta, dtype=float)

    def subset(self, index):
        return DielectricFresnel(self.eta[index])

    def reflectance(self, cos_i):
        return np.repeat(dielectric(cos_i, self.eta)[0][:, None], 3, axis=1)

    def average(self):
        return np.repeat(dielectric_average(self.eta)[:, None], 3, axis=1)

    def table_terms(self):
        return [(np.ones((len(self.eta), 3)), "R", self.eta)]


class TintedDielectricFresnel:
    """Cycles' Principled/Glass dielectric: F = mix(f0, 1, s), s = (F_real - F0_real) /
    (1 - F0_real) clipped to [0, 1], with F_real the exact dielectric of ``eta`` and f0
    (N, 3) = F0(IOR) x Specular Tint (x 2 Specular IOR Level where it is not 0.5)."""

    def __init__(self, eta, f0):
        self.eta = np.asarray(eta, dtype=float)
        self.f0 = rgb_per_hit(f0, len(self.eta))

    def subset(self, index):
        return TintedDielectricFresnel(self.eta[index], self.f0[index])

    def _s(self, F_real):
        F0 = f0_from_ior(self.eta)
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(F0 < 1.0, (F_real - F0) / (1.0 - F0), 1.0)
        return np.clip(s, 0.0, 1.0)

    def reflectance(self, cos_i):
        s = self._s(dielectric(cos_i, self.eta)[0])[:, None]
        return self.f0 + (1.0 - self.f0) * s

    def average(self):
        s = self._s(dielectric_average(self.eta))[:, None]
        return self.f0 + (1.0 - self.f0) * s

    def table_terms(self):
        # F = f0 + (1 - f0)(F_real - F0) / (1 - F0) (the clip is inactive: F_real >= F0).
        F0 = f0_from_ior(self.eta)[:, None]
        scale = (1.0 - self.f0) / np.maximum(1.0 - F0, 1e-12)
        return [(self.f0 - scale * F0, "E", None), (scale, "R", self.eta)]


class F82TintFresnel:
    """Cycles' metal: F0 = base colour (N, 3), F82 tint = Specular Tint (N, 3)."""

    def __init__(self, f0, tint=1.0):
        self.f0 = np.clip(np.asarray(f0, dtype=float), 0.0, 1.0)
        tint = np.clip(np.broadcast_to(np.asarray(tint, dtype=float), self.f0.shape), 0.0, 1.0)
        self.tint = tint
        self.b = f82_tint_b(self.f0, tint)

    def subset(self, index):
        return F82TintFresnel(self.f0[index], self.tint[index])

    def reflectance(self, cos_i):
        return f82(cos_i, self.f0, self.b)

    def average(self):
        return self.f0 + (1.0 - self.f0) / 21.0 - self.b / 126.0

    def table_terms(self):
        return [(self.f0, "E", None), (1.0 - self.f0, "E5", None), (-self.b, "E6", None)]


class ConductorFresnel:
    """The physical conductor: complex IOR n + i k per channel (N, 3)."""

    def __init__(self, n, k):
        self.n = np.maximum(np.asarray(n, dtype=float), 0.0)
        self.k = np.maximum(np.asarray(k, dtype=float), 0.0)

    def subset(self, index):
        return ConductorFresnel(self.n[index], self.k[index])

    def reflectance(self, cos_i):
        return conductor(cos_i, self.n, self.k)

    def _f82_fit(self):
        count = len(self.n)
        f0 = conductor(np.ones(count), self.n, self.k)
        b = f82_b_from_value(f0, conductor(np.full(count, 1.0 / 7.0), self.n, self.k))
        return f0, b

    def average(self):
        f0, b = self._f82_fit()
        return np.clip(f0 + (1.0 - f0) / 21.0 - b / 126.0, 0.0, 1.0)

    def table_terms(self):
        # The albedo through the F82 curve fitted at 0 and 82 degrees (as Cycles does for Fss).
        f0, b = self._f82_fit()
        return [(f0, "E", None), (1.0 - f0, "E5", None), (-b, "E6", None)]


class ConstantFresnel:
    """F = ``color`` (N, 3) at every angle (the Glossy BSDF: its colour is the closure weight,
    Fresnel "none")."""

    def __init__(self, color):
        self.color = np.asarray(color, dtype=float)

    def subset(self, index):
        return ConstantFresnel(self.color[index])

    def reflectance(self, cos_i):
        return self.color

    def average(self):
        return self.color

    def table_terms(self):
        return [(self.color, "E", None)]


# -- Thin-film iridescence (Belcour and Barla 2017) -----------------------------------------------
THIN_FILM_TABLE = Path(__file__).resolve().parent / "data" / "thin_film_table.npz"
THIN_FILM_CUTOFF = 0.1          # nm: thinner films are off (Cycles' THINFILM_THICKNESS_CUTOFF)


@lru_cache(maxsize=1)
def thin_film_table():
    """(re, im) (3, 512): the Rec.709 sensitivities S_c(OPD) (``tools/thin_film_table.py``)."""
    with np.load(THIN_FILM_TABLE, allow_pickle=False) as data:
        return data["re"].astype(np.float64), data["im"].astype(np.float64)


def _sensitivity(opd):
    """S_c at optical path differences ``opd`` [nm] (N,) -> (re, im) (N, 3): the table read at
    x = 2 pi OPD / 60000 by node-centred linear interpolation, clamped to its last node."""
    re, im = thin_film_table()
    size = re.shape[1]
    f = np.clip(2.0 * np.pi * np.asarray(opd, float) / 60000.0, 0.0, 1.0) * (size - 1)
    i = np.minimum(f.astype(int), size - 2)
    t = (f - i)[:, None]
    return ((1 - t) * re[:, i].T + t * re[:, i + 1].T, (1 - t) * im[:, i].T + t * im[:, i + 1].T)


def _polarized_dielectric(cos_i, eta):
    """(R_s, R_p, cos_t, sign_s, sign_p, tir) of a smooth dielectric of relative index ``eta``
    for cosines ``cos_i`` (sign ignored); cos_t <= 0 (the refracted ray, against the normal),
    sign_* the sign of the reflected amplitude (the cosine of its phase shift)."""
    c = np.minimum(np.abs(cos_i), 1.0)
    eta = np.asarray(eta, float)
    squared = eta * eta - (1.0 - c * c)
    tir = squared <= 0.0
    cos_t = -np.sqrt(np.maximum(squared, 0.0)) / eta
    with np.errstate(divide="ignore", invalid="ignore"):
        r_s = (c + eta * cos_t) / (c - eta * cos_t)
        r_p = (cos_t + eta * c) / (eta * c - cos_t)
    r_s = np.where(tir, 1.0, np.nan_to_num(r_s, nan=1.0))
    r_p = np.where(tir, 1.0, np.nan_to_num(r_p, nan=1.0))
    return (r_s * r_s, r_p * r_p, cos_t, np.where(r_s >= 0, 1.0, -1.0),
            np.where(r_p >= 0, 1.0, -1.0), tir)


def _polarized_conductor(cos_i, eta1, n, k, f82_value=None):
    """(R_s, R_p, phasor_s, phasor_p) of a conductor n + i k seen from a medium of index
    ``eta1`` (complex unit phasors of the reflected amplitudes); with ``f82_value`` both
    reflectances follow the F82 curve through it at the rescaled F0 instead."""
    c = np.abs(cos_i)
    e1 = eta1
    t1 = n * n - k * k - e1 * e1 * (1.0 - c * c)
    t2 = np.sqrt(t1 * t1 + (2.0 * n * k) ** 2)
    u2 = np.maximum(0.5 * (t2 + t1), 0.0)
    v2 = np.maximum(0.5 * (t2 - t1), 0.0)
    u, v = np.sqrt(u2), np.sqrt(v2)
    with np.errstate(divide="ignore", invalid="ignore"):
        if f82_value is not None:
            nn, kk2 = n / e1, (k / e1) ** 2
            f0 = ((nn - 1.0) ** 2 + kk2) / ((nn + 1.0) ** 2 + kk2)
            s = 1.0 - np.clip(c, 0.0, 1.0)
            s5 = s ** 5
            b = f82_b_from_value(f0, f82_value)
            R_s = np.clip(f0 + (1.0 - f0) * s5 - b * c * s5 * s, 0.0, 1.0)
            R_p = R_s
        else:
            R_s = np.nan_to_num(((e1 * c - u) ** 2 + v2) / ((e1 * c + u) ** 2 + v2))
            t3 = (n * n - k * k) * c
            t4 = 2.0 * n * k * c
            R_p = np.nan_to_num(((t3 - e1 * u) ** 2 + (t4 - e1 * v) ** 2)
                                / ((t3 + e1 * u) ** 2 + (t4 + e1 * v) ** 2))
        phasor_s = (-u2 - v2 + (e1 * c) ** 2) + 1j * (-2.0 * e1 * c * v)
        phasor_p = (((n * n + k * k) * c) ** 2 - e1 * e1 * (u2 + v2)) + \
            1j * (2.0 * e1 * c * (2.0 * n * k * u - (n * n - k * k) * v))
    phasor_s = np.where(np.abs(phasor_s) > 0, phasor_s / np.abs(phasor_s), 1.0)
    phasor_p = np.where(np.abs(phasor_p) > 0, phasor_p / np.abs(phasor_p), 1.0)
    return R_s, R_p, phasor_s, phasor_p


def _airy(R12, R23, opd, phasor):
    """Belcour and Barla's Eq. 10 truncated after m = 3 (as Cycles): (N, 3)."""
    T121 = 1.0 - R12
    R123 = R12 * R23
    r123 = np.sqrt(R123)
    with np.errstate(divide="ignore", invalid="ignore"):
        Rs = np.nan_to_num(T121 * T121 * R23 / (1.0 - R123))
    R = Rs + R12
    Cm = Rs - T121
    acc = phasor * np.ones_like(R)
    for m in range(1, 4):
        Cm = Cm * r123
        s_re, s_im = _sensitivity(m * opd)
        R = R + Cm * 2.0 * (acc.real * s_re + acc.imag * s_im)
        acc = acc * phasor
    return R


def iridescence(cos_i, film_ior, thickness, n, k=None, f82_value=None):
    """Thin-film reflectance (N, 3) seen from air (index 1) at cosines ``cos_i`` (N,): a film
    of ``film_ior`` (N,) and ``thickness`` [nm] (N,) over a dielectric of index ``n`` (N,) or,
    with ``k`` (N, 3), a conductor n + i k ((N, 3); ``f82_value`` (N, 3) makes its
    reflectance the F82 curve's). Cycles' ``fresnel_iridescence_channel``: films under 1 nm
    blend their index towards air's; TIR at either interface gives 1; the Airy sum over
    m <= 3 with the channel sensitivities, the polarisations averaged, clipped to [0, 1]."""
    cos_i = np.asarray(cos_i, float)
    thickness = np.asarray(thickness, float)
    film = np.asarray(film_ior, float)
    t = np.clip(thickness, 0.0, 1.0)
    film = np.where(thickness < 1.0, 1.0 + (film - 1.0) * t * t * (3.0 - 2.0 * t), film)
    R12s, R12p, cos2, sign12s, sign12p, tir = _polarized_dielectric(cos_i, film)
    cos2_, film_, thick_ = cos2[:, None], film[:, None], thickness[:, None]
    if k is None:
        R23s, R23p, _, sign23s, sign23p, tir23 = _polarized_dielectric(
            -cos2, np.asarray(n, float) / film)
        tir = tir | tir23
        R23s, R23p = R23s[:, None], R23p[:, None]
        phasor23s, phasor23p = sign23s[:, None], sign23p[:, None]
    else:
        R23s, R23p, phasor23s, phasor23p = _polarized_conductor(-cos2_, film_, n, k, f82_value)
    opd = (-2.0 * film_ * thick_ * cos2_)[:, 0]
    R_s = _airy(R12s[:, None], R23s, opd, phasor23s * -sign12s[:, None])
    R_p = _airy(R12p[:, None], R23p, opd, phasor23p * -sign12p[:, None])
    R = np.clip(0.5 * (R_s + R_p), 0.0, 1.0)
    return np.where(tir[:, None], 1.0, R)


def gulbrandsen_nk(f0, f82_value):
    """(n, k) (N, 3) of Gulbrandsen's "Artist Friendly Metallic Fresnel" read with r = F0
    (capped at 0.999) and g = the F82 curve's value at 82 degrees, as Cycles maps its F82 metal
    to a conductor under a film."""
    r = np.minimum(f0, 0.999)
    root = np.sqrt(r)
    n = (1.0 + root) / (1.0 - root) * (1.0 - f82_value) + (1.0 - r) / (1.0 + r) * f82_value
    k = np.sqrt(np.maximum((r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r), 0.0))
    return n, k


class ThinFilmDielectricFresnel(TintedDielectricFresnel):
    """The Principled/Glass dielectric under a thin film: the film's reflectance over the
    substrate of index ``eta`` (``iridescence``), then scaled per channel towards f0 / F0_real
    by s = clip((F - 1) / (F0_real - 1)) (Cycles' artistic F0 control under a film). The
    multiple-scattering Fss is the film-free one (``average``), as in Cycles. ``film_ior`` is
    the film's index relative to the outside (a back face divides it by the bulk index)."""

    smooth_estimate = True

    def __init__(self, eta, f0, thickness, film_ior):
        super().__init__(eta, f0)
        count = len(self.eta)
        self.thickness = np.broadcast_to(np.asarray(thickness, float), (count,)).copy()
        self.film_ior = np.broadcast_to(np.asarray(film_ior, float), (count,)).copy()

    def subset(self, index):
        return ThinFilmDielectricFresnel(self.eta[index], self.f0[index], self.thickness[index],
                                         self.film_ior[index])

    def key(self, i):
        """The parameters of hit ``i`` (a cache key for the integrated albedo)."""
        return ("dielectric", float(self.eta[i]), *self.f0[i].tolist(),
                float(self.thickness[i]), float(self.film_ior[i]))

    def reflectance(self, cos_i):
        F = iridescence(cos_i, self.film_ior, self.thickness, self.eta)
        F0 = f0_from_ior(self.eta)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.clip((F - 1.0) / (F0 - 1.0), 0.0, 1.0)
            factor = self.f0 / F0
        scaled = F * (1.0 + (factor - 1.0) * s)
        keep = (F0 <= 1e-5) | np.all(F == 1.0, axis=1, keepdims=True)
        return np.where(keep, F, np.nan_to_num(scaled))

    def table_terms(self):
        return None


class ThinFilmF82Fresnel(F82TintFresnel):
    """Cycles' F82-tint metal under a thin film: the conductor of ``gulbrandsen_nk`` (F0, the
    F82 value), its reflectance the F82 curve's, under the film (``iridescence``)."""

    smooth_estimate = True

    def __init__(self, f0, tint, thickness, film_ior):
        super().__init__(f0, tint)
        count = len(self.f0)
        self.thickness = np.broadcast_to(np.asarray(thickness, float), (count,)).copy()
        self.film_ior = np.broadcast_to(np.asarray(film_ior, float), (count,)).copy()

    def subset(self, index):
        return ThinFilmF82Fresnel(self.f0[index], self.tint[index], self.thickness[index],
                                  self.film_ior[index])

    def key(self, i):
        return ("f82", *self.f0[i].tolist(), *self.tint[i].tolist(), float(self.thickness[i]),
                float(self.film_ior[i]))

    def reflectance(self, cos_i):
        g = f82(np.full(len(self.f0), 1.0 / 7.0), self.f0, self.b)
        n, k = gulbrandsen_nk(self.f0, g)
        return iridescence(cos_i, self.film_ior, self.thickness, n, k, g)

    def table_terms(self):
        return None


class ThinFilmConductorFresnel(ConductorFresnel):
    """The physical conductor n + i k under a thin film (``iridescence``, exact polarised
    conductor reflectances); Fss film-free through the F82 fit, as ``ConductorFresnel``."""

    smooth_estimate = True

    def __init__(self, n, k, thickness, film_ior):
        super().__init__(n, k)
        count = len(self.n)
        self.thickness = np.broadcast_to(np.asarray(thickness, float), (count,)).copy()
        self.film_ior = np.broadcast_to(np.asarray(film_ior, float), (count,)).copy()

    def subset(self, index):
        return ThinFilmConductorFresnel(self.n[index], self.k[index], self.thickness[index],
                                        self.film_ior[index])

    def key(self, i):
        return ("conductor", *self.n[i].tolist(), *self.k[i].tolist(),
                float(self.thickness[i]), float(self.film_ior[i]))

    def reflectance(self, cos_i):
        return iridescence(cos_i, self.film_ior, self.thickness, self.n, self.k)

    def table_terms(self):
        return None
