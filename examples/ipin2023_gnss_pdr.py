"""IPIN 2023 smartphone trials: GNSS alone, PDR alone, PDR+GNSS (with and without the
magnetometer), and a 60 s GNSS outage.

Every log in ``../shared/data/handheld_phone_ipin2023`` runs through
``configs/ipin2023_trial01.yaml`` with its defaults (start from the first confirmed fix,
heading acquired while the phone walks, magnetometer on where its field turns with the
gyro), scored at the surveyed points (POSI lines) with the competition's metric (the 75th
percentile of the horizontal error), the median and the maximum:

* GNSS alone: the phone's fixes, scored like the estimates (points outside their span skipped);
* PDR alone: PDR+GNSS with the GNSS masked once the heading is resolved (the fixes until
  then only set the start and the heading; "-" where it never resolves);
* PDR+GNSS, and the same with ``magnetometer.enabled=false``;
* PDR+GNSS with the GNSS masked for the first 60 s of walking after the first point.

The last column is the time the heading resolved (s) and how often handling the phone
re-opened it. ``--set KEY=VALUE`` overrides every run, e.g.
``--set systems.hand_phone.initial.heading_hypotheses=8``.

Usage: python examples/ipin2023_gnss_pdr.py [--set KEY=VALUE]...
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from bodyfusion.core.layout import load_layout
from bodyfusion.evaluation.metrics import score_systems
from bodyfusion.io.phone_log import read_getsensordata
from bodyfusion.runner import run_layout
from bodyfusion.base.types import Trajectory

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "ipin2023_trial01.yaml"
DATA = ROOT.parent / "shared" / "data" / "handheld_phone_ipin2023"
TO_THE_END_S = 86_400.0
"""An outage that lasts to the end of any log (a day; a layout's durations are at most a week)."""


def stats(err: np.ndarray) -> str:
    return f"{np.percentile(err, 50):.2f} / {np.percentile(err, 75):.2f} / {err.max():.2f}"


def pdr_gnss_run(log_path: Path, outage: tuple[float, float] | None, extra: list[str]):
    overrides = [f"systems.hand_phone.phone_log={log_path}", f"truth.path={log_path}", *extra]
    if outage is not None:
        overrides.append(f"outages=[{{system: hand_phone, start_s: {outage[0]}, duration_s: {outage[1]}}}]")
    return run_layout(load_layout(CONFIG, overrides))


def errors(result) -> np.ndarray:
    return result.scores["hand_phone"].horizontal_error_m


def gnss_errors(log_path: Path, result) -> np.ndarray:
    """The fixes as a trajectory, scored against the same points and origin as ``result``."""
    gnss = read_getsensordata(log_path).gnss
    enu = gnss.enu(result.frame.geodetic_origin)
    _, scores = score_systems({"hand_phone": Trajectory(gnss.t, enu, np.zeros_like(enu))},
                              {"hand_phone": result.truths["hand_phone"]}, alignment="none")
    return scores["hand_phone"].horizontal_error_m


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="layout override of every run")
    args = parser.parse_args()
    logs = sorted(DATA.glob("IPIN2023_T3_*.txt"))
    if not logs:
        raise SystemExit(f"ipin2023_gnss_pdr: no IPIN 2023 logs (IPIN2023_T3_*.txt) in {DATA}: this example reads the "
                         "shared recordings beside the repository")
    table = Table(title="Horizontal error at the surveyed points, m: p50 / p75 (IPIN metric) / max")
    for col in ("trial", "GNSS alone", "PDR alone", "PDR+GNSS", "no magnetometer", "60 s outage", "heading"):
        table.add_column(col, justify="right")
    for path in logs:
        both = pdr_gnss_run(path, None, args.overrides)
        hand = both.systems["hand_phone"]
        resolved = hand.heading_resolved_s
        pdr = "-" if resolved is None else stats(errors(pdr_gnss_run(path, (resolved + 0.5, TO_THE_END_S),
                                                                      args.overrides)))
        no_mag = pdr_gnss_run(path, None, [*args.overrides, "systems.hand_phone.magnetometer.enabled=false"])
        first_point = float(both.truths["hand_phone"].t[0])
        masked = pdr_gnss_run(path, (first_point, 60.0), args.overrides)
        heading = hand.diagnostics()["heading"]
        table.add_row(path.stem.replace("IPIN2023_T3_Training", ""), stats(gnss_errors(path, both)), pdr,
                      stats(errors(both)), stats(errors(no_mag)), stats(errors(masked)),
                      f"{'-' if resolved is None else f'{resolved:.0f} s'}, reopened {heading.get('reopened', 0)}")
    Console(width=170).print(table)


if __name__ == "__main__":
    main()
