"""kinfw against FIGAROH 1.0.2 on real TIAGo data: the same folds, the same samples, one run.

Run from the repository root (FIGAROH is the ``figaroh`` extra, a benchmark baseline
that kinfw never imports)::

    pip install -e ".[test,bench,figaroh]"
    python benchmarks/bench_figaroh.py              # full run
    python benchmarks/bench_figaroh.py --quick      # fewer rows and one timing repeat
    python benchmarks/bench_figaroh.py --folds 5 --seed 0

For every dataset of :data:`DATASETS` (a FIGAROH CSV and the kinfw JSON converted from it
by ``kinfw import-csv``, both in ``tests/data/tiago_figaroh/``), on the nominal
``tiago_no_hand.urdf`` of example-robot-data for both tools:

1. k-fold cross-validation by sample, one split for both tools
   (``np.random.default_rng(seed).permutation(n)`` then ``np.array_split(., k)``, the
   split of :func:`kinfw.verification.evaluation.crossvalidate`). Each row is trained on the
   training folds only and predicts the held-out fold with nothing refitted:

   - kinfw ``none`` (nominal joints; only what the URDF cannot know: the tracker frame
     and the marker offset) and ``frames`` (base and tool frames), ``offsets``, ``full``
     (:func:`kinfw.identification.identify`, default Huber loss), and the default of
     ``kinfw calibrate`` (``--params auto``): on each training fold,
     :func:`kinfw.verification.evaluation.choose_parameters` (its own inner
     cross-validation on that training fold only), then ``identify`` with the chosen set
     and prior; what each fold chose is printed;
   - FIGAROH ``BaseCalibration`` with its default estimation method (``structural``),
     ``map_cv`` (prior scale chosen by FIGAROH's own inner cross-validation on the
     training samples) and, without ``--quick``, ``map_cv`` with ``cv_per_group``; base
     and tool frames estimated (``known_baseframe`` / ``known_tipframe`` False, as
     figaroh-examples' TIAGo and UR10 calibrations), ``outlier_threshold`` 0.05 m (the
     TIAGo example's; FIGAROH refits without training samples above it). The held-out
     samples are removed with FIGAROH's own ``del_list``.

   Columns: held-out position RMS (mm) = the RMS over ALL held-out samples of all folds
   of the 3D position error norm (pooled, not a mean of per-fold RMS); orientation RMS
   (deg, the angle of ``R_meas^T R_pred``) when the data has orientations; mean fit time
   per fold (s): kinfw ``identify`` (plus ``choose_parameters`` for the default) on
   data already in memory, FIGAROH construction (reads its YAML and CSV) + ``initialize``
   (parameter selection; ``map_cv``'s inner cross-validation) + ``solve``.
2. Timing on all the data: the whole process as a user runs it, each in a fresh
   subprocess (interpreter start, imports, reading files, fit, writing nothing for
   FIGAROH / the calibrated URDF for kinfw): ``kinfw calibrate DATA --urdf URDF --out
   TMP`` (default options) vs FIGAROH construct + ``initialize`` + ``solve``
   (``structural``); then in-process the fit alone: kinfw ``choose_parameters`` +
   ``identify`` (what ``kinfw calibrate`` computes) and ``identify`` with ``full``, vs
   FIGAROH ``initialize`` + ``solve`` and ``solve`` alone. Medians of the repeats and the
   ratios kinfw / FIGAROH.

Fairness checks (the script stops if one fails): the JSON's joint values and marker
positions equal the CSV rows FIGAROH reads, sample by sample; every FIGAROH fold trains on
exactly the rows kinfw trains on. Errors of both tools are computed the same way: the
norm of (prediction - measurement) in the tracker frame, for every held-out sample (no
held-out sample is dropped as an outlier for either tool).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common (kinfw comes from pip install -e .)
    sys.path.insert(0, str(REPO))

from benchmarks.common import format_table, load_average, machine_info

DATA_DIR = REPO / "tests" / "data" / "tiago_figaroh"

#: One line per dataset: (name, FIGAROH CSV, kinfw JSON converted from it, tool frame:
#: the URDF frame the marker is fixed to, FIGAROH's ``tool_frame``). Files in DATA_DIR.
DATASETS: tuple[tuple[str, str, str, str], ...] = (
    (
        "vicon_gripper3_base1",
        "vicon_calibration_gripper3_base1.csv",
        "vicon_gripper3_base1.json",
        "arm_7_link",
    ),
)

#: The nominal URDF, in example-robot-data (the test extra).
URDF_RELATIVE = "tiago_description/robots/tiago_no_hand.urdf"

#: FIGAROH rows: (label, ``estimation`` settings); the last is skipped with --quick.
FIGAROH_METHODS: tuple[tuple[str, dict], ...] = (
    ("FIGAROH structural (default)", {"method": "structural"}),
    ("FIGAROH map_cv", {"method": "map_cv"}),
    ("FIGAROH map_cv, cv_per_group", {"method": "map_cv", "cv_per_group": True}),
)

#: ``(sigma_m, lever_m)`` of the uniform priors scored with ``full`` (the grid the default
#: searched until issue 37: angles ``sigma / lever``).
UNIFORM_PRIORS = tuple((m, lever) for m in (0.3e-3, 1e-3, 3e-3, 10e-3) for lever in (0.1, 0.5))

#: kinfw parameter sets scored besides the default.
KINFW_SETS = ("none", "frames", "offsets", "full")

#: FIGAROH's unified configuration, as figaroh-examples' ``tiago_unified_config.yaml``
#: (task calibration, variant vicon_calibration), the tool frame and data per dataset.
_CONFIG = """\
_metadata:
  schema_version: "2.0"
  config_type: "robot_configuration"
