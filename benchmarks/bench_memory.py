"""Peak memory and time of ``kinfw calibrate`` against the sample count, this checkout
beside a baseline checkout (issue 23: memory linear in the samples, 10,000 samples in
seconds).

Data, per sample count N (seeded; the true robot has random geometric errors):

- ``ur10 points``: the UR10 (DH, :func:`kinfw.verification.studies.ur10_urdf`), one
  marker of unknown offset on ``tool0`` seen by motion capture in an unknown frame
  ``mocap`` (N points, 0.5 mm noise);
- ``ur10 poses``: ``tool0`` poses in the root (N poses, 0.5 mm and 0.05 deg noise);
- ``head poses``: the built-in IIS head (:func:`kinfw.builtin_head_urdf`), as
  ``kinfw simulate`` makes it: stage 1 (9 plate poses per joint, 55 samples) and N
  stage 2 configurations at which the cameras see the target (a target pose per camera
  that sees it);
- ``head pixels``: the same with stage 2 as images (``kinfw simulate --pixels``) of a
  4 x 3 chessboard of 80 mm squares (12 corners, 0.5 px noise): N configurations, about
  1.2 images and 14 corners each.

Each file is calibrated by ``kinfw calibrate DATA --urdf URDF --out X`` with the default
options (``--params PARAMS`` to choose; with this much data the default model choice
picks ``full`` without cross-validation) in a fresh child process, for this checkout and
for a baseline checkout (``--baseline-dir DIR``, e.g. ``git worktree add --detach
/tmp/base <parent>``; the child points the editable install's package map at it:
:func:`benchmarks.common.repo_prelude`). Columns: peak resident set size (``ru_maxrss``
of the child, MB), wall and CPU time (user + system, s; less sensitive to other load),
the baseline / this ratios, and how far the two calibrated URDFs are apart (``identical``,
else the largest absolute difference of their numbers). A run that fails (e.g.
``MemoryError`` under the address-space cap ``--cap-gb``) shows its error.

The residual functions are compiled once per machine and kept
(:mod:`kinfw.identification.problem`, ``~/.cache/kinfw/casadi``): the first run of a
robot and observation layout compiles them (0.5-3 s); ``--cold`` gives this checkout's
every run an empty cache, so that its times include the compiling.

Run from the repository root: ``python benchmarks/bench_memory.py [--baseline-dir DIR]
[--sizes 1000,10000] [--large] [--data ur10-points,ur10-poses,head-poses,head-pixels]
[--baseline-max N] [--cap-gb G] [--cold]`` (``--large`` adds N = 100000; the baseline
runs only up to ``--baseline-max`` samples, default 10000: its 100k runs take many
minutes).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import REPO, format_table, machine_info, repo_prelude, wall_time_line

#: The unknown motion-capture frame in the robot root, [R | p] (m).
MOCAP_T_ROOT = np.array(
    [
        [0.0, -1.0, 0.0, 0.8],
        [1.0, 0.0, 0.0, -0.3],
        [0.0, 0.0, 1.0, 0.1],
        [0.0, 0.0, 0.0, 1.0],
    ]
)

#: The datasets, by the name ``--data`` takes.
DATA = ("ur10-points", "ur10-poses", "head-poses", "head-pixels")

#: The board of ``head-pixels``.
BOARD = "chessboard:4x3:0.08"


def write_ur10_data(directory: Path, n: int, seed: int = 0) -> tuple[Path, dict[str, Path]]:
    """The UR10's nominal URDF and its ``points`` and ``poses`` files of n samples."""
    from kinfw.measurements import Measurements, write_measurements
    from kinfw.model import load_robot
    from kinfw.simulation import perturb_robot, random_configurations, simulate_at
    from kinfw.verification.studies import UR10_JOINTS, ur10_urdf

    rng = np.random.default_rng(seed)
    urdf = directory / "ur10.urdf"
    urdf.write_text(ur10_urdf())
    nominal = load_robot(urdf)
    truth = load_robot(perturb_robot(nominal, rng))
    names = list(UR10_JOINTS)
    qs = random_configurations(*nominal.joint_limits(names), n, rng, fraction=0.8)
    offset = np.array([0.03, -0.02, 0.05])
    data = simulate_at(truth, qs, names, markers=[("tool0", offset, "ball")], rng=rng, noise_m=5e-4)
    R, p = MOCAP_T_ROOT[:3, :3], MOCAP_T_ROOT[:3, 3]
    points = tuple(
        replace(g, meas_p_point=g.meas_p_point @ R.T + p, measured_in="mocap") for g in data.points
    )
    files = {
        "ur10-points": directory / f"ur10_points_{n}.json",
        "ur10-poses": directory / f"ur10_poses_{n}.json",
    }
    write_measurements(files["ur10-points"], Measurements(data.joint_names, data.qs, points=points))
    poses = simulate_at(
        truth, qs, names, frames=["tool0"], rng=rng, noise_m=5e-4, noise_rad=np.radians(0.05)
    )
    write_measurements(files["ur10-poses"], poses)
    return urdf, files


