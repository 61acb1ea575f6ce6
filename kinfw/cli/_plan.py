"""``kinfw plan``: choose the configurations to measure (:mod:`kinfw.identification.planning`).

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from kinfw.cli._args import add_package_dir_option, add_xacro_option, load_model, number
from kinfw.files import check_outputs


def add_plan_parser(sub) -> None:
    """The ``plan`` sub-command."""
    positive = number(float, low=0.0, low_open=True)
    count = number(int, low=1)
    p = sub.add_parser(
        "plan",
        help="choose which configurations to measure, and how many",
        description="Choose N configurations that minimise the predicted held-out error of "
        "the calibrated model (I-optimal: RMS position error of the observed frames at "
        "random test configurations, from the Fisher information of the calibration "
        "problem at the nominal robot; greedy selection then Fedorov exchange).",
    )
    p.add_argument("--urdf", type=Path, default=None, help="nominal URDF (default: IIS-head)")
    add_xacro_option(p)
    p.add_argument("--frames", help="stage 1: frames measured by a tracker, comma-separated")
    p.add_argument("--points", action="store_true", help="stage 1: measure frame origins only")
    p.add_argument("--cameras", help="stage 2: cameras seeing a fixed board, comma-separated")
    p.add_argument("--pixels", action="store_true", help="stage 2 as the board's corners in px")
    p.add_argument("--board", default="chessboard:9x6:0.04", help="stage 2 board spec")
    p.add_argument("--n", type=count, default=30, help="configurations to choose (default 30)")
    p.add_argument("--params", default="full", help="parameter set (default full)")
    p.add_argument("--pool", type=Path, help="candidate joint states (JSON file)")
    p.add_argument(
        "--within-limits",
        type=number(float, low=0.0, high=1.0, low_open=True),
        default=None,
        help="random candidates in this centred fraction of each joint range (default 0.8)",
    )
    p.add_argument("--candidates", type=count, default=1000, help="random candidates (1000)")
    p.add_argument("--test", type=count, default=200, help="test configurations (200)")
    p.add_argument("--noise-mm", type=positive, default=0.5, help="position noise, mm (0.5)")
    p.add_argument("--noise-deg", type=positive, default=0.5, help="rotation noise, deg (0.5)")
    p.add_argument("--pixel-sigma", type=positive, default=0.5, help="pixel noise, px (0.5)")
    p.add_argument("--tracker", help='tracker position "x y z" in the root frame, m')
    p.add_argument("--max-facing-deg", type=positive, default=60.0)
    p.add_argument(
        "--collisions",
        action="store_true",
        help="drop self-colliding candidates (refused when the URDF's collision meshes are "
        "not found: give --package-dir)",
    )
    add_package_dir_option(p)
    p.add_argument("--protocol", choices=("free", "per-joint"), default="free")
    p.add_argument("--per-joint", type=count, default=5, help="per-joint protocol: M values")
    p.add_argument("--target-mm", type=positive, default=None, help="smallest N below this")
    p.add_argument("--out", type=Path, help="plan file to write (JSON)")
    p.add_argument(
        "--plot",
        type=Path,
        help="error vs N plot to write (its suffix names the format: png, pdf, svg...)",
    )
    p.add_argument("--seed", type=number(int, low=0), default=0)
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_plan, check_outputs=check_plan_outputs)


def _setup(args, robot):
    import numpy as np

    from kinfw.cli._args import frames_arg
    from kinfw.cli._fit import params_arg
    from kinfw.identification.planning import Setup

    if not (args.frames or args.cameras):
        frames = robot.default_frames  # default: stage 1, else stage 2
        cameras = () if frames else robot.default_cameras
        if not (frames or cameras):
            frames_arg(None, (), "--frames or --cameras", robot)  # raises the hint
    else:
        frames = frames_arg(args.frames, (), "--frames", robot) if args.frames else ()
        cameras = frames_arg(args.cameras, (), "--cameras", robot) if args.cameras else ()
    for f in (*frames, *cameras):
        robot.frame_id(f)  # an unknown frame: one-line error naming the links
    tracker = None
    if args.tracker is not None:
        from kinfw.cli._args import up_arg

        tracker = np.array(up_arg(args.tracker))
    return Setup(
        frames=tuple(frames),
        frame_kind="point" if args.points else "pose",
        cameras=tuple(cameras),
        pixels=args.pixels,
        board=args.board,
        noise_m=args.noise_mm * 1e-3,
        noise_rad=math.radians(args.noise_deg),
        pixel_sigma=args.pixel_sigma,
        parameters=params_arg(args.params),
        tracker_p=tracker,
        max_facing_deg=args.max_facing_deg,
    )


def cmd_plan(args: argparse.Namespace) -> int:

    if args.pool is not None and args.within_limits is not None:
        raise ValueError("give --pool or --within-limits, not both")
    robot = load_model(args.urdf, args)
    setup = _setup(args, robot)
    summary = {"urdf": str(args.urdf), "frames": list(setup.frames)}
    summary["cameras"] = list(setup.cameras)
    if args.protocol == "per-joint":
        return _plan_per_joint(args, robot, setup, summary)
    from kinfw.identification.planning import (
        PoolTooSmallError,
        plan_measurement,
        plot_plan,
        read_pool,
        write_plan,
    )

    names = robot.topology(setup.observed).joint_names
    try:
        plan = plan_measurement(
            robot,
            setup,
            args.n,
            pool_qs=None if args.pool is None else read_pool(args.pool, names),
            within_limits=args.within_limits,
            candidates=args.candidates,
            n_test=args.test,
            collisions=args.collisions,
            package_dirs=tuple(args.package_dir),
            target_m=None if args.target_mm is None else args.target_mm * 1e-3,
            seed=args.seed,
        )
    except PoolTooSmallError as exc:
        raise ValueError(f"--n {args.n}: {exc.reason}") from None
    summary.update(_plan_summary(plan))
    if args.out is not None:
        setup_doc = {k: summary[k] for k in ("urdf", "frames", "cameras")} | {
            "kind": setup.frame_kind,
            "pixels": setup.pixels,
            "noise_mm": args.noise_mm,
            "noise_deg": args.noise_deg,
            "pixel_sigma": args.pixel_sigma,
            "params": args.params,
            "seed": args.seed,
        }
        write_plan(args.out, plan, setup_doc)
    if args.plot is not None:
        plot_plan(args.plot, plan)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    _print_plan(args, plan)
    return 0


def _plan_per_joint(args: argparse.Namespace, robot, setup, summary: dict) -> int:
    """``kinfw plan --protocol per-joint``: Shih et al.'s protocol, planned."""
    import numpy as np

    from kinfw.identification.planning import evaluation_set, plan_per_joint

    rng = np.random.default_rng(args.seed)
    tests = evaluation_set(robot, setup, args.test, rng, fraction=args.within_limits or 0.8)
    out = plan_per_joint(
        robot,
        setup,
        args.per_joint,
        joint_names=tests.joint_names,
        test_qs=tests.qs,
        w_T_target=tests.w_T_target,
    )
    summary.update({k: v for k, v in out.items() if k != "qs"})
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"per-joint protocol, {args.per_joint} values per joint ({out['n_planned']} "
            f"configurations): predicted held-out position RMS "
            f"{out['planned_position_rms_m'] * 1e3:.4f} mm planned, "
            f"{out['even_position_rms_m'] * 1e3:.4f} mm evenly spaced; the paper's 9 "
            f"evenly spaced ({out['n_paper']}): {out['paper_position_rms_m'] * 1e3:.4f} mm"
        )
    return 0


