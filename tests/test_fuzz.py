"""The quick subset of the fuzz suite (``tests/fuzz.py``; the full run is ``make fuzz``): 60
damaged or hostile inputs, 20 each of .blend, ASE and baked maps, from a fixed seed, each
rendered by the ``lanterna`` command in its own process. Every one must be handled well: a
clear refusal (exit 2, one line naming the damaged file) or a finite, non-negative picture;
no crash, hang, traceback, NaN or unnamed refusal. (About a minute on 2 cores.)"""
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy")
sys.path.insert(0, str(Path(__file__).resolve().parent))
import fuzz  # noqa: E402


def test_sixty_damaged_inputs_are_handled_well(tmp_path):
    rows = fuzz.run_all(seed=19, count=60, work=tmp_path)
    bad = [f"{r['kind']} ({r['damage']}): {r['outcome']}: {r['message']}" for r in rows
           if r["outcome"] not in fuzz.GOOD]
    assert len(rows) == 60
    assert bad == [], "\n".join(bad) + "\n" + fuzz.table(rows)
    kinds = {r["kind"] for r in rows if r["outcome"] == "refused"}
    assert kinds == {"blend", "ase", "maps"}        # each kind met damage it had to refuse