def write_head_data(directory: Path, n: int, *, pixels: bool, seed: int = 0) -> Path:
    """The IIS head's ``kinfw simulate`` data with n stage 2 configurations (poses, or
    images of :data:`BOARD`)."""
    from kinfw.measurements import write_measurements
    from kinfw.model import builtin_head_urdf, load_robot
    from kinfw.simulation import simulate_measurements

    sim = simulate_measurements(
        load_robot(builtin_head_urdf()),
        stages=(1, 2),
        stage2_samples=n,
        pixels=pixels,
        board=BOARD if pixels else None,
        seed=seed,
    )
    path = directory / f"head_{'pixels' if pixels else 'poses'}_{n}.json"
    write_measurements(path, sim.data)
    return path


def write_data(directory: Path, n: int, which: tuple[str, ...]) -> dict[str, tuple[Path, Path]]:
    """Per dataset of ``which``, its nominal URDF and its measurement file of n samples."""
    from kinfw.model import builtin_head_urdf

    out = {}
    if {"ur10-points", "ur10-poses"} & set(which):
        urdf, files = write_ur10_data(directory, n)
        out.update({k: (urdf, v) for k, v in files.items() if k in which})
    head = Path(builtin_head_urdf())
    for name, pixels in (("head-poses", False), ("head-pixels", True)):
        if name in which:
            out[name] = (head, write_head_data(directory, n, pixels=pixels))
    return out


