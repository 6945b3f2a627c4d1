"""The internal scene: inert numpy arrays and small dataclasses, no ``bpy``.

Everything the renderer needs and nothing more. Exporters (``engine/blender/export.py``)
and tests build a :class:`Scene`; the stages only read it.

Units are SI and radiometric, following the seed (section 3 and the table of symbols, 16.2)
and Blender's conventions as measured against Cycles (DESIGN.md section 3):

==================  ==========================================================================
quantity            meaning
==================  ==========================================================================
positions           metres, world space, Z up (Blender's)
``diffuse``         diffuse reflectance rho_d per RGB channel, in [0, 1]; BRDF rho_d / pi
``specular``        perfect specular reflectance rho_s per channel, in [0, 1]
``exitance``        radiant exitance M [W/m^2] per channel; radiance L = M / pi per emitting side
point ``flux``      radiant flux Phi [W] per channel; E = Phi cos(theta) / (4 pi r^2) (Eq. 7.1)
point ``radius``    metres; a sphere (or facing disk) light of radiance Phi / (4 pi^2 R^2)
sun ``irradiance``  W/m^2 at normal incidence per channel
area ``power``      W per channel; one-sided Lambertian, L = P / (pi A)
world ``radiance``  W m^-2 sr^-1 per channel, a uniform environment
==================  ==========================================================================

Triangles are stored as a float32 array ``(T, 3, 3)`` (triangle, corner, xyz) with per-corner
shading normals of the same shape, a material id and an object id per triangle. Surfaces are
two-sided; the geometric normal is turned towards the incoming ray at shading time. Textured
materials read per-corner coordinates (``corner_attributes``: UV maps, object-space position
and normal, generated coordinates, colour and geometry attributes; ``engine/textures.py``)
through ``Material.graph``.

:func:`Scene.validate` checks shapes, dtypes and values and drops triangles that cannot be
traced (NaN or infinite corners, zero area), counting them in ``warnings``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Material", "PointLight", "SpotLight", "SunLight", "AreaLight", "World", "Camera", "Scene",
    "SceneError",
]


class SceneError(ValueError):
    """Raised for input that cannot be rendered; the message names the object and the problem."""


# Embree intersects in float32 and multiplies three coordinates together: beyond about
# cbrt(3.4e38) = 7e12 m its products overflow and rays miss (measured: a ray from 1e11 m
# hits a triangle with corners at 1e12 m; one from 1e12 m misses a triangle with corners at
# 1e13 m; at 1e19 m every ray misses). Triangles with a corner farther out are skipped.
MAX_COORDINATE = 1e12
# Powers, exitances, reflectances: a photon's power, k of them summed over a disc of radius
# r and the pixels are float32 (3.4e38). Measured: a 1e36 W light still renders exactly
# (linear in the power), 1e38 W is 18 % off, 1e40 W gives inf and NaN. 1e30 keeps 1e8 of
# headroom, the factor 1 / r^2 of a light 1e-4 m from a surface.
MAX_VALUE = 1e30
# Area lights with sides further apart than this are skipped (``Scene.validate``).
MAX_AREA_ASPECT = 1e6


def _rgb(value, name: str, what: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{name}: {what} is not finite ({arr.tolist()})")
    if np.any(arr < 0):
        raise SceneError(f"{name}: {what} is negative ({arr.tolist()})")
    if np.any(arr > MAX_VALUE):
        raise SceneError(f"{name}: {what} {arr.tolist()} is beyond {MAX_VALUE:g}, where the "
                         "renderer's float32 arithmetic overflows")
    return arr


def _vec3(value, name: str, what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{name}: {what} is not finite ({arr.tolist()})")
    return arr


def _unit(value, name: str, what: str) -> np.ndarray:
    arr = _vec3(value, name, what)
    norm = np.linalg.norm(arr)
    if norm < 1e-12:
        raise SceneError(f"{name}: {what} has zero length")
    return arr / norm


@dataclass
class Material:
    """The seed's three radiometric properties (section 3.2)."""

    name: str
    diffuse: np.ndarray = field(default_factory=lambda: np.full(3, 0.8))
    specular: np.ndarray = field(default_factory=lambda: np.zeros(3))
    exitance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    emit_both_sides: bool = True  # Cycles emits from both faces of an emissive mesh
    # The Blender shader's weighted closures (``engine/shaders.py``), kept for the material
    # system and the Material panel; the three properties above are what is rendered today.
    closures: tuple = ()
    # The node graph (``engine.nodes.Graph``) that node-driven closure inputs read
    # (``Closure.textures``; ``engine/textures.py``); None when no input is node-driven.
    graph: object = None
    # The graph socket (node name, output) of a node-driven Normal (a Normal Map), the
    # world-space shading normal at camera hits (``bsdf.MaterialTable.shading_normals``).
    shading_normal: tuple | None = None

    def __post_init__(self):
        self.diffuse = _rgb(self.diffuse, self.name, "diffuse reflectance")
        self.specular = _rgb(self.specular, self.name, "specular reflectance")
        self.exitance = _rgb(self.exitance, self.name, "radiant exitance")


