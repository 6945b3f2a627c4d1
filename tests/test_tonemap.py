"""The seed's tone curve (engine/tonemap.py, seed Fig. 11.1 and section 12.2.1) and the
``lanterna tonemap`` / ``lanterna render --png --sensitivity`` commands.

The curve is checked against its closed form: v = 0.75 L / p1 below the knee, 0.75 + 0.25 (L -
p1) / (p2 - p1) up to the saturation point, 1 above; RGB = floor(255 v + 0.5). The float curve
must match to 1e-12 (float64 arithmetic on exact inputs); the 8-bit values exactly.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from lanterna.engine import imageio, tonemap
from lanterna.engine.tonemap import KNEE_FRACTION, KNEE_VALUE, ToneMapError


def rgb8(v):
    return int(np.floor(255.0 * v + 0.5))


# -- The curve --------------------------------------------------------------------------------
def test_curve_matches_the_closed_form_at_its_landmarks():
    p2, p1 = 2.0, 0.5
    L = np.array([0.0, p1 / 2, p1, (p1 + p2) / 2, p2, 2 * p2, 1e30])
    expected = [0.0, KNEE_VALUE / 2, KNEE_VALUE, (KNEE_VALUE + 1) / 2, 1.0, 1.0, 1.0]
    np.testing.assert_allclose(tonemap.tone_curve(L, p2, p1), expected, rtol=0, atol=1e-12)
    img = np.broadcast_to(L[None, :, None], (1, L.size, 3))
    out = tonemap.seed_tone_curve(img, p2, p1)
    assert out.dtype == np.uint8 and out.shape == (1, L.size, 3)
    # 0 -> 0, knee -> 191 (0.75 * 255 = 191.25), p2 and above -> 255
    assert out[0, :, 0].tolist() == [0, 96, 191, 223, 255, 255, 255]
    assert out[0, :, 0].tolist() == [rgb8(v) for v in expected]


def test_default_knee_is_a_quarter_of_the_sensitivity():
    assert KNEE_FRACTION == 0.25 and KNEE_VALUE == 0.75
    assert tonemap.check_parameters(4.0) == (4.0, 1.0)
    L = np.array([1.0, 0.5, 2.5])
    np.testing.assert_allclose(tonemap.tone_curve(L, 4.0), tonemap.tone_curve(L, 4.0, 1.0),
                               rtol=0, atol=0)
    np.testing.assert_allclose(tonemap.tone_curve(L, 4.0), [0.75, 0.375, 0.875], atol=1e-12)


def test_curve_is_continuous_monotonic_and_scales_with_the_sensitivity():
    p2, p1 = 3.0, 0.4
    L = np.linspace(0.0, 2 * p2, 200_001)
    v = tonemap.tone_curve(L, p2, p1)
    assert np.all(np.diff(v) >= 0.0)
    assert v[0] == 0.0 and v[-1] == 1.0
    assert np.abs(np.diff(v)).max() < 1e-4            # no jump (steepest slope * step = 3e-5)
    below, above = L < p1, (L > p1) & (L < p2)
    slope_low = np.diff(v[below]) / np.diff(L[below])
    slope_high = np.diff(v[above]) / np.diff(L[above])
    np.testing.assert_allclose(slope_low, KNEE_VALUE / p1, rtol=1e-6)
    np.testing.assert_allclose(slope_high, (1 - KNEE_VALUE) / (p2 - p1), rtol=1e-6)
    # The sensitivity is a scale of the radiance axis: v(c L; c p2, c p1) = v(L; p2, p1).
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 2 * p2, (16, 16, 3))
    for c in (0.25, 8.0):
        assert np.array_equal(tonemap.seed_tone_curve(c * img, c * p2, c * p1),
                              tonemap.seed_tone_curve(img, p2, p1))


def test_per_channel_and_the_two_limits_of_section_11_2():
    p2 = 1.0
    pixel = np.array([[[2 * p2, 0.0, p2 / 4]]])   # red saturated, green black, blue at the knee
    assert tonemap.seed_tone_curve(pixel, p2).tolist() == [[[255, 0, 191]]]
    rng = np.random.default_rng(2)
    img = rng.uniform(0.01, 5.0, (8, 8, 3))
    img[0, 0] = (3.0, 0.0, 3.0)
    # A very sensitive eye (p2 far below every radiance): only 0 and 255 (the seed's footnote).
    sat = tonemap.seed_tone_curve(img, 1e-6)
    assert set(np.unique(sat).tolist()) == {0, 255}
    assert sat[0, 0].tolist() == [255, 0, 255]
    # A very insensitive eye (p2 far above): all black.
    assert not tonemap.seed_tone_curve(img, 1e6).any()


def test_grey_input_and_non_finite_values():
    grey = np.array([[0.0, 0.5, 1.0]])
    out = tonemap.seed_tone_curve(grey, 2.0)
    assert out.shape == (1, 3, 3) and out[0, :, 0].tolist() == [0, 191, rgb8(0.75 + 0.25 / 3)]
    assert np.array_equal(out[..., 0], out[..., 2])
    odd = np.array([[[np.nan, np.inf, -np.inf], [-1.0, 0.0, 1e30]]], np.float32)
    assert tonemap.seed_tone_curve(odd, 1.0).tolist() == [[[0, 255, 0], [0, 0, 255]]]


@pytest.mark.parametrize("p2, p1, message", [
    (0.0, None, "p2 must be > 0"),
    (-1.0, None, "p2 must be > 0"),
    (float("nan"), None, "must be finite"),
    (float("inf"), None, "must be finite"),
    ("bright", None, "must be a number"),
    (1.0, 1.0, "knee p1 must lie between 0"),
    (1.0, 2.0, "knee p1 must lie between 0"),
    (1.0, 0.0, "knee p1 must lie between 0"),
    (1.0, float("nan"), "must be finite"),
])
def test_bad_parameters_are_refused(p2, p1, message):
    with pytest.raises(ToneMapError, match=message):
        tonemap.seed_tone_curve(np.ones((2, 2, 3)), p2, p1)


def test_bad_shapes_are_refused():
    for shape in ((4,), (2, 2, 4), (0, 3, 3)):
        with pytest.raises(ToneMapError, match="must be an"):
            tonemap.seed_tone_curve(np.ones(shape), 1.0)


def test_auto_sensitivity_puts_the_knee_at_the_95th_percentile():
    # Brightest channel per pixel: 0, 1, ..., 99 (numpy's linear percentile: 94.05).
    values = np.arange(100, dtype=np.float64).reshape(10, 10)
    img = np.stack([values, values / 2, np.zeros_like(values)], axis=-1)
    p2, p1 = tonemap.auto_sensitivity(img)
    assert p1 == pytest.approx(94.05, abs=1e-9) and p2 == pytest.approx(4 * 94.05, abs=1e-9)
    v = tonemap.tone_curve(img[..., 0], p2, p1)
    assert (v <= KNEE_VALUE).mean() == 0.95             # 95 % of the pixels below the knee
    # Non-finite pixels are ignored; a mostly black picture uses its brightest value.
    img[0, 0, 0], img[0, 1, 1] = np.inf, np.nan
    assert tonemap.auto_sensitivity(img)[1] == pytest.approx(np.percentile(
        np.delete(values.ravel(), [0, 1]), 95), abs=1e-9)
    sparse = np.zeros((10, 10, 3))
    sparse[3, 4] = (0.0, 2.0, 0.0)
    assert tonemap.auto_sensitivity(sparse) == (8.0, 2.0)
    assert tonemap.auto_sensitivity(np.zeros((4, 4, 3))) == (1.0, 0.25)


# -- Files ------------------------------------------------------------------------------------
def test_read_radiance_picks_rgb_a_single_layer_or_grey(tmp_path):
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0, 3, (5, 7, 3)).astype(np.float32)
    rgba = np.concatenate([rgb, np.ones((5, 7, 1), np.float32)], axis=2)
    imageio.write_exr(tmp_path / "rgba.exr", rgba)
    assert np.array_equal(tonemap.read_radiance(tmp_path / "rgba.exr"), rgb)
    # A Blender-style multilayer file: Y plus ViewLayer.Combined.R/G/B.
    imageio.write_exr(tmp_path / "layer.exr", rgb[..., 0],
                      extra_channels={"ViewLayer.Combined": rgb})
    assert np.array_equal(tonemap.read_radiance(tmp_path / "layer.exr"), rgb)
    imageio.write_exr(tmp_path / "grey.exr", rgb[..., 1])
    assert np.array_equal(tonemap.read_radiance(tmp_path / "grey.exr"),
                          np.repeat(rgb[..., 1:2], 3, axis=2))
    imageio.write_exr(tmp_path / "two.exr", rgb[..., 0],
                      extra_channels={"Direct": rgb, "Indirect": rgb})
    with pytest.raises(ToneMapError, match="no single RGB layer"):
        tonemap.read_radiance(tmp_path / "two.exr")


# -- The command line -------------------------------------------------------------------------
from lanterna.engine.blender import cli  # noqa: E402  (no bpy at import)


def run_error(capfd, argv):
    """``main(argv)`` must fail with one stderr line ``lanterna: error: ...`` and status 2."""
    capfd.readouterr()
    code = cli.main(argv)
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (argv, err)
    assert len(lines) == 1 and lines[0].startswith("lanterna: error: "), err
    return lines[0]


def read_png(path):
    from PIL import Image

    with Image.open(path) as p:
        assert p.mode == "RGB"
        return np.asarray(p)


def test_tonemap_command_round_trip(tmp_path, capfd):
    rng = np.random.default_rng(4)
    image = rng.uniform(0, 2.5, (12, 20, 3)).astype(np.float32)
    image[0, 0] = (0.0, 0.5, 100.0)
    exr, png = tmp_path / "in.exr", tmp_path / "out.png"
    imageio.write_exr(exr, image)
    assert cli.main(["tonemap", str(exr), str(png), "--sensitivity", "2", "--knee", "0.5"]) == 0
    assert "sensitivity p2 = 2, knee p1 = 0.5" in capfd.readouterr().out
    out = read_png(png)
    assert out.shape == (12, 20, 3)
    assert np.array_equal(out, tonemap.seed_tone_curve(image, 2.0, 0.5))
    assert out[0, 0].tolist() == [0, 191, 255]
    # Default: automatic sensitivity.
    assert cli.main(["tonemap", str(exr), str(png)]) == 0
    assert np.array_equal(read_png(png),
                          tonemap.seed_tone_curve(image, *tonemap.auto_sensitivity(image)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.exr", "out.png"]


def test_tonemap_command_errors_leave_nothing_behind(tmp_path, capfd):
    exr, png = tmp_path / "in.exr", tmp_path / "out.png"
    imageio.write_exr(exr, np.ones((4, 4, 3), np.float32))
    (tmp_path / "notes.exr").write_text("not an image\n")
    (tmp_path / "broken.exr").write_bytes(tonemap.EXR_MAGIC + b"\x02\x00\x00\x00garbage")
    cases = [
        (["tonemap", str(tmp_path / "missing.exr"), str(png)], "no such file"),
        (["tonemap", str(tmp_path / "notes.exr"), str(png)], "not an OpenEXR file"),
        (["tonemap", str(tmp_path / "broken.exr"), str(png)], "cannot be read as OpenEXR"),
        (["tonemap", str(tmp_path), str(png)], "not a file"),
        (["tonemap", str(exr), str(png), "--sensitivity", "0"], "must be a finite radiance > 0"),
        (["tonemap", str(exr), str(png), "--sensitivity", "-2"], "must be a finite radiance > 0"),
        (["tonemap", str(exr), str(png), "--sensitivity", "inf"], "finite radiance"),
        (["tonemap", str(exr), str(png), "--sensitivity", "lots"], "number or 'auto'"),
        (["tonemap", str(exr), str(png), "--sensitivity", "1", "--knee", "1"], "must be below"),
        (["tonemap", str(exr), str(png), "--sensitivity", "1", "--knee", "3"], "must be below"),
        (["tonemap", str(exr), str(png), "--knee", "0.1"], "needs --sensitivity"),
        (["tonemap", str(exr), str(tmp_path / "out.jpg")], "must end in .png"),
        (["tonemap", str(exr), str(tmp_path / "no" / "out.png")], "does not exist"),
        (["tonemap", str(exr)], "required"),
    ]
    for argv, message in cases:
        line = run_error(capfd, argv)
        assert message in line, (argv, line)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.exr", "in.exr", "notes.exr"]


def test_tonemap_command_does_not_import_bpy(tmp_path):
    exr = tmp_path / "in.exr"
    imageio.write_exr(exr, np.full((3, 3, 3), 0.5, np.float32))
    code = ("import sys; from lanterna.engine.blender import cli; "
            f"rc = cli.main(['tonemap', {str(exr)!r}, {str(tmp_path / 'o.png')!r}]); "
            "print('bpy' in sys.modules, rc)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "False 0"
    assert os.path.isfile(tmp_path / "o.png")


def test_render_writes_a_tone_mapped_png(tmp_path, capfd):
    pytest.importorskip("bpy")
    from lanterna.engine.blender import registration

    was = registration.is_registered()
    exr, png = tmp_path / "r.exr", tmp_path / "r.png"
    try:
        # Refused before rendering: nothing written.
        base = ["render", "--scene", "scene1", "--resolution", "32x24", "-o", str(exr)]
        assert "need --png" in run_error(capfd, base + ["--sensitivity", "1"])
        assert "must be below" in run_error(capfd, base + ["--png", str(png), "--sensitivity",
                                                           "1", "--knee", "2"])
        assert list(tmp_path.iterdir()) == []
        code = cli.main(base + ["--samples", "1", "--light-samples", "1", "--bounces", "0",
                                "--seed", "3", "--png", str(png), "--sensitivity", "1.5",
                                "--knee", "0.3", "--quiet"])
        assert code == 0, capfd.readouterr().err
        assert "sensitivity p2 = 1.5, knee p1 = 0.3" in capfd.readouterr().out
        assert sorted(p.name for p in tmp_path.iterdir()) == ["r.exr", "r.png"]
        out = read_png(png)
        assert out.shape == (24, 32, 3)
        image = imageio.read_exr_rgb(exr)
        assert np.array_equal(out, tonemap.seed_tone_curve(image, 1.5, 0.3))
        assert out.max() > 0, "the seed's Scene 1 is lit"
    finally:
        if not was:
            registration.unregister()


def test_layer_picks_a_pass(tmp_path, capfd):
    """--layer converts one pass of a file that holds several (render --passes)."""
    rgb = np.full((4, 6, 3), 0.5, np.float32)
    direct = np.zeros((4, 6, 3), np.float32)
    direct[1, 2] = 3.0
    path = tmp_path / "p.exr"
    imageio.write_exr(path, rgb, extra_channels={"Direct": direct, "ViewLayer.Photons": rgb * 2})
    np.testing.assert_array_equal(tonemap.read_radiance(path, layer="Direct"), direct)
    np.testing.assert_array_equal(tonemap.read_radiance(path, layer="Photons"), rgb * 2)
    np.testing.assert_array_equal(tonemap.read_radiance(path), rgb)        # the image itself
    with pytest.raises(ToneMapError, match="no layer 'Indirect'.*Direct"):
        tonemap.read_radiance(path, layer="Indirect")
    out = tmp_path / "d.png"
    assert cli.main(["tonemap", str(path), str(out), "--layer", "Direct", "--sensitivity", "2"]) == 0
    from PIL import Image
    with Image.open(out) as im:
        px = np.asarray(im.convert("RGB"))
    assert px[1, 2].tolist() == [255, 255, 255] and px.sum() == 3 * 255
