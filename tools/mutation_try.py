"""Run given tests against given mutants of a staged module, one pytest process each.

    python tools/mutation_try.py <module> <test path> [...] < names.txt

Reads mutant names (one a line, or "name: status" lines of a results file; only the lines
whose status is not "killed") and prints "<name>: killed | survived | timeout". For writing
tests against the survivors between two runs of tools/mutation.sh: the stage
mutation/stage/<module>/mutants/ must exist (it does after a run). The test paths are taken
from the working tree, so a test being written is tried at once; the figures in the tables
come from tools/mutation.sh only.
"""
import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent


def main(module, *tests):
    stage = ROOT / "mutation" / "stage" / module / "mutants"
    env = dict(os.environ, PYTHONPATH=str(stage), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    paths = [str((ROOT / t).resolve()) if not os.path.isabs(t) else t for t in tests]
    for line in sys.stdin:
        name, _, status = line.strip().partition(": ")
        if not name or status == "killed":
            continue
        env["MUTANT_UNDER_TEST"] = name
        try:
            rc = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                                 *paths], cwd=stage, env=env, capture_output=True,
                                timeout=120).returncode
            verdict = "survived" if rc == 0 else "killed" if rc == 1 else f"error {rc}"
        except subprocess.TimeoutExpired:
            verdict = "timeout"
        print(f"{name}: {verdict}", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
