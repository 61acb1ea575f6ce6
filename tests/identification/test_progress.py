"""The estimators tell kinfw.progress each Levenberg-Marquardt iteration with its cost,
the cost the solver's result has (checked by recomputing it), and say nothing when
nobody listens."""

import io
import itertools
import re

import numpy as np

from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, levenberg_marquardt
from kinfw.model import load_robot
from kinfw.progress import LineReporter, reporting
from kinfw.simulation import perturb_robot
from tests.head_data import plate_data
from tests.paths import HEAD_URDF
from tests.recorder import Recorder

T = np.linspace(0.0, 2.0, 20)
Y = 3.0 * np.exp(-1.3 * T) + 0.01 * np.sin(7.0 * T)  # a small misfit: the cost stays > 0


def _exponential(x, with_jacobian):
    """Residuals ``x0 exp(x1 t) - y`` (one row per observation) and their Jacobian."""
    e = np.exp(x[1] * T)
    J = np.column_stack([e, x[0] * T * e]) if with_jacobian else None
    return x[0] * e - Y, J


def _costs(task) -> list[float]:
    return [float(note.removeprefix("cost ")) for _, note in task.steps]


def test_each_iteration_and_its_cost_is_told_and_the_last_is_the_solution_cost():
    x0 = np.array([1.0, 0.0])
    recorder = Recorder()
    with reporting(recorder):
        x, iterations, converged = levenberg_marquardt(
            _exponential, x0, np.ones(2, bool), [(len(T), 1)], "linear", np.ones(len(T)), 100
        )
    assert converged
    (task,) = recorder.tasks
    assert (task.name, task.total, task.unit, task.closed) == (
        "Levenberg-Marquardt",
        None,
        "iteration",
        True,
    )
    # iteration 0 is the start; one step per iteration after it
    assert [done for done, _ in task.steps] == list(range(iterations + 1))
    costs = _costs(task)
    # independent truth: 0.5 |r|^2 at the start and at the returned solution
    np.testing.assert_allclose(costs[0], 0.5 * np.sum(_exponential(x0, False)[0] ** 2), rtol=1e-5)
    np.testing.assert_allclose(costs[-1], 0.5 * np.sum(_exponential(x, False)[0] ** 2), rtol=1e-5)
    assert all(b <= a for a, b in itertools.pairwise(costs))
    assert costs[-1] < 1e-3 * costs[0]


def _head_problem():
    nominal = load_robot(HEAD_URDF)
    truth = load_robot(
        perturb_robot(nominal, np.random.default_rng(4), origin_mm=3.0, origin_deg=0.5)
    )
    return nominal, plate_data(truth, 30, 8)


def test_refine_lines_have_decreasing_costs_ending_at_the_result_cost():
    """Piped lines of a refinement under a given noise (one Levenberg-Marquardt run): its
    stages, then the iterations with costs that never increase, the last being the
    result's cost (0.5 |r|^2 of the whitened residuals at the estimate)."""
    nominal, data = _head_problem()
    out = io.StringIO()
    with reporting(LineReporter(out, every=1)):
        result = refine(nominal, data, noise=NoiseModel(0.5e-3, 0.005), loss="linear")
    lines = [line.split(" s  ", 1)[1] for line in out.getvalue().splitlines()]
    assert lines[0] == "refine: start values (30 samples)"
    iterations = [
        re.fullmatch(r"Levenberg-Marquardt: iteration (\d+), cost (\S+)", t) for t in lines[1:]
    ]
    assert all(iterations), lines
    steps = [int(m.group(1)) for m in iterations]
    costs = [float(m.group(2)) for m in iterations]
    assert steps == list(range(len(steps))) and steps[-1] == result.iterations
    assert all(b <= a for a, b in itertools.pairwise(costs))
    assert costs[-1] < 0.01 * costs[0]
    np.testing.assert_allclose(costs[-1], result.cost, rtol=1e-5)


def test_refine_with_noise_rounds_tells_each_round_and_its_iterations():
    nominal, data = _head_problem()
    recorder = Recorder()
    with reporting(recorder):
        result = refine(nominal, data, loss="linear", noise_rounds=3)
    assert recorder.stages == [
        "refine: start values (30 samples)",
        *(f"refine: noise estimate, round {r}/3" for r in (1, 2, 3)),
    ]
    runs = [t for t in recorder.tasks if t.name == "Levenberg-Marquardt"]
    assert len(runs) == 3 and all(t.depth == 0 and t.closed for t in runs)
    assert sum(t.steps[-1][0] for t in runs) == result.iterations
    for t in runs:
        costs = _costs(t)
        assert all(b <= a for a, b in itertools.pairwise(costs))


def test_the_library_prints_nothing_by_default(capfd):
    nominal, data = _head_problem()
    refine(nominal, data, loss="huber")
    assert capfd.readouterr() == ("", "")
