"""Command-line interface (docs/contract.md): ``fusion run | live | simulate | study | reproduce | validate | report |
example | plugins``.

Each command imports what it needs when it runs (the compiled kernels, matplotlib, Dask are
heavy), so ``fusion --help`` and ``fusion plugins`` answer at once."""

from __future__ import annotations

import logging
import sys
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable
from typing import Annotated, Literal

import typer

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.base.interrupts import (Terminated, answer_pending, as_process, exit_aborted, exit_terminated,
                                        restore_signals, take_signals)
from bodyfusion.base.progress import ProgressCallback, reporting

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Fuse body-worn pedestrian navigation systems under body distance constraints.")

SetOption = Annotated[list[str] | None, typer.Option("--set", help="Override a config field: KEY=VALUE (dotted path).")]
log = logging.getLogger("bodyfusion.cli")  # also when run as __main__ (python -m bodyfusion.cli)


@dataclass
class ConsoleOptions:
    """What the command line shows, set by its global options: ``verbosity`` -1 (``-q``: errors
    only), 0 (warnings and each command's summary), 1 (``-v``: each stage), 2 (``-vv``: debug)."""

    verbosity: int = 0

    @property
    def quiet(self) -> bool:
        return self.verbosity < 0

    @property
    def bars(self) -> bool:
        """Progress bars: on a terminal, or with ``-v`` (then also into a file or pipe)."""
        return not self.quiet and (sys.stderr.isatty() or self.verbosity > 0)


CONSOLE = ConsoleOptions()


def say(text: str) -> None:
    """A line of a command's summary on stdout (none with ``-q``)."""
    if not CONSOLE.quiet:
        typer.echo(text)


def _bar(description: str, unit: str = "") -> AbstractContextManager[ProgressCallback | None]:
    """A progress bar on stderr when the console shows them (:attr:`ConsoleOptions.bars`)."""
    return reporting(CONSOLE.bars, description, unit)


def _print_version(value: bool) -> None:
    if value:
        from bodyfusion import __version__

        typer.echo(f"bodyfusion {__version__}")
        raise typer.Exit()


@app.callback()
def options(version: Annotated[bool, typer.Option("--version", callback=_print_version, is_eager=True,
                                                  help="Print the version and exit.")] = False,
            verbose: Annotated[int, typer.Option("-v", "--verbose", count=True,
                                                 help="Say more on stderr: -v each stage and progress bars, "
                                                      "-vv debug.")] = 0,
            quiet: Annotated[bool, typer.Option("-q", "--quiet",
                                                help="Errors only: no warnings, summaries or progress bars.")] = False,
            ) -> None:
    """Global options, given before the command: ``fusion -v run ...``."""
    if verbose and quiet:
        raise typer.BadParameter("-q and -v exclude each other", param_hint="-q/-v")
    CONSOLE.verbosity = -1 if quiet else min(verbose, 2)
    configure_logging(CONSOLE.verbosity)
    # a first run's compile notice, where progress bars show too (a terminal, or -v)
    logging.getLogger("bodyfusion.core.compile_ahead").setLevel(logging.INFO if CONSOLE.bars else logging.NOTSET)


@app.command()
def run(config: Annotated[Path, typer.Argument(help="Layout YAML file.")],
        out: Annotated[Path | None, typer.Option("--out", help="Output folder (default ./out/<config name>).")] = None,
        set_: SetOption = None,
        seed: Annotated[int, typer.Option("--seed", help="Seed for every random choice of the run.")] = 0,
        overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace the outputs (an earlier run's, or files "
                                                                    "of their names) in --out (refused otherwise).")]
        = False) -> None:
    """Run a layout and write metrics.json, trajectories.csv and plots."""
    from bodyfusion.evaluation.figure_process import FigureProcess

    figure_process = FigureProcess.start()  # first: matplotlib loads there while this process runs
    from bodyfusion.outputs.write import earlier_run

    earlier = out is not None and earlier_run(out)  # an earlier run's outputs, replaced (--overwrite)
    try:
        from rich.console import Console
        from rich.table import Table

        from bodyfusion.runner import run as run_layout

        with _bar("fusing", "s of data") as progress:
            result, out_dir = run_layout(config, set_ or [], out, seed, progress, figure_process, overwrite)
    finally:
        if figure_process is not None:
            figure_process.close()
    if CONSOLE.quiet:
        return
    console = Console(stderr=False)
    replaced = " (the earlier run's outputs there replaced)" if earlier else ""
    table = Table(title=f"{result.loaded.name} → {out_dir}{replaced}")
    for col in ("system", "samples", "distance m", "h-RMSE m", "h-max m", "% dist", "loop m"):
        table.add_column(col, justify="right")
    import json

    doc = json.loads((out_dir / "metrics.json").read_text())
    for name, block in doc["systems"].items():
        h = block.get("horizontal_error_m", {})

        def fmt(v: float | None, spec: str = ".3f") -> str:
            return "-" if v is None else format(v, spec)

        table.add_row(name, str(block["samples"]), fmt(block.get("distance_m"), ".1f"), fmt(h.get("rmse")),
                      fmt(h.get("max")), fmt(block.get("final_error_pct_distance"), ".2f"), fmt(block.get("loop_closure_m")))
    console.print(table)
    for line in counted_policies(doc):
        console.print(line)
    rt = doc["runtime"]
    console.print(f"{rt['samples']} samples, navigation {rt['navigation_s']:.2f} s "
                  f"({rt['samples_per_s']:,.0f} samples/s), total {rt['wall_s']:.2f} s")


