"""Cold and warm start of the README's main command, and what numba compiles for it.

Runs ``fusion run configs/dual_foot_vicon.yaml --out DIR`` (the README's main command: both
feet of the vendored 120 s Vicon walk) in fresh processes, each timed from process start to
exit (wall clock), with ``NUMBA_CACHE_DIR`` pointing at a new empty folder:

1. cold: the first process compiles every kernel it calls and writes numba's on-disk cache;
2. warm: a second process on the same cache loads them instead;
3. instrumented: a third process on another empty cache records every compilation from
   numba's ``numba:compile`` events — the kernel, its argument types and the seconds spent
   compiling it, not counting the kernels it compiled in turn (nested compilations) — and,
   after the run, how many compiled signatures each kernel holds. The fuser's kernels, which a
   first run compiles in a forked process beside the systems' (``bodyfusion.core.compile_ahead``)
   and then loads from the cache, are not among them.

``--config`` runs another layout the same way (``--simulate``: a scenario, which ``fusion
simulate`` writes out first, untimed, and whose layout runs): the way to survey what each kind
of layout compiles.

Prints the cold and warm wall and CPU times (median of ``--repeats`` pairs, each pair on a
new cache; the CPU time, user + system, is the figure to compare on a shared machine), the
time a process takes to import ``bodyfusion.cli`` alone (the floor of a warm start), the kernels by compile time (seconds, signatures; kernels with more than one
signature are the ones the call sites feed different types), the totals, and as its last
line ``cold_s=<s> warm_s=<s> kernels=<n> signatures=<n> compile_s=<s>`` (wall seconds, the
project's kernels and their signatures, all compile seconds of the instrumented run).

Run: python benchmarks/cold_start.py [--repeats 1] [--top 25] [--set KEY=VALUE ...] [--config PATH [--simulate]]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "dual_foot_vicon.yaml"


def fusion_run(config: Path, out: Path, overrides: list[str]) -> list[str]:
    """``fusion run CONFIG --out DIR --overwrite`` with ``--set`` overrides (the README's main
    command with the default ``config``; run again and again into one folder)."""
    sets = [arg for kv in overrides for arg in ("--set", kv)]
    return ["run", str(config), "--out", str(out), "--overwrite", *sets]


def timed_process(argv: list[str], cache: Path) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one fresh ``python`` process with the arguments
    ``argv`` on the numba cache ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *argv], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"python {' '.join(argv)} failed")
    return wall, usage.ru_utime + usage.ru_stime


def child(record: Path, argv: list[str]) -> None:
    """Run the command in this process with numba's compile events recorded into ``record``."""
    import numba
    from numba.core import event

    compiled: list[dict] = []
    stack: list[list[float]] = []  # per open compilation: [start, seconds spent in nested ones]

    class Recorder(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            stack.append([time.perf_counter(), 0.0])

        def on_end(self, ev: event.Event) -> None:
            start, nested = stack.pop()
            total = time.perf_counter() - start
            if stack:
                stack[-1][1] += total
            fn = ev.data["dispatcher"].py_func
            compiled.append({"kernel": f"{fn.__module__}.{fn.__qualname__}", "seconds": total - nested,
                             "args": str(ev.data["args"])})

    event.register("numba:compile", Recorder())
    t0 = time.perf_counter()
    sys.argv = ["fusion", *argv]
    from bodyfusion.cli import main

    try:
        main()
    except SystemExit as stop:
        if stop.code not in (None, 0):
            raise
    wall = time.perf_counter() - t0
    signatures = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("bodyfusion"):
            continue
        for obj in vars(module).values():
            if isinstance(obj, numba.core.registry.CPUDispatcher) and obj.overloads:
                fn = obj.py_func
                signatures[f"{fn.__module__}.{fn.__qualname__}"] = len(obj.overloads)
    record.write_text(json.dumps({"wall_s": wall, "compiled": compiled, "signatures": signatures}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1, help="cold/warm pairs, each on a new cache (median)")
    ap.add_argument("--top", type=int, default=25, help="kernels listed")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="layout override KEY=VALUE")
    ap.add_argument("--config", type=Path, default=CONFIG, help="the layout to run (default: the main command's)")
    ap.add_argument("--simulate", action="store_true", help="--config is a scenario: simulate it first (untimed)")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    if len(sys.argv) > 2 and sys.argv[1] == "--child":  # the command follows the record's path as is
        child(Path(sys.argv[2]), sys.argv[3:])
        return
    args = ap.parse_args()
    cold, warm = [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        config = args.config.resolve()
        if args.simulate:
            subprocess.run([sys.executable, "-m", "bodyfusion", "simulate", str(config), "--out", str(folder / "sim")],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            config = folder / "sim" / "config.yaml"
        command = fusion_run(config, folder / "out", args.overrides)
        imports = timed_process(["-c", "import bodyfusion.cli"], folder / "cache_imports")
        for k in range(args.repeats):
            cache = folder / f"cache{k}"
            cold.append(timed_process(["-m", "bodyfusion", *command], cache))
            warm.append(timed_process(["-m", "bodyfusion", *command], cache))
        record = folder / "compiled.json"
        subprocess.run([sys.executable, __file__, "--child", str(record), *command],
                       env=dict(os.environ, NUMBA_CACHE_DIR=str(folder / "cache_instrumented")), check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        doc = json.loads(record.read_text())
    cold_s, cold_cpu = (statistics.median(v) for v in zip(*cold))
    warm_s, warm_cpu = (statistics.median(v) for v in zip(*warm))
    per_kernel: dict[str, list[float]] = defaultdict(list)
    for item in doc["compiled"]:
        per_kernel[item["kernel"]].append(item["seconds"])
    ranked = sorted(per_kernel.items(), key=lambda kv: -sum(kv[1]))
    ours = {k: v for k, v in per_kernel.items() if k.startswith("bodyfusion")}
    ours_s = sum(sum(v) for v in ours.values())
    ours_sigs = sum(len(v) for v in ours.values())
    library_s = sum(sum(v) for k, v in per_kernel.items() if k not in ours)
    print(f"{' '.join(['fusion', *command])}")
    print(f"cold (empty numba cache): {cold_s:.2f} s wall, {cold_cpu:.2f} s CPU; warm (cache filled): {warm_s:.2f} s "
          f"wall, {warm_cpu:.2f} s CPU; importing bodyfusion.cli alone: {imports[0]:.2f} s wall, {imports[1]:.2f} s CPU")
    print(f"compiled in the cold run ({doc['wall_s']:.2f} s in-process): {len(ours)} project kernels, {ours_sigs} "
          f"signatures, {ours_s:.2f} s; numba's implementations of the numpy and Python calls they make: "
          f"{len(per_kernel) - len(ours)}, {library_s:.2f} s (seconds exclude nested compilations)")
    for name, secs in ranked[:args.top]:
        print(f"  {sum(secs):6.2f} s  {len(secs):2d} sig  {name}")
    if len(ranked) > args.top:
        rest_s = sum(sum(v) for _, v in ranked[args.top:])
        print(f"  {rest_s:6.2f} s  the other {len(ranked) - args.top} kernels")
    multi = {k: n for k, n in doc["signatures"].items() if n > 1}
    if multi:
        print("kernels holding several signatures: " + ", ".join(f"{k} ({n})" for k, n in sorted(multi.items())))
    print(f"cold_s={cold_s:.2f} warm_s={warm_s:.2f} kernels={len(ours)} signatures={ours_sigs} "
          f"compile_s={ours_s + library_s:.2f}")


if __name__ == "__main__":
    main()
