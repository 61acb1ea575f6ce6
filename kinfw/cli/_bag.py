"""``kinfw import-bag``: a ROS 1 or ROS 2 bag into a kinfw measurement file.

Reading and alignment are :func:`kinfw.measurements.read_bag` and
:func:`kinfw.measurements.measurements_from_bag`; ``--time-offset auto`` estimates the
offset with :func:`kinfw.identification.handeye.best_time_offset` on
:func:`kinfw.measurements.time_offset_streams` (the nominal URDF's forward kinematics
for the robot's poses). Like :mod:`kinfw.cli`, this module imports only the standard
library at start-up.
"""

from __future__ import annotations

import argparse
import math
import warnings
from pathlib import Path

from kinfw import progress
from kinfw.cli._args import (
    add_payload_options,
    add_xacro_option,
    load_model,
    number,
    with_payload,
)
from kinfw.files import check_output_dir, check_outputs

#: Camera (or mocap) samples the offset estimator uses at most: its hand-eye solve takes
#: all O(n^2) pairs.
OFFSET_SAMPLES = 100
#: The offsets whose objective is within this factor of the minimum are printed as the
#: estimate's flat range (how sharply the data fix it).
FLAT_FACTOR = 1.5

SECONDS = number(float, low=0.0, low_open=True, unit="(s)")
POSITIVE = number(float, low=0.0, low_open=True)


def _offset(text: str) -> float | str:
    """``--time-offset``: ``auto`` or seconds."""
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or seconds, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number of seconds, got {text!r}")
    return value


def add_import_bag_parser(sub: argparse._SubParsersAction) -> None:
    """The ``import-bag`` sub-command."""
    p = sub.add_parser(
        "import-bag",
        help="convert a ROS 1 / ROS 2 bag (joint states + mocap, points or TF) into a "
        "measurement file",
        description="Read sensor_msgs/JointState on --joint-states and one measurement "
        "stream (--pose: geometry_msgs/PoseStamped, --point: PointStamped, --tf PARENT "
        "CHILD: a chain on /tf and /tf_static) from a ROS 1 .bag or a ROS 2 bag folder, "
        "interpolate the joints linearly at each measurement stamp minus the time offset, "
        "drop measurements the joints cannot place, and write a kinfw-measurements file. "
        'Needs the rosbags package (pip install "kinfw[ros]").',
    )
    p.add_argument("bag", type=Path, help="ROS 1 .bag file or ROS 2 bag folder")
    p.add_argument("--urdf", type=Path, required=True, help="URDF naming the joints")
    add_xacro_option(p)
    _add_stream_options(p)
    _add_frame_options(p)
    _add_alignment_options(p)
    add_payload_options(p)
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="measurement file to write (JSON); with --images, the folder to write",
    )
    p.set_defaults(func=cmd_import_bag, check_outputs=check_import_bag_outputs)


def _add_stream_options(p: argparse.ArgumentParser) -> None:
    """The topics read: joint states and one measurement stream."""
    p.add_argument(
        "--joint-states",
        default="/joint_states",
        metavar="TOPIC",
        help="sensor_msgs/JointState topic (default /joint_states)",
    )
    stream = p.add_mutually_exclusive_group(required=True)
    stream.add_argument("--pose", metavar="TOPIC", help="geometry_msgs/PoseStamped topic")
    stream.add_argument("--point", metavar="TOPIC", help="geometry_msgs/PointStamped topic")
    stream.add_argument(
        "--tf",
        nargs=2,
        metavar=("PARENT", "CHILD"),
        help="pose of CHILD in PARENT composed through /tf and /tf_static",
    )
    stream.add_argument(
        "--images",
        metavar="TOPIC",
        help="sensor_msgs/Image or CompressedImage topic: write the images, their joint "
        "values (joints.csv, for kinfw detect --joints) and stamps (images.json) into the "
        "folder --out",
    )


def _add_frame_options(p: argparse.ArgumentParser) -> None:
    """What the stream measures: the URDF frame, a marker, a measurement frame, a target."""
    p.add_argument(
        "--frame",
        help="URDF frame measured, carrying the marker, or carrying the camera (--target); "
        "required but with --images",
    )
    p.add_argument(
        "--marker",
        default=None,
        help="the stream measures a marker NAME of unknown pose (offset) on --frame",
    )
    p.add_argument(
        "--measured-in",
        default=None,
        help="measurement frame, not in the URDF (default: the stream's frame_id or TF "
        "parent; the URDF root link if that is empty or the root)",
    )
    p.add_argument(
        "--target",
        default=None,
        help="read the poses as camera_T_target of a fixed target NAME seen by a camera "
        "on --frame; needs --camera-frame",
    )
    p.add_argument(
        "--camera-frame",
        default=None,
        help="with --target: the camera's own URDF link, fixed to --frame",
    )


