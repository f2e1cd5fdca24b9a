"""Examples packaged with bodyfusion, so an installed package can start without the repository:
``fusion example NAME --out DIR`` (:func:`write_example`) writes an example's layouts, scenarios
or study, the recordings they read (with their licences) and a README into a folder, every path
relative to it. The files are the repository's ``configs/`` with data paths into ``data/``."""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from importlib.resources import files
from importlib.resources.abc import Traversable
from pathlib import Path

from bodyfusion.base.errors import FusionError


@dataclass(frozen=True)
class Example:
    """One example: ``files`` (this package's layouts, scenarios and studies, written at the
    folder's top), ``data`` (recordings, each written as ``data/<name>/`` with its licence),
    ``about`` (what it is and where the data come from) and the ``commands`` that run it
    (``{dir}``: the folder)."""

    name: str
    summary: str
    files: tuple[str, ...]
    commands: tuple[str, ...]
    about: str = ""
    data: tuple[str, ...] = ()


EXAMPLES = {e.name: e for e in (
    Example("dual_foot_vicon", "both feet of a 120 s walk, Vicon truth (recorded, MIT)",
            ("dual_foot_vicon.yaml", "dual_foot_vicon_position_fixes.yaml"),
            ("fusion run {dir}/dual_foot_vicon.yaml --out {dir}/out",
             "fusion run {dir}/dual_foot_vicon_position_fixes.yaml --out {dir}/out_fixes"),
            about="Both feet, 60 Hz, 120 s, with Vicon motion-capture truth, from Hu & Hu, \"Constrained Factor "
                  "Graph Optimization for Robust Networked Pedestrian Inertial Navigation\", IEEE/ION PLANS 2025 "
                  "(repository Azurehappen/Constrained-ZUPT-FGO), MIT licence: data/dual_foot_vicon_hu2025/LICENSE. "
                  "dual_foot_vicon.yaml bounds the feet's separation; dual_foot_vicon_position_fixes.yaml also "
                  "aids each foot with the authors' noisy position fixes.",
            data=("dual_foot_vicon_hu2025",)),
    Example("sim_dual_foot_square", "a simulated walk: both feet twice round a 20 m x 10 m rectangle",
            ("sim_dual_foot_square.yaml",),
            ("fusion simulate {dir}/sim_dual_foot_square.yaml --out {dir}/sim",
             "fusion run {dir}/sim/config.yaml --out {dir}/out"),
            about="A scenario: fusion simulate writes the sensor files, truth.csv and a layout (config.yaml) "
                  "that fusion run runs."),
    Example("foot_hand_gnss_outage", "a simulated foot INS and phone (PDR + GNSS) with a 60 s GNSS outage",
            ("foot_hand_gnss_outage.yaml",),
            ("fusion simulate {dir}/foot_hand_gnss_outage.yaml --out {dir}/sim",
             "fusion run {dir}/sim/config.yaml --out {dir}/out"),
            about="A scenario: fusion simulate writes the sensor files, truth.csv and a layout (config.yaml) "
                  "that fusion run runs."),
    Example("gnss_outage_study_smoke", "the GNSS-outage study cut down to 8 runs (2 layouts, 2 outages, 2 seeds)",
            ("gnss_outage_study_smoke.yaml", "foot_hand_gnss_outage.yaml", "dual_foot_hand_gnss.yaml"),
            ("fusion study {dir}/gnss_outage_study_smoke.yaml --out {dir}/out",),
            about="A study over two simulated scenarios: results.parquet, summary.csv and plots in the output "
                  "folder (--executor dask needs pip install \"bodyfusion[study]\")."),
)}
"""The packaged examples by name."""


def example(name: str) -> Example:
    """The example called ``name``; a user error lists them otherwise."""
    if name not in EXAMPLES:
        raise FusionError(f"no example {name!r}: choose one of {', '.join(EXAMPLES)} (fusion example --list)")
    return EXAMPLES[name]


def commands(ex: Example, folder: Path) -> list[str]:
    """The commands that run ``ex`` written in ``folder``, as a shell takes them."""
    return [c.format(dir=shlex.quote(str(folder))) for c in ex.commands]


def write_example(name: str, folder: str | Path) -> list[Path]:
    """Write the example ``name`` into ``folder`` (created; no file already there is overwritten):
    its files, ``data/<recording>/`` for each recording it reads, and ``README.md``. Returns the
    paths written at the folder's top (files, data folders, README)."""
    ex = example(name)
    folder = Path(folder)
    targets = [folder / f for f in ex.files] + [folder / "data" / d for d in ex.data] + [folder / "README.md"]
    if clash := next((t for t in targets if t.exists()), None):
        raise FusionError(f"{clash}: exists; not overwritten (choose another --out)")
    source = files(__name__).joinpath("files")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for f in ex.files:
            (folder / f).write_bytes(source.joinpath(f).read_bytes())
        for d in ex.data:
            _copy_tree(source.joinpath("data", d), folder / "data" / d)
        (folder / "README.md").write_text(readme(ex))
    except OSError as err:
        raise FusionError(f"{folder}: cannot write the example: {err.strerror or err}") from None
    return targets


def _copy_tree(source: Traversable, target: Path) -> None:
    target.mkdir(parents=True)
    for item in source.iterdir():
        if item.is_dir():
            _copy_tree(item, target / item.name)
        else:
            (target / item.name).write_bytes(item.read_bytes())


def readme(ex: Example) -> str:
    """The README.md written with ``ex``: what it is, and how to run it from its folder."""
    run = "\n".join(f"    {c}" for c in commands(ex, Path(".")))
    return f"# {ex.name}: {ex.summary}\n\n{ex.about}\n\nRun in this folder:\n\n{run}\n"
