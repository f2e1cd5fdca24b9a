"""A study's plots: each outage error against the outage duration, one curve per layout and
parameter values (drawn by :func:`bodyfusion.evaluation.plots.plot_against_outage_duration`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bodyfusion.evaluation.plots import plot_against_outage_duration


def write_plots(out_dir: Path, rows: list[dict[str, Any]], params: list[str]) -> list[Path]:
    """One PNG per outage metric: its value against the outage duration, one curve per layout
    and parameter set."""
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
            path = out_dir / f"{metric.split('.', 1)[1].removesuffix('_m')}_vs_outage.png"
            system = next(r["outage.system"] for r in rows if r.get("outage.system"))
            plot_against_outage_duration(path, curves, f"{title} ({system})")
            written.append(path)
    return written
