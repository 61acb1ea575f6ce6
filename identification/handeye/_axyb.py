"""Simultaneous hand-eye and robot-world calibration ``A = X B Y``, iteratively.

Hirsh, DeSouza & Kak, "An Iterative Approach to the Hand-Eye and Base-World Calibration
Problem" (ICRA 2001). The paper's frames map onto the plain batches of
:func:`solve_axyb` as

    A[i] = c_i_T_w  (camera calibration: pose of the world/target in the camera)
    X    = c_T_e    (hand-eye: pose of the end effector in the camera)
    B[i] = e_i_T_b  (robot kinematics: pose of the base in the end effector)
    Y    = b_T_w    (base-world: pose of the world in the base)

so that eqs. (1)-(6) read ``A[i] = X @ B[i] @ Y`` (the paper's ``^aH_b`` is our ``a_T_b``).
:func:`solve_axyb` takes and returns them by the frames of the package's convention
(:mod:`kinfw.identification.handeye`), with the robot's hand (end effector ``e``) and
base ``b`` and the target that defines the world ``w``: ``camera_T_targets`` (``A``),
``base_T_hands`` (``B^-1``, or ``hand_T_bases`` = ``B``), and the result's
``camera_T_hand`` (``X``, the inverse of ``hand_T_camera``) and ``base_T_target``
(``Y``); ``X`` and ``Y`` stay as aliases.

The algorithm (paper section 3)
    Rotations: from a guess of ``Y`` (the identity in the paper) every pose gives an
    estimate of ``X`` (eqs. 1-3 solved for ``X``, eq. 9); the estimates are averaged as
    quaternions, the averaged ``X`` gives one estimate of ``Y`` per pose, these are
    averaged, and so on until the estimates stop changing. The conjugation of eq. (10)
    keeps the error's scalar part (Appendix A), and the normalised average of quaternions
    with equal scalar parts and different axes has a larger one: the error shrinks each
    cycle (section 4) -- except at exactly 180 degrees, where the scalar part is 0 and
    never grows; a random new guess gets out of it.
    Translations: the same alternation on eqs. (4)-(6) with the rotations fixed.

Quaternions here are kinfw's, scalar last ``(x, y, z, w)``; the paper's ``(s, v)`` is our
``(w; x, y, z)``. Products and averages are written for that layout throughout; nothing
is converted.

The iteration itself, its quaternion signs and why it converges (it is the power
iteration of one 4x4 matrix) are in :mod:`kinfw.identification.handeye`; the checks of
the data and the iteration's start in :mod:`kinfw.identification.handeye`.

Refinement (``refine=True``, the default) adds, measured in the notes of
:func:`solve_axyb`:

1. a closed-form start instead of the identity: the top singular pair of ``N`` (the
   iteration's own fixed point, computed directly -- the quaternion counterpart of
   Shah's 2013 Kronecker-product solution, which gives the same rotations to ~1e-4 deg)
   and the exact linear least squares for the translations. The paper's iteration then
   stops after 2 iterations and cannot stall;
2. then the maximum-likelihood X and Y on SE(3) with the camera pose ``A`` noisy in
   rotation and translation, both weighted by noise scales estimated from the residuals
   (free of the length unit), robust to outlying poses, with the covariance of X and Y
   and a verdict (:func:`kinfw.identification.handeye.fit_absolute`), started from the
   closed form of 1.; when that fit is not clean (poses rejected among fewer than 30,
   not converged, verdict not "determined"), Shah's and Li's closed forms
   (:mod:`kinfw.identification.handeye`) start fits too and the best is kept. The former
   refinement (Gauss-Newton on the rotations alone, then least squares for the
   translations) ignored what the translations say about the rotations: on Tabb DS1
   X moves from 0.545 to 0.175 deg of Tabb's reference, at motions <= 15 deg (1 deg +
   2 mm noise, 10 views) the median X error drops from 2.6 to 0.25 deg. The paper's
   iteration runs first only when a guess or the history is asked for.

``refine=False`` is the paper's algorithm alone, from the identity or the given guess.
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import inverse_transform, rotation_angle, transform_from_rotation_translation
from kinfw.identification.handeye._axyb_iteration import (
    STALL_RAD,
    AXYBError,
    RotationRun,
    TranslationRun,
    iteration_matrix,
    rotation_iteration,
    translation_iteration,
)
from kinfw.identification.handeye._axyb_start import check_motion, check_start, start_of_y
from kinfw.identification.handeye._checks import check_pose_pairs, poses_by_keyword
from kinfw.identification.handeye._ml import PoseFit, Start, assess, fit_absolute
from kinfw.identification.handeye._quaternion import (
    consistent_quats_xyzw,
    rotation_from_quat_xyzw,
)
from kinfw.identification.handeye._result import AXYBResult
from kinfw.identification.handeye._starts import candidate_starts
from kinfw.identification.handeye._uncertainty import Verdict, combined_verdict, uncertainty

log = logging.getLogger(__name__)


@poses_by_keyword("camera_T_targets", "base_T_hands")
def convergence_factor(
    *,
    camera_T_targets: ArrayLike,
    base_T_hands: ArrayLike | None = None,
    hand_T_bases: ArrayLike | None = None,
) -> float:
    """Error shrink factor per iteration of the paper's rotation alternation.

    The alternation is a power iteration on the 4x4 matrix ``N`` (module docstring), so
    the rotation error shrinks by ``(sigma_2 / sigma_1)^2`` of ``N`` per iteration: near
    1 for weakly spread rotations (slow), near 0 for well spread ones.

    Parameters
    ----------
    camera_T_targets, base_T_hands, hand_T_bases : array_like, shape (n, 4, 4), keyword-only
        As for :func:`solve_axyb`: the camera poses and one of the two robot pose batches.
    """
    As, Bs = _checked_poses(camera_T_targets, base_T_hands, hand_T_bases)
    q_As, q_Bs = consistent_quats_xyzw(As[:, :3, :3], Bs[:, :3, :3])
    s = np.linalg.svd(iteration_matrix(q_As, q_Bs), compute_uv=False)
    return float((s[1] / s[0]) ** 2)


def _checked_poses(
    camera_T_targets: ArrayLike, base_T_hands: ArrayLike | None, hand_T_bases: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``A = camera_T_targets`` and ``B = hand_T_bases`` (given, or the inverses of
    ``base_T_hands``), checked; exactly one of the robot pose batches must be given."""
    if (base_T_hands is None) == (hand_T_bases is None):
        raise AXYBError(
            "give the robot's poses as base_T_hands (forward kinematics: the hand's pose in "
            "the base) or as hand_T_bases (their inverses, Hirsh et al.'s B), exactly one "
            f"of them; got {'both' if base_T_hands is not None else 'neither'}"
        )
    robot_name = "base_T_hands" if hand_T_bases is None else "hand_T_bases"
    As, robot = check_pose_pairs(
        camera_T_targets,
        base_T_hands if hand_T_bases is None else hand_T_bases,
        error=AXYBError,
        names=("camera_T_targets", robot_name),
        why="two give one relative motion, whose axis leaves a rotation of the hand-eye "
        "and base-target transforms undetermined; Hirsh et al. section 4",
    )
    return As, robot if hand_T_bases is not None else inverse_transform(robot)


