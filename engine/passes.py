"""Render passes: what the renderer computed, as images beside Combined (issue 5; seed 12).

What it computes
    The diagnostic passes, each an (H, W, 3) float32 image of the render window, row 0 at the
    top, from the maps a render built (``pipeline.render(..., passes=...)`` calls these after
    the camera stage; Direct, Indirect and Emission come straight from the camera batches):

    ==============  ===============  ======================================================
    ``--passes``    pass (EXR layer)  what it shows
    ==============  ===============  ======================================================
    direct          Direct            exact direct light (``full`` mode)
    indirect        Indirect          indirect light: cache, gather or photon map
                                      (``full`` mode)
    emission        Emission          emitters and the world seen from the camera or in
                                      mirrors
    photon-map      PhotonMap         the seed's direct view of the photon map (9.5, Fig.
                                      12.6): the k-nearest estimate times rho_d / pi at the
                                      first hit of each pixel's centre
    cache-points    CachePoints       each irradiance-cache record visible from the camera
                                      as a white dot (1.0) on black (Fig. 12.4)
    photons         Photons           each stored photon visible from the camera as a dot of
                                      its own colour (power / its largest channel: white
                                      photons are white, the blue wall's blue) on black
                                      (Fig. 12.5)
    shadow-classes  ShadowClasses     shadow-photon classes at each pixel centre's first
                                      hit: green = lit, red = penumbra, blue = umbra, each
                                      the share of the shadow-photon lights in that class
                                      (several lights mix); black where no light has
                                      shadow photons or the surface is not diffuse
    cache-usage     CacheUsage        per pixel, the share of its indirect look-ups
                                      interpolated from records (green) and gathered afresh
                                      because no record covered them (red)
    ==============  ===============  ======================================================

    Cycles' light passes (below), summed by the camera stage: by the
    kind of each path's first bounce (Diff: diffuse; Gloss: glossy lobes, mirrors and glass
    reflecting; Trans: glass transmitting), light after one bounce (Dir) and after more
    (Ind), each divided by the first hit's albedo of that kind (Col), as Cycles writes them:

    =====================  ========  ===============================================
    ``--passes``           pass      what it shows
    =====================  ========  ===============================================
    diffuse-direct         DiffDir   diffuse first bounce, light after one bounce / DiffCol
    diffuse-indirect       DiffInd   diffuse first bounce, light after more / DiffCol
    diffuse-color          DiffCol   first hit's rho_d (x share under a Principled layer)
    glossy-direct          GlossDir  as Diff*, glossy first bounce
    glossy-indirect        GlossInd
    glossy-color           GlossCol  first hit's reflected albedo (glossy lobes, rho_s)
    transmission-direct    TransDir  as Diff*, glass transmitting at the first bounce
    transmission-indirect  TransInd
    transmission-color     TransCol  first hit's transmitted albedo (glass lobes)
    emit                   Emit      emitters seen from the camera (Cycles' Emission)
    environment            Env       the world seen from the camera (Cycles' Environment)
    =====================  ========  ===============================================

    Combined = Direct + Indirect + Emission (to float rounding) in ``full`` mode; in
    ``photon-map`` mode Combined = PhotonMap-like estimate (held in Indirect) + Emission.
    Combined = (DiffDir + DiffInd) DiffCol + (GlossDir + GlossInd) GlossCol + (TransDir +
    TransInd) TransCol + Emit + Env (to float rounding), Cycles' split; Lanterna's own
    Direct / Indirect / Emission split by estimator instead (emitters seen in mirrors are
    Emission there, Glossy Direct here). Where an image world with a sun hands its smooth
    sky to the final gather (``lights.EnvironmentLight.gather_sky``), that sky's light comes
    with the cache's irradiance, in channels of its own (``indirect.FinalGather.channels``),
    and is filed as direct light, as the sun's: Diffuse Direct (and Direct) at the first hit.

Cycles' light passes (issue 23, item 5)
    Each camera path carries a label, the kind of its first bounce (``DIFFUSE`` 0,
    ``GLOSSY`` 1, ``TRANSMISSION`` 2), and every contribution the path makes goes to that
    kind, as in Cycles (``kernel/film/light_passes.h``):

    * light that reaches the camera after exactly one bounce is Direct: at the first hit,
      the direct light of light samples (diffuse: Diffuse; glossy lobes: Glossy), and the
      emitters, lights' glints and the world met by the ray that leaves the first hit
      (a mirror, glossy or glass ray: Glossy, or Transmission where it went through);
    * everything later is Indirect: the indirect estimate and caustics at the first hit
      (the diffuse part: Diffuse; the glossy lobes' part where the path ends there, by
      each lobe's albedo: Glossy for reflection, Transmission for what glass passes),
      and all light shaded at the second and later hits (Glossy or Transmission after a
      mirror, glossy or glass first bounce);
    * emitters seen from the camera go to Emit, the world seen from the camera to Env.

    The Color passes are the first hit's albedo per kind (Cycles' ``surface_shader_diffuse``
    / ``_glossy`` / ``_transmission``), mean over a pixel's samples: Diffuse rho_d times the
    share left under a Principled specular layer; Glossy the reflection lobes' directional
    albedo at wo (metal, Glossy, the Principled layer, glass's reflected branch) plus the
    seed's mirror rho_s; Transmission the glass lobes' transmitted albedo. As Cycles writes
    them, the Direct and Indirect passes are the light divided by the Color (0 where the
    Color is 0), so that, to float rounding,

        Combined = sum over kinds of (Dir + Ind) x Col + Emit + Env.

    In ``photon-map`` mode the photon map's estimate at a diffuse first hit (all its light)
    goes to Diffuse Indirect. Light samples at a glossy hit reach only its reflection side,
    so Transmission Direct holds the emitters and world seen through glass in one crossing.

    ``LIGHT_PASSES`` maps ``--passes`` names to pass names (Blender's own: ``DiffDir``,
    ``DiffInd``, ``DiffCol``, ``GlossDir`` ... ``TransCol``, ``Emit``, ``Env``);
    ``LightSums(pixels, samples)`` collects one camera batch ((pixels, 3) sums, radiance
    [W m^-2 sr^-1] x samples, colours x samples); ``light_pass_images`` divides them into
    the passes.

    Cost: nothing when no light pass is asked for (the camera then makes no ``LightSums``):
    when asked, one label per path, the glass lobes' albedo split at the first hit, and a
    few (pixels, 3) sums.

Parameters
    ``hits``: ``CentreHits`` of the pixel centres (one ray per pixel through its centre);
    ``k`` photons per estimate and ``max_radius`` [m] as the render used them.

Visibility of points (cache records, photons): a point is drawn when the ray from the camera
towards it first meets a surface within ``VISIBLE_TOLERANCE`` x its distance of it (points
lie on surfaces, so the ray stops at them or at an occluder in front).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import pixel_rays
from .shadow_photons import LIT, PENUMBRA, UMBRA

DIFFUSE, GLOSSY, TRANSMISSION = 0, 1, 2
KIND_PREFIX = ("Diff", "Gloss", "Trans")
KIND_WORDS = ("diffuse", "glossy", "transmission")
DIRECT, INDIRECT = 0, 1

# --passes name -> pass name (Cycles' / Blender's render pass names)
LIGHT_PASSES = {f"{word}-{part}": f"{prefix}{suffix}"
                for word, prefix in zip(KIND_WORDS, KIND_PREFIX)
                for part, suffix in (("direct", "Dir"), ("indirect", "Ind"), ("color", "Col"))}
LIGHT_PASSES.update({"emit": "Emit", "environment": "Env"})
LIGHT_PASS_NAMES = tuple(LIGHT_PASSES.values())


PASSES = {
    "direct": "Direct",
    "indirect": "Indirect",
    "emission": "Emission",
    "photon-map": "PhotonMap",
    "cache-points": "CachePoints",
    "photons": "Photons",
    "shadow-classes": "ShadowClasses",
    "cache-usage": "CacheUsage",
    **LIGHT_PASSES,
}
PASS_NAMES = tuple(PASSES.values())
VISIBLE_TOLERANCE = 1e-3
LIT_RGB, PENUMBRA_RGB, UMBRA_RGB = (0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)


def parse_passes(text) -> tuple[str, ...]:
    """``"direct,indirect"`` (or a list, or ``"all"``) -> pass names (``("Direct",
    "Indirect")``); an unknown name raises ValueError listing the known ones."""
    if text is None or text == "":
        return ()
    items = text.split(",") if isinstance(text, str) else list(text)
    items = [str(i).strip() for i in items if str(i).strip()]
    if items == ["all"]:
        return PASS_NAMES
    by_name = {**PASSES, **{v.lower(): v for v in PASS_NAMES}, **{v: v for v in PASS_NAMES}}
    out = []
    for item in items:
        key = by_name.get(item) or by_name.get(item.lower())
        if key is None:
            raise ValueError(f"unknown pass {item!r}; passes are {', '.join(PASSES)} or all")
        if key not in out:
            out.append(key)
    return tuple(out)


@dataclass
class CentreHits:
    """First hits of one ray per window pixel through the pixel's centre."""

    pixel: np.ndarray        # (n,) window pixel index (row-major, top row first) of each hit
    x: np.ndarray            # (n, 3) hit position [m]
    ns: np.ndarray           # (n, 3) shading normal, towards the camera
    ng: np.ndarray           # (n, 3) geometric normal, towards the camera
    surface: object          # bsdf.SurfaceParams at the hits
    diffuse: np.ndarray      # (n,) bool: the material reflects diffusely
    shape: tuple             # (H, W) of the window


