"""``kinfw simulate``: perturb a nominal URDF into a "true" robot and simulate its
measurements (stage 1 poses one joint at a time, stage 2 camera observations or images of a
board, rendered as PNG files with ``--images``, or a plan file's configurations;
motion-capture markers in an unknown frame, probes touching a plane),
:mod:`kinfw.simulation`.

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from kinfw.cli._args import (
    COUNT,
    DEG,
    MM,
    SEED,
    add_camera_option,
    add_xacro_option,
    camera_inputs,
    frames_arg,
    load_model,
    number,
    parse_payload,
)
from kinfw.files import check_output_dir, check_outputs, write_text_atomic


# -- parser -------------------------------------------------------------------------------
def add_simulate_parser(sub: argparse._SubParsersAction) -> None:
    """The ``simulate`` sub-command."""
    p = sub.add_parser(
        "simulate",
        help="simulate measurements of a perturbed robot",
        description="Perturb the nominal URDF into a 'true' robot and simulate "
        "its measurements: stage 1 poses of --frames, one joint at a time "
        "(Shih et al. section 4.1); stage 2 camera observations of a fixed "
        "target at random configurations, or images of a board (--pixels, rendered "
        "with --images); motion-capture markers (--markers); probes touching a plane "
        "(--contacts).",
    )
    p.add_argument(
        "--urdf", type=Path, default=None, help="nominal URDF (default: the built-in IIS-head)"
    )
    add_xacro_option(p)
    p.add_argument("--out", type=Path, required=True, help="measurement file to write (JSON)")
    p.add_argument("--truth-out", type=Path, required=True, help="true robot URDF to write")
    p.add_argument(
        "--per-joint",
        type=COUNT,
        default=9,
        help="stage 1 measurements per joint (default 9, as the paper)",
    )
    _add_noise_options(p)
    _add_configuration_options(p)
    _add_pixel_options(p)
    _add_probe_options(p)
    p.add_argument(
        "--plan",
        type=Path,
        default=None,
        help="a plan file (kinfw plan --out): measure at its configurations, in its order "
        "(stage 1 and stage 2), instead of one joint at a time / random",
    )
    p.add_argument(
        "--compliance",
        action="append",
        type=_compliance_spec,
        metavar="[JOINT=]RAD_PER_NM",
        help="the true robot's joint compliance under gravity: one value for every joint "
        "on the measured paths, or JOINT=VALUE (repeatable; the others rigid), rad/Nm "
        "(m/N for a prismatic joint); the file records the readings that deflect to the "
        "simulated configurations (calibrate it with --model compliance)",
    )
    p.add_argument(
        "--payloads",
        type=parse_payload,
        metavar="FRAME:MAX_KG[:CX,CY,CZ]",
        help="every sample carries a load on FRAME of a mass drawn uniformly in 0 .. MAX_KG, "
        "its centre of mass at CX,CY,CZ in FRAME (m); written as the samples' payloads "
        "(with --compliance the deflection follows it)",
    )
    p.add_argument(
        "--gravity",
        nargs=3,
        type=number(float),
        metavar=("GX", "GY", "GZ"),
        help="gravity in the URDF root frame, m/s^2 (default 0 0 -9.81), written to the file",
    )
    p.add_argument(
        "--truth-model",
        action="append",
        type=_truth_block,
        metavar="SPEC[@VALUES]",
        help="more of what the true robot's URDF cannot hold, at its true values "
        "(repeatable): gear-scale:JOINT@S, coupling:JOINT=K*OTHER, compliance:J1,J2@C1,C2 "
        "(the --model specs of calibrate; VALUES comma-separated, one per entry)",
    )
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_simulate, check_outputs=check_simulate_outputs)


def _truth_block(text: str):
    """A block of ``--truth-model SPEC[@VALUES]``, started at its true values."""
    from kinfw.model import block_from_spec

    spec, _, values = text.partition("@")
    try:
        block = block_from_spec(spec)
        if values:
            block = block.with_start([float(v) for v in values.split(",")])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    if block.size == 0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: name the joints (compliance:J1,J2@C1,C2), or use --compliance"
        )
    return block


def _compliance_spec(text: str) -> tuple[str | None, float]:
    """``VALUE`` or ``JOINT=VALUE`` of ``--compliance``."""
    joint, _, value = text.rpartition("=")
    try:
        c = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected RAD_PER_NM or JOINT=RAD_PER_NM (a number >= 0)"
        ) from None
    if not (c >= 0 and c < float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r}: the compliance must be finite and >= 0")
    return joint or None, c


def _truth_options(args: argparse.Namespace) -> dict:
    """What the true robot's URDF cannot hold and what loads it: the keyword arguments
    ``compliance``, ``truth_model``, ``payloads`` and ``gravity`` of :func:`kinfw.simulate`."""
    from kinfw.model import ModelSpec

    return {
        "compliance": _compliance_arg(args.compliance),
        "truth_model": ModelSpec(tuple(args.truth_model)) if args.truth_model else None,
        "payloads": args.payloads,
        "gravity": args.gravity,
    }


def _compliance_arg(entries) -> float | dict[str, float] | None:
    """``--compliance`` as :func:`kinfw.simulate` takes it."""
    if not entries:
        return None
    if len(entries) == 1 and entries[0][0] is None:
        return entries[0][1]
    if any(joint is None for joint, _ in entries):
        raise ValueError("--compliance: give one VALUE for every joint, or JOINT=VALUE entries")
    return dict(entries)


def _add_noise_options(p: argparse.ArgumentParser) -> None:
    """``simulate``: the measurement noise and the true robot's errors."""
    p.add_argument(
        "--noise-mm",
        type=MM,
        default=0.5,
        help="position noise sigma per axis, mm (default 0.5); of the distance of contacts",
    )
    p.add_argument(
        "--noise-deg", type=DEG, default=0.5, help="rotation noise angle sigma, deg (default 0.5)"
    )
    p.add_argument(
        "--stereo-mm",
        type=MM,
        default=None,
        help="simulate the stereo rig: point noise sigma on the nine-circle "
        "plate, mm (replaces --noise-mm/--noise-deg for stage 1 poses)",
    )
    p.add_argument(
        "--error-mm",
        type=MM,
        default=2.0,
        help="true robot: joint origin error sigma, mm (default 2)",
    )
    p.add_argument(
        "--error-deg",
        type=DEG,
        default=0.5,
        help="true robot: joint origin and axis error sigma, deg (default 0.5)",
    )


