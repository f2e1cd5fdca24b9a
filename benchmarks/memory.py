"""Peak memory of a long dual-foot + hand run with constraints and the whole-run RTS, and where it goes.

The walk of ``benchmarks/soak.py`` (both feet with ICM-20948-class IMUs at 100 Hz, a phone with
1 Hz GNSS that drops out 2 min in every 10, the three maximum-separation constraints, projection
with cross-covariances) for ``--hours`` (default 1), simulated once, then run as a user would,
``fusion run config.yaml --set smoother.kind=rts``:

1. in a fresh process: wall time and peak resident memory (``wait4`` rusage);
2. in a second process, the resident memory (``VmRSS``, and the high-water mark ``VmHWM``)
   after each phase — systems built (inputs read), truth read, headings aligned, navigation
   and fusion, smoothing, scoring, outputs written;
3. in a third, instrumented, process the same and the numpy/Python allocations
   (``tracemalloc``: held at the end of the phase and the phase's own peak; tracing adds to
   the resident memory), the ten largest allocation sites held before the outputs are
   written, and the arrays each system holds, by attribute (``nbytes``).

Prints the figures; last line ``peak_rss_mb=<MB> wall_s=<s> samples=<n>`` (of the plain run).

Run: python benchmarks/memory.py [--hours 1] [--keep DIR]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
MB = 2.0**20


def soak_scenario(hours: float) -> dict:
    """The soak benchmark's scenario (``benchmarks/soak.py``)."""
    spec = importlib.util.spec_from_file_location("soak", HERE / "soak.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.scenario(hours)


def proc_status_mb() -> tuple[float, float]:
    """(VmRSS, VmHWM) of this process, MB."""
    fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    return float(fields["VmRSS"].split()[0]) / 1024.0, float(fields["VmHWM"].split()[0]) / 1024.0


def held_arrays(obj: object, prefix: str, out: dict[str, int], depth: int = 3, seen: set[int] | None = None) -> None:
    """Bytes of the numpy arrays reachable from ``obj`` through attributes, lists and dicts
    (``depth`` levels; views counted once by their base), by attribute path."""
    seen = set() if seen is None else seen
    if isinstance(obj, np.ndarray):
        base = obj if obj.base is None else obj.base
        if id(base) not in seen and isinstance(base, np.ndarray):
            seen.add(id(base))
            out[prefix] = out.get(prefix, 0) + base.nbytes
        return
    if depth == 0 or id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, dict):
        items = obj.items()
    elif isinstance(obj, (list, tuple)):
        if obj and all(isinstance(v, np.ndarray) for v in obj):
            items = [("[]", v) for v in obj]
        else:
            items = [(f"[{k}]", v) for k, v in enumerate(obj[:50])]
    elif hasattr(obj, "__dict__"):
        items = vars(obj).items()
    else:
        return
    for key, value in items:
        held_arrays(value, f"{prefix}.{key}" if not str(key).startswith("[") else f"{prefix}{key}", out, depth - 1,
                    seen)


def child(config: Path, out: Path, report: Path, trace: bool = True) -> None:
    """Run the layout with the phases marked (``trace``: and the allocations traced); the
    figures into ``report`` (JSON)."""
    from bodyfusion.runner import batch as core_run

    if trace:
        tracemalloc.start(1)  # numpy's allocations are charged to the project line that made them

    phases: list[dict] = []

    def mark(name: str) -> None:
        current, peak = tracemalloc.get_traced_memory()
        rss, hwm = proc_status_mb()
        phases.append({"phase": name, "rss_mb": rss, "hwm_mb": hwm, "traced_mb": current / MB,
                       "traced_peak_mb": peak / MB})
        tracemalloc.reset_peak()

    sites: list[tuple[str, float]] = []
    systems_held: dict[str, int] = {}

    def top_sites() -> None:
        for stat in tracemalloc.take_snapshot().statistics("lineno")[:10]:
            where = stat.traceback[0]
            sites.append((f"{Path(where.filename).parent.name}/{Path(where.filename).name}:{where.lineno}",
                          stat.size / MB))

    build, truth, align = core_run.build_systems, core_run.load_truth, core_run.align_headings
    smooth, write = core_run.smooth_systems, core_run.write_outputs

    def build_marked(*args, **kwargs):
        systems = build(*args, **kwargs)
        mark("systems built (inputs read)")
        return systems

    def truth_marked(*args, **kwargs):
        tracks = truth(*args, **kwargs)
        mark("truth read")
        return tracks

    def align_marked(*args, **kwargs):
        rotations = align(*args, **kwargs)
        mark("headings aligned")
        return rotations

    def smooth_marked(systems, cfg, *joint):
        mark("navigation and fusion")
        result = smooth(systems, cfg, *joint)
        mark("smoothing")
        return result

    def write_marked(result, *args, **kwargs):
        if trace:
            top_sites()
        for name, system in result.systems.items():
            held_arrays(system, name, systems_held)
        mark("scoring")
        write(result, *args, **kwargs)
        mark("outputs written")

    core_run.build_systems, core_run.load_truth, core_run.align_headings = build_marked, truth_marked, align_marked
    core_run.smooth_systems, core_run.write_outputs = smooth_marked, write_marked
    t0 = time.perf_counter()
    core_run.run(config, ["smoother.kind=rts"], out)
    report.write_text(json.dumps({"wall_s": time.perf_counter() - t0, "phases": phases, "sites": sites,
                                  "held": systems_held}))


