"""The library as a notebook uses it: load a layout, edit it, run it on simulated streams held in
memory, take the results as pandas DataFrames, then run your own data with no CSV in between.

    python examples/notebook_api.py

Each block below is a notebook cell; nothing is written to disk. The API (``bodyfusion``):
``simulate`` (a scenario's streams in memory and a layout that reads them), ``load_layout`` (a
YAML file, a dict or models; overrides as a dict), ``run`` (with ``data=`` and ``truth=`` tables)
and the result's tables: ``to_frame``, ``errors``, ``states``, ``covariances``, ``events``,
``innovations``, ``constraint_events``.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from pydantic import ValidationError

import bodyfusion as bf

ROOT = Path(__file__).resolve().parents[1]
pd.set_option("display.width", 120)


def main() -> None:
    # --- 1. Both feet and a hand-held phone with GNSS, simulated in memory ------------------
    # The scenario walks a 200 m loop; the overrides shorten the walk and the GNSS outage.
    sim = bf.simulate(ROOT / "configs" / "dual_foot_hand_gnss.yaml",
                      {"path.waypoints_m": [[0, 0], [0, 30], [25, 30], [0, 0]],
                       "systems.hand_phone.gnss.outages": [{"start_s": 20, "duration_s": 10}]}, seed=1)
    print(f"{sim.distance_m:.0f} m in {sim.duration_s:.0f} s; streams:",
          {name: list(sections) for name, sections in sim.data.items()})
    print(sim.data["left_foot"]["data"].head(3), "\n")  # the IMU table its file would hold

    # --- 2. Edit the layout: every field set is validated ------------------------------------
    layout = bf.load_layout(sim.layout, {"fuser.inequality": "projection"})  # overrides as a dict
    layout.systems["left_foot"].filter.kind = "ckf"
    layout.systems["left_foot"].filter.colour_factor = 0.3
    try:
        layout.fuser.method = "bogus"
    except ValidationError as err:
        print("refused:", err.errors()[0]["msg"], "\n")

    # --- 3. Run and look at the tables -------------------------------------------------------
    result = bf.run(layout)
    trajectories = result.to_frame()  # system, t, east_m, north_m, up_m, sd_*, v_*, heading_deg...
    print(trajectories.groupby("system")[["sd_east_m", "sd_north_m"]].max(), "\n")
    print(result.errors().groupby("system").horizontal_error_m.agg(["mean", "max"]), "\n")
    print(result.innovations().groupby(["system", "aiding"]).nis.agg(["count", "mean"]), "\n")
    active = result.constraint_events().query("active")
    print(active.groupby("pair")[["distance_before_m", "distance_after_m", "multiplier"]].mean(), "\n")
    print(result.states("left_foot")[["t", "v_north_mps", "heading_deg", "gyro_bias_z_radps"]].tail(3), "\n")
    cov = result.covariances("hand_phone")  # the hand PDR stores its whole error-state covariance
    print(cov.states, cov.matrix.shape)
    print(result.events().groupby(["system", "event"]).duration_s.agg(["count", "mean"]), "\n")

    # --- 4. Your own data: a DataFrame per system, no CSV ------------------------------------
    imu = pd.read_csv(ROOT / "examples" / "data" / "dual_foot_vicon_hu2025" / "imuMeasLeft.csv")  # any loader
    own = {"systems": {"left_foot": {"plugin": "foot_ins", "data": {
        "time_column": "time_index", "time_scale": 1 / 60, "acc_columns": ["acc_x", "acc_y", "acc_z"],
        "gyro_columns": ["gyro_x", "gyro_y", "gyro_z"]}}}}
    walk = bf.run(own, data={"left_foot": imu}).to_frame()
    print(walk[["t", "east_m", "north_m", "sd_east_m", "heading_deg"]].iloc[::1800])


if __name__ == "__main__":
    main()
