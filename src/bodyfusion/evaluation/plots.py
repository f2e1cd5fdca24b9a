"""Figures of scored runs (plan view against truth, several methods' tracks of one system,
horizontal error against time with its σ band, error CDF, horizontal NEES against time) and of
studies (an error against the GNSS outage duration).

A run's figures take the run: a :class:`~bodyfusion.evaluation.scored_run.ScoredRun`, such as
the :class:`~bodyfusion.results.run_result.RunResult` a run returns or the
:class:`~bodyfusion.evaluation.scored_run.ScoredTracks` read back from a run folder. Positions
are ENU metres in the run's frame (plan view: east vs north, after the evaluation transform),
time in seconds. Every ``plot_*`` function returns a :class:`matplotlib.figure.Figure`: with ``ax=`` it
draws into that Axes (a panel of the caller's figure) and returns ``ax.figure``; without, it
draws into a new figure of its own. Saving is separate (:func:`save_figure`, any of PNG, PDF,
SVG at a chosen dpi; :func:`write_run_plots` for a run's standard set). New figures use the Agg
canvas directly: no pyplot, no global state, safe in worker processes and without a display.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.backend_bases import RendererBase
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cbook import is_math_text
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.layout_engine import ConstrainedLayoutEngine
from matplotlib.lines import Line2D
from matplotlib.ticker import LogFormatter

from bodyfusion.base.files import replaced_atomically
from bodyfusion.base.sections import FiguresConfig
from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.evaluation.metrics import SystemScore, error_cdf, horizontal_sigma_m, score_systems
from bodyfusion.evaluation.colours import colours, system_colours
from bodyfusion.evaluation.scored_run import ScoredRun
from bodyfusion.evaluation.thinning import thin_index

DPI = FiguresConfig().dpi
"""Resolution of saved figures unless the layout says otherwise, dots per inch."""
FORMATS = ("png", "pdf", "svg")
"""The formats :func:`save_figure` writes."""
BAND_ALPHA = 0.15
"""Opacity of σ and confidence bands: light, drawn behind the lines."""


# --------------------------------------------------------------------------- figures and files


class MeasuredMargins(ConstrainedLayoutEngine):
    """Constrained layout, measured from the labels alone for a figure of one Axes.

    A figure of one subplot gets margins that hold its title, axis labels, tick labels (major
    and minor, as the locators and formatters give them at the limits the Axes will be drawn
    with), the axis offset text and a legend placed to the right of the Axes (as
    :func:`_legend_outside` places it), ``w_pad`` and ``h_pad`` (inches) from the edges: each
    text is measured once, without the trial drawings of every tick and artist that
    constrained layout makes (a run's four figures draw and save in about three quarters of
    its CPU time). Any other figure, and one whose Axes would be left less than a quarter of
    the width or height, gets matplotlib's constrained layout."""

    MIN_FRACTION = 0.25
    """Smallest share of the figure's width and height left to the Axes by measured margins."""

    def execute(self, fig: Figure) -> None:
        axes = fig.axes
        if len(axes) != 1 or axes[0].get_subplotspec() is None:
            return super().execute(fig)
        ax, renderer = axes[0], fig._get_renderer()
        for _ in range(1 if ax.get_aspect() == "auto" else 2):  # an equal-aspect Axes' limits follow its box
            ax.apply_aspect()
            sides = _margins_px(ax, renderer, self._params["w_pad"] * fig.dpi, self._params["h_pad"] * fig.dpi)
            width, height = fig.bbox.width, fig.bbox.height
            left, bottom, right, top = sides[0] / width, sides[1] / height, 1.0 - sides[2] / width, 1.0 - sides[3] / height
            if right - left < self.MIN_FRACTION or top - bottom < self.MIN_FRACTION:
                return super().execute(fig)
            fig.subplotpars.update(left=left, bottom=bottom, right=right, top=top)  # as subplots_adjust sets them
            ax._set_position(ax.get_subplotspec().get_position(fig))