def _share(value, name: str) -> float:
    """A light's photon share: a finite weight >= 0 (1 = photons in proportion to flux)."""
    try:
        share = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{name}: photon share {value!r} is not a number") from None
    if not (np.isfinite(share) and share >= 0):
        raise SceneError(f"{name}: photon share {value!r} must be a finite number >= 0")
    return share


def _radius(value, name: str) -> float:
    """A point / spot light's radius [m]: a finite number >= 0."""
    try:
        radius = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{name}: radius {value!r} is not a number") from None
    if not (np.isfinite(radius) and radius >= 0):
        raise SceneError(f"{name}: radius {value!r} m must be a finite number >= 0")
    return radius


@dataclass
class PointLight:
    """Isotropic point light of radiant flux ``flux`` [W] (seed 3.3.1, Eq. 7.1).

    ``radius`` [m] (default 0: a point, hard shadows) is Blender's Radius
    (``shadow_soft_size``). With ``radius`` R > 0 the light has a size, as in Cycles 4.x/5.x,
    with radiance L = Phi / (4 pi^2 R^2) (Cycles: Phi / (pi x sphere area)):
    * ``soft_falloff`` False: a Lambertian sphere of radius R; its flux is Phi and outside it
      E = Phi cos(theta) / (4 pi d^2) wherever the whole sphere is above the horizon;
    * ``soft_falloff`` True (default, Blender's Soft Falloff default): a disk of radius R
      facing each shading point, so E = Phi cos(theta) / (4 pi (d^2 + R^2)) on its axis.
    Both cast soft shadows. ``soft_falloff`` is ignored when ``radius`` is 0.
    ``camera_visible`` (Blender's Visibility > Camera; off by default, as for a new light in
    Blender): camera rays see a light with a radius, as in Cycles.
    """

    name: str
    position: np.ndarray
    flux: np.ndarray
    photon_share: float = 1.0
    radius: float = 0.0
    soft_falloff: bool = True
    camera_visible: bool = False

    def __post_init__(self):
        self.position = _vec3(self.position, self.name, "position")
        self.flux = _rgb(self.flux, self.name, "flux")
        self.photon_share = _share(self.photon_share, self.name)
        self.radius = _radius(self.radius, self.name)
        self.soft_falloff = bool(self.soft_falloff)
        self.camera_visible = bool(self.camera_visible)


@dataclass
class SpotLight:
    """A point light masked to a cone, as Blender's spot: same intensity Phi/(4 pi) on axis.

    ``direction`` is the cone axis (the way light travels). ``half_angle`` [rad] is half of
    Blender's spot size; ``blend`` in [0, 1] is Blender's spot blend (smooth edge).
    ``radius`` [m] (default 0) and ``soft_falloff`` (default True) as for :class:`PointLight`:
    a sphere (or facing disk) of radiance Phi / (4 pi^2 R^2) whose emission along a direction
    is masked by the cone evaluated on that direction (Cycles: each light sample's own
    direction from the light to the shading point; no mask for points inside the sphere).
    """

    name: str
    position: np.ndarray
    direction: np.ndarray
    flux: np.ndarray
    half_angle: float
    blend: float = 0.0
    photon_share: float = 1.0
    radius: float = 0.0
    soft_falloff: bool = True
    camera_visible: bool = False

    def __post_init__(self):
        self.photon_share = _share(self.photon_share, self.name)
        self.radius = _radius(self.radius, self.name)
        self.soft_falloff = bool(self.soft_falloff)
        self.camera_visible = bool(self.camera_visible)
        self.position = _vec3(self.position, self.name, "position")
        self.direction = _unit(self.direction, self.name, "direction")
        self.flux = _rgb(self.flux, self.name, "flux")
        if not (0.0 < self.half_angle <= np.pi):
            raise SceneError(f"{self.name}: spot half angle {self.half_angle} rad is outside (0, pi]")
        self.blend = float(np.clip(self.blend, 0.0, 1.0))