@app.command()
def live(config: Annotated[Path, typer.Argument(help="Layout YAML file.")], *,
         source: Annotated[str, typer.Option(
             "--source", help="replay (the layout's recordings), tcp://HOST:PORT or udp://HOST:PORT (JSON or CSV lines).")
         ] = "replay",
         speed: Annotated[str, typer.Option("--speed", help="Replay pace: a factor of real time, or max.")] = "1",
         sink: Annotated[list[str] | None, typer.Option(
             "--sink", help="Where states go: - (JSON lines on stdout), tcp://HOST:PORT, or a .jsonl, .csv, "
                            ".parquet or .mcap file; repeatable.")] = None,
         out: Annotated[Path | None, typer.Option("--out", help="Also write the finished run's outputs here.")] = None,
         overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace the outputs (an earlier run's, or "
                                                                     "files of their names) in --out, and sink "
                                                                     "files that exist.")] = False,
         interval: Annotated[float, typer.Option("--interval", help="Seconds of data between states.")] = 0.1,
         lookahead: Annotated[float, typer.Option("--lookahead", help="Seconds behind the newest sample at "
                                                                      "which decisions are final.")] = 2.0,
         warmup: Annotated[float, typer.Option("--warmup", help="Seconds of data before the run starts.")] = 10.0,
         keep: Annotated[float | None, typer.Option("--keep", help="Seconds of history held behind the decided "
                                                                  "data (memory bounded for a run of any length; "
                                                                  "the finished run covers the last of them). "
                                                                  "Default: all of it.")] = None,
         set_: SetOption = None,
         seed: Annotated[int, typer.Option("--seed", help="Seed for every random choice of the run.")] = 0) -> None:
    """Fuse a layout live: replay its recordings at a pace or take a line stream, and emit states as they are made."""
    import time

    from bodyfusion.core.layout import load_layout
    from bodyfusion.live.engine import REPLAN_BATCH_S, REPLAN_S, LiveRun
    from bodyfusion.live.sinks import EverySink, open_sink
    from bodyfusion.live.sources import line_rows, replay, replay_rows

    pace = None if speed == "max" else _positive(speed, "--speed")
    for value, key in ((interval, "--interval"), (lookahead, "--lookahead"), (warmup, "--warmup")):
        _positive(str(value), key)
    loaded = load_layout(config, set_ or [])
    if out is not None:
        from bodyfusion.outputs.write import check_output_folder

        check_output_folder(out, overwrite)
    sinks = []
    try:
        for target in sink or ["-"]:
            sinks.append(open_sink(target, overwrite))
    except FusionError:
        for opened in sinks:
            opened.close()
        raise
    replan = REPLAN_BATCH_S if source == "replay" and pace is None else REPLAN_S
    run = LiveRun(loaded, [EverySink(sinks)], lookahead_s=lookahead, warmup_s=warmup, replan_s=replan,
                  output_interval_s=interval, seed=seed, keep_s=keep)
    wall0 = time.perf_counter()

    def status(r: LiveRun, t: float) -> None:
        if CONSOLE.quiet:
            return
        lag = "" if r.fusion is None else f", {t - r.fusion.fuser.schedule.horizon:.1f} s behind the data"
        h = r.output.totals
        held = f", holding {r.held_s:.0f} s of data" if r.keep_s is not None else ""
        smoothed = f" ({r.output.smoothed_emitted} smoothed)" if r.smoothed is not None else ""
        print(f"live: {time.perf_counter() - wall0:.0f} s, {r.emitted} states{smoothed}{lag}{held}; constraint active "
              f"{h['constraint_active']}/{h['constraint_epochs']}, rejected {h['measurements_rejected']}, "
              f"fights {h['fights']}", file=sys.stderr)

    try:
        rows = replay_rows(run) if source == "replay" else line_rows(run, source)
        replay(run, rows, pace if source == "replay" else None, status=status)
        result = run.close()
    except BaseException:
        run.output.close()  # every sink's file complete
        raise
    if out is not None:
        from bodyfusion.outputs.write import write_outputs

        answer_pending()  # interrupted where the exception was dropped: no outputs replaced
        write_outputs(result, out, str(config), total_wall_s=time.perf_counter() - wall0)
    if not CONSOLE.quiet:
        revised = {n: s.revised_inputs for n, s in result.systems.items() if getattr(s, "revised_inputs", 0)}
        dropped = {n: b.dropped for n, b in run.buffers.items() if b.dropped}
        smoothed = f" and {run.output.smoothed_emitted} smoothed" if run.smoothed is not None else ""
        print(f"live: {run.emitted} states{smoothed} in {time.perf_counter() - wall0:.1f} s"
              + (f"; rows dropped for a time not after the newest: {dropped}" if dropped else "")
              + (f"; samples whose inputs the whole recording would have made otherwise: {revised}" if revised
                 else ""), file=sys.stderr)
        for finding in result.findings:
            print(finding.line(), file=sys.stderr)


