"""Hand-eye calibration ``A X = X B``: Tsai & Lenz (1989), as in stage 2 of Shih et al.,
then maximum likelihood on SE(3) (:mod:`kinfw.identification.handeye`).

The problem (Shih et al. 1992, section 5, eqs. 68-71)
------------------------------------------------------
A camera (the *eye*) is rigidly mounted on the robot's end effector (the *hand*) and
looks at a target fixed in the world (the package's convention,
:mod:`kinfw.identification.handeye`). At pose ``i`` the robot's forward kinematics gives
``A[i] = base_T_hand`` and the camera's extrinsic calibration gives
``B[i] = camera_T_target``. The target does not move, so (eqs. 68-69)::

    base_T_target = A[i] @ X @ B[i]          for every i,   X = hand_T_camera.

:func:`solve_axxb` takes the poses by these frame names and names the result by them,
:attr:`HandEyeResult.hand_T_camera`; ``X`` is kept as an alias.

For two poses ``i, j`` this becomes (eqs. 70-71; the paper's ``k, j`` are our ``i, j``)::

    A_ij X = X B_ij,   A_ij = inv(A[j]) @ A[i],   B_ij = B[j] @ inv(B[i]).

``A_ij`` is the hand's motion expressed in the hand frame, ``B_ij`` the same motion seen
in the camera frame. Both are conjugate, so their rotation angles agree; their axes are
related by ``a = X_R b``.

The start uses every pair of poses (up to ``ALL_PAIRS_UP_TO`` poses; beyond, a fixed
number of pairs per pose, :func:`motion_pairs`), in both orders (``A_ji = inv(A_ij)``);
pairs whose hand rotation is below ``min_angle_rad`` carry no information on the
rotation and are left out. The answer is the maximum-likelihood fit of the absolute
poses, which does not depend on the order of the samples.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    average_transform,
    inverse_transform,
    rotation_angle,
    rotation_vector_from_matrix,
    transform_from_rotation_translation,
)
from kinfw.identification.handeye._checks import check_pose_pairs, poses_by_keyword
from kinfw.identification.handeye._ml import PoseFit, fit_absolute
from kinfw.identification.handeye._result import HandEyeResult
from kinfw.identification.handeye._starts import candidate_starts
from kinfw.identification.handeye._tsai import PARALLEL_AXES_RAD, largest_line_angle, tsai_rotation
from kinfw.identification.handeye._uncertainty import (
    Uncertainty,
    Verdict,
    inverse_covariance_map,
    uncertainty,
)

log = logging.getLogger(__name__)

#: Below this rotation condition (smallest / largest singular value) a warning is logged.
POOR_CONDITION = 0.05

#: An RMS difference between the rotation angles of A_ij and B_ij, or an RMS rotation
#: residual of A_ij X = X B_ij, beyond this means the poses do not describe one rigid
#: hand-eye setup.
INCONSISTENT_RAD = np.radians(5.0)
#: Up to this many poses every pair gives a relative motion; beyond, ``MOTION_STRIDES``
#: pairs per pose (:func:`motion_pairs`), so the start costs O(n), not O(n^2).
ALL_PAIRS_UP_TO = 25
MOTION_STRIDES = 6


class HandEyeError(ValueError):
    """The poses cannot determine the hand-eye transform; the message says why."""


@poses_by_keyword("base_T_hands", "camera_T_targets")
def solve_axxb(
    *,
    base_T_hands: ArrayLike,
    camera_T_targets: ArrayLike,
    min_angle_rad: float = np.radians(2.0),
) -> HandEyeResult:
    """Hand-eye transform ``hand_T_camera`` (Tsai & Lenz's ``X``) from absolute poses:
    maximum likelihood started from Tsai & Lenz.

    The package's convention (eye-in-hand, :mod:`kinfw.identification.handeye`): a camera
    rigid on the robot's hand looks at a target fixed in the world, so that
    ``base_T_hands[i] @ hand_T_camera @ camera_T_targets[i]`` is the same
    ``base_T_target`` for every ``i``. Every argument is keyword-only.

    Parameters
    ----------
    base_T_hands : array_like, shape (n, 4, 4)
        Pose of the hand in the robot's base at each pose: the forward kinematics
        (OpenCV's ``gripper2base``; the paper's ``A[i]``). Any length unit, the same as
        ``camera_T_targets``'.
    camera_T_targets : array_like, shape (n, 4, 4)
        Pose of the target in the camera at each pose: the camera's extrinsics (OpenCV's
        ``target2cam``; the paper's ``B[i]``).
    min_angle_rad : float
        Relative motions whose hand rotation is smaller than this are not used.

    Returns
    -------
    HandEyeResult
        ``hand_T_camera`` (alias ``X``) and ``base_T_target`` (alias ``Y``) in the input
        length unit, the covariance and verdict, the rejected poses, and the fit's
        quality.

    Raises
    ------
    HandEyeError
        Fewer than 3 poses, shapes that differ, a matrix that is not a rigid transform
        (names the argument and index), no motion with a rotation of at least
        ``min_angle_rad``, all motions about one axis (then the rotation of X about it and
        its translation along it are not determined), or motions of the hand and the
        camera that no single X relates even after outlying poses are rejected
        (mispaired samples, one of the batches inverted, eye-to-hand data given as
        eye-in-hand, a camera that is not rigid on the hand). Poorly determined X (small
        motions) is not an error: see ``verdict`` and ``sigma_rotation_deg``.
    TypeError
        A positional argument (the message names the keywords): the meaning of the
        batches is given by their names only.

    Warnings
    --------
    Two mistakes cannot be detected, because the data stay consistent: the loop
    ``base -> hand -> camera -> target -> base`` is merely walked the other way. With the
    two batches swapped the answer is ``target_T_base``; with both inverted it is
    ``base_T_target``.

    Eye-to-hand (a camera fixed in the world, the target on the hand) is the same
    equation with base and hand exchanged: pass ``base_T_hands=inverse(base_T_hand)``
    (the hand's forward kinematics inverted); ``hand_T_camera`` is then ``base_T_camera``
    and ``base_T_target`` is ``hand_T_target``.

    Notes
    -----
    Pairs ``i < j`` (:func:`motion_pairs`: all of them up to ``ALL_PAIRS_UP_TO`` poses)
    give ``A_ij X = X B_ij`` (Shih et al. eqs. 70-71); both orders of each pair are
    stacked (the second is the inverse motion), which leaves the rotation system
    unchanged and, with all pairs, makes the translation system exactly invariant to
    sample order.

    Rotation (Tsai & Lenz 1989, eqs. 12 and 14): with the modified Rodrigues
    vector ``P = 2 sin(theta/2) u`` of a rotation by ``theta`` about the unit axis ``u``
    (twice the vector part of its quaternion with non-negative scalar part), every motion
    gives ``skew(P_A + P_B) P'_X = P_B - P_A`` with ``P'_X = tan(theta_X/2) u_X``, solved by
    linear least squares over all motions. Tsai's ``P_X = 2 P'_X / sqrt(1 + |P'_X|^2)`` is
    the rotation by ``theta_X = 2 atan(|P'_X|)`` about ``P'_X``, computed in that form
    (accurate up to theta_X = pi).

    ``P'_X`` is infinite when X turns by pi; near there the system is ill-conditioned,
    and exactly there every ``P_A + P_B`` is parallel to X's axis, so the stacked matrix
    loses rank with X's axis as its null vector. When the first estimate ``R0`` turns by
    more than ``PRE_ROTATE_ABOVE_RAD`` (150 deg), or the system has lost rank (then
    ``R0`` is the half turn about the null vector), the rotation is re-solved for
    ``X_R' = X_R R0^T``, which is close to the identity::

        A_R X_R = X_R B_R,  X_R = X_R' R0   =>   A_R X_R' = X_R' (R0 B_R R0^T),

    i.e. Tsai's equations with ``P_B`` replaced by ``R0 P_B`` (conjugation rotates the
    axis and keeps the angle); then ``X_R = X_R' R0``.

    A motion within ``HALF_TURN_BAND_RAD`` of a half turn has a quaternion sign that
    rounding or noise can flip, which breaks ``P_A = X_R P_B``: such motions are left
    out of the first estimate (when the others determine it) and their ``P_B`` takes the
    sign that agrees with it.

    Translation (Tsai & Lenz 1989, eq. 15): ``(A_R - I) t_X = X_R t_B - t_A``, stacked
    over all motions, linear least squares. It is linear in the lengths, so the result
    scales with the input unit, and the rotation does not use lengths at all.

    Tsai & Lenz's X is only a start (its rotation ignores what the translations say,
    which costs most at small motions). The answer is the maximum-likelihood X and
    ``base_T_target`` of the absolute poses ``B[i] = X^-1 A[i]^-1 base_T_target`` with
    the camera's pose noisy (rotation and translation, weighted by noise scales
    estimated from the residuals, so the answer does not depend on the length unit):
    :func:`kinfw.identification.handeye.fit_absolute`, started from the quaternion closed
    form (no singularity at a half turn), robust to outlying poses (Huber, then
    rejection beyond :func:`kinfw.identification.handeye.rejection_threshold`, named in
    ``rejected``; a consensus start of minimal subsets when a pose stays off among few);
    when that fit is not clean -- poses rejected among fewer than 30, not converged, or
    a verdict other than "determined" -- Tsai & Lenz's, Park's, Andreff's and
    Daniilidis' closed forms (:func:`kinfw.identification.handeye.candidate_starts`)
    start fits too and the best is kept. Its covariance gives ``sigma_rotation_deg``,
    ``sigma_translation`` and ``verdict``.
    Measured (1 deg + 2 mm on the camera pose, 10 views, 300 trials, motions <= 15 deg):
    X's rotation error median 0.22 deg, p90 0.39 deg (Tsai & Lenz alone: 2.7 / 4.6 deg);
    the errors whitened by the reported covariance have mean squared norm 6.5 (6 for an
    exact covariance).

    References
    ----------
    R. Y. Tsai and R. K. Lenz, "A new technique for fully autonomous and efficient 3D
    robotics hand/eye calibration", IEEE Trans. Robotics and Automation 5(3), 345-358,
    1989 (equation numbers as OpenCV's implementation cites them).
    S.-W. Shih, J.-S. Jin, K.-H. Wei and Y.-P. Hung, "Kinematic Identification of an Active
    Binocular System Using Stereo Vision", TR-92-007, Academia Sinica, 1992, section 5,
    eqs. (68)-(71).
    """
    base_T_hands, camera_T_targets = check_pose_pairs(
        base_T_hands,
        camera_T_targets,
        error=HandEyeError,
        names=("base_T_hands", "camera_T_targets"),
    )
    if not 0.0 <= min_angle_rad < np.pi:
        raise HandEyeError(f"min_angle_rad must be in [0, pi), got {min_angle_rad!r}")
    motions = _informative_motions(base_T_hands, camera_T_targets, min_angle_rad)
    hand_R_camera, singular_values = tsai_rotation(motions.rotvecs_A, motions.rotvecs_B)
    length = float(np.sqrt(np.mean(np.sum(camera_T_targets[:, :3, 3] ** 2, axis=1))))

    def fallback_starts() -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Park, Andreff and Daniilidis as ``(camera_T_hand, base_T_target)``."""
        found = candidate_starts(base_T_hands, camera_T_targets, problem="axxb")
        return [(inverse_transform(X), Y) for X, Y in found.values()]

    # Maximum likelihood on the absolute poses, camera_T_target[i] = camera_T_hand @
    # hand_T_base[i] @ base_T_target with the noise in the camera's pose; when that fit
    # is not clean, the other closed forms start it too.
    fit = fit_absolute(
        camera_T_targets,
        inverse_transform(base_T_hands),
        [lambda: _tsai_start(motions, hand_R_camera, base_T_hands, camera_T_targets)],
        fallback_starts=fallback_starts,
        accept=lambda f: _x_uncertainty(f, length)[1].verdict is Verdict.DETERMINED,
    )
    hand_T_camera = inverse_transform(fit.camera_T_hand)
    covariance, unc = _x_uncertainty(fit, length)
    keep, rms_rotation, rms_translation = _motion_residuals(motions, fit.inliers, hand_T_camera)
    condition = float(singular_values[-1] / singular_values[0])
    if condition < POOR_CONDITION:
        log.warning(
            "solve_axxb: the motions turn mostly about one axis (rotation condition "
            "%.3g); X's rotation about it and its translation along it are poorly "
            "determined: add motions about other axes",
            condition,
        )
    if fit.rejected:
        log.info("solve_axxb: poses %s rejected as outliers", list(fit.rejected))
    return HandEyeResult(
        hand_T_camera=hand_T_camera,
        n_pairs=int(np.count_nonzero(keep)),
        rms_rotation_rad=rms_rotation,
        rms_translation=rms_translation,
        rotation_condition=condition,
        axis_spread_rad=float(motions.spread),
        base_T_target=fit.base_T_target,
        covariance=covariance,
        sigma_rotation_deg=unc.sigma_rotation_deg,
        sigma_translation=unc.sigma_translation,
        verdict=unc.verdict,
        verdict_message=unc.message,
        rejected=fit.rejected,
        noise_rotation_rad=fit.sigma_rotation_rad,
        noise_translation=fit.sigma_translation,
        iterations=fit.iterations,
    )


@dataclass(frozen=True, slots=True)
class _Motions:
    """The informative relative motions ``A_ij X = X B_ij`` of pose pairs ``i < j``
    (Shih et al. eq. 71), those whose hand rotation is at least ``min_angle_rad``.

    Attributes
    ----------
    i, j : ndarray of intp, shape (m,)
        The poses of each pair.
    A_ijs : ndarray, shape (m, 4, 4)
        ``inv(base_T_hands[j]) @ base_T_hands[i]``: the hand's motion in the hand frame.
    B_ijs : ndarray, shape (m, 4, 4)
        ``camera_T_targets[j] @ inv(camera_T_targets[i])``: the same motion in the camera
        frame.
    rotvecs_A, rotvecs_B : ndarray, shape (m, 3)
        Their rotation vectors, radians.
    spread : float
        Largest angle between the rotation axes of the ``A_ijs``, radians.
    """

    i: NDArray[np.intp]
    j: NDArray[np.intp]
    A_ijs: NDArray[np.float64]
    B_ijs: NDArray[np.float64]
    rotvecs_A: NDArray[np.float64]
    rotvecs_B: NDArray[np.float64]
    spread: float


def _informative_motions(
    base_T_hands: NDArray[np.float64],
    camera_T_targets: NDArray[np.float64],
    min_angle_rad: float,
) -> _Motions:
    """The relative motions of :func:`motion_pairs` that turn the hand by at least
    ``min_angle_rad``, checked: there is one, the hand's and the camera's rotation angles
    agree (:func:`_check_angles_agree`), and the axes are not all parallel (else
    :class:`HandEyeError`)."""
    i, j = motion_pairs(len(base_T_hands))
    A_ijs = inverse_transform(base_T_hands[j]) @ base_T_hands[i]
    B_ijs = camera_T_targets[j] @ inverse_transform(camera_T_targets[i])
    angles_A = rotation_angle(A_ijs[:, :3, :3])
    angles_B = rotation_angle(B_ijs[:, :3, :3])

    used = angles_A >= min_angle_rad
    if not np.any(used):
        raise HandEyeError(
            f"no informative motion: every relative rotation of the hand is below "
            f"min_angle_rad = {np.degrees(min_angle_rad):.3g} deg (largest "
            f"{np.degrees(angles_A.max()):.3g} deg over {len(angles_A)} pose pairs); "
            f"rotate the hand between poses, about at least two different axes"
        )
    _check_angles_agree(angles_A, angles_B, i, j)

    i, j = i[used], j[used]
    A_ijs, B_ijs = A_ijs[used], B_ijs[used]
    rotvecs_A = rotation_vector_from_matrix(A_ijs[:, :3, :3])
    rotvecs_B = rotation_vector_from_matrix(B_ijs[:, :3, :3])
    axes_A = rotvecs_A / angles_A[used, None]
    spread = largest_line_angle(axes_A)
    if spread < PARALLEL_AXES_RAD:
        axis = np.linalg.eigh(np.einsum("ki,kj->ij", axes_A, axes_A))[1][:, -1]
        raise HandEyeError(
            f"all relative rotations are about one axis ({np.array2string(axis, precision=4)} "
            f"in the hand frame, spread {np.degrees(spread):.3g} deg < "
            f"{np.degrees(PARALLEL_AXES_RAD):.3g} deg over {len(axes_A)} motions); the rotation "
            f"of X about it and the translation of X along it are not determined: add motions "
            f"about another axis"
        )
    return _Motions(i, j, A_ijs, B_ijs, rotvecs_A, rotvecs_B, spread)


def _tsai_start(
    motions: _Motions,
    hand_R_camera: NDArray[np.float64],
    base_T_hands: NDArray[np.float64],
    camera_T_targets: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tsai & Lenz's X with rotation ``hand_R_camera`` (translation by eq. 15 over both
    orders of every pair), as ``(camera_T_hand, base_T_target)``."""
    A2 = np.concatenate([motions.A_ijs, inverse_transform(motions.A_ijs)])
    B2 = np.concatenate([motions.B_ijs, inverse_transform(motions.B_ijs)])
    lhs = (A2[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,kj->ki", hand_R_camera, B2[:, :3, 3]) - A2[:, :3, 3]).reshape(-1)
    tsai = transform_from_rotation_translation(
        hand_R_camera, np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    )
    return inverse_transform(tsai), average_transform(base_T_hands @ tsai @ camera_T_targets)


def _x_uncertainty(fit: PoseFit, length: float) -> tuple[NDArray[np.float64], Uncertainty]:
    """hand_T_camera's covariance (from that of its inverse, camera_T_hand) and its
    verdict; ``length`` is the RMS camera-target distance."""
    G = inverse_covariance_map(fit.camera_T_hand)
    covariance = G @ fit.covariance[:6, :6] @ G.T
    return covariance, uncertainty(covariance, length, frame="the camera frame")


def _motion_residuals(
    motions: _Motions, inliers: NDArray[np.bool_], hand_T_camera: NDArray[np.float64]
) -> tuple[NDArray[np.bool_], float, float]:
    """Residuals of ``A_ij X = X B_ij`` over the motions between poses kept (``inliers``;
    all motions when none is), both orders of each: the motions used, the RMS rotation
    residual (radians) and the RMS translation residual (input unit).

    Raises :class:`HandEyeError`, naming the worst pair, when the RMS rotation residual
    exceeds ``INCONSISTENT_RAD``.
    """
    i, j = motions.i, motions.j
    keep = inliers[i] & inliers[j]
    if not np.any(keep):
        keep = np.ones_like(keep)
    A_k, B_k = motions.A_ijs[keep], motions.B_ijs[keep]
    A_k = np.concatenate([A_k, inverse_transform(A_k)])
    B_k = np.concatenate([B_k, inverse_transform(B_k)])
    left = A_k @ hand_T_camera
    right = hand_T_camera @ B_k
    rot_res = rotation_angle(np.swapaxes(left[:, :3, :3], 1, 2) @ right[:, :3, :3])
    trans_res = np.linalg.norm(left[:, :3, 3] - right[:, :3, 3], axis=1)
    rms_rotation = float(np.sqrt(np.mean(rot_res**2)))
    if rms_rotation > INCONSISTENT_RAD:
        k = int(np.argmax(rot_res[: np.count_nonzero(keep)]))
        ik, jk = i[keep][k], j[keep][k]
        motion = float(np.degrees(np.median(rotation_angle(A_k[:, :3, :3]))))
        small = (
            (
                f" The motions are small (median relative rotation {motion:.3g} deg), so "
                "camera noise may also be the cause: move the robot through larger "
                "rotations (tens of degrees about different axes)."
            )
            if motion < 30.0
            else ""
        )
        raise HandEyeError(
            f"no single X relates the motions of the hand and the camera: RMS rotation "
            f"residual of "
            f"A_ij X = X B_ij is {np.degrees(rms_rotation):.3g} deg (worst: poses {ik} and "
            f"{jk}, {np.degrees(rot_res[k]):.3g} deg) > {np.degrees(INCONSISTENT_RAD):.3g} deg."
            f"{small} A batch may be inverted: base_T_hands must be the robot's forward "
            f"kinematics (OpenCV gripper2base) and camera_T_targets the camera's extrinsics "
            f"(OpenCV target2cam); for a camera fixed in the world looking at a target on "
            f"the hand (eye-to-hand) pass base_T_hands = inverse(base_T_hand), and "
            f"hand_T_camera is then base_T_camera"
        )
    return keep, rms_rotation, float(np.sqrt(np.mean(trans_res**2)))


def motion_pairs(n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pose pairs ``(i, j)``, ``i < j``, whose relative motions start the solve.

    Every pair up to ``ALL_PAIRS_UP_TO`` poses. Beyond, each pose is paired with the poses
    ``MOTION_STRIDES`` strides ahead (cyclically), the strides evenly spread over
    ``1 .. n // 2``: about ``MOTION_STRIDES * n`` pairs, every pose in ``2 *
    MOTION_STRIDES`` of them, and pairs far apart in the recording (large motions) as
    well as neighbours. The maximum-likelihood fit uses the absolute poses, so the pairs
    only choose its start and the consistency checks.
    """
    if n <= ALL_PAIRS_UP_TO:
        return np.triu_indices(n, 1)
    strides = np.unique(np.round(np.linspace(1, n // 2, MOTION_STRIDES)).astype(np.intp))
    first = np.tile(np.arange(n), len(strides))
    second = (first + np.repeat(strides, n)) % n
    key = np.unique(np.minimum(first, second) * n + np.maximum(first, second))
    return key // n, key % n


def _check_angles_agree(
    angles_A: NDArray[np.float64],
    angles_B: NDArray[np.float64],
    i: NDArray[np.intp],
    j: NDArray[np.intp],
) -> None:
    """A motion and its view from the camera are conjugate: their rotation angles agree.

    The median difference is tested, so that pairs in the tail of the measurement noise
    or involving one outlying pose (rejected later) do not reject the data; the worst
    pair is named.
    """
    diff = np.abs(angles_A - angles_B)
    rms = float(np.sqrt(np.median(diff**2)))
    n_bad = int(np.count_nonzero(diff > INCONSISTENT_RAD))
    if rms > INCONSISTENT_RAD:
        k = int(np.argmax(diff))
        raise HandEyeError(
            f"the hand's and the camera's motions are inconsistent: the rotation angles of "
            f"their relative motions differ by a median {np.degrees(rms):.3g} deg (> "
            f"{np.degrees(INCONSISTENT_RAD):.3g} deg; {n_bad} of {len(diff)} pose pairs differ "
            f"by more); worst: between poses {i[k]} and "
            f"{j[k]} the hand turns {np.degrees(angles_A[k]):.3g} deg but the camera "
            f"{np.degrees(angles_B[k]):.3g} deg. base_T_hands[k] and camera_T_targets[k] must "
            f"be taken at the same pose k, with the camera rigid on the hand: check the "
            f"pairing and order of the samples "
            f"(inverting or swapping the batches does not change these angles)"
        )
