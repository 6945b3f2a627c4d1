"""The seed's tone curve: linear radiance -> 8-bit RGB with a saturation point (sensitivity).

What it computes (seed section 11.2, Figure 11.1; section 12.2.1, Figures 12.12 and 12.13)
    The seed saves the radiance of every pixel and converts it to RGB with the function of
    Figure 11.1, whose one parameter is the **saturation point** or **luminous sensitivity**
    ``p2``: every radiance above ``p2`` gets the RGB value of ``p2`` (255). Below it the curve
    has two pieces meeting at the knee ``p1``: from 0 to ``p1`` lies the radiance reflected
    by 95 % of a room lit by a lamp, from ``p1`` to ``p2`` the ceiling near the lamp, and
    ``p2`` is the lamp's own surface. Vision "is very sensitive to low intensities and very
    little to the others", so the first piece is steep and the second shallow::

        v(L) = V1 * L / p1                                  0  <= L <= p1
        v(L) = V1 + (1 - V1) * (L - p1) / (p2 - p1)         p1 <  L <  p2
        v(L) = 1                                            L  >= p2
        RGB  = floor(255 * v(L) + 0.5)                      (round half up, 0..255)

    ``seed_tone_curve(radiance, sensitivity, knee=None)``  the curve above, per pixel and
        per channel, as a ``(H, W, 3)`` uint8 array.
    ``auto_sensitivity(radiance)``  ``(p2, p1)`` for an image when none is given.
    ``read_radiance(path)``  the RGB radiance of an OpenEXR file; ``write_png(path, rgb8)``.

Parameters and units
    ``radiance``  ``(H, W, 3)`` linear radiance [W m^-2 sr^-1] (any float dtype; also
        ``(H, W)``, treated as grey). Row 0 is the top, as everywhere in Lanterna.
    ``sensitivity`` ``p2`` [W m^-2 sr^-1], finite and > 0: the saturation point. A low ``p2``
        is a very sensitive eye (bright picture, and in the limit every channel either 0 or
        255); a high ``p2`` an insensitive one (dark picture, in the limit all black).
    ``knee`` ``p1`` [W m^-2 sr^-1], finite, 0 < p1 < p2; default ``KNEE_FRACTION * p2`` =
        ``p2 / 4``.

Choices where the seed is silent (its Figure 11.1 is not in the text), and why
    * **The knee's height** ``V1 = KNEE_VALUE = 0.75`` (RGB 191) and the **default knee**
      ``p1 = p2 / 4``. The text fixes only the shape: a steep first piece holding most of
      the scene and a shallow second one up to the saturation point. With these numbers the
      first piece is 9 times steeper than the second and spends three quarters of the RGB
      range on the radiance below the knee. ``p1`` follows ``p2`` (rather than staying a
      fixed radiance) because the seed's conversion takes ``p2`` alone and a very high ``p2``
      must give an all-black picture, which a fixed knee would not. In the seed's own
      renders (Scene 2 here) 95 % of the pixels lie below about a fifth to a third of the
      brightest, so a quarter matches the room of section 11.2.
    * **Per channel**, not on luminance: the seed converts ``fluxoRadianteVermelho``, ``Verde``
      and ``Azul`` alike, and its footnote says a completely saturated picture holds only
      pixels such as (255, 0, 255), (0, 0, 255) and (255, 255, 255), channel values 0 or 255,
      which only a per-channel curve gives. Bright colours therefore drift towards their
      saturated primaries (the red cylinder turns pure red), as in Figure 12.13.
    * **No sRGB or gamma encoding** on top: the curve *is* the seed's perceptual mapping from
      radiance to the RGB value stored in the picture, so ``v`` is written as it is (the PNG
      is then shown as sRGB by any viewer). Lanterna's other PNGs (``imageio.write_png``,
      ``lanterna render --png`` without ``--sensitivity``) are the sRGB encoding of the
      clipped linear value instead.
    * **Automatic sensitivity** (``auto_sensitivity``): the knee is put at the 95th
      percentile of each pixel's brightest channel, ``p1 = P95``, and ``p2 = p1 /
      KNEE_FRACTION``: the curve of section 11.2, whose range 0..p1 holds "95 % of the
      room". If that percentile is 0 (a mostly black picture) the brightest finite value is
      used instead; an all-black picture gets ``p2 = 1`` (any value gives black).
    * **Non-finite and negative values** are mapped deterministically, not refused: NaN -> 0,
      -inf and negative radiance -> 0, +inf -> 255 (saturated). ``auto_sensitivity`` ignores
      non-finite values.

Errors
    Bad parameters or unreadable files raise ``ToneMapError`` (a ``ValueError``) with a
    one-line message that the command line prints as it is.
"""
from __future__ import annotations