def centre_hits(scene, accel, surfaces) -> CentreHits:
    """First hits of one ray per window pixel through its centre (``surfaces``: the scene's
    ``surfaces.SceneSurfaces``)."""
    width, height = scene.camera.window_size
    origins, directions, tmax = pixel_rays(scene.camera, 0, width * height, 1,
                                           np.random.default_rng(0), centres=True)
    t_hit, prim, bu, bv = accel.intersect(origins, directions, tmax)
    hit = np.nonzero(prim >= 0)[0]
    t_hit, prim, bu, bv, d = t_hit[hit], prim[hit], bu[hit], bv[hit], directions[hit]
    x = origins[hit] + t_hit[:, None] * d
    ng, ns, _front = surfaces.normals(prim, bu, bv, d)
    surface = surfaces.params(prim, bu, bv, d)
    return CentreHits(pixel=hit, x=x, ns=ns, ng=ng, surface=surface,
                      diffuse=surface.is_diffuse, shape=(height, width))


def diagnostic_passes(wanted, scene, settings, maps, usage) -> dict:
    """The passes of ``wanted`` made from the maps after the camera stage (all but Direct,
    Indirect and Emission): ``maps`` is the render's ``preparation.Prepared`` (accel,
    surfaces, lights, photon map and its radius and filter, shadow map, cache) and ``usage``
    the camera's Cache usage shares."""
    shape = scene.camera.window_size[::-1]
    out = {}
    hits = None
    if {"PhotonMap", "ShadowClasses"} & set(wanted):
        hits = centre_hits(scene, maps.accel, maps.surfaces)
    if "PhotonMap" in wanted:
        # All stored photons (in full mode with the photon map at the hit the map keeps only
        # the photons that bounced, so the view shows indirect light there).
        out["PhotonMap"] = photon_map_view(hits, maps.photon_map, settings.photon_k,
                                           maps.radius or np.inf, 0, maps.cone)
    if "ShadowClasses" in wanted:
        out["ShadowClasses"] = shadow_classes_image(hits, maps.shadow_map,
                                                    range(len(maps.lights.sampled)))
    if "Photons" in wanted:
        out["Photons"] = photons_image(scene.camera, maps.accel, maps.photon_map, shape)
    if "CachePoints" in wanted:
        out["CachePoints"] = cache_points_image(scene.camera, maps.accel, maps.cache, shape)
    if "CacheUsage" in wanted:
        out["CacheUsage"] = cache_usage_image(usage, shape)
    return out


