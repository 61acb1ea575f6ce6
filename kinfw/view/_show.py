"""The view of ``kinfw view`` and :func:`kinfw.show`: the nominal robot as a ghost, the
calibrated one in colour, one sample's measurements with their residual lines, and the
calibration's targets; served live by meshcat on 127.0.0.1, or written as one
self-contained HTML file."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from numpy.typing import ArrayLike

from kinfw.files import sidecar_path
from kinfw.measurements import Measurements
from kinfw.model import BlockKey, Robot
from kinfw.records import CalibrationSidecar, read_sidecar
from kinfw.view._html import OfflineWindow, write_html
from kinfw.view._scene import as_robot, scene, targets_from_sidecar

if TYPE_CHECKING:
    import meshcat


def show(
    nominal: Robot | str | Path,
    calibrated: Robot | str | Path | None = None,
    data: Measurements | None = None,
    *,
    sidecar: str | Path | CalibrationSidecar | None = None,
    sample: int | None = None,
    residual_scale: float = 10.0,
    up: ArrayLike | None = None,
    package_dirs: Sequence[str | Path] = (),
    html: str | Path | None = None,
) -> Path | meshcat.Visualizer:
    """Show a calibration in 3D, as ``kinfw view`` does: :func:`kinfw.show`.

    Parameters
    ----------
    nominal, calibrated : Robot or path
        The nominal robot (a grey ghost) and the calibrated one (solid; optional); a
        path or URDF text is loaded (:func:`kinfw.load_robot`).
    data : Measurements, optional
        One sample's observations are drawn, with lines from prediction to measurement.
    sidecar : path or CalibrationSidecar, optional
        The calibration's sidecar: its targets are drawn, observations made in an
        external frame placed by its ``w_T_root``, and contacts and markers drawn with
        its planes, balls, divots, marker poses and probe offsets; its model spec
        (compliance, gear scales: :attr:`kinfw.model.Robot.spec`) puts the calibrated
        robot at the joint values its readings give. Default:
        ``CALIBRATED.kinfw.json`` beside a ``calibrated`` file, when there is one.
    sample : int, optional
        The sample of ``data`` drawn (default 0).
    residual_scale : float
        Residual lines are this many times the error.
    up : array_like, shape (3,), optional
        The root frame's up direction (default the URDF's ``<kinfw up>`` hint, else z).
    package_dirs : sequence of path
        Where ``package://`` meshes live.
    html : path, optional
        Write the scene to this self-contained HTML file (no network needed to open it)
        instead of serving it.

    Returns
    -------
    Path or meshcat.Visualizer
        The HTML file written; without ``html``, the visualizer serving the scene on
        127.0.0.1 (its ``url()``), for as long as this process runs.
    """
    calibrated = None if calibrated is None else as_robot(calibrated, "calibrated")
    if sidecar is None and calibrated is not None and not calibrated.source.startswith("<"):
        guess = sidecar_path(calibrated.source)
        sidecar = guess if guess.is_file() else None
    extra: dict[str, Any] = {}
    if sidecar is not None:
        doc = sidecar if isinstance(sidecar, CalibrationSidecar) else read_sidecar(sidecar)
        if calibrated is not None and doc.robot_blocks and not calibrated.spec:
            calibrated = calibrated.with_spec(doc.spec())  # compliance...: drawn deflected
        extra = {
            "targets": targets_from_sidecar(doc),
            "meas_T_root": doc.w_T_root,
            # planes, balls, divots, markers, probe offsets: what the contacts and
            # markers of the data are drawn with (targets and frames come above)
            "unknowns": {
                BlockKey(kind, name): value
                for (kind, name), value in doc.known_frames().items()
                if kind not in ("target", "frame")
            },
        }
    vis = scene(
        nominal,
        calibrated,
        data,
        sample=sample,
        residual_scale=residual_scale,
        up=up,
        package_dirs=tuple(package_dirs),
        window=OfflineWindow() if html is not None else None,
        **extra,
    )
    return vis if html is None else write_html(vis, html)
