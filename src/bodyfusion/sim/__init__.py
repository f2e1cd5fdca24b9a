"""Simulation with exact truth: a walking pedestrian and the systems worn.

``simulate(scenario, out_dir, seed)`` writes sensor files, ``truth.csv`` and a runnable
``config.yaml``; ``simulated(scenario, seed)`` holds the same in memory (its tables are what the
files hold: :mod:`~bodyfusion.sim.files`). Modules: :mod:`~bodyfusion.sim.paths` (body paths by arc length),
:mod:`~bodyfusion.sim.gait_config` (the ``gait`` section), :mod:`~bodyfusion.sim.foot_motion` (a foot: swing, stance), :mod:`~bodyfusion.sim.gait` (the walk's plan), :mod:`~bodyfusion.sim.imu` (ideal IMU and
sensor errors), :mod:`~bodyfusion.sim.scenario` (the scenario file and :func:`simulate`).
"""

from bodyfusion.sim.scenario import Simulated, SimulationResult, load_scenario, simulate, simulated

__all__ = ["Simulated", "SimulationResult", "load_scenario", "simulate", "simulated"]
