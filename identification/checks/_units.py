"""Unit checks: refuse data whose numbers are in another unit than the one they were read in.

The reader (:func:`kinfw.measurements.read_measurements`) converts every value to SI by
the units the file declares. A file that says ``m``/``rad`` whose numbers are millimetres
or degrees is therefore read 1000x or 57.3x off, and a least-squares fit of it still
"converges" (to residuals of tens of millimetres, or metres) and writes a wrong URDF.
:func:`check_units` compares the data with the nominal robot *before* any estimation and
raises :class:`UnitError` naming the likely cause and the fix.

Motion (decisive): the evidence of :func:`unit_diagnostics`
(:mod:`kinfw.identification.checks`, which explains it): the data is refused when its
measured motion agrees with the nominal robot's only in another unit.

Residuals after the fit (a last line, :func:`check_fit`). A refinement of every
parameter absorbs any geometry error of the nominal; when it still leaves a median
position residual above :data:`FIT_LIMIT_M` (20 mm) or a median orientation residual
above :data:`FIT_LIMIT_RAD` (5 deg), the data does not describe this robot in these
units (real measuring systems are 10 to 1000 times better), and nothing is written.

Joint limits (supporting, and a fallback). Values far outside the URDF limits (a
revolute joint whose values span 144 with limits 0..3.14 rad) are named in the message;
when no reading explains the motion either (score above :data:`LIMIT_SCORE`), values
more than :data:`LIMIT_FACTOR` times the limit span outside the limits are refused on
their own.

A file that declares its units correctly passes: its values are converted on reading.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from kinfw.identification.checks._units_evidence import (
    JointValues,
    UnitDiagnostics,
    UnitHypothesis,
    unit_diagnostics,
)
from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import DatasetError

if TYPE_CHECKING:
    from kinfw.identification import RefineResult


log = logging.getLogger(__name__)

#: Joint values this many limit spans outside the URDF limits are refused on their own
#: when no reading of the data explains the measured motion and the values as read
#: score above LIMIT_SCORE.
LIMIT_FACTOR = 10.0
LIMIT_SCORE = 0.3
#: A refinement over every parameter that leaves a median position residual above this
#: (m) or a median orientation residual above FIT_LIMIT_RAD is refused (check_fit).
FIT_LIMIT_M = 0.02
FIT_LIMIT_RAD = math.radians(5.0)
#: The measured motion per unit joint value must be within this of 1 (closed form).
SCALE_TOLERANCE = 0.1


class UnitError(DatasetError):
    """The numbers of a dataset are in another unit than the one they were read in."""


def _limits_text(j: JointValues) -> str:
    unit = "rad" if j.revolute else "m"
    return (
        f"joint {j.joint!r} values {j.low:.4g}..{j.high:.4g} (URDF limits "
        f"{j.lower:.4g}..{j.upper:.4g} {unit})"
    )


def _fix(hyp: UnitHypothesis, all_revolute: bool, any_prismatic: bool) -> str:
    fixes = []
    if hyp.joint_scale:
        looks = hyp.joint_looks.split(" read as ")[0]
        # "angle": "deg" converts prismatic values too: then only joint_units will do
        if all_revolute and looks == "degrees" and not any_prismatic:
            fixes.append('declare "units": {"angle": "deg"} (or per joint "joint_units")')
        else:
            fixes.append(
                'declare the unit of each joint in "joint_units" (one of "m", '
                '"mm", "rad", "deg" per entry of "joint_names")'
            )
    if hyp.length_scale != 1.0:
        unit = "mm" if hyp.length_scale < 1.0 else "m"
        fixes.append(f'declare "units": {{"length": "{unit}"}}')
    text = " and ".join(fixes) + ", or convert the numbers"
    return text[0].upper() + text[1:]


def check_units(nominal: Robot, data: Measurements) -> UnitDiagnostics:
    """Refuse data whose joint values or lengths are in another unit than read.

    Parameters
    ----------
    nominal : Robot
        The nominal URDF.
    data : Measurements

    Returns
    -------
    UnitDiagnostics
        The evidence, when the data passes.

    Raises
    ------
    UnitError
        Naming the file, the joints (with their values against the URDF limits) or the
        measured lengths, the ratio seen and the fix.
    """
    diag = unit_diagnostics(nominal, data)
    src = data.source
    if diag.refused:
        hyp = diag.best
        parts = []
        seen = ", ".join(repr(f) for f in diag.frames[:4]) + (
            ", ..." if len(diag.frames) > 4 else ""
        )
        if hyp.joint_scale:
            names = list(hyp.joint_scale)
            scale = next(iter(hyp.joint_scale.values()))
            far = [j for j in diag.joints if j.joint in hyp.joint_scale and j.outside_spans > 1]
            shown = "; ".join(_limits_text(j) for j in far[:3])
            parts.append(
                f"the values of joint(s) {names} look like {hyp.joint_looks}"
                + (f" ({shown})" if shown else "")
                + f": the measured motion of {seen} matches the nominal robot's only with "
                f"the values multiplied by {scale:.4g}"
            )
        if hyp.length_scale != 1.0:
            parts.append(
                f"the measured positions of {seen} look like {hyp.length_looks}: they move "
                f"{diag.length_ratio:.4g} times the nominal robot's prediction (median over "
                f"{diag.n_pairs} sample pairs)"
            )
        revolute = {j.joint for j in diag.joints if j.revolute}
        prismatic = {j.joint for j in diag.joints if not j.revolute}
        raise UnitError(
            f"{src}: {'; and '.join(parts)} (mean relative motion discrepancy "
            f"{diag.score_as_read:.2f} as read, {diag.best_score:.2f} rescaled). "
            f"{_fix(hyp, revolute <= set(hyp.joint_scale), bool(prismatic))}"
        )
    far = [j for j in diag.joints if j.outside_spans > LIMIT_FACTOR]
    if far and diag.score_as_read > LIMIT_SCORE:
        raise UnitError(
            f"{src}: {'; '.join(_limits_text(j) for j in far[:3])}: far outside the URDF "
            "limits, and the measured motion does not match the nominal robot's (mean "
            f"relative discrepancy {diag.score_as_read:.2f}): are the joint values in "
            'another unit (degrees, mm)? Declare "units" / "joint_units", or convert them'
        )
    log.info(
        "%s: units agree with the nominal robot (discrepancy %.3f over %d pairs)",
        src,
        diag.score_as_read,
        diag.n_pairs,
    )
    return diag


def check_joint_scale(
    name: str, scale: float, *, revolute: bool, source: str, error: type[UnitError] = UnitError
) -> None:
    """Refuse a joint whose measured motion per unit of its value is not 1.

    Used by the closed form, which measures the motion of each joint alone.

    Parameters
    ----------
    name : str
        Joint name.
    scale : float
        Measured rotation (rad) or translation (m) per unit of the joint value.
    revolute : bool
    source : str
        Dataset name, for the message.
    error : type, optional
        The :class:`UnitError` subclass to raise (the closed form's is also a
        ``ProtocolError``).

    Raises
    ------
    UnitError
        When ``|scale - 1| > SCALE_TOLERANCE`` (0.1), naming the likely unit.
    """
    if not abs(scale - 1.0) > SCALE_TOLERANCE:  # NaN (scale not measured) passes
        return
    if revolute:
        raise error(
            f"{source}: joint {name!r} turns {scale:.4g} rad per unit of its joint value "
            "(expected 1): are its values in another unit (degrees read as radians, or "
            "a gear ratio)? Fix the file's units / joint_units"
        )
    raise error(
        f"{source}: joint {name!r} moves {scale:.4g} m per unit of its joint value "
        "(expected 1): are its values in another unit (mm read as m)? Fix the file's "
        "units / joint_units"
    )


def median_residuals(result: RefineResult) -> tuple[float, float]:
    """Median position (m) and orientation (rad) residual norms over every observation
    of a refinement (0 for a component no observation has)."""
    pos = [
        np.linalg.norm(g.position_m, axis=1) for g in result.residuals if g.position_m is not None
    ]
    rot = [
        np.linalg.norm(g.rotation_rad, axis=1)
        for g in result.residuals
        if g.rotation_rad is not None
    ]
    med_p = float(np.median(np.concatenate(pos))) if pos else 0.0
    med_r = float(np.median(np.concatenate(rot))) if rot else 0.0
    return med_p, med_r


def check_fit(result: RefineResult, source: str) -> None:
    """Refuse a refinement over every parameter that still does not fit the data.

    Parameters
    ----------
    result : RefineResult
        A refinement with ``parameters="full"`` (a smaller parameter set may leave
        large residuals for good data: the nominal joints are kept).
    source : str
        Dataset name, for the message.

    Raises
    ------
    UnitError
        When the median position residual norm over all observations exceeds
        :data:`FIT_LIMIT_M` or the median orientation one :data:`FIT_LIMIT_RAD`, naming
        the worst observation group.
    """
    med_p, med_r = median_residuals(result)
    if med_p <= FIT_LIMIT_M and med_r <= FIT_LIMIT_RAD:
        return
    with_position = [g for g in result.residuals if g.position_m is not None]
    worst = max(with_position, key=lambda g: float(np.median(np.linalg.norm(g.position_m, axis=1))))
    raise UnitError(
        f"{source}: the refinement over every parameter still leaves a median residual of "
        f"{1e3 * med_p:.3g} mm and {math.degrees(med_r):.3g} deg: the data does not "
        "describe this robot; nothing was written\n"
        f"worst: {worst.kind} {worst.frame!r}, noise "
        f"{'estimated' if result.noise.estimated else 'given'} "
        f"{1e3 * result.noise.position_m:.3g} mm. "
        'Are the units right ("units", "joint_units": mm read as m, degrees read as '
        "radians), the joint order, and the URDF this robot's?"
    )