# ---------------------------------------------------------------------- entry point


@poses_by_keyword("camera_T_targets", "base_T_hands")
def solve_axyb(
    *,
    camera_T_targets: ArrayLike,
    base_T_hands: ArrayLike | None = None,
    hand_T_bases: ArrayLike | None = None,
    hand_T_camera_guess: ArrayLike | None = None,
    base_T_target_guess: ArrayLike | None = None,
    tol: float = 1e-12,
    max_iterations: int = 1000,
    rng: np.random.Generator | None = None,
    refine: bool = True,
    record_history: bool = False,
) -> AXYBResult:
    """Hand-eye ``camera_T_hand`` and base-target ``base_T_target`` of
    ``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target`` (Hirsh et
    al.'s ``A[i] ≈ X @ B[i] @ Y``).

    The package's convention (eye-in-hand, :mod:`kinfw.identification.handeye`): a camera
    rigid on the robot's hand looks at a target fixed in the world; the same inputs as
    :func:`kinfw.identification.handeye.solve_axxb`, and the answer is the same camera
    mount, ``result.hand_T_camera``. Every argument is keyword-only.

    Parameters
    ----------
    camera_T_targets : array_like, shape (n, 4, 4)
        Pose of the target in the camera at each pose (camera extrinsics, OpenCV's
        ``target2cam``; the paper's ``A[i] = c_iH_w``, the target defining the world),
        n >= 3. Any length unit; the result uses the same.
    base_T_hands : array_like, shape (n, 4, 4), optional
        Pose of the hand in the robot's base at each pose (forward kinematics, OpenCV's
        ``gripper2base``), the same length unit.
    hand_T_bases : array_like, shape (n, 4, 4), optional
        Instead of ``base_T_hands``: their inverses, the paper's ``B[i] = e_iH_b``
        (OpenCV's ``base2gripper``), used as given. Exactly one of the two.
    hand_T_camera_guess, base_T_target_guess : array_like, shape (4, 4), optional
        A guess of one unknown (the paper starts from a guess of ``Y``, eq. 7); give at
        most one. The camera mount is turned into ``Y``'s start by one averaging step.
        The translation of ``base_T_target_guess`` starts the translation alternation.
        Default: the identity ``Y`` for ``refine=False`` (as the paper), the closed-form
        solution for ``refine=True``.
    tol : float
        Convergence: rotation updates below ``tol`` rad, translation updates below
        ``tol`` times the RMS length of the input translations, Gauss-Newton steps below
        ``tol`` rad.
    max_iterations : int
        Cap on the iterations of each alternation (rotation, restarts included; then
        translation).
    rng : numpy.random.Generator, optional
        Source of the random restarts; default ``np.random.default_rng(0)``, so results
        are reproducible.
    refine : bool
        Closed-form start, then the robust maximum-likelihood fit on SE(3) (module
        docstring). ``False``: the paper's algorithm alone (its covariance and verdict
        are evaluated at its estimate).
    record_history : bool
        Keep the estimates after each iteration in ``camera_T_hand_history`` /
        ``base_T_target_history``.

    Returns
    -------
    AXYBResult
        ``camera_T_hand`` (``X``; its inverse ``hand_T_camera``) and ``base_T_target``
        (``Y``) in the input length unit, and the fit's quality.

    Raises
    ------
    AXYBError
        Fewer than 3 poses, mismatched or non-rigid inputs (naming the argument and the
        index), both or neither of ``base_T_hands`` and ``hand_T_bases``, motions that
        cannot determine the transforms (rotations of the hand all about one axis, or
        none: the message says which part is undetermined), both guesses given, or a
        final RMS rotation residual above ``STALL_RAD`` (the poses do not follow the
        model: check the pairing and directions of the poses). Not converging within
        ``max_iterations`` with a sensible residual is not an error: ``converged=False``
        and a logged warning.
    TypeError
        A positional argument (the message names the keywords): the meaning of the
        batches is given by their names only.

    Warnings
    --------
    Eye-to-hand (a camera fixed in the world, the target on the hand) is the same
    equation with base and hand exchanged: pass the forward kinematics as
    ``hand_T_bases``; ``camera_T_hand`` is then ``camera_T_base`` and ``base_T_target``
    is ``hand_T_target``.

    Notes
    -----
    In the paper's letters ``A = camera_T_target``, ``B = hand_T_base``,
    ``X = camera_T_hand``, ``Y = base_T_target``. Rotations, eqs. (1)-(3) and (7)-(10):
    alternate ``X <- avg_i A_i Y^-1 B_i^-1`` and
    ``Y <- avg_i B_i^-1 X^-1 A_i`` (quaternion averages); translations, eqs. (4)-(6):
    alternate the averages of ``t_X = t_A - R_X (R_B t_Y + t_B)`` and
    ``t_Y = R_B^T (R_X^T (t_A - t_X) - t_B)``. Stall at 180 degrees (section 4, last
    paragraph): restart from a random rotation.

    What the former ``refine=True`` (rotation-only Gauss-Newton) gained over the paper's
    iteration, measured (seeded; the set-ups are in
    ``tests/identification/handeye/test_axb.py``; the
    maximum-likelihood refinement that replaced it is measured in the module docstring):

    * 10 views, each ``A`` rotated by 1 deg about a random axis, 200 trials: accuracy
      unchanged -- rotation errors of X and Y against the truth mean 0.34 deg, 95 %
      0.60 deg, max 0.81 deg (all below the 1-degree noise, the paper's Fig. 4 claim)
      both ways, the estimates 6e-6 deg apart at most. Iterations: median 57 (max 353)
      from the identity, 2 + 2 from the closed form; ~2 ms either way;
    * 3 views, same noise: the paper's iteration from the identity is still unconverged
      after 1000 iterations in 26 of 200 trials (mean rotation error 3.1 deg against
      1.6 deg refined; the refined fit never has a larger residual than the truth);
    * Tabb DS1 (real, 88 poses, factor 0.993 per iteration): from the identity the
      paper's iteration stops unconverged at 1000 iterations, 0.0036 deg and 0.32 mm
      from the optimum (5760 iterations get within 5e-6 deg and 0.07 mm of it); refined:
      4 iterations, a few milliseconds;
    * a start 180 degrees off: the closed form cannot stall, so no restart.

    References
    ----------
    R. L. Hirsh, G. N. DeSouza, A. C. Kak, "An iterative approach to the hand-eye and
    base-world calibration problem", ICRA 2001, eqs. (1)-(10), Appendix A.
    M. Shah, "Solving the robot-world/hand-eye calibration problem using the Kronecker
    product", J. Mechanisms Robotics 5(3), 2013 (the closed form, here in quaternions).
    """
    As, Bs = _checked_poses(camera_T_targets, base_T_hands, hand_T_bases)
    X0, Y0 = _checked_guesses(hand_T_camera_guess, base_T_target_guess)
    if not tol > 0.0 or max_iterations < 1:
        raise AXYBError(f"need tol > 0 and max_iterations >= 1, got {tol!r}, {max_iterations!r}")
    rng = np.random.default_rng(0) if rng is None else rng
    R_As, R_Bs = As[:, :3, :3], Bs[:, :3, :3]
    check_motion(R_Bs)
    q_As, q_Bs = consistent_quats_xyzw(R_As, R_Bs)
    N = iteration_matrix(q_As, q_Bs)

    q_Y0, t_Y0 = start_of_y(As, Bs, N, X0=X0, Y0=Y0, closed_form=refine)

    run_paper = not refine or record_history or X0 is not None or Y0 is not None
    rot = tra = None
    iterations = restarts = 0
    converged = True
    if run_paper:
        rot, tra, X, Y = _paper_iteration(
            As, Bs, N, q_Y0, t_Y0, tol=tol, max_iterations=max_iterations, rng=rng, refine=refine
        )
        converged = rot.converged and tra.converged
        iterations, restarts = rot.iterations + tra.iterations, rot.restarts
    if refine:
        fit = _refined_fit(As, Bs, [(lambda X=X, Y=Y: (X, Y))] if run_paper else [])
        X, Y, converged = fit.camera_T_hand, fit.base_T_target, fit.converged
    else:
        fit = assess(As, Bs, X, Y)

    rms_rot, rms_tra = _rms_residuals(As, Bs, X, Y, fit.inliers)
    if rms_rot > STALL_RAD:
        raise AXYBError(
            f"no consistent X, Y: RMS rotation residual {np.degrees(rms_rot):.3g} deg "
            f"after {iterations} rotation iterations and {restarts} restarts; check that "
            f"the poses are paired and oriented as camera_T_target[i] = camera_T_hand @ "
            f"hand_T_base[i] @ base_T_target (A[i] = X @ B[i] @ Y)"
        )
    length = float(np.sqrt(np.mean(np.sum(As[:, :3, 3] ** 2, axis=1))))
    unc_X = uncertainty(fit.covariance[:6, :6], length, frame="the hand frame")
    unc_Y = uncertainty(fit.covariance[6:, 6:], length, frame="the target frame")
    verdict, message = combined_verdict([("camera_T_hand", unc_X), ("base_T_target", unc_Y)])

    history_X = history_Y = None
    if record_history and rot is not None and tra is not None:
        history_X, history_Y = _histories(rot, tra, As, Bs, t_Y0)

    return AXYBResult(
        camera_T_hand=X,
        base_T_target=Y,
        iterations=iterations,
        converged=bool(converged),
        restarts=restarts,
        rms_rotation_rad=rms_rot,
        rms_translation=rms_tra,
        camera_T_hand_history=history_X,
        base_T_target_history=history_Y,
        covariance=fit.covariance,
        sigma_rotation_deg=np.stack([unc_X.sigma_rotation_deg, unc_Y.sigma_rotation_deg]),
        sigma_translation=np.stack([unc_X.sigma_translation, unc_Y.sigma_translation]),
        verdict=verdict,
        verdict_message=message,
        rejected=fit.rejected,
        noise_rotation_rad=fit.sigma_rotation_rad,
        noise_translation=fit.sigma_translation,
    )


