"""Consistency harness: is each estimator's horizontal covariance as large as its error?

Simulates ``configs/consistency_walk.yaml`` (both feet and a hand-held phone, one-minute laps
of a rectangle; every filter told its simulated sensor's own error model) for ``--seeds``
seeds and walks of ``--minutes`` minutes, runs each case on every walk and prints, per case
and walk length, the horizontal position NEES (2 dof; a consistent estimator averages 2):

* at 5, 30 and 60 minutes: the mean over the runs and over the minute ending there (the end
  of a shorter walk where the time is past it);
* over the whole walk: the mean NEES and the share of epochs inside one epoch's two-sided
  95 % band [0.0506, 7.38];
* the horizontal RMSE (m), the mean over the runs;

then the time profile of the longest walk (the Monte-Carlo NEES in the minute ending at each
time), beside the 95 % band of a mean over that many runs. Cases (``--cases``):

* ``forward``, ``rts``, ``fb``, ``fb-rts``: each foot alone (``smoother.kind``; both feet
  count, two runs a seed);
* ``dual-foot``: both feet within 0.9 m (the scenario's fuser: projection at stance starts);
* ``foot-hand``: the left foot and the phone (PDR + GNSS, masked 120–180 s) within 1.5 m,
  a row for each.

Nothing here is tuned: the layouts are the scenario's with the defaults of every estimator.
Writes into ``--out``: ``results.json`` (every run's figures and the profiles) and
``nees_profile_<minutes>min.png``; the simulations go to ``--out``/sim and are removed after
each seed unless ``--keep``. A run that fails is reported and left out; results.json is
rewritten after every seed, so a stopped harness leaves the runs it made.

Usage: python examples/consistency.py [--seeds 20] [--minutes 5 30 60] [--cases ...]
                                      [--quick] [--out out/consistency] [--keep]
``--quick``: 3 seeds of 5 minutes. The full run (20 seeds, 5 + 30 + 60 minutes) takes about
2 hours on one core.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.evaluation.consistency import NeesTrack, chi2_band
from bodyfusion.evaluation.plots import plot_nees, save_figure
from bodyfusion.evaluation.scored_run import ScoredTracks
from bodyfusion.sim import simulate

SCENARIO = Path(__file__).resolve().parents[1] / "configs" / "consistency_walk.yaml"
CHECKPOINTS_MIN = (5, 30, 60)
"""Times (min) the NEES is reported at."""
PROFILE_MIN = (1, 2, 5, 10, 15, 20, 30, 40, 50, 60)
"""Times (min) of the printed profile."""
WINDOW_S = 60.0
"""The NEES at a time is the mean over the window of this length ending there."""
GRID_S = 1.0
"""Spacing (s) of the common time grid the runs' NEES are sampled on."""
FEET = ("left_foot", "right_foot")


@dataclass(frozen=True)
class Case:
    """A layout derived from the scenario's: the ``systems`` kept (every one scored), the
    scenario's constraints among them and its fuser when ``constrained`` (else none), and the
    smoother; ``rows``: the systems reported together (name → systems)."""

    label: str
    systems: tuple[str, ...]
    constrained: bool
    smoother: str = "none"
    rows: dict[str, tuple[str, ...]] = field(default_factory=dict)


CASES = {
    "forward": Case("forward filter", FEET, False, rows={"feet": FEET}),
    "rts": Case("RTS", FEET, False, "rts", rows={"feet": FEET}),
    "fb": Case("FB", FEET, False, "fb", rows={"feet": FEET}),
    "fb-rts": Case("FB-RTS", FEET, False, "fb-rts", rows={"feet": FEET}),
    "dual-foot": Case("dual foot, 0.9 m", FEET, True, rows={"feet": FEET}),
    "foot-hand": Case("foot + hand, 1.5 m", ("left_foot", "hand_phone"), True,
                      rows={"foot": ("left_foot",), "hand": ("hand_phone",)}),
}


