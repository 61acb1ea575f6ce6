"""The CPC forward kinematics in CasADi, symbolic in the joint values and parameters.

The PyPI ``pin`` wheel has no ``pinocchio.casadi``, so the chain of
:mod:`kinfw.model` is written here directly as CasADi SX matrix products. The parameters
are the chart of :meth:`kinfw.model.CPCModel.perturbed` around a reference model, so
``delta = 0`` reproduces the reference and derivatives are exact and smooth (also at
``b_z = 0``, where the paper's ``(b_x, b_y)`` coordinates are singular).
``kinfw.verification.evaluation`` checks this graph against the numpy path and Pinocchio.

CasADi is imported here, not by ``import kinfw``.
"""

from __future__ import annotations

import numpy as np

from kinfw.geometry import rigid_from_chart_casadi
from kinfw.model._cpc import CPCModel


def _casadi():
    try:
        import casadi
    except ImportError as exc:  # pragma: no cover - casadi is a core dependency
        raise ImportError("kinfw.model needs CasADi: pip install casadi") from exc
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


def cpc_reference_vector(model: CPCModel) -> np.ndarray:
    """The numbers of ``model`` that :func:`cpc_fk_function` embeds, as one vector.

    Per joint ``b`` (3), the two axis-tilt basis vectors (6), ``l`` (3), ``cos beta``,
    ``sin beta``; then per end frame the tool rotation (9, column-major) and position (3).
    With ``symbolic_reference=True`` the function takes this vector as its third input.
    """
    cs = np.stack([np.cos(model.beta), np.sin(model.beta)], axis=1)
    joints = np.concatenate([model.b, model.axis_bases().reshape(-1, 6), model.l, cs], axis=1)
    tools = np.concatenate(
        [np.swapaxes(model.tool_T[:, :3, :3], 1, 2).reshape(-1, 9), model.tool_T[:, :3, 3]], axis=1
    )
    return np.concatenate([joints.reshape(-1), tools.reshape(-1)])


def cpc_fk_function(
    model: CPCModel,
    frames: tuple[str, ...] | list[str] | None = None,
    *,
    symbolic_reference: bool = False,
):
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
        configurations at once. With ``symbolic_reference``, a third input ``reference``
        (:func:`cpc_reference_vector`): the graph then depends only on the topology and
        the joint signs, so one function serves every model of that structure.
    """
    ca = _casadi()
    topo = model.topology
    frames = topo.frames if frames is None else tuple(frames)
    frame_idx = [model._frame_index(f) for f in frames]
    q = ca.SX.sym("q", model.n_joints)
    delta = ca.SX.sym("delta", model.n_parameters)
    if symbolic_reference:
        ref = ca.SX.sym("reference", len(cpc_reference_vector(model)))
        per_joint = [ref[14 * j : 14 * (j + 1)] for j in range(model.n_joints)]
        t0 = 14 * model.n_joints
        tools = [
            (
                ca.reshape(ref[t0 + 12 * e : t0 + 12 * e + 9], 3, 3),
                ref[t0 + 12 * e + 9 : t0 + 12 * (e + 1)],
            )
            for e in range(len(topo.frames))
        ]
    else:
        ref = None
        numeric = cpc_reference_vector(model)
        per_joint = [numeric[14 * j : 14 * (j + 1)] for j in range(model.n_joints)]
        tools = [
            (ca.DM(model.tool_T[e, :3, :3]), ca.DM(model.tool_T[e, :3, 3]))
            for e in range(len(topo.frames))
        ]

    k = 0
    moved = []  # w_T_F_j' per joint
    for j, (rev, p) in enumerate(zip(topo.revolute, topo.parent, strict=True)):
        c_j = per_joint[j]
        v = c_j[0:3] + delta[k] * c_j[3:6] + delta[k + 1] * c_j[6:9]
        l = ca.DM(c_j[9:12]) if ref is None else c_j[9:12]
        b = v / ca.norm_2(v)
        k += 2
        if rev:
            l = l + ca.vertcat(delta[k], delta[k + 1], 0)
            k += 2
        c, s = c_j[12], c_j[13]
        Rz = (
            ca.DM([[c, -s, 0], [s, c, 0], [0, 0, 1]])
            if ref is None
            else ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
        )
        R = _rotation_from_axis(ca, b) @ Rz
        link = _homogeneous(ca, R, R @ l)
        sq = model.sign[j] * q[j]
        if rev:
            cq, sn = ca.cos(sq), ca.sin(sq)
            motion = ca.vertcat(
                ca.horzcat(cq, -sn, 0, 0),
                ca.horzcat(sn, cq, 0, 0),
                ca.horzcat(0, 0, 1, 0),
                ca.horzcat(0, 0, 0, 1),
            )
        else:
            motion = _homogeneous(ca, ca.DM.eye(3), ca.vertcat(0, 0, sq))
        moved.append((link if p < 0 else moved[p] @ link) @ motion)

    outputs = []
    for e in range(len(topo.frames)):
        tool = rigid_from_chart_casadi(tools[e], delta[k : k + 6])
        k += 6
        p = topo.frame_parent[e]
        outputs.append(tool if p < 0 else moved[p] @ tool)
    return ca.Function(
        "cpc_fk",
        [q, delta] if ref is None else [q, delta, ref],
        [outputs[i] for i in frame_idx],
        ["q", "delta"] if ref is None else ["q", "delta", "reference"],
        [f"w_T_{topo.frames[i]}" for i in frame_idx],
    )
