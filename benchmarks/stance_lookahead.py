"""How far ahead the foot INS's stance detection looks: the delay a live run needs to make the
batch run's decisions.

A streaming foot INS can run its filter behind the newest sample by the detection's look-ahead
L and reproduce the batch run bit for bit, if the stance decisions about a sample never change
once the data reach L beyond it. This measures L on every shared foot recording (PyShoe's 21
trials, both Vicon feet, the x-io loop; each prefix read and repaired as the foot INS reads a
recording, the default detector and watchdog, :func:`bodyfusion.plugins.foot_ins.stance.detect_stance`):
the recording is cut at every ``--step`` seconds, stance is detected on each prefix alone, and L is
the least delay such that every prefix agrees with the whole recording on every sample at least
L before its cut. Printed per recording, and the largest over all.

Usage: python benchmarks/stance_lookahead.py [--data ../shared/data] [--step 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import generalisation as gen  # noqa: E402  (the benchmark beside this one: the data sets' layouts)

from bodyfusion.base.types import ImuStream  # noqa: E402
from bodyfusion.core.layout import validate_layout  # noqa: E402
from bodyfusion.io.imu import read_imu  # noqa: E402
from bodyfusion.nav.earth import normal_gravity  # noqa: E402
from bodyfusion.plugins.foot_ins.input_policy import repair_saturation  # noqa: E402
from bodyfusion.plugins.foot_ins.stance import detect_stance  # noqa: E402

DELAYS_S = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0, 20.0, 30.0)
"""The look-aheads tried, s."""


def _prefix(stream: ImuStream, n: int) -> ImuStream:
    return ImuStream(stream.t[:n], stream.acc_b[:n], stream.gyro_b[:n],
                     None if stream.stance is None else stream.stance[:n], stream.source)


def lookahead_s(stream: ImuStream, detect, step_s: float) -> float:
    """The least delay of :data:`DELAYS_S` at which every prefix's stance agrees with the whole
    recording's on every sample that far before the cut (inf: none of them)."""
    whole = detect(stream)
    t = stream.t
    needed = 0.0
    for cut in np.arange(t[0] + step_s, t[-1], step_s):
        n = int(np.searchsorted(t, cut))
        part = detect(_prefix(stream, n))
        differ = np.flatnonzero(part != whole[:n])
        if differ.size:
            needed = max(needed, float(cut - t[differ[0]]))
    return next((d for d in DELAYS_S if d >= needed), float("inf"))


def _feet(data: Path) -> list[tuple[str, dict, str]]:
    """(recording, layout, foot system) of every shared foot recording."""
    out = [(f"pyshoe/{trial.name}", gen.pyshoe_layout(trial), "foot")
           for trial in gen.DATASETS["pyshoe"][1](data / gen.DATASETS["pyshoe"][0])]
    for folder in gen.DATASETS["vicon"][1](data / gen.DATASETS["vicon"][0]):
        layout = gen.vicon_layout(Path(folder))
        out += [(f"vicon/{name}", layout, name) for name in layout["systems"]]
    out += [(f"xio/{Path(csv).name}", gen.xio_layout(Path(csv)), "foot")
            for csv in gen.DATASETS["xio"][1](data / gen.DATASETS["xio"][0])]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=lambda p: Path(p).resolve(), default=gen.DEFAULT_DATA)
    parser.add_argument("--step", type=float, default=5.0, help="seconds between cuts")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"stance_lookahead: no shared data at {args.data}")
        return 0
    worst = 0.0
    for recording, layout, foot in _feet(args.data):
        loaded = validate_layout(layout, None, args.data)
        cfg = loaded.system_configs[foot]
        lay = loaded.layout
        gravity = lay.gravity_mps2 if lay.gravity_mps2 is not None else normal_gravity(lay.latitude_deg, lay.height_m)
        stream = read_imu(cfg.data)

        def detect(s: ImuStream) -> np.ndarray:  # as the foot INS: clipped runs repaired, then detected
            s = ImuStream(s.t, s.acc_b.copy(), s.gyro_b.copy(), s.stance, s.source)
            repair_saturation(s, foot)
            return detect_stance(s, cfg.detector, gravity, f"systems.{foot}.detector").stance

        needed = lookahead_s(stream, detect, args.step)
        worst = max(worst, needed)
        print(f"  {recording:<40} {stream.t[-1] - stream.t[0]:7.1f} s  look-ahead {needed:g} s")
    print(f"stance_lookahead: worst={worst:g} s (cuts every {args.step:g} s; tried {', '.join(map(str, DELAYS_S))})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
