"""A run's files (docs/contract.md): metrics.json and the plots (:mod:`~bodyfusion.outputs.write`),
the trajectory files for other tools and their reader (:mod:`~bodyfusion.outputs.trajectories`)."""
