"""Textured materials: the per-hit values of shader inputs that nodes drive, and the seed's
material (rho_d, rho_s, M) they make at each hit.

What it computes
----------------
A Blender material drives shader inputs (Base Color, Emission Color, Roughness ...) with node
trees. Export (``engine/blender/export.py``) records each such input on its closure
(``shaders.Closure.textures``: parameter -> factors whose product is its value), keeps the
material's node graph (``scene.Material.graph``, an ``engine.nodes.Graph``) and puts on the
scene the per-corner coordinates the graphs read (``Scene.corner_attributes``: ``"uv"`` the
active render UV map (T, 3, 2), ``"uv:<name>"`` each UV map by name, ``"position"`` and
``"normal"`` object space (T, 3, 3), ``"generated"`` the mesh's texture-space coordinate
(T, 3, 3), ``"color"`` / ``"color:<name>"`` and ``"attr:<name>"`` colour and geometry
attributes as RGBA (T, 3, 4); float32). At a hit these are interpolated with the hit's barycentrics (corner
weights 1 - u - v, u, v, as ``surfaces.SceneSurfaces.normals`` uses them) and handed to
``nodes.evaluate``.

:class:`MaterialTextures` (one per ``bsdf.MaterialTable``):

``textured`` (M,) bool
    materials with at least one node-driven input.
``mean_closures[m]``
    the material's closures with each node-driven input replaced by its mean over the
    material's surface (``MEAN_SAMPLES`` area-uniform points, a fixed seed): what the
    per-material tables (the planner, roulette shares) and the glossy and glass lobes use.
``reduction(material_id, prim, bu, bv)`` -> (diffuse, specular, exitance) (k, 3) float64
    the seed's rho_d, rho_s and M (``shaders.seed_reduction``) at hits on triangles ``prim``
    of one material, clipped as export clips a material (negative values to 0, rho_d + rho_s
    scaled down to 1 where it exceeds 1); ``reflectance`` (rho_d, rho_s) and ``exitance`` (M)
    are its two halves, each evaluating only the node-driven inputs it reads
    (``EMISSION_PARAMS`` feed M and nothing else), so that a light sample or a photon leaving
    an emitter reads no albedo texture and a hit that needs the albedo no emission texture
    (``bsdf.SurfaceParams`` asks for each half when one of its slots is first read). A batch
    evaluates the material's graph once for all its inputs (``nodes.Evaluator``) and
    interpolates only the corner attributes its nodes read (:class:`HitInputs`).
``lookups_per_hit(material)`` -> (reflectance, emission) image look-ups per evaluation, for
    the cost estimate (``engine/estimate.py``).

A Mix Shader's node-driven Fac is a per-hit factor on the weights of the closures below it
(``Closure.textures[WEIGHT]``: Fac for the second shader, 1 - Fac, ``COMPLEMENT``, for the
first; :func:`weight_at`); export's static material takes the socket's own value
(:func:`default_weight`). The lobes (glossy, metal, glass, sheen, a Principled BSDF's) are
made once per material with the weight's mean and scaled at each hit by the weight there
over that mean (``with_ratios``).

What follows the texture at each hit, and what takes its mean
    The diffuse reflectance (camera shading, the photons' stored power and roulette, gather
    rays, the cache's records: all read ``bsdf.SurfaceParams.diffuse`` at their own hit), the
    specular share of the roulette, the exitance seen by rays and the Mix Shader weights of
    every lobe follow the texture exactly, and so do the lobes' Roughness, a Principled BSDF's
    Metallic, its Base Color (the metal's f0 and the transmission's tint) and its
    Transmission Weight (``bsdf.LobeInputs``). The lobes' other parameters (anisotropy, a
    coat's or sheen's) use the mean of their node-driven inputs; export names every such
    input in a warning (:func:`approximations`).

Light Path in a material: Is Camera Ray tells camera rays (the camera path's hits, also those
gone straight on through transparent surfaces, as Cycles keeps the flag) from all others
(photons, gather rays, cache records, light samples of emitters, reflections). Materials
whose node-driven inputs read a Light Path node (``light_path``) are evaluated with
``CAMERA_FLAG`` in their hit values: 1 where the caller says the hit is a camera ray's
(``bsdf.SurfaceParams(camera=...)``), 0 elsewhere; a mixed weight's mean is the larger of its
means for the two kinds of ray (so that the lobe exists for both and the per-hit ratio picks
it), the other inputs' means are a lighting ray's. Light Path's other outputs follow the ray
(``"ray:<output>"`` hit values, ``bsdf.SurfaceParams(ray=...)``): a camera ray's first hit
reads 0 in all of them; the camera path's reflections and refractions read Cycles' flags and
depths for the bounces they took (``ray_after_bounce``); gather rays and cache records'
rays read a diffuse bounce's (``DIFFUSE_RAY``: Is Diffuse Ray, Is Reflection Ray, Ray Depth
and Diffuse Depth 1), and after a mirror, glossy or glass surface that bounce's too;
photons read a diffuse bounce's at every hit (a photon does not know the path that will
see it); light samples of emitters read 0. Ray Length is each segment's length. A mixed weight's
mean is the largest over a lighting ray, a camera ray and one of each kind of camera-path
ray.

Conversions follow Cycles: a colour feeding a number by its luminance (``nodes.LUMA``), a
vector by the mean of its components, a number feeding a colour on all three channels.
Numbers are clipped to the ranges export clips the socket values to (``PARAM_RANGES``).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from . import nodes
from .shaders import CLOSURE_KINDS, seed_reduction

__all__ = ["MaterialTextures", "HitInputs", "approximations", "interpolate_corners",
           "WEIGHT", "COMPLEMENT", "WEIGHT_EXACT_KINDS", "default_weight", "weight_at",
           "lookups_per_hit", "EMISSION_PARAMS", "MEAN_SAMPLES", "CAMERA_FLAG", "DIFFUSE_RAY",
           "RAY_FLAGS", "RAY_DEPTHS", "STRAIGHT_ON", "ray_after_bounce",
           "PARAM_RANGES", "EXACT_PARAMS", "PER_TRIANGLE"]

# Area-uniform points per textured material for the means the lobes use.
MEAN_SAMPLES = 4096
# Parameter -> (low, high) as export clips the socket values (None: no bound).
PARAM_RANGES = {
    "metallic": (0.0, 1.0), "roughness": (0.0, 1.0), "alpha": (0.0, 1.0),
    "diffuse_roughness": (0.0, 1.0), "subsurface_weight": (0.0, 1.0),
    "anisotropic": (0.0, 1.0), "transmission": (0.0, 1.0), "coat_roughness": (0.0, 1.0),
    "sheen_roughness": (0.0, 1.0), "specular_ior_level": (0.0, None),
    "coat_weight": (0.0, None), "sheen_weight": (0.0, None),
    "thin_film_thickness": (0.0, None), "anisotropy": (-1.0, 1.0),
}
# The inputs the seed's exitance M reads (``shaders.seed_reduction``), closure kind -> its
# parameter; no other input changes M, and these change nothing else of the reduction.
EMISSION_KEY = {"principled": "emission", "emission": "radiance"}
EMISSION_PARAMS = set(EMISSION_KEY.items())
# (closure kind, parameter) pairs whose per-hit value is rendered exactly (see the module
# docstring); the others' lobes take their mean.
EXACT_PARAMS = {("principled", "base_color"), ("principled", "metallic"),
                ("principled", "transmission"), ("principled", "emission"),
                ("principled", "subsurface_weight"),
                ("diffuse", "color"), ("translucent", "color"), ("sheen", "color"),
                ("emission", "radiance")}


def interpolate_corners(corner: np.ndarray, prim, bu, bv) -> np.ndarray:
    """(N, k) float64: a (T, 3, k) per-corner attribute at hits on triangles ``prim`` with
    barycentrics (bu, bv)."""
    c = np.take(corner, prim, axis=0)
    u, v = np.asarray(bu, np.float64), np.asarray(bv, np.float64)
    w = 1.0 - u - v
    out = np.empty((c.shape[0], c.shape[2]))
    for k in range(c.shape[2]):        # a column at a time, widened to float64 as it goes
        out[:, k] = c[:, 0, k] * w + c[:, 1, k] * u + c[:, 2, k] * v
    return out


# ``Closure.textures`` key of a closure's per-hit weight: the node-driven Facs of the Mix
# Shaders above it (factors ``((node, output), constant)``, or ``((node, output, COMPLEMENT),
# constant)`` for 1 - Fac; ``constant`` the socket's own value, export's static guess).
WEIGHT = "weight"
COMPLEMENT = "complement"
# Closure kinds whose per-hit weight is all in the seed's rho_d, rho_t or M at the hit; the
# others' lobes are scaled per hit by the weight over its mean (``MaterialTextures.
# reflectance(with_ratios=True)``, ``bsdf.SurfaceParams.lobe_ratio``).
WEIGHT_EXACT_KINDS = ("diffuse", "emission", "translucent")

# Nodes whose outputs depend on the hit's view and world-space geometry (``nodes`` module
# docstring: "incoming", "normal_world", ...): materials whose inputs read them are evaluated
# with the hit's own ray (``MaterialTextures.view_at``).
VIEW_NODES = ("ShaderNodeFresnel", "ShaderNodeLayerWeight", "ShaderNodeNewGeometry")
# The hit value that tells a camera ray's hit (1) from any other ray's (0) to Light Path's Is
# Camera Ray (``nodes`` module docstring: ``"ray:<output>"``).
CAMERA_FLAG = "ray:Is Camera Ray"
# The Light Path values of a ray leaving a diffuse camera hit (Cycles' path flags after one
# diffuse reflection): what gather rays, cache records' rays and photons read, and the
# means of a material for lighting (``MaterialTextures._means``).
DIFFUSE_RAY = {"Is Diffuse Ray": 1.0, "Is Reflection Ray": 1.0, "Ray Depth": 1.0,
               "Diffuse Depth": 1.0}
# The other rays a camera path sends (``ray_after_bounce``), one of each kind, for the means:
# a glossy and a sharp reflection, a refraction.
_PATH_RAYS = (
    {"Is Glossy Ray": 1.0, "Is Reflection Ray": 1.0, "Ray Depth": 1.0, "Glossy Depth": 1.0},
    {"Is Glossy Ray": 1.0, "Is Singular Ray": 1.0, "Is Reflection Ray": 1.0, "Ray Depth": 1.0,
     "Glossy Depth": 1.0},
    {"Is Glossy Ray": 1.0, "Is Singular Ray": 1.0, "Is Transmission Ray": 1.0,
     "Ray Depth": 1.0, "Transmission Depth": 1.0})

# Light Path's flags and depths that a bounce changes (``ray_after_bounce``).
RAY_FLAGS = ("Is Diffuse Ray", "Is Glossy Ray", "Is Singular Ray", "Is Reflection Ray",
             "Is Transmission Ray")
RAY_DEPTHS = ("Ray Depth", "Diffuse Depth", "Glossy Depth", "Transmission Depth",
              "Transparent Depth")
# A bounce whose new direction has this cosine or more with the old one went on straight: a
# transparent surface, which changes no flag (Transparent Depth + 1).
STRAIGHT_ON = 1.0 - 1e-5


def ray_after_bounce(previous, directions, incoming, normals, singular) -> dict:
    """{Light Path output: (N,)} of N rays sent on by a glossy, mirror, glass or transparent
    surface, as Cycles' path state has them after that bounce: ``previous`` the values of
    the rays that arrived (``RAY_FLAGS`` and ``RAY_DEPTHS``; None or a missing one: 0, a
    camera ray's), ``directions`` / ``incoming`` (N, 3) the new and the arriving rays,
    ``normals`` (N, 3) the surfaces', ``singular`` (N,) bool where a delta lobe (mirror,
    smooth glass) sent the ray. A ray gone straight on (``STRAIGHT_ON``) keeps what it had,
    Transparent Depth + 1; any other is a glossy ray (Is Glossy Ray 1, Is Diffuse Ray 0, Is
    Singular Ray for a delta lobe), a reflection (Glossy Depth + 1) or a transmission
    (Transmission Depth + 1), Ray Depth + 1."""
    n = len(directions)
    before = {k: (np.zeros(n) if previous is None or k not in previous else
                  np.broadcast_to(np.asarray(previous[k], np.float64), (n,)))
              for k in RAY_FLAGS + RAY_DEPTHS}
    straight = np.einsum("ij,ij->i", directions, incoming) > STRAIGHT_ON
    through = np.einsum("ij,ij->i", directions, normals) < 0
    out = {"Is Diffuse Ray": np.zeros(n), "Is Glossy Ray": np.ones(n),
           "Is Singular Ray": np.asarray(singular, np.float64),
           "Is Reflection Ray": (~through).astype(np.float64),
           "Is Transmission Ray": through.astype(np.float64),
           "Ray Depth": before["Ray Depth"] + 1.0,
           "Diffuse Depth": before["Diffuse Depth"],
           "Glossy Depth": before["Glossy Depth"] + ~through,
           "Transmission Depth": before["Transmission Depth"] + through,
           "Transparent Depth": before["Transparent Depth"] + straight}
    return {k: (v if k == "Transparent Depth" else np.where(straight, before[k], v))
            for k, v in out.items()}


# Closure kinds whose lobes take a node-driven Roughness per hit (``bsdf.LobeInputs``).
LOBE_ROUGHNESS = ("glossy", "metallic", "glass", "refraction", "principled")

# Per-triangle attributes among ``Scene.corner_attributes``: taken, not interpolated.
PER_TRIANGLE = ("normal_matrix",)


class HitInputs(Mapping):
    """The per-hit coordinates ``nodes.evaluate`` reads at hits (prim, bu, bv): each corner
    attribute interpolated only when a node first asks for it, then kept (a per-triangle one,
    ``PER_TRIANGLE``, taken as it is); ``hit_values``: per-hit arrays given as they are (the
    world-space values of a camera hit: ``bsdf.MaterialTable.shading_normals``); with
    ``"bary_dx"`` / ``"bary_dy"`` (N, 2) among them, ``"dx:<key>"`` / ``"dy:<key>"`` are the
    corner attributes' changes across the hit's footprint (what Bump reads)."""

    def __init__(self, corners: dict, prim, bu, bv, hit_values: dict | None = None):
        self._corners, self._hits = corners, (prim, bu, bv)
        self._done = dict(hit_values or {})

    def __getitem__(self, key):
        if key not in self._done:
            axis, _, base = key.partition(":")
            if axis in ("dx", "dy") and base in self._corners and base not in PER_TRIANGLE \
                    and f"bary_{axis}" in self._done:
                # The attribute's change across the footprint: its barycentric derivative
                # (``bary_dx`` / ``bary_dy`` (N, 2): d(bu, bv) along the footprint's axes).
                c = np.take(self._corners[base], self._hits[0], axis=0).astype(np.float64)
                duv = self._done[f"bary_{axis}"]
                self._done[key] = (duv[:, :1] * (c[:, 1] - c[:, 0])
                                   + duv[:, 1:] * (c[:, 2] - c[:, 0]))
                return self._done[key]
            if key in PER_TRIANGLE:
                self._done[key] = np.take(self._corners[key], self._hits[0],
                                          axis=0).astype(np.float64)
            else:
                self._done[key] = interpolate_corners(self._corners[key], *self._hits)
        return self._done[key]

    def __contains__(self, key):
        axis, _, base = key.partition(":")
        if axis in ("dx", "dy") and f"bary_{axis}" in self._done:
            return base in self._corners and base not in PER_TRIANGLE
        return key in self._corners or key in self._done

    def __iter__(self):
        return iter(set(self._corners) | set(self._done))

    def __len__(self):
        return len(set(self._corners) | set(self._done))


def _as_param(value: np.ndarray, kind_default, graph, socket) -> np.ndarray:
    """A node output (N,) or (N, 3) as a parameter of the default's shape (Cycles' implicit
    conversions: colour -> number by luminance, vector -> number by the mean)."""
    value = np.asarray(value, np.float64)
    if isinstance(kind_default, tuple):
        return np.repeat(value[:, None], 3, axis=1) if value.ndim == 1 else value
    if value.ndim == 2:
        out_kind = graph.nodes[socket[0]].outputs.get(socket[1], "VALUE")
        return value @ nodes.LUMA if out_kind == "RGBA" else value.mean(axis=1)
    return value


def _clip(param: str, value):
    low, high = PARAM_RANGES.get(param, (None, None))
    if low is None and high is None:
        return value
    return np.clip(value, low, high)


def param_at(evaluator: "nodes.Evaluator", graph, kind: str, param: str, factors) -> np.ndarray:
    """The per-hit value (N,) or (N, 3) of one node-driven parameter: the product of its
    factors, each a node output (of ``evaluator``, one batch of hits on ``graph``) or a
    constant."""
    default = CLOSURE_KINDS[kind][param]
    n = evaluator.n
    value = None
    for socket, constant in factors:
        if socket is None:
            part = np.asarray(constant, np.float64)
        else:
            part = _as_param(evaluator.value(tuple(socket)), default, graph, socket)
        value = part if value is None else value * part
    if isinstance(default, tuple):
        value = np.broadcast_to(value, (n, 3))
    else:
        value = np.broadcast_to(value, (n,))
    return _clip(param, np.array(value, np.float64))


def default_weight(closure) -> float:
    """The product of a closure's node-driven weight factors at their sockets' own values
    (what export's static material uses); 1 without any."""
    return float(np.prod([constant for _socket, constant in closure.textures.get(WEIGHT, ())]))


def weight_at(evaluator: "nodes.Evaluator", graph, factors) -> np.ndarray:
    """(N,) the per-hit factor on a closure's weight: the product of its Mix Shader Facs
    (``WEIGHT`` factors), each node output taken as a number (a colour by its luminance),
    clamped to [0, 1] as Cycles clamps a Mix Shader's Fac, and its complement 1 - Fac for
    the Mix's first shader (``COMPLEMENT``)."""
    out = np.ones(evaluator.n)
    for socket, _constant in factors:
        fac = _as_param(evaluator.value(tuple(socket[:2])), 0.0, graph, socket[:2])
        fac = np.clip(np.broadcast_to(fac, (evaluator.n,)), 0.0, 1.0)
        out = out * (1.0 - fac if socket[2:] == (COMPLEMENT,) else fac)
    return out


def _upstream(graph, node: str) -> set:
    """Names of ``node`` and every node linked into it, directly or not."""
    into = {}
    for (to_node, _), (from_node, _) in graph.links.items():
        into.setdefault(to_node, []).append(from_node)
    seen, stack = set(), [node]
    while stack:
        name = stack.pop()
        if name not in seen:
            seen.add(name)
            stack.extend(into.get(name, ()))
    return seen


def _reads_nodes(material, graph, kinds=VIEW_NODES) -> bool:
    """Whether any node-driven input of ``material`` reads a node of ``kinds`` (by default
    the ``VIEW_NODES``)."""
    if graph is None:
        return False
    upstream = set()
    for c in material.closures:
        for factors in c.textures.values():
            for socket, _constant in factors:
                if socket is not None:
                    upstream |= _upstream(graph, socket[0])
    return any(name in graph.nodes and graph.nodes[name].type in kinds
               for name in upstream)


def lookups_per_hit(material) -> tuple[int, int]:
    """(reflectance, emission): the image look-ups one per-hit evaluation of the material's
    node-driven (rho_d, rho_s) and M makes (``MaterialTextures.reflectance`` /
    ``exitance``): the Image Texture nodes with an image upstream of the inputs each part
    reads; a part driven by other nodes only (procedural textures, coordinates) counts 1,
    an undriven part 0. What the cost estimate counts (``engine/estimate.py``)."""
    graph = getattr(material, "graph", None)
    if graph is None:
        return 0, 0
    parts = {"reflectance": set(), "emission": set()}
    driven = {"reflectance": False, "emission": False}
    for c in material.closures:
        for param, factors in c.textures.items():
            kinds = (("reflectance", "emission") if param == WEIGHT else
                     ("emission",) if (c.kind, param) in EMISSION_PARAMS else ("reflectance",))
            for socket, _constant in factors:
                if socket is not None:
                    for part in kinds:
                        driven[part] = True
                        parts[part] |= _upstream(graph, socket[0])
    out = []
    for part in ("reflectance", "emission"):
        images = sum(1 for name in parts[part] if name in graph.nodes
                     and graph.nodes[name].type == "ShaderNodeTexImage"
                     and graph.nodes[name].props.get("image") in graph.images)
        out.append(max(images, 1) if driven[part] else 0)
    return out[0], out[1]


def approximations(closures) -> list[str]:
    """What a material's node-driven inputs lose (one message each, naming the node and the
    input): inputs of glossy and glass lobes take their mean over the surface."""
    out = []
    for c in closures:
        for param in c.textures:
            if param == WEIGHT or (c.kind, param) in EXACT_PARAMS:
                continue
            if param == "roughness" and c.kind in LOBE_ROUGHNESS:
                continue                      # per hit (``bsdf.LobeInputs``)
            if c.kind == "principled" and param in ("base_color", "transmission"):
                continue
            out.append(f"{param.replace('_', ' ').title()} of '{c.node}' is driven by nodes; "
                       "its glossy and glass lobes use its mean over the surface (per-hit "
                       "values reach the diffuse, the emission and the roulette only)")
    return out


class MaterialTextures:
    """The node-driven inputs of a scene's materials (module docstring)."""

    def __init__(self, scene):
        self.scene = scene
        self.corners = dict(getattr(scene, "corner_attributes", None) or {})
        self.graphs = [getattr(m, "graph", None) for m in scene.materials]
        self.textured = np.array([g is not None and any(c.textures for c in m.closures)
                                  for m, g in zip(scene.materials, self.graphs)], bool)
        # Materials with a lobe-bearing closure (not ``WEIGHT_EXACT_KINDS``) that a
        # node-driven Mix Shader Fac weighs per hit.
        self.lobe_weighted = np.array([t and any(WEIGHT in c.textures and c.kind not in
                                                 WEIGHT_EXACT_KINDS for c in m.closures)
                                       for m, t in zip(scene.materials, self.textured)], bool)
        # Materials whose lobes' Roughness is node-driven (per hit: ``LOBE_ROUGHNESS``).
        self.lobe_roughness = np.array([t and any("roughness" in c.textures and c.kind in
                                                  LOBE_ROUGHNESS for c in m.closures)
                                        for m, t in zip(scene.materials, self.textured)], bool)
        # Materials with a Principled BSDF whose Metallic, Base Color or Transmission Weight
        # is node-driven: its metal lobe's weight and colour, its glass lobe's weight and
        # tint, and its dielectric lobes' weight, per hit. Base Color reaches the lobes only
        # through a metal or glass part: driven alone, under a Metallic and a Transmission
        # Weight of 0, it leaves them as they are (and the hits need no per-hit inputs).
        self.lobe_principled = np.array([t and any(c.kind == "principled" and (
            "metallic" in c.textures or "transmission" in c.textures
            or ("base_color" in c.textures and (np.any(c.params.get("metallic", 0.0) > 0)
                                                or np.any(c.params.get("transmission", 0.0)
                                                          > 0))))
            for c in m.closures)
            for m, t in zip(scene.materials, self.textured)], bool)
        # Materials whose node-driven inputs read the view (``VIEW_NODES``).
        self.view_inputs = np.array([t and _reads_nodes(m, g) for m, g, t in
                                     zip(scene.materials, self.graphs, self.textured)], bool)
        # Materials whose node-driven inputs read Light Path (``CAMERA_FLAG``).
        self.light_path = np.array([t and _reads_nodes(m, g, ("ShaderNodeLightPath",))
                                    for m, g, t in zip(scene.materials, self.graphs,
                                                       self.textured)], bool)
        self.any = bool(self.textured.any())
        self.mean_closures = [tuple(m.closures) for m in scene.materials]
        self.mean_reduction = {}
        for material_id in np.flatnonzero(self.textured):
            self._means(int(material_id))

    def view_at(self, prim, bu, bv, directions=None) -> dict:
        """The world-space hit values ``VIEW_NODES`` read at hits (prim, bu, bv) of rays
        travelling along ``directions`` (N, 3) (Cycles' shader data: the normals turned to
        the side the ray arrives from, ``incoming`` = -direction, ``backfacing`` 1 on the
        back side). Without directions the view is along the normal (normal incidence: what
        a cache record, a light sample of an emitter and the surface means read)."""
        scene = self.scene
        tri = np.take(scene.triangles, prim, axis=0).astype(np.float64)
        bu, bv = np.asarray(bu, np.float64), np.asarray(bv, np.float64)
        weights = np.stack([1.0 - bu - bv, bu, bv], axis=1)
        position = np.einsum("nk,nkj->nj", weights, tri)
        ng = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        ng /= np.maximum(np.linalg.norm(ng, axis=1, keepdims=True), 1e-300)
        ns = ng
        if getattr(scene, "shading_normals", None) is not None:
            corner = np.take(scene.shading_normals, prim, axis=0).astype(np.float64)
            ns = np.einsum("nk,nkj->nj", weights, corner)
            ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-300)
        if directions is None:
            return {"normal_world": ns, "true_normal_world": ng, "incoming": ns.copy(),
                    "backfacing": np.zeros(len(prim)), "position_world": position}
        d = np.asarray(directions, np.float64)
        back = np.einsum("ij,ij->i", ng, d) > 0
        sign = np.where(back, -1.0, 1.0)[:, None]
        return {"normal_world": ns * sign, "true_normal_world": ng * sign, "incoming": -d,
                "backfacing": back.astype(np.float64), "position_world": position}

    def inputs(self, prim, bu, bv) -> HitInputs:
        """The per-hit coordinates ``nodes.evaluate`` reads, at hits (prim, bu, bv)
        (interpolated when first read)."""
        return HitInputs(self.corners, prim, bu, bv)

    def shading_normal(self, material_id: int, prim, bu, bv, hit_values: dict) -> np.ndarray:
        """(k, 3) the world-space normal that the material's node-driven Normal
        (``Material.shading_normal``, a Normal Map) gives at hits (prim, bu, bv) on its
        triangles; ``hit_values``: the hits' world-space inputs (``nodes`` module docstring:
        "normal_world", "true_normal_world", "incoming", "backfacing", "position_world", and
        for Bump the footprint "dPdx", "dPdy" with its barycentric "bary_dx", "bary_dy")."""
        material = self.scene.materials[material_id]
        inputs = HitInputs(self.corners, prim, bu, bv, hit_values)
        return np.asarray(nodes.evaluate(material.graph, tuple(material.shading_normal),
                                         inputs, len(prim)), np.float64)

    def closures_at(self, material_id: int, prim, bu, bv, part: str = "all",
                    hit_values: dict | None = None) -> list:
        """The material's closures with per-hit parameters at hits (prim, bu, bv); the
        material's graph is evaluated once for all of them (each node once). ``part``:
        "all", or "reflectance" / "emission" for only the node-driven inputs that the seed's
        (rho_d, rho_s) / M read (``EMISSION_PARAMS``; the others keep their means).
        ``hit_values``: the hits' view (:meth:`view_at`), for materials whose inputs read it
        (``view_inputs``; without it, the view along the normal), and ``CAMERA_FLAG`` (N,)
        for those that read Light Path (without it, 0: not a camera ray)."""
        graph = self.graphs[material_id]
        if self.view_inputs[material_id] and (hit_values is None
                                              or "incoming" not in hit_values):
            hit_values = {**self.view_at(prim, bu, bv), **(hit_values or {})}
        if self.light_path[material_id] and (hit_values is None
                                             or CAMERA_FLAG not in hit_values):
            hit_values = {**(hit_values or {}), CAMERA_FLAG: np.zeros(len(prim))}
        evaluator = nodes.Evaluator(graph, HitInputs(self.corners, prim, bu, bv, hit_values),
                                    len(prim))
        out = []
        for c in self.scene.materials[material_id].closures:
            wanted = [param for param in c.textures if param != WEIGHT and (
                part == "all" or ((c.kind, param) in EMISSION_PARAMS) == (part == "emission"))]
            if not wanted and WEIGHT not in c.textures:
                out.append(c)
                continue
            params = dict(c.params)
            for param in wanted:
                params[param] = param_at(evaluator, graph, c.kind, param, c.textures[param])
            hit = c.at_hits(params)
            if WEIGHT in c.textures:
                hit.weight = c.weight * weight_at(evaluator, graph, c.textures[WEIGHT])[:, None]
            out.append(hit)
        return out

    def reduction(self, material_id: int, prim, bu, bv):
        """(diffuse, specular, exitance) (k, 3) at hits on triangles ``prim`` of material
        ``material_id`` with barycentrics (bu, bv), clipped as export clips materials."""
        diffuse, specular = self.reflectance(material_id, prim, bu, bv)
        return diffuse, specular, self.exitance(material_id, prim, bu, bv)

    def reflectance(self, material_id: int, prim, bu, bv, with_translucent: bool = False,
                    with_ratios: bool = False, hit_values: dict | None = None):
        """(diffuse, specular) (k, 3) of :meth:`reduction` alone: only the node-driven inputs
        that they read are evaluated (an emission texture is not); ``with_translucent``: also
        the translucent closures' rho_t (``shaders.SeedMaterial.translucent``). Where
        rho_d + rho_s + rho_t exceeds 1 in a channel, all three are scaled down together.
        ``with_ratios``: also (k, C) each closure's weight at the hit over its weight in
        ``mean_closures`` (1 for closures without a node-driven weight; 0 where the mean is
        0), by which its glossy and glass lobes are scaled per hit, (k, C) the Roughness of
        closures whose lobes take it per hit, (k, C) a Principled BSDF's Metallic, (k, C, 3)
        its Base Color and (k, C) its Transmission Weight where nodes drive them (NaN
        elsewhere). ``hit_values``: see
        :meth:`closures_at`."""
        n = len(prim)
        closures = self.closures_at(material_id, prim, bu, bv, "reflectance", hit_values)
        seed = seed_reduction(closures)
        diffuse, specular, translucent = (np.maximum(np.broadcast_to(x, (n, 3)), 0.0)
                                          for x in (seed.diffuse, seed.specular,
                                                    seed.translucent))
        total = (diffuse + specular + translucent).max(axis=1, keepdims=True)
        scale = 1.0 / np.maximum(total, 1.0)
        out = (diffuse * scale, specular * scale)
        if with_translucent:
            out += (translucent * scale,)
        if with_ratios:
            ratios = np.ones((n, len(closures)))
            roughness = np.full((n, len(closures)), np.nan)
            metallic = np.full((n, len(closures)), np.nan)
            base = np.full((n, len(closures), 3), np.nan)
            transmission = np.full((n, len(closures)), np.nan)
            originals = self.scene.materials[material_id].closures
            for j, (c, mean) in enumerate(zip(closures, self.mean_closures[material_id])):
                if WEIGHT in originals[j].textures:
                    top = float(np.max(mean.weight))
                    hit = np.broadcast_to(c.weight, (n, 3)).max(axis=1)
                    ratios[:, j] = hit / top if top > 0 else 0.0
                if "roughness" in originals[j].textures and c.kind in LOBE_ROUGHNESS:
                    roughness[:, j] = np.broadcast_to(c.params["roughness"], (n,))
                if c.kind == "principled" and "metallic" in originals[j].textures:
                    metallic[:, j] = np.broadcast_to(c.params["metallic"], (n,))
                if c.kind == "principled" and "base_color" in originals[j].textures:
                    base[:, j] = np.broadcast_to(c.params["base_color"], (n, 3))
                if c.kind == "principled" and "transmission" in originals[j].textures:
                    transmission[:, j] = np.clip(np.broadcast_to(c.params["transmission"],
                                                                 (n,)), 0.0, 1.0)
            out += ((ratios, roughness, metallic, base, transmission),)
        return out

    def exitance(self, material_id: int, prim, bu, bv, hit_values: dict | None = None):
        """The exitance (k, 3) of :meth:`reduction` alone (what emitters and photons leaving
        them read): only the emission inputs are evaluated, summed as ``seed_reduction``
        sums them (M = pi x emission x the closure's weight)."""
        n = len(prim)
        out = np.zeros((n, 3))
        for c in self.closures_at(material_id, prim, bu, bv, "emission", hit_values):
            key = EMISSION_KEY.get(c.kind)
            if key is not None:
                out += c.weight * (np.pi * np.asarray(c.params[key], np.float64))
        return np.maximum(out, 0.0)

    def textured_part(self, part: str) -> np.ndarray:
        """(M,) bool: materials with a node-driven input that ``part`` ("reflectance",
        "emission") reads."""
        out = np.zeros(len(self.textured), bool)
        for m in np.flatnonzero(self.textured):
            out[m] = any(param == WEIGHT or ((c.kind, param) in EMISSION_PARAMS)
                         == (part == "emission")
                         for c in self.scene.materials[m].closures for param in c.textures)
        return out

    def _means(self, material_id: int) -> None:
        """Fill ``mean_closures`` and ``mean_reduction`` of one textured material from
        ``MEAN_SAMPLES`` area-uniform points on its triangles."""
        scene = self.scene
        tris = np.flatnonzero(scene.material_ids == material_id)
        material = scene.materials[material_id]
        if len(tris) == 0:
            return
        t = scene.triangles[tris].astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        rng = np.random.default_rng(0)
        cdf = np.cumsum(area)
        pick = np.minimum(np.searchsorted(cdf, rng.random(MEAN_SAMPLES) * cdf[-1],
                                          side="right"), len(tris) - 1)
        su = np.sqrt(rng.random(MEAN_SAMPLES))
        v = rng.random(MEAN_SAMPLES)
        bu, bv = su * (1.0 - v), su * v            # area-uniform barycentrics
        prim = tris[pick]
        lighting = None
        if self.light_path[material_id]:
            lighting = {f"ray:{k}": np.full(len(prim), v) for k, v in DIFFUSE_RAY.items()}
        closures = self.closures_at(material_id, prim, bu, bv, hit_values=lighting)
        seen = []
        if self.light_path[material_id]:
            # What camera rays and the rays of camera paths meet: a closure mixed in for them
            # alone gets its lobe too.
            seen = [self.closures_at(material_id, prim, bu, bv, hit_values=values)
                    for values in [{CAMERA_FLAG: np.ones(len(prim))}] + [
                        {f"ray:{k}": np.full(len(prim), v) for k, v in ray.items()}
                        for ray in _PATH_RAYS]]
        means = []
        for c, original in zip(closures, material.closures):
            if not original.textures:
                means.append(original)
                continue
            params = dict(original.params)
            for param in original.textures:
                if param == WEIGHT:
                    continue
                value = np.mean(c.params[param], axis=0)
                params[param] = tuple(float(x) for x in value) if np.ndim(value) else \
                    float(value)
            mean = original.scaled(1.0)
            if WEIGHT in original.textures:        # the mixed weight's mean over the surface
                mean.weight = np.mean(np.broadcast_to(c.weight, (len(prim), 3)), axis=0)
                for other in seen:
                    mean.weight = np.maximum(mean.weight, np.mean(np.broadcast_to(
                        other[len(means)].weight, (len(prim), 3)), axis=0))
            mean.params = {k: (np.asarray(v, np.float64) if isinstance(v, tuple) else v)
                           for k, v in params.items()}
            means.append(mean)
        self.mean_closures[material_id] = tuple(means)
        d, s, e = self.reduction(material_id, prim, bu, bv)
        self.mean_reduction[material_id] = (d.mean(axis=0), s.mean(axis=0), e.mean(axis=0))
