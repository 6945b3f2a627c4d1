"""Materials at hits: the parameters per hit and the BSDF they make, over arrays of hits.

This is the seam every stage reads a material through (photon tracing, the final gather,
direct light and camera shading): parameters are fetched per hit by one function,
``MaterialTable.at(material_ids)``, so that textures can later feed the same slots, and the
scattering is asked of lobes with one interface (pbrt's ``f`` / ``Sample_f`` / ``PDF``):

    ``evaluate(wo, wi, n)``  BSDF value f [1/sr] (N, 3)
    ``sample(wo, n, u)``     (wi, weight = f cos / pdf (N, 3), pdf [1/sr] (N,)) for (N, 2)
                             uniform numbers ``u``
    ``pdf(wo, wi, n)``       density of ``sample`` [1/sr] (N,)
    ``albedo()``             directional albedo (N, 3): the share of light it reflects

Directions are unit (N, 3) arrays pointing away from the surface (``wo`` towards the viewer,
``wi`` towards the light), ``n`` the shading normal on ``wo``'s side.

Today's materials are the seed's (section 3.2): a Lambertian lobe of reflectance rho_d
(f = rho_d / pi) plus a perfect mirror of reflectance rho_s (a delta lobe: ``evaluate`` and
``pdf`` are 0, ``sample`` returns the mirror direction with weight rho_s and pdf inf), and an
exitance M [W/m^2] (radiance M / pi per emitting side). ``SurfaceBSDF`` composes the two lobes.

``roulette_probabilities(rho_d, rho_s)`` is Russian roulette's choice between the lobes
(seed 9.2, DESIGN.md §4): each lobe with the largest channel of its reflectance, both scaled by
1 / (P_d + P_s) where that sum exceeds 1, so that a survivor's power, scaled by rho / P per
channel, never grows in any channel.

Parameters (per material, ``Scene.materials``; per hit after ``at``)
    =================  =======  ===========================================================
    name               unit     meaning
    =================  =======  ===========================================================
    diffuse            [0, 1]   rho_d per RGB channel (Lambertian reflectance)
    specular           [0, 1]   rho_s per RGB channel (perfect mirror)
    exitance           W/m^2    radiant exitance M per channel
    emitted_radiance   W/m^2/sr L_e = M / pi per emitting side
    both_sides         bool     emits from both faces (Cycles' Emission shader does)
    transport_diffuse  [0, 1]   what photons see: rho_d, below Principled layers (sheen,
                                coat, specular) x the cosine-weighted mean of their diffuse
                                share (``material_averages``)
    transport_specular [0, 1]   the photons' and gather rays' specular share: rho_s plus the
                                layers' cosine-weighted mean albedo;
                                a specular pick samples the glossy lobes (``sample_glossy``)
    =================  =======  ===========================================================

Glossy and glass lobes per material (``glossy_material``): ``GlossyLobe`` (GGX reflection),
``GlassLobe`` (dielectric), ``SheenLobe`` (microfibre sheen), composed as Cycles composes the
Principled BSDF (``svm/closure.h``: sheen over coat over metal, transmission and the
dielectric specular layer over the diffuse, each layer scaling what is below it by
``closure_layering_weight``, clip(1 - max_channel(share x E(mu_o))), the coat also by its tint
along the refracted view ray: ``TopLayer``) and the other nodes; ``layer_diffuse_factor`` is
the diffuse share (RGB) below the layers at a view direction and ``reflection_albedo`` the
reflection lobes' summed albedo (what a camera-path probe and a gather ray read where they
land); ``material_averages`` their cosine-weighted means, what photons and gather rays see.
Thin film (Principled, Metallic BSDF) enters through the Fresnel (``engine/fresnel.py``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import fresnel as fresnel_model
from . import microfacet
from . import sampling
from .shaders import seed_reduction
from .textures import CAMERA_FLAG, MaterialTextures
from .lobes import (MicrofacetGlass, MicrofacetReflection, OrenNayar, Sheen, SmoothGlass,
                    SmoothReflection)

__all__ = ["MaterialTable", "SurfaceParams", "Lambertian", "PerfectMirror", "SurfaceBSDF",
           "roulette_probabilities", "reflect", "GlossyLobe", "GlassLobe", "GlossyMaterial",
           "glossy_material", "sample_glossy", "layer_diffuse_factor", "layer_average",
           "material_averages", "reflection_albedo", "SheenLobe", "TopLayer", "lobe_shares",
           "diffuse_roughness", "RoughDiffuseHits"]

# Below this alpha_x alpha_y a microfacet lobe is a mirror (Cycles' delta threshold).
DELTA_ALPHA2 = 2e-10
# The narrowest width a per-hit Roughness gives a lobe that is rough at its mean.
MIN_TEXTURED_ALPHA = np.sqrt(DELTA_ALPHA2) * 1.01
# Cycles skips Principled components of weight at or below this (``CLOSURE_WEIGHT_CUTOFF``).
CLOSURE_WEIGHT_CUTOFF = 1e-5


def roulette_probabilities(rho_d: np.ndarray, rho_s: np.ndarray):
    """Russian roulette's probabilities (P_d, P_s) from the diffuse and specular reflectances
    (K, 3): each the largest channel of its reflectance, both scaled by 1 / (P_d + P_s) where
    that sum exceeds 1 (DESIGN.md §4). A survivor's power is scaled by rho / P per channel, so
    no channel's weight grows (rho_c <= max rho = P). The seed's channel-averaged P let a
    channel grow: rho = (0.9, 0.6, 0.3) gave P = 0.6 and red x1.5 a bounce, a red variance
    series in 1.5^2 x 0.6 = 1.35 a bounce, which diverges."""
    p_d = np.max(rho_d, axis=1) if len(rho_d) else np.zeros(0)
    p_s = np.max(rho_s, axis=1) if len(rho_s) else np.zeros(0)
    total = p_d + p_s
    over = total > 1.0
    if over.any():
        p_d = np.where(over, p_d / np.where(over, total, 1.0), p_d)
        p_s = np.where(over, p_s / np.where(over, total, 1.0), p_s)
    return p_d, p_s


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror direction of travel ``d`` about unit normals ``n`` (N, 3): d - 2 (d.n) n."""
    return d - 2.0 * np.einsum("ij,ij->i", d, n)[:, None] * n


