"""The ``--jobs N`` / ``--executor dask://HOST:PORT`` options and the address they name."""

import argparse
import importlib.util
import re

import pytest

from kinfw.executors import add_executor_options, dask_scheduler_address


@pytest.mark.parametrize(
    ("spec", "address"),
    [
        ("dask://127.0.0.1:8786", "tcp://127.0.0.1:8786"),
        ("dask://scheduler.lab:1", "tcp://scheduler.lab:1"),
        ("dask://[::1]:8786/", "tcp://[::1]:8786"),
    ],
)
def test_a_dask_url_names_the_schedulers_tcp_address(spec, address):
    assert dask_scheduler_address(spec) == address


@pytest.mark.parametrize(
    "spec",
    [
        "tcp://127.0.0.1:8786",  # Dask's own form: the option says dask://
        "dask://127.0.0.1",  # no port
        "dask://:8786",  # no host
        "dask://host:0",
        "dask://host:70000",
        "dask://host:port",
        "dask://user@host:8786",
        "dask://host:8786/path",
        "dask://host:8786?x=1",
        "127.0.0.1:8786",
        "",
    ],
)
def test_anything_else_is_refused_with_the_form_expected(spec):
    with pytest.raises(
        ValueError, match=r"expected dask://HOST:PORT .*got " + re.escape(repr(spec))
    ):
        dask_scheduler_address(spec)


def _parser() -> argparse.ArgumentParser:
    class Parser(argparse.ArgumentParser):
        def error(self, message):
            raise ValueError(message)

    p = Parser(prog="t")
    add_executor_options(p, tasks="the fits")
    return p


def test_the_default_runs_in_this_process():
    args = _parser().parse_args([])
    assert (args.jobs, args.executor) == (1, None)
    args = _parser().parse_args(["--jobs", "3"])
    assert (args.jobs, args.executor) == (3, None)
    args = _parser().parse_args(["--executor", "dask://h:8786"])
    assert (args.jobs, args.executor) == (1, "dask://h:8786")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--jobs", "0"], "argument --jobs: expected an integer >= 1, got '0'"),
        (["--jobs", "two"], "argument --jobs: expected an integer >= 1, got 'two'"),
        (["--executor", "tcp://h:1"], "argument --executor: expected dask://HOST:PORT"),
        (
            ["--jobs", "2", "--executor", "dask://h:1"],
            "argument --executor: not allowed with argument --jobs",
        ),
    ],
)
def test_bad_options_are_argument_errors(argv, message):
    with pytest.raises(ValueError, match=message):
        _parser().parse_args(argv)


def test_an_executor_without_dask_installed_says_how_to_install_it(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else real(name)
    )
    with pytest.raises(ValueError, match=r"not installed: pip install 'kinfw\[dask\]'"):
        _parser().parse_args(["--executor", "dask://h:8786"])
