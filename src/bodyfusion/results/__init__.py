"""What a run produced (:class:`~bodyfusion.results.run_result.RunResult`: the systems with their
histories, the trajectories, the truth, the scores, consistency and findings) and its tables as
pandas DataFrames (:mod:`~bodyfusion.results.frames`)."""
