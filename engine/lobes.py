"""Blender's surface lobes as Cycles builds them, over arrays of hits: GGX reflection with a
Fresnel, rough and smooth dielectric glass, smooth reflection, Oren-Nayar (Fujii's model with
the energy-preserving multiple-scattering term), translucent and transparent.

Every lobe has the interface of ``engine/bsdf.py`` (pbrt's f / Sample_f / PDF):

    ``evaluate(wo, wi, n)``  f [1/sr] (N, 3)
    ``sample(wo, n, u)``     (wi, weight = f |cos| / pdf (N, 3), pdf [1/sr] (N,)); ``u`` (N, 2),
                             or (N, 3) for the glass lobes (the third number picks reflection or
                             refraction). Directions sampled on the wrong side come back with
                             weight 0 and pdf 0; delta lobes return pdf = inf.
    ``pdf(wo, wi, n)``       the density of ``sample`` [1/sr] (N,); 0 for delta lobes
    ``albedo(wo, n)``        the directional albedo (N, 3): int f |cos| dwi (from the tables of
                             ``engine/microfacet.py`` where it has no closed form; within
                             about 1 % of the sampled mean for isotropic lobes, up to 7 % off
                             at grazing views (mu < 0.05) of near-mirrors with eta < 1, where
                             the tables' linear interpolation meets a kink; for anisotropic
                             GGX it is Cycles' isotropic stand-in at (alpha_x alpha_y)^(1/4),
                             up to 20 % off for a 3:1 aspect)
    ``albedo_split(wo, n)``  glass lobes only: ``albedo``'s (reflected, transmitted) branches
    ``layer_albedo(wo, n)``  reflection lobes: what the lobe takes from the light below it as a
                             layer (``albedo``; for a thin-film Fresnel Cycles' estimate from
                             the smooth F(mu_o)). A Fresnel without tables (thin film) has its
                             albedo integrated over visible normals on a 32-cosine grid, cached
                             per distinct lobe.
    ``subset(index)``        the lobe at the hits ``index``

Directions are unit (N, 3) arrays pointing away from the surface (wo to the viewer, wi to the
light); ``n`` is the shading normal on wo's side. Cycles' "wi" (towards the viewer) is our wo.

Lobes and the papers they follow
    ``MicrofacetReflection``  f = F(wo.h) D(h) G2(wo, wi) / (4 |wo.n| |wi.n|), h = (wo + wi)/|.|
        (Walter et al. 2007 Eq. 20; anisotropic GGX, Heitz 2014), sampled by visible normals
        (Heitz 2018): weight F G2 / G1(wo), pdf G1(wo) D / (4 wo.n).
    ``MicrofacetGlass``  adds refraction (Walter et al. 2007 Eq. 21 with Cycles' half vector
        h = -(wo + eta wi)/|.|): f_t = (1 - F) D G2 |wo.h| |wi.h| eta^2 / (|wo + eta wi|^2
        |wo.n| |wi.n|); reflection is picked with probability P = <F R> / <F R + (1 - F) T>
        (channel means; R, T the tints), which is F for untinted glass, as Cycles does.
    ``SmoothGlass``, ``SmoothReflection``  the delta limits: weight R F / P, T (1 - F) / (1 - P),
        and F(wo.n) x colour.
    ``OrenNayar``  Cycles' ``bsdf_oren_nayar.h``: Fujii's "improved Oren-Nayar" (FON,
        mimosa-pudica.net/improved-oren-nayar.html) A = 1 / (pi + sigma (pi/2 - 2/3)),
        B = sigma A, f_ss = rho (A + B s / max(mu_o, mu_i)) where s = wo.wi - mu_o mu_i > 0
        (else rho (A + B s)), whose albedo is E(mu) = pi A + B G(mu) in closed form, plus the
        multiple-scattering term of the energy-preserving Oren-Nayar (EON, Portsmouth, Kutz
        and Hill 2025, JCGT 14(1); OpenPBR) f_ms = rho E_ms (1 - E(mu_o))(1 - E(mu_i)) with
        E_ms = rho'^2 Eavg / (pi (1 - Eavg)(1 - rho' (1 - Eavg))), rho' = clip(rho, 0, 1),
        and Cycles' Eavg = pi A + B (2 pi - 5.6)/3 (the exact mean of E: 2 int G mu dmu =
        (2 pi - 5.6)/3 to 1e-10 by quadrature, so the white furnace is 1). Note the leading rho: Cycles multiplies
        the whole closure (the multiple-scattering term included) by the colour, so its
        f_ms carries rho^3 where the EON paper has rho^2; we follow Cycles. Cosine sampling.
    ``Sheen``  Cycles' microfibre sheen (Zeltner, Burley and Chiang 2022, "Practical
        Multiple-Scattering Sheen Using Linearly Transformed Cosines"): f cos = A D(wi), D a
        linearly transformed cosine of (a, b) in the frame of wo, A the albedo, read from our
        32 x 32 table over (mu_o, roughness) (``tools/sheen_ltc_table.py``: measured from
        Cycles' renders and fitted by moments). Sampled exactly (weight A). Like Cycles' it is
        not reciprocal (the transform follows wo).
    ``Translucent``  colour / pi on the side opposite wo; cosine sampling about -n.
    ``Transparent``  a delta pass-through: wi = -wo, weight = colour.

Cycles' conventions kept here (``intern/cycles/kernel/closure/bsdf_microfacet.h``)
    * Roughness: alpha = roughness^2, Cycles' anisotropic mappings (``microfacet.alpha_*``);
      glass is isotropic (Cycles supports no anisotropic transmission).
    * Masking-shadowing: height-correlated G2 = 1 / (1 + L(wo) + L(wi)) for reflection and
      refraction alike.
    * Radiance across a refracting interface is NOT scaled by 1/eta^2: the refraction weight
      is (1 - F) G2/G1 / (1 - P) with no index factor (smooth glass: (1 - F)/(1 - P)), in
      camera paths and light paths alike. The eta^2 of f_t is the Jacobian of the half vector,
      so f_t(wo, wi) / eta(wi side)^2 = f_t(wi, wo) / eta(wo side)^2 (generalised
      reciprocity, Veach 1997 §5.2), not f_t(wo, wi) = f_t(wi, wo). Physically, flux crosses
      an interface unscaled and radiance gains eta^2 inside the denser medium; Cycles
      transports the unscaled quantity, which is the same once a path has left the medium
      again, and differs only for a camera or an emitter inside a medium. A photon tracer
      that wants Cycles' brightness therefore uses the same ``sample`` with the photon's
      reversed direction as wo: its weight is the share of flux carried on.
    * Near-deltas: an index within 1e-4 of 1 refracts straight through (pdf inf), as Cycles
      treats it; widths are kept >= 1e-4 in the formulas. Cycles (to 5.1) switches a
      microfacet closure to a delta below alpha_x alpha_y = 2e-10; the caller picks
      ``SmoothReflection`` / ``SmoothGlass`` there.
    * Where the refraction half vector gives a pair no microfacet can connect (wo.h and wi.h
      not on opposite sides of h), f_t and pdf are 0. Cycles evaluates such pairs without
      that check (a TODO in its ``bsdf_microfacet_eval``), which only matters for light
      samples through rough glass; sampling never produces them.
    * Multiple scattering ("Multiscatter GGX", the Principled BSDF's default), Cycles'
      ``microfacet_ggx_preserve_energy``: with E(mu_o) the single-scattering albedo for F = 1
      (reflection: table E; glass: table G with the index), Eavg its cosine-weighted mean and
      Fss the Fresnel's mean (``fresnel.*.average()``; Cycles uses the transmission tint for
      glass), f and the weight are multiplied by 1 + Fms (1 - E) / E with
      Fms = Fss Eavg / (1 - Fss (1 - Eavg)) (Kulla and Conty 2017), per channel. The factor
      depends on wo alone (set up from the view direction), so the compensated lobe is not
      reciprocal; at F = 1 its albedo is 1 up to the tables' interpolation. Anisotropic GGX
      reads the tables at (alpha_x alpha_y)^(1/4) as Cycles does, which restores only part
      of the missing energy (0.78-1.0 at roughness 0.7, anisotropy 0.8). Glass whose
      Fresnel is raised above the real one (Principled f0 > F0(IOR), Specular Tint or IOR
      Level above 1) can exceed 1 at grazing views under this formula, as in Cycles.

Parameters (per hit; (N,) unless RGB (N, 3))
    ==================  ========  =================================================  =========
    name                unit      meaning                                            default
    ==================  ========  =================================================  =========
    alpha_x, alpha_y    1         GGX widths (``microfacet.alpha_principled``)       -
    tangent             unit      direction of alpha_x (N, 3)                        None (iso)
    fresnel             object    ``engine/fresnel.py`` (reflection lobes)           -
    multiscatter        bool      Cycles' Multiscatter GGX compensation              False
    alpha               1         glass width (isotropic)                            -
    eta                 1         relative IOR eta(wi side) / eta(wo side)            -
    reflection_tint     RGB       glass reflection colour                            1
    transmission_tint   RGB       glass transmission colour                          1
    f0                  RGB       Principled remap of the glass Fresnel (see         None
                                  ``fresnel.TintedDielectricFresnel``)
    albedo (rho)        RGB       Oren-Nayar colour                                  -
    sigma               [0, 1]    Oren-Nayar roughness (Diffuse Roughness)           -
    roughness (sheen)   [0, 1]    sheen roughness (clamped to >= 1e-3, as Cycles)    -
    color               RGB       translucent / transparent / mirror colour          -
    ==================  ========  =================================================  =========
"""
from __future__ import annotations