robot:
  name: "tiago"
  properties:
    joints:
      active_joints: [{joints}]
tasks:
  calibration:
    enabled: true
    parameters:
      calibration_level: "full_params"
      include_non_geometric: false
      outlier_threshold: 0.05
      estimation: {estimation}
    kinematics:
      base_frame: "universe"
      tool_frame: "{tool_frame}"
    measurements:
      markers:
        - name: "marker"
          reference_joint: "{reference_joint}"
          measurable_dof: [{dof}]
          sensor_type: "tracker"
      poses:
        base_pose: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        tool_pose: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    data:
      source_file: "{csv}"
      validation_data_file: ""
      number_of_samples: {n}
"""


# -- FIGAROH -----------------------------------------------------------------------------


def _quiet_figaroh() -> None:
    """FIGAROH logs every stage and warns about its default cost: silence both."""
    warnings.filterwarnings("ignore")
    logging.disable(logging.WARNING)


def figaroh_model(urdf: Path):
    """FIGAROH's robot: ``figaroh.tools.robot.load_robot`` fails on the URDF's missing
    meshes, so a geometry-free Pinocchio model of the same kinematics, wrapped."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(urdf))
    robot = pin.RobotWrapper(model)
    robot.q0 = pin.neutral(model)
    return robot


def figaroh_calibrator(robot, config: Path, del_list=()):
    """FIGAROH's ``BaseCalibration`` on ``config`` without the samples ``del_list``,
    constructed (reads the YAML and CSV) and initialized (parameter selection), both
    metrology frames estimated."""
    from figaroh.calibration import BaseCalibration
    from figaroh.calibration.calibration_tools import calc_updated_fkm

    class Calibration(BaseCalibration):
        # BaseCalibration's default cost (log-map residual, weighted), without its
        # "implement a robot-specific cost" warning
        def cost_function(self, var):
            pee = calc_updated_fkm(self.model, self.data, var, self.q_measured, self.calib_config)
            return self.apply_measurement_weighting(
                self._compute_logmap_residuals(self.PEE_measured, pee)
            )

    cal = Calibration(robot, str(config), del_list=list(del_list))
    cal.calib_config["known_baseframe"] = False
    cal.calib_config["known_tipframe"] = False
    cal.initialize()
    return cal


def figaroh_solve(cal):
    with contextlib.redirect_stdout(io.StringIO()):  # FIGAROH prints a summary
        return cal.solve(enable_logging=False)


