"""The photon estimate's disc where a surface ends (``Accelerator.disc_coverage``; no bpy).

A k-nearest-neighbour estimate divides the photons on its surface by pi r^2. Where the disc
crosses an edge (a wall rising from the floor, the rim of a box's top) part of that area is
not surface, and the estimate came out too dark there: about 1 % over a closed box
(``tests/test_analytic_modes.py``), 2-3 % of the indirect light in a room's corner. The
coverage is the share of the disc that its surface covers; the estimate divides by that
share of pi r^2. Where another surface took many of the k nearest photons, the estimate
asks for more and takes its radius at the k-th that counts (``PhotonMap._kept_k``).

Closed forms: a straight edge at distance d from the centre of a disc of radius r leaves
1 - (theta - sin theta cos theta) / pi of it, theta = acos(d / r). The coverage sums 8 polar
directions turned by a hash of each point, so one point's value scatters about it; the means
over many points are checked (one point's SD about the closed form: 0.021, measured below).
"""
import numpy as np
import pytest

from analytic import box_room, icosphere, quad
from lanterna.engine.accel import COVERAGE_MIN, Accelerator
from lanterna.engine.photons import PhotonMap

UP = np.array([0.0, 0.0, 1.0])


def edge_share(d, r):
    theta = np.arccos(np.clip(d / r, -1.0, 1.0))
    return 1.0 - (theta - np.sin(theta) * np.cos(theta)) / np.pi


def floor_points(rng, count, x_range, y_range=(1.0, 3.0)):
    return np.column_stack([rng.uniform(*x_range, count), rng.uniform(*y_range, count),
                            np.zeros(count)])


@pytest.fixture(scope="module")
def room():
    accel = Accelerator(box_room(size=(4.0, 4.0, 3.0)), threads=1)
    yield accel
    accel.close()


def test_inside_a_face_the_whole_disc_counts(room):
    rng = np.random.default_rng(1)
    x = floor_points(rng, 500, (1.0, 3.0))
    share = room.disc_coverage(x, np.tile(UP, (500, 1)), np.full(500, 0.2))
    assert np.all(share == 1.0)


def test_a_wall_rising_from_the_floor_cuts_the_disc(room):
    """Floor points 0-0.1 m from the left wall (x = 0), r = 0.1: the mean coverage over 2000
    points in bins of distance is the half-plane share (SD of one point 0.021, so a bin's
    mean of ~200 points scatters by 0.0015; measured: within 0.0023; bound 0.01)."""
    rng = np.random.default_rng(2)
    r = 0.1
    x = floor_points(rng, 2000, (0.0, r))
    share = room.disc_coverage(x, np.tile(UP, (len(x), 1)), np.full(len(x), r))
    bins = np.digitize(x[:, 0], np.linspace(0, r, 11)) - 1
    for b in range(10):
        inside = bins == b
        expect = edge_share(x[inside, 0], r).mean()
        assert share[inside].mean() == pytest.approx(expect, abs=0.01), b


def test_a_corner_leaves_a_quarter(room):
    corner = np.array([[1e-3, 1e-3, 0.0], [4.0 - 1e-3, 4.0 - 1e-3, 0.0]])
    share = room.disc_coverage(corner, np.tile(UP, (2, 1)), np.full(2, 0.5))
    np.testing.assert_allclose(share, 0.25, atol=0.01)
    assert COVERAGE_MIN == 0.25


def test_the_rim_of_a_box_s_top_cuts_the_disc_from_below():
    """A closed 1 m cube on no floor: its top's points near the rim x = 1 see nothing above
    them; the probes just below the top meet the cube's side from inside."""
    faces = [quad([0.5, 0.5, 1.0], [0.5, 0, 0], [0, 0.5, 0]), quad([0.5, 0.5, 0.0], [0.5, 0, 0], [0, 0.5, 0]),
             quad([0.0, 0.5, 0.5], [0, 0.5, 0], [0, 0, 0.5]), quad([1.0, 0.5, 0.5], [0, 0.5, 0], [0, 0, 0.5]),
             quad([0.5, 0.0, 0.5], [0.5, 0, 0], [0, 0, 0.5]), quad([0.5, 1.0, 0.5], [0.5, 0, 0], [0, 0, 0.5])]
    accel = Accelerator(np.concatenate(faces), threads=1)
    rng = np.random.default_rng(3)
    r = 0.1
    d = rng.uniform(0.0, r, 1500)
    x = np.column_stack([1.0 - d, rng.uniform(0.3, 0.7, len(d)), np.ones(len(d))])
    share = accel.disc_coverage(x, np.tile(UP, (len(x), 1)), np.full(len(x), r))
    assert share.mean() == pytest.approx(edge_share(d, r).mean(), abs=0.006)
    accel.close()


def test_a_curved_surface_is_not_an_edge():
    """A closed geodesic sphere (R = 1 m, facets 5 deg apart) at its facets' centres, r =
    5 cm: the probes below meet the sphere itself a few cm on, turned a few degrees only."""
    tris = icosphere(radius=1.0, subdivisions=4)
    accel = Accelerator(tris, threads=1)
    c = tris.astype(np.float64).mean(axis=1)
    n = c / np.linalg.norm(c, axis=1, keepdims=True)
    assert np.all(accel.disc_coverage(c, n, np.full(len(c), 0.05)) == 1.0)
    assert np.all(accel.disc_coverage(c, -n, np.full(len(c), 0.05)) == 1.0)
    accel.close()


