"""Damaged and hostile inputs, seeded: .blend files, ASE scenes with their .mat files, and baked
maps, each fed to the ``lanterna`` command in a process of its own (issue 22).

What it does
    ``cases(seed, count)`` makes ``count`` inputs from three valid ones (the Cornell box of
    ``tests/parity_scenes.py`` saved as a .blend, ``tests/data/ase/room.ase`` with ``room.mat``,
    and the maps ``lanterna bake`` writes for that .blend), in equal shares, each damaged one
    way, drawn from ``seed``:
        blend  one to eight flipped bits, a zeroed or random run of bytes, a truncation, a
               damaged header;
        ase    a truncation, a deleted or duplicated line, a number made NaN, inf, 1e308,
               -1e308 or a word, a count off by one, a byte flipped, a .mat value made bad;
        maps   an entry's values made NaN, inf, 3e38, -1e30 or 0, rows dropped, an integer
               dtype, a cache option (cell_fraction 0 or 1e-300, radius ratio 1), a
               representative or slice pointing outside, a byte of the zip flipped, an entry
               whose header promises 4e9 x 3 floats.
    ``run_case(case, work)`` renders it (16 x 12 pixels, 1 sample, 2k photons) with a time
    limit and sorts the outcome:
        ``refused``   exit 2 and one line ``lanterna: error: ...`` naming the damaged file
        ``rendered``  exit 0 and a finite, non-negative EXR
        ``crash``     killed by a signal; ``hang``: over the time limit; ``traceback``:
                      exit 1 or a Python traceback; ``bad output``: exit 0 with NaN, inf or
                      negative pixels, or no EXR; ``silent``: a refusal without the file's
                      name
    ``python tests/fuzz.py --count 420 --csv out/fuzz.csv`` (``make fuzz``) runs them on both
    cores and prints a table by kind and outcome; ``tests/test_fuzz.py`` runs a quick subset.
"""
from __future__ import annotations

import argparse
import csv
import io
import os
import re
import shutil
import subprocess
import sys
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ASE = HERE / "data" / "ase" / "room.ase"
RENDER = ["--resolution", "16x12", "--samples", "1", "--photons", "2000", "--seed", "1",
          "--quiet"]
GOOD = ("refused", "rendered")
TIMEOUT = 120


@dataclass
class Case:
    kind: str              # blend, ase, maps
    damage: str            # how it was damaged
    files: dict            # name -> bytes
    argv: list             # the command, with {dir} for the case's folder


# -- The valid inputs --------------------------------------------------------------------------
BUILD_ROOM = ("import sys, bpy; sys.path.insert(0, {tests!r}); import parity_scenes; "
              "parity_scenes.build('cornell'); "
              "bpy.ops.wm.save_as_mainfile(filepath={path!r}, check_existing=False, "
              "compress=False)")


def originals(work: Path) -> dict:
    """The three valid inputs, made once into ``work``: the Cornell box of
    ``tests/parity_scenes.py`` (an area light, so all three maps exist) as an uncompressed .blend
    (a flipped bit of a compressed one only breaks the decompression), the ASE
    pair, and the maps ``lanterna bake`` makes of that .blend with ``RENDER``'s settings (so
    ``--maps`` accepts them)."""
    work.mkdir(parents=True, exist_ok=True)
    blend, maps = work / "room.blend", work / "room_maps.npz"
    if not blend.exists():
        subprocess.run([sys.executable, "-c", BUILD_ROOM.format(tests=str(HERE),
                                                                path=str(blend))],
                       check=True, capture_output=True)
    if not maps.exists():
        subprocess.run([sys.executable, "-m", "lanterna.engine.blender.cli", "bake",
                        str(blend), *RENDER, "-o", str(maps)], check=True, capture_output=True)
    return {"blend": blend.read_bytes(), "blend_path": str(blend), "ase": ASE.read_bytes(),
            "mat": ASE.with_suffix(".mat").read_bytes(), "maps": maps.read_bytes()}


# -- Damage -------------------------------------------------------------------------------------
def _blend_case(rng, data: bytes) -> tuple[str, bytes]:
    b = bytearray(data)
    how = rng.choice(["bits", "zero run", "random run", "truncate", "header"])
    if how == "bits":
        n = int(rng.integers(1, 9))
        for _ in range(n):
            i = int(rng.integers(0, len(b)))
            b[i] ^= 1 << int(rng.integers(0, 8))
        return f"{n} flipped bits", bytes(b)
    if how in ("zero run", "random run"):
        start, length = int(rng.integers(0, len(b))), int(rng.integers(1, 4096))
        run = bytes(length) if how == "zero run" else rng.integers(0, 256, length,
                                                                   np.uint8).tobytes()
        b[start:start + length] = run[:len(b) - start]
        return f"{how} of {length} bytes", bytes(b)
    if how == "truncate":
        cut = int(rng.integers(0, len(b)))
        return f"truncated at {cut}", bytes(b[:cut])
    i = int(rng.integers(7, 12))
    b[i] = int(rng.integers(0, 256))
    return f"header byte {i}", bytes(b)


