"""Tables of the head studies: the CRLB study and the robustness study (Markdown text).

:func:`format_crlb` formats a :class:`kinfw.verification.studies.CRLBStudy`,
:func:`format_robustness` a :class:`kinfw.verification.studies.RobustStudy`; the figures are
:mod:`kinfw.verification.studies`.
"""

from __future__ import annotations

import numpy as np

from kinfw.verification.evaluation import NORMAL_COVERAGE
from kinfw.verification.studies._common import sample_std
from kinfw.verification.studies._crlb_study import CRLBStudy
from kinfw.verification.studies._head_experiment import rms_over
from kinfw.verification.studies._robust import RobustStudy


def format_crlb(study: CRLBStudy) -> str:
    """Markdown tables of the CRLB study: errors per frame, coverage, noise (mm, deg)."""
    s = study
    frames = s.setup.frames
    columns = (
        ("start", s.start_rms_mm),
        ("refined", s.refined_rms_mm),
        ("estimated_noise", s.estimated_noise_rms_mm),
        ("crlb", s.crlb_rms_mm),
    )
    lines = [
        f"Cramér-Rao bound study: {s.trials} trials; held-out RMS position error against "
        "the truth (mm), pooled over trials (sqrt of the mean square).",
        s.setup.describe() + ".",
        "",
        "| frame | closed form + hand-eye | refined (σ given) | refined (σ estimated) "
        "| CRLB | refined / CRLB |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for e, frame in enumerate(frames):
        cells = [f"{rms_over(v[:, e], 0):.3f}" for _, v in columns]
        lines.append(
            f"| {frame} | " + " | ".join(cells) + f" | {s.pooled_ratio_per_frame[e]:.3f} |"
        )
    cells = [f"{rms_over(s.trial_rms_mm(name), 0):.3f}" for name, _ in columns]
    lines.append("| **all frames** | " + " | ".join(cells) + f" | {s.pooled_ratio():.3f} |")
    ratio = s.ratio
    lines += [
        "",
        f"refined / CRLB per trial: median {np.median(ratio):.3f}, min {ratio.min():.3f}, "
        f"max {ratio.max():.3f}; {100 * s.within_band:.0f} % of the trials inside the 5-95 % "
        f"band an efficient estimator would show (90 % expected; typical band "
        f"{np.median(s.ratio_band[:, 0]):.2f}-{np.median(s.ratio_band[:, 1]):.2f}). Pooled "
        f"{s.pooled_ratio():.3f} (target <= 1.05; σ estimated: "
        f"{s.pooled_ratio('estimated_noise'):.3f}).",
        "",
        "Coverage: fraction of parameters with |estimate - truth| <= k σ (σ as refine "
        f"reports it), {s.z.shape[1]} free parameters x {s.trials} trials:",
        "",
        "| k | normal | CPC model (σ given) | target pose (σ given) | all (σ given) "
        "| all (σ estimated) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for k, expected in NORMAL_COVERAGE.items():
        cells = [
            s.coverage(k, kind="model"),
            s.coverage(k, kind="target"),
            s.coverage(k),
            s.coverage(k, estimated_noise=True),
        ]
        lines.append(
            f"| {k:g} | {100 * expected:.1f} % | "
            + " | ".join(f"{100 * c:.1f} %" for c in cells)
            + " |"
        )
    z = s.z[np.isfinite(s.z)]
    true = s.true_noise
    est, ratio_n = s.noise_estimates, s.noise_ratio
    lines += [
        "",
        f"RMS of (estimate - truth) / σ: {np.sqrt(np.mean(z**2)):.3f} (1 expected). "
        f"NEES (x_hat - x)^T C^-1 (x_hat - x): mean {s.nees.mean():.1f} over {s.trials} "
        f"trials (chi-square: {s.n_parameters} ± {np.sqrt(2.0 * s.n_parameters / s.trials):.1f})"
        f"; reduced chi-square of the fit, σ given: mean {s.sigma_hat2.mean():.3f}.",
        "",
        "| noise (per component) | true | estimated, mean ± std | estimated / true: "
        "mean, min, max |",
        "|---|---:|---:|---:|",
        f"| position (mm) | {1e3 * true[0]:.4f} | {1e3 * est[:, 0].mean():.4f} ± "
        f"{1e3 * sample_std(est[:, 0]):.4f} | {ratio_n[:, 0].mean():.3f}, "
        f"{ratio_n[:, 0].min():.3f}, {ratio_n[:, 0].max():.3f} |",
        f"| orientation (deg) | {np.degrees(true[1]):.4f} | {np.degrees(est[:, 1].mean()):.4f}"
        f" ± {np.degrees(sample_std(est[:, 1])):.4f} | {ratio_n[:, 1].mean():.3f}, "
        f"{ratio_n[:, 1].min():.3f}, {ratio_n[:, 1].max():.3f} |",
        "",
        f"{np.sum(s.seconds):.1f} s ({np.mean(s.seconds):.2f} s per trial).",
    ]
    return "\n".join(lines)


def format_robustness(study: RobustStudy) -> str:
    """Markdown table of the robustness study: held-out errors and detection per variant."""
    s = study
    ratio = s.ratio_to_clean
    lines = [
        f"Robustness study: {s.trials} trials; {100 * s.outlier_fraction:g} % of the "
        f"observations corrupted by {s.outlier_mm:g} mm and {s.outlier_deg:g} deg "
        f"({int(s.n_planted.sum())} planted among {int(s.n_observations.sum())}). Held-out RMS "
        "position error against the truth (mm), all frames.",
        s.setup.describe() + ".",
        "",
        "| refinement | RMS error: median | max | / clean: median | max | planted "
        "down-weighted | clean down-weighted |",
        "|---|---:|---:|---:|---:|---:|---:|",
        f"| clean data, linear (reference) | {np.median(s.clean_rms_mm):.3f} | "
        f"{s.clean_rms_mm.max():.3f} | 1 | 1 | – | – |",
        f"| start (closed form + hand-eye), corrupted | {np.median(s.start_rms_mm):.3f} | "
        f"{s.start_rms_mm.max():.3f} | {np.median(s.start_rms_mm / s.clean_rms_mm):.2f} | "
        f"{np.max(s.start_rms_mm / s.clean_rms_mm):.2f} | – | – |",
    ]
    for v, label in enumerate(s.labels):
        lines.append(
            f"| {label} | {np.median(s.rms_mm[:, v]):.3f} | {s.rms_mm[:, v].max():.3f} | "
            f"{np.median(ratio[:, v]):.2f} | {ratio[:, v].max():.2f} | "
            f"{100 * s.recall[v]:.0f} % | {100 * s.false_alarm_rate[v]:.1f} % |"
        )
    estimated = [v for v, (_, noise) in enumerate(s.variants) if noise == "estimated"]
    if estimated:
        sp = 1e3 * s.noise_used[:, estimated, 0]
        lines += [
            "",
            f"Noise estimated with outliers: position {np.median(sp):.2f} mm per "
            f"component (median; true {s.setup.sigma_mm:g} mm).",
        ]
    lines += [
        "",
        "Down-weighted: refine's `downweighted` (observations beyond the robust "
        "loss's threshold: the 99 % quantile of a clean residual norm) or `rejected` "
        "(beyond the 99.9 % quantile: excluded and the problem refitted).",
        "",
        f"{np.sum(s.seconds):.1f} s ({np.mean(s.seconds):.2f} s per trial).",
    ]
    return "\n".join(lines)
