"""The study behind ``kinfw demo``: the IIS-head experiment of Shih et al. (1992) in
simulation, end to end.

A true robot is the built-in IIS-head URDF with 5 mm / 1 deg errors. Stage 1: the
plates seen by the stereo rig, one joint at a time (9 per joint); stage 2: both cameras
see a fixed target in 30 random configurations; noise sigma 0.5 mm / 0.5 deg. The
calibration runs closed form, A = X B Y and the joint least squares; 100 held-out random
configurations score it against noisy measurements and against the noise-free truth.

With ``pixels=True`` stage 2 is images instead: each camera (default intrinsics,
:func:`kinfw.simulation.default_intrinsics`: 640 x 480, fx = fy = 600 px) sees the
corners of a fixed chessboard (:data:`kinfw.simulation.DEFAULT_BOARD`) in 30 random
configurations where it is in view (:func:`kinfw.simulation.pixel_views`), pixel
noise :data:`PIXEL_SIGMA` px; the calibration minimises the reprojection error jointly
with the kinematics. The held-out tables are the same (camera_T_target of the board at
100 configurations, from the noise-free truth and with pose noise); the held-out
reprojection error is measured on 30 fresh images (:attr:`DemoResult.held_out_pixels`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinfw import progress
from kinfw.camera import parse_board
from kinfw.files import write_text_atomic
from kinfw.identification.checks import ChangeBound
from kinfw.measurements import concatenate_measurements, write_measurements
from kinfw.model import BlockKey, Robot, builtin_head_urdf, load_robot
from kinfw.observations import TargetObservations
from kinfw.records import CalibrationReport, ReprojectionSection, StageErrors, write_report
from kinfw.simulation import (
    DEFAULT_BOARD,
    default_intrinsics,
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    pixel_views,
    random_configurations,
    simulate_at,
)
from kinfw.verification.evaluation import reprojection_section
from kinfw.verification.reporting import (
    before_after_rows,
    calibrate_and_report,
    errors_by_group,
    plot_stage_errors,
)

#: What :func:`run_demo` writes into its output directory.
DEMO_FILES = (
    "data.json",
    "held_out.json",
    "true.urdf",
    "calibrated.urdf",
    "calibrated.kinfw.json",
    "report.json",
    "errors.png",
    "scene.html",
)
#: Simulated measurement noise: position sigma per axis (mm), rotation angle sigma (deg).
#: The demo's true head is off the URDF by 5 mm / 1 deg per axis (sigma): its calibration
#: is checked against the bound for that known error (43 mm / 8.7 deg), not the default
#: 20 mm / 2 deg a URDF of a real robot is held to.
DEMO_BOUND = ChangeBound.for_known_error(5e-3, math.radians(1.0))
NOISE_MM = 0.5
NOISE_DEG = 0.5
#: Simulated pixel noise of ``pixels=True``, px per image coordinate.
PIXEL_SIGMA = 0.5
#: Stage 2 random configurations; with ``pixels=True`` also the held-out image ones.
N_STAGE2 = 30


@dataclass(frozen=True, slots=True)
class DemoResult:
    """What the demo computed and wrote.

    Attributes
    ----------
    report : CalibrationReport
        The calibration report (``report.json``), with the held-out errors against the
        noise-free true robot (``errors_vs_truth_held_out``,
        ``rms_vs_truth_held_out_by_stage``).
    n_stage1 : int
        One-joint-at-a-time configurations of stage 1.
    out : Path
        The output directory (:meth:`file`: the path of one of :data:`DEMO_FILES`).
    held_out_pixels : ReprojectionSection or None
        With ``pixels=True``: the reprojection error (px) of the calibration on the
        images of :data:`N_STAGE2` fresh configurations (per camera, per image, the
        worst named; also the report's ``reprojection_held_out``).
    """

    report: CalibrationReport
    n_stage1: int
    out: Path
    held_out_pixels: ReprojectionSection | None = None

    def file(self, name: str) -> Path:
        """Path of one of :data:`DEMO_FILES`."""
        if name not in DEMO_FILES:
            raise ValueError(f"{name!r}: not a demo file; expected one of {DEMO_FILES}")
        return self.out / name


def run_demo(
    out: str | Path,
    *,
    seed: int = 0,
    pixels: bool = False,
) -> DemoResult:
    """Simulate, calibrate and evaluate the IIS-head; write :data:`DEMO_FILES` into ``out``
    (created if missing; each file atomically).

    Parameters
    ----------
    out : path
        Output directory.
    seed : int
        Seed of the true robot's errors, the configurations and the noise.
    pixels : bool
        Stage 2 from images of a chessboard (module docstring) instead of target poses.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    progress.stage("simulating the IIS-head's measurements")
    nominal = load_robot(builtin_head_urdf())
    rng = np.random.default_rng(seed)
    truth_xml = perturb_robot(nominal, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0)
    truth = load_robot(truth_xml)
    plates, cameras = nominal.default_frames, nominal.default_cameras
    names = nominal.topology((*plates, *cameras)).joint_names
    lower, upper = nominal.joint_limits(names)
    noise = {"noise_m": NOISE_MM * 1e-3, "noise_rad": np.radians(NOISE_DEG)}
    # stage 1: plates seen by the stereo rig, one joint at a time; stage 2: the cameras
    # see a fixed target at random configurations.
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=9, fraction=0.8)
    views = _pixel_views_options(cameras) if pixels else None
    data, w_T_target, target = _training_data(
        truth, names, plates, cameras, qs1, lower, upper, rng, noise, views
    )
    q_test = random_configurations(lower, upper, 100, rng, fraction=0.8)
    held_out = _held_out(truth, q_test, names, plates, cameras, target, w_T_target, rng, noise)
    exact = _held_out(truth, q_test, names, plates, cameras, target, w_T_target, rng, {})
    held_out_pixels = None
    if pixels:
        held_out_pixels, _ = pixel_views(
            truth,
            names,
            lower,
            upper,
            N_STAGE2,
            rng,
            sigma_px=PIXEL_SIGMA,
            w_T_board=w_T_target,
            **views,
        )
    progress.stage(f"writing the simulated data into {out}")
    write_measurements(out / "data.json", data)
    write_measurements(out / "held_out.json", held_out)
    write_text_atomic(out / "true.urdf", truth_xml)
    fitted = calibrate_and_report(
        nominal,
        data,
        parameters="full",
        data_path=out / "data.json",
        held_out=held_out,
        change_bound=DEMO_BOUND,
    )
    report, result = fitted.write(out / "calibrated.urdf"), fitted.calibration
    calibrated = load_robot(out / "calibrated.urdf")
    report = _with_errors_vs_truth(report, nominal, result.stages, calibrated, exact)
    if held_out_pixels is not None:
        held_out_pixels = reprojection_section(calibrated, held_out_pixels, result.refined.unknowns)
        report = replace(report, reprojection_held_out=held_out_pixels)
    write_report(out / "report.json", report)
    plot_stage_errors(
        report.rms_vs_truth_held_out_by_stage,
        out / "errors.png",
        title="IIS-head demo: held-out error against the true robot",
    )
    progress.stage("the plot and the 3D scene")
    _write_scene(out, nominal, calibrated, data)
    return DemoResult(report, len(qs1), out, held_out_pixels)


