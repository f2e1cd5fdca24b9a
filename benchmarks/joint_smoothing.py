"""The joint RTS of two feet against each foot's own RTS, on the embedded dual-foot Vicon walk.

``configs/dual_foot_vicon.yaml`` with ``fuser.cross_covariance=true`` (and ``--limit`` metres
between the feet, default the layout's own) is fused once; then, in turn, ``--repeats`` times,
the joint RTS of the two feet over the fuser's joint corrections
(:func:`bodyfusion.core.joint_smoothing.smooth_jointly`) and each foot's own whole-run RTS
(:func:`bodyfusion.plugins.foot_ins.smoothing.smooth_system`, the corrections kept as known
inputs) run on the same record; each is timed by its median CPU time (after one untimed call of
each: compilation). Printed: samples/s of each (both feet's samples), the joint corrections
and the events they make, and as the last line
``joint_samples_per_s=… alone_samples_per_s=… ratio=…`` (joint / alone time).

Run: python benchmarks/joint_smoothing.py [--repeats 7] [--limit 0.4]
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
from pathlib import Path

from bodyfusion.core.joint_smoothing import smooth_jointly
from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.plugins.foot_ins.smoothing import smooth_system
from bodyfusion.runner.batch import prepare_fusion

VICON = Path(__file__).resolve().parents[1] / "configs" / "dual_foot_vicon.yaml"


def cpu_ms(job, repeats: int) -> float:
    """Median CPU milliseconds of ``job`` over ``repeats`` calls after one untimed call."""
    job()
    times = []
    for _ in range(repeats):
        gc.collect()
        t0 = time.process_time()
        job()
        times.append(time.process_time() - t0)
    return 1e3 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--limit", type=float, default=None, help="the feet's limit (m); default the layout's")
    args = parser.parse_args()
    overrides = ["fuser.cross_covariance=true", "smoother.kind=rts", "output.plots=false"]
    if args.limit is not None:
        overrides.append(f"constraints.0.distance_m={args.limit}")
    loaded = load_layout(VICON, overrides)
    fusion = prepare_fusion(loaded)
    fusion.fuser.finish()
    cfg: SmootherConfig = loaded.layout.smoother
    log = fusion.fuser.joint.corrections
    feet = [fusion.systems[name] for name in log.names]
    samples = sum(foot.samples for foot in feet)

    def joint() -> None:
        diagnostics = smooth_jointly({foot.name: foot.joint_smoothing_member(cfg) for foot in feet}, log)
        joint.events = diagnostics[feet[0].name]["joint"]["events"]

    def alone() -> None:
        for foot in feet:
            smooth_system(foot, cfg)

    joint_ms, alone_ms = cpu_ms(joint, args.repeats), cpu_ms(alone, args.repeats)
    print(f"{samples} samples (both feet), {len(log.t)} joint corrections, {joint.events} events")
    print(f"joint RTS: {joint_ms:.1f} ms, {samples / joint_ms * 1e3:,.0f} samples/s")
    print(f"each foot's own RTS: {alone_ms:.1f} ms, {samples / alone_ms * 1e3:,.0f} samples/s")
    print(f"joint_samples_per_s={samples / joint_ms * 1e3:.0f} alone_samples_per_s={samples / alone_ms * 1e3:.0f} "
          f"ratio={joint_ms / alone_ms:.2f}")


if __name__ == "__main__":
    main()