def photon_map_view(hits: CentreHits, photon_map, k, max_radius, min_bounces,
                    cone_filter=None) -> np.ndarray:
    """The seed's direct view of the photon map (9.5): L = rho_d / pi * E_k at each pixel
    centre's first diffuse hit (E_k: the k-nearest estimate, Eq. 9.11, counting photons of
    at least ``min_bounces`` bounces)."""
    h, w = hits.shape
    image = np.zeros((h * w, 3), np.float32)
    d = np.nonzero(hits.diffuse)[0]
    if len(d) and photon_map is not None and len(photon_map):
        e = photon_map.irradiance(hits.x[d], hits.ng[d], k=k, max_radius=max_radius,
                                  min_bounces=min_bounces, cone_filter=cone_filter)
        image[hits.pixel[d]] = e * hits.surface.diffuse_over_pi[d]
    return image.reshape(h, w, 3)


def shadow_classes_image(hits: CentreHits, shadow_map, light_indices) -> np.ndarray:
    """Green / red / blue shares of the lights in ``light_indices`` (indices in
    ``lights.sampled`` that the shadow-photon map covers) for which each pixel centre's
    first diffuse hit is lit / penumbra / umbra."""
    h, w = hits.shape
    image = np.zeros((h * w, 3), np.float32)
    lights = [li for li in light_indices if shadow_map is not None and shadow_map.covers(li)]
    d = np.nonzero(hits.diffuse)[0]
    if not lights or not len(d):
        return image.reshape(h, w, 3)
    colours = {LIT: np.array(LIT_RGB, np.float32), PENUMBRA: np.array(PENUMBRA_RGB, np.float32),
               UMBRA: np.array(UMBRA_RGB, np.float32)}
    acc = np.zeros((len(d), 3), np.float32)
    for li in lights:
        cls = shadow_map.classify(hits.x[d], hits.ns[d], li)
        for value, rgb in colours.items():
            acc[cls == value] += rgb
    image[hits.pixel[d]] = acc / len(lights)
    return image.reshape(h, w, 3)


