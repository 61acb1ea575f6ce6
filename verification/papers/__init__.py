"""The papers' experiments in simulation: Shih et al. (1992) Fig. 11 and Table 4, Hirsh,
DeSouza & Kak (2001) Figs. 3 and 4.
"""

from __future__ import annotations

from kinfw.verification.papers._hirsh_experiments import (
    CONVERGED_DEG,
    PAPER_NOISE_DEG,
    PAPER_VIEWS,
    SOLVER_MAX_ITERATIONS,
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
    SimulatedProblem,
    draw_problem,
    quaternion_angle,
    random_problem,
    rotate_about_random_axes,
    rotations_about_random_axes,
)
from kinfw.verification.papers._shih_experiments import (
    PAPER_ACCURACY_MM,
    PAPER_PER_JOINT,
    Fig11Result,
    StudySetup,
    Trial,
    calibrate_once,
    check_sigmas_mm,
    fig11_study,
    positions_m,
    setup_study,
    trial_rng,
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
    PAPER_TABLE4_FRAMES,
    PAPER_TABLE4_MU_MM,
    PAPER_TABLE4_SIGMA_MM,
    Table4Result,
    table4_study,
)

__all__ = [
    "CONVERGED_DEG",
    "PAPER_ACCURACY_MM",
    "PAPER_NOISE_DEG",
    "PAPER_PER_JOINT",
    "PAPER_TABLE4_FRAMES",
    "PAPER_TABLE4_MU_MM",
    "PAPER_TABLE4_SIGMA_MM",
    "PAPER_VIEWS",
    "SOLVER_MAX_ITERATIONS",
    "Fig11Result",
    "HirshResult",
    "SimulatedProblem",
    "StudySetup",
    "Table4Result",
    "Trial",
    "calibrate_once",
    "check_sigmas_mm",
    "draw_problem",
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
    "positions_m",
    "quaternion_angle",
    "random_problem",
    "rotate_about_random_axes",
    "rotations_about_random_axes",
    "run_fig11",
    "run_hirsh",
    "run_table4",
    "setup_study",
    "shih_figures_main",
    "table4_study",
    "trial_rng",
]