class MaterialTable:
    """The scene's materials as (M, 3) float64 arrays indexed by material id (the values as
    the float32 ``Scene.material_table`` holds them), and what the planner asks of them."""

    def __init__(self, scene):
        table = scene.material_table()
        self.diffuse = table["diffuse"].astype(np.float64)
        self.specular = table["specular"].astype(np.float64)
        self.exitance = table["exitance"].astype(np.float64)
        # Node-driven inputs (issue 24): per-hit values through ``at``; the per-material rows
        # and the lobes hold their means over the surface (``engine/textures.py``).
        self.textures = MaterialTextures(scene)
        self.textured = self.textures.textured
        self.textured_reflectance = self.textures.textured_part("reflectance")
        self.textured_emission = self.textures.textured_part("emission")
        for material_id, (d, s, e) in self.textures.mean_reduction.items():
            self.diffuse[material_id], self.specular[material_id] = d, s
            self.exitance[material_id] = e
        # Glossy lobes (issue 23): per material a GlossyMaterial or None.
        self.glossy = [glossy_material(closures) for closures in self.textures.mean_closures]
        self.camera_glossy = np.array([g is not None for g in self.glossy], bool)
        self.has_glossy = bool(self.camera_glossy.any())
        # Materials whose glossy or glass lobes a node-driven Mix Shader Fac weighs per hit
        # (``SurfaceParams.lobe_ratio``), and the closure of each material's specular layer.
        self.lobe_weighted = self.textures.lobe_weighted & self.camera_glossy
        self.has_lobe_weights = bool(self.lobe_weighted.any())
        # ... and those whose lobes' Roughness is node-driven (``LobeInputs.roughness``).
        self.lobe_textured = (self.lobe_weighted
                              | ((self.textures.lobe_roughness | self.textures.lobe_principled)
                                 & self.camera_glossy))
        self.has_lobe_inputs = bool(self.lobe_textured.any())
        self.closure_count = max([len(m.closures) for m in scene.materials] + [1])
        self.lobe_ratio = np.ones((len(self.diffuse), self.closure_count))
        self.lobe_roughness = np.full((len(self.diffuse), self.closure_count), np.nan)
        self.lobe_metallic = np.full((len(self.diffuse), self.closure_count), np.nan)
        self.lobe_base = np.full((len(self.diffuse), self.closure_count, 3), np.nan)
        self.lobe_transmission = np.full((len(self.diffuse), self.closure_count), np.nan)
        # The mean Metallic and Transmission Weight each material's specular layer was made
        # with (0 without one).
        self.layer_metallic = np.array([g.layer.metallic_mean if g is not None and
                                        g.layer is not None else 0.0 for g in self.glossy])
        self.layer_transmission = np.array([g.layer.transmission_mean if g is not None and
                                            g.layer is not None else 0.0 for g in self.glossy])
        self.layer_closure = np.array([g.layer.closure if g is not None and g.layer is not None
                                       else -1 for g in self.glossy], np.int64)
        # Materials with a glass lobe (light passes through them).
        self.transmissive = np.array([g is not None and any(lobe.transmits for lobe in g.lobes)
                                      for g in self.glossy], bool)
        self.has_transmission = bool(self.transmissive.any())
        # What photons and gather rays see (``transport_*``): the camera's diffuse and
        # specular, but for a Principled specular layer, which takes its cosine-weighted mean
        # albedo E_avg from the diffuse below it (1 - max E_avg) and becomes a specular share
        # E_avg that photons and gather rays sample by its GGX lobe (``layer_average``).
        # ``layer_kept`` (M, 3) the diffuse share below the layers and ``layer_albedo``
        # (M, 3) the layered specular, their cosine-weighted means (``material_averages``).
        self.layer_kept = np.ones_like(self.diffuse)
        self.layer_albedo = np.zeros_like(self.diffuse)
        self.has_layer = any(g is not None and g.layered for g in self.glossy)
        for material_id, spec in enumerate(self.glossy):
            if spec is not None and spec.layered:
                share, average = material_averages(spec)
                self.layer_kept[material_id] = share
                self.layer_albedo[material_id] = average
        # Translucent closures (Cycles' Translucent BSDF): rho_t (M, 3), f = rho_t / pi for
        # light from the far side; photons and gather rays see it as a diffuse share that
        # leaves on the far side. Textured colours per hit (``SurfaceParams.translucent``).
        self.translucent = np.array([seed_reduction(closures).translucent for closures in
                                     self.textures.mean_closures], np.float64).reshape(-1, 3)
        self.is_translucent = np.any(self.translucent > 0, axis=1)
        self.has_translucent = bool(self.is_translucent.any())
        self.transport_diffuse = self.diffuse * self.layer_kept + self.translucent
        self.transport_specular = self.specular + self.layer_albedo
        self.emitted_radiance = self.exitance / np.pi
        self.both_sides = table["both_sides"]
        self.diffuse_over_pi = self.diffuse / np.pi
        self.is_transport_specular = np.any(self.transport_specular > 0, axis=1)
        # Photons are stored, and the camera's diffuse estimates made, at hits that reflect or
        # transmit diffusely.
        self.reflects_diffuse = np.any(self.diffuse > 0, axis=1)
        self.is_diffuse = self.reflects_diffuse | self.is_translucent
        self.is_specular = np.any(self.specular > 0, axis=1)
        self.is_emissive = np.any(self.exitance > 0, axis=1)
        self.has_specular = bool(self.is_specular.any())
        self.has_transport_specular = bool(self.is_transport_specular.any())
        self.has_emission = bool(self.is_emissive.any())
        self.count = len(self.diffuse)
        # Oren-Nayar roughness sigma of each material's diffuse (``diffuse_roughness``):
        # 0 for Lambert's.
        self.diffuse_sigma = np.array([diffuse_roughness(c) for c in
                                       self.textures.mean_closures], np.float64)
        self.has_oren_nayar = bool(np.any(self.diffuse_sigma > 0))
        # Materials whose Normal nodes drive (``Material.shading_normal``: a Normal Map).
        self.normal_mapped = np.array([getattr(m, "shading_normal", None) is not None
                                       for m in scene.materials], bool)
        self.has_shading_normals = bool(self.normal_mapped.any())
        # Where no input is node-driven every parameter is one value per material: stages
        # may then work on per-material tables (the camera's histogram of direct light).
        self.constant_per_material = not self.textures.any
        # Some material reads Light Path (Is Camera Ray): the camera tells its rays apart.
        self.reads_light_path = bool(self.textures.light_path.any())

    def shading_normals(self, material_ids, prim, bu, bv, x, ns, ng, wo, front,
                        footprint=None) -> np.ndarray:
        """(N, 3) float32: the shading normals at camera hits, ``ns`` (the smooth normal
        turned to the viewer) replaced on materials with a node-driven Normal by what their
        nodes give (``textures.MaterialTextures.shading_normal``, one evaluation per
        material), turned to the viewer's side. As Cycles keeps a mapped normal from
        reflecting the view below the surface (``ensure_valid_specular_reflection``), a hit
        whose mapped normal would mirror ``wo`` below the geometric normal ``ng`` (or that
        is not finite) keeps ``ns``: a simpler guard than Cycles' bend towards it.
        ``x`` [m] the hits, ``wo`` (N, 3) unit towards the viewer, ``front`` (N,) bool
        front-face hits, ``footprint`` (N,) [m] the width of the pixel's footprint at each hit
        (default 1 mm): Bump's finite differences step across it, along two orthogonal
        tangents of the geometric normal as Cycles' compact ray differentials do (for a height
        smooth at the pixel's scale the bumped normal does not depend on the width)."""
        material_ids = np.asarray(material_ids)
        out = np.array(ns, np.float32, copy=True)
        for material_id in np.flatnonzero(self.normal_mapped):
            rows = np.flatnonzero(material_ids == material_id)
            if len(rows) == 0:
                continue
            hit_values = {"normal_world": ns[rows].astype(np.float64),
                          "true_normal_world": ng[rows].astype(np.float64),
                          "incoming": wo[rows].astype(np.float64),
                          "backfacing": (~np.asarray(front)[rows]).astype(np.float64),
                          "position_world": x[rows].astype(np.float64)}
            hit_values.update(self._footprint(prim[rows], hit_values["true_normal_world"],
                                              1e-3 if footprint is None else footprint[rows]))
            n = self.textures.shading_normal(int(material_id), prim[rows], bu[rows], bv[rows],
                                             hit_values)
            n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            n = np.where((np.einsum("ij,ij->i", n, hit_values["normal_world"]) < 0)[:, None],
                         -n, n)
            mirrored = reflect(-hit_values["incoming"], n)
            ok = np.all(np.isfinite(n), axis=1) & (
                np.einsum("ij,ij->i", mirrored, hit_values["true_normal_world"]) > 0)
            out[rows[ok]] = n[ok]
        return out

    def _footprint(self, prim, n, width) -> dict:
        """dPdx, dPdy (k, 3) [m]: two orthogonal tangents of length ``width`` at hits with
        unit geometric normals ``n`` (dPdx x dPdy along n: Cycles' compact differentials
        spread the same way around Ng), and bary_dx, bary_dy (k, 2): the changes of
        the barycentrics (bu, bv) of triangles ``prim`` along them (least squares on the
        triangle's edges)."""
        # Cycles' frame (``make_orthonormals``): (1, 1, 1) x n, or (-1, 1, 1) x n where n has
        # equal components.
        x, y, z = n[:, 0], n[:, 1], n[:, 2]
        equal = (x == y) & (x == z)
        e1 = np.stack([z - y, np.where(equal, x + z, x - z), np.where(equal, -y - x, y - x)],
                      axis=1)
        e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-300)
        e2 = np.cross(n, e1)
        w = np.broadcast_to(np.asarray(width, np.float64), (len(n),))[:, None]
        dpdx, dpdy = e1 * w, e2 * w
        tri = np.take(self.textures.scene.triangles, prim, axis=0).astype(np.float64)
        a, b = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        aa, ab, bb = (np.einsum("ij,ij->i", *pair) for pair in ((a, a), (a, b), (b, b)))
        det = aa * bb - ab * ab
        inv = np.where(det > 0, 1.0 / np.where(det > 0, det, 1.0), 0.0)
        out = {"dPdx": dpdx, "dPdy": dpdy}
        for axis, dp in (("x", dpdx), ("y", dpdy)):
            pa, pb = np.einsum("ij,ij->i", dp, a), np.einsum("ij,ij->i", dp, b)
            out[f"bary_d{axis}"] = np.stack([(bb * pa - ab * pb) * inv,
                                              (aa * pb - ab * pa) * inv], axis=1)
        return out

    def at(self, material_ids: np.ndarray, prim=None, bu=None, bv=None,
           directions=None, camera=None, ray=None) -> "SurfaceParams":
        """The parameters at hits on triangles of ``material_ids`` (N,): the one function
        through which every stage reads a material. ``prim`` (N,) the triangles and (bu, bv)
        the barycentrics of the hits: textured materials read their per-hit values there
        (without them, their means over the surface); ``directions`` (N, 3) the rays'
        (camera, gather, photon), for inputs that read the view (Fresnel, Layer Weight,
        Geometry: ``textures.MaterialTextures.view_at``); ``camera`` (N,) bool, the hits of
        camera rays, for Light Path's Is Camera Ray (None: none are); ``ray`` {Light Path
        output: scalar or (N,)}, the rays' other Light Path values (``textures.RAY_VALUES``;
        None: 0, a camera ray's)."""
        return SurfaceParams(self, np.asarray(material_ids), prim, bu, bv, directions, camera,
                             ray)


# SurfaceParams slots that textures make per-hit (the rest stay per material): those of the
# reflectance and those of the emission, each evaluated only when first asked for (a light
# sample or a photon leaving an emitter reads no reflectance, a gather ray meeting an
# emitter no emission texture).
REFLECTANCE_SLOTS = ("diffuse", "specular", "diffuse_over_pi", "transport_diffuse",
                     "transport_specular", "translucent", "lobe_ratio", "lobe_roughness",
                     "lobe_metallic", "lobe_base", "lobe_transmission")