def case_layout(config: dict, case: Case, path: Path) -> Path:
    """Write the case's layout, derived from the simulated ``config``, to ``path``."""
    keep = set(case.systems)
    layout = {k: v for k, v in config.items() if k not in ("systems", "constraints", "outages", "fuser", "smoother")}
    layout["systems"] = {name: section for name, section in config["systems"].items() if name in keep}
    outages = [o for o in config.get("outages", []) if o["system"] in keep]
    if outages:
        layout["outages"] = outages
    if case.constrained:
        layout["constraints"] = [c for c in config["constraints"] if set(c["between"]) <= keep]
        layout["fuser"] = config["fuser"]
    layout["smoother"] = {"kind": case.smoother}
    path.write_text(yaml.safe_dump(layout, sort_keys=False))
    return path


@dataclass
class Runs:
    """The runs of one row (case, walk, systems): NEES on the common grid, per-run figures."""

    grid: np.ndarray
    nees: list[np.ndarray] = field(default_factory=list)
    mean_nees: list[float] = field(default_factory=list)
    in_band: list[float] = field(default_factory=list)
    rmse: list[float] = field(default_factory=list)
    failed: int = 0

    def add(self, track: NeesTrack, rmse: float) -> None:
        """One run's NEES track (sampled at the grid times: the epoch at or after each) and RMSE (m)."""
        k = np.minimum(np.searchsorted(track.t, self.grid), track.t.size - 1)
        self.nees.append(track.nees[k])
        summary = track.summary()
        self.mean_nees.append(summary["mean"])
        self.in_band.append(summary["in_band_fraction"])
        self.rmse.append(rmse)

    def monte_carlo(self) -> np.ndarray:
        """The mean NEES over the runs at each grid time."""
        return np.nanmean(np.vstack(self.nees), axis=0) if self.nees else np.full(self.grid.size, np.nan)

    def at(self, minutes: float) -> float:
        """The Monte-Carlo NEES over the window ending at ``minutes`` (the walk's end if earlier);
        NaN if the walk ends more than a window before it."""
        end = min(60.0 * minutes, self.grid[-1])
        if 60.0 * minutes - end > WINDOW_S:
            return float("nan")
        window = (self.grid > end - WINDOW_S) & (self.grid <= end)
        return float(np.nanmean(self.monte_carlo()[window]))


def run_seed(seed: int, minutes: int, cases: list[str], out: Path, keep: bool,
             table: dict[tuple[str, int, str], Runs]) -> None:
    """Simulate one walk and run every case on it; add the runs to ``table``."""
    sim_dir = out / "sim" / f"{minutes}min_seed{seed}"
    sim = simulate(SCENARIO, sim_dir, seed=seed, overrides=[f"path.laps={minutes}"], overwrite=True)
    config = yaml.safe_load(sim.config_path.read_text())
    grid = np.arange(0.0, sim.duration_s, GRID_S)
    line = []
    for key in cases:
        case = CASES[key]
        rows = {row: table.setdefault((key, minutes, row), Runs(grid)) for row in case.rows}
        t0 = time.perf_counter()
        try:
            result = run_layout(load_layout(case_layout(config, case, sim_dir / f"{key}.yaml")), seed=seed)
        except Exception as err:  # noqa: BLE001 - the harness reports a failing estimator and goes on
            for runs in rows.values():
                runs.failed += 1
            line.append(f"{key} FAILED ({type(err).__name__}: {err})")
            continue
        for row, names in case.rows.items():
            for name in names:
                rows[row].add(result.nees[name], result.scores[name].metrics["horizontal_error_m"]["rmse"])
        figures = ", ".join(f"{name} {result.nees[name].summary()['mean']:.3g}" for name in case.systems)
        line.append(f"{key} NEES {figures} ({time.perf_counter() - t0:.0f} s)")
    print(f"{minutes} min, seed {seed} ({sim.duration_s:.0f} s): " + "; ".join(line), flush=True)
    if not keep:
        shutil.rmtree(sim_dir)


def print_table(table: dict[tuple[str, int, str], Runs]) -> None:
    head = "".join(f"{f'NEES@{m}min':>11}" for m in CHECKPOINTS_MIN)
    print(f"\n{'case':<30}{'walk':>6}{'runs':>6}{head}{'mean NEES':>11}{'in band':>9}{'RMSE m':>8}")
    for (key, m, row), runs in table.items():
        label = CASES[key].label + (f" ({row})" if len(CASES[key].rows) > 1 else "")
        n = len(runs.nees)
        if not n:
            print(f"{label:<30}{m:>5}'{n:>6}  all {runs.failed} failed")
            continue
        at = "".join(f"{runs.at(c):>11.3g}" if c <= m else f"{'-':>11}" for c in CHECKPOINTS_MIN)
        failed = f"  ({runs.failed} failed)" if runs.failed else ""
        print(f"{label:<30}{m:>5}'{n:>6}{at}{np.mean(runs.mean_nees):>11.3g}{np.mean(runs.in_band):>9.2f}"
              f"{np.mean(runs.rmse):>8.3f}{failed}")


