"""Generalisation benchmark: every recording with truth in ``../shared/data`` at default settings.

Each data set has ONE layout template (what is worn, where the files are, their units and
frames — nothing tuned); every recording of the set is run through it with the project's
defaults and scored with the project's scorer (:func:`bodyfusion.evaluation.metrics.score_systems`):

* ``foot_vicon_pyshoe`` (21 trials, one foot, 200 Hz): horizontal RMSE, first-3 m alignment;
  beside it PyShoe's own published trajectory (``pyshoe.csv``) scored the same way, and the
  run's ``zupt_mean_nis``;
* ``dual_foot_vicon_hu2025`` (both feet, 60 Hz): horizontal RMSE per foot, one alignment for
  both feet; beside it Hu & Hu's EKF-ZUPT (their own alignment, from the data's table);
* ``single_foot_loop_xio`` (one foot, 400 Hz, a closed loop): loop-closure error; beside it
  x-io's published 0.421 m;
* ``handheld_phone_ipin2023`` (nine phone logs): the 75th percentile of the horizontal error
  at the surveyed points (the competition's metric); beside it the phone's GNSS alone, scored
  the same way (its first fix before GNSS starts, its last held after it stops, so both are scored
  at every surveyed point; ``gnss_coverage`` is the share of points inside the GNSS span), and the
  ratio PDR+GNSS / GNSS.

Each data set ends with a summary line ``<set>: median=<m> p90=<m> worst=<m> failed=<n>``.
``--set KEY=VALUE`` overrides every layout (e.g. ``--set smoother.kind=rts``; ``feet.KEY`` sets KEY
of every foot system, e.g. ``--set feet.detector.kind=shoe``); ``--only SET``
runs one set; ``--json FILE`` writes every row. Without ``../shared/data`` (or ``--data``) the
benchmark says so and exits 0.

Usage: python benchmarks/generalisation.py [--only pyshoe|vicon|xio|ipin] [--set K=V]... [--workers N]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data"

FOOT_PREFIX = "feet."
"""``--set feet.KEY=VALUE`` sets ``systems.<name>.KEY`` of every foot_ins system of every layout."""

XIO_PUBLISHED_LOOP_M = 0.421
"""x-io Gait-Tracking's own final displacement on long_walk.csv (data README)."""


@dataclass
class Row:
    """One recording's result: ``value`` is the data set's figure of merit (m)."""

    dataset: str
    recording: str
    value: float | None = None
    peer: float | None = None
    extra: dict = field(default_factory=dict)
    error: str | None = None


# --------------------------------------------------------------------------- templates


def pyshoe_layout(trial: Path) -> dict:
    """One foot, 200 Hz, MicroStrain (z down at rest); truth x = north, y = east."""
    return {
        "name": f"pyshoe_{trial.name}",
        "systems": {"foot": {
            "plugin": "foot_ins",
            "data": {"path": str(trial / "imu.csv"), "time_column": "t",
                     "acc_columns": ["acc_x", "acc_y", "acc_z"], "gyro_columns": ["gyro_x", "gyro_y", "gyro_z"]},
        }},
        "truth": {"path": str(trial / "truth.csv"), "time_column": "t", "systems": {"foot": ["x", "y"]},
                  "frame": "ned"},
        "output": {"plots": False},
    }


def vicon_layout(folder: Path) -> dict:
    """Both feet, 60 Hz sample counter, nothing but their data columns (one frame for both is the
    default); Vicon truth with z down."""
    def foot(side: str) -> dict:
        return {"plugin": "foot_ins",
                "data": {"path": str(folder / f"imuMeas{side}.csv"), "time_column": "time_index",
                         "time_scale": 1 / 60, "acc_columns": ["acc_x", "acc_y", "acc_z"],
                         "gyro_columns": ["gyro_x", "gyro_y", "gyro_z"]}}
    return {
        "name": "dual_foot_vicon",
        "systems": {"left_foot": foot("Left"), "right_foot": foot("Right")},
        "truth": {"path": str(folder / "positionGt.csv"), "time_column": "time_index", "time_scale": 1 / 60,
                  "systems": {"left_foot": ["pos_left_x", "pos_left_y", "pos_left_z"],
                              "right_foot": ["pos_right_x", "pos_right_y", "pos_right_z"]},
                  "frame": ["x", "-y", "-z"]},
        "output": {"plots": False},
    }


def xio_layout(csv: Path) -> dict:
    """One foot, NGIMU in g and deg/s; the walk is a loop."""
    return {
        "name": "xio_long_walk",
        "systems": {"foot": {
            "plugin": "foot_ins",
            "data": {"path": str(csv), "time_column": "Time (s)",
                     "acc_columns": [f"Accelerometer {a} (g)" for a in "XYZ"],
                     "gyro_columns": [f"Gyroscope {a} (deg/s)" for a in "XYZ"],
                     "acc_unit": "g", "gyro_unit": "deg/s"},
        }},
        "truth": {"loop": True},
        "output": {"plots": False},
    }