def project_to_window(camera, points: np.ndarray):
    """Window pixel (row-major, top row first; -1 outside the window or behind the camera)
    and distance [m] from the camera (its eye, or for an orthographic camera its plane) of each
    world-space point: the inverse of ``camera.pixel_rays``' pixel-centre mapping."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    local = camera.to_camera_space(p)             # camera space: looks along -z
    full_w, full_h = camera.resolution
    if camera.panorama:                           # frame coordinates in [0, 1]
        ok = np.linalg.norm(local, axis=1) > camera.clip_start
        u, v = camera.panorama_coordinates(local)
    else:
        depth = -local[:, 2]
        ok = depth > camera.clip_start
        lx, ly = local[:, 0], local[:, 1]
        if not camera.orthographic:               # on the plane at unit distance
            safe = np.where(ok, depth, 1.0)
            lx, ly = lx / safe, ly / safe
        u = (lx - (camera.shift_x - camera.tan_half_x)) / (2 * camera.tan_half_x)
        v = (ly - (camera.shift_y - camera.tan_half_y)) / (2 * camera.tan_half_y)
    px, py = np.floor(u * full_w), np.floor(v * full_h)
    x0, y0, x1, y1 = camera.border
    ok &= (px >= x0) & (px < x1) & (py >= y0) & (py < y1)
    win_w, win_h = x1 - x0, y1 - y0
    col = px - x0
    row = (win_h - 1) - (py - y0)
    pixel = np.where(ok, row * win_w + col, -1).astype(np.int64)
    return pixel, camera.rays_to(p)[2]


def visible_points(camera, accel, points: np.ndarray):
    """(window pixel, mask of visible points): projection plus an occlusion ray each."""
    pixel, _dist = project_to_window(camera, points)
    inside = np.nonzero(pixel >= 0)[0]
    visible = np.zeros(len(pixel), bool)
    if len(inside):
        origins, d, dist_in = camera.rays_to(np.asarray(points, np.float64)[inside])
        t, prim, _u, _v = accel.intersect(origins.astype(np.float32), d.astype(np.float32),
                                          None)
        reach = dist_in * (1.0 - VISIBLE_TOLERANCE) - 1e-6
        visible[inside] = (prim < 0) | (t >= reach)
    return pixel, visible


def points_image(camera, accel, points: np.ndarray, colours, shape) -> np.ndarray:
    """An image of black with each visible point as one pixel of its colour ((n, 3) or one
    RGB); where several points fall in one pixel the last one listed is kept."""
    h, w = shape
    image = np.zeros((h * w, 3), np.float32)
    if len(points):
        pixel, visible = visible_points(camera, accel, points)
        keep = np.nonzero(visible)[0]
        colours = np.broadcast_to(np.asarray(colours, np.float32), (len(points), 3))
        image[pixel[keep]] = colours[keep]
    return image.reshape(h, w, 3)


def photons_image(camera, accel, photon_map, shape) -> np.ndarray:
    """Fig. 12.5: the stored photons visible from the camera, each a dot of its colour:
    power / its own largest channel (so every dot is bright, whatever its power)."""
    if photon_map is None or not len(photon_map):
        return np.zeros(shape + (3,), np.float32)
    power = np.asarray(photon_map.power, np.float32)
    peak = np.maximum(power.max(axis=1, keepdims=True), np.float32(1e-30))
    return points_image(camera, accel, photon_map.positions, power / peak, shape)


def cache_points_image(camera, accel, cache, shape) -> np.ndarray:
    """Fig. 12.4: every irradiance-cache record visible from the camera as a white dot."""
    if cache is None or not len(cache):
        return np.zeros(shape + (3,), np.float32)
    return points_image(camera, accel, cache.positions, (1.0, 1.0, 1.0), shape)


def cache_usage_image(usage: np.ndarray | None, shape) -> np.ndarray:
    """Per pixel: red = share of its look-ups gathered afresh, green = share interpolated,
    from the camera batches' (pixels, 2) counts (interpolated, gathered) per sample."""
    h, w = shape
    image = np.zeros((h * w, 3), np.float32)
    if usage is not None:
        total = usage.sum(axis=1)
        asked = total > 0
        image[asked, 1] = usage[asked, 0] / total[asked]
        image[asked, 0] = usage[asked, 1] / total[asked]
    return image.reshape(h, w, 3)