def print_profile(table: dict[tuple[str, int, str], Runs], minutes: int) -> None:
    times = [p for p in PROFILE_MIN if p <= minutes]
    rows = {k: v for k, v in table.items() if k[1] == minutes and v.nees}
    if not rows:
        return
    print(f"\nTime profile of the {minutes}-minute walk: Monte-Carlo NEES in the minute ending at each time")
    print(f"{'case':<30}{'runs':>6}" + "".join(f"{f'{p} min':>9}" for p in times) + "   95 % band of the mean")
    for (key, _, row), runs in rows.items():
        label = CASES[key].label + (f" ({row})" if len(CASES[key].rows) > 1 else "")
        lo, hi = chi2_band(2, runs=len(runs.nees))
        print(f"{label:<30}{len(runs.nees):>6}" + "".join(f"{runs.at(p):>9.3g}" for p in times)
              + f"   [{lo:.2f}, {hi:.2f}]")


def save(table: dict[tuple[str, int, str], Runs], minutes: list[int], out: Path, plots: bool = True) -> None:
    """results.json and (``plots``) the profile plots."""
    doc = []
    for (key, m, row), runs in table.items():
        mc = runs.monte_carlo()
        per_minute = [float(np.nanmean(mc[(runs.grid > t - WINDOW_S) & (runs.grid <= t)]))
                      for t in np.arange(WINDOW_S, runs.grid[-1] + WINDOW_S, WINDOW_S)] if runs.nees else []
        doc.append({"case": key, "label": CASES[key].label, "row": row, "minutes": m, "runs": len(runs.nees),
                    "failed": runs.failed, "nees_at_min": {str(c): runs.at(c) for c in CHECKPOINTS_MIN if c <= m},
                    "mean_nees": runs.mean_nees, "in_band_fraction": runs.in_band, "rmse_m": runs.rmse,
                    "monte_carlo_nees_per_minute": per_minute})
    (out / "results.json").write_text(json.dumps(doc, indent=1, allow_nan=True) + "\n")
    for m in minutes if plots else []:
        tracks = {CASES[key].label + (f" ({row})" if len(CASES[key].rows) > 1 else ""):
                  NeesTrack(runs.grid, runs.monte_carlo(), runs=len(runs.nees))
                  for (key, mm, row), runs in table.items() if mm == m and runs.nees}
        save_figure(plot_nees(ScoredTracks(nees=tracks), title=f"Monte-Carlo horizontal NEES, {m}-minute walks"),
                    out / f"nees_profile_{m}min.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--minutes", type=int, nargs="+", default=[5, 30, 60])
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument("--quick", action="store_true", help="3 seeds of 5 minutes")
    ap.add_argument("--out", type=Path, default=Path("out/consistency"))
    ap.add_argument("--keep", action="store_true", help="keep the simulated walks")
    args = ap.parse_args()
    seeds, minutes = (3, [5]) if args.quick else (args.seeds, sorted(args.minutes))
    args.out.mkdir(parents=True, exist_ok=True)
    table: dict[tuple[str, int, str], Runs] = {}
    t0 = time.perf_counter()
    for m in minutes:
        for seed in range(seeds):
            run_seed(seed, m, args.cases, args.out, args.keep, table)
            save(table, minutes, args.out, plots=False)  # the runs so far, should the harness be stopped
    table = dict(sorted(table.items(), key=lambda kv: (list(CASES).index(kv[0][0]), kv[0][1])))
    print(f"\nHorizontal NEES (2 dof, expected 2; one epoch's 95 % band [0.0506, 7.38]) and RMSE, "
          f"{seeds} seed(s), {time.perf_counter() - t0:.0f} s")
    print_table(table)
    print_profile(table, minutes[-1])
    save(table, minutes, args.out)
    print(f"\nwrote {args.out / 'results.json'} and nees_profile_<minutes>min.png")


if __name__ == "__main__":
    main()
