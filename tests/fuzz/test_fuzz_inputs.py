"""Fuzzing: corrupted IMU, truth, GNSS (CSV, NMEA), phone-log, UWB-range files and layouts, each
through ``fusion validate`` and ``fusion run`` in-process. A run either refuses the input with
exit code 2 and one line, or finishes with exit code 0, a trajectories.csv without NaN and a
metrics.json that is strict JSON; never a traceback, never a hang (60 s per command); and a
corrupted file that changes a score past a margin says so with a warning (no silent wrong
result).

Examples per target: ``BODYFUSION_FUZZ_EXAMPLES`` (default 25; 7 targets → 175 inputs).
Hypothesis is derandomised: the same inputs every run, so a failure reproduces. With
``BODYFUSION_FUZZ_TABLE`` set, every case's outcome is appended to that CSV (the long mode:
``benchmarks/fuzz_long.py``)."""

from __future__ import annotations

import contextlib
import copy
import csv
import io
import json
import logging
import math
import os
import shutil
import signal
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, Phase, given, settings

from bodyfusion.cli import main
from tests.fuzz.corruptions import layout_edits, nmea_edits, text_edits
from tests.fuzz.recording import write_recording

EXAMPLES = int(os.environ.get("BODYFUSION_FUZZ_EXAMPLES", "25"))
COMMAND_TIMEOUT_S = 60

fuzz = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
                phases=tuple(p for p in Phase if p is not Phase.shrink or not os.environ.get("FUZZ_NO_SHRINK")))


class Hang(Exception):
    pass


@contextlib.contextmanager
def time_limit(seconds: int) -> Iterator[None]:
    def expire(*_):
        raise Hang(f"command ran over {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def fusion(*args: str) -> tuple[int, str]:
    """``fusion ARGS`` in this process → (exit code, stderr). Exceptions other than the CLI's
    exit propagate: they are the tracebacks the suite looks for."""
    err = io.StringIO()
    argv = sys.argv
    sys.argv = ["fusion", *args]
    log = logging.getLogger("bodyfusion")
    handlers, propagate, level = list(log.handlers), log.propagate, log.level
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err), \
                time_limit(COMMAND_TIMEOUT_S):
            main()
        code = 0
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else 1
    finally:
        sys.argv = argv
        log.handlers[:], log.propagate, log.level = handlers, propagate, level  # as the CLI found it
    return code, err.getvalue()


def _no_constant(name: str) -> float:
    raise ValueError(f"metrics.json holds {name}, not JSON")


def recorded(target: str, edits: list) -> contextlib.AbstractContextManager:
    """The case's outcome appended to the table at ``BODYFUSION_FUZZ_TABLE`` (CSV: target, classes,
    outcome, detail, case, and what ``fusion validate`` said: ok or refused) when that is set (the long mode, ``benchmarks/fuzz_long.py``):
    ``refused`` (exit 2, one line), ``ran`` (exit 0, finite outputs), ``silent`` (a silent wrong
    result, :func:`silent_change`) or ``defect`` (anything else); the test fails on the last two."""
    table = os.environ.get("BODYFUSION_FUZZ_TABLE")
    return _recording(Path(table), target, edits) if table else contextlib.nullcontext()


@contextlib.contextmanager
def _recording(table: Path, target: str, edits: list) -> Iterator[None]:
    classes = "+".join(sorted({type(e).__name__ for e in edits})) or "none"
    outcome, detail, validated = "ran", "", ""
    try:
        yield
        outcome = CASE_OUTCOME.pop("outcome", "ran")
        validated = CASE_OUTCOME.pop("validate", "")
    except BaseException as err:
        first = str(err).splitlines()[0][:160] if str(err) else ""
        outcome = "silent" if first.startswith("silent wrong result") else "defect"
        detail = f"{type(err).__name__}: {first}"
        raise
    finally:
        new = not table.exists()
        with table.open("a", newline="") as f:
            writer = csv.writer(f)
            if new:
                writer.writerow(["target", "classes", "outcome", "detail", "case", "validate"])
            writer.writerow([target, classes, outcome, detail, repr(edits)[:300], validated])


CASE_OUTCOME: dict[str, str] = {}
"""What :func:`check_outcome` found of the case it checked last (``refused`` or ``ran``)."""


SILENT_FACTOR, SILENT_M = 1.5, 0.2
"""A corrupted file's run is a silent wrong result when, with no ``warning:`` line, a system's
horizontal RMSE (m) moved beyond this factor of the clean run's, plus this margin, either way
(a wrong track, or a wrong score: truth in other units)."""


def silent_change(clean: dict, doc: dict, err: str) -> str | None:
    """What a run's metrics.json ``doc`` changed from the ``clean`` run's without a warning on its
    stderr ``err`` (a system gone or its score moved past :data:`SILENT_FACTOR`), or None."""
    if any(line.startswith("warning:") for line in err.splitlines()):
        return None
    scores = {name: (block.get("horizontal_error_m") or {}).get("rmse") for name, block in doc["systems"].items()}
    for name, block in clean["systems"].items():
        before = block["horizontal_error_m"]["rmse"]
        after = scores.get(name)
        if after is None:
            return f"{name}: scored in the clean run ({before:.3f} m), not in this one, and no warning"
        if after > SILENT_FACTOR * before + SILENT_M or before > SILENT_FACTOR * after + SILENT_M:
            return f"{name}: horizontal RMSE {before:.3f} → {after:.3f} m, and no warning"
    return None


