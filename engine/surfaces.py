"""What a ray hit: the surface's normals and its material, for arrays of hits.

What it computes
    ``SceneSurfaces(scene)``  the per-triangle data that shading needs, gathered once per
        render: unit geometric normals (T, 3) float32 (from the corner winding), the
        per-corner shading normals where a mesh is smooth (None where every mesh is flat: a
        flat mesh's corner normals equal the geometric one and need no interpolation), the
        material ids and the ``bsdf.MaterialTable``.
    ``normals(prim, bu, bv, d)``  at hits of rays ``d`` on triangles ``prim`` with
        barycentrics (bu, bv): the geometric normal turned towards the viewer, the shading
        normal (interpolated from the corners; the geometric one where the mesh is flat or
        the interpolated one faces away from the viewer) and whether the wound front side
        was hit. Blender meshes have any winding, so every surface is two-sided (DESIGN §3).
    ``strand_points(prim, bu, bv, x)``, ``strand_normals(prim, bu, bv, d)``  hits on hair
        tubes lifted onto their round surface, and the round curve's normal there.
    ``params(prim, bu, bv)``  the material parameters at hits on triangles ``prim`` with
        barycentrics (bu, bv) (``MaterialTable.at``; textured materials need the barycentrics
        for their per-hit values, and give their means without them).
"""
from __future__ import annotations

import numpy as np

from . import sampling
from .bsdf import MaterialTable, SurfaceParams


