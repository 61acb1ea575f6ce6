"""Tables, figures and command line of the Shih et al. (1992) studies: Fig. 11 and Table 4.

``kinfw reproduce {fig11,table4} --out DIR`` runs :func:`kinfw.verification.papers.fig11_study` or
:func:`kinfw.verification.papers.table4_study` on the built-in head, writes its PNG and
JSON and prints its table.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from kinfw.verification.papers._shih_experiments import (
    PAPER_ACCURACY_MM,
    PAPER_PER_JOINT,
    Fig11Result,
    fig11_study,
)
from kinfw.verification.papers._shih_table4 import (
    PAPER_TABLE4_MU_MM,
    PAPER_TABLE4_SIGMA_MM,
    Table4Result,
    table4_study,
)
from kinfw.verification.studies import (
    choice_main,
    log_axes,
    new_figure,
    run_on_head,
    save_figure,
    shared_legend,
)

# -- text tables -----------------------------------------------------------------------


def _sigma_label(sigma_mm: float, sigma_rad: float) -> str:
    return f"σ = {sigma_mm:g} mm (rotation σ = {np.degrees(sigma_rad):.2f}°)"


def format_fig11(result: Fig11Result) -> str:
    """Markdown table of Fig. 11: mean ± std over trials of the positioning error (mm).

    Rows are ``M`` (measurements per joint), columns the noise levels; below it the
    paper's conclusion beside ours.
    """
    r = result
    head = [
        f"σ = {s:g} mm ({np.degrees(a):.2f}°)"
        for s, a in zip(r.sigmas_mm, r.sigmas_rad, strict=True)
    ]
    lines = [
        "Shih et al. (1992) Fig. 11 in simulation: mean positioning error (mm) of the "
        f"closed-form model on {r.n_test} held-out configurations, mean ± std over "
        f"{r.trials} trials ({', '.join(r.setup.frames)}).",
        r.setup.describe() + ".",
        "",
        "| M per joint | " + " | ".join(head) + " |",
        "|---:|" + "---:|" * len(head),
    ]
    for k, m in enumerate(r.per_joint):
        cells = [f"{r.mean_mm[s, k]:.3g} ± {r.std_mm[s, k]:.2g}" for s in range(len(head))]
        mark = " (paper's choice)" if m == PAPER_PER_JOINT else ""
        lines.append(f"| {m}{mark} | " + " | ".join(cells) + " |")
    smallest = r.smallest_per_joint(PAPER_ACCURACY_MM)
    ours = "; ".join(
        f"σ = {s:g} mm: {'none of the M tried' if np.isnan(m) else f'M >= {int(m)}'}"
        for s, m in zip(r.sigmas_mm, smallest, strict=True)
    )
    lines += [
        "",
        f"Paper: for {PAPER_ACCURACY_MM:g} mm accuracy the observation error must stay below "
        "0.5 mm and more than five measurements per joint are needed; it chose "
        f"{PAPER_PER_JOINT} (its Fig. 11 gives no numbers).",
        f"Ours: mean error below {PAPER_ACCURACY_MM:g} mm for {ours}.",
    ]
    return "\n".join(lines)


def format_table4(result: Table4Result) -> str:
    """Markdown table of Table 4: mu and sigma of ``|error|`` per axis and branch (mm),
    the paper's real-data values beside ours (vs noisy measurements and vs truth)."""
    r = result
    floor = r.sigma_mm * np.sqrt(2.0 / np.pi)
    lines = [
        f"Shih et al. (1992) Table 4 in simulation: calibrated with {r.per_joint} measurements "
        f"per joint, {_sigma_label(r.sigma_mm, r.sigma_rad)}; {r.n_test} test configurations "
        f"x {r.trials} trials pooled. mu, sigma: mean and std of |error| (mm).",
        r.setup.describe() + ".",
        "",
        "| branch | axis | paper mu | paper sigma | ours vs measured mu | sigma "
        "| ours vs truth mu | sigma |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for e, (frame, row) in enumerate(zip(r.setup.frames, r.paper_rows(), strict=True)):
        for a, axis in enumerate("xyz"):
            paper = (
                ["–", "–"]
                if row is None
                else [f"{PAPER_TABLE4_MU_MM[row, a]:.2f}", f"{PAPER_TABLE4_SIGMA_MM[row, a]:.2f}"]
            )
            ours = [
                r.measured_mu_mm[e, a],
                r.measured_sigma_mm[e, a],
                r.truth_mu_mm[e, a],
                r.truth_sigma_mm[e, a],
            ]
            lines.append(
                f"| {frame} | {axis} | "
                + " | ".join(paper)
                + " | "
                + " | ".join(f"{v:.2f}" for v in ours)
                + " |"
            )
    lines += [
        "",
        "Paper: real data (stereo rig, about 0.5 mm), nine test configurations; its errors "
        "include the measurement noise, like 'vs measured'.",
        f"Noise floor vs measured: E|N(0, σ)| = σ sqrt(2/π) = {floor:.2f} mm per axis.",
    ]
    return "\n".join(lines)


# -- plots -----------------------------------------------------------------------------


def plot_fig11(result: Fig11Result, path: str | Path) -> Path:
    """Write Fig. 11 as a PNG: mean positioning error vs measurements per joint.

    One line per noise level with ± std (over trials) error bars, log-scale error axis,
    the paper's 1 mm requirement dashed and its choice ``M = 9`` dotted.

    Returns
    -------
    Path
        ``path``.
    """
    r = result
    fig = new_figure((8.0, 6.2))
    ax = fig.add_subplot()
    mean, std = r.mean_mm, r.std_mm
    for s, (sigma, sigma_rad) in enumerate(zip(r.sigmas_mm, r.sigmas_rad, strict=True)):
        # On a log axis, a lower bar below zero cannot be drawn: stop it at 5 % of the mean.
        lower = np.minimum(std[s], 0.95 * mean[s])
        ax.errorbar(
            r.per_joint,
            mean[s],
            yerr=np.stack([lower, std[s]]),
            marker="o",
            markersize=4,
            capsize=3,
            linewidth=1.5,
            label=_sigma_label(sigma, sigma_rad),
        )
    ax.axhline(
        PAPER_ACCURACY_MM,
        color="0.2",
        linestyle="--",
        linewidth=1.2,
        label=f"paper's requirement: {PAPER_ACCURACY_MM:g} mm",
    )
    if r.per_joint.min() <= PAPER_PER_JOINT <= r.per_joint.max():
        ax.axvline(
            PAPER_PER_JOINT,
            color="0.5",
            linestyle=":",
            linewidth=1.2,
            label=f"paper's choice: M = {PAPER_PER_JOINT}",
        )
    positive = mean[mean > 0]
    if positive.size and positive.max() / positive.min() > 8.0:
        log_axes(ax, "y")
    ax.set_xticks(r.per_joint)
    ax.set_xlabel("measurements per joint, M")
    ax.set_ylabel("mean positioning error (mm), ± std over trials")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(
        "Reproduction of Shih et al. (1992) Fig. 11: closed-form CPC identification\n"
        f"{r.trials} random trials per point (new true robot each), {r.n_test} held-out "
        f"test configurations, {' + '.join(r.setup.frames)}",
        fontsize=10,
    )
    fig.legend(fontsize=8.5, loc="outside lower center", ncols=3)
    return save_figure(fig, path)


def plot_table4(result: Table4Result, path: str | Path) -> Path:
    """Write Table 4 as a PNG: mu ± sigma of ``|error|`` per axis, one panel per branch,
    the paper's real-data values beside ours (vs noisy measurements and vs truth).

    Returns
    -------
    Path
        ``path``.
    """
    r = result
    frames = r.setup.frames
    fig = new_figure((4.2 * len(frames) + 1.0, 5.0))
    axes = fig.subplots(1, len(frames), sharey=True, squeeze=False)[0]
    x = np.arange(3)
    series = [
        ("paper (real data)", PAPER_TABLE4_MU_MM, PAPER_TABLE4_SIGMA_MM, "0.55"),
        ("ours vs noisy measurements", r.measured_mu_mm, r.measured_sigma_mm, "tab:blue"),
        ("ours vs truth", r.truth_mu_mm, r.truth_sigma_mm, "tab:orange"),
    ]
    width = 0.8 / len(series)
    rows = r.paper_rows()
    for e, (ax, frame) in enumerate(zip(axes, frames, strict=True)):
        for i, (label, mu, sigma, color) in enumerate(series):
            if i == 0 and rows[e] is None:
                continue
            k = rows[e] if i == 0 else e
            # |error| >= 0: a lower bar that would cross zero stops there.
            yerr = np.stack([np.minimum(sigma[k], mu[k]), sigma[k]])
            ax.bar(
                x + (i - 1) * width,
                mu[k],
                width,
                yerr=yerr,
                capsize=3,
                color=color,
                label=label,
                error_kw={"elinewidth": 1.0},
            )
        ax.axhline(
            r.sigma_mm * np.sqrt(2.0 / np.pi),
            color="0.2",
            linestyle=":",
            linewidth=1.0,
            label="measurement noise alone, σ√(2/π)",
        )
        ax.set_xticks(x, ["x", "y", "z"])
        ax.set_title(frame)
        ax.set_xlabel("axis of the measurement frame")
        ax.set_ylim(bottom=0.0)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].set_ylabel("|error| (mm): bar = mean, whisker = ± std")
    shared_legend(fig, axes)
    fig.suptitle(
        f"Reproduction of Shih et al. (1992) Table 4: {r.per_joint} measurements per joint, "
        f"{_sigma_label(r.sigma_mm, r.sigma_rad)}\n"
        f"{r.n_test} held-out test configurations × {r.trials} trials (new true robot each); "
        "paper: real data",
        fontsize=10,
    )
    return save_figure(fig, path)


