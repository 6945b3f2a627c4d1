"""Primary rays: a pinhole camera with Blender's framing and a Blackman-Harris pixel filter.

What it computes
    For pixels of the render window and ``samples`` samples per pixel, ray origins on the
    near plane and unit directions in world space. Sample positions inside a pixel are
    stratified (a jittered grid when ``samples`` is a square, a Latin hypercube otherwise)
    and then warped by the filter's inverse CDF, so each sample is added to its own pixel
    with weight 1 (filter importance sampling, as Cycles does).

Parameters
    ``camera``        ``engine.scene.Camera`` (frame extents at unit distance, shift, clip
                      start/end, border window; y counted from the bottom like Blender).
    ``samples``       samples per pixel (default 16).
    ``filter_width``  Blackman-Harris width in pixels (default 1.5, Cycles' default).

The seed's camera (3.4) has a position, a view direction, an up vector, the image-plane
distance and a horizontal aperture; Blender's camera gives the same through its matrix,
sensor fit and clip start (the image-plane distance: nothing nearer is seen).
"""
from __future__ import annotations

import numpy as np

from . import sampling


def pixel_rays(camera, pixel_start: int, pixel_stop: int, samples: int, rng: np.random.Generator,
               filter_width: float = 1.5):
    """Rays for window pixels [pixel_start, pixel_stop) in row-major order, top row first.

    Returns (origins (P*S, 3) float64, directions (P*S, 3) float64 unit, tmax (P*S,)),
    samples of one pixel contiguous.
    """
    x0, y0, x1, y1 = camera.border
    win_w, win_h = x1 - x0, y1 - y0
    full_w, full_h = camera.resolution
    pix = np.arange(pixel_start, pixel_stop)
    row, col = np.divmod(pix, win_w)
    px = x0 + col                                   # full-frame column
    py = y0 + (win_h - 1 - row)                     # full-frame row from the bottom
    u = sampling.stratified_2d(len(pix), samples, rng)          # (P, S, 2)
    off = sampling.filter_offsets(u, filter_width)
    sx = (px[:, None] + 0.5 + off[..., 0]) / full_w * 2.0 - 1.0
    sy = (py[:, None] + 0.5 + off[..., 1]) / full_h * 2.0 - 1.0
    local = np.empty((sx.size, 3))
    local[:, 0] = sx.reshape(-1) * camera.tan_half_x + camera.shift_x
    local[:, 1] = sy.reshape(-1) * camera.tan_half_y + camera.shift_y
    local[:, 2] = -1.0
    m = camera.matrix
    rotation = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)  # ignore the camera's scale
    world = local @ rotation.T                     # z = -1 plane, not yet unit
    length = np.linalg.norm(world, axis=1)
    origins = m[:3, 3] + world * camera.clip_start  # on the near plane (camera-space z = -clip_start)
    directions = world / length[:, None]
    tmax = (camera.clip_end - camera.clip_start) * length
    return origins, directions, tmax
