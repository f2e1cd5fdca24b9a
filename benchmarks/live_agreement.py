"""Does a live run give the batch run? Every shared foot recording, replayed live and run batch.

Each recording's layout (as the generalisation benchmark builds it: PyShoe's 21 trials, the
dual-foot Vicon walk with its constraint, the x-io loop) is run batch
(:func:`bodyfusion.runner.batch.run_layout`) and live (:class:`bodyfusion.live.engine.LiveRun`,
its rows replayed as fast as it takes them, the engine's defaults: look-ahead 2 s, a pass every
0.5 s of data, 30 s of context). Per recording: whether every track is the batch one bit for
bit, the largest position difference (m), the samples whose inputs the whole recording would
have made otherwise (``revised_inputs``), whether the live run levelled on another rest than
the whole recording's (``live_levelling``: a batch run levels on the first rest as still as the
recording's stillest, which a live run cannot know), and the replay's speed (× real time), and both runs' horizontal RMSE against the truth. A
recording is *explained* when it is identical or one of those two says why it is not.

``--set KEY=VALUE`` overrides every layout. With ``--set smoother.kind=fixed-lag`` the live run
also emits the fixed-lag smoother's stream (:mod:`bodyfusion.live.smoothed`); each recording's line
then says whether every smoothed state is the batch fixed-lag smoother's track at its sample, bit
for bit (``smoothed identical``), and the largest difference.

Last line: ``identical=<n>/<recordings> explained=<n>/<recordings> revised_samples=<sum>
max_difference_m=<m>`` (and ``smoothed_identical=<n>/<recordings> smoothed_max_difference_m=<m>``
with the fixed-lag smoother).

Usage: python benchmarks/live_agreement.py [--data ../shared/data] [--set KEY=VALUE]...
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import generalisation as gen  # noqa: E402  (the benchmark beside this one: the data sets' layouts)

from bodyfusion.core.layout import validate_layout  # noqa: E402
from bodyfusion.core.layout_io import apply_overrides  # noqa: E402
from bodyfusion.live.engine import LiveRun  # noqa: E402
from bodyfusion.live.sources import replay, replay_rows  # noqa: E402
from bodyfusion.runner.batch import run_layout  # noqa: E402


class SmoothedStates:
    """A sink keeping the smoothed states a live run emits."""

    def __init__(self) -> None:
        self.states = []

    def write(self, state) -> None:
        if state.smoothed_lag_s is not None:
            self.states.append(state)

    def close(self) -> None:
        pass

    def difference(self, tracks) -> float:
        """The largest |smoothed state − ``tracks`` at its sample| (m) over every state and system."""
        worst = 0.0
        for name, track in tracks.items():
            t = np.array([s.systems[name].t for s in self.states])
            p = np.array([s.systems[name].position_n for s in self.states])
            i = np.minimum(np.searchsorted(track.t, t), len(track.t) - 1)
            worst = max(worst, float(np.abs(track.pos_n[i] - p).max()) if np.array_equal(track.t[i], t) else np.inf)
        return worst


def _layouts(data: Path) -> list[tuple[str, dict]]:
    out = [(f"pyshoe/{trial.name}", gen.pyshoe_layout(trial))
           for trial in gen.DATASETS["pyshoe"][1](data / gen.DATASETS["pyshoe"][0])]
    out += [(f"vicon/{Path(folder).name}", gen.vicon_layout(Path(folder)))
            for folder in gen.DATASETS["vicon"][1](data / gen.DATASETS["vicon"][0])]
    out += [(f"xio/{Path(csv).name}", gen.xio_layout(Path(csv)))
            for csv in gen.DATASETS["xio"][1](data / gen.DATASETS["xio"][0])]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=lambda p: Path(p).resolve(), default=gen.DEFAULT_DATA)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override every layout")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"live_agreement: no shared data at {args.data}")
        return 0
    identical, explained, revised, worst = 0, 0, 0, 0.0
    changes: list[float] = []
    recordings = _layouts(args.data)
    smoothed_identical, smoothed_worst = 0, 0.0
    for recording, layout in recordings:
        layout = apply_overrides(layout, args.set)
        batch = run_layout(validate_layout(layout, None, args.data))
        states = SmoothedStates()
        run = LiveRun(validate_layout(layout, None, args.data), [states])
        rows = list(replay_rows(run))
        wall0 = time.perf_counter()
        replay(run, iter(rows))
        live = run.close()
        speed = (rows[-1][0] - rows[0][0]) / (time.perf_counter() - wall0)
        same = all(np.array_equal(live.trajectories[n].pos_n, t.pos_n) for n, t in batch.trajectories.items())
        diff = max(float(np.abs(live.trajectories[n].pos_n - t.pos_n).max()) for n, t in batch.trajectories.items())
        moved = sum(s.revised_inputs for s in live.systems.values())
        levelled = [f.system for f in live.findings if f.kind == "live_levelling"]
        explained += same or bool(moved or levelled)
        identical += same
        revised += moved
        worst = max(worst, diff)
        rmse = [(score.metrics["horizontal_error_m"]["rmse"], live.scores[n].metrics["horizontal_error_m"]["rmse"])
                for n, score in batch.scores.items()]
        changes += [b - a for a, b in rmse]
        smoothed = ""
        if states.states:
            sdiff = states.difference(batch.trajectories)
            smoothed_identical += sdiff == 0.0
            smoothed_worst = max(smoothed_worst, sdiff)
            smoothed = f"  smoothed {'identical' if sdiff == 0.0 else f'max {sdiff:.3g} m'} ({len(states.states)})"
        print(f"  {recording:<40} {'identical' if same else 'differs':<9} max {diff:.3g} m  revised {moved:>5}  "
              f"{'levelled otherwise' if levelled else '':<18} h-RMSE batch {'/'.join(f'{a:.3f}' for a, _ in rmse)} "
              f"live {'/'.join(f'{b:.3f}' for _, b in rmse)} m  {speed:6.1f}x real time{smoothed}")
    changes_a = np.array(changes)
    print(f"live h-RMSE minus batch h-RMSE over {changes_a.size} tracks: median {np.median(changes_a):+.4f} m, "
          f"largest {changes_a.max():+.4f} m, smallest {changes_a.min():+.4f} m")
    smoothed_line = (f" smoothed_identical={smoothed_identical}/{len(recordings)} "
                     f"smoothed_max_difference_m={smoothed_worst:.3g}") if "smoother.kind=fixed-lag" in args.set else ""
    print(f"identical={identical}/{len(recordings)} explained={explained}/{len(recordings)} revised_samples={revised} "
          f"max_difference_m={worst:.3g}{smoothed_line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
