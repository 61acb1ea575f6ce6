"""Plain-text output of the ``kinfw`` commands: tables (:func:`format_table`, the
accuracy report's :func:`accuracy_table`); progress on stderr is :mod:`kinfw.progress`'s.

Like :mod:`kinfw.cli`, this module imports only the standard library at start-up.
"""

from __future__ import annotations

from collections.abc import Sequence


def format_table(rows: Sequence[Sequence[str]], header: Sequence[str]) -> str:
    """Plain-text table: the header and the rows, each column right-aligned."""
    widths = [max(len(str(r[k])) for r in (header, *rows)) for k in range(len(header))]
    lines = ["  ".join(str(h).rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(str(c).rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(lines)


def metric_format(name: str, unit: str) -> str:
    """The format spec of a metric's values in tables: the registered kinds' own
    (:attr:`kinfw.observations.Metric.fmt`), ``".3g"`` for a metric none has."""
    from kinfw.observations import kinds

    return next(
        (m.fmt for k in kinds() for m in k.metrics if (m.name, m.unit) == (name, unit)), ".3g"
    )


def number(value, fmt: str) -> str:
    """A table cell: an undefined number (None, NaN) is ``-``."""
    return "-" if value is None or value != value else format(value, fmt)


def accuracy_table(report_dict: dict) -> str:
    """Plain-text table of :meth:`kinfw.verification.evaluation.AccuracyReport.to_dict`:
    a column per error key of any group (``position_rms_mm``, ``height_max_mm``,
    ``tilt_deg``; ``-`` where a group's kind has no such metric), then per metric with
    axes the mean/std of ``|error|`` per axis (Shih et al. Table 4)."""
    from kinfw.records import ErrorValue

    fixed = ("frame", "kind", "marker", "entity", "n", "samples")
    keys = dict.fromkeys(k for g in report_dict["groups"] for k in g if k not in fixed)
    values = [ErrorValue.from_key(k, 0.0) for k in keys if not k.startswith("abs_")]
    axes = dict.fromkeys(k.split("_", 2)[2] for k in keys if k.startswith("abs_mean_"))
    rows = []
    for g in report_dict["groups"]:
        # one probe on a table and a wall: a row each, named (AccuracyReport.entities)
        kind = g["kind"] + (f" {g['entity']}" if g.get("entity") else "")
        cells = [number(g.get(v.key), metric_format(v.name, v.unit)) for v in values]
        for suffix in axes:
            mu, sd = g.get(f"abs_mean_{suffix}"), g.get(f"abs_std_{suffix}")
            pairs = [] if mu is None or sd is None else zip(mu, sd, strict=True)
            cells.append(" ".join(f"{m:.3f}/{s:.3f}" for m, s in pairs) or "-")
        rows.append(
            [g["frame"] + (f" [{g['marker']}]" if g["marker"] else ""), kind, g["n"], *cells]
        )
    header = ["frame", "kind", "n", *(v.label() for v in values)]
    for suffix in axes:
        names, unit = suffix.rsplit("_", 1)
        header.append(f"|e| {' '.join(names)} mean/std {unit}")
    return format_table(rows, header)
