"""The figure of :mod:`kinfw.verification.studies` (``gaze.png``): cumulative distributions
of the errors on the true robots, nominal vs calibrated model."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from kinfw.verification.studies._common import new_figure, save_figure, shared_legend

if TYPE_CHECKING:
    from kinfw.verification.studies._gaze_study import GazeStudy

#: Line colour per model, line style per camera.
COLOURS = {"nominal": "tab:red", "calibrated": "tab:blue"}
STYLES = ("-", "--")


def _cdf(ax, values: NDArray[np.float64], **kwargs) -> None:
    v = np.sort(values.ravel())
    ax.plot(v, np.arange(1, len(v) + 1) / len(v), **kwargs)


def plot_gaze(study: GazeStudy, path: str | Path) -> Path:
    """Four panels of CDFs: pointing error per camera, the raw optical-axis angle with
    the head's fixation floor, triangulation error, UR10 reach position error; nominal
    (red) vs calibrated (blue). Written to ``path`` (PNG)."""
    from kinfw.verification.studies._gaze_study import count_noun

    s = study
    fig = new_figure((10.0, 7.0))
    axes = fig.subplots(2, 2)
    (pointing, axis), (triangulation, arm) = axes
    for m, model in enumerate(("nominal", "calibrated")):
        colour = COLOURS[model]
        for c, camera in enumerate(s.setup.cameras):
            style = {"color": colour, "linestyle": STYLES[c % 2]}
            _cdf(
                pointing,
                np.degrees(s.pointing_rad[:, :, m, c]),
                label=f"{model}, {camera}",
                **style,
            )
            _cdf(axis, np.degrees(s.axis_rad[:, :, m, c]), **style)
        _cdf(triangulation, 1e3 * s.triangulation_m[:, :, m], color=colour)
        _cdf(arm, 1e3 * s.arm_position_m[:, :, m], color=colour)
    _cdf(
        axis,
        np.degrees(s.model_error_rad[:, :, 1]),
        color="0.55",
        linestyle=":",
        linewidth=1.5,
        zorder=1,
        label="fixation floor (calibrated model's own angle)",
    )
    pointing.set(
        xlabel="pointing error on the true head (deg)", title="where the point lands vs meant"
    )
    axis.set(xlabel="angle, true optical axis to point (deg)", title="raw fixation angle")
    triangulation.set(xlabel="triangulation error (mm)", title="3D point from both cameras' rays")
    arm.set(xlabel="tool0 position error (mm)", title="UR10 reaching held-out poses")
    # exact fixations (angles ~1e-15 deg) would stretch the log axis over 15 decades
    axis.set_xlim(left=1e-3)
    for ax in axes.ravel():
        ax.set_xscale("log")
        ax.set_ylabel("fraction of points")
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(
        f"Using the calibration: {count_noun(s.setup.trials, 'simulated true head')} x "
        f"{s.setup.points} points at {s.setup.distance_min_m:g}-{s.setup.distance_max_m:g} m, "
        f"{count_noun(s.setup.trials, 'true UR10')} x {s.setup.targets} poses",
        fontsize=10,
    )
    shared_legend(fig, axes.ravel())
    return save_figure(fig, path)