def _add_configuration_options(p: argparse.ArgumentParser) -> None:
    """``simulate``: the stages, their configurations and the frames observed."""
    p.add_argument(
        "--fraction",
        type=number(float, low=0.0, high=1.0, low_open=True),
        default=0.8,
        help="fraction of each joint range used (default 0.8)",
    )
    p.add_argument(
        "--stage",
        choices=("1", "2", "both"),
        default=None,
        help="stage 1 (one joint at a time), 2 (random configurations seen by the cameras) "
        "or both (default 1; with --pixels: both, and 1 is an error; with --markers or "
        "--contacts and no --pixels: neither)",
    )
    p.add_argument(
        "--stage2-samples",
        type=COUNT,
        default=30,
        help="stage 2 random configurations (default 30)",
    )
    p.add_argument("--frames", help="stage 1 frames, comma-separated (default: URDF hint)")
    p.add_argument("--cameras", help="stage 2 cameras, comma-separated (default: URDF hint)")


def _add_pixel_options(p: argparse.ArgumentParser) -> None:
    """``simulate``: stage 2 as images of a board (``--pixels``) and the cameras."""
    p.add_argument(
        "--pixels",
        action="store_true",
        help="stage 2 as images: the corners of a fixed --board seen by each camera "
        "('pixels' observations; a corner is seen when in front of the camera, within 60 "
        "deg of its axis and 5 px inside the image; an image is dropped when the board is "
        "seen more than 70 deg from its normal, or with fewer than 4 corners, all of a "
        "chessboard's, or corners on one line; configurations where no camera sees the "
        "board are drawn again)",
    )
    p.add_argument(
        "--pixel-sigma",
        type=number(float, low=0.0, unit="px"),
        default=0.5,
        help="with --pixels: pixel noise sigma per image coordinate, px (default 0.5)",
    )
    p.add_argument(
        "--board",
        default=None,
        help="with --pixels: the board, chessboard:COLSxROWS:SQUARE_M or "
        "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] (default chessboard:9x6:0.04)",
    )
    add_camera_option(p)
    p.add_argument(
        "--images",
        type=Path,
        metavar="DIR",
        default=None,
        help="with --pixels (implied): also render each image of the board as a PNG, in "
        "DIR/CAMERA/ with the configurations (joints.csv) and intrinsics (camera.json) "
        "that kinfw detect reads",
    )
    p.add_argument(
        "--target-frame",
        metavar="LINK",
        default=None,
        help="with --pixels: the board rides on URDF frame LINK (eye-to-hand: a board on the "
        "flange seen by a camera on a link fixed to the root), centred on its origin and "
        "facing the cameras at the middle of the joint ranges; default fixed in the world",
    )
    p.add_argument(
        "--image-noise",
        type=number(float, low=0.0),
        default=2.0,
        help="with --images: Gaussian noise of each pixel, grey levels of 255 (default 2)",
    )