import numpy as np

from functools import lru_cache
from pathlib import Path

from . import fresnel as fresnel_module
from . import microfacet as mf
from . import sampling

__all__ = ["MicrofacetReflection", "MicrofacetGlass", "SmoothGlass", "SmoothReflection",
           "OrenNayar", "Translucent", "Transparent", "Sheen", "sheen_table", "compensation"]


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _unit(v):
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(length > 0, length, 1.0)


def _per_hit(x, count, dtype=float):
    return np.broadcast_to(np.asarray(x, dtype=dtype), (count,)).copy()


def compensation(E, E_avg, F_avg):
    """Cycles' multiple-scattering factor 1 + Fms (1 - E) / E (N, 3), Fms = Fss Eavg /
    (1 - Fss (1 - Eavg)), from E (N,), Eavg (N,) and Fss (N, 3)."""
    E = np.maximum(E, 1e-4)[:, None]
    E_avg = E_avg[:, None]
    F_ms = F_avg * E_avg / (1.0 - F_avg * (1.0 - E_avg))
    return 1.0 + F_ms * (1.0 - E) / E


# -- GGX reflection --------------------------------------------------------------------------------
class MicrofacetReflection:
    """GGX reflection with a Fresnel object (``engine/fresnel.py``), isotropic or anisotropic."""

    def __init__(self, alpha_x, alpha_y, fresnel, tangent=None, multiscatter=False):
        self.alpha_x = np.asarray(alpha_x, dtype=float)
        count = len(self.alpha_x)
        self.alpha_y = _per_hit(alpha_y, count)
        self.fresnel = fresnel
        self.tangent = None if tangent is None else np.asarray(tangent, dtype=float)
        self.multiscatter = _per_hit(multiscatter, count, bool)

    def subset(self, index):
        return MicrofacetReflection(self.alpha_x[index], self.alpha_y[index],
                                    self.fresnel.subset(index),
                                    None if self.tangent is None else self.tangent[index],
                                    self.multiscatter[index])

    def _local(self, n, *vectors):
        t, b = mf.frame(n, self.tangent)
        return [mf.to_local(v, t, b, n) for v in vectors] + [(t, b)]

    def _scale(self, mu_o):
        """The multiple-scattering factor (N, 3) at the view cosines mu_o."""
        out = np.ones((len(mu_o), 3))
        m = self.multiscatter
        if m.any():
            r = mf.table_roughness(self.alpha_x[m], self.alpha_y[m])
            E = mf.table("E", r, np.clip(mu_o[m], 0.0, 1.0))
            E_avg = mf.table("Eavg", r)
            out[m] = compensation(E, E_avg, self.fresnel.subset(m).average())
        return out

    def evaluate(self, wo, wi, n):
        lo, li, _ = self._local(n, wo, wi)
        valid = (lo[:, 2] > 0) & (li[:, 2] > 0)
        h = _unit(lo + li)
        with np.errstate(divide="ignore", invalid="ignore"):
            value = mf.ggx_d(h, self.alpha_x, self.alpha_y) * \
                mf.g2(lo, li, self.alpha_x, self.alpha_y) / (4.0 * lo[:, 2] * li[:, 2])
        value = np.where(valid, value, 0.0)
        F = self.fresnel.reflectance(np.clip(_dot(lo, h), 0.0, 1.0))
        return F * value[:, None] * self._scale(lo[:, 2])

    def pdf(self, wo, wi, n):
        lo, li, _ = self._local(n, wo, wi)
        valid = (lo[:, 2] > 0) & (li[:, 2] > 0)
        h = _unit(lo + li)
        with np.errstate(divide="ignore", invalid="ignore"):
            p = mf.g1(lo, self.alpha_x, self.alpha_y) * \
                mf.ggx_d(h, self.alpha_x, self.alpha_y) / (4.0 * lo[:, 2])
        return np.where(valid, p, 0.0)

    def sample(self, wo, n, u):
        lo, (t, b) = self._local(n, wo)
        above = lo[:, 2] > 0
        v = np.where(above[:, None], lo, [[0.0, 0.0, 1.0]])
        h = mf.sample_vndf(v, self.alpha_x, self.alpha_y, u[:, :2])
        c = _dot(v, h)
        li = 2.0 * c[:, None] * h - v
        valid = above & (li[:, 2] > 0)
        lam_o = mf.ggx_lambda(v, self.alpha_x, self.alpha_y)
        lam_i = mf.ggx_lambda(li, self.alpha_x, self.alpha_y)
        ratio = np.where(valid, (1.0 + lam_o) / (1.0 + lam_o + lam_i), 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = mf.ggx_d(h, self.alpha_x, self.alpha_y) / ((1.0 + lam_o) * 4.0 * v[:, 2])
        pdf = np.where(valid, pdf, 0.0)
        weight = self.fresnel.reflectance(np.clip(c, 0.0, 1.0)) * ratio[:, None] * \
            self._scale(lo[:, 2])
        return mf.from_local(li, t, b, n), weight, pdf

    def layer_albedo(self, wo, n):
        """What a layer of this lobe takes from the light below it (Cycles' albedo estimate):
        ``albedo``, but F(mu_o) of the smooth surface times Cycles' multiple-scattering
        darkening (1 + Fms (1 - E)/E) / (1 + (1 - E)/E) for a thin-film Fresnel, whose
        microfacet albedo Cycles does not tabulate."""
        if not getattr(self.fresnel, "smooth_estimate", False):
            return self.albedo(wo, n)
        mu = np.clip(_dot(wo, n), 0.0, 1.0)
        F = self.fresnel.reflectance(mu)
        scale = np.ones_like(F)
        m = self.multiscatter
        if m.any():
            r = mf.table_roughness(self.alpha_x[m], self.alpha_y[m])
            E = np.maximum(mf.table("E", r, mu[m]), 1e-4)[:, None]
            full = compensation(E[:, 0], mf.table("Eavg", r), self.fresnel.subset(m).average())
            scale[m] = full / (1.0 + (1.0 - E) / E)
        return F * scale * (mu > 0)[:, None]

    def _integrated_albedo(self, mu):
        """int F G2/G1 over visible normals (N, 3) for Fresnels without tables: on a grid of
        32 view cosines by 32 x 32 stratified normals per distinct lobe (cached), read back by
        linear interpolation in mu."""
        out = np.zeros((len(mu), 3))
        keys = [(float(ax), float(ay), self.fresnel.key(i))
                for i, (ax, ay) in enumerate(zip(self.alpha_x, self.alpha_y))]
        for key in set(keys):
            hits = np.array([k == key for k in keys])
            grid = _ALBEDO_CACHE.get(key)
            if grid is None:
                first = int(np.flatnonzero(hits)[0])
                grid = _integrate_albedo(key[0], key[1], self.fresnel.subset([first]))
                _ALBEDO_CACHE[key] = grid
            nodes = np.linspace(0.0, 1.0, len(grid))
            out[hits] = np.stack([np.interp(mu[hits], nodes, grid[:, c]) for c in range(3)], 1)
        return out

    def albedo(self, wo, n):
        mu = np.clip(_dot(wo, n), 0.0, 1.0)
        r = mf.table_roughness(self.alpha_x, self.alpha_y)
        if self.fresnel.table_terms() is None:
            total = np.minimum(self._integrated_albedo(mu), mf.table("E", r, mu)[:, None])
            return total * self._scale(mu) * (mu > 0)[:, None]
        total = 0.0
        for coefficient, name, eta in self.fresnel.table_terms():
            total = total + coefficient * mf.table(name, r, mu, eta)[:, None]
        # F <= 1 bounds the albedo by the white lobe's (the conductor's F82 fit can overshoot).
        total = np.clip(total, 0.0, mf.table("E", r, mu)[:, None])
        return total * self._scale(mu) * (mu > 0)[:, None]


_ALBEDO_CACHE: dict = {}


def _integrate_albedo(ax, ay, fresnel, nodes=32, side=32):
    """(nodes, 3): the single-scattering albedo int F(v.h) G2/G1 of GGX (ax, ay) over visible
    normals at mu = linspace(1e-4, 1), by side^2 stratified samples (``microfacet.sample_vndf``,
    Heitz 2018), for a one-hit Fresnel object."""
    u = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1)
         .reshape(-1, 2) + 0.5) / side
    k = len(u)
    mu = np.clip(np.linspace(0.0, 1.0, nodes), 1e-4, 1.0)
    m = np.repeat(mu, k)
    v = np.stack([np.sqrt(1.0 - m * m), np.zeros_like(m), m], axis=1)
    a_x, a_y = np.full(len(m), ax), np.full(len(m), ay)
    h = mf.sample_vndf(v, a_x, a_y, np.tile(u, (nodes, 1)))
    c = np.clip(_dot(v, h), 0.0, 1.0)
    w = 2.0 * c[:, None] * h - v
    lam_v = mf.ggx_lambda(v, a_x, a_y)
    ratio = np.where(w[:, 2] > 0, (1.0 + lam_v) / (1.0 + lam_v + mf.ggx_lambda(w, a_x, a_y)), 0.0)
    F = fresnel.subset(np.zeros(len(m), dtype=int)).reflectance(c)
    return (F * ratio[:, None]).reshape(nodes, k, 3).mean(axis=1)


