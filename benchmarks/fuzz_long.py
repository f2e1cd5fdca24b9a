"""The fuzzing suite's long mode: thousands of corrupted inputs, and a table of what became of each.

Runs ``tests/fuzz/test_fuzz_inputs.py`` and ``tests/fuzz/test_fuzz_live.py`` (every reader's
file and the layout corrupted by Hypothesis's edits: truncations, garbage lines, non-finite or
absurd numbers in a field or a column, scaled and swapped columns, duplicated, deleted or
reversed lines, re-encodings, NMEA checksums redone, layout keys set wrong, deleted or added;
each case through ``fusion validate`` and ``fusion run``; the live engine's rows edited
likewise: bad cells, missing columns, unknown systems, late and reversed rows, time jumps) with
``--examples`` per target (9 targets, the phone's live rows a third as many; default 300: 2,500
cases), derandomised (the same cases every time), and every case's outcome recorded: ``refused``
(exit 2, one ``error:`` line), ``ran`` (exit 0, finite trajectories, strict JSON), ``silent`` (a
score moved past the suite's margin with no warning: a silent wrong result) or ``defect``
(anything else: a traceback, a hang over 60 s, a non-finite output, a second error line).

Writes ``--table`` (CSV: target, classes, outcome, detail, case, validate) and prints the
summary per target and per edit class; last line ``cases=… refused=… ran=… silent=… defects=…``.

Run: python benchmarks/fuzz_long.py [--examples 300] [--table fuzz_cases.csv]
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


def summarise(table: Path) -> tuple[dict[tuple[str, str], collections.Counter], collections.Counter]:
    """(target, edit class) → outcome counts, and the totals."""
    per: dict[tuple[str, str], collections.Counter] = collections.defaultdict(collections.Counter)
    totals: collections.Counter = collections.Counter()
    with table.open(newline="") as f:
        for row in csv.DictReader(f):
            for cls in row["classes"].split("+"):
                per[(row["target"], cls)][row["outcome"]] += 1
            totals[row["outcome"]] += 1
    return per, totals


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=300, help="cases per target (8 targets)")
    parser.add_argument("--table", type=Path, default=Path("fuzz_cases.csv"))
    args = parser.parse_args(argv)
    args.table.unlink(missing_ok=True)
    env = {**os.environ, "BODYFUSION_FUZZ_EXAMPLES": str(args.examples), "BODYFUSION_FUZZ_TABLE": str(args.table.resolve()),
           "FUZZ_NO_SHRINK": "1"}
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                    "tests/fuzz/test_fuzz_inputs.py", "tests/fuzz/test_fuzz_live.py"], cwd=ROOT, env=env)
    per, totals = summarise(args.table)
    print(f"{'target':<24} {'edit class':<16} {'cases':>6} {'refused':>8} {'ran':>6} {'silent':>7} {'defects':>8}")
    for (target, cls), counts in sorted(per.items()):
        print(f"{target:<24} {cls:<16} {sum(counts.values()):>6} {counts['refused']:>8} {counts['ran']:>6} "
              f"{counts['silent']:>7} {counts['defect']:>8}")
    print(f"cases={sum(totals.values())} refused={totals['refused']} ran={totals['ran']} silent={totals['silent']} "
          f"defects={totals['defect']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
