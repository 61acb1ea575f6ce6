"""``kinfw gaze`` and ``kinfw reach``: use a (calibrated) model to fixate a point with a
head's cameras (:mod:`kinfw.control.gaze`) or to put a frame at a pose or point
(:mod:`kinfw.control.reach`).

Exit codes (both commands): 0 when the point is fixated / the target reached (within
1e-6 rad and 1e-6 m by the model), :data:`NOT_MET` (3) when it is not (the closest
achievable answer is still printed), 2 on bad input, 1 on an internal error.

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Callable
from pathlib import Path

__all__ = ["NOT_MET", "add_control_parsers", "cmd_gaze", "cmd_reach", "parse_joint_values"]

log = logging.getLogger("kinfw")

#: Exit code when the point is not fixated / the target not reached (output printed).
NOT_MET = 3
#: ``gaze`` warns about a point farther than this from the root frame (m): a head looks at
#: things metres away; a point kilometres away is usually millimetres given as metres.
GAZE_PLAUSIBLE_M = 100.0

_UNIT_M = {"m": 1.0, "mm": 1e-3}
_JOINT_SUFFIXES = {"deg": ("revolute", math.pi / 180.0), "mm": ("prismatic", 1e-3)}


# -- parser ------------------------------------------------------------------------------
def _joint_value(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` of ``--q`` (the value is checked against the joint later)."""
    name, sep, value = text.partition("=")
    if not sep or not name or not value:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    return name.strip(), value.strip()


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", type=Path, help="URDF of the robot (nominal or calibrated)")
    p.add_argument(
        "--unit",
        choices=tuple(_UNIT_M),
        default="m",
        help="length unit of the target's position (default m)",
    )
    p.add_argument(
        "--q",
        action="append",
        type=_joint_value,
        default=[],
        metavar="NAME=VALUE",
        help="start value of a joint, and its value if it is not solved for: rad or m "
        "(URDF units), or with a unit, 30deg or 250mm; joints not given start at the "
        "middle of their range (repeatable)",
    )
    p.add_argument(
        "--free",
        metavar="J1,J2,...",
        help="joints to solve for, comma-separated (default: see the command's description)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def add_control_parsers(
    sub: argparse._SubParsersAction,
    number: Callable[..., Callable[[str], float | int]],
    frame_file: Callable[[str], tuple[str, Path]],
) -> None:
    """The ``gaze`` and ``reach`` sub-commands (``number``: :func:`kinfw.cli_args.number`,
    ``frame_file``: the ``FRAME=FILE`` parser of ``--camera``)."""
    real = number(float)
    p = sub.add_parser(
        "gaze",
        help="joint values that fixate a 3D point with the head's cameras",
        description="Joint values that put a point on every camera's optical axis (or on "
        "a pixel, --pixel), by the model: a closed-form start, then bounded Gauss-Newton "
        "on Pinocchio's kinematics, within the joint limits. When no joint values fixate "
        "the point (out of range, or a vertical disparity between the cameras that no "
        "joint removes), the closest achievable fixation and each camera's remaining "
        "angle. Default free joints: each camera's own joints and the shared joints "
        "nearest the cameras, two per camera (pan, tilt and both vergences on the IIS "
        f"head). Exit code 0 fixated, {NOT_MET} not fixated, 2 bad input.",
    )
    _add_common(p)
    p.add_argument(
        "--point",
        type=real,
        nargs=3,
        required=True,
        metavar=("X", "Y", "Z"),
        help="the point in the robot's root frame (the measurement frame; the IIS head's "
        "'world', the stereo rig), metres (or --unit mm)",
    )
    p.add_argument(
        "--cameras",
        help="camera frames, comma-separated (z = optical axis; default: the URDF's hint)",
    )
    p.add_argument(
        "--pixel",
        type=real,
        nargs=2,
        metavar=("U", "V"),
        help="see the point at this pixel (OpenCV convention, px) in every camera, "
        "instead of on the optical axis; needs --camera for every camera",
    )
    p.add_argument(
        "--camera",
        action="append",
        type=frame_file,
        metavar="FRAME=FILE",
        help="with --pixel: intrinsics of camera FRAME (ROS camera_info / OpenCV YAML or "
        "JSON file), one per camera (repeatable)",
    )
    p.add_argument(
        "--html",
        type=Path,
        metavar="SCENE.html",
        help="write a Meshcat scene (self-contained HTML): the robot at the solution, each "
        "camera's aimed ray to the point's distance, and the point",
    )
    p.set_defaults(func=cmd_gaze)

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
    _add_common(p)
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
        "--restarts",
        type=number(int, low=0),
        default=50,
        help="random starts after the first at most (default 50)",
    )
    p.add_argument("--seed", type=number(int, low=0), default=0, help="seed of the starts")
    p.set_defaults(func=cmd_reach)


