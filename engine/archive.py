"""Reading numpy ``.npz`` archives that may be damaged or hostile, checked before anything is
decompressed (a leaf: imports nothing of Lanterna).

What it computes
    ``entry_headers(path)`` -> {entry: ``EntryHeader``}: for every ``.npy`` member its dtype
        and shape from the ``.npy`` header (only the header's bytes are decompressed) and its
        size as the zip declares it. Raises ``ArchiveError`` for a file that is not a zip, a
        member that is not ``.npy``, a header that cannot be read, pickled objects, and an
        entry whose declared size is not the header plus the array the header promises.
    ``check_schema(headers, schema, prefix)`` -> problems: each entry ``prefix + name`` of
        ``schema`` present, of an allowed dtype, and of the shape the schema gives; a shape is
        a tuple of sizes and symbols (``"P"``: the photons), every symbol standing for one
        count across the entries that name it, so that arrays that go together agree in
        length before any is read.
    ``check_budget(headers, budget)``: ``ArchiveError`` when the entries would need more than
        ``budget`` bytes once decompressed.

A schema is {entry: (dtypes, shape)}: ``dtypes`` a tuple of numpy dtype strings ("<f4", "|u1")
or "U" for a string of any length; ``shape`` () for a scalar, None for any shape.
"""
from __future__ import annotations

import zipfile
from dataclasses import dataclass

import numpy as np

__all__ = ["ArchiveError", "EntryHeader", "entry_headers", "check_schema", "check_budget"]


class ArchiveError(ValueError):
    """An archive that cannot be taken; the message says which entry and why. ``whole`` is
    true when the file is no archive at all (as opposed to a bad entry)."""

    def __init__(self, message: str, whole: bool = False):
        super().__init__(message)
        self.whole = whole


@dataclass(frozen=True)
class EntryHeader:
    name: str                 # the entry's name, without ".npy"
    dtype: np.dtype
    shape: tuple
    declared: int             # its uncompressed size as the zip's directory says [bytes]
    header: int               # the .npy header's length [bytes]

    @property
    def nbytes(self) -> int:
        """The array's size as its header promises it [bytes]."""
        return int(np.prod(self.shape, dtype=np.float64) * self.dtype.itemsize)

    @property
    def consistent(self) -> bool:
        """The zip declares exactly the header plus the array the header promises."""
        return self.declared == self.header + self.nbytes


def entry_headers(path) -> dict[str, EntryHeader]:
    """Every entry's ``.npy`` header (module docstring)."""
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        try:
            with open(path, "rb") as fh:
                single = fh.read(6) == b"\x93NUMPY"
        except OSError:
            single = False
        if single:
            raise ArchiveError("a single numpy array, not an .npz archive", whole=True) from None
        raise ArchiveError(f"not a numpy .npz archive ({exc})", whole=True) from None
    out = {}
    with archive:
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                raise ArchiveError(f"the member '{info.filename}' is not a numpy array")
            name = info.filename[:-len(".npy")]
            try:
                with archive.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                            else np.lib.format.read_array_header_2_0)
                    shape, _fortran, dtype = read(fh)
                    header = fh.tell()
            except (ValueError, OSError, EOFError, zipfile.BadZipFile, SyntaxError,
                    TypeError, NotImplementedError) as exc:
                raise ArchiveError(f"the entry '{name}' has no readable array header "
                                   f"({type(exc).__name__}: {exc})") from None
            if dtype.hasobject:
                raise ArchiveError(f"the entry '{name}' holds pickled Python objects, which "
                                   "Lanterna does not load")
            head = EntryHeader(name, dtype, tuple(int(s) for s in shape),
                               int(info.file_size), int(header))
            if not head.consistent:
                raise ArchiveError(f"the entry '{name}' declares {head.declared:,} bytes, but "
                                   f"its header promises {head.header + head.nbytes:,}")
            out[name] = head
    return out


def _dtype_ok(dtype: np.dtype, allowed) -> bool:
    for spec in allowed:
        if spec == "U":
            if dtype.kind == "U":
                return True
        elif dtype == np.dtype(spec):
            return True
    return False


def check_schema(headers: dict, schema: dict, prefix: str = "") -> list[str]:
    """Problems of the entries ``prefix + name`` against ``schema`` (module docstring)."""
    problems, counts = [], {}
    for name, (dtypes, shape) in schema.items():
        key = prefix + name
        head = headers.get(key)
        if head is None:
            problems.append(f"the entry '{key}' is missing")
            continue
        if not _dtype_ok(head.dtype, dtypes):
            wanted = " or ".join("a string" if d == "U" else str(np.dtype(d)) for d in dtypes)
            problems.append(f"the entry '{key}' is {head.dtype}, not {wanted}")
            continue
        if shape is None:
            continue
        if len(head.shape) != len(shape):
            problems.append(f"the entry '{key}' has shape {head.shape}, not {len(shape)}-"
                            "dimensional")
            continue
        for size, want in zip(head.shape, shape):
            if isinstance(want, str):
                seen = counts.setdefault(want, (size, key))
                if seen[0] != size:
                    problems.append(f"the entry '{key}' has {size:,} rows where "
                                    f"'{seen[1]}' has {seen[0]:,}")
                    break
            elif size != want:
                problems.append(f"the entry '{key}' has shape {head.shape}, not "
                                f"{tuple(shape)}")
                break
    return problems


def check_budget(headers: dict, budget: int | None) -> None:
    """``ArchiveError`` when the entries need more than ``budget`` bytes (None: no limit)."""
    total = sum(h.nbytes for h in headers.values())
    if budget is not None and total > budget:
        biggest = max(headers.values(), key=lambda h: h.nbytes)
        raise ArchiveError(f"its arrays would need {total / 2**30:.1f} GiB once read (the "
                           f"largest, '{biggest.name}', {biggest.nbytes / 2**30:.1f} GiB), more "
                           f"than the {budget / 2**30:.1f} GiB this machine can spare")
