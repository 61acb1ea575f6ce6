"""Visual check of a calibration in meshcat: nominal ghost, calibrated robot, data, residuals.

:func:`scene` draws, in one meshcat scene,

- the nominal robot as a translucent grey ghost and the calibrated robot in colour,
  overlaid at one configuration (Pinocchio's ``MeshcatVisualizer``: URDF boxes,
  cylinders, spheres and the meshes that can be found; when meshes are missing, the
  robot's links as a skeleton too, triads and segments between joint origins, with one
  logged warning for them all);
- the observations of one sample of a dataset, each kind through its ``drawing``
  (:class:`kinfw.observations.Drawing`): a triad (x red, y green, z blue, 3 cm, a
  dark ball at the origin) per measured orientation (a ``pose``; a ``target`` where a
  camera saw it), a ball per measured position (a ``point``);
- a residual line per observation, from the model's prediction towards the measurement,
  ``residual_scale`` times as long as the error so that millimetres show, coloured by
  the error (:data:`RESIDUAL_COLOR_STOPS_MM`);
- fixed targets (e.g. from the calibration sidecar, :func:`targets_from_sidecar`) as a
  flat board with a triad, and the cameras' frames as smaller triads.

Triads and residual lines are thin cylinders drawn over everything (WebGL draws lines one
pixel wide whatever their ``linewidth``). Everything is placed under the node
``/meshcat/kinfw`` in root-link coordinates; that node's transform ``display_T_root``
puts the centre of the framed points at the display origin, which meshcat 0.3.2's orbit
camera always looks at, with ``up`` along the display's z axis. Paths below
``/meshcat/kinfw``::

    nominal/visuals/<link>_<i>               the ghost (the solid model when alone)
    calibrated/visuals/<link>_<i>            the calibrated robot
    measured/poses/<frame>[@<marker>]        triad of a measured pose: x, y, z, origin
    measured/points/<frame>[@<marker>]       ball of a measured point
    measured/targets/<camera>/<target>       triad of a target where the camera saw it
    residuals/poses/<frame>[@<marker>]       residual line; also residuals/points/...
    residuals/targets/<camera>/<target>        and residuals/targets/...
    measured/pixels/<camera>/<target>/<k>    an image's point k: the measured pixel's
                                             ray at the predicted point's depth (a ball)
    predicted/pixels/<camera>/<target>/<k>   ... where the model puts the point
    residuals/pixels/<camera>/<target>/<k>   ... and the residual line between them
    targets/<target>                         a fixed target: board and triad
    cameras/<camera>                         triad of a camera frame
    cameras/<camera>/frustum/{ray,edge}<k>   the frustum of a camera with intrinsics:
                                             the image's corners at 0.2 m

A residual line's node has the transform ``[R | root_p_predicted]`` with R's y axis along
the error; its child ``stick`` is a cylinder of height ``residual_scale * |measured -
predicted|`` reaching from the node's origin along y, its child ``tip`` a ball at the end.

:func:`write_html` saves the scene as one self-contained HTML file (meshcat's viewer
script inlined, no network access). Without a server, draw into an
:class:`OfflineWindow`. meshcat is imported inside the functions: ``import kinfw`` does not
load it.

The robot's geometry and the view's framing are drawn by :mod:`kinfw.view`; the
offline window and the HTML file are in :mod:`kinfw.view` (:class:`OfflineWindow`,
:func:`write_html` and :func:`external_urls` are re-exported here).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform
from kinfw.measurements import Measurements, check_against_robot
from kinfw.model import STANDARD_GRAVITY, BlockKey, Robot, load_robot
from kinfw.observations import MissingValue, NumericContext, kind_of, node_name
from kinfw.records import CalibrationSidecar, read_sidecar
from kinfw.view._cameras import draw_cameras
from kinfw.view._draw import (
    TRIAD_LENGTH,
    overlay_object,
    rgb_int,
    stick,
    transform_from_translation,
    triad,
    up_direction,
)
from kinfw.view._robot import draw_robot, frame_scene

if TYPE_CHECKING:
    import meshcat

logger = logging.getLogger(__name__)

GHOST_RGBA = (0.25, 0.25, 0.28, 0.35)
"""Colour of the nominal robot's ghost: translucent grey (RGBA in [0, 1])."""
SOLID_RGBA = (0.1, 0.45, 0.85, 1.0)
"""Colour of the calibrated robot (of the nominal one when it is drawn alone)."""
TARGET_RGBA = (0.95, 0.8, 0.25, 0.8)
"""Colour of a fixed target's flat box."""
RESIDUAL_COLOR_STOPS_MM = (
    (0.0, (0.0, 0.7, 0.2)),
    (2.0, (1.0, 0.6, 0.0)),
    (10.0, (0.85, 0.0, 0.85)),
)
"""Residual line colour against the error (before scaling), mm: green at 0 mm, orange at
2 mm, magenta at 10 mm and more, linear in between."""
TARGET_SIZE = (0.16, 0.12, 0.004)
"""Size of a fixed target's box along its x, y, z axes, metres (z: the target normal)."""
POINT_RADIUS = 0.004
"""Radius of a measured point's sphere, metres."""
POINT_RGB = (0.45, 0.1, 0.6)
"""Colour of a measured point's sphere."""
RESIDUAL_RADIUS = 0.0015
"""Radius of a residual line's cylinder, metres (its tip is a ball 1.6 times wider)."""
MEASURED_RGB = (0.1, 0.1, 0.1)
"""Colour of the ball at the origin of a measured pose's triad."""
PREDICTED_RGB = (0.0, 0.55, 0.75)
"""Colour of the small ball where the model predicts a point of an image."""


