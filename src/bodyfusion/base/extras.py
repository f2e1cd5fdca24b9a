"""Optional dependencies, installed with the package's extras: ``[socp]`` (cvxpy, for
``fuser.method=socp``) and ``[study]`` (Dask distributed, for ``--executor dask``). Each is
imported where it is used, through :func:`import_optional`."""

from __future__ import annotations

import importlib
from types import ModuleType

from bodyfusion.base.errors import MissingExtraError


def import_optional(module: str, extra: str, needed_by: str, package: str | None = None) -> ModuleType:
    """``import module``, or a one-line :class:`MissingExtraError` naming ``extra``:
    ``fuser.method=socp needs the optional dependency cvxpy: pip install "bodyfusion[socp]"``
    (``package``: the distribution to name, default the module's top-level name)."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        top = module.partition(".")[0]
        message = f'{needed_by} needs the optional dependency {package or top}: pip install "bodyfusion[{extra}]"'
        if err.name is not None and err.name.partition(".")[0] != top:  # installed, but it does not import
            message += f" ({err})"
        raise MissingExtraError(message) from None
