"""Universal Robots' kinematics file: the ``default_kinematics.yaml`` that the driver's
``ur_calibration`` writes from a robot's factory calibration and ``ur_description``'s xacro
reads (``kinematics_parameters_file``), from a calibrated URDF of a UR arm
(:func:`ur_kinematics_from_robot`) or a DH table (:func:`ur_kinematics_from_dh`).

The file holds, per joint, the ``<origin>`` of ``ur_description``'s joint: ``kinematics:``
then ``shoulder``, ``upper_arm``, ``forearm``, ``wrist_1``, ``wrist_2``, ``wrist_3``, each
``{x, y, z, roll, pitch, yaw}`` (metres; URDF's fixed-axis roll, pitch, yaw,
``R = Rz(yaw) Ry(pitch) Rx(roll)``), and ``hash``. The xacro builds the chain

``base_link -[rpy 0 0 pi]- base_link_inertia -[shoulder, Rz(q1)]- shoulder_link -[upper_arm,
Rz(q2)]- upper_arm_link ... -[wrist_3, Rz(q6)]- wrist_3_link -[rpy 0 -pi/2 -pi/2]- flange
-[rpy pi/2 pi pi/2]- tool0``

with every joint rotating about the z axis of its child link frame; the fixed transforms
(:data:`BASE_LINK_T_INERTIA`, :data:`WRIST_3_T_TOOL0`) are written in the xacro, not in the
file.

What a calibrated URDF can hold and the file cannot, and what this module does with it:

- a joint axis that is not the child frame's z: the link frame is turned by the minimal
  rotation taking z onto the axis (:func:`kinfw.model.rotation_from_axis`), and the next
  origin re-expressed, so the forward kinematics is unchanged; the link's meshes and
  inertia, attached to the frame in ``ur_description``, turn with it (by the axis tilt,
  :attr:`URKinematics.axis_tilts_rad`). Tilts above :data:`MAX_AXIS_TILT_DEG` are refused.
- fixed joints between ``base_link`` and ``shoulder_link`` that differ from the xacro's
  ``rpy 0 0 pi``: folded into the ``shoulder`` origin (exact).
- ``tool0`` off the ``wrist_3`` axis (a calibrated tool frame): ``wrist_3_link`` is put
  on the axis as close as it goes, and the rest is returned as a constant
  :attr:`URKinematics.tool0_T_calibrated_tool0` (identity when exact), which belongs to
  whatever is mounted on ``tool0``.
- the pose of ``base_link`` in the URDF's root (``ur_robot``'s ``origin`` block):
  returned as :attr:`URKinematics.root_T_base_link`, not in the file.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import inverse_transform
from kinfw.model import Robot, check_robot, rotation_from_axis
from kinfw.urdf._edit import ExportError, rpy_from_matrix

#: The file's keys, one per joint, base first.
UR_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
#: ``ur_description``'s joint names (after its ``tf_prefix``), in the same order.
UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: Largest angle between a calibrated joint axis and its link frame's z that is
#: re-expressed (the link's meshes turn by it); larger ones are a different joint.
MAX_AXIS_TILT_DEG = 5.0


def _rpy_transform(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = pin.rpy.rpyToMatrix(roll, pitch, yaw)
    return out


#: ``base_link_T_base_link_inertia`` of ``ur_description``'s xacro (REP-103 ``base_link``
#: to the controller's base frame).
BASE_LINK_T_INERTIA = _rpy_transform(0.0, 0.0, np.pi)
#: ``wrist_3_link_T_tool0`` of the xacro: ``wrist_3_link -> flange -> tool0``.
WRIST_3_T_TOOL0 = _rpy_transform(0.0, -np.pi / 2, -np.pi / 2) @ _rpy_transform(
    np.pi / 2, np.pi, np.pi / 2
)


@dataclass(frozen=True, slots=True)
class URKinematics:
    """The six joint origins of a UR arm in ``ur_description``'s convention.

    Attributes
    ----------
    parent_T_origins : ndarray, shape (6, 4, 4)
        Each joint's ``<origin>``: its child link frame in its parent link frame at
        q = 0 (``shoulder`` in ``base_link_inertia``, ..., ``wrist_3`` in
        ``wrist_2_link``), metres; the joint turns about the child frame's z.
    tool0_T_calibrated_tool0 : ndarray, shape (4, 4)
        The calibrated ``tool0`` in the ``tool0`` the file gives (constant over q):
        identity when the file reproduces it; else the offset of a calibrated tool
        frame off the ``wrist_3`` axis, for the mount of what is on ``tool0``.
    root_T_base_link : ndarray, shape (4, 4)
        ``base_link`` in the URDF's root link (``ur_robot``'s ``origin`` block).
    axis_tilts_rad : ndarray, shape (6,)
        Angle between each joint's axis and its child link frame's z in the URDF; links
        1-5 were turned by it (their meshes turn with them in ``ur_description``),
        ``wrist_3_link`` is placed by ``tool0`` instead.
    """

    parent_T_origins: NDArray[np.float64]
    tool0_T_calibrated_tool0: NDArray[np.float64]
    root_T_base_link: NDArray[np.float64]
    axis_tilts_rad: NDArray[np.float64]


def ur_kinematics_from_dh(
    d: ArrayLike, a: ArrayLike, alpha: ArrayLike, theta: ArrayLike | None = None
) -> URKinematics:
    """The file's origins from a UR's DH table, composed as ``ur_calibration`` does.

    Parameters
    ----------
    d, a : array_like, shape (6,)
        DH offsets along z and lengths along x (metres); UR publishes ``d1, a2, a3, d4,
        d5, d6`` (``a6 = 0``: the file has no room for it, a non-zero one is refused).
    alpha : array_like, shape (6,)
        DH twists about x (rad); ``alpha6 = 0`` likewise.
    theta : array_like, shape (6,), optional
        DH joint offsets (rad), the controller's calibration ``delta_theta``; default 0.

    Returns
    -------
    URKinematics
        ``parent_T_origins[0] = Rz(theta1) Tz(d1)``, then
        ``parent_T_origins[i] = Tx(a_i) Rx(alpha_i) Rz(theta_{i+1}) Tz(d_{i+1})``: the
        DH frame i is ``wrist_3_link``'s chain frame i, so ``prod_i origin_i Rz(q_i)``
        equals the DH forward kinematics ``prod_i Rz(theta_i + q_i) Tz(d_i) Tx(a_i)
        Rx(alpha_i)``.

    Notes
    -----
    ``ur_calibration`` (Universal_Robots_ROS2_Driver, ``Calibration::getSimplified``)
    splits each DH row into ``Rz(theta) Tz(d)`` and ``Tx(a) Rx(alpha)`` and multiplies
    each second half with the next first half, as here. It converts the rotations with
    Eigen's ``eulerAngles(0, 1, 2)`` (moving axes, ``Rx Ry Rz``), which ``ur_description``
    reads as URDF's fixed-axis ``rpy`` (``Rz Ry Rx``); the two agree when a rotation is
    about one axis (every nominal UR table) and differ otherwise (``Rx(alpha) Rz(theta)``
    read back as ``Rz(theta) Rx(alpha)``: ``sqrt(2) theta`` for ``alpha = +-pi/2``).
    :func:`ur_kinematics_text` writes URDF's ``rpy`` of the matrices, the convention the
    xacro reads.
    """
    d, a, alpha = (_six(v, name) for v, name in ((d, "d"), (a, "a"), (alpha, "alpha")))
    theta = np.zeros(6) if theta is None else _six(theta, "theta")
    if a[5] != 0.0 or alpha[5] != 0.0:
        raise ValueError(
            f"a6 = {float(a[5])!r}, alpha6 = {float(alpha[5])!r}: ur_description has no "
            "frame after wrist_3 for them (both are 0 on every UR)"
        )

    def rz_tz(k: int) -> NDArray[np.float64]:
        out = _rpy_transform(0.0, 0.0, theta[k])
        out[2, 3] = d[k]
        return out

    def tx_rx(k: int) -> NDArray[np.float64]:
        out = _rpy_transform(alpha[k], 0.0, 0.0)
        out[0, 3] = a[k]
        return out

    origins = np.stack([rz_tz(0), *(tx_rx(k - 1) @ rz_tz(k) for k in range(1, 6))])
    return URKinematics(origins, np.eye(4), np.eye(4), np.zeros(6))


def _six(values: ArrayLike, name: str) -> NDArray[np.float64]:
    out = np.asarray(values, dtype=float)
    if out.shape != (6,):
        raise ValueError(f"{name}: expected 6 values (one per UR joint), got shape {out.shape}")
    return out


def _ur_prefix(robot: Robot) -> str:
    """The ``tf_prefix`` of a URDF whose movable joints are a UR's; ExportError else."""
    names = [n for n in robot.joint_names if n.endswith(UR_JOINTS[0])]
    prefixes = [n[: -len(UR_JOINTS[0])] for n in names]
    if len(prefixes) != 1:
        found = "none" if not names else ", ".join(names)
        raise ExportError(
            f"{robot.source}: not a UR arm: ur_description's joints are "
            f"{', '.join(UR_JOINTS)} (after a tf_prefix); joints named "
            f"*{UR_JOINTS[0]}: {found} (joints: {list(robot.joint_names)})"
        )
    return prefixes[0]