def _text_px(renderer: RendererBase, text: str, size: str | float) -> tuple[float, float]:
    """Width and height (display units) of the one-line ``text`` at font ``size`` as the
    figure's renderer draws it (mathtext between ``$`` too; a line is at least as high as
    ``lp``, as matplotlib lays text out)."""
    if not text:
        return 0.0, 0.0
    font, usetex = FontProperties(size=size), mpl.rcParams["text.usetex"]
    width, height, _ = renderer.get_text_width_height_descent(text, font, ismath="TeX" if usetex else is_math_text(text))
    return width, max(height, renderer.get_text_width_height_descent("lp", font, ismath="TeX" if usetex else False)[1])


def _tick_labels_px(axis: Axis, renderer: RendererBase) -> tuple[float, float, float]:
    """Widest and tallest tick label (major and minor, display units) of ``axis`` at its view
    limits, and the width of the label at its upper end."""
    lo, hi = sorted(axis.get_view_interval())
    size = mpl.rcParams[f"{axis.axis_name}tick.labelsize"]
    labels: dict[float, str] = {}
    for locs, formatter in ((axis.get_minorticklocs(), axis.get_minor_formatter()),
                            (axis.get_majorticklocs(), axis.get_major_formatter())):
        locs = [v for v in locs if lo <= v <= hi]
        labels |= {v: label for v, label in zip(locs, formatter.format_ticks(locs) if locs else []) if label}
    sizes = {label: _text_px(renderer, label, size) for label in set(labels.values())}
    last = sizes[labels[max(labels)]][0] if labels else 0.0
    return max((w for w, _ in sizes.values()), default=0.0), max((h for _, h in sizes.values()), default=0.0), last


def _margins_px(ax: Axes, renderer: RendererBase, w_pad: float, h_pad: float) -> tuple[float, float, float, float]:
    """Left, bottom, right and top margins (display units) that hold ``ax``'s texts and its
    legend to the right, ``w_pad`` (left, right) and ``h_pad`` (bottom, top) from the figure's edges."""
    fig = ax.get_figure(root=True)
    points = fig.dpi / 72.0
    tick = {name: (mpl.rcParams[f"{name}tick.major.size"] + mpl.rcParams[f"{name}tick.major.pad"]) * points
            for name in "xy"}
    x_w, x_h, x_last = _tick_labels_px(ax.xaxis, renderer)
    y_w, _, _ = _tick_labels_px(ax.yaxis, renderer)
    label_size = mpl.rcParams["axes.labelsize"]
    y_label = _text_px(renderer, ax.get_ylabel(), label_size)[1]  # drawn turned by 90°
    x_label = _text_px(renderer, ax.get_xlabel(), label_size)[1]
    title = _text_px(renderer, ax.get_title(), mpl.rcParams["axes.titlesize"])[1]
    offsets = [_text_px(renderer, axis.get_major_formatter().get_offset(), mpl.rcParams[f"{name}tick.labelsize"])[1]
               for axis, name in ((ax.xaxis, "x"), (ax.yaxis, "y"))]
    left = w_pad + y_label + ax.yaxis.labelpad * points + y_w + tick["y"]
    bottom = h_pad + x_label + ax.xaxis.labelpad * points + x_h + tick["x"] + offsets[0]
    top = h_pad + title + mpl.rcParams["axes.titlepad"] * points + offsets[1]
    legend = ax.get_legend()
    if legend is None:
        right = w_pad + x_last / 2.0
    else:  # anchored at 1.02 of the Axes' width: right = w_pad + legend + 0.02 (figure width - left - right)
        right = (w_pad + legend.get_window_extent(renderer).width + 0.02 * (fig.bbox.width - left)) / 1.02
    return left, bottom, right, top


def new_figure(width_in: float = 8.0, height_in: float = 4.5) -> Figure:
    """A figure (inches) on the Agg canvas with :class:`MeasuredMargins` layout (legends outside
    the Axes get their room), not registered with pyplot."""
    fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout=MeasuredMargins())
    FigureCanvasAgg(fig)
    return fig


def _axes(ax: Axes | None, width_in: float = 8.0, height_in: float = 4.5) -> Axes:
    """``ax`` itself, or the one Axes of a new figure."""
    return ax if ax is not None else new_figure(width_in, height_in).add_subplot(1, 1, 1)


