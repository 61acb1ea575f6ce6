"""Typed reading of a parsed JSON document (a calibration sidecar or report): every
error is a :class:`CalibrationFileError` naming the file and the key path
(``targets[0].root_T_target``), like :class:`kinfw.measurements.DatasetError`."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray


class CalibrationFileError(ValueError):
    """A calibration sidecar or report that cannot be read.

    The message names the file, the key path (``unknowns[2].value``) and what was
    expected.
    """


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass(frozen=True, slots=True)
class DocReader:
    """Typed access to a parsed JSON document; every error names ``source`` and the key.

    ``at`` is the key path of the object being read (``""`` for the top level).
    """

    source: str

    def fail(self, at: str, expected: str, got: Any = ...) -> CalibrationFileError:
        where = at or "top level"
        tail = "" if got is ... else f", got {_short(got)}"
        return CalibrationFileError(f"{self.source}: {where}: expected {expected}{tail}")

    @staticmethod
    def path(at: str, key: str | int) -> str:
        if isinstance(key, int):
            return f"{at}[{key}]"
        return f"{at}.{key}" if at else key

    def obj(self, value: Any, at: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(at, "an object", value)
        return value

    def value(self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False) -> Any:
        if key not in doc:
            if optional:
                return None
            raise self.fail(self.path(at, key), "a value (the key is missing)")
        return doc[key]

    def string(
        self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False
    ) -> str | None:
        v = self.value(doc, key, at, optional=optional)
        if v is None and optional:
            return None
        if not isinstance(v, str):
            raise self.fail(self.path(at, key), "a string" + (" or null" if optional else ""), v)
        return v

    def number(
        self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False
    ) -> float | None:
        """A number; null is NaN (the reports write an undefined number, a point's
        rotation, as null), or None with ``optional``."""
        v = self.value(doc, key, at, optional=optional)
        if v is None:
            return None if optional else math.nan
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(self.path(at, key), "a number" + (" or null" if optional else ""), v)
        return float(v)

    def integer(self, doc: dict[str, Any], key: str, at: str) -> int:
        v = self.value(doc, key, at)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(self.path(at, key), "an integer", v)
        return v

    def boolean(self, doc: dict[str, Any], key: str, at: str) -> bool:
        v = self.value(doc, key, at)
        if not isinstance(v, bool):
            raise self.fail(self.path(at, key), "true or false", v)
        return v

    def items(
        self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False
    ) -> list[Any] | None:
        v = self.value(doc, key, at, optional=optional)
        if v is None and optional:
            return None
        if not isinstance(v, list):
            raise self.fail(self.path(at, key), "a list" + (" or null" if optional else ""), v)
        return v

    def array(
        self, value: Any, at: str, shape: tuple[int, ...] | None = None, *, allow_null: bool = False
    ) -> NDArray[np.float64]:
        """Nested lists of numbers as a float array (``shape`` checked when given);
        with ``allow_null`` a null entry is NaN."""
        what = f"an array of shape {shape}" if shape else "an array of numbers"
        try:
            if allow_null:
                value = _nulls_to_nan(value)
            a = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise self.fail(at, what, value) from None
        if isinstance(value, bool | str | dict) or (shape is not None and a.shape != shape):
            raise self.fail(at, what, value)
        if not allow_null and not np.all(np.isfinite(a)):
            raise self.fail(at, what + " (finite)", value)
        return a

    def strings(self, doc: dict[str, Any], key: str, at: str) -> tuple[str, ...]:
        v = self.items(doc, key, at)
        if not all(isinstance(s, str) for s in v):
            raise self.fail(self.path(at, key), "a list of strings", v)
        return tuple(v)

    def rows(self, cls: Any, doc: dict[str, Any], key: str, at: str) -> tuple:
        """The list under ``key`` read item by item with ``cls.from_dict(item, self,
        "at.key[k]")`` (a report section's rows).

        Parameters
        ----------
        cls : type
            A record with a classmethod ``from_dict(doc, reader, at)``.
        doc : dict
            The object holding the list.
        key : str
        at : str
            The key path of ``doc``.

        Returns
        -------
        tuple
            One ``cls`` per item, in file order.
        """
        path = self.path(at, key)
        return tuple(
            cls.from_dict(d, self, f"{path}[{k}]") for k, d in enumerate(self.items(doc, key, at))
        )

    def header(self, doc: Any, fmt: str, version: int) -> dict[str, Any]:
        doc = self.obj(doc, "")
        if doc.get("format") != fmt:
            raise self.fail("format", f"{fmt!r} (is this a {fmt} file?)", doc.get("format"))
        if doc.get("version") != version:
            raise self.fail(
                "version",
                f"{version} (this kinfw reads {fmt} version {version})",
                doc.get("version"),
            )
        return doc


def _nulls_to_nan(value: Any) -> Any:
    if value is None:
        return math.nan
    if isinstance(value, list):
        return [_nulls_to_nan(v) for v in value]
    return value