def _plan_summary(plan) -> dict:
    """The plan's numbers in the ``--json`` summary (display units)."""
    return {
        "n": len(plan.qs),
        "pool": plan.pool_size,
        "dropped": plan.dropped,
        "seconds": plan.seconds,
        **{m.headline: m.scale * v for m, v in plan.predicted},
        f"random_{plan.objective.headline}": plan.objective.scale * plan.random_rms,
        "curve": [{"n": k, "planned_mm": a * 1e3, "random_mm": b * 1e3} for k, a, b in plan.curve],
    }


def _print_plan(args: argparse.Namespace, plan) -> None:
    """The plan's predicted errors, and the table of them against N."""
    from kinfw.cli._tables import format_table

    print(
        f"planned {len(plan.qs)} of {plan.pool_size} candidates in {plan.seconds:.2f} s"
        + (f" (dropped: {plan.dropped})" if plan.dropped else "")
        + ": predicted held-out "
        + ", ".join(f"{m.name} RMS {m.scale * v:.4f} {m.unit}" for m, v in plan.predicted)
        + f"; random: {plan.objective.scale * plan.random_rms:.4f} {plan.objective.unit}"
    )
    rows = [[k, f"{a * 1e3:.4f}", f"{b * 1e3:.4f}"] for k, a, b in plan.curve]
    print(format_table(rows, ["N", "planned mm", "random mm"]))
    if args.out is not None:
        print(f"wrote {args.out}")


def check_plan_outputs(args: argparse.Namespace) -> None:
    """``kinfw plan``'s outputs, checked before any work."""
    check_outputs(
        {"--out": args.out, "--plot": args.plot},
        inputs={"--urdf": args.urdf, "--pool": args.pool},
        figures=("--plot",),
    )