EMISSION_SLOTS = ("exitance", "emitted_radiance")
TEXTURED_SLOTS = REFLECTANCE_SLOTS + EMISSION_SLOTS
# Hits whose textures are evaluated at once (``SurfaceParams._textured_hits``): a graph's
# temporaries for more rows than this fall out of the CPU's caches into fresh memory pages.
# The textured room's panel radiance at 400,000 light samples: 0.14-0.22 s at once, 0.08 s
# in batches of 65,536 (the same values).
TEXTURE_BATCH = 1 << 16


class SurfaceParams:
    """Material parameters per hit (N,) or (N, 3), each fetched when first asked for; at hits
    on textured materials (``MaterialTable.textured``) with their (prim, bu, bv) given, the
    ``TEXTURED_SLOTS`` hold the per-hit values (``textures.MaterialTextures.reflectance`` and
    ``exitance``, each part evaluated when one of its slots is first read)."""

    def __init__(self, table: MaterialTable, material: np.ndarray, prim=None, bu=None,
                 bv=None, directions=None, camera=None, ray=None):
        self.table = table
        self.material = material            # (N,) material ids (per-material fast paths)
        self.hits = None if prim is None or not table.textures.any else (
            np.asarray(prim), np.asarray(bu), np.asarray(bv))
        self.directions = None if directions is None or self.hits is None \
            or not table.textures.view_inputs.any() else np.asarray(directions)
        # (N,) bool: hits of camera rays, where materials read Light Path (else None)
        self.camera = None if camera is None or self.hits is None \
            or not table.textures.light_path.any() else \
            np.broadcast_to(np.asarray(camera, bool), (len(material),))
        # {Light Path output: (N,)}: the rays' other Light Path values (else None)
        self.ray = None if not ray or self.hits is None \
            or not table.textures.light_path.any() else \
            {k: np.broadcast_to(np.asarray(v, np.float64), (len(material),))
             for k, v in ray.items()}
        self._cache = {}
        # The node-driven reflectance at the hits (``_textured_reflectance``; False: not
        # evaluated yet).
        self._textured = False
        self._textured_rows = None     # (hits on those materials, their compact rows)
        # Slots a subset inherits, each taken from its parent's array when first read:
        # {name: (parent's array, integer index into it)}.
        self._inherited = {}

    def __len__(self):
        return len(self.material)

    def _take(self, name):
        if name not in self._cache:
            if name in self._inherited:
                array, index = self._inherited.pop(name)
                self._cache[name] = np.take(array, index, axis=0)
            elif self.hits is not None and name in REFLECTANCE_SLOTS:
                self._cache[name] = self._reflectance_slot(name)
            elif self.hits is not None and name in EMISSION_SLOTS:
                self._emission_slots()
            else:
                self._cache[name] = np.take(getattr(self.table, name), self.material, axis=0)
        return self._cache[name]

    def _textured_hits(self, textured: np.ndarray):
        """(material id, indices of hits on it) for the materials of these hits that
        ``textured`` (M,) marks, the hits in batches of at most ``TEXTURE_BATCH``."""
        material = self.material
        for material_id in np.unique(material[textured[material]]):
            at = np.flatnonzero(material == material_id)
            for start in range(0, len(at), TEXTURE_BATCH):
                yield int(material_id), at[start:start + TEXTURE_BATCH]

    def _view(self, material_id: int, at):
        """The view of hits ``at`` on ``material_id`` where its inputs read it and, where they
        read Light Path, whether each is a camera ray's (``textures.CAMERA_FLAG``); else
        None."""
        textures = self.table.textures
        values = None
        if textures.view_inputs[material_id]:
            prim, bu, bv = self.hits
            values = textures.view_at(prim[at], bu[at], bv[at],
                                      None if self.directions is None else self.directions[at])
        if textures.light_path[material_id] and self.camera is not None:
            values = {**(values or {}), CAMERA_FLAG: self.camera[at].astype(np.float64)}
        if textures.light_path[material_id] and self.ray is not None:
            values = {**(values or {}), **{f"ray:{k}": v[at] for k, v in self.ray.items()}}
        return values

    def _textured_reflectance(self):
        """The node-driven reflectance at the hits on materials whose reflectance is
        node-driven, evaluated once for all ``REFLECTANCE_SLOTS`` (and shared with
        ``subset``s): (position (N,) of each hit's row in the compact arrays, -1 for hits on
        other materials; {"diffuse", "specular", "translucent": (K, 3), "ratio",
        "roughness", "metallic", "transmission": (K, C), "base": (K, C, 3)}, the closures'
        columns past a material's own at their defaults), or None where no hit is on such
        a material."""
        if self._textured is False:
            table, material = self.table, self.material
            prim, bu, bv = self.hits
            parts = []
            for material_id, at in self._textured_hits(table.textured_reflectance):
                diffuse, specular, translucent, lobes = table.textures.reflectance(
                    material_id, prim[at], bu[at], bv[at], with_translucent=True,
                    with_ratios=True, hit_values=self._view(material_id, at))
                parts.append((at, diffuse, specular, translucent, lobes))
            if not parts:
                self._textured = None
                return None
            count, closures = sum(len(p[0]) for p in parts), table.closure_count
            compact = {"ratio": np.ones((count, closures)),
                       "roughness": np.full((count, closures), np.nan),
                       "metallic": np.full((count, closures), np.nan),
                       "base": np.full((count, closures, 3), np.nan),
                       "transmission": np.full((count, closures), np.nan)}
            position = np.full(len(material), -1, np.int64)
            start = 0
            for at, *_rest, (weights, rough, metal, colour, tw) in parts:
                rows = slice(start, start + len(at))
                position[at] = np.arange(start, start + len(at))
                c = weights.shape[1]
                compact["ratio"][rows, :c], compact["roughness"][rows, :c] = weights, rough
                compact["metallic"][rows, :c], compact["base"][rows, :c] = metal, colour
                compact["transmission"][rows, :c] = tw
                start += len(at)
            for k, name in enumerate(("diffuse", "specular", "translucent"), start=1):
                compact[name] = np.concatenate([np.asarray(p[k], np.float64).reshape(-1, 3)
                                                for p in parts])
            self._textured = (position, compact)
        return self._textured

    # Per-hit lobe inputs (``LobeInputs``): the compact arrays' names and defaults.
    _LOBE_SLOTS = {"lobe_ratio": ("ratio", 1.0), "lobe_roughness": ("roughness", np.nan),
                   "lobe_metallic": ("metallic", np.nan), "lobe_base": ("base", np.nan),
                   "lobe_transmission": ("transmission", np.nan)}

    def _reflectance_slot(self, name):
        """One of the ``REFLECTANCE_SLOTS``: the per-material rows, those of hits on
        materials whose reflectance is node-driven replaced by their per-hit values
        (``_textured_reflectance``); each slot is formed only when read (a photon's
        roulette reads two of them, a camera hit's direct light one)."""
        table, material = self.table, self.material
        textured = self._textured_reflectance()
        if name in self._LOBE_SLOTS:
            key, default = self._LOBE_SLOTS[name]
            shape = (len(material), table.closure_count) + ((3,) if key == "base" else ())
            out = np.full(shape, default)
        else:
            out = np.take(getattr(table, name), material, axis=0)
        if textured is None:
            return out
        position, compact = textured
        if self._textured_rows is None:         # formed once for all the slots read
            at = np.flatnonzero(position >= 0)
            self._textured_rows = (at, np.take(position, at))
        at, rows = self._textured_rows
        if name in self._LOBE_SLOTS:
            out[at] = np.take(compact[self._LOBE_SLOTS[name][0]], rows, axis=0)
        elif name in ("diffuse", "specular", "translucent"):
            out[at] = np.take(compact[name], rows, axis=0)
        elif name == "diffuse_over_pi":
            out[at] = np.take(compact["diffuse"], rows, axis=0) / np.pi
        elif name == "transport_diffuse":
            out[at] = (np.take(compact["diffuse"], rows, axis=0)
                       * np.take(table.layer_kept, material[at], axis=0)
                       + np.take(compact["translucent"], rows, axis=0))
        elif name == "transport_specular":
            layer = np.take(table.layer_albedo, material[at], axis=0)
            if table.has_lobe_inputs:    # a specular layer mixed in, or metal, per hit
                closure = np.take(table.layer_closure, material[at])
                mixed = np.flatnonzero(closure >= 0)
                pick = (np.take(rows, mixed), closure[mixed])
                layer[mixed] *= compact["ratio"][pick][:, None]
                layer[mixed] *= metal_factor("dielectric", compact["metallic"][pick],
                                             np.take(table.layer_metallic,
                                                     material[at][mixed]))[:, None]
                layer[mixed] *= transmission_factor("below", compact["transmission"][pick],
                                                    np.take(table.layer_transmission,
                                                            material[at][mixed]))[:, None]
            out[at] = np.take(compact["specular"], rows, axis=0) + layer
        else:
            raise KeyError(name)
        return out

    def _emission_slots(self) -> None:
        """The ``EMISSION_SLOTS``: the per-material rows, those of hits on materials whose
        emission is node-driven replaced by their per-hit values (both slots at once)."""
        table, material = self.table, self.material
        exitance = np.take(table.exitance, material, axis=0)
        prim, bu, bv = self.hits
        for material_id, at in self._textured_hits(table.textured_emission):
            exitance[at] = table.textures.exitance(material_id, prim[at], bu[at], bv[at],
                                                   self._view(material_id, at))
        self._cache["exitance"] = exitance
        self._cache["emitted_radiance"] = exitance / np.pi

    diffuse = property(lambda self: self._take("diffuse"))
    specular = property(lambda self: self._take("specular"))
    exitance = property(lambda self: self._take("exitance"))
    diffuse_over_pi = property(lambda self: self._take("diffuse_over_pi"))
    emitted_radiance = property(lambda self: self._take("emitted_radiance"))
    both_sides = property(lambda self: self._take("both_sides"))
    is_diffuse = property(lambda self: self._take("is_diffuse"))
    reflects_diffuse = property(lambda self: self._take("reflects_diffuse"))
    is_specular = property(lambda self: self._take("is_specular"))
    camera_glossy = property(lambda self: self._take("camera_glossy"))
    transport_diffuse = property(lambda self: self._take("transport_diffuse"))
    translucent = property(lambda self: self._take("translucent"))
    is_translucent = property(lambda self: self._take("is_translucent"))
    transport_specular = property(lambda self: self._take("transport_specular"))
    is_transport_specular = property(lambda self: self._take("is_transport_specular"))

    @property
    def lobe_inputs(self) -> "LobeInputs | None":
        """The lobes' per-hit inputs (``LobeInputs``: node-driven Mix Shader weights and
        Roughness), or None where no material here has any (the lobes made with the
        material's means are then exact)."""
        if self.hits is None or not self.table.has_lobe_inputs \
                or not self.table.lobe_textured[self.material].any():
            return None
        return LobeInputs(self._take("lobe_ratio"), self._take("lobe_roughness"),
                          self._take("lobe_metallic"), self._take("lobe_base"),
                          self._take("lobe_transmission"))


    def replace_diffuse(self, index, diffuse) -> None:
        """Set the diffuse reflectance (k, 3) of the hits ``index`` (and what follows from it:
        ``diffuse_over_pi``, ``transport_diffuse``): the camera's pixel-averaged texture
        (``integrator.supersample_textures``)."""
        for name in ("diffuse", "diffuse_over_pi", "transport_diffuse", "translucent"):
            self._take(name)
        cache = self._cache
        for name in ("diffuse", "diffuse_over_pi", "transport_diffuse"):
            cache[name] = np.array(cache[name], np.float64)
        keep = np.take(self.table.layer_kept, self.material[index], axis=0)
        cache["diffuse"][index] = diffuse
        cache["diffuse_over_pi"][index] = diffuse / np.pi
        cache["transport_diffuse"][index] = diffuse * keep + cache["translucent"][index]

    def subset(self, index) -> "SurfaceParams":
        """The parameters of the hits ``index`` (an index array or mask)."""
        out = SurfaceParams(self.table, self.material[index])
        if self.hits is not None:
            out.hits = tuple(h[index] for h in self.hits)
            out.directions = None if self.directions is None else self.directions[index]
            out.camera = None if self.camera is None else self.camera[index]
            out.ray = None if self.ray is None else {k: v[index] for k, v in self.ray.items()}
            # The parent's per-hit slots, indexed only when the subset reads them (most
            # subsets read a few of them).
            rows = np.arange(len(self.material))[index] if isinstance(index, slice) \
                else np.asarray(index)
            rows = np.flatnonzero(rows) if rows.dtype == bool else rows
            out._inherited = {k: (v, rows) for k, v in self._cache.items()
                              if k in TEXTURED_SLOTS}
            out._inherited.update((k, (array, np.take(parent_rows, rows)))
                                  for k, (array, parent_rows) in self._inherited.items()
                                  if k not in out._inherited)
            # The textures' values, for the slots the parent has not formed.
            if self._textured is None:
                out._textured = None
            elif self._textured is not False:
                position, compact = self._textured
                kept = np.take(position, rows)
                out._textured = (kept, compact) if (kept >= 0).any() else None
        return out

    def bsdf(self, transport: bool = False) -> "SurfaceBSDF":
        """The seed's BSDF at these hits; ``transport``: as photons and gather rays see it
        (``MaterialTable.transport_diffuse`` / ``transport_specular``)."""
        return SurfaceBSDF(self, transport)


