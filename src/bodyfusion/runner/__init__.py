"""A run from a layout to its outputs: the systems built (:mod:`~bodyfusion.runner.assemble`), the
truth read (:mod:`~bodyfusion.runner.truth`), fused, smoothed, scored and written
(:mod:`~bodyfusion.runner.batch`); the files a layout names checked before it runs
(:mod:`~bodyfusion.runner.layout_files`)."""

from bodyfusion.runner.assemble import build_systems, layout_context
from bodyfusion.runner.batch import run, run_layout

__all__ = ["build_systems", "layout_context", "run", "run_layout"]