def check_outcome(layout: Path, out: Path, clean: dict | None = None) -> None:
    """validate then run: exit 0 or 2; a refusal says one ``error:`` line; a finished run wrote
    finite trajectories and strict JSON, and, given the ``clean`` run's metrics of the same layout,
    did not change a score past :data:`SILENT_FACTOR` without a warning."""
    code, err = fusion("validate", str(layout))
    assert code in (0, 2), f"validate exit {code}: {err}"
    CASE_OUTCOME["validate"] = "refused" if code == 2 else "ok"
    code, err = fusion("run", str(layout), "--out", str(out))
    assert code in (0, 2), f"run exit {code}: {err}"
    if code == 2:
        errors = [line for line in err.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and "Traceback" not in err, err
        CASE_OUTCOME["outcome"] = "refused"
        return
    doc = json.loads((out / "metrics.json").read_text(), parse_constant=_no_constant)
    with (out / "trajectories.csv").open() as f:
        reader = csv.reader(f)
        header = next(reader)
        for row in reader:  # an empty cell: a state the system does not have, or a σ it does not give
            values = [float(v) for v in row[1:] if v]
            assert len(values) >= 7, f"a position or its σ missing in trajectories.csv: {dict(zip(header, row))}"
            assert all(math.isfinite(v) for v in values), f"non-finite value in trajectories.csv: {dict(zip(header, row))}"
    silent = silent_change(clean, doc, err) if clean is not None else None
    assert silent is None, f"silent wrong result: {silent}"


@pytest.fixture(scope="module")
def recording() -> Iterator[tuple[Path, dict[str, Path]]]:
    """The clean recording, written once, and its layouts; each clean layout runs (also
    compiles the kernels before the timed examples)."""
    folder = Path(tempfile.mkdtemp(prefix="fuzz_recording_"))
    layouts = write_recording(folder)
    for name, layout in layouts.items():
        code, err = fusion("run", str(layout), "--out", str(folder / f"clean_{name}"))
        assert code == 0, err
    yield folder, layouts
    shutil.rmtree(folder, ignore_errors=True)


def write_text(path: Path, text: str) -> None:
    try:
        data = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:
        data = text.encode("utf-8", "surrogatepass")
    path.write_bytes(data)


def corrupt_and_run(recording: tuple[Path, dict[str, Path]], layout: str, target: str,
                    edits: list[Callable[[str], str]]) -> None:
    folder, layouts = recording
    with tempfile.TemporaryDirectory(prefix="fuzz_case_") as case:
        case_dir = Path(case)
        for path in folder.iterdir():
            if path.is_file():
                os.link(path, case_dir / path.name)  # hard links: only the corrupted file is new
        text = (folder / target).read_text()
        for edit in edits:
            text = edit(text)
        (case_dir / target).unlink()
        write_text(case_dir / target, text)
        clean = json.loads((folder / f"clean_{layout}" / "metrics.json").read_text())
        with recorded(target, edits):
            check_outcome(case_dir / layouts[layout].name, case_dir / "out", clean)


TARGETS = [("csv", "left_foot_imu.csv"), ("csv", "truth.csv"), ("csv", "hand_phone_gnss.csv"),
           ("csv", "feet_tags_ranges.csv"), ("phone_log", "hand_phone_log.txt")]


@pytest.mark.slow
@pytest.mark.parametrize(("layout", "target"), TARGETS, ids=[t for _, t in TARGETS])
@fuzz
@given(edits=text_edits)
def test_corrupted_file_is_refused_or_run_finite(recording, layout, target, edits):
    corrupt_and_run(recording, layout, target, edits)


@pytest.mark.slow
@fuzz
@given(edits=nmea_edits)
def test_corrupted_nmea_is_refused_or_run_finite(recording, edits):
    corrupt_and_run(recording, "nmea", "hand_phone_gnss.nmea", edits)


@pytest.mark.slow
@fuzz
@given(edits=layout_edits)
def test_corrupted_layout_is_refused_or_run_finite(recording, edits):
    folder, layouts = recording
    doc_edits, text_edits_ = edits
    doc = copy.deepcopy(yaml.safe_load(layouts["csv"].read_text()))
    for edit in doc_edits:
        edit(doc)
    text = yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
    for edit in text_edits_:
        text = edit(text)
    with tempfile.TemporaryDirectory(prefix="fuzz_layout_", dir=folder) as case:
        layout = Path(case) / "layout.yaml"
        layout.write_text(text)
        # the layout's data paths are relative to its folder: point them at the recording
        text = text.replace("path: ", "path: ../")
        layout.write_text(text)
        with recorded("layout.yaml", [*doc_edits, *text_edits_]):
            check_outcome(layout, Path(case) / "out")
