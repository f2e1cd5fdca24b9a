"""The interactive (plotly) figures of ``report.html``: a run's plan view against truth,
horizontal error against time with its 2DRMS band, NEES profile, NIS per aiding type and
constraint activity; a study's metrics against its parameter.

Positions are ENU metres (estimates after the evaluation transform, in the truth's frame),
times seconds. Long series are thinned to :data:`~bodyfusion.evaluation.thinning.MAX_POINTS`
points per trace and sent as float32, so a report stays a few MB.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from bodyfusion.evaluation.colours import PALETTE, colours, system_colours
from bodyfusion.evaluation.metrics import horizontal_sigma_m
from bodyfusion.io.gnss import enu_to_geodetic
from bodyfusion.evaluation.scored_run import ScoredRun
from bodyfusion.evaluation.thinning import thin_index

HEIGHT_PX = 460


def _colour(i: int) -> str:
    """The i-th colour of the palette, for what is no system (a bar of counts)."""
    return PALETTE[i % len(PALETTE)]


def _rgba(colour: str, alpha: float, factor: float = 1.0) -> str:
    """``#rrggbb`` as ``rgba(...)``, each channel times ``factor`` (< 1: darker)."""
    r, g, b = (int(colour[k:k + 2], 16) * factor for k in (1, 3, 5))
    return f"rgba({r:.0f},{g:.0f},{b:.0f},{alpha})"


def _f32(values: np.ndarray) -> np.ndarray:
    return np.asarray(values, dtype=np.float32)


def _layout(fig: go.Figure, title: str, x: str, y: str, **extra: Any) -> go.Figure:
    fig.update_layout(**{"title": title, "template": "plotly_white", "height": HEIGHT_PX, "xaxis_title": x,
                         "yaxis_title": y, "hovermode": "closest", "margin": {"l": 60, "r": 20, "t": 50, "b": 50},
                         **extra})
    return fig


def _legend_marks(fig: go.Figure) -> None:
    """Legend entries that explain the start and end markers."""
    for name, symbol in (("start", "circle-open"), ("end", "square")):
        fig.add_scatter(x=[None], y=[None], mode="markers", name=name, legendgroup="marks",
                        marker={"symbol": symbol, "size": 10, "color": "#555"})


def plan_view(run: ScoredRun) -> go.Figure:
    """Estimates (solid, after the evaluation transform) against truth (dashed, darker; surveyed
    points as crosses), east vs north at equal scale; circles at the starts, squares at the ends."""
    fig = go.Figure()
    palette = system_colours(run)
    for name, traj in run.trajectories.items():
        colour, truth = palette[name], run.truths.get(name)
        if truth is not None:
            p = truth.pos_n[thin_index(len(truth.t))] if not truth.sparse else truth.pos_n
            fig.add_scatter(x=_f32(p[:, 0]), y=_f32(p[:, 1]), name=f"{name} truth", legendgroup=name,
                            mode="markers" if truth.sparse else "lines",
                            line={"color": _rgba(colour, 1.0, 0.55), "width": 1.2, "dash": "dash"},
                            marker={"symbol": "x", "size": 9, "color": _rgba(colour, 1.0, 0.55)})
        pos = run.transform.apply(traj.pos_n)
        idx = thin_index(len(pos))
        score = run.scores.get(name)
        rmse = f" (RMSE {score.metrics['horizontal_error_m']['rmse']:.2f} m)" if score is not None else ""
        fig.add_scatter(x=_f32(pos[idx, 0]), y=_f32(pos[idx, 1]), customdata=_f32(traj.t[idx]), mode="lines",
                        name=name + rmse, legendgroup=name, line={"color": colour, "width": 1.6},
                        hovertemplate="t %{customdata:.2f} s<br>east %{x:.2f} m<br>north %{y:.2f} m")
        if len(pos):
            for k, symbol in ((0, "circle-open"), (-1, "square")):
                fig.add_scatter(x=[float(pos[k, 0])], y=[float(pos[k, 1])], mode="markers", legendgroup=name,
                                showlegend=False, hoverinfo="skip",
                                marker={"symbol": symbol, "size": 11, "color": colour, "line": {"width": 2}})
    _legend_marks(fig)
    rotation = np.degrees(run.transform.rotation_rad)
    title = "Trajectories, plan view" + (f" (estimates aligned: rotation {rotation:.1f}°)" if rotation else "")
    _layout(fig, title, "east [m]", "north [m]", height=620)
    fig.update_yaxes(scaleanchor="x", scaleratio=1)
    return fig


