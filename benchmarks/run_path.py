"""The path one ``fusion run`` takes through the package: its stops and how often it climbs back.

Runs ``fusion run LAYOUT`` (default: the dual-foot Vicon layout) under a profiler hook that sees
every call into a bodyfusion function and prints:

- ``stops``: the distinct functions the run enters, ``files``: the modules they are in;
- ``climbs_by_name``: calls from a module into a module of a higher layer (docs/architecture.md,
  :data:`bodyfusion.testing.imports.LAYERS`) that the caller imports — a reader following the
  run goes back up to code the lower layer names (the architecture tests forbid these);
- ``climbs_through_contract``: calls from a lower layer into a higher one that the caller does
  not import: the core driving a plugin through the sensor contract, a registry calling a
  plugin's hooks, a worker calling the function it was handed. The reader follows these down
  from the caller's interface, not up; each is listed with its count.

Last line: ``stops=… files=… climbs_by_name=… climbs_through_contract=…``.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
from pathlib import Path

from bodyfusion.testing.imports import LAYERS, ImportGraph

ROOT = Path(__file__).resolve().parents[1]


def trace(layout: Path, out: Path) -> tuple[list[tuple[str, str]], collections.Counter]:
    """The (module, function) a run enters, in order of first entry, and (caller module, callee
    module) call counts."""
    from bodyfusion.cli import main

    order: dict[tuple[str, str], None] = {}
    calls: collections.Counter = collections.Counter()

    def hook(frame, event, arg):  # noqa: ARG001 - the profiler's signature
        if event != "call":
            return
        module = frame.f_globals.get("__name__", "")
        if not module.startswith("bodyfusion"):
            return
        back = frame.f_back
        while back is not None and not back.f_globals.get("__name__", "").startswith("bodyfusion"):
            back = back.f_back
        order.setdefault((module, frame.f_code.co_qualname))
        if back is not None and back.f_globals["__name__"] != module:
            calls[(back.f_globals["__name__"], module)] += 1

    argv, sys.argv = sys.argv, ["fusion", "-q", "run", str(layout), "--out", str(out)]
    sys.setprofile(hook)
    try:
        main()
    except SystemExit:
        pass
    finally:
        sys.setprofile(None)
        sys.argv = argv
    return list(order), calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("layout", nargs="?", type=Path, default=ROOT / "configs" / "dual_foot_vicon.yaml")
    args = parser.parse_args()
    import bodyfusion

    graph = ImportGraph(Path(bodyfusion.__file__).parent).graph(everywhere=True)
    with tempfile.TemporaryDirectory() as tmp:
        stops, calls = trace(args.layout, Path(tmp))
    files = {module for module, _ in stops}

    def rank(module: str) -> int | None:
        layer = ImportGraph.layer(module)
        return LAYERS.index(layer) if layer in LAYERS else None

    by_name, through = [], []
    for (caller, callee), count in sorted(calls.items()):
        a, b = rank(caller), rank(callee)
        if a is None or b is None or b >= a:
            continue
        (by_name if callee in graph.get(caller, ()) else through).append((caller, callee, count))
    for kind, rows in (("by name", by_name), ("through the contract", through)):
        print(f"climbs {kind}:")
        for caller, callee, count in rows:
            print(f"  {caller} -> {callee} ({count} calls)")
    print(f"stops={len(stops)} files={len(files)} climbs_by_name={len(by_name)} "
          f"climbs_through_contract={len(through)}")


if __name__ == "__main__":
    main()
