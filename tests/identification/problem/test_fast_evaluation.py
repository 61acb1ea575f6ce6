"""The fast evaluation paths of the least-squares problem (issue 23): compiled residual
functions over chunks of samples, the kept last evaluation, the free columns only, the
leverages by blocks, and Levenberg-Marquardt's stop at the minimum."""

import io
import itertools
import logging

import numpy as np
import pytest

import kinfw.identification.problem._compiled as compiled_module
from kinfw.identification.problem import (
    MAP_CHUNK,
    NoiseModel,
    build_problem,
    column_norms,
    covariance_and_identifiability,
    levenberg_marquardt,
    leverage_sums,
    leverages,
    normal_equations,
    tall_r,
)
from kinfw.identification.problem._problem import chunks
from kinfw.model import load_robot
from kinfw.progress import reporting, task
from kinfw.simulation import random_configurations, simulate_at
from tests.recorder import Recorder
from tests.robots import ARM_6R


def _arm_problem(n: int, seed: int = 0):
    """The 6R arm's flange poses and a marker's points, n samples, noisy."""
    arm = load_robot(ARM_6R)
    rng = np.random.default_rng(seed)
    names = arm.topology(("flange",)).joint_names
    qs = random_configurations(*arm.joint_limits(names), n, rng, fraction=0.8)
    poses = simulate_at(arm, qs, names, frames=["flange"], rng=rng, noise_m=1e-3, noise_rad=1e-3)
    points = simulate_at(arm, qs, names, markers=[("flange", [0.02, -0.01, 0.05])], rng=rng)
    data = poses.with_groups([*poses.all_groups(), *points.all_groups()])
    return build_problem(arm, data), rng


def _per_sample(group, x, free):
    """The reference: CasADi's own function (virtual machine), one sample at a time."""
    f = group.functions.rj_free(free)
    r, J = [], []
    for i in range(len(group.sample)):
        ri, Jti = f(group.qs[:, i], group.data[:, i], x, group.const)
        r.append(np.asarray(ri).ravel())
        J.append(np.asarray(Jti).T)
    return np.concatenate(r), np.concatenate(J)


@pytest.mark.slow
def test_chunked_compiled_evaluation_equals_casadi_per_sample_bit_for_bit():
    """Across chunk borders (2 chunks + 5 samples): the same numbers as CasADi's virtual
    machine sample by sample (compiled without fused multiply-add; without a compiler
    the functions are CasADi's own)."""
    problem, rng = _arm_problem(2 * MAP_CHUNK + 5)
    x = rng.normal(scale=1e-2, size=problem.n_parameters)
    free = problem.free
    for g in problem.groups:
        r, J = g.evaluate(x, True, free)
        r_ref, J_ref = _per_sample(g, x, free)
        np.testing.assert_array_equal(r, r_ref)
        np.testing.assert_array_equal(J, J_ref)
        r_only, none = g.evaluate(x + 1e-3, False, free)
        assert none is None
        np.testing.assert_array_equal(r_only, _per_sample(g, x + 1e-3, free)[0])


def test_the_last_evaluation_is_kept_and_not_shared_by_a_replaced_group():
    from dataclasses import replace

    problem, rng = _arm_problem(20)
    g = problem.groups[0]
    x = rng.normal(scale=1e-2, size=problem.n_parameters)
    r, J = g.evaluate(x, True, problem.free)
    again, J_again = g.evaluate(x.copy(), True, problem.free)
    assert again is r and J_again is J
    r_only, _ = g.evaluate(x, False, problem.free)  # the residuals of the kept evaluation
    assert r_only is r
    moved = replace(g, const=g.const + 1e-3)  # other numbers: its own evaluation
    r_moved, _ = moved.evaluate(x, False, problem.free)
    assert np.abs(r_moved - r).max() > 1e-6
    assert g.evaluate(x, False, problem.free)[0] is r


