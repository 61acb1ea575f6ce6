"""The one chart of a rigid frame: ``T = T0 [cayley(d[:3] / 2) | d[3:]]``.

Every rigid unknown of kinfw (a CPC tool transform, a target's pose, a marker, the pose
of the root in an external measurement frame, the base) moves around its start ``T0`` by
six numbers ``d``: a rotation on the right by the Cayley map of half the first three,
and a translation added in the outer frame::

    R = R0 cayley(a),  a = d[:3] / 2      (a = tan(theta / 2) u, the Gibbs vector)
    p = p0 + d[3:]

``cayley(a) = I + 2 / (1 + a.a) (K + K K)`` with ``K = [a]x`` is smooth everywhere with
derivative ``[d[:3]]x`` at zero, so ``d[:3]`` is the small rotation vector (rad) and
``d[3:]`` the position change (m). Its inverse is ``d[:3] = 2 vee(dR - dR^T) / (1 +
tr dR)`` (undefined at a half turn).

The 3x3 Cayley entries are written once, as scalar formulas of ``(x, y, z)``
(:func:`cayley_entries`), and assembled by numpy (batched) and CasADi.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray


def cayley_entries(x: Any, y: Any, z: Any) -> tuple[Any, ...]:
    """The nine entries (row-major) of ``cayley((x, y, z))``, for numbers, arrays or SX.

    ``cayley(a) = I + 2 / (1 + |a|^2) ([a]x + [a]x^2)`` with ``a = (x, y, z)`` the Gibbs
    vector ``tan(theta / 2) u``. Only arithmetic is used, so the same formulas serve numpy
    (element-wise over any batch shape) and CasADi symbols.
    """
    c = 2.0 / (1.0 + x * x + y * y + z * z)
    return (
        1.0 - c * (y * y + z * z),
        c * (x * y - z),
        c * (x * z + y),
        c * (x * y + z),
        1.0 - c * (x * x + z * z),
        c * (y * z - x),
        c * (x * z - y),
        c * (y * z + x),
        1.0 - c * (x * x + y * y),
    )


def cayley_rotation(a: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices of Gibbs vectors ``a`` (..., 3): shape (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    e = cayley_entries(a[..., 0], a[..., 1], a[..., 2])
    return np.stack(e, axis=-1).reshape((*a.shape[:-1], 3, 3))


def rotation_chart(dR: ArrayLike) -> NDArray[np.float64]:
    """Chart coordinates ``d`` (..., 3) of rotations ``dR`` (..., 3, 3): ``dR = cayley(d/2)``.

    ``d = 2 vee(dR - dR^T) / (1 + tr dR)``: twice the Gibbs vector, the rotation vector to
    first order (rad); undefined at a half turn.
    """
    dR = np.asarray(dR, dtype=float)
    a = np.stack(
        [
            dR[..., 2, 1] - dR[..., 1, 2],
            dR[..., 0, 2] - dR[..., 2, 0],
            dR[..., 1, 0] - dR[..., 0, 1],
        ],
        axis=-1,
    )
    return 2.0 * a / (1.0 + np.trace(dR, axis1=-2, axis2=-1))[..., None]


def rigid_from_chart(T0: ArrayLike, d: ArrayLike) -> NDArray[np.float64]:
    """``T0 [cayley(d[:3] / 2) | d[3:]]`` in numpy, batched.

    Parameters
    ----------
    T0 : array_like, shape (..., 4, 4)
        Start pose (the chart's origin), metres.
    d : array_like, shape (..., 6)
        Rotation (rad, on the right) then translation (m, in the outer frame).

    Returns
    -------
    ndarray, shape (broadcast of ..., 4, 4)
    """
    T0, d = np.asarray(T0, dtype=float), np.asarray(d, dtype=float)
    R = T0[..., :3, :3] @ cayley_rotation(0.5 * d[..., :3])
    p = T0[..., :3, 3] + d[..., 3:6]
    out = np.zeros((*R.shape[:-2], 4, 4))
    out[..., :3, :3] = R
    out[..., :3, 3] = p
    out[..., 3, 3] = 1.0
    return out


def chart_from_rigid(T0: ArrayLike, T: ArrayLike) -> NDArray[np.float64]:
    """The inverse of :func:`rigid_from_chart`: ``d`` (..., 6) with ``T = T0 [cayley(d[:3]/2)
    | d[3:]]`` (rad, m)."""
    T0, T = np.asarray(T0, dtype=float), np.asarray(T, dtype=float)
    dR = np.swapaxes(T0[..., :3, :3], -1, -2) @ T[..., :3, :3]
    return np.concatenate([rotation_chart(dR), T[..., :3, 3] - T0[..., :3, 3]], axis=-1)


def rigid_from_chart_casadi(T0: Any, d: Any) -> Any:
    """``T0 [cayley(d[:3] / 2) | d[3:]]`` as a CasADi 4x4 (``d``: 6 SX or MX entries).

    ``T0`` is a (4, 4) array, or a symbolic pair ``(R0 (3x3), p0 (3x1))`` so that the
    start is an input of the graph (one graph for every start).
    """
    import casadi as ca

    if isinstance(T0, tuple):
        R0, p0 = T0
    else:
        T0 = np.asarray(T0, dtype=float)
        R0, p0 = ca.DM(T0[:3, :3]), ca.DM(T0[:3, 3])
    e = cayley_entries(0.5 * d[0], 0.5 * d[1], 0.5 * d[2])
    dR = ca.vertcat(
        ca.horzcat(e[0], e[1], e[2]), ca.horzcat(e[3], e[4], e[5]), ca.horzcat(e[6], e[7], e[8])
    )
    R = R0 @ dR
    p = p0 + ca.vertcat(d[3], d[4], d[5])
    return ca.vertcat(ca.horzcat(R, p), ca.horzcat(0, 0, 0, 1))
