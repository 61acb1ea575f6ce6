"""Hand-eye calibration from pose pairs for ``kinfw handeye``: kinfw's solver, OpenCV's
closed forms and the registered closed-form starts (a plugin's) side by side, and their
held-out errors.

Every method is fitted to the same ``(base_T_hands, camera_T_targets)`` for either setup
(:func:`kinfw.identification.handeye._calibration.solver_hand_poses`) and returns
``(mount_T_camera, holder_T_target)``. A held-out pair ``i`` is predicted by closing the
loop, ``camera_T_target = inv(mount_T_camera) @ inv(A[i]) @ holder_T_target`` with
``A[i]`` the solver's hand pose, and compared with the measured one: the rotation angle
between them (deg) and the distance between their translations (input unit).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    average_transform,
    inverse_transform,
    rotation_angle,
    transform_from_rotation_translation,
)
from kinfw.identification.handeye._axxb import solve_axxb
from kinfw.identification.handeye._calibration import HandEyeCalibration, solver_hand_poses
from kinfw.identification.handeye._result import HandEyeResult
from kinfw.identification.handeye._starts import START_METHODS
from kinfw.measurements import PosePairs, drop_duplicate_pairs
from kinfw.plugins import load_plugins

#: The methods :func:`fit_method` knows: kinfw's maximum likelihood (``solve_axxb``),
#: OpenCV's ``calibrateHandEye`` (AX = XB) and ``calibrateRobotWorldHandEye`` (AX = ZB).
HANDEYE_METHODS = ("kinfw", "tsai", "park", "horaud", "andreff", "daniilidis", "shah", "li")
_HAND_EYE = {"tsai", "park", "horaud", "andreff", "daniilidis"}


def handeye_methods() -> tuple[str, ...]:
    """Every method :func:`fit_method` knows: :data:`HANDEYE_METHODS`, then the
    closed-form starts registered under other names
    (:func:`~kinfw.identification.handeye.register_start`: a plugin's or a program's;
    the plugins loaded first). The built-in starts share OpenCV's names, which mean
    OpenCV's implementation here."""
    load_plugins()
    return (*HANDEYE_METHODS, *(n for n in START_METHODS if n not in HANDEYE_METHODS))


