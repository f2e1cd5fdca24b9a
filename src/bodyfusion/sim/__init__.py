"""Simulation with exact truth: a walking pedestrian and the systems worn.

``simulate(scenario, out_dir, seed)`` writes sensor files, ``truth.csv`` and a runnable
``config.yaml``. Modules: :mod:`~bodyfusion.sim.paths` (body paths by arc length),
:mod:`~bodyfusion.sim.gait_config` (the ``gait`` section), :mod:`~bodyfusion.sim.foot_motion` (a foot: swing, stance), :mod:`~bodyfusion.sim.gait` (the walk's plan), :mod:`~bodyfusion.sim.imu` (ideal IMU and
sensor errors), :mod:`~bodyfusion.sim.scenario` (the scenario file and :func:`simulate`).
"""

from bodyfusion.sim.scenario import SimulationResult, load_scenario, simulate

__all__ = ["SimulationResult", "load_scenario", "simulate"]
