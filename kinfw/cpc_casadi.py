"""The CPC forward kinematics in CasADi, symbolic in the joint values and parameters.

The PyPI ``pin`` wheel has no ``pinocchio.casadi``, so the chain of
:mod:`kinfw.cpc` is written here directly as CasADi SX matrix products. The parameters
are the chart of :meth:`kinfw.cpc.CPCModel.perturbed` around a reference model, so
``delta = 0`` reproduces the reference and derivatives are exact and smooth (also at
``b_z = 0``, where the paper's ``(b_x, b_y)`` coordinates are singular).
``verification.crosscheck`` checks this graph against the numpy path and Pinocchio.

CasADi is imported here, not by ``import kinfw``.
"""

from __future__ import annotations

import numpy as np

from kinfw.chart import rigid_from_chart_casadi
from kinfw.cpc import CPCModel

__all__ = ["cpc_fk_function"]


def _casadi():
    try:
        import casadi
    except ImportError as exc:  # pragma: no cover - casadi is a core dependency
        raise ImportError("kinfw.cpc_casadi needs CasADi: pip install casadi") from exc
    return casadi


def _rotation_from_axis(ca, b):
    """Shih et al. eq. (4) on a CasADi 3-vector."""
    bx, by, bz = b[0], b[1], b[2]
    c = 1.0 / (1.0 + bz)
    return ca.vertcat(
        ca.horzcat(1 - bx * bx * c, -bx * by * c, bx),
        ca.horzcat(-bx * by * c, 1 - by * by * c, by),
        ca.horzcat(-bx, -by, bz),
    )


def _homogeneous(ca, R, p):
    return ca.vertcat(ca.horzcat(R, p), ca.horzcat(0, 0, 0, 1))


def cpc_fk_function(model: CPCModel, frames: tuple[str, ...] | list[str] | None = None):
    """CasADi function ``fk(q, delta) -> (w_T_e1, w_T_e2, ...)``.

    Parameters
    ----------
    model : CPCModel
        Reference model: the chart's origin (``delta = 0``).
    frames : sequence of str, optional
        End frames to output (default: all, in ``model.topology.frames`` order).

    Returns
    -------
    casadi.Function
        Inputs ``q`` (J,) in ``topology.joint_names`` order (rad, m) and ``delta``
        (``model.n_parameters``,) in the chart of ``model.parameter_names``; one 4x4 SX
        output ``w_T_<frame>`` per frame. Use ``.map(n)`` to evaluate over n
        configurations at once.
    """
    ca = _casadi()
    topo = model.topology
    frames = topo.frames if frames is None else tuple(frames)
    frame_idx = [model._frame_index(f) for f in frames]
    q = ca.SX.sym("q", model.n_joints)
    delta = ca.SX.sym("delta", model.n_parameters)
    bases = model.axis_bases()

    k = 0
    moved = []  # w_T_F_j' per joint
    for j, (rev, p) in enumerate(zip(topo.revolute, topo.parent, strict=True)):
        v = model.b[j] + delta[k] * bases[j, 0] + delta[k + 1] * bases[j, 1]
        b = v / ca.norm_2(v)
        k += 2
        l = ca.DM(model.l[j])
        if rev:
            l = l + ca.vertcat(delta[k], delta[k + 1], 0)
            k += 2
        c, s = np.cos(model.beta[j]), np.sin(model.beta[j])
        R = _rotation_from_axis(ca, b) @ ca.DM([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        link = _homogeneous(ca, R, R @ l)
        sq = model.sign[j] * q[j]
        if rev:
            cq, sn = ca.cos(sq), ca.sin(sq)
            motion = ca.vertcat(ca.horzcat(cq, -sn, 0, 0), ca.horzcat(sn, cq, 0, 0),
                                ca.horzcat(0, 0, 1, 0), ca.horzcat(0, 0, 0, 1))
        else:
            motion = _homogeneous(ca, ca.DM.eye(3), ca.vertcat(0, 0, sq))
        moved.append((link if p < 0 else moved[p] @ link) @ motion)

    outputs = []
    for e in range(len(topo.frames)):
        tool = rigid_from_chart_casadi(model.tool_T[e], delta[k : k + 6])
        k += 6
        p = topo.frame_parent[e]
        outputs.append(tool if p < 0 else moved[p] @ tool)
    return ca.Function(
        "cpc_fk",
        [q, delta],
        [outputs[i] for i in frame_idx],
        ["q", "delta"],
        [f"w_T_{topo.frames[i]}" for i in frame_idx],
    )
