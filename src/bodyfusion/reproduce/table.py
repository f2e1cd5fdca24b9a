"""A reproduction's table: one cell of a paper's table per row, the paper's figure beside ours.

``table.csv`` columns (docs/contract.md): ``paper`` (s000, s001, s002, s004), ``case`` (named
as in the paper: ZUPT, RTS, FB, FB-RTS; DC-KF …), ``metric``, ``paper_value`` (empty where the
paper gives none), ``our_value`` (the mean over seeds), ``our_sd`` (the seed-to-seed standard
deviation, ddof 1; empty for one seed), ``n_seeds``. ``README.md`` beside it: the comparison
in words, then the table.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bodyfusion.base.files import replaced_atomically

COLUMNS = ("paper", "case", "metric", "paper_value", "our_value", "our_sd", "n_seeds")
REPRODUCTION_FILES = ("table.csv", "README.md")
"""What :func:`write_reproduction` writes into its folder."""


def seed_sd(values: Sequence[float]) -> float:
    """The seed-to-seed spread of ``values``: their sample standard deviation (0 for one seed)."""
    v = np.asarray(values, dtype=float)
    return float(v.std(ddof=1)) if v.size > 1 else 0.0


@dataclass(frozen=True)
class Cell:
    """One cell of a paper's table: the paper's figure (None: not given) and ours over seeds."""

    paper: str
    case: str
    metric: str
    paper_value: float | None
    our_value: float
    our_sd: float | None
    n_seeds: int

    @classmethod
    def over_seeds(cls, paper: str, case: str, metric: str, paper_value: float | None,
                   values: Sequence[float]) -> Cell:
        """The cell of per-seed ``values``: their mean and sample standard deviation."""
        v = np.asarray(values, dtype=float)
        return cls(paper, case, metric, paper_value, float(v.mean()), seed_sd(v) if v.size > 1 else None,
                   int(v.size))

    def row(self) -> list[str]:
        """The CSV row: numbers as Python prints them, empty where absent."""
        def text(x: float | None) -> str:
            return "" if x is None or (isinstance(x, float) and math.isnan(x)) else repr(float(x))

        return [self.paper, self.case, self.metric, text(self.paper_value), text(self.our_value), text(self.our_sd),
                str(self.n_seeds)]


def markdown_table(cells: Sequence[Cell]) -> str:
    """The cells as a Markdown table (ours as mean ± sd)."""
    lines = ["| case | metric | paper | ours (mean ± sd) | seeds |", "|---|---|---:|---:|---:|"]
    for c in cells:
        paper = "—" if c.paper_value is None else f"{c.paper_value:.4g}"
        ours = f"{c.our_value:.4g}" + ("" if c.our_sd is None else f" ± {c.our_sd:.2g}")
        lines.append(f"| {c.case} | {c.metric} | {paper} | {ours} | {c.n_seeds} |")
    return "\n".join(lines)


def write_reproduction(out: Path, cells: Sequence[Cell], text: str) -> None:
    """``out``/table.csv and ``out``/README.md (``text``, then the table), each written whole
    then put in place."""
    out.mkdir(parents=True, exist_ok=True)
    table, readme = (out / name for name in REPRODUCTION_FILES)
    with replaced_atomically(table) as path, path.open("w", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(COLUMNS)
        writer.writerows(c.row() for c in cells)
    with replaced_atomically(readme) as path:
        path.write_text(text.rstrip() + "\n\n" + markdown_table(cells) + "\n")
