"""User-facing errors: each prints as one line naming the file (and line) or the config key."""

from __future__ import annotations

from pathlib import Path


class FusionError(Exception):
    """An error caused by the user's input; the CLI prints ``str(err)`` and exits non-zero."""


class NotReady(FusionError):
    """A live run's recording is too short yet for a system to start (no rest to level on)."""


class InputError(FusionError):
    """Bad data file: ``path:line: reason`` (line is 1-based, as an editor shows it)."""

    def __init__(self, path: str | Path, reason: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.reason = reason
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")


class ConfigError(FusionError):
    """Bad layout: ``file: dotted.key.path: reason``. ``others``: the further errors found in the
    same check (``fusion validate`` prints them all; the error itself is the first)."""

    def __init__(self, key: str, reason: str, path: str | Path | None = None,
                 others: tuple[ConfigError, ...] = ()) -> None:
        self.key = key
        self.path = None if path is None else str(path)
        self.reason = reason
        self.others = tuple(others)
        parts = [p for p in (self.path, key) if p]
        super().__init__(": ".join([*parts, reason]))

    @classmethod
    def of(cls, errors: list[ConfigError]) -> ConfigError:
        """The first of ``errors`` carrying the rest as its ``others``."""
        first = errors[0]
        return cls(first.key, first.reason, first.path, (*first.others, *errors[1:]))

    def every(self) -> list[ConfigError]:
        """This error and its others, in the order found."""
        return [ConfigError(self.key, self.reason, self.path), *self.others]


class MissingExtraError(FusionError):
    """An optional dependency is not installed: ``what needs the optional dependency X: pip
    install "bodyfusion[extra]"``."""