# -- runs on the built-in head ---------------------------------------------------------


def run_fig11(out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any) -> Fig11Result:
    """Run :func:`kinfw.verification.papers.fig11_study` (on the built-in IIS-head
    unless ``urdf``) and write ``fig11.png`` and ``fig11.json`` into ``out_dir``;
    ``kwargs`` go to the study."""
    return run_on_head(fig11_study, plot_fig11, out_dir, "fig11", urdf, kwargs)


def run_table4(
    out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any
) -> Table4Result:
    """Run :func:`kinfw.verification.papers.table4_study` (on the built-in IIS-head unless
    ``urdf``) and write ``table4.png`` and ``table4.json`` into ``out_dir``; ``kwargs`` go
    to the study."""
    return run_on_head(table4_study, plot_table4, out_dir, "table4", urdf, kwargs)


def shih_figures_main(argv: Sequence[str] | None = None) -> int:
    """``kinfw reproduce {fig11,table4} --out DIR [--trials N]
    [--seed S]``: run one study on the built-in head, write its PNG and JSON, print the
    table."""
    return choice_main(
        argv,
        prog="kinfw reproduce",
        description="Shih et al. (1992) section 6 in simulation: Fig. 11 or Table 4.",
        trials_help="random trials (default: 10 per Fig. 11 point, 20 for Table 4)",
        studies={"fig11": (run_fig11, format_fig11), "table4": (run_table4, format_table4)},
    )