import math
import os

import numpy as np

__all__ = [
    "KNEE_FRACTION", "KNEE_VALUE", "AUTO_PERCENTILE", "ToneMapError", "check_parameters",
    "tone_curve", "seed_tone_curve", "auto_sensitivity", "read_radiance", "write_png",
]

KNEE_FRACTION = 0.25    # default p1 / p2
KNEE_VALUE = 0.75       # v(p1): the knee's height, a fraction of 255
AUTO_PERCENTILE = 95.0  # automatic knee: this percentile of the pixels' brightest channel
EXR_MAGIC = b"\x76\x2f\x31\x01"


class ToneMapError(ValueError):
    """Bad tone-curve parameters or an unusable input file (one-line message)."""


def _finite_number(value, name: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ToneMapError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ToneMapError(f"{name} must be finite, got {value}")
    return value


def check_parameters(sensitivity, knee=None) -> tuple[float, float]:
    """Validated ``(p2, p1)``; ``knee=None`` gives the default ``KNEE_FRACTION * p2``."""
    p2 = _finite_number(sensitivity, "the sensitivity p2")
    if p2 <= 0.0:
        raise ToneMapError(f"the sensitivity p2 must be > 0, got {p2:g}")
    if knee is None:
        return p2, KNEE_FRACTION * p2
    p1 = _finite_number(knee, "the knee p1")
    if not 0.0 < p1 < p2:
        raise ToneMapError(f"the knee p1 must lie between 0 and the sensitivity p2 = {p2:g} "
                           f"(exclusive), got {p1:g}")
    return p2, p1


def _as_rgb(radiance) -> np.ndarray:
    img = np.asarray(radiance)
    if img.dtype.kind not in "fiu":
        raise ToneMapError(f"the radiance must be numbers, got dtype {img.dtype}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ToneMapError(f"the radiance must be an (H, W, 3) or (H, W) array, got shape "
                           f"{img.shape}")
    return img.astype(np.float64, copy=False)


def tone_curve(radiance, sensitivity, knee=None) -> np.ndarray:
    """The curve ``v(L)`` in [0, 1] (float64, same shape as ``radiance``), before rounding."""
    p2, p1 = check_parameters(sensitivity, knee)
    x = np.asarray(radiance, dtype=np.float64)
    x = np.nan_to_num(x, nan=0.0, posinf=np.inf, neginf=0.0)  # NaN, -inf -> 0; +inf stays
    x = np.maximum(x, 0.0)
    low = KNEE_VALUE * (x / p1)
    high = KNEE_VALUE + (1.0 - KNEE_VALUE) * ((x - p1) / (p2 - p1))
    with np.errstate(invalid="ignore"):   # inf in the unused branch
        v = np.where(x <= p1, low, high)
    return np.where(x >= p2, 1.0, v)


def seed_tone_curve(radiance, sensitivity, knee=None) -> np.ndarray:
    """``(H, W, 3)`` uint8: the seed's curve (Fig. 11.1) per channel, rounded half up.

    ``sensitivity`` is the saturation point ``p2`` [W m^-2 sr^-1]; ``knee`` the point ``p1``
    (default ``p2 / 4``). See the module docstring for the curve and its choices.
    """
    img = _as_rgb(radiance)
    v = tone_curve(img, sensitivity, knee)
    return np.floor(255.0 * v + 0.5).astype(np.uint8)


def auto_sensitivity(radiance) -> tuple[float, float]:
    """``(p2, p1)`` for ``radiance``: the knee at the 95th percentile of the pixels'
    brightest channel (section 11.2's "95 % of the room"), ``p2 = p1 / KNEE_FRACTION``."""
    img = _as_rgb(radiance)
    brightest = np.max(np.where(np.isfinite(img), np.maximum(img, 0.0), 0.0), axis=2)
    finite = np.isfinite(img).all(axis=2)
    values = brightest[finite] if finite.any() else np.zeros(1)
    p1 = float(np.percentile(values, AUTO_PERCENTILE))
    if not p1 > 0.0:
        p1 = float(values.max())
    if not (p1 > 0.0 and math.isfinite(p1 / KNEE_FRACTION)):
        return 1.0, KNEE_FRACTION
    return p1 / KNEE_FRACTION, p1


# -- Files ------------------------------------------------------------------------------------
def read_radiance(path, layer: str | None = None) -> np.ndarray:
    """The radiance of an OpenEXR file as ``(H, W, 3)`` float32 (row 0 = top).

    ``layer``: take ``<layer>.R/.G/.B`` (or, in a Blender multilayer file,
    ``<view layer>.<layer>.R`` ...) instead; missing -> ``ToneMapError`` naming the layers.

    Takes channels ``R``, ``G``, ``B`` (an ``RGBA`` file's alpha is ignored); else the one
    layer ``<layer>.R/.G/.B`` (Blender's multilayer ``ViewLayer.Combined.R`` ... preferred
    when there are several); else a grey ``Y`` channel. Anything else is a ``ToneMapError``.
    """
    from . import imageio

    path = os.fspath(path)
    if not os.path.exists(path):
        raise ToneMapError(f"{path}: no such file")
    if not os.path.isfile(path):
        raise ToneMapError(f"{path}: not a file")
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as exc:
        raise ToneMapError(f"{path}: cannot read ({exc.strerror})") from None
    if head != EXR_MAGIC:
        raise ToneMapError(f"{path}: not an OpenEXR file")
    try:
        channels = imageio.read_exr(path)
    except Exception as exc:   # OpenEXR raises RuntimeError (and others) on a damaged file
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ToneMapError(f"{path}: cannot be read as OpenEXR: {reason}") from None

    names = set(channels)
    prefixes = sorted({n[:-1] for n in names if n.endswith(("R", "G", "B"))
                       and all(n[:-1] + c in names for c in "RGB")})
    if layer is not None:
        match = [p for p in prefixes if p == f"{layer}." or p.endswith(f".{layer}.")]
        if len(match) != 1:
            shown = ", ".join(p.rstrip(".") for p in prefixes if p) or "none"
            raise ToneMapError(f"{path}: no layer {layer!r} (layers: {shown})")
        return np.stack([channels[match[0] + c] for c in "RGB"], axis=-1).astype(np.float32)
    combined = [p for p in prefixes if p.endswith("Combined.")]
    if "" in prefixes:
        chosen = [channels[c] for c in "RGB"]
    elif len(prefixes) == 1 or len(combined) == 1:
        prefix = prefixes[0] if len(prefixes) == 1 else combined[0]
        chosen = [channels[prefix + c] for c in "RGB"]
    elif not prefixes and "Y" in names:
        chosen = [channels["Y"]] * 3
    else:
        shown = ", ".join(sorted(names)[:12]) + (" ..." if len(names) > 12 else "")
        raise ToneMapError(f"{path}: no single RGB layer to tone-map (channels: {shown})")
    image = np.stack(chosen, axis=-1).astype(np.float32, copy=False)
    if image.ndim != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise ToneMapError(f"{path}: the image is empty (shape {image.shape[:2]})")
    return image


def write_png(path, rgb8) -> None:
    """Write ``(H, W, 3)`` uint8 (row 0 = top) as an 8-bit RGB PNG, values as they are.

    Writes in place; wrap the call in ``imageio.atomic_output`` for all-or-nothing writing.
    """
    from PIL import Image

    data = np.asarray(rgb8)
    if data.dtype != np.uint8 or data.ndim != 3 or data.shape[2] != 3:
        raise ToneMapError(f"the PNG data must be (H, W, 3) uint8, got {data.shape} "
                           f"{data.dtype}")
    Image.fromarray(np.ascontiguousarray(data), mode="RGB").save(os.fspath(path), format="PNG")