def figaroh_predict(cal, x: NDArray, q: NDArray) -> NDArray:
    """FIGAROH's predicted measurements of joint values ``q`` (n, nq) with parameters
    ``x``: shape (n, d), d = 3 (position, m) or 6 (position m, Pinocchio RPY rad)."""
    from figaroh.calibration.calibration_tools import calc_updated_fkm

    cfg = dict(cal.calib_config)
    cfg["NbSample"] = q.shape[0]
    out = calc_updated_fkm(cal.model, cal.data, x, q, cfg)
    return np.asarray(out).reshape(-1, q.shape[0]).T  # dof-major -> (n, d)


def figaroh_measured(cal) -> tuple[NDArray, NDArray]:
    """The calibrator's joint values (n, nq) and measurements (n, d), in sample order."""
    q = np.asarray(cal.q_measured)
    return q, np.asarray(cal.PEE_measured).reshape(-1, q.shape[0]).T


def rotation_angles(rpy_meas: NDArray, rpy_pred: NDArray) -> NDArray:
    """Angle (rad) of ``R_meas^T R_pred`` per row, Pinocchio RPY (n, 3) each."""
    import pinocchio as pin

    return np.array(
        [
            np.linalg.norm(pin.log3(pin.rpy.rpyToMatrix(a).T @ pin.rpy.rpyToMatrix(b)))
            for a, b in zip(rpy_meas, rpy_pred, strict=True)
        ]
    )


def write_config(path: Path, csv: Path, tool_frame: str, estimation: dict) -> Path:
    """FIGAROH's YAML for one dataset and estimation method (joints and measured degrees
    of freedom from the CSV header, the marker's joint from the URDF)."""
    header = csv.read_text().splitlines()[0].strip().strip(",").split(",")
    joints = [c for c in header if c.endswith("_joint")]
    has_rotation = "phix1" in header
    n = sum(1 for line in csv.read_text().splitlines()[1:] if line.strip())
    from tests.erd import urdf_path

    robot = figaroh_model(urdf_path(URDF_RELATIVE))
    model = robot.model
    reference = model.names[model.frames[model.getFrameId(tool_frame)].parentJoint]
    est = "{" + ", ".join(f"{k}: {str(v).lower()}" for k, v in estimation.items()) + "}"
    path.write_text(
        _CONFIG.format(
            joints=", ".join(f'"{j}"' for j in joints),
            estimation=est,
            tool_frame=tool_frame,
            reference_joint=reference,
            dof=", ".join(["true"] * 3 + ["true" if has_rotation else "false"] * 3),
            csv=csv,
            n=n,
        )
    )
    return path


def figaroh_fit_process(config: str, urdf: str) -> None:
    """The whole FIGAROH process timed in a subprocess (``--figaroh-fit``)."""
    _quiet_figaroh()
    figaroh_solve(figaroh_calibrator(figaroh_model(Path(urdf)), Path(config)))


# -- the comparison ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Row:
    """One model's held-out errors over all folds: position (m), rotation (rad, NaN
    without orientations) per held-out sample, fit time per fold (s), and a note."""

    label: str
    position_m: NDArray[np.float64]
    rotation_rad: NDArray[np.float64]
    fit_s: list[float]
    note: str = ""

    def cells(self, has_rotation: bool) -> list[str]:
        if np.isnan(self.position_m).any():  # a fold failed: no pooled score
            cells = [self.label, "-", "-"] + (["-"] if has_rotation else [])
            return [*cells, f"{np.mean(self.fit_s):.2f}", self.note]
        pos = 1e3 * np.sqrt(np.mean(self.position_m**2))
        cells = [self.label, f"{pos:.2f}", f"{1e3 * np.max(self.position_m):.1f}"]
        if has_rotation:
            cells.append(f"{np.degrees(np.sqrt(np.nanmean(self.rotation_rad**2))):.2f}")
        return [*cells, f"{np.mean(self.fit_s):.2f}", self.note]


def folds_of(n: int, k: int, seed: int) -> list[NDArray[np.int64]]:
    """Held-out sample indices per fold: the split of ``crossvalidate``."""
    order = np.random.default_rng(seed).permutation(n)
    return [np.sort(f) for f in np.array_split(order, k)]


