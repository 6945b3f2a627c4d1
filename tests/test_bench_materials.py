"""``lanterna bench --materials`` (bench/materials.py): its pure figures on hand-made data.

No renders and no bpy: Cycles' time for an error and the ratio's bounds (below the curve's
fewest samples, beyond its most), the goal's verdict, the 4 x 4 block error, the stored
reference's noise, and the section of docs/performance.md replaced with the rest kept. The
renders themselves are the benchmark's (run by hand, figures in docs/performance.md).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from lanterna.bench import materials


CURVE = [(1.0, 0.4), (4.0, 0.2), (16.0, 0.1), (64.0, 0.05)]   # error ~ t^-1/2
SAMPLES = [16, 64, 256, 1024]


def test_speed_ratio_interpolates_and_bounds():
    r = materials.speed_ratio(2.0, 0.1 * math.sqrt(2), CURVE, SAMPLES)   # between 4 and 16 s
    assert r["status"] == "interpolated" and r["bound"] == "="
    assert r["seconds"] == pytest.approx(8.0) and r["ratio"] == pytest.approx(0.25)
    assert materials.ratio_text(r) == "0.25" and materials.goal_met(r) is True
    slow = materials.speed_ratio(20.0, 0.1 * math.sqrt(2), CURVE, SAMPLES)
    assert slow["ratio"] == pytest.approx(2.5) and materials.goal_met(slow) is False
    below = materials.speed_ratio(3.0, 0.5, CURVE, SAMPLES)    # Cycles better at 16 spp
    assert below["bound"] == ">=" and below["ratio"] == pytest.approx(3.0)
    assert "below 16 spp" in below["text"] and materials.ratio_text(below) == ">= 3.00"
    assert materials.goal_met(below) is False
    beyond = materials.speed_ratio(8.0, 0.01, CURVE, SAMPLES)  # Cycles never gets there
    assert beyond["bound"] == "<" and beyond["ratio"] == pytest.approx(0.125)
    assert "beyond 1024 spp" in beyond["text"] and materials.goal_met(beyond) is True
    assert materials.goal_met(materials.speed_ratio(64.0, 0.01, CURVE, SAMPLES)) is None
    none = materials.speed_ratio(1.0, 0.1, [], SAMPLES)
    assert none["status"] == "n/a" and materials.ratio_text(none) == "-"


def test_block_error_and_reference_noise(tmp_path):
    ref = np.ones((8, 8, 3))
    img = ref.copy()
    img[:2, :2] = 3.0                      # one block of 16 is 3x: its mean error 2
    assert materials.block_rel_rmse(img, ref) == pytest.approx(2.0 / 4.0)
    noisy = ref + np.where(np.indices((8, 8, 3)).sum(axis=0) % 2, 0.1, -0.1)  # zero-mean
    assert materials.block_rel_rmse(noisy, ref) == pytest.approx(0.0, abs=1e-12)
    np.savez(tmp_path / "r.npz", image=ref.astype(np.float32),
             pixel_var=np.full((8, 8, 3), 4e-4, np.float32), spp=256, seeds=np.arange(4))
    loaded = materials.reference_from_npz(tmp_path / "r.npz")
    assert loaded["variance"] == pytest.approx(4e-4) and loaded["samples"] == 1024
    with pytest.raises(materials.BenchError):
        materials.reference_from_npz(tmp_path / "missing.npz")


def _run_data():
    def scene(name, seconds, error, curve):
        rows = [{"samples": s, "seconds": t, "error": e} for s, (t, e) in zip(SAMPLES, curve)]
        entry = materials.speed_ratio(seconds, error, curve, SAMPLES)
        return {"scene": name, "resolution": [80, 60], "samples": SAMPLES,
                "lanterna": {"seconds": seconds, "error": error, "block_rel_rmse": 0.8 * error,
                             "region_worst": 2 * error,
                             "stages": {"camera": 0.6 * seconds, "photons": 0.3 * seconds,
                                        "lights": 0.001}},
                "cycles": entry, "cycles_oidn": entry, "cycles_rows": rows, "oidn_rows": rows}

    return {"machine": {"date": "2026-12-03", "cpu_count": 2, "cpu": "x", "platform": "p",
                        "load_average_start": [2.0, 1, 1], "load_average_end": [3.5, 1, 1]},
            "minutes": 12.0, "cycles_samples": SAMPLES,
            "scenes": {"principled_room": scene("principled_room", 10.0, 0.1, CURVE),
                       "mix_floor": scene("mix_floor", 2.0, 0.5, CURVE)}}


def test_section_replaced_and_the_rest_kept():
    section = materials.section_markdown(_run_data(), "materials/plot.png")
    assert section.startswith(materials.SECTION_TITLE + "\n")
    assert "lanterna bench --materials" in section and "load average 2.0-3.5" in section
    assert "![error against time, per scene](materials/plot.png)" in section
    assert "**principled_room**: misses the goal (ratio 0.6" in section    # 10 s / 16 s
    assert "camera 6.0 s (60 %), photons 3.0 s (30 %)" in section          # lights < 5 %: left out
    # Budget 0.5 x 16 s = 8 s; everything but the camera 10 - 6 = 4 s.
    assert ("needs final at this error in <= 8.0 s; everything but the camera stage takes "
            "4.0 s, which leaves the camera 4.0 s (it takes 6.0 s)") in section
    assert "below 16 spp" in section and "**>= 2.00**" in section
    doc = "# Performance\n\nintro\n\n## A\n\ntable\n"
    once = materials.replace_section(doc, section)
    assert once.startswith(doc) and once.count(materials.SECTION_TITLE) == 1
    assert materials.section_of(once) == section
    middle = once + "\n## Later\n\nkept\n"
    twice = materials.replace_section(middle, materials.SECTION_TITLE + "\n\nnew\n")
    assert twice == doc + "\n" + materials.SECTION_TITLE + "\n\nnew\n\n## Later\n\nkept\n"
    assert materials.section_of(doc) is None


def test_worlds_suite_check_at_256_and_its_own_section():
    data = _run_data()
    data["suite"] = "worlds"
    yard = data["scenes"].pop("principled_room")
    yard["scene"] = "yard"
    data["scenes"] = {"yard": yard}
    rows = yard["cycles_rows"]                     # CURVE: 256 spp = 16 s at 0.1
    check = materials.check_at_samples(yard)      # final: 10 s at 0.1
    assert check["samples"] == 256 and check["error_ok"] and check["time_ratio"] == pytest.approx(10 / 16)
    assert check["met"] is False                   # 0.625 > 0.5
    yard["lanterna"]["seconds"] = 7.0
    assert materials.check_at_samples(yard)["met"] is True
    yard["lanterna"]["error"] = 0.11               # above Cycles-256's error: missed
    assert materials.check_at_samples(yard)["met"] is False
    assert materials.check_at_samples({"cycles_rows": rows[:2], "lanterna": {}}) is None
    section = materials.section_markdown(data, "materials/worlds.png")
    title = materials.SUITES["worlds"].section
    assert section.startswith(title + "\n") and "lanterna bench --materials --worlds" in section
    assert "tests/world_scenes.py" in section and "misses issue 24's check" in section
    # both suites' sections live side by side; each rewrite keeps the other
    doc = materials.replace_section("# P\n", materials.section_markdown(_run_data(), "p.png"))
    both = materials.replace_section(doc, section, title)
    assert materials.section_of(both, title) == section
    assert materials.section_of(both) == materials.section_of(doc)
    with pytest.raises(materials.BenchError):
        materials.parse_args(["--worlds", "--scenes", "principled_room"])
    assert materials.parse_args(["--worlds"]).scenes == ["yard_320", "yard", "window_room"]
