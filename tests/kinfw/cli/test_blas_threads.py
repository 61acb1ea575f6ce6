"""The command line runs with one BLAS thread unless the environment sets the count."""

import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

from kinfw.cli._main import BLAS_THREAD_VARIABLES, _one_blas_thread


def _blas_threads() -> set[int]:
    return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}


def test_commands_run_with_one_blas_thread_and_restore_the_count(monkeypatch):
    for name in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert np.ones(2) @ np.ones(2) == 2.0  # BLAS loaded
    with threadpool_limits(limits=2, user_api="blas"):
        with _one_blas_thread():
            assert _blas_threads() == {1}
        assert _blas_threads() == {2}


def test_a_thread_count_set_in_the_environment_holds(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    with threadpool_limits(limits=2, user_api="blas"), _one_blas_thread():
        assert _blas_threads() == {2}
