"""Figures of the head studies: the CRLB study and the robustness study (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kinfw.verification.evaluation import NORMAL_COVERAGE
from kinfw.verification.studies._common import log_axes, new_figure, save_figure
from kinfw.verification.studies._crlb_study import CRLBStudy
from kinfw.verification.studies._head_experiment import rms_over
from kinfw.verification.studies._robust import RobustStudy


def plot_crlb(study: CRLBStudy, path: str | Path) -> Path:
    """Write the CRLB study as a PNG: error vs bound, ratio per trial, coverage.

    Left: each trial's held-out RMS position error of each end frame against the RMS
    error its Cramér-Rao bound implies, for the refined model (true noise given) and the
    closed-form + hand-eye start, with ``y = x``; large diamonds pool the trials per
    frame. Middle: the ratio refined / CRLB of each trial (all frames) inside the band
    an efficient estimator would show, and the pooled ratio. Right: the fraction of
    parameters within 1, 2 and 3 reported standard deviations of the truth, beside a
    normal distribution's.

    Returns
    -------
    Path
        ``path``.
    """
    s = study
    fig = new_figure((16.0, 5.6))
    ax, mx, bx = fig.subplots(1, 3, width_ratios=(1.1, 1.0, 0.9))
    _plot_crlb_errors(ax, s)
    _plot_crlb_ratios(mx, s)
    _plot_crlb_coverage(bx, s)
    fig.suptitle(
        f"Refined calibration vs its Cramér-Rao bound: {s.trials} trials, new true head each; "
        f"noise {s.setup.sigma_mm:g} mm, {s.setup.sigma_deg:g}°; {s.setup.per_joint} values "
        f"per joint + {s.setup.stage2_views} target views; {s.setup.n_test} held-out "
        "configurations",
        fontsize=10,
    )
    return save_figure(fig, path)


def _plot_crlb_errors(ax, s: CRLBStudy) -> None:
    """Left panel of :func:`plot_crlb`: held-out RMS error vs the CRLB's, per trial and frame."""
    colors = ("tab:blue", "tab:green", "tab:red", "tab:purple", "tab:orange", "tab:brown")
    for e, frame in enumerate(s.setup.frames):
        color = colors[e % len(colors)]
        ax.scatter(
            s.crlb_rms_mm[:, e], s.start_rms_mm[:, e], marker="^", s=14, color=color, alpha=0.3
        )
        ax.scatter(
            s.crlb_rms_mm[:, e],
            s.refined_rms_mm[:, e],
            marker="o",
            s=16,
            color=color,
            alpha=0.75,
            label=frame,
        )
        ax.scatter(
            rms_over(s.crlb_rms_mm[:, e], 0),
            rms_over(s.refined_rms_mm[:, e], 0),
            marker="D",
            s=90,
            color=color,
            edgecolor="k",
            linewidth=1.2,
            zorder=4,
        )
    values = np.concatenate(
        [s.crlb_rms_mm.ravel(), s.refined_rms_mm.ravel(), s.start_rms_mm.ravel()]
    )
    line = np.array([0.8 * values.min(), 1.25 * values.max()])
    ax.plot(line, line, color="0.2", linewidth=1.2, label="y = x (efficient)")
    ax.scatter([], [], marker="o", color="0.4", label="refined, σ given (per trial)")
    ax.scatter([], [], marker="^", color="0.4", alpha=0.4, label="closed form + hand-eye start")
    ax.scatter([], [], marker="D", color="0.4", edgecolor="k", label="pooled over trials")
    log_axes(ax, "both")
    ax.set_xlim(*line)
    ax.set_ylim(*line)
    ax.set_aspect("equal")
    ax.set_xlabel("RMS error implied by the Cramér-Rao bound (mm)")
    ax.set_ylabel("held-out RMS position error vs truth (mm)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left")
    ax.set_title("per trial and end frame", fontsize=10)


def _plot_crlb_ratios(mx, s: CRLBStudy) -> None:
    """Middle panel of :func:`plot_crlb`: refined / CRLB RMS error per trial, in its band."""
    t = np.arange(1, s.trials + 1)
    mx.fill_between(
        t,
        s.ratio_band[:, 0],
        s.ratio_band[:, 1],
        step="mid",
        color="0.85",
        label="5-95 % for an efficient estimator",
    )
    mx.plot(
        t,
        s.trial_rms_mm("estimated_noise") / s.trial_rms_mm("crlb"),
        "x",
        color="tab:orange",
        label="refined, σ estimated",
    )
    mx.plot(t, s.ratio, "o", color="tab:blue", label="refined, σ given")
    mx.axhline(1.0, color="0.2", linewidth=1.0)
    mx.axhline(
        s.pooled_ratio(),
        color="tab:blue",
        linestyle="--",
        linewidth=1.2,
        label=f"pooled: {s.pooled_ratio():.3f}",
    )
    mx.set_xlabel("trial (new true head each)")
    mx.set_ylabel("held-out RMS error / CRLB RMS error (all frames)")
    mx.grid(True, alpha=0.3)
    mx.legend(fontsize=8, loc="upper right")
    mx.set_title(
        f"ratio per trial; NEES mean {s.nees.mean():.1f} (χ²: {s.n_parameters})", fontsize=10
    )


