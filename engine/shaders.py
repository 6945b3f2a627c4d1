"""Surface shaders as Cycles sees them: a flat list of weighted closures, and what today's
renderer makes of them.

What it computes
----------------
Cycles evaluates a material's node tree into a list of *closures*, each a BSDF (or an
emission) with an RGB weight: a Mix Shader multiplies the weights of the closures below its
two inputs by (1 - Fac) and Fac, an Add Shader concatenates the two lists. A :class:`Closure`
here is one entry of that list: the node's kind, its weight, its inputs as numbers (constant
per material for now; the textures issue feeds per-hit values into the same slots through
``bsdf.MaterialTable.at``) and the node's name, for messages. Export
(``engine/blender/export.py``) builds the list from Blender's nodes; ``CLOSURE_KINDS`` below
is the list of kinds, their parameters and defaults (Blender 5.2 LTS's node defaults).

:func:`seed_reduction` turns closures into the seed's three radiometric properties (section
3.2: a Lambertian rho_d, a perfect mirror rho_s and an exitance M), the material model the
camera, the photons and the cache evaluate today, and names every approximation it makes, so
that nothing is approximated without a word:

=============  ================================================================================
closure        seed material (weight w multiplies each line)
=============  ================================================================================
principled     rho_d = Base Color (1 - Metallic)(1 - Transmission); rho_s = Base Color x
               Metallic + sqrt(Base Color)(1 - Metallic) Transmission, the roulette's shares
               (node-driven alpha: reported; a constant
               Alpha < 1 is exported as Cycles composes it, a Transparent closure of
               weight 1 - Alpha beside the Principled one of weight Alpha).
               Sheen, coat, the metal, the dielectric specular layer (thin film on them
               and the transmission through the Fresnel; ``bsdf.MaterialTable.transport_*`` for photons and gather
               rays) and the transmission are rendered everywhere by their lobes
               (``bsdf.glossy_material``), layered as Cycles layers them
diffuse        rho_d = Color (Roughness > 0: Oren-Nayar at camera hits, ``bsdf.RoughDiffuseHits``;
               Lambertian for photons and gather rays: reported)
glossy         rho_s = Color, the roulette's share; rendered everywhere as GGX
metallic       rho_s = Base Color (F82) or ((n-1)^2 + k^2) / ((n+1)^2 + k^2) (physical), the
               roulette's share; rendered everywhere as GGX with the F82-tint or conductor
               Fresnel
glass,         rho_s = Color: rendered everywhere (camera, photons, gather) by its glass lobe
refraction     (``bsdf.GlassLobe``: smooth or GGX dielectric); rho_s is its roulette share
transparent    rho_s = Color, the roulette's share; rendered everywhere by a glass lobe of
               index 1 (straight through; behind it lit by photons, not shadow rays: reported)
holdout        black (reported)
translucent    rho_t = Color (``SeedMaterial.translucent``): f = rho_t / pi for light arriving on
               the far side (Cycles' Translucent BSDF), the far side's irradiance x rho_t / pi
sheen          rho_s = Color, the roulette's share; rendered everywhere by the microfibre lobe
               (``bsdf.SheenLobe``; Ashikhmin is reported and rendered as Microfiber)
emission       M = pi x Color x Strength (radiance Color x Strength on each side)
=============  ================================================================================

Parameters of a closure (``Closure.params``; colours are linear RGB, (3,) float64)
    see ``CLOSURE_KINDS``: every key a kind has, with its default. Roughness is Blender's
    (alpha = roughness^2 for GGX), IOR is relative (outside medium 1), angles in units of a
    full turn as Blender's Anisotropic Rotation, thin-film thickness in nm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Closure", "CLOSURE_KINDS", "SeedMaterial", "seed_reduction", "lobe_names"]

_WHITE = (1.0, 1.0, 1.0)
_GREY = (0.8, 0.8, 0.8)

# kind -> {parameter: default}. Colours are 3-tuples; everything else a float (booleans 0/1).
CLOSURE_KINDS: dict[str, dict] = {
    "principled": {
        "base_color": _GREY, "metallic": 0.0, "roughness": 0.5, "ior": 1.5, "alpha": 1.0,
        "thin_wall": 0.0, "diffuse_roughness": 0.0, "subsurface_weight": 0.0,
        "specular_ior_level": 0.5, "specular_tint": _WHITE, "anisotropic": 0.0,
        "anisotropic_rotation": 0.0, "transmission": 0.0, "coat_weight": 0.0,
        "coat_roughness": 0.03, "coat_ior": 1.5, "coat_tint": _WHITE, "sheen_weight": 0.0,
        "sheen_roughness": 0.5, "sheen_tint": _WHITE, "emission": (0.0, 0.0, 0.0),
        "thin_film_thickness": 0.0, "thin_film_ior": 1.33,
    },
    "diffuse": {"color": _GREY, "roughness": 0.0},
    "glossy": {"color": _GREY, "roughness": 0.5, "anisotropy": 0.0, "rotation": 0.0},
    "metallic": {
        "base_color": (0.617, 0.577, 0.540), "edge_tint": (0.695, 0.726, 0.770),
        "ior": (2.757, 2.513, 2.231), "extinction": (3.867, 3.404, 3.009), "physical": 0.0,
        "roughness": 0.5, "anisotropy": 0.0, "rotation": 0.0, "thin_film_thickness": 0.0,
        "thin_film_ior": 1.33,
    },
    "glass": {"color": _WHITE, "roughness": 0.0, "ior": 1.5, "thin_film_thickness": 0.0,
              "thin_film_ior": 1.33},
    "refraction": {"color": _WHITE, "roughness": 0.0, "ior": 1.45},
    "transparent": {"color": _WHITE},
    "translucent": {"color": _GREY},
    "sheen": {"color": _GREY, "roughness": 0.5},
    "emission": {"radiance": _WHITE},
    "holdout": {},
}


@dataclass
class Closure:
    """One weighted closure of a material (see the module docstring).

    ``kind`` a key of ``CLOSURE_KINDS``; ``weight`` (3,) the product of the Mix/Add factors
    above it; ``params`` the kind's parameters (missing ones take ``CLOSURE_KINDS``'
    defaults); ``node`` the Blender node's name; ``distribution`` Blender's microfacet
    distribution (``MULTI_GGX``, ``GGX``, ``BECKMANN``, ``ASHIKHMIN_SHIRLEY``) or ""."""

    kind: str
    weight: np.ndarray = field(default_factory=lambda: np.ones(3))
    params: dict = field(default_factory=dict)
    node: str = ""
    distribution: str = ""
    # Inputs driven by shader nodes (issue 24): parameter -> factors whose product is its
    # per-hit value, each ``(socket, constant)``: ``socket`` a (node, output identifier) of the
    # material's ``nodes.Graph`` or None for the constant (a Mix of colour x strength is two
    # factors). ``params`` then holds the value's mean over the surface (``engine/textures.py``).
    textures: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.kind not in CLOSURE_KINDS:
            raise ValueError(f"unknown closure kind {self.kind!r}")
        self.weight = np.broadcast_to(np.asarray(self.weight, np.float64), (3,)).copy()
        full = {}
        for key, default in CLOSURE_KINDS[self.kind].items():
            value = self.params.get(key, default)
            full[key] = (np.broadcast_to(np.asarray(value, np.float64), (3,)).copy()
                         if isinstance(default, tuple) else float(value))
        unknown = set(self.params) - set(full)
        if unknown:
            raise ValueError(f"closure {self.kind!r} has no parameter(s) {sorted(unknown)}")
        self.params = full

    def scaled(self, factor) -> "Closure":
        """This closure with its weight multiplied by ``factor`` (a scalar or RGB)."""
        return Closure(self.kind, self.weight * np.asarray(factor, np.float64), dict(self.params),
                       self.node, self.distribution, dict(self.textures))

    def at_hits(self, params: dict) -> "Closure":
        """A copy whose parameters are ``params``, per-hit arrays ((N,) numbers, (N, 3)
        colours) allowed, taken as they are (no defaults filled, no checks): what
        ``engine/textures.py`` hands to :func:`seed_reduction` at textured hits."""
        out = object.__new__(Closure)
        out.kind, out.weight, out.params = self.kind, self.weight, params
        out.node, out.distribution, out.textures = self.node, self.distribution, {}
        return out


@dataclass
class SeedMaterial:
    """The seed's material (section 3.2) made of closures, and the approximations made."""

    diffuse: np.ndarray
    specular: np.ndarray
    exitance: np.ndarray
    notes: list = field(default_factory=list)
    # rho_t: the translucent closures' diffuse transmission (light from the far side)
    translucent: np.ndarray = field(default_factory=lambda: np.zeros(3))


