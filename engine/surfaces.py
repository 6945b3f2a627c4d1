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
