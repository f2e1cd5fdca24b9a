"""Generalisation benchmark: every recording with truth in ``../shared/data``, and simulated gaits, at defaults.

Each data set has ONE layout template (what is worn, where the files are, their units and
frames — nothing tuned, no heading, no limit); every recording of the set is run through it
with the project's defaults and scored with the project's scorer
(:func:`bodyfusion.evaluation.metrics.score_systems`):

* ``foot_vicon_pyshoe`` (21 trials, one foot, 200 Hz): horizontal RMSE, first-3 m alignment;
  beside it PyShoe's own published trajectory (``pyshoe.csv``) scored the same way;
* ``dual_foot_vicon_hu2025`` (both feet, 60 Hz): horizontal RMSE per foot in one joint frame
  (one alignment for both feet), the feet on their own (``vicon``) and held by the body's
  default limit (``vicon_limit``); beside it Hu & Hu's EKF-ZUPT (their own alignment, from the
  data's table);
* ``single_foot_loop_xio`` (one foot, 400 Hz, a closed loop): loop-closure error; beside it
  x-io's published 0.421 m;
* ``handheld_phone_ipin2023`` (nine phone logs): the 75th percentile of the horizontal error
  at the surveyed points (the competition's metric); beside it the phone's GNSS alone as the
  run itself reports it (metrics.json ``sensor_alone``: the last fix at or before each point),
  and the ratio PDR+GNSS / GNSS;
* ``sim`` (simulated with truth, seed 1, both feet run from their data columns alone, first-3 m
  alignment): a walk, a long consumer-grade walk, stairs, a run, and a run with no still instant
  whose gyroscope clips in every swing (``scenarios/running_rolling.yaml``).

Every foot's row carries the detector's decisions (stance share, stances missed and filled by
the watchdog, clipped runs) and its motion, from the run's own stride table (the majority of
its strides' ``motion``, stairs up and down counted as ``stairs``, with the share of each). After each data set's summary line
``<set>: median=<m> p90=<m> worst=<m> failed=<n>``, the foot recordings are summed up by
motion: ``motion <kind>: n=<recordings> median=<m> worst=<m>`` (a recording counts under its
majority motion; ``mixed`` where none has 70 % of the strides).

``--set KEY=VALUE`` overrides every layout (e.g. ``--set smoother.kind=rts``; ``feet.KEY`` sets KEY
of every foot system, e.g. ``--set feet.detector.kind=shoe``); ``--only SET`` runs one set;
``--json FILE`` writes every row. Without ``../shared/data`` (or ``--data``) only the
simulations run.

Usage: python benchmarks/generalisation.py [--only pyshoe|vicon|vicon_limit|xio|ipin|sim] [--set K=V]... [--workers N]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import traceback
from collections import Counter
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
SIMULATIONS = {
    "walk": ROOT / "configs" / "sim_dual_foot_square.yaml",
    "walk_consumer": ROOT / "configs" / "sim_dual_foot_consumer_walk.yaml",
    "stairs": ROOT / "configs" / "sim_stairs.yaml",
    "run": ROOT / "configs" / "sim_running.yaml",
    "run_rolling_clipped": ROOT / "benchmarks" / "scenarios" / "running_rolling.yaml",
}
"""Simulated recordings (name → scenario), each simulated with seed 1."""
MIXED_SHARE = 0.7
"""A recording whose commonest stride motion has less than this share is ``mixed``."""


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


def vicon_layout(folder: Path, limit: bool = False) -> dict:
    """Both feet, 60 Hz sample counter, nothing but their data columns (one frame for both is the
    default), with ``limit`` the body's default limit between them; Vicon truth with z down."""
    def foot(side: str) -> dict:
        return {"plugin": "foot_ins",
                "data": {"path": str(folder / f"imuMeas{side}.csv"), "time_column": "time_index",
                         "time_scale": 1 / 60, "acc_columns": ["acc_x", "acc_y", "acc_z"],
                         "gyro_columns": ["gyro_x", "gyro_y", "gyro_z"]}}
    return {
        "name": "dual_foot_vicon",
        "systems": {"left_foot": foot("Left"), "right_foot": foot("Right")},
        **({"constraints": [{"between": ["left_foot", "right_foot"]}]} if limit else {}),
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


def simulated_layout(folder: Path) -> dict:
    """The feet of a simulation (``fusion simulate``'s ``config.yaml`` in ``folder``) from their data
    columns alone (no stance labels, heading, filter or detector settings), its truth aligned on
    the first 3 m as a recording's would be."""
    generated = yaml.safe_load((folder / "config.yaml").read_text())
    systems = {}
    for name, section in generated["systems"].items():
        data = {k: v for k, v in section["data"].items() if k != "stance_column"}
        systems[name] = {"plugin": "foot_ins", "data": {**data, "path": str(folder / data["path"])}}
    return {"name": f"sim_{folder.name}", "systems": systems,
            "truth": {"path": str(folder / "truth.csv"), "format": "long", "alignment": "first_3m"},
            "output": {"plots": False}}


# --------------------------------------------------------------------------- scoring


def _run(layout: dict, overrides: list[str]):
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import run_layout

    feet = [name for name, section in layout["systems"].items() if section["plugin"] == "foot_ins"]
    overrides = [o for o in overrides if not o.startswith(FOOT_PREFIX)] + [
        f"systems.{name}.{o[len(FOOT_PREFIX):]}" for o in overrides if o.startswith(FOOT_PREFIX) for name in feet]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{layout['name']}.yaml"
        path.write_text(yaml.safe_dump(layout, sort_keys=False))
        return run_layout(load_layout(path, overrides))


def _foot_notes(result, name: str) -> dict:
    """The detector's decisions and the motion of a foot, and the run's warnings about it."""
    system = result.systems[name]
    d = system.diagnostics()
    motions = Counter(m.replace("_up", "").replace("_down", "") for m in system.strides().get("motion", []))
    strides = sum(motions.values())
    top, count = motions.most_common(1)[0] if strides else ("none", 0)
    clipped = getattr(system, "clipping", {})
    return {"motion": top if strides and count >= MIXED_SHARE * strides else "mixed",
            "motions": {m: round(c / strides, 2) for m, c in motions.most_common()} if strides else {},
            "stance": d["stance_fraction"], "missed": d["missed_stances"], "fallback": d["fallback_updates"],
            "clipped_runs": sum(len(c.runs) for c in clipped.values()), "zupt_nis": d["zupt_mean_nis"],
            "findings": [f.kind for f in result.findings if f.system in (name, None) and f.severity == "warning"]}


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
                _foot_notes(result, "foot"))]


