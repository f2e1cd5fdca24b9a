"""Running the conformance checks on a plugin class: :func:`check_system` and its report.

One call runs every check on a sensor-system class (:mod:`bodyfusion.testing.systems`) or an
aiding-source class (:mod:`bodyfusion.testing.aiding`) and raises :class:`ConformanceError`
(an ``AssertionError``) naming each failing check, or returns the :class:`ConformanceReport`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from bodyfusion.core.system import AidingSource, LayoutContext
from bodyfusion.testing.aiding import AIDING_CHECKS, AidingChecker
from bodyfusion.testing.inputs import default_context
from bodyfusion.testing.systems import CHECKS, Skip, SystemChecker


@dataclass
class CheckResult:
    """Outcome of one check: ``status`` is ``passed``, ``failed`` or ``skipped``."""

    name: str
    status: str
    detail: str = ""


@dataclass
class ConformanceReport:
    """Every check's result for one plugin class."""

    plugin: str
    results: list[CheckResult] = field(default_factory=list)

    def _names(self, status: str) -> list[str]:
        return [r.name for r in self.results if r.status == status]

    @property
    def passed(self) -> list[str]:
        return self._names("passed")

    @property
    def failed(self) -> list[str]:
        return self._names("failed")

    @property
    def skipped(self) -> list[str]:
        return self._names("skipped")

    def result(self, name: str) -> CheckResult:
        return next(r for r in self.results if r.name == name)

    def __str__(self) -> str:
        head = (f"conformance of plugin {self.plugin!r}: {len(self.passed)} passed, {len(self.failed)} failed, "
                f"{len(self.skipped)} skipped")
        lines = [head]
        for r in self.results:
            if r.status != "passed":
                lines.append(f"  [{r.name}] {r.status}: {r.detail}")
        return "\n".join(lines)


class ConformanceError(AssertionError):
    """Raised by :func:`check_system` when a check fails; ``report`` has every result."""

    def __init__(self, report: ConformanceReport) -> None:
        super().__init__(str(report))
        self.report = report


def check_system(system_cls: type, config: Mapping[str, Any], *, name: str = "system",
                 context: LayoutContext | None = None, chunks: int = 5,
                 bad_configs: Sequence[tuple[Mapping[str, Any], str]] = (), stochastic: bool | None = None,
                 error_model: str | None = None, allow_undocumented: Iterable[str] = (),
                 checks: Iterable[str] | None = None, raise_on_failure: bool = True) -> ConformanceReport:
    """Run every conformance check (:data:`CHECKS`) on a sensor-system plugin class, or
    those of :data:`AIDING_CHECKS` on an aiding-source class.

    Parameters
    ----------
    system_cls: the :class:`~bodyfusion.core.system.SensorSystem` subclass.
    config: a valid layout section for it, as a dict (``plugin`` may be left out);
        relative paths resolve against ``context.base_dir``.
    name: the system's name in the layout (error keys read ``systems.<name>.<key>``).
    context: layout facts; default :func:`~bodyfusion.testing.inputs.default_context` (g 9.80665, seed 0, base dir ".").
    chunks: uniform chunk ends for the covariance and chunking checks (sync times are added).
    bad_configs: ``(config, dotted_key)`` pairs that must be refused with a ConfigError
        naming ``systems.<name>.<dotted_key>`` (see :func:`~bodyfusion.testing.inputs.with_value`).
    stochastic: True if the system draws random numbers (another seed must differ), False
        if it must not depend on the seed, None to check only same seed → same bits.
    error_model: override of the class's ``error_model`` attribute (``"strapdown15"``).
    allow_undocumented: dotted parameter paths known to be undocumented (a ratchet: an
        entry that is documented, or no field, fails the check).
    checks: run only these checks (and those they need); default all.
    raise_on_failure: raise :class:`ConformanceError` if any check fails (default).

    Returns the :class:`ConformanceReport`. Each check records ``passed``, ``failed`` (with
    the reason) or ``skipped`` (does not apply, or a check it needs failed).
    """
    ctx = context if context is not None else default_context()
    plugin = getattr(system_cls, "plugin_name", getattr(system_cls, "__name__", repr(system_cls)))
    aiding = isinstance(system_cls, type) and issubclass(system_cls, AidingSource)
    names = AIDING_CHECKS if aiding else CHECKS
    checker = AidingChecker if aiding else SystemChecker
    chk = checker(system_cls, config, name, ctx, chunks, bad_configs, stochastic, error_model, allow_undocumented)
    wanted = set(names if checks is None else checks)
    unknown = wanted - set(names)
    if unknown:
        raise ValueError(f"unknown checks {sorted(unknown)}; known: {', '.join(names)}")
    report = ConformanceReport(str(plugin))
    needs = {"interface": (), "documented": ("interface",), "bad_config": ("interface",), "build": ("interface",)}
    for check in names:
        if check not in wanted and not (check in ("interface", "build") and wanted - {"interface", "documented"}):
            continue
        blockers = [r.name for r in report.results
                    if r.status == "failed" and r.name in needs.get(check, ("interface", "build"))]
        if blockers:
            report.results.append(CheckResult(check, "skipped", f"not run: {', '.join(blockers)} failed"))
            continue
        try:
            detail = getattr(chk, f"check_{check}")()
            report.results.append(CheckResult(check, "passed", detail or ""))
        except Skip as skip:
            report.results.append(CheckResult(check, "skipped", str(skip)))
        except AssertionError as err:
            report.results.append(CheckResult(check, "failed", str(err)))
        except Exception as err:  # noqa: BLE001 - a crash inside a check is that check's failure
            report.results.append(CheckResult(check, "failed", f"raised {type(err).__name__}: {err}"))
    if raise_on_failure and report.failed:
        raise ConformanceError(report)
    return report