# -- Dielectric glass ----------------------------------------------------------------------------------
def _glass_fresnel(eta, f0, film=None):
    """The interface's Fresnel: the exact dielectric of ``eta``, remapped towards ``f0`` (N, 3)
    where given, under a thin film where ``film`` = (thickness [nm] (N,), film index relative
    to the side the light comes from (N,)) is given (Cycles' generalised Schlick with its film:
    ``fresnel.ThinFilmDielectricFresnel``, f0 the exact F0 where not given)."""
    if film is not None:
        base = (np.repeat(fresnel_module.f0_from_ior(eta)[:, None], 3, axis=1) if f0 is None
                else fresnel_module.rgb_per_hit(f0, len(eta)))
        return fresnel_module.ThinFilmDielectricFresnel(eta, base, film[0], film[1])
    return (fresnel_module.DielectricFresnel(eta) if f0 is None
            else fresnel_module.TintedDielectricFresnel(eta, f0))


def _film_per_hit(film, count):
    """A film (thickness, index) as two (count,) arrays, or None."""
    return None if film is None else (_per_hit(film[0], count), _per_hit(film[1], count))


def _film_subset(film, index):
    return None if film is None else (film[0][index], film[1][index])


def _reflect_probability(F, reflection_tint, transmission_tint):
    r = (F * reflection_tint).mean(axis=1)
    t = ((1.0 - F) * transmission_tint).mean(axis=1)
    total = r + t
    return np.divide(r, total, out=np.zeros_like(r), where=total > 0)


