"""``lanterna bench --sweep`` (bench/sweep.py): outputs, front, interpolation.

The sweep runs once, in-process, with ``--quick`` on the seed's Scene 1 at 32 x 24 (two knobs,
photon_k and cache_error, around a cheaper base: the final preset with 50k photons, gather
6 x 24 and 4 spp; the ``preview`` preset marked; Cycles at 4 and 16 spp: 4 Lanterna renders
and 2 Cycles renders plus warm-ups, about 25 s on 2 busy cores), against a reference EXR made
here by Cycles (128 spp, a seed of its own). Cycles, not Lanterna at high samples, because
that is what the sweep's references are (another renderer's picture of the same scene, so
Lanterna's errors include its bias, as in real use), and at 32 x 24 it costs about a second;
its noise does not matter, since this checks the plumbing (files, columns, one row per
point), not the figures. The numerics (the Pareto front, the
log-log interpolation, Cycles' time for an error) are checked on hand-made data. Bad flags
give one ``lanterna bench: error:`` line and status 2, before any rendering.
"""
from __future__ import annotations

import csv
import json
import math

import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("matplotlib")

from lanterna.engine import imageio  # noqa: E402
from lanterna.bench import main as bench, sweep as bench_sweep, vs_cycles as bench_cycles  # noqa: E402

RESOLUTION = (32, 24)
CYCLES_SAMPLES = (4, 16)
KNOBS = ("photon_k", "cache_error")


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sweep")
    configure, render_exr, _source = bench_cycles.cycles_functions()
    bscene = bench_cycles.build_seed_scene("scene1", RESOLUTION)
    configure(bscene, 128, 301, gi=True)
    image, _seconds = render_exr(bscene, str(tmp / "cycles_ref_render.exr"))
    ref = tmp / "reference.exr"
    imageio.write_exr(str(ref), image.astype("float32"))
    out = tmp / "out"
    argv = ["--scenes", "scene1", "--resolution", "x".join(map(str, RESOLUTION)),
            "--reference", str(ref), "--quick", "--knobs", ",".join(KNOBS),
            "--base", "photons=50000,gather=6x24,samples=4", "--presets", "preview",
            "--cycles-samples", ",".join(map(str, CYCLES_SAMPLES)), "--out", str(out)]
    status = bench_sweep.main(argv)
    return status, out


def test_sweep_writes_csv_json_and_plot(sweep):
    status, out = sweep
    assert status == 0
    data = json.loads((out / "scene1_sweep.json").read_text())
    png = (out / "scene1_sweep.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    with open(out / "scene1_sweep.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))

    # One row per point: base + one value per knob (--quick) + the preview preset, then
    # Cycles without and with OIDN per sample count.
    lanterna = [p for p in data["points"] if p["method"] == "Lanterna"]
    assert len(lanterna) == 1 + len(KNOBS) + 1
    assert sorted({p["knob"] for p in lanterna}) == sorted(("base", "preset") + KNOBS)
    assert len(data["points"]) == len(lanterna) + 2 * len(CYCLES_SAMPLES)
    assert len(rows) == len(data["points"])
    for column in ("scene", "method", "knob", "value", "settings", "seconds", "rel_rmse",
                   "rel_rmse_corrected", "region_mean_rel_error", "region_worst_rel_error",
                   "peak_rss_mb", "samples", "share_photons", "share_camera", "share_other",
                   "on_front", "cpu_seconds"):
        assert column in rows[0], column
    assert {r["method"] for r in rows} == {"Lanterna", "Cycles", "Cycles+OIDN"}
    for r in rows:
        assert float(r["seconds"]) > 0 and float(r["rel_rmse"]) > 0
        json.loads(r["settings"])
        if r["method"] == "Lanterna":
            assert float(r["peak_rss_mb"]) > 0
            shares = [float(v) for k, v in r.items() if k.startswith("share_") and v]
            assert abs(sum(shares) - 1.0) < 0.05
    # The given EXR's noise is unknown: the compared error is the plain relative RMSE.
    assert all(p["rel_rmse_corrected"] is None and p["error"] == p["rel_rmse"]
               for p in data["points"])
    # The analysis is there: a front, the preset's place and Cycles' time for its error.
    assert data["front"] and data["front"][0]["label"]
    preview = data["presets"]["preview"]
    assert preview["front_error_ratio"] >= 1.0 - 1e-12
    assert {preview["cycles"]["status"], preview["cycles_oidn"]["status"]} <= {
        "interpolated", "at_most", "beyond"}
    assert data["machine"]["cpu_count"] and data["command"].startswith("lanterna bench --sweep")


