"""List the surviving mutants of a module with their diffs, sorted into kinds.

    python tools/mutation_survivors.py <module> [results.txt]

Run after tools/mutation.sh <module> (it reads mutation/stage/<module>/, the stage with its
mutants/, and by default mutation/results/after/<module>.txt). Prints each survivor's one-line diff under a proposed kind; the kinds are
mechanical guesses (a dtype argument dropped, a stats key renamed, a slice end past the
array's width, ...) that a person then confirms or moves (mutation/survivors_<module>.txt).
"""
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent

KINDS = [
    ("dtype", re.compile(r"astype\(None|, None\)|np\.float(32|64)\)|\(None, copy|dtype=None|"
                         r"astype\([^)]*, \)|ascontiguousarray\([^,]+, \)|asarray\([^,]+, \)")),
    ("copy flag", re.compile(r"copy=(True|False)|copy=None")),
    ("kd-tree leaf size / workers / threads", re.compile(r"leafsize|workers=|ThreadPoolExecutor\(")),
    ("slice end past the width", re.compile(r"\[:, ?\d:\d\]|\[\.\.\., ?\d:\d\]")),
    ("random stream only", re.compile(r"rng\.random\(\(|stratified_2d\(")),
    ("stats key / timing", re.compile(r"XX|_seconds|perf_counter|stats\[")),
    ("boundary < / <=", re.compile(r"<=|>=")),
]


def diff_of(stage, name):
    out = subprocess.run([str(ROOT / ".venv-mut/bin/mutmut"), "show", name], cwd=stage,
                         capture_output=True, text=True).stdout
    lines = [l for l in out.splitlines() if l[:1] in "+-" and not l.startswith(("+++", "---"))]
    return lines


def main(module, results=None):
    stage = ROOT / "mutation" / "stage" / module
    results = pathlib.Path(results) if results else ROOT / "mutation" / "results" / "after" / f"{module}.txt"
    names = [l.strip().rsplit(": ", 1) for l in results.read_text().splitlines() if ": " in l]
    survivors = [(n, s) for n, s in names if s not in ("killed", "not checked")]
    groups = {}
    for name, status in survivors:
        lines = diff_of(stage, name)
        plus = " ".join(l for l in lines if l.startswith("+"))
        kind = next((k for k, rx in KINDS if rx.search(plus)), "other")
        groups.setdefault(kind, []).append((name, status, lines))
    for kind, items in groups.items():
        print(f"## {kind} ({len(items)})")
        for name, status, lines in items:
            print(f"{name.rsplit('.', 1)[-1]} [{status}]")
            for l in lines:
                print("    " + l.strip()[:160])
        print()


if __name__ == "__main__":
    main(*sys.argv[1:])
