"""Scoring against truth by the evaluation protocol (:mod:`~bodyfusion.evaluation.metrics`)
and the plots of a run (:mod:`~bodyfusion.evaluation.plots`)."""
