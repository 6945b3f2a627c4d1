"""The ``lanterna`` command: render a .blend, an .ase or a seed scene to EXR, bake a scene's
maps, save the seed scenes, run the benchmarks.

Usage
-----
``lanterna render [SCENE.blend | SCENE.ase [--materials FILE.mat]] -o OUT.exr [--png OUT.png]``
    ``[--report REPORT.json] [--maps MAPS.npz]``
    ``[--sensitivity P2|auto] [--knee P1]``
    ``[--scene scene1|scene2] [--resolution WxH] [--samples N] [--light-samples N]``
    ``[--bounces N] [--seed N] [--threads N] [--mode full|photon-map] [--photons N]``
    ``[--photon-k N] [--photon-radius R] [--photon-filter none|cone] [--photon-lookups N]``
    ``[--preset custom|preview|final] [--indirect cache|gather|photon-map] [--gather MxN]``
    ``[--gather-guided X] [--cache-error A] [--no-cache-refine] [--no-shadow-photons]``
    ``[--dry-run]``

    Renders the active scene of ``SCENE.blend`` with Lanterna (whatever engine the file names),
    an ``.ase`` scene imported as File > Import > ASE does (its companion ``.mat`` file next to
    it, or ``--materials``), or the seed's Scene 1 (``--scene`` picks another) when no file is
    given. ``--maps`` renders with maps from ``lanterna bake`` (or the add-on's Save) instead
    of building them; maps made for another scene or other map settings are refused, naming
    what differs. A ``.blend`` is read and rendered in a child process: Blender's reader can
    crash on a damaged file (a segmentation fault), which is then reported as
    ``lanterna: error: FILE: Blender could not read it (damaged file?)``, status 2 (measured
    cost of the child: about 0.1 s a render). Flags override
    the scene's ``Scene.lanterna`` settings; ``--resolution`` sets the full frame at 100 %.
    A render region (border) in the file is honoured as Blender does: with Crop the EXR holds
    the region only, otherwise the full frame with zeros outside the region.
    Writes ``OUT.exr`` (channels R, G, B, float32, linear radiance [W m^-2 sr^-1]), the
    optional sRGB ``OUT.png`` (clipped, no tone mapping) and the optional JSON report: the
    pipeline's report, the export statistics, warnings, settings, timings and peak memory.
    Progress and warnings go to stderr. With ``--sensitivity`` the PNG is made with the
    seed's tone curve instead (``engine/tonemap.py``, Fig. 11.1), as ``lanterna tonemap``.
    ``--dry-run`` exports the scene, prints the plan and each stage's estimated time and
    memory (``engine/estimate.py``) and exits 0 without rendering or writing anything (no
    ``-o`` needed). A render whose estimated memory exceeds what is available is refused
    before any work (status 2).

``lanterna bake [SCENE.blend | SCENE.ase | --scene NAME] -o MAPS.npz [the render's settings]``
    Every stage but the camera (photon map, irradiance cache, shadow photons), saved to
    ``MAPS.npz`` for ``render --maps`` or the add-on's Load.

``lanterna tonemap IN.exr OUT.png [--sensitivity P2|auto] [--knee P1]``
    The seed's conversion of radiance to RGB (section 11.2, Fig. 11.1; section 12.2.1):
    radiance at and above the saturation point ``P2`` [W m^-2 sr^-1] is 255, the knee
    ``P1`` defaults to ``P2 / 4``; ``auto`` (the default) puts the knee at the 95th
    percentile of the pixels' brightest channel. Reads channels R, G, B (or one layer's,
    e.g. ``ViewLayer.Combined``); writes an 8-bit PNG. Needs no ``bpy``.

``lanterna scene scene1|scene2 -o FILE.blend``
    Builds a seed scene (``engine/blender/seed_scenes.py``) and saves it.

``lanterna bench [...]``
    Hands its arguments to ``bench/main.py``'s ``main`` (a checkout's benchmarks; an installed
    add-on has none and says so).

Errors in the input (bad flags, a missing or unreadable .blend, an output that cannot be
written, a scene the exporter rejects) end with one line ``lanterna: error: ...`` on stderr
and exit status 2, before any rendering where they can be found early. Outputs are written
to temporary names in their own directories and renamed once all of them are complete, so
nothing is ever half-written. Ctrl-C stops the render between batches and writes nothing
(status 130). ``bpy`` is imported only once a command needs it, so ``--help`` is quick.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import dataclasses
import sys
import time

from ..settings import SETTINGS, RenderSettings

PROG = "lanterna"
RENDER_DEFAULTS = dataclasses.asdict(RenderSettings())
SEED_SCENES = ("scene1", "scene2")
BLEND_MAGIC = (b"BLENDER", b"\x28\xb5\x2f\xfd", b"\x1f\x8b")  # plain, zstd, gzip
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_CANCELLED = 0, 1, 2, 130


class UsageError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse would print the usage and exit; we want one line
        raise UsageError(message)


# -- Argument types ---------------------------------------------------------------------------
def _int_at_least(lowest: int, highest: int | None = None):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < lowest or (highest is not None and value > highest):
            bound = f"at least {lowest}" if highest is None else f"between {lowest} and {highest}"
            raise argparse.ArgumentTypeError(f"must be {bound}, got {value}")
        return value
    parse.__name__ = "integer"
    return parse


def _float_between(lowest: float, highest: float):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not (lowest <= value <= highest):
            raise argparse.ArgumentTypeError(f"must be a number between {lowest:g} and "
                                             f"{highest:g}, got {text}")
        return value
    parse.__name__ = "number"
    return parse


def _grid(text: str) -> tuple[int, int]:
    parts = text.lower().replace("×", "x").split("x")
    try:
        m, n = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MxN such as 8x32, got {text!r}") from None
    (m_lo, m_hi), (n_lo, n_hi) = ((SETTINGS[k].minimum, SETTINGS[k].maximum)
                                  for k in ("gather_m", "gather_n"))
    if not (m_lo <= m <= m_hi and n_lo <= n <= n_hi):
        raise argparse.ArgumentTypeError(f"M must be {m_lo:g}-{m_hi:g} and N {n_lo:g}-{n_hi:g}, "
                                         f"got {text}")
    return m, n


def _resolution(text: str) -> tuple[int, int]:
    parts = text.lower().replace("×", "x").split("x")
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 640x480, got {text!r}") \
            from None
    if not (1 <= w <= 65536 and 1 <= h <= 65536):
        raise argparse.ArgumentTypeError(f"width and height must be 1 to 65536, got {w}x{h}")
    return w, h


def _radiance(allow_auto: bool):
    def parse(text: str):
        if allow_auto and text.strip().lower() == "auto":
            return "auto"
        try:
            value = float(text)
        except ValueError:
            expected = "a number or 'auto'" if allow_auto else "a number"
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not (0.0 < value < float("inf")):
            raise argparse.ArgumentTypeError(f"must be a finite radiance > 0, got {text}")
        return value
    parse.__name__ = "radiance"
    return parse


def _tone_parameters(args) -> None:
    """Check --sensitivity and --knee together (before any work)."""
    if args.knee is not None and args.sensitivity in (None, "auto"):
        raise UsageError("--knee P1 needs --sensitivity P2 (a number)")
    if args.knee is not None and not args.knee < args.sensitivity:
        raise UsageError(f"--knee {args.knee:g} must be below --sensitivity "
                         f"{args.sensitivity:g}")


def _write_tone_png(path: str, image, sensitivity, knee) -> dict:
    """The seed's tone curve of ``image`` written to ``path``; returns the p2 and p1 used."""
    from .. import tonemap

    try:
        if sensitivity == "auto":
            sensitivity, knee = tonemap.auto_sensitivity(image)
        p2, p1 = tonemap.check_parameters(sensitivity, knee)
        tonemap.write_png(path, tonemap.seed_tone_curve(image, p2, p1))
    except tonemap.ToneMapError as exc:
        raise UsageError(str(exc)) from None
    return {"sensitivity": p2, "knee": p1}


