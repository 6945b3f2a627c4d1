"""The ASE importer: ``engine/ase.py`` (parser, companion material file) and
``ops/import_ase.py`` (File > Import > ASCII Scene Export).

1. The hand-written sample ``tests/data/ase/room.ase`` + ``room.mat`` (a 4 x 4 x 3 m room: floor,
   walls, a box rotated 30 deg about Z, an emissive ceiling panel; three materials, a target
   camera, an omni and a directional light) parses into exactly the objects written in it.
   Coordinates are compared exactly (they are read, not computed) or, where they are computed
   from the file's 4-decimal rotation rows, within 2e-4 m.
2. Hand-made broken files: each raises :class:`AseError` whose message starts with
   ``path:line:`` at the line of the fault and names the object and what was expected.
3. Deterministic fuzzing from the sample: truncation at many byte offsets, every number
   replaced by a non-number, unknown keys inserted at every line, counts made huge or wrong,
   face indices out of range, and seeded random byte edits (hypothesis, derandomized). Each
   variant parses into the same result as the original (its change was in content that is
   skipped) or raises ``AseError`` with a line number; never another exception. Where the
   outcome is determined (a number under a key that is read), the test asserts which one and
   the line.
4. Blender: the operator creates the right objects, meshes, materials and lights in a new
   collection; a broken file leaves ``bpy.data`` unchanged; a failure midway is rolled back.
"""
from __future__ import annotations

import math
import os
import re
import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from lanterna.engine import ase
from lanterna.engine.ase import AseError

DATA = os.path.join(os.path.dirname(__file__), "data", "ase")
ROOM = os.path.join(DATA, "room.ase")
ROOM_MAT = os.path.join(DATA, "room.mat")
with open(ROOM, encoding="utf-8") as _fh:
    ROOM_TEXT = _fh.read()
with open(ROOM_MAT, encoding="utf-8") as _fh:
    MAT_TEXT = _fh.read()

ERROR_PREFIX = re.compile(r"^(?P<path>.*?):(?P<line>\d+): \S")


# -- Helpers ----------------------------------------------------------------------------------
def line_of(text: str, needle: str, start_line: int = 1) -> int:
    """1-based number of the first line at or after ``start_line`` containing ``needle``."""
    for number, line in enumerate(text.split("\n"), 1):
        if number >= start_line and needle in line:
            return number
    raise AssertionError(f"{needle!r} not in the text")


def replace_on_line(text: str, line: int, old: str, new: str) -> str:
    lines = text.split("\n")
    assert old in lines[line - 1], (old, lines[line - 1])
    lines[line - 1] = lines[line - 1].replace(old, new, 1)
    return "\n".join(lines)


def _tm(tm):
    return None if tm is None else (None if tm.rows is None else tm.rows.tobytes(),
                                    tm.translation.tobytes())


def _mat(m):
    return (m.name, None if m.diffuse is None else tuple(m.diffuse),
            tuple(_mat(s) for s in m.submaterials))


def canon(f: ase.AseFile):
    """Everything a parse yields except line numbers (insertions shift them)."""
    return (f.version, tuple(_mat(m) for m in f.materials),
            tuple((g.name, _tm(g.tm), g.vertices.tobytes(), g.faces.tobytes(),
                   g.mtlids.tobytes(), g.material_ref) for g in f.geoms),
            tuple((c.name, _tm(c.tm), _tm(c.target), c.fov) for c in f.cameras),
            tuple((x.name, x.type, _tm(x.tm), _tm(x.target), tuple(x.color), x.intensity,
                   x.hotspot, x.falloff, x.enabled) for x in f.lights))


ROOM_CANON = canon(ase.parse_ase(ROOM_TEXT, ROOM))


def outcome(text: str, path: str = ROOM):
    """("ok", canon) or ("error", line, message); any exception but AseError fails the test,
    and so does an AseError without ``path:line:`` or with a line outside the text."""
    try:
        return ("ok", canon(ase.parse_ase(text, path)))
    except AseError as exc:
        message = str(exc)
        m = ERROR_PREFIX.match(message)
        assert m and m["path"] == path, message
        line = int(m["line"])
        n_lines = text.replace("\r\n", "\n").replace("\r", "\n").count("\n") + 1
        assert 1 <= line <= n_lines, message
        return ("error", line, message)


def mat_outcome(text: str, path: str = ROOM_MAT):
    try:
        c = ase.parse_companion(text, path)
        return ("ok", (c.unit, {k: (v.diffuse.tolist(), v.specular.tolist(), v.exitance.tolist())
                                for k, v in c.materials.items()},
                       {k: v[0] for k, v in c.light_power.items()}))
    except AseError as exc:
        m = ERROR_PREFIX.match(str(exc))
        assert m and m["path"] == path, str(exc)
        return ("error", int(m["line"]), str(exc))


def assert_error(text: str, line: int, *fragments: str, path: str = ROOM):
    result = outcome(text, path)
    assert result[0] == "error", f"expected an error at line {line}, the file parsed"
    assert result[1] == line, result[2]
    for fragment in fragments:
        assert fragment in result[2], (fragment, result[2])
    return result[2]


