"""``lanterna bench --textures`` (bench/texture_cost.py): its pure parts, no renders, no bpy.

* ``mean_scene`` turns every textured material into an untextured one whose seed reduction
  and closures are the textured one's means (``MaterialTable`` of the twin then holds the
  same per-material rows and reads no texture), and leaves the other materials as they are.
* ``summary`` takes medians over the alternating renders; ``extra`` is median / median - 1;
  the goal's verdict is on the CPU time at 20 %; the section names the figures and replaces
  only its own part of docs/performance.md.
"""
from __future__ import annotations

import numpy as np
import pytest

from lanterna.bench import texture_cost as textures
from lanterna.engine.bsdf import MaterialTable

from test_estimate import _textured_room


def test_mean_scene_keeps_the_means_and_drops_the_textures():
    scene, _byte, _hdr = _textured_room()
    scene.corner_attributes["uv"] = np.random.default_rng(1).random((12, 3, 2)).astype(
        np.float32)
    table = MaterialTable(scene)
    twin = textures.mean_scene(scene)
    mean = MaterialTable(twin)
    assert table.textured.tolist() == [False, True, True, True]
    assert not mean.textured.any() and not mean.textures.any
    assert twin.materials[0] is scene.materials[0]
    for name in ("diffuse", "specular", "exitance"):
        assert np.allclose(getattr(mean, name), getattr(table, name), rtol=1e-6, atol=1e-9)
    # The textured floor's per-hit diffuse varies; the twin's is its mean everywhere.
    prim = np.array([0, 0, 1]); bu = np.array([0.1, 0.5, 0.2]); bv = np.array([0.1, 0.3, 0.6])
    ids = scene.material_ids[prim]
    assert np.ptp(table.at(ids, prim, bu, bv).diffuse[:, 0]) > 0.01
    assert np.allclose(mean.at(twin.material_ids[prim], prim, bu, bv).diffuse,
                       table.diffuse[ids])
    assert twin.triangles is scene.triangles and twin.corner_attributes == {}


def _data(textured, mean, cpu_textured, cpu_mean):
    def runs(walls, cpus):
        return [{"seconds": w, "cpu_seconds": c, "stages": {"camera": w / 2, "photons": w / 4}}
                for w, c in zip(walls, cpus)]
    return {"renders": {"textured": runs(textured, cpu_textured), "mean": runs(mean, cpu_mean)}}


def test_summary_medians_extra_and_goal():
    data = _data([12.0, 30.0, 11.0], [10.0, 10.0, 11.0], [12.5, 11.5, 11.0], [10.0, 10.2, 9.9])
    s = textures.summary(data)
    assert s["seconds"] == {"textured": 12.0, "mean": 10.0}
    assert s["extra_seconds"] == pytest.approx(0.2)
    assert s["extra_cpu_seconds"] == pytest.approx(11.5 / 10.0 - 1)      # medians
    assert s["goal_met"] is True                          # CPU: +20 % (wall +20 % too)
    assert s["stages"]["camera"] == {"textured": 6.0, "mean": 5.0}
    slow = textures.summary(_data([1.0], [1.0], [12.2], [10.0]))       # wall +0 %, CPU +22 %
    assert slow["goal_met"] is False and textures.extra([], [1.0]) is None


def test_section_replaces_only_its_own_part():
    from lanterna.bench.materials import replace_section

    data = _data([12.0], [10.0], [12.0], [10.0])
    data.update(machine={"date": "2026-12-04", "cpu_count": 2, "cpu": "x", "platform": "p",
                         "load_average_start": [1.5], "load_average_end": [0.5]},
                minutes=4.2, repeat=1,
                memory={"images": 3, "bytes": 6656, "float32_bytes": 26624,
                        "dtypes": ["uint8"]},
                estimate={"texture_bytes": 6656, "lookups": 2.5e6, "texture_seconds": 0.4,
                          "rate": 1.6e-7})
    data["summary"] = textures.summary(data)
    section = textures.section_markdown(data)
    assert section.startswith(textures.SECTION_TITLE)
    assert "**+20.0 %**" in section and "Goal met" in section and "6,656 bytes" in section
    doc = "# Performance\n\nintro\n\n## Materials against Cycles (issue 23)\n\nkept\n"
    once = replace_section(doc, section, textures.SECTION_TITLE)
    twice = replace_section(once, section, textures.SECTION_TITLE)
    assert once == twice and "kept" in once and once.count(textures.SECTION_TITLE) == 1