def kinfw_rows(nominal, data, folds, sets, priors: bool) -> tuple[list[Row], list[str]]:
    """kinfw's held-out rows: each set, ``full`` with each prior of :data:`UNIFORM_PRIORS`
    (``priors``: the grid the default searched until issue 37), ``full`` under the prior
    by group chosen from the training fold, then the default; and what the default chose
    on each fold.

    A fit that raises (a fold too small for it) is reported in the row's note, its
    held-out errors NaN (the row then prints no RMS).
    """
    from kinfw.identification import identify
    from kinfw.identification.problem import Unknown
    from kinfw.verification.evaluation import choose_parameters, held_out_errors

    def fit_predict(train, test, parameters, prior):
        chosen = isinstance(prior, str)  # "chosen": the group sigmas from the training fold
        result = identify(
            nominal,
            train,
            parameters=parameters,
            prior=None if chosen else prior,
            choose_prior=chosen,
        )
        unknowns = result.refined.unknowns
        if result.refined.model_frame is not None:  # the root's pose in the tracker frame
            unknowns = (*unknowns, Unknown("frame", result.refined.model_frame, result.w_T_root))
        held = held_out_errors(nominal, result.urdf_xml, unknowns, test)
        pos, samples = held.values("position")
        rot = held.values("rotation")[0]
        rot = rot if len(rot) else np.full(len(pos), np.nan)  # points: no orientation
        order = np.argsort(samples, kind="stable")
        return pos[order], rot[order]

    everything = np.arange(data.n_samples)
    runs = [(s, s, None) for s in sets]
    if priors:
        runs += [
            (f"full, prior {1e3 * m:g} mm / {1e3 * m / lever:g} mrad", "full", (m, m / lever))
            for m, lever in UNIFORM_PRIORS
        ]
    runs.append(("full, prior by group (chosen)", "full", "chosen"))
    runs.append(("default (--params auto)", None, None))
    rows, chosen = [], []
    for label, parameters, prior in runs:
        pos, rot, times, failed = [], [], [], []
        for f, test_ids in enumerate(folds):
            train = data.subset(np.setdiff1d(everything, test_ids))
            test = data.subset(test_ids)
            with warnings.catch_warnings():  # the data's warnings, said by kinfw calibrate
                warnings.simplefilter("ignore", UserWarning)
                start = time.perf_counter()
                try:
                    fold_parameters, fold_prior = parameters, prior
                    if parameters is None:  # the default: chosen on the training fold only
                        choice = choose_parameters(nominal, train)
                        fold_parameters, fold_prior = choice.parameters, choice.prior
                        chosen.append(f"fold {f}: {choice.label} ({choice.reason})")
                    p, r = fit_predict(train, test, fold_parameters, fold_prior)
                except Exception as error:  # reported, not hidden: the row shows it
                    if parameters is None:
                        why = str(error).split(" (joint")[0].replace(f"{data.source}: ", "")
                        chosen.append(
                            f"fold {f}: choose_parameters FAILED, {type(error).__name__}: {why}"
                        )
                    failed.append(f)
                    p = r = np.full(len(test_ids), np.nan)
                times.append(time.perf_counter() - start)
            pos.append(p)
            rot.append(r)
        note = "nominal joints; tracker frame + marker fitted" if label == "none" else ""
        if failed:
            note = f"FAILED on folds {failed} (see below)"
        rows.append(Row(f"kinfw {label}", np.concatenate(pos), np.concatenate(rot), times, note))
    return rows, chosen


def figaroh_rows(robot, configs, folds, q_all, meas_all) -> list[Row]:
    """FIGAROH's held-out rows, one per configuration (label, YAML path)."""
    n = q_all.shape[0]
    rows = []
    for label, config in configs:
        pos, rot, times, params = [], [], [], set()
        for test_ids in folds:
            start = time.perf_counter()
            np.random.seed(0)  # noqa: NPY002  (FIGAROH's retry perturbs with it)
            cal = figaroh_calibrator(robot, config, del_list=test_ids.tolist())
            result = figaroh_solve(cal)
            times.append(time.perf_counter() - start)
            train_ids = np.setdiff1d(np.arange(n), test_ids)
            q_train, _ = figaroh_measured(cal)
            if not np.array_equal(q_train, q_all[train_ids]):
                raise SystemExit(f"{label}: FIGAROH's training rows are not the fold's")
            pred = figaroh_predict(cal, result.x, q_all[test_ids])
            pos.append(np.linalg.norm(pred[:, :3] - meas_all[test_ids, :3], axis=1))
            rot.append(
                rotation_angles(meas_all[test_ids, 3:6], pred[:, 3:6])
                if pred.shape[1] == 6
                else np.full(len(test_ids), np.nan)
            )
            params.add(len(cal.calib_config["param_name"]))
        note = f"{'/'.join(map(str, sorted(params)))} parameters"
        rows.append(Row(label, np.concatenate(pos), np.concatenate(rot), times, note))
    return rows