def ipin_layout(log: Path) -> dict:
    """A phone in the hand: PDR + the phone's GNSS, scored at the log's surveyed points."""
    return {
        "name": f"ipin_{log.stem}",
        "systems": {"hand_phone": {"plugin": "hand_pdr", "phone_log": str(log), "gnss": {"format": "phone_log"}}},
        "truth": {"path": str(log), "format": "phone_log", "score_systems": ["hand_phone"], "alignment": "none"},
        "output": {"plots": False},
    }


# --------------------------------------------------------------------------- scoring


def _run(layout: dict, overrides: list[str]):
    from bodyfusion.core.layout import load_layout
    from bodyfusion.core.run import run_layout

    feet = [name for name, section in layout["systems"].items() if section["plugin"] == "foot_ins"]
    overrides = [o for o in overrides if not o.startswith(FOOT_PREFIX)] + [
        f"systems.{name}.{o[len(FOOT_PREFIX):]}" for o in overrides if o.startswith(FOOT_PREFIX) for name in feet]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{layout['name']}.yaml"
        path.write_text(yaml.safe_dump(layout, sort_keys=False))
        return run_layout(load_layout(path, overrides))


def _zupt_nis(result, name: str) -> float | None:
    return result.systems[name].diagnostics().get("zupt_mean_nis")


def pyshoe_row(trial: Path, overrides: list[str]) -> list[Row]:
    from bodyfusion.evaluation.metrics import score_systems
    from bodyfusion.io.truth import read_truth_csv
    from bodyfusion.base.types import Trajectory

    result = _run(pyshoe_layout(trial), overrides)
    score = result.scores["foot"].metrics["horizontal_error_m"]["rmse"]
    peer = read_truth_csv(trial / "pyshoe.csv", position_columns={"foot": ["x", "y"]}, time_column="t")["foot"]
    ned_to_enu = np.column_stack([peer.pos_n[:, 1], peer.pos_n[:, 0], np.zeros(len(peer.t))])
    _, peer_scores = score_systems({"foot": Trajectory(peer.t, ned_to_enu, np.zeros_like(ned_to_enu))},
                                   {"foot": result.truths["foot"]})
    return [Row("pyshoe", trial.name, score, peer_scores["foot"].metrics["horizontal_error_m"]["rmse"],
                {"zupt_mean_nis": _zupt_nis(result, "foot"), **_notes(result)})]


def _hu_ekf_zupt(folder: Path) -> dict[str, float]:
    """Hu & Hu's EKF-ZUPT horizontal RMS per foot from the data's own table."""
    for line in (folder / "statistics_report_hor.csv").read_text().splitlines()[1:]:
        cells = [c.strip() for c in line.split(",")]
        if cells[0] == "EKF-ZUPT":
            return {"right_foot": float(cells[2]), "left_foot": float(cells[5])}
    return {}


def vicon_rows(folder: Path, overrides: list[str]) -> list[Row]:
    result = _run(vicon_layout(folder), overrides)
    peers = _hu_ekf_zupt(folder)
    return [Row("vicon", name, result.scores[name].metrics["horizontal_error_m"]["rmse"], peers.get(name),
                {"zupt_mean_nis": _zupt_nis(result, name), **_notes(result)})
            for name in ("left_foot", "right_foot")]


def xio_row(csv: Path, overrides: list[str]) -> list[Row]:
    from bodyfusion.evaluation.metrics import loop_closure_m

    result = _run(xio_layout(csv), overrides)
    return [Row("xio", csv.stem, loop_closure_m(result.trajectories["foot"]), XIO_PUBLISHED_LOOP_M,
                {"zupt_mean_nis": _zupt_nis(result, "foot"), **_notes(result)})]


