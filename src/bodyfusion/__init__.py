"""bodyfusion: fusing body-worn pedestrian navigation systems under body distance constraints.

Packages: :mod:`bodyfusion.core` (layouts, plugin registry, the system interfaces, the fuser,
constraints, runs and their outputs: it knows no sensor), :mod:`bodyfusion.nav` (the navigation
toolbox the plugins share), :mod:`bodyfusion.io` (readers of IMU, truth, GNSS and phone-log
files), :mod:`bodyfusion.evaluation` (scoring and plots), :mod:`bodyfusion.plugins` (the built-in
sensor systems), :mod:`bodyfusion.sim` (simulation with truth), :mod:`bodyfusion.study`
(studies over many runs), :mod:`bodyfusion.testing` (the conformance kit for plugins).

The library's entry points are at the root (:mod:`bodyfusion.api`): :func:`load_layout` (a YAML
file, a dict or models; overrides as a dict or dotted strings), :func:`run` (with in-memory data),
:func:`simulate`, :func:`run_study`; a run's :class:`RunResult` gives its tables as DataFrames.
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"

_API = {"load_layout": "bodyfusion.api", "run": "bodyfusion.api", "simulate": "bodyfusion.api",
        "run_study": "bodyfusion.api", "Simulation": "bodyfusion.api", "Layout": "bodyfusion.core.layout",
        "LoadedLayout": "bodyfusion.core.layout", "RunResult": "bodyfusion.results.run_result"}
"""The library's names (:mod:`bodyfusion.api`), loaded when first used: ``import bodyfusion`` and
the command line stay quick (the compiled kernels and pandas load with a run)."""

__all__ = ["Layout", "LoadedLayout", "RunResult", "Simulation", "__version__", "load_layout", "run", "run_study",
           "simulate"]


def __getattr__(name: str) -> object:  # no typing import: the command takes its signals sooner
    if name not in _API:
        raise AttributeError(f"module 'bodyfusion' has no attribute {name!r}")
    value = getattr(importlib.import_module(_API[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