def save_figure(fig: Figure, path: str | Path, formats: Sequence[str] = ("png",), dpi: int = DPI) -> list[Path]:
    """Write ``fig`` once per format (:data:`FORMATS`) as ``path`` with that format's suffix
    (a ``.png``/``.pdf``/``.svg`` suffix of ``path`` is replaced); ``dpi`` in dots per inch.
    Creates the folder; each file replaces an earlier one in one step
    (:func:`~bodyfusion.base.files.replaced_atomically`). Returns the files written."""
    path = Path(path)
    if path.suffix.lower().lstrip(".") in FORMATS:
        path = path.with_suffix("")
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise ValueError(f"unknown figure format(s) {unknown}: expected some of {list(FORMATS)}")
    path.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for fmt in formats:
        out = path.with_name(f"{path.name}.{fmt}")
        with replaced_atomically(out) as partial:
            fig.savefig(partial, dpi=dpi, format=fmt)
        written.append(out)
    return written


_SUPERSCRIPTS = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


class DecadeLabels(LogFormatter):
    """Base-10 log-axis tick labels in plain text: 10ᵏ (Unicode superscripts) at the decades,
    the number (``%g``) between them, on the ticks matplotlib's default log formatter labels —
    without mathtext, whose first use costs a process about 0.2 s."""

    def __init__(self, labelOnlyBase: bool = True) -> None:
        super().__init__(base=10.0, labelOnlyBase=labelOnlyBase)

    def _num_to_string(self, x: float, vmin: float, vmax: float) -> str:
        decade = round(math.log10(x))
        if math.isclose(x, 10.0**decade, rel_tol=1e-9):
            return "10" + str(decade).translate(_SUPERSCRIPTS)
        return f"{x:g}"


def _log_y(ax: Axes) -> None:
    """The vertical axis of ``ax`` on a base-10 log scale, labelled by :class:`DecadeLabels`
    (minor ticks as matplotlib labels them: only when the axis spans few decades)."""
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(DecadeLabels())
    ax.yaxis.set_minor_formatter(DecadeLabels(labelOnlyBase=False))


def _darker(colour: str, factor: float = 0.55) -> tuple[float, float, float]:
    r, g, b = to_rgb(colour)
    return (r * factor, g * factor, b * factor)


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


def _legend_outside(ax: Axes, handles: list | None = None, **kwargs) -> None:
    """The legend to the right of the axes, clear of the data."""
    extra = {"handles": handles} if handles is not None else {}
    ax.legend(**extra, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="small", **kwargs)


# --------------------------------------------------------------------------- plan view


def _draw_track(ax: Axes, pos: np.ndarray, colour, label: str, ls: str = "-") -> None:
    """A track (N, ≥2) east, north, m: a line, an open circle at its start, a filled square at its end."""
    idx = thin_index(len(pos))
    ax.plot(pos[idx, 0], pos[idx, 1], ls=ls, color=colour, lw=1.2, label=label, zorder=3)
    if len(pos):
        ax.plot(pos[0, 0], pos[0, 1], "o", color=colour, ms=7, mfc="white", mew=1.5, zorder=4)
        ax.plot(pos[-1, 0], pos[-1, 1], "s", color=colour, ms=6, zorder=4)


def _draw_truth(ax: Axes, truth: TruthTrack, colour, label: str) -> None:
    """Dense truth as a thin dashed line, sparse truth (surveyed points) as crosses."""
    p = np.asarray(truth.pos_n, dtype=float)
    if truth.sparse:
        ax.plot(p[:, 0], p[:, 1], "x", color=colour, ms=8, mew=2, ls="none", label=f"{label} (surveyed points)",
                zorder=2)
    else:
        idx = thin_index(len(p))
        ax.plot(p[idx, 0], p[idx, 1], "--", color=colour, lw=1.0, label=label, zorder=2)


def _finish_plan_view(ax: Axes, title: str, drawn: bool, north_note: str = "") -> None:
    ax.set_title(title)
    ax.set_xlabel("east [m]")
    ax.set_ylabel(f"north [m]{north_note}")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    if not drawn:
        _no_data(ax, "no trajectories")
        return
    handles, _ = ax.get_legend_handles_labels()
    marks = [Line2D([], [], marker="o", color="0.3", mfc="white", ls="none", label="start"),
             Line2D([], [], marker="s", color="0.3", ls="none", label="end")]
    _legend_outside(ax, handles + marks)


