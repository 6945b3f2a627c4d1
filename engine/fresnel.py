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
BSDF uses it). Thin-film iridescence is not implemented.
"""
from __future__ import annotations

import numpy as np

__all__ = ["dielectric", "conductor", "f82_tint_b", "f82", "f0_from_ior",
           "dielectric_average", "DielectricFresnel", "TintedDielectricFresnel",
           "F82TintFresnel", "ConductorFresnel", "ConstantFresnel", "rgb_per_hit"]

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