@dataclass
class SunLight:
    """Distant light: ``irradiance`` [W/m^2] at normal incidence arriving along ``direction``.

    ``direction`` is the way the light travels (Blender: the sun's local -Z). ``angle`` [rad] is
    the full angular diameter of the sun's disc (Blender's Angle); 0 gives a hard shadow.
    A sun with an angle is a disc of radiance irradiance / (pi sin^2(angle / 2)) (Cycles'),
    which rays leaving the scene meet: camera rays when ``camera_visible`` (Blender's
    Visibility > Camera, off for a new light) and rays after a mirror or smooth glass.
    """

    name: str
    direction: np.ndarray
    irradiance: np.ndarray
    angle: float = 0.0
    photon_share: float = 1.0
    camera_visible: bool = False

    def __post_init__(self):
        self.photon_share = _share(self.photon_share, self.name)
        self.camera_visible = bool(self.camera_visible)
        self.direction = _unit(self.direction, self.name, "direction")
        self.irradiance = _rgb(self.irradiance, self.name, "irradiance")
        self.angle = float(np.clip(self.angle, 0.0, np.pi))


AREA_SHAPES = ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE")


@dataclass
class AreaLight:
    """A planar one-sided Lambertian emitter, Blender's area light.

    ``matrix`` is the 4x4 world matrix; the light lies in its local XY plane, centred at the
    origin, and emits towards local -Z. ``size_x``/``size_y`` [m] are the side lengths (the
    diameters for disk and ellipse) before the matrix's scale, which is applied. ``power`` [W]
    per channel gives radiance L = P / (pi A). ``collimated`` marks Blender's Spread ~ 0: the
    seed's circular directional light (Eq. 7.2), all light along the normal.
    ``shadow_photons`` False keeps shadow photons (seed 7.2, 9.6) from leaving this light:
    its points are not classified and every shadow ray to it is traced (Blender's
    ``Light.lanterna.shadow_photons``). ``camera_visible`` (Blender's Visibility > Camera,
    off by default as for a new light in Blender): camera rays see the light's emitting side,
    as in Cycles.
    """

    name: str
    shape: str
    matrix: np.ndarray
    size_x: float
    size_y: float
    power: np.ndarray
    collimated: bool = False
    photon_share: float = 1.0
    shadow_photons: bool = True
    camera_visible: bool = False

    def __post_init__(self):
        self.photon_share = _share(self.photon_share, self.name)
        self.shadow_photons = bool(self.shadow_photons)
        self.camera_visible = bool(self.camera_visible)
        self.matrix = np.asarray(self.matrix, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(self.matrix)):
            raise SceneError(f"{self.name}: transform is not finite")
        if self.shape not in AREA_SHAPES:
            raise SceneError(f"{self.name}: unknown area light shape {self.shape!r}")
        self.power = _rgb(self.power, self.name, "power")
        if self.shape in ("SQUARE", "DISK"):
            self.size_y = self.size_x
        if not (self.size_x > 0 and self.size_y > 0):
            raise SceneError(f"{self.name}: area light size must be positive")

    # Derived geometry in world space -------------------------------------------------------
    @property
    def center(self) -> np.ndarray:
        return self.matrix[:3, 3].copy()

    @property
    def axis_u(self) -> np.ndarray:
        """Half-extent vector along the light's local X (world space, scale applied)."""
        return self.matrix[:3, 0] * (0.5 * self.size_x)

    @property
    def axis_v(self) -> np.ndarray:
        return self.matrix[:3, 1] * (0.5 * self.size_y)

    @property
    def normal(self) -> np.ndarray:
        """Unit emission direction (local -Z in world space)."""
        n = np.cross(self.axis_u, self.axis_v)
        norm = np.linalg.norm(n)
        if norm == 0:
            raise SceneError(f"{self.name}: area light is degenerate (zero scale)")
        return -n / norm

    @property
    def area(self) -> float:
        """World-space area [m^2]."""
        parallelogram = 4.0 * np.linalg.norm(np.cross(self.axis_u, self.axis_v))
        return float(parallelogram * (np.pi / 4.0 if self.shape in ("DISK", "ELLIPSE") else 1.0))

    @property
    def radiance(self) -> np.ndarray:
        return self.power / (np.pi * self.area)


