"""``report.html``: one self-contained page on a run or study folder, to open in a browser.

:func:`write_report` reads only the folder's files (:mod:`bodyfusion.evaluation.report_data`)
and writes ``<folder>/report.html`` with plotly.js and every figure's data embedded: it opens
without a network and can be mailed or archived as one file. A run's page: the metrics table,
the plan view against truth, the horizontal error against time with its 2DRMS band, the NEES
profile, the NIS of each aiding type and the constraint activity
(:mod:`bodyfusion.evaluation.report_figures`), and metrics.json itself. A study's page: its
summary table and each summarised metric against the study's parameter.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import plotly.graph_objects as go
from plotly.offline import get_plotlyjs

from bodyfusion.base.errors import FusionError, InputError
from bodyfusion.evaluation import report_figures as figures
from bodyfusion.evaluation.report_data import RunFolder, StudyFolder, read_folder

REPORT_FILE = "report.html"
PLOT_CONFIG = {"displaylogo": False, "responsive": True}
"""plotly options of every figure: no logo link, resizes with the window."""

STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 1200px; padding: 0 1em; color: #222; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ddd; }
p.meta, p.note { color: #555; font-size: 0.9em; }
div.wide { overflow-x: auto; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
th { background: #f4f4f4; text-align: left; }
pre { background: #f8f8f8; padding: 1em; overflow: auto; font-size: 0.8em; }
"""


def _version() -> str:
    try:
        return version("bodyfusion")
    except PackageNotFoundError:
        return "unknown"


def _cell(value: Any) -> str:
    if value is None or value == "":
        return "<td>–</td>"
    if isinstance(value, bool):
        return f"<td>{value}</td>"
    if isinstance(value, (int, float)):
        return f'<td class="num">{value:.4g}</td>' if isinstance(value, float) else f'<td class="num">{value}</td>'
    try:
        return f'<td class="num">{float(value):.4g}</td>'
    except ValueError:
        return f"<td>{html.escape(str(value))}</td>"


def table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """An HTML table; numbers right-aligned to 4 significant digits, missing cells as a dash."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(_cell(v) for v in row) + "</tr>" for row in rows)
    return f'<div class="wide"><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>'


def _figure(fig: go.Figure | None, div_id: str, missing: str) -> str:
    """The figure's div and the script that draws it (plotly.js is in the page's head), or a
    note saying why there is none."""
    if fig is None:
        return f'<p class="note">{html.escape(missing)}</p>'
    return fig.to_html(full_html=False, include_plotlyjs=False, div_id=div_id, config=PLOT_CONFIG)


def _section(title: str, *parts: str) -> str:
    return f"<section><h2>{html.escape(title)}</h2>{''.join(parts)}</section>"


def _note(text: str) -> str:
    return f'<p class="note">{html.escape(text)}</p>'


def _page(title: str, meta: str, sections: list[str]) -> str:
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{html.escape(title)}</title><style>{STYLE}</style>"
            f'<script type="text/javascript">{get_plotlyjs()}</script></head>\n<body>'
            f'<h1>{html.escape(title)}</h1><p class="meta">{html.escape(meta)}</p>\n'
            + "\n".join(sections) + "\n</body></html>\n")


# --------------------------------------------------------------------------- run


def _system_rows(metrics: dict[str, Any]) -> list[list[Any]]:
    rows = []
    for name, b in metrics.get("systems", {}).items():
        h, v = b.get("horizontal_error_m", {}), b.get("vertical_error_m", {})
        nees = (b.get("health") or {}).get("nees") or {}
        share = nees.get("in_band_fraction")
        alone = (b.get("sensor_alone") or {}).get("horizontal_error_m") or {}
        rows.append([name, b.get("samples"), b.get("distance_m"), h.get("rmse"), h.get("mean"), h.get("p75"),
                     h.get("p95"), h.get("max"), alone.get("p75"), v.get("rmse"), b.get("final_error_pct_distance"),
                     b.get("loop_closure_m"), nees.get("mean"), None if share is None else 100.0 * share])
    return rows


SYSTEM_HEADER = ("system", "samples", "distance m", "h-RMSE m", "h-mean m", "h-p75 m", "h-p95 m", "h-max m",
                 "sensor alone h-p75 m", "v-RMSE m", "final % distance", "loop closure m", "NEES mean",
                 "NEES % in band")


def _findings(metrics: dict[str, Any]) -> str:
    """The run's health findings, one line each (metrics.json ``health.findings``), warnings first."""
    found = sorted((metrics.get("health") or {}).get("findings") or [], key=lambda f: f.get("severity") != "warning")
    if not found:
        return _note("No finding: nothing in this run looked wrong to it.")
    rows = [[f.get("severity"), f.get("system") or "run",
             "" if f.get("t_start") is None else f"{f['t_start']:.1f}–{f['t_end']:.1f} s",
             f.get("message"), f.get("cause"), f.get("advice")] for f in found]
    return table(("severity", "system", "time", "what", "likely cause", "try"), rows)