def _checked_guesses(
    hand_T_camera_guess: ArrayLike | None, base_T_target_guess: ArrayLike | None
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """The starts ``X0 = camera_T_hand`` (the inverse of ``hand_T_camera_guess``) and
    ``Y0 = base_T_target_guess``, checked, None where not given; at most one is given."""
    if hand_T_camera_guess is not None and base_T_target_guess is not None:
        raise AXYBError(
            "give hand_T_camera_guess or base_T_target_guess, not both: the iteration "
            "starts from one guess (Hirsh et al. eq. 7) and derives the other"
        )
    X0 = Y0 = None
    if hand_T_camera_guess is not None:
        X0 = inverse_transform(check_start(hand_T_camera_guess, "hand_T_camera_guess"))
    if base_T_target_guess is not None:
        Y0 = check_start(base_T_target_guess, "base_T_target_guess")
    return X0, Y0


def _paper_iteration(
    As: NDArray[np.float64],
    Bs: NDArray[np.float64],
    N: NDArray[np.float64],
    q_Y0: NDArray[np.float64],
    t_Y0: NDArray[np.float64],
    *,
    tol: float,
    max_iterations: int,
    rng: np.random.Generator,
    refine: bool,
) -> tuple[RotationRun, TranslationRun, NDArray[np.float64], NDArray[np.float64]]:
    """The paper's algorithm from ``Y``'s start ``(q_Y0, t_Y0)``: the rotation alternation
    on the iteration matrix ``N``, then the translation alternation; both runs and the
    estimates ``X``, ``Y`` (4, 4). Not converging is logged (a warning unless ``refine``
    continues from the estimate)."""
    rot = rotation_iteration(N, q_Y0, tol=tol, max_iterations=max_iterations, rng=rng)
    R_X, R_Y = rotation_from_quat_xyzw(rot.q_X), rotation_from_quat_xyzw(rot.q_Y)
    tra = translation_iteration(As, Bs, R_X, t_Y0, tol=tol, max_iterations=max_iterations)
    if not (rot.converged and tra.converged):
        (log.info if refine else log.warning)(
            "the paper's iteration did not converge within %d iterations (rotation: %s, "
            "translation: %s)%s",
            max_iterations,
            rot.converged,
            tra.converged,
            "; the refinement continues from its estimate" if refine else "",
        )
    X = transform_from_rotation_translation(R_X, tra.t_X)
    Y = transform_from_rotation_translation(R_Y, tra.t_Y)
    return rot, tra, X, Y


def _refined_fit(As: NDArray[np.float64], Bs: NDArray[np.float64], starts: list[Start]) -> PoseFit:
    """The robust maximum-likelihood fit of ``A = X B Y`` from the closed form and
    ``starts``, Shah's and Li's closed forms as fallback starts, accepted when both X and
    Y are determined; non-convergence and rejected poses are logged."""
    length_A = float(np.sqrt(np.mean(np.sum(As[:, :3, 3] ** 2, axis=1))))

    def determined(f: PoseFit) -> bool:
        unc = [
            uncertainty(f.covariance[:6, :6], length_A),
            uncertainty(f.covariance[6:, 6:], length_A),
        ]
        return all(u.verdict is Verdict.DETERMINED for u in unc)

    def fallback_starts() -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Shah's and Li's closed forms (X, Y)."""
        return list(candidate_starts(As, Bs, problem="axyb").values())

    fit = fit_absolute(As, Bs, starts, fallback_starts=fallback_starts, accept=determined)
    if not fit.converged:
        log.warning("the maximum-likelihood refinement did not converge")
    if fit.rejected:
        log.info("solve_axyb: poses %s rejected as outliers", list(fit.rejected))
    return fit


def _rms_residuals(
    As: NDArray[np.float64],
    Bs: NDArray[np.float64],
    X: NDArray[np.float64],
    Y: NDArray[np.float64],
    inliers: NDArray[np.bool_],
) -> tuple[float, float]:
    """RMS rotation (radians) and translation (input unit) residuals of
    ``A[i] = X @ B[i] @ Y`` over the ``inliers``."""
    fit_T = X @ Bs[inliers] @ Y
    rms_rot = float(
        np.sqrt(
            np.mean(rotation_angle(np.swapaxes(As[inliers, :3, :3], 1, 2) @ fit_T[:, :3, :3]) ** 2)
        )
    )
    rms_tra = float(np.sqrt(np.mean(np.sum((fit_T[:, :3, 3] - As[inliers, :3, 3]) ** 2, axis=1))))
    return rms_rot, rms_tra


def _histories(
    rot: RotationRun,
    tra: TranslationRun,
    As: NDArray[np.float64],
    Bs: NDArray[np.float64],
    t_Y0: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The estimates of ``X`` and ``Y`` after each iteration of the paper's algorithm,
    (k, 4, 4) each: during the rotation phase with ``Y``'s starting translation ``t_Y0``
    and the ``X`` translation it implies, then the translation phase's translations with
    the final rotations."""
    R_X_rot = rotation_from_quat_xyzw(rot.history_X)
    R_Y_rot = rotation_from_quat_xyzw(rot.history_Y)
    # rotation phase: Y's starting translation and the X translation it implies
    t_X_rot = As[:, :3, 3].mean(axis=0) - R_X_rot @ (
        Bs[:, :3, :3].mean(axis=0) @ t_Y0 + Bs[:, :3, 3].mean(axis=0)
    )
    k_tra = tra.iterations
    R_X_final = rotation_from_quat_xyzw(rot.q_X)
    R_Y_final = rotation_from_quat_xyzw(rot.q_Y)
    history_X = transform_from_rotation_translation(
        np.concatenate([R_X_rot, np.broadcast_to(R_X_final, (k_tra, 3, 3))]),
        np.concatenate([t_X_rot, tra.history_X]),
    )
    history_Y = transform_from_rotation_translation(
        np.concatenate([R_Y_rot, np.broadcast_to(R_Y_final, (k_tra, 3, 3))]),
        np.concatenate([np.broadcast_to(t_Y0, (len(R_Y_rot), 3)), tra.history_Y]),
    )
    return history_X, history_Y
