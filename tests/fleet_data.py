"""A simulated fleet on disk, for the fleet tests and ``benchmarks/bench_fleet.py``:
perturbed copies of the built-in IIS-head (:func:`kinfw.simulate`, stage 1: both plates'
poses, one joint at a time), one folder per robot holding ``robot.urdf`` (the nominal)
and ``data.json``; and how to compare the reports of two runs."""

from __future__ import annotations

import shutil
from pathlib import Path

from kinfw.measurements import write_measurements
from kinfw.model import load_robot
from kinfw.simulation import simulate_measurements
from tests.paths import HEAD_URDF

#: The keys of a report or sidecar that say when it was made, where it was written and
#: how long the solve took: all that differs between two runs of one calibration.
RUN_DETAILS = frozenset({"created", "sidecar", "seconds"})


def without_run_details(doc):
    """A parsed report or sidecar without :data:`RUN_DETAILS`, at any depth."""
    if isinstance(doc, dict):
        return {k: without_run_details(v) for k, v in doc.items() if k not in RUN_DETAILS}
    if isinstance(doc, list):
        return [without_run_details(v) for v in doc]
    return doc


def write_fleet(root: Path, n_robots: int, *, per_joint: int = 4, seed: int = 0) -> list[Path]:
    """``root/rNN/{robot.urdf,data.json}`` for ``n_robots`` true heads (seeds ``seed``,
    ``seed + 1``, ...) measured at ``per_joint`` values of each joint; returns the
    folders."""
    nominal = load_robot(HEAD_URDF)
    folders = []
    for r in range(n_robots):
        sim = simulate_measurements(nominal, per_joint=per_joint, seed=seed + r)
        folder = root / f"r{r:02d}"
        folder.mkdir(parents=True, exist_ok=True)
        write_measurements(folder / "data.json", sim.data)
        shutil.copyfile(HEAD_URDF, folder / "robot.urdf")
        folders.append(folder)
    return folders
