"""engine/imageio.py: EXR round trips bit for bit, PNG holds the sRGB encoding, atomic writes."""
import os

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from lanterna.engine import imageio


def test_exr_round_trip_is_exact_for_float32(tmp_path):
    rng = np.random.default_rng(7)
    image = (rng.standard_normal((13, 17, 3)) * 10.0 ** rng.integers(-30, 30, (13, 17, 3)))
    image = image.astype(np.float32)
    image[0, 0] = [0.0, -0.0, np.float32(1e-45)]            # zero, signed zero, a denormal
    image[1, 1] = [np.finfo(np.float32).max, np.inf, -np.inf]
    direct = rng.random((13, 17, 3)).astype(np.float32)
    depth = rng.random((13, 17)).astype(np.float32) * 100
    path = tmp_path / "round.exr"
    imageio.write_exr(path, image, {"Direct": direct, "Depth.Z": depth},
                      attributes={"software": "Lanterna test"})

    channels = imageio.read_exr(path)
    assert sorted(channels) == ["B", "Depth.Z", "Direct.B", "Direct.G", "Direct.R", "G", "R"]
    back = imageio.read_exr_rgb(path)
    assert back.dtype == np.float32 and back.shape == (13, 17, 3)
    assert np.array_equal(back.view(np.uint32), image.view(np.uint32))  # bit for bit
    assert np.array_equal(imageio.read_exr_rgb(path, layer="Direct"), direct)
    assert np.array_equal(channels["Depth.Z"], depth)

    with OpenEXR.File(str(path), separate_channels=True) as f:
        assert f.header()["software"] == "Lanterna test"
        assert all(ch.type() == OpenEXR.FLOAT for ch in f.channels().values())


def test_exr_rows_are_top_down(tmp_path):
    """Row 0 of the array is the first scanline of the file (the top of the picture)."""
    image = np.zeros((4, 3, 3), np.float32)
    image[:, :, 0] = np.arange(4, dtype=np.float32)[:, None]
    path = tmp_path / "rows.exr"
    imageio.write_exr(path, image)
    with OpenEXR.File(str(path)) as f:
        (x0, y0), (x1, y1) = f.header()["dataWindow"]
        assert (x0, y0, x1, y1) == (0, 0, 2, 3)
        assert f.header()["lineOrder"] == OpenEXR.INCREASING_Y
    assert imageio.read_exr(path)["R"][:, 0].tolist() == [0.0, 1.0, 2.0, 3.0]


def test_exr_rejects_bad_shapes(tmp_path):
    with pytest.raises(ValueError):
        imageio.write_exr(tmp_path / "a.exr", np.zeros((4, 4, 2)))
    with pytest.raises(ValueError):
        imageio.write_exr(tmp_path / "b.exr", np.zeros((4, 4, 3)), {"Depth.Z": np.zeros((3, 4))})
    assert list(tmp_path.iterdir()) == []  # checked before anything is written


def test_png_values_follow_srgb(tmp_path):
    # linear:   0   0.002  0.18  0.5  1.0  2.0 (clipped)  -1 (clipped)  NaN
    # expected: 0   7      118   188  255  255            0             0
    # (sRGB(0.002) = 12.92 x 0.002 = 0.0258 -> 6.6; sRGB(0.18) = 0.4614 -> 117.6;
    #  sRGB(0.5) = 1.055 x 0.5^(1/2.4) - 0.055 = 0.7354 -> 187.5)
    values = np.array([0.0, 0.002, 0.18, 0.5, 1.0, 2.0, -1.0, np.nan], np.float32)
    image = np.repeat(values[None, :, None], 3, axis=2)
    image[..., 1] *= 0.0                                   # green channel black
    path = tmp_path / "ramp.png"
    imageio.write_png(path, image)
    with Image.open(path) as png:
        assert png.mode == "RGB" and png.size == (8, 1)
        data = np.asarray(png)
    assert data[0, :, 0].tolist() == [0, 7, 118, 188, 255, 255, 0, 0]
    assert data[0, :, 1].tolist() == [0] * 8
    assert np.array_equal(data[0, :, 2], data[0, :, 0])


def test_png_rows_are_top_down(tmp_path):
    image = np.zeros((6, 4, 3), np.float32)
    image[0] = 1.0  # top row white
    path = tmp_path / "top.png"
    imageio.write_png(path, image)
    data = np.asarray(Image.open(path))
    assert data[0].min() == 255 and data[1:].max() == 0


def test_srgb_transfer_functions():
    x = np.linspace(0, 1, 1001)
    assert np.allclose(imageio.srgb_to_linear(imageio.linear_to_srgb(x)), x, atol=1e-12)
    # Continuous at the knee and exact at the ends.
    assert imageio.linear_to_srgb(0.0031308) == pytest.approx(0.040449936, abs=1e-6)
    assert imageio.linear_to_srgb(1.0) == pytest.approx(1.0, abs=1e-12)


def test_atomic_output_leaves_nothing_half_written(tmp_path):
    target = tmp_path / "out.exr"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with imageio.atomic_output(target) as tmp:
            with open(tmp, "wb") as f:
                f.write(b"partial")
            raise RuntimeError("crash while writing")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]

    with imageio.atomic_output(target) as tmp:
        assert os.path.dirname(tmp) == str(tmp_path)
        imageio.write_exr(tmp, np.ones((2, 2, 3), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    assert imageio.read_exr_rgb(target).tolist() == np.ones((2, 2, 3)).tolist()


def test_write_json_is_all_or_nothing_and_output_problem_names_the_cause(tmp_path):
    path = tmp_path / "report.json"
    imageio.write_json(path, {"a": 1})
    assert path.read_text() == '{\n  "a": 1\n}'
    with pytest.raises(ValueError):                       # NaN refused: the old file stays
        imageio.write_json(path, {"a": float("nan")}, allow_nan=False)
    assert path.read_text() == '{\n  "a": 1\n}'
    assert sorted(os.listdir(tmp_path)) == ["report.json"]
    assert imageio.output_problem(path) is None
    assert "does not exist" in imageio.output_problem(tmp_path / "missing" / "x.json")
    assert "is a directory" in imageio.output_problem(tmp_path)
