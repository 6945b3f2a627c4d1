"""Reader of 3ds Max ASE files (ASCII Scene Export) and of the seed's companion material file,
no ``bpy``: the seed's input format (thesis section 3: "o protótipo lê cenas geradas pelo 3ds
Max ... exportadas no formato de arquivo ASE"; section 3.2: "foi criado um arquivo
complementar ao ASE contendo a descrição dos materiais").

What it computes
----------------
:func:`load` reads ``scene.ase`` and its companion ``scene.mat`` (same folder, same stem) and
returns an :class:`AseScene` of plain dataclasses and numpy arrays, ready for the Blender
importer (``ops/import_ase.py``) to turn into objects without further checks: meshes
(:class:`MeshSpec`: world-space float64 vertices ``(N, 3)`` [m], the object matrix from
``*NODE_TM``, the vertices in that object's space, int64 faces ``(M, 3)``, a material slot per
face), materials (:class:`MaterialSpec`: rho_d, rho_s, M), cameras (:class:`CameraSpec`) and
lights (:class:`LightSpec`). :func:`parse_ase` and :func:`parse_companion` are the two parsers
on their own (text in, raw dataclasses out, in the file's units).

Everything is read and checked before anything is returned: a malformed or truncated file
raises :class:`AseError` (a ``ValueError``) whose message starts ``path:line:`` and says what
was expected and what was found, naming the object (``*NODE_NAME``) or material it was in. No
partial result is ever returned, so nothing is half-imported.

The ASE subset read
-------------------
Tokens: ``*KEY`` (letters, digits, ``_``), ``{``, ``}``, ``"strings"`` (one line, no escapes)
and bare words (numbers, ``Omni``, ``A:``; a word ends after a ``:``, so ``A:0`` is ``A:``
``0``). The file must start with ``*3DSMAX_ASCIIEXPORT <integer version>``. Keys read:

* ``*MATERIAL_LIST { *MATERIAL_COUNT n  *MATERIAL i { *MATERIAL_NAME "..."
  *MATERIAL_DIFFUSE r g b  *NUMSUBMTLS k  *SUBMATERIAL j { ... } } }``. The count must precede
  the materials and match them; indices are 0..n-1, each once. ``*MATERIAL_DIFFUSE`` is only a
  fallback for materials missing from the companion file. Multi/Sub-Object materials: the face's
  ``*MESH_MTLID`` m picks submaterial m mod k (recursively, as 3ds Max does).
* ``*GEOMOBJECT { *NODE_NAME "..."  *NODE_TM {...}  *MESH {...}  *MATERIAL_REF i }``, all but
  ``*MATERIAL_REF`` required. ``*MESH { *MESH_NUMVERTEX n  *MESH_NUMFACES m
  *MESH_VERTEX_LIST { *MESH_VERTEX i x y z ... }  *MESH_FACE_LIST { *MESH_FACE i: A: a B: b C: c
  [AB: e BC: e CA: e]  [*MESH_SMOOTHING ...]  [*MESH_MTLID id] ... } }``. The counts must come
  before their lists; every index 0..n-1 (0..m-1) must be listed exactly once; face corners must
  be vertex indices 0..n-1. ASE vertices are in world space (3ds Max writes them through the
  node's object TM), so they are kept as they are, and also expressed in the object's space
  (inverse ``*NODE_TM``) so that Blender shows the object with its pivot and rotation.
* ``*NODE_TM { *TM_ROW0 / 1 / 2  x y z  *TM_ROW3 x y z  *TM_POS x y z }``: 3ds Max transforms
  row vectors, ``p_world = p_local * TM``, so ROW0..2 are the images of the local X, Y, Z axes
  (the columns of Blender's 3x3) and ROW3 (or ``*TM_POS`` when ROW3 is absent) is the
  translation. ROW0..2 come all three or not at all; without them the rotation is the identity,
  or for a camera or light with a target, the look-at rotation towards the target (world +Z up).
  ``*TM_ROTAXIS``, ``*TM_ROTANGLE``, ``*TM_SCALE``... repeat the rows and are skipped. A
  singular object TM (zero scale) is replaced by the identity, with a warning.
* ``*CAMERAOBJECT { *NODE_NAME  *NODE_TM (the camera)  [*NODE_TM (its target)]
  *CAMERA_SETTINGS { *CAMERA_FOV rad } }``: the horizontal field of view in radians, default
  pi/4 (3ds Max's 45 deg), within [0.0065, 3.0] rad (what a Blender camera holds). Cameras look
  along their local -Z with +Y up, in 3ds Max as in Blender.
* ``*LIGHTOBJECT { *NODE_NAME  *LIGHT_TYPE Omni|Target|Free|Directional  *NODE_TM
  [*NODE_TM (target)]  [*LIGHT_USELIGHT 0|1]  *LIGHT_SETTINGS { *LIGHT_COLOR r g b
  *LIGHT_INTENS f  *LIGHT_HOTSPOT deg  *LIGHT_FALLOFF deg } }``. Defaults (3ds Max's): colour
  white, intensity (multiplier) 1, hotspot 43 deg, falloff 45 deg. Omni -> point light,
  Target/Free (spots) -> spot of cone angle = falloff (1..180 deg) and blend
  1 - hotspot/falloff, Directional -> sun. Lights shine along their local -Z. Negative colours
  and multipliers (3ds Max "darklights") are refused.
* ``*GROUP "name" { ... }`` holds objects like the top level does (the group itself is dropped;
  at most ``MAX_NESTING`` groups deep).

Line ends may be LF, CRLF or CR. Vertex and face lines in 3ds Max's spelling are read whole by
one regular expression each (the fast path, about 10 us a line); any other spelling, and any
line failing a check, goes through the tokens, with the same result or the detailed error.

The file must end with the ``}`` closing its last top-level block (3ds Max's files do), so that
a file cut inside a block or inside a key is refused as truncated; a cut right after a complete
object cannot be told from a smaller file and reads as one.

Unknown keys (``*SCENE``, ``*COMMENT``, ``*SHAPEOBJECT``, ``*HELPEROBJECT``, ``*TM_ANIMATION``,
``*MESH_NORMALS``, ``*MESH_TVERTLIST``, ``*MAP_DIFFUSE``...) anywhere are skipped with their
values and their nested ``{...}`` block, which must be balanced. Keys that are read are strict:
exact value types and counts, nothing else before the next key or ``}``, and read only once per
block (a repeated ``*NODE_NAME``, ``*MESH``, ``*TM_ROW0``... is an error). A file with no
geometry, camera or light is refused. Counts are guarded before anything is allocated: at most
``MAX_COUNT`` (50 million), and no more items than the file's size could hold
(``MIN_ITEM_BYTES`` bytes per vertex, face or material). Numbers must be finite decimals of
magnitude at most ``MAX_ABS`` (1e30); ``nan``, ``inf``, ``1e999`` and MSVC's ``1.#QNAN`` are
refused.

The companion material file (``scene.mat``)
-------------------------------------------
The seed names the three values but not how its file spelled them; this format is Lanterna's.
A UTF-8 text file, one statement per line; ``#`` at the start of a line or after white space
starts a comment (not inside quotes or a word); blank lines are ignored; keywords are lower
case; names are in double quotes exactly as the ASE's ``*MATERIAL_NAME`` / ``*NODE_NAME``. It
must end with the line ``end`` (so that a truncated file is recognised)::

    # room.mat - radiometric materials for room.ase
    unit 1.0                                  # optional: metres per ASE unit (default 1)
    material "White" diffuse 0.8 specular 0 exitance 0
    material "Green" diffuse 0.1 0.6 0.1 specular 0.2 0.2 0.2
    material "Lamp"  diffuse 0.5 exitance 25.0 25.0 20.0
    light "Omni01" power 150                  # optional: replaces the ASE intensity
    end

``material "<name>"`` is followed by any of ``diffuse``, ``specular``, ``exitance`` (each at
most once, in any order), each with one number (grey) or three (R G B, linear). Fields left out
are 0. ``diffuse`` is the diffuse (Lambertian) reflectance rho_d and ``specular`` the perfect
mirror reflectance rho_s, fractions in [0, 1] per channel (seed section 3.2, 9.2); ``exitance``
is the radiant exitance M [W/m^2] per channel, >= 0 (radiance L = M / pi from each side; a
material with M > 0 makes its triangles mesh lights, seed 3.3.3). rho_d + rho_s > 1 in a channel
is kept and warned about: the renderer scales both down to conserve energy
(``engine/blender/export.py``). ``light "<name>" power P`` sets a light's power instead of the
conversion below: the flux P [W] of an Omni or spot, the irradiance P [W/m^2] of a Directional
light (times the ASE ``*LIGHT_COLOR``). ``unit s`` (0 < s <= 1e6) scales all ASE positions
by s metres. Exitance is at most 1e9 W/m^2 (what ``Material.lanterna`` holds).
Unknown keywords, repeated names, missing or extra numbers, negative, non-finite or > 1
reflectances are errors with the line number. A material referenced by the ASE but absent
from the companion file (or the file itself absent) takes rho_d from ``*MATERIAL_DIFFUSE``
(default 0.8) and no specular or exitance, with a warning; entries that name nothing in the
ASE are warned about.

Light power without a companion entry (parameters, module constants)
--------------------------------------------------------------------
3ds Max's scanline lights have no physical unit: a white light of multiplier 1 without decay
shows a white Lambertian surface facing it as 1.0, i.e. radiance L = 1, irradiance E = pi. So:
Directional: sun irradiance E = ``SUN_IRRADIANCE_PER_INTENSITY`` (pi W/m^2) x ``*LIGHT_INTENS``;
Omni and spots: flux P = ``POINT_WATTS_PER_INTENSITY`` (4 pi^2 W, E = pi at 1 m by the seed's
Eq. 7.1, E = P / (4 pi r^2)) x ``*LIGHT_INTENS``. Colours multiply per channel (DESIGN.md
section 3: point Power [W], sun Strength [W/m^2]).
"""
from __future__ import annotations

