"""Compute the thin-film sensitivity table of ``engine/fresnel.py`` (Belcour and Barla 2017,
"A Practical Extension to Microfacet Theory for the Modeling of Varying Iridescence", their
Fourier-space spectral integration) and write ``engine/data/thin_film_table.npz``.

What it computes
    For each linear Rec.709 channel c (the RGB colour matching function s_c = M x (x, y, z)
    of the CIE 1931 2-degree observer, M the XYZ (D65) to linear Rec.709 matrix Cycles uses by
    default), as a function of the optical path difference OPD [nm]:

        S_c(OPD) = sum_j s_c(nu_j) exp(-2 pi i OPD nu_j) / sum_j s_c(nu_j)

    over wavenumbers nu = 1 / lambda on a uniform grid (s_c taken per unit wavenumber:
    s(lambda) lambda^2), normalised so that S_c(0) = 1. The Airy summation then adds
    2 C_m Re(phasor^m conj(S_c(m OPD))) per order m (``fresnel.iridescence``). The grid is the
    one Cycles' kernel reads (``thin_film_table`` look-up): nu_j = j pi / 60 um^-1,
    j = 0 .. 1021, and OPD_k = k 60 / (1022 pi) um for k = 0 .. 511, i.e. the table is read
    at x = 2 pi OPD / 60000 nm in [0, 1] by node-centred linear interpolation.

    The CIE functions are read from the 5 nm CIE 1931 table that Blender's Cycles kernel ships
    (``bpy/<version>/scripts/addons_core/cycles/source/kernel/tables.h``, 380-780 nm), natural
    cubic spline in wavelength, 0 outside. (Cycles' own table was made from the 1 nm CIE
    table, 360-830 nm; the difference is below 1e-3 in S.)

Run (a few seconds)::

    .venv/bin/python tools/thin_film_table.py [--out engine/data/thin_film_table.npz]

Output: ``re``, ``im`` (3, 512) float64, ``opd_nm`` (512,), ``note``.
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

ROOT = Path(__file__).resolve().parents[1]
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                          [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])
SIZE, POINTS = 512, 1022


def cie_1931() -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths [nm] (81,), xyz (81, 3)) of the 5 nm CIE 1931 table shipped with bpy."""
    import bpy
    scripts = next(p for p in Path(bpy.__file__).resolve().parents if p.name == "scripts")
    path = scripts / "addons_core" / "cycles" / "source" / "kernel" / "tables.h"
    text = path.read_text()
    body = text[text.index("cie_color_match"):]
    body = body[body.index("{") + 1:body.index("};")]
    rows = re.findall(r"\{([^{}]*)\}", body)
    xyz = np.array([[float(v.strip().rstrip("f")) for v in row.split(",") if v.strip()]
                    for row in rows])
    return 380.0 + 5.0 * np.arange(len(xyz)), xyz


def build() -> dict:
    wavelengths, xyz = cie_1931()
    splines = [CubicSpline(wavelengths, xyz[:, c], bc_type="natural", extrapolate=False)
               for c in range(3)]
    nu = np.arange(POINTS) * np.pi / 60.0                    # 1/um
    nu[0] = 1e-40
    lam = 1000.0 / nu                                        # nm
    with np.errstate(invalid="ignore"):
        xyz_nu = np.stack([np.nan_to_num(s(lam)) / (nu * nu) for s in splines], axis=0)
    rgb = XYZ_TO_REC709 @ xyz_nu                             # (3, POINTS)
    k = np.arange(SIZE)
    phase = np.exp(-2j * np.pi * np.outer(k, np.arange(POINTS)) / POINTS)   # (SIZE, POINTS)
    spectrum = rgb @ phase.T                                 # (3, SIZE)
    spectrum /= spectrum[:, :1].real
    opd = k * 60000.0 / (2.0 * np.pi * (SIZE - 1))
    return {"re": spectrum.real, "im": spectrum.imag, "opd_nm": opd,
            "note": np.array("made by tools/thin_film_table.py (CIE 1931 2 deg, 5 nm, "
                             "linear Rec.709)")}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "engine" / "data" /
                        "thin_film_table.npz")
    args = parser.parse_args(argv)
    np.savez_compressed(args.out, **build())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