def _positive(text: str, key: str) -> float:
    """``text`` as a positive number, else a ConfigError naming ``key``."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise ConfigError(key, f"{text!r}: give a positive number" + (" or max" if key == "--speed" else ""))
    return value


COUNTED = ("dropped", "reordered", "rejected", "gated", "skipped", "not_converged", "fallbacks", "resets", "warnings")
"""Words that mark a count of what a policy did to the input or the estimate (metrics.json keys)."""


def counted_policies(doc: dict) -> list[str]:
    """One line per part of the run (input, each system, aiding source, the constraints) with
    every non-zero count metrics.json holds of what was dropped, rejected, gated, skipped or
    did not converge: the console's summary of the counted policies."""
    def counts(block: dict, prefix: str = "") -> list[str]:
        out = []
        for key, value in block.items():
            if isinstance(value, dict):
                out += counts(value, f"{prefix}{key}.")
            elif isinstance(value, (int, float)) and not isinstance(value, bool) and value and any(
                    word in key for word in COUNTED):
                out.append(f"{prefix}{key} {value:g}")
        return out

    parts = {"input": {k: v for k, v in doc.get("input", {}).items() if not isinstance(v, list)}}
    parts |= {name: block.get("diagnostics", {}) for name, block in doc.get("systems", {}).items()}
    parts |= doc.get("aiding", {})
    if "constraints" in doc:
        parts["constraints"] = doc["constraints"]
    warned = len(doc.get("input", {}).get("warnings", []))
    lines = [f"{name}: " + ", ".join(found) for name, block in parts.items() if (found := counts(block))]
    if warned:
        lines.append(f"{warned} warning(s) about the input, above and in metrics.json input.warnings")
    return lines


@app.command()
def simulate(scenario: Annotated[Path, typer.Argument(help="Scenario YAML file.")],
             out: Annotated[Path, typer.Option("--out", help="Output folder.")],
             seed: Annotated[int, typer.Option("--seed")] = 0,
             set_: SetOption = None,
             overwrite: Annotated[bool, typer.Option(
                 "--overwrite", help="Replace files of the names it writes in --out (refused otherwise).")] = False
             ) -> None:
    """Simulate a walk: sensor files, truth.csv and a ready config.yaml."""
    from bodyfusion.sim import simulate as simulate_scenario

    with _bar("simulating", "systems") as progress:
        result = simulate_scenario(scenario, out, seed=seed, overrides=set_ or [], progress=progress,
                                   overwrite=overwrite)
    say(f"wrote {result.config_path}")