def _hu_ekf_zupt(folder: Path) -> dict[str, float]:
    """Hu & Hu's EKF-ZUPT horizontal RMS per foot from the data's own table."""
    for line in (folder / "statistics_report_hor.csv").read_text().splitlines()[1:]:
        cells = [c.strip() for c in line.split(",")]
        if cells[0] == "EKF-ZUPT":
            return {"right_foot": float(cells[2]), "left_foot": float(cells[5])}
    return {}


def _vicon(folder: Path, overrides: list[str], limit: bool) -> list[Row]:
    result = _run(vicon_layout(folder, limit), overrides)
    peers = _hu_ekf_zupt(folder)
    key = "vicon_limit" if limit else "vicon"
    return [Row(key, name, result.scores[name].metrics["horizontal_error_m"]["rmse"], peers.get(name),
                _foot_notes(result, name)) for name in ("left_foot", "right_foot")]


def vicon_rows(folder: Path, overrides: list[str]) -> list[Row]:
    return _vicon(folder, overrides, False)


def vicon_limit_rows(folder: Path, overrides: list[str]) -> list[Row]:
    return _vicon(folder, overrides, True)


def xio_row(csv: Path, overrides: list[str]) -> list[Row]:
    from bodyfusion.evaluation.metrics import loop_closure_m

    result = _run(xio_layout(csv), overrides)
    return [Row("xio", csv.stem, loop_closure_m(result.trajectories["foot"]), XIO_PUBLISHED_LOOP_M,
                _foot_notes(result, "foot"))]


def ipin_row(log: Path, overrides: list[str]) -> list[Row]:
    result = _run(ipin_layout(log), overrides)
    p75 = result.scores["hand_phone"].metrics["horizontal_error_m"]["p75"]
    gnss_p75 = result.sensor_alone["hand_phone"]["horizontal_error_m"]["p75"]
    d = result.systems["hand_phone"].diagnostics()
    return [Row("ipin", log.stem.replace("IPIN2023_T3_", ""), p75, gnss_p75,
                {"ratio": p75 / gnss_p75, "steps": d["steps"], "reanchored": d["gnss"]["reanchored"],
                 "track_heading": d["gnss"]["track_heading_accepted"]})]


def sim_rows(scenario: Path, overrides: list[str]) -> list[Row]:
    from bodyfusion.sim import simulate

    name = next(k for k, v in SIMULATIONS.items() if v == scenario)
    with tempfile.TemporaryDirectory() as tmp:
        simulate(scenario, Path(tmp) / name, seed=1)
        result = _run(simulated_layout(Path(tmp) / name), overrides)
        return [Row("sim", f"{name}/{foot}", result.scores[foot].metrics["horizontal_error_m"]["rmse"], None,
                    _foot_notes(result, foot)) for foot in result.scores]


