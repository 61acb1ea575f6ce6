"""Assembly of the least-squares problem: :func:`build_problem`.

It lays the parameter vector out block by block (the robot's CPC chart, base, zero
offsets and any extra robot block, :mod:`~kinfw.identification.problem`; then every
unknown the observation kinds ask for: external measurement frames, targets, markers,
offsets, or a new kind's own),
takes start values from the kinds' closed-form estimators
(:mod:`~kinfw.identification.problem`), builds per group a CasADi residual and its exact
Jacobian (:mod:`~kinfw.identification.problem`), and returns the
:class:`~kinfw.identification.problem.LeastSquaresProblem`. There is no branch on an
observation kind here.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem._functions import group_functions
from kinfw.identification.problem._gauge import relative_gauge, robot_blocks
from kinfw.identification.problem._problem import LeastSquaresProblem, ResidualGroup, Unknown
from kinfw.identification.problem._start import estimate_unknowns, express_in
from kinfw.measurements import Measurements, check_against_robot, robot_measurement_frames
from kinfw.model import (
    CPC_KEY,
    Block,
    BlockKey,
    BlockSamples,
    CPCModel,
    PriorScales,
    Robot,
    RobotBlock,
    cpc_from_geometry,
    cpc_from_robot,
    geometry_from_robot,
    prior_groups,
    prior_sigmas,
    spec_prior_mean,
)
from kinfw.observations import DatasetError, kind_of

logger = logging.getLogger("kinfw.identification.problem")


def _free_intrinsics(
    blocks: list[Block], cameras: bool | Sequence[str], source: str
) -> list[Block]:
    """``blocks`` with the intrinsics blocks of ``cameras`` (True: all) freed."""
    have = {b.key.name for b in blocks if b.key.kind == "intrinsics"}
    names = have if cameras is True else set(cameras or ())
    missing = sorted(names - have)
    if missing:
        seen = ", ".join(repr(c) for c in sorted(have)) or "none"
        raise DatasetError(
            f"{source}: refine_intrinsics: no 'pixels' observations of camera "
            f"{missing[0]!r} (cameras with pixels: {seen})"
        )
    return [
        b.with_free(np.ones(b.size, bool))
        if b.key.kind == "intrinsics" and b.key.name in names
        else b
        for b in blocks
    ]


def build_problem(
    robot: Robot,
    measurements: Measurements,
    *,
    start: Robot | None = None,
    targets: dict[str, NDArray] | None = None,
    parameters: str | tuple[str, ...] = "full",
    prior: PriorScales | tuple[float, float] | None = None,
    known: tuple[Unknown, ...] = (),
    refine_intrinsics: bool | Sequence[str] = (),
    extra_blocks: tuple[RobotBlock, ...] = (),
) -> LeastSquaresProblem:
    """Assemble the least-squares problem (see :func:`kinfw.identification.refine`).

    ``known`` gives start values for unknown blocks (e.g. a previous calibration's target
    pose and markers) instead of estimating them from these data; ``targets`` gives
    target poses ``root_T_target`` the same way. ``refine_intrinsics`` frees the
    intrinsics blocks (``BlockKey("intrinsics", camera)``, fixed by default) of the
    named cameras, or of every camera when True. ``extra_blocks`` are robot blocks
    besides the CPC chart, base and zero offsets (:class:`kinfw.model.RobotBlock`), after
    the robot's own (:attr:`kinfw.model.Robot.spec`: a calibration's compliance...),
    which an extra block of the same key replaces; each bound to these data
    (:meth:`~kinfw.model.RobotBlock.for_data`) and fed its per-sample inputs.
    """
    measurements = check_against_robot(measurements, robot)
    prior = PriorScales.of(prior)
    start = robot if start is None else start
    groups = list(measurements.all_groups())
    # frames of the robot that observations are measured in (a head camera) are end
    # frames of the model too: the prediction is inv(w_T_c) w_T_frame
    robot_in = robot_measurement_frames(measurements, robot)
    observed = tuple(dict.fromkeys((*measurements.observed_frames, *robot_in)))
    model_frame = _single_external_frame(groups, robot_in)
    model0 = cpc_from_robot(start, observed)
    q_all = measurements.q_of(model0.topology.joint_names)
    samples = BlockSamples(
        robot,
        tuple(model0.topology.joint_names),
        q_all,
        measurements.sample_payloads(),
        measurements.gravity,
    )
    extra = _bound_blocks(robot, extra_blocks, samples)
    # the start values (an external frame's pose, targets...) at the joint values after
    # the robot blocks' hooks: a calibration's compliance moves the frames by millimetres
    q_start = _start_joint_values(extra, samples)
    given = _given_starts(known, targets)
    fitted_frame = []
    if model_frame is not None:
        model0 = express_in(
            model0, measurements, q_start, model_frame, given.get(BlockKey("frame", model_frame))
        )
        if BlockKey("frame", model_frame) not in given:
            fitted_frame.append(
                (BlockKey("frame", model_frame), f"pose of the root link in {model_frame!r}")
            )
    unknown, fitted = estimate_unknowns(measurements, groups, model0, q_start, model_frame, given)
    unknown = _free_intrinsics(unknown, refine_intrinsics, measurements.source)
    blocks = (
        *robot_blocks(
            model0,
            robot,
            groups,
            model_frame,
            parameters,
            with_prior=prior is not None and bool(prior.scales),
            extra=extra,
        ),
        *unknown,
    )
    residual_groups = _residual_groups(model0, blocks, groups, model_frame, q_all, samples)
    if robot_in:  # relative measurements: fix what they leave undetermined
        blocks = _fix_relative_gauge(
            robot, model0, blocks, residual_groups, robot_in, measurements.source
        )
    prior_mean, prior_sigma, groups = _prior_rows(
        blocks, prior, robot, observed, model0, model_frame
    )
    return LeastSquaresProblem(
        model0,
        model_frame,
        tuple(blocks),
        tuple(residual_groups),
        prior_mean,
        prior_sigma,
        (*fitted_frame, *fitted),
        q_start,
        groups,
    )


def _bound_blocks(
    robot: Robot, extra_blocks: tuple[RobotBlock, ...], samples: BlockSamples
) -> tuple[RobotBlock, ...]:
    """The robot's own blocks (:attr:`kinfw.model.Robot.spec`: a calibration's
    compliance...) but those an extra block of the same key replaces, then the extra
    ones, each bound to these samples (:meth:`kinfw.model.RobotBlock.for_data`)."""
    given_keys = {b.key for b in extra_blocks}
    own = tuple(b for b in robot.spec.blocks if b.key not in given_keys)
    return tuple(
        b.for_data(samples) if isinstance(b, RobotBlock) else b for b in (*own, *extra_blocks)
    )


def _start_joint_values(
    blocks: tuple[RobotBlock, ...], samples: BlockSamples
) -> NDArray[np.float64]:
    """The samples' joint values (n, J) after the robot blocks' joint hooks at their
    starts (the readings' maps, then the deflections): what the start model sees."""
    q = samples.qs
    for stage in ("readings", "deflection"):
        for b in blocks:
            if isinstance(b, RobotBlock) and b.stage == stage:
                q = b.joint_values(q, samples)
    return q


def _single_external_frame(groups: list, robot_in: Sequence[str]) -> str | None:
    """The external frame every observation is measured in, if there is one and no
    observation is measured in a frame of the robot; else None (the URDF root)."""
    in_frames = {kind_of(g).measured_in(g) for g in groups} - set(robot_in)
    if len(in_frames) == 1 and None not in in_frames and not robot_in:
        return next(iter(in_frames))  # everything in one external frame
    return None


def _given_starts(
    known: tuple[Unknown, ...], targets: dict[str, NDArray] | None
) -> dict[BlockKey, NDArray]:
    """Start values by block key: ``known`` first, then the ``targets`` poses it does not
    give."""
    given = {BlockKey(u.kind, u.name): u.value for u in known}
    given.update(
        {
            BlockKey("target", n): T
            for n, T in (targets or {}).items()
            if BlockKey("target", n) not in given
        }
    )
    return given


def _residual_groups(
    model0: CPCModel,
    blocks: tuple[Block, ...],
    groups: list,
    model_frame: str | None,
    q_all: NDArray[np.float64],
    samples: BlockSamples,
) -> list[ResidualGroup]:
    """Per observation group its CasADi residual with the group's joint values (and
    the robot blocks' per-sample inputs after them) and data; every number (reference
    model, block starts) is an input of the functions."""
    const = np.concatenate([b.constants() for b in blocks])
    functions = group_functions(model0, blocks, groups, model_frame, len(const))
    inputs = [b.sample_inputs(samples) for b in blocks if isinstance(b, RobotBlock)]
    q_in = np.hstack([q_all, *inputs])
    return [
        ResidualGroup(
            kind_of(g),
            g,
            q_in[g.sample].T,
            np.asarray(kind_of(g).data(g), dtype=float).T,
            fn,
            const,
        )
        for g, fn in zip(groups, functions, strict=True)
    ]


def _fix_relative_gauge(
    robot: Robot,
    model0: CPCModel,
    blocks: tuple[Block, ...],
    residual_groups: list[ResidualGroup],
    robot_in: Sequence[str],
    source: str,
) -> tuple[Block, ...]:
    """``blocks`` with what relative measurements (in the robot's frames ``robot_in``)
    leave undetermined fixed at its start (:func:`relative_gauge`), logged."""
    lower, upper = robot.joint_limits(model0.topology.joint_names)
    blocks, fixed = relative_gauge(tuple(blocks), residual_groups, lower, upper)
    if fixed:
        logger.info(
            "%s: measured in the robot's %s: %d parameters the relative poses do not "
            "determine are fixed at their start: %s",
            source,
            list(robot_in),
            len(fixed),
            ", ".join(fixed),
        )
    return blocks


def _prior_rows(
    blocks: tuple[Block, ...],
    prior: PriorScales | None,
    robot: Robot,
    observed: tuple[str, ...],
    model0: CPCModel,
    model_frame: str | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[tuple[str | None, str], ...]]:
    """Mean and sigma, shape (P,), of the Gaussian ``prior`` by group
    (:func:`~kinfw.identification.problem.prior_groups`; without a prior or a group's
    sigma: inf), and every parameter's ``(group, unit)``. Its mean on the CPC chart is
    the nominal URDF when the model is in the root frame (else the start), on a model
    spec block the rigid model, elsewhere the start (intrinsics: the camera file's).

    The CPC chart's end-frame tools (a camera's or marker body's mount, the flange's tool
    frame) are the group ``"tools"``, which :meth:`PriorScales.uniform` leaves free: they
    are what ``"frames"`` fits freely, and a URDF's mount is often a rough guess
    (centimetres, degrees), not a machined length. A prior there pinned a wrist camera
    3.5 cm and 118 sigma from its URDF guess (industrial_calibration's circle grid,
    ``benchmarks/bench_circles_real.py``); without it ``"full"`` under a tight prior tends
    to ``"frames"``, as FIGAROH's MAP priors do (frames estimated freely).
    """
    groups = prior_groups(blocks, _joint_entries(model0))
    P = len(groups)
    prior_mean = spec_prior_mean(blocks, P)
    if prior is not None and model_frame is None:  # deviations from the nominal
        _, s = _block_slice(blocks, CPC_KEY)
        nominal = cpc_from_geometry(geometry_from_robot(robot, observed), sign=model0.sign)
        prior_mean[s] = model0.chart_coordinates(nominal)
    return prior_mean, prior_sigmas(groups, prior), groups


def _block_slice(blocks: tuple[Block, ...], key: BlockKey) -> tuple[Block, slice]:
    """The block of ``key`` and its slice of the parameter vector."""
    k = 0
    for b in blocks:
        if b.key == key:
            return b, slice(k, k + b.size)
        k += b.size
    raise KeyError(key)


def _joint_entries(model: CPCModel) -> int:
    """Number of the CPC chart's joint entries (axis tilts, and line offsets of revolute
    joints), which come before its end frames' tools (:attr:`CPCModel.parameter_names`)."""
    return 2 * len(model.topology.joint_names) + 2 * int(np.sum(model.topology.revolute))