@app.command()
def study(study_file: Annotated[Path, typer.Argument(metavar="STUDY", help="Study YAML file.")],
          out: Annotated[Path, typer.Option("--out", help="Output folder (a study there is resumed).")],
          executor: Annotated[Literal["local", "dask"], typer.Option(
              "--executor", help="A local process pool or a Dask cluster.")] = "local",
          workers: Annotated[int | None, typer.Option("--workers", help="Processes (default: all cores).")] = None,
          scheduler: Annotated[str | None, typer.Option(
              "--scheduler", help="Dask scheduler address, tcp://host:port (default: a LocalCluster).")] = None) -> None:
    """Run a study: layouts × overrides × GNSS outages × seeds; results.parquet, summary.csv, plots."""
    from bodyfusion.study import run_study

    report = run_study(study_file, out, executor, workers, scheduler, progress=CONSOLE.bars)
    say(f"{report.total} runs: {report.done} done, {report.failed} failed, {report.skipped} skipped "
               f"in {report.wall_s:.1f} s ({report.runs_per_s:.2f} runs/s, {report.executor}, "
               f"{report.workers} workers) -> {report.out_dir}")


@app.command()
def reproduce(paper: Annotated[str, typer.Argument(metavar="PAPER", help="s000, s001, s002, s004 or all.")],
              out: Annotated[Path, typer.Option("--out", help="Output folder: table.csv and README.md.")],
              seeds: Annotated[int, typer.Option("--seeds", help="Seeds per experiment.")] = 10,
              jobs: Annotated[int, typer.Option("--jobs", help="Processes.")] = 1,
              overwrite: Annotated[bool, typer.Option(
                  "--overwrite", help="Replace table.csv and README.md in --out (refused otherwise).")] = False
              ) -> None:
    """Reproduce a source paper's table where its mechanism acts: the paper's figures beside ours."""
    from bodyfusion.reproduce import reproduce as reproduce_paper

    cells = reproduce_paper(paper, out, seeds, jobs, overwrite)
    say(f"{len(cells)} cells -> {out / 'table.csv'}, {out / 'README.md'}")


@app.command()
def validate(config: Annotated[Path, typer.Argument(help="Layout YAML file.")], set_: SetOption = None) -> None:
    """Check a layout without reading its data: both stages (layout and each plugin's section),
    finite and plausible numbers, a feasible constraint set; then every file it names is a file
    with the columns the layout names (all problems listed, one line each), and their time
    bases overlap (read from each file's first and last lines)."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner.layout_files import disjoint_time_bases, file_problems

    try:
        loaded = load_layout(config, set_ or [])
    except ConfigError as err:  # every error of every section, one line each
        for each in err.every():
            print(f"error: {each}", file=sys.stderr)
        sys.exit(2)
    problems = file_problems(loaded)
    for key, problem in problems:  # every one at once, one line each
        print(f"error: {ConfigError(key, problem, config)}", file=sys.stderr)
    if problems:
        sys.exit(2)
    if loaded.layout.constraints and loaded.layout.fuser.method == "none":
        log.warning("fuser.method is none: the %d constraint(s) are not enforced", len(loaded.layout.constraints))
    for line in disjoint_time_bases(loaded):
        log.warning(line)
    say(f"{config}: ok ({len(loaded.system_configs)} systems: {', '.join(loaded.system_configs)})")


@app.command()
def report(folder: Annotated[Path, typer.Argument(metavar="RUN_OR_STUDY_DIR",
                                                  help="A folder written by fusion run or fusion study.")]) -> None:
    """Write report.html into a run or study folder: one self-contained page (interactive plots,
    tables, data embedded; opens without a network) read from the folder's files only."""
    from bodyfusion.evaluation.report import write_report

    say(f"wrote {write_report(folder)}")


@app.command()
def example(name: Annotated[str | None, typer.Argument(help="The example to write (fusion example --list).")] = None,
            out: Annotated[Path | None, typer.Option("--out", help="Folder to write it into (default ./NAME).")] = None,
            list_: Annotated[bool, typer.Option("--list", help="List the examples.")] = False) -> None:
    """Write a packaged example into a folder: its layouts, scenarios or study, the recordings
    they read (with their licences) and a README; then run it as the lines printed say."""
    from bodyfusion.examples import EXAMPLES, commands, write_example
    from bodyfusion.examples import example as find

    if list_:
        for ex in EXAMPLES.values():
            typer.echo(f"{ex.name:<24} {ex.summary}")
        return
    if name is None:
        raise FusionError("name an example: fusion example NAME (fusion example --list lists them)")
    folder = out if out is not None else Path(name)
    written = write_example(name, folder)
    say(f"wrote {folder}: {', '.join(str(p.relative_to(folder)) + '/' * p.is_dir() for p in written)}")
    for line in commands(find(name), folder):
        say(f"next: {line}")


@app.command()
def plugins() -> None:
    """List the installed plugins, the systems each provides, and its package and version."""
    from bodyfusion.core.registry import get_registry

    for info in get_registry().describe():
        typer.echo(f"{', '.join(info.systems):<20} {info.module:<32} {info.package} {info.version}")


