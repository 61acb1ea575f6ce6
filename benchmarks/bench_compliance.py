"""Joint compliance under gravity and payload (issue 36): the default against the noise
floor, rigid data unchanged, compensation by reach, and the cost of a compliant fit.

Simulated compliant arms (the project's simulator, ``kinfw.simulate``): the UR10 and
TIAGo's arm of example-robot-data, with their URDF inertias, three tracker reflectors on
the flange (noise ``SIGMA_M`` per axis, in an unknown tracker frame), joint errors of
1 mm / 0.2 deg, every joint's compliance ``C_TRUE``; with and without a payload that
varies per sample (0 to ``PAYLOAD_KG`` on the flange). Each dataset is split into
alternate training and held-out samples.

Tables:

1. held-out position RMS (mm) of ``kinfw calibrate``'s default (``--params auto``: the
   model choice, which now weighs a compliance), of ``full`` alone (the URDF alone) and of
   ``full`` with ``--model compliance``, against the noise floor ``sqrt(3) sigma``;
2. rigid data (no compliance): the default's held-out error against the rigid default's
   (the model choice without the compliance candidate, what ``kinfw calibrate`` fitted
   before it), which must stay within 1 %;
3. compensation: ``kinfw.reach`` of random flange points with the calibrated model
   (compliant, and rigid; trained with payloads varying, reflectors in the root with
   known offsets so the flange itself is determined) under a random payload, the command
   sent to the true compliant robot under that payload: the error it achieves;
4. cost: a 10,000-sample fit (``refine``) with and without the compliance.

``python benchmarks/bench_compliance.py [--quick] [--seed S]``
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings

import numpy as np

from benchmarks.common import format_table, load_average, wall_time_line
from kinfw.control import reach
from kinfw.model import ModelSpec, Payloads, load_robot
from kinfw.simulation import simulate_measurements
from kinfw.verification.evaluation import choose_parameters
from kinfw.verification.reporting import calibrate_and_report
from tests.erd import urdf_path

SIGMA_M = 0.02e-3
C_TRUE = 5e-6  # rad/Nm
PAYLOAD_KG = 10.0
ROBOTS = {
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
    "tiago": ("tiago_description/robots/tiago_no_hand.urdf", "arm_7_link"),
}
REFLECTORS_M = ((0.1, 0.0, 0.05), (0.0, 0.1, 0.05), (0.0, 0.0, 0.15))


def _simulated(nominal, flange, n, seed, compliance, in_root=False, payload=False):
    """The arm measured by the reflectors (in a tracker frame, or with known offsets in
    the root), with a payload of 0 to ``PAYLOAD_KG`` per sample on the flange or none,
    split alternately into training and held-out samples."""
    sim = simulate_measurements(
        nominal,
        markers=[(flange, np.array(p)) for p in REFLECTORS_M],
        mocap_frame=None if in_root else "mocap",
        offsets_known=in_root,
        mocap_samples=n,
        noise_m=SIGMA_M,
        error_mm=1.0,
        error_deg=0.2,
        compliance=compliance,
        payloads=(flange, PAYLOAD_KG, (0.0, 0.0, 0.1)) if payload else None,
        seed=seed,
    )
    data = sim.data
    return sim, data.subset(np.arange(0, n, 2)), data.subset(np.arange(1, n, 2))


def _held_rms_mm(result) -> float:
    return max(r.after[0].value for r in result.report.errors_held_out)


def _calibrated(nominal, train, test, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate_and_report(nominal, train, held_out=test, **options)


def accuracy_rows(n: int, seed: int) -> list[list[str]]:
    rows = []
    for (name, (path, flange)), payload in itertools.product(ROBOTS.items(), (False, True)):
        nominal = load_robot(urdf_path(path))
        _, train, test = _simulated(nominal, flange, n, seed, C_TRUE, payload=payload)
        floor = np.sqrt(3.0) * SIGMA_M * 1e3
        default = _calibrated(nominal, train, test)
        rigid = _calibrated(nominal, train, test, parameters="full")
        compliant = _calibrated(nominal, train, test, parameters="full", model=["compliance"])
        chosen = default.choice.label if default.choice is not None else "given"
        rows.append(
            [
                name,
                f"0-{PAYLOAD_KG:g} kg" if payload else "none",
                str(train.n_samples),
                f"{floor:.4f}",
                f"{_held_rms_mm(default):.4f}",
                f"{_held_rms_mm(default) / floor:.3f}",
                f"{_held_rms_mm(rigid):.4f}",
                f"{_held_rms_mm(compliant):.4f}",
                chosen,
            ]
        )
    return rows


def rigid_rows(n: int, seed: int) -> list[list[str]]:
    rows = []
    for name, (path, flange) in ROBOTS.items():
        nominal = load_robot(urdf_path(path))
        _, train, test = _simulated(nominal, flange, n, seed + 100, None)
        default = _calibrated(nominal, train, test)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            before = choose_parameters(nominal, train, model_spec=False)
        old = _calibrated(nominal, train, test, parameters=before.parameters, prior=before.prior)
        ratio = _held_rms_mm(default) / _held_rms_mm(old)
        rows.append(
            [
                name,
                str(train.n_samples),
                f"{_held_rms_mm(old):.4f}",
                f"{_held_rms_mm(default):.4f}",
                f"{ratio:.4f}",
                default.choice.label if default.choice else "given",
            ]
        )
    return rows


def compensation_rows(n: int, seed: int, targets: int) -> list[list[str]]:
    """Reach with each calibrated model, the command sent to the true compliant robot
    under a random payload: the distance of the flange it achieves from the target. The
    reflectors are measured in the root with known offsets here, so the flange (not only
    the reflectors) is determined and the root is the truth's."""
    rows = []
    rng = np.random.default_rng(seed)
    for name, (path, flange) in ROBOTS.items():
        nominal = load_robot(urdf_path(path))
        sim, train, test = _simulated(nominal, flange, n, seed, C_TRUE, in_root=True, payload=True)
        truth = sim.truth
        models = {
            "compliant": _calibrated(nominal, train, test, parameters="full", model=["compliance"]),
            "rigid": _calibrated(nominal, train, test, parameters="full"),
        }
        names = truth.joint_names
        lower, upper = truth.joint_limits(names)
        lo, hi = np.maximum(lower, -np.pi), np.minimum(upper, np.pi)
        errors = {label: [] for label in models}
        for _ in range(targets):
            q = lo + (hi - lo) * rng.uniform(0.2, 0.8, size=len(names))
            target = truth.frame_poses(q, flange, names)[:3, 3]  # reachable: the truth's
            load = Payloads.constant(1, flange, rng.uniform(0.0, PAYLOAD_KG), (0.0, 0.0, 0.1))
            for label, result in models.items():
                got = reach(result.robot, flange, target, q_start=q, payload=load)
                physical = truth.spec.joint_values(truth, names, got.command[None], load)[0]
                achieved = truth.frame_poses(physical, flange, names)[:3, 3]
                errors[label].append(np.linalg.norm(achieved - target))
        for label, e in errors.items():
            e = 1e3 * np.array(e)
            rows.append(
                [name, label, str(targets), f"{np.sqrt(np.mean(e**2)):.4f}", f"{e.max():.4f}"]
            )
    return rows


