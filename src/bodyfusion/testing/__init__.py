"""Conformance checks for sensor-system plugins.

One call runs every check on a plugin class and raises :class:`ConformanceError` (an
``AssertionError``) naming each failing check::

    from bodyfusion.testing import check_system

    def test_my_plugin_conforms():
        check_system(MySystem, {"data": {"path": "tests/data/log.csv"}},
                     bad_configs=[({"data": {"path": "x.csv"}, "noise_pa": -1}, "noise_pa")])

See ``docs/plugin_guide.md`` for the contract the checks enforce. The modules:

- :mod:`~bodyfusion.testing.conformance`: :func:`check_system` and its report;
- :mod:`~bodyfusion.testing.systems`: the checks of a sensor system, :data:`CHECKS`, each described;
- :mod:`~bodyfusion.testing.aiding`: the checks of an aiding source, :data:`AIDING_CHECKS`;
- :mod:`~bodyfusion.testing.documentation`: the rule for documented parameters;
- :mod:`~bodyfusion.testing.jacobians`: analytic Jacobians against central differences, and
  the core 15-state INS error model (:data:`STRAPDOWN15`);
- :mod:`~bodyfusion.testing.inputs`: a default layout context, configs with one value changed;
- :mod:`~bodyfusion.testing.compare`: bit-for-bit comparison of arrays.
"""

from bodyfusion.testing.aiding import AIDING_CHECKS
from bodyfusion.testing.conformance import CheckResult, ConformanceError, ConformanceReport, check_system
from bodyfusion.testing.documentation import undocumented_fields
from bodyfusion.testing.inputs import default_context, with_value
from bodyfusion.testing.jacobians import (STRAPDOWN15, JacobianCase, check_jacobian, numerical_jacobian,
                                          random_nominal_state, strapdown15_jacobian_cases)
from bodyfusion.testing.systems import CHECKS

__all__ = [
    "AIDING_CHECKS", "CHECKS", "CheckResult", "ConformanceError", "ConformanceReport", "JacobianCase", "STRAPDOWN15",
    "check_jacobian", "check_system", "default_context", "numerical_jacobian", "random_nominal_state",
    "strapdown15_jacobian_cases", "undocumented_fields", "with_value",
]
