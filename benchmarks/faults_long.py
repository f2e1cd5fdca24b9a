"""The fault-injection suite's long mode: many runs stopped, raced and starved, and a table of what
became of each.

Runs ``tests/fuzz/test_fault_injection.py`` with ``--cases`` per fault class (kill, interrupt and
terminate at a random moment; two runs into one folder at once; a write limit that fills the
disk) and the four special files as data, each case drawn from its own seed (the same cases every
time), and records every outcome: ``previous`` / ``new`` (every data file the earlier or the new
run's), ``mixed`` (each file whole, some of each: a run killed between two files), ``refused``
(exit 2, one line), ``defect`` (a torn or missing file, a process left behind, a traceback, a
refusal of more than one line, a hang).

Writes ``--table`` (CSV: class, case, outcome, detail) and prints the outcomes per class; last
line ``cases=… previous=… new=… mixed=… refused=… defects=…``.

Run: python benchmarks/faults_long.py [--cases 40] [--table fault_cases.csv]
"""

from __future__ import annotations

import argparse
import collections
import csv
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUTCOMES = ("previous", "new", "mixed", "refused", "defect")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=40, help="cases per fault class (5 classes, plus 4 special files)")
    parser.add_argument("--table", type=Path, default=Path("fault_cases.csv"))
    args = parser.parse_args(argv)
    args.table.unlink(missing_ok=True)
    env = {**os.environ, "BODYFUSION_FAULT_CASES": str(args.cases), "BODYFUSION_FAULT_TABLE": str(args.table.resolve())}
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                    "tests/fuzz/test_fault_injection.py"], cwd=ROOT, env=env)
    per: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    with args.table.open(newline="") as fh:
        for row in csv.DictReader(fh):
            per[row["class"]][row["outcome"]] += 1
    print(f"{'fault class':<14} {'cases':>6} " + " ".join(f"{o:>9}" for o in OUTCOMES))
    totals: collections.Counter = collections.Counter()
    for cls, counts in sorted(per.items()):
        totals.update(counts)
        print(f"{cls:<14} {sum(counts.values()):>6} " + " ".join(f"{counts[o]:>9}" for o in OUTCOMES))
    print(f"cases={sum(totals.values())} " + " ".join(f"{o if o != 'defect' else 'defects'}={totals[o]}"
                                                      for o in OUTCOMES))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