@dataclass
class LobeInputs:
    """Per-hit inputs of the hits' lobes, N rows (``LobeInputs[index]`` takes rows):
    ``ratio`` (N, C) each closure's node-driven Mix Shader weight at the hit over its mean
    over the surface (what the material's lobes were made with; 1 without one), ``roughness``
    (N, C) each closure's node-driven Roughness at the hit (NaN: the lobe's own),
    ``metallic`` (N, C) and ``base`` (N, C, 3) a Principled BSDF's node-driven Metallic and
    Base Color (NaN: its mean): its metal lobe's weight and colour, its dielectric lobes'
    weight (``GlossyLobe.metal_part``), the glass lobe's tint; ``transmission`` (N, C) its
    node-driven Transmission Weight (NaN: its mean): the glass lobe's weight and the
    specular layer's below it (``transmission_part``)."""

    ratio: np.ndarray
    roughness: np.ndarray
    metallic: np.ndarray
    base: np.ndarray
    transmission: np.ndarray

    def __getitem__(self, index) -> "LobeInputs":
        return LobeInputs(self.ratio[index], self.roughness[index], self.metallic[index],
                          self.base[index], self.transmission[index])


# -- Lobes ----------------------------------------------------------------------------------------
class Lambertian:
    """f = rho / pi on the normal's side; cosine-weighted sampling (pdf cos / pi, Eq. 9.5)."""

    def __init__(self, reflectance: np.ndarray):
        self.reflectance = reflectance            # (N, 3)

    def subset(self, index) -> "Lambertian":
        return Lambertian(self.reflectance[index])

    def evaluate(self, wo, wi, n):
        same = np.einsum("ij,ij->i", wi, n) > 0
        return self.reflectance / np.pi * same[:, None]

    def sample(self, wo, n, u):
        wi = sampling.cosine_directions(n, u)
        cos = np.einsum("ij,ij->i", wi, n)
        return wi, self.reflectance, np.maximum(cos, 0.0) / np.pi

    def pdf(self, wo, wi, n):
        return np.maximum(np.einsum("ij,ij->i", wi, n), 0.0) / np.pi

    def albedo(self):
        return self.reflectance


class PerfectMirror:
    """A delta lobe: all of rho leaves in the mirror direction. ``evaluate`` and ``pdf`` are 0
    for any pair of directions (a delta has no density); ``sample`` returns the mirror
    direction with weight rho and pdf inf."""

    def __init__(self, reflectance: np.ndarray):
        self.reflectance = reflectance

    def subset(self, index) -> "PerfectMirror":
        return PerfectMirror(self.reflectance[index])

    def evaluate(self, wo, wi, n):
        return np.zeros((len(wi), 3))

    def sample(self, wo, n, u=None):
        return reflect(-wo, n), self.reflectance, np.full(len(wo), np.inf)

    def pdf(self, wo, wi, n):
        return np.zeros(len(wi))

    def albedo(self):
        return self.reflectance


class SurfaceBSDF:
    """The seed's material at hits: ``diffuse`` (Lambertian) + ``mirror`` (PerfectMirror).
    ``sample`` picks a lobe with the roulette's probabilities (normalised: a pick, not an
    absorption) and divides by that probability."""

    def __init__(self, params: SurfaceParams, transport: bool = False):
        self.params = params
        self.rho_d = params.transport_diffuse if transport else params.diffuse
        self.rho_s = params.transport_specular if transport else params.specular
        self.diffuse = Lambertian(self.rho_d)
        self.mirror = PerfectMirror(self.rho_s)

    def lobe_probabilities(self):
        """Russian roulette's (P_d, P_s) at each hit (``roulette_probabilities``)."""
        return roulette_probabilities(self.rho_d, self.rho_s)

    def absorption(self) -> np.ndarray:
        """The share of light a hit absorbs per channel, 1 - rho_d - rho_s, in [0, 1]."""
        return np.clip(1.0 - self.rho_d - self.rho_s, 0.0, 1.0)

    def evaluate(self, wo, wi, n):
        return self.diffuse.evaluate(wo, wi, n)

    def pdf(self, wo, wi, n):
        p_d, p_s = self.lobe_probabilities()
        total = np.where(p_d + p_s > 0, p_d + p_s, 1.0)
        return p_d / total * self.diffuse.pdf(wo, wi, n)

    def sample(self, wo, n, u_lobe, u):
        """(wi, weight, pdf, mirrored): lobe picked by ``u_lobe`` (N,) in proportion to the
        roulette's probabilities; hits that reflect nothing get weight 0."""
        p_d, p_s = self.lobe_probabilities()
        total = p_d + p_s
        share_d = np.divide(p_d, total, out=np.zeros_like(p_d), where=total > 0)
        mirrored = (u_lobe >= share_d) & (p_s > 0)
        wi, weight, pdf = self.diffuse.sample(wo, n, u)
        weight = np.divide(weight, share_d[:, None], out=np.zeros_like(weight),
                           where=share_d[:, None] > 0)
        pdf = pdf * share_d
        if mirrored.any():
            m = np.flatnonzero(mirrored)
            share_s = 1.0 - share_d[m]
            wi[m] = reflect(-wo[m], n[m])
            weight[m] = np.divide(self.rho_s[m], share_s[:, None],
                                  out=np.zeros((len(m), 3)), where=share_s[:, None] > 0)
            pdf[m] = np.inf
        return wi, weight, pdf, mirrored

    def albedo(self):
        return self.rho_d + self.rho_s


