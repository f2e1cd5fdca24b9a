"""A study's plots: each outage error against the outage duration, one curve per layout and
parameter values (drawn by :func:`bodyfusion.evaluation.plots.plot_against_outage_duration`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bodyfusion.base.sections import FiguresConfig
from bodyfusion.evaluation.plots import plot_against_outage_duration, save_figure
from bodyfusion.study.results import PLOT_SUFFIX


def write_plots(out_dir: Path, rows: list[dict[str, Any]], params: list[str],
                figures: FiguresConfig | None = None) -> list[Path]:
    """One plot per outage metric, in the ``figures`` formats and dpi (default PNG): its value
    (m) against the outage duration (s), one curve per layout and parameter set. Returns the
    files written."""
    figures = figures or FiguresConfig()
    written = []
    for metric, title in (("outage.end_error_m", "Horizontal error at the end of the GNSS outage"),
                          ("outage.max_error_m", "Largest horizontal error during the GNSS outage")):
        curves: dict[str, dict[float, list[float]]] = {}
        for row in rows:
            if row["status"] != "ok" or row.get("outage.duration_s") is None or row.get(metric) is None:
                continue
            label = " ".join([row["layout"], *(f"{p[len('param.'):]}={row.get(p)}" for p in params)])
            curves.setdefault(label, {}).setdefault(float(row["outage.duration_s"]), []).append(float(row[metric]))
        if curves:
            name = f"{metric.split('.', 1)[1].removesuffix('_m')}{PLOT_SUFFIX}"
            system = next(r["outage.system"] for r in rows if r.get("outage.system"))
            fig = plot_against_outage_duration(curves, f"{title} ({system})")
            written += save_figure(fig, out_dir / name, figures.formats, figures.dpi)
    return written