def fit_method(
    method: str, *, base_T_hands: ArrayLike, camera_T_targets: ArrayLike, setup: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(mount_T_camera, holder_T_target)`` fitted by ``method`` (:func:`handeye_methods`),
    each (4, 4) in the input length unit.

    OpenCV's AX = XB methods give no target pose: it is the chordal mean of
    ``A[i] @ X @ B[i]`` over the pairs (:func:`kinfw.geometry.average_transform`). A
    registered start is called on the solver's poses in its problem's letters
    (:data:`~kinfw.identification.handeye.START_METHODS`): ``"axxb"`` gives
    ``(hand_T_camera, base_T_target)``, ``"axyb"`` ``(camera_T_hand, base_T_target)``.
    Raises ValueError for an unknown method; OpenCV's and a start's own errors pass
    through.
    """
    A = solver_hand_poses(base_T_hands, setup)
    B = np.asarray(camera_T_targets, dtype=float)
    if method == "kinfw":
        r = solve_axxb(base_T_hands=A, camera_T_targets=B)
        return r.hand_T_camera, r.base_T_target
    if method not in HANDEYE_METHODS and method in handeye_methods():
        start = START_METHODS[method]
        if start.problem == "axxb":
            X, Y = start.solve(A, B)
            return np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
        X, Y = start.solve(B, inverse_transform(A))
        return inverse_transform(X), np.asarray(Y, dtype=float)
    import cv2

    if method in _HAND_EYE:
        R, t = cv2.calibrateHandEye(
            np.ascontiguousarray(A[:, :3, :3]),
            np.ascontiguousarray(A[:, :3, 3:]),
            np.ascontiguousarray(B[:, :3, :3]),
            np.ascontiguousarray(B[:, :3, 3:]),
            method=getattr(cv2, f"CALIB_HAND_EYE_{method.upper()}"),
        )
        X = transform_from_rotation_translation(R, np.ravel(t))
        return X, average_transform(A @ X @ B)
    if method in {"shah", "li"}:
        A_inv = inverse_transform(A)
        R_bw, t_bw, R_gc, t_gc = cv2.calibrateRobotWorldHandEye(
            np.ascontiguousarray(B[:, :3, :3]),
            np.ascontiguousarray(B[:, :3, 3:]),
            np.ascontiguousarray(A_inv[:, :3, :3]),
            np.ascontiguousarray(A_inv[:, :3, 3:]),
            method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{method.upper()}"),
        )
        # OpenCV's gripper2cam is camera_T_hand, its base2world target_T_base
        X = inverse_transform(transform_from_rotation_translation(R_gc, np.ravel(t_gc)))
        Y = inverse_transform(transform_from_rotation_translation(R_bw, np.ravel(t_bw)))
        return X, Y
    raise ValueError(f"unknown hand-eye method {method!r} (one of {', '.join(handeye_methods())})")


@dataclass(frozen=True, slots=True)
class HeldOutErrors:
    """Loop-closure errors of held-out pairs.

    Attributes
    ----------
    rotation_deg : ndarray, shape (n,)
        Angle between the predicted and the measured ``camera_T_target``, degrees.
    translation : ndarray, shape (n,)
        Distance between their translations, input length unit.
    """

    rotation_deg: NDArray[np.float64]
    translation: NDArray[np.float64]

    @property
    def rms_rotation_deg(self) -> float:
        """RMS of :attr:`rotation_deg`."""
        return float(np.sqrt(np.mean(self.rotation_deg**2)))

    @property
    def rms_translation(self) -> float:
        """RMS of :attr:`translation`."""
        return float(np.sqrt(np.mean(self.translation**2)))


def loop_closure_errors(
    mount_T_camera: ArrayLike,
    holder_T_target: ArrayLike,
    *,
    base_T_hands: ArrayLike,
    camera_T_targets: ArrayLike,
    setup: str,
) -> HeldOutErrors:
    """Errors of the loop closure predicted by a calibration on pose pairs it was not
    fitted to (the module's docstring)."""
    A = solver_hand_poses(base_T_hands, setup)
    predicted = inverse_transform(mount_T_camera) @ inverse_transform(A) @ holder_T_target
    measured = np.asarray(camera_T_targets, dtype=float)
    predicted_R_measured = np.swapaxes(predicted[:, :3, :3], -1, -2) @ measured[:, :3, :3]
    rot = np.degrees(rotation_angle(predicted_R_measured))
    trans = np.linalg.norm(predicted[:, :3, 3] - measured[:, :3, 3], axis=-1)
    return HeldOutErrors(rot, trans)


def repeated_pairs(
    base_T_hands: ArrayLike,
    camera_T_targets: ArrayLike,
    *,
    held_base_T_hands: ArrayLike,
    held_camera_T_targets: ArrayLike,
    tol: float = 1e-9,
) -> list[int]:
    """Indices of the held-out pairs equal (within ``tol`` per entry) to a pair of the
    fit: their errors would be in-sample, not held-out."""
    A, B = np.asarray(base_T_hands, dtype=float), np.asarray(camera_T_targets, dtype=float)
    HA = np.asarray(held_base_T_hands, dtype=float)
    HB = np.asarray(held_camera_T_targets, dtype=float)
    same = (np.abs(HA[:, None] - A[None]).max(axis=(-2, -1)) <= tol) & (
        np.abs(HB[:, None] - B[None]).max(axis=(-2, -1)) <= tol
    )
    return [int(i) for i in np.flatnonzero(same.any(axis=1))]


def kfold_errors(
    method: str,
    *,
    base_T_hands: ArrayLike,
    camera_T_targets: ArrayLike,
    setup: str,
    k: int,
    seed: int = 0,
) -> HeldOutErrors:
    """Held-out errors of ``method`` by k-fold cross-validation: the pairs shuffled
    (``seed``) into ``k`` folds, each predicted by the fit to the others; the errors of
    every pair, in the input's order. Raises ValueError for ``k < 2`` or ``k`` above
    the number of pairs."""
    A = np.asarray(base_T_hands, dtype=float)
    B = np.asarray(camera_T_targets, dtype=float)
    n = len(A)
    if not 2 <= k <= n:
        raise ValueError(f"k-fold: k = {k}; it must be between 2 and the {n} pairs")
    folds = np.array_split(np.random.default_rng(seed).permutation(n), k)
    rot, trans = np.empty(n), np.empty(n)
    for test in folds:
        train = np.setdiff1d(np.arange(n), test)
        X, Y = fit_method(method, base_T_hands=A[train], camera_T_targets=B[train], setup=setup)
        e = loop_closure_errors(X, Y, base_T_hands=A[test], camera_T_targets=B[test], setup=setup)
        rot[test], trans[test] = e.rotation_deg, e.translation
    return HeldOutErrors(rot, trans)


def calibrate_pose_pairs(
    *,
    base_T_hands: ArrayLike,
    camera_T_targets: ArrayLike,
    setup: str,
    frames: Sequence[str] = ("tool0", "camera_link"),
    keep_duplicates: bool = False,
) -> tuple[HandEyeCalibration, HandEyeResult]:
    """kinfw's hand-eye calibration (:func:`kinfw.identification.handeye.solve_axxb`) of
    either setup, as a :class:`HandEyeCalibration` (and the solver's result).

    Parameters
    ----------
    base_T_hands, camera_T_targets : array_like, shape (n, 4, 4)
        Pose of the hand in the base and of the target in the camera at each pose,
        metres (the calibration's unit).
    setup : str
        ``"eye-in-hand"`` or ``"eye-to-hand"``.
    frames : (str, str)
        Names of the mount frame and the camera frame, for ROS outputs.
    keep_duplicates : bool
        Keep the pairs that repeat an earlier one (``--keep-duplicates``). By default they
        are dropped first, with one ``UserWarning`` naming them
        (:func:`kinfw.measurements.drop_duplicate_pairs`): a pair recorded twice would
        shrink every sigma by 1/sqrt(2). ``n_samples`` and ``rejected`` count the pairs
        kept.

    Raises
    ------
    HandEyeError
        From the solver: the poses cannot determine the transform (the message says why).
    """
    hands, views = np.asarray(base_T_hands, dtype=float), np.asarray(camera_T_targets, dtype=float)
    if not keep_duplicates and hands.ndim == 3 and hands.shape == views.shape:
        kept = drop_duplicate_pairs(PosePairs(hands, views, "pose pairs"), stacklevel=3)
        hands, views = kept.base_T_hands, kept.sensor_T_targets
    A = solver_hand_poses(hands, setup)
    r = solve_axxb(base_T_hands=A, camera_T_targets=views)
    calibration = HandEyeCalibration(
        setup=setup,
        mount_T_camera=r.hand_T_camera,
        holder_T_target=r.base_T_target,
        covariance=r.covariance,
        verdict=r.verdict.value,
        verdict_message=r.verdict_message,
        n_samples=len(A),
        rejected=tuple(int(i) for i in r.rejected),
        mount_frame=frames[0],
        camera_frame=frames[1],
    )
    return calibration, r


@dataclass(frozen=True, slots=True)
class MethodResult:
    """One method's fit and held-out errors (:func:`compare_methods`).

    Attributes
    ----------
    method : str
        A name of :func:`handeye_methods`.
    mount_T_camera, holder_T_target : ndarray, shape (4, 4), or None
        The fit (input unit); None when the method failed.
    holdout : HeldOutErrors or None
        Loop-closure errors on the held-out pairs, when given.
    kfold : HeldOutErrors or None
        k-fold errors, when ``k`` is given.
    error : str or None
        Why the method failed (its exception's message), else None.
    """

    method: str
    mount_T_camera: NDArray[np.float64] | None
    holder_T_target: NDArray[np.float64] | None
    holdout: HeldOutErrors | None
    kfold: HeldOutErrors | None
    error: str | None = None


def compare_methods(
    methods: Sequence[str],
    calibration: HandEyeCalibration,
    *,
    base_T_hands: ArrayLike,
    camera_T_targets: ArrayLike,
    held_out: tuple[ArrayLike, ArrayLike] | None = None,
    k: int | None = None,
) -> list[MethodResult]:
    """kinfw's ``calibration`` and each of ``methods`` on the same pairs, with their
    loop-closure errors on ``held_out`` pairs ``(base_T_hands, camera_T_targets)`` and
    by ``k``-fold cross-validation; kinfw first. A method that raises is a result with
    its ``error`` (OpenCV's closed forms fail on some data); kinfw's errors propagate."""
    setup = calibration.setup
    data = {"base_T_hands": base_T_hands, "camera_T_targets": camera_T_targets}
    results = []
    for method in ["kinfw", *methods]:
        try:
            X, Y = (
                (calibration.mount_T_camera, calibration.holder_T_target)
                if method == "kinfw"
                else fit_method(method, **data, setup=setup)
            )
            held = None
            if held_out is not None:
                A, B = held_out
                held = loop_closure_errors(X, Y, base_T_hands=A, camera_T_targets=B, setup=setup)
            fold = kfold_errors(method, **data, setup=setup, k=k) if k else None
            results.append(MethodResult(method, X, Y, held, fold))
        except Exception as exc:
            if method == "kinfw":
                raise
            results.append(MethodResult(method, None, None, None, None, " ".join(str(exc).split())))
    return results