def _chain_at_zero(robot: Robot, prefix: str):
    """``base_link_T_child`` and the unit axis (child frame) of each UR joint at q = 0,
    ``base_link_T_tool0`` and ``root_T_base_link``; ExportError when the path from
    ``base_link`` to ``tool0`` is not the six UR joints (in order, revolute) and fixed
    joints."""
    base, tool = f"{prefix}base_link", f"{prefix}tool0"
    for link in (base, tool):
        if link not in robot.link_names:
            raise ExportError(f"{robot.source}: not a UR arm: no link {link!r}")
    path = robot.path_joints(tool)
    parents = [j.parent for j in path]
    if base not in parents:
        raise ExportError(f"{robot.source}: not a UR arm: {base!r} is not on the path to {tool!r}")
    start = parents.index(base)
    root_T_base = np.eye(4)
    for j in path[:start]:
        root_T_base = root_T_base @ j.parent_T_child
    base_T_link = np.eye(4)
    base_T_children, axes = [], []
    movable = [j for j in path[start:] if j.type != "fixed"]
    expected = [prefix + n for n in UR_JOINTS]
    if [j.name for j in movable] != expected or any(
        j.type not in ("revolute", "continuous") for j in movable
    ):
        found = [f"{j.name} ({j.type})" for j in movable]
        raise ExportError(
            f"{robot.source}: not a UR arm: the joints from {base!r} to {tool!r} are "
            f"{found}; ur_description's are the revolute {expected}"
        )
    for j in path[start:]:
        base_T_link = base_T_link @ j.parent_T_child
        if j.type != "fixed":
            base_T_children.append(base_T_link.copy())
            axes.append(j.axis / np.linalg.norm(j.axis))
    return np.stack(base_T_children), np.stack(axes), base_T_link, root_T_base


