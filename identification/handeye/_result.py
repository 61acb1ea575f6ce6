"""The result of the hand-eye calibration ``A X = X B``: :class:`HandEyeResult`.

Returned by :func:`kinfw.identification.handeye.solve_axxb` (and re-exported there): the
transform ``hand_T_camera`` (the papers' ``X``), the target's pose, the covariance and
verdict of the maximum-likelihood fit, and the quality of the fit of the relative
motions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["HandEyeResult"]


@dataclass(frozen=True, slots=True)
class HandEyeResult:
    """Hand-eye transform and the quality of its fit.

    Attributes
    ----------
    hand_T_camera : ndarray, shape (4, 4)
        Pose of the camera (the eye) in the hand frame, in the input length unit: the
        unknown ``X`` of ``A X = X B``.
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
        The target's pose in the robot base, estimated with X (``Y`` of
        ``A[i] X B[i] = Y``), input length unit.
    covariance : ndarray, shape (6, 6)
        Covariance of X's error ``(dphi, dt)``: ``dphi`` the rotation vector of
        ``X_true = X exp(dphi)`` in the camera frame (rad^2), ``dt`` the translation error
        in the hand frame (input unit^2); from the maximum-likelihood fit with the noise
        scales estimated from the residuals.
    sigma_rotation_deg : ndarray, shape (3,)
        1-sigma rotation uncertainty of X per camera axis, degrees.
    sigma_translation : ndarray, shape (3,)
        1-sigma translation uncertainty of X per hand axis, input length unit.
    verdict : str
        ``"determined"``, ``"poorly determined (sigma ... deg, ...)"`` or
        ``"undetermined (<worst direction>)"``
        (:func:`kinfw.identification.handeye.uncertainty`).
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
    ``X`` is a read-only alias of ``hand_T_camera`` for readers of Tsai & Lenz and
    Shih et al., who call the hand-eye transform ``X``.
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
    verdict: str
    rejected: tuple[int, ...]
    noise_rotation_rad: float
    noise_translation: float
    iterations: int

    @property
    def X(self) -> NDArray[np.float64]:
        """Alias of :attr:`hand_T_camera`: the papers' ``X`` in ``A X = X B``."""
        return self.hand_T_camera

    @property
    def Y(self) -> NDArray[np.float64]:
        """Alias of :attr:`base_T_target`: ``A[i] X B[i] = Y``."""
        return self.base_T_target