class MicrofacetGlass:
    """Rough dielectric: GGX reflection and refraction (isotropic), Cycles' Glass BSDF and the
    Principled BSDF's transmission."""

    def __init__(self, alpha, eta, reflection_tint=1.0, transmission_tint=1.0, f0=None,
                 multiscatter=False, film=None):
        self.alpha = np.asarray(alpha, dtype=float)
        count = len(self.alpha)
        self.eta = _per_hit(eta, count)
        self.reflection_tint = fresnel_module.rgb_per_hit(reflection_tint, count)
        self.transmission_tint = fresnel_module.rgb_per_hit(transmission_tint, count)
        self.f0 = None if f0 is None else fresnel_module.rgb_per_hit(f0, count)
        self.film = _film_per_hit(film, count)
        self.fresnel = _glass_fresnel(self.eta, self.f0, self.film)
        self.multiscatter = _per_hit(multiscatter, count, bool)

    def subset(self, index):
        return MicrofacetGlass(self.alpha[index], self.eta[index], self.reflection_tint[index],
                               self.transmission_tint[index],
                               None if self.f0 is None else self.f0[index],
                               self.multiscatter[index], _film_subset(self.film, index))

    def _scale(self, mu_o):
        out = np.ones((len(mu_o), 3))
        m = self.multiscatter
        if m.any():
            r = np.sqrt(self.alpha[m])
            E = mf.table("G", r, np.clip(mu_o[m], 0.0, 1.0), self.eta[m])
            E_avg = mf.table("Gavg", r, None, self.eta[m])
            out[m] = compensation(E, E_avg, self.transmission_tint[m])
        return out

    def _terms(self, wo, wi, n):
        """(f (N, 3), pdf (N,)) of both branches at once."""
        a, eta = self.alpha, self.eta
        cos_o, cos_i = _dot(wo, n), _dot(wi, n)
        refl = (cos_o > 0) & (cos_i > 0)
        refr = (cos_o > 0) & (cos_i < 0)
        ht = -(wo + eta[:, None] * wi)
        h = _unit(np.where(refr[:, None], ht, wo + wi))
        h = h * np.where(_dot(h, n) < 0, -1.0, 1.0)[:, None]
        c_o, c_i = _dot(wo, h), _dot(wi, h)
        refr &= (c_o > 0) & (c_i < 0)
        F = self.fresnel.reflectance(np.clip(c_o, 0.0, 1.0))
        P = _reflect_probability(F, self.reflection_tint, self.transmission_tint)
        D = mf.ggx_d_iso(_dot(h, n), a)
        lam_o, lam_i = mf.ggx_lambda_iso(cos_o, a), mf.ggx_lambda_iso(cos_i, a)
        G2 = 1.0 / (1.0 + lam_o + lam_i)
        G1 = 1.0 / (1.0 + lam_o)
        with np.errstate(divide="ignore", invalid="ignore"):
            common_r = D / (4.0 * cos_o)
            jac = eta ** 2 * np.abs(c_i) / np.sum(ht * ht, axis=1)       # d omega_h / d wi
            common_t = D * np.abs(c_o) / cos_o * jac
            f_r = common_r * G2 / cos_i
            f_t = common_t * G2 / np.abs(cos_i)
            p_r = P * G1 * common_r
            p_t = (1.0 - P) * G1 * common_t
        f = np.where(refl[:, None], F * self.reflection_tint * f_r[:, None], 0.0) + \
            np.where(refr[:, None], (1.0 - F) * self.transmission_tint * f_t[:, None], 0.0)
        pdf = np.where(refl, p_r, 0.0) + np.where(refr, p_t, 0.0)
        f = np.nan_to_num(f, nan=0.0, posinf=0.0)
        return f * self._scale(cos_o), np.nan_to_num(pdf, nan=0.0, posinf=0.0)

    def evaluate(self, wo, wi, n):
        return self._terms(wo, wi, n)[0]

    def pdf(self, wo, wi, n):
        return self._terms(wo, wi, n)[1]

    def sample(self, wo, n, u):
        a, eta = self.alpha, self.eta
        t, b = sampling.orthonormal_basis(n)
        lo = mf.to_local(wo, t, b, n)
        above = lo[:, 2] > 0
        v = np.where(above[:, None], lo, [[0.0, 0.0, 1.0]])
        h = mf.sample_vndf(v, a, a, u[:, :2])
        c = _dot(v, h)
        _, cos_t = fresnel_module.dielectric(c, eta)
        F = self.fresnel.reflectance(c)
        P = _reflect_probability(F, self.reflection_tint, self.transmission_tint)
        refract = u[:, 2] >= P
        li = np.where(refract[:, None],
                      -v / eta[:, None] + (c / eta - cos_t)[:, None] * h,
                      2.0 * c[:, None] * h - v)
        valid = above & np.where(refract, li[:, 2] < 0, li[:, 2] > 0)
        lam_o = mf.ggx_lambda_iso(v[:, 2], a)
        lam_i = mf.ggx_lambda_iso(li[:, 2], a)
        ratio = np.where(valid, (1.0 + lam_o) / (1.0 + lam_o + lam_i), 0.0)
        D = mf.ggx_d_iso(h[:, 2], a)
        with np.errstate(divide="ignore", invalid="ignore"):
            common_r = D / (4.0 * v[:, 2])
            ht = v + eta[:, None] * li
            common_t = D * c / v[:, 2] * eta ** 2 * np.abs(_dot(li, h)) / np.sum(ht * ht, axis=1)
            pdf = np.where(refract, (1.0 - P) * common_t, P * common_r) / (1.0 + lam_o)
            share = np.where(refract[:, None], (1.0 - F) * self.transmission_tint /
                             (1.0 - P)[:, None], F * self.reflection_tint / P[:, None])
        weight = np.nan_to_num(share) * ratio[:, None] * self._scale(lo[:, 2])
        pdf = np.where(valid, np.nan_to_num(pdf, nan=0.0, posinf=0.0), 0.0)
        # An index within 1e-4 of 1 refracts straight through: a delta, as in Cycles.
        straight = valid & refract & (np.abs(eta - 1.0) < 1e-4)
        pdf = np.where(straight, np.inf, pdf)
        weight = np.where(straight[:, None], np.nan_to_num(share) * self._scale(lo[:, 2]), weight)
        return mf.from_local(li, t, b, n), weight, pdf

    def albedo(self, wo, n):
        reflected, transmitted = self.albedo_split(wo, n)
        return reflected + transmitted

    def albedo_split(self, wo, n):
        """(reflected, transmitted) (N, 3): the two branches of ``albedo`` apart (Cycles'
        Glossy and Transmission Color of a glass closure)."""
        mu = np.clip(_dot(wo, n), 0.0, 1.0)
        r = np.sqrt(self.alpha)
        G = mf.table("G", r, mu, self.eta)
        scale = self._scale(mu) * (mu > 0)[:, None]
        if self.film is not None:
            # Under a film (no tables, as in Cycles): the single-scattering total split by
            # the smooth Fresnel at the view, F(mu_o) reflected and 1 - F(mu_o) transmitted.
            F = self.fresnel.reflectance(mu)
            return (F * G[:, None] * self.reflection_tint * scale,
                    (1.0 - F) * G[:, None] * self.transmission_tint * scale)
        R = mf.table("R", r, mu, self.eta)
        reflected = sum(coefficient * mf.table(name, r, mu, e)[:, None]
                        for coefficient, name, e in self.fresnel.table_terms())
        if self.f0 is None:
            carried = np.ones((len(mu), 3))
        else:                                       # 1 - F' = (1 - F)(1 - f0) / (1 - F0)
            F0 = fresnel_module.f0_from_ior(self.eta)[:, None]
            carried = (1.0 - self.f0) / np.maximum(1.0 - F0, 1e-12)
        transmitted = carried * np.clip(G - R, 0.0, None)[:, None]
        return (reflected * self.reflection_tint * scale,
                transmitted * self.transmission_tint * scale)


