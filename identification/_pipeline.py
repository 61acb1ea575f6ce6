"""The calibration pipeline: closed form, hand-eye, joint refinement, as the data allows.

This is the Python API behind ``kinfw calibrate``::

    from kinfw.model import load_robot
    from kinfw.measurements import read_measurements
    from kinfw.identification._pipeline import identify

    result = identify(load_robot("nominal.urdf"), read_measurements("data.json"))
    open("calibrated.urdf", "w").write(result.urdf_xml)
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.geometry import average_transform
from kinfw.identification._closed_form import ClosedFormResult, ProtocolError, identify_closed_form
from kinfw.identification.checks import (
    InsufficientDataError,
    UnitError,
    check_fit,
    check_redundancy,
    check_units,
    fit_warnings,
    median_residuals,
)
from kinfw.identification.handeye import CamerasResult, calibrate_cameras
from kinfw.identification.problem import (
    CHOICE_START,
    UNDETERMINED_LEFT,
    NoiseModel,
    RefineResult,
    build_problem,
    refine,
)
from kinfw.measurements import (
    Measurements,
    check_joint_motion,
    check_measurements,
    fixed_in_experiment,
    observed_joints,
)
from kinfw.model import ModelSpec, PriorScales, Robot, check_robot, geometry_from_cpc
from kinfw.observations import DatasetError, evenly_spaced
from kinfw.urdf import ExportResult, edit_urdf, export_urdf

log = logging.getLogger(__name__)

#: ``closed-form``: Shih et al.'s closed form and the hand-eye step only;
#: ``refine``: then the joint nonlinear least squares over everything (default).
METHODS = ("refine", "closed-form")


@dataclass(frozen=True, slots=True)
class Calibration:
    """A calibrated URDF and the stages that produced it.

    Attributes
    ----------
    urdf_xml : str
        The calibrated URDF: the nominal one with only joint origins and axes changed.
    stages : tuple of (str, str)
        ``(stage name, URDF text after it)`` for every stage that ran, in order
        (``"closed form"``, ``"hand-eye"``, ``"refine"``), for before/after reports.
    closed_form : ClosedFormResult or None
        Stage 1, when the data has one-joint-at-a-time ``pose`` observations.
    export : ExportResult or None
        The last export (measurement-frame pose ``w_T_root``, moved link frames).
    cameras : CamerasResult or None
        The hand-eye step, when the data has ``target`` observations (with method
        ``refine`` on a subsample of the views: ``n_views`` says how many).
    refined : RefineResult or None
        The joint refinement (method ``refine``).
    notes : tuple of str
        Stages skipped and why.
    spec : ModelSpec
        What the URDF cannot hold, calibrated (the refinement's
        :attr:`RefineResult.spec`): the URDF takes the joint values after its hooks.
    """

    urdf_xml: str
    stages: tuple[tuple[str, str], ...]
    closed_form: ClosedFormResult | None
    export: ExportResult | None
    cameras: CamerasResult | None
    refined: RefineResult | None
    notes: tuple[str, ...]
    spec: ModelSpec = field(default_factory=ModelSpec)

    @property
    def prior(self) -> PriorScales | None:
        """The prior the refinement was made under (given, or chosen from the data:
        :attr:`PriorScales.how`); None without one or a refinement."""
        return None if self.refined is None else self.refined.prior

    @property
    def w_T_root(self) -> NDArray[np.float64]:
        """Pose of the URDF root in the measurement frame (identity when the root is it)."""
        return np.eye(4) if self.export is None else self.export.w_T_root


def identify(
    nominal: Robot,
    data: Measurements,
    *,
    method: str = "refine",
    noise: NoiseModel | None = None,
    loss: str = "huber",
    parameters: str | tuple[str, ...] = "full",
    prior: PriorScales | tuple[float, float] | None = None,
    choose_prior: bool = False,
    refine_intrinsics: bool | tuple[str, ...] = (),
    model: ModelSpec | None = None,
) -> Calibration:
    """Calibrate ``nominal`` from ``data``.

    1. Closed form (Shih et al. section 4) when the data has one-joint-at-a-time
       ``pose`` observations in the root frame; it rewrites the joints on their paths.
    2. Hand-eye (section 5; Hirsh et al.) when it has ``target`` or ``pixels``
       observations (these through each image's PnP pose): each camera's fixed mount
       and the target pose, on the kinematics so far; with ``method="refine"``, whose
       start it only is, from at most :data:`HANDEYE_START_VIEWS` views of each camera
       evenly spread over its samples.
    3. With ``method="refine"``: the joint nonlinear least squares over every unknown and
       every observation (:func:`kinfw.identification.refine`), started from 1-2 (or
       from the nominal URDF when they could not run), then exported.

    Parameters
    ----------
    nominal : Robot
    data : Measurements
    method : {"refine", "closed-form"}
    noise : NoiseModel, optional
        Measurement noise for the refinement; default estimated.
    loss : {"huber", "linear", "cauchy"}
        Robust loss of the refinement (default Huber: a gross outlier is down-weighted
        whatever the parameter set; on clean data it costs little, its threshold being the
        99 % quantile of a clean residual).
    parameters : str or tuple of joint names
        Parameter set of the refinement (:func:`kinfw.identification.refine`):
        ``"full"``, ``"offsets"``, ``"frames"``, ``"none"`` or joint names.
    prior : PriorScales or (sigma_m, sigma_rad), optional
        Gaussian prior on deviations from the nominal geometry, one sigma per parameter
        group (:class:`kinfw.identification.PriorScales`; a pair: one length and one
        angle sigma). A deliberately restricted model, like a smaller ``parameters``
        set: its residuals are neither refused nor warned about (a too strong prior
        just predicts badly; the model choice scores it so).
    choose_prior : bool
        Choose the prior's group sigmas from the data by the linearised
        leave-one-sample-out error (:func:`kinfw.identification.refine`), from
        ``prior`` (default :data:`CHOICE_START`); :attr:`Calibration.prior` holds them.
    refine_intrinsics : bool or tuple of str
        Cameras of ``pixels`` observations whose intrinsics the refinement estimates
        too (True: all; :func:`kinfw.identification.refine`).
    model : ModelSpec, optional
        Robot blocks the URDF cannot hold, estimated with the geometry by the
        refinement (``--model compliance``, ``gear-scale:JOINT``...:
        :class:`kinfw.model.ModelSpec`), instead of ``nominal``'s own
        (:attr:`kinfw.model.Robot.spec`, empty for a URDF); their estimates are
        :attr:`Calibration.spec`.

    Checks, before any estimation (each raises a :class:`DatasetError` naming the
    file, the joints or frames and the fix):

    - units (:func:`kinfw.identification.checks.check_units`): joint values or lengths in
      another unit than the one they were read in (degrees read as radians, mm as m);
      a closed-form unit refusal (a joint that turns 0.0175 rad per unit of its value)
      is a refusal too, in every method;
    - with ``method="refine"``: every joint on a measured path moves, and the residuals
      determine the free parameters with redundancy
      (:func:`kinfw.identification.checks.check_redundancy`; with ``parameters="full"``
      the message says whether ``"frames"`` would be determined);
    - after the refinement over every parameter (without a prior), that it fits
      (:func:`kinfw.identification.checks.check_fit`).

    Each stage is told to :mod:`kinfw.progress` as it begins (the refinement's
    Levenberg-Marquardt iterations too) and logged (``INFO``) with what it found.

    After the refinement over every parameter without a prior, residuals that follow the
    joint values or exceed a plausible noise are warned about (``UserWarning``, one line
    each, naming the frame, the joint and the likely cause:
    :func:`kinfw.identification.checks.fit_warnings`).

    Raises
    ------
    DatasetError
        When no stage can use the data, or a check or stage refuses it (with the reason).
    TypeError
        ``nominal`` or ``data`` is not a Robot / Measurements (a path: load it first),
        naming the argument.
    """
    nominal = check_robot(nominal, "nominal")
    data = check_measurements(data, "data")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    progress.stage("checking the units")
    check_units(nominal, data)
    if model:
        if method != "refine":
            raise ValueError(
                f"model {', '.join(model.texts)}: robot blocks are estimated by the "
                f"refinement; method {method!r} cannot (use method 'refine')"
            )
        nominal = nominal.with_spec(model)
    prior = PriorScales.of(prior)
    if choose_prior and prior is None:
        prior = CHOICE_START
    options = _RefineOptions(noise, loss, parameters, prior, refine_intrinsics, choose_prior)
    if method == "refine":
        progress.stage("checking that the data determine the parameters (start values)")
        fixed_note = _check_refinable(nominal, data, options)
    clock = time.perf_counter()

    def done(message: str) -> None:
        nonlocal clock
        log.info("%s (%.2f s)", message, time.perf_counter() - clock)
        clock = time.perf_counter()

    closed_form = export = cameras = refined = None
    stages: list[tuple[str, str]] = []
    notes: list[str] = [fixed_note] if method == "refine" and fixed_note else []
    xml = nominal.urdf_xml
    if parameters == "full" and any(g.marker is None and g.measured_in is None for g in data.poses):
        progress.stage("closed form (Shih et al.)")
        closed_form, skipped = _try_closed_form(nominal, data, method)
        if closed_form is None:
            notes.append(skipped)
        else:
            export = export_urdf(nominal, closed_form.geometry)
            xml = export.urdf_xml
            stages.append(("closed form", xml))
            done(
                f"closed form: {len(closed_form.model.topology.joint_names)} joints, "
                f"position RMS {1e3 * closed_form.position_rms_m:.3f} mm"
            )
    if (data.targets or data.groups("pixels")) and parameters != "none":
        progress.stage("hand-eye")
        # only the refinement's start: a well-spread subsample is as good and far cheaper
        cameras = calibrate_cameras(
            Robot(xml, nominal.source), _start_views(data) if method == "refine" else data
        )
        xml = _with_camera_mounts(xml, cameras)
        stages.append(("hand-eye", xml))
        done(f"hand-eye: {len(cameras.cameras)} camera(s)")
    if method == "refine":
        progress.stage("refine: joint least squares over every unknown")
        refined, found = _refine_checked(
            nominal, data, Robot(xml, nominal.source), cameras, options
        )
        for warning in found:
            warnings.warn(f"{data.source}: {warning}", UserWarning, stacklevel=2)
        export = export_urdf(
            nominal,
            geometry_from_cpc(refined.model),
            root_is_measurement_frame=refined.model_frame is None,
            base_motion=refined.w_T_base,
        )
        xml = export.urdf_xml
        stages.append(("refine", xml))
        done(
            f"refine: {refined.identifiability.n_parameters} free parameters, "
            f"{refined.iterations} iterations, reduced chi-square {refined.sigma_hat2:.3g}"
        )
    if not stages:
        raise DatasetError(
            f"{data.source}: nothing to calibrate: the closed form needs one-joint-at-a-time "
            "'pose' observations in the root frame and the hand-eye step 'target' "
            "observations; use the default method 'refine' for any other data"
        )
    for note in notes:
        log.info(note)
    spec = refined.spec if refined is not None else ModelSpec()
    return Calibration(
        xml, tuple(stages), closed_form, export, cameras, refined, tuple(notes), spec
    )


#: Samples per ``target`` or ``pixels`` group that the hand-eye stage sees when it only
#: starts the refinement (:func:`_start_views`): its closed form and robust fit cost
#: about 0.3 ms a view, a few hundred views determine a start to well within the
#: refinement's reach.
HANDEYE_START_VIEWS = 500


def _start_views(data: Measurements) -> Measurements:
    """``data`` restricted to the samples of at most :data:`HANDEYE_START_VIEWS` views of
    each ``target`` or ``pixels`` group, evenly spread over the group's samples in order
    (:func:`kinfw.observations.evenly_spaced`); ``data`` itself when no group has more."""
    views = [np.unique(g.sample) for g in (*data.targets, *data.groups("pixels"))]
    if all(len(v) <= HANDEYE_START_VIEWS for v in views):
        return data
    picked = [v[evenly_spaced(len(v), HANDEYE_START_VIEWS)] for v in views]
    return data.subset(np.unique(np.concatenate(picked)))


@dataclass(frozen=True, slots=True)
class _RefineOptions:
    """The options of :func:`identify` that its refinement takes (see there)."""

    noise: NoiseModel | None
    loss: str
    parameters: str | tuple[str, ...]
    prior: PriorScales | None
    refine_intrinsics: bool | tuple[str, ...]
    choose_prior: bool = False


def _check_refinable(nominal: Robot, data: Measurements, options: _RefineOptions) -> str:
    """The checks of :func:`identify` before a refinement: every joint on a measured path
    moves but those fixed in this experiment (:func:`kinfw.measurements.fixed_in_experiment`:
    said in the note returned, "" for none), and the residuals determine the free
    parameters with redundancy."""
    parameters, prior = options.parameters, options.prior
    # every joint on a measured path must move, or its geometry is not observed
    fixed = fixed_in_experiment(data, nominal)
    if parameters in ("full", "offsets"):
        check_joint_motion(data, observed_joints(data, nominal), fixed=fixed)
    cameras_seen = {g.camera for g in (*data.targets, *data.groups("pixels"))}
    smaller = None
    if parameters == "full":
        smaller = (
            "frames",
            build_problem(nominal, data, parameters="frames", prior=prior),
        )
    check_redundancy(
        build_problem(
            nominal,
            data,
            parameters=parameters,
            prior=prior,
            refine_intrinsics=options.refine_intrinsics,
        ),
        noise_given=options.noise is not None,
        n_samples=data.n_samples,
        source=data.source,
        cameras=cameras_seen,
        smaller=smaller,
    )
    if not fixed:
        return ""
    return (
        f"joint(s) {', '.join(fixed)} never move and carry no observed frame, only the "
        "frame a contact surface is fixed to (its unknown pose absorbs them): fixed in "
        "this experiment; their parameters are not identifiable from these data and stay "
        "at the nominal"
    )


def _try_closed_form(
    nominal: Robot, data: Measurements, method: str
) -> tuple[ClosedFormResult | None, str]:
    """The closed form of :func:`identify`, or None and why it was skipped (a refusal
    raises with ``method="closed-form"`` and for a unit error)."""
    if nominal.exact_joints and method != "closed-form":
        return None, (
            f"closed form skipped: it would move the exact joints {list(nominal.exact_joints)}"
            " (the URDF's <kinfw exact>); the refinement starts from the nominal"
        )
    try:
        return identify_closed_form(nominal, data), ""
    except ProtocolError as exc:
        if method == "closed-form" or isinstance(exc, UnitError):
            raise
        return None, f"closed form skipped: {exc}"


def _with_camera_mounts(xml: str, cameras: CamerasResult) -> str:
    """``xml`` with each camera's joint origin set to its hand-eye mount (a camera that
    saw several targets: the average of its mounts)."""
    mounts: dict[str, list[NDArray]] = {}
    for c in cameras.cameras:
        mounts.setdefault(c.joint, []).append(c.hand_T_camera)
    return edit_urdf(
        xml,
        joint_origins={
            joint: average_transform(np.stack(poses)) for joint, poses in mounts.items()
        },
    )


def _refine_checked(
    nominal: Robot,
    data: Measurements,
    start: Robot,
    cameras: CamerasResult | None,
    options: _RefineOptions,
) -> tuple[RefineResult, tuple[str, ...]]:
    """The refinement stage of :func:`identify` from ``start`` and the hand-eye's target
    poses, its fit checked when the model is unrestricted; with the fit warnings to
    issue."""
    targets = dict(cameras.root_T_targets) if cameras is not None else None
    refined = refine(
        nominal,
        data,
        start=start,
        targets=targets,
        noise=options.noise,
        loss=options.loss,
        parameters=options.parameters,
        prior=options.prior,
        choose_prior=options.choose_prior,
        refine_intrinsics=options.refine_intrinsics,
    )
    # a smaller set, or a prior, is a deliberately restricted model (baselines, the
    # model choice's candidates): its residuals are expected to show what it leaves out
    unrestricted = options.parameters == "full" and options.prior is None
    found = fit_warnings(refined, data) if unrestricted else ()
    if unrestricted:
        try:
            check_fit(refined, data.source)
        except UnitError as exc:  # the residuals' structure names a likelier cause
            order = _quaternion_order_hint(nominal, data, options)
            written = [f"as written: {exc}"] if order else [str(exc)]
            also = [f"also: {w}" for w in found]
            raise UnitError("\n".join((*order, *written, *also))) from None
        # a fit that passes but is contradicted by its residuals may still be the wrong
        # quaternion order (a few frames, the rest of the error absorbed by the geometry)
        order = _quaternion_order_hint(nominal, data, options) if found else ()
        if order:
            raise UnitError("\n".join((*order, *(f"as written: {w}" for w in found))))
    # drifted along what the data do not determine and not brought back: meaningless geometry
    if refined.undetermined > UNDETERMINED_LEFT:
        raise InsufficientDataError(_undetermined_refusal(nominal, data, refined, options))
    return refined, found


def _undetermined_refusal(
    nominal: Robot, data: Measurements, refined: RefineResult, options: _RefineOptions
) -> str:
    """Why a refinement is refused whose estimate moved along what the data do not
    determine and could not be brought back
    (:attr:`RefineResult.undetermined`): the exported geometry would be meaningless
    there (the root's joint moved by a metre on little contact data), whatever the
    predictions."""
    try:  # the export of a degenerate estimate (an axis turned over) may not exist
        exported = Robot(
            export_urdf(
                nominal,
                geometry_from_cpc(refined.model),
                root_is_measurement_frame=refined.model_frame is None,
                base_motion=refined.w_T_base,
            ).urdf_xml,
            nominal.source,
        )
    except ValueError:
        shown, scale = "", ""
    else:
        worst = max(
            (
                np.linalg.norm(
                    exported.joint(n).parent_T_child[:3, 3] - nominal.joint(n).parent_T_child[:3, 3]
                ),
                n,
            )
            for n in refined.model.topology.joint_names
        )
        shown = f" (the largest move of a joint origin: {worst[1]!r} by {worst[0]:.3g} m)"
        scale = _scale_drift(nominal, exported, data)
    params = options.parameters if isinstance(options.parameters, str) else "the mask"
    return (
        f"{data.source}: too little data to refine --params {params}: the fit "
        + ("converged" if refined.converged else "did not converge")
        + f" in {refined.iterations} iterations and moved "
        f"{refined.undetermined:.3g} (m, rad) along directions these data do not "
        f"determine, which it cannot bring back to the nominal URDF{shown}: the exported "
        f"geometry would be meaningless there.{scale} Refine fewer parameters, "
        + (
            "add a prior (--prior-mm, --prior-deg)"
            if options.prior is None
            else f"a tighter prior than {options.prior.label.removeprefix('prior ')}"
        )
        + ", or add data"
    )


#: A refused fit whose observed frames' distances between samples are all this far from
#: the nominal's in the same ratio (its 5-95 % range within :data:`SCALE_SPREAD` of it)
#: has drifted in scale (:func:`_scale_drift`).
SCALE_DRIFT = 0.05
SCALE_SPREAD = 0.25


def _scale_drift(nominal: Robot, exported: Robot, data: Measurements, n: int = 100) -> str:
    """A sentence when the refused fit ``exported`` is the nominal robot scaled: the
    distances between its observed frames' positions at ``n`` of the data's samples are
    :data:`SCALE_DRIFT` or more off the nominal's, in one ratio. Contacts with one plane,
    one point or a ball of unknown radius hold for the robot and the surface scaled
    together about the surface (a robot of any size touches a plane through its base), so
    they do not determine the size; their noise alone pulls on it. Empty otherwise."""
    qs = data.qs[np.linspace(0, data.n_samples - 1, min(n, data.n_samples)).astype(int)]
    ratios = []
    for frame in data.observed_frames:
        try:
            a, b = (
                r.frame_poses(qs, frame, data.joint_names)[:, :3, 3] for r in (nominal, exported)
            )
        except (KeyError, ValueError):
            continue
        d0 = np.linalg.norm(a[:, None] - a[None], axis=-1)
        d1 = np.linalg.norm(b[:, None] - b[None], axis=-1)
        far = d0 > 0.1 * d0.max()
        ratios.append(d1[far] / d0[far])
    if not ratios or not (values := np.concatenate(ratios)).size:
        return ""
    low, mid, high = np.percentile(values, [5, 50, 95])
    if abs(mid - 1.0) < SCALE_DRIFT or high - low > SCALE_SPREAD * mid:
        return ""
    return (
        f" The fitted robot is {mid:.3g} times the nominal's size (the distances between "
        f"the observed frames over the samples, {low:.3g}-{high:.3g}): contacts with one "
        "plane, one point or a ball of unknown radius hold for the robot scaled with the "
        "surface, so they cannot tell its size; a length they fix can (a ball of known "
        "radius, planes at known distances, poses or points from a tracker)."
    )


def _quaternion_order_hint(
    nominal: Robot, data: Measurements, options: _RefineOptions
) -> tuple[str, ...]:
    """When the data do not fit but would with their quaternions in the other order
    (:meth:`kinfw.measurements.Measurements.with_quaternions_reordered`) without a
    warning about the fit: a first line saying so and a line with the fit in that
    order, to put first; else nothing."""
    swapped = data.with_quaternions_reordered()
    if swapped is None:
        return ()
    progress.stage("the data do not fit: trying the quaternions in the other order")
    # a trial: its warnings (warned or logged) are about data the user did not give
    package = logging.getLogger("kinfw.identification")
    level = package.level
    package.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            result = refine(nominal, swapped, noise=options.noise, loss=options.loss)
            check_fit(result, data.source)
    except ValueError:  # no better in the other order: not the cause
        return ()
    finally:
        package.setLevel(level)
    if fit_warnings(result, swapped):  # no cleaner in the other order either
        return ()
    pos, rot = median_residuals(result)
    return (
        f"{data.source}: the orientations look like quaternions stored scalar first "
        "(w, x, y, z), kinfw reads them scalar last (quat_xyzw): reorder them in the file",
        f"read in that order, the data fit (median residual {1e3 * pos:.3g} mm, "
        f"{np.degrees(rot):.3g} deg)",
    )
