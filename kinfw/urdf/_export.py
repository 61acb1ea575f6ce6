"""Write a calibrated kinematic model back into the robot's own URDF.

:func:`export_urdf` takes the nominal robot and a calibrated screw geometry
(:class:`kinfw.model.ZeroGeometry`, the joint lines and end-frame poses at ``q = 0`` in the
measurement frame ``w``) and returns the URDF text with new joint origins and axes only;
:func:`edit_urdf` (:mod:`kinfw.urdf`, re-exported here with :class:`ExportError`)
is the text editor underneath, which changes exactly the elements it is asked to and
keeps everything else (comments, ``<transmission>``, ``<gazebo>``, ``<calibration>``,
meshes, attribute order, whitespace) as lxml parsed it.

Why changing origins and axes is enough (product of exponentials): the forward kinematics
of a tree is ``w_T_e(q) = prod_j exp(S_j q_j) w_T_e(0)`` over the joints on ``e``'s
chain, so two models whose joint lines ``S_j`` and end-frame poses ``w_T_e(0)`` agree at
``q = 0`` agree at every configuration. The exporter therefore places, at ``q = 0``,
each measured joint's child link frame on the calibrated line and each end frame at its
calibrated pose, and keeps every other link frame where the nominal URDF has it.

Frames: ``w`` is the measurement frame, ``C_L`` (``w_T_L`` in code) the calibrated pose
of link ``L`` at ``q = 0``, and ``old_T_new`` the shift of a link frame that had to move
so that it lies on its calibrated joint axis (its visuals, collisions and inertials are
re-expressed so they stay where they were).
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw.files import write_text_atomic
from kinfw.geometry import inverse_transform, register_points
from kinfw.model import JointInfo, Robot, ZeroGeometry
from kinfw.urdf._edit import SAME_TOL, ExportError, edit_urdf

ON_AXIS_TOL = 1e-9
"""Largest distance (m) of a revolute end frame's origin from its calibrated axis."""

_MIN_LEVER_M = 0.1


@dataclass(frozen=True, slots=True)
class ExportResult:
    """A calibrated URDF and what the export decided.

    Attributes
    ----------
    urdf_xml : str
        The calibrated URDF text.
    w_T_root : ndarray, shape (4, 4)
        Pose of the URDF root link in the measurement frame ``w`` (metres). Identity when
        the root link is the measurement frame; otherwise the estimated placement, which
        is reported here and not written into the URDF.
    link_shifts : tuple of (str, ndarray of shape (4, 4))
        Links whose frame had to move onto a calibrated axis (or onto a measured end
        frame), as ``old_T_new``: the new frame in the nominal one. Their visuals,
        collisions, inertials and other child joints were re-expressed so they did not move.
    """

    urdf_xml: str
    w_T_root: NDArray[np.float64]
    link_shifts: tuple[tuple[str, NDArray[np.float64]], ...]