def _rmse_label(name: str, score: SystemScore | None) -> str:
    if score is None:
        return name
    return f"{name} (RMSE {score.metrics['horizontal_error_m']['rmse']:.2f} m)"


def _frame_note(run: ScoredRun) -> str:
    """Where "north" of the plan view is, when the run's own frame is drawn (no evaluation
    rotation) and its azimuths are not from North."""
    frame = run.frame
    if frame.heading_reference == "north" or run.transform.rotation_rad != 0.0:
        return ""
    return f" (heading of {frame.heading_reference})" if frame.heading_reference != "unknown" else " (heading unknown)"


def plot_trajectories(run: ScoredRun, *, ax: Axes | None = None) -> Figure:
    """Plan view (east vs north, m, equal aspect) of each system's estimate of ``run`` after its
    evaluation alignment as a solid line, with its truth as a dashed line in a darker shade
    (surveyed points as crosses); open circles mark the starts, squares the ends. Where the run
    is scored the legend gives each system's horizontal RMSE."""
    transform = run.transform
    colour = system_colours(run)
    ax = _axes(ax, 8.0, 6.0)
    for name, traj in run.trajectories.items():
        _draw_track(ax, transform.apply(np.asarray(traj.pos_n, dtype=float)), colour[name],
                    _rmse_label(name, run.scores.get(name)))
    for name, truth in run.truths.items():
        _draw_truth(ax, truth, _darker(colour[name]), f"{name} truth")
    title = "Trajectories (plan view)"
    if transform.rotation_rad != 0.0 or np.any(np.asarray(transform.translation_m) != 0):
        title += f", estimates aligned: rotation {np.degrees(transform.rotation_rad):.1f}°"
    _finish_plan_view(ax, title, bool(run.trajectories or run.truths), _frame_note(run))
    return ax.figure


def plot_method_comparison(runs: Mapping[str, ScoredRun], system: str, *, ax: Axes | None = None) -> Figure:
    """Plan view (east vs north, m) of ``system``'s track as several runs estimated it (label →
    run, e.g. ``filter``, ``rts``, ``fb-rts``), each after its run's evaluation alignment, in its
    own colour, against the truth of the first run that has one (black, dashed); with truth the
    legend gives each method's horizontal RMSE. Starts and ends marked as in :func:`plot_trajectories`."""
    tracks = {label: run for label, run in runs.items() if system in run.trajectories}
    colour = colours(tracks)
    aligned = {label: Trajectory(t.t, run.transform.apply(np.asarray(t.pos_n, dtype=float)), t.pos_sd, t.pos_cov_en)
               for label, run in tracks.items() for t in (run.trajectories[system],)}
    truth = next((run.truths[system] for run in runs.values() if system in run.truths), None)
    scores: dict[str, SystemScore] = {}
    if truth is not None and aligned:
        _, scores = score_systems(aligned, dict.fromkeys(aligned, truth), alignment="none")
    ax = _axes(ax, 8.0, 6.0)
    if truth is not None:
        _draw_truth(ax, truth, "k", "truth")
    for label, traj in aligned.items():
        _draw_track(ax, np.asarray(traj.pos_n), colour[label], _rmse_label(label, scores.get(label)))
    _finish_plan_view(ax, f"{system + ': ' if system else ''}methods compared (plan view)",
                      bool(tracks or truth is not None))
    return ax.figure


# --------------------------------------------------------------------------- errors