NUMBER = re.compile(rb"-?\d+\.?\d*(?:[eE][-+]?\d+)?")


def _ase_case(rng, ase: bytes, mat: bytes) -> tuple[str, bytes, bytes]:
    how = rng.choice(["truncate", "delete line", "duplicate line", "number", "count", "byte",
                      "mat value"])
    lines = ase.split(b"\n")
    if how == "truncate":
        cut = int(rng.integers(0, len(ase)))
        return f"truncated at {cut}", ase[:cut], mat
    if how in ("delete line", "duplicate line"):
        i = int(rng.integers(0, len(lines)))
        lines = lines[:i] + lines[i + 1:] if how == "delete line" else \
            lines[:i + 1] + [lines[i]] + lines[i + 1:]
        return f"{how} {i + 1}", b"\n".join(lines), mat
    if how in ("number", "count", "mat value"):
        target = mat if how == "mat value" else ase
        found = list(NUMBER.finditer(target))
        if how == "count":
            counted = [m for m in found if re.match(rb"\d+$", m.group())]
            found = counted or found
        m = found[int(rng.integers(0, len(found)))]
        if how == "count":
            new = str(int(m.group()) + int(rng.choice([-1, 1]))).encode()
        else:
            new = rng.choice([b"nan", b"inf", b"1e308", b"-1e308", b"-1", b"word", b""])
        damaged = target[:m.start()] + new + target[m.end():]
        what = f"{how} {m.group().decode()} -> {new.decode() or 'nothing'}"
        return (what, ase, damaged) if how == "mat value" else (what, damaged, mat)
    b = bytearray(ase)
    i = int(rng.integers(0, len(b)))
    b[i] = int(rng.integers(0, 256))
    return f"byte {i}", bytes(b), mat


def _rewrite_npz(data: bytes, change) -> bytes:
    """The archive ``data`` with entries changed by ``change(entries) -> entries``."""
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        entries = {k: z[k] for k in z.files}
    out = io.BytesIO()
    np.savez(out, **change(entries))
    return out.getvalue()


MAP_ENTRIES = ("photons.power", "photons.positions", "cache.irradiance", "cache.radius",
               "cache.trans_grad", "shadow_photons.positions", "shadow_photons.rep_radius")


def _maps_case(rng, data: bytes) -> tuple[str, bytes]:
    how = rng.choice(["value", "rows", "dtype", "option", "index", "zip byte", "bomb"])
    if how == "value":
        key = str(rng.choice(MAP_ENTRIES))
        value = float(rng.choice([np.nan, np.inf, 3e38, -1e30, 0.0, -1.0]))

        def change(e):
            a = e[key].copy()
            flat = a.reshape(-1)
            flat[int(rng.integers(0, len(flat)))] = value
            e[key] = a
            return e
        return f"{key} = {value:g}", _rewrite_npz(data, change)
    if how == "rows":
        key = str(rng.choice(MAP_ENTRIES))
        return f"{key} one row short", _rewrite_npz(data, lambda e: {**e, key: e[key][:-1]})
    if how == "dtype":
        key = str(rng.choice(MAP_ENTRIES))
        return f"{key} as int64", _rewrite_npz(data, lambda e: {**e, key: e[key].astype(np.int64)})
    if how == "option":
        key, value = [("cache.cell_fraction", 0.0), ("cache.cell_fraction", 1e-300),
                      ("cache.radius_ratio", 1.0), ("cache.e_min", 0.0),
                      ("shadow_photons.k", 0), ("shadow_photons.penumbra_factor", 10 ** 9)][
            int(rng.integers(0, 6))]
        return f"{key} = {value:g}", _rewrite_npz(
            data, lambda e: {**e, key: np.array(value, e[key].dtype)})
    if how == "index":
        key = str(rng.choice(["shadow_photons.rep_index", "shadow_photons.slices.values",
                              "shadow_photons.rep_class"]))
        return f"{key} out of range", _rewrite_npz(
            data, lambda e: {**e, key: np.full_like(e[key], np.iinfo(e[key].dtype).max)})
    if how == "zip byte":
        b = bytearray(data)
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
        return f"zip byte {i}", bytes(b)
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False,
                                                  "shape": (4_000_000_000, 3)})
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            blob = src.read(info)
            if info.filename == "photons.power.npy":
                blob = header.getvalue() + b"\0" * 64
            dst.writestr(info.filename, blob)
    return "photons.power declares 4e9 x 3 floats", out.getvalue()