@dataclass
class World:
    """The environment: a constant radiance ``radiance`` [W m^-2 sr^-1] from every direction,
    or, where ``environment`` is set (an ``engine.environment.Environment``: an HDRI or a baked
    sky), that image's radiance per direction; ``radiance`` is then its mean over the sphere
    (for estimates and reports). ``portals``: Cycles' light portals (area lights marked
    ``is_portal``, emitting side into the room), windows through which the environment's
    photons and light samples go; they are not lights. ``camera``: where the world's nodes
    read Cycles' Light Path Is Camera Ray, the World that camera rays see (those from the
    camera and those that went on straight through transparent surfaces); this World (with
    Is Camera Ray 0) lights the scene and is what reflections, refractions, gather rays and
    photons meet. None: the camera sees this World too."""

    radiance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    environment: object = None
    portals: list = field(default_factory=list)
    camera: "World | None" = None

    def __post_init__(self):
        if self.environment is not None:
            self.radiance = self.environment.mean_radiance()
        self.radiance = _rgb(self.radiance, "World", "colour")

    @property
    def seen_by_camera(self) -> "World":
        """The World camera rays see (``camera``, or this one)."""
        return self if self.camera is None else self.camera

    @property
    def has_sky_to_gather(self) -> bool:
        """An image with bright patches (a sun, ``Environment.bright``) and no portals: the
        world whose light samples take the sun alone where a final gather runs, the gather
        the smooth rest (``lights.EnvironmentLight.gather_sky``)."""
        return (self.environment is not None and self.environment.bright is not None
                and not self.portals)

    @property
    def is_black(self) -> bool:
        if self.environment is not None:
            return bool(self.environment.black) or not bool(np.any(self.radiance > 0))
        return not bool(np.any(self.radiance > 0))

    def radiance_towards(self, directions: np.ndarray) -> np.ndarray:
        """Radiance (N, 3) arriving from unit ``directions`` (N, 3): the image's, or the
        constant colour broadcast."""
        if self.environment is not None:
            return self.environment.radiance(directions)
        return np.broadcast_to(self.radiance, (len(directions), 3))


