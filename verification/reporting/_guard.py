"""What the plausibility guard's verdict on a calibration about to be written
(:func:`kinfw.identification.checks.fit_plausibility`) becomes: its record for the report
and sidecar (:func:`guard_summary`) and, beyond the bound, the error that names the
likely causes (:func:`implausible_message`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from kinfw.identification.checks import Plausibility
from kinfw.model import PriorScales, Robot
from kinfw.records import BeforeAfter, GuardSummary, RefineSection

#: Changes listed in the error, largest first; the others are counted.
LISTED = 6


def prior_bounds(prior: PriorScales | None, verdict: Plausibility) -> str:
    """What the chosen prior bounds, in words, and what the guard bounds."""
    guard = f"the guard bounds the URDF's origins at {verdict.bound_text()} ({verdict.why})"
    prior = PriorScales.of(prior)
    if prior is None:
        return f"no prior; {guard}"
    return (
        f"the prior ({prior.label.removeprefix('prior ')}) is on the "
        "CPC parameters' deviations from the nominal (each joint line's position and "
        f"direction, each frame's pose), not on the URDF's origins; {guard}"
    )


def guard_summary(
    verdict: Plausibility, prior: PriorScales | None, *, allowed: bool
) -> GuardSummary:
    """The guard's record for the report and the sidecar."""
    largest = verdict.changes[0] if verdict.changes else None
    return GuardSummary(
        verdict.bound_m,
        verdict.bound_rad,
        verdict.why,
        prior_bounds(prior, verdict),
        None if largest is None else largest.text(),
        verdict.largest_ratio,
        tuple(c.text() for c in verdict.beyond),
        allowed and not verdict.plausible,
    )


def nominal_misfit(rows: Sequence[BeforeAfter], verdict: Plausibility) -> str | None:
    """When the nominal URDF predicts the calibration data worse than the guard's bound
    on a move (a group's position or distance RMS before calibration, metres): the worst
    such group in words; None otherwise."""
    worst = None
    for row in rows:
        for value in row.before:
            if value.unit != "mm" or not value.stat or value.value != value.value:
                continue
            ratio = 1e-3 * value.value / verdict.bound_m
            if ratio > 1.0 and (worst is None or ratio > worst[0]):
                worst = (ratio, f"{row.group} {value.value:.3g} mm {value.stat}")
    return None if worst is None else worst[1]


def implausible_message(
    source: str,
    nominal: Robot,
    verdict: Plausibility,
    *,
    misfit: str | None,
    refine: RefineSection | None,
    option: str = "--allow-large-changes",
) -> str:
    """The guard's error: a first line (under 200 characters) with the largest change and
    the bound, then each change beyond it and the likely causes, in order (target
    geometry or board size, another robot's URDF, a unit, a direction the data do not
    determine), each with what it would look like."""
    beyond = verdict.beyond
    top = beyond[0]
    name = nominal.model.name or "?"
    first = (
        f"{source}: implausible calibration, not written: {top.name} moved "
        f"{1e3 * top.shift_m:.3g} mm / {math.degrees(top.turn_rad):.3g} deg, "
        f"{top.ratio:.3g} x the bound ({option} writes it)"
    )
    lines = [first, f"changes beyond the bound {verdict.bound_text()} ({verdict.why}):"]
    lines += [f"  {c.text()}" for c in beyond[:LISTED]]
    if len(beyond) > LISTED:
        lines.append(f"  ... and {len(beyond) - LISTED} more")
    moved = ", ".join(f"{c.name} {1e3 * c.shift_m:.3g} mm" for c in beyond[:3])
    lines.append("likely causes, in order:")
    lines.append(
        "  1. the target's geometry or the board's size is wrong (square size, marker "
        "offsets, plane, a camera's intrinsics): the residuals stay small while a camera "
        "mount or the joints near the target move by centimetres"
    )
    robot = (
        f'  2. the URDF (<robot name="{name}">) may be another robot\'s: its nominal '
        f"predicts the data far worse ({misfit}) than the bound, and the fit needs "
        f"moves of link lengths ({moved})"
        if misfit
        else f'  2. the URDF (<robot name="{name}">) is another robot\'s: the nominal '
        "would predict the data centimetres off and link lengths would change "
        f"({moved})"
    )
    lines.append(robot)
    lines.append(
        "  3. a unit: joint values in degrees read as radians, or positions in mm read as "
        "m: moves of about 57 or 1000 times what is plausible"
    )
    unseen = [] if refine is None else refine.identifiability.not_identifiable
    undetermined = (
        "; not identifiable here: "
        + "; ".join(", ".join(u.parameters) for u in unseen[:3])
        + (" ..." if len(unseen) > 3 else "")
        if unseen
        else ""
    )
    lines.append(
        "  4. a direction the data do not determine (held by the prior alone): a move "
        f"along it that the residuals do not see{undetermined}"
    )
    if misfit:  # the nominal's misfit puts another robot first
        lines[-4], lines[-3] = lines[-3].replace("  2.", "  1."), lines[-4].replace("  1.", "  2.")
    return "\n".join(lines)