import functools
import math
import os
import re
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Optional

import numpy as np

__all__ = [
    "AseError", "AseFile", "AseMaterial", "AseGeom", "AseCamera", "AseLight", "NodeTM",
    "Companion", "CompanionMaterial", "AseScene", "MaterialSpec", "MeshSpec", "CameraSpec",
    "LightSpec", "parse_ase", "parse_companion", "load", "companion_path",
    "MAX_COUNT", "MIN_ITEM_BYTES", "POINT_WATTS_PER_INTENSITY", "SUN_IRRADIANCE_PER_INTENSITY",
    "DEFAULT_FOV", "DEFAULT_DIFFUSE",
]

#: Largest vertex, face or material count accepted (before allocating anything).
MAX_COUNT = 50_000_000
#: Fewest bytes one listed vertex / face / material can take ("*MESH_VERTEX 0 0 0 0" is 20):
#: a count above file size / MIN_ITEM_BYTES cannot be honest.
MIN_ITEM_BYTES = 12
#: Omni and spot flux [W] per unit of ``*LIGHT_INTENS``: 4 pi^2, E = pi W/m^2 at 1 m.
POINT_WATTS_PER_INTENSITY = 4.0 * math.pi ** 2
#: Directional light irradiance [W/m^2] per unit of ``*LIGHT_INTENS``.
SUN_IRRADIANCE_PER_INTENSITY = math.pi
#: 3ds Max's default camera field of view [rad] (45 deg).
DEFAULT_FOV = math.pi / 4
#: Accepted field of view [rad]: what a Blender camera can hold.
FOV_RANGE = (0.0065, 3.0)
#: Largest magnitude of any number read [file units]: positions stay finite in Blender's
#: float32 meshes even after the largest ``unit`` (``MAX_UNIT`` m per unit).
MAX_ABS = 1e30
MAX_UNIT = 1e6
#: Largest exitance [W/m^2] (what ``Material.lanterna.exitance`` holds).
MAX_EXITANCE = 1e9
#: Deepest nesting of ``*GROUP`` blocks and of submaterials.
MAX_NESTING = 32
#: rho_d of a material with neither a companion entry nor ``*MATERIAL_DIFFUSE``.
DEFAULT_DIFFUSE = 0.8
#: 3ds Max's default spot hotspot and falloff cone angles [deg].
DEFAULT_HOTSPOT, DEFAULT_FALLOFF = 43.0, 45.0

LIGHT_TYPES = {"Omni": "POINT", "Target": "SPOT", "Free": "SPOT", "Directional": "SUN"}


class AseError(ValueError):
    """A malformed, truncated or unsupported ASE or companion file. The message starts with
    ``path:line:`` (the line where the problem was found) and names what was expected."""


# =============================================================================================
# Raw results of the parsers (file units)
# =============================================================================================
@dataclass
class NodeTM:
    """One ``*NODE_TM`` block: ``rows`` (3, 3) = TM_ROW0..2 or None, ``translation`` (3,)."""
    line: int
    rows: Optional[np.ndarray]
    translation: np.ndarray

    def matrix(self) -> np.ndarray:
        """4x4 matrix in Blender's column-vector convention (p_world = M @ p_local)."""
        m = np.eye(4)
        if self.rows is not None:
            m[:3, :3] = self.rows.T
        m[:3, 3] = self.translation
        return m


@dataclass
class AseMaterial:
    """``*MATERIAL`` / ``*SUBMATERIAL``: name, optional ``*MATERIAL_DIFFUSE``, submaterials."""
    index: int
    name: str
    line: int
    diffuse: Optional[np.ndarray] = None
    submaterials: list = field(default_factory=list)


@dataclass
class AseGeom:
    """``*GEOMOBJECT``: world-space vertices (N, 3) float64, faces (M, 3) int64, the
    ``*MESH_MTLID`` of every face (M,) int64, ``*MATERIAL_REF`` (None when absent)."""
    name: str
    line: int
    tm: NodeTM
    vertices: np.ndarray
    faces: np.ndarray
    mtlids: np.ndarray
    material_ref: Optional[int] = None
    material_ref_line: int = 0


@dataclass
class AseCamera:
    name: str
    line: int
    tm: NodeTM
    target: Optional[NodeTM]
    fov: float
    fov_line: int


@dataclass
class AseLight:
    name: str
    line: int
    type: str                     # Omni, Target, Free or Directional
    tm: NodeTM
    target: Optional[NodeTM]
    color: np.ndarray
    intensity: float
    hotspot: float                # deg
    falloff: float                # deg
    falloff_line: int
    enabled: bool = True


@dataclass
class AseFile:
    path: str
    version: int
    materials: list               # AseMaterial by index
    geoms: list
    cameras: list
    lights: list


@dataclass
class CompanionMaterial:
    name: str
    line: int
    diffuse: np.ndarray
    specular: np.ndarray
    exitance: np.ndarray


@dataclass
class Companion:
    """Parsed companion file: ``unit`` [m per ASE unit], materials and light powers by name."""
    path: str
    unit: float = 1.0
    unit_line: int = 0
    materials: dict = field(default_factory=dict)     # name -> CompanionMaterial
    light_power: dict = field(default_factory=dict)   # name -> (power, line)
    warnings: list = field(default_factory=list)