def _fmt(value) -> str:
    arr = np.asarray(value, float)
    if arr.ndim == 0:
        return f"{float(arr):.3g}"
    return "(" + ", ".join(f"{x:.3g}" for x in arr) + ")"


def _per_hit(value) -> np.ndarray:
    """A number, or (N,) per-hit numbers as an (N, 1) column that multiplies (N, 3) colours."""
    value = np.asarray(value, np.float64)
    return value[:, None] if value.ndim == 1 else value


# What an Oren-Nayar diffuse gets (``bsdf.RoughDiffuseHits``), said once per material.
OREN_NAYAR_NOTE = ("(Oren-Nayar, as Cycles) shapes direct light at camera hits; light reaching "
                   "it through the irradiance cache, gather and photons is taken as if it came "
                   "evenly (x the lobe's directional albedo), and photons and gather rays see "
                   "a Lambertian diffuse of its colour")


def _principled(c: Closure, note):
    p = c.params
    name = f"'{c.node}'"
    metallic = _per_hit(np.clip(p["metallic"], 0, 1))
    transmission = _per_hit(np.clip(p["transmission"], 0, 1))
    base = p["base_color"]
    diffuse = base * (1 - metallic) * (1 - transmission)
    # The transmission is a glass lobe (``bsdf.GlassLobe``); here its share of the roulette.
    specular = base * metallic + (1 - metallic) * transmission * np.sqrt(np.clip(base, 0, None))
    exitance = math.pi * p["emission"]
    metallic_max, transmission_max = float(np.max(metallic)), float(np.max(transmission))
    if transmission_max > 0 and np.any(p["thin_wall"] > 0):
        note(f"Thin Wall of {name} is ignored: its transmission is rendered as a solid "
             "glass object's surface")
    if np.any(p["alpha"] < 1):
        note(f"Alpha {_fmt(np.mean(p['alpha']))} of {name} (driven by nodes) is ignored "
             "(rendered opaque)")
    if np.any(p["subsurface_weight"] > 0) and metallic_max < 1 and transmission_max < 1:
        note(f"Subsurface Weight {_fmt(np.mean(p['subsurface_weight']))} of {name} is approximated: "
             "rendered as a diffuse lobe of the Base Color (no subsurface scattering)")
    if np.any(p["diffuse_roughness"] > 0) and metallic_max < 1 and transmission_max < 1:
        note(f"Diffuse Roughness {_fmt(np.mean(p['diffuse_roughness']))} of {name} "
             f"{OREN_NAYAR_NOTE}")
    return diffuse, specular, exitance