# -- shared ------------------------------------------------------------------------------
def parse_joint_values(robot, given: list[tuple[str, str]]):
    """The start configuration (all movable joints, URDF units): the middle of each
    range, overridden by ``--q NAME=VALUE`` (VALUE in rad / m, or with a ``deg`` / ``mm``
    suffix). Raises ValueError naming the joint and the joints there are."""
    from kinfw.control.solver import middle_configuration

    q = middle_configuration(robot)
    names = robot.joint_names
    seen: set[str] = set()
    for name, text in given:
        if name not in names:
            raise ValueError(f"--q {name}={text}: no movable joint {name!r}; joints: {list(names)}")
        if name in seen:
            raise ValueError(f"--q {name}={text}: joint {name!r} is given twice")
        seen.add(name)
        kind = "revolute" if robot.joint(name).is_revolute else "prismatic"
        scale, number = 1.0, text
        for suffix, (suffix_kind, suffix_scale) in _JOINT_SUFFIXES.items():
            if text.endswith(suffix):
                if kind != suffix_kind:
                    raise ValueError(
                        f"--q {name}={text}: {name!r} is {kind}; '{suffix}' is for "
                        f"{suffix_kind} joints"
                    )
                scale, number = suffix_scale, text[: -len(suffix)]
        try:
            value = float(number) * scale
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise ValueError(
                f"--q {name}={text}: expected a number ({'rad' if kind == 'revolute' else 'm'}"
                f", or with '{'deg' if kind == 'revolute' else 'mm'}')"
            )
        q[names.index(name)] = value
    return q


def _free_arg(robot, text: str | None) -> tuple[str, ...] | None:
    if text is None:
        return None
    free = tuple(v for v in text.replace(",", " ").split() if v)
    if not free:
        raise ValueError("--free: expected joint names, comma-separated")
    unknown = [n for n in free if n not in robot.joint_names]
    if unknown:
        raise ValueError(
            f"--free: no movable joint {', '.join(map(repr, unknown))}; joints: "
            f"{list(robot.joint_names)}"
        )
    twice = sorted({n for n in free if free.count(n) > 1})
    if twice:
        raise ValueError(f"--free: joint {', '.join(map(repr, twice))} given twice")
    return free


def _check_distance(where: str, position_m, plausible_m: float, unit: str) -> None:
    """Refuse a target more than 1,000 km from the root frame (not a length in metres)
    and warn beyond ``plausible_m``: usually millimetres given as metres."""
    import numpy as np

    hint = "; were millimetres given as metres? (--unit mm)" if unit == "m" else ""
    largest = float(np.max(np.abs(position_m)))
    distance_m = (
        largest * float(np.linalg.norm(np.asarray(position_m) / largest)) if largest else 0.0
    )
    if distance_m > 1e6:
        raise ValueError(f"{where} is {distance_m:.3g} m from the root frame{hint}")
    if distance_m > plausible_m:
        log.warning("%s is %.4g m from the root frame%s", where, distance_m, hint)


def _joint_rows(robot, q, free: tuple[str, ...], at_limits: tuple[str, ...]) -> list[dict]:
    """Per joint: URDF value and display value (deg / mm), free, at a limit."""
    rows = []
    for name, value in zip(robot.joint_names, q, strict=True):
        revolute = robot.joint(name).is_revolute
        rows.append(
            {
                "joint": name,
                "value": float(value),
                "display": math.degrees(value) if revolute else 1e3 * value,
                "unit": "deg" if revolute else "mm",
                "free": name in free,
                "at_limit": name in at_limits,
            }
        )
    return rows


