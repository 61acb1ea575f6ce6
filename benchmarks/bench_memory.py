"""Peak memory and wall time of ``kinfw calibrate --params full`` against the sample count
(issue 23: memory must grow linearly in the samples).

Data: the UR10 (DH, :func:`kinfw.verification.studies.ur10_urdf`) with random geometric
errors (:func:`kinfw.simulation.perturb_robot`), random configurations, and two
measurement files per size N:

- ``points``: one marker of unknown offset on ``tool0`` seen by motion capture in an
  unknown frame ``mocap`` (N points, 0.5 mm noise);
- ``poses``: ``tool0`` poses in the root (N poses, 0.5 mm and 0.05 deg noise).

Each file is calibrated by ``kinfw calibrate --params full`` in a child process (the
model choice of ``--params auto`` is left out); the table gives its peak resident set
size (``ru_maxrss`` of the child) and wall time, for this checkout and, side by side,
for a baseline checkout (``--baseline-dir DIR``, e.g. a ``git worktree add`` of the
parent commit; the child points the editable install's package map at that checkout).
The last column says whether both wrote byte-identical calibrated URDFs. A baseline run
that fails (e.g. ``MemoryError`` under the address-space cap ``--cap-gb``) shows its error.

Run from the repository root: ``python benchmarks/bench_memory.py [--baseline-dir DIR]
[--sizes 1000,10000] [--large] [--cap-gb G]`` (``--large`` adds N = 100000).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import REPO, format_table, machine_info

#: The unknown motion-capture frame in the robot root, [R | p] (m).
MOCAP_T_ROOT = np.array(
    [
        [0.0, -1.0, 0.0, 0.8],
        [1.0, 0.0, 0.0, -0.3],
        [0.0, 0.0, 1.0, 0.1],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def write_data(directory: Path, n: int, seed: int = 0) -> tuple[Path, dict[str, Path]]:
    """The nominal URDF and the ``points`` and ``poses`` measurement files of n samples."""
    from kinfw.measurements import Measurements, write_measurements
    from kinfw.model import load_robot
    from kinfw.simulation import perturb_robot, random_configurations, simulate
    from kinfw.verification.studies import UR10_JOINTS, ur10_urdf

    rng = np.random.default_rng(seed)
    urdf = directory / "ur10.urdf"
    urdf.write_text(ur10_urdf())
    nominal = load_robot(urdf)
    truth = load_robot(perturb_robot(nominal, rng))
    names = list(UR10_JOINTS)
    qs = random_configurations(*nominal.joint_limits(names), n, rng, fraction=0.8)
    offset = np.array([0.03, -0.02, 0.05])
    data = simulate(truth, qs, names, markers=[("tool0", offset, "ball")], rng=rng, noise_m=5e-4)
    R, p = MOCAP_T_ROOT[:3, :3], MOCAP_T_ROOT[:3, 3]
    points = tuple(
        replace(g, meas_p_point=g.meas_p_point @ R.T + p, measured_in="mocap") for g in data.points
    )
    files = {"points": directory / f"points_{n}.json", "poses": directory / f"poses_{n}.json"}
    write_measurements(files["points"], Measurements(data.joint_names, data.qs, points=points))
    poses = simulate(
        truth, qs, names, frames=["tool0"], rng=rng, noise_m=5e-4, noise_rad=np.radians(0.05)
    )
    write_measurements(files["poses"], poses)
    return urdf, files


def run_calibrate(
    repo: Path, urdf: Path, data: Path, out: Path, cap_bytes: int | None
) -> tuple[float, float, str]:
    """Peak RSS (MB) and wall time (s) of ``kinfw calibrate --params full`` run on
    ``repo``'s code in a fresh child, and its last error line ('' when it succeeded)."""
    env = dict(os.environ, KINFW_BENCH_REPO=str(repo))
    code = (  # point the editable install's package map at ``repo``
        "import os, sys; from pathlib import Path; repo = os.environ['KINFW_BENCH_REPO']\n"
        "for m in list(sys.modules.values()):\n"
        "    mp = getattr(m, 'MAPPING', None)\n"
        "    if isinstance(mp, dict) and 'kinfw' in mp:\n"
        "        old = str(Path(mp['kinfw']).parent)\n"
        "        mp.update({k: repo + v[len(old):] for k, v in mp.items()})\n"
        "import kinfw.identification\n"
        "assert kinfw.identification.__file__.startswith(repo)\n"
        "from kinfw.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    args = [sys.executable, "-c", code, "calibrate", str(data), "--urdf", str(urdf)]
    args += ["--out", str(out), "--params", "full"]

    def limit() -> None:
        if cap_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (cap_bytes, cap_bytes))

    # ru_maxrss of RUSAGE_CHILDREN is the largest of all waited-for children: measure
    # each run in its own intermediate process so that earlier runs do not mask it
    wrapper = (
        "import resource, subprocess, sys, time; "
        "t = time.perf_counter(); "
        "p = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
        "dt = time.perf_counter() - t; "
        "kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss; "
        "err = (p.stderr.strip().splitlines() or [''])[-1] if p.returncode else ''; "
        "print(kb, dt, err, sep='\\t')"
    )
    proc = subprocess.run(
        [sys.executable, "-c", wrapper, *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=repo,
        preexec_fn=limit,
        check=True,
    )
    kb, dt, err = proc.stdout.rstrip("\n").split("\t", 2)
    return int(kb) / 1024.0, float(dt), err


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline-dir", type=Path, help="checkout to compare with")
    parser.add_argument("--sizes", default="1000,10000", help="sample counts, comma-separated")
    parser.add_argument("--large", action="store_true", help="also N = 100000")
    parser.add_argument(
        "--cap-gb", type=float, default=16.0, help="address-space cap of each child (GB)"
    )
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")] + ([100_000] if args.large else [])
    cap = int(args.cap_gb * 2**30) if args.cap_gb > 0 else None
    print(machine_info())
    print(f"kinfw calibrate --params full, UR10; child address-space cap {args.cap_gb:g} GB\n")
    checkouts = [("this", REPO)] + ([("baseline", args.baseline_dir)] if args.baseline_dir else [])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            urdf, files = write_data(Path(tmp), n)
            for kind, data in files.items():
                row, outs = [kind, f"{n}"], []
                for label, repo in checkouts:
                    outs.append(Path(tmp, f"{label}_{kind}_{n}.urdf"))
                    mb, dt, err = run_calibrate(repo.resolve(), urdf, data, outs[-1], cap)
                    row += [f"{mb:.0f}", f"{dt:.1f}" if not err else f"failed: {err[:40]}"]
                if len(outs) == 2:
                    same = (
                        all(o.exists() for o in outs)
                        and outs[0].read_bytes() == outs[1].read_bytes()
                    )
                    row.append("yes" if same else "NO")
                rows.append(row)
                print("  ".join(row), flush=True)
    header = ["data", "N"]
    for label, _ in checkouts:
        header += [f"{label} peak MB", f"{label} s"]
    header += ["same URDF"] if args.baseline_dir else []
    print()
    print(format_table(header, rows))


if __name__ == "__main__":
    main()
