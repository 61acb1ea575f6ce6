"""Checks shared by the hand-eye solvers and their closed-form starts.

:func:`check_pose_pairs` is the one input check of every hand-eye solver
(:func:`solve_axxb`, :func:`solve_axyb` and the closed forms of ``_starts_axxb.py`` and
``_starts_axyb.py``):
two batches of rigid poses paired pose by pose, rotations accepted within
``ORTHONORMAL_TOL`` and re-orthonormalised.

The closed forms share :class:`StartError` (a closed form cannot determine the answer)
and the linear algebra that raises it: :func:`solve_normal` (rank-deficient normal
equations), :func:`nearest_rotation` (Andreff et al. 2001, eq. (15): a singular rotation
block), and :func:`length_scale`, the RMS length by which the methods that mix lengths
and rotation entries in one system divide the lengths, which makes them equivariant to
the length unit.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, project_to_rotation

#: Relative singular value below which a linear system is taken as rank-deficient.
RANK_TOL = 1e-10
#: Accepted orthonormality error of input rotations of every hand-eye solver: real data
#: printed with six significant digits is off by ~1e-6 (Tabb DS1: 1.2e-6); accepted
#: rotations are re-orthonormalised.
ORTHONORMAL_TOL = 1e-5

Pose = NDArray[np.float64]


class StartError(ValueError):
    """A closed form cannot determine ``X`` (and ``Y``) from these poses; says why."""


_Solver = TypeVar("_Solver", bound=Callable[..., Any])


def poses_by_keyword(*names: str) -> Callable[[_Solver], _Solver]:
    """Make a positional call of a hand-eye solver a ``TypeError`` that names the
    keywords ``names``: the papers' ``A`` and ``B`` are other frames in ``A X = X B``
    than in ``A = X B Y``, so a positional pair is ambiguous."""

    def decorate(solve: _Solver) -> _Solver:
        @functools.wraps(solve)
        def keyword_only(*args: Any, **kwargs: Any) -> Any:
            if args:
                keywords = ", ".join(f"{name}=..." for name in names)
                raise TypeError(
                    f"{solve.__name__}() takes the poses by keyword only ({keywords}); got "
                    f"{len(args)} positional argument(s): the papers' A and B are other "
                    "frames in Tsai & Lenz's A X = X B than in Hirsh et al.'s A = X B Y"
                )
            return solve(**kwargs)

        return cast(_Solver, keyword_only)

    return decorate


def check_pose_pairs(
    A: ArrayLike,
    B: ArrayLike,
    *,
    error: type[ValueError] = ValueError,
    prefix: str = "",
    why: str = "two motions about different axes",
    names: tuple[str, str] = ("A", "B"),
) -> tuple[Pose, Pose]:
    """Validate two pose batches (n, 4, 4) paired pose by pose, n >= 3: the inputs of
    every hand-eye solver and closed form.

    The checks of :func:`kinfw.geometry.check_transform`, on both batches in one pass
    (the hot path of a 3-view solve); rotations off by more than 1e-12 are
    re-orthonormalised (real data printed with six digits is off by ~1e-6). Errors are
    raised as ``error`` with ``prefix`` (e.g. ``"park_axxb: "``), naming the batch (by
    ``names``, e.g. the solver's keywords ``("base_T_hands", "camera_T_targets")``) and
    the index; ``why`` says what three poses are needed for.
    """
    T_A, T_B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    name_A, name_B = names
    for name, T in ((name_A, T_A), (name_B, T_B)):
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise error(f"{prefix}{name}: expected shape (n, 4, 4), got {T.shape}")
    if T_A.shape != T_B.shape:
        raise error(
            f"{prefix}{name_A} and {name_B} must hold the same number of poses, got "
            f"{name_A} {T_A.shape} and {name_B} {T_B.shape}"
        )
    n = len(T_A)
    if n < 3:
        raise error(f"{prefix}at least 3 poses are needed ({why}), got {n}")
    T = np.concatenate([T_A, T_B])
    R = T[:, :3, :3]
    err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    bad = ~np.isfinite(T).all(axis=(1, 2)) | (np.abs(T[:, 3] - (0.0, 0.0, 0.0, 1.0)).max(1) > 0)
    bad |= ~(err <= ORTHONORMAL_TOL) | ~(np.linalg.det(R) > 0.0)
    if np.any(bad):
        k = int(np.argmax(bad))
        name, idx = (name_A, k) if k < n else (name_B, k - n)
        try:
            check_transform(T[k], name=f"{prefix}{name}[{idx}]", tol=ORTHONORMAL_TOL)
        except ValueError as e:
            raise error(str(e)) from e
        raise error(f"{prefix}{name}[{idx}]: not a rigid transform")  # pragma: no cover
    off = err > 1e-12
    if np.any(off):
        T = T.copy()
        T[off, :3, :3] = project_to_rotation(R[off])
    return T[:n], T[n:]


def check_start_poses(A: ArrayLike, B: ArrayLike, method: str) -> tuple[Pose, Pose]:
    """:func:`check_pose_pairs` for the closed forms: errors as :class:`StartError`
    prefixed with ``method`` (e.g. ``"park_axxb"``). ``A``, ``B``: (n, 4, 4), n >= 3."""
    return check_pose_pairs(A, B, error=StartError, prefix=f"{method}: ")


def length_scale(*translations: NDArray[np.float64]) -> float:
    """RMS length over the given translations (each reshaped to (m, 3), any length unit),
    in that unit; 1 when all are zero. The closed forms divide lengths by it before a
    solve that mixes lengths and rotation entries."""
    t = np.concatenate([np.reshape(x, (-1, 3)) for x in translations])
    scale = float(np.sqrt(np.mean(np.sum(t**2, axis=1))))
    return scale if scale > 0.0 else 1.0


def solve_normal(N: NDArray[np.float64], r: NDArray[np.float64], what: str) -> NDArray:
    """Solve the symmetric positive semi-definite normal equations ``N x = r`` ((k, k) and
    (k,)) by eigendecomposition; raise :class:`StartError` with the message ``what`` when
    the smallest eigenvalue is below ``RANK_TOL`` times the largest."""
    w, V = np.linalg.eigh(N)
    if w[0] <= RANK_TOL * w[-1]:
        raise StartError(what)
    return V @ ((V.T @ r) / w)


def nearest_rotation(M: NDArray[np.float64], method: str) -> NDArray[np.float64]:
    """The rotation (3, 3) nearest to ``M`` (3, 3) after scaling it to determinant +1 (a
    negative determinant flips the sign): Andreff et al. (2001), eq. (15); OpenCV's
    ``normalizeRotation``. Raises :class:`StartError` (prefixed with ``method``) when
    ``M`` is singular."""
    det = float(np.linalg.det(M))
    if not np.isfinite(det) or abs(det) < 1e-12 * max(float(np.abs(M).max()), 1e-300) ** 3:
        raise StartError(f"{method}: the solved rotation block is singular (det {det:.3g})")
    return project_to_rotation(np.sign(det) * M)