def _joint_table(rows: list[dict]) -> str:
    from kinfw.cli_tables import format_table

    table = [
        [
            r["joint"],
            f"{r['display']:.4f}",
            r["unit"],
            "free" if r["free"] else "held",
            "at limit" if r["at_limit"] else "",
        ]
        for r in rows
    ]
    return format_table(table, ["joint", "value", "unit", "solved", "limit"])


def _joints_json(rows: list[dict]) -> dict:
    return {
        r["joint"]: {
            "value": r["value"],
            r["unit"]: r["display"],
            "free": r["free"],
            "at_limit": r["at_limit"],
        }
        for r in rows
    }


# -- kinfw gaze --------------------------------------------------------------------------
def _camera_rays(args, cameras: tuple[str, ...]):
    """The rays of ``--pixel`` (one per camera), or None for the optical axes."""
    import numpy as np

    from kinfw.camera_model import CameraError, read_camera

    given = args.camera or []
    if args.pixel is None:
        if given:
            raise ValueError(
                f"--camera {given[0][0]}={given[0][1]}: intrinsics are only used with --pixel"
            )
        return None
    intrinsics = {}
    for frame, file in given:
        if frame in intrinsics:
            raise ValueError(f"--camera {frame}={file}: camera {frame!r} is given twice")
        if frame not in cameras:
            raise ValueError(
                f"--camera {frame}={file}: {frame!r} is not one of the cameras {list(cameras)}"
            )
        try:
            intrinsics[frame] = read_camera(file)
        except CameraError as exc:
            raise ValueError(f"--camera {frame}={file}: {exc}") from None
    missing = [c for c in cameras if c not in intrinsics]
    if missing:
        raise ValueError(
            f"--pixel {args.pixel[0]:g} {args.pixel[1]:g}: needs the intrinsics of every "
            f"camera; give --camera FRAME=FILE for {', '.join(missing)}"
        )
    uv = np.array(args.pixel, dtype=float)
    for c in cameras:
        cam = intrinsics[c]
        if not (0.0 <= uv[0] <= cam.width - 1 and 0.0 <= uv[1] <= cam.height - 1):
            log.warning(
                "--pixel %g %g is outside camera %r's image (%d x %d px)",
                *uv,
                c,
                cam.width,
                cam.height,
            )
    return np.array([intrinsics[c].rays(uv) for c in cameras])


