"""What ``kinfw gaze`` (:mod:`kinfw.cli._gaze`) and ``kinfw reach`` (:mod:`kinfw.cli._reach`)
share: their common options (model, ``--unit``, ``--q``, ``--free``, ``--json``), the start
configuration from ``--q``, the free joints from ``--free``, the check of a target's
distance, and the table of the joint values they print.

Exit codes (both commands): 0 when the point is fixated / the target reached (within
1e-6 rad and 1e-6 m by the model), :data:`NOT_MET` (3) when it is not (the closest
achievable answer is still printed), 2 on bad input, 1 on an internal error.

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

from kinfw.cli._args import add_xacro_option

log = logging.getLogger("kinfw")

#: Exit code when the point is not fixated / the target not reached (output printed).
NOT_MET = 3

#: Metres per unit of ``--unit``.
UNIT_M = {"m": 1.0, "mm": 1e-3}
_JOINT_SUFFIXES = {"deg": ("revolute", math.pi / 180.0), "mm": ("prismatic", 1e-3)}


# -- parser ------------------------------------------------------------------------------
def _joint_value(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` of ``--q`` (the value is checked against the joint later)."""
    name, sep, value = text.partition("=")
    if not sep or not name or not value:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    return name.strip(), value.strip()


def add_joint_options(p: argparse.ArgumentParser) -> None:
    """The options of ``gaze`` and ``reach``: model, ``--unit``, ``--q``, ``--free``, ``--json``."""
    p.add_argument("model", type=Path, help="URDF of the robot (nominal or calibrated)")
    add_xacro_option(p)
    p.add_argument(
        "--unit",
        choices=tuple(UNIT_M),
        default="m",
        help="length unit of the target's position (default m)",
    )
    p.add_argument(
        "--q",
        action="append",
        type=_joint_value,
        default=[],
        metavar="NAME=VALUE",
        help="start value of a joint, and its value if it is not solved for: rad or m "
        "(URDF units), or with a unit, 30deg or 250mm; joints not given start at the "
        "middle of their range (repeatable)",
    )
    p.add_argument(
        "--free",
        metavar="J1,J2,...",
        help="joints to solve for, comma-separated (default: see the command's description)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")


# -- shared ------------------------------------------------------------------------------
def parse_joint_values(robot, given: list[tuple[str, str]]):
    """The start configuration (all movable joints, URDF units): the middle of each
    range, overridden by ``--q NAME=VALUE`` (VALUE in rad / m, or with a ``deg`` / ``mm``
    suffix). Raises ValueError naming the joint and the joints there are."""
    from kinfw.control import middle_configuration

    q = middle_configuration(robot)
    names = robot.joint_names
    seen: set[str] = set()
    for name, text in given:
        if name not in names:
            raise ValueError(f"--q {name}={text}: no movable joint {name!r}; joints: {list(names)}")
        if name in seen:
            raise ValueError(f"--q {name}={text}: joint {name!r} is given twice")
        seen.add(name)
        kind = "revolute" if robot.joint(name).is_revolute else "prismatic"
        scale, number = 1.0, text
        for suffix, (suffix_kind, suffix_scale) in _JOINT_SUFFIXES.items():
            if text.endswith(suffix):
                if kind != suffix_kind:
                    raise ValueError(
                        f"--q {name}={text}: {name!r} is {kind}; '{suffix}' is for "
                        f"{suffix_kind} joints"
                    )
                scale, number = suffix_scale, text[: -len(suffix)]
        try:
            value = float(number) * scale
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise ValueError(
                f"--q {name}={text}: expected a number ({'rad' if kind == 'revolute' else 'm'}"
                f", or with '{'deg' if kind == 'revolute' else 'mm'}')"
            )
        q[names.index(name)] = value
    return q


def free_arg(robot, text: str | None) -> tuple[str, ...] | None:
    if text is None:
        return None
    free = tuple(v for v in text.replace(",", " ").split() if v)
    if not free:
        raise ValueError("--free: expected joint names, comma-separated")
    unknown = [n for n in free if n not in robot.joint_names]
    if unknown:
        raise ValueError(
            f"--free: no movable joint {', '.join(map(repr, unknown))}; joints: "
            f"{list(robot.joint_names)}"
        )
    twice = sorted({n for n in free if free.count(n) > 1})
    if twice:
        raise ValueError(f"--free: joint {', '.join(map(repr, twice))} given twice")
    return free


def check_distance(where: str, position_m, plausible_m: float, unit: str) -> None:
    """Refuse a target more than 1,000 km from the root frame (not a length in metres)
    and warn beyond ``plausible_m``: usually millimetres given as metres."""
    import numpy as np

    hint = "; were millimetres given as metres? (--unit mm)" if unit == "m" else ""
    largest = float(np.max(np.abs(position_m)))
    distance_m = (
        largest * float(np.linalg.norm(np.asarray(position_m) / largest)) if largest else 0.0
    )
    if distance_m > 1e6:
        raise ValueError(f"{where} is {distance_m:.3g} m from the root frame{hint}")
    if distance_m > plausible_m:
        log.warning("%s is %.4g m from the root frame%s", where, distance_m, hint)


def joint_rows(robot, q, free: tuple[str, ...], at_limits: tuple[str, ...]) -> list[dict]:
    """Per joint: URDF value and display value (deg / mm), free, at a limit."""
    rows = []
    for name, value in zip(robot.joint_names, q, strict=True):
        revolute = robot.joint(name).is_revolute
        rows.append(
            {
                "joint": name,
                "value": float(value),
                "display": math.degrees(value) if revolute else 1e3 * value,
                "unit": "deg" if revolute else "mm",
                "free": name in free,
                "at_limit": name in at_limits,
            }
        )
    return rows


def joint_table(rows: list[dict]) -> str:
    from kinfw.cli._tables import format_table

    table = [
        [
            r["joint"],
            f"{r['display']:.4f}",
            r["unit"],
            "free" if r["free"] else "held",
            "at limit" if r["at_limit"] else "",
        ]
        for r in rows
    ]
    return format_table(table, ["joint", "value", "unit", "solved", "limit"])


def joints_json(rows: list[dict]) -> dict:
    return {
        r["joint"]: {
            "value": r["value"],
            r["unit"]: r["display"],
            "free": r["free"],
            "at_limit": r["at_limit"],
        }
        for r in rows
    }