# -- Cycles' light passes (issue 23, item 5) ----------------------------------------------
class LightSums:
    """One camera batch's sums for the light passes: ``light`` (kind, Direct/Indirect,
    pixels, 3), ``color`` (kind, pixels, 3), ``emit`` and ``env`` (pixels, 3); each
    contribution added per sample (pixel = sample // samples), to the kind its caller names
    (after the first bounce, each path's first-bounce kind, which the integrator carries per
    ray: a sample split at smooth glass has a reflected and a refracted path)."""

    def __init__(self, pixels: int, samples: int):
        self.samples = samples
        self.light = np.zeros((3, 2, pixels, 3))
        self.color = np.zeros((3, pixels, 3))
        self.emit = np.zeros((pixels, 3))
        self.env = np.zeros((pixels, 3))

    def _add(self, target, sample, values):
        pixel = np.asarray(sample) // self.samples
        for c in range(3):
            target[:, c] += np.bincount(pixel, weights=values[:, c], minlength=len(target))

    def add(self, sample, values, direct: bool, kind):
        """Add ``values`` (n, 3) of samples ``sample`` (n,) to the Direct (``direct``) or
        Indirect pass of ``kind``: an int for all, or (n,) one per value."""
        slot = DIRECT if direct else INDIRECT
        if len(values) == 0:
            return
        if np.ndim(kind) == 0:
            self._add(self.light[kind, slot], sample, values)
            return
        kinds = np.asarray(kind)
        for k in range(3):
            sel = kinds == k
            if sel.any():
                self._add(self.light[k, slot], sample[sel], values[sel])

    def add_color(self, sample, kind: int, values):
        """The first hit's albedo ``values`` (n, 3) of ``kind`` at samples ``sample``."""
        self._add(self.color[kind], sample, values)

    def add_seen(self, sample, values, world: bool):
        """Emitters (``world`` False: Emit) or the world (Env) seen from the camera."""
        self._add(self.env if world else self.emit, sample, values)

    def stacked(self) -> np.ndarray:
        """The sums as one (11, pixels, 3) array, in the order of ``LIGHT_PASS_NAMES``
        before division (Dir, Ind, Col per kind, then Emit, Env), divided by samples."""
        rows = []
        for k in range(3):
            rows += [self.light[k, DIRECT], self.light[k, INDIRECT], self.color[k]]
        return np.stack(rows + [self.emit, self.env]) / self.samples


def light_pass_images(stacked: np.ndarray, wanted) -> dict:
    """(11, pixels, 3) means (``LightSums.stacked``) -> {pass name: (pixels, 3) float32} for
    the names of ``wanted``: Dir and Ind divided by Col per channel, 0 where Col is 0."""
    out = {}
    for k, prefix in enumerate(KIND_PREFIX):
        direct, indirect, color = stacked[3 * k: 3 * k + 3]
        for suffix, value in (("Dir", direct), ("Ind", indirect)):
            if f"{prefix}{suffix}" in wanted:
                out[f"{prefix}{suffix}"] = np.divide(
                    value, color, out=np.zeros_like(value), where=color > 0).astype(np.float32)
        if f"{prefix}Col" in wanted:
            out[f"{prefix}Col"] = color.astype(np.float32)
    for index, name in ((9, "Emit"), (10, "Env")):
        if name in wanted:
            out[name] = stacked[index].astype(np.float32)
    return out
