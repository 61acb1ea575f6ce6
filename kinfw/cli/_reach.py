"""``kinfw reach``: use a (calibrated) model to put a frame at a pose or its origin at a
point (:mod:`kinfw.control`); exit code 0 reached, :data:`kinfw.cli.NOT_MET`
not.

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from kinfw.cli._args import add_package_dir_option, load_model, number, parse_payload
from kinfw.cli._control import (
    NOT_MET,
    UNIT_M,
    add_joint_options,
    check_distance,
    free_arg,
    joint_rows,
    joint_table,
    joints_json,
    parse_joint_values,
)
from kinfw.files import check_outputs


# -- parser -------------------------------------------------------------------------------
def add_reach_parser(sub: argparse._SubParsersAction) -> None:
    """The ``reach`` sub-command."""
    real = number(float)
    p = sub.add_parser(
        "reach",
        help="joint values that put a frame at a pose or a point",
        description="Joint values that put --frame at a pose (position and orientation) or "
        "its origin at a point, by the model: damped least squares on Pinocchio's "
        "Jacobian within the joint limits, from the start (--q) then from random starts "
        "(--restarts, --seed) until one reaches. Default free joints: every movable joint "
        f"on the path to the frame. Exit code 0 reached, {NOT_MET} not reached (the "
        "closest configuration found is printed), 2 bad input.",
    )
    add_joint_options(p)
    p.add_argument("--frame", required=True, help="the URDF link or joint that reaches")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument(
        "--pose",
        type=real,
        nargs=7,
        metavar=("X", "Y", "Z", "QX", "QY", "QZ", "QW"),
        help="the target pose in the robot's root frame: position, metres (or --unit mm), "
        "and unit quaternion, scalar last (as quat_xyzw in measurement files)",
    )
    target.add_argument(
        "--point",
        type=real,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="a target point for the frame's origin (orientation free), root frame, "
        "metres (or --unit mm)",
    )
    p.add_argument(
        "--payload",
        type=parse_payload,
        metavar="FRAME:MASS_KG[:CX,CY,CZ]",
        help="what the robot carries (centre of mass in FRAME, m): with a compliance in the "
        "model's sidecar, the command compensates its deflection under this load",
    )
    p.add_argument(
        "--gravity",
        nargs=3,
        type=real,
        metavar=("GX", "GY", "GZ"),
        help="gravity in the root frame, m/s^2, for a compliance's deflection (default: the "
        "calibration's, recorded in its sidecar, else 0 0 -9.81)",
    )
    p.add_argument(
        "--no-sidecar",
        action="store_true",
        help="ignore the calibration sidecar beside the model: the URDF alone (no "
        "compliance, gear scale or coupling of its model spec)",
    )
    p.add_argument(
        "--measured-in",
        metavar="FRAME",
        help="the target is given in this external frame (the tracker's, the mocap's) "
        "instead of the root: placed by the calibration sidecar beside the model (its "
        "measurement frame's pose of the root; a calibration's root is gauge when its "
        "data were measured in an external frame)",
    )
    p.add_argument(
        "--restarts",
        type=number(int, low=0),
        default=50,
        help="random starts after the first at most (default 50)",
    )
    p.add_argument("--seed", type=number(int, low=0), default=0, help="seed of the starts")
    p.add_argument(
        "--html",
        type=Path,
        metavar="SCENE.html",
        help="write a Meshcat scene (self-contained HTML): the robot at the answer, the "
        "target (a triad for a pose, a sphere for a point), the frame's triad, and a line "
        "from the frame to the target when not reached",
    )
    add_package_dir_option(p)
    p.set_defaults(func=cmd_reach, check_outputs=check_reach_outputs)


# -- kinfw reach -------------------------------------------------------------------------
def _reach_bound_m(robot, frame: str) -> float:
    """An upper bound of the distance from the root frame the origin of ``frame`` can
    reach: the joint origins' offsets on its path plus the prismatic joints' travel (m)."""
    import numpy as np

    bound = 0.0
    for joint in robot.path_joints(frame):
        bound += float(np.linalg.norm(joint.parent_T_child[:3, 3]))
        if joint.type == "prismatic":
            bound += max(abs(joint.lower), abs(joint.upper))
    return bound


def _reach_target(args):
    """``root_T_target`` (4, 4) from ``--pose`` or ``root_p_target`` (3,) from ``--point``
    (metres)."""
    import numpy as np

    from kinfw.geometry import transform_from_xyz_quat_xyzw
    from kinfw.observations import QUAT_NORM_TOL

    scale = UNIT_M[args.unit]
    if args.point is not None:
        return np.array(args.point, dtype=float) * scale
    xyz = np.array(args.pose[:3], dtype=float) * scale
    quat = np.array(args.pose[3:], dtype=float)
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise ValueError(
            f"--pose: the quaternion QX QY QZ QW = {' '.join(f'{v:g}' for v in quat)} has "
            f"norm {norm:.6g}; expected a unit quaternion (within {QUAT_NORM_TOL:g}), "
            "scalar last"
        )
    return transform_from_xyz_quat_xyzw(xyz, quat)


def _root_target(args, target):
    """``target`` in the root frame: as given, or from ``--measured-in FRAME`` through
    the sidecar's ``meas_T_root`` (a clear error when the sidecar is missing or measured
    in another frame)."""
    import numpy as np

    from kinfw.files import sidecar_path
    from kinfw.records import read_sidecar

    if args.measured_in is None:
        return target
    side = sidecar_path(args.model)
    if not Path(side).is_file():
        raise ValueError(
            f"--measured-in {args.measured_in}: no calibration sidecar {side} beside the "
            "model: the pose of the measurement frame comes from the calibration"
        )
    sidecar = read_sidecar(side)
    if sidecar.measurement_frame != args.measured_in:
        raise ValueError(
            f"--measured-in {args.measured_in}: the calibration {side} was measured in "
            f"{sidecar.measurement_frame or 'the root frame ' + repr('(no external frame)')}"
        )
    root_T_meas = np.linalg.inv(sidecar.w_T_root)
    if target.shape == (3,):
        return root_T_meas[:3, :3] @ target + root_T_meas[:3, 3]
    return root_T_meas @ target


def _payload(args, robot):
    """The :class:`kinfw.model.Payloads` of one sample of ``--payload``, or None; its
    frame checked, and a warning when the model has no spec for it to act on."""
    from kinfw.model import Payloads

    if args.payload is None:
        return None
    frame, mass_kg, com = args.payload
    robot.frame_id(frame)  # an unknown frame: one line naming the links
    if not robot.spec:
        warnings.warn(
            f"--payload: {args.model} has no model spec (no calibration sidecar with a "
            "compliance beside it): the payload changes nothing",
            UserWarning,
            stacklevel=1,
        )
    return Payloads.constant(1, frame, mass_kg, com)


def _gravity(args):
    """``--gravity``, else the calibration's (its sidecar's), else the standard one."""
    from kinfw.files import sidecar_path
    from kinfw.model import STANDARD_GRAVITY
    from kinfw.records import read_sidecar

    if args.gravity is not None:
        return tuple(args.gravity)
    side = sidecar_path(args.model)
    if not args.no_sidecar and Path(side).is_file():
        gravity = read_sidecar(side).gravity
        if gravity is not None:
            return tuple(gravity)
    return STANDARD_GRAVITY


def cmd_reach(args: argparse.Namespace) -> int:
    import math

    from kinfw.control import reach
    from kinfw.files import json_text

    robot = load_model(args.model, args)
    robot.frame_id(args.frame)  # an unknown frame: one line naming the links
    target = _root_target(args, _reach_target(args))
    position = target if target.shape == (3,) else target[:3, 3]
    check_distance(
        f"--{'point' if args.point is not None else 'pose'} position",
        position,
        2.0 * _reach_bound_m(robot, args.frame),
        args.unit,
    )
    q_start = parse_joint_values(robot, args.q)
    free = free_arg(robot, args.free)
    result = reach(
        robot,
        args.frame,
        target,
        q_start=q_start,
        free_joints=free,
        restarts=args.restarts,
        seed=args.seed,
        payload=_payload(args, robot),
        gravity=_gravity(args),
    )
    rows = joint_rows(robot, result.q, result.free_joints, result.at_limits)
    rotation_deg = (
        None if result.rotation_error_rad is None else math.degrees(result.rotation_error_rad)
    )
    if args.html is not None:
        from kinfw.view import write_reach_html

        write_reach_html(robot, result, args.html, package_dirs=tuple(args.package_dir))
    if args.json:
        print(
            json_text(
                {
                    "model": str(args.model),
                    "root_frame": robot.root_link,
                    "frame": result.frame,
                    "target": "pose" if args.pose is not None else "point",
                    "root_T_target": result.root_T_target.tolist(),
                    "joint_names": list(result.joint_names),
                    "q": result.q.tolist(),
                    "command": result.command.tolist(),
                    "joints": joints_json(rows),
                    "free_joints": list(result.free_joints),
                    "position_error_mm": 1e3 * result.position_error_m,
                    "rotation_error_deg": rotation_deg,
                    "reached": result.reached,
                    "at_limits": list(result.at_limits),
                    "starts": result.starts,
                    "html": None if args.html is None else str(args.html),
                }
            )
        )
        return 0 if result.reached else NOT_MET
    what = "pose" if args.pose is not None else "point"
    print(f"reaching a {what} with {result.frame!r} in {robot.root_link!r}, model {args.model}")
    print(joint_table(rows))
    if robot.spec:
        _print_command(robot, result)
    print(f"position error: {1e3 * result.position_error_m:.6f} mm")
    if rotation_deg is not None:
        print(f"rotation error: {rotation_deg:.6f} deg")
    print(f"reached: {'yes' if result.reached else 'no'}")
    print(f"at limits: {', '.join(result.at_limits) or 'none'}")
    print(f"starts used: {result.starts} of {args.restarts + 1}")
    if not result.reached:
        print(
            f"not reached: the closest configuration found is printed (exit code {NOT_MET}); "
            "more --restarts, another --q start, or the target is out of reach"
        )
    if args.html is not None:
        print(f"wrote {args.html}")
    return 0 if result.reached else NOT_MET


def _print_command(robot, result) -> None:
    """The joint command that gives the joint values through the model spec (a
    compliance's deflection compensated), the joints it changes."""
    moved = [
        (name, q, c)
        for name, q, c in zip(result.joint_names, result.q, result.command, strict=True)
        if abs(c - q) > 0
    ]
    print(
        f"command (the readings to send, {robot.spec.summary()} compensated): "
        + ", ".join(f"{n} {c:.9g} ({_change(robot, n, c - q)})" for n, q, c in moved)
        if moved
        else f"command: the joint values above ({robot.spec.summary()} changes none here)"
    )


def _change(robot, joint: str, delta: float) -> str:
    """A joint command's change, in deg (revolute) or mm (prismatic)."""
    import math

    if robot.joint(joint).is_revolute:
        return f"{math.degrees(delta):+.4f} deg"
    return f"{1e3 * delta:+.4f} mm"


def check_reach_outputs(args: argparse.Namespace) -> None:
    """``kinfw reach --html``'s scene file."""
    if args.html is not None:
        check_outputs({"--html": args.html}, inputs={"model": args.model})
