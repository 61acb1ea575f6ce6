"""The two-stage head experiment that the CRLB and robustness studies repeat.

Stage 1, the stereo rig measures both plates one joint at a time
(:func:`kinfw.simulation.one_joint_at_a_time`, ``per_joint`` values per joint);
stage 2, both cameras see a fixed target at ``stage2_views`` random configurations (the
experiment ``kinfw demo`` runs on the IIS-head). Every trial draws a new true head (the
nominal URDF with 5 mm / 1 deg errors, :func:`kinfw.simulation.perturb_robot`),
simulates the data with the noise of Shih et al.'s Fig. 10 (each position component
``N(0, sigma)``; the orientation turned about a uniformly random axis by an angle
``N(0, sigma_rad)``) and starts from the pipeline (closed form + hand-eye,
:func:`kinfw.identification.identify`); the studies then refine everything jointly
(:func:`kinfw.identification.refine`): :func:`crlb_study` against the Cramér-Rao bound
(:func:`~kinfw.verification.evaluation.cramer_rao`), :func:`robustness_study` with planted
outliers.

Noise. Per-component orientation noise is ``sigma_rad / sqrt(3)``: a rotation by
``N(0, sigma_rad)`` about a uniformly random axis has covariance ``sigma_rad^2 / 3 I``
(:class:`ExperimentSetup.noise` is the whitening ``refine`` is given). Those components
are not Gaussian, so the bound computed under a Gaussian likelihood is, strictly, the
covariance of the best *linear* unbiased estimator (Gauss-Markov), which least squares
reaches to first order for any noise with that covariance; the orientation residual is
``sin(theta) u`` rather than ``theta u``, a difference of order ``theta^3``.

Random numbers. Trial ``t`` draws everything (truth, stage-2 configurations, noise,
held-out configurations) from ``numpy.random.default_rng([seed, 7, t])``
(:func:`simulate_experiment`) and the robustness study's outliers from
``default_rng([seed, 8, t])``: trial ``t`` of the robustness study corrupts exactly the
data of trial ``t`` of the CRLB study, and a study's trials do not depend on how many
are run.

References
----------
S.-W. Shih et al., "Kinematic identification of an active binocular head", 1992 (the
experiment, Fig. 10).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import identify
from kinfw.identification.problem import NoiseModel
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.model import CPCModel, Robot, load_robot
from kinfw.simulation import (
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
    simulate_at,
)
from kinfw.verification.evaluation import check_count
from kinfw.verification.studies._common import FieldsJSON

_EXPERIMENT_TAG = 7  # seeds (module docstring)


@dataclass(frozen=True, slots=True)
class ExperimentSetup(FieldsJSON):
    """The two-stage head experiment every trial of a study repeats.

    Attributes
    ----------
    urdf : str
        Source of the nominal URDF.
    plates, cameras : tuple of str
        Frames the stereo rig measures (stage 1) and camera frames that see the target
        (stage 2).
    joint_names : tuple of str
        Joints carrying those frames: column order of every configuration.
    error_mm, error_deg : float
        Geometric errors of the true robot: each origin translation component, mm; each
        origin rotation angle and axis tilt, degrees.
    sigma_mm : float
        Measurement noise per position component, mm.
    sigma_deg : float
        Measurement noise: rotation angle about a random axis, degrees.
    per_joint : int
        Stage-1 values per joint.
    stage2_views : int
        Stage-2 random configurations.
    n_test : int
        Held-out configurations per trial.
    fraction : float
        Centred part of each joint range used for every configuration.
    seed : int
    """

    urdf: str
    plates: tuple[str, ...]
    cameras: tuple[str, ...]
    joint_names: tuple[str, ...]
    error_mm: float
    error_deg: float
    sigma_mm: float
    sigma_deg: float
    per_joint: int
    stage2_views: int
    n_test: int
    fraction: float
    seed: int

    @property
    def frames(self) -> tuple[str, ...]:
        """Every end frame: plates, then cameras."""
        return (*self.plates, *self.cameras)

    @property
    def noise(self) -> NoiseModel:
        """The true noise as ``refine`` whitens it: per position component (m) and per
        orientation component, ``radians(sigma_deg) / sqrt(3)`` (rad)."""
        return NoiseModel(1e-3 * self.sigma_mm, float(np.radians(self.sigma_deg) / np.sqrt(3.0)))

    def describe(self) -> str:
        """One line for headers and titles."""
        return (
            f"truth = nominal + N(0, {self.error_mm:g} mm) origins, N(0, "
            f"{self.error_deg:g} deg) rotations and axes; stage 1: {self.per_joint} "
            f"values per joint, {' + '.join(self.plates)}; stage 2: {self.stage2_views} "
            f"random views of a fixed target by {' + '.join(self.cameras)}; noise "
            f"{self.sigma_mm:g} mm per axis, {self.sigma_deg:g} deg about a random axis; "
            f"{self.n_test} held-out configurations"
        )


def check_positive(value: float, name: str) -> float:
    """``value`` as a float; a ``ValueError`` naming ``name`` unless finite and > 0."""
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name}: expected a finite value > 0, got {value}")
    return value


def setup_experiment(
    nominal: Robot,
    *,
    sigma_mm: float,
    sigma_deg: float,
    per_joint: int,
    stage2_views: int,
    n_test: int,
    seed: int,
    error_mm: float = 5.0,
    error_deg: float = 1.0,
    fraction: float = 0.8,
) -> ExperimentSetup:
    """The checked set-up of a study on ``nominal`` (plates and cameras from its
    ``<kinfw>`` hint); the arguments are :class:`ExperimentSetup`'s fields."""
    plates, cameras = nominal.default_frames, nominal.default_cameras
    if not plates or not cameras:
        raise ValueError(
            f"{nominal.source}: the study needs a URDF with a "
            '<kinfw frames="..." cameras="..."/> hint (plates and cameras)'
        )
    if not 0.0 < float(fraction) <= 1.0:
        raise ValueError(f"fraction: expected 0 < fraction <= 1, got {fraction}")
    return ExperimentSetup(
        urdf=nominal.source,
        plates=plates,
        cameras=cameras,
        joint_names=nominal.topology((*plates, *cameras)).joint_names,
        error_mm=check_positive(error_mm, "error_mm"),
        error_deg=check_positive(error_deg, "error_deg"),
        sigma_mm=check_positive(sigma_mm, "sigma_mm"),
        sigma_deg=check_positive(sigma_deg, "sigma_deg"),
        per_joint=check_count(per_joint, "per_joint", 2),
        stage2_views=check_count(stage2_views, "stage2_views", 3),
        n_test=check_count(n_test, "n_test", 1),
        fraction=float(fraction),
        seed=int(seed),
    )


