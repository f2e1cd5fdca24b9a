"""Fixed-lag smoothing against the filter and the whole-run RTS, on every shared foot recording.

The fixed-lag smoother (``smoother.kind: fixed-lag``) smooths each stride with the data up to
at least ``lag_s`` after it: the estimate a live run could emit with that delay. Here it runs
at several lags over the foot recordings of the generalisation benchmark
(:mod:`generalisation`: PyShoe's 21 trials, the dual-foot Vicon walk with and without the
body's limit, the x-io loop; each scored by its set's figure of merit), beside the filter alone
(``none``) and the whole-run RTS (``rts``). For each set it prints the median figure and, per
recording, how far the fixed-lag figure is from the RTS one (mean |fixed-lag − RTS|, m): the
gap that should close as the lag grows. The data set's own figure is affected by heading drift
over the whole walk, which a short lag cannot undo: the in-stride errors are what a lag of a
stride or two smooths.

Usage: python benchmarks/fixed_lag.py [--data ../shared/data] [--lags 0.5 1 2 4 8 30] [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import generalisation as gen  # noqa: E402  (the benchmark beside this one)

SETS = ("pyshoe", "vicon", "vicon_limit", "xio")


def _figures(keys: tuple[str, ...], data: Path, overrides: list[str], workers: int) -> dict[tuple[str, str], float]:
    """(set, recording) → the set's figure of merit under ``overrides``."""
    jobs = [(key, str(rec)) for key in keys for rec in gen.DATASETS[key][1](data / gen.DATASETS[key][0])]
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        rows = [row for f in [pool.submit(gen._job, key, rec, overrides) for key, rec in jobs] for row in f.result()]
    return {(r.dataset, r.recording): (np.nan if r.value is None else r.value) for r in rows}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=lambda p: Path(p).resolve(), default=gen.DEFAULT_DATA)
    parser.add_argument("--lags", type=float, nargs="+", default=[0.5, 1.0, 2.0, 4.0, 8.0, 30.0])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"fixed_lag: no shared data at {args.data}")
        return 0
    methods = {"filter": ["smoother.kind=none"], "rts": ["smoother.kind=rts"],
               **{f"lag {lag:g} s": ["smoother.kind=fixed-lag", f"smoother.lag_s={lag}"] for lag in args.lags}}
    figures = {name: _figures(SETS, args.data, ov, args.workers) for name, ov in methods.items()}
    print(f"{'method':<12}" + "".join(f"{key + ' median':>20}{'|x - rts| mean':>16}" for key in SETS))
    for name, fig in figures.items():
        cells = []
        for key in SETS:
            recs = [k for k in fig if k[0] == key]
            values = np.array([fig[k] for k in recs])
            gap = np.array([abs(fig[k] - figures["rts"][k]) for k in recs])
            cells.append(f"{np.nanmedian(values):20.4f}{np.nanmean(gap):16.4f}")
        print(f"{name:<12}" + "".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