def run_calibrate(
    repo: Path,
    urdf: Path,
    data: Path,
    out: Path,
    *,
    params: str | None,
    cap_bytes: int | None,
    cache_dir: Path | None = None,
) -> tuple[float, float, float, str]:
    """Peak RSS (MB), wall and CPU time (s) of ``kinfw calibrate`` run on ``repo``'s code
    in a fresh child, and its last error line ('' when it succeeded)."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["KINFW_CACHE_DIR"] = str(cache_dir)
    code = (
        repo_prelude(repo)
        + "import sys\nimport kinfw.identification\n"
        + f"assert kinfw.identification.__file__.startswith({str(repo)!r})\n"
        + "from kinfw.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    args = [sys.executable, "-c", code, "calibrate", str(data), "--urdf", str(urdf)]
    args += ["--out", str(out)] + (["--params", params] if params else [])

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
        "u = resource.getrusage(resource.RUSAGE_CHILDREN); "
        "err = (p.stderr.strip().splitlines() or [''])[-1] if p.returncode else ''; "
        "print(u.ru_maxrss, dt, u.ru_utime + u.ru_stime, err, sep='\\t')"
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
    kb, dt, cpu, err = proc.stdout.rstrip("\n").split("\t", 3)
    return int(kb) / 1024.0, float(dt), float(cpu), err


_NUMBER = re.compile(r"-?\d+\.\d+(?:e-?\d+)?")


def urdf_difference(a: Path, b: Path) -> str:
    """``identical``, the largest absolute difference of the two URDFs' numbers when
    only numbers differ, or ``DIFFERENT``."""
    if not (a.exists() and b.exists()):
        return "-"
    ta, tb = a.read_text(), b.read_text()
    if ta == tb:
        return "identical"
    na, nb = _NUMBER.findall(ta), _NUMBER.findall(tb)
    if _NUMBER.sub("#", ta) != _NUMBER.sub("#", tb) or len(na) != len(nb):
        return "DIFFERENT"
    diff = max(abs(float(x) - float(y)) for x, y in zip(na, nb, strict=True))
    return f"numbers within {diff:.1e}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline-dir", type=Path, help="checkout to compare with")
    parser.add_argument("--sizes", default="1000,10000", help="sample counts, comma-separated")
    parser.add_argument("--large", action="store_true", help="also N = 100000")
    parser.add_argument(
        "--data", default=",".join(DATA), help=f"datasets, comma-separated, of {', '.join(DATA)}"
    )
    parser.add_argument("--params", default=None, help="kinfw calibrate --params (default: none)")
    parser.add_argument(
        "--baseline-max", type=int, default=10_000, help="largest N the baseline runs"
    )
    parser.add_argument(
        "--cap-gb", type=float, default=16.0, help="address-space cap of each child (GB)"
    )
    parser.add_argument(
        "--cold", action="store_true", help="this checkout compiles its functions in every run"
    )
    args = parser.parse_args()
    started = time.perf_counter()
    sizes = [int(s) for s in args.sizes.split(",")] + ([100_000] if args.large else [])
    which = tuple(d.strip() for d in args.data.split(","))
    unknown = sorted(set(which) - set(DATA))
    if unknown:
        parser.error(f"--data: unknown {', '.join(unknown)} (choose from {', '.join(DATA)})")
    cap = int(args.cap_gb * 2**30) if args.cap_gb > 0 else None
    print(machine_info())
    options = f"--params {args.params}" if args.params else "default options"
    print(
        f"kinfw calibrate ({options}); child address-space cap {args.cap_gb:g} GB; "
        f"compiled functions {'compiled in every run' if args.cold else 'cached'}\n"
    )
    checkouts = [("this", REPO.resolve())]
    if args.baseline_dir:
        checkouts.append(("baseline", args.baseline_dir.resolve()))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            for name, (urdf, data) in write_data(Path(tmp), n, which).items():
                row: list[str] = [name, f"{n}"]
                results, outs = {}, {}
                for label, repo in checkouts:
                    outs[label] = Path(tmp, f"{label}_{name}_{n}.urdf")
                    if label == "baseline" and n > args.baseline_max:
                        results[label] = None
                        continue
                    cache = Path(tempfile.mkdtemp(dir=tmp)) if args.cold else None
                    results[label] = run_calibrate(
                        repo,
                        urdf,
                        data,
                        outs[label],
                        params=args.params,
                        cap_bytes=cap,
                        cache_dir=cache if label == "this" else None,
                    )
                for label, _ in checkouts:
                    res = results[label]
                    if res is None:
                        row += ["skipped", "-", "-"]
                    elif res[3]:
                        row += [f"{res[0]:.0f}", f"failed: {res[3][:40]}", "-"]
                    else:
                        row += [f"{res[0]:.0f}", f"{res[1]:.1f}", f"{res[2]:.1f}"]
                if args.baseline_dir:
                    this, base = results["this"], results["baseline"]
                    ok = this and base and not this[3] and not base[3]
                    ratios = [base[1] / this[1], base[2] / this[2], base[0] / this[0]] if ok else []
                    row += [f"{v:.1f}x" for v in ratios] if ok else ["-", "-", "-"]
                    row.append(urdf_difference(outs["this"], outs["baseline"]) if ok else "-")
                rows.append(row)
                print("  ".join(row), flush=True)
    header = ["data", "N"]
    for label, _ in checkouts:
        header += [f"{label} peak MB", f"{label} wall s", f"{label} CPU s"]
    if args.baseline_dir:
        header += ["wall base/this", "CPU base/this", "memory base/this", "URDFs"]
    print()
    print(format_table(header, rows))
    print(wall_time_line(started))


if __name__ == "__main__":
    main()
