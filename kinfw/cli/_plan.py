"""``kinfw plan``: choose the configurations to measure (:mod:`kinfw.identification.planning`).

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

__all__ = ["add_plan_parser", "cmd_plan", "read_pool"]


def add_plan_parser(sub, number) -> None:
    """The ``plan`` sub-command (``number``: :func:`kinfw.cli.number`)."""
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
    p.add_argument("--collisions", action="store_true", help="drop self-colliding candidates")
    p.add_argument("--protocol", choices=("free", "per-joint"), default="free")
    p.add_argument("--per-joint", type=count, default=5, help="per-joint protocol: M values")
    p.add_argument("--target-mm", type=positive, default=None, help="smallest N below this")
    p.add_argument("--out", type=Path, help="plan file to write (JSON)")
    p.add_argument("--plot", type=Path, help="error vs N plot to write (PNG/PDF/SVG)")
    p.add_argument("--seed", type=number(int, low=0), default=0)
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_plan)


def read_pool(path: Path, joint_names) -> object:
    """Candidate joint states (n, J) in ``joint_names`` order from a JSON file: a
    ``kinfw-measurements`` file (its samples) or ``{"joint_names": [...],
    "configurations": [[...], ...]}`` (a plan file is one)."""
    import numpy as np

    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc.msg} at line {exc.lineno})") from None
    if isinstance(doc, dict) and doc.get("format") == "kinfw-measurements":
        from kinfw.measurements import read_measurements

        data = read_measurements(path)
        names, qs = data.joint_names, data.qs
    else:
        names = doc.get("joint_names") if isinstance(doc, dict) else None
        if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
            raise ValueError(f'{path}: "joint_names": expected a list of joint names')
        try:
            qs = np.array(doc.get("configurations"), dtype=float)
        except (TypeError, ValueError):
            qs = np.empty((0,))
        if qs.ndim != 2 or qs.shape[1] != len(names) or not np.isfinite(qs).all():
            raise ValueError(
                f'{path}: "configurations": expected rows of {len(names)} finite joint values'
            )
    missing = [j for j in joint_names if j not in names]
    if missing:
        raise ValueError(f'{path}: "joint_names": missing the joints {missing}')
    return qs[:, [list(names).index(j) for j in joint_names]]


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
    import numpy as np

    from kinfw.cli._tables import format_table
    from kinfw.identification.planning import (
        candidate_pool,
        plan_configurations,
        plan_per_joint,
        write_plan,
    )
    from kinfw.model import load_robot
    from kinfw.simulation import random_configurations

    if args.pool is not None and args.within_limits is not None:
        raise ValueError("give --pool or --within-limits, not both")
    robot = load_robot(args.urdf)
    setup = _setup(args, robot)
    names = robot.topology(setup.observed).joint_names
    lower, upper = robot.joint_limits(names)
    rng = np.random.default_rng(args.seed)
    fraction = args.within_limits or 0.8
    w_T = setup.target_pose(robot, names, 0.5 * (lower + upper)) if setup.cameras else None
    test = random_configurations(lower, upper, args.test, rng, fraction=fraction)
    if setup.cameras:  # the held-out error where the board is seen
        test = candidate_pool(robot, setup, names, w_T, qs=test).qs
    summary = {"urdf": str(args.urdf), "frames": list(setup.frames)}
    summary["cameras"] = list(setup.cameras)
    if args.protocol == "per-joint":
        out = plan_per_joint(
            robot, setup, args.per_joint, joint_names=names, test_qs=test, w_T_target=w_T
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
    if args.pool is not None:
        pool = candidate_pool(robot, setup, names, w_T, qs=read_pool(args.pool, names))
    else:
        pool = candidate_pool(
            robot,
            setup,
            names,
            w_T,
            within_limits=fraction,
            n=args.candidates,
            rng=rng,
            collisions=args.collisions,
        )
    if len(pool.qs) < args.n and args.target_mm is None:
        raise ValueError(
            f"--n {args.n}: only {len(pool.qs)} candidates satisfy the constraints "
            f"(dropped: {pool.dropped or 'none'})"
        )
    ns = sorted({k for k in (5, 10, 15, 20, 30, 40, 60, 100, args.n) if k <= len(pool.qs)})
    plan = plan_configurations(
        robot,
        setup,
        pool.qs,
        args.n,
        joint_names=names,
        test_qs=test,
        w_T_target=w_T,
        rng=rng,
        curve_ns=ns,
        target_m=None if args.target_mm is None else args.target_mm * 1e-3,
        dropped=pool.dropped,
    )
    summary.update(
        {
            "n": len(plan.qs),
            "pool": plan.pool_size,
            "dropped": plan.dropped,
            "seconds": plan.seconds,
            **{m.headline: m.scale * v for m, v in plan.predicted},
            f"random_{plan.objective.headline}": plan.objective.scale * plan.random_rms,
            "curve": [
                {"n": k, "planned_mm": a * 1e3, "random_mm": b * 1e3} for k, a, b in plan.curve
            ],
        }
    )
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
        _plot(args.plot, plan)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
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
    return 0


def _plot(path: Path, plan) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [c[0] for c in plan.curve]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(n, [c[1] * 1e3 for c in plan.curve], "o-", label="planned")
    ax.plot(n, [c[2] * 1e3 for c in plan.curve], "s--", label="random (mean)")
    ax.set_xlabel("configurations N")
    ax.set_ylabel("predicted held-out position RMS (mm)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp{path.suffix}")
    fig.savefig(tmp)
    plt.close(fig)
    tmp.replace(path)
