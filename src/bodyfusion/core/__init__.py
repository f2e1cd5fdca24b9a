"""The framework, which knows no sensor: layouts (:mod:`~bodyfusion.core.layout`), the plugin
registry (:mod:`~bodyfusion.core.registry`), the system interfaces (:mod:`~bodyfusion.core.system`),
the fuser and its distance constraints, heading alignment of systems worn together, runs and
their outputs."""