def map_view(run: ScoredRun) -> go.Figure | None:
    """Each system's track (and its truth, dashed) in WGS-84 longitude and latitude about the
    run's geodetic origin, at equal ground scale along both axes, hover giving the time and the
    coordinates: a map without tiles (nothing fetched when the page is viewed). None where the
    frame has no geodetic origin."""
    origin = run.frame.geodetic_origin
    if origin is None:
        return None
    fig = go.Figure()
    palette = system_colours(run)
    for name, traj in run.trajectories.items():
        colour, truth = palette[name], run.truths.get(name)
        if truth is not None:
            k = thin_index(len(truth.t)) if not truth.sparse else slice(None)
            llh = enu_to_geodetic(np.nan_to_num(truth.pos_n[k], nan=0.0), origin)
            fig.add_scatter(x=llh[:, 1], y=llh[:, 0], name=f"{name} truth", legendgroup=name,
                            mode="markers" if truth.sparse else "lines",
                            line={"color": _rgba(colour, 1.0, 0.55), "width": 1.2, "dash": "dash"},
                            marker={"symbol": "x", "size": 9, "color": _rgba(colour, 1.0, 0.55)})
        idx = thin_index(len(traj.t))
        llh = enu_to_geodetic(np.nan_to_num(traj.pos_n[idx], nan=0.0), origin)
        fig.add_scatter(x=llh[:, 1], y=llh[:, 0], customdata=_f32(traj.t[idx]), mode="lines", name=name,
                        legendgroup=name, line={"color": colour, "width": 1.6},
                        hovertemplate="t %{customdata:.2f} s<br>lat %{y:.7f}°<br>lon %{x:.7f}°")
    _layout(fig, f"Map: WGS-84 about the origin {origin[0]:.5f}°, {origin[1]:.5f}°", "longitude [°]",
            "latitude [°]", height=620)
    fig.update_yaxes(scaleanchor="x", scaleratio=1.0 / np.cos(np.radians(origin[0])), tickformat=".5f")
    fig.update_xaxes(tickformat=".5f")
    return fig


def error_vs_time(run: ScoredRun) -> go.Figure:
    """Horizontal error (m) against time (s) at the truth epochs with each system's 2DRMS band
    (0 to 2 √(σ_E² + σ_N²)), the axis following the errors; without truth, the 2DRMS alone."""
    fig = go.Figure()
    top = 0.0
    palette = system_colours(run)
    for name, traj in run.trajectories.items():
        colour, score = palette[name], run.scores.get(name)
        t = score.t if score is not None else traj.t
        idx = thin_index(len(t))
        band = 2.0 * horizontal_sigma_m(traj, t[idx])
        fig.add_scatter(x=_f32(t[idx]), y=_f32(band), name=f"{name} 2DRMS", legendgroup=name, fill="tozeroy",
                        fillcolor=_rgba(colour, 0.08), line={"color": colour, "width": 1, "dash": "dot"})
        if score is not None:
            err = score.horizontal_error_m
            fig.add_scatter(x=_f32(t[idx]), y=_f32(err[idx]), name=name, legendgroup=name,
                            line={"color": colour}, mode="lines+markers" if len(t) < 50 else "lines")
            top = max(top, float(np.nanmax(err)) if np.isfinite(err).any() else 0.0)
    title = "Horizontal error against time, with the 2DRMS band" if run.scores else \
        "Horizontal 2DRMS against time (no truth in this folder: no errors)"
    _layout(fig, title, "time [s]", "horizontal error [m]" if run.scores else "2DRMS [m]")
    if top > 0:
        fig.update_yaxes(range=[0.0, 1.1 * top])
    return fig