def _add_alignment_options(p: argparse.ArgumentParser) -> None:
    """The time offset and the rules that drop measurements the joints cannot place."""
    p.add_argument(
        "--time-offset",
        type=_offset,
        default=0.0,
        metavar="auto|SECONDS",
        help="added to the joint stamps (positive: the measurement stamps lag); auto: "
        "estimated from the poses and the nominal URDF (default 0)",
    )
    p.add_argument(
        "--max-offset",
        type=SECONDS,
        default=0.1,
        metavar="SECONDS",
        help="with --time-offset auto: search offsets in [-S, S] (default 0.1)",
    )
    p.add_argument(
        "--max-gap",
        type=SECONDS,
        default=0.05,
        metavar="SECONDS",
        help="drop a measurement whose two surrounding joint states are further apart "
        "(default 0.05)",
    )
    p.add_argument(
        "--max-interpolation-error",
        type=POSITIVE,
        default=1e-3,
        metavar="RAD",
        help="drop a measurement where linear interpolation of a joint errs by more, "
        "estimated from its curvature (rad or m; default 0.001)",
    )
    p.add_argument(
        "--still",
        type=POSITIVE,
        default=None,
        metavar="SPEED",
        help="keep only measurements where every joint moves slower (rad/s or m/s): the "
        "stops of a stop-and-go recording",
    )


def check_import_bag_outputs(args: argparse.Namespace) -> None:
    """``kinfw import-bag``'s measurement file (or image folder), never the URDF or the
    bag; ``--frame`` given unless ``--images``."""
    from kinfw.measurements import IMAGE_JOINTS_CSV, IMAGE_STAMPS_JSON

    if args.images is not None:
        files = (IMAGE_JOINTS_CSV, IMAGE_STAMPS_JSON)
        check_output_dir(args.out, label="--out", files=files)
        return
    if args.frame is None:
        raise ValueError("--frame is required with --pose, --point and --tf")
    check_outputs({"--out": args.out}, inputs={"--urdf": args.urdf, "bag": args.bag})


def _rate(t_s) -> str:
    span = float(t_s[-1] - t_s[0])
    return f"{(len(t_s) - 1) / span:.1f} Hz" if span > 0 else "one stamp"


def cmd_import_bag(args: argparse.Namespace) -> int:
    """``kinfw import-bag``: a bag to a measurement file (module docstring)."""
    from kinfw.measurements import (
        check_against_robot,
        measurements_from_bag,
        read_bag,
        write_measurements,
    )

    robot = load_model(args.urdf, args)
    progress.stage(f"reading {args.bag}")
    if args.images is not None:
        return _import_images(robot, args)
    recording = read_bag(
        args.bag,
        robot=robot,
        joint_states=args.joint_states,
        pose=args.pose,
        point=args.point,
        tf=tuple(args.tf) if args.tf else None,
        max_gap_s=args.max_gap,
    )
    joints, measured = recording.joints, recording.measured
    counts = {name: (msgtype, n) for name, msgtype, n in recording.topics}
    print(
        f"read {args.bag} (ROS {recording.ros_version}): {len(recording.topics)} topics; "
        f"{joints.topic}: {joints.n_messages} messages, {_rate(joints.t_s[0])}, joints "
        f"{', '.join(joints.names)}"
        + (f" (not in the URDF, not read: {', '.join(joints.ignored)})" if joints.ignored else "")
    )
    msgtype = counts.get(measured.source, ("tf2_msgs/msg/TFMessage", 0))[0]
    print(
        f"{measured.source} ({msgtype}): {len(measured.t_s)} {measured.kind}s, "
        f"{_rate(measured.t_s)}, in {measured.parent or '(no frame_id)'!r}"
    )
    offset_s = args.time_offset
    if offset_s == "auto":
        offset_s = _estimate_offset(recording, robot, args)
    measurements, alignment = measurements_from_bag(
        recording,
        robot=robot,
        frame=args.frame,
        offset_s=offset_s,
        marker=args.marker,
        measured_in=args.measured_in,
        target=args.target,
        camera_frame=args.camera_frame,
        max_gap_s=args.max_gap,
        max_interpolation_error=args.max_interpolation_error,
        still_speed=args.still,
    )
    measurements = with_payload(measurements, args)
    check_against_robot(measurements, robot)
    write_measurements(args.out, measurements)
    _print_alignment(alignment, args)
    (group,) = measurements.all_groups()
    print(
        f"wrote {args.out}: {measurements.n_samples} samples, joints "
        f"{', '.join(measurements.joint_names)}; {type(group).kind} observations of "
        f"{args.camera_frame if args.target is not None else args.frame!r}"
    )
    return 0