# -- Glossy materials seen by the camera (issue 23) ----------------------------------------------
@dataclass
class GlossyLobe:
    """One GGX reflection lobe of a material: ``weight`` (3,) times a ``MicrofacetReflection``
    (or ``SmoothReflection`` below ``DELTA_ALPHA2``) of widths (alpha_x, alpha_y) and a Fresnel
    made by ``make_fresnel(count)``; ``multiscatter`` is Cycles' Multiscatter GGX."""

    weight: np.ndarray
    alpha_x: float
    alpha_y: float
    make_fresnel: object
    multiscatter: bool
    depth: int = 0
    closure: int = -1           # the material's closure it comes from (``LobeInputs``)
    # How its closure's Roughness makes its widths: ("glossy" | "principled", anisotropy)
    # (``microfacet.alpha_glossy`` / ``alpha_principled``); None: not from a Roughness.
    roughness_map: tuple | None = None
    # In a Principled BSDF: "metal" (weight x Metallic, Fresnel from Base Color ``base_mean``)
    # or "dielectric" (weight x (1 - Metallic)), made at ``metallic_mean``; None elsewhere.
    metal_part: str | None = None
    metallic_mean: float = 0.0
    base_mean: np.ndarray | None = None
    # Below a Principled BSDF's transmission: "below" (weight x (1 - Transmission Weight)),
    # made at ``transmission_mean``; None elsewhere.
    transmission_part: str | None = None
    transmission_mean: float = 0.0
    transmits = False

    @property
    def delta(self) -> bool:
        return self.alpha_x * self.alpha_y < DELTA_ALPHA2

    def at(self, count: int, front=None, roughness=None, base=None):
        """The lobe at ``count`` hits (``front`` is for glass; a reflection ignores it);
        ``roughness`` (count,): its closure's Roughness per hit (NaN: its own widths). A lobe
        smooth at the mean stays smooth; a rough one keeps alpha^2 above ``DELTA_ALPHA2``.
        ``base`` (count, 3): a metal part's Base Color per hit (NaN: ``base_mean``)."""
        if base is not None and self.metal_part == "metal" and self.base_mean is not None:
            f0 = np.where(np.isnan(base), self.base_mean, np.clip(np.nan_to_num(base), 0, 1))
            fresnel = self.make_fresnel(count, f0=f0)
        else:
            fresnel = self.make_fresnel(count)
        if self.delta:
            return SmoothReflection(fresnel)
        ax, ay = np.full(count, self.alpha_x), np.full(count, self.alpha_y)
        if roughness is not None and self.roughness_map is not None:
            kind, aniso = self.roughness_map
            given = ~np.isnan(roughness)
            to_alpha = microfacet.alpha_principled if kind == "principled" \
                else microfacet.alpha_glossy
            hx, hy = to_alpha(np.where(given, roughness, 0.0), aniso)
            ax = np.where(given, np.maximum(hx, MIN_TEXTURED_ALPHA), ax)
            ay = np.where(given, np.maximum(hy, MIN_TEXTURED_ALPHA), ay)
        return MicrofacetReflection(ax, ay, fresnel, multiscatter=self.multiscatter)


@dataclass
class GlassLobe:
    """A dielectric interface of a material (Glass, Refraction, Principled Transmission):
    ``weight`` (3,) times a ``MicrofacetGlass`` of width ``alpha`` (``SmoothGlass`` below
    ``DELTA_ALPHA2``) with index ``ior`` inside over outside: a hit on the front face (the
    ray arriving from outside) refracts with eta = ior, one on the back face with 1 / ior.
    ``reflection_tint`` / ``transmission_tint`` (3,) colour the two branches; ``f0`` (3,) is
    the Principled remap of the Fresnel (None: the exact dielectric); ``film_thickness`` [nm]
    and ``film_ior`` a thin film over it (Cycles' interference: ``lobes._glass_fresnel``).
    Light samples reach only its reflection side (a light behind glass is not reachable by a
    shadow ray, in Cycles too); what it transmits of a light comes through its own rays."""

    weight: np.ndarray
    alpha: float
    ior: float
    reflection_tint: np.ndarray
    transmission_tint: np.ndarray
    f0: np.ndarray | None
    multiscatter: bool
    depth: int = 0
    closure: int = -1
    roughness_map: tuple | None = None      # ("glass",): alpha = Roughness^2
    metal_part: str | None = None           # "dielectric" in a Principled BSDF
    metallic_mean: float = 0.0
    film_thickness: float = 0.0             # Thin Film Thickness [nm]; 0: no film
    film_ior: float = 1.33                  # Thin Film IOR
    # A Principled BSDF's transmission: "glass" (weight x Transmission Weight), made at
    # ``transmission_mean``; None elsewhere.
    transmission_part: str | None = None
    transmission_mean: float = 0.0
    transmits = True

    @property
    def delta(self) -> bool:
        return self.alpha * self.alpha < DELTA_ALPHA2

    def at(self, count: int, front=None, roughness=None, base=None):
        """The lobe at ``count`` hits; ``roughness`` as ``GlossyLobe.at``; ``base`` (N, 3) a
        Principled BSDF's node-driven Base Color per hit (NaN where not driven): its
        transmission tint there, sqrt(clip(Base Color, 0, 1)) per crossing, as Cycles."""
        front = np.ones(count, bool) if front is None else np.asarray(front, bool)
        transmission_tint = self.transmission_tint
        if base is not None and self.metal_part == "dielectric":
            given = ~np.isnan(base[:, 0])
            if given.any():
                transmission_tint = np.where(given[:, None],
                                             np.sqrt(np.clip(np.nan_to_num(base), 0.0, 1.0)),
                                             self.transmission_tint)
        eta = np.where(front, float(self.ior), 1.0 / float(self.ior))
        film = None
        if self.film_thickness > 0:
            # Cycles: the film's index over the side the light comes from (a back face
            # divides it by the bulk index).
            film = (np.full(count, self.film_thickness),
                    np.where(front, self.film_ior, self.film_ior / float(self.ior)))
        if self.delta:
            return SmoothGlass(eta, self.reflection_tint, transmission_tint, self.f0, film)
        alpha = np.full(count, float(self.alpha))
        if roughness is not None and self.roughness_map is not None:
            given = ~np.isnan(roughness)
            r = np.clip(np.where(given, roughness, 0.0), 0.0, 1.0)
            alpha = np.where(given, np.maximum(r * r, MIN_TEXTURED_ALPHA), alpha)
        return MicrofacetGlass(alpha, eta, self.reflection_tint,
                               transmission_tint, self.f0, multiscatter=self.multiscatter,
                               film=film)


@dataclass
class SheenLobe:
    """Cycles' microfibre sheen (the Sheen BSDF node and the Principled BSDF's sheen):
    ``weight`` (3,) times a ``lobes.Sheen`` of ``roughness`` (Zeltner et al. 2022's LTC, our
    table measured from Cycles: ``tools/sheen_ltc_table.py``). Not sharp, not a delta."""

    weight: np.ndarray
    roughness: float
    depth: int = 0
    closure: int = -1
    roughness_map = None              # its own Roughness, not per hit
    metal_part = None
    transmission_part = None
    transmits = False
    sharp = False
    delta = False

    def at(self, count: int, front=None, roughness=None, base=None):
        return Sheen(np.full(count, self.roughness))


@dataclass
class TopLayer:
    """A layer Cycles' Principled BSDF puts over everything below it (``svm/closure.h``):
    the sheen, then the coat. ``lobe`` is its own lobe (its ``weight`` the closure's weight
    times ``share``); ``share`` (3,) its weight relative to the layers below (Sheen Weight x
    Sheen Tint, Coat Weight). The layers below are scaled by ``cover(wo, n)`` (N, 3): Cycles'
    ``closure_layering_weight``, clip(1 - max_channel(share x E(mu_o)), 0, 1) with E the lobe's
    directional albedo, times, for a coat, the tint's absorption along the refracted view ray,
    mix(1, tint^(1 / cos_t), Coat Weight) with cos_t = sqrt(1 - (1 - mu_o^2) / coat_ior^2)
    (Beer's law through a coat of unit thickness, normalised at normal incidence; Cycles takes
    the view direction's path alone)."""

    lobe: object
    share: np.ndarray
    tint: np.ndarray | None = None
    coat_weight: float = 0.0
    coat_ior: float = 1.5

    def cover(self, wo, n) -> np.ndarray:
        albedo = self.lobe.at(len(wo)).albedo(wo, n)
        out = np.clip(1.0 - (self.share[None, :] * albedo).max(axis=1), 0.0, 1.0)
        out = np.repeat(out[:, None], 3, axis=1)
        if self.tint is not None:
            mu = np.clip(np.einsum("ij,ij->i", wo, n), 0.0, 1.0)
            cos_t = np.sqrt(np.maximum(1.0 - (1.0 - mu * mu) / self.coat_ior ** 2, 1e-12))
            absorbed = np.maximum(self.tint, 0.0)[None, :] ** (1.0 / cos_t)[:, None]
            out *= 1.0 + self.coat_weight * (absorbed - 1.0)
        return out