# =============================================================================================
# 1. The sample
# =============================================================================================
def test_room_parses_into_the_written_objects():
    f = ase.parse_ase(ROOM_TEXT, ROOM)
    assert f.version == 200
    assert [m.name for m in f.materials] == ["White", "Green", "Lamp"]
    assert f.materials[1].diffuse.tolist() == [0.1, 0.6, 0.1]
    assert [g.name for g in f.geoms] == ["Floor", "Walls", "Box01", "Lamp"]
    assert [len(g.vertices) for g in f.geoms] == [4, 8, 8, 4]
    assert [len(g.faces) for g in f.geoms] == [2, 10, 12, 2]
    assert [g.material_ref for g in f.geoms] == [1, 0, 0, 2]
    floor, walls, box, lamp = f.geoms
    assert floor.vertices.tolist() == [[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]
    assert floor.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert walls.faces[8].tolist() == [4, 5, 6] and walls.vertices[6].tolist() == [2, 2, 3]
    assert box.vertices[5].tolist() == [1.483, 0.417, 1.0]
    assert box.mtlids.tolist() == [1, 1, 0, 0, 4, 4, 3, 3, 5, 5, 2, 2]
    assert box.tm.rows.tolist() == [[0.866, 0.5, 0], [-0.5, 0.866, 0], [0, 0, 1]]
    assert box.tm.translation.tolist() == [0.8, 0.6, 0.5]
    assert lamp.vertices[:, 2].tolist() == [2.98] * 4

    (camera,) = f.cameras
    assert camera.name == "Camera01" and camera.fov == 1.0
    assert camera.tm.translation.tolist() == [0, -1.9, 1.4]
    assert camera.target.translation.tolist() == [0, 2, 1]

    omni, sun = f.lights
    assert (omni.name, omni.type, sun.name, sun.type) == ("Omni01", "Omni", "Direct01",
                                                          "Directional")
    assert omni.tm.translation.tolist() == [0.5, 0, 2.6]
    assert omni.color.tolist() == [1, 0.95, 0.9] and omni.intensity == 1.0
    assert sun.intensity == 0.5 and sun.enabled and omni.enabled


def test_room_loads_with_its_companion_file():
    s = ase.load(ROOM)
    assert s.material_path == ROOM_MAT and s.unit == 1.0 and s.warnings == []
    mats = {m.name: m for m in s.materials}
    assert [m.name for m in s.materials] == ["Green", "White", "Lamp"]      # first use
    assert mats["White"].diffuse.tolist() == [0.8] * 3
    assert mats["White"].specular.tolist() == [0] * 3
    assert mats["Green"].diffuse.tolist() == [0.1, 0.6, 0.1]
    assert mats["Green"].specular.tolist() == [0.2] * 3
    assert mats["Lamp"].exitance.tolist() == [30, 30, 24]
    assert mats["Lamp"].diffuse.tolist() == [0.5] * 3
    assert mats["Lamp"].source == "room.mat line 8"

    meshes = {m.name: m for m in s.meshes}
    assert [m.slots for m in s.meshes] == [["Green"], ["White"], ["White"], ["Lamp"]]
    for m in s.meshes:
        # World positions are the file's; the object matrix maps the local ones onto them.
        back = m.local_vertices @ m.matrix[:3, :3].T + m.matrix[:3, 3]
        np.testing.assert_allclose(back, m.vertices, atol=1e-12)
        assert m.face_slots.tolist() == [0] * len(m.faces)
    box = meshes["Box01"]
    # The file's rows are cos/sin 30 deg rounded to 4 decimals: local corners within 2e-4.
    np.testing.assert_allclose(np.abs(box.local_vertices), 0.5, atol=2e-4)
    np.testing.assert_allclose(box.matrix[:3, 0], [0.866, 0.5, 0])           # ROW0 = local X
    assert meshes["Walls"].local_vertices[:, 2].tolist() == [-1.5] * 4 + [1.5] * 4

    (camera,) = s.cameras
    assert camera.fov == 1.0
    forward = -camera.matrix[:3, 2]
    to_target = np.array([0, 3.9, -0.4]) / np.linalg.norm([0, 3.9, -0.4])
    np.testing.assert_allclose(forward / np.linalg.norm(forward), to_target, atol=2e-4)

    omni, sun = s.lights
    assert (omni.kind, omni.power, omni.power_source) == ("POINT", 60.0, "room.mat line 9")
    assert omni.matrix[:3, 3].tolist() == [0.5, 0, 2.6]
    assert sun.kind == "SUN"
    assert sun.power == pytest.approx(0.5 * math.pi, rel=1e-15)   # *LIGHT_INTENS 0.5 x pi
    np.testing.assert_allclose(-sun.matrix[:3, 2], [0, 0.342, -0.9397], atol=1e-12)


def test_fast_line_path_equals_the_token_path(monkeypatch):
    """Vertex and face lines read whole (the fast path) give what the tokens give."""
    variants = (ROOM_TEXT.replace("A:    0 B:", "A:0 B:")
                .replace("*MESH_FACE    1:", "*MESH_FACE 1 :"))
    fast = [canon(ase.parse_ase(t)) for t in (ROOM_TEXT, variants)]
    never = re.compile(r"(?!)")
    monkeypatch.setattr(ase, "_VERTEX_LINE", never)
    monkeypatch.setattr(ase, "_FACE_LINE", never)
    slow = [canon(ase.parse_ase(t)) for t in (ROOM_TEXT, variants)]
    assert fast == slow
    assert fast[0] == fast[1] == ROOM_CANON


MULTI = """*3DSMAX_ASCIIEXPORT 200
*MATERIAL_LIST {
  *MATERIAL_COUNT 1
  *MATERIAL 0 {
    *MATERIAL_NAME "Multi"
    *MATERIAL_CLASS "Multi/Sub-Object"
    *NUMSUBMTLS 2
    *SUBMATERIAL 0 { *MATERIAL_NAME "Red" *MATERIAL_DIFFUSE 0.7 0.1 0.1 }
    *SUBMATERIAL 1 { *MATERIAL_NAME "Blue" }
  }
}
*GROUP "Furniture" {
  *GEOMOBJECT {
    *NODE_NAME "Strip"
    *NODE_TM { *TM_POS 1 2 3 }
    *MESH {
      *MESH_NUMVERTEX 5
      *MESH_NUMFACES 3
      *MESH_VERTEX_LIST {
        *MESH_VERTEX 0 0 0 0
        *MESH_VERTEX 2 1 1 0
        *MESH_VERTEX 1 1 0 0
        *MESH_VERTEX 3 2 0 0
        *MESH_VERTEX 4 2 1 0
      }
      *MESH_FACE_LIST {
        *MESH_FACE 0: A:0 B:1 C:2 *MESH_MTLID 3
        *MESH_FACE 2 : a: 2 b: 3 c: 4
        *MESH_MTLID 2
        *MESH_FACE 1: A: 1 B: 3 C: 2 AB: 1 *MESH_SMOOTHING *MESH_MTLID 0
      }
    }
    *MATERIAL_REF 0
  }
}
"""


def test_submaterials_groups_and_face_spellings(tmp_path):
    path = tmp_path / "multi.ase"
    path.write_text(MULTI)
    s = ase.load(str(path))                  # no companion file: ASE diffuse, with warnings
    (m,) = s.meshes
    assert m.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 0, 0], [2, 1, 0]]
    assert m.faces.tolist() == [[0, 1, 2], [1, 3, 2], [2, 3, 4]]
    # MTLIDs 3, 0, 2 -> submaterial 3 mod 2 = Blue, Red, Red; slots in first-use order.
    assert m.slots == ["Red", "Blue"] and m.face_slots.tolist() == [1, 0, 0]
    assert m.matrix[:3, 3].tolist() == [1, 2, 3] and m.matrix[:3, :3].tolist() == np.eye(3).tolist()
    red, blue = (next(x for x in s.materials if x.name == n) for n in ("Red", "Blue"))
    assert red.diffuse.tolist() == [0.7, 0.1, 0.1] and red.exitance.tolist() == [0, 0, 0]
    assert blue.diffuse.tolist() == [ase.DEFAULT_DIFFUSE] * 3
    assert len(s.warnings) == 1 and "no companion material file multi.mat" in s.warnings[0]