def plot_error_vs_time(run: ScoredRun, *, ax: Axes | None = None) -> Figure:
    """Horizontal error (m) against time (s) at the truth epochs, one line per scored system of
    ``run``, with its 2DRMS band (0 to 2 √(σ_E² + σ_N²), about 95–98 % of a consistent filter's
    errors) shaded lightly behind it, its edge dotted. The vertical axis follows the errors: a
    band wider than them is cut at the top rather than squeezing the errors flat."""
    scores, estimates = run.scores, run.trajectories
    ax = _axes(ax)
    colour = system_colours(run)
    top = 0.0
    for name, sc in scores.items():
        if name in estimates:
            band = 2.0 * horizontal_sigma_m(estimates[name], sc.t)
            idx = thin_index(sc.t.size)
            ax.fill_between(sc.t[idx], 0.0, band[idx], color=colour[name], alpha=BAND_ALPHA / 2, lw=0, zorder=1)
            ax.plot(sc.t[idx], band[idx], ":", color=colour[name], lw=0.9, zorder=2, label=f"{name} 2DRMS")
        idx = thin_index(sc.t.size)
        sparse_like = sc.t.size < 50
        ax.plot(sc.t[idx], sc.horizontal_error_m[idx], "-o" if sparse_like else "-", ms=4, lw=1.0,
                color=colour[name], label=name, zorder=3)
        finite = sc.horizontal_error_m[np.isfinite(sc.horizontal_error_m)]
        top = max(top, float(finite.max()) if finite.size else 0.0)
    ax.set_title("Horizontal error against time")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("horizontal error [m]")
    ax.set_ylim(0.0, 1.1 * top if top > 0 else None)
    ax.grid(True, alpha=0.3)
    if scores:
        _legend_outside(ax)
    else:
        _no_data(ax, "no truth: nothing scored")
    return ax.figure


def plot_error_cdf(run: ScoredRun, *, ax: Axes | None = None) -> Figure:
    """Empirical CDF of the horizontal error (m) per scored system of ``run``."""
    scores = run.scores
    ax = _axes(ax)
    colour = system_colours(run)
    for name, sc in scores.items():
        e, p = error_cdf(sc.horizontal_error_m)
        if e.size:
            ax.step(np.concatenate(([0.0], e)), np.concatenate(([0.0], p)), where="post",
                    color=colour[name], lw=1.2, label=name)
    ax.set_title("CDF of horizontal error")
    ax.set_xlabel("horizontal error [m]")
    ax.set_ylabel("cumulative probability")
    ax.set_ylim(0, 1.02)
    ax.set_xlim(left=0)
    ax.grid(True, alpha=0.3)
    if scores:
        _legend_outside(ax)
    else:
        _no_data(ax, "no truth: nothing scored")
    return ax.figure


def plot_nees(run: ScoredRun, title: str = "Horizontal position NEES against time",
              *, ax: Axes | None = None) -> Figure:
    """Horizontal NEES (2 dof) against time (s) per scored system of ``run``, log scale, with
    the two-sided 95 % chi-square band of one epoch (of a Monte-Carlo mean: of ``runs`` runs)
    shaded and the expected value (the dof) as a line; the legend gives each system's mean NEES
    and the share of epochs inside the band."""
    tracks = run.nees
    ax = _axes(ax)
    colour = system_colours(run)
    low = []
    for name, track in tracks.items():
        ok = np.isfinite(track.nees) & (track.nees > 0)
        t, v = track.t[ok], track.nees[ok]
        if not v.size:
            continue
        idx = thin_index(v.size)
        s = track.summary()
        ax.plot(t[idx], v[idx], "-", lw=0.8, color=colour[name], zorder=3,
                label=f"{name} (mean {s['mean']:.3g}, {100 * s['in_band_fraction']:.0f} % in band)")
        low.append(np.percentile(v, 1))
    bands = {(track.dof, track.runs): track.band() for track in tracks.values()}
    for (dof, runs), (lo, hi) in sorted(bands.items()):
        of = f", mean of {runs} runs" if runs > 1 else ""
        ax.axhspan(lo, hi, color="0.5", alpha=BAND_ALPHA, lw=0, zorder=1,
                   label=f"95 % band, {dof} dof{of} [{lo:.3g}, {hi:.3g}]")
    for dof in sorted({dof for dof, _ in bands}):
        ax.axhline(dof, color="k", lw=1.0, ls="--", zorder=2, label=f"expected ({dof})")
    if low:  # the first epochs (a covariance and an error near 0) would stretch the axis for decades
        ax.set_ylim(bottom=min(min(low), *(lo / 3.0 for lo, _ in bands.values())))
    else:
        _no_data(ax, "no finite NEES")
    fitted = sorted({track.alignment for track in tracks.values()} - {"none"})
    ax.set_title(title + (f" (frame fitted: {', '.join(fitted)})" if fitted else ""))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("NEES [-]")
    _log_y(ax)
    ax.grid(True, which="major", alpha=0.3)
    if tracks:
        _legend_outside(ax)
    return ax.figure


# --------------------------------------------------------------------------- studies


