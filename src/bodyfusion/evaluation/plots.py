"""PNG plots of scored runs (plan view against truth, horizontal error vs time, error CDF,
horizontal NEES vs time) and of studies (an error against the GNSS outage duration).

Positions are ENU metres (plan view: east vs north), time in seconds. Uses
``matplotlib.figure.Figure`` with the Agg canvas directly: no pyplot, no global state,
safe in worker processes and without a display.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bodyfusion.evaluation.consistency import NeesTrack
from bodyfusion.evaluation.metrics import PlanarTransform, SystemScore, error_cdf
from bodyfusion.base.types import Trajectory, TruthTrack

DPI = 120
MAX_POINTS = 20000
"""Most points drawn per line (longer series are decimated evenly)."""


def _new_figure(width_in: float = 7.0, height_in: float = 5.0) -> Figure:
    fig = Figure(figsize=(width_in, height_in), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, format="png")
    fig.clear()


def _colours(names: list[str]) -> dict[str, str]:
    cycle = [f"C{i % 10}" for i in range(len(names))]
    return dict(zip(names, cycle))


def _no_data(ax, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


def plot_trajectories(
    path: Path,
    estimates: Mapping[str, Trajectory],
    scores: Mapping[str, SystemScore] | None,
    transform: PlanarTransform,
    truths: Mapping[str, TruthTrack] | None,
) -> None:
    """Plan view (east vs north, m, equal aspect) of each estimate after ``transform``, with truth.

    Dense truth is drawn as a dashed line, sparse truth (surveyed points) as markers; a circle
    marks each estimate's start. With ``scores`` the legend gives each system's horizontal RMSE.
    """
    truths = truths or {}
    scores = scores or {}
    names = list(dict.fromkeys([*estimates, *truths]))
    colour = _colours(names)
    fig = _new_figure(7.0, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    for name, traj in estimates.items():
        pos = transform.apply(np.asarray(traj.pos_n, dtype=float))
        label = name
        if name in scores:
            rmse = scores[name].metrics["horizontal_error_m"]["rmse"]
            label = f"{name} (RMSE {rmse:.2f} m)"
        ax.plot(pos[:, 0], pos[:, 1], "-", color=colour[name], lw=1.2, label=label)
        if len(pos):
            ax.plot(pos[0, 0], pos[0, 1], "o", color=colour[name], ms=6, mfc="none")
    for name, truth in truths.items():
        p = np.asarray(truth.pos_n, dtype=float)
        if truth.sparse:
            ax.plot(p[:, 0], p[:, 1], "x", color=colour[name], ms=8, mew=2, ls="none",
                    label=f"{name} truth (surveyed points)")
        else:
            ax.plot(p[:, 0], p[:, 1], "--", color=colour[name], lw=1.0, alpha=0.7, label=f"{name} truth")
    if not names:
        _no_data(ax, "no trajectories")
    ident = PlanarTransform.identity()
    aligned = not (
        transform.rotation_rad == ident.rotation_rad
        and np.all(np.asarray(transform.translation_m) == 0)
        and transform.vertical_offset_m == 0
    )
    title = "Trajectories (plan view)"
    if aligned:
        title += f", estimates aligned: rotation {np.degrees(transform.rotation_rad):.1f}°"
    ax.set_title(title)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    if names:
        ax.legend(loc="best", fontsize="small")
    _save(fig, path)


def plot_error_vs_time(path: Path, scores: Mapping[str, SystemScore]) -> None:
    """Horizontal error (m) against time (s) at the truth epochs, one line per system."""
    fig = _new_figure()
    ax = fig.add_subplot(1, 1, 1)
    colour = _colours(list(scores))
    for name, sc in scores.items():
        sparse_like = len(sc.t) < 50
        ax.plot(sc.t, sc.horizontal_error_m, "-o" if sparse_like else "-", ms=4, lw=1.0,
                color=colour[name], label=name)
    if not scores:
        _no_data(ax, "no truth: nothing scored")
    ax.set_title("Horizontal error against time")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("horizontal error [m]")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    if scores:
        ax.legend(loc="best", fontsize="small")
    _save(fig, path)


def plot_error_cdf(path: Path, scores: Mapping[str, SystemScore]) -> None:
    """Empirical CDF of horizontal error (m) per system."""
    fig = _new_figure()
    ax = fig.add_subplot(1, 1, 1)
    colour = _colours(list(scores))
    for name, sc in scores.items():
        e, p = error_cdf(sc.horizontal_error_m)
        if e.size:
            ax.step(np.concatenate(([0.0], e)), np.concatenate(([0.0], p)), where="post",
                    color=colour[name], lw=1.2, label=name)
    if not scores:
        _no_data(ax, "no truth: nothing scored")
    ax.set_title("CDF of horizontal error")
    ax.set_xlabel("horizontal error [m]")
    ax.set_ylabel("cumulative probability")
    ax.set_ylim(0, 1.02)
    ax.set_xlim(left=0)
    ax.grid(True, alpha=0.3)
    if scores:
        ax.legend(loc="lower right", fontsize="small")
    _save(fig, path)


def plot_nees(path: Path, tracks: Mapping[str, NeesTrack], title: str = "Horizontal position NEES against time") -> None:
    """Horizontal NEES (2 dof) against time (s) per system, log scale, with the two-sided 95 %
    chi-square band of one epoch (of a Monte-Carlo mean: of ``runs`` runs) shaded and the
    expected value (the dof) as a line; the legend gives each system's mean NEES and the
    share of epochs inside the band."""
    crowded = len(tracks) > 4  # the legend goes beside the axes
    fig = _new_figure(10.0 if crowded else 7.0, 5.0)
    ax = fig.add_subplot(1, 1, 1)
    colour = _colours(list(tracks))
    low = []
    for name, track in tracks.items():
        ok = np.isfinite(track.nees) & (track.nees > 0)
        t, v = track.t[ok], track.nees[ok]
        if not v.size:
            continue
        step = max(1, v.size // MAX_POINTS)
        s = track.summary()
        ax.plot(t[::step], v[::step], "-", lw=0.8, color=colour[name],
                label=f"{name} (mean {s['mean']:.3g}, {100 * s['in_band_fraction']:.0f} % in band)")
        low.append(np.percentile(v, 1))
    bands = {(track.dof, track.runs): track.band() for track in tracks.values()}
    for (dof, runs), (lo, hi) in sorted(bands.items()):
        of = f", mean of {runs} runs" if runs > 1 else ""
        ax.axhspan(lo, hi, color="0.5", alpha=0.15, lw=0, label=f"95 % band, {dof} dof{of} [{lo:.3g}, {hi:.3g}]")
    for dof in sorted({dof for dof, _ in bands}):
        ax.axhline(dof, color="k", lw=1.0, ls="--", label=f"expected ({dof})")
    if low:  # the first epochs (a covariance and an error near 0) would stretch the axis for decades
        ax.set_ylim(bottom=min(min(low), *(lo / 3.0 for lo, _ in bands.values())))
    else:
        _no_data(ax, "no finite NEES")
    fitted = sorted({track.alignment for track in tracks.values()} - {"none"})
    ax.set_title(title + (f" (frame fitted: {', '.join(fitted)})" if fitted else ""))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("NEES [-]")
    ax.set_yscale("log")
    ax.grid(True, which="major", alpha=0.3)
    if crowded:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")
        fig.subplots_adjust(right=0.62)
    elif tracks:
        ax.legend(loc="best", fontsize="small")
    _save(fig, path)


def plot_against_outage_duration(path: Path, curves: Mapping[str, Mapping[float, Sequence[float]]],
                                 title: str, ylabel: str = "horizontal error [m]") -> None:
    """An error (m) against the GNSS outage duration (s): per curve (label → duration → one value
    per run) the mean with its 95 % confidence band (Student t) and the 90th percentile, dashed."""
    from scipy.stats import t as student_t  # scipy.stats is slow to import; only study plots need it

    fig = _new_figure()
    ax = fig.add_subplot(1, 1, 1)
    colour = _colours(list(curves))
    for label, by_duration in curves.items():
        d = np.array(sorted(by_duration), dtype=float)
        runs = [np.asarray(by_duration[k], dtype=float) for k in sorted(by_duration)]
        runs = [v[np.isfinite(v)] for v in runs]
        mean = np.array([v.mean() if v.size else np.nan for v in runs])
        half = np.array([student_t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size) if v.size > 1 else np.nan
                         for v in runs])
        p90 = np.array([np.percentile(v, 90) if v.size else np.nan for v in runs])
        n = min((v.size for v in runs), default=0)
        ax.plot(d, mean, "-o", ms=4, color=colour[label], label=f"{label} (mean, n ≥ {n})")
        ax.fill_between(d, mean - half, mean + half, color=colour[label], alpha=0.2, lw=0)
        ax.plot(d, p90, "--", color=colour[label], lw=1.0, alpha=0.8, label=f"{label} (90th percentile)")
    if not curves:
        _no_data(ax, "no successful runs")
    ax.set_title(title)
    ax.set_xlabel("GNSS outage duration [s]")
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0)
    ax.set_xlim(left=0)
    ax.grid(True, alpha=0.3)
    if curves:
        ax.legend(loc="lower right", fontsize="small", title="band: 95 % confidence of the mean",
                  title_fontsize="small")
    _save(fig, path)