TARGETS = """*3DSMAX_ASCIIEXPORT 200
*CAMERAOBJECT {
  *NODE_NAME "Cam"
  *NODE_TM { *TM_POS 0 -5 1 }
  *NODE_TM { *NODE_NAME "Cam.Target" *TM_POS 0 0 1 }
}
*LIGHTOBJECT {
  *NODE_NAME "Spot"
  *LIGHT_TYPE Target
  *NODE_TM { *TM_POS 3 0 4 }
  *NODE_TM { *TM_POS 3 0 0 }
  *LIGHT_USELIGHT 0
  *LIGHT_SETTINGS { *LIGHT_COLOR 1 0.5 0 *LIGHT_INTENS 2 *LIGHT_HOTSPOT 30 *LIGHT_FALLOFF 60 }
}
"""


def test_targets_without_rows_look_at_the_target(tmp_path):
    (tmp_path / "t.ase").write_text(TARGETS)
    (tmp_path / "t.mat").write_text("unit 0.5\nend\n")
    s = ase.load(str(tmp_path / "t.ase"))
    (cam,), (spot,) = s.cameras, s.lights
    assert cam.fov == ase.DEFAULT_FOV
    np.testing.assert_allclose(cam.matrix[:3, 3], [0, -2.5, 0.5])          # unit 0.5 m
    np.testing.assert_allclose(-cam.matrix[:3, 2], [0, 1, 0], atol=1e-15)  # looks along +Y
    np.testing.assert_allclose(cam.matrix[:3, 1], [0, 0, 1], atol=1e-15)   # up is +Z
    assert np.linalg.det(cam.matrix[:3, :3]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(-spot.matrix[:3, 2], [0, 0, -1], atol=1e-15)  # straight down
    assert spot.kind == "SPOT" and spot.color.tolist() == [1, 0.5, 0]
    assert spot.power == pytest.approx(2 * 4 * math.pi ** 2, rel=1e-15)
    assert spot.spot_size == pytest.approx(math.radians(60), rel=1e-15)
    assert spot.spot_blend == pytest.approx(0.5, rel=1e-15)
    assert not spot.enabled and any("switched off" in w for w in s.warnings)


def test_unit_scales_positions_and_keeps_object_space_consistent(tmp_path):
    (tmp_path / "room.ase").write_text(ROOM_TEXT)
    (tmp_path / "room.mat").write_text(MAT_TEXT.replace("unit 1.0", "unit 0.01"))
    s = ase.load(str(tmp_path / "room.ase"))
    ref = ase.load(ROOM)
    for a, b in zip(s.meshes, ref.meshes):
        np.testing.assert_allclose(a.vertices, 0.01 * b.vertices, rtol=1e-15)
        np.testing.assert_allclose(a.local_vertices, 0.01 * b.local_vertices, atol=1e-15)
        np.testing.assert_allclose(a.matrix[:3, :3], b.matrix[:3, :3], rtol=0)
    assert s.lights[0].matrix[:3, 3].tolist() == pytest.approx([0.005, 0, 0.026])


def test_core_reader_does_not_import_bpy():
    import subprocess
    import sys
    code = ("import sys; from lanterna.engine import ase; "
            "s = ase.load(sys.argv[1]); print(len(s.meshes), 'bpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, ROOM], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["4", "False"]


# =============================================================================================
# 2. Hand-made broken files: line and message
# =============================================================================================
def _floor(needle):
    return line_of(ROOM_TEXT, needle, line_of(ROOM_TEXT, '*NODE_NAME "Floor"'))


def _walls(needle):
    return line_of(ROOM_TEXT, needle, line_of(ROOM_TEXT, '*NODE_NAME "Walls"'))


def _box(needle):
    return line_of(ROOM_TEXT, needle, line_of(ROOM_TEXT, '*NODE_NAME "Box01"'))


def test_count_disagreeing_with_the_list():
    n = _floor("*MESH_NUMVERTEX 4")
    text = replace_on_line(ROOM_TEXT, n, "*MESH_NUMVERTEX 4", "*MESH_NUMVERTEX 5")
    assert_error(text, _floor("*MESH_VERTEX_LIST {"), "GEOMOBJECT 'Floor'",
                 f"*MESH_NUMVERTEX is 5 (line {n})", "lists 4 vertices", "no *MESH_VERTEX 4")
    # One face fewer than listed: the second face's number is out of range.
    text = replace_on_line(ROOM_TEXT, _floor("*MESH_NUMFACES 2"), "2", "1")
    assert_error(text, _floor("*MESH_FACE    1:"), "GEOMOBJECT 'Floor'",
                 "found 1 (*MESH_NUMFACES is 1)")


def test_face_index_out_of_range_negative_and_repeated():
    line = _floor("*MESH_FACE    0:")
    assert_error(replace_on_line(ROOM_TEXT, line, "C:    2", "C:    4"), line,
                 "GEOMOBJECT 'Floor'", "integer 0..3", "corner C of *MESH_FACE 0", "found 4")
    assert_error(replace_on_line(ROOM_TEXT, line, "A:    0", "A:    -1"), line, "found -1")
    line1 = _floor("*MESH_FACE    1:")
    assert_error(replace_on_line(ROOM_TEXT, line1, "*MESH_FACE    1:", "*MESH_FACE    0:"),
                 line1, "*MESH_FACE 0 appears twice (first at line " + str(line) + ")")
    v5 = _walls("*MESH_VERTEX    5")
    assert_error(replace_on_line(ROOM_TEXT, v5, "*MESH_VERTEX    5", "*MESH_VERTEX    4"), v5,
                 "GEOMOBJECT 'Walls'", "*MESH_VERTEX 4 appears twice")


@pytest.mark.parametrize("bad, fragment", [
    ("nan", "(not finite)"), ("-inf", "(not finite)"), ("1.#QNAN0", "(not finite)"),
    ("1e999", "magnitude at most 1e+30"), ("abc", "expected a number"),
])
def test_non_numbers_and_non_finite_numbers(bad, fragment):
    line = _walls("*MESH_VERTEX    5")
    text = replace_on_line(ROOM_TEXT, line, "2.0000", bad)
    message = assert_error(text, line, "GEOMOBJECT 'Walls'", fragment, f"found '{bad}'",
                           "*MESH_VERTEX 5 x y z, value 1 of 3")
    assert message.startswith(f"{ROOM}:{line}: in GEOMOBJECT 'Walls': expected ")


@pytest.mark.parametrize("key, what", [("*MESH_NUMVERTEX 8", "vertices"),
                                       ("*MESH_NUMFACES 12", "faces")])
@pytest.mark.parametrize("count", [10 ** 6, 10 ** 8, 10 ** 12, 10 ** 40])
def test_huge_counts_are_refused_before_allocating(key, what, count):
    line = _box(key)
    text = replace_on_line(ROOM_TEXT, line, key.split()[1], str(count))
    tracemalloc.start()
    try:
        message = assert_error(text, line, "GEOMOBJECT 'Box01'", str(count))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 4_000_000, peak                      # nothing of the count's size
    if count > ase.MAX_COUNT:
        assert f"exceeds the limit of 50,000,000 {what}" in message
    else:
        assert f"more {what} than a file of" in message


@pytest.mark.parametrize("old, new, start, needle, fragments", [
    # The error's line: the first line holding ``needle`` at or after the line holding
    # ``start`` (None: the file's start), in the edited text.
    ("*MATERIAL_REF 2", "*MATERIAL_REF 7", None, "*MATERIAL_REF 7",
     ("GEOMOBJECT 'Lamp'", "*MATERIAL_REF 7 names no material", "holds 3")),
    ("*LIGHT_TYPE Omni", "*LIGHT_TYPE Sky", None, "*LIGHT_TYPE Sky",
     ("LIGHTOBJECT 'Omni01'", "expected a light type", "found 'Sky'")),
    ("*CAMERA_FOV 1.0000", "*CAMERA_FOV 45.0", None, "*CAMERA_FOV",
     ("CAMERAOBJECT 'Camera01'", "outside 0.0065..3.0 rad")),
    ("*LIGHT_INTENS 0.5000", "*LIGHT_INTENS -2", None, "*LIGHT_INTENS -2",
     ("LIGHTOBJECT 'Direct01'", "darklights")),
    ('*NODE_NAME "Lamp"\n\t*NODE_TM', '*NODE_NAME "Lamp\n\t*NODE_TM', None, '*NODE_NAME "Lamp',
     ("expected a closing '\"'",)),
    ("*TIMEVALUE 0\n\t\t*MESH_NUMVERTEX 4\n", "*TIMEVALUE 0\n\t\t*MESH_NUMVERTEX 4 5\n",
     None, "*MESH_NUMVERTEX 4 5",
     ("GEOMOBJECT 'Floor'", "expected a *KEY or '}' after the value of *MESH_NUMVERTEX",
      "found '5'")),
    ('\t*NODE_TM {\n\t\t*NODE_NAME "Walls"', '\t*NODE_NAME "W2"\n\t*NODE_TM {\n\t\t'
     '*NODE_NAME "Walls"', None, '*NODE_NAME "W2"',
     ("GEOMOBJECT 'Walls'", "*NODE_NAME appears twice (first at line")),
    ("\t\t*TM_ROW1 -0.5000\t0.8660\t0.0000\n", "", '*NODE_NAME "Box01"', "*NODE_TM {",
     ("GEOMOBJECT 'Box01'", "expected *TM_ROW1 in *NODE_TM")),
    ("*MATERIAL_COUNT 3", "*MATERIAL_COUNT 4", None, "*MATERIAL_LIST {",
     ("*MATERIAL_COUNT is 4", "holds 3 *MATERIAL blocks (no *MATERIAL 3)")),
    ("*MATERIAL 2 {", "*MATERIAL 1 {", '*MATERIAL_NAME "Green"', "*MATERIAL 1 {",
     ("*MATERIAL 1 appears twice",)),
    ("\t*MESH {\n\t\t*MESH_NUMVERTEX 4\n", "\t*MESH {\n", '*NODE_NAME "Lamp"',
     "*MESH_VERTEX_LIST {",
     ("GEOMOBJECT 'Lamp'", "expected *MESH_NUMVERTEX before *MESH_VERTEX_LIST")),
    ("*3DSMAX_ASCIIEXPORT\t200\n", "", None, "*COMMENT",
     ("expected *3DSMAX_ASCIIEXPORT at the start of an ASE file", "found key *COMMENT")),
    ("*LIGHT_FALLOFF 1.2000", "*LIGHT_FALLOFF 1.2000\n*LIGHT_FALLOFF 3", None,
     "*LIGHT_FALLOFF 3", ("LIGHTOBJECT 'Direct01'", "*LIGHT_FALLOFF appears twice")),
])
def test_broken_files_name_line_object_and_expectation(old, new, start, needle, fragments):
    assert ROOM_TEXT.count(old) == 1, old
    text = ROOM_TEXT.replace(old, new)
    line = line_of(text, needle, line_of(text, start) if start else 1)
    assert_error(text, line, *fragments)


def test_line_ends_and_deep_nesting():
    """CRLF and CR files read like LF files, with the same line numbers in errors; nesting
    beyond MAX_NESTING is an AseError, not a RecursionError."""
    for newline in ("\r\n", "\r"):
        assert outcome(ROOM_TEXT.replace("\n", newline)) == ("ok", ROOM_CANON)
        broken = ROOM_TEXT.replace("*CAMERA_FOV 1.0000", "*CAMERA_FOV x").replace("\n", newline)
        assert outcome(broken)[1] == line_of(ROOM_TEXT, "*CAMERA_FOV")
    mat = ase.parse_companion(MAT_TEXT.replace("\n", "\r"), "m.mat")
    assert mat.materials["Lamp"].line == 8
    depth = 5000
    text = ("*3DSMAX_ASCIIEXPORT 200\n" + '*GROUP "g" {\n' * depth
            + ROOM_TEXT[ROOM_TEXT.index("*LIGHTOBJECT"):] + "}\n" * depth)
    assert_error(text, 2 + ase.MAX_NESTING, "*GROUP blocks nested more than 32 deep")
    shallow = ("*3DSMAX_ASCIIEXPORT 200\n" + '*GROUP "g" {\n' * 3
               + ROOM_TEXT[ROOM_TEXT.index("*LIGHTOBJECT"):] + "}\n" * 3)
    assert [x.name for x in ase.parse_ase(shallow).lights] == ["Omni01", "Direct01"]


def test_truncated_and_unbalanced_files():
    end = ROOM_TEXT.rstrip()
    assert end.endswith("}")
    text = end[:-1]                                        # the last closing brace is gone
    opened = line_of(ROOM_TEXT, '*NODE_NAME "Direct01"') - 1
    assert_error(text, text.count("\n") + 1,
                 f"expected '}}' closing the *LIGHTOBJECT block opened at line {opened}, "
                 f"found end of file (truncated file?)")
    assert_error(ROOM_TEXT + "}\n", ROOM_TEXT.count("\n") + 1, "no block open")
    cut = ROOM_TEXT.index("*MAP_DIFFUSE {") + len("*MAP_DIFFUSE {")
    assert_error(ROOM_TEXT[:cut], line_of(ROOM_TEXT, "*MAP_DIFFUSE {"),
                 "closing the block of *MAP_DIFFUSE", "skipped as unknown")
    header_only = ROOM_TEXT[:ROOM_TEXT.index("*GEOMOBJECT")]
    assert_error(header_only, header_only.count("\n") + 1, "nothing to import")


# -- The companion file ------------------------------------------------------------------------
def test_companion_format():
    c = ase.parse_companion(
        '# comment\n\nunit 0.25   # metres per unit\n'
        'material "A#1"   exitance 1 2 3 diffuse 0.5   # "quoted" comment\n'
        'material "B"\r\nlight "L" power 7.5\nend\n# trailing comment\n', "x.mat")
    assert c.unit == 0.25 and c.unit_line == 3
    a, b = c.materials["A#1"], c.materials["B"]
    assert a.diffuse.tolist() == [0.5] * 3 and a.exitance.tolist() == [1, 2, 3]
    assert a.specular.tolist() == [0, 0, 0] and a.line == 4
    assert b.diffuse.tolist() == [0, 0, 0]                # fields left out are 0
    assert c.light_power == {"L": (7.5, 6)} and c.warnings == []
    warn = ase.parse_companion('material "M" diffuse 0.7 specular 0.5\nend', "w.mat")
    assert len(warn.warnings) == 1
    assert warn.warnings[0].startswith('w.mat:1: material "M": diffuse + specular reflectance')
    assert warn.materials["M"].diffuse.tolist() == [0.7] * 3           # kept as written


@pytest.mark.parametrize("text, line, fragment", [
    ('material "A" diffuse 0.5 0.5\nend\n', 1, "expected 1 (grey) or 3 (R G B) numbers"),
    ('material "A" diffuse 1.5\nend\n', 1, "above 1"),
    ('material "A" specular -0.1\nend\n', 1, "is negative"),
    ('material "A" exitance nan\nend\n', 1, "expected a finite number (exitance of material"),
    ('material "A" exitance 2e9\nend\n', 1, "above 1e+09"),
    ('material "A" diffuse 0.5 shine 3\nend\n', 1,
     "expected a number (diffuse) or 'diffuse', 'specular' or 'exitance', found 'shine'"),
    ('material "A" shine 3\nend\n', 1, "expected 'diffuse', 'specular' or 'exitance'"),
    ('material "A" diffuse 0.5# no space\nend\n', 1, "found '0.5#'"),
    ('material "A" diffuse 0.5 diffuse 0.4\nend\n', 1, "'diffuse' appears twice"),
    ('material "A"\n\nmaterial "A"\nend\n', 3, 'material "A" appears twice (first at line 1)'),
    ('material A diffuse 0.5\nend\n', 1, "expected a quoted name after 'material'"),
    ('material "" diffuse 0.5\nend\n', 1, "non-empty material name"),
    ('material "A diffuse 0.5\nend\n', 1, "expected a closing '\"'"),
    ('colour "A" 1\nend\n', 1, "expected 'material', 'light', 'unit' or 'end'"),
    ('light "L" watts 3\nend\n', 1, "expected 'power'"),
    ('light "L" power -3\nend\n', 1, "is negative"),
    ('unit 0\nend\n', 1, "expected a unit in (0, 1e+06]"),
    ('unit 1\nunit 2\nend\n', 2, "'unit' appears twice"),
    ('material "A" diffuse 0.5\n', 2, "expected 'end' as the last statement"),
    ('end\nmaterial "A"\n', 2, "expected nothing after 'end' (line 1)"),
])
def test_companion_errors(text, line, fragment):
    result = mat_outcome(text, "c.mat")
    assert result[0] == "error" and result[1] == line, result
    assert fragment in result[2], result[2]


def test_missing_and_unused_companion_entries(tmp_path):
    (tmp_path / "room.ase").write_text(ROOM_TEXT)
    (tmp_path / "room.mat").write_text(
        'material "White" diffuse 0.5\nmaterial "Ghost" diffuse 0.1\nlight "Nobody" power 1\n'
        'end\n')
    s = ase.load(str(tmp_path / "room.ase"))
    mats = {m.name: m for m in s.materials}
    assert mats["White"].diffuse.tolist() == [0.5] * 3
    assert mats["Green"].diffuse.tolist() == [0.1, 0.6, 0.1]     # from *MATERIAL_DIFFUSE
    assert mats["Green"].specular.tolist() == [0, 0, 0]
    text = "\n".join(s.warnings)
    assert 'no entry for material "Green"' in text and 'no entry for material "Lamp"' in text
    assert 'room.mat:2: material "Ghost" names no material' in text
    assert 'room.mat:3: light "Nobody" names no LIGHTOBJECT' in text
    assert s.lights[0].power == pytest.approx(4 * math.pi ** 2)   # *LIGHT_INTENS 1


def test_unreadable_file_is_an_ase_error(tmp_path):
    with pytest.raises(AseError, match="cannot read the file"):
        ase.load(str(tmp_path / "missing.ase"))
    (tmp_path / "a.ase").write_text(TARGETS)
    with pytest.raises(AseError, match="cannot read the file"):
        ase.load(str(tmp_path / "a.ase"), str(tmp_path / "missing.mat"))


# =============================================================================================
# 3. Fuzzing from the sample (deterministic)
# =============================================================================================
READ_KEYS = {
    "*3DSMAX_ASCIIEXPORT", "*MATERIAL_COUNT", "*MATERIAL", "*MATERIAL_DIFFUSE", "*NUMSUBMTLS",
    "*SUBMATERIAL", "*TM_ROW0", "*TM_ROW1", "*TM_ROW2", "*TM_ROW3", "*TM_POS",
    "*MESH_NUMVERTEX", "*MESH_NUMFACES", "*MESH_VERTEX", "*MESH_FACE", "*MESH_MTLID",
    "*MATERIAL_REF", "*CAMERA_FOV", "*LIGHT_COLOR", "*LIGHT_INTENS", "*LIGHT_HOTSPOT",
    "*LIGHT_FALLOFF", "*LIGHT_USELIGHT",
}
NUMBER = re.compile(r"(?<!\S)[-+]?\d+(?:\.\d+)?(?=[\s:]|$)")
NOT_NUMBERS = ("abc", "nan", "1e999", "1.#QNAN0", "-inf", "3x", "0x10")


def _number_sites(text: str):
    """(offset, end, key, line) of every number outside quotes; key: the *KEY it belongs to."""
    sites = []
    for m in NUMBER.finditer(text):
        line_start = text.rfind("\n", 0, m.start()) + 1
        before = text[line_start:m.start()]
        if before.count('"') % 2:
            continue                                   # inside a string
        keys = re.findall(r"\*[A-Za-z0-9_]+", before)
        sites.append((m.start(), m.end(), keys[-1] if keys else None,
                      text.count("\n", 0, m.start()) + 1))
    return sites


def test_fuzz_every_number_replaced_by_a_non_number():
    sites = _number_sites(ROOM_TEXT)
    assert len(sites) > 500
    read = skipped = 0
    for k, (start, end, key, line) in enumerate(sites):
        bad = NOT_NUMBERS[k % len(NOT_NUMBERS)]
        result = outcome(ROOM_TEXT[:start] + bad + ROOM_TEXT[end:])
        if key in READ_KEYS:
            assert result[0] == "error" and result[1] == line, (key, line, result)
            assert "expected" in result[2] and f"found '{bad}" in result[2], result[2]
            read += 1
        else:                                          # values of skipped keys
            assert result == ("ok", ROOM_CANON), (key, line, result)
            skipped += 1
    assert read > 350 and skipped > 80, (read, skipped)


def _object_ends(text: str):
    """Offsets where a top-level object block ends, and how far whitespace runs after it."""
    out = []
    for m in re.finditer(r"^\*(GEOMOBJECT|CAMERAOBJECT|LIGHTOBJECT) \{$", text, re.M):
        close = text.index("\n}", m.end()) + 2
        after = close
        while after < len(text) and text[after].isspace():
            after += 1
        out.append((close, after))
    return out


def test_fuzz_truncation():
    ends = _object_ends(ROOM_TEXT)
    assert len(ends) == 7
    full = ase.parse_ase(ROOM_TEXT)
    expected_ok = {k for close, after in ends for k in range(close, after + 1)}
    offsets = set(range(0, len(ROOM_TEXT), 11))
    offsets |= {m.start() for m in re.finditer("\n", ROOM_TEXT)}
    offsets |= {min(m.start() + 2, len(ROOM_TEXT)) for m in re.finditer("\n", ROOM_TEXT)}
    offsets |= expected_ok
    ok = set()
    for k in sorted(offsets):
        result = outcome(ROOM_TEXT[:k])
        if result[0] == "ok":
            ok.add(k)
            # A cut right after a complete object is a valid, smaller file: the first objects.
            f = ase.parse_ase(ROOM_TEXT[:k])
            n_objects = len(f.geoms) + len(f.cameras) + len(f.lights)
            assert result[1][:2] == ROOM_CANON[:2]
            for part in (2, 3, 4):
                assert result[1][part] == ROOM_CANON[part][:len(result[1][part])]
            assert n_objects == sum(close <= k for close, _ in ends)
    assert ok == expected_ok & offsets
    assert len(offsets) > 900 and len(ok) < 25
    assert len(full.geoms) == 4


UNKNOWN = (
    '*LANTERNA_FUZZ_KEY 1 2.5 "text with } and { inside" word',
    '*LANTERNA_FUZZ_BLOCK "x" {\n*NESTED 1 2 3\n*DEEPER {\n*MESH_VERTEX 0 9 9 9\n}\n}',
    '*LANTERNA_FUZZ_FLAG',
    '*MESH_SMOOTHING 1,2,3',
)


def test_fuzz_unknown_keys_are_skipped_everywhere():
    lines = ROOM_TEXT.split("\n")
    for i in range(len(lines) + 1):
        extra = UNKNOWN[i % len(UNKNOWN)]
        result = outcome("\n".join(lines[:i] + [extra] + lines[i:]))
        if i == 0:                                     # before the header: not an ASE file
            assert result[0] == "error" and result[1] == 1
            assert "expected *3DSMAX_ASCIIEXPORT" in result[2]
        elif i >= len(lines) - 1 and not extra.endswith("}"):
            # After the last block: the file no longer ends with '}' (as if truncated).
            assert result[0] == "error" and result[1] == i + 1, result
            assert "expected the file to end with the '}' of its last block" in result[2]
        else:
            assert result == ("ok", ROOM_CANON), (i, extra, result)


def test_fuzz_wrong_counts_and_face_indices():
    """Every count off by one and every face corner just out of range is an error naming the
    object; every count made huge is refused at its own line."""
    object_names = ("Floor", "Walls", "Box01", "Lamp")
    for m in re.finditer(r"\*(MESH_NUMVERTEX|MESH_NUMFACES|MATERIAL_COUNT) (\d+)", ROOM_TEXT):
        line = ROOM_TEXT.count("\n", 0, m.start()) + 1
        for value in (int(m[2]) - 1, int(m[2]) + 1, 10 ** 7, 10 ** 18):
            text = ROOM_TEXT[:m.start(2)] + str(value) + ROOM_TEXT[m.end(2):]
            result = outcome(text)
            assert result[0] == "error", (m.group(), value)
            if m[1] != "MATERIAL_COUNT":
                assert any(f"GEOMOBJECT '{n}'" in result[2] for n in object_names), result
            if value >= 10 ** 7:
                assert result[1] == line and str(value) in result[2], result
    counts = 0
    for m in re.finditer(r"(?<![A-Z])([ABC]):\s+(\d+)", ROOM_TEXT):
        line = ROOM_TEXT.count("\n", 0, m.start()) + 1
        owner = [n for n in object_names
                 if ROOM_TEXT.rfind(f'*NODE_NAME "{n}"', 0, m.start()) >= 0][-1]
        nv = {"Floor": 4, "Walls": 8, "Box01": 8, "Lamp": 4}[owner]
        text = ROOM_TEXT[:m.start(2)] + str(nv) + ROOM_TEXT[m.end(2):]
        result = outcome(text)
        assert result[0] == "error" and result[1] == line, result
        assert f"GEOMOBJECT '{owner}'" in result[2] and f"0..{nv - 1}" in result[2], result
        counts += 1
    assert counts == 3 * 26


@settings(max_examples=150, deadline=None, derandomize=True)
@given(edits=st.lists(st.tuples(st.integers(0, len(ROOM_TEXT)), st.integers(0, 8),
                                st.sampled_from(["", "}", "{", '"', "*", "*X ", "9", "-",
                                                 "\n", "nan", "A:", "\x00", "é"])),
                      min_size=1, max_size=4))
def test_fuzz_random_edits_end_in_an_ase_error_or_a_parse(edits):
    text = ROOM_TEXT
    for offset, delete, insert in edits:
        offset = min(offset, len(text))
        text = text[:offset] + insert + text[offset + delete:]
    outcome(text)                   # asserts: parses, or AseError with path:line:


def test_fuzz_companion_truncation_and_numbers():
    end = MAT_TEXT.index("\nend") + len("\nend")
    reference = mat_outcome(MAT_TEXT)
    assert reference[0] == "ok"
    for k in range(len(MAT_TEXT) + 1):
        result = mat_outcome(MAT_TEXT[:k])
        if k >= end:
            assert result == reference
        else:
            assert result[0] == "error", (k, result)
    checked = 0
    for k, m in enumerate(NUMBER.finditer(MAT_TEXT)):
        line_start = MAT_TEXT.rfind("\n", 0, m.start()) + 1
        in_comment = "#" in MAT_TEXT[line_start:m.start()]
        bad = NOT_NUMBERS[k % len(NOT_NUMBERS)]
        result = mat_outcome(MAT_TEXT[:m.start()] + bad + MAT_TEXT[m.end():])
        if in_comment:
            assert result == reference
        else:
            line = MAT_TEXT.count("\n", 0, m.start()) + 1
            assert result[0] == "error" and result[1] == line, result
            checked += 1
    assert checked == 15                 # every number of room.mat outside comments


# =============================================================================================
# 4. Blender
# =============================================================================================
def _bpy():
    return pytest.importorskip("bpy")


@pytest.fixture
def blender():
    """Factory settings, Lanterna registered; the previous registration state restored."""
    bpy = _bpy()
    from lanterna.engine.blender import registration
    was = registration.is_registered()
    registration.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy
    if not was:
        registration.unregister()


def _counts(bpy):
    d = bpy.data
    return {name: len(getattr(d, name)) for name in
            ("objects", "meshes", "materials", "cameras", "lights", "collections")}


def test_operator_is_in_the_import_menu_only_while_registered():
    bpy = _bpy()
    from lanterna.engine.blender import registration
    from lanterna.ops import import_ase
    was = registration.is_registered()
    registration.register()
    try:
        assert import_ase.LANTERNA_OT_import_ase.is_registered
        assert import_ase._menu in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()
        assert import_ase.LANTERNA_OT_import_ase.bl_idname == "import_scene.lanterna_ase"
        assert import_ase.LANTERNA_OT_import_ase.bl_label == "ASCII Scene Export (.ase)"
    finally:
        registration.unregister()
    assert not import_ase.LANTERNA_OT_import_ase.is_registered
    assert import_ase._menu not in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()
    if was:
        registration.register()


def test_blender_import_of_the_room(blender):
    bpy = blender
    assert bpy.ops.import_scene.lanterna_ase(filepath=ROOM) == {'FINISHED'}
    coll = bpy.data.collections["room"]
    assert coll.name in bpy.context.scene.collection.children
    assert sorted(o.name for o in coll.objects) == sorted(
        ["Floor", "Walls", "Box01", "Lamp", "Camera01", "Omni01", "Direct01"])
    objs = bpy.data.objects
    assert [len(objs[n].data.vertices) for n in ("Floor", "Walls", "Box01", "Lamp")] == \
        [4, 8, 8, 4]
    assert [len(objs[n].data.polygons) for n in ("Floor", "Walls", "Box01", "Lamp")] == \
        [2, 10, 12, 2]
    # World positions (matrix_world @ local) are the file's, to float32 precision.
    box = objs["Box01"]
    world = np.array([box.matrix_world @ v.co for v in box.data.vertices])
    np.testing.assert_allclose(world, ase.parse_ase(ROOM_TEXT).geoms[2].vertices, atol=1e-6)
    np.testing.assert_allclose(np.array(box.matrix_world)[:3, 3], [0.8, 0.6, 0.5], atol=1e-7)

    assert [s.material.name for s in objs["Floor"].material_slots] == ["Green"]
    assert [s.material.name for s in objs["Lamp"].material_slots] == ["Lamp"]
    lamp = bpy.data.materials["Lamp"].lanterna
    assert not lamp.derive_from_nodes
    np.testing.assert_allclose(lamp.exitance, [30, 30, 24], rtol=1e-7)
    np.testing.assert_allclose(lamp.diffuse, [0.5] * 3, rtol=1e-7)
    green = bpy.data.materials["Green"].lanterna
    np.testing.assert_allclose(green.diffuse, [0.1, 0.6, 0.1], rtol=1e-7)
    np.testing.assert_allclose(green.specular, [0.2] * 3, rtol=1e-7)

    omni, sun, cam = objs["Omni01"], objs["Direct01"], objs["Camera01"]
    assert (omni.data.type, omni.data.shadow_soft_size, omni.data.energy) == ('POINT', 0.0, 60.0)
    np.testing.assert_allclose(omni.data.color, [1, 0.95, 0.9], rtol=1e-7)
    np.testing.assert_allclose(omni.location, [0.5, 0, 2.6], atol=1e-7)
    assert sun.data.type == 'SUN' and sun.data.energy == pytest.approx(math.pi / 2, rel=1e-7)
    assert cam.data.sensor_fit == 'HORIZONTAL' and cam.data.angle == pytest.approx(1.0, 1e-6)
    assert bpy.context.scene.camera == cam

    # The renderer's exporter reads the imported scene: 26 triangles, the companion values.
    from lanterna.engine.blender import export
    scene = export.export_scene(bpy.context.evaluated_depsgraph_get(), resolution=(32, 24))
    assert len(scene.triangles) == 26 and len(scene.lights) == 2
    by_name = {m.name: m for m in scene.materials}
    np.testing.assert_allclose(by_name["Lamp"].exitance, [30, 30, 24], rtol=1e-7)
    np.testing.assert_allclose(by_name["Green"].specular, [0.2] * 3, rtol=1e-7)


def _broken_variants():
    sites = _number_sites(ROOM_TEXT)
    vertex = next(s for s in sites if s[2] == "*MESH_VERTEX")
    face = re.search(r"C:\s+(\d+)", ROOM_TEXT)
    huge = re.search(r"\*MESH_NUMFACES (\d+)", ROOM_TEXT)
    return {
        "truncated": (ROOM_TEXT[:len(ROOM_TEXT) // 2], MAT_TEXT),
        "truncated_late": (ROOM_TEXT[:-3], MAT_TEXT),
        "word": (ROOM_TEXT[:vertex[0]] + "abc" + ROOM_TEXT[vertex[1]:], MAT_TEXT),
        "nan": (ROOM_TEXT[:vertex[0]] + "nan" + ROOM_TEXT[vertex[1]:], MAT_TEXT),
        "face_index": (ROOM_TEXT[:face.start(1)] + "99" + ROOM_TEXT[face.end(1):], MAT_TEXT),
        "huge_count": (ROOM_TEXT[:huge.start(1)] + "999999999999" + ROOM_TEXT[huge.end(1):],
                       MAT_TEXT),
        "bad_mat": (ROOM_TEXT, MAT_TEXT.replace("diffuse 0.8", "diffuse 1.8")),
        "truncated_mat": (ROOM_TEXT, MAT_TEXT[:-5]),
    }


@pytest.mark.parametrize("variant", sorted(_broken_variants()))
def test_blender_import_of_a_broken_file_creates_nothing(blender, tmp_path, variant):
    bpy = blender
    ase_text, mat_text = _broken_variants()[variant]
    (tmp_path / "room.ase").write_text(ase_text, encoding="utf-8")
    (tmp_path / "room.mat").write_text(mat_text, encoding="utf-8")
    before = _counts(bpy)
    # Blender turns the operator's ERROR report into a RuntimeError for a Python caller.
    with pytest.raises(RuntimeError) as info:
        bpy.ops.import_scene.lanterna_ase(filepath=str(tmp_path / "room.ase"))
    assert re.search(r"room\.(ase|mat):\d+: ", str(info.value)), str(info.value)
    assert _counts(bpy) == before
    assert bpy.context.scene.camera is None


def test_blender_failure_midway_is_rolled_back(blender, monkeypatch):
    bpy = blender
    from lanterna.ops import import_ase

    def broken(spec):
        raise RuntimeError(f"simulated failure creating light {spec.name}")

    monkeypatch.setattr(import_ase, "_make_light", broken)
    before = _counts(bpy)
    with pytest.raises(RuntimeError, match="simulated failure creating light Omni01"):
        import_ase.import_ase(ROOM, bpy.context)
    assert _counts(bpy) == before and bpy.context.scene.camera is None
    with pytest.raises(RuntimeError, match="import failed and was undone"):
        bpy.ops.import_scene.lanterna_ase(filepath=ROOM)
    assert _counts(bpy) == before


def test_import_function_summary(blender):
    bpy = blender
    from lanterna.ops import import_ase
    summary = import_ase.import_ase(ROOM, bpy.context)
    assert summary["collection"] == "room"
    assert summary["meshes"] == ["Floor", "Walls", "Box01", "Lamp"]
    assert summary["materials"] == ["Green", "White", "Lamp"]
    assert summary["cameras"] == ["Camera01"]
    assert summary["lights"] == ["Omni01", "Direct01"] and summary["warnings"] == []
    # A second import makes a second collection; Blender renames what clashes.
    again = import_ase.import_ase(ROOM, bpy.context)
    assert again["collection"] == "room.001" and again["meshes"][0] == "Floor.001"


def test_blender_degenerate_and_repeated_faces_are_dropped_with_warnings(blender, tmp_path):
    bpy = blender
    from lanterna.ops import import_ase
    (tmp_path / "tri.ase").write_text(
        "*3DSMAX_ASCIIEXPORT 200\n*GEOMOBJECT {\n*NODE_NAME \"Tri\"\n*NODE_TM { *TM_POS 0 0 0 }\n"
        "*MESH {\n*MESH_NUMVERTEX 3\n*MESH_NUMFACES 3\n*MESH_VERTEX_LIST {\n"
        "*MESH_VERTEX 0 0 0 0\n*MESH_VERTEX 1 1 0 0\n*MESH_VERTEX 2 0 1 0\n}\n"
        "*MESH_FACE_LIST {\n*MESH_FACE 0: A: 0 B: 1 C: 2\n*MESH_FACE 1: A: 0 B: 1 C: 1\n"
        "*MESH_FACE 2: A: 1 B: 2 C: 0\n}\n}\n}\n")
    summary = import_ase.import_ase(str(tmp_path / "tri.ase"), bpy.context)
    text = "\n".join(summary["warnings"])
    assert "GEOMOBJECT 'Tri': 1 face(s) repeat a vertex (degenerate) and are dropped" in text
    assert "Blender kept 1 of its 2 faces" in text                # face 2 repeats face 0
    assert len(bpy.data.objects["Tri"].data.polygons) == 1
    assert "no companion material file tri.mat" in text
