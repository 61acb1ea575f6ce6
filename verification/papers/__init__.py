"""The papers' experiments in simulation: Shih et al. (1992) Fig. 11 and Table 4, Hirsh,
DeSouza & Kak (2001) Figs. 3 and 4.
"""

from __future__ import annotations

from kinfw.verification.papers._hirsh_experiments import (
    CONVERGED_DEG,
    HirshResult,
    hirsh_study,
)
from kinfw.verification.papers._hirsh_figures import (
    format_hirsh,
    hirsh_figures_main,
    load_hirsh,
    plot_hirsh,
    run_hirsh,
)
from kinfw.verification.papers._hirsh_problem import (
    quaternion_angle,
    random_problem,
    rotate_about_random_axes,
    rotations_about_random_axes,
)
from kinfw.verification.papers._shih_experiments import (
    Fig11Result,
    StudySetup,
    fig11_study,
)
from kinfw.verification.papers._shih_figures import (
    format_fig11,
    format_table4,
    plot_fig11,
    plot_table4,
    run_fig11,
    run_table4,
    shih_figures_main,
)
from kinfw.verification.papers._shih_table4 import (
    PAPER_TABLE4_MU_MM,
    PAPER_TABLE4_SIGMA_MM,
    Table4Result,
    table4_study,
)

__all__ = [
    "CONVERGED_DEG",
    "PAPER_TABLE4_MU_MM",
    "PAPER_TABLE4_SIGMA_MM",
    "Fig11Result",
    "HirshResult",
    "StudySetup",
    "Table4Result",
    "fig11_study",
    "format_fig11",
    "format_hirsh",
    "format_table4",
    "hirsh_figures_main",
    "hirsh_study",
    "load_hirsh",
    "plot_fig11",
    "plot_hirsh",
    "plot_table4",
    "quaternion_angle",
    "random_problem",
    "rotate_about_random_axes",
    "rotations_about_random_axes",
    "run_fig11",
    "run_hirsh",
    "run_table4",
    "shih_figures_main",
    "table4_study",
]