@dataclass
class GlossyMaterial:
    """The glossy lobes of one material and, for a Principled BSDF, its layers: ``tops`` (the
    sheen and the coat, top first, ``TopLayer``) over everything, and the dielectric specular
    ``layer`` over the diffuse, which scales it by 1 - max_channel(E_layer(mu_o)) (Cycles'
    ``closure_layering_weight``; E the layer's directional albedo with its Fresnel and
    multiple-scattering compensation). A lobe of ``depth`` k lies below the first k tops:
    its weight is ``lobe.weight`` times their covers at the view direction."""

    lobes: list
    layer: GlossyLobe | None = None
    tops: list = field(default_factory=list)

    @property
    def layered(self) -> bool:
        """Whether anything below a layer depends on the view direction."""
        return self.layer is not None or bool(self.tops)

    def _covers(self, wo, n):
        """[1, cover_0, cover_0 cover_1, ...] (N, 3) each: what reaches depth k."""
        out = [np.ones((len(wo), 3))]
        for top in self.tops:
            out.append(out[-1] * top.cover(wo, n))
        return out

    def lobe_weights(self, wo, n, per_hit=None) -> list:
        """Each lobe's weight (N, 3) at view directions ``wo``: ``weight`` x the covers above,
        x its closure's ``per_hit.ratio`` where given (``LobeInputs``: a node-driven Mix
        Shader Fac's value at each hit over its mean)."""
        if not self.tops:
            out = [np.broadcast_to(lobe.weight, (len(wo), 3)) for lobe in self.lobes]
        else:
            covers = self._covers(wo, n)
            out = [lobe.weight[None, :] * covers[lobe.depth] for lobe in self.lobes]
        if per_hit is None:
            return out
        out = [w * per_hit.ratio[:, lobe.closure, None] if lobe.closure >= 0 else w
               for w, lobe in zip(out, self.lobes)]
        for j, lobe in enumerate(self.lobes):
            if lobe.metal_part is not None and lobe.closure >= 0:
                out[j] = out[j] * metal_factor(lobe.metal_part,
                                               per_hit.metallic[:, lobe.closure],
                                               lobe.metallic_mean)[:, None]
            if lobe.transmission_part is not None and lobe.closure >= 0:
                out[j] = out[j] * transmission_factor(lobe.transmission_part,
                                                      per_hit.transmission[:, lobe.closure],
                                                      lobe.transmission_mean)[:, None]
        return out

    def diffuse_factor(self, wo, n) -> np.ndarray:
        """(N, 3) the share of the diffuse below the layers at view directions ``wo``."""
        out = self._covers(wo, n)[-1] if self.tops else np.ones((len(wo), 3))
        if self.layer is not None:
            albedo = self.layer.at(len(wo)).layer_albedo(wo, n)
            out = out * np.clip(1.0 - albedo.max(axis=1), 0.0, 1.0)[:, None]
        return out

    def entries(self, count: int, wo, n, front=None, per_hit=None) -> list:
        """[(weight (N, 3), lobe at the hits, delta)] for ``count`` hits; ``per_hit``
        (``LobeInputs``): weights per hit (``lobe_weights``), and each lobe at its closure's
        per-hit Roughness where one is node-driven."""
        weights = self.lobe_weights(wo, n, per_hit)
        if per_hit is None:
            return [(w, lobe.at(count, front), lobe.delta)
                    for w, lobe in zip(weights, self.lobes)]
        return [(w, lobe.at(count, front, _roughness_of(lobe, per_hit),
                            None if lobe.closure < 0 else per_hit.base[:, lobe.closure]),
                 lobe.delta) for w, lobe in zip(weights, self.lobes)]


def _cosine_views(points: int = 64):
    mu = (np.arange(points) + 0.5) / points
    wo = np.stack([np.sqrt(1.0 - mu * mu), np.zeros(points), mu], axis=1)
    n = np.ascontiguousarray(np.broadcast_to([0.0, 0.0, 1.0], (points, 3)))
    return mu, wo, n


def material_averages(spec: GlossyMaterial, points: int = 64):
    """(diffuse share (3,), layered specular (3,)): the cosine-weighted means
    2 int_0^1 g(mu) mu dmu of the diffuse factor below the layers and of the layered lobes'
    albedo (the tops' lobes x the covers above them, plus the specular layer's), by the
    midpoint rule over ``points`` view cosines: what photons and gather rays see of a
    Principled BSDF's layers (``MaterialTable.transport_*``)."""
    mu, wo, n = _cosine_views(points)
    diffuse = 2.0 * (spec.diffuse_factor(wo, n) * mu[:, None]).mean(axis=0)
    covers = spec._covers(wo, n)
    specular = np.zeros(3)
    for k, top in enumerate(spec.tops):
        albedo = top.lobe.weight[None, :] * top.lobe.at(points).albedo(wo, n) * covers[k]
        specular += 2.0 * (albedo * mu[:, None]).mean(axis=0)
    if spec.layer is not None:
        albedo = spec.layer.at(points).albedo(wo, n) * spec.layer.weight[None, :] * covers[-1]
        specular += 2.0 * (albedo * mu[:, None]).mean(axis=0)
    return diffuse, specular


def layer_average(layer: GlossyLobe, points: int = 64) -> np.ndarray:
    """The cosine-weighted mean of a specular layer's directional albedo (3,), E_avg =
    2 int_0^1 E(mu) mu dmu, by the midpoint rule over ``points`` view cosines."""
    mu = (np.arange(points) + 0.5) / points
    wo = np.stack([np.sqrt(1.0 - mu * mu), np.zeros(points), mu], axis=1)
    n = np.broadcast_to([0.0, 0.0, 1.0], (points, 3))
    albedo = layer.at(points).albedo(wo, np.ascontiguousarray(n)) * layer.weight[None, :]
    return 2.0 * (albedo * mu[:, None]).mean(axis=0)


def _principled_tops(c, p):
    """The sheen and coat layers of a Principled closure (``TopLayer``s, top first), as
    ``svm/closure.h`` stacks them: sheen (Sheen Weight x Sheen Tint, the microfibre lobe of
    Sheen Roughness) over the coat (Coat Weight, GGX of alpha = Coat Roughness^2 with the
    dielectric Fresnel of Coat IOR and Multiscatter GGX, as Cycles always sets it up), over
    everything else."""
    tops = []
    sheen_weight = max(float(p["sheen_weight"]), 0.0)
    if sheen_weight > CLOSURE_WEIGHT_CUTOFF:
        share = sheen_weight * np.maximum(p["sheen_tint"], 0.0)
        tops.append(TopLayer(SheenLobe(c.weight * share, float(np.clip(p["sheen_roughness"], 0, 1)),
                                       depth=0), share))
    coat_weight = max(float(p["coat_weight"]), 0.0)
    if coat_weight > CLOSURE_WEIGHT_CUTOFF:
        coat_ior = max(float(p["coat_ior"]), 1.0)
        alpha = float(np.clip(p["coat_roughness"], 0, 1)) ** 2
        lobe = GlossyLobe(c.weight * coat_weight, alpha, alpha,
                          lambda n, eta=coat_ior: fresnel_model.DielectricFresnel(np.full(n, eta)),
                          True, depth=len(tops))
        tint = np.maximum(p["coat_tint"], 0.0)
        tops.append(TopLayer(lobe, np.full(3, coat_weight),
                             None if np.all(tint == 1.0) else tint, coat_weight, coat_ior))
    return tops


