"""Kill rates per module from tools/mutation.sh's results.

    python tools/mutation_summary.py mutation/results/before [--survivors]

Reads <folder>/<module>.txt (one "mutant: status" a line), <module>.seconds and, for a
sampled run, <module>.total: "of" is the module's mutant count, "mutants" those run.
Kill rate = killed / (mutants - no tests - skipped); timeouts and suspicious mutants are
counted apart (neither killed nor survived). A sampled run lists its sample only; the 95 %
interval (Wilson) says how far the sample's rate may be from the module's. ``--survivors``
lists the mutants not killed.
"""
import collections
import math
import pathlib
import sys

MODULES = ("photons", "shadow_photons", "irradiance_cache", "gather", "direct")


def read(path):
    status = {}
    for line in path.read_text().splitlines():
        name, _, st = line.strip().rpartition(": ")
        if name:
            status[name] = st
    return status


def wilson(k, n, z=1.96):
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def main(folder, survivors=False):
    folder = pathlib.Path(folder)
    print(f"{'module':<18}{'of':>6}{'mutants':>8}{'killed':>8}{'survived':>9}{'timeout':>8}"
          f"{'suspic.':>8}{'no tests':>9}{'other':>6}{'kill rate':>10}{'95 % interval':>16}"
          f"{'seconds':>9}")
    for mod in MODULES:
        res = folder / f"{mod}.txt"
        if not res.exists():
            continue
        status = read(res)
        c = collections.Counter(status.values())
        tested = len(status) - c["no tests"] - c["skipped"]
        other = len(status) - sum(c[k] for k in ("killed", "survived", "timeout", "suspicious",
                                                 "no tests"))
        secs_file = folder / f"{mod}.seconds"
        secs = secs_file.read_text().strip() if secs_file.exists() else "-"
        rate = f"{100 * c['killed'] / tested:.1f} %" if tested else "-"
        lo, hi = wilson(c["killed"], tested)
        ci = f"{100 * lo:.0f}-{100 * hi:.0f} %" if tested else "-"
        total_file = folder / f"{mod}.total"
        total = total_file.read_text().strip() if total_file.exists() else len(status)
        print(f"{mod:<18}{total:>6}{len(status):>8}{c['killed']:>8}{c['survived']:>9}{c['timeout']:>8}"
              f"{c['suspicious']:>8}{c['no tests']:>9}{other:>6}{rate:>10}{ci:>16}{secs:>9}")
        if survivors:
            for name, st in status.items():
                if st != "killed":
                    print(f"    {st:<10} {name}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "mutation/results/before", "--survivors" in sys.argv)
