"""Primary rays: Blender's perspective, orthographic and equirectangular cameras, with the
thin lens (depth of field) as Cycles models it, Blender's framing and a Blackman-Harris pixel
filter.

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
    Depth of field: ``camera.aperture_radius`` [m] (0 = pinhole), ``focus_distance`` [m],
    ``aperture_blades`` (0 or >= 3), ``aperture_rotation`` [rad], ``aperture_ratio``; the
    lens points are stratified per pixel, in a random order (``aperture_points``).

The seed's camera (3.4) has a position, a view direction, an up vector, the image-plane
distance and a horizontal aperture; Blender's camera gives the same through its matrix,
sensor fit and clip start (the image-plane distance: nothing nearer is seen). Depth of field
follows the thin lens of Cook, Porter and Carpenter (1984) as Cycles applies it (``_lens_rays``).
"""
from __future__ import annotations

import numpy as np

from . import sampling


def pixel_rays(camera, pixel_start: int, pixel_stop: int, samples: int, rng: np.random.Generator,
               filter_width: float = 1.5, centres: bool = False, pixels=None,
               positions=None):
    """Rays for window pixels [pixel_start, pixel_stop) in row-major order, top row first.

    Returns (origins (P*S, 3) float32, directions (P*S, 3) float32 unit, tmax (P*S,)),
    samples of one pixel contiguous. ``centres``: every sample through the pixel's centre
    (the irradiance cache's placement passes). ``pixels``: these window pixels (row-major
    indices) instead of the range. ``positions``: (P, S, 2) numbers in [0, 1)^2 to place the
    samples with (warped by the filter as the stratified ones are) instead of drawing them.
    """
    x0, y0, x1, y1 = camera.border
    win_w, win_h = x1 - x0, y1 - y0
    full_w, full_h = camera.resolution
    pix = np.arange(pixel_start, pixel_stop) if pixels is None else np.asarray(pixels, np.int64)
    row, col = np.divmod(pix, win_w)
    px = x0 + col                                   # full-frame column
    py = y0 + (win_h - 1 - row)                     # full-frame row from the bottom
    # Stratified positions: every pixel visits each of its strata once (the order of the
    # strata carries no information, so no per-pixel shuffle is needed).
    if positions is None:
        u = sampling.stratified_2d(len(pix), samples, rng, shuffle=False)      # (P, S, 2)
    else:
        u = np.array(positions, np.float32).reshape(len(pix), samples, 2)     # a copy
    if centres:
        off = np.zeros(u.shape, np.float32)
    else:
        off = sampling.filter_offsets(u, filter_width, out=u if u.dtype == np.float32 else None)
    scale_x = np.float32(2.0 * camera.tan_half_x / full_w)
    scale_y = np.float32(2.0 * camera.tan_half_y / full_h)
    # Position on the plane z = -1 in camera space: pixel centre (per pixel) plus offset.
    # Work on flat (P*S,) columns: fast, unlike broadcasting over a last axis of 3.
    cx = ((px + 0.5) * scale_x + (camera.shift_x - camera.tan_half_x)).astype(np.float32)
    cy = ((py + 0.5) * scale_y + (camera.shift_y - camera.tan_half_y)).astype(np.float32)
    lx = off[..., 0] * scale_x
    lx += cx[:, None]
    ly = off[..., 1] * scale_y
    ly += cy[:, None]
    lx, ly = lx.reshape(-1), ly.reshape(-1)
    if camera.orthographic or camera.panorama or (camera.aperture_radius > 0 and not centres):
        lens = None
        if camera.aperture_radius > 0 and not centres:
            # Lens positions stratified per pixel, in a random order (so that they are not
            # paired with the pixel positions' strata).
            lens = aperture_points(sampling.stratified_2d(len(pix), samples, rng).reshape(-1, 2),
                                   camera)
        return _lens_rays(camera, lx, ly, lens)
    m = camera.matrix
    rotation = camera.rotation.astype(np.float32)
    position = m[:3, 3].astype(np.float32)
    clip_start = np.float32(camera.clip_start)
    count = len(lx)
    origins = np.empty((count, 3), np.float32)
    directions = np.empty((count, 3), np.float32)
    tmp = np.empty(count, np.float32)
    for c in range(3):
        # World-space column c of (lx, ly, -1) rotated: on the plane z = -1, not yet unit.
        world = directions[:, c]
        np.multiply(lx, rotation[c, 0], out=world)
        world += np.multiply(ly, rotation[c, 1], out=tmp)
        world -= rotation[c, 2]
        np.multiply(world, clip_start, out=origins[:, c])        # on the near plane
        origins[:, c] += position[c]
    length = np.sqrt(sampling.dot_rows(directions, directions))
    sampling.scale_rows(directions, np.float32(1.0) / length, out=directions)
    tmax = np.float32(camera.clip_end - camera.clip_start) * length
    return origins, directions, tmax