def _principled_lobes(c, lobes):
    """Cycles' Principled stack (``svm/closure.h``): sheen and coat over everything
    (``_principled_tops``), then metal (F82 tint), transmission (glass), then the dielectric
    specular layer over the diffuse; returns (layer, tops) (alpha is not rendered yet: export
    names it)."""
    p, weight = c.params, c.weight.copy()
    tops = _principled_tops(c, p)
    lobes.extend(top.lobe for top in tops)
    depth = len(tops)
    multiscatter = c.distribution in ("MULTI_GGX", "")
    ax, ay = (float(v) for v in microfacet.alpha_principled(p["roughness"], p["anisotropic"]))
    metallic = float(np.clip(p["metallic"], 0, 1))
    film = float(p["thin_film_thickness"])
    film = film if film > fresnel_model.THIN_FILM_CUTOFF else 0.0
    film_ior = max(float(p["thin_film_ior"]), 1e-5)
    if metallic > 0:
        f0 = np.clip(p["base_color"], 0, 1)
        tint = np.clip(p["specular_tint"], 0, 1)
        if film:
            make = (lambda n, f0=f0, tint=tint: fresnel_model.ThinFilmF82Fresnel(
                np.broadcast_to(f0, (n, 3)), np.broadcast_to(tint, (n, 3)), film, film_ior))
        else:
            make = (lambda n, f0=f0, tint=tint: fresnel_model.F82TintFresnel(
                np.broadcast_to(f0, (n, 3)), tint))
        lobes.append(GlossyLobe(weight * metallic, ax, ay, make, multiscatter, depth=depth,
                                metal_part="metal", metallic_mean=metallic, base_mean=f0))
        weight = weight * (1 - metallic)
    ior = max(float(p["ior"]), 1e-5)
    f0 = float(fresnel_model.f0_from_ior(ior))
    eta = ior
    if p["specular_ior_level"] != 0.5:
        f0 *= 2.0 * p["specular_ior_level"]
        root = np.sqrt(min(f0, 1.0 - 1e-9))
        eta = float((1 + root) / (1 - root))
        if ior < 1:
            eta = 1.0 / eta
    tinted = f0 * np.maximum(p["specular_tint"], 0)
    transmission = float(np.clip(p["transmission"], 0, 1))
    if transmission > 0 and np.any(weight > 0):
        # Cycles' Principled glass (``svm/closure.h``): IOR itself (Specular IOR Level remaps
        # the dielectric layer only), f0 = F0(IOR) x Specular Tint (kept only where it
        # differs from the exact dielectric), the reflection untinted and sqrt(Base Color)
        # on each crossing of the surface (twice for light through a solid object).
        plain = np.all(p["specular_tint"] == 1.0)
        glass_f0 = float(fresnel_model.f0_from_ior(ior)) * np.maximum(p["specular_tint"], 0)
        lobes.append(GlassLobe(weight * transmission, float(p["roughness"]) ** 2, ior,
                               np.ones(3), np.sqrt(np.clip(p["base_color"], 0, 1)),
                               None if plain else np.broadcast_to(glass_f0, (3,)).copy(),
                               multiscatter, depth=depth, metal_part="dielectric",
                               metallic_mean=metallic, film_thickness=film,
                               film_ior=film_ior, transmission_part="glass",
                               transmission_mean=transmission))
    weight = weight * (1 - transmission)
    if (eta == 1.0 and not film) or not np.any(weight > 0):
        return None, tops
    if film:
        # Cycles' dielectric under a film: the Airy reflectance over the substrate of index
        # eta, scaled towards f0 (``fresnel.ThinFilmDielectricFresnel``).
        make = (lambda n, eta=eta, tinted=tinted: fresnel_model.ThinFilmDielectricFresnel(
            np.full(n, eta), np.broadcast_to(tinted, (n, 3)), film, film_ior))
    else:
        make = (lambda n, eta=eta, tinted=tinted: fresnel_model.TintedDielectricFresnel(
            np.full(n, eta), np.broadcast_to(tinted, (n, 3))))
    layer = GlossyLobe(weight, ax, ay, make, multiscatter, depth=depth,
                       metal_part="dielectric", metallic_mean=metallic,
                       transmission_part="below", transmission_mean=transmission)
    lobes.append(layer)
    return layer, tops


def glossy_material(closures) -> GlossyMaterial | None:
    """The glossy and glass lobes of a material's closures (``engine/shaders.py``): Principled
    (metal, transmission and dielectric layer), Glossy (Fresnel = its colour), Metallic (F82
    tint or the physical conductor), Glass, Refraction and Transparent closures; None when
    there are none.
    Diffuse, emission and the rest stay with the seed's reduction (``shaders.seed_reduction``)."""
    lobes, layer, tops = [], None, []
    for index, c in enumerate(closures):
        if not np.any(c.weight > 0):
            continue
        first = len(lobes)
        p = c.params
        multiscatter = c.distribution in ("MULTI_GGX", "")
        if c.kind == "principled":
            found, found_tops = _principled_lobes(c, lobes)
            own = {id(top.lobe) for top in found_tops}        # coat and sheen: their own
            for lobe in lobes[first:]:                        # roughness, not Roughness
                if id(lobe) not in own:
                    lobe.roughness_map = (("glass",) if isinstance(lobe, GlassLobe) else
                                          ("principled", p["anisotropic"]))
            if found is not None or found_tops:
                if layer is not None or tops:
                    return None          # two layered Principled closures: not split yet
                layer, tops = found, found_tops
        elif c.kind == "glossy":
            ax, ay = (float(v) for v in microfacet.alpha_glossy(p["roughness"], p["anisotropy"]))
            color = np.clip(p["color"], 0, None)
            lobes.append(GlossyLobe(c.weight.copy(), ax, ay,
                                    lambda n, color=color: fresnel_model.ConstantFresnel(
                                        np.broadcast_to(color, (n, 3))),
                                    multiscatter, roughness_map=("glossy", p["anisotropy"])))
        elif c.kind == "metallic":
            ax, ay = (float(v) for v in microfacet.alpha_glossy(p["roughness"], p["anisotropy"]))
            film = max(float(p["thin_film_thickness"]), 1e-5)
            film = film if film > fresnel_model.THIN_FILM_CUTOFF else 0.0
            film_ior = max(float(p["thin_film_ior"]), 1e-5)
            if p["physical"] and film:
                make = (lambda n, ior=p["ior"], k=p["extinction"]:
                        fresnel_model.ThinFilmConductorFresnel(
                            np.broadcast_to(ior, (n, 3)), np.broadcast_to(k, (n, 3)), film,
                            film_ior))
            elif p["physical"]:
                make = (lambda n, ior=p["ior"], k=p["extinction"]:
                        fresnel_model.ConductorFresnel(np.broadcast_to(ior, (n, 3)),
                                                       np.broadcast_to(k, (n, 3))))
            elif film:
                make = (lambda n, f0=np.clip(p["base_color"], 0, 1),
                        tint=np.clip(p["edge_tint"], 0, 1):
                        fresnel_model.ThinFilmF82Fresnel(np.broadcast_to(f0, (n, 3)),
                                                         np.broadcast_to(tint, (n, 3)), film,
                                                         film_ior))
            else:
                make = (lambda n, f0=np.clip(p["base_color"], 0, 1),
                        tint=np.clip(p["edge_tint"], 0, 1):
                        fresnel_model.F82TintFresnel(np.broadcast_to(f0, (n, 3)), tint))
            lobes.append(GlossyLobe(c.weight.copy(), ax, ay, make, multiscatter,
                                    roughness_map=("glossy", p["anisotropy"])))
        elif c.kind == "sheen":
            # The Sheen BSDF node: the microfibre lobe (Cycles' default distribution).
            lobes.append(SheenLobe(c.weight * np.maximum(p["color"], 0),
                                   float(np.clip(p["roughness"], 0, 1))))
        elif c.kind in ("glass", "refraction"):
            # Glass: the colour tints both branches (it is the closure's weight in Cycles);
            # Refraction: the refracted branch alone, (1 - F) of the light.
            color = np.clip(p["color"], 0, None)
            reflection = color if c.kind == "glass" else np.zeros(3)
            film = float(p.get("thin_film_thickness", 0.0))
            film = film if c.kind == "glass" and film > fresnel_model.THIN_FILM_CUTOFF else 0.0
            lobes.append(GlassLobe(c.weight.copy(), float(p["roughness"]) ** 2,
                                   max(float(p["ior"]), 1e-5), reflection, color.copy(), None,
                                   multiscatter, roughness_map=("glass",), film_thickness=film,
                                   film_ior=max(float(p.get("thin_film_ior", 1.33)), 1e-5)))
        elif c.kind == "transparent":
            # Straight through, tinted by its colour: a smooth interface of index 1 that
            # reflects nothing (Cycles' Transparent BSDF; Principled Alpha < 1 mixes one in).
            lobes.append(GlassLobe(c.weight.copy(), 0.0, 1.0, np.zeros(3),
                                   np.clip(p["color"], 0, None).copy(), None, False))
        for lobe in lobes[first:]:
            lobe.closure = index
    if not lobes:
        return None
    return GlossyMaterial(lobes, layer, tops)


def diffuse_roughness(closures) -> float:
    """The Oren-Nayar roughness sigma of a material's diffuse: Principled Diffuse Roughness
    and Diffuse BSDF Roughness, averaged over its diffuse closures by the weight of their
    diffuse (one diffuse lobe per material: ``shaders.seed_reduction`` names a material whose
    diffuse closures differ)."""
    total = weighted = 0.0
    for c in closures:
        p = c.params
        if c.kind == "principled":
            share = (1 - float(np.clip(np.mean(p["metallic"]), 0, 1))) * \
                (1 - float(np.clip(np.mean(p["transmission"]), 0, 1)))
            sigma = float(np.mean(p["diffuse_roughness"]))
        elif c.kind == "diffuse":
            share, sigma = 1.0, float(np.mean(p["roughness"]))
        else:
            continue
        w = float(np.mean(c.weight)) * share
        total += w
        weighted += w * float(np.clip(sigma, 0, 1))
    return weighted / total if total > 0 else 0.0


