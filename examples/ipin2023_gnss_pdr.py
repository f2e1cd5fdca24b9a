"""IPIN 2023 smartphone trials: GNSS alone, PDR alone, PDR+GNSS, and a 60 s GNSS outage.

Scores each at the surveyed points (POSI lines) with the competition's metric (the 75th
percentile of the horizontal error) plus the median and the maximum:

* GNSS alone: the phone's fixes, interpolated to the points' times;
* PDR alone: PDR+GNSS with the GNSS masked once the initial heading is aligned (the
  fixes until then, the first 15 m of walking, only set the start and the heading);
* PDR+GNSS: ``configs/ipin2023_trial01.yaml`` as it is;
* PDR+GNSS with the GNSS masked for the first 60 s of walking after the first point.

``--magnetometer`` adds a row per trial with the magnetometer heading aiding on (the
layout's ``magnetometer`` section: WMM field check, declination); ``--set KEY=VALUE``
overrides that run further, e.g. ``--set systems.hand_phone.magnetometer.field_check=null``.

Usage: python examples/ipin2023_gnss_pdr.py [--magnetometer [--set KEY=VALUE]...]
(reads ../shared/data/handheld_phone_ipin2023)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from pymap3d import geodetic2enu
from rich.console import Console
from rich.table import Table

from fusion.config import load_layout
from fusion.phone_log import read_getsensordata
from fusion.run import run_layout

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "ipin2023_trial01.yaml"
DATA = ROOT.parent / "shared" / "data" / "handheld_phone_ipin2023"
TRIALS = {"Trial01 rep04": "IPIN2023_T3_TrainingTrial01_repetition04.txt",
          "Trial03 rep03": "IPIN2023_T3_TrainingTrial03_repetition03.txt"}


def stats(err: np.ndarray) -> str:
    return f"{np.percentile(err, 50):.2f} / {np.percentile(err, 75):.2f} / {err.max():.2f}"


def pdr_gnss_run(log_path: Path, outage: tuple[float, float] | None, extra: list[str]):
    overrides = [f"systems.hand_phone.phone_log={log_path}", f"truth.path={log_path}", *extra]
    if outage is not None:
        overrides.append(f"outages=[{{system: hand_phone, start_s: {outage[0]}, duration_s: {outage[1]}}}]")
    return run_layout(load_layout(CONFIG, overrides))


def errors(result) -> np.ndarray:
    return result.scores["hand_phone"].horizontal_error_m


def magnetometer_note(result) -> str:
    """Accepted / rejected by the gate / rejected by the field check."""
    c = result.systems["hand_phone"].diagnostics().get("magnetometer")
    return "off" if c is None else f"on ({c['accepted']}/{c['rejected_gate']}/{c['rejected_field']})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--magnetometer", action="store_true", help="add runs with the magnetometer on")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="layout override of the magnetometer runs")
    args = parser.parse_args()
    variants = [[]] + ([["systems.hand_phone.magnetometer.enabled=true", *args.overrides]] if args.magnetometer else [])
    table = Table(title="Horizontal error at the surveyed points, m: p50 / p75 (IPIN metric) / max; "
                        "magnetometer updates accepted / gated out / failed field check (PDR+GNSS)")
    for col in ("trial", "magnetometer", "GNSS alone", "PDR alone", "PDR+GNSS", "PDR+GNSS, 60 s outage"):
        table.add_column(col, justify="right")
    for trial, file in TRIALS.items():
        path = DATA / file
        log = read_getsensordata(path)
        ref = log.reference
        origin = load_layout(CONFIG).layout.geodetic_origin
        g = log.gnss.enu(origin)
        e, n, _ = geodetic2enu(ref.lat_deg, ref.lon_deg, np.full(len(ref.t), origin[2]), *origin)
        gnss_err = np.hypot(np.interp(ref.t, log.gnss.t, g[:, 0]) - e, np.interp(ref.t, log.gnss.t, g[:, 1]) - n)
        for extra in variants:
            both = pdr_gnss_run(path, None, extra)
            aligned = both.systems["hand_phone"].heading_alignment_end_s
            pdr = pdr_gnss_run(path, (aligned + 0.5, 1e6), extra)
            masked = pdr_gnss_run(path, (float(ref.t[0]), 60.0), extra)
            table.add_row(trial, magnetometer_note(both), stats(gnss_err), stats(errors(pdr)), stats(errors(both)),
                          stats(errors(masked)))
    Console(width=160).print(table)


if __name__ == "__main__":
    main()