def aperture_points(u: np.ndarray, camera) -> np.ndarray:
    """(N, 2) points [m] on the camera's lens in its x, y plane from (N, 2) numbers in
    [0, 1)^2, uniform by area: a disk, or with ``aperture_blades`` >= 3 a regular polygon
    whose circumradius is the aperture radius and whose first edge's middle lies at
    ``aperture_rotation`` (Cycles' ``regular_polygon_sample``); x divided by
    ``aperture_ratio``."""
    u = np.asarray(u, np.float64).reshape(-1, 2)
    blades = camera.aperture_blades
    if blades < 3:
        p = sampling.square_to_disk(u)
    else:
        scaled = u[:, 0] * blades
        corner = np.minimum(np.floor(scaled), blades - 1)
        a = np.sqrt(scaled - corner)              # uniform point of the corner's triangle
        b = u[:, 1] * a
        a = 1.0 - a
        half = np.pi / blades
        x, y = (a + b) * np.cos(half), (a - b) * np.sin(half)
        turn = camera.aperture_rotation + corner * (2.0 * np.pi / blades)
        c, s = np.cos(turn), np.sin(turn)
        p = np.stack([c * x - s * y, s * x + c * y], axis=1)
    p *= camera.aperture_radius
    p[:, 0] /= camera.aperture_ratio
    return p


def _lens_rays(camera, lx, ly, lens):
    """``pixel_rays`` for an equirectangular or orthographic camera or a thin lens (``lens``:
    (N, 2) points on it [m], or None for the pinhole), as Cycles' ``camera_sample_panorama``,
    ``camera_sample_perspective`` and ``camera_sample_orthographic``: a ray through the lens
    point aims at the point of the focus plane its pixel sample sees through the lens's
    centre, and starts where it crosses the near clip (perspective: at clip start / cos of the
    pinhole ray's angle along it)."""
    count = len(lx)
    lx, ly = lx.astype(np.float64), ly.astype(np.float64)
    start = float(camera.clip_start)
    local_o = np.zeros((count, 3))
    if camera.panorama:
        # The frame [0, 1]^2 of Cycles' equirectangular camera (``Camera.panorama``).
        u = (lx - (camera.shift_x - camera.tan_half_x)) / (2.0 * camera.tan_half_x)
        v = (ly - (camera.shift_y - camera.tan_half_y)) / (2.0 * camera.tan_half_y)
        d = camera.panorama_directions(u, v)
        local_o = d * start
        reach = np.full(count, camera.clip_end - start)
    elif camera.orthographic:
        local_o[:, 0], local_o[:, 1] = lx, ly
        d = np.zeros((count, 3))
        d[:, 2] = -1.0
        if lens is not None:
            d[:, 0], d[:, 1], d[:, 2] = -lens[:, 0], -lens[:, 1], -camera.focus_distance
            d /= np.linalg.norm(d, axis=1)[:, None]
            local_o[:, :2] += lens
        local_o += d * (start / -d[:, 2])[:, None]
        reach = np.full(count, camera.clip_end - start)
    else:
        pinhole = np.stack([lx, ly, -np.ones(count)], axis=1)
        stretch = np.linalg.norm(pinhole, axis=1)          # 1 / cos of the pinhole ray's angle
        if lens is None:
            d = pinhole
        else:
            d = pinhole * camera.focus_distance
            d[:, :2] -= lens
            local_o[:, :2] = lens
        d /= np.linalg.norm(d, axis=1)[:, None]
        local_o += d * (start * stretch)[:, None]
        reach = (camera.clip_end - start) * stretch
    rotation = camera.rotation
    origins = (local_o @ rotation.T + camera.matrix[:3, 3]).astype(np.float32)
    directions = (d @ rotation.T).astype(np.float32)
    length = np.sqrt(sampling.dot_rows(directions, directions))
    sampling.scale_rows(directions, np.float32(1.0) / length, out=directions)
    return origins, directions, reach.astype(np.float32)
