"""Memory of a long live run that keeps a bounded history (``fusion live --keep``).

The walk of ``benchmarks/soak.py``: both feet with ICM-20948-class IMUs at 100 Hz and a
hand-held phone (IMU at 100 Hz, GNSS at 1 Hz), the three maximum-separation constraints, projection
with cross-covariances, for ``--hours`` (default 24), simulated once (``fusion simulate``, its
own process); ``--no-phone``: the feet alone. A second process replays it through
:class:`~bodyfusion.live.engine.LiveRun` as fast as it runs (a pass every 30 s of data, a state
every 0.1 s to a sink that counts them), keeping ``--keep`` s of history (default 60); its rows
come from ``fusion live``'s replay (:func:`~bodyfusion.live.sources.replay_rows`: each file read
a chunk of lines at a time and merged in time order), so the source holds no recording. The
resident memory (``VmRSS``) is sampled every half hour of data; the peak is the process's
high-water mark (``VmHWM``), which also holds what a pass or the close took between samples. The
layout's truth is read as the run goes and every state emitted is scored against it
(``whole_run``); with ``--no-truth`` it is left out, as in the field.

Prints the samples; last line ``peak_rss_mb=<MB> first_half_growth_mb=<MB> last_half_growth_mb=<MB>
hours=<h> wall_s=<s>`` (growth: resident memory at the half-way sample to the last, and from the
first sample after warm-up to the half-way one).

``--set KEY=VALUE`` overrides the layout (``--set smoother.kind=fixed-lag``: the live fixed-lag
smoother's stream too; the sink counts its states with the others).

Run: python benchmarks/live_memory.py [--hours 24] [--keep 60] [--no-truth] [--no-phone] [--keep-dir DIR]
     [--set KEY=VALUE]...
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent


def scenario(hours: float, phone: bool) -> dict:
    """The soak benchmark's scenario (``benchmarks/soak.py``), without the phone and its
    constraints unless ``phone``."""
    spec = importlib.util.spec_from_file_location("soak", HERE / "soak.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = module.scenario(hours)
    out["name"] = f"live_memory_{hours:g}h"
    if not phone:
        del out["systems"]["hand_phone"]
        out["layout"]["systems"] = {}
        out["layout"]["constraints"] = [c for c in out["layout"]["constraints"] if "hand_phone" not in c["between"]]
    return out


def rss_mb(key: str = "VmRSS") -> float:
    """Resident memory of this process (MB): now (``VmRSS``) or its high-water mark (``VmHWM``)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


class Counter:
    """A sink that counts the states."""

    def __init__(self) -> None:
        self.states = 0

    def write(self, state: object) -> None:
        self.states += 1

    def close(self) -> None:
        pass


def replay(config: Path, keep_s: float, overrides: list[str]) -> None:
    """The live replay, in this process (the child): prints a sample every half hour of data."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.live.engine import REPLAN_BATCH_S, LiveRun
    from bodyfusion.live.sources import replay_rows

    sink = Counter()
    run = LiveRun(load_layout(config, overrides), [sink], replan_s=REPLAN_BATCH_S, keep_s=keep_s)
    wall0 = time.perf_counter()
    t0, next_sample = None, 0.0
    for t, name, row in replay_rows(run):
        if t0 is None:
            t0 = t
        run.push(name, row)
        if t - t0 >= next_sample:
            print(f"sample data_h={(t - t0) / 3600:.2f} rss_mb={rss_mb():.1f} states={sink.states} "
                  f"wall_s={time.perf_counter() - wall0:.0f}", flush=True)
            next_sample += 1800.0
    run.close()
    print(f"sample data_h={(t - t0) / 3600:.2f} rss_mb={rss_mb():.1f} states={sink.states} "
          f"wall_s={time.perf_counter() - wall0:.0f} closed", flush=True)
    print(f"high_water rss_mb={rss_mb('VmHWM'):.1f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=24.0, help="walk duration, hours")
    parser.add_argument("--keep", type=float, default=60.0, help="history kept, s (fusion live --keep)")
    parser.add_argument("--keep-dir", type=Path, help="keep the simulated walk in this folder")
    parser.add_argument("--no-truth", action="store_true", help="run the layout without its truth")
    parser.add_argument("--no-phone", action="store_true", help="the feet alone")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override the layout")
    parser.add_argument("--replay", type=Path, help=argparse.SUPPRESS)  # the child: replay this config
    args = parser.parse_args()
    if args.replay is not None:
        replay(args.replay, args.keep, args.set)
        return
    work = args.keep_dir or Path(tempfile.mkdtemp(prefix="live_memory_"))
    try:
        work.mkdir(parents=True, exist_ok=True)
        scenario_path = work / "scenario.yaml"
        scenario_path.write_text(yaml.safe_dump(scenario(args.hours, not args.no_phone)))
        walk = work / "walk"
        subprocess.run(["fusion", "simulate", str(scenario_path), "--out", str(walk), "--overwrite"], check=True,
                       stdout=subprocess.DEVNULL)
        if args.no_truth:
            config = yaml.safe_load((walk / "config.yaml").read_text())
            config.pop("truth", None)
            (walk / "config.yaml").write_text(yaml.safe_dump(config))
        wall0 = time.perf_counter()
        child = subprocess.run([sys.executable, __file__, "--replay", str(walk / "config.yaml"), "--keep",
                                str(args.keep), *(f"--set={o}" for o in args.set)], check=True, capture_output=True,
                               text=True)
        wall = time.perf_counter() - wall0
        print(child.stdout, end="")
        samples = [dict(kv.split("=") for kv in line.split()[1:5]) for line in child.stdout.splitlines()
                   if line.startswith("sample")]
        hours = [float(s["data_h"]) for s in samples]
        rss = [float(s["rss_mb"]) for s in samples]
        high_water = next(float(line.split("=")[1]) for line in child.stdout.splitlines()
                          if line.startswith("high_water"))
        warm = next(k for k, h in enumerate(hours) if h >= 0.5)  # after the first half hour
        half = min(range(len(hours)), key=lambda k: abs(hours[k] - hours[-1] / 2))
        print(f"peak_rss_mb={high_water:.1f} first_half_growth_mb={rss[half] - rss[warm]:.1f} "
              f"last_half_growth_mb={rss[-1] - rss[half]:.1f} hours={hours[-1]:.2f} wall_s={wall:.0f}")
    finally:
        if args.keep_dir is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