class SmoothGlass:
    """A smooth dielectric (delta): mirror reflection with probability P, refraction
    otherwise; weights R F / P and T (1 - F) / (1 - P), no eta^2 (Cycles' convention)."""

    def __init__(self, eta, reflection_tint=1.0, transmission_tint=1.0, f0=None, film=None):
        self.eta = np.asarray(eta, dtype=float)
        count = len(self.eta)
        self.reflection_tint = fresnel_module.rgb_per_hit(reflection_tint, count)
        self.transmission_tint = fresnel_module.rgb_per_hit(transmission_tint, count)
        self.f0 = None if f0 is None else fresnel_module.rgb_per_hit(f0, count)
        self.film = _film_per_hit(film, count)
        self.fresnel = _glass_fresnel(self.eta, self.f0, self.film)

    def subset(self, index):
        return SmoothGlass(self.eta[index], self.reflection_tint[index],
                           self.transmission_tint[index],
                           None if self.f0 is None else self.f0[index],
                           _film_subset(self.film, index))

    def evaluate(self, wo, wi, n):
        return np.zeros((len(wi), 3))

    def pdf(self, wo, wi, n):
        return np.zeros(len(wi))

    def _outcomes(self, wo, n):
        """(cos (N,), F (N, 3), reflected (N, 3), refracted (N, 3)) at views ``wo``."""
        c = np.clip(_dot(wo, n), 0.0, 1.0)
        _, cos_t = fresnel_module.dielectric(c, self.eta)
        return (c, self.fresnel.reflectance(c), 2.0 * c[:, None] * n - wo,
                -wo / self.eta[:, None] + (c / self.eta - cos_t)[:, None] * n)

    def sample(self, wo, n, u):
        c, F, reflected, refracted = self._outcomes(wo, n)
        P = _reflect_probability(F, self.reflection_tint, self.transmission_tint)
        refract = u[:, -1] >= P
        wi = np.where(refract[:, None], refracted, reflected)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(refract[:, None],
                              (1.0 - F) * self.transmission_tint / (1.0 - P)[:, None],
                              F * self.reflection_tint / P[:, None])
        weight = np.where((c > 0)[:, None], np.nan_to_num(weight), 0.0)
        return wi, weight, np.where(c > 0, np.inf, 0.0)

    def branches(self, wo, n):
        """Both of ``sample``'s outcomes at once (splitting instead of picking):
        ((wi_reflected, R F), (wi_refracted, T (1 - F))), each (N, 3); their weights sum to
        ``albedo``, so one ray down each branch is ``sample``'s expectation without the pick's
        variance. Under total internal reflection the refracted weight is 0."""
        c, F, reflected, refracted = self._outcomes(wo, n)
        facing = (c > 0)[:, None]
        return ((reflected, np.where(facing, F * self.reflection_tint, 0.0)),
                (refracted, np.where(facing, (1.0 - F) * self.transmission_tint, 0.0)))

    def albedo(self, wo, n):
        F = self.fresnel.reflectance(np.clip(_dot(wo, n), 0.0, 1.0))
        return F * self.reflection_tint + (1.0 - F) * self.transmission_tint

    def albedo_split(self, wo, n):
        """(reflected F tint_r, transmitted (1 - F) tint_t) (N, 3): ``albedo``'s branches."""
        F = self.fresnel.reflectance(np.clip(_dot(wo, n), 0.0, 1.0))
        return F * self.reflection_tint, (1.0 - F) * self.transmission_tint