def cmd_gaze(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.cli_args import frames_arg
    from kinfw.control.gaze import GazeSolver
    from kinfw.files import json_text
    from kinfw.robot import load_robot

    robot = load_robot(args.model)
    cameras = frames_arg(args.cameras, robot.default_cameras, "--cameras", robot)
    for c in cameras:
        robot.frame_id(c)  # an unknown frame: one line naming the links
    q_start = parse_joint_values(robot, args.q)
    free = _free_arg(robot, args.free)
    rays = _camera_rays(args, cameras)
    point = np.array(args.point, dtype=float) * _UNIT_M[args.unit]
    _check_distance("--point", point, GAZE_PLAUSIBLE_M, args.unit)
    solver = GazeSolver(robot, cameras, free_joints=free)
    fix = solver.fixate(point, camera_rays=rays, q_start=q_start)
    rows = _joint_rows(robot, fix.q, fix.free_joints, fix.at_limits)
    errors_deg = np.degrees(fix.error_rad)
    if args.html is not None:
        from kinfw.view_gaze import write_gaze_html

        write_gaze_html(robot, fix, args.html)
    if args.json:
        print(
            json_text(
                {
                    "model": str(args.model),
                    "root_frame": robot.root_link,
                    "point_m": point.tolist(),
                    "pixel": None if args.pixel is None else list(args.pixel),
                    "cameras": list(fix.cameras),
                    "camera_rays": fix.camera_rays.tolist(),
                    "joint_names": list(fix.joint_names),
                    "q": fix.q.tolist(),
                    "joints": _joints_json(rows),
                    "free_joints": list(fix.free_joints),
                    "error_deg": dict(zip(fix.cameras, errors_deg.tolist(), strict=True)),
                    "fixated": fix.fixated,
                    "closest_achievable": not fix.fixated,
                    "at_limits": list(fix.at_limits),
                    "iterations": fix.iterations,
                    "html": None if args.html is None else str(args.html),
                }
            )
        )
        return 0 if fix.fixated else NOT_MET
    aim = "optical axes" if args.pixel is None else f"pixel ({args.pixel[0]:g}, {args.pixel[1]:g})"
    print(
        f"fixating ({', '.join(f'{v:.4f}' for v in point)}) m in {robot.root_link!r} with "
        f"{', '.join(fix.cameras)} ({aim}), model {args.model}"
    )
    print(_joint_table(rows))
    for c, e in zip(fix.cameras, errors_deg, strict=True):
        print(f"{c}: {e:.4f} deg between the ray and the point")
    print(f"fixated: {'yes' if fix.fixated else 'no'}")
    print(f"at limits: {', '.join(fix.at_limits) or 'none'}")
    if not fix.fixated:
        print(
            f"closest achievable fixation: no joint values put the point on every ray "
            f"({_why_not_fixated(fix)}); these leave {max(errors_deg):.4f} deg at most "
            "(see docs/control.md)"
        )
    if args.html is not None:
        print(f"wrote {args.html}")
    return 0 if fix.fixated else NOT_MET


def _why_not_fixated(fix) -> str:
    """Why a fixation is only the closest achievable, from its joints at limits and the
    rank of the rays' motion (:attr:`kinfw.control.gaze.Fixation.rank`)."""
    needed = 2 * len(fix.cameras)
    if fix.at_limits:
        return f"{', '.join(fix.at_limits)} at a limit"
    if len(fix.free_joints) < needed:
        return (
            f"{len(fix.free_joints)} free joint(s) for {len(fix.cameras)} camera(s): "
            f"aiming needs {needed} (--free)"
        )
    if fix.rank < needed:
        return (
            f"the free joints turn the rays in only {fix.rank} of {needed} directions, and "
            "this point needs another: the cameras' geometry (on the IIS head, a vertical "
            "disparity no joint removes) or a joint that does not aim (a roll about an "
            "optical axis)"
        )
    return "out of reach from this start: try another --q start"


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

    from kinfw.measurements import QUAT_NORM_TOL
    from kinfw.transforms import transform_from_xyz_quat_xyzw

    scale = _UNIT_M[args.unit]
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


def cmd_reach(args: argparse.Namespace) -> int:
    import math

    from kinfw.control.reach import reach
    from kinfw.files import json_text
    from kinfw.robot import load_robot

    robot = load_robot(args.model)
    robot.frame_id(args.frame)  # an unknown frame: one line naming the links
    target = _reach_target(args)
    position = target if target.shape == (3,) else target[:3, 3]
    _check_distance(
        f"--{'point' if args.point is not None else 'pose'} position",
        position,
        2.0 * _reach_bound_m(robot, args.frame),
        args.unit,
    )
    q_start = parse_joint_values(robot, args.q)
    free = _free_arg(robot, args.free)
    result = reach(
        robot,
        args.frame,
        target,
        q_start=q_start,
        free_joints=free,
        restarts=args.restarts,
        seed=args.seed,
    )
    rows = _joint_rows(robot, result.q, result.free_joints, result.at_limits)
    rotation_deg = (
        None if result.rotation_error_rad is None else math.degrees(result.rotation_error_rad)
    )
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
                    "joints": _joints_json(rows),
                    "free_joints": list(result.free_joints),
                    "position_error_mm": 1e3 * result.position_error_m,
                    "rotation_error_deg": rotation_deg,
                    "reached": result.reached,
                    "at_limits": list(result.at_limits),
                    "starts": result.starts,
                }
            )
        )
        return 0 if result.reached else NOT_MET
    what = "pose" if args.pose is not None else "point"
    print(f"reaching a {what} with {result.frame!r} in {robot.root_link!r}, model {args.model}")
    print(_joint_table(rows))
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
    return 0 if result.reached else NOT_MET
