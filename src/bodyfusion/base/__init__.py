"""The vocabulary every layer shares: user-facing errors (:mod:`~bodyfusion.base.errors`), the
data containers passed between readers, systems and scoring (:mod:`~bodyfusion.base.types`), the
building blocks of layout sections (:mod:`~bodyfusion.base.sections`) and seeded random streams
(:mod:`~bodyfusion.base.seeding`). It imports nothing else of the package."""