# =============================================================================================
# Resolved results of load() (metres, Blender conventions)
# =============================================================================================
@dataclass
class MaterialSpec:
    """A material to create: rho_d, rho_s in [0, 1] and M [W/m^2], (3,) float64 each."""
    name: str
    diffuse: np.ndarray
    specular: np.ndarray
    exitance: np.ndarray
    source: str                   # where the values came from, for the summary


@dataclass
class MeshSpec:
    """A mesh object: ``matrix`` (4, 4) world matrix [m]; ``vertices`` world space (N, 3) [m];
    ``local_vertices`` = inverse(matrix) applied to them; ``faces`` (M, 3) int64;
    ``face_slots`` (M,) int64 into ``slots`` (material names; empty: no material)."""
    name: str
    line: int
    matrix: np.ndarray
    vertices: np.ndarray
    local_vertices: np.ndarray
    faces: np.ndarray
    face_slots: np.ndarray
    slots: list


@dataclass
class CameraSpec:
    """A camera: world matrix (4, 4) [m] looking along local -Z, horizontal fov [rad]."""
    name: str
    line: int
    matrix: np.ndarray
    fov: float


@dataclass
class LightSpec:
    """A light: ``kind`` POINT / SPOT / SUN, world matrix (shines along local -Z), ``color``
    (3,) in [0, inf), ``power`` [W] (POINT, SPOT) or [W/m^2] (SUN), spot cone ``spot_size``
    [rad] and ``spot_blend`` in [0, 1]."""
    name: str
    line: int
    kind: str
    matrix: np.ndarray
    color: np.ndarray
    power: float
    power_source: str
    spot_size: float = 0.0
    spot_blend: float = 0.0
    enabled: bool = True


@dataclass
class AseScene:
    path: str
    material_path: Optional[str]
    unit: float
    materials: list               # MaterialSpec, each name once, in first-use order
    meshes: list
    cameras: list
    lights: list
    warnings: list


# =============================================================================================
# Tokenizer
# =============================================================================================
class _Tok(NamedTuple):
    kind: str                     # key, {, }, str, word, eof
    text: str
    line: int


_TOKEN = re.compile(r'''
    (?P<ws>\s+)
  | (?P<key>\*[A-Za-z0-9_]+)
  | (?P<lb>\{)
  | (?P<rb>\})
  | (?P<str>"[^"]*")
  | (?P<badstr>"[^"]*$)
  | (?P<word>[^\s{}":]+:?|:)
''', re.X)
_KIND = {"key": "key", "lb": "{", "rb": "}", "str": "str", "word": "word"}
_FLOAT = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_INT = re.compile(r"[-+]?\d+")
_NONFINITE = re.compile(r"[-+]?(?:nan|inf|infinity|\d*\.?\d*#\w*)", re.I)


_KEY = re.compile(r"\*[A-Za-z0-9_]+")
_SPECIAL = re.compile(r'["{}:]')


class _Lexer:
    """Tokens of one line at a time, with line numbers. ``seek`` lets the parser read whole
    lines of a vertex or face list itself (the fast path) and resume tokenising after them."""

    def __init__(self, text: str, path: str):
        self.lines = text.split("\n")
        self.path = path
        self.index = 0            # next line to tokenise (0-based)
        self.buf: list = []
        self.pos = 0
        self.first = False        # the last token returned began its line

    def next(self) -> _Tok:
        while self.pos >= len(self.buf):
            if self.index >= len(self.lines):
                self.first = False
                return _Tok("eof", "", max(len(self.lines), 1))
            self.buf = self._line(self.lines[self.index], self.index + 1)
            self.index += 1
            self.pos = 0
        self.first = self.pos == 0
        self.pos += 1
        return self.buf[self.pos - 1]

    def seek(self, index: int):
        """Continue with line ``index`` (0-based), dropping what is left of the current one."""
        self.index, self.buf, self.pos = index, [], 0

    def _line(self, line: str, line_no: int) -> list:
        if _SPECIAL.search(line) is None:
            # Plain words and keys only (most lines of a file): split is enough.
            words = line.split()
            if all(w[0] != "*" or _KEY.fullmatch(w) for w in words):
                return [_Tok("key" if w[0] == "*" else "word", w, line_no) for w in words]
        out = []
        for m in _TOKEN.finditer(line):
            group = m.lastgroup
            if group == "ws":
                continue
            if group == "badstr":
                raise AseError(f"{self.path}:{line_no}: expected a closing '\"' on the same "
                               f"line, found end of line (string {m.group()[:40]!r})")
            out.append(_Tok(_KIND[group], m.group(), line_no))
        return out


# Whole-line patterns of the fast path: the common spelling of a vertex and of a face. A line
# that does not match, or whose values fail a check, goes through the tokens (same result,
# and the detailed error).
_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
_VERTEX_LINE = re.compile(rf"\s*\*MESH_VERTEX\s+(\d+)\s+{_NUM}\s+{_NUM}\s+{_NUM}\s*")
_FACE_LINE = re.compile(r"\s*\*MESH_FACE\s+(\d+)\s*:\s*A:\s*(\d+)\s+B:\s*(\d+)\s+C:\s*(\d+)"
                        r"(?:\s+AB:\s*[-+]?\d+\s+BC:\s*[-+]?\d+\s+CA:\s*[-+]?\d+)?"
                        r"(?:\s+\*MESH_SMOOTHING(?:\s+[\d,]+)?)?(?:\s+\*MESH_MTLID\s+(\d+))?\s*")


def _what(what) -> str:
    return what() if callable(what) else what


def _describe(tok: _Tok) -> str:
    if tok.kind == "eof":
        return "end of file"
    if tok.kind == "key":
        return f"key {tok.text}"
    text = tok.text if len(tok.text) <= 40 else tok.text[:37] + "..."
    if tok.kind == "str":
        return f"string {text}"
    return f"'{text}'"