DATASETS: dict[str, tuple[str | None, Callable[[Path], list[Path]], Callable[[Path, list[str]], list[Row]], str, str]] = {
    # key: (folder in the data, its recordings, runner, figure, peer)
    "pyshoe": ("foot_vicon_pyshoe", lambda d: sorted(p for p in d.iterdir() if (p / "imu.csv").exists()),
               pyshoe_row, "h-RMSE m", "PyShoe m"),
    "vicon": ("dual_foot_vicon_hu2025", lambda d: [d], vicon_rows, "h-RMSE m (feet on their own)", "Hu&Hu EKF m"),
    "vicon_limit": ("dual_foot_vicon_hu2025", lambda d: [d], vicon_limit_rows, "h-RMSE m (the body's limit)",
                    "Hu&Hu EKF m"),
    "xio": ("single_foot_loop_xio", lambda d: [d / "long_walk.csv"], xio_row, "loop m", "x-io m"),
    "ipin": ("handheld_phone_ipin2023", lambda d: sorted(d.glob("IPIN2023_T3_*.txt")), ipin_row,
             "p75 m", "GNSS alone p75 m"),
    "sim": (None, lambda d: list(SIMULATIONS.values()), sim_rows, "h-RMSE m", "-"),
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


def by_motion(rows: list[Row]) -> list[str]:
    """``motion <kind>: n=… median=… worst=…`` of the foot recordings (not the dual-foot or loop
    figures, which measure other things), by their majority motion."""
    kinds: dict[str, list[float]] = {}
    for r in rows:
        if r.dataset in ("pyshoe", "sim") and r.value is not None and "motion" in r.extra:
            kinds.setdefault(r.extra["motion"], []).append(r.value)
    return [f"motion {kind}: n={len(v)} median={np.median(v):.3f} worst={max(v):.3f}" for kind, v in sorted(kinds.items())]


def _extra_text(extra: dict) -> str:
    shown = []
    for k, v in extra.items():
        if k in ("notes", "motions") or v is None or v == []:
            continue
        shown.append(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}")
    if extra.get("motions"):
        shown.append("strides=" + ",".join(f"{m}:{s:.0%}" for m, s in extra["motions"].items()))
    return " ".join(shown)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=lambda p: Path(p).resolve(), default=DEFAULT_DATA, help="the shared data folder")
    parser.add_argument("--only", choices=sorted(DATASETS), action="append", help="run only these data sets")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="layout override applied to every recording")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--json", type=Path, help="write every row to this file")
    args = parser.parse_args(argv)
    keys = args.only or list(DATASETS)
    if not args.data.is_dir():
        print(f"generalisation: no shared data at {args.data}; the simulations only")
        keys = [k for k in keys if DATASETS[k][0] is None]
    jobs = [(key, str(rec)) for key in keys
            for rec in DATASETS[key][1](args.data / DATASETS[key][0] if DATASETS[key][0] else args.data)]
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        futures = [pool.submit(_job, key, rec, args.overrides) for key, rec in jobs]
        results = [row for f in futures for row in f.result()]
    print(f"defaults{'' if not args.overrides else ' with ' + ' '.join(args.overrides)}")
    lines = []
    for key in keys:
        rows = [r for r in results if r.dataset == key]
        folder, _, _, figure, peer = DATASETS[key]
        print(f"\n{folder or 'simulated gaits'}: {figure} (peer: {peer})")
        for r in rows:
            if r.error:
                print(f"  {r.recording:<40} FAILED {r.error}")
                continue
            peer_txt = f"{r.peer:8.3f}" if r.peer is not None else "       -"
            print(f"  {r.recording:<40} {r.value:8.3f} {peer_txt}  {_extra_text(r.extra)}")
        line = f"{key}: {summary(rows)}"
        peers = [r for r in rows if r.peer is not None and r.value is not None]
        if peers:
            line += f" peer_median={np.median([r.peer for r in peers]):.3f} peer_worst={max(r.peer for r in peers):.3f}"
            line += f" at_or_below_peer={sum(r.value <= r.peer for r in peers)}/{len(peers)}"
        if key == "ipin":
            ratios = [r.extra["ratio"] for r in rows if r.error is None]
            line += (f" ratio_median={np.median(ratios):.2f} better_or_equal={sum(x <= 1.0 for x in ratios)}/{len(rows)}"
                     if ratios else "")
        lines.append(line)
    print()
    for line in lines + by_motion(results):
        print(line)
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