def cases(seed: int, count: int, valid: dict) -> list[Case]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        kind = ("blend", "ase", "maps")[i % 3]
        if kind == "blend":
            damage, blob = _blend_case(rng, valid["blend"])
            out.append(Case(kind, damage, {"scene.blend": blob},
                            ["render", "{dir}/scene.blend", *RENDER, "-o", "{dir}/out.exr"]))
        elif kind == "ase":
            damage, ase, mat = _ase_case(rng, valid["ase"], valid["mat"])
            out.append(Case(kind, damage, {"room.ase": ase, "room.mat": mat},
                            ["render", "{dir}/room.ase", *RENDER, "-o", "{dir}/out.exr"]))
        else:
            damage, blob = _maps_case(rng, valid["maps"])
            out.append(Case(kind, damage, {"maps.npz": blob},
                            ["render", valid["blend_path"], *RENDER, "--maps",
                             "{dir}/maps.npz", "-o", "{dir}/out.exr"]))
    return out


# -- Running and sorting -------------------------------------------------------------------------
def run_case(case: Case, work: Path) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    for name, blob in case.files.items():
        (work / name).write_bytes(blob)
    argv = [a.replace("{dir}", str(work)) for a in case.argv]
    cmd = [sys.executable, "-m", "lanterna.engine.blender.cli", *argv]
    t0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, errors="replace",
                              timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return {"outcome": "hang", "code": None, "seconds": TIMEOUT, "message": ""}
    seconds = time.perf_counter() - t0
    err = done.stderr
    lines = [line for line in err.splitlines() if line.startswith("lanterna: error:")]
    if done.returncode < 0:
        outcome = "crash"
    elif "Traceback" in err or done.returncode == 1:
        outcome = "traceback"
    elif done.returncode == 2:
        outcome = ("refused" if len(lines) == 1 and any(name in lines[0] for name in case.files)
                   else "silent")
    elif done.returncode == 0:
        outcome = "rendered" if _finite_exr(work / "out.exr") else "bad output"
    else:
        outcome = f"exit {done.returncode}"
    tail = err.strip().splitlines()
    message = lines[0] if lines else (tail[-1] if tail else "")
    return {"outcome": outcome, "code": done.returncode, "seconds": round(seconds, 2),
            "message": message[:200]}


def _finite_exr(path: Path) -> bool:
    if not path.exists():
        return False
    from lanterna.engine import imageio

    image = imageio.read_exr_rgb(path)
    return bool(np.isfinite(image).all() and image.min() >= 0)


def run_all(seed: int, count: int, work: Path, workers: int = 2) -> list[dict]:
    valid = originals(work / "valid")
    todo = cases(seed, count, valid)

    def one(item):
        i, case = item
        folder = work / f"case{i:04d}"
        result = run_case(case, folder)
        shutil.rmtree(folder, ignore_errors=True)
        return {"case": i, "kind": case.kind, "damage": case.damage, **result}

    with ThreadPoolExecutor(workers) as pool:
        return list(pool.map(one, enumerate(todo)))


def table(rows: list[dict]) -> str:
    outcomes = ["refused", "rendered", "crash", "hang", "traceback", "bad output", "silent"]
    outcomes += sorted({r["outcome"] for r in rows} - set(outcomes))
    head = "| kind | cases | " + " | ".join(outcomes) + " |"
    out = [head, "|" + "---|" * (len(outcomes) + 2)]
    for kind in ("blend", "ase", "maps"):
        mine = [r for r in rows if r["kind"] == kind]
        counts = [sum(r["outcome"] == o for r in mine) for o in outcomes]
        out.append(f"| {kind} | {len(mine)} | " + " | ".join(map(str, counts)) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--count", type=int, default=420)
    parser.add_argument("--csv", default="out/fuzz.csv")
    parser.add_argument("--work", default="out/fuzz")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    rows = run_all(args.seed, args.count, Path(args.work), args.workers)
    Path(args.csv).parent.mkdir(parents=True, exist_ok=True)
    with open(args.csv, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(table(rows))
    bad = [r for r in rows if r["outcome"] not in GOOD]
    for r in bad:
        print(f"  case {r['case']} {r['kind']} ({r['damage']}): {r['outcome']}: {r['message']}")
    print(f"{len(rows)} inputs in {(time.perf_counter() - t0) / 60:.1f} min; {len(bad)} not "
          f"handled well; CSV {args.csv}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