def _run_facts(run: RunFolder) -> list[list[Any]]:
    m = run.metrics
    tf = m.get("evaluation", {}).get("transform", {})
    c = m.get("constraints") or {}
    rt = m.get("runtime") or {}
    inp = m.get("input") or {}
    facts = [["config", m.get("config")], ["config SHA-256", m.get("config_sha256")],
             ["evaluation alignment", m.get("alignment")], ["alignment rotation deg", tf.get("rotation_deg")],
             ["navigation frame", run.tracks.frame.describe()],
             ["truth in this folder", run.truth_source or "none"],
             ["constraints", c.get("method", "none")], ["input samples dropped", inp.get("dropped_samples")],
             ["input warnings", len(inp.get("warnings") or [])], ["samples", rt.get("samples")],
             ["navigation samples/s", rt.get("samples_per_s")], ["wall time s", rt.get("wall_s")]]
    if isinstance(c.get("smoothed"), dict):
        facts.append(["constrained smoothed samples", c["smoothed"].get("constrained_samples")])
    return facts


def run_page(run: RunFolder) -> str:
    """The page of a run folder."""
    m = run.metrics
    name = Path(str(m.get("config") or run.folder.name)).stem
    warnings = (m.get("input") or {}).get("warnings") or []
    truth_note = (f"Truth from {run.truth_source}; estimates mapped into its frame by the recorded evaluation "
                  "transform and scored at the truth epochs." if run.truth_source else
                  "This folder holds no truth (truth.csv or tum/<system>_truth.txt): the plots show the estimates "
                  "and their uncertainty only; the error statistics above are those metrics.json records.")
    sections = [
        _section("Health findings", _findings(m)),
        _section("Metrics", table(SYSTEM_HEADER, _system_rows(m)), table(("run", "value"), _run_facts(run)),
                 "".join(_note(f"warning: {w}") for w in warnings)),
        _section("Trajectory", _note(truth_note), _figure(figures.plan_view(run.tracks), "plot-trajectory", "")),
        *([_section("Map", _figure(map_, "plot-map", ""))] if (map_ := figures.map_view(run.tracks)) else []),
        _section("Horizontal error", _note("2DRMS = 2 √(σ_E² + σ_N²) of the trajectory covariance: about "
                                           "95–98 % of a consistent filter's horizontal errors lie below it."),
                 _figure(figures.error_vs_time(run.tracks), "plot-error", "")),
        _section("Consistency: NEES", _figure(figures.nees_profile(m), "plot-nees",
                                              "No NEES: the run had no truth to score against.")),
        _section("Consistency: NIS", _figure(figures.nis_means(m), "plot-nis", "No aiding update was made.")),
        _section("Constraint activity",
                 _note("Totals from metrics.json: a run folder records no per-epoch constraint events."),
                 _figure(figures.constraint_activity(m), "plot-constraints", "The layout has no constraints.")),
        _section("metrics.json", f"<details><summary>the whole file</summary><pre>"
                                 f"{html.escape(json.dumps(m, indent=1))}</pre></details>"),
    ]
    meta = f"Run folder {run.folder.resolve()} · bodyfusion {_version()}"
    return _page(f"Run report: {name}", meta, sections)


# --------------------------------------------------------------------------- study


def study_page(study: StudyFolder) -> str:
    """The page of a study folder."""
    s = study.study
    name = s.get("name") or study.folder.name
    counts = ", ".join(f"{k} {s[k]}" for k in ("runs", "done", "failed", "skipped") if k in s)
    meta = (f"Study folder {study.folder.resolve()}" + (f" · {counts}" if counts else "")
            + (f" · results.parquet: {study.runs} runs" if study.runs is not None else "")
            + f" · bodyfusion {_version()}")
    if not study.summary:
        return _page(f"Study report: {name}", meta, [_section("Summary", _note(
            "summary.csv is missing or empty: no run succeeded yet (results.parquet holds the errors)."))])
    header = list(study.summary[0])
    metrics = list(dict.fromkeys(row["metric"] for row in study.summary if row.get("metric")))
    plots = [_figure(figures.study_metric(study.summary, metric), f"plot-metric-{k}", "")
             for k, metric in enumerate(metrics)]
    sections = [
        _section("Summary", _note("summary.csv: per layout, parameter values and outage duration, the statistics "
                                  "of the runs that succeeded (m)."),
                 table(header, [[row.get(h) for h in header] for row in study.summary])),
        _section(f"Metrics against {figures.study_axis(study.summary)}", *plots),
    ]
    return _page(f"Study report: {name}", meta, sections)


# --------------------------------------------------------------------------- entry point


MALFORMED = (AttributeError, IndexError, KeyError, TypeError, ValueError)
"""What reading a folder's documents raises where a value is of another type or shape than the
writers give (an object where a number was, a list cut short...)."""


def write_report(folder: str | Path) -> Path:
    """Write ``report.html`` into a run folder (``fusion run``) or a study folder (``fusion
    study``) from the folder's files only; returns its path. A folder that is neither, or whose
    files are unreadable, raises :class:`~bodyfusion.base.errors.FusionError` naming it."""
    folder = Path(folder)
    try:
        content = read_folder(folder)
        page = run_page(content) if isinstance(content, RunFolder) else study_page(content)
    except MALFORMED as err:  # a document of another shape than the writer's: edited, or another tool's
        run = (folder / "metrics.json").is_file()
        detail = str(err).strip().splitlines()[0][:160] if str(err).strip() else ""
        raise InputError(folder / "metrics.json" if run else folder,
                         ("" if run else "study.json or summary.csv: ") + f"not as bodyfusion writes it "
                         f"({type(err).__name__}: {detail}); write the folder again with the command that made it"
                         ) from None
    path = folder / REPORT_FILE
    try:
        path.write_text(page, encoding="utf-8")
    except OSError as err:
        raise FusionError(f"{path}: cannot write the report: {err.strerror}") from None
    return path
