"""Data preparation of ``A = X B Y`` (:func:`kinfw.identification.handeye.solve_axyb`;
``A = camera_T_target``, ``B = hand_T_base``, ``X = camera_T_hand``,
``Y = base_T_target``).

:func:`check_motion` refuses rotations of ``B`` that cannot determine X and Y (and warns
when they barely do), :func:`check_start` checks a guess of X or Y, and
:func:`start_of_y` gives the paper's iteration its start: from a guess, the closed form,
or the identity.
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, project_to_rotation, quat_xyzw_from_matrix
from kinfw.identification.handeye._axyb_iteration import AXYBError, normalise
from kinfw.identification.handeye._axyb_refinement import translations_least_squares
from kinfw.identification.handeye._checks import ORTHONORMAL_TOL
from kinfw.identification.handeye._quaternion import rotation_from_quat_xyzw

# The solver's logger: its messages are filtered as kinfw.identification.handeye's.
log = logging.getLogger("kinfw.identification.handeye")

#: Off-axis rotation spread of ``B`` (rad) below which X and Y are called undetermined.
MIN_MOTION_RAD = 1e-3
#: Below this spread (rad) X and Y are poorly determined: a warning is logged.
WEAK_MOTION_RAD = np.radians(2.0)


def check_start(T: ArrayLike, name: str) -> NDArray[np.float64]:
    """A guess of X or Y as a rigid transform, its rotation projected onto SO(3).

    Parameters
    ----------
    T : array_like, shape (4, 4)
        The guess (``hand_T_camera_guess`` or ``base_T_target_guess`` of
        :func:`kinfw.identification.handeye.solve_axyb`).
    name : str
        Its name, for the message.

    Returns
    -------
    ndarray, shape (4, 4)
        A copy with an exactly orthonormal rotation.

    Raises
    ------
    AXYBError
        Naming ``name``: another shape, or not a rigid transform.
    """
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise AXYBError(f"{name}: expected shape (4, 4), got {T.shape}")
    try:
        T = check_transform(T, name, tol=ORTHONORMAL_TOL).copy()
    except ValueError as err:
        raise AXYBError(str(err)) from err
    T[:3, :3] = project_to_rotation(T[:3, :3])
    return T


def check_motion(R_Bs: NDArray[np.float64]) -> None:
    """Raise when the rotations of ``B`` cannot determine X and Y.

    Parameters
    ----------
    R_Bs : ndarray, shape (n, 3, 3)
        The rotations of ``B``.

    Raises
    ------
    AXYBError
        When the off-axis spread is below :data:`MIN_MOTION_RAD`, naming the undetermined
        axes (below :data:`WEAK_MOTION_RAD` a warning is logged).

    Notes
    -----
    X and Y are determined iff no unit ``v`` has ``R_B[i] v`` the same for every ``i``
    (all relative rotations about one axis): with ``u = R_B[i] v``, ``X Rot(u, phi)``
    and ``Rot(v, -phi) Y`` fit as well, and so do the translations moved by
    ``(-lambda R_X u, lambda v)``. ``sigma``, the largest singular value of
    ``mean_i R_B[i]``, is 1 exactly then; ``1 - sigma^2`` is the smallest eigenvalue, per
    pose, of the Schur complement of the translation normal equations. The off-axis
    spread ``2 asin(sqrt(1 - sigma^2))`` is the relative rotation angle for two poses.
    """
    U, S, Vt = np.linalg.svd(R_Bs.mean(axis=0))
    spreads = 2.0 * np.arcsin(np.sqrt(np.clip(1.0 - S**2, 0.0, 1.0)))
    if spreads[1] < MIN_MOTION_RAD:
        raise AXYBError(
            f"the rotations of B barely differ (spread {np.degrees(spreads[1]):.3g} deg, "
            f"need {np.degrees(MIN_MOTION_RAD):.3g} deg): the poses determine neither the "
            f"rotations nor the translations of X and Y, only their combination X B Y"
        )
    if spreads[0] < MIN_MOTION_RAD:
        sense = np.sign(U[np.argmax(np.abs(U[:, 0])), 0])  # an axis has no sign
        u, v = np.round(sense * U[:, 0], 4) + 0.0, np.round(sense * Vt[0], 4) + 0.0
        raise AXYBError(
            f"all rotations of B are about one axis (off-axis spread "
            f"{np.degrees(spreads[0]):.3g} deg, need {np.degrees(MIN_MOTION_RAD):.3g} deg): "
            f"the rotation of X about u = {u.tolist()} (in B's left frame), "
            f"that of Y about v = {v.tolist()} (in B's right frame) and the "
            f"translations along these axes are undetermined; add poses that rotate "
            f"about another axis"
        )
    if spreads[0] < WEAK_MOTION_RAD:
        log.warning(
            "weak motion: the rotations of B spread only %.3g deg off their common axis; "
            "X and Y will be poorly determined and the iteration slow (factor %.6f per "
            "iteration)",
            np.degrees(spreads[0]),
            S[0] ** 2,
        )


def start_of_y(
    As: NDArray[np.float64],
    Bs: NDArray[np.float64],
    N: NDArray[np.float64],
    *,
    X0: NDArray[np.float64] | None,
    Y0: NDArray[np.float64] | None,
    closed_form: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The start of the paper's iteration: ``Y``'s rotation and translation.

    Parameters
    ----------
    As, Bs : ndarray, shape (n, 4, 4)
        The checked poses of :func:`kinfw.identification.handeye.solve_axyb`, input length unit.
    N : ndarray, shape (4, 4)
        The rotation iteration's matrix
        (:func:`~kinfw.identification.handeye._axyb_iteration.iteration_matrix`).
    X0, Y0 : ndarray, shape (4, 4), or None, keyword-only
        A guess of one unknown, ``camera_T_hand`` or ``base_T_target`` (at most one
        given), checked by :func:`check_start`: ``Y0`` is used as it is, ``X0`` is turned
        into ``Y``'s start by one averaging step (Hirsh et al. eqs. 3 and 6).
    closed_form : bool, keyword-only
        Without a guess: the iteration's fixed point in closed form (the top singular
        pair of ``N``) and the exact linear least squares for the translations; else the
        identity, as the paper.

    Returns
    -------
    q_Y0 : ndarray, shape (4,)
        Rotation of ``Y``, quaternion ``(x, y, z, w)``.
    t_Y0 : ndarray, shape (3,)
        Translation of ``Y``, input length unit.
    """
    R_Bs = Bs[:, :3, :3]
    if Y0 is not None:
        q_Y0, t_Y0 = quat_xyzw_from_matrix(Y0[:3, :3]), Y0[:3, 3]
    elif X0 is not None:
        q_Y0, _ = normalise(N.T @ quat_xyzw_from_matrix(X0[:3, :3]))
        t_Y0 = np.mean(
            np.einsum("nji,nj->ni", R_Bs, (As[:, :3, 3] - X0[:3, 3]) @ X0[:3, :3] - Bs[:, :3, 3]),
            axis=0,
        )
    elif closed_form:
        U, _, Vt = np.linalg.svd(N)  # the iteration's fixed point in closed form
        q_Y0 = Vt[0]
        _, t_Y0 = translations_least_squares(As, Bs, rotation_from_quat_xyzw(U[:, 0]))
    else:
        q_Y0, t_Y0 = np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3)
    return q_Y0, t_Y0
