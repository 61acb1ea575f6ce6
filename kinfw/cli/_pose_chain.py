"""``kinfw pose-chain``: a robot known only by its logged hand poses, as a URDF and a joints
file ``kinfw detect`` reads (:mod:`kinfw.model._pose_chain`).

    kinfw pose-chain POSES.csv --camera-frame camera --urdf-out chain.urdf \\
        --joints-out joints.csv
    kinfw detect IMAGES... --board SPEC --joints joints.csv --camera INTRINSICS.yaml \\
        --frame camera --out data.json
    kinfw calibrate data.json --urdf chain.urdf --out calibrated.urdf

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path

from kinfw.files import check_outputs, write_text_atomic

_METRES_PER = {"m": 1.0, "mm": 1e-3}


def add_pose_chain_parser(sub: argparse._SubParsersAction) -> None:
    """The ``pose-chain`` sub-command."""
    p = sub.add_parser(
        "pose-chain",
        help="hand poses without joint values: a six-joint chain URDF and its joints file",
        description="Read the hand's logged poses (base_T_hand: a CSV with the columns hand_x, "
        "hand_y, hand_z, hand_qx, hand_qy, hand_qz, hand_qw, or x, y, z, qx, qy, qz, qw, "
        "quaternion scalar last, and optionally 'image' naming each row's image) and "
        "write a URDF whose six joints (x, y, z prismatic; yaw, pitch, roll revolute) put"
        " its hand at each pose exactly, with the camera's link on a fixed joint, and the"
        " joints file kinfw detect pairs with the images. The URDF declares the chain's"
        " joints exact (<kinfw exact>), so kinfw calibrate fits the frames only: the "
        "camera's mount and the board's pose from the pixels.",
    )
    p.add_argument("poses", type=Path, help="CSV of the hand's poses in the base")
    p.add_argument(
        "--camera-frame",
        required=True,
        help="the camera's optical frame: a link on a fixed joint (identity start) whose "
        "origin, the mount, kinfw calibrate estimates",
    )
    p.add_argument(
        "--setup",
        choices=("eye-in-hand", "eye-to-hand"),
        default="eye-in-hand",
        help="the camera on the hand, a board fixed (default); or the camera fixed to the "
        "base, the board on the hand (detect --target-frame HAND)",
    )
    p.add_argument("--hand", default="hand", help="name of the hand's link (default hand)")
    p.add_argument("--base", default="base", help="name of the base link (default base)")
    p.add_argument(
        "--unit",
        choices=("m", "mm"),
        default="m",
        help="length unit of the CSV's positions (default m)",
    )
    p.add_argument("--urdf-out", type=Path, required=True, help="URDF to write")
    p.add_argument("--joints-out", type=Path, required=True, help="joints CSV to write")
    p.set_defaults(func=cmd_pose_chain, check_outputs=check_pose_chain_outputs)


def cmd_pose_chain(args: argparse.Namespace) -> int:
    """``kinfw pose-chain``: the chain's URDF and joint values."""
    from kinfw.measurements import read_hand_poses
    from kinfw.model import POSE_CHAIN_JOINTS, pose_chain_joint_values, pose_chain_urdf

    poses = read_hand_poses(args.poses)
    base_T_hands = poses.base_T_hands.copy()
    base_T_hands[:, :3, 3] *= _METRES_PER[args.unit]
    urdf = pose_chain_urdf(
        camera=args.camera_frame,
        hand=args.hand,
        base=args.base,
        camera_on="hand" if args.setup == "eye-in-hand" else "base",
    )
    q = pose_chain_joint_values(base_T_hands)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow((["image"] if poses.images else []) + list(POSE_CHAIN_JOINTS))
    for i, row in enumerate(q):
        writer.writerow(([poses.images[i]] if poses.images else []) + [repr(float(v)) for v in row])
    write_text_atomic(args.urdf_out, urdf)
    write_text_atomic(args.joints_out, out.getvalue())
    board = "" if args.setup == "eye-in-hand" else f" --target-frame {args.hand}"
    print(
        f"wrote {args.urdf_out} (joints {', '.join(POSE_CHAIN_JOINTS)}; {args.camera_frame!r} "
        f"on {args.hand if args.setup == 'eye-in-hand' else args.base!r}) and "
        f"{args.joints_out} ({len(q)} rows{', keyed by image' if poses.images else ''}); next:\n"
        f"  kinfw detect IMAGES... --board SPEC --joints {args.joints_out} "
        f"--camera INTRINSICS.yaml --frame {args.camera_frame}{board} --out DATA.json\n"
        f"  kinfw calibrate DATA.json --urdf {args.urdf_out} --out CALIBRATED.urdf"
    )
    return 0


def check_pose_chain_outputs(args: argparse.Namespace) -> None:
    """``kinfw pose-chain``'s URDF and joints file, never the poses CSV."""
    check_outputs(
        {"--urdf-out": args.urdf_out, "--joints-out": args.joints_out},
        inputs={"poses": args.poses},
    )