def _health(metrics: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Name → health block of every system and aiding source in metrics.json."""
    blocks = {**metrics.get("systems", {}), **metrics.get("aiding", {})}
    return {name: block["health"] for name, block in blocks.items() if isinstance(block.get("health"), dict)}


def nees_profile(metrics: dict[str, Any]) -> go.Figure | None:
    """Each system's horizontal NEES, mean per time bin (metrics.json ``health.nees.profile``),
    log scale, against the 95 % band of one epoch and the expected value; None without truth."""
    tracks = {name: h["nees"] for name, h in _health(metrics).items() if isinstance(h.get("nees"), dict)}
    if not tracks:
        return None
    fig = go.Figure()
    palette = colours(metrics.get("systems", {}))  # every system's place, as in the run's other figures
    for name, nees in tracks.items():
        prof = nees.get("profile") or {}
        mean, share = nees.get("mean"), nees.get("in_band_fraction")
        facts = ([f"mean {mean:.3g}"] if mean is not None else []) + (
            [f"{100 * share:.0f} % of epochs in band"] if share is not None else [])
        label = f"{name} ({', '.join(facts)})" if facts else name
        fig.add_scatter(x=prof.get("t_s", []), y=prof.get("mean", []), mode="lines+markers", name=label,
                        line={"color": palette[name]})
    first = next(iter(tracks.values()))
    lo, hi = first.get("band") or (None, None)
    if lo is not None:
        fig.add_hrect(y0=lo, y1=hi, fillcolor="grey", opacity=0.15, line_width=0, layer="below")
    fig.add_hline(y=first.get("expected", 2.0), line_dash="dash", line_color="black",
                  annotation_text=f"expected ({first.get('expected', 2.0):g}); band: 95 % of one epoch")
    _layout(fig, "Horizontal NEES against time (bin means)", "time [s]", "NEES [-]")
    fig.update_yaxes(type="log")
    return fig


def nis_means(metrics: dict[str, Any]) -> go.Figure | None:
    """Mean NIS of every aiding type of every system (bars) beside its expected value, the
    update's dimension (black marks); None where no update was made."""
    rows = [(name, kind, tally) for name, h in _health(metrics).items()
            for kind, tally in (h.get("nis") or {}).items() if tally.get("count") and tally.get("mean") is not None]
    if not rows:
        return None
    labels = [f"{name} · {kind}" for name, kind, _ in rows]
    fig = go.Figure()
    fig.add_bar(x=labels, y=[t["mean"] for _, _, t in rows], name="mean NIS", marker_color=_colour(0),
                customdata=[[t["count"], t.get("beyond_gate", 0)] for _, _, t in rows],
                hovertemplate="%{x}<br>mean %{y:.3g}<br>%{customdata[0]} updates, %{customdata[1]} beyond the gate")
    fig.add_scatter(x=labels, y=[t["expected"] for _, _, t in rows], mode="markers", name="expected (dof)",
                    marker={"symbol": "line-ew-open", "size": 40, "color": "black", "line": {"width": 3}})
    return _layout(fig, "Mean NIS per aiding type", "system · aiding", "NIS [-]")


def constraint_activity(metrics: dict[str, Any]) -> go.Figure | None:
    """The constraint totals of metrics.json: epochs, activations, solver fallbacks and
    non-converged solves (counts); the largest violation before and after the correction (m).
    None when the layout has no constraints."""
    c = metrics.get("constraints")
    if not c or "epochs" not in c:
        return None
    fig = make_subplots(rows=1, cols=2, column_widths=[0.6, 0.4],
                        subplot_titles=("constraint epochs and activations", "largest violation [m]"))
    counts = {"epochs": c.get("epochs"), "activations": c.get("activations"),
              "solver fallbacks": c.get("solver_fallbacks"), "not converged": c.get("not_converged")}
    counts = {k: v for k, v in counts.items() if v is not None}
    fig.add_bar(x=list(counts), y=list(counts.values()), marker_color=_colour(0), name="count", row=1, col=1)
    fig.add_bar(x=["before", "after"], y=[c.get("max_violation_before_m"), c.get("max_violation_after_m")],
                marker_color=[_colour(1), _colour(2)], name="violation", row=1, col=2)
    _layout(fig, f"Constraint activity ({c.get('method', '?')}), totals of the run", "", "", showlegend=False,
            margin={"l": 60, "r": 20, "t": 90, "b": 50})
    fig.update_yaxes(title_text="count", row=1, col=1)
    return fig


# --------------------------------------------------------------------------- studies


def _number(cell: str | None) -> float | None:
    try:
        return float(cell) if cell not in (None, "") else None
    except ValueError:
        return None


def study_axis(summary: list[dict[str, str]]) -> str:
    """The column a study's metrics are drawn against: the outage duration where the study has
    outages, else its first parameter, else the layout."""
    columns = list(summary[0]) if summary else []
    if any(_number(row.get("outage_duration_s")) is not None for row in summary):
        return "outage_duration_s"
    return next((c for c in columns if c.startswith("param.")), "layout")


def confidence_half_width(sd: float | None, runs: float | None) -> float | None:
    """Half the 95 % confidence interval of a mean of ``runs`` values of sample standard
    deviation ``sd`` (Student t), the statistic the study's PNG plots draw too
    (:func:`~bodyfusion.evaluation.plots.plot_against_outage_duration`); None below two runs."""
    if sd is None or runs is None or runs < 2:
        return None
    from scipy.stats import t as student_t  # slow to import; only the study figures need it

    return float(student_t.ppf(0.975, runs - 1) * sd / np.sqrt(runs))


def study_metric(summary: list[dict[str, str]], metric: str) -> go.Figure:
    """One summary metric (m) against :func:`study_axis`: per layout and other parameter
    values the mean with its 95 % confidence interval (:func:`confidence_half_width`, as the
    PNG plots draw it) and the 90th percentile dotted; hover gives the runs."""
    axis = study_axis(summary)
    keys = [c for c in (summary[0] if summary else {}) if c == "layout" or c.startswith("param.")]
    groups: dict[str, list[dict[str, str]]] = {}
    for row in summary:
        if row.get("metric") == metric:
            label = " ".join(row[k] if k == "layout" else f"{k[len('param.'):]}={row[k]}" for k in keys if k != axis)
            groups.setdefault(label or metric, []).append(row)
    fig = go.Figure()
    numeric = all(_number(r.get(axis)) is not None for rows in groups.values() for r in rows)
    palette = colours(sorted(groups))  # by label, as the study's PNG plots
    for label, rows in groups.items():
        rows = sorted(rows, key=lambda r: _number(r.get(axis)) or 0.0) if numeric else rows
        x = [_number(r.get(axis)) if numeric else r.get(axis) for r in rows]
        fig.add_scatter(x=x, y=[_number(r.get("mean")) for r in rows], mode="lines+markers", name=f"{label} mean",
                        legendgroup=label, line={"color": palette[label]},
                        error_y={"type": "data", "array": [confidence_half_width(_number(r.get("sd")),
                                                                                 _number(r.get("runs"))) or 0.0
                                                           for r in rows],
                                 "thickness": 1, "color": _rgba(palette[label], 0.5)},
                        customdata=[[r.get("runs"), r.get("failed")] for r in rows],
                        hovertemplate="%{x}: mean %{y:.3g}<br>%{customdata[0]} runs, %{customdata[1]} failed")
        fig.add_scatter(x=x, y=[_number(r.get("p90")) for r in rows], mode="lines", name=f"{label} p90",
                        legendgroup=label, line={"color": palette[label], "dash": "dot", "width": 1})
    title = f"{metric} against {axis} (mean with its 95 % confidence interval, 90th percentile dotted)"
    return _layout(fig, title, axis, "value [m]" if "_m." in metric or metric.endswith("_m") else "value")
