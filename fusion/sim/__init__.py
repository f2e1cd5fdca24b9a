"""Simulation with exact truth: a walking pedestrian and the systems worn.

``simulate(scenario, out_dir, seed)`` writes sensor files, ``truth.csv`` and a runnable
``config.yaml``. Modules: :mod:`~fusion.sim.paths` (body paths by arc length),
:mod:`~fusion.sim.gait` (feet: stance, swing), :mod:`~fusion.sim.imu` (ideal IMU and
sensor errors), :mod:`~fusion.sim.scenario` (the scenario file and :func:`simulate`).
"""

from fusion.sim.scenario import SimulationResult, load_scenario, simulate

__all__ = ["SimulationResult", "load_scenario", "simulate"]