def plot_against_outage_duration(curves: Mapping[str, Mapping[float, Sequence[float]]], title: str,
                                 ylabel: str = "horizontal error [m]", *, ax: Axes | None = None) -> Figure:
    """An error (m) against the GNSS outage duration (s): per curve (label → duration → one value
    per run) each run as a small dot, the mean as a line with its 95 % confidence interval (Student
    t) as a light error bar, and the 90th percentile dashed. Curves are set a little apart along
    the duration axis so their bars do not overlap. The vertical axis follows the runs, means and
    percentiles: the interval of a few runs, wider than them, is cut off rather than drawn to scale."""
    # scipy.stats is slow to import; only study plots need it
    from scipy.stats import t as student_t

    ax = _axes(ax)
    colour = colours(sorted(curves))  # by label, as the study report's HTML figure
    span = max((abs(float(d)) for by_duration in curves.values() for d in by_duration), default=0.0) or 1.0
    top = 0.0
    for k, (label, by_duration) in enumerate(curves.items()):
        d = np.array(sorted(by_duration), dtype=float) + 0.012 * span * (k - (len(curves) - 1) / 2)
        runs = [np.asarray(by_duration[key], dtype=float) for key in sorted(by_duration)]
        runs = [v[np.isfinite(v)] for v in runs]
        mean = np.array([v.mean() if v.size else np.nan for v in runs])
        half = np.array([student_t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size) if v.size > 1 else np.nan
                         for v in runs])
        p90 = np.array([np.percentile(v, 90) if v.size else np.nan for v in runs])
        sizes = sorted({v.size for v in runs})
        n = f"n = {sizes[0]}" if len(sizes) == 1 else f"n = {sizes[0]}–{sizes[-1]}"
        ax.errorbar(d, mean, yerr=half, fmt="none", ecolor=colour[label], elinewidth=1.0, capsize=3, alpha=0.5,
                    zorder=1)
        ax.plot(np.repeat(d, [v.size for v in runs]), np.concatenate(runs), ".", color=colour[label], ms=3,
                alpha=0.5, zorder=2)
        ax.plot(d, mean, "-o", ms=4, color=colour[label], zorder=3, label=f"{label} (mean, {n})")
        ax.plot(d, p90, "--", color=colour[label], lw=1.0, alpha=0.8, zorder=3, label=f"{label} (90th percentile)")
        values = np.concatenate([*runs, mean, p90])
        values = values[np.isfinite(values)]
        top = max(top, float(values.max()) if values.size else 0.0)
    ax.set_title(title)
    ax.set_xlabel("GNSS outage duration [s]")
    ax.set_ylabel(ylabel)
    ax.set_ylim(0.0, 1.1 * top if top > 0 else None)
    ax.grid(True, alpha=0.3)
    if curves:
        _legend_outside(ax, title="dots: runs; bars: 95 % confidence\nof the mean", title_fontsize="small")
    else:
        _no_data(ax, "no successful runs")
    return ax.figure


# --------------------------------------------------------------------------- a run's set


RUN_FIGURES = ("trajectory", "error_vs_time", "error_cdf", "nees")
"""A run's figures, in the order :func:`write_run_plots` writes them; all but the trajectory only
where something was scored."""


def run_figure_names(run: ScoredRun) -> list[str]:
    """The figures of :data:`RUN_FIGURES` ``run`` draws."""
    return list(RUN_FIGURES) if run.scores else ["trajectory"]


_RUN_PLOTS = {"trajectory": plot_trajectories, "error_vs_time": plot_error_vs_time, "error_cdf": plot_error_cdf,
              "nees": plot_nees}


def write_run_plots(out_dir: str | Path, run: ScoredRun, figures: FiguresConfig | None = None,
                    names: Sequence[str] | None = None) -> list[Path]:
    """``run``'s plots in ``out_dir`` in the ``figures`` formats and dpi (default PNG): trajectory;
    where something was scored, error_vs_time (with the 2DRMS bands), error_cdf and nees
    (:func:`run_figure_names`); ``names``: only those of them. Returns the files written."""
    figures = figures or FiguresConfig()
    out_dir = Path(out_dir)
    return [path for name in run_figure_names(run) if names is None or name in names
            for path in save_figure(_RUN_PLOTS[name](run), out_dir / name, figures.formats, figures.dpi)]