def check_same_samples(data, q_all: NDArray, meas_all: NDArray, csv: Path) -> None:
    """The JSON is the CSV: same joints and marker positions, sample by sample."""
    qs = np.asarray(data.qs)
    (points,) = data.points
    if qs.shape[0] != q_all.shape[0]:
        raise SystemExit(f"{csv}: {q_all.shape[0]} rows, the JSON has {qs.shape[0]} samples")
    # FIGAROH's q is the model's full configuration; the JSON's joints are its first ones
    if not np.allclose(q_all[:, : qs.shape[1]], qs, atol=1e-12) or not np.allclose(
        meas_all[points.sample, :3], points.meas_p_point, atol=1e-12
    ):
        raise SystemExit(f"{csv}: the JSON's samples differ from the CSV's rows")


def median(xs) -> float:
    return statistics.median(xs)


def timing(urdf: Path, csv_json: Path, config: Path, robot, nominal, data, repeats: int) -> str:
    """Whole process (subprocesses) and fit alone (in process), medians and ratios."""
    from kinfw.identification import identify
    from kinfw.verification.evaluation import choose_parameters

    kinfw_exe = Path(sys.executable).with_name("kinfw")
    whole = {"kinfw": [], "figaroh": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            for name, cmd in (
                (
                    "kinfw",
                    [
                        *(str(kinfw_exe), "calibrate", str(csv_json), "--urdf", str(urdf)),
                        *("--out", str(Path(tmp, "calibrated.urdf"))),
                    ],
                ),
                (
                    "figaroh",
                    [sys.executable, __file__, "--figaroh-fit", str(config), str(urdf)],
                ),
            ):
                start = time.perf_counter()
                subprocess.run(cmd, check=True, capture_output=True)
                whole[name].append(time.perf_counter() - start)
    solve = {"kinfw default": [], "kinfw full": [], "figaroh init+solve": [], "figaroh solve": []}
    label = ""
    for _ in range(repeats):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            start = time.perf_counter()
            choice = choose_parameters(nominal, data)
            identify(nominal, data, parameters=choice.parameters, prior=choice.prior)
            solve["kinfw default"].append(time.perf_counter() - start)
            label = choice.label
            start = time.perf_counter()
            identify(nominal, data, parameters="full")
            solve["kinfw full"].append(time.perf_counter() - start)
        np.random.seed(0)  # noqa: NPY002
        start = time.perf_counter()
        cal = figaroh_calibrator(robot, config)
        mid = time.perf_counter()
        figaroh_solve(cal)
        end = time.perf_counter()
        solve["figaroh init+solve"].append(end - start)
        solve["figaroh solve"].append(end - mid)
    w_k, w_f = median(whole["kinfw"]), median(whole["figaroh"])
    s = {k: median(v) for k, v in solve.items()}
    rows = [
        [
            "whole process (subprocess)",
            f"{w_k:.2f}",
            f"{w_f:.2f}",
            f"{w_k / w_f:.2f}",
            "kinfw calibrate (default) vs FIGAROH construct+initialize+solve",
        ],
        [
            "fit, in process",
            f"{s['kinfw default']:.2f}",
            f"{s['figaroh init+solve']:.2f}",
            f"{s['kinfw default'] / s['figaroh init+solve']:.2f}",
            f"kinfw choose_parameters+calibrate ({label}) vs FIGAROH construct+init+solve",
        ],
        [
            "solve only, in process",
            f"{s['kinfw full']:.2f}",
            f"{s['figaroh solve']:.2f}",
            f"{s['kinfw full'] / s['figaroh solve']:.2f}",
            "kinfw calibrate(full) vs FIGAROH solve() after initialize",
        ],
    ]
    return (
        f"kinfw default on all {data.n_samples} samples: {label} ({choice.reason})\n"
        f"timing on all {data.n_samples} samples, median of {repeats}\n"
        + format_table(["", "kinfw s", "FIGAROH s", "kinfw/FIGAROH", "what"], rows)
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rows, one timing repeat")
    parser.add_argument("--folds", type=int, default=5, help="folds (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the fold split")
    parser.add_argument("--repeats", type=int, default=None, help="timing repeats (3; quick 1)")
    parser.add_argument(  # internal: the FIGAROH process timed in a subprocess
        "--figaroh-fit", nargs=2, metavar=("CONFIG", "URDF"), help=argparse.SUPPRESS
    )
    args = parser.parse_args(argv)
    # FIGAROH's ndcurves re-registers a Pinocchio converter on import, and says so
    warnings.filterwarnings("ignore", "to-Python converter", RuntimeWarning)
    try:
        import figaroh  # noqa: F401
    except ImportError:
        print(
            "bench_figaroh: FIGAROH is not installed: pip install -e '.[figaroh]' "
            "(the figaroh extra, figaroh==1.0.2)",
            file=sys.stderr,
        )
        return 2
    if args.figaroh_fit:
        figaroh_fit_process(*args.figaroh_fit)
        return 0
    _quiet_figaroh()
    started = time.perf_counter()
    repeats = args.repeats or (1 if args.quick else 3)
    from importlib.metadata import version

    import pinocchio as pin

    from kinfw.measurements import read_measurements
    from kinfw.model import load_robot
    from tests.erd import urdf_path

    urdf = urdf_path(URDF_RELATIVE)
    print(
        machine_info(
            [("pinocchio", pin.__version__), ("figaroh", version("figaroh"))],
            code=[("kinfw", str(REPO)), ("urdf", str(urdf))],
        )
    )
    print(
        f"mode       {'quick' if args.quick else 'full'}, {args.folds}-fold by sample, "
        f"seed {args.seed}, timing repeats {repeats}"
    )
    print(
        "position RMS = RMS over all held-out samples (all folds pooled) of the 3D error "
        "norm, mm; max = the largest; rotation = angle of R_meas^T R_pred; fit s = mean "
        "per fold"
    )
    nominal = load_robot(urdf)
    robot = figaroh_model(urdf)
    sets = ("none", "frames", "full") if args.quick else KINFW_SETS
    methods = FIGAROH_METHODS[:2] if args.quick else FIGAROH_METHODS
    with tempfile.TemporaryDirectory() as tmp:
        for name, csv_name, json_name, tool_frame in DATASETS:
            csv, json_path = DATA_DIR / csv_name, DATA_DIR / json_name
            data = read_measurements(json_path)
            configs = [
                (label, write_config(Path(tmp, f"{name}_{i}.yaml"), csv, tool_frame, est))
                for i, (label, est) in enumerate(methods)
            ]
            q_all, meas_all = figaroh_measured(figaroh_calibrator(robot, configs[0][1]))
            check_same_samples(data, q_all, meas_all, csv)
            has_rotation = meas_all.shape[1] == 6
            folds = folds_of(data.n_samples, args.folds, args.seed)
            print(
                f"\n== {name}: {data.n_samples} samples, tool frame {tool_frame}, "
                f"{'6D poses' if has_rotation else '3D points'}; folds (held-out samples): "
                + "; ".join(",".join(map(str, f)) for f in folds)
            )
            rows, chosen = kinfw_rows(nominal, data, folds, sets, priors=not args.quick)
            rows += figaroh_rows(robot, configs, folds, q_all, meas_all)
            headers = ["model", "pos RMS mm", "max mm"]
            headers += ["rot RMS deg"] if has_rotation else []
            headers += ["fit s/fold", "note"]
            print(format_table(headers, [r.cells(has_rotation) for r in rows]))
            print("kinfw default, chosen on each training fold:")
            print("\n".join(f"  {c}" for c in chosen))
            print()
            print(timing(urdf, json_path, configs[0][1], robot, nominal, data, repeats))
    print(
        f"\ntotal benchmark wall time {time.perf_counter() - started:.1f} s, "
        f"load avg now {load_average()}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
