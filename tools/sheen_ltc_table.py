"""Measure Cycles' microfibre sheen lobe by rendering, fit our own LTC table to it, and write
``engine/data/sheen_ltc.npz`` (the table ``engine/lobes.py``'s ``Sheen`` reads).

Why measured and not fitted from the volumetric model. Cycles' Sheen BSDF ("Microfiber") is
the LTC fit of Zeltner, Burley and Chiang 2022 ("Practical Multiple-Scattering Sheen Using
Linearly Transformed Cosines") to a Monte Carlo simulation of a volumetric layer of fibre-like
microflakes. Re-simulating that layer needs its exact parameters (flake distribution, density,
thickness, albedo), which the paper's short talk does not pin down well enough to reproduce a
table to 1 %; so we measure the lobe Cycles actually renders and fit our own table to it.

Model measured (``intern/cycles/kernel/closure/bsdf_sheen.h``, read for its conventions):
f(wo, wi) cos(theta_i) = A(mu_o, r) D(wi), where D is a linearly transformed cosine
    D(w) = z a^2 / (pi ((a x + b z)^2 + (a y)^2 + z^2)^2)            (local frame, x along the
view direction's tangential part, z the normal), a probability density on the upper hemisphere
(the transform keeps z), and A the lobe's directional albedo; a, b, A are bilinear look-ups in a
32 x 32 table over (mu_o, roughness), node-centred (value i / 31). Sampling D exactly, a sample's
weight is A: lit by a uniform white world with BSDF sampling only, every camera sample of a
sheen tile returns A exactly.

Method (one mosaic, tiles as ``tests/data/make_principled_albedo.py`` makes them: flat quads seen
by an orthographic camera at fixed cos(theta), invisible to all rays but the camera's, lit by
the world only; the world is not sampled as a light, so only the BSDF's own samples see it):
  1. world = 1: the tile's mean is A(mu, r).
  2. worlds g_y = (1 + d_y) / 2 and g_z = (1 + d_z) / 2 (d the world direction a ray leaves
     along): the tile's mean is A (1 + E[d_y]) / 2, A (1 + E[d_z]) / 2, hence the mean
     direction of D in world axes, and with the tile's frame (rotated by theta about x: normal
     (0, -sin t, cos t), tangent towards the viewer (0, cos t, sin t)) the local moments E[x],
     E[z].
  3. per node, (a, b) solving E_D[x] = E[x], E_D[z] = E[z] (least squares over a fixed
     256 x 256 stratified grid of cosine samples pushed through the transform).
Nodes that cannot be rendered are solved from the bilinear read Cycles makes there: mu = 0 is
rendered at mu = 0.01 (weight 0.69 on node 0, 0.31 on node 1), mu = 1 at 1 - 1e-4 (so the view
has a tangent), roughness 0 is clamped by Cycles to 1e-3 (weight 0.969 on node 0).

Run (bpy 5.2.3, about 2 minutes under ``nice`` on 2 busy cores)::

    nice .venv/bin/python tools/sheen_ltc_table.py [--samples 256] [--out engine/data/sheen_ltc.npz]

Output ``engine/data/sheen_ltc.npz``: ``A``, ``a``, ``b`` (32 x 32 float64, [mu index, r index]),
``Ex``, ``Ez`` (the measured moments), ``se_Ex``, ``se_Ez`` (their standard errors from the
spread of the tile's pixels), ``note``.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "data"))

SIZE = 32
TILE, GAP, MARGIN = 12, 2, 2
PIXEL = 0.01
MU_LOW, MU_HIGH, R_LOW = 0.01, 1.0 - 1e-4, 1e-3


def _mu_nodes():
    mu = np.arange(SIZE) / (SIZE - 1)
    mu[0], mu[-1] = MU_LOW, MU_HIGH
    return mu


def _world(scene, mode):
    """World radiance 1, (1 + d_y)/2 or (1 + d_z)/2 over ray directions d; not a light."""
    import bpy
    world = bpy.data.worlds.new(f"World {mode}")
    world.use_nodes = True
    tree = world.node_tree
    bg = tree.nodes["Background"]
    bg.inputs["Strength"].default_value = 1.0
    if mode == "one":
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    else:
        geometry = tree.nodes.new("ShaderNodeNewGeometry")
        split = tree.nodes.new("ShaderNodeSeparateXYZ")
        affine = tree.nodes.new("ShaderNodeMath")
        affine.operation = "MULTIPLY_ADD"
        # Incoming points back along the ray: d = -Incoming, so (1 + d) / 2 = -0.5 I + 0.5
        affine.inputs[1].default_value = -0.5
        affine.inputs[2].default_value = 0.5
        tree.links.new(geometry.outputs["Incoming"], split.inputs[0])
        tree.links.new(split.outputs["Y" if mode == "y" else "Z"], affine.inputs[0])
        tree.links.new(affine.outputs[0], bg.inputs["Color"])
    world.cycles.sampling_method = "NONE"
    scene.world = world


def build(mode):
    import bpy
    import parity_scenes as ps
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    _world(scene, mode)
    w = h = SIZE * (TILE + GAP) + GAP
    scene.render.resolution_x, scene.render.resolution_y = w, h
    scene.render.resolution_percentage = 100
    cam_data = bpy.data.cameras.new("Ortho")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = w * PIXEL
    cam_data.clip_start, cam_data.clip_end = 0.1, 100.0
    cam = bpy.data.objects.new("Ortho", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.0, 0.0, 20.0)
    scene.camera = cam
    half = TILE * PIXEL / 2
    bounds = {}
    mus = _mu_nodes()
    for j in range(SIZE):                              # rows: roughness j / 31
        mat = bpy.data.materials.new(f"sheen r{j}")
        nodes = mat.node_tree.nodes
        nodes.remove(nodes["Principled BSDF"])
        sheen = nodes.new("ShaderNodeBsdfSheen")
        sheen.distribution = "MICROFIBER"
        sheen.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        sheen.inputs["Roughness"].default_value = j / (SIZE - 1)
        mat.node_tree.links.new(sheen.outputs[0], nodes["Material Output"].inputs["Surface"])
        y0 = GAP + j * (TILE + GAP)
        cy = (h / 2 - (y0 + TILE / 2)) * PIXEL
        for i, mu in enumerate(mus):                   # columns: view cosine
            x0 = GAP + i * (TILE + GAP)
            cx = (x0 + TILE / 2 - w / 2) * PIXEL
            hy = half / mu
            obj = ps._mesh_object(f"t{j}_{i}", [(-half, -hy, 0), (half, -hy, 0), (half, hy, 0),
                                                (-half, hy, 0)], [(0, 1, 2, 3)], mat)
            obj.rotation_euler = (math.acos(mu), 0.0, 0.0)
            obj.location = (cx, cy, 0.0)
            for ray in ("diffuse", "glossy", "transmission", "shadow", "volume_scatter"):
                setattr(obj, f"visible_{ray}", False)
            bounds[(i, j)] = (y0 + MARGIN, y0 + TILE - MARGIN, x0 + MARGIN, x0 + TILE - MARGIN)
    bpy.context.view_layer.update()
    return scene, bounds


def measure(samples, seed=1):
    """(A, mean g_y, mean g_z, se of both) per (mu, r) tile, each (32, 32)."""
    import make_cycles_refs as mcr
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode, spp in (("one", 4), ("y", samples), ("z", samples)):
            scene, bounds = build(mode)
            mcr.configure_cycles(scene, spp, seed, gi=True)
            scene.cycles.max_bounces = 1
            img, dt = mcr.render_exr(scene, str(Path(tmp) / f"sheen_{mode}.exr"))
            print(f"  world {mode}: {spp} spp, {dt:.1f} s; gap {img[:GAP - 1].mean():.4f}",
                  flush=True)
            mean = np.zeros((SIZE, SIZE))
            se = np.zeros((SIZE, SIZE))
            for (i, j), (y0, y1, x0, x1) in bounds.items():
                tile = img[y0:y1, x0:x1, 1]
                mean[i, j] = tile.mean()
                se[i, j] = tile.std(ddof=1) / math.sqrt(tile.size)
            out[mode] = (mean, se)
    return out


# -- LTC fit ---------------------------------------------------------------------------------
_G = 256
_U = (np.stack(np.meshgrid(np.arange(_G), np.arange(_G), indexing="ij"), -1).reshape(-1, 2)
      + 0.5) / _G
_R = np.sqrt(_U[:, 0])
_DISK = np.stack([_R * np.cos(2 * np.pi * _U[:, 1]), _R * np.sin(2 * np.pi * _U[:, 1])], 1)
_DZ = np.sqrt(np.maximum(1.0 - (_DISK ** 2).sum(1), 0.0))


def ltc_moments(a, b):
    """(E[x], E[z]) of the LTC density D of (a, b) (module docstring)."""
    v = np.stack([(_DISK[:, 0] - _DZ * b) / a, _DISK[:, 1] / a, _DZ], 1)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[:, 0].mean(), v[:, 2].mean()


def fit_node(ex, ez, guess=(1.0, 0.0)):
    from scipy.optimize import least_squares

    def residual(p):
        mx, mz = ltc_moments(np.exp(p[0]), p[1])
        return [mx - ex, mz - ez]

    sol = least_squares(residual, [np.log(guess[0]), guess[1]], method="lm")
    return float(np.exp(sol.x[0])), float(sol.x[1]), float(np.abs(sol.fun).max())


def _unmix_edges(t):
    """Node values from the values read at the edge positions (module docstring)."""
    t = t.copy()
    f0 = MU_LOW * (SIZE - 1)                        # 0.31 of node 1 in the mu = 0 column
    t[0] = (t[0] - f0 * t[1]) / (1 - f0)
    f1 = (1 - MU_HIGH) * (SIZE - 1)                 # node 30's share in the mu = 1 column
    t[-1] = (t[-1] - f1 * t[-2]) / (1 - f1)
    g0 = R_LOW * (SIZE - 1)
    t[:, 0] = (t[:, 0] - g0 * t[:, 1]) / (1 - g0)
    return t


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--out", type=Path, default=ROOT / "engine" / "data" / "sheen_ltc.npz")
    parser.add_argument("--raw", type=Path, help="save/reuse the raw measurements here")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    if args.raw and args.raw.exists():
        raw = dict(np.load(args.raw))
    else:
        m = measure(args.samples)
        raw = {"one": m["one"][0], "y": m["y"][0], "z": m["z"][0], "se_y": m["y"][1],
               "se_z": m["z"][1]}
        if args.raw:
            np.savez(args.raw, **raw)
    A = raw["one"]
    mus = _mu_nodes()
    t = np.arccos(mus)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        dy = 2 * raw["y"] / A - 1
        dz = 2 * raw["z"] / A - 1
        ex = np.cos(t) * dy + np.sin(t) * dz
        ez = -np.sin(t) * dy + np.cos(t) * dz
        se_ex = 2 * np.hypot(raw["se_y"], raw["se_z"]) / A
    a = np.zeros((SIZE, SIZE))
    b = np.zeros((SIZE, SIZE))
    worst = 0.0
    for j in range(SIZE):
        guess = (1.0, 0.0)
        for i in range(SIZE - 1, -1, -1):
            if not A[i, j] > 1e-5:
                continue
            a[i, j], b[i, j], res = fit_node(ex[i, j], ez[i, j], guess)
            guess = (a[i, j], b[i, j])
            worst = max(worst, res)
    # The edge nodes solved from their neighbours stay physical: A >= 0.
    table = {"A": np.clip(_unmix_edges(A), 0.0, None), "a": _unmix_edges(a), "b": _unmix_edges(b),
             "Ex": ex, "Ez": ez, "se_Ex": se_ex,
             "note": np.array(f"made by tools/sheen_ltc_table.py --samples {args.samples} "
                              "(Cycles 5.2 Sheen BSDF, Microfiber, measured by rendering)")}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, **table)
    print(f"worst moment residual {worst:.2e}; largest SE of E[x] {np.nanmax(se_ex):.2e}; "
          f"{time.perf_counter() - start:.0f} s -> {args.out}")


if __name__ == "__main__":
    main()