def seed_reduction(closures) -> SeedMaterial:
    """The seed's (rho_d, rho_s, M) of a list of :class:`Closure` (see the module docstring's
    table), with one note per approximation, each naming the node. Values are not clipped
    (export clips them, with its own message)."""
    diffuse, specular, exitance = np.zeros(3), np.zeros(3), np.zeros(3)
    translucent = np.zeros(3)
    notes: list[str] = []

    def note(message: str) -> None:
        if message not in notes:
            notes.append(message)

    for c in closures:
        p, w, name = c.params, c.weight, f"'{c.node}'"
        d = s = e = np.zeros(3)
        if c.kind == "principled":
            d, s, e = _principled(c, note)
        elif c.kind == "diffuse":
            d = p["color"]
            if np.any(p["roughness"] > 0):
                note(f"Roughness {_fmt(np.mean(p['roughness']))} of Diffuse BSDF {name} "
                     f"{OREN_NAYAR_NOTE}")
        elif c.kind == "emission":
            e = math.pi * p["radiance"]
        elif c.kind in ("glossy", "metallic"):
            if c.kind == "metallic" and p["physical"]:
                n, k = p["ior"], p["extinction"]
                s = ((n - 1) ** 2 + k ** 2) / np.maximum((n + 1) ** 2 + k ** 2, 1e-12)
            else:
                s = p["base_color"] if c.kind == "metallic" else p["color"]
        elif c.kind in ("glass", "refraction"):
            # Rendered by its glass lobe (``bsdf.GlassLobe``) everywhere; rho_s is its share
            # in the photons' roulette and marks it as a surface rays go on from.
            s = np.asarray(p["color"], np.float64)
        elif c.kind == "transparent":
            # Rendered by a glass lobe of index 1 (``bsdf.glossy_material``): rays and
            # photons go straight through; rho_s is its share of the roulette.
            s = np.asarray(p["color"], np.float64)
            note(f"Transparent BSDF {name}: light reaches what lies behind it through camera "
                 "rays and photons (the caustic map), not through shadow rays as in Cycles")
        elif c.kind == "holdout":
            note(f"Holdout {name} is not supported; rendered black")
        elif c.kind == "translucent":
            translucent = translucent + w * np.asarray(p["color"], np.float64)
        elif c.kind == "sheen":
            # Rendered by its microfibre lobe (``bsdf.SheenLobe``); rho_s is its roulette share.
            s = np.asarray(p["color"], np.float64)
            if c.distribution not in ("", "MICROFIBER"):
                note(f"Sheen BSDF {name}: the {c.distribution.title()} distribution is "
                     "rendered as Microfiber")
        diffuse = diffuse + w * d
        specular = specular + w * s
        exitance = exitance + w * e
    return SeedMaterial(diffuse, specular, exitance, notes, translucent)


