"""``lanterna bench --hair`` (bench/hair_vs_cycles.py): its pure parts, no renders."""
import numpy as np
import pytest

from lanterna.bench import hair_vs_cycles as bench_hair
from lanterna.bench.materials import section_of


def test_region_ratios_and_error_read_luminance():
    ref = np.ones((4, 4, 3))
    image = ref.copy()
    image[:2] *= 0.5
    regions = {"top": (slice(0, 2), slice(None)), "bottom": (slice(2, 4), slice(None))}
    ratios = bench_hair.region_ratios(image, ref, regions)
    assert ratios == pytest.approx({"top": 0.5, "bottom": 1.0})
    assert bench_hair.rel_rmse(image, ref) == pytest.approx(np.sqrt(0.5 * 0.25))


def test_the_section_is_one_titled_section_with_every_region():
    data = {"date": "2026-12-07", "machine": "2 CPUs", "blender": "5.2.3", "strands": 10,
            "triangles": 1000, "reference_samples": 2048, "regions": ["fur", "core"],
            "lanterna": {"seconds": 20.0, "error": 0.03, "stages": {"camera": 12.0}},
            "cycles": {"samples": 256, "seconds": 7.0, "error": 0.015},
            "ratios": {"fur": 0.9, "core": 0.76}, "cycles_ratios": {"fur": 1.0, "core": 1.0},
            "direct_ratios": {"fur": 0.99, "core": 0.94}}
    text = bench_hair.section_markdown(data)
    assert section_of("# Doc\n\n" + text + "\n## Next\n", bench_hair.SECTION_TITLE) \
        .strip() == text.strip()
    assert "| 0.900 | 0.760 |" in text and "| 0.990 | 0.940 |" in text