@dataclass
class Camera:
    """Blender's perspective, orthographic or equirectangular camera with sensor fit and shift
    resolved, and its thin lens (depth of field) as Cycles models it.

    ``matrix`` is the 4x4 camera-to-world matrix (the camera looks along local -Z, +Y is up).
    ``tan_half_x``/``tan_half_y`` are the half extents of the full frame on the plane at unit
    distance (perspective), or in metres (``orthographic``: the frame is Orthographic Scale
    wide on its fitted side); ``shift_x``/``shift_y`` move the frame on that plane (same
    units). ``clip_start`` [m] is the seed's image-plane distance: nothing nearer is visible.
    ``resolution`` is the full frame (width, height) in pixels; ``border`` = (x0, y0, x1, y1)
    in pixels, y from the bottom like Blender, x1/y1 exclusive, selects the rendered window
    (the whole frame when None).

    ``panorama`` "EQUIRECTANGULAR" (default "": none): Cycles' equirectangular camera, the
    frame spanning longitudes ``longitude_min``..``longitude_max`` from left to right and
    latitudes ``latitude_min``..``latitude_max`` from bottom to top [rad] about the camera's
    view axis (-Z, longitude 0) and up axis (+Y, latitude pi/2); its frame extents are then
    0.5 on each side (the frame is [0, 1]^2 around its centre).

    Depth of field (off when ``aperture_radius`` is 0): rays leave a lens of radius
    ``aperture_radius`` [m] in the camera's plane and meet on the plane ``focus_distance`` [m]
    in front of it; ``aperture_blades`` >= 3 makes the lens a regular polygon turned by
    ``aperture_rotation`` [rad], and ``aperture_ratio`` squeezes it horizontally (anamorphic
    bokeh: the lens's x is divided by it), as Cycles' ``camera_sample_aperture`` does.
    """

    matrix: np.ndarray
    tan_half_x: float
    tan_half_y: float
    resolution: tuple[int, int]
    shift_x: float = 0.0
    shift_y: float = 0.0
    clip_start: float = 1e-3
    clip_end: float = 1e30
    border: tuple[int, int, int, int] | None = None
    name: str = "Camera"
    orthographic: bool = False
    aperture_radius: float = 0.0
    focus_distance: float = 10.0
    aperture_blades: int = 0
    aperture_rotation: float = 0.0
    aperture_ratio: float = 1.0
    panorama: str = ""
    longitude_min: float = -math.pi
    longitude_max: float = math.pi
    latitude_min: float = -0.5 * math.pi
    latitude_max: float = 0.5 * math.pi

    def __post_init__(self):
        self.matrix = np.asarray(self.matrix, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(self.matrix)):
            raise SceneError(f"{self.name}: transform is not finite")
        self.orthographic = bool(self.orthographic)
        if not (math.isfinite(self.aperture_radius) and self.aperture_radius >= 0):
            raise SceneError(f"{self.name}: aperture radius {self.aperture_radius} m must be "
                             f"zero (no depth of field) or positive")
        if self.aperture_radius > 0:
            if not (math.isfinite(self.focus_distance) and self.focus_distance > 0):
                raise SceneError(f"{self.name}: focus distance {self.focus_distance} m must "
                                 f"be positive for depth of field")
            if not (math.isfinite(self.aperture_ratio) and self.aperture_ratio > 0):
                raise SceneError(f"{self.name}: aperture ratio {self.aperture_ratio} must be "
                                 f"positive")
            if not math.isfinite(self.aperture_rotation):
                raise SceneError(f"{self.name}: aperture rotation is not finite")
        self.aperture_blades = int(self.aperture_blades)
        if self.panorama not in ("", "EQUIRECTANGULAR"):
            raise SceneError(f"{self.name}: panoramic projection {self.panorama!r} is not "
                             f"supported (only EQUIRECTANGULAR)")
        if self.panorama and (self.orthographic or self.aperture_radius > 0):
            raise SceneError(f"{self.name}: a panoramic camera is neither orthographic nor "
                             f"has depth of field here")
        if not all(math.isfinite(v) for v in (self.longitude_min, self.longitude_max,
                                              self.latitude_min, self.latitude_max)):
            raise SceneError(f"{self.name}: panoramic latitude/longitude range is not finite")
        w, h = (int(v) for v in self.resolution)
        if w < 1 or h < 1:
            raise SceneError(f"{self.name}: resolution {w}x{h} must be at least 1x1")
        self.resolution = (w, h)
        if not (self.tan_half_x > 0 and self.tan_half_y > 0):
            raise SceneError(f"{self.name}: field of view must be positive")
        if self.border is None:
            self.border = (0, 0, w, h)
        x0, y0, x1, y1 = (int(v) for v in self.border)
        x0, x1 = max(0, x0), min(w, x1)
        y0, y1 = max(0, y0), min(h, y1)
        if x1 <= x0 or y1 <= y0:
            raise SceneError(f"{self.name}: render border {self.border} is empty")
        self.border = (x0, y0, x1, y1)

    @property
    def window_size(self) -> tuple[int, int]:
        x0, y0, x1, y1 = self.border
        return x1 - x0, y1 - y0

    @property
    def position(self) -> np.ndarray:
        """The camera's location [m] (for an orthographic camera, the centre of its plane)."""
        return self.matrix[:3, 3].copy()

    @property
    def pixel_angle(self) -> float:
        """A pixel's width at unit distance (perspective; panoramic: its longitude span, the
        width at the equator); 0 for an orthographic camera."""
        if self.panorama:
            return abs(self.longitude_max - self.longitude_min) / self.resolution[0]
        return 0.0 if self.orthographic else 2.0 * self.tan_half_x / self.resolution[0]

    def panorama_directions(self, u, v) -> np.ndarray:
        """(N, 3) unit directions in the camera's frame (x right, y up, looking along -z) of
        an equirectangular camera at frame coordinates u, v in [0, 1] (v from the bottom),
        as Cycles' ``equirectangular_range_to_direction`` in its panoramic camera frame."""
        phi = (self.longitude_min - self.longitude_max) * np.asarray(u, np.float64) \
            - self.longitude_min
        theta = (self.latitude_min - self.latitude_max) * np.asarray(v, np.float64) \
            - self.latitude_min + 0.5 * math.pi
        sin_t = np.sin(theta)
        # Cycles' frame (x forward, y left, z up) in Blender's camera frame.
        return np.stack([-sin_t * np.sin(phi), np.cos(theta), -sin_t * np.cos(phi)], axis=-1)

    def panorama_coordinates(self, local) -> tuple[np.ndarray, np.ndarray]:
        """The inverse of ``panorama_directions``: frame coordinates (u, v) of camera-frame
        points or directions (N, 3)."""
        local = np.asarray(local, np.float64).reshape(-1, 3)
        x, y, z = -local[:, 2], -local[:, 0], local[:, 1]       # Cycles' frame
        r = np.maximum(np.linalg.norm(local, axis=1), 1e-300)
        phi = np.arctan2(y, x)
        theta = np.arccos(np.clip(z / r, -1.0, 1.0))
        u = (phi + self.longitude_min) / (self.longitude_min - self.longitude_max)
        v = (theta + self.latitude_min - 0.5 * math.pi) / (self.latitude_min - self.latitude_max)
        return u, v

    @property
    def pixel_width(self) -> float:
        """A pixel's width [m] at any distance (orthographic); 0 for a perspective camera."""
        return 2.0 * self.tan_half_x / self.resolution[0] if self.orthographic else 0.0

    def footprint(self, distance) -> np.ndarray:
        """The width [m] of a pixel seen at ``distance`` [m] from the camera (the pinhole's:
        depth of field's blur is not counted, as Cycles' ray differentials do not count it)."""
        return self.pixel_width + np.asarray(distance, np.float64) * self.pixel_angle

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) the camera frame's axes in world space, as columns (the matrix's scale
        removed)."""
        m = self.matrix[:3, :3]
        return m / np.linalg.norm(m, axis=0)

    def to_camera_space(self, points) -> np.ndarray:
        """(N, 3) world points [m] in the camera's frame (x right, y up, looking along -z)."""
        return (np.asarray(points, np.float64).reshape(-1, 3) - self.matrix[:3, 3]) \
            @ self.rotation

    def rays_to(self, points):
        """(origins, unit directions, distances [m]) of the pinhole's rays that end at each
        world point: from the eye (perspective) or from the camera's plane along its axis
        (orthographic)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if not self.orthographic:         # perspective and panoramic: from the eye
            eye = self.matrix[:3, 3]
            d = p - eye
            dist = np.linalg.norm(d, axis=1)
            return (np.broadcast_to(eye, p.shape).copy(),
                    d / np.maximum(dist, 1e-30)[:, None], dist)
        depth = -self.to_camera_space(p)[:, 2]
        axis = -self.rotation[:, 2]
        origins = p - depth[:, None] * axis
        return origins, np.broadcast_to(axis, p.shape).copy(), depth

    @classmethod
    def look_at(cls, eye, target, up=(0.0, 0.0, 1.0), fov_x_deg: float = 60.0,
                resolution=(64, 48), **kwargs) -> "Camera":
        """Convenience for tests: a camera at ``eye`` looking at ``target``."""
        eye = np.asarray(eye, float)
        forward = np.asarray(target, float) - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(up, float))
        if np.linalg.norm(right) < 1e-9:
            right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        true_up = np.cross(right, forward)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, true_up, -forward, eye
        tx = np.tan(np.radians(fov_x_deg) / 2)
        w, h = resolution
        return cls(matrix=m, tan_half_x=tx, tan_half_y=tx * h / w, resolution=resolution, **kwargs)


@dataclass
class Scene:
    """Triangles, materials, lights, world and camera. See the module docstring for units."""

    triangles: np.ndarray                 # (T, 3, 3) float32, world space [m]
    material_ids: np.ndarray              # (T,) int32 into ``materials``
    materials: list[Material]
    camera: Camera
    shading_normals: np.ndarray | None = None   # (T, 3, 3) float32, unit; None = flat
    object_ids: np.ndarray | None = None  # (T,) int32 into ``object_names``
    object_names: list[str] = field(default_factory=list)
    lights: list = field(default_factory=list)
    world: World = field(default_factory=World)
    warnings: list[str] = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    # Per-corner coordinates that textured materials read, name -> (T, 3, k) float32
    # ("uv", "uv:<name>", "position", "normal", "generated"; "color" / "color:<name>" and
    # "attr:<name>" (T, 3, 4) RGBA colour and geometry attributes; for shading normals also
    # "tangent" / "tangent:<name>" (T, 3, 4) and "normal_matrix" (T, 3, 3), one matrix per
    # triangle, not per corner; ``engine/textures.py``).
    corner_attributes: dict = field(default_factory=dict)
    # (T,) bool: the triangles of hair tubes (``engine/hair.py``), strands far thinner than
    # the irradiance cache's records (``indirect.CachedIndirect`` gathers their indirect light
    # per sample); None: none.
    strands: np.ndarray | None = None

    def __post_init__(self):
        if self.object_ids is None:
            self.object_ids = np.zeros(len(np.asarray(self.material_ids).reshape(-1)), np.int32)
        if not self.object_names:
            self.object_names = ["Mesh"]

    def validate(self) -> "Scene":
        """Check the arrays, drop untraceable triangles and report them. Returns ``self``."""
        tris = np.asarray(self.triangles, dtype=np.float32)
        if tris.ndim != 3 or tris.shape[1:] != (3, 3):
            tris = tris.reshape(-1, 3, 3) if tris.size % 9 == 0 else None
            if tris is None:
                raise SceneError("Scene: triangles must have shape (T, 3, 3)")
        count = len(tris)
        self._check_materials()
        mids = np.asarray(self.material_ids, dtype=np.int32).reshape(-1)
        if len(mids) != count:
            raise SceneError(f"Scene: {len(mids)} material ids for {count} triangles")
        if count and (mids.min() < 0 or mids.max() >= len(self.materials)):
            raise SceneError("Scene: a triangle names a material that does not exist")
        oids = (np.zeros(count, np.int32) if self.object_ids is None
                else np.asarray(self.object_ids, dtype=np.int32).reshape(-1))
        if not self.object_names:
            self.object_names = ["Mesh"]
        normals = None if self.shading_normals is None else np.asarray(self.shading_normals, np.float32)
        if normals is not None and normals.shape != tris.shape:
            raise SceneError("Scene: shading normals must match the triangles' shape")

        # Drop NaN / infinite corners and zero-area triangles, naming the objects.
        finite = np.all(np.isfinite(tris), axis=(1, 2))
        with np.errstate(invalid="ignore", over="ignore"):
            cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
            doubled_area_sq = np.einsum("ij,ij->i", cross, cross)
        # Each triangle against its own coordinates (one far-away triangle must not make the
        # others "too small"): zero area, or so small that float32 cannot resolve it.
        with np.errstate(invalid="ignore"):
            scale = np.max(np.abs(np.where(np.isfinite(tris), tris, 0)), axis=(1, 2),
                           initial=0.0).astype(np.float64)
        in_range = finite & (scale <= MAX_COORDINATE)
        keep = in_range & (doubled_area_sq > (scale * 1e-7) ** 4)
        if count and not np.all(keep):
            for reason, mask in (("non-finite vertices", ~finite),
                                 (f"vertices beyond {MAX_COORDINATE:g} m (float32 overflow)",
                                  finite & ~in_range),
                                 ("zero area", in_range & ~keep)):
                if np.any(mask):
                    names = sorted({self.object_names[i] if 0 <= i < len(self.object_names) else "?"
                                    for i in np.unique(oids[mask])})
                    self.warnings.append(
                        f"{', '.join(names)}: skipped {int(mask.sum())} triangles with {reason}")
            self.stats["skipped_triangles"] = int((~keep).sum())
        self._check_lights()
        cam = self.camera
        if not cam.clip_end > cam.clip_start:
            text = (f"{cam.name}: clip start {cam.clip_start:g} m is not before clip end "
                    f"{cam.clip_end:g} m, so the camera sees nothing and the picture is black")
            if text not in self.warnings:          # validate may run more than once
                self.warnings.append(text)
        for key, corner in list(self.corner_attributes.items()):
            corner = np.asarray(corner, np.float32)
            if corner.ndim != 3 or corner.shape[:2] != (count, 3):
                raise SceneError(f"Scene: corner attribute '{key}' must have shape (T, 3, k) "
                                 f"for the {count} triangles, not {corner.shape}")
            corner = np.where(np.isfinite(corner), corner, 0.0).astype(np.float32)
            self.corner_attributes[key] = np.ascontiguousarray(corner[keep])
        self.triangles = np.ascontiguousarray(tris[keep])
        self.material_ids = np.ascontiguousarray(mids[keep])
        self.object_ids = np.ascontiguousarray(oids[keep])
        if self.strands is not None:
            strands = np.asarray(self.strands, bool).reshape(-1)
            if len(strands) != count:
                raise SceneError(f"Scene: {len(strands)} strand flags for {count} triangles")
            strands = strands[keep]
            self.strands = np.ascontiguousarray(strands) if strands.any() else None
        if normals is not None:
            normals = normals[keep]
            bad = ~np.all(np.isfinite(normals), axis=(1, 2))
            lengths = np.sqrt(np.einsum("tkj,tkj->tk", normals, normals))
            bad |= np.any(~(lengths > 1e-6), axis=1)
            if np.any(bad):
                normals[bad] = self.geometric_normals()[bad][:, None, :]
                lengths[bad] = 1.0
            if np.any(np.abs(lengths - 1.0) > 1e-4):
                normals = normals / lengths[..., None]
            self.shading_normals = np.ascontiguousarray(normals, dtype=np.float32)
        return self

    def _check_lights(self):
        """Drop, with a warning naming it, every area light that cannot be sampled: an area
        that is not finite and positive, a radiance beyond ``MAX_VALUE``, or sides further apart
        than ``MAX_AREA_ASPECT`` (1e30 x 1e-30 m rendered black without a word; the light
        samplers' irradiance, measured under a strip 2 m up, is within 0.5 % of the closed form
        up to an aspect of 1e7 and 0 at 1e8)."""
        kept = []
        for light in self.lights:
            if isinstance(light, AreaLight):
                area = light.area
                sides = np.linalg.norm(light.axis_u), np.linalg.norm(light.axis_v)
                aspect = max(sides) / min(sides) if min(sides) > 0 else np.inf
                radiance = light.power / (np.pi * area) if area > 0 else np.full(3, np.inf)
                if not (np.isfinite(area) and area > 0 and aspect <= MAX_AREA_ASPECT
                        and np.all(radiance <= MAX_VALUE)):
                    self.warnings.append(
                        f"{light.name}: an area light of {2 * sides[0]:g} x {2 * sides[1]:g} m "
                        f"(area {area:g} m^2) cannot be sampled; skipped")
                    continue
            kept.append(light)
        self.lights = kept

    def _check_materials(self):
        """The materials again (their fields can be set after construction): finite and >= 0,
        else SceneError naming the material. Where rho_d + rho_s > 1 in a channel both are
        scaled down in that channel, with a warning: such a surface would reflect more than it
        receives (photons gain power at every bounce, a closed room never converges)."""
        for m in self.materials:
            who = f"Material '{m.name}'"
            m.diffuse = _rgb(m.diffuse, who, "diffuse reflectance")
            m.specular = _rgb(m.specular, who, "specular reflectance")
            m.exitance = _rgb(m.exitance, who, "radiant exitance")
            total = m.diffuse + m.specular
            if np.any(total > 1.0 + 1e-6):
                self.warnings.append(f"{who}: diffuse + specular reflectance "
                                     f"{np.round(total, 4).tolist()} exceeds 1; scaled down "
                                     "to conserve energy")
                scale = 1.0 / np.maximum(total, 1.0)
                m.diffuse, m.specular = m.diffuse * scale, m.specular * scale

    # Derived quantities ----------------------------------------------------------------------
    def geometric_normals(self) -> np.ndarray:
        """Unit geometric normals (T, 3) float32, from the corner winding."""
        t = self.triangles.astype(np.float64)
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return (n / np.where(norm > 0, norm, 1.0)).astype(np.float32)

    def triangle_areas(self) -> np.ndarray:
        t = self.triangles.astype(np.float64)
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds of the geometry (and the camera position) [m]."""
        pts = [self.camera.matrix[:3, 3][None]]
        if len(self.triangles):
            pts.append(self.triangles.reshape(-1, 3).astype(np.float64))
        allp = np.concatenate(pts)
        return allp.min(axis=0), allp.max(axis=0)

    @property
    def extent(self) -> float:
        """Diagonal of the bounds [m]; sets the ray offsets and default radii."""
        lo, hi = self.bounds()
        return float(max(np.linalg.norm(hi - lo), 1e-30))

    def material_table(self) -> dict[str, np.ndarray]:
        """Materials as (M, 3) float32 arrays, indexed by material id."""
        return {
            "diffuse": np.array([m.diffuse for m in self.materials], np.float32).reshape(-1, 3),
            "specular": np.array([m.specular for m in self.materials], np.float32).reshape(-1, 3),
            "exitance": np.array([m.exitance for m in self.materials], np.float32).reshape(-1, 3),
            "both_sides": np.array([m.emit_both_sides for m in self.materials], bool),
        }