class SmoothReflection:
    """A mirror (delta) with a Fresnel object: weight F(wo.n) (the roughness-0 limit of
    ``MicrofacetReflection``)."""

    def __init__(self, fresnel):
        self.fresnel = fresnel

    def subset(self, index):
        return SmoothReflection(self.fresnel.subset(index))

    def evaluate(self, wo, wi, n):
        return np.zeros((len(wi), 3))

    def pdf(self, wo, wi, n):
        return np.zeros(len(wi))

    def sample(self, wo, n, u=None):
        c = _dot(wo, n)
        weight = self.fresnel.reflectance(np.clip(c, 0.0, 1.0)) * (c > 0)[:, None]
        return 2.0 * c[:, None] * n - wo, weight, np.where(c > 0, np.inf, 0.0)

    def albedo(self, wo, n):
        c = _dot(wo, n)
        return self.fresnel.reflectance(np.clip(c, 0.0, 1.0)) * (c > 0)[:, None]

    layer_albedo = albedo


# -- Sheen -------------------------------------------------------------------------------------------
SHEEN_TABLE = Path(__file__).resolve().parent / "data" / "sheen_ltc.npz"


@lru_cache(maxsize=1)
def sheen_table() -> dict:
    """The sheen LTC table {"A", "a", "b": (32 mu, 32 roughness)} (``tools/sheen_ltc_table.py``)."""
    with np.load(SHEEN_TABLE, allow_pickle=False) as data:
        return {k: data[k].astype(np.float64) for k in ("A", "a", "b")}


