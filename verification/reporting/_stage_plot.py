"""The figure of a calibration's errors by stage: position RMS per observation group after
each pipeline stage, as grouped bars (matplotlib, imported when drawing)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kinfw.files import atomic_path
from kinfw.records import StageErrors


def plot_stage_errors(
    stages: tuple[StageErrors, ...], path: str | Path, *, title: str = ""
) -> Path:
    """Grouped bars: per observation group the headline of its first metric (position
    RMS mm, pixel RMS px, ...; log scale) after each stage (the report's
    ``rms_by_stage`` or ``rms_vs_truth_held_out_by_stage``)."""
    stage_rms = {s.stage: {g: v.value for g, v in s.rms} for s in stages}
    metrics = dict.fromkeys((v.name, v.unit) for _, v in stages[0].rms)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    stages = list(stage_rms)
    groups = list(stage_rms[stages[0]])
    fig = Figure(figsize=(8.5, 4.2))
    FigureCanvasAgg(fig)
    # fixed margins: the constrained layout engine costs more than the rest of the plot
    fig.subplots_adjust(left=0.08, right=0.99, top=0.93, bottom=0.25)
    ax = fig.add_subplot()
    width = 0.8 / len(stages)
    colours = ["0.6", "tab:orange", "tab:green", "tab:blue", "tab:purple"]
    x = np.arange(len(groups))
    for k, stage in enumerate(stages):
        values = [stage_rms[stage][g] for g in groups]
        bars = ax.bar(
            x + (k - (len(stages) - 1) / 2) * width,
            values,
            width,
            label=stage,
            color=colours[k % len(colours)],
        )
        ax.bar_label(bars, labels=[f"{v:.2g}" for v in values], fontsize=7, padding=1)
    ax.set_yscale("log")
    ax.set_xticks(x, groups)
    what = ", ".join(f"{name} RMS ({unit}" for name, unit in metrics)
    ax.set_ylabel(f"held-out {what}, log scale)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(
        title="after stage",
        ncols=len(stages),
        loc="upper center",
        bbox_to_anchor=(0.5, -0.11),
        frameon=False,
    )
    if title:
        ax.set_title(title, fontsize=10)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format=path.suffix.lstrip(".") or "png")
    return path