def _print_alignment(alignment, args: argparse.Namespace) -> None:
    """The offset used, how many measurements were kept and, per reason, dropped."""
    rules = {
        "outside": "outside the joint states' time range",
        "gap": f"joint states more than {args.max_gap:g} s apart",
        "fast": f"interpolation error above {args.max_interpolation_error:g}",
        "moving": f"a joint faster than {args.still:g}" if args.still else "",
    }
    dropped = ", ".join(f"{n} {r} ({rules[r]})" for r, n in alignment.dropped.items() if n)
    n_dropped = alignment.n_measured - len(alignment.kept)
    print(
        f"paired at time offset {alignment.offset_s:+.4f} s: kept {len(alignment.kept)} of "
        f"{alignment.n_measured} measurements"
        + (f", dropped {n_dropped}: {dropped}" if n_dropped else "")
    )


def _estimate_offset(recording, robot, args: argparse.Namespace) -> float:
    """``--time-offset auto``: the estimate, printed with its objective and flat range."""
    import numpy as np

    from kinfw.identification.handeye import best_time_offset
    from kinfw.measurements import time_offset_streams

    streams = time_offset_streams(recording, robot, args.frame, target=args.target is not None)
    step = max(1, math.ceil(len(streams[2]) / OFFSET_SAMPLES))
    # one task around the search: the hand-eye fit of each candidate offset is an inner loop
    with progress.task("time offset: a hand-eye fit per candidate offset", 1) as search:
        result = best_time_offset(
            *streams,
            search_s=(-args.max_offset, args.max_offset),
            max_gap_s=args.max_gap,
            step=step,
        )
        search.advance()
    spreads, offsets = result.position_spreads, result.offsets_s
    best = int(np.argmin(spreads))
    flat = spreads <= FLAT_FACTOR * spreads[best]
    lo = hi = best
    while lo > 0 and flat[lo - 1]:
        lo -= 1
    while hi < len(flat) - 1 and flat[hi + 1]:
        hi += 1
    print(
        f"time offset (auto, {result.n_pairs} samples, offsets {offsets[0]:+.3f} to "
        f"{offsets[-1]:+.3f} s): {result.offset_s:+.4f} s; implied constant pose spread "
        f"{result.position_spread * 1e3:.3g} mm (median); within {FLAT_FACTOR:g}x of it "
        f"for offsets {offsets[lo]:+.4f} to {offsets[hi]:+.4f} s"
    )
    if result.offset_s in (offsets[0], offsets[-1]):
        warnings.warn(
            f"the best time offset {result.offset_s:+.4f} s is at the edge of the search "
            f"range; widen it (--max-offset > {args.max_offset:g})",
            stacklevel=1,
        )
    return result.offset_s


def _import_images(robot, args: argparse.Namespace) -> int:
    """``kinfw import-bag --images``: the images and their joint values into a folder."""
    from kinfw.measurements import IMAGE_JOINTS_CSV, IMAGE_STAMPS_JSON, write_bag_images

    if args.time_offset == "auto":
        raise ValueError(
            "--time-offset auto needs poses (--pose, --tf); with --images give the offset "
            "in seconds (estimate it from the board poses: run kinfw detect, then "
            "kinfw handeye, or import a pose stream of the same recording)"
        )
    if args.payload is not None or args.gravity is not None:
        raise ValueError(
            "--payload and --gravity go into a measurement file; --images writes images "
            "(kinfw detect writes the measurement file from them)"
        )
    written = write_bag_images(
        args.bag,
        args.out,
        robot=robot,
        images=args.images,
        joint_states=args.joint_states,
        offset_s=args.time_offset,
        max_gap_s=args.max_gap,
        max_interpolation_error=args.max_interpolation_error,
        still_speed=args.still,
    )
    _print_alignment(written.alignment, args)
    print(
        f"wrote {args.out}: {len(written.files)} images, {IMAGE_JOINTS_CSV} (joints "
        f"{', '.join(written.joint_names)}) and {IMAGE_STAMPS_JSON}; next: kinfw detect "
        f"{args.out}/image_* --joints {args.out / IMAGE_JOINTS_CSV} --board ... --camera ... "
        f"--frame CAMERA_FRAME"
    )
    return 0