def test_free_columns_are_those_of_the_full_jacobian():
    problem, rng = _arm_problem(30)
    noise = NoiseModel(1e-3, 1e-3)
    x = rng.normal(scale=1e-2, size=problem.n_parameters)
    r_all, J_all = problem.evaluate(x, noise, True)
    r_free, J_free = problem.evaluate_free(x, noise, True)
    r_only, J_only = problem.evaluate(x, noise, True, only_free=True)
    np.testing.assert_allclose(r_free, r_all, rtol=0, atol=1e-12)
    np.testing.assert_allclose(J_free, J_all[:, problem.free], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(J_only[:, problem.free], J_free)
    np.testing.assert_array_equal(J_only[:, ~problem.free], 0.0)
    np.testing.assert_array_equal(r_only, r_free)


@pytest.mark.parametrize("shape", [(20_000, 7), (9_000, 30)])
def test_leverages_by_blocks_equal_the_hat_matrix_diagonal(shape):
    rng = np.random.default_rng(5)
    A = rng.normal(size=shape) * np.logspace(-3, 3, shape[1])  # columns of any scale
    Q, _ = np.linalg.qr(A)
    h = leverages(A)
    np.testing.assert_allclose(h, np.sum(Q**2, axis=1), rtol=1e-10, atol=1e-14)
    assert h.sum() == pytest.approx(shape[1], abs=1e-8)  # trace of the hat matrix


def test_leverages_of_a_rank_deficient_matrix_are_numpys_thin_qr():
    rng = np.random.default_rng(6)
    A = rng.normal(size=(10_000, 4))
    A = np.column_stack([A, A[:, 0] + A[:, 1]])  # rank 4
    Q, _ = np.linalg.qr(A)
    np.testing.assert_array_equal(leverages(A), np.sum(Q**2, axis=1))


def test_levenberg_marquardt_stops_at_the_minimum_without_retrying():
    """A linear problem: one Gauss-Newton step reaches the least-squares solution (the
    truth: numpy's lstsq); at the minimum the solver stops without a string of
    rejected steps (the old loop spent up to ~40 residual evaluations there)."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(300, 4))
    b = rng.normal(size=300)
    calls = {True: 0, False: 0}

    def evaluate(x, with_jacobian):
        calls[with_jacobian] += 1
        return A @ x - b, (A if with_jacobian else None)

    x, iterations, converged = levenberg_marquardt(
        evaluate, np.zeros(4), np.ones(4, bool), [(300, 1)], "linear", np.full(300, 1e9), 50
    )
    np.testing.assert_allclose(x, np.linalg.lstsq(A, b, rcond=None)[0], rtol=1e-9, atol=1e-12)
    assert converged
    assert iterations <= 3
    assert calls[False] <= 3 and calls[True] <= 3


def test_without_a_compiler_casadi_evaluates_the_functions(monkeypatch):
    import casadi as ca

    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.sin(x) * x[0]])
    monkeypatch.setenv("KINFW_COMPILE", "0")
    assert compiled_module.compiler() is None
    assert compiled_module.compiled(f, compiled_module.COMPILE_SAMPLES) is f
    monkeypatch.delenv("KINFW_COMPILE")
    monkeypatch.setenv("CC", "no-such-compiler-kinfw")
    assert compiled_module.compiled(f, compiled_module.COMPILE_SAMPLES) is f


def test_a_failing_compiler_is_reported_once_and_casadi_takes_over(monkeypatch, tmp_path, caplog):
    import casadi as ca

    monkeypatch.setattr(compiled_module, "_FAILED", [])
    monkeypatch.setattr(compiled_module, "_NATIVE_REFUSED", [])
    monkeypatch.setenv("KINFW_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # exists, always fails (with and without -march)
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.cos(x) * x[1]])
    with caplog.at_level(logging.WARNING, logger="kinfw.identification.problem"):
        assert compiled_module.compiled(f, compiled_module.COMPILE_SAMPLES) is f
        assert compiled_module.compiled(f, compiled_module.COMPILE_SAMPLES) is f  # not retried
    assert len([r for r in caplog.records if "compiling" in r.getMessage()]) == 1


def test_a_compiled_function_is_kept_on_disk_and_loaded_again(monkeypatch, tmp_path):
    import casadi as ca

    if compiled_module.compiler() is None:
        pytest.fail("no C compiler on this machine: the compiled path is not tested")
    monkeypatch.setenv("KINFW_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled_module, "_LOADED", {})
    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [ca.sqrt(x) * x[2] + ca.exp(x[0])])
    g = compiled_module.compiled(f, compiled_module.COMPILE_SAMPLES)
    assert g is not f
    assert not compiled_module._NATIVE_REFUSED  # built for this processor
    (library,) = tmp_path.glob("kinfw_*.so")
    stamp = library.stat().st_mtime_ns
    monkeypatch.setattr(compiled_module, "_LOADED", {})  # a new process: from the disk
    h = compiled_module.compiled(f, 1)  # in the cache: loaded, however few the samples
    assert h is not f
    assert library.stat().st_mtime_ns == stamp  # not compiled again
    v = np.array([0.3, 1.7, 2.9])
    np.testing.assert_array_equal(np.asarray(h(v)), np.asarray(f(v)))
    np.testing.assert_array_equal(np.asarray(g(v)), np.asarray(f(v)))


def test_a_small_groups_function_is_compiled_only_once_in_the_cache_or_when_asked(
    monkeypatch, tmp_path
):
    """Compiling pays for large groups only: a function of a few samples not yet in the
    cache stays CasADi's own (nothing compiled); one of COMPILE_SAMPLES samples is
    compiled, saying so first even inside a loop, and then serves the few samples too;
    KINFW_COMPILE=1 compiles whatever the size."""
    import casadi as ca

    if compiled_module.compiler() is None:
        pytest.fail("no C compiler on this machine: the compiled path is not tested")
    monkeypatch.setenv("KINFW_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled_module, "_LOADED", {})
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.tanh(x) * x[1] + 0.5])
    few = compiled_module.COMPILE_SAMPLES - 1
    recorder = Recorder()
    with reporting(recorder):
        assert compiled_module.compiled(f, few) is f
        assert not list(tmp_path.glob("kinfw_*.so")) and recorder.stages == []
        with task("Levenberg-Marquardt"):  # a stage would not be shown in here
            g = compiled_module.compiled(f, compiled_module.COMPILE_SAMPLES)
    assert g is not f and len(list(tmp_path.glob("kinfw_*.so"))) == 1
    assert recorder.stages == [
        f"compiling a residual function into C for this machine, once (kept in {tmp_path})"
    ]
    assert compiled_module.compiled(f, few) is g  # already compiled: it costs nothing
    v = np.array([0.3, -1.2])
    np.testing.assert_array_equal(np.asarray(g(v)), np.asarray(f(v)))
    h = ca.Function("h", [x], [ca.atan(x) * x[0]])
    monkeypatch.setenv("KINFW_COMPILE", "1")
    assert compiled_module.compiled(h, 1) is not h
    assert len(list(tmp_path.glob("kinfw_*.so"))) == 2


def test_chunks_cover_every_sample_once_in_few_sizes():
    for m in (1, 5, 2047, MAP_CHUNK, 2 * MAP_CHUNK + 5, 10_000, 99_999):
        spans = chunks(m)
        assert spans[0][0] == 0 and spans[-1][1] == m
        assert all(b0 == a1 for (_, b0), (a1, _) in itertools.pairwise(spans))
        sizes = {b - a for a, b in spans}
        assert sizes <= {MAP_CHUNK >> i for i in range(12)}  # MAP_CHUNK and powers of two
        assert len([s for s in (b - a for a, b in spans) if s < MAP_CHUNK]) == len(
            sizes - {MAP_CHUNK}
        )  # each smaller size at most once


def test_normal_equations_by_blocks_equal_the_dense_products():
    rng = np.random.default_rng(8)
    J = rng.normal(size=(9_001, 12)) * np.logspace(-2, 2, 12)
    r, w = rng.normal(size=9_001), rng.uniform(0.1, 1.0, size=9_001)
    columns = np.arange(12) % 3 != 1
    A, b = J[:, columns] * w[:, None], r * w
    G, g = normal_equations(J, r, w, columns)
    np.testing.assert_allclose(G, A.T @ A, rtol=1e-12, atol=1e-12 * np.abs(A.T @ A).max())
    np.testing.assert_allclose(g, A.T @ b, rtol=1e-11, atol=1e-12 * np.abs(A.T @ b).max())
    np.testing.assert_allclose(column_norms(J), np.linalg.norm(J, axis=0), rtol=1e-13)


@pytest.mark.parametrize("n", [7, 500, 20_000])
def test_tall_r_has_the_singular_values_of_the_scaled_matrix(n):
    """R of the blocked QR: R^T R = A^T A and the singular values of A (numpy's SVD of
    the whole matrix), rank-deficient A included."""
    rng = np.random.default_rng(9)
    A = rng.normal(size=(n, 10)) * np.logspace(-3, 3, 10)
    A[:, 4] = A[:, 0] - 2e3 * A[:, 9] / 1e3  # a null direction
    scale = 1.0 / np.linalg.norm(A, axis=0)
    R = tall_r(A, scale)
    As = A * scale
    assert R.shape == (min(n, 10), 10)
    np.testing.assert_allclose(R.T @ R, As.T @ As, atol=1e-12)
    s_ref = np.linalg.svd(As, compute_uv=False)
    np.testing.assert_allclose(np.linalg.svd(R, compute_uv=False), s_ref, atol=1e-12)


def test_leverages_with_a_row_scale_are_those_of_the_scaled_rows():
    rng = np.random.default_rng(10)
    A = rng.normal(size=(12_000, 6))
    w = rng.uniform(0.2, 1.0, size=12_000)
    Q, _ = np.linalg.qr(A * w[:, None])
    np.testing.assert_allclose(leverages(A, w), np.sum(Q**2, axis=1), rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("redundant", [False, True])
def test_covariance_by_blocks_equals_the_dense_pseudo_inverse(redundant):
    """The covariance from the blocked QR's R equals sigma^2 (Js^T Js)^+ / (c c^T) of
    numpy's pseudo-inverse of the whole column-scaled Jacobian (rcond 1e-8), on 14,000
    rows (blocks of 4,096); with a column made the double of another (a gauge-like
    redundancy) the rank drops by one and the null direction names both."""
    problem, rng = _arm_problem(2_000)
    arm = load_robot(ARM_6R)
    names = arm.topology(("flange",)).joint_names
    qs = random_configurations(*arm.joint_limits(names), 2_000, rng, fraction=0.8)
    data = simulate_at(arm, qs, names, frames=["flange"], rng=rng, noise_m=1e-3, noise_rad=1e-3)
    x = rng.normal(scale=1e-2, size=problem.n_parameters)
    _, J = problem.evaluate(x, NoiseModel(1e-3, 1e-3), True)
    free = problem.free
    idx = np.flatnonzero(free)
    if redundant:
        J[:, idx[3]] = 2.0 * J[:, idx[1]]
    Jf = J[:, free]
    c = np.linalg.norm(Jf, axis=0)
    pinv = np.linalg.pinv(Jf / c, rcond=1e-8)
    reference = pinv @ pinv.T / np.outer(c, c) * 2.5
    covariance, ident = covariance_and_identifiability(
        J, free, list(problem.names), 2.5, data, problem.model0
    )
    scale = np.abs(reference).max()
    np.testing.assert_allclose(covariance[np.ix_(idx, idx)], reference, atol=1e-10 * scale)
    np.testing.assert_array_equal(covariance[~free], 0.0)
    assert ident.rank == len(idx) - int(redundant)
    if redundant:
        ((involved, _),) = ident.unidentifiable
        assert {problem.names[idx[1]], problem.names[idx[3]]} <= set(involved)
    # the free columns alone give the same
    covariance_free, _ = covariance_and_identifiability(
        Jf, free, list(problem.names), 2.5, data, problem.model0
    )
    np.testing.assert_array_equal(covariance_free, covariance)


def test_problem_normal_equations_equal_the_whitened_jacobians_products():
    """Without forming the whitened Jacobian: A^T A, A^T b and the per-component grams
    equal those of evaluate_free's arrays scaled row by row (prior rows included)."""
    arm = load_robot(ARM_6R)
    rng = np.random.default_rng(11)
    names = arm.topology(("flange",)).joint_names
    qs = random_configurations(*arm.joint_limits(names), 1_500, rng, fraction=0.8)
    data = simulate_at(arm, qs, names, frames=["flange"], rng=rng, noise_m=1e-3, noise_rad=1e-3)
    problem = build_problem(arm, data, prior=(1e-3, 1e-3))
    assert len(problem.prior_rows)
    noise = NoiseModel(1e-3, 2e-3)
    x = rng.normal(scale=1e-3, size=problem.n_parameters)
    r, J = problem.evaluate_free(x, noise, True)
    w = rng.uniform(0.5, 1.0, size=len(r))
    normal = problem.normal_equations(x, noise, w, by_component=True)
    A, b = J * w[:, None], r * w
    scale = np.abs(A.T @ A).max()
    np.testing.assert_allclose(normal.G, A.T @ A, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(normal.g, A.T @ b, rtol=0, atol=1e-12 * np.abs(A.T @ b).max())
    np.testing.assert_allclose(normal.b, b, rtol=1e-14, atol=0)
    n_obs = len(problem.groups[0].sample)
    A3 = A[: 6 * n_obs].reshape(n_obs, 6, -1)
    position, rotation = A3[:, :3].reshape(-1, A.shape[1]), A3[:, 3:].reshape(-1, A.shape[1])
    np.testing.assert_allclose(
        normal.by_component["position"], position.T @ position, rtol=0, atol=1e-13 * scale
    )
    np.testing.assert_allclose(
        normal.by_component["rotation"], rotation.T @ rotation, rtol=0, atol=1e-13 * scale
    )


def test_leverage_sums_are_the_sums_of_the_hat_matrix_diagonal():
    rng = np.random.default_rng(12)
    A = rng.normal(size=(3_000, 8)) * np.logspace(-2, 2, 8)
    part = np.arange(3_000) % 3 == 0
    Q, _ = np.linalg.qr(A)
    h = np.sum(Q**2, axis=1)
    sums = leverage_sums(A.T @ A, {"a": A[part].T @ A[part], "b": A[~part].T @ A[~part]})
    assert sums["a"] == pytest.approx(h[part].sum(), rel=1e-10)
    assert sums["b"] == pytest.approx(h[~part].sum(), rel=1e-10)
    # a zero column or a rank-deficient matrix: the rows' own leverages decide
    A[:, 3] = 0.0
    assert leverage_sums(A.T @ A, {"a": A.T @ A}) is None
    A[:, 3] = A[:, 0] + A[:, 1]
    assert leverage_sums(A.T @ A, {"a": A.T @ A}) is None


def test_the_first_calibration_of_many_samples_says_it_compiles_and_the_next_does_not(
    monkeypatch, tmp_path
):
    """A planar 2R arm's 256 tool poses (a group large enough to pay for compiling), an
    empty cache: the piped lines say each compilation, even inside the Levenberg-Marquardt
    loop; the same calibration again (a new process: nothing loaded) compiles nothing, and
    both estimates are the virtual machine's to the last bit."""
    from kinfw.identification import identify
    from kinfw.identification.problem import clear_function_cache
    from kinfw.progress import LineReporter
    from tests.robots import PLANAR_2R

    if compiled_module.compiler() is None:
        pytest.fail("no C compiler on this machine: the compiled path is not tested")
    nominal = load_robot(PLANAR_2R)
    rng = np.random.default_rng(4)
    names = nominal.topology(("tool",)).joint_names
    qs = random_configurations(*nominal.joint_limits(names), 256, rng, fraction=0.8)
    data = simulate_at(nominal, qs, names, frames=["tool"], rng=rng, noise_m=1e-4, noise_rad=1e-3)
    assert len(data.poses[0].sample) >= compiled_module.COMPILE_SAMPLES
    monkeypatch.setenv("KINFW_CACHE_DIR", str(tmp_path))

    def run() -> tuple[list[str], np.ndarray]:
        clear_function_cache()
        monkeypatch.setattr(compiled_module, "_LOADED", {})
        out = io.StringIO()
        with reporting(LineReporter(out)):
            fit = identify(nominal, data, parameters="full").refined
        return [line.split(" s  ", 1)[1] for line in out.getvalue().splitlines()], fit.estimate

    first, compiled_estimate = run()
    notice = f"compiling a residual function into C for this machine, once (kept in {tmp_path})"
    compiles = [i for i, line in enumerate(first) if line == notice]
    assert compiles and len(compiles) == len(list(tmp_path.glob("kinfw_*.so")))
    assert any(first[i - 1].startswith("Levenberg-Marquardt") for i in compiles[1:]), first
    again, cached_estimate = run()
    assert notice not in again
    monkeypatch.setenv("KINFW_COMPILE", "0")
    _, vm_estimate = run()
    np.testing.assert_array_equal(compiled_estimate, vm_estimate)
    np.testing.assert_array_equal(cached_estimate, vm_estimate)