def _point_spec(text: str) -> tuple[str, tuple[float, float, float] | None]:
    """``FRAME`` or ``FRAME:X,Y,Z`` (metres) -> ``(frame, offset or None)``."""
    frame, _, xyz = text.partition(":")
    if not frame.strip():
        raise argparse.ArgumentTypeError(f"expected FRAME or FRAME:X,Y,Z, got {text!r}")
    if not xyz:
        return frame.strip(), None
    try:
        x, y, z = (float(v) for v in xyz.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected FRAME:X,Y,Z (three numbers, metres), got {text!r}"
        ) from None
    if not all(map(math.isfinite, (x, y, z))):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return frame.strip(), (x, y, z)


def _plane_spec(text: str) -> tuple[float, float, float, float]:
    """``NX,NY,NZ,D`` -> the four numbers (a non-zero normal)."""
    nx, ny, nz, d = _numbers_spec(4, "NX,NY,NZ,D")(text)
    if nx == ny == nz == 0.0:
        raise argparse.ArgumentTypeError(f"expected a non-zero normal: {text!r}")
    return nx, ny, nz, d


def _numbers_spec(count: int, what: str) -> Callable[[str], tuple[float, ...]]:
    """An argparse type: ``count`` finite numbers separated by commas (``what`` names
    them in the message)."""

    def parse(text: str) -> tuple[float, ...]:
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            values = ()
        if len(values) != count or not all(map(math.isfinite, values)):
            raise argparse.ArgumentTypeError(f"expected {what} ({count} numbers), got {text!r}")
        return values

    return parse


