"""Run the head studies on the built-in IIS-head: files and the command line.

``kinfw reproduce {crlb,robust} --out DIR`` runs
:func:`kinfw.verification.studies.crlb_study` or
:func:`kinfw.verification.studies.robustness_study`, writes
its PNG and JSON and prints its table.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kinfw.verification.studies._common import choice_main, run_on_head
from kinfw.verification.studies._crlb_study import CRLBStudy, crlb_study
from kinfw.verification.studies._head_study_plots import plot_crlb, plot_robustness
from kinfw.verification.studies._head_study_tables import format_crlb, format_robustness
from kinfw.verification.studies._robust import RobustStudy, robustness_study


def run_crlb(out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any) -> CRLBStudy:
    """Run :func:`kinfw.verification.studies.crlb_study` (on the built-in IIS-head unless
    ``urdf``) and write ``crlb.png`` and ``crlb.json`` into ``out_dir``; ``kwargs`` go to
    the study."""
    return run_on_head(crlb_study, plot_crlb, out_dir, "crlb", urdf, kwargs)


def run_robustness(
    out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any
) -> RobustStudy:
    """Run :func:`kinfw.verification.studies.robustness_study` (on the built-in IIS-head unless
    ``urdf``) and write ``robust.png`` and ``robust.json`` into ``out_dir``; ``kwargs`` go
    to the study."""
    return run_on_head(robustness_study, plot_robustness, out_dir, "robust", urdf, kwargs)


def head_studies_main(argv: Sequence[str] | None = None) -> int:
    """``kinfw reproduce {crlb,robust} --out DIR [--trials N] [--seed S]``: run
    one study on the built-in head, write its PNG and JSON, print the table."""
    return choice_main(
        argv,
        prog="kinfw reproduce",
        description="crlb: refined calibration vs its Cramér-Rao bound; robust: refinement "
        "with planted outliers (linear, Huber, Cauchy losses).",
        trials_help="random trials (default: 30 for crlb, 20 for robust)",
        studies={"crlb": (run_crlb, format_crlb), "robust": (run_robustness, format_robustness)},
    )