# -- small helpers -----------------------------------------------------------------------


def as_robot(robot: Robot | str | Path, name: str) -> Robot:
    if isinstance(robot, Robot):
        return robot
    if isinstance(robot, (str, Path)):
        return load_robot(robot)
    raise TypeError(f"{name}: expected a Robot or a URDF path, got {type(robot).__name__}")


def residual_color(error_m: float) -> tuple[float, float, float]:
    """RGB of a residual line for an error of ``error_m`` metres (see
    :data:`RESIDUAL_COLOR_STOPS_MM`)."""
    e = 1e3 * float(error_m)
    stops = RESIDUAL_COLOR_STOPS_MM
    if e <= stops[0][0]:
        return stops[0][1]
    for (e0, c0), (e1, c1) in itertools.pairwise(stops):
        if e <= e1:
            t = (e - e0) / (e1 - e0)
            return tuple(float(a + t * (b - a)) for a, b in zip(c0, c1, strict=True))
    return stops[-1][1]


# -- the scene ---------------------------------------------------------------------------


def scene(
    nominal: Robot | str | Path,
    calibrated: Robot | str | Path | None = None,
    data: Measurements | None = None,
    *,
    q: ArrayLike | None = None,
    joint_names: Sequence[str] | None = None,
    sample: int | None = None,
    targets: Iterable[tuple[str, ArrayLike]] = (),
    window: Any = None,
    residual_scale: float = 10.0,
    meas_T_root: ArrayLike | None = None,
    up: ArrayLike | None = None,
    package_dirs: Sequence[str | Path] = (),
    ghost_rgba: Sequence[float] = GHOST_RGBA,
    solid_rgba: Sequence[float] | None = SOLID_RGBA,
    unknowns: Mapping[BlockKey, ArrayLike] | None = None,
) -> meshcat.Visualizer:
    """Draw a calibration for a visual check: nominal ghost, calibrated robot, data.

    Parameters
    ----------
    nominal : Robot or path
        The nominal robot, drawn as a translucent ghost (``ghost_rgba``); drawn solid
        (``solid_rgba``) when there is no ``calibrated`` robot.
    calibrated : Robot or path, optional
        The calibrated robot, drawn solid. Residuals are its errors (the nominal's when
        it is None).
    data : Measurements, optional
        Measurements; the observations of one sample are drawn.
    q : array_like, shape (k,), optional
        Joint values (rad, m) at which both robots are drawn, in the order of
        ``joint_names``. Default: the configuration of sample ``sample`` of ``data``
        (sample 0), else all zeros.
    joint_names : sequence of str, optional
        Order of ``q``; default ``data.joint_names`` with data, else the nominal robot's
        movable joints.
    sample : int, optional
        Sample of ``data`` whose observations are drawn. Default 0 when ``q`` is not
        given; when ``q`` is given, observations are drawn only if ``sample`` is (the
        caller vouches that it was measured at ``q``).
    targets : iterable of (str, array_like (4, 4))
        Fixed targets ``(name, root_T_target)`` (e.g. :func:`targets_from_sidecar`):
        drawn as a flat box and a triad; ``target`` observations of a known target get
        a residual line from the target towards where the camera saw it.
    window : object, optional
        A meshcat window (``send(command)`` and ``get_scene()``), e.g.
        :class:`OfflineWindow`. None starts a meshcat server on 127.0.0.1.
    residual_scale : float
        Residual lines are ``residual_scale`` times the error (default 10: 1 mm -> 1 cm).
    meas_T_root : array_like, shape (4, 4), optional
        Pose of the root link in the data's ``measured_in`` frame (the sidecar's
        ``w_T_root``); observations made in such a frame are skipped without it.
    up : array_like, shape (3,), optional
        The direction, in the root frame, to show upwards. Default: the ``up`` attribute
        of the URDF's ``<kinfw>`` element (``<kinfw up="0 -1 0"/>``), else ``+z``.
    package_dirs : sequence of path
        Folders searched for ``package://`` meshes. When meshes are not found, one
        warning says how many and where, and the robot is drawn as a skeleton too.
    ghost_rgba, solid_rgba : sequence of 4 floats
        Colours of the ghost and of the solid robot; ``solid_rgba=None`` keeps the
        URDF's materials.
    unknowns : mapping of BlockKey to array_like, optional
        Values of other unknown blocks in the root frame (a marker's pose (4, 4), a
        point offset (3,), a kind's own): observations that need them get residual
        lines. Every kind is drawn by its
        :meth:`~kinfw.observations.ObservationKind.drawing`.

    Returns
    -------
    meshcat.Visualizer
        The visualizer (its ``window`` is ``window``); see :func:`write_html`.

    Notes
    -----
    Framing: the camera looks at the centre of the bounding box of the moving links'
    visuals (links behind a movable joint), the observations, their predictions and the
    cameras, from the side of the root origin (where the measurement system is when the
    root link is the measurement frame), 15 deg above the horizon, close enough that
    all of them fill most of the view; fixed links and targets are drawn but not
    framed. ``/Axes`` and ``/Grid`` are hidden. ``get_image`` is never called.
    """
    import meshcat

    nominal = as_robot(nominal, "nominal")
    calibrated = None if calibrated is None else as_robot(calibrated, "calibrated")
    model = calibrated if calibrated is not None else nominal
    if not residual_scale > 0:
        raise ValueError(f"residual_scale: expected a positive number, got {residual_scale}")
    if data is not None:
        data = check_against_robot(data, model)
    if joint_names is None:
        joint_names = data.joint_names if data is not None else nominal.joint_names
    joint_names = tuple(joint_names)
    sample, q = _sample_and_configuration(data, joint_names, sample, q)
    targets = tuple(
        (str(name), check_transform(np.asarray(T, float), name=f"targets[{name!r}]"))
        for name, T in targets
    )
    up = up_direction(model, up)

    vis = meshcat.Visualizer() if window is None else meshcat.Visualizer(window=window)
    root = vis["kinfw"]
    # the calibrated robot at the joint values its readings give through its model spec
    # (a compliance's deflection, a gear scale); the nominal ghost at the readings
    q_model = q
    if model.spec:
        loads = (
            (None, STANDARD_GRAVITY)
            if data is None or sample is None
            else (
                data.sample_payloads().subset([sample]),
                data.gravity,
            )
        )
        q_model = model.spec.joint_values(model, joint_names, q[None], *loads)[0]
    robot_ps = _draw_robots(
        vis, nominal, calibrated, (q, q_model), joint_names, ghost_rgba, solid_rgba, package_dirs
    )
    focus_ps = []
    if data is not None and sample is not None:
        values = _known_values(data, targets, meas_T_root, unknowns)
        focus_ps.append(
            _draw_observations(
                root, model, data, sample, q_model, joint_names, values, residual_scale
            )
        )
    focus_ps.append(draw_cameras(root, model, data, q_model, joint_names))
    _draw_targets(root, targets)
    focus = np.concatenate([*robot_ps, *focus_ps])

    frame_scene(vis, root, focus, up)
    return vis


