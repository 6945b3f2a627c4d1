"""Image files: OpenEXR (linear float32) and PNG (sRGB, 8 bit), written atomically.

No ``bpy``: the command line, the benchmarks and the tests all write their pictures here.

Conventions
-----------
* Images are ``(H, W, 3)`` (or ``(H, W)``) arrays of linear radiance [W m^-2 sr^-1], row 0 is
  the **top** of the picture (the pipeline's convention, and OpenEXR's ``INCREASING_Y``).
* :func:`write_exr` stores channels ``R``, ``G``, ``B`` as 32-bit float, plus any extra named
  channels, e.g. ``{"Direct": (H, W, 3)}`` becomes ``Direct.R``, ``Direct.G``, ``Direct.B`` and
  ``{"Depth.Z": (H, W)}`` is stored as it is. ZIP compression (lossless).
* :func:`write_png` applies the sRGB transfer function (IEC 61966-2-1) to the linear values,
  clipped to [0, 1], and rounds to 8 bit. No tone mapping, no exposure: 1.0 is white. It is a
  preview; the EXR is the result.
* :func:`atomic_output` gives a temporary name in the target's directory and renames it over
  the target only when the block succeeds, so a crash never leaves a half-written file;
  :func:`write_json` writes a report that way, and :func:`output_problem` says before any
  work why a file could not be written there (the benchmarks check their ``--json`` first).
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile

import numpy as np

__all__ = [
    "write_exr", "read_exr", "read_exr_rgb", "write_png", "linear_to_srgb", "srgb_to_linear",
    "atomic_output", "write_json", "output_problem",
]


# -- Transfer functions -----------------------------------------------------------------------
def linear_to_srgb(x) -> np.ndarray:
    """sRGB encoding of linear values (IEC 61966-2-1); input clipped to [0, 1], NaN -> 0."""
    x = np.nan_to_num(np.asarray(x, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(v) -> np.ndarray:
    """Inverse of :func:`linear_to_srgb` for encoded values in [0, 1]."""
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


# -- Atomic writing ---------------------------------------------------------------------------
@contextlib.contextmanager
def atomic_output(path):
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    On an exception the temporary file is removed and ``path`` is left as it was.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp",
                               dir=directory)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_json(path, data, **dump_options) -> None:
    """``data`` as indented JSON at ``path``, all or nothing (:func:`atomic_output`);
    ``dump_options`` go to ``json.dump`` (e.g. ``default=str``, ``allow_nan=False``)."""
    with atomic_output(path) as tmp, open(tmp, "w") as fh:
        json.dump(data, fh, indent=2, **dump_options)


def output_problem(path) -> str | None:
    """Why ``path`` cannot be written (its directory is missing or not writable, or it is a
    directory), or None: asked before long work, so that it does not end in a traceback."""
    path = os.path.abspath(os.fspath(path))
    parent = os.path.dirname(path)
    if os.path.isdir(path):
        return f"{path} is a directory"
    if not os.path.isdir(parent):
        return f"directory {parent} does not exist"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"directory {parent} is not writable"
    return None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# -- OpenEXR ----------------------------------------------------------------------------------
def _as_hw(arr: np.ndarray, shape: tuple[int, int], name: str) -> np.ndarray:
    arr = np.asarray(arr, dtype=np.float32)
    if arr.shape != shape:
        raise ValueError(f"EXR channel {name!r} has shape {arr.shape}, expected {shape}")
    return np.ascontiguousarray(arr)


def _channels(image, extra_channels) -> dict[str, np.ndarray]:
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4) or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image must be (H, W, 3), (H, W, 4) or (H, W); got {img.shape}")
    hw = img.shape[:2]
    names = {1: "Y", 3: "RGB", 4: "RGBA"}[img.shape[2]]
    out = {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate(names)}
    for key, value in (extra_channels or {}).items():
        value = np.asarray(value, dtype=np.float32)
        if value.ndim == 3 and value.shape[2] in (3, 4):
            for i, c in enumerate("RGBA"[: value.shape[2]]):
                out[f"{key}.{c}"] = _as_hw(value[..., i], hw, f"{key}.{c}")
        else:
            out[key] = _as_hw(value, hw, key)
    return out


def write_exr(path, image, extra_channels=None, attributes=None) -> None:
    """Write ``image`` (linear, row 0 = top) as a float32 OpenEXR file.

    ``extra_channels``: ``{name: (H, W)}`` stored as channel ``name``, or ``{layer: (H, W, 3)}``
    stored as ``layer.R``, ``layer.G``, ``layer.B``. ``attributes``: extra header entries
    (strings or numbers), e.g. ``{"software": "Lanterna"}``. The file is written in place; wrap
    the call in :func:`atomic_output` for all-or-nothing writing.
    """
    import OpenEXR

    channels = _channels(image, extra_channels)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        header[str(key)] = value
    OpenEXR.File(header, channels).write(os.fspath(path))


def read_exr(path) -> dict[str, np.ndarray]:
    """Every channel of an OpenEXR file as ``{name: (H, W) float32}`` (row 0 = top), from
    every part of a multi-part file (Blender writes each pass of a multilayer EXR as a part)."""
    import OpenEXR

    with OpenEXR.File(os.fspath(path), separate_channels=True) as f:
        return {name: np.array(ch.pixels, dtype=np.float32)
                for part in f.parts for name, ch in part.channels.items()}


def read_exr_rgb(path, layer: str | None = None) -> np.ndarray:
    """The ``R``, ``G``, ``B`` channels (or ``layer.R`` ...) as one ``(H, W, 3)`` float32 array."""
    channels = read_exr(path)
    prefix = f"{layer}." if layer else ""
    try:
        return np.stack([channels[prefix + c] for c in "RGB"], axis=-1)
    except KeyError as exc:
        raise KeyError(f"{os.fspath(path)}: no channel {exc.args[0]!r} "
                       f"(has {sorted(channels)})") from None


# -- PNG --------------------------------------------------------------------------------------
def write_png(path, image) -> None:
    """Write linear ``image`` (H, W, 3) or (H, W, 4), row 0 = top, as an 8-bit sRGB PNG.

    Colour channels go through :func:`linear_to_srgb` (clipped to [0, 1]); alpha is stored
    linearly. Values are rounded to the nearest of 0..255.
    """
    from PIL import Image

    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValueError(f"image must be (H, W, 3) or (H, W, 4); got {img.shape}")
    encoded = linear_to_srgb(img[..., :3])
    if img.shape[2] == 4:
        alpha = np.clip(np.nan_to_num(img[..., 3:4], nan=0.0), 0.0, 1.0)
        encoded = np.concatenate([encoded, alpha], axis=2)
    data = np.round(encoded * 255.0).astype(np.uint8)
    Image.fromarray(data, mode="RGBA" if data.shape[2] == 4 else "RGB").save(
        os.fspath(path), format="PNG")
