"""The one reader of CSV text kinfw's CSV inputs share (``import-csv``, ``detect``'s joints,
``handeye``'s pose pairs, ``pose-chain``'s hand poses): spreadsheet dialects read the same
everywhere.

A UTF-8 byte-order mark is skipped; the separator is ``,``, ``;`` or a tab (the one the
first non-blank line, the header, holds most of); with ``;`` or a tab, numbers may use
decimal commas (``0,25``), and a file mixing decimal commas and points is refused. Blank
lines are skipped; each row keeps its line number in the file for messages.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass

from kinfw.observations import DatasetError

_DECIMAL_COMMA = re.compile(r"(?<![\d.,])-?\d+,\d+(?![\d.,])")
_DECIMAL_POINT = re.compile(r"(?<![\d.,])-?\d+\.\d+(?![\d.,])")


@dataclass(frozen=True, slots=True)
class CsvTable:
    """The non-blank rows of a CSV text, split by its dialect.

    Attributes
    ----------
    rows : tuple of (int, list of str)
        Each non-blank row's line number in the file (1-based) and its cells, as
        written (not stripped); the first is the header.
    delimiter : str
        ``","``, ``";"`` or ``"\\t"``.
    decimal_comma : bool
        Numbers are written ``0,25`` (only with ``;`` or a tab).
    """

    rows: tuple[tuple[int, list[str]], ...]
    delimiter: str
    decimal_comma: bool

    def number(self, cell: str) -> float:
        """The cell as a float, a decimal comma read as a point in a decimal-comma file.

        Raises
        ------
        ValueError
            The cell is not a number (the caller names the file, line and column).
        """
        return float(cell.replace(",", ".") if self.decimal_comma else cell)


def csv_table(text: str, source: str) -> CsvTable:
    """Split CSV ``text`` (the file ``source``, for messages) by its dialect (see the
    module docstring).

    Raises
    ------
    DatasetError
        Naming ``source``: numbers with both decimal commas and decimal points.
    """
    lines = text.lstrip("\ufeff").splitlines()
    header = next((line for line in lines if line.strip()), "")
    delimiter = max(",;\t", key=header.count)
    if header.count(delimiter) == 0:
        delimiter = ","
    comma = False
    if delimiter != ",":
        body = "\n".join(lines[lines.index(header) + 1 :]) if header else ""
        comma = _DECIMAL_COMMA.search(body) is not None
        if comma and _DECIMAL_POINT.search(body) is not None:
            raise DatasetError(
                f"{source}: numbers with both decimal commas and decimal points (separator "
                f"{delimiter!r}): write every number with one of them"
            )
    rows = tuple(
        (line, row)
        for line, row in enumerate(csv.reader(lines, delimiter=delimiter), start=1)
        if any(cell.strip() for cell in row)
    )
    return CsvTable(rows, delimiter, comma)
