"""A layout fused live: rows pushed as they arrive, states emitted as the data decide them.

:class:`LiveRun` takes each system's rows as its data section names their columns (the file's
own columns and units: ``time_column``, ``acc_columns``...; one schema per sensor type, the
layout's), by :meth:`LiveRun.push`. It runs the batch run's path on a growing recording
(:mod:`bodyfusion.runner.batch`): once every system holds ``warmup_s`` of data, the systems are
built on that first part (bound as in-memory tables), levelled and heading-aligned as a batch
run does, and handed to the fuser (:func:`~bodyfusion.runner.batch.prepare_fusion`); then every
``replan_s`` of new data each system takes its longer table
(:meth:`~bodyfusion.core.capabilities.Streaming.extend`) and the fuser advances to the time
all of them have decided (:meth:`~bodyfusion.core.fuser.Fuser.advance`), emitting an
:class:`~bodyfusion.core.epoch_state.EpochState` every ``output_interval_s`` of data to the
sinks. A start that fails on the data so far (a foot has not ended its first rest, no system
has walked far enough to align its heading) is tried again every :data:`RETRY_S` of data, and
at the close on the whole recording. :meth:`LiveRun.close` completes the recording and finishes the run as a batch run does
(:func:`~bodyfusion.runner.batch.finish_fusion`): the same :class:`~bodyfusion.results.run_result.RunResult`.

Bounded history (``keep_s``, ``fusion live --keep``): every ``keep_s`` of decided data each
system forgets its samples more than ``keep_s`` behind its decided time, as far as what it still
has to decide allows (:meth:`~bodyfusion.core.capabilities.Streaming.forget_before`), its buffer
as many rows (:meth:`RowBuffer.forget`) and the fuser its older constraint epochs
(:meth:`~bodyfusion.core.fuser.Fuser.forget_before`): a run of any length holds a bounded
memory and emits the states of a run that keeps everything; its finished result covers the part
kept.

Streams: a system's data section paces the run (its rows are waited for); a system may stream
aiding sections beside it (:meth:`~bodyfusion.core.capabilities.Streaming.streamed_sections`: the
phone's GNSS), whose rows are taken as they come and never hold the run up. Each is a
:class:`RowBuffer` in ``buffers``, named by :meth:`LiveRun.stream_name`.

Delay: a state at t is emitted once every system's data reach t + the look-ahead (2 s) and the
next replan has run. Each system must offer :class:`~bodyfusion.core.capabilities.Streaming`
(the foot INS, the hand-held phone and the UWB tag do). An aiding source's rows (a UWB tag's
ranges) do not pace the run (:attr:`~bodyfusion.core.capabilities.Streaming.paces_live`): they are
taken as they come, and one that arrives after the fuser passed its time is counted late by the
schedule, not applied.

Smoothing: with ``smoother.kind: fixed-lag`` every system that smooths live
(:meth:`~bodyfusion.core.capabilities.Smoothing.live_smoother`: the foot INS) hands on after each
pass the samples its fixed-lag smoother now decides, merged into a second stream of epochs
(:mod:`bodyfusion.live.smoothed`); the other smoothers need the whole run and are refused.

Scores: with ``keep_s`` and a truth, every state emitted is scored as it passes
(:class:`~bodyfusion.evaluation.streamed_scores.StreamedScores`, the result's ``whole_run``),
and the truth is read as the run goes (:func:`~bodyfusion.runner.truth.truth_stream`, a
:class:`~bodyfusion.io.truth.TruthWindow` per system): held from the earliest epoch the scores
or the part kept still need, so that a scored run of any length holds a bounded truth too. The
finished result is scored against the truth of the part kept.
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
import time
from collections import deque
from collections.abc import Mapping, Sequence

import numpy as np

from bodyfusion.base.errors import ConfigError, FusionError, InputError, NotReady
from bodyfusion.base.records import GrowingArray
from bodyfusion.base.sections import TableSection
from bodyfusion.core.capabilities import Smoothing, Streaming, offers
from bodyfusion.core.compile_ahead import compile_fuser_kernels
from bodyfusion.core.epoch_state import EpochOutput, EpochSink
from bodyfusion.core.layout import LoadedLayout
from bodyfusion.core.registry import get_registry
from bodyfusion.evaluation.streamed_scores import StreamedScores
from bodyfusion.io.truth import TruthWindow
from bodyfusion.live.smoothed import SmoothedEpochs
from bodyfusion.results.run_result import RunResult
from bodyfusion.runner.batch import Fusion, finish_fusion, prepare_fusion
from bodyfusion.runner.truth import truth_stream

LOOKAHEAD_S = 2.0
"""Default look-ahead (s) behind the newest sample at which a system's decisions are final: a
foot INS's stance decisions need at most about 1 s on every shared foot recording
(``benchmarks/stance_lookahead.py``)."""
WARMUP_S = 10.0
"""Data (s) every system holds before the run starts: its levelling rest and first metres."""
REPLAN_S = 0.5
"""Data (s) between two passes over the growing recordings, when they arrive at their pace."""
REPLAN_BATCH_S = 30.0
"""Data (s) between two passes of a replay as fast as it runs: fewer passes for the same data
(a pass derives its context again whatever the data it adds)."""
RETRY_S = 2.0
"""Data (s) between two tries to start on a recording not ready yet."""
LATENCIES_KEPT = 1 << 16
"""Passes whose latency a run keeps (the last ones: 9 h of passes every 0.5 s)."""
OUTPUT_INTERVAL_S = 0.1
"""Spacing (s) of the output epochs."""
LIVE_BOUNDS = {"lookahead_s": ("fusion live --lookahead", 0.01, 600.0),
               "warmup_s": ("fusion live --warmup", 0.01, 3600.0),
               "replan_s": ("LiveRun's replan_s", 0.01, 600.0),
               "output_interval_s": ("fusion live --interval", 1e-3, 3600.0),
               "keep_s": ("fusion live --keep", 10.0, 30 * 86400.0)}
"""A live run's timing parameter → (its command-line option, least and most value, s): an output
epoch every millisecond at the most; decisions, warm-up and passes within minutes; a history
kept of 10 s (less than a pass derives again) to 30 days."""


def _is_nan(value: object) -> bool:
    """``value`` is a NaN (a failed measurement a reader drops by its policy) or empty."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return True
    try:
        return math.isnan(float(value))  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return False