class SceneSurfaces:
    """Per-triangle normals and materials of a scene (module docstring)."""

    def __init__(self, scene):
        self.materials = MaterialTable(scene)
        self.material_ids = scene.material_ids
        self.triangles = scene.triangles
        # Hair tubes (``Scene.strands``): their hits are lifted onto the round surface the
        # tube stands for (``strand_points``).
        self.strands = scene.strands
        self.geometric_normals = scene.geometric_normals().astype(np.float32)
        self.shading_normals = scene.shading_normals
        # Flat-shaded meshes need no interpolation: drop normals equal to the geometric ones.
        if self.shading_normals is not None:
            agree = np.einsum("tkj,tj->tk", self.shading_normals, self.geometric_normals)
            if not np.any(np.abs(agree) < 0.99999):
                self.shading_normals = None

    def params(self, prim: np.ndarray, bu=None, bv=None, directions=None,
               camera=None, ray=None) -> SurfaceParams:
        """Material parameters at hits on triangles ``prim`` with barycentrics (bu, bv) of
        rays along ``directions`` (for inputs that read the view), ``camera`` (N,) bool where
        they are camera rays' (Light Path's Is Camera Ray), ``ray`` the rays' other Light
        Path values (``MaterialTable.at``)."""
        return self.materials.at(self.material_ids[prim], prim, bu, bv, directions, camera,
                                 ray)

    def normals(self, prim, bu, bv, d):
        """(ng, ns, front) at hits of rays ``d`` (module docstring)."""
        ng = np.take(self.geometric_normals, prim, axis=0)    # take: faster than ng[prim]
        facing = sampling.dot_rows(ng, d)
        front = facing < 0                                    # the ray meets the front side
        if not front.all():                                   # turn ng towards the viewer
            sampling.scale_rows(ng, np.where(front, np.float32(1), np.float32(-1)), out=ng)
        if self.shading_normals is None:
            return ng, ng, front
        corner = self.shading_normals[prim]
        w = np.stack([1.0 - bu - bv, bu, bv], axis=1)[..., None]
        ns = (corner * w).sum(axis=1)
        ns = np.where(front[:, None], ns, -ns)
        ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-12)
        # A shading normal that points away from the viewer would shade the wrong side.
        ns = np.where((np.einsum("ij,ij->i", ns, d) < 0)[:, None], ns, ng).astype(np.float32)
        return ng, ns, front

    def strand_points(self, prim, bu, bv, x):
        """Hits ``x`` on hair tubes' triangles ``prim`` lifted onto the smooth surface their
        corner normals describe (Hanika 2021, "Hacking the Shadow Terminator": each corner's
        tangent plane lifts the point by how far it lies below it, weighted by the
        barycentrics). A tube is a polygon inside the round curve Cycles traces; from its flat
        faces, rays that leave the round surface (towards a light the smooth normal faces, a
        gather ray near the horizon) met the tube's own neighbouring face, and a fur ball's
        direct light came out 7 % dark against Cycles."""
        tri = self.triangles[prim].astype(np.float64)
        nrm = self.shading_normals[prim].astype(np.float64)
        b = np.stack([1.0 - bu - bv, bu, bv], axis=1)
        p = np.asarray(x, np.float64)
        below = np.minimum(np.einsum("nkj,nkj->nk", p[:, None, :] - tri, nrm), 0.0)
        return p - np.einsum("nk,nk,nkj->nj", b, below, nrm)

    def strand_normals(self, prim, bu, bv, d):
        """Shading normals (N, 3) at hits of rays ``d`` on hair tubes' side triangles
        ``prim``: the round curve's normal where the same ray meets it, instead of the corner
        normals' interpolation. In the plane across the tube, the chord point a ray meets lies
        rho = R cos(pi / S) / cos(phi) from the axis (R the polygon's circumradius, S its
        sides, phi the angle between the interpolated radial direction and the face's
        normal), and the round curve of radius r = R sin(pi / S) / (pi / S) (``engine/hair.py``
        widens the polygon by the inverse) meets the same ray at the impact parameter
        b = rho sin(theta), theta the radial direction's angle off the ray: its normal is
        (b / r) across the ray plus sqrt(1 - (b / r)^2) back along the ray (grazing where
        b > r). Interpolated instead, a hexagonal tube lit from the camera's side came out
        4.5 % dark (the pixels of a strand hold too few normals facing the light). S and the
        axis come from the corner normals themselves (the two that differ most are a side
        apart, and the axis is across them and the face's normal); the radius' slope along
        the axis is kept. Where the corners hardly differ (the flat caps) the interpolation
        is kept."""
        tri = self.triangles[prim].astype(np.float64)
        corner = self.shading_normals[prim].astype(np.float64)
        d = np.asarray(d, np.float64)
        w = np.stack([1.0 - bu - bv, bu, bv], axis=1)
        n = np.einsum("nk,nkj->nj", w, corner)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        face *= np.where(np.einsum("ij,ij->i", face, n) < 0, -1.0, 1.0)[:, None]
        face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300)
        pairs = np.stack([corner[:, 0] - corner[:, 1], corner[:, 1] - corner[:, 2],
                          corner[:, 2] - corner[:, 0]], axis=1)
        spread = np.linalg.norm(pairs, axis=2)
        widest = np.argmax(spread, axis=1)
        step = pairs[np.arange(len(prim)), widest]
        axis = np.cross(face, step)
        axis_len = np.linalg.norm(axis, axis=1)
        usable = (spread.max(axis=1) > 0.1) & (axis_len > 1e-6)
        axis /= np.maximum(axis_len, 1e-300)[:, None]

        def across(v):
            v = v - np.einsum("ij,ij->i", v, axis)[:, None] * axis
            length = np.linalg.norm(v, axis=1)
            return v / np.maximum(length, 1e-300)[:, None], length

        n_across, _ = across(n)
        face_across, _ = across(face)
        back, back_len = across(-d)               # towards the viewer, across the tube
        a0, _ = across(corner[np.arange(len(prim)), widest])
        a1, _ = across(corner[np.arange(len(prim)), (widest + 1) % 3])
        half = 0.5 * np.arccos(np.clip(np.einsum("ij,ij->i", a0, a1), -1.0, 1.0))
        usable &= (back_len > 1e-3) & (half > 1e-3) & (np.einsum("ij,ij->i", n_across, back) > 0)
        half = np.where(usable, half, 0.5)
        cos_face = np.clip(np.einsum("ij,ij->i", n_across, face_across), 1e-3, 1.0)
        rho_over_r = (half / np.tan(half)) / cos_face
        lateral = n_across - np.einsum("ij,ij->i", n_across, back)[:, None] * back
        beta = rho_over_r[:, None] * lateral                  # (b / r) across the ray
        b = np.linalg.norm(beta, axis=1)
        beta /= np.maximum(b, 1.0)[:, None]
        rounded = beta + np.sqrt(np.maximum(1.0 - np.minimum(b, 1.0) ** 2, 0.0))[:, None] * back
        tilt = np.einsum("ij,ij->i", n, axis)
        rounded = (rounded * np.sqrt(np.maximum(1.0 - tilt ** 2, 0.0))[:, None]
                   + tilt[:, None] * axis)
        rounded /= np.maximum(np.linalg.norm(rounded, axis=1, keepdims=True), 1e-300)
        return np.where(usable[:, None], rounded, n)
