"""Reading one observation of a ``kinfw-measurements`` file: checks that name the culprit.

:class:`ObservationReader` is what an observation kind's
:meth:`~kinfw.observations.ObservationKind.parse` reads its dict with: every check
raises a :class:`DatasetError` that names the file, the key path
(``samples[7].observations[1].quat_xyzw``) and what was expected, and lengths are
converted to metres from the file's unit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from itertools import chain
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: The largest magnitude of a number in a measurement file, in any unit it is written in
#: (m, mm, rad, deg, px): 1e9 mm is 1,000 km. A larger one (a placeholder 1e300) is
#: refused where it is read, before it overflows a computation that would blame another
#: cause (a joint's unit).
MAX_MAGNITUDE = 1e9


def _number_problem(x: Any, expected: str) -> str | None:
    """Why ``x`` is not a number :class:`ObservationReader` takes, or None."""
    if not isinstance(x, (int, float)) or isinstance(x, bool):
        return f"expected {expected}, got {describe(x)}"
    try:
        value = float(x)
    except OverflowError:  # an integer too large for a float
        value = math.inf
    if not math.isfinite(value):
        return f"expected {expected}, got {describe(x)}"
    if abs(value) > MAX_MAGNITUDE:
        return (
            f"{value:.6g} is no measurement (its magnitude is above {MAX_MAGNITUDE:.0e} in "
            "any unit: m, mm, rad, deg, px); a placeholder or corrupt number?"
        )
    return None


class DatasetError(ValueError):
    """A measurement file or dataset that cannot be used.

    The message names the file (``Measurements.source``), the sample index and key path
    when relevant (``samples[7].observations[1].quat_xyzw``) and what was expected.
    """


def describe(value: Any) -> str:
    """A short description of a JSON value for 'got ...' in messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return repr(value if len(value) <= 40 else value[:37] + "...")
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


class ObservationReader:
    """Validation helpers that raise :class:`DatasetError` naming the file and key path.

    Attributes
    ----------
    source : str
        File name used in messages.
    length_unit : {"m", "mm"}
        The file's length unit (:meth:`lengths` converts to metres).
    default_measured_in : str or None
        The file's top-level ``measured_in``.
    quaternions, rounded : int, list of float
        Quaternions read, and the norm deviations of the rounded ones (one warning per
        file, by the reader of the file).
    """

    def __init__(
        self, source: str, length_unit: str = "m", default_measured_in: str | None = None
    ) -> None:
        self.source = source
        self.length_unit = length_unit
        self.default_measured_in = default_measured_in
        #: quaternions read, and the norm deviations of those that were rounded
        self.quaternions = 0
        self.rounded: list[float] = []
        #: camera intrinsics by frame (the file's "cameras" section and any given)
        self.cameras: dict[str, Any] = {}

    def error(self, where: str, what: str) -> DatasetError:
        return DatasetError(
            f"{self.source}: {where}: {what}" if where else f"{self.source}: {what}"
        )

    def get(self, obj: dict[str, Any], key: str, where: str, expected: str) -> Any:
        """A required key; JSON null is an error too."""
        value = obj.get(key)
        if value is None:
            state = "missing" if key not in obj else "null"
            raise self.error(_join(where, key), f"{state}; expected {expected}")
        return value

    def string(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(where, f"expected a non-empty string, got {describe(value)}")
        return value

    def optional_string(self, obj: dict[str, Any], key: str, where: str) -> str | None:
        value = obj.get(key)
        return None if value is None else self.string(value, _join(where, key))

    def choice(self, value: Any, where: str, choices: tuple[str, ...]) -> str:
        if not isinstance(value, str) or value not in choices:
            options = ", ".join(repr(c) for c in choices)
            raise self.error(where, f"expected one of {options}, got {describe(value)}")
        return value

    def numbers(self, value: Any, n: int, where: str, what: str = "") -> list[float]:
        """A list of ``n`` finite numbers of magnitude at most :data:`MAX_MAGNITUDE`, as
        floats."""
        what = f" ({what})" if what else ""
        if not isinstance(value, list):
            raise self.error(where, f"expected a list of {n} numbers{what}, got {describe(value)}")
        if len(value) != n:
            raise self.error(where, f"expected {n} numbers{what}, got {len(value)}")
        if all(type(x) is float and abs(x) <= MAX_MAGNITUDE for x in value):
            return list(value)  # the usual case, checked at once (else item by item below)
        out = []
        for k, x in enumerate(value):
            problem = _number_problem(x, "a finite number")
            if problem:
                raise self.error(f"{where}[{k}]", problem)
            out.append(float(x))
        return out

    def numbers_many(self, values: Sequence[Any], n: int) -> NDArray[np.float64] | None:
        """Many lists of ``n`` numbers at once, as an (m, n) float array; None when any
        value is not one :meth:`numbers` takes (then :meth:`numbers`, one at a time,
        names it)."""
        if set(map(type, values)) != {list} or set(map(len, values)) != {n}:
            return None
        flat = list(chain.from_iterable(values))
        if not set(map(type, flat)) <= {float, int}:  # bool is neither
            return None
        try:
            out = np.array(flat, dtype=float).reshape(len(values), n)
        except OverflowError:  # an integer too large for a float
            return None
        return out if (np.abs(out) <= MAX_MAGNITUDE).all() else None  # NaN compares False

    def number(self, obj: dict[str, Any], key: str, where: str, expected: str) -> float:
        """One required finite number of magnitude at most :data:`MAX_MAGNITUDE`."""
        value = self.get(obj, key, where, expected)
        problem = _number_problem(value, expected)
        if problem:
            raise self.error(_join(where, key), problem)
        return float(value)

    def lengths(self, values: Sequence[float]) -> list[float]:
        """Lengths in the file's unit converted to metres."""
        return [x / 1000.0 for x in values] if self.length_unit == "mm" else list(values)

    def list_of(self, value: Any, where: str, what: str) -> list[Any]:
        if not isinstance(value, list) or not value:
            raise self.error(where, f"expected a non-empty list of {what}, got {describe(value)}")
        return value

    def obj(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(where, f"expected an object, got {describe(value)}")
        return value

    def not_allowed(self, obs: dict[str, Any], key: str, where: str, kind: str, why: str) -> None:
        """Refuse a key that does not belong on this kind of observation."""
        if obs.get(key) is not None:
            raise self.error(_join(where, key), f"not allowed on a {kind!r} observation ({why})")
