"""Work fanned out to a Dask scheduler (``--executor dask://HOST:PORT``,
:func:`kinfw.verification.evaluation.open_executor`) against a local cluster of two
worker processes: cross-validation, a study and a fleet give what they give in this
process, to the bit; and the errors of a scheduler that is not there."""

import json
import socket
import sys

import numpy as np
import pytest

from kinfw import progress
from kinfw.model import load_robot
from kinfw.simulation import perturb_robot
from kinfw.verification.evaluation import crossvalidate, open_executor
from tests.cli_run import run_cli
from tests.fleet_data import without_run_details, write_fleet
from tests.head_data import plate_data
from tests.recorder import Recorder


@pytest.fixture(scope="module")
def cluster():
    """``dask://HOST:PORT`` of a local cluster: two worker processes of one thread (the
    tasks travel pickled, as to another machine)."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as local:
        yield local.scheduler_address.replace("tcp://", "dask://")


def _fold_numbers(cv):
    return np.array(
        [
            [s.of("position"), s.of("rotation"), s.worst, s.condition, s.n_parameters, s.n_train]
            for s in cv.scores
        ]
    )


@pytest.mark.slow
def test_crossvalidation_on_the_cluster_gives_the_serial_scores(cluster, head):
    truth = load_robot(perturb_robot(head, np.random.default_rng(11), origin_mm=5.0))
    data = plate_data(truth, 24, 12)
    kwargs = {"k": 3, "seed": 5, "sets": ("none", "frames", "full")}
    serial = crossvalidate(head, data, **kwargs)
    recorder = Recorder()
    with open_executor(address=cluster) as executor, progress.reporting(recorder):
        cv = crossvalidate(head, data, executor=executor, **kwargs)
    assert [(s.fold, s.parameters) for s in cv.scores] == [
        (f, p) for f in range(3) for p in ("none", "frames", "full")
    ]
    np.testing.assert_array_equal(_fold_numbers(cv), _fold_numbers(serial))
    (fits,) = recorder.tasks  # the fits are told as they come back from the workers
    assert fits.total == 9 and [d for d, _ in fits.steps] == list(range(1, 10))


@pytest.mark.slow
def test_a_fleet_on_the_cluster_writes_the_serial_files(cluster, tmp_path, capsys):
    write_fleet(tmp_path / "robots", 3, per_joint=4, seed=20)
    # an understated noise: each robot warns, and its warnings come back from the workers
    argv = ["fleet", str(tmp_path / "robots" / "*" / "data.json"), "--params", "full"]
    argv += ["--sigma-mm", "0.1", "--sigma-deg", "0.1"]
    code, serial, _ = run_cli([*argv, "--out", tmp_path / "serial"], capsys)
    assert code == 0, serial
    code, remote, _ = run_cli([*argv, "--out", tmp_path / "remote", "--executor", cluster], capsys)
    assert code == 0, remote
    assert remote.replace("remote", "serial") == serial
    written = sorted(p.relative_to(tmp_path / "serial") for p in (tmp_path / "serial").rglob("*"))
    assert written == sorted(
        p.relative_to(tmp_path / "remote") for p in (tmp_path / "remote").rglob("*")
    )
    assert len([p for p in written if p.suffix == ".urdf"]) == 3
    summary = json.loads((tmp_path / "serial" / "summary.json").read_text())
    assert all(row["warnings"] for row in summary["robots"])
    for path in written:
        a, b = ((tmp_path / run / path) for run in ("serial", "remote"))
        if path.suffix == ".urdf" or path.name == "summary.json":
            assert a.read_bytes() == b.read_bytes(), path
        elif a.is_file():  # the report and sidecar: all but when, where and how long
            da, db = (without_run_details(json.loads(p.read_text())) for p in (a, b))
            assert da == db, path


@pytest.mark.slow
def test_a_study_on_the_cluster_writes_the_serial_json(cluster, tmp_path, capsys):
    argv = ["reproduce", "table4", "--trials", "3", "--seed", "2"]
    assert run_cli([*argv, "--out", tmp_path / "serial"], capsys)[0] == 0
    assert run_cli([*argv, "--out", tmp_path / "remote", "--executor", cluster], capsys)[0] == 0
    serial, remote = ((tmp_path / d / "table4.json").read_bytes() for d in ("serial", "remote"))
    assert serial == remote


@pytest.mark.slow
def test_no_scheduler_at_the_address_is_an_error_that_names_it():
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with (
        pytest.raises(OSError, match=rf"no Dask scheduler answered at tcp://127.0.0.1:{port}"),
        open_executor(address=f"dask://127.0.0.1:{port}", connect_timeout_s=0.5),
    ):
        pass


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"jobs": 2, "address": "dask://h:1"},
            "give jobs .* or a Dask scheduler address, not both",
        ),
        ({"address": "tcp://h:1"}, "expected dask://HOST:PORT"),
        ({"jobs": 0}, "jobs: expected an integer >= 1, got 0"),
    ],
)
def test_bad_specs_are_refused_before_connecting(kwargs, message):
    with pytest.raises(ValueError, match=message), open_executor(**kwargs):
        pass


def test_an_address_without_dask_installed_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed: ImportError
    with (
        pytest.raises(
            ImportError, match=r"needs Dask's distributed .* pip install 'kinfw\[dask\]'"
        ),
        open_executor(address="dask://h:1"),
    ):
        pass