def ur_kinematics_from_robot(robot: Robot) -> URKinematics:
    """The file's origins from a (calibrated) URDF of a UR arm, with the same forward
    kinematics of ``tool0`` up to :attr:`URKinematics.tool0_T_calibrated_tool0`.

    Parameters
    ----------
    robot : Robot
        A URDF with ``ur_description``'s ``base_link``, ``tool0`` and the six joints
        (:data:`UR_JOINTS`, after one common prefix) on the path between them, revolute,
        in order; fixed joints between them may be anything.

    Returns
    -------
    URKinematics
        With ``base_link_T_tool0(q)`` of the file's chain (:data:`BASE_LINK_T_INERTIA`,
        ``origin_i Rz(q_i)``, :data:`WRIST_3_T_TOOL0`) times ``tool0_T_calibrated_tool0``
        equal to the URDF's at every q.

    Raises
    ------
    TypeError
        ``robot`` is not a :class:`kinfw.model.Robot` (a path: load it first).
    ExportError
        Not a UR arm (which name or joint is missing or in the way), or a joint axis more
        than :data:`MAX_AXIS_TILT_DEG` off its link frame's z.

    Notes
    -----
    Link frames are placed at q = 0 in ``base_link``: ``L_0`` is
    :data:`BASE_LINK_T_INERTIA`; ``L_i`` (i = 1..5) the URDF's child link frame of joint
    i turned by ``rotation_from_axis(axis_i)`` (on the joint line, z along it); ``L_6``
    the frame on the ``wrist_3`` line nearest ``base_link_T_tool0 inv(WRIST_3_T_TOOL0)``
    (same origin projected on the line, z turned onto it by the minimal rotation). Then
    ``origin_i = inv(L_{i-1}) L_i``. Every joint i turns about its line ``(L_i z, L_i
    origin)`` in both models, so by the product of exponentials they agree at every q
    where they agree at q = 0.
    """
    robot = check_robot(robot, "robot")
    prefix = _ur_prefix(robot)
    base_T_children, axes, base_T_tool0, root_T_base = _chain_at_zero(robot, prefix)
    tilts = np.arccos(np.clip(axes[:, 2], -1.0, 1.0))
    worst = int(np.argmax(tilts))
    if np.degrees(tilts[worst]) > MAX_AXIS_TILT_DEG:
        raise ExportError(
            f"{robot.source}: joint {prefix + UR_JOINTS[worst]!r} turns about "
            f"{axes[worst].tolist()} in its link frame, {np.degrees(tilts[worst]):.3g} deg "
            f"off z; ur_description turns every joint about z, and more than "
            f"{MAX_AXIS_TILT_DEG:g} deg is not a calibration of that joint"
        )
    base_T_links = base_T_children.copy()
    base_T_links[:, :3, :3] = base_T_children[:, :3, :3] @ rotation_from_axis(axes)
    # wrist_3_link: where tool0 puts it, moved onto the wrist_3 line
    implied = base_T_tool0 @ inverse_transform(WRIST_3_T_TOOL0)
    line_z, line_p = base_T_links[5, :3, 2], base_T_links[5, :3, 3]
    wrist_3 = np.eye(4)
    wrist_3[:3, :3] = _turn_onto(implied[:3, 2], line_z) @ implied[:3, :3]
    wrist_3[:3, 3] = line_p + line_z * (line_z @ (implied[:3, 3] - line_p))
    base_T_links[5] = wrist_3
    parents = np.concatenate([BASE_LINK_T_INERTIA[None], base_T_links[:-1]])
    origins = inverse_transform(parents) @ base_T_links
    tool0_T_calibrated = inverse_transform(wrist_3 @ WRIST_3_T_TOOL0) @ base_T_tool0
    return URKinematics(origins, tool0_T_calibrated, root_T_base, tilts)


