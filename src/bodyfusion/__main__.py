"""The ``fusion`` command as a process (``python -m bodyfusion`` and the ``fusion`` script):
SIGINT and SIGTERM are taken before any module of the command line loads and ignored once the
command has ended (:func:`~bodyfusion.base.interrupts.as_process`). A signal before this module's
first instruction (the interpreter's own start, some 30 ms) ends the process as by default.
:func:`bodyfusion.cli.main` is the same command for a caller in its own process (its handlers put
back as they were)."""

from __future__ import annotations

from bodyfusion.base.interrupts import as_process


def _command() -> None:
    from bodyfusion import cli  # the command line's modules load with the signals taken

    cli.command()


def main() -> None:
    """The ``fusion`` command (see the module docstring)."""
    as_process(_command)


if __name__ == "__main__":
    main()