def measured(command: list[str]) -> tuple[float, float]:
    """(wall s, peak RSS MB) of ``command`` in a fresh process; its output goes to our stderr."""
    start = time.perf_counter()
    proc = subprocess.Popen(command, stdout=sys.stderr, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(command)} failed")
    return time.perf_counter() - start, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0, help="walk duration, hours")
    ap.add_argument("--keep", type=Path, help="folder for the files (default: a temporary one, removed)")
    ap.add_argument("--child", nargs=3, type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--no-trace", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(*args.child, trace=not args.no_trace)
        return
    folder = args.keep or Path(tempfile.mkdtemp(prefix="memory_"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        scn = folder / "scenario.yaml"
        scn.write_text(yaml.safe_dump(soak_scenario(args.hours), sort_keys=False))
        fusion = [sys.executable, "-m", "bodyfusion"]
        subprocess.run([*fusion, "simulate", str(scn), "--out", str(folder / "data")], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        config = folder / "data" / "config.yaml"
        wall, peak = measured([*fusion, "run", str(config), "--out", str(folder / "out"), "--set",
                               "smoother.kind=rts"])
        samples = json.loads((folder / "out" / "metrics.json").read_text())["runtime"]["samples"]
        plain_report, report = folder / "phases.json", folder / "memory.json"
        measured([sys.executable, __file__, "--child", str(config), str(folder / "out_phases"), str(plain_report),
                  "--no-trace"])
        measured([sys.executable, __file__, "--child", str(config), str(folder / "out_instrumented"), str(report)])
        plain, doc = json.loads(plain_report.read_text()), json.loads(report.read_text())
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    print(f"{args.hours:g} h dual-foot + hand, constraints, smoother.kind=rts: {samples} samples")
    print(f"fusion run: wall {wall:.1f} s, peak RSS {peak:.0f} MB")
    print(f"after each phase: RSS / high-water mark of a run ({plain['wall_s']:.1f} s); of a run with tracemalloc "
          f"({doc['wall_s']:.1f} s): RSS / high-water mark / numpy+Python allocations held / their peak within the "
          "phase, MB")
    for q, p in zip(plain["phases"], doc["phases"]):
        print(f"  {p['phase']:28s} {q['rss_mb']:7.0f} {q['hwm_mb']:7.0f}   {p['rss_mb']:7.0f} {p['hwm_mb']:7.0f} "
              f"{p['traced_mb']:7.0f} {p['traced_peak_mb']:7.0f}")
    print("largest allocation sites held before the outputs are written, MB:")
    for where, size in doc["sites"]:
        print(f"  {size:7.1f}  {where}")
    held = sorted(doc["held"].items(), key=lambda kv: -kv[1])
    total = sum(doc["held"].values())
    print(f"arrays the systems hold: {total / MB:.0f} MB; the largest, MB:")
    for name, size in held[:12]:
        print(f"  {size / MB:7.1f}  {name}")
    print(f"peak_rss_mb={peak:.0f} wall_s={wall:.1f} samples={samples}")


if __name__ == "__main__":
    main()