def export_urdf(
    robot: Robot,
    geometry: ZeroGeometry,
    *,
    root_is_measurement_frame: bool = True,
    base_motion: NDArray[np.float64] | None = None,
) -> ExportResult:
    """A URDF whose Pinocchio FK reproduces a calibrated screw geometry exactly.

    Parameters
    ----------
    robot : Robot
        The nominal robot; its URDF text is edited.
    geometry : ZeroGeometry
        Calibrated joint lines and end-frame poses at q = 0 in the measurement frame
        ``w`` (metres), with ``geometry.topology == robot.topology(frames)``.
    root_is_measurement_frame : bool, keyword-only
        True when ``w`` is the URDF root link (a dataset without ``measured_in``). Then a
        fixed root-to-base joint (the root's only child joint, when it is fixed) takes the
        registered world-to-base placement. False when ``w`` is external: the root's
        placement in ``w`` is estimated and returned, not written.
    base_motion : ndarray, shape (4, 4), optional
        The rigid motion ``w_T_base`` of the whole nominal robot that the calibration
        estimated (:attr:`kinfw.identification.RefineResult.w_T_base`). With the root as
        the measurement frame and a fixed root-to-base joint, that joint takes the
        nominal base placement moved by it, instead of a registration of the end frames:
        joints whose lines only moved with the base (not estimated, or exact) then keep
        their origins and axes. Ignored otherwise.

    Returns
    -------
    ExportResult
        The URDF: loaded with :func:`kinfw.model.load_robot`, its
        ``frame_poses(qs, e, topology.joint_names)`` equals
        ``inv(w_T_root) @ w_T_e(q)`` of the geometry for every end frame ``e``.

    Raises
    ------
    ExportError
        If the geometry does not belong to this robot, or an end frame is the child link
        of a revolute joint but its calibrated origin is more than ``ON_AXIS_TOL`` off the
        calibrated axis (a link frame must lie on its joint axis), or the root link is an
        end frame that is not at the anchor pose.

    Notes
    -----
    Walk from the root, parents first. With ``C_P`` the new pose of the parent link in
    ``w``, ``D_P`` its shift ``old_T_new`` and ``O_k`` the nominal origin of joint k, the
    child's candidate pose is ``A_C = C_P inv(D_P) O_k`` (where the nominal URDF puts it).
    A measured revolute joint's child is moved from ``A_C`` to the closest point of the
    calibrated line (orientation kept), a measured prismatic joint's child stays at
    ``A_C``, and its axis becomes ``R_C^T d``. An end frame takes its calibrated pose;
    below a fixed joint its body really moved (no shift), below a movable joint the link
    shifts. Everything else stays at ``A_C``. The anchor (base or root) is placed by
    :func:`_register_frames` so that the measured frames move as little as possible.
    """
    topology = robot.topology(geometry.topology.frames)
    if topology != geometry.topology:
        raise ExportError(
            f"geometry.topology {geometry.topology} does not match the robot's "
            f"topology for its frames: {topology}"
        )
    w_T_root, w_T_placed = _anchor(robot, geometry, root_is_measurement_frame, base_motion)
    lines = {name: j for j, name in enumerate(topology.joint_names)}
    w_T_links = {robot.root_link: w_T_root}
    old_T_news: dict[str, NDArray[np.float64]] = {}
    joint_origins: dict[str, NDArray[np.float64]] = {}
    joint_axes: dict[str, NDArray[np.float64]] = {}
    for joint in _joints_from_root(robot):
        w_T_parent = w_T_links[joint.parent]
        new_T_old = inverse_transform(old_T_news.get(joint.parent, np.eye(4)))
        w_T_candidate = w_T_parent @ new_T_old @ joint.parent_T_child
        w_T_child = w_T_placed.get(joint.child)
        if joint.name in lines:
            j = lines[joint.name]
            old_T_new = _shift_onto_line(
                joint, w_T_candidate, geometry.axes[j], geometry.points[j], w_T_child
            )
            if _close(old_T_new, np.eye(4), SAME_TOL):  # rounding only: keep the nominal frame
                old_T_new = np.eye(4)
            else:
                old_T_news[joint.child] = old_T_new
            w_T_child = w_T_candidate @ old_T_new
            joint_axes[joint.name] = w_T_child[:3, :3].T @ _unit(geometry.axes[j])
        elif w_T_child is None:  # stays on its parent's old frame (link_shifts re-express it)
            w_T_links[joint.child] = w_T_candidate
            continue
        joint_origins[joint.name] = inverse_transform(w_T_parent) @ w_T_child
        w_T_links[joint.child] = w_T_child
    xml = edit_urdf(
        robot.urdf_xml, joint_origins=joint_origins, joint_axes=joint_axes, link_shifts=old_T_news
    )
    return ExportResult(urdf_xml=xml, w_T_root=w_T_root, link_shifts=tuple(old_T_news.items()))


def _unit(v: ArrayLike) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _close(a: NDArray[np.float64], b: NDArray[np.float64], tol: float) -> bool:
    return bool(np.abs(a - b).max() <= tol)


def _joints_from_root(robot: Robot) -> list[JointInfo]:
    """Every URDF joint, parents first (breadth first, document order among siblings)."""
    by_parent: dict[str, list[JointInfo]] = {}
    for joint in robot.joints:
        by_parent.setdefault(joint.parent, []).append(joint)
    order: list[JointInfo] = []
    links = [robot.root_link]
    for link in links:  # grows while iterating: a breadth-first queue
        for joint in by_parent.get(link, []):
            order.append(joint)
            links.append(joint.child)
    return order


def _shift_onto_line(
    joint: JointInfo,
    w_T_candidate: NDArray[np.float64],
    axis: ArrayLike,
    point: ArrayLike,
    w_T_end: NDArray[np.float64] | None,
) -> NDArray[np.float64]:
    """Shift ``old_T_new`` of a measured joint's child link from its candidate pose.

    Parameters
    ----------
    joint : JointInfo
    w_T_candidate : ndarray, shape (4, 4)
        Where the nominal URDF puts the child link (the "old" frame), in ``w``.
    axis, point : array_like, shape (3,)
        Direction and a point (m) of the calibrated joint line in ``w``.
    w_T_end : ndarray, shape (4, 4), or None
        Calibrated pose of the child link when it is an end frame.

    Returns
    -------
    ndarray, shape (4, 4)
        To the end frame when the child is one; else, for a revolute joint, the pure
        translation onto the closest point of the line (rotation exactly identity, so
        rounding does not build up along a chain); else identity.
    """
    if w_T_end is not None:
        old_T_end = inverse_transform(w_T_candidate) @ w_T_end
        if joint.is_revolute:
            _check_on_line(joint, w_T_end[:3, 3], axis, point)
        return old_T_end
    old_T_new = np.eye(4)
    if joint.is_revolute:
        w_p_foot = _closest_point(w_T_candidate[:3, 3], axis, point)
        old_T_new[:3, 3] = w_T_candidate[:3, :3].T @ (w_p_foot - w_T_candidate[:3, 3])
    return old_T_new


def _closest_point(
    w_p: NDArray[np.float64], axis: ArrayLike, point: ArrayLike
) -> NDArray[np.float64]:
    """The point of the line ``(axis, point)`` closest to ``w_p`` (all in ``w``, metres)."""
    direction, point = _unit(axis), np.asarray(point, dtype=float)
    return point + ((w_p - point) @ direction) * direction