@dataclass(frozen=True, slots=True)
class Experiment:
    """One trial's truth, data and held-out configurations (``setup.joint_names`` order)."""

    truth: Robot
    data: Measurements
    root_T_targets: dict[str, NDArray[np.float64]]
    test_qs: NDArray[np.float64]


def simulate_experiment(nominal: Robot, setup: ExperimentSetup, trial: int) -> Experiment:
    """A new true head, its two-stage data and held-out configurations (module docstring)."""
    rng = np.random.default_rng([setup.seed, _EXPERIMENT_TAG, trial])
    truth = load_robot(
        perturb_robot(
            nominal,
            rng,
            origin_mm=setup.error_mm,
            origin_deg=setup.error_deg,
            axis_deg=setup.error_deg,
        )
    )
    names = setup.joint_names
    lower, upper = nominal.joint_limits(names)
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=setup.per_joint, fraction=setup.fraction)
    qs2 = random_configurations(lower, upper, setup.stage2_views, rng, fraction=setup.fraction)
    w_T_target = default_target_pose(truth, qs2, names, setup.cameras)
    noise = {"noise_m": 1e-3 * setup.sigma_mm, "noise_rad": float(np.radians(setup.sigma_deg))}
    data = concatenate_measurements(
        simulate_at(truth, qs1, names, frames=setup.plates, rng=rng, **noise),
        simulate_at(
            truth, qs2, names, cameras=setup.cameras, rng=rng, w_T_target=w_T_target, **noise
        ),
    )
    test_qs = random_configurations(lower, upper, setup.n_test, rng, fraction=setup.fraction)
    targets = {name: w_T_target for name in dict.fromkeys(g.target for g in data.targets)}
    return Experiment(truth, data, targets, test_qs)


def pipeline_start(
    nominal: Robot, data: Measurements
) -> tuple[Robot, dict[str, NDArray[np.float64]]]:
    """Closed form + hand-eye: the start URDF and target poses ``refine`` begins from."""
    cal = identify(nominal, data, method="closed-form")
    targets = {} if cal.cameras is None else dict(cal.cameras.root_T_targets)
    return Robot(cal.urdf_xml, nominal.source), targets


def in_model_order(
    qs: NDArray[np.float64], names: Sequence[str], model: CPCModel
) -> NDArray[np.float64]:
    """Columns of ``qs`` (in ``names`` order) in the model's joint order."""
    return qs[:, [list(names).index(j) for j in model.topology.joint_names]]


def position_ms(
    model: CPCModel,
    truth: CPCModel,
    qs: NDArray[np.float64],
    names: Sequence[str],
    frames: Sequence[str],
) -> NDArray[np.float64]:
    """Mean square position error of each frame over ``qs`` (``names`` order), (E,), m^2."""
    q_model, q_truth = in_model_order(qs, names, model), in_model_order(qs, names, truth)
    return np.array(
        [
            np.mean(
                np.sum(
                    (
                        model.frame_poses(q_model, f)[:, :3, 3]
                        - truth.frame_poses(q_truth, f)[:, :3, 3]
                    )
                    ** 2,
                    axis=1,
                )
            )
            for f in frames
        ]
    )


def rms_over(values_mm: NDArray[np.float64], axis: int | tuple[int, ...]) -> Any:
    """RMS of RMS values (equal counts): sqrt of the mean of their squares."""
    return np.sqrt(np.mean(np.square(values_mm), axis=axis))