def _add_probe_options(p: argparse.ArgumentParser) -> None:
    """``simulate``: motion-capture markers and contacts (plane, ball, point)."""
    p.add_argument(
        "--markers",
        type=_point_spec,
        action="append",
        metavar="FRAME[:X,Y,Z]",
        help="a motion-capture marker on URDF frame FRAME at X,Y,Z (m, in FRAME; default "
        "a random 5 cm offset), measured at --mocap-samples random configurations in "
        "--mocap-frame; its offset is left to the calibration (repeatable: marker1, "
        "marker2, ...)",
    )
    p.add_argument(
        "--mocap-frame",
        default="mocap",
        help="the frame the markers are measured in: a name not in the URDF (its pose is "
        "random and left to the calibration; default mocap) or the URDF's root",
    )
    p.add_argument(
        "--mocap-samples",
        type=COUNT,
        default=40,
        help="random configurations at which the markers are measured (default 40)",
    )
    p.add_argument(
        "--contacts",
        type=_point_spec,
        action="append",
        metavar="FRAME[:X,Y,Z]",
        help="a probe on URDF frame FRAME at X,Y,Z (m, in FRAME; default a random 5 cm "
        "offset) that touches the plane (--sphere: the ball; --point: the point) at "
        "--contact-samples configurations (random ones projected onto the contact); its "
        "offset is left to the calibration (repeatable: probe1, probe2, ...)",
    )
    p.add_argument(
        "--plane",
        type=_plane_spec,
        metavar="NX,NY,NZ,D",
        default=None,
        help="the plane {x : n . x = d} in the URDF root (d in m; n is normalised); "
        "default normal to the root's z through the first probe at the middle of the "
        "joint ranges",
    )
    p.add_argument(
        "--sphere",
        type=_numbers_spec(4, "CX,CY,CZ,R"),
        metavar="CX,CY,CZ,R",
        default=None,
        help="instead of a plane, a ball of centre CX,CY,CZ in the URDF root and radius R "
        "(m) that the probes touch: 'sphere' observations with the radius given and the "
        "centre left to the calibration",
    )
    p.add_argument(
        "--point",
        type=_numbers_spec(3, "CX,CY,CZ"),
        metavar="CX,CY,CZ",
        default=None,
        help="instead of a plane, a point (a divot) in the URDF root (m) that the probes "
        "are placed on in many orientations: 'divot' observations (--noise-mm per axis), "
        "the point left to the calibration",
    )
    p.add_argument(
        "--plane-name",
        default=None,
        help="the name of the plane (ball, point) in the file (default table, ball, divot)",
    )
    p.add_argument(
        "--plane-frame",
        metavar="LINK",
        default=None,
        help="the URDF link the plane is fixed to (a table link on fixed joints from the "
        "root): --plane is given in it, and the file's plane observations are measured_in "
        "it (default: the root)",
    )
    p.add_argument(
        "--contact-samples",
        type=COUNT,
        default=60,
        help="contacts per probe (default 60)",
    )
    p.add_argument(
        "--offsets-known",
        action="store_true",
        help="write the markers' and probes' offsets into the file (known to the "
        "calibration) instead of leaving them to be estimated",
    )


# -- kinfw simulate ----------------------------------------------------------------------
def _intrinsics(args, cameras: tuple[str, ...]) -> dict:
    """The intrinsics of ``--camera FRAME=FILE``, each FRAME a stage 2 camera."""
    from kinfw.camera import CameraError, read_camera

    given = {}
    for frame, file in args.camera or ():
        if frame not in cameras:
            raise ValueError(
                f"--camera {frame}={file}: {frame!r} is not a stage 2 camera "
                f"(cameras: {', '.join(cameras)})"
            )
        try:
            given[frame] = read_camera(file)
        except CameraError as exc:
            raise ValueError(f"--camera {frame}={file}: {exc}") from None
    return given


def _pixel_summary(sim, sigma_px: float) -> dict:
    """The board, its true pose (``root_T_board``: in ``target_frame`` when the board is
    on one) and the images and corners per camera of ``--pixels`` data."""
    return {
        "board": sim.board,
        "target_frame": sim.target_frame,
        "root_T_board": sim.w_T_board.tolist(),
        "sigma_px": sigma_px,
        "cameras": [
            {
                "camera": g.camera,
                "images": len(g.images()[0]),
                "points": len(g.sample),
                "default": g.camera in sim.default_cameras,
            }
            for g in sim.data.groups("pixels")
        ],
    }


def cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.measurements import write_measurements
    from kinfw.simulation import simulate_measurements

    nominal = load_model(args.urdf, args)
    args.pixels = args.pixels or args.images is not None
    markers, contacts = args.markers or [], args.contacts or []
    if args.pixels and args.stage == "1":
        raise ValueError(
            "--pixels --stage 1: --pixels makes stage 2 images; give --stage 2 or both "
            "(the default with --pixels)"
        )
    if args.stage is not None:
        stages = {"1": (1,), "2": (2,), "both": (1, 2)}[args.stage]
    else:  # --pixels are stage 2 images: with the stage 1 poses by default
        stages = (1, 2) if args.pixels else () if (markers or contacts) else (1,)
    frames = (
        frames_arg(args.frames, nominal.default_frames, "--frames", nominal) if 1 in stages else ()
    )
    cameras = (
        frames_arg(args.cameras, nominal.default_cameras, "--cameras", nominal)
        if 2 in stages
        else ()
    )
    probe_frames = [frame for frame, _ in (*markers, *contacts)]
    on = () if args.target_frame is None else (args.target_frame,)
    names = nominal.topology((*frames, *cameras, *probe_frames, *on)).joint_names
    sim = simulate_measurements(
        nominal,
        stages=stages,
        frames=frames,
        cameras=cameras,
        per_joint=args.per_joint,
        stage2_samples=args.stage2_samples,
        fraction=args.fraction,
        noise_m=args.noise_mm * 1e-3,
        noise_rad=np.radians(args.noise_deg),
        stereo_sigma_m=None if args.stereo_mm is None else args.stereo_mm * 1e-3,
        error_mm=args.error_mm,
        error_deg=args.error_deg,
        pixels=args.pixels,
        pixel_sigma=args.pixel_sigma,
        board=args.board,
        intrinsics=_intrinsics(args, cameras) if args.pixels and cameras else None,
        configurations=_plan_qs(args.plan, names) if args.plan is not None else None,
        markers=markers,
        mocap_frame=args.mocap_frame,
        mocap_samples=args.mocap_samples,
        contacts=contacts,
        plane=args.plane,
        plane_name=args.plane_name,
        plane_frame=args.plane_frame,
        sphere=args.sphere,
        point=args.point,
        contact_samples=args.contact_samples,
        offsets_known=args.offsets_known,
        target_frame=args.target_frame,
        **_truth_options(args),
        seed=args.seed,
    )
    write_measurements(args.out, sim.data)
    write_text_atomic(args.truth_out, sim.truth_xml)
    if args.images is not None and sim.w_T_board is not None:
        from kinfw.camera import parse_board
        from kinfw.simulation import write_board_images

        write_board_images(
            args.images,
            sim,
            parse_board(sim.board),
            noise_sigma=args.image_noise,
            rng=np.random.default_rng([args.seed, 1]),
        )
    _print_simulated(args, sim)
    return 0


def _true_model(truth) -> list[dict] | None:
    """The true robot's model spec (its blocks' names and true values), None when the
    truth is the URDF alone."""
    return truth.spec.to_list() if truth.spec else None


