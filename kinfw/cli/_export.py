"""``kinfw export``: a calibrated URDF in the forms ROS 2 loads.

::

    kinfw export robot-description CALIBRATED.urdf --out DIR
    kinfw export ur-kinematics CALIBRATED.urdf --out my_robot_calibration.yaml

``robot-description`` writes the URDF, ``robot_state_publisher``'s parameter file and a
launch file (:func:`kinfw.urdf.write_robot_description`); ``ur-kinematics`` writes, for a
UR arm, the kinematics file ``ur_description`` reads (:func:`kinfw.urdf.ur_kinematics_from_robot`)
and prints what the file cannot hold. Like the other command modules, only the standard
library is imported at start-up.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinfw.cli._args import add_xacro_option, load_model
from kinfw.files import check_output_dir, check_outputs, check_writable, write_text_atomic

_ON_TOL = 1e-9  # m and rad: an offset below this is rounding


def add_export_parser(sub: argparse._SubParsersAction) -> None:
    """The ``export`` sub-command and its two kinds."""
    p = sub.add_parser(
        "export",
        help="write a calibrated URDF for ROS 2 (robot_description, UR kinematics YAML)",
        description="Write a (calibrated) URDF in the forms ROS 2 loads.",
    )
    kinds = p.add_subparsers(dest="kind", required=True, metavar="KIND")
    rd = kinds.add_parser(
        "robot-description",
        help="robot_state_publisher's parameter file and a launch file",
        description="Write DIR/robot_description.urdf, DIR/robot_state_publisher.yaml "
        "(robot_state_publisher: ros__parameters: robot_description: the URDF) and "
        "DIR/robot_description.launch.py (a robot_state_publisher node reading the URDF "
        "next to it).",
    )
    rd.add_argument("urdf", metavar="URDF", help="the calibrated URDF (or xacro, or - for stdin)")
    rd.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    add_xacro_option(rd)
    rd.set_defaults(func=_cmd_robot_description, check_outputs=_check_dir)
    ur = kinds.add_parser(
        "ur-kinematics",
        help="Universal Robots' kinematics YAML (ur_description's kinematics_parameters_file)",
        description="Write the kinematics file of a UR arm (per joint x, y, z, roll, "
        "pitch, yaw; ur_calibration's format, which ur_description reads) from a "
        "calibrated URDF with ur_description's base_link, tool0 and six joints. Joint "
        "axes off their link frame's z are re-expressed (the link frames turn by the "
        "tilt, printed); a tool0 off the wrist_3 axis, which the file cannot hold, is "
        "printed as tool0_T_calibrated_tool0 for the mount of what is on tool0.",
    )
    ur.add_argument("urdf", metavar="URDF", help="the calibrated URDF (or xacro, or - for stdin)")
    ur.add_argument(
        "--out", type=Path, required=True, metavar="FILE.yaml", help="the kinematics file"
    )
    add_xacro_option(ur)
    ur.set_defaults(func=_cmd_ur_kinematics, check_outputs=_check_file)


def _inputs(args: argparse.Namespace) -> dict[str, Path]:
    return {} if args.urdf == "-" else {"URDF": Path(args.urdf)}


def _check_dir(args: argparse.Namespace) -> None:
    from kinfw.urdf import ROBOT_DESCRIPTION_FILES

    files = tuple(ROBOT_DESCRIPTION_FILES.values())
    check_output_dir(args.out, label="--out", files=files)
    if args.out.is_dir():  # the URDF read may be one of the files written
        for name in files:
            check_writable(args.out / name, label=f"--out .../{name}", inputs=_inputs(args))


def _check_file(args: argparse.Namespace) -> None:
    check_outputs({"--out": args.out}, inputs=_inputs(args))


def _cmd_robot_description(args: argparse.Namespace) -> int:
    from kinfw.urdf import write_robot_description

    robot = load_model(args.urdf, args)
    for path in write_robot_description(args.out, robot.urdf_xml):
        print(f"kinfw export: wrote {path}")
    _print_left_out(robot, "the robot_description")
    return 0


def _print_left_out(robot, where: str) -> None:
    """Name what a URDF-only output leaves out of a calibration (its model spec, read
    from the sidecar beside the URDF): nothing is dropped silently."""
    if robot.spec:
        print(
            f"  {where} holds the geometry only; it leaves out {robot.spec.summary()}, which "
            "no URDF holds: see the calibration's sidecar and per-joint YAML (*.joints.yaml)"
        )


def _xyz_rpy_line(name: str, T) -> str:
    import numpy as np
    import pinocchio as pin

    xyz = np.array2string(1e3 * T[:3, 3], precision=4, suppress_small=True)
    rpy = np.array2string(np.degrees(pin.rpy.matrixToRpy(T[:3, :3])), precision=5)
    return f"{name}: xyz [mm] {xyz}  rpy [deg] {rpy}"


def _cmd_ur_kinematics(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.geometry import rotation_angle
    from kinfw.urdf import UR_JOINTS, ur_kinematics_from_robot, ur_kinematics_text

    robot = load_model(args.urdf, args)
    kinematics = ur_kinematics_from_robot(robot)
    write_text_atomic(args.out, ur_kinematics_text(kinematics))
    print(f"kinfw export: wrote {args.out} (UR kinematics of {robot.source})")
    _print_left_out(robot, "the UR kinematics file")
    tilts = np.degrees(kinematics.axis_tilts_rad)
    if tilts[:5].max() > 0.0:
        turned = ", ".join(f"{j} {t:.4f}" for j, t in zip(UR_JOINTS[:5], tilts, strict=False))
        print(f"  joint axes re-expressed on z; link frames (and meshes) turned [deg]: {turned}")
    offset = kinematics.tool0_T_calibrated_tool0
    off_m = float(np.linalg.norm(offset[:3, 3]))
    off_rad = float(rotation_angle(offset[:3, :3]))
    if off_m > _ON_TOL or off_rad > _ON_TOL:
        print(
            f"  the calibrated tool0 is {1e3 * off_m:.4g} mm / {np.degrees(off_rad):.4g} deg "
            "off the tool0 the file gives (it is off the wrist_3 axis); the file cannot "
            "hold it: put this on the mount of what is on tool0:"
        )
        print("  " + _xyz_rpy_line("tool0_T_calibrated_tool0", offset))
    if not np.allclose(kinematics.root_T_base_link, np.eye(4), rtol=0.0, atol=_ON_TOL):
        root = robot.root_link
        print(
            f"  base_link in {root} (ur_robot's origin block, not in the file): "
            + _xyz_rpy_line("", kinematics.root_T_base_link).lstrip(": ")
        )
    return 0
