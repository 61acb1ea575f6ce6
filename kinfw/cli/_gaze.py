"""``kinfw gaze``: use a (calibrated) model to fixate a point with a head's cameras
(:mod:`kinfw.control`); exit code 0 fixated, :data:`kinfw.cli.NOT_MET` not.

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from kinfw.cli._args import (
    add_package_dir_option,
    camera_inputs,
    frame_file,
    load_model,
    number,
)
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

log = logging.getLogger("kinfw")

#: ``gaze`` warns about a point farther than this from the root frame (m): a head looks at
#: things metres away; a point kilometres away is usually millimetres given as metres.
GAZE_PLAUSIBLE_M = 100.0


# -- parser -------------------------------------------------------------------------------
def add_gaze_parser(sub: argparse._SubParsersAction) -> None:
    """The ``gaze`` sub-command."""
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
    add_joint_options(p)
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
    add_package_dir_option(p)
    p.set_defaults(func=cmd_gaze, check_outputs=check_gaze_outputs)


# -- kinfw gaze --------------------------------------------------------------------------
def _camera_rays(args, cameras: tuple[str, ...]):
    """The rays of ``--pixel`` (one per camera), or None for the optical axes."""
    import numpy as np

    from kinfw.camera import CameraError, read_camera

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

    from kinfw.cli._args import frames_arg
    from kinfw.control import fixate
    from kinfw.files import json_text

    robot = load_model(args.model, args)
    cameras = frames_arg(args.cameras, robot.default_cameras, "--cameras", robot)
    for c in cameras:
        robot.frame_id(c)  # an unknown frame: one line naming the links
    q_start = parse_joint_values(robot, args.q)
    free = free_arg(robot, args.free)
    rays = _camera_rays(args, cameras)
    point = np.array(args.point, dtype=float) * UNIT_M[args.unit]
    check_distance("--point", point, GAZE_PLAUSIBLE_M, args.unit)
    fix = fixate(robot, point, cameras=cameras, camera_rays=rays, q_start=q_start, free_joints=free)
    rows = joint_rows(robot, fix.q, fix.free_joints, fix.at_limits)
    errors_deg = np.degrees(fix.error_rad)
    if args.html is not None:
        from kinfw.view import write_gaze_html

        write_gaze_html(robot, fix, args.html, package_dirs=tuple(args.package_dir))
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
                    "command": fix.command.tolist(),
                    "joints": joints_json(rows),
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
    print(joint_table(rows))
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
    rank of the rays' motion (:attr:`kinfw.control.Fixation.rank`)."""
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


def check_gaze_outputs(args: argparse.Namespace) -> None:
    """``kinfw gaze --html``'s scene file."""
    if args.html is not None:
        check_outputs({"--html": args.html}, inputs={"model": args.model, **camera_inputs(args)})
