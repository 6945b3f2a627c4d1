"""Closed-form irradiance for the analytic tests, and small scene builders (no bpy).

* point light: E = Phi cos(theta) / (4 pi r^2)                       (seed Eq. 7.1)
* disk light on its axis: E = pi L r^2 / (d^2 + r^2)                 (DESIGN.md §6)
* polygon light: Lambert's formula E = L/2 sum_k Theta_k (gamma_k . n), with gamma_k the unit
  normal of the plane through x and edge k, Theta_k the angle the edge subtends at x.
"""
from __future__ import annotations

import numpy as np

from lanterna.engine.scene import Camera, Material, Scene


def point_irradiance(x, n, light_pos, flux):
    d = np.asarray(light_pos, float) - x
    r2 = np.einsum("ij,ij->i", d, d)
    cos = np.maximum(np.einsum("ij,ij->i", d, n) / np.sqrt(r2), 0.0)
    return np.asarray(flux, float)[None] * (cos / (4 * np.pi * r2))[:, None]


def disk_axis_irradiance(radiance, radius, distance):
    return np.pi * radiance * radius ** 2 / (distance ** 2 + radius ** 2)


def polygon_irradiance(x, n, polygon, radiance):
    """Lambert's formula for a uniformly emitting polygon (visible side), at one point."""
    verts = np.asarray(polygon, float) - np.asarray(x, float)
    total = 0.0
    for k in range(len(verts)):
        a, b = verts[k], verts[(k + 1) % len(verts)]
        a_hat, b_hat = a / np.linalg.norm(a), b / np.linalg.norm(b)
        theta = np.arccos(np.clip(a_hat @ b_hat, -1, 1))
        gamma = np.cross(a, b)
        gamma /= np.linalg.norm(gamma)
        total += theta * (gamma @ n)
    return 0.5 * abs(total) * np.asarray(radiance, float)


def quad(c, du, dv):
    """Two triangles for the parallelogram centred at c with half axes du, dv."""
    c, du, dv = (np.asarray(v, float) for v in (c, du, dv))
    p = [c - du - dv, c + du - dv, c + du + dv, c - du + dv]
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]], np.float32)


def box_room(size=(4.0, 4.0, 3.0), scale=1.0):
    """Inward-facing closed box [0, sx] x [0, sy] x [0, sz] (12 triangles), times ``scale``."""
    sx, sy, sz = size
    faces = [
        quad([sx / 2, sy / 2, 0], [sx / 2, 0, 0], [0, sy / 2, 0]),        # floor
        quad([sx / 2, sy / 2, sz], [sx / 2, 0, 0], [0, sy / 2, 0]),       # ceiling
        quad([0, sy / 2, sz / 2], [0, sy / 2, 0], [0, 0, sz / 2]),        # left
        quad([sx, sy / 2, sz / 2], [0, sy / 2, 0], [0, 0, sz / 2]),       # right
        quad([sx / 2, sy, sz / 2], [sx / 2, 0, 0], [0, 0, sz / 2]),       # back
        quad([sx / 2, 0, sz / 2], [sx / 2, 0, 0], [0, 0, sz / 2]),        # front
    ]
    return np.concatenate(faces) * np.float32(scale)


def plane_scene(lights, size=10.0, rho=1.0, resolution=(32, 32), height=4.0, fov=90.0):
    tris = quad([0, 0, 0], [size / 2, 0, 0], [0, size / 2, 0])
    cam = Camera.look_at([0, 0, height], [0, 0, 0], up=(0, 1, 0), fov_x_deg=fov,
                         resolution=resolution)
    return Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                 materials=[Material("white", diffuse=rho)], camera=cam, lights=list(lights))


def icosphere(radius=1.0, subdivisions=3, center=(0.0, 0.0, 0.0)):
    """Triangles (20 * 4^s, 3, 3) float32 of a geodesic sphere: an icosahedron whose faces
    are split in four ``subdivisions`` times, vertices pushed onto the sphere."""
    t = (1.0 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    tris = v[f] / np.linalg.norm(v[f], axis=2, keepdims=True)
    for _ in range(subdivisions):
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        ab, bc, ca = [(p + q) / np.linalg.norm(p + q, axis=1, keepdims=True)
                      for p, q in ((a, b), (b, c), (c, a))]
        tris = np.concatenate([np.stack(s, 1) for s in
                               ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return (tris * radius + np.asarray(center, float)).astype(np.float32)


def triangle_area_sum(tris):
    tris = np.asarray(tris, float)
    return 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
