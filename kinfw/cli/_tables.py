"""Plain-text output of the ``kinfw`` commands: tables (:func:`format_table`, the
accuracy report's :func:`accuracy_table`) and progress lines on stderr.

Like :mod:`kinfw.cli`, this module imports only the standard library at start-up.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

__all__ = ["accuracy_table", "format_table", "progress_printer"]

log = logging.getLogger("kinfw")


def progress_printer():
    """Progress lines on stderr when a person is watching (a terminal, or --verbose)."""
    if sys.stderr.isatty() or log.isEnabledFor(logging.INFO):
        return lambda message: print(f"  {message}", file=sys.stderr, flush=True)
    return None


def format_table(rows: Sequence[Sequence[str]], header: Sequence[str]) -> str:
    """Plain-text table: the header and the rows, each column right-aligned."""
    widths = [max(len(str(r[k])) for r in (header, *rows)) for k in range(len(header))]
    lines = ["  ".join(str(h).rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(str(c).rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(lines)


def accuracy_table(report_dict: dict) -> str:
    """Plain-text table of :meth:`kinfw.verification.evaluation.AccuracyReport.to_dict`."""
    rows = []
    has_px = any("pixel_rms_px" in g for g in report_dict["groups"])

    def num(value, fmt: str) -> str:  # an undefined number (NaN, null) is "-"
        return "-" if value is None or value != value else format(value, fmt)

    for g in report_dict["groups"]:
        mu, sd = g["abs_mean_xyz_mm"], g["abs_std_xyz_mm"]
        table4 = " ".join(
            f"{m:.3f}/{s:.3f}" for m, s in zip(mu, sd, strict=True) if m == m and s == s
        )
        rows.append(
            [
                g["frame"] + (f" [{g['marker']}]" if g["marker"] else ""),
                g["kind"],
                g["n"],
                num(g["position_mean_mm"], ".3f"),
                num(g["position_rms_mm"], ".3f"),
                num(g["position_max_mm"], ".3f"),
                num(g["rotation_rms_deg"], ".4f"),
                num(g["rotation_max_deg"], ".4f"),
                table4 or "-",
                *([f"{g['pixel_rms_px']:.3g}"] if "pixel_rms_px" in g else ["-"] * has_px),
            ]
        )
    header = [
        "frame",
        "kind",
        "n",
        "pos mean mm",
        "pos RMS mm",
        "pos max mm",
        "rot RMS deg",
        "rot max deg",
        "|e| x y z mean/std mm (Table 4)",
        *(["pixel RMS px"] if has_px else []),
    ]
    return format_table(rows, header)