def ipin_row(log: Path, overrides: list[str]) -> list[Row]:
    from bodyfusion.evaluation.metrics import score_systems
    from bodyfusion.io.phone_log import read_getsensordata
    from bodyfusion.base.types import Trajectory

    result = _run(ipin_layout(log), overrides)
    p75 = result.scores["hand_phone"].metrics["horizontal_error_m"]["p75"]
    gnss = read_getsensordata(log).gnss
    truth = result.truths["hand_phone"]
    # GNSS alone as its user has it: the first fix before GNSS starts, the last one held after it
    # stops, so both are scored at every surveyed point
    t = np.concatenate([[min(truth.t[0], gnss.t[0]) - 1.0], gnss.t, [max(truth.t[-1], gnss.t[-1]) + 1.0]])
    enu = gnss.enu(result.geodetic_origin)
    enu = np.vstack([enu[:1], enu, enu[-1:]])
    _, gnss_scores = score_systems({"hand_phone": Trajectory(t, enu, np.zeros_like(enu))}, {"hand_phone": truth},
                                   alignment="none")
    gnss_p75 = gnss_scores["hand_phone"].metrics["horizontal_error_m"]["p75"]
    covered = float(np.mean((truth.t >= gnss.t[0]) & (truth.t <= gnss.t[-1])))
    return [Row("ipin", log.stem.replace("IPIN2023_T3_", ""), p75, gnss_p75,
                {"ratio": p75 / gnss_p75, "gnss_coverage": covered, **_notes(result)})]


def _notes(result) -> dict:
    notes = result.input_report.notes
    return {"notes": notes} if notes else {}


DATASETS: dict[str, tuple[str, Callable[[Path], list[Path]], Callable[[Path, list[str]], list[Row]], str, str]] = {
    # key: (folder, recordings in it, runner, figure, peer)
    "pyshoe": ("foot_vicon_pyshoe", lambda d: sorted(p for p in d.iterdir() if (p / "imu.csv").exists()),
               pyshoe_row, "h-RMSE m", "PyShoe m"),
    "vicon": ("dual_foot_vicon_hu2025", lambda d: [d], vicon_rows, "h-RMSE m", "Hu&Hu EKF m"),
    "xio": ("single_foot_loop_xio", lambda d: [d / "long_walk.csv"], xio_row, "loop m", "x-io m"),
    "ipin": ("handheld_phone_ipin2023", lambda d: sorted(d.glob("IPIN2023_T3_*.txt")), ipin_row,
             "p75 m", "GNSS p75 m"),
}


def _job(key: str, recording: str, overrides: list[str]) -> list[Row]:
    runner = DATASETS[key][2]
    try:
        return runner(Path(recording), overrides)
    except Exception as err:  # a failed recording is a result of the benchmark, not its end
        detail = str(err).splitlines()[0] if str(err) else type(err).__name__
        if os.environ.get("BENCH_TRACEBACK"):
            traceback.print_exc()
        return [Row(key, Path(recording).name, error=f"{type(err).__name__}: {detail}")]


def summary(rows: list[Row]) -> str:
    values = np.array([r.value for r in rows if r.value is not None and np.isfinite(r.value)])
    failed = sum(r.value is None or not np.isfinite(r.value) for r in rows)
    if values.size == 0:
        return f"median=nan p90=nan worst=nan failed={failed}"
    return (f"median={np.median(values):.3f} p90={np.percentile(values, 90):.3f} worst={values.max():.3f} "
            f"failed={failed}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the shared data folder")
    parser.add_argument("--only", choices=sorted(DATASETS), action="append", help="run only these data sets")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="layout override applied to every recording")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--json", type=Path, help="write every row to this file")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"generalisation: no shared data at {args.data}; skipped")
        return 0
    keys = args.only or list(DATASETS)
    jobs = [(key, str(rec)) for key in keys for rec in DATASETS[key][1](args.data / DATASETS[key][0])]
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        futures = [pool.submit(_job, key, rec, args.overrides) for key, rec in jobs]
        results = [row for f in futures for row in f.result()]
    print(f"defaults{'' if not args.overrides else ' with ' + ' '.join(args.overrides)}")
    lines = []
    for key in keys:
        rows = [r for r in results if r.dataset == key]
        _, _, _, figure, peer = DATASETS[key]
        print(f"\n{DATASETS[key][0]}: {figure} (peer: {peer})")
        for r in rows:
            if r.error:
                print(f"  {r.recording:<40} FAILED {r.error}")
                continue
            extra = " ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                             for k, v in r.extra.items() if k != "notes" and v is not None)
            peer_txt = f"{r.peer:8.3f}" if r.peer is not None else "       -"
            print(f"  {r.recording:<40} {r.value:8.3f} {peer_txt}  {extra}")
        line = f"{key}: {summary(rows)}"
        peers = [r for r in rows if r.peer is not None and r.value is not None]
        if peers:
            line += f" peer_median={np.median([r.peer for r in peers]):.3f} peer_worst={max(r.peer for r in peers):.3f}"
        if key == "ipin":
            ratios = [r.extra["ratio"] for r in rows if r.error is None]
            line += (f" ratio_median={np.median(ratios):.2f} better_or_equal={sum(x <= 1.0 for x in ratios)}/{len(rows)}"
                     if ratios else "")
        lines.append(line)
    print()
    for line in lines:
        print(line)
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