class _StderrHandler(logging.StreamHandler):
    """A handler that writes to whatever ``sys.stderr`` is when it emits (so the CLI can be run
    in-process, with stderr redirected, many times, and a progress bar's console can print the
    lines above the bar)."""

    @property
    def stream(self):  # type: ignore[override]
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass


LEVELS = {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO, 2: logging.DEBUG}
"""Verbosity (-q: -1, default 0, -v: 1, -vv: 2) → the level of the ``bodyfusion`` logger."""


def configure_logging(verbosity: int = 0) -> None:
    """The package's log records (``bodyfusion`` and its module loggers) as one line each on
    stderr, ``warning: ...`` (``info:``, ``debug:``, ``error:``), at the level ``verbosity``
    selects (:data:`LEVELS`); the handler is installed once however often ``main`` runs."""
    log = logging.getLogger("bodyfusion")
    if not any(isinstance(h, _StderrHandler) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(_LevelFormatter("%(message)s"))
        log.addHandler(handler)
    log.setLevel(LEVELS[max(-1, min(2, verbosity))])
    log.propagate = False


class _LevelFormatter(logging.Formatter):
    """``level: message``, the level in lower case, as the CLI prints its ``error:`` line."""

    def format(self, record: logging.LogRecord) -> str:
        return f"{record.levelname.lower()}: {super().format(record)}"


def main() -> None:
    """Entry point for a caller in its own process: user errors print one line on stderr and exit
    2, never a traceback; Ctrl-C (SIGINT) exits 130 and SIGTERM 143, each after every open file is
    closed whole (:func:`~bodyfusion.base.interrupts.take_signals`); the caller's signal handlers
    and the package logger's handlers, level and propagation (:func:`configure_logging`) are put
    back after. The process entry is :func:`bodyfusion.__main__.main`."""
    package_log = logging.getLogger("bodyfusion")
    logging_before = (package_log.handlers[:], package_log.level, package_log.propagate)
    previous = take_signals()
    try:
        command()
    finally:
        restore_signals(previous)
        package_log.handlers[:], package_log.propagate = logging_before[0], logging_before[2]
        package_log.setLevel(logging_before[1])


def command() -> None:
    """The command line's work and its exit status, SIGINT and SIGTERM taken already (:func:`main`)."""
    CONSOLE.verbosity = 0  # until the global options say otherwise
    configure_logging()
    unraisable = sys.unraisablehook
    sys.unraisablehook = _dropped_signal(unraisable)
    try:
        _dispatch()
    finally:
        sys.unraisablehook = unraisable


def _dropped_signal(hook: Callable[..., None]) -> Callable[..., None]:
    """``hook`` but for a signal's exception raised where Python can only drop it (inside a C
    callback: LLVM's, as numba compiles): not printed as a traceback, since the command answers
    the signal (:func:`~bodyfusion.base.interrupts.answer_pending`)."""
    def quiet(unraisable) -> None:
        if not isinstance(unraisable.exc_value, (KeyboardInterrupt, Terminated)):
            hook(unraisable)
    return quiet


def _interrupted(err: BaseException) -> bool:
    """Whether a KeyboardInterrupt is among the causes of ``err``."""
    seen: set[int] = set()
    cause: BaseException | None = err
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


def _dispatch() -> None:
    """The command, its outcome turned into the exit status (:func:`main`)."""
    try:
        code = app(standalone_mode=False)  # typer hands back Ctrl-C as exit code 130 here
        answer_pending()  # a signal whose exception a C callback dropped
        if code == 130:
            raise KeyboardInterrupt
        if isinstance(code, int) and code:
            sys.exit(code)
    except Terminated:
        exit_terminated()
    except FusionError as err:
        more = len(getattr(err, "others", ()))
        print(f"error: {err}" + (f" (and {more} more: fusion validate lists every one)" if more else ""),
              file=sys.stderr)
        sys.exit(2)
    except (typer.Abort, KeyboardInterrupt):
        exit_aborted()
    except Exception as err:  # usage errors, from click or from typer's own copy of it
        if _interrupted(err):  # Ctrl-C inside a library that wrapped it (pydantic building a model class)
            exit_aborted()
        import click

        if isinstance(err, (click.ClickException, typer.TyperException)) and hasattr(err, "show"):
            err.show()
            sys.exit(getattr(err, "exit_code", 2))
        raise


if __name__ == "__main__":  # python -m bodyfusion.cli: as the process entry runs it, once this module has loaded
    as_process(command)