def _print_simulated(args: argparse.Namespace, sim) -> None:
    """What ``kinfw simulate`` wrote: the JSON summary (``--json``) or a few lines."""
    data = sim.data
    pixels = _pixel_summary(sim, args.pixel_sigma) if args.pixels and sim.cameras else None
    probes = _probe_summary(sim)
    if args.json:
        print(
            json.dumps(
                {
                    "pixels": pixels,
                    **probes,
                    "images": None if args.images is None else str(args.images),
                    "data": str(args.out),
                    "truth": str(args.truth_out),
                    "n_samples": data.n_samples,
                    "frames": list(data.observed_frames),
                    "noise_mm": args.noise_mm,
                    "noise_deg": args.noise_deg,
                    "stereo_mm": args.stereo_mm,
                    "error_mm": args.error_mm,
                    "error_deg": args.error_deg,
                    "truth_model": _true_model(sim.truth),
                    "seed": args.seed,
                },
                indent=2,
            )
        )
        return
    poses = bool(sim.frames) or (bool(sim.cameras) and not args.pixels)
    noise = (
        [f"{args.noise_mm} mm", f"{args.noise_deg} deg"]
        if poses
        else [f"{args.noise_mm} mm"]
        if sim.markers or sim.probes
        else []
    )
    if args.stereo_mm is not None and sim.frames:
        noise.append(f"stereo rig {args.stereo_mm} mm per point")
    print(
        f"wrote {args.out}: {data.n_samples} samples of {', '.join(data.observed_frames)}"
        + (f" (noise {', '.join(noise)})" if noise else "")
    )
    if pixels is not None:
        print(
            f"  stage 2 as images of {pixels['board']}"
            + ("" if sim.target_frame is None else f" on {sim.target_frame!r}")
            + f" (pixel noise {args.pixel_sigma:g} px): "
            + "; ".join(
                f"{c['camera']}: {c['images']} images, {c['points']} corners"
                + (" (default intrinsics: 640x480, fx = fy = 600 px)" if c["default"] else "")
                for c in pixels["cameras"]
            )
        )
    if args.images is not None and pixels is not None:
        print(
            f"  rendered the images in {args.images}/CAMERA/ (PNG, joints.csv, camera.json; "
            f"image noise {args.image_noise:g} grey levels) for kinfw detect"
        )
    for key, title in (("markers", "marker"), ("probes", "probe")):
        for p in probes[key]:
            xyz = ", ".join(f"{1e3 * v:.1f}" for v in p["offset_m"])
            print(f"  {title} {p['name']} on {p['frame']}: true offset ({xyz}) mm")
    if probes["mocap_T_root"] is not None:
        print(f"  markers measured in {probes['mocap_frame']!r}, a frame of random pose")
    if probes["plane"] is not None:
        n, d = probes["plane"][:3], probes["plane"][3]
        print(
            f"  plane {probes['plane_name']!r}: n = ({', '.join(f'{v:.4f}' for v in n)}), "
            f"d = {d:.4f} m in the root"
            + (f", fixed to {probes['plane_frame']!r}" if probes["plane_frame"] else "")
        )
    for key, what in (("sphere", "ball"), ("point", "point")):
        if probes[key] is not None:
            c = ", ".join(f"{v:.4f}" for v in probes[key][:3])
            radius = f", radius {probes[key][3]:.4f} m" if key == "sphere" else ""
            print(f"  {what} {probes['plane_name']!r}: centre ({c}) m{radius}")
    print(
        f"wrote {args.truth_out}: the true robot (nominal with errors of "
        f"{args.error_mm} mm / {args.error_deg} deg, seed {args.seed})"
    )


def _probe_summary(sim) -> dict:
    """The markers, probes, mocap frame and plane of a simulation, JSON-ready."""

    def listed(points):
        return [{"frame": p.frame, "name": p.name, "offset_m": p.offset.tolist()} for p in points]

    return {
        "markers": listed(sim.markers),
        "mocap_frame": sim.mocap_frame,
        "mocap_T_root": None if sim.mocap_T_w is None else sim.mocap_T_w.tolist(),
        "probes": listed(sim.probes),
        "plane_name": sim.plane_name,
        "plane": None if sim.plane is None else sim.plane.tolist(),
        "plane_frame": sim.plane_frame,
        "sphere": None if sim.sphere is None else sim.sphere.tolist(),
        "point": None if sim.point is None else sim.point.tolist(),
    }


def _plan_qs(path: Path, names: Sequence[str]) -> Any:
    """The configurations of a plan file in ``names`` order (every joint named)."""
    from kinfw.identification.planning import read_plan

    plan_names, qs = read_plan(path)
    missing = [j for j in names if j not in plan_names]
    if missing:
        raise ValueError(f'{path}: "joint_names": missing the joints {missing}')
    return qs[:, [plan_names.index(j) for j in names]]


def check_simulate_outputs(args: argparse.Namespace) -> None:
    """``kinfw simulate``'s outputs, checked before any work."""
    check_outputs(
        {"--out": args.out, "--truth-out": args.truth_out},
        inputs={"--urdf": args.urdf, "--plan": args.plan, **camera_inputs(args)},
    )
    if args.images is not None:
        check_output_dir(args.images, label="--images")