def _read_2d(grid, x, y):
    """Cycles' node-centred bilinear read of ``grid`` [x, y] at x, y in [0, 1] (clamped)."""
    size_x, size_y = grid.shape
    fx = np.clip(x, 0.0, 1.0) * (size_x - 1)
    fy = np.clip(y, 0.0, 1.0) * (size_y - 1)
    ix = np.minimum(fx.astype(int), size_x - 2)
    iy = np.minimum(fy.astype(int), size_y - 2)
    tx, ty = fx - ix, fy - iy
    return ((1 - tx) * (1 - ty) * grid[ix, iy] + tx * (1 - ty) * grid[ix + 1, iy]
            + (1 - tx) * ty * grid[ix, iy + 1] + tx * ty * grid[ix + 1, iy + 1])


class Sheen:
    """Cycles' microfibre sheen (``bsdf_sheen.h``; Zeltner, Burley and Chiang 2022): in the
    frame (t, b, n) with t along wo's tangential part, f cos_i = A D(wi) with the linearly
    transformed cosine D(w) = z a^2 / (pi ((a x + b z)^2 + (a y)^2 + z^2)^2), a density on the
    upper hemisphere, so f = A a^2 / (pi len^4), sampled exactly (weight A, pdf D). A, a, b are
    read at (mu_o, roughness) from our table (``sheen_table``), roughness clamped to
    [1e-3, 1] as Cycles does; a lobe with a < 1e-5 or A < 1e-5 is off (Cycles skips it)."""

    def __init__(self, roughness):
        self.roughness = np.clip(np.asarray(roughness, dtype=float), 1e-3, 1.0)

    def subset(self, index):
        return Sheen(self.roughness[index])

    def _setup(self, wo, n):
        mu = _dot(wo, n)
        table = sheen_table()
        A = _read_2d(table["A"], mu, self.roughness)
        a = _read_2d(table["a"], mu, self.roughness)
        b = _read_2d(table["b"], mu, self.roughness)
        on = (mu > 0) & (np.abs(a) >= 1e-5) & (A >= 1e-5)
        t0, b0 = sampling.orthonormal_basis(n)
        tangent = wo - mu[:, None] * n
        length = np.linalg.norm(tangent, axis=1, keepdims=True)
        ok = length[:, 0] > 1e-7
        t = np.where(ok[:, None], tangent / np.where(ok[:, None], length, 1.0), t0)
        bt = np.where(ok[:, None], np.cross(n, t), b0)
        return np.where(on, A, 0.0), np.where(on, a, 1.0), np.where(on, b, 0.0), on, t, bt

    @staticmethod
    def _density(local, a, b):
        len2 = (a * local[:, 0] + b * local[:, 2]) ** 2 + (a * local[:, 1]) ** 2 + local[:, 2] ** 2
        return a * a / (np.pi * len2 * len2)

    def evaluate(self, wo, wi, n):
        A, a, b, on, t, bt = self._setup(wo, n)
        local = mf.to_local(wi, t, bt, n)
        valid = on & (local[:, 2] > 0)
        f = np.where(valid, A * self._density(local, a, b), 0.0)
        return np.repeat(f[:, None], 3, axis=1)

    def pdf(self, wo, wi, n):
        A, a, b, on, t, bt = self._setup(wo, n)
        local = mf.to_local(wi, t, bt, n)
        valid = on & (local[:, 2] > 0)
        return np.where(valid, local[:, 2] * self._density(local, a, b), 0.0)

    def sample(self, wo, n, u):
        A, a, b, on, t, bt = self._setup(wo, n)
        r = np.sqrt(u[:, 0])
        phi = 2.0 * np.pi * u[:, 1]
        x, y = r * np.cos(phi), r * np.sin(phi)
        z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
        local = _unit(np.stack([(x - z * b) / a, y / a, z], axis=1))
        valid = on & (local[:, 2] > 0)
        pdf = np.where(valid, local[:, 2] * self._density(local, a, b), 0.0)
        weight = np.repeat(np.where(valid, A, 0.0)[:, None], 3, axis=1)
        return mf.from_local(local, t, bt, n), weight, pdf

    def albedo(self, wo, n):
        A = self._setup(wo, n)[0]
        return np.repeat(A[:, None], 3, axis=1)


# -- Diffuse family ----------------------------------------------------------------------------------
_ON_G0 = np.pi / 2.0 - 2.0 / 3.0
_ON_GL_X, _ON_GL_W = np.polynomial.legendre.leggauss(64)