def _sample_and_configuration(
    data: Measurements | None,
    joint_names: tuple[str, ...],
    sample: int | None,
    q: ArrayLike | None,
) -> tuple[int | None, NDArray[np.float64]]:
    """Check ``sample``; default ``q`` to its configuration (sample 0), else zeros.

    Returns the sample whose observations are drawn (None: none) and ``q``, shape (k,).
    """
    if sample is not None and (data is None or not 0 <= sample < data.n_samples):
        n = 0 if data is None else data.n_samples
        valid = f"0 to {n - 1}" if n else "no sample: there is no data"
        raise IndexError(f"sample {sample} is out of range for {n} samples ({valid})")
    if q is None:
        if data is not None and data.n_samples:
            sample = 0 if sample is None else int(sample)
            q = data.qs[sample]
        else:
            q = np.zeros(len(joint_names))
    q = np.asarray(q, dtype=float)
    if q.shape != (len(joint_names),):
        raise ValueError(
            f"q: expected shape ({len(joint_names)},) for joints {list(joint_names)}, got {q.shape}"
        )
    return sample, q


def _draw_robots(
    vis: meshcat.Visualizer,
    nominal: Robot,
    calibrated: Robot | None,
    qs: tuple[NDArray[np.float64], NDArray[np.float64]],
    joint_names: tuple[str, ...],
    ghost_rgba: Sequence[float],
    solid_rgba: Sequence[float] | None,
    dirs: Sequence[Path],
) -> list[NDArray[np.float64]]:
    """Draw the nominal ghost (if there is a calibrated robot) at the readings and the
    solid robot at its joint values: ``qs = (readings, joint values)``.

    Returns the points to frame of each robot drawn (see :func:`draw_robot`).
    """
    q, q_model = qs
    robot_ps = []
    if calibrated is not None:
        robot_ps.append(
            draw_robot(
                vis,
                nominal,
                "kinfw/nominal",
                nominal.pin_configurations(q, joint_names)[0],
                ghost_rgba,
                dirs,
            )
        )
    model = calibrated if calibrated is not None else nominal
    robot_ps.append(
        draw_robot(
            vis,
            model,
            "kinfw/calibrated" if calibrated is not None else "kinfw/nominal",
            model.pin_configurations(q_model, joint_names)[0],
            solid_rgba,
            dirs,
        )
    )
    return robot_ps