def _check_on_line(
    joint: JointInfo, w_p_end: NDArray[np.float64], axis: ArrayLike, point: ArrayLike
) -> None:
    distance = np.linalg.norm(w_p_end - _closest_point(w_p_end, axis, point))
    if distance > ON_AXIS_TOL:
        raise ExportError(
            f"end frame {joint.child!r} is the child link of revolute joint {joint.name!r}, "
            f"so its origin must lie on the joint axis, but the calibrated origin is "
            f"{distance:.3g} m off the calibrated axis; measure a frame attached to "
            f"{joint.child!r} by a fixed joint instead (add a fixed child link such as a "
            "tool or plate frame to the URDF)"
        )


def _anchor(
    robot: Robot,
    geometry: ZeroGeometry,
    root_is_measurement_frame: bool,
    base_motion: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]]]:
    """``w_T_root`` and the links placed outright: ``{link: w_T_link}`` at q = 0.

    The placed links are the end-frame links (a joint frame is its child link's frame at
    q = 0) and, under a fixed root-to-base joint, the base. The anchor (that base, or the
    root when ``w`` is external) is the nominal one moved by ``base_motion`` when given
    (the base), else registered so that the nominal end frames land on the calibrated
    ones.
    """
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    frames = geometry.topology.frames
    root_T_ends = np.stack([data.oMf[robot.frame_id(f)].homogeneous for f in frames])
    w_T_placed: dict[str, NDArray[np.float64]] = {}
    for frame, w_T_e in zip(frames, geometry.w_T_frames, strict=True):
        link = frame if frame in robot.link_names else robot.joint(frame).child
        if link in w_T_placed and not _close(w_T_placed[link], w_T_e, ON_AXIS_TOL):
            raise ExportError(
                f"end frames {frames} name link {link!r} twice with different calibrated poses"
            )
        w_T_placed[link] = np.asarray(w_T_e, dtype=float)
    w_T_root = np.eye(4)
    root_joints = [j for j in robot.joints if j.parent == robot.root_link]
    if not root_is_measurement_frame:
        w_T_root = _register_frames(root_T_ends, geometry.w_T_frames)
    elif len(root_joints) == 1 and root_joints[0].type == "fixed":
        base = root_joints[0].child
        root_T_base = data.oMf[robot.frame_id(base)].homogeneous
        if base_motion is not None:
            w_T_base = np.asarray(base_motion, dtype=float) @ root_T_base
        else:
            w_T_base = _register_frames(
                inverse_transform(root_T_base) @ root_T_ends, geometry.w_T_frames
            )
        w_T_placed.setdefault(base, w_T_base)
    root = robot.root_link
    if root in w_T_placed and not _close(w_T_placed[root], w_T_root, ON_AXIS_TOL):
        raise ExportError(
            f"end frame {root!r} is the root link, whose pose in the measurement "
            "frame is fixed by the anchor; it cannot take its calibrated pose"
        )
    return w_T_root, w_T_placed


def _register_frames(
    a_T_frames: NDArray[np.float64], w_T_frames: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Least-squares rigid ``w_T_a`` with ``w_T_a @ a_T_frames ~ w_T_frames``.

    Parameters
    ----------
    a_T_frames : ndarray, shape (E, 4, 4)
        Nominal end-frame poses in the anchor frame ``a``, metres.
    w_T_frames : ndarray, shape (E, 4, 4)
        Calibrated end-frame poses in ``w``, metres.

    Returns
    -------
    ndarray, shape (4, 4)

    Notes
    -----
    Arun, Huang & Blostein (1987) SVD registration (Shih et al. eqs. 16–22) of four
    points per frame, its origin and origin + L x / y / z with ``L = max(0.1 m, largest
    distance between the frame origins)``, with the det = -1 reflection fix. A single
    frame gives the exact ``w_T_e @ inv(a_T_e)``.
    """
    if len(a_T_frames) == 1:
        return w_T_frames[0] @ inverse_transform(a_T_frames[0])
    origins = a_T_frames[:, :3, 3]
    lever = max(_MIN_LEVER_M, np.linalg.norm(origins[:, None] - origins[None], axis=-1).max())

    def points(T: NDArray[np.float64]) -> NDArray[np.float64]:
        axes = np.swapaxes(T[:, :3, :3], 1, 2) * lever  # rows: L x, L y, L z
        return np.concatenate([T[:, :3, 3], (T[:, None, :3, 3] + axes).reshape(-1, 3)])

    return register_points(points(a_T_frames), points(w_T_frames))


def write_urdf(path: str | PathLike[str], result_or_xml: ExportResult | str) -> None:
    """Write an exported URDF (or URDF text) to ``path`` as UTF-8, exactly as given.

    The text keeps the XML declaration of the input URDF when it had one; newlines are
    not translated. The file is written atomically
    (:func:`kinfw.files.write_text_atomic`): a failure leaves a previous file intact.
    """
    xml = result_or_xml.urdf_xml if isinstance(result_or_xml, ExportResult) else result_or_xml
    write_text_atomic(path, xml, newline="")