def oren_nayar_g(mu):
    """Fujii's G(mu) = sin t (t - sin t cos t) + (2/3) tan t (1 - sin^3 t) - (2/3) sin t,
    t = acos(mu): the albedo of the B term, E(mu) = pi A + B G(mu); G(0) = pi/2 - 2/3."""
    mu = np.clip(np.asarray(mu, dtype=float), 0.0, 1.0)
    small = mu < 1e-6
    m = np.where(small, 1.0, mu)
    s = np.sqrt(np.maximum(1.0 - m * m, 0.0))
    theta = np.arccos(m)
    g = s * (theta - s * m) + (2.0 / 3.0) * (s / m) * (1.0 - s ** 3) - (2.0 / 3.0) * s
    return np.where(small, _ON_G0 - mu, g)


# 2 int_0^1 G(mu) mu dmu by quadrature (Cycles writes it (2 pi - 5.6) / 3; they agree to 1e-10).
_ON_G_MEAN = float(np.sum(0.5 * _ON_GL_W * 2.0 * 0.5 * (_ON_GL_X + 1.0) *
                          oren_nayar_g(0.5 * (_ON_GL_X + 1.0))))
_ON_G_MEAN_CYCLES = (2.0 * np.pi - 5.6) / 3.0


class OrenNayar:
    """Cycles' Oren-Nayar (Fujii's FON plus the EON multiple-scattering term; module
    docstring). ``albedo`` is rho (N, 3), ``sigma`` the roughness in [0, 1] (N,)."""

    def __init__(self, albedo, sigma):
        self.rho = np.asarray(albedo, dtype=float)
        count = len(self.rho)
        self.sigma = np.clip(_per_hit(sigma, count), 0.0, 1.0)
        self.A = 1.0 / (np.pi + self.sigma * _ON_G0)
        self.B = self.sigma * self.A
        rho = np.clip(self.rho, 0.0, 1.0)
        e_avg = (np.pi * self.A + _ON_G_MEAN_CYCLES * self.B)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            ems = rho ** 2 * e_avg / (np.pi * (1.0 - e_avg) * (1.0 - rho * (1.0 - e_avg)))
        self.E_ms = np.where((self.B > 0)[:, None], np.nan_to_num(ems), 0.0)

    def subset(self, index):
        return OrenNayar(self.rho[index], self.sigma[index])

    def _E(self, mu):
        return np.pi * self.A + self.B * oren_nayar_g(mu)

    def evaluate(self, wo, wi, n):
        mu_o, mu_i = _dot(wo, n), _dot(wi, n)
        valid = (mu_o > 0) & (mu_i > 0)
        mo, mi = np.clip(mu_o, 0.0, 1.0), np.clip(mu_i, 0.0, 1.0)
        s = _dot(wo, wi) - mo * mi
        t = np.where(s > 0, s / np.maximum(np.maximum(mo, mi), 1e-30), s)
        single = (self.A + self.B * t)[:, None]
        multi = self.E_ms * ((1.0 - self._E(mo)) * (1.0 - self._E(mi)))[:, None]
        return self.rho * (single + multi) * valid[:, None]

    def pdf(self, wo, wi, n):
        return np.maximum(_dot(wi, n), 0.0) / np.pi * (_dot(wo, n) > 0)

    def sample(self, wo, n, u):
        wi = sampling.cosine_directions(n, u[:, :2])
        pdf = self.pdf(wo, wi, n)
        weight = np.pi * self.evaluate(wo, wi, n)          # f cos / (cos / pi)
        return wi, weight, pdf

    def albedo(self, wo, n):
        mu = np.clip(_dot(wo, n), 0.0, 1.0)
        E = self._E(mu)
        mean_E = np.pi * self.A + _ON_G_MEAN * self.B
        multi = self.E_ms * (np.pi * (1.0 - E) * (1.0 - mean_E))[:, None]
        return self.rho * (E[:, None] + multi) * (mu > 0)[:, None]


class Translucent:
    """Lambertian transmission: colour / pi on the side opposite wo (Cycles' Translucent
    BSDF), cosine-sampled about -n."""

    def __init__(self, color):
        self.color = np.asarray(color, dtype=float)

    def subset(self, index):
        return Translucent(self.color[index])

    def evaluate(self, wo, wi, n):
        back = (_dot(wi, n) < 0) & (_dot(wo, n) > 0)
        return self.color / np.pi * back[:, None]

    def pdf(self, wo, wi, n):
        return np.maximum(-_dot(wi, n), 0.0) / np.pi * (_dot(wo, n) > 0)

    def sample(self, wo, n, u):
        wi = sampling.cosine_directions(-n, u[:, :2])
        ok = (_dot(wo, n) > 0)[:, None]
        return wi, self.color * ok, self.pdf(wo, wi, n)

    def albedo(self, wo, n):
        return self.color * (_dot(wo, n) > 0)[:, None]


class Transparent:
    """A delta pass-through (Cycles' Transparent BSDF): wi = -wo, weight colour."""

    def __init__(self, color):
        self.color = np.asarray(color, dtype=float)

    def subset(self, index):
        return Transparent(self.color[index])

    def evaluate(self, wo, wi, n):
        return np.zeros((len(wi), 3))

    def pdf(self, wo, wi, n):
        return np.zeros(len(wi))

    def sample(self, wo, n, u=None):
        return -wo, self.color.copy(), np.full(len(wo), np.inf)

    def albedo(self, wo=None, n=None):
        return self.color