def _known_values(
    data: Measurements,
    targets: tuple[tuple[str, NDArray], ...],
    meas_T_root: ArrayLike | None,
    unknowns: Mapping[BlockKey, ArrayLike] | None,
) -> dict[BlockKey, NDArray]:
    """The block values the view knows: the targets, ``meas_T_root`` for every
    measurement frame of the data, and ``unknowns``."""
    values = {BlockKey("target", name): T for name, T in targets}
    if meas_T_root is not None:
        meas_T_root = check_transform(np.asarray(meas_T_root, float), name="meas_T_root")
        for g in data.all_groups():
            measured_in = kind_of(g).measured_in(g)
            if measured_in is not None:
                values[BlockKey("frame", measured_in)] = meas_T_root
    values.update({k: np.asarray(v, dtype=float) for k, v in (unknowns or {}).items()})
    return values


def _draw_observations(
    root: meshcat.Visualizer,
    model: Robot,
    data: Measurements,
    sample: int,
    q: NDArray,
    joint_names: tuple[str, ...],
    values: dict[BlockKey, NDArray],
    residual_scale: float,
) -> NDArray[np.float64]:
    """The observations of one sample and their residual lines, every kind through its
    :meth:`~kinfw.observations.ObservationKind.drawing`; return the points to
    frame (the measured and predicted positions of the kinds that ask for it)."""
    import meshcat.geometry as mg

    context = NumericContext.from_robot(model, q, joint_names, values)
    drawn = []
    for g in data.all_groups():
        kind = kind_of(g)
        rows = np.flatnonzero(g.sample == sample)
        if not rows.size:
            continue
        try:
            drawing = kind.drawing(kind.take(g, rows, np.zeros(len(rows), np.int64)), context)
        except MissingValue as exc:
            hint = (
                "; pass meas_T_root (the sidecar's w_T_root) to draw it"
                if exc.key.kind == "frame"
                else ""
            )
            logger.warning(
                "%s: sample %d: cannot draw %r (%s)%s", data.source, sample, g, exc, hint
            )
            continue
        except NotImplementedError as exc:
            logger.info("%s: %s", data.source, exc)
            continue
        # one row per observation (a pose, a point): the group's node; many (an
        # image's points): one child node per row, <node>/<k>
        many = len(drawing.w_p_measured) > 1
        for k in range(len(drawing.w_p_measured)):
            path = drawing.node + (f"/{k}" if many else "")
            node = root["measured/" + path]
            w_p = drawing.w_p_measured[k]
            if drawing.w_R_measured is not None:
                w_T = np.eye(4)
                w_T[:3, :3], w_T[:3, 3] = drawing.w_R_measured[k], w_p
                triad(node, w_T, origin_rgb=MEASURED_RGB)
            else:
                node.set_object(overlay_object(mg.Sphere(POINT_RADIUS), POINT_RGB))
                node.set_transform(transform_from_translation(w_p))
            if drawing.focus:
                drawn.append(w_p)
            if drawing.w_p_predicted is None:
                logger.info(
                    "%s: sample %d: no residual for %s (%s is unknown)",
                    data.source,
                    sample,
                    drawing.node,
                    drawing.missing,
                )
                continue
            w_p_pred = drawing.w_p_predicted[k]
            _residual_line(root["residuals/" + path], w_p_pred, w_p, residual_scale)
            if drawing.w_R_measured is None and many:
                # the predicted point too: a small ball (where the model puts the point)
                root["predicted/" + path].set_object(
                    overlay_object(mg.Sphere(0.5 * POINT_RADIUS), PREDICTED_RGB)
                )
                root["predicted/" + path].set_transform(transform_from_translation(w_p_pred))
            if drawing.focus:
                drawn.append(w_p_pred)
    return np.array(drawn).reshape(-1, 3)