def lobe_names(closures) -> list[str]:
    """The scattering lobes a material's closures make, in Cycles' terms (what the Material
    panel lists): e.g. ``["diffuse", "specular (dielectric)", "emission"]``."""
    names: list[str] = []

    def add(name):
        if name not in names:
            names.append(name)

    for c in closures:
        if not np.any(c.weight > 0):
            continue
        p = c.params
        if c.kind == "principled":
            metallic, transmission = p["metallic"], p["transmission"]
            if metallic < 1 and transmission < 1:
                add("diffuse" if p["diffuse_roughness"] == 0 else "diffuse (Oren-Nayar)")
            if metallic < 1 and p["specular_ior_level"] > 0:
                add("specular (dielectric)")
            if metallic > 0:
                add("specular (metal, F82 tint)")
            if transmission > 0 and metallic < 1:
                add("transmission")
            if p["coat_weight"] > 0:
                add("coat")
            if p["sheen_weight"] > 0:
                add("sheen")
            if p["subsurface_weight"] > 0:
                add("subsurface")
            if np.any(p["emission"] > 0):
                add("emission")
        elif c.kind == "diffuse":
            add("diffuse" if p["roughness"] == 0 else "diffuse (Oren-Nayar)")
        elif c.kind == "glossy":
            add("specular (glossy)")
        elif c.kind == "metallic":
            add("specular (metal, physical)" if p["physical"] else "specular (metal, F82 tint)")
        elif c.kind in ("glass", "refraction"):
            add("transmission")
        elif c.kind == "transparent":
            add("transparent")
        else:
            add(c.kind)
    return names