def _passes(text: str):
    from ..passes import parse_passes
    try:
        return parse_passes(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _setting_flag(parser, name: str) -> None:
    """``--name`` for render setting ``name``, with its limits, choices, description and
    default from ``engine/settings.py`` (the contract Blender's properties follow too)."""
    spec, default = SETTINGS[name], RENDER_DEFAULTS[name]
    flag = "--" + name.replace("_", "-")
    text = f"{spec.description} (default {default})"
    if spec.choices:
        parser.add_argument(flag, choices=tuple(c[0] for c in spec.choices), default=None,
                            help=text)
    elif isinstance(default, int):
        parser.add_argument(flag, type=_int_at_least(int(spec.minimum), int(spec.maximum)),
                            metavar="N", help=text)
    else:
        parser.add_argument(flag, type=_float_between(spec.minimum, spec.maximum), metavar="X",
                            help=text)


def _scene_flags(parser, verb: str) -> None:
    """The scene to use and the render settings, shared by ``render`` and ``bake``."""
    parser.add_argument("blend", nargs="?", metavar="SCENE",
                        help=f"the .blend or .ase to {verb} (default: the seed's Scene 1)")
    parser.add_argument("--scene", choices=SEED_SCENES, default=None,
                        help=f"{verb} a seed scene built by code instead of a file")
    parser.add_argument("--materials", metavar="FILE.mat",
                        help="an .ase scene's companion material file (default: the .mat of "
                             "the same name next to it)")
    parser.add_argument("--resolution", type=_resolution, metavar="WxH",
                        help="full-frame size in pixels (percentage set to 100)")
    for name in ("samples", "light_samples", "bounces", "mode", "photons", "photon_k",
                 "photon_radius", "photon_filter", "preset", "indirect"):
        _setting_flag(parser, name)
    parser.add_argument("--gather", type=_grid, metavar="MxN",
                        help="final gather strata: M in theta x N in phi (default "
                             f"{RENDER_DEFAULTS['gather_m']}x{RENDER_DEFAULTS['gather_n']})")
    for name in ("gather_guided", "cache_error"):
        _setting_flag(parser, name)
    parser.add_argument("--no-shadow-photons", action="store_true",
                        help="trace every shadow ray (no lit/umbra classification)")
    parser.add_argument("--no-cache-refine", action="store_true",
                        help="place cache records by Ward's geometric weight only (no check "
                             "against the neighbours' gathers)")
    for name in ("photon_lookups", "seed", "threads"):
        _setting_flag(parser, name)
    parser.add_argument("--quiet", action="store_true", help="no progress line")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Lanterna: photon-mapping renderer for Blender scenes.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    render = sub.add_parser("render", help="render a .blend, an .ase or a seed scene to EXR",
                            description="Render a .blend or an .ase scene (or the seed's Scene "
                                        "1) to OpenEXR.")
    _scene_flags(render, "render")
    render.add_argument("-o", "--output", metavar="OUT.exr",
                        help="the OpenEXR file to write (R, G, B float32, linear); required "
                             "unless --dry-run")
    render.add_argument("--png", metavar="OUT.png", help="also write an sRGB 8-bit PNG")
    render.add_argument("--sensitivity", type=_radiance(True), metavar="P2",
                        help="make the PNG with the seed's tone curve (Fig. 11.1): saturation "
                             "point P2 in W m^-2 sr^-1, or 'auto'")
    render.add_argument("--knee", type=_radiance(False), metavar="P1",
                        help="the tone curve's knee (default P2/4)")
    render.add_argument("--report", metavar="REPORT.json", help="write the render report as JSON")
    render.add_argument("--passes", type=_passes, metavar="LIST", default=(),
                        help="extra passes written as EXR layers (Direct.R, ...): comma-separated "
                             "from direct, indirect, emission, photon-map, cache-points, photons, "
                             "shadow-classes, cache-usage, Cycles' light passes diffuse-direct, "
                             "diffuse-indirect, diffuse-color, glossy-/transmission- the same, "
                             "emit, environment (or their names DiffDir, ...), or all")
    render.add_argument("--maps", metavar="MAPS.npz",
                        help="render with maps baked before (lanterna bake) for this scene and "
                             "these map settings instead of building them")
    render.add_argument("--dry-run", action="store_true",
                        help="print the plan and each stage's estimated time and memory, "
                             "render and write nothing (engine/estimate.py)")

    bake = sub.add_parser("bake", help="bake a scene's maps (photons, cache, shadow photons)",
                          description="Build the photon map, the irradiance cache and the "
                                      "shadow photons of a scene, as a render would, and save "
                                      "them to an .npz that 'lanterna render --maps' and the "
                                      "add-on's Load can use.")
    _scene_flags(bake, "bake")
    bake.add_argument("-o", "--output", required=True, metavar="MAPS.npz",
                      help="the maps file to write")

    scene = sub.add_parser("scene", help="save a seed scene as a .blend",
                           description="Build one of the seed's scenes and save it.")
    scene.add_argument("name", choices=SEED_SCENES)
    scene.add_argument("-o", "--output", required=True, metavar="FILE.blend")

    tone = sub.add_parser("tonemap", help="convert an EXR to PNG with the seed's tone curve",
                          description="Convert linear radiance (OpenEXR) to an 8-bit PNG with "
                                      "the seed's tone curve (Fig. 11.1, section 12.2.1).")
    tone.add_argument("input", metavar="IN.exr", help="OpenEXR file of linear radiance")
    tone.add_argument("output", metavar="OUT.png", help="the PNG to write")
    tone.add_argument("--sensitivity", type=_radiance(True), default="auto", metavar="P2",
                      help="saturation point P2 in W m^-2 sr^-1 (default 'auto': knee at the "
                           "95th percentile)")
    tone.add_argument("--knee", type=_radiance(False), metavar="P1",
                      help="the knee P1, 0 < P1 < P2 (default P2/4)")
    tone.add_argument("--layer", default=None, metavar="NAME",
                      help="the EXR layer to convert, e.g. a pass written by render --passes "
                           "(Direct, CachePoints, ...; default: the image itself)")

    sub.add_parser("bench", help="run the benchmarks (arguments are passed on)", add_help=False)
    return parser


# -- Checks before any work -------------------------------------------------------------------
def _check_output(path: str, suffix: str, flag: str) -> str:
    path = os.path.abspath(os.path.expanduser(path))
    if not path.lower().endswith(suffix):
        raise UsageError(f"{flag} {path}: the file name must end in {suffix}")
    if os.path.isdir(path):
        raise UsageError(f"{flag} {path}: is a directory")
    directory = os.path.dirname(path)
    if not os.path.isdir(directory):
        raise UsageError(f"{flag} {path}: directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise UsageError(f"{flag} {path}: directory {directory} is not writable")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise UsageError(f"{flag} {path}: file exists and is not writable")
    return path


def check_blend(path: str) -> str:
    path = os.path.abspath(os.path.expanduser(path))
    _check_readable(path)
    with open(path, "rb") as f:
        head = f.read(8)
    if not head.startswith(BLEND_MAGIC):
        raise UsageError(f"{path}: not a .blend file")
    return path


def _check_readable(path: str) -> None:
    if not os.path.exists(path):
        raise UsageError(f"{path}: no such file")
    if not os.path.isfile(path):
        raise UsageError(f"{path}: not a file")
    try:
        with open(path, "rb") as f:
            f.read(1)
    except OSError as exc:
        raise UsageError(f"{path}: cannot read ({exc.strerror})") from None


def _scene_input(args) -> tuple[str, str | None]:
    """(kind, path) of the scene a command reads: ("blend", file), ("ase", file) or ("seed",
    None); every problem found before Blender is started."""
    if args.blend and args.scene:
        raise UsageError("give either SCENE or --scene, not both")
    if args.blend and args.blend.lower().endswith(".ase"):
        path = os.path.abspath(os.path.expanduser(args.blend))
        _check_readable(path)
        if args.materials:
            _check_readable(os.path.abspath(os.path.expanduser(args.materials)))
        return "ase", path
    if args.materials:
        raise UsageError("--materials goes with an .ase scene")
    if args.blend:
        return "blend", check_blend(args.blend)
    return "seed", None


# -- Blender side -----------------------------------------------------------------------------
def _ensure_registered():
    from . import registration

    registration.register()  # idempotent


def open_blend(path: str):
    import bpy

    _stage("open")
    try:
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False, use_scripts=False)
    except RuntimeError as exc:
        reason = " ".join(str(exc).split())
        reason = reason[len("Error: "):] if reason.startswith("Error: ") else reason
        raise UsageError(f"{path}: cannot be opened: {reason}") from None
    _stage("opened")
    return bpy.context.scene


def _open_ase(path: str, materials: str | None):
    """A fresh empty scene with the .ase imported into it (``ops/import_ase.py``: meshes,
    materials from the companion .mat file, lights, camera)."""
    import bpy

    from ...ops.import_ase import import_ase
    from ..ase import AseError

    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        summary = import_ase(path, bpy.context, materials and os.path.abspath(
            os.path.expanduser(materials)))
    except AseError as exc:
        raise UsageError(str(exc)) from None
    for text in summary.get("warnings", ()):
        print(f"{PROG}: warning: {' '.join(str(text).split())}", file=sys.stderr)
    if bpy.context.scene.camera is None:
        raise UsageError(f"{path}: the scene holds no camera to render from")
    return bpy.context.scene


class _Loaded:
    """A scene as a render, a bake or a dry run reads it: the Blender scene, the exported
    ``Scene``, the resolved settings, where it came from and how long loading took."""

    def __init__(self, args, kind: str, path: str | None):
        import bpy  # noqa: F401  (slow import, only now)
        from ..scene import SceneError
        from . import export, seed_scenes

        _ensure_registered()
        t0 = time.perf_counter()
        if kind == "blend":
            scene = open_blend(path)
        elif kind == "ase":
            scene = _open_ase(path, args.materials)
        else:
            scene = seed_scenes.build(args.scene or "scene1")
        _apply_overrides(scene, args)
        self.load_seconds = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.scene = scene
        self.source = path or f"seed:{args.scene or 'scene1'}"
        self.resolution = export.render_resolution(scene.render)
        if self.resolution[0] < 1 or self.resolution[1] < 1:
            raise UsageError(f"the scene's resolution is {self.resolution[0]}x"
                             f"{self.resolution[1]} pixels")
        self.border = export.render_border(scene.render, self.resolution)
        try:
            self.lscene = export.export_scene(bpy.context.evaluated_depsgraph_get(),
                                              resolution=self.resolution, border=self.border)
            self.settings = export.export_settings(scene).resolved()   # the preset applied
            self.settings.validate()
        except SceneError as exc:
            raise UsageError(str(exc)) from None
        self.export_seconds = time.perf_counter() - t0
        _stage("render")


# -- A .blend in a child process: Blender's reader can crash on a damaged file -----------------
STAGE_FILE_ENV = "LANTERNA_STAGE_FILE"


def _stage(name: str) -> None:
    """Tell the parent process (``_run_isolated``) which step this child has reached."""
    path = os.environ.get(STAGE_FILE_ENV)
    if path:
        with open(path, "w", encoding="ascii") as f:
            f.write(name)
        if os.environ.get("LANTERNA_TEST_CRASH_AT") == name:     # tests: a crash right here
            os.abort()


def _crashed(code: int) -> bool:
    """A child that died of a signal (POSIX: negative code) or of an exception Windows raised
    (an NTSTATUS error code such as 0xC0000005, an access violation)."""
    return code < 0 or code >= 0xC0000000


def _run_isolated(argv: list[str], blend: str) -> int:
    """The command again in a child process; this one only waits. Blender's .blend reader
    does not survive every damaged file: a flipped bit can crash it (a segmentation fault,
    no Python exception) inside ``open_mainfile``. The child tells which step it reached
    (``_stage``), so a crash while reading is reported as a damaged file, exit 2, and one
    later as an internal error, exit 1. Costs one more interpreter start (about 0.3 s);
    Ctrl-C reaches the child, which stops between batches and writes nothing."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="lanterna-") as tmp:
        stage_file = os.path.join(tmp, "stage")
        env = dict(os.environ, **{STAGE_FILE_ENV: stage_file})
        with _sigint_ignored():
            code = subprocess.call([sys.executable, "-m", f"{__package__}.cli", *argv], env=env)
        if not _crashed(code):
            return code
        try:
            with open(stage_file, encoding="ascii") as f:
                stage = f.read().strip()
        except OSError:
            stage = "start"
    if stage == "open":
        print(f"{PROG}: error: {blend}: Blender could not read it (damaged file?)",
              file=sys.stderr)
        return EXIT_USAGE
    when = "before reading" if stage == "start" else "after reading"
    print(f"{PROG}: internal error: Blender crashed (exit code {code}) {when} {blend}",
          file=sys.stderr)
    return EXIT_INTERNAL


@contextlib.contextmanager
def _sigint_ignored():
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:                              # not the main thread
        previous = None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _apply_overrides(scene, args) -> None:
    if args.resolution is not None:
        scene.render.resolution_x, scene.render.resolution_y = args.resolution
        scene.render.resolution_percentage = 100
    settings = scene.lanterna
    for flag in ("samples", "light_samples", "bounces", "seed", "threads", "photons",
                 "photon_k", "photon_radius", "photon_lookups"):
        value = getattr(args, flag)
        if value is not None:
            setattr(settings, flag, value)
    if args.gather is not None:
        settings.gather_m, settings.gather_n = args.gather
    if args.cache_error is not None:
        settings.cache_error = args.cache_error
    if args.gather_guided is not None:
        settings.gather_guided = args.gather_guided
    if args.no_cache_refine:
        settings.cache_refine = False
    if args.no_shadow_photons:
        settings.shadow_photons = False
    preset = args.preset or str(settings.preset).lower()
    if preset != "custom":
        overridden = [f"--{flag.replace('_', '-')}" for flag in
                      ("samples", "light_samples", "photons", "gather", "cache_error", "indirect")
                      if getattr(args, flag) is not None]
        if overridden:
            print(f"{PROG}: warning: the {preset} preset sets {', '.join(overridden)}; "
                  "those flags are ignored (use --preset custom)", file=sys.stderr)
    for flag in ("mode", "photon_filter", "indirect", "preset"):   # core names -> enum ids
        value = getattr(args, flag)
        if value is not None:
            setattr(settings, flag, value.upper().replace("-", "_"))


class _Progress:
    """One progress line on stderr: rewritten in place on a terminal, else every 10 %."""

    def __init__(self, enabled: bool, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = enabled and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.last_step = -1
        self.started = time.perf_counter()
        self.dirty = False

    def __call__(self, fraction: float, text: str = "") -> None:
        if not self.enabled:
            return
        pct = int(round(100 * max(0.0, min(1.0, fraction))))
        line = f"{PROG}: {pct:3d}% {text} ({time.perf_counter() - self.started:.1f} s)"
        if self.tty:
            self.stream.write("\r\033[K" + line)
            self.dirty = True
        elif pct // 10 != self.last_step:
            self.last_step = pct // 10
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.dirty:
            self.stream.write("\n")
            self.stream.flush()
            self.dirty = False


@contextlib.contextmanager
def _sigint_flag():
    """While active, Ctrl-C sets ``flag['set']`` instead of raising (main thread only)."""
    flag = {"set": False}

    def handler(_signum, _frame):
        flag["set"] = True

    try:
        previous = signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main thread
        previous = None
    try:
        yield flag
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _full_frame(image, scene_camera, crop: bool):
    """Place the border window into the full frame (zeros outside) unless cropping."""
    import numpy as np

    width, height = scene_camera.resolution
    x0, y0, x1, y1 = scene_camera.border
    if crop or (x0, y0, x1, y1) == (0, 0, width, height):
        return image
    full = np.zeros((height, width, 3), np.float32)
    full[height - y1:height - y0, x0:x1] = image
    return full


def cmd_render(args) -> int:
    started = time.perf_counter()
    # 1. Everything that can be checked without Blender, before any work.
    kind, path = _scene_input(args)
    if args.dry_run:   # issue 6: the estimate only; no output is checked or written
        return _dry_run(args, kind, path)
    if not args.output:
        raise UsageError("the following arguments are required: -o/--output")
    outputs = {"exr": _check_output(args.output, ".exr", "-o")}
    if args.png:
        outputs["png"] = _check_output(args.png, ".png", "--png")
    elif args.sensitivity is not None or args.knee is not None:
        raise UsageError("--sensitivity and --knee need --png OUT.png")
    _tone_parameters(args)
    if args.report:
        outputs["report"] = _check_output(args.report, ".json", "--report")
    if len(set(outputs.values())) != len(outputs):
        raise UsageError("the output files must be different")
    maps_path = None
    if args.maps:
        maps_path = os.path.abspath(os.path.expanduser(args.maps))
        _check_readable(maps_path)

    # 2. Load the scene and export it (3).
    from ..scene import SceneError
    from .. import imageio, pipeline
    from ..artifacts import load_artifacts
    from ..memory import peak_memory

    loaded = _Loaded(args, kind, path)
    scene, lscene, settings = loaded.scene, loaded.lscene, loaded.settings
    resolution, border = loaded.resolution, loaded.border
    load_seconds, export_seconds = loaded.load_seconds, loaded.export_seconds
    warnings = []

    def warn(text):
        text = " ".join(str(text).split())
        if text not in warnings:
            warnings.append(text)
            print(f"{PROG}: warning: {text}", file=sys.stderr)

    for text in lscene.warnings:
        warn(text)
    artifacts = None
    if maps_path:
        try:
            artifacts = load_artifacts(maps_path, lscene, settings)
        except SceneError as exc:                  # ArtifactError: names the file and why
            raise UsageError(str(exc)) from None

    # 4. Render.
    progress = _Progress(enabled=not args.quiet)
    t0 = time.perf_counter()
    with _sigint_flag() as interrupted:
        try:
            result = pipeline.render(lscene, settings, progress=progress,
                                     cancelled=lambda: interrupted["set"], passes=args.passes,
                                     artifacts=artifacts)
        except SceneError as exc:
            raise UsageError(str(exc)) from None
        finally:
            progress.close()
    render_seconds = time.perf_counter() - t0
    for text in (result.report or {}).get("warnings", ()):
        warn(text)
    if result.cancelled or interrupted["set"]:
        print(f"{PROG}: cancelled; nothing written", file=sys.stderr)
        return EXIT_CANCELLED

    # 5. Write everything to temporary names, then rename all.
    image = _full_frame(result.image, lscene.camera, crop=bool(scene.render.use_crop_to_border))
    t0 = time.perf_counter()
    report = {
        "lanterna": _version(),
        "scene": loaded.source,
        "maps": maps_path,
        "blender_scene": scene.name,
        "resolution": list(resolution),
        "border": list(border) if border else None,
        "image_size": [int(image.shape[1]), int(image.shape[0])],
        "settings": _settings_dict(settings),
        "export": dict(lscene.stats),
        "warnings": warnings,
        "pipeline": result.report,
        "outputs": outputs,
        "time": {"load_seconds": load_seconds, "export_seconds": export_seconds,
                 "render_seconds": render_seconds},
    }
    with contextlib.ExitStack() as stack:
        exr_tmp = stack.enter_context(imageio.atomic_output(outputs["exr"]))
        layers = {name: _full_frame(result.passes[name], lscene.camera,
                                    crop=bool(scene.render.use_crop_to_border))
                  for name in args.passes if name in result.passes}
        imageio.write_exr(exr_tmp, image, extra_channels=layers,
                          attributes={"software": f"Lanterna {_version()}"})
        if "png" in outputs:
            png_tmp = stack.enter_context(imageio.atomic_output(outputs["png"]))
            if args.sensitivity is None:
                imageio.write_png(png_tmp, image)
            else:
                report["tonemap"] = _write_tone_png(png_tmp, image, args.sensitivity, args.knee)
        if "report" in outputs:
            report_tmp = stack.enter_context(imageio.atomic_output(outputs["report"]))
            report["time"]["write_seconds"] = time.perf_counter() - t0
            report["time"]["total_seconds"] = time.perf_counter() - started
            report.update(peak_memory().to_report())
            with open(report_tmp, "w", encoding="utf-8") as f:
                json.dump(_plain(report), f, indent=2, allow_nan=False)
                f.write("\n")
    total = time.perf_counter() - started
    h, w = image.shape[:2]
    print(f"{PROG}: wrote {outputs['exr']} ({w}x{h}, {settings.samples} spp) "
          f"in {total:.2f} s ({render_seconds:.2f} s rendering)")
    if "tonemap" in report:
        print(f"{PROG}: wrote {outputs['png']} with the seed's tone curve, sensitivity p2 = "
              f"{report['tonemap']['sensitivity']:.6g}, knee p1 = "
              f"{report['tonemap']['knee']:.6g} W m^-2 sr^-1")
    return EXIT_OK


def _dry_run(args, kind: str, path: str | None) -> int:
    """``render --dry-run``: export as a render would, print the plan and the estimate of each
    stage (``engine/estimate.py``), render and write nothing."""
    from ..scene import SceneError
    from .. import estimate

    loaded = _Loaded(args, kind, path)
    lscene, settings = loaded.lscene, loaded.settings
    try:
        result = estimate.estimate_cost(lscene, settings, passes=args.passes,
                                        reused=bool(args.maps))
    except (SceneError, estimate.RatesError) as exc:
        raise UsageError(str(exc)) from None
    for text in list(lscene.warnings) + list(result.warnings):
        print(f"{PROG}: warning: {' '.join(str(text).split())}", file=sys.stderr)
    w, h = lscene.camera.window_size
    print(f"{PROG}: dry run of {loaded.source}: {w}x{h} px, {settings.samples} spp, preset "
          f"{settings.preset}, {result.workers} workers; rates {result.rates_source}")
    print("plan:")
    for stage, reason in result.plan.items():
        print(f"  {stage:<20}{reason}")
    print(result.table())
    try:
        estimate.check_memory(result, result.available_bytes)
    except SceneError as exc:
        print(f"{PROG}: a render would be refused: {' '.join(str(exc).split())}")
    print(f"{PROG}: nothing rendered, nothing written")
    return EXIT_OK


def _plain(obj):
    """``obj`` as plain JSON data: numpy values converted, NaN and infinities as None."""
    import math

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    return str(obj)


def _settings_dict(settings) -> dict:
    import dataclasses

    return dataclasses.asdict(settings) if dataclasses.is_dataclass(settings) else dict(settings)


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("lanterna")
    except Exception:
        return "unknown"


def cmd_bake(args) -> int:
    """``lanterna bake``: every stage but the camera, saved as a maps file (``pipeline.bake``,
    ``artifacts.save_artifacts``), for ``lanterna render --maps`` or the add-on's Load."""
    kind, path = _scene_input(args)
    output = _check_output(args.output, ".npz", "-o")
    from ..scene import SceneError
    from .. import pipeline
    from ..artifacts import save_artifacts

    loaded = _Loaded(args, kind, path)
    for text in loaded.lscene.warnings:
        print(f"{PROG}: warning: {' '.join(str(text).split())}", file=sys.stderr)
    progress = _Progress(enabled=not args.quiet)
    t0 = time.perf_counter()
    with _sigint_flag() as interrupted:
        try:
            artifacts = pipeline.bake(loaded.lscene, loaded.settings, progress=progress,
                                      cancelled=lambda: interrupted["set"])
        except SceneError as exc:
            raise UsageError(str(exc)) from None
        finally:
            progress.close()
    if artifacts.report.get("cancelled") or interrupted["set"]:
        print(f"{PROG}: cancelled; nothing written", file=sys.stderr)
        return EXIT_CANCELLED
    try:
        save_artifacts(output, artifacts, scene_name=loaded.scene.name)
    except SceneError as exc:
        raise UsageError(str(exc)) from None
    counts = artifacts.counts()
    print(f"{PROG}: wrote {output} ({counts['photons']:,} photons, {counts['cache']:,} cache "
          f"records, {counts['shadow_photons']:,} shadow photons) in "
          f"{time.perf_counter() - t0:.2f} s")
    return EXIT_OK


def cmd_scene(args) -> int:
    path = _check_output(args.output, ".blend", "-o")
    from . import seed_scenes  # imports bpy

    _ensure_registered()
    seed_scenes.save(args.name, path)  # Blender writes to "path@" and renames: atomic
    print(f"{PROG}: wrote {path}")
    return EXIT_OK


def cmd_tonemap(args) -> int:
    from .. import imageio, tonemap  # no bpy

    _tone_parameters(args)
    output = _check_output(args.output, ".png", "OUT.png")
    try:
        image = tonemap.read_radiance(os.path.abspath(os.path.expanduser(args.input)),
                                      layer=args.layer)
    except tonemap.ToneMapError as exc:
        raise UsageError(str(exc)) from None
    with imageio.atomic_output(output) as tmp:
        used = _write_tone_png(tmp, image, args.sensitivity, args.knee)
    h, w = image.shape[:2]
    print(f"{PROG}: wrote {output} ({w}x{h}, sensitivity p2 = {used['sensitivity']:.6g}, "
          f"knee p1 = {used['knee']:.6g} W m^-2 sr^-1)")
    return EXIT_OK


BENCH_PACKAGE = __package__.rsplit(".", 2)[0] + ".bench"    # lanterna.bench: the checkout's


def cmd_bench(argv: list[str]) -> int:
    """``lanterna bench ...``: the benchmarks live outside the add-on, in the checkout's
    ``bench/`` folder (``lanterna.bench`` in a development install); they are found by name
    when present, so that nothing in the add-on depends on them."""
    import importlib
    import importlib.util

    if importlib.util.find_spec(BENCH_PACKAGE) is None:
        raise UsageError("the benchmarks are not part of an installed add-on: run "
                         "'lanterna bench' from a checkout of Lanterna (make render sets one up)")
    bench_main = importlib.import_module(BENCH_PACKAGE + ".main").main
    return int(bench_main(argv) or 0)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if argv and argv[0] == "bench":
            return cmd_bench(argv[1:])
        args = build_parser().parse_args(argv)
        if args.command in ("render", "bake"):
            kind, path = _scene_input(args)
            if kind == "blend" and STAGE_FILE_ENV not in os.environ:
                return _run_isolated(argv, path)
            return cmd_render(args) if args.command == "render" else cmd_bake(args)
        if args.command == "scene":
            return cmd_scene(args)
        if args.command == "tonemap":
            return cmd_tonemap(args)
        build_parser().print_help(sys.stderr)
        return EXIT_USAGE
    except UsageError as exc:
        message = " ".join(str(exc).split())
        print(f"{PROG}: error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help, or a module that calls sys.exit
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else EXIT_USAGE)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_CANCELLED
    except Exception as exc:  # a bug: say so in one line, the traceback only on request
        print(f"{PROG}: internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        if os.environ.get("LANTERNA_DEBUG"):
            import traceback

            traceback.print_exc()
        else:
            print(f"{PROG}: set LANTERNA_DEBUG=1 for the traceback", file=sys.stderr)
        return EXIT_INTERNAL


def run() -> None:
    """The ``lanterna`` command: ``main()``, then the exit (``compat.exit_process``: bpy 4.2 and
    4.5 as a module cannot exit normally once Lanterna is registered)."""
    from .compat import exit_process

    exit_process(main())


if __name__ == "__main__":
    run()