def _turn_onto(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """The minimal rotation taking unit ``u`` onto unit ``v`` (a half turn about an axis
    normal to ``u`` when ``v = -u``)."""
    w = np.cross(u, v)
    c = float(u @ v)
    if 1.0 + c < 1e-12:
        normal = np.cross(u, np.eye(3)[int(np.argmin(np.abs(u)))])
        normal /= np.linalg.norm(normal)
        return 2.0 * np.outer(normal, normal) - np.eye(3)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _kinematics_hash(values: Sequence[float]) -> str:
    digest = hashlib.sha256(" ".join(map(repr, values)).encode()).hexdigest()
    return f"kinfw_{digest[:16]}"


def ur_kinematics_text(kinematics: URKinematics) -> str:
    """The ``default_kinematics.yaml``-style text of ``kinematics``.

    Numbers by ``repr`` (exact round trip); ``roll, pitch, yaw`` are URDF's fixed-axis
    angles of each origin's rotation, checked to reproduce it. ``hash`` is
    ``kinfw_`` and 16 hex digits of the values' SHA-256: the driver compares it with the
    controller's own calibration hash and warns when they differ, which they do for any
    file not read from that controller.
    """
    import yaml

    section: dict[str, object] = {}
    values: list[float] = []
    for name, T in zip(UR_SEGMENTS, kinematics.parent_T_origins, strict=True):
        rpy = rpy_from_matrix(T[:3, :3], f"{name} origin")
        numbers = [float(v) for v in (*T[:3, 3], *rpy)]
        values += numbers
        section[name] = dict(zip(("x", "y", "z", "roll", "pitch", "yaw"), numbers, strict=True))
    section["hash"] = _kinematics_hash(values)
    header = (
        "# UR kinematics (ur_description's kinematics_parameters_file), written by kinfw\n"
        "# from a calibrated model: per joint the <origin> xyz (m) and URDF rpy (rad).\n"
    )
    return header + yaml.safe_dump({"kinematics": section}, sort_keys=False)