def cost_rows(n: int, seed: int) -> list[list[str]]:
    """``refine`` of ``n`` samples, rigid and compliant, each twice in a fresh compile
    cache (``KINFW_CACHE_DIR``): the first run builds and compiles its CasADi graph, the
    second loads it (what every later calibration of the robot costs)."""
    import os
    import tempfile

    from kinfw.identification import refine

    rows = []
    for name, (path, flange) in ROBOTS.items():
        nominal = load_robot(urdf_path(path))
        sim = simulate_measurements(
            nominal,
            markers=[(flange, np.array(p)) for p in REFLECTORS_M],
            mocap_samples=n,
            noise_m=SIGMA_M,
            compliance=C_TRUE,
            seed=seed,
        )
        times = {}
        with tempfile.TemporaryDirectory() as cache:
            os.environ["KINFW_CACHE_DIR"] = cache
            for label, robot in (
                ("rigid", nominal),
                ("compliant", nominal.with_spec(ModelSpec.parse(["compliance"]))),
            ):
                runs = []
                for _ in range(2):
                    t0 = time.perf_counter()
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        refine(robot, sim.data, loss="linear")
                    runs.append(time.perf_counter() - t0)
                times[label] = runs
        rows.append(
            [
                name,
                str(n),
                f"{times['rigid'][0]:.2f}",
                f"{times['compliant'][0]:.2f}",
                f"{times['rigid'][1]:.2f}",
                f"{times['compliant'][1]:.2f}",
                f"{times['compliant'][1] / times['rigid'][1]:.2f}",
            ]
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples and targets")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    started = time.perf_counter()
    n, targets, big = (120, 10, 2000) if args.quick else (400, 30, 10000)
    print(f"bench_compliance: load average {load_average()}; {n} samples per set")
    print("\n1. compliant arms, held out (position RMS mm; floor sqrt(3) sigma):")
    print(
        format_table(
            [
                "robot",
                "payload",
                "train",
                "floor",
                "default",
                "default/floor",
                "full alone",
                "full+compliance",
                "default chose",
            ],
            accuracy_rows(n, args.seed),
        )
    )
    print("\n2. rigid arms: the default with the compliance candidate vs without it:")
    print(
        format_table(
            ["robot", "train", "before mm", "now mm", "now/before", "now chose"],
            rigid_rows(n, args.seed),
        )
    )
    print("\n3. compensation: reach with the calibrated model, sent to the true robot:")
    print(
        format_table(
            ["robot", "model", "targets", "RMS mm", "max mm"],
            compensation_rows(n, args.seed, targets),
        )
    )
    print(f"\n4. cost of a {big}-sample fit (refine, linear loss; cold: compiling its graph):")
    print(
        format_table(
            [
                *("robot", "samples", "rigid cold s", "compliant cold s"),
                *("rigid s", "compliant s", "ratio"),
            ],
            cost_rows(big, args.seed),
        )
    )
    print(wall_time_line(started))


if __name__ == "__main__":
    main()