def _plot_crlb_coverage(bx, s: CRLBStudy) -> None:
    """Right panel of :func:`plot_crlb`: parameters within k reported sigma of the truth."""
    ks = list(NORMAL_COVERAGE)
    bars = (
        ("CPC model, σ given", [s.coverage(k, kind="model") for k in ks], "tab:blue"),
        ("target pose, σ given", [s.coverage(k, kind="target") for k in ks], "tab:green"),
        ("all, σ estimated", [s.coverage(k, estimated_noise=True) for k in ks], "tab:orange"),
    )
    x = np.arange(len(ks))
    width = 0.8 / len(bars)
    for i, (label, cover, color) in enumerate(bars):
        bx.bar(x + (i - 1) * width, 100 * np.array(cover), width, color=color, label=label)
    for xi, k in zip(x, ks, strict=True):
        bx.hlines(
            100 * NORMAL_COVERAGE[k],
            xi - 0.45,
            xi + 0.45,
            color="0.1",
            linewidth=1.5,
            label="normal distribution" if xi == 0 else None,
        )
    bx.set_xticks(x, [f"±{k:g} σ" for k in ks])
    bx.set_ylim(0, 105)
    bx.set_ylabel("parameters with |estimate - truth| <= k σ (%)")
    bx.grid(True, axis="y", alpha=0.3)
    bx.legend(fontsize=8, loc="lower right")
    bx.set_title(
        f"coverage, σ as reported: {s.n_parameters} parameters x {s.trials} trials", fontsize=10
    )


def plot_robustness(study: RobustStudy, path: str | Path) -> Path:
    """Write the robustness study as a PNG: held-out errors per variant, and detection.

    Left: each trial's held-out RMS position error (log scale) for the corrupted start
    and every variant, beside the clean-data result. Right: the fraction of planted
    outliers and of clean observations that each variant down-weighted.

    Returns
    -------
    Path
        ``path``.
    """
    s = study
    fig = new_figure((12.0, 5.4))
    ax, bx = fig.subplots(1, 2, width_ratios=(1.4, 1.0))
    labels = [
        "clean data,\nlinear",
        "start,\ncorrupted",
        *[lb.replace(", ", ",\n") for lb in s.labels],
    ]
    columns = [s.clean_rms_mm, s.start_rms_mm, *s.rms_mm.T]
    rng = np.random.default_rng(0)  # horizontal jitter only
    for i, values in enumerate(columns):
        ax.scatter(
            i + rng.uniform(-0.15, 0.15, len(values)),
            values,
            s=16,
            alpha=0.7,
            color="tab:green" if i == 0 else ("0.55" if i == 1 else "tab:blue"),
        )
        ax.hlines(np.median(values), i - 0.3, i + 0.3, color="0.1", linewidth=2)
    ax.axhline(np.median(s.clean_rms_mm), color="tab:green", linestyle=":", linewidth=1)
    log_axes(ax, "y")
    ax.set_xticks(range(len(columns)), labels, fontsize=8)
    ax.set_ylabel("held-out RMS position error vs truth (mm); bar = median")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.set_title("per trial, all end frames", fontsize=10)
    x = np.arange(len(s.variants))
    planted = bx.bar(x - 0.2, 100 * s.recall, 0.4, color="tab:red", label="planted outliers")
    clean = bx.bar(
        x + 0.2, 100 * s.false_alarm_rate, 0.4, color="tab:gray", label="clean observations"
    )
    for bars in (planted, clean):
        bx.bar_label(bars, fmt="%.0f", fontsize=7.5)
    bx.set_xticks(x, [lb.replace(", ", ",\n") for lb in s.labels], fontsize=8)
    bx.set_ylim(0, 122)
    bx.set_yticks(np.arange(0, 101, 20))
    bx.set_ylabel("down-weighted by refine (weight < 0.5), %")
    bx.grid(True, axis="y", alpha=0.3)
    bx.legend(fontsize=8, loc="upper center", ncols=2)
    bx.set_title("detection", fontsize=10)
    fig.suptitle(
        f"Robust refinement: {100 * s.outlier_fraction:g} % of observations corrupted by "
        f"{s.outlier_mm:g} mm and {s.outlier_deg:g}° ({s.trials} trials); noise "
        f"{s.setup.sigma_mm:g} mm, {s.setup.sigma_deg:g}°",
        fontsize=10,
    )
    return save_figure(fig, path)