def _finite(value: object) -> float | None:
    """``value`` as a finite float, or None (not a number, NaN or infinite)."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):  # an int beyond a float's range too
        return None
    return number if math.isfinite(number) else None


class RowBuffer:
    """The rows of one of a system's streamed sections as they arrive: the columns the section
    reads, and each row's time (s) as the section defines it, in
    :class:`~bodyfusion.base.records.GrowingArray` records (the section's text columns, an anchor's
    id, as text beside the numbers). ``key``: the section's dotted key (``systems.NAME.SECTION``);
    ``paces``: the run waits for these rows (a navigation system's data section), or takes them as
    they come (an aiding section, a phone's GNSS, a UWB tag's ranges)."""

    def __init__(self, section: TableSection, key: str, paces: bool = True) -> None:
        self.section, self.key, self.paces = section, key, paces
        self.system, _, self.section_name = key.removeprefix("systems.").rpartition(".")
        self.columns = section.required_columns()
        self.text_columns = [c for c in self.columns if c in section.text_columns()]
        self.number_columns = [c for c in self.columns if c not in self.text_columns]
        self._gap_columns = set(section.gap_columns())
        self._share_times = section.rows_share_times
        self._time_column = getattr(section, "time_column", None)
        self._time_scale = float(getattr(section, "time_scale", 1.0))
        self._rate_hz = getattr(section, "rate_hz", None)
        self._data = GrowingArray((len(self.number_columns),), capacity=1024)
        self._text = GrowingArray((len(self.text_columns),), dtype=object, capacity=1024)
        self._t = GrowingArray((), capacity=1024)
        self._time_index = (self.number_columns.index(self._time_column) if self._time_column is not None
                            else None)
        self.newest_t = -math.inf
        """Time (s) of the newest row (−∞ before the first)."""
        self.dropped = 0
        """Rows dropped for a time not after the newest (before it, where rows may share a time)."""
        self.forgotten = 0
        """Rows forgotten from the front (:meth:`forget`): row k held is the stream's row k + forgotten."""

    def add(self, row: Mapping[str, float | str]) -> bool:
        """Append ``row`` (column → value; every column the section reads); a row whose time is not
        after the newest (before it, where rows share times) is dropped and counted (``dropped``):
        the rows of a live recording come in time order, so that row k is sample k for good. True
        when it was kept."""
        try:  # the common row: numbers, every one finite
            values = [float(row[c]) for c in self.number_columns]  # type: ignore[arg-type]
            plain = all(map(math.isfinite, values))
        except (KeyError, TypeError, ValueError, OverflowError):
            plain = False
        if not plain:
            values = [self.cell(c, row.get(c)) for c in self.number_columns]  # type: ignore[misc]
        text = [self.cell(c, row.get(c)) for c in self.text_columns] if self.text_columns else None
        if not plain and None in values or text is not None and None in text:
            self._refuse(row)
        t = (values[self._time_index] * self._time_scale if self._time_index is not None
             else float(self._time(0.0, self.forgotten + self.rows)))
        if t < self.newest_t or (t == self.newest_t and not self._share_times):
            self.dropped += 1
            return False
        self._data.append(values)
        if text is not None:
            self._text.append(np.array(text, dtype=object))
        self._t.append(t)
        self.newest_t = t
        return True

    def cell(self, column: str, value: object) -> float | str | None:
        """``value`` as the section reads ``column``: a finite float (NaN for an empty or NaN cell of
        a gap column), or a name in a text column; None when it is neither."""
        if column in self.text_columns:
            return value.strip() or None if isinstance(value, str) else None
        if column in self._gap_columns and _is_nan(value):
            return math.nan
        return _finite(value)

    def _refuse(self, row: Mapping[str, object]) -> None:
        """The error for a row without a column the section reads, or with a cell that is no finite
        number (refused as the batch reader refuses a bad cell, here with the system's row number;
        NaN allowed in a gap column) or no text in a text column."""
        missing = [c for c in self.columns if c not in row]
        if missing:
            raise ConfigError(self.key, f"a row without column(s) {', '.join(missing)}")
        where = f"{self.key}: row {self.forgotten + self.rows + self.dropped + 1}"
        for c in self.text_columns:
            if not isinstance(row[c], str) or not row[c].strip():
                raise InputError(where, f"{c} is {reprlib.repr(row[c])}, not a name")
        bad = next(c for c in self.number_columns if self.cell(c, row[c]) is None)
        raise InputError(where, f"{bad} is {reprlib.repr(row[bad])}, not a finite number")

    def forget(self, d: int) -> None:
        """Drop the first ``d`` rows held (their system forgot as many samples)."""
        d = min(max(d, 0), self.rows)
        self._data.drop_first(d)
        if self.text_columns:
            self._text.drop_first(d)
        self._t.drop_first(d)
        self.forgotten += d

    @property
    def rows(self) -> int:
        """Rows held."""
        return len(self._t)

    def times(self, columns: Mapping[str, np.ndarray], first: int = 0) -> np.ndarray:
        """Times (s) of rows ``columns`` (column → array), the first of them row ``first``
        (:meth:`_time`)."""
        n = len(next(iter(columns.values())))
        value = np.asarray(columns[self._time_column], dtype=float) if self._time_column is not None else 0.0
        return np.broadcast_to(self._time(value, first + np.arange(n)), (n,))

    def time_of(self, row: Mapping[str, object], k: int) -> float | None:
        """The time (s) of the stream's row ``k`` with cells ``row`` (None: its time cell is no
        finite number)."""
        if self._time_column is None:
            return float(self._time(0.0, k))
        value = _finite(row.get(self._time_column))
        return None if value is None else float(self._time(value, k))

    def _time(self, value: float | np.ndarray, row: int | np.ndarray) -> float | np.ndarray:
        """The time (s) of a row (scalars or arrays) as the section defines it: its time column's
        ``value`` × ``time_scale``, or the row number ``row`` / ``rate_hz``."""
        if self._time_column is not None:
            return value * self._time_scale
        return row / float(self._rate_hz)

    @property
    def span_s(self) -> float:
        """Time (s) from the first row held to the newest."""
        t = self._t.view()
        return float(t[-1] - t[0]) if t.size else 0.0

    def table(self) -> dict[str, np.ndarray]:
        """The rows so far as an in-memory table (column → array; a text column's of str)."""
        data, text = self._data.view(), self._text.view()
        out = {c: data[:, k] for k, c in enumerate(self.number_columns)}
        out.update({c: text[:len(data), k] for k, c in enumerate(self.text_columns)})
        return {c: out[c] for c in self.columns}


class LiveRun:
    """``loaded`` fused live (module docstring). ``sinks``: where the output epochs go;
    ``lookahead_s``, ``warmup_s``, ``replan_s``, ``output_interval_s`` (s); ``seed`` as a batch
    run's; ``keep_s``: the history (s) held behind the decided data (None: all of it), so that a
    run of any length holds a bounded memory (module docstring). Results: ``fusion`` (None until
    started), ``emitted`` epochs, ``latency_s``: for every pass, the wall time (s) from the
    arrival of the row that made it due to its last epoch emitted (the data's own delay, the
    look-ahead and the replan interval, comes on top), for the last :data:`LATENCIES_KEPT` passes."""

    def __init__(self, loaded: LoadedLayout, sinks: Sequence[EpochSink] = (), *, lookahead_s: float = LOOKAHEAD_S,
                 warmup_s: float = WARMUP_S, replan_s: float = REPLAN_S, output_interval_s: float = OUTPUT_INTERVAL_S,
                 seed: int = 0, keep_s: float | None = None) -> None:
        for key, value in (("lookahead_s", lookahead_s), ("warmup_s", warmup_s), ("replan_s", replan_s),
                           ("output_interval_s", output_interval_s), ("keep_s", keep_s)):
            if value is None:
                continue
            option, least, most = LIVE_BOUNDS[key]
            if not least <= value <= most:
                raise ConfigError(f"{key} ({option})", f"{value!r} s: give {least:g} to {most:g} s")
        self.loaded = loaded.checked()
        layout = self.loaded.layout
        if layout.smoother.kind not in ("none", "fixed-lag"):
            raise ConfigError("smoother.kind", f"{layout.smoother.kind}: a live run smooths with fixed-lag only "
                                               "(or none)", loaded.path)
        self.buffers: dict[str, RowBuffer] = {}
        """Every streamed section's rows, by stream: a system's name for its data section,
        ``NAME.SECTION`` for an aiding section (:meth:`stream_name`)."""
        for name, cfg in self.loaded.system_configs.items():
            cls = get_registry().system_class(cfg.plugin, key=f"systems.{name}.plugin", path=loaded.path)
            if not issubclass(cls, Streaming) or cls.data_section is None:
                raise ConfigError(f"systems.{name}.plugin", f"{cfg.plugin} does not run live (it cannot take a "
                                                            "growing recording)", loaded.path)
            try:
                sections = cls.streamed_sections(cfg)
            except ConfigError as err:
                raise ConfigError(f"systems.{name}.{err.key}", err.reason, loaded.path) from None
            for k, section_name in enumerate(sections):
                section = getattr(cfg, section_name)
                key = f"systems.{name}.{section_name}"
                if keep_s is not None and getattr(section, "time_column", None) is None:
                    raise ConfigError(f"{key}.time_column", "a live run that keeps a bounded history (--keep) needs "
                                                            "each row's time in a column, not a row count / rate_hz",
                                      loaded.path)
                self.buffers[self.stream_name(name, None if k == 0 else section_name)] = RowBuffer(
                    section, key, k == 0 and cls.paces_live)
        self._pacing = [b for b in self.buffers.values() if b.paces]
        self.output = EpochOutput(output_interval_s, sinks)
        self.lookahead_s, self.warmup_s, self.replan_s, self.seed = lookahead_s, warmup_s, replan_s, seed
        self.keep_s = keep_s
        self._forgot_at = -math.inf
        self.fusion: Fusion | None = None
        self.latency_s: deque[float] = deque(maxlen=LATENCIES_KEPT)
        self._planned_t = -math.inf
        self._start_after_s = warmup_s
        self.started: tuple[float, float] | None = None
        """When the run started: the data's time (s) and the wall time (s, :func:`time.perf_counter`)
        at the end of its first pass (None: not yet, or only at the close)."""
        self.truth: dict[str, TruthWindow] = {}
        """The truth by system as the scores read it: with ``keep_s``, read as the run goes; else the
        tracks read whole (module docstring)."""
        self.scorer: StreamedScores | None = None
        """With ``keep_s`` and a truth: the scores of every state emitted (the finished result's
        ``whole_run``; its ``scores`` cover the part kept)."""
        self.smoothed: SmoothedEpochs | None = None
        """With ``smoother.kind: fixed-lag``, once started: the smoothed stream (:mod:`bodyfusion.live.smoothed`)."""
        self.smoothed_scorer: StreamedScores | None = None
        """With the smoothed stream and a truth: the scores of every smoothed state emitted."""
        self.not_smoothed: dict[str, str] = {}
        """The systems not in the smoothed stream, and why."""
        self.not_started: NotReady | None = None
        """Why the run could not start on the data so far (it tries again every :data:`RETRY_S` of data)."""

    @property
    def emitted(self) -> int:
        return self.output.emitted

    @property
    def held_s(self) -> float:
        """The longest recording (s) a system's buffer holds now: with ``keep_s``, about ``keep_s``
        to twice it plus what each pass derives again; without, the whole run so far."""
        return max(b.span_s for b in self.buffers.values())

    @staticmethod
    def stream_name(system: str, section: str | None = None) -> str:
        """The name of a system's stream of rows: the system's own for its data section (``section``
        None), ``SYSTEM.SECTION`` for an aiding section (a phone's ``hand.gnss``)."""
        return system if section is None else f"{system}.{section}"

    def push(self, system: str, row: Mapping[str, float], section: str | None = None) -> None:
        """A row of ``system``'s data section (column → value, as the section names them), or of its
        aiding ``section`` (a phone's ``gnss``), then a pass when one is due (:meth:`pump`)."""
        buffer = self.buffers.get(system if section is None else f"{system}.{section}")
        if buffer is None:
            raise ConfigError("system", f"{self.stream_name(system, section)!r} is no stream of this layout "
                                        f"({', '.join(self.buffers)})")
        arrived = time.perf_counter()
        buffer.add(row)
        if self.fusion is not None and buffer.newest_t < self._planned_t + self.replan_s:
            return  # no pass is due before every pacing stream reaches that time, this one included
        if self.pump():
            self.latency_s.append(time.perf_counter() - arrived)

    def pump(self) -> bool:
        """Start once every system holds the warm-up; afterwards a pass every ``replan_s`` of data.
        True when it made a pass. The data sections pace it; an aiding section's rows (fixes) are
        taken as they come."""
        newest = min(b.newest_t for b in self._pacing)
        if self.fusion is None:
            if all(b.span_s >= self._start_after_s for b in self._pacing):
                self.loaded.tables.update({b.key: b.table() for b in self.buffers.values()})
                try:
                    self.fusion = prepare_fusion(self.loaded, self.seed, output=self.output,
                                                 lookahead_s=self.lookahead_s, read_truth=self.keep_s is None)
                except NotReady as err:  # not enough yet: no rest ended, no system travelled far enough to align
                    self.not_started = err
                    self._start_after_s += RETRY_S
                    return False
                compile_fuser_kernels(self.loaded.layout)  # loaded now: no later pass waits ~10 ms for one
                self._open_truth()
                if self.keep_s is not None and self.truth:  # the result will cover the last part only
                    truth = self.loaded.layout.truth
                    self.scorer = StreamedScores(self.truth, truth.alignment, truth.alignment_distance_m)
                    self.output.sinks = [*self.output.sinks, self.scorer]
                self._start_smoothing()
                self._advance(newest)
                self.started = (newest, time.perf_counter())
                return True
            return False
        if newest >= self._planned_t + self.replan_s:
            self._read_tables(lambda s: s.extend())
            self._advance(newest)
            return True
        return False

    def _open_truth(self) -> None:
        """The truth windows (:attr:`truth`): with ``keep_s`` each system's track read as the run
        goes, a first chunk read now (a system without one has no truth; a file refused there is
        refused now); else the tracks read whole."""
        if self.keep_s is None:
            self.truth = {name: TruthWindow(iter([track])) for name, track in self.fusion.truths.items()}
            return
        cfg = self.loaded.layout.truth
        if cfg is None or (cfg.path is None and cfg.table is None):
            return
        for name in self.loaded.layout.systems:
            window = TruthWindow(truth_stream(cfg, self.fusion.origin, name), name)
            window.read_through(-math.inf)
            if window.error is not None and not window.epochs:  # refused from its start, as a batch run refuses it
                raise window.error
            if window.epochs:
                self.truth[name] = window

    def _read_tables(self, read) -> None:
        """Bind each buffer's rows to its system's section (the section the built system reads) and
        let each system ``read`` them."""
        for b in self.buffers.values():
            getattr(self.fusion.built[b.system].config, b.section_name).bind(b.table(), b.key)
        for plugin in self.fusion.built.values():
            read(plugin)

    def _start_smoothing(self) -> None:
        """With ``smoother.kind: fixed-lag``: every system that smooths live in the smoothed stream
        (the others in :attr:`not_smoothed`), scored where the layout has a truth for it."""
        cfg = self.loaded.layout.smoother
        if cfg.kind == "none":
            return
        smoothers = {}
        for name, system in self.fusion.systems.items():
            if not offers(system, Smoothing):
                self.not_smoothed[name] = "it does not smooth"
                continue
            try:
                smoothers[name] = system.live_smoother(cfg)
            except FusionError as err:
                self.not_smoothed[name] = str(err)
        self.smoothed = SmoothedEpochs(smoothers, self.output, cfg.lag_s)
        truths = {name: window for name, window in self.truth.items() if name in smoothers}
        if truths:
            truth = self.loaded.layout.truth
            self.smoothed_scorer = StreamedScores(truths, truth.alignment, truth.alignment_distance_m, smoothed=True)
            self.output.sinks = [*self.output.sinks, self.smoothed_scorer]

    def _advance(self, newest: float) -> None:
        self._planned_t = newest
        self.fusion.fuser.advance()
        if self.smoothed is not None:
            self.smoothed.advance()
        self._forget()

    def _forget(self) -> None:
        """With ``keep_s``: once the decided data have run ``keep_s`` past the last time forgotten,
        every system forgets its samples more than ``keep_s`` before them and its buffer as many
        rows (so each row is moved about once, and at most 2 × ``keep_s`` of rows are held)."""
        if self.keep_s is None:
            return
        decided = min(s.decided_until() for s in self.fusion.systems.values())
        if not math.isfinite(decided) or decided - self.keep_s < self._forgot_at + self.keep_s:
            return
        self._forgot_at = decided - self.keep_s
        for window in self.truth.values():  # the finish scores the part kept
            window.hold_from(self._forgot_at)
        for name, system in self.fusion.built.items():  # the navigation systems and the aiding sources
            for section_name, rows in system.forget_before(self._forgot_at).items():
                self.buffers[self.stream_name(name, None if section_name == system.data_section else section_name)
                             ].forget(rows)
        for monitor in self.fusion.monitors.values():
            monitor.forget_passed()
        self.fusion.fuser.forget_before(self._forgot_at)

    def close(self) -> RunResult:
        """The recordings are complete: every system reads its whole table, the run finishes as a
        batch run (:func:`~bodyfusion.runner.batch.finish_fusion`, every remaining epoch emitted)
        and the sinks are closed. A run that never started starts now, on the whole recording; one
        without any row is refused."""
        try:
            if self.fusion is None:  # never ready: the whole recording is in hand now
                if not all(b.rows for b in self.buffers.values() if b.paces):
                    raise ConfigError("--source", "no rows arrived for " + ", ".join(
                        n for n, b in self.buffers.items() if b.paces and not b.rows))
                self.loaded.tables.update({b.key: b.table() for b in self.buffers.values()})
                self.fusion = prepare_fusion(self.loaded, self.seed, output=self.output, lookahead_s=self.lookahead_s,
                                             complete=True, read_truth=self.keep_s is None)
                self._open_truth()
                self._start_smoothing()
            if self.keep_s is not None and self.truth:  # the truth of the part kept, and the spans read
                self.fusion.truths = {name: window.track() for name, window in self.truth.items()}
                self.fusion.truth_spans = {name: window.span for name, window in self.truth.items()}
            self._read_tables(lambda s: s.close_stream())
            result = finish_fusion(self.fusion)
            if self.smoothed is not None:  # the recordings complete: every segment to the end
                self.smoothed.advance(final=True)
                result = dataclasses.replace(result, live_smoothing={
                    **self.smoothed.diagnostics(), "not_smoothed": dict(self.not_smoothed)})
            self.output.close()  # the last states scored
            if self.scorer is not None:
                result = dataclasses.replace(result, whole_run=self.scorer.scores())
            if self.smoothed_scorer is not None:
                result = dataclasses.replace(result, whole_run_smoothed=self.smoothed_scorer.scores())
            return result
        finally:
            self.output.close()
