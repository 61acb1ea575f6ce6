"""The results of the hand-eye solvers: :class:`HandEyeResult` of
:func:`kinfw.identification.handeye.solve_axxb` and :class:`AXYBResult` of
:func:`kinfw.identification.handeye.solve_axyb`.

Both name their transforms by the frames of the package's one convention (eye-in-hand;
:mod:`kinfw.identification.handeye`): ``hand_T_camera``, the pose of the camera in the
hand, and ``base_T_target``, the pose of the target in the robot's base, with
``base_T_target = base_T_hand[i] @ hand_T_camera @ camera_T_target[i]`` for every pose
``i``. The papers' ``X`` and ``Y`` are read-only aliases; they differ between the papers
(Tsai & Lenz's ``X`` is ``hand_T_camera``, Hirsh et al.'s is ``camera_T_hand``), which is
why the code reads the frame names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import inverse_transform
from kinfw.identification.handeye._uncertainty import Verdict


@dataclass(frozen=True, slots=True)
class HandEyeResult:
    """Hand-eye transform and the quality of its fit (``A X = X B``, Tsai & Lenz).

    Attributes
    ----------
    hand_T_camera : ndarray, shape (4, 4)
        Pose of the camera (the eye) in the hand frame, in the input length unit.
    n_pairs : int
        Relative motions (unordered pose pairs) used.
    rms_rotation_rad : float
        RMS over the motions used of the angle of ``(A_ij X)^-1 X B_ij``, radians.
    rms_translation : float
        RMS over the motions used (both orders) of the translation residual of
        ``A_ij X = X B_ij``, in the input length unit.
    rotation_condition : float
        Smallest over largest singular value of Tsai's stacked rotation system as finally
        solved: 1 is ideal, towards 0 the rotation of X is poorly determined. It reflects
        the spread of the motion axes, and also drops as X's own rotation grows towards
        150 deg, beyond which the system is re-solved about the first estimate.
    axis_spread_rad : float
        Largest angle between the rotation axes (as lines) of the motions used, radians:
        0 means all about one axis.
    base_T_target : ndarray, shape (4, 4)
        The target's pose in the robot base, estimated with ``hand_T_camera``, input
        length unit.
    covariance : ndarray, shape (6, 6)
        Covariance of ``hand_T_camera``'s error ``(dphi, dt)``: ``dphi`` the rotation
        vector of ``X_true = X exp(dphi)`` in the camera frame (rad^2), ``dt`` the
        translation error in the hand frame (input unit^2); from the maximum-likelihood
        fit with the noise scales estimated from the residuals.
    sigma_rotation_deg : ndarray, shape (3,)
        1-sigma rotation uncertainty of ``hand_T_camera`` per camera axis, degrees.
    sigma_translation : ndarray, shape (3,)
        1-sigma translation uncertainty of ``hand_T_camera`` per hand axis, input length
        unit.
    verdict : Verdict
        How well the poses determine ``hand_T_camera``
        (:func:`kinfw.identification.handeye.uncertainty`).
    verdict_message : str
        The verdict in words, for people: ``"determined"``, ``"poorly determined (sigma
        ... deg, ...)"`` or ``"undetermined (<worst direction>)"``.
    rejected : tuple of int
        Indices of the poses rejected as outliers (squared whitened residual above
        :func:`kinfw.identification.handeye.rejection_threshold`: chi^2_6's quantile at
        ``1 - 0.01 / n``, at least its 99.9 % quantile).
    noise_rotation_rad, noise_translation : float
        The camera pose's noise scales per axis estimated from the residuals (radians,
        input unit).
    iterations : int
        Levenberg-Marquardt steps of the maximum-likelihood refinement.

    Notes
    -----
    Read-only aliases for readers of Tsai & Lenz and Shih et al.: ``X`` is
    ``hand_T_camera`` (``A X = X B`` with ``A`` the hand's and ``B`` the camera's
    motions), ``Y`` is ``base_T_target`` (``A[i] X B[i] = Y`` for the absolute poses).
    """

    hand_T_camera: NDArray[np.float64]
    n_pairs: int
    rms_rotation_rad: float
    rms_translation: float
    rotation_condition: float
    axis_spread_rad: float
    base_T_target: NDArray[np.float64]
    covariance: NDArray[np.float64]
    sigma_rotation_deg: NDArray[np.float64]
    sigma_translation: NDArray[np.float64]
    verdict: Verdict
    verdict_message: str
    rejected: tuple[int, ...]
    noise_rotation_rad: float
    noise_translation: float
    iterations: int

    @property
    def X(self) -> NDArray[np.float64]:
        """Tsai & Lenz's ``X`` in ``A X = X B``: :attr:`hand_T_camera` itself."""
        return self.hand_T_camera

    @property
    def Y(self) -> NDArray[np.float64]:
        """``Y`` of ``A[i] X B[i] = Y``: :attr:`base_T_target` itself."""
        return self.base_T_target