# =============================================================================================
# ASE parser
# =============================================================================================
class _AseParser:
    """Recursive descent over the token stream with one token of look-ahead."""

    def __init__(self, text: str, path: str, size: int):
        self.path = path
        self.size = size
        self.lexer = _Lexer(text, path)
        self.tok = self.lexer.next()
        self.last = self.tok                # the last token consumed
        self.context = ""
        self.result: Optional[AseFile] = None
        self.material_list_line: Optional[int] = None

    # -- primitives ---------------------------------------------------------------------------
    def advance(self) -> _Tok:
        tok = self.last = self.tok
        self.tok = self.lexer.next()
        return tok

    def fast_lines(self, pattern: re.Pattern, take: Callable) -> None:
        """Read whole lines matching ``pattern`` while ``take(match, line_no)`` accepts them,
        starting at the current token if it begins its line; then resume tokenising."""
        if not self.lexer.first or self.tok.kind != "key":
            return
        lines = self.lexer.lines
        index = start = self.tok.line - 1
        match = pattern.fullmatch
        while index < len(lines):
            m = match(lines[index])
            if m is None or not take(m, index + 1):
                break
            index += 1
        if index > start:
            self.lexer.seek(index)
            self.tok = self.lexer.next()

    def error(self, message: str, line: Optional[int] = None):
        where = f"in {self.context}: " if self.context else ""
        raise AseError(f"{self.path}:{line or self.tok.line}: {where}{message}")

    def expected(self, what: str):
        self.error(f"expected {what}, found {_describe(self.tok)}")

    # ``what`` (the value's description in error messages) is a string or, where it would
    # be formatted once per vertex, a callable that builds it only when an error is raised.
    def number(self, what, part: str = "") -> float:
        tok = self.tok
        if tok.kind == "word" and _FLOAT.fullmatch(tok.text):
            value = float(tok.text)
            if abs(value) <= MAX_ABS:
                self.advance()
                return value
            self.error(f"expected a number of magnitude at most {MAX_ABS:g} "
                       f"({_what(what)}{part}), found '{tok.text}'")
        if tok.kind == "word" and _NONFINITE.fullmatch(tok.text):
            self.error(f"expected a finite number ({_what(what)}{part}), found '{tok.text}' "
                       f"(not finite)")
        self.expected(f"a number ({_what(what)}{part})")

    def numbers(self, n: int, what) -> np.ndarray:
        return np.array([self.number(what, f", value {i + 1} of {n}") for i in range(n)])

    def integer(self, what, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
        tok = self.tok
        if not (tok.kind == "word" and _INT.fullmatch(tok.text)):
            self.expected(f"an integer ({_what(what)})")
        value = int(tok.text)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            rng = f"{lo}..{hi}" if hi is not None else f">= {lo}"
            self.error(f"expected an integer {rng} ({_what(what)}), found {value}")
        self.advance()
        return value

    def string(self, what: str) -> str:
        if self.tok.kind != "str":
            self.expected(f'a quoted string ({what})')
        return self.advance().text[1:-1]

    def label(self, label: str, what):
        if not (self.tok.kind == "word" and self.tok.text.upper() == label):
            self.expected(f"'{label}' ({_what(what)})")
        self.advance()

    def count(self, key: _Tok, what: str) -> int:
        """A count, refused when it exceeds MAX_COUNT or what the file's size can hold."""
        n = self.integer(f"number of {what} after {key.text}", lo=0)
        limit = self.size // MIN_ITEM_BYTES
        if n > MAX_COUNT:
            self.error(f"{key.text} {n} exceeds the limit of {MAX_COUNT:,} {what}", key.line)
        if n > limit:
            self.error(f"{key.text} {n} is more {what} than a file of {self.size:,} bytes can "
                       f"list (at most {limit:,})", key.line)
        return n

    def block(self, handlers: dict, opener: Optional[_Tok], fast: Optional[tuple] = None):
        """Read ``{ *KEY ... }`` (``opener`` is the key owning the block; None: the file's top
        level, ended by end of file). Known keys go to their handler, called with the key
        token after it was consumed; unknown keys are skipped with their values and block.
        ``fast`` = (pattern, take) reads matching whole lines first (:meth:`fast_lines`)."""
        if opener is not None:
            if self.tok.kind != "{":
                self.expected(f"'{{' opening the {opener.text} block")
            self.advance()
        while True:
            if fast is not None and self.lexer.first and self.tok.kind == "key":
                self.fast_lines(*fast)
            tok = self.tok
            if tok.kind == "key":
                self.advance()
                handler = handlers.get(tok.text)
                if handler is None:
                    self.skip(tok)
                    continue
                handler(tok)
                if self.tok.kind not in ("key", "}", "eof"):
                    self.expected(f"a *KEY or '}}' after the value of {tok.text} (line "
                                  f"{tok.line})")
            elif tok.kind == "}":
                if opener is None:
                    self.error("found '}' with no block open (too many closing braces)")
                self.advance()
                return
            elif tok.kind == "eof":
                if opener is None:
                    return
                self.error(f"expected '}}' closing the {opener.text} block opened at line "
                           f"{opener.line}, found end of file (truncated file?)")
            else:
                self.expected("a *KEY" + (" or '}'" if opener is not None else ""))

    def skip(self, key: _Tok):
        """Skip an unknown key: its words and strings, then a balanced ``{...}`` if one comes."""
        while self.tok.kind in ("word", "str"):
            self.advance()
        if self.tok.kind != "{":
            return
        depth = 0
        while True:
            tok = self.advance()
            if tok.kind == "{":
                depth += 1
            elif tok.kind == "}":
                depth -= 1
                if depth == 0:
                    return
            elif tok.kind == "eof":
                self.error(f"expected '}}' closing the block of {key.text} (line {key.line}, "
                           f"skipped as unknown), found end of file (truncated file?)")

    def once(self, seen: dict, key: _Tok):
        """A key that may appear only once per block: remember it, refuse a second one."""
        if key.text in seen:
            self.error(f"{key.text} appears twice (first at line {seen[key.text]})", key.line)
        seen[key.text] = key.line

    # -- file ---------------------------------------------------------------------------------
    def parse(self) -> AseFile:
        tok = self.tok
        if not (tok.kind == "key" and tok.text == "*3DSMAX_ASCIIEXPORT"):
            self.expected("*3DSMAX_ASCIIEXPORT at the start of an ASE file")
        self.advance()
        version = self.integer("ASE version after *3DSMAX_ASCIIEXPORT", lo=0)
        self.result = AseFile(self.path, version, [], [], [], [])

        def duplicate_header(key):
            self.error(f"{key.text} appears twice (it belongs only at the start)", key.line)

        depth = [0]

        def group(key):
            if self.tok.kind == "str":
                self.advance()
            if depth[0] >= MAX_NESTING:
                self.error(f"*GROUP blocks nested more than {MAX_NESTING} deep", key.line)
            depth[0] += 1
            self.block(top, key)
            depth[0] -= 1

        top = {
            "*3DSMAX_ASCIIEXPORT": duplicate_header,
            "*MATERIAL_LIST": self.material_list,
            "*GEOMOBJECT": self.geomobject,
            "*CAMERAOBJECT": self.cameraobject,
            "*LIGHTOBJECT": self.lightobject,
            "*GROUP": group,
        }
        self.block(top, None)
        res = self.result
        if self.last.kind != "}":
            self.error(f"expected the file to end with the '}}' of its last block, found "
                       f"{_describe(self.last)} at the end (truncated file?)", self.last.line)
        if not (res.geoms or res.cameras or res.lights):
            self.error("expected at least one *GEOMOBJECT, *CAMERAOBJECT or *LIGHTOBJECT, "
                       "found none: nothing to import")
        for geom in res.geoms:
            if geom.material_ref is not None and geom.material_ref >= len(res.materials):
                self.context = f"GEOMOBJECT '{geom.name}'"
                self.error(f"*MATERIAL_REF {geom.material_ref} names no material: the "
                           f"*MATERIAL_LIST holds {len(res.materials)}", geom.material_ref_line)
        return res

    # -- materials ----------------------------------------------------------------------------
    def material_list(self, key: _Tok):
        if self.material_list_line is not None:
            self.error(f"*MATERIAL_LIST appears twice (first at line {self.material_list_line})",
                       key.line)
        self.material_list_line = key.line
        state = {"count": None, "count_line": key.line}
        materials: dict = {}

        def count(k):
            if state["count"] is not None:
                self.error("*MATERIAL_COUNT appears twice in the *MATERIAL_LIST", k.line)
            state["count"] = self.count(k, "materials")
            state["count_line"] = k.line

        def material(k):
            if state["count"] is None:
                self.error("expected *MATERIAL_COUNT before the first *MATERIAL", k.line)
            n = state["count"]
            if n == 0:
                self.error("*MATERIAL given but *MATERIAL_COUNT is 0", k.line)
            index = self.integer(f"material index after *MATERIAL (*MATERIAL_COUNT is {n})",
                                 lo=0, hi=n - 1)
            if index in materials:
                self.error(f"*MATERIAL {index} appears twice (first at line "
                           f"{materials[index].line})", k.line)
            materials[index] = self.material(k, index, depth=0)

        self.block({"*MATERIAL_COUNT": count, "*MATERIAL": material}, key)
        n = state["count"] or 0
        if len(materials) != n:
            missing = next(i for i in range(n) if i not in materials)
            self.error(f"*MATERIAL_COUNT is {n} (line {state['count_line']}) but the "
                       f"*MATERIAL_LIST holds {len(materials)} *MATERIAL blocks (no *MATERIAL "
                       f"{missing})", key.line)
        self.result.materials = [materials[i] for i in range(n)]

    def material(self, key: _Tok, index: int, depth: int) -> AseMaterial:
        outer = self.context
        self.context = f"{key.text.lstrip('*')} {index}"
        seen: dict = {}
        mat = AseMaterial(index, "", key.line)
        subs: dict = {}
        state = {"nsub": None, "nsub_line": key.line}

        def name(k):
            self.once(seen, k)
            mat.name = self.string("material name")
            self.context = f"{key.text.lstrip('*')} {index} '{mat.name}'"

        def diffuse(k):
            self.once(seen, k)
            mat.diffuse = self.numbers(3, "*MATERIAL_DIFFUSE r g b")

        def numsub(k):
            self.once(seen, k)
            state["nsub"] = self.count(k, "submaterials")
            state["nsub_line"] = k.line

        def sub(k):
            if state["nsub"] is None:
                self.error("expected *NUMSUBMTLS before the first *SUBMATERIAL", k.line)
            n = state["nsub"]
            if n == 0:
                self.error("*SUBMATERIAL given but *NUMSUBMTLS is 0", k.line)
            i = self.integer("submaterial index after *SUBMATERIAL", lo=0, hi=n - 1)
            if i in subs:
                self.error(f"*SUBMATERIAL {i} appears twice (first at line {subs[i].line})",
                           k.line)
            if depth >= MAX_NESTING:
                self.error(f"submaterials nested more than {MAX_NESTING} deep", k.line)
            subs[i] = self.material(k, i, depth + 1)

        self.block({"*MATERIAL_NAME": name, "*MATERIAL_DIFFUSE": diffuse,
                    "*NUMSUBMTLS": numsub, "*SUBMATERIAL": sub}, key)
        if "*MATERIAL_NAME" not in seen:
            self.error(f"expected *MATERIAL_NAME in {key.text} {index}", key.line)
        n = state["nsub"] or 0
        if len(subs) != n:
            missing = next(i for i in range(n) if i not in subs)
            self.error(f"*NUMSUBMTLS is {n} (line {state['nsub_line']}) but {len(subs)} "
                       f"*SUBMATERIAL blocks follow (no *SUBMATERIAL {missing})", key.line)
        mat.submaterials = [subs[i] for i in range(n)]
        self.context = outer
        return mat

    # -- objects ------------------------------------------------------------------------------
    def node_name(self, seen: dict, key: _Tok, kind: str, obj):
        self.once(seen, key)
        obj["name"] = self.string("object name")
        self.context = f"{kind} '{obj['name']}'"

    def node_tm(self, key: _Tok) -> NodeTM:
        seen: dict = {}
        vals: dict = {}

        def vec(k):
            self.once(seen, k)
            vals[k.text] = self.numbers(3, f"{k.text} x y z")

        def name(k):
            self.once(seen, k)
            self.string("node name")

        keys = ("*TM_ROW0", "*TM_ROW1", "*TM_ROW2", "*TM_ROW3", "*TM_POS")
        self.block({**{k: vec for k in keys}, "*NODE_NAME": name}, key)
        rows = [vals.get(k) for k in keys[:3]]
        if any(r is not None for r in rows) and any(r is None for r in rows):
            missing = next(k for k, r in zip(keys, rows) if r is None)
            self.error(f"expected {missing} in *NODE_TM (TM_ROW0, TM_ROW1 and TM_ROW2 come "
                       f"together)", key.line)
        translation = vals.get("*TM_ROW3", vals.get("*TM_POS"))
        if translation is None:
            self.error("expected *TM_ROW3 or *TM_POS (the position) in *NODE_TM", key.line)
        return NodeTM(key.line, np.array(rows) if rows[0] is not None else None, translation)

    def object_block(self, key: _Tok, kind: str, handlers: dict, max_tms: int) -> dict:
        """Common part of GEOMOBJECT / CAMERAOBJECT / LIGHTOBJECT: NODE_NAME and NODE_TM(s)."""
        outer = self.context
        self.context = f"{kind} (line {key.line})"
        obj: dict = {"name": None, "tms": [], "seen": {}}

        def tm(k):
            if len(obj["tms"]) >= max_tms:
                what = "once" if max_tms == 1 else "at most twice (object and target)"
                self.error(f"*NODE_TM may appear {what} in a {kind}", k.line)
            obj["tms"].append(self.node_tm(k))

        bound = {k: functools.partial(h, obj=obj) for k, h in handlers.items()}
        self.block({"*NODE_NAME": lambda k: self.node_name(obj["seen"], k, kind, obj),
                    "*NODE_TM": tm, **bound}, key)
        if obj["name"] is None:
            self.error(f"expected *NODE_NAME in the {kind} block opened at line {key.line}",
                       key.line)
        if not obj["tms"]:
            self.error(f"expected *NODE_TM (the object's transform) in {kind} "
                       f"'{obj['name']}'", key.line)
        obj["outer"] = outer
        return obj

    def geomobject(self, key: _Tok):
        def mesh(k, obj):
            self.once(obj["seen"], k)
            obj["mesh"] = self.mesh(k)

        def material_ref(k, obj):
            self.once(obj["seen"], k)
            obj["material_ref"] = self.integer("material index after *MATERIAL_REF", lo=0)
            obj["material_ref_line"] = k.line

        obj = self.object_block(key, "GEOMOBJECT",
                                {"*MESH": mesh, "*MATERIAL_REF": material_ref}, 1)
        if "mesh" not in obj:
            self.error(f"expected a *MESH block in GEOMOBJECT '{obj['name']}'", key.line)
        vertices, faces, mtlids = obj["mesh"]
        self.result.geoms.append(AseGeom(obj["name"], key.line, obj["tms"][0], vertices, faces,
                                         mtlids, obj.get("material_ref"),
                                         obj.get("material_ref_line", 0)))
        self.context = obj["outer"]

    def mesh(self, key: _Tok):
        seen: dict = {}
        st: dict = {}

        def numvertex(k):
            self.once(seen, k)
            st["nv"], st["nv_line"] = self.count(k, "vertices"), k.line

        def numfaces(k):
            self.once(seen, k)
            st["nf"], st["nf_line"] = self.count(k, "faces"), k.line

        def vertex_list(k):
            self.once(seen, k)
            if "nv" not in st:
                self.error("expected *MESH_NUMVERTEX before *MESH_VERTEX_LIST", k.line)
            n = st["nv"]
            verts = np.zeros((n, 3))
            lines = np.zeros(n, np.int64)

            def vertex(v):
                i = self.integer(lambda: f"vertex index after *MESH_VERTEX (0..{n - 1}; "
                                 f"*MESH_NUMVERTEX is {n})", lo=0, hi=n - 1)
                if lines[i]:
                    self.error(f"*MESH_VERTEX {i} appears twice (first at line {lines[i]})",
                               v.line)
                verts[i] = self.numbers(3, lambda: f"*MESH_VERTEX {i} x y z")
                lines[i] = v.line

            def take(m, line_no):               # fast path: the same checks as vertex()
                i = int(m[1])
                if i >= n or lines[i]:
                    return False
                xyz = (float(m[2]), float(m[3]), float(m[4]))
                if not max(abs(xyz[0]), abs(xyz[1]), abs(xyz[2])) <= MAX_ABS:
                    return False
                verts[i] = xyz
                lines[i] = line_no
                return True

            self.block({"*MESH_VERTEX": vertex}, k, fast=(_VERTEX_LINE, take))
            listed = int(np.count_nonzero(lines))
            if listed != n:
                missing = int(np.flatnonzero(lines == 0)[0])
                self.error(f"*MESH_NUMVERTEX is {n} (line {st['nv_line']}) but "
                           f"*MESH_VERTEX_LIST lists {listed} vertices (no *MESH_VERTEX "
                           f"{missing})", k.line)
            st["verts"] = verts

        def face_list(k):
            self.once(seen, k)
            for need, key_name in (("nv", "*MESH_NUMVERTEX"), ("nf", "*MESH_NUMFACES")):
                if need not in st:
                    self.error(f"expected {key_name} before *MESH_FACE_LIST", k.line)
            n, nv = st["nf"], st["nv"]
            faces = np.zeros((n, 3), np.int64)
            mtlids = np.zeros(n, np.int64)
            lines = np.zeros(n, np.int64)
            last = {"i": None}

            def face(f):
                i = self.face_index(n)
                if lines[i]:
                    self.error(f"*MESH_FACE {i} appears twice (first at line {lines[i]})",
                               f.line)
                for c, label in enumerate(("A:", "B:", "C:")):
                    self.label(label, lambda: f"corner {label[0]} of *MESH_FACE {i}")
                    if nv == 0:
                        self.error(f"*MESH_FACE {i} needs vertices but *MESH_NUMVERTEX is 0")
                    faces[i, c] = self.integer(lambda: f"vertex index of corner {label[0]} of "
                                               f"*MESH_FACE {i}; *MESH_NUMVERTEX is {nv}",
                                               lo=0, hi=nv - 1)
                # Optional edge-visibility flags "AB: 1 BC: 1 CA: 0" (ignored).
                while self.tok.kind == "word" and self.tok.text.upper() in ("AB:", "BC:",
                                                                            "CA:"):
                    edge = self.advance().text
                    self.integer(lambda: f"edge flag after {edge} of *MESH_FACE {i}")
                lines[i] = f.line
                last["i"] = i

            def mtlid(m):
                i = last["i"]
                if i is None:
                    self.error("expected *MESH_FACE before *MESH_MTLID", m.line)
                mtlids[i] = self.integer(lambda: f"material id of *MESH_FACE {i}", lo=0,
                                         hi=2**31 - 1)

            def take(m, line_no):               # fast path: the same checks as face()
                i = int(m[1])
                if i >= n or lines[i]:
                    return False
                abc = (int(m[2]), int(m[3]), int(m[4]))
                if max(abc) >= nv:
                    return False
                if m[5] is not None:
                    mtlid_value = int(m[5])
                    if mtlid_value > 2**31 - 1:
                        return False
                    mtlids[i] = mtlid_value
                faces[i] = abc
                lines[i] = line_no
                last["i"] = i
                return True

            self.block({"*MESH_FACE": face, "*MESH_MTLID": mtlid}, k,
                       fast=(_FACE_LINE, take))
            listed = int(np.count_nonzero(lines))
            if listed != n:
                missing = int(np.flatnonzero(lines == 0)[0])
                self.error(f"*MESH_NUMFACES is {n} (line {st['nf_line']}) but "
                           f"*MESH_FACE_LIST lists {listed} faces (no *MESH_FACE {missing})",
                           k.line)
            st["faces"], st["mtlids"] = faces, mtlids

        self.block({"*MESH_NUMVERTEX": numvertex, "*MESH_NUMFACES": numfaces,
                    "*MESH_VERTEX_LIST": vertex_list, "*MESH_FACE_LIST": face_list}, key)
        for need, what in (("nv", "*MESH_NUMVERTEX"), ("nf", "*MESH_NUMFACES")):
            if need not in st:
                self.error(f"expected {what} in *MESH", key.line)
        if "verts" not in st:
            if st["nv"]:
                self.error(f"expected *MESH_VERTEX_LIST in *MESH (*MESH_NUMVERTEX is "
                           f"{st['nv']})", key.line)
            st["verts"] = np.zeros((0, 3))
        if "faces" not in st:
            if st["nf"]:
                self.error(f"expected *MESH_FACE_LIST in *MESH (*MESH_NUMFACES is "
                           f"{st['nf']})", key.line)
            st["faces"], st["mtlids"] = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
        return st["verts"], st["faces"], st["mtlids"]

    def face_index(self, n: int) -> int:
        what = f"face number followed by ':' after *MESH_FACE (0..{n - 1})"
        tok = self.tok
        if tok.kind == "word" and tok.text.endswith(":") and _INT.fullmatch(tok.text[:-1]):
            i = int(tok.text[:-1])
        elif tok.kind == "word" and _INT.fullmatch(tok.text):
            i = int(tok.text)
            self.advance()
            if not (self.tok.kind == "word" and self.tok.text == ":"):
                self.expected(f"':' after the face number {i}")
        else:
            self.expected(f"a {what}")
        if not 0 <= i < n:
            self.error(f"expected a {what}, found {i} (*MESH_NUMFACES is {n})")
        self.advance()
        return i

    def cameraobject(self, key: _Tok):
        def settings(k, obj):
            self.once(obj["seen"], k)
            inner: dict = {}

            def fov(f):
                self.once(inner, f)
                obj["fov"] = self.number("*CAMERA_FOV in radians")
                obj["fov_line"] = f.line
                lo, hi = FOV_RANGE
                if not lo <= obj["fov"] <= hi:
                    self.error(f"*CAMERA_FOV {obj['fov']:g} rad is outside {lo}..{hi} rad "
                               f"(the field of view is in radians)", f.line)

            self.block({"*CAMERA_FOV": fov}, k)

        obj = self.object_block(key, "CAMERAOBJECT", {"*CAMERA_SETTINGS": settings}, 2)
        tms = obj["tms"]
        self.result.cameras.append(AseCamera(obj["name"], key.line, tms[0],
                                             tms[1] if len(tms) > 1 else None,
                                             obj.get("fov", DEFAULT_FOV),
                                             obj.get("fov_line", key.line)))
        self.context = obj["outer"]

    def lightobject(self, key: _Tok):
        def light_type(k, obj):
            self.once(obj["seen"], k)
            tok = self.tok
            if not (tok.kind == "word" and tok.text in LIGHT_TYPES):
                self.expected("a light type after *LIGHT_TYPE (Omni, Target, Free or "
                              "Directional)")
            obj["type"] = self.advance().text

        def uselight(k, obj):
            self.once(obj["seen"], k)
            obj["enabled"] = bool(self.integer("*LIGHT_USELIGHT 0 or 1", lo=0, hi=1))

        def settings(k, obj):
            self.once(obj["seen"], k)
            inner: dict = {}

            def color(c):
                self.once(inner, c)
                obj["color"] = self.numbers(3, "*LIGHT_COLOR r g b")
                if np.any(obj["color"] < 0):
                    self.error(f"*LIGHT_COLOR {obj['color'].tolist()} is negative (negative "
                               f"light is not supported)", c.line)

            def intens(c):
                self.once(inner, c)
                obj["intensity"] = self.number("*LIGHT_INTENS multiplier")
                if obj["intensity"] < 0:
                    self.error(f"*LIGHT_INTENS {obj['intensity']:g} is negative (3ds Max "
                               f"'darklights' are not supported)", c.line)

            def angle(c):
                self.once(inner, c)
                obj[c.text] = self.number(f"{c.text} in degrees")
                obj[c.text + "_line"] = c.line

            self.block({"*LIGHT_COLOR": color, "*LIGHT_INTENS": intens,
                        "*LIGHT_HOTSPOT": angle, "*LIGHT_FALLOFF": angle}, k)

        obj = self.object_block(key, "LIGHTOBJECT",
                                {"*LIGHT_TYPE": light_type, "*LIGHT_USELIGHT": uselight,
                                 "*LIGHT_SETTINGS": settings}, 2)
        if "type" not in obj:
            self.error(f"expected *LIGHT_TYPE in LIGHTOBJECT '{obj['name']}'", key.line)
        kind = LIGHT_TYPES[obj["type"]]
        hotspot = obj.get("*LIGHT_HOTSPOT", DEFAULT_HOTSPOT)
        falloff = obj.get("*LIGHT_FALLOFF", DEFAULT_FALLOFF)
        falloff_line = obj.get("*LIGHT_FALLOFF_line", key.line)
        if kind == "SPOT":
            if not 1.0 <= falloff <= 180.0:
                self.error(f"spot falloff {falloff:g} deg is outside 1..180 deg (the cone "
                           f"angle, in degrees)", falloff_line)
            if not 0.0 <= hotspot <= 180.0:
                self.error(f"spot hotspot {hotspot:g} deg is outside [0, 180] deg",
                           obj.get("*LIGHT_HOTSPOT_line", key.line))
        tms = obj["tms"]
        self.result.lights.append(AseLight(
            obj["name"], key.line, obj["type"], tms[0], tms[1] if len(tms) > 1 else None,
            obj.get("color", np.ones(3)), obj.get("intensity", 1.0), hotspot, falloff,
            falloff_line, obj.get("enabled", True)))
        self.context = obj["outer"]


def _decode(data: bytes) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("cp1252", errors="replace")  # 3ds Max writes the ANSI code page


def parse_ase(text: str, path: str = "<ase>") -> AseFile:
    """Parse the text of an ASE file (see the module docstring); ``path`` names it in errors.
    Raises :class:`AseError`."""
    size = len(text.encode("utf-8", errors="replace"))
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return _AseParser(text, path, size).parse()


# =============================================================================================
# Companion material file
# =============================================================================================
_MAT_TOKEN = re.compile(r'\s*(?:(?P<str>"[^"]*")|(?P<bad>"[^"]*$)|(?P<comment>#.*)'
                        r'|(?P<word>[^\s"]+))')
_FIELDS = ("diffuse", "specular", "exitance")


def parse_companion(text: str, path: str = "<mat>") -> Companion:
    """Parse a companion material file (format in the module docstring). Raises
    :class:`AseError` naming the line, and the material where there is one."""
    out = Companion(path)
    ended = None
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    for line_no, line in enumerate(lines, 1):
        toks = []                                   # (kind, text)
        pos = 0
        line = line.rstrip("\r")
        while pos < len(line):
            m = _MAT_TOKEN.match(line, pos)
            if m is None or m.end() == pos:         # only trailing whitespace is left
                break
            pos = m.end()
            if m.lastgroup == "bad":
                raise AseError(f"{path}:{line_no}: expected a closing '\"' on the same line, "
                               f"found end of line")
            if m.lastgroup == "comment":
                break
            toks.append((m.lastgroup, m.group(m.lastgroup)))
        if not toks:
            continue

        def err(message, _n=line_no):
            raise AseError(f"{path}:{_n}: {message}")

        def found(i):
            if i >= len(toks):
                return "end of line"
            kind, t = toks[i]
            return f"string {t}" if kind == "str" else f"'{t}'"

        def num(i, what):
            if i < len(toks) and toks[i][0] == "word" and _FLOAT.fullmatch(toks[i][1]):
                v = float(toks[i][1])
                if abs(v) <= MAX_ABS:
                    return v
            err(f"expected a finite number ({what}), found {found(i)}")

        if ended is not None:
            err(f"expected nothing after 'end' (line {ended}), found {found(0)}")
        kind, word = toks[0]
        if kind == "word" and word == "end":
            if len(toks) > 1:
                err(f"expected end of line after 'end', found {found(1)}")
            ended = line_no
            continue
        if kind != "word" or word not in ("material", "light", "unit"):
            err(f"expected 'material', 'light', 'unit' or 'end', found {found(0)}")

        if word == "unit":
            if out.unit_line:
                err(f"'unit' appears twice (first at line {out.unit_line})")
            out.unit = num(1, "metres per ASE unit after 'unit'")
            if not 0 < out.unit <= MAX_UNIT:
                err(f"expected a unit in (0, {MAX_UNIT:g}] (metres per ASE unit), found "
                    f"{out.unit:g}")
            if len(toks) > 2:
                err(f"expected end of line after the unit, found {found(2)}")
            out.unit_line = line_no
            continue

        if len(toks) < 2 or toks[1][0] != "str":
            err(f"expected a quoted name after '{word}', found {found(1)}")
        name = toks[1][1][1:-1]
        if not name:
            err(f"expected a non-empty {word} name, found \"\"")
        table = out.materials if word == "material" else out.light_power
        if name in table:
            first = table[name].line if word == "material" else table[name][1]
            err(f"{word} \"{name}\" appears twice (first at line {first})")

        if word == "light":
            if len(toks) < 3 or toks[2] != ("word", "power"):
                err(f"light \"{name}\": expected 'power', found {found(2)}")
            power = num(3, f"power of light \"{name}\" in W (W/m^2 for Directional)")
            if power < 0:
                err(f"light \"{name}\": power {power:g} is negative")
            if len(toks) > 4:
                err(f"light \"{name}\": expected end of line after the power, found "
                    f"{found(4)}")
            out.light_power[name] = (power, line_no)
            continue

        values = {}
        i = 2
        while i < len(toks):
            kind, f = toks[i]
            if kind != "word" or f not in _FIELDS:
                err(f"material \"{name}\": expected 'diffuse', 'specular' or 'exitance', "
                    f"found {found(i)}")
            if f in values:
                err(f"material \"{name}\": '{f}' appears twice")
            j = i + 1
            nums = []
            while j < len(toks) and not (toks[j][0] == "word" and toks[j][1] in _FIELDS):
                word_j = toks[j][1]
                if toks[j][0] != "word" or not (_FLOAT.fullmatch(word_j)
                                                or _NONFINITE.fullmatch(word_j)):
                    err(f"material \"{name}\": expected a number ({f}) or 'diffuse', "
                        f"'specular' or 'exitance', found {found(j)}")
                nums.append(num(j, f"{f} of material \"{name}\""))
                j += 1
            if len(nums) not in (1, 3):
                err(f"material \"{name}\": expected 1 (grey) or 3 (R G B) numbers after "
                    f"'{f}', found {len(nums)}")
            rgb = np.array(nums * 3 if len(nums) == 1 else nums, dtype=np.float64)
            if np.any(rgb < 0):
                err(f"material \"{name}\": {f} {rgb.tolist()} is negative")
            if f == "exitance" and np.any(rgb > MAX_EXITANCE):
                err(f"material \"{name}\": exitance {rgb.tolist()} is above {MAX_EXITANCE:g} "
                    f"W/m^2")
            if f != "exitance" and np.any(rgb > 1):
                err(f"material \"{name}\": {f} reflectance {rgb.tolist()} is above 1 "
                    f"(reflectances are fractions in [0, 1])")
            values[f] = rgb
            i = j
        zero = np.zeros(3)
        mat = CompanionMaterial(name, line_no, values.get("diffuse", zero.copy()),
                                values.get("specular", zero.copy()),
                                values.get("exitance", zero.copy()))
        total = mat.diffuse + mat.specular
        if np.any(total > 1 + 1e-9):
            out.warnings.append(
                f"{path}:{line_no}: material \"{name}\": diffuse + specular reflectance "
                f"{np.round(total, 4).tolist()} exceeds 1; kept as written, the renderer "
                f"scales both down to conserve energy")
        out.materials[name] = mat
    if ended is None:
        raise AseError(f"{path}:{max(len(lines), 1)}: expected 'end' as the last statement, "
                       f"found end of file (truncated file?)")
    return out


# =============================================================================================
# load(): both files -> AseScene
# =============================================================================================
def companion_path(ase_path: str) -> str:
    """The companion file of ``ase_path``: same folder and stem, extension ``.mat``."""
    return os.path.splitext(ase_path)[0] + ".mat"


def _read(path: str) -> str:
    try:
        with open(path, "rb") as fh:
            return _decode(fh.read())
    except OSError as exc:
        raise AseError(f"{path}: cannot read the file: {exc.strerror or exc}") from None


def _look_at(position: np.ndarray, target: np.ndarray) -> Optional[np.ndarray]:
    """3x3 rotation whose -Z points from ``position`` to ``target``, +Y up (world +Z hint)."""
    f = target - position
    n = np.linalg.norm(f)
    if not n > 1e-12:
        return None
    f = f / n
    up = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    x = np.cross(f, up)
    x /= np.linalg.norm(x)
    y = np.cross(x, f)
    return np.column_stack([x, y, -f])


def _world_matrix(path: str, name: str, kind: str, tm: NodeTM, target: Optional[NodeTM],
                  unit: float) -> np.ndarray:
    m = tm.matrix()
    m[:3, 3] *= unit
    if tm.rows is None and target is not None:
        rot = _look_at(tm.translation, target.translation)
        if rot is None:
            raise AseError(f"{path}:{target.line}: in {kind} '{name}': expected a target "
                           f"apart from the object, found it at the object's position "
                           f"{tm.translation.tolist()}")
        m[:3, :3] = rot
    return m


def _leaf(mat: AseMaterial, mtlid: int) -> AseMaterial:
    while mat.submaterials:
        mat = mat.submaterials[mtlid % len(mat.submaterials)]
    return mat


def load(ase_path: str, material_path: Optional[str] = None) -> AseScene:
    """Read ``ase_path`` and its companion file (``material_path``; default
    :func:`companion_path`, optional: when absent, ASE diffuse colours are used with a
    warning) into an :class:`AseScene` in metres. Raises :class:`AseError`."""
    raw = parse_ase(_read(ase_path), ase_path)
    warnings: list = []
    if material_path is None:
        default = companion_path(ase_path)
        if os.path.exists(default):
            material_path = default
    if material_path is not None:
        comp = parse_companion(_read(material_path), material_path)
        warnings.extend(comp.warnings)
    else:
        comp = Companion("")
        warnings.append(f"{ase_path}: no companion material file "
                        f"{os.path.basename(companion_path(ase_path))}; materials take "
                        f"*MATERIAL_DIFFUSE as diffuse reflectance, with no specular "
                        f"reflectance and no exitance")
    unit = comp.unit

    # Materials actually used, each name once, in first-use order.
    specs: dict = {}
    all_names = set()

    def collect(m):
        all_names.add(m.name)
        for s in m.submaterials:
            collect(s)

    for m in raw.materials:
        collect(m)

    def material_spec(mat: AseMaterial) -> str:
        if mat.name in specs:
            return mat.name
        entry = comp.materials.get(mat.name)
        if entry is not None:
            specs[mat.name] = MaterialSpec(mat.name, entry.diffuse.copy(), entry.specular.copy(),
                                           entry.exitance.copy(),
                                           f"{os.path.basename(comp.path)} line {entry.line}")
            return mat.name
        if mat.diffuse is not None:
            diffuse = np.clip(mat.diffuse, 0.0, 1.0)
            source = f"*MATERIAL_DIFFUSE (line {mat.line})"
        else:
            diffuse = np.full(3, DEFAULT_DIFFUSE)
            source = "default grey"
        if comp.path:
            warnings.append(f"{comp.path}: no entry for material \"{mat.name}\" (used in "
                            f"{os.path.basename(ase_path)}); diffuse reflectance "
                            f"{np.round(diffuse, 4).tolist()} from {source}, no specular "
                            f"reflectance, no exitance")
        specs[mat.name] = MaterialSpec(mat.name, diffuse, np.zeros(3), np.zeros(3), source)
        return mat.name

    meshes = []
    for g in raw.geoms:
        slots: list = []
        face_slots = np.zeros(len(g.faces), np.int64)
        if g.material_ref is not None:
            top = raw.materials[g.material_ref]
            if top.submaterials:
                leaf_ids = {}
                ids = np.unique(g.mtlids) if len(g.faces) else np.zeros(0, np.int64)
                for mtlid in ids.tolist():
                    name = material_spec(_leaf(top, mtlid))
                    if name not in leaf_ids:
                        leaf_ids[name] = len(slots)
                        slots.append(name)
                    face_slots[g.mtlids == mtlid] = leaf_ids[name]
            else:
                slots.append(material_spec(top))
        vertices = g.vertices * unit
        faces = g.faces
        bad = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | \
              (faces[:, 2] == faces[:, 0])
        if np.any(bad):
            warnings.append(f"{ase_path}:{g.line}: GEOMOBJECT '{g.name}': {int(bad.sum())} "
                            f"face(s) repeat a vertex (degenerate) and are dropped")
            faces, face_slots = faces[~bad], face_slots[~bad]
        matrix = _world_matrix(ase_path, g.name, "GEOMOBJECT", g.tm, None, unit)
        rot = matrix[:3, :3]
        scale = max(float(np.abs(rot).max()), 1e-300)
        if abs(np.linalg.det(rot / scale)) < 1e-9:
            warnings.append(f"{ase_path}:{g.tm.line}: GEOMOBJECT '{g.name}': *NODE_TM is "
                            f"singular (zero scale); the object gets the identity transform")
            matrix = np.eye(4)
            local = vertices.copy()
        else:
            local = (vertices - matrix[:3, 3]) @ np.linalg.inv(rot).T
        meshes.append(MeshSpec(g.name, g.line, matrix, vertices, local, faces, face_slots,
                               slots))

    cameras = [CameraSpec(c.name, c.line,
                          _world_matrix(ase_path, c.name, "CAMERAOBJECT", c.tm, c.target, unit),
                          c.fov) for c in raw.cameras]

    lights = []
    for light in raw.lights:
        kind = LIGHT_TYPES[light.type]
        matrix = _world_matrix(ase_path, light.name, "LIGHTOBJECT", light.tm, light.target,
                               unit)
        entry = comp.light_power.get(light.name)
        if entry is not None:
            power = entry[0]
            source = f"{os.path.basename(comp.path)} line {entry[1]}"
        else:
            per = SUN_IRRADIANCE_PER_INTENSITY if kind == "SUN" else POINT_WATTS_PER_INTENSITY
            power = per * light.intensity
            source = f"*LIGHT_INTENS {light.intensity:g} x {per:.4g}"
        size = math.radians(light.falloff) if kind == "SPOT" else 0.0
        blend = (float(np.clip(1.0 - light.hotspot / light.falloff, 0.0, 1.0))
                 if kind == "SPOT" else 0.0)
        if not light.enabled:
            warnings.append(f"{ase_path}:{light.line}: LIGHTOBJECT '{light.name}' is switched "
                            f"off (*LIGHT_USELIGHT 0); imported hidden from renders")
        lights.append(LightSpec(light.name, light.line, kind, matrix, light.color.copy(),
                                float(power), source, size, blend, light.enabled))

    light_names = {light.name for light in raw.lights}
    for name, (_, line) in comp.light_power.items():
        if name not in light_names:
            warnings.append(f"{comp.path}:{line}: light \"{name}\" names no LIGHTOBJECT in "
                            f"{os.path.basename(ase_path)}; ignored")
    for name, entry in comp.materials.items():
        if name not in all_names:
            warnings.append(f"{comp.path}:{entry.line}: material \"{name}\" names no material "
                            f"in {os.path.basename(ase_path)}; ignored")
    return AseScene(ase_path, material_path, unit, list(specs.values()), meshes, cameras,
                    lights, warnings)
