"""Scoring against truth by the evaluation protocol (:mod:`~bodyfusion.evaluation.metrics`),
the figures of a run or study (:mod:`~bodyfusion.evaluation.plots`) and its HTML report
(:mod:`~bodyfusion.evaluation.report`)."""