@dataclass(frozen=True, slots=True)
class AXYBResult:
    """Estimate of ``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target``
    (Hirsh et al.'s ``A[i] ≈ X @ B[i] @ Y``) and its quality.

    Attributes
    ----------
    camera_T_hand : ndarray, shape (4, 4)
        Pose of the hand (end effector) in the camera frame, input length unit: the
        paper's hand-eye ``c_T_e``, the inverse of :attr:`hand_T_camera`.
    base_T_target : ndarray, shape (4, 4)
        Pose of the target (the paper's world) in the robot's base frame, input length
        unit: the paper's base-world ``b_T_w``.
    iterations : int
        Iterations of the paper's alternation, rotation plus translation phase (restarts
        included; the refinement's steps are not counted).
    converged : bool
        Whether the final stage met the tolerance: the paper's iterations for
        ``refine=False``, the maximum-likelihood refinement for ``refine=True``.
    restarts : int
        Random restarts after a stall of the rotation iteration (the paper's 180 degrees).
    rms_rotation_rad : float
        RMS over poses of the angle between ``X B[i] Y`` and ``A[i]``, radians.
    rms_translation : float
        RMS over poses of the distance between the translations of ``X B[i] Y`` and
        ``A[i]``, input length unit.
    camera_T_hand_history, base_T_target_history : ndarray, shape (iterations, 4, 4), or None
        With ``record_history=True``: the estimates after each iteration of the paper's
        alternation (before any refinement). During the rotation phase the translations
        are those of the translation start: ``base_T_target``'s starting translation,
        and for ``camera_T_hand`` the average of eqs. (4)-(6) given it and the current
        rotation.
    covariance : ndarray, shape (12, 12)
        Covariance of the errors ``(dphi_X, dt_X, dphi_Y, dt_Y)`` of
        ``X = camera_T_hand`` and ``Y = base_T_target``: rotations as
        ``X_true = X exp(dphi_X)`` (radians, in X's and Y's child frames: hand and
        target), translations in the parent frames (camera and base), input unit; from
        the maximum-likelihood fit with noise scales estimated from the residuals
        (:func:`kinfw.identification.handeye.fit_absolute`; for ``refine=False``
        evaluated at the paper's estimate).
    sigma_rotation_deg, sigma_translation : ndarray, shape (2, 3)
        1-sigma per axis of ``camera_T_hand`` (row 0) and ``base_T_target`` (row 1),
        degrees and input unit, in the frames of ``covariance``.
    verdict : Verdict
        The worse of the verdicts on ``camera_T_hand`` and ``base_T_target``.
    verdict_message : str
        That verdict in words, for people, naming the transform: ``"determined"`` or
        e.g. ``"poorly determined (camera_T_hand: sigma ...)"``.
    rejected : tuple of int
        Poses rejected as outliers (squared whitened residual above
        :func:`kinfw.identification.handeye.rejection_threshold`: chi^2_6's quantile at
        ``1 - 0.01 / n``, at least its 99.9 % quantile); empty for ``refine=False``.
    noise_rotation_rad, noise_translation : float
        The camera pose's noise scales per axis estimated from the residuals.

    Notes
    -----
    :attr:`hand_T_camera` is the convention's name of the camera mount, the same
    quantity as :attr:`HandEyeResult.hand_T_camera`. For readers of Hirsh et al., the
    paper's names are read-only aliases: ``X`` is ``camera_T_hand``, ``Y`` is
    ``base_T_target``, ``history_X`` and ``history_Y`` are ``camera_T_hand_history`` and
    ``base_T_target_history``.
    """

    camera_T_hand: NDArray[np.float64]
    base_T_target: NDArray[np.float64]
    iterations: int
    converged: bool
    restarts: int
    rms_rotation_rad: float
    rms_translation: float
    camera_T_hand_history: NDArray[np.float64] | None
    base_T_target_history: NDArray[np.float64] | None
    covariance: NDArray[np.float64]
    sigma_rotation_deg: NDArray[np.float64]
    sigma_translation: NDArray[np.float64]
    verdict: Verdict
    verdict_message: str
    rejected: tuple[int, ...]
    noise_rotation_rad: float
    noise_translation: float

    @property
    def hand_T_camera(self) -> NDArray[np.float64]:
        """Pose of the camera in the hand frame, (4, 4), input length unit: the inverse
        of :attr:`camera_T_hand`."""
        return inverse_transform(self.camera_T_hand)

    @property
    def X(self) -> NDArray[np.float64]:
        """Hirsh et al.'s left unknown ``X`` of ``A = X B Y``: :attr:`camera_T_hand`."""
        return self.camera_T_hand

    @property
    def Y(self) -> NDArray[np.float64]:
        """Hirsh et al.'s right unknown ``Y`` of ``A = X B Y``: :attr:`base_T_target`."""
        return self.base_T_target

    @property
    def history_X(self) -> NDArray[np.float64] | None:
        """:attr:`camera_T_hand_history` under the paper's name."""
        return self.camera_T_hand_history

    @property
    def history_Y(self) -> NDArray[np.float64] | None:
        """:attr:`base_T_target_history` under the paper's name."""
        return self.base_T_target_history