def test_the_estimate_by_a_wall_is_the_uniform_irradiance(room):
    """Photons of power 1 W spread uniformly (a jittered grid) over the floor and the left
    wall at 20 000 per m^2: E = 20 000 W/m^2 everywhere. At floor points 0-4 cm from the
    wall (k = 50: r = 2.8 cm) the estimate with the coverage averages E (seeds 4-7: 0.991-
    0.996 of it, the mean of 400 points scattering by 0.3 %; bound 2 %); without it, the
    share of the disc that the floor keeps (0.84-0.86 of E)."""
    rng = np.random.default_rng(4)
    density = 20_000.0
    side = 1.0 / np.sqrt(density)
    g = np.arange(0.0, 1.0, side)
    u, v = np.meshgrid(g, g, indexing="ij")
    jitter = rng.uniform(0, side, (2,) + u.shape)
    a, b = (u + jitter[0]).ravel(), (v + jitter[1]).ravel()
    floor = np.column_stack([a, 1.5 + b, np.zeros_like(a)])
    wall = np.column_stack([np.zeros_like(a), 1.5 + b, a])
    pos = np.concatenate([floor, wall])
    normals = np.concatenate([np.tile(UP, (len(a), 1)), np.tile([1.0, 0, 0], (len(a), 1))])
    pmap = PhotonMap(pos.astype(np.float32), np.ones((len(pos), 3), np.float32),
                     (-normals).astype(np.float16), normals.astype(np.float16),
                     np.zeros(len(pos), np.uint8)).build()
    x = floor_points(rng, 400, (0.0, 0.04), (1.8, 2.2))
    up = np.tile(UP, (len(x), 1))
    with_coverage = pmap.irradiance(x, up, k=50, coverage=room.disc_coverage)[:, 0]
    without = pmap.irradiance(x, up, k=50)[:, 0]
    assert with_coverage.mean() == pytest.approx(density, rel=0.02)
    assert without.mean() < 0.9 * density


def test_the_gather_s_estimates_take_the_coverage(monkeypatch):
    """The render's precomputed estimates (what gather rays read in the cache and gather
    modes) are built with the scene's own coverage."""
    from lanterna.engine import preparation
    from lanterna.engine.pipeline import RenderSettings, render
    from lanterna.engine.scene import Camera, Material, Scene

    seen = {}
    build = preparation.RadianceEstimates.build

    def spy(*args, **kwargs):
        seen.update(kwargs)
        return build(*args, **kwargs)

    monkeypatch.setattr(preparation.RadianceEstimates, "build", spy)
    tris = box_room(size=(2.0, 2.0, 2.0))
    scene = Scene(triangles=tris, material_ids=np.zeros(len(tris), np.int32),
                  materials=[Material("glow", diffuse=0.5, exitance=np.full(3, 1.0))],
                  camera=Camera.look_at([1, 0.2, 1], [1, 2, 1], resolution=(8, 8)))
    render(scene, RenderSettings(indirect="cache", samples=1, photons=20_000))
    coverage = seen["coverage"]
    assert coverage.__func__ is Accelerator.disc_coverage
    assert isinstance(coverage.__self__, Accelerator)


def _jittered_grid(rng, density):
    side = 1.0 / np.sqrt(density)
    g = np.arange(0.0, 1.0, side)
    u, v = np.meshgrid(g, g, indexing="ij")
    jitter = rng.uniform(0, side, (2,) + u.shape)
    return (u + jitter[0]).ravel(), (v + jitter[1]).ravel()


def test_by_a_bright_wall_the_radius_comes_from_the_photons_that_count(room):
    """A floor of 5 000 photons per m^2 by a wall of 80 000: the 50 nearest of a floor point
    by the wall are mostly the wall's, and an estimate from the few floor photons left is
    noisy (its SD over 400 points 0-3 cm from the wall: 0.17-0.19 of E, seeds 0-3). Asked
    again for 4 k neighbours, the 50th floor photon marks the radius: SD 0.079-0.085, the
    mean 0.977-1.017 of E (bounds: SD 0.12, mean within 6 %, 4 SD of the seeds' means)."""
    rng = np.random.default_rng(0)
    a, b = _jittered_grid(rng, 5000.0)
    c, d = _jittered_grid(rng, 80000.0)
    pos = np.concatenate([np.column_stack([a, 1.5 + b, 0 * a]), np.column_stack([0 * c, 1.5 + d, c])])
    normals = np.concatenate([np.tile(UP, (len(a), 1)), np.tile([1.0, 0, 0], (len(c), 1))])
    pmap = PhotonMap(pos.astype(np.float32), np.ones((len(pos), 3), np.float32),
                     (-normals).astype(np.float16), normals.astype(np.float16),
                     np.zeros(len(pos), np.uint8)).build()
    x = floor_points(rng, 400, (0.0, 0.03), (1.8, 2.2))
    e = pmap.irradiance(x, np.tile(UP, (len(x), 1)), k=50, coverage=room.disc_coverage)[:, 0]
    e /= 5000.0
    assert e.mean() == pytest.approx(1.0, abs=0.06)
    assert e.std() < 0.12
