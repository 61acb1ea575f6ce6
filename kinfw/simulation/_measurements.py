"""A whole simulated calibration experiment, as ``kinfw simulate`` and
:func:`kinfw.simulate` make it: the nominal robot perturbed into a "true" one, then its
measurements (stage 1: poses of frames, one joint at a time; stage 2: camera observations
of a fixed target, or images of a board, at random configurations; or both stages at
given configurations, a plan's), then motion-capture markers of unknown offset measured
in an unknown external frame, and probes touching a plane, a ball or a point (random
configurations projected onto the contact, :mod:`kinfw.simulation._contacts`).

Every random draw comes from one generator seeded by ``seed``, in a fixed order (the
truth, stage 1, stage 2, the markers, the contacts), so a seed reproduces the experiment
exactly, and adding markers or contacts leaves the stages' data unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.camera import Board, CameraIntrinsics, parse_board
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.model import (
    BlockKey,
    BlockSamples,
    JointComplianceBlock,
    ModelSpec,
    Payloads,
    Robot,
    check_robot,
    load_robot,
)
from kinfw.observations import (
    DivotContacts,
    PlaneContacts,
    PointObservations,
    SphereContacts,
    offset_key,
    perturb_transforms,
)
from kinfw.simulation._contacts import contact_configurations, level_plane, plane_through
from kinfw.simulation._perturb import (
    finite_limits,
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
)
from kinfw.simulation._pixels import (
    DEFAULT_BOARD,
    MIN_CORNERS,
    board_pose_facing,
    default_intrinsics,
    pixel_views,
    simulate_pixels,
)
from kinfw.simulation._simulate import default_target_pose, simulate_at

#: Length of a marker's or probe's offset drawn when none is given, metres.
DEFAULT_OFFSET_M = 0.05


@dataclass(frozen=True, slots=True, eq=False)
class SimulatedProbe:
    """A motion-capture marker or a contact probe of a simulation: its true offset.

    Attributes
    ----------
    frame : str
        URDF frame the point rides on.
    name : str
        The marker's name in the measurement file (``marker``).
    offset : ndarray, shape (3,)
        Its true position in ``frame``, metres.
    """

    frame: str
    name: str
    offset: NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class SimulatedMeasurements:
    """The true robot and its simulated measurements (:func:`simulate_measurements`).

    Attributes
    ----------
    truth_xml : str
        The true robot's URDF (the nominal with random errors of its joint origins and
        axes; every float written with ``repr``).
    truth : Robot
        The same, loaded.
    data : Measurements
        The measurements: stage 1 then stage 2.
    joint_names : tuple of str
        The joints on the paths to the frames and cameras (the order of
        ``configurations``).
    frames, cameras : tuple of str
        Stage 1 frames and stage 2 cameras simulated (empty for a stage not simulated).
    board : str or None
        With ``pixels``: the board's spec (:func:`kinfw.camera.parse_board`).
    default_cameras : tuple of str
        With ``pixels``: the cameras given no intrinsics, simulated with
        :func:`kinfw.simulation.default_intrinsics`.
    w_T_board : ndarray, shape (4, 4), or None
        With ``pixels``: the board's true pose in the root frame ``w`` (in
        ``target_frame`` when given), metres.
    markers : tuple of SimulatedProbe
        The motion-capture markers.
    mocap_frame : str or None
        With markers: the external frame they are measured in (None: the root).
    mocap_T_w : ndarray, shape (4, 4), or None
        With markers in an external frame: the root's true pose in it, metres.
    probes : tuple of SimulatedProbe
        The probes touching the plane (the ball, the point).
    plane : ndarray, shape (4,), or None
        With probes on a plane: ``(n, d)``, ``{x : n . x = d}`` in ``w`` (``d`` metres).
    plane_name : str or None
        With probes: the name of the plane (the ball, the point) in the measurement file.
    plane_frame : str or None
        With probes on a plane fixed to a URDF frame other than the root: that frame
        (the observations' ``measured_in``; :attr:`plane` is still in ``w``).
    sphere : ndarray, shape (4,), or None
        With probes on a ball: its centre in ``w`` and its radius, metres.
    point : ndarray, shape (3,), or None
        With probes on a point: the point in ``w``, metres.
    target_frame : str or None
        With ``pixels``: the URDF frame the board is fixed to (None: the world).
    """

    truth_xml: str
    truth: Robot
    data: Measurements
    joint_names: tuple[str, ...]
    frames: tuple[str, ...]
    cameras: tuple[str, ...]
    board: str | None = None
    default_cameras: tuple[str, ...] = ()
    w_T_board: NDArray[np.float64] | None = None
    markers: tuple[SimulatedProbe, ...] = ()
    mocap_frame: str | None = None
    mocap_T_w: NDArray[np.float64] | None = None
    probes: tuple[SimulatedProbe, ...] = ()
    plane: NDArray[np.float64] | None = None
    plane_name: str | None = None
    plane_frame: str | None = None
    sphere: NDArray[np.float64] | None = None
    point: NDArray[np.float64] | None = None
    target_frame: str | None = None


def _observed(
    nominal: Robot,
    stages: tuple[int, ...],
    frames: Sequence[str] | None,
    cameras: Sequence[str] | None,
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The stage 1 frames and stage 2 cameras: the given ones, else the URDF's hints,
    for the stages simulated; ValueError when a stage has none."""
    out = []
    for stage, given, hint, name in (
        (1, frames, nominal.default_frames, "frames"),
        (2, cameras, nominal.default_cameras, "cameras"),
    ):
        chosen = () if stage not in stages else tuple(hint if given is None else given)
        if stage in stages and not chosen:
            raise ValueError(
                f"{nominal.source}: give the stage {stage} {name}; this URDF has no "
                f'<kinfw {name}="..."/> hint. Links: {", ".join(nominal.link_names)}'
            )
        out.append(chosen)
    return out[0], out[1]


def _stage2(
    truth: Robot,
    cameras: tuple[str, ...],
    names: tuple[str, ...],
    limits: tuple[NDArray[np.float64], NDArray[np.float64]],
    rng: np.random.Generator,
    planned: NDArray[np.float64] | None,
    *,
    noise: dict[str, float],
    board: Board | None,
    intrinsics: dict[str, CameraIntrinsics],
    pixel_sigma: float,
    stage2_samples: int,
    fraction: float,
    target_frame: str | None,
) -> tuple[Measurements, NDArray[np.float64] | None]:
    """Stage 2: ``cameras`` see a fixed target (its pose, ``camera_T_target``), or with a
    ``board`` the board's points in images (cameras with ``intrinsics``), at the
    ``planned`` configurations, else at random ones within ``limits`` (``(lower,
    upper)``); images where no camera sees the board are dropped (planned) or drawn
    again (random). Returns the data and, with a ``board``, its pose ``w_T_board`` (in
    ``target_frame`` when the board is on that URDF frame)."""
    lower, upper = limits
    if board is None:
        qs = planned
        if qs is None:
            qs = random_configurations(lower, upper, stage2_samples, rng, fraction=fraction)
        w_T_target = default_target_pose(truth, qs, names, cameras)
        data = simulate_at(
            truth, qs, names, cameras=cameras, rng=rng, w_T_target=w_T_target, **noise
        )
        return data, None
    min_corners = MIN_CORNERS if board.partial else board.count
    if planned is not None:
        w_T_board = board_pose_facing(
            truth,
            0.5 * (lower + upper),
            names,
            cameras,
            board.points,
            target_frame=target_frame,
        )
        data, _ = simulate_pixels(
            truth,
            planned,
            names,
            cameras=intrinsics,
            board_p=board.points,
            w_T_board=w_T_board,
            rng=rng,
            sigma_px=pixel_sigma,
            min_corners=min_corners,
            target_frame=target_frame,
        )
        return data, w_T_board
    return pixel_views(
        truth,
        names,
        lower,
        upper,
        stage2_samples,
        rng,
        cameras=intrinsics,
        board_p=board.points,
        sigma_px=pixel_sigma,
        fraction=fraction,
        min_corners=min_corners,
        target_frame=target_frame,
    )


def simulate_measurements(
    nominal: Robot,
    *,
    stages: tuple[int, ...] | None = None,
    frames: Sequence[str] | None = None,
    cameras: Sequence[str] | None = None,
    per_joint: int = 9,
    stage2_samples: int = 30,
    fraction: float = 0.8,
    noise_m: float = 5e-4,
    noise_rad: float = float(np.radians(0.5)),
    stereo_sigma_m: float | None = None,
    error_mm: float = 2.0,
    error_deg: float = 0.5,
    pixels: bool = False,
    pixel_sigma: float = 0.5,
    board: str | None = None,
    intrinsics: Mapping[str, CameraIntrinsics] | None = None,
    configurations: ArrayLike | None = None,
    markers: Sequence[tuple[str, ArrayLike | None]] = (),
    mocap_frame: str | None = "mocap",
    mocap_samples: int = 40,
    contacts: Sequence[tuple[str, ArrayLike | None]] = (),
    plane: ArrayLike | None = None,
    plane_name: str | None = None,
    plane_frame: str | None = None,
    sphere: ArrayLike | None = None,
    point: ArrayLike | None = None,
    contact_samples: int = 60,
    offsets_known: bool = False,
    target_frame: str | None = None,
    compliance: float | Mapping[str, float] | None = None,
    truth_model: ModelSpec | None = None,
    payloads: tuple[str, float, ArrayLike] | None = None,
    gravity: ArrayLike | None = None,
    seed: int = 0,
) -> SimulatedMeasurements:
    """Perturb ``nominal`` into a true robot and simulate its measurements, as
    ``kinfw simulate`` does (the same defaults): :func:`kinfw.simulate`.

    Parameters
    ----------
    nominal : Robot
        The nominal robot (:func:`kinfw.load_robot`).
    stages : tuple of int, optional
        ``()``, ``(1,)``, ``(2,)`` or ``(1, 2)``; default ``(1,)``, with ``pixels``
        ``(1, 2)``, with ``markers`` or ``contacts`` (and no ``pixels``) ``()``.
    frames, cameras : sequence of str, optional
        Stage 1 frames and stage 2 camera frames; default the URDF's ``<kinfw>`` hints.
    per_joint : int
        Stage 1: values per joint, one joint at a time (Shih et al. section 4.1).
    stage2_samples : int
        Stage 2: random configurations.
    fraction : float
        The centred fraction of each joint range used.
    noise_m, noise_rad : float
        Pose noise: sigma per axis (m) and of the angle about a random axis (rad).
    stereo_sigma_m : float, optional
        Simulate the stereo rig instead for stage 1: point noise on the nine-circle
        plate (m).
    error_mm, error_deg : float
        The true robot's errors: joint origins (mm; deg) and axes (deg), sigmas
        (:func:`kinfw.simulation.perturb_robot`).
    pixels : bool
        Stage 2 as images of ``board`` (``pixels`` observations) with pixel noise
        ``pixel_sigma`` (px) per image coordinate.
    board : str, optional
        With ``pixels``: the board spec (default :data:`DEFAULT_BOARD`).
    intrinsics : mapping of str to CameraIntrinsics, optional
        With ``pixels``: per camera; default :func:`default_intrinsics`.
    configurations : array_like, shape (n, J), optional
        Measure both stages at these configurations, in order (a plan's), columns in
        the order of ``nominal.topology(frames + cameras).joint_names``
        (:attr:`SimulatedMeasurements.joint_names`), rad/m; default one joint at a time
        (stage 1) and random (stage 2).
    markers : sequence of (str, array_like or None)
        Motion-capture markers: ``(frame, offset)``, the marker's true position in URDF
        frame ``frame`` (3,), metres, or None for a random one (:data:`DEFAULT_OFFSET_M`
        long, uniform direction). Named ``marker1``, ``marker2``, ... in order; their
        ``point`` observations leave the offset out (unknown) unless ``offsets_known``.
    mocap_frame : str or None
        The external frame the markers are measured in (not a frame of the URDF); its
        true pose is random (``mocap_T_w``: translation N(0, 1 m) per axis, a rotation
        by N(0, 1 rad) about a uniform axis). None: the markers are measured in the root.
    mocap_samples : int
        Random configurations at which every marker is measured (noise ``noise_m`` per
        axis).
    contacts : sequence of (str, array_like or None)
        Probes touching the plane: ``(frame, offset)`` as ``markers``, named ``probe1``,
        ``probe2``, ...; each touches it at ``contact_samples`` configurations of its
        own (:func:`kinfw.simulation.contact_configurations`), the ``plane``
        observation's distance noise ``noise_m``.
    plane : array_like, shape (4,), optional
        ``(n, d)`` of the plane ``{x : n . x = d}`` in the root frame (in
        ``plane_frame`` when given; ``n`` is normalised; ``d`` metres); default the plane
        normal to the root's z through the first probe at the middle of the joint ranges
        (of the true robot).
    plane_name : str, optional
        The name of the plane (the ball, the point) in the measurement file; default
        ``table`` (``ball``, ``divot``).
    plane_frame : str, optional
        The URDF frame the plane is fixed to (a table link of the URDF), written as the
        plane observations' ``measured_in``; it must be fixed to the root (no movable
        joint between them). Default: the root.
    sphere : array_like, shape (4,), optional
        Instead of a plane, a ball the probes touch: its centre in the root frame and its
        radius, metres; ``sphere`` observations, the radius given (a tooling ball's is
        known), the centre left to the calibration.
    point : array_like, shape (3,), optional
        Instead of a plane, a point (a divot) the probes are placed on, in the root
        frame, metres; ``divot`` observations (the placement noise ``noise_m`` per
        axis), the point left to the calibration.
    contact_samples : int
        Contacts per probe.
    offsets_known : bool
        Write the markers' and probes' offsets into the file (known) instead of leaving
        them to be estimated.
    target_frame : str, optional
        With ``pixels``: the board rides on this URDF frame (a board on the flange seen
        by a static camera, eye-to-hand), its centre at the frame's origin facing the
        cameras at the middle of the joint ranges; its observations say
        ``"target_frame"``. Default: the board is fixed in the world.
    compliance : float or mapping of str to float, optional
        The true robot's joint compliance (:class:`kinfw.model.JointComplianceBlock`):
        rad/Nm (m/N for a prismatic joint) of every joint on the measured paths, or by
        joint (the others rigid). Every sampler draws the physical configurations as
        without it; the file records the readings that deflect to them under gravity
        (:meth:`kinfw.model.ModelSpec.readings`: ``q - c tau(q)``, exact), so the data
        are what an encoder-side controller would log. The truth's :attr:`Robot.spec`
        holds it.
    truth_model : ModelSpec, optional
        More of what the true robot's URDF cannot hold (gear scales, couplings, a
        compliance of some joints), each block at its true value (its ``start``), in the
        same way: the readings are :meth:`kinfw.model.ModelSpec.readings` of the
        simulated configurations.
    payloads : (str, float, array_like), optional
        ``(frame, max_kg, com_m)``: every sample carries a load on ``frame`` of a mass
        drawn uniformly in ``[0, max_kg]``, its centre of mass at ``com_m`` (3,) in that
        frame (m), written as the samples' payloads (with a compliance, the deflection
        follows it). Drawn from a generator of its own (``[seed, 2]``), so the rest of
        the experiment is the one without payloads.
    gravity : array_like, shape (3,), optional
        Gravity in the root frame (m/s^2; default 9.81 along -z), written to the file: a
        robot mounted on a wall or upside down deflects under it.
    seed : int
        Seeds the one generator of every draw.

    Returns
    -------
    SimulatedMeasurements

    Raises
    ------
    TypeError
        ``nominal`` is not a Robot (naming it).
    ValueError
        ``pixels`` without stage 2, a stage with no frames or cameras, intrinsics of a
        frame that is not a stage 2 camera, a ``mocap_frame`` of the URDF, a plane out
        of a probe's reach.
    """
    nominal = check_robot(nominal, "nominal")
    if stages is None:
        stages = (1, 2) if pixels else () if (markers or contacts) else (1,)
    stages = tuple(stages)
    if pixels and 2 not in stages:
        raise ValueError(f"pixels: stage 2 makes the images; got stages {stages}")
    if target_frame is not None and not pixels:
        raise ValueError(f"target_frame {target_frame!r}: a board on the robot needs pixels")
    if target_frame is not None:
        nominal.frame_id(target_frame)  # an unknown frame is named with the links
    frames, cameras = _observed(nominal, stages, frames, cameras)
    given = dict(intrinsics or {})
    if set(given) - set(cameras):
        raise ValueError(
            f"intrinsics of {sorted(set(given) - set(cameras))}: not stage 2 cameras "
            f"(cameras: {', '.join(cameras)})"
        )
    rng = np.random.default_rng(seed)
    truth_xml = perturb_robot(
        nominal, rng, origin_mm=error_mm, origin_deg=error_deg, axis_deg=error_deg
    )
    truth = load_robot(truth_xml)
    probe_frames = [frame for frame, _ in (*markers, *contacts)]
    on = () if target_frame is None else (target_frame,)
    names = nominal.topology((*frames, *cameras, *probe_frames, *on)).joint_names
    lower, upper = finite_limits(*nominal.joint_limits(names))  # continuous: +-pi
    noise = {"noise_m": noise_m, "noise_rad": noise_rad}
    if stereo_sigma_m is not None:
        noise["stereo_sigma_m"] = stereo_sigma_m
    planned = None if configurations is None else np.asarray(configurations, dtype=float)
    parts: list[Measurements] = []
    if frames:
        qs = planned
        if qs is None:
            qs, _ = one_joint_at_a_time(lower, upper, per_joint=per_joint, fraction=fraction)
        parts.append(simulate_at(truth, qs, names, frames=frames, rng=rng, **noise))
    shown = parse_board(board or DEFAULT_BOARD) if cameras and pixels else None
    w_T_board = None
    if cameras:
        stage2, w_T_board = _stage2(
            truth,
            cameras,
            names,
            (lower, upper),
            rng,
            planned,
            noise=noise,
            board=shown,
            intrinsics={c: given.get(c) or default_intrinsics(c) for c in cameras},
            pixel_sigma=pixel_sigma,
            stage2_samples=stage2_samples,
            fraction=fraction,
            target_frame=target_frame,
        )
        parts.append(stage2)
    at = _Sampling(truth, names, (lower, upper), fraction, rng, noise_m, offsets_known)
    mocap = _Mocap(mocap_frame, None, ())
    if markers:
        mocap = _simulate_markers(at, markers, mocap_frame, mocap_samples)
        parts.append(mocap.data)
    touch = _Touch()
    if contacts:
        touch = _simulate_contacts(
            at, contacts, (plane, sphere, point), plane_name, contact_samples, plane_frame
        )
        parts.extend(touch.data)
    data = concatenate_measurements(*parts)
    if gravity is not None:
        from dataclasses import replace

        data = replace(data, gravity=np.asarray(gravity, dtype=float))
    if payloads is not None:
        data = _with_payloads(truth, data, payloads, np.random.default_rng([seed, 2]))
    blocks = () if truth_model is None else truth_model.blocks
    if compliance is not None:
        blocks = (_compliance_block(names, compliance), *blocks)
    if blocks:
        truth, data = _with_truth_model(truth, data, names, ModelSpec(blocks))
    return SimulatedMeasurements(
        truth_xml,
        truth,
        data,
        names,
        frames,
        cameras,
        board=None if shown is None else shown.spec(),
        default_cameras=tuple(sorted(set(cameras) - set(given))) if shown is not None else (),
        w_T_board=w_T_board,
        markers=mocap.markers,
        mocap_frame=mocap.frame if markers else None,
        mocap_T_w=mocap.mocap_T_w,
        probes=touch.probes,
        plane=touch.plane,
        plane_name=touch.name,
        plane_frame=plane_frame if touch.plane is not None else None,
        sphere=touch.sphere,
        point=touch.point,
        target_frame=target_frame,
    )


def _with_payloads(
    truth: Robot, data: Measurements, payloads: tuple[str, float, ArrayLike], rng
) -> Measurements:
    """``data`` with a random payload per sample (see :func:`simulate_measurements`)."""
    from dataclasses import replace

    frame, max_kg, com_m = payloads
    truth.frame_id(frame)  # an unknown frame: named with the links
    if not (np.isfinite(max_kg) and max_kg >= 0):
        raise ValueError(f"payloads: the largest mass must be >= 0 kg, got {max_kg}")
    n = data.n_samples
    masses = rng.uniform(0.0, float(max_kg), size=n)
    com = np.tile(np.asarray(com_m, dtype=float).reshape(3), (n, 1))
    return replace(data, payloads=Payloads((frame,), np.zeros(n, np.intp), masses, com))


def _compliance_block(
    names: tuple[str, ...], compliance: float | Mapping[str, float]
) -> JointComplianceBlock:
    """The true compliance of ``names`` (rad/Nm, m/N): one value for all, or by joint."""
    if isinstance(compliance, Mapping):
        unknown = sorted(set(compliance) - set(names))
        if unknown:
            raise ValueError(
                f"compliance of {unknown}: not joints on the measured paths ({', '.join(names)})"
            )
        values = np.array([float(compliance.get(j, 0.0)) for j in names])
    else:
        values = np.full(len(names), float(compliance))
    if not np.all(np.isfinite(values)) or np.any(values < 0):
        raise ValueError(f"compliance: expected finite values >= 0 (rad/Nm, m/N), got {values}")
    return JointComplianceBlock.from_spec(",".join(names)).with_start(values)


def _with_truth_model(
    truth: Robot, data: Measurements, names: tuple[str, ...], spec: ModelSpec
) -> tuple[Robot, Measurements]:
    """The truth with its model spec, and ``data`` with the readings that give the
    simulated (physical) configurations through it."""
    from dataclasses import replace

    samples = BlockSamples(truth, names, data.q_of(names), data.sample_payloads(), data.gravity)
    spec = spec.bound(samples)
    q_read = spec.readings(truth, names, samples.qs, samples.payloads, samples.gravity)
    qs = data.qs.copy()
    for k, name in enumerate(names):
        qs[:, data.joint_names.index(name)] = q_read[:, k]
    return truth.with_spec(spec), replace(data, qs=qs)


# -- markers and contacts ----------------------------------------------------------------


def _probes(
    points: Sequence[tuple[str, ArrayLike | None]], prefix: str, rng: np.random.Generator
) -> tuple[SimulatedProbe, ...]:
    """The points named ``prefix1``, ``prefix2``, ...: their given offsets, else drawn
    (:data:`DEFAULT_OFFSET_M` long, uniform direction), in order."""
    out = []
    for k, (frame, offset) in enumerate(points, start=1):
        if offset is None:
            direction = rng.normal(size=3)
            offset = DEFAULT_OFFSET_M * direction / np.linalg.norm(direction)
        offset = np.asarray(offset, dtype=float)
        if offset.shape != (3,) or not np.isfinite(offset).all():
            raise ValueError(f"{prefix} on {frame!r}: expected 3 finite numbers, got {offset!r}")
        out.append(SimulatedProbe(str(frame), f"{prefix}{k}", offset))
    return tuple(out)


@dataclass(frozen=True, slots=True, eq=False)
class _Sampling:
    """What the markers' and the contacts' simulations share: the true robot, the joints
    (``names``) and their ``limits`` (``(lower, upper)``) and ``fraction`` drawn in, the
    generator, the noise (m) and whether the offsets are written as known."""

    truth: Robot
    names: tuple[str, ...]
    limits: tuple[NDArray[np.float64], NDArray[np.float64]]
    fraction: float
    rng: np.random.Generator
    noise_m: float
    offsets_known: bool


@dataclass(frozen=True, slots=True, eq=False)
class _Mocap:
    """Simulated markers: the external frame, the root's true pose in it, the markers
    and their data."""

    frame: str | None
    mocap_T_w: NDArray[np.float64] | None
    markers: tuple[SimulatedProbe, ...]
    data: Measurements | None = None


def _simulate_markers(
    at: _Sampling, markers: Sequence[tuple[str, ArrayLike | None]], mocap_frame: str | None, n: int
) -> _Mocap:
    """``point`` observations of every marker at ``n`` random configurations, in the
    external frame ``mocap_frame`` (None or the root: in the root)."""
    external = mocap_frame not in (None, at.truth.root_link)
    if external and at.truth.has_frame(mocap_frame):
        raise ValueError(
            f"mocap_frame {mocap_frame!r} is a frame of the URDF; the motion-capture frame "
            "is external (a name the URDF does not use), or the root "
            f"{at.truth.root_link!r}"
        )
    probes = _probes(markers, "marker", at.rng)
    unknowns: dict[BlockKey, NDArray[np.float64]] = {}
    mocap_T_w = None
    if external:
        mocap_T_w = perturb_transforms(np.eye(4)[None], at.rng, 1.0, 1.0)[0]
        unknowns[BlockKey("frame", mocap_frame)] = mocap_T_w
    qs = random_configurations(*at.limits, n, at.rng, fraction=at.fraction)
    sample = np.arange(n)
    templates = []
    for probe in probes:
        unknowns[offset_key(probe.frame, probe.name)] = probe.offset
        templates.append(
            PointObservations(
                frame=probe.frame,
                sample=sample,
                meas_p_point=np.zeros((n, 3)),
                offset=probe.offset if at.offsets_known else None,
                marker=None if at.offsets_known else probe.name,
                measured_in=mocap_frame if external else None,
            )
        )
    data = simulate_at(
        at.truth, qs, at.names, groups=templates, unknowns=unknowns, rng=at.rng, noise_m=at.noise_m
    )
    return _Mocap(mocap_frame if external else None, mocap_T_w, probes, data)


@dataclass(frozen=True, slots=True, eq=False)
class _Touch:
    """Simulated contacts: what is touched (the plane ``(n, d)``, the ball ``(c, r)`` or
    the point ``c``) and its name, the probes and one dataset per probe."""

    plane: NDArray[np.float64] | None = None
    sphere: NDArray[np.float64] | None = None
    point: NDArray[np.float64] | None = None
    name: str | None = None
    probes: tuple[SimulatedProbe, ...] = ()
    data: tuple[Measurements, ...] = ()


def _simulate_contacts(
    at: _Sampling,
    contacts: Sequence[tuple[str, ArrayLike | None]],
    touched: tuple[ArrayLike | None, ArrayLike | None, ArrayLike | None],
    name: str | None,
    n: int,
    plane_frame: str | None = None,
) -> _Touch:
    """``plane`` (``sphere``, ``divot``) observations: each probe touches the plane (the
    ball ``(c, r)``, the point ``c``: ``touched``, at most one given) at ``n``
    configurations; a plane given in ``plane_frame`` (see :func:`simulate_measurements`)
    is touched where the true robot holds that frame."""
    probes = _probes(contacts, "probe", at.rng)
    plane, sphere, point = (None if v is None else np.asarray(v, dtype=float) for v in touched)
    if sum(v is not None for v in (plane, sphere, point)) > 1:
        raise ValueError("contacts: give at most one of plane, sphere, point")
    for what, v, size in (("plane", plane, 4), ("sphere", sphere, 4), ("point", point, 3)):
        if v is not None and (v.shape != (size,) or not np.isfinite(v).all()):
            raise ValueError(f"{what}: expected {size} finite numbers, got {v.tolist()!r}")
    if sphere is not None and sphere[3] <= 0.0:
        raise ValueError(f"sphere: expected a radius > 0 m, got {sphere[3]!r}")
    if plane_frame is not None:
        if sphere is not None or point is not None:
            raise ValueError("plane_frame: only a plane can be fixed to a URDF frame here")
        if plane is not None:
            plane = _plane_in_root(at.truth, plane_frame, plane)
    if sphere is None and point is None:
        if plane is None:
            first = probes[0]
            plane = level_plane(
                at.truth, at.names, *at.limits, frame=first.frame, offset=first.offset
            )
        else:
            plane = plane_through(plane[:3] * (plane[3] / (plane[:3] @ plane[:3])), plane[:3])
    name = name or ("table" if plane is not None else "ball" if sphere is not None else "divot")
    data = []
    for probe in probes:
        qs = contact_configurations(
            at.truth,
            at.names,
            *at.limits,
            n,
            at.rng,
            frame=probe.frame,
            offset=probe.offset,
            plane=plane,
            sphere=sphere,
            point=point,
            fraction=at.fraction,
        )
        # the probe is on the surface (to CONTACT_TOLERANCE_M): the measured distance
        # (the gap to the point) is the noise alone (exactly 0 without noise)
        rows = 3 if point is not None else 1
        noise = (
            at.rng.normal(0.0, at.noise_m, (n, rows)) if at.noise_m > 0.0 else np.zeros((n, rows))
        )
        probe_fields = {
            "frame": probe.frame,
            "sample": np.arange(n),
            "offset": probe.offset if at.offsets_known else None,
            "marker": None if at.offsets_known else probe.name,
        }
        if plane is not None:
            group = PlaneContacts(
                distance_m=noise[:, 0], plane=name, measured_in=plane_frame, **probe_fields
            )
        elif sphere is not None:
            group = SphereContacts(
                distance_m=noise[:, 0], sphere=name, radius=float(sphere[3]), **probe_fields
            )
        else:
            group = DivotContacts(gap_m=noise, divot=name, **probe_fields)
        data.append(
            Measurements(joint_names=at.names, qs=qs, source="<simulated>").with_groups([group])
        )
    return _Touch(plane, sphere, point, name, probes, tuple(data))


def _plane_in_root(robot: Robot, frame: str, plane: ArrayLike) -> NDArray[np.float64]:
    """The plane ``(n, d)`` (4,) given in ``frame`` (fixed to the root) in the root:
    with ``root_T_frame = (R, t)``, ``x = R y + t`` for ``n . y = d`` gives ``(R n) . x =
    d + (R n) . t`` (``n`` normalised first)."""
    if not robot.has_frame(frame):
        raise ValueError(f"plane_frame: {frame!r} is not a frame of the URDF")
    moving = robot.movable_path(frame)
    if moving:
        raise ValueError(
            f"plane_frame: {frame!r} moves with the joints {list(moving)}: a plane to "
            "simulate must be fixed to the root (a table link on fixed joints)"
        )
    plane = np.asarray(plane, dtype=float)
    if plane.shape != (4,) or not np.isfinite(plane).all() or not plane[:3].any():
        raise ValueError(f"plane: expected 4 finite numbers n, d (n not 0), got {plane.tolist()!r}")
    T = robot.frame_poses(np.zeros(len(robot.joint_names)), frame)
    n = T[:3, :3] @ (plane[:3] / np.linalg.norm(plane[:3]))
    return np.concatenate([n, [plane[3] / np.linalg.norm(plane[:3]) + n @ T[:3, 3]]])