def _pixel_views_options(cameras):
    """Keyword arguments of :func:`pixel_views` for ``cameras`` seeing the default board."""
    intrinsics = {c: default_intrinsics(c) for c in cameras}
    board = parse_board(DEFAULT_BOARD)
    return {"cameras": intrinsics, "board_p": board.points, "min_corners": board.count}


def _training_data(truth, names, plates, cameras, qs1, lower, upper, rng, noise, views):
    """Stage 1 (``plates`` at ``qs1``) and stage 2 (``cameras`` see a fixed target at
    random configurations, from images if ``views``) simulated on ``truth``.

    Returns the dataset, the target's pose ``w_T_target`` (4, 4) and its name.
    """
    if views is not None:
        stage1 = simulate_at(truth, qs1, names, frames=plates, rng=rng, **noise)
        stage2, w_T_target = pixel_views(
            truth, names, lower, upper, N_STAGE2, rng, sigma_px=PIXEL_SIGMA, **views
        )
        target = "board"
    else:  # (this order of the draws reproduces the README's numbers)
        qs2 = random_configurations(lower, upper, N_STAGE2, rng, fraction=0.8)
        w_T_target = default_target_pose(truth, qs2, names, cameras)
        stage1 = simulate_at(truth, qs1, names, frames=plates, rng=rng, **noise)
        stage2 = simulate_at(
            truth, qs2, names, cameras=cameras, rng=rng, w_T_target=w_T_target, **noise
        )
        target = "target"
    return concatenate_measurements(stage1, stage2), w_T_target, target


def _with_errors_vs_truth(report, nominal, stages, calibrated, exact):
    """``report`` with the held-out errors against the truth (``exact``, noise-free):
    before/after rows and the RMS of each calibration stage (``stages``: name, URDF)."""
    nominal_errors = errors_by_group(nominal, exact)
    truth_rms = [StageErrors.of("nominal", nominal_errors)]
    truth_rms += [
        StageErrors.of(name, errors_by_group(Robot(xml, name), exact)) for name, xml in stages
    ]
    return replace(
        report,
        errors_vs_truth_held_out=before_after_rows(
            nominal_errors, errors_by_group(calibrated, exact)
        ),
        rms_vs_truth_held_out_by_stage=tuple(truth_rms),
    )


def _write_scene(out, nominal, calibrated, data):
    """Write ``out/scene.html``: the nominal ghost, the calibrated robot and one sample."""
    from kinfw.view import OfflineWindow, scene, targets_from_sidecar, write_html

    # the drawn sample: the first with images (pixels), else the first
    drawn = next((int(g.sample[0]) for g in data.groups("pixels")), 0)
    write_html(
        scene(
            nominal,
            calibrated,
            data,
            sample=drawn,
            targets=targets_from_sidecar(out / "calibrated.kinfw.json"),
            residual_scale=30.0,
            window=OfflineWindow(),
        ),
        out / "scene.html",
    )


def _held_out(truth, qs, names, plates, cameras, target, w_T_target, rng, noise):
    """Held-out plate poses and ``camera_T_target`` of the fixed target (named
    ``target``) at ``qs``, with ``noise`` (``noise_m``, ``noise_rad``; none if empty)."""
    groups = [
        TargetObservations(
            camera=c,
            sample=np.arange(len(qs)),
            camera_T_target=np.tile(np.eye(4), (len(qs), 1, 1)),
            target=target,
        )
        for c in cameras
    ]
    return simulate_at(
        truth,
        qs,
        names,
        frames=plates,
        groups=groups,
        unknowns={BlockKey("target", target): w_T_target},
        rng=rng,
        **noise,
    )