def _residual_line(
    node: meshcat.Visualizer, root_p_pred: NDArray, root_p_meas: NDArray, residual_scale: float
) -> None:
    """A residual line from the prediction towards the measurement, scaled."""
    import meshcat.geometry as mg

    error = root_p_meas - root_p_pred
    rgb = residual_color(float(np.linalg.norm(error)))
    stick(node, root_p_pred, residual_scale * error, RESIDUAL_RADIUS, rgb)
    node["tip"].set_object(overlay_object(mg.Sphere(1.6 * RESIDUAL_RADIUS), rgb))
    node["tip"].set_transform(
        transform_from_translation([0.0, residual_scale * float(np.linalg.norm(error)), 0.0])
    )


def _draw_targets(
    root: meshcat.Visualizer, targets: tuple[tuple[str, NDArray], ...]
) -> NDArray[np.float64]:
    import meshcat.geometry as mg

    for name, root_T_target in targets:
        node = root["targets/" + node_name(name)]
        material = mg.MeshLambertMaterial(
            color=rgb_int(TARGET_RGBA), opacity=TARGET_RGBA[3], transparent=True
        )
        node["board"].set_object(mg.Box(TARGET_SIZE), material)
        node["board"].set_transform(transform_from_translation([0.0, 0.0, -0.5 * TARGET_SIZE[2]]))
        triad(node["triad"], np.eye(4), length=2 * TRIAD_LENGTH)
        node.set_transform(root_T_target)
    return np.array([T[:3, 3] for _, T in targets]).reshape(-1, 3)


# -- files -------------------------------------------------------------------------------


def targets_from_sidecar(
    sidecar: str | Path | CalibrationSidecar,
) -> tuple[tuple[str, NDArray[np.float64]], ...]:
    """``(name, root_T_target)`` of every target in a calibration sidecar
    (``*.kinfw.json`` written by ``kinfw calibrate``, or one read by
    :func:`kinfw.records.read_sidecar`), for :func:`scene`'s ``targets``: the
    refined pose when the calibration refined it, else the hand-eye one
    (:attr:`~kinfw.records.CalibrationSidecar.root_T_targets`)."""
    doc = sidecar if isinstance(sidecar, CalibrationSidecar) else read_sidecar(sidecar)
    return tuple((t, check_transform(T, name=f"targets[{t!r}]")) for t, T in doc.root_T_targets)