def test_final_preset_is_the_base_point():
    base, _text = bench_sweep.base_values("final")
    points = bench_sweep.plan_points(bench_sweep.DEFAULT_KNOBS, True, base, ["preview", "final"])
    assert points[0]["label"] == "base = final"
    assert [p["knob"] for p in points].count("preset") == 1          # preview only
    full = bench_sweep.plan_points(bench_sweep.DEFAULT_KNOBS, False, base, ["preview", "final"])
    assert len(full) == 21          # base + 4 + 3 + 4 + 4 + 4 + preview
    assert len({json.dumps(p["values"], sort_keys=True) for p in full}) == len(full)


def test_pareto_front_on_hand_made_points():
    pts = [(1, 10), (2, 5), (3, 6), (4, 2), (2, 5), (0.5, 20), (5, 2), (4, 3), (6, 1)]
    front = bench_sweep.pareto_front(pts)
    assert front == [5, 0, 1, 3, 8]          # (0.5,20) (1,10) (2,5) (4,2) (6,1)
    assert bench_sweep.pareto_front([]) == []
    assert bench_sweep.pareto_front([(1, 1)]) == [0]


def test_loglog_interpolation_on_a_power_law():
    xs = [1.0, 4.0, 16.0, 64.0]
    ys = [3.0 * x ** -0.5 for x in xs]
    for x in (1.0, 2.0, 7.3, 30.0, 64.0):
        assert bench_sweep.loglog_interp(x, xs, ys) == pytest.approx(3.0 * x ** -0.5, rel=1e-12)
    assert bench_sweep.loglog_interp(0.5, xs, ys) is None
    assert bench_sweep.loglog_interp(65.0, xs, ys) is None
    front = list(zip(xs, ys))
    assert bench_sweep.front_error_at(front, 8.0) == pytest.approx(3.0 / math.sqrt(8.0))
    assert bench_sweep.front_error_at(front, 100.0) == pytest.approx(ys[-1])   # flat after
    assert bench_sweep.front_error_at(front, 0.9) is None                      # none this fast
    # Cycles' time for an error on e = 2 s^-0.5 (samples in order): s = (2 / e)^2.
    curve = [(s, 2.0 * s ** -0.5) for s in (1.0, 4.0, 16.0, 64.0)]
    t = bench_sweep.time_for_error(curve, 0.5)
    assert t["status"] == "interpolated" and t["seconds"] == pytest.approx(16.0)
    t = bench_sweep.time_for_error(curve, 0.7)
    assert t["status"] == "interpolated" and t["seconds"] == pytest.approx((2 / 0.7) ** 2)
    assert bench_sweep.time_for_error(curve, 3.0) == {"seconds": 1.0, "status": "at_most"}
    assert bench_sweep.time_for_error(curve, 0.1) == {"seconds": None, "status": "beyond"}


def _one_error_line(capfd, code):
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith("lanterna bench: error: ") and "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("argv, words", [
    (["--knobs", "photons,focus"], "unknown knob 'focus'"),
    (["--resolution", "30x22"], "multiples of 4"),
    (["--resolution", "big"], "160x120"),
    (["--cycles-samples", "16,x"], "--cycles-samples"),
    (["--reference", "/no/such/ref.exr", "--scenes", "scene1"], "no such file"),
    (["--reference-samples", "1"], "--reference-samples"),
    (["--base", "gather=12"], "MxN"),
    (["--base", "photons=lots"], "--base"),
    (["--presets", "draft"], "unknown preset"),
    (["--scenes", "scene7"], "unknown seed scene"),
    (["a.blend", "--scenes", "scene1"], "not both"),
    (["/no/such/file.blend"], "no such file"),
    (["--repeat", "0"], "--repeat"),
    (["--frobnicate"], "unrecognized"),
])
def test_bad_flags_give_one_error_line(capfd, argv, words):
    capfd.readouterr()
    line = _one_error_line(capfd, bench_sweep.main(argv))
    assert words in line, line


def test_sweep_and_vs_cycles_together_are_refused(capfd):
    capfd.readouterr()
    line = _one_error_line(capfd, bench.main(["--sweep", "--vs-cycles"]))
    assert "not both" in line