class RoughDiffuseHits:
    """The hits of one camera-path vertex whose diffuse is Oren-Nayar (``MaterialTable.
    diffuse_sigma`` > 0; Cycles' model, ``lobes.OrenNayar``): ``index`` (k,) those hits among
    the vertex's N, ``row_of`` (N,) each hit's row in ``lobe`` (-1 elsewhere), ``lobe`` the
    k hits' lobe (their own diffuse colour per hit), ``wo``, ``n`` (k, 3) their view and
    shading normal. Direct light takes f(wo, wi) per light sample; light that reaches them
    through the irradiance estimates (cache, gather, photons, caustics) is taken as if it
    came evenly: ``indirect_factor`` (N, 3) the lobe's directional albedo over rho (1
    elsewhere) multiplies rho / pi x E."""

    def __init__(self, table: MaterialTable, surface: "SurfaceParams", wo, n):
        sigma = table.diffuse_sigma[surface.material]
        count = len(sigma)
        self.index = np.flatnonzero(sigma > 0)
        self.row_of = np.full(count, -1)
        self.row_of[self.index] = np.arange(len(self.index))
        rho = np.asarray(surface.diffuse, np.float64)[self.index]
        self.wo = np.asarray(wo, np.float64)[self.index]
        self.n = np.asarray(n, np.float64)[self.index]
        self.lobe = OrenNayar(rho, sigma[self.index])
        self.indirect_factor = np.ones((count, 3))
        with np.errstate(divide="ignore", invalid="ignore"):
            factor = self.lobe.albedo(self.wo, self.n) / rho
        self.indirect_factor[self.index] = np.where(rho > 0, np.nan_to_num(factor), 1.0)

    @property
    def count(self) -> int:
        return len(self.index)


def layer_diffuse_factor(table: MaterialTable, material_ids, wo, n) -> np.ndarray:
    """(N, 3) the share of the diffuse below each hit's Principled layers (sheen, coat,
    specular) at view directions ``wo`` (``GlossyMaterial.diffuse_factor``), 1 where the
    material has none."""
    out = np.ones((len(material_ids), 3))
    layered = [m for m in np.unique(material_ids)
               if table.glossy[m] is not None and table.glossy[m].layered]
    for material_id in layered:
        hits = np.flatnonzero(material_ids == material_id)
        out[hits] = table.glossy[material_id].diffuse_factor(wo[hits], n[hits])
    return out


def reflection_albedo(table: MaterialTable, material_ids, wo, n, per_hit=None) -> np.ndarray:
    """(N, 3) the summed directional albedo of each hit's glossy reflection lobes (glass lobes
    left out; sheen and coat with the covers above the lobes below) at view directions
    ``wo``: 0 where the material has none. ``per_hit``: the hits' ``LobeInputs``."""
    out = np.zeros((len(material_ids), 3))
    for material_id in np.unique(material_ids):
        spec = table.glossy[material_id]
        if spec is None:
            continue
        hits = np.flatnonzero(material_ids == material_id)
        rows = None if per_hit is None else per_hit[hits]
        for w, lobe, _delta in spec.entries(len(hits), wo[hits], n[hits], per_hit=rows):
            if not hasattr(lobe, "albedo_split"):
                out[hits] += w * lobe.albedo(wo[hits], n[hits])
    return out


def _share_factor(value, mean, complement: bool) -> np.ndarray:
    """(N,) what a lobe made at a Principled share's ``mean`` is scaled by at hits of
    ``value`` (N,) (NaN: the mean): value / mean, or with ``complement`` (1 - value) /
    (1 - mean)."""
    v = np.where(np.isnan(value), mean, value)
    if complement:
        return (1.0 - v) / np.maximum(1.0 - mean, 1e-12)
    return v / np.maximum(mean, 1e-12)


def metal_factor(part: str, metallic, mean) -> np.ndarray:
    """``_share_factor`` of Metallic: Metallic / mean for the "metal" part, (1 - Metallic) /
    (1 - mean) for a "dielectric" one (``GlossyLobe.metal_part``)."""
    return _share_factor(metallic, mean, part != "metal")


def transmission_factor(part: str, transmission, mean) -> np.ndarray:
    """``_share_factor`` of Transmission Weight: t / mean for the "glass" part, (1 - t) /
    (1 - mean) for the specular layer "below" it (``GlossyLobe.transmission_part``)."""
    return _share_factor(transmission, mean, part != "glass")


def _roughness_of(lobe, per_hit: LobeInputs):
    """(N,) the per-hit Roughness of ``lobe``'s closure (NaN where not node-driven), or None
    where the lobe does not take one."""
    if lobe.closure < 0 or lobe.roughness_map is None:
        return None
    r = per_hit.roughness[:, lobe.closure]
    return None if np.all(np.isnan(r)) else r


def lobe_shares(lobes, wo, n) -> np.ndarray:
    """(N, J) the probabilities with which ``sample_glossy`` picks each of the J lobes
    ``lobes`` ((weight (3,) or (N, 3), lobe at the N hits) pairs) at view directions ``wo``: the largest
    channel of weight x albedo(wo), normalised over the lobes (rows of 0 where none reflects)."""
    shares = np.stack([(w * lobe.albedo(wo, n)).max(axis=1) for w, lobe in lobes], axis=1)
    total = shares.sum(axis=1, keepdims=True)
    return np.divide(shares, total, out=np.zeros_like(shares), where=total > 0)


def sample_glossy(table: MaterialTable, material_ids, wo, n, rng, front=None,
                  with_delta: bool = False, per_hit=None, split_glass: bool = False):
    """One direction per hit on materials with glossy lobes (``table.glossy``), in the hits'
    order, grouped by material: a lobe picked in proportion to the largest channel of its
    weight x albedo(wo) (the weight with the covers of the layers above it;
    ``lobe_shares``), then sampled. Returns (wi (N, 3), weight (N, 3) = w f |cos| / (pdf P),
    pdf (N,) = P x the picked lobe's pdf [1/sr], inf for a delta lobe, 0 where nothing was
    sampled): each ray estimates its own lobe's light, so ``pdf`` is the density that
    multiple importance sampling weighs it by. ``wo``, ``n`` (N, 3) float64, ``n`` on wo's
    side; ``front`` (N,) whether each hit is on the front face (glass refracts into the
    object there; None: all are). ``with_delta``: also return delta (N,), whether the picked
    lobe is a delta (a mirror or smooth glass). ``per_hit``: the hits' ``LobeInputs``
    (per-hit Mix Shader weights and Roughness of the lobes; None: their means).
    ``split_glass``: where smooth glass (``lobes.SmoothGlass``) is picked, its ray reflects
    with weight w R F / P_lobe and a twin refracts with w T (1 - F) / P_lobe instead of one of
    them being picked (``SmoothGlass.branches``); the twins come last in the return value, as
    (rows (M,) into the hits, wi (M, 3), weight (M, 3)), pdf inf."""
    count = len(material_ids)
    twins = []
    wi_out = np.zeros((count, 3))
    weight_out = np.zeros((count, 3))
    pdf_out = np.zeros(count)
    delta_out = np.zeros(count, bool)
    for material_id in np.unique(material_ids):
        spec = table.glossy[material_id]
        hits = np.flatnonzero(material_ids == material_id)
        if spec is None:
            continue
        side = None if front is None else front[hits]
        wo_h, n_h = wo[hits], n[hits]
        lobes = spec.entries(len(hits), wo_h, n_h, side,
                             None if per_hit is None else per_hit[hits])
        shares = lobe_shares([(w, lobe) for w, lobe, _ in lobes], wo_h, n_h)
        total = shares.sum(axis=1)
        cdf = np.cumsum(shares, axis=1)
        pick = np.minimum((cdf < rng.random(len(hits))[:, None]).sum(axis=1), len(lobes) - 1)
        u = rng.random((len(hits), 3))
        for j, (w, lobe, delta) in enumerate(lobes):
            sel = np.flatnonzero((pick == j) & (total > 0))
            if len(sel) == 0:
                continue
            at = hits[sel]
            if split_glass and hasattr(lobe, "branches"):
                scale = w[sel] / shares[sel, j][:, None]
                (wi, weight), (wi_t, weight_t) = lobe.subset(sel).branches(wo_h[sel], n_h[sel])
                pdf = np.full(len(sel), np.inf)
                through = np.flatnonzero(np.any(weight_t > 0, axis=1))
                twins.append((at[through], wi_t[through],
                              np.nan_to_num(weight_t[through] * scale[through])))
            else:
                wi, weight, pdf = lobe.subset(sel).sample(wo_h[sel], n_h[sel], u[sel])
            wi_out[at] = wi
            weight_out[at] = np.nan_to_num(weight * w[sel] / shares[sel, j][:, None])
            pdf_out[at] = pdf * shares[sel, j]
            delta_out[at] = delta
    result = (wi_out, weight_out, pdf_out) + ((delta_out,) if with_delta else ())
    if split_glass:
        rows = [np.concatenate(parts) for parts in zip(*twins)] if twins else [
            np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))]
        result += (tuple(rows),)
    return result
