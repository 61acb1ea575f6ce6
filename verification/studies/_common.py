"""Plumbing shared by the simulation studies: arrays, JSON, figures, files, command line.

The studies (the papers' experiments of :mod:`kinfw.verification.papers`, the CRLB and
robustness studies of this package) each run random trials, keep
the raw numbers in a frozen result with read-only arrays, and write the result as a PNG
and a JSON side by side; a ``*_main`` (:func:`~kinfw.verification.papers.shih_figures_main`,
:func:`~kinfw.verification.papers.hirsh_figures_main`, :func:`head_studies_main`, behind
``kinfw reproduce``) runs a study (its trials told to :mod:`kinfw.progress`, which the
command shows on stderr) and prints its table. What they share
is here: argument checks and sample statistics, the array and dataclass conversions of
their ``to_dict`` / ``from_dict``, matplotlib figures without pyplot, the output files,
and the command-line scaffolding.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any, Self, TypeVar, get_origin, get_type_hints

import numpy as np
from numpy.typing import NDArray

from kinfw.executors import add_executor_options
from kinfw.files import atomic_path, write_text_atomic
from kinfw.model import builtin_head_urdf, load_robot
from kinfw.verification.evaluation import open_executor

R = TypeVar("R")


# -- checks and statistics -----------------------------------------------------------------


def sample_std(values: NDArray[np.float64], axis: int | tuple[int, ...] = 0) -> NDArray[np.float64]:
    """Sample standard deviation along ``axis`` (``ddof = 1``; 0 for a single value)."""
    n = np.prod([values.shape[a] for a in np.atleast_1d(axis)])
    return np.std(values, axis=axis, ddof=1 if n > 1 else 0)


# -- arrays and JSON -----------------------------------------------------------------------


def readonly(values: Any, dtype: Any = float) -> NDArray:
    """A new array of ``values`` with ``dtype``, not writeable."""
    out = np.array(values, dtype=dtype)
    out.flags.writeable = False
    return out


def freeze(*arrays: NDArray) -> None:
    """Make ``arrays`` read-only in place (the arrays a frozen result holds)."""
    for a in arrays:
        a.flags.writeable = False


def json_list(values: NDArray) -> Any:
    """``values.tolist()`` with NaN and infinities as ``None`` (strict JSON)."""
    if values.dtype.kind == "f":
        return np.where(np.isfinite(values), values, None).tolist()
    return values.tolist()


def json_lists(obj: Any, names: Iterable[str], *, strict: bool = False) -> dict[str, Any]:
    """``{name: obj.<name>.tolist()}`` for the array attributes ``names``, in that order;
    with ``strict``, NaN and infinities become ``None`` (:func:`json_list`)."""
    return {
        name: json_list(getattr(obj, name)) if strict else getattr(obj, name).tolist()
        for name in names
    }


def arrays_from(
    doc: Mapping[str, Any], dtypes: Mapping[str, Any], *, writeable: bool = True
) -> dict[str, NDArray]:
    """``{name: np.array(doc[name], dtype)}`` for each ``name: dtype`` of ``dtypes``: the
    arrays of a result read back from JSON lists (read-only with ``writeable=False``)."""
    out = {name: np.array(doc[name], dtype=dtype) for name, dtype in dtypes.items()}
    if not writeable:
        freeze(*out.values())
    return out


class FieldsJSON:
    """Mixin for a dataclass of scalars and tuples of strings (a study's set-up): its
    ``to_dict`` and ``from_dict``, field by field."""

    __slots__ = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every field, in order, tuples as lists."""
        out = {}
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            out[f.name] = list(value) if isinstance(value, tuple) else value
        return out

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> Self:
        """The instance written by :meth:`to_dict`, each field converted by its annotation
        (``str``, ``int``, ``float`` or a ``tuple``)."""
        hints = get_type_hints(cls)
        values = {}
        for f in fields(cls):  # type: ignore[arg-type]
            hint = hints[f.name]
            if get_origin(hint) is tuple:
                values[f.name] = tuple(doc[f.name])
            elif hint in (str, int, float):
                values[f.name] = hint(doc[f.name])
            else:
                raise TypeError(f"{cls.__name__}.{f.name}: cannot read a {hint} from JSON")
        return cls(**values)


# -- figures -------------------------------------------------------------------------------


def new_figure(size: tuple[float, float]) -> Any:
    """A matplotlib Figure rendered by the Agg canvas, without pyplot's global state."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Any, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` (a PNG at 130 dpi, atomically) and return ``path`` as a
    Path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, format="png")
    return path


def plain_log_ticks(axis: Any) -> None:
    """Major ticks at 1, 2, 5 x 10^k labelled as plain numbers, no minor labels, on a
    log-scaled ``axis`` (``ax.xaxis`` or ``ax.yaxis``)."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_formatter(NullFormatter())


def log_axes(ax: Any, which: str) -> None:
    """Log scale with plain-number ticks at 1, 2, 5 x 10^k: on the y axis, or on both
    axes when ``which == "both"``."""
    if which == "both":
        ax.set_xscale("log")
    ax.set_yscale("log")
    for axis in (ax.xaxis, ax.yaxis) if which == "both" else (ax.yaxis,):
        plain_log_ticks(axis)


def shared_legend(fig: Any, axes: Iterable[Any]) -> None:
    """One legend below the figure for every panel of ``axes``: one entry per label, with
    the handle of the last panel that has it."""
    legend: dict[str, Any] = {}
    for ax in axes:
        legend.update(zip(*reversed(ax.get_legend_handles_labels()), strict=True))
    fig.legend(legend.values(), legend.keys(), fontsize=8.5, loc="outside lower center", ncols=4)


# -- output files --------------------------------------------------------------------------


def output_dir(out_dir: str | Path) -> Path:
    """``out_dir`` as a Path, created with its parents if missing."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_json(path: Path, doc: Any, *, allow_nan: bool = True) -> None:
    """Write ``doc`` to ``path`` as JSON (indent 1, a final newline); ``allow_nan=False``
    refuses NaN and infinities (strict JSON). Written atomically."""
    write_text_atomic(path, json.dumps(doc, indent=1, allow_nan=allow_nan) + "\n")


def write_study(
    result: Any, out_dir: str | Path, name: str, plot: Callable[[Any, Path], Path]
) -> None:
    """Write ``<name>.png`` (``plot(result, path)``) and ``<name>.json``
    (``result.to_dict()``) side by side into ``out_dir``."""
    out = output_dir(out_dir)
    plot(result, out / f"{name}.png")
    write_json(out / f"{name}.json", result.to_dict())


def run_on_head(
    study: Callable[..., R],
    plot: Callable[[R, Path], Path],
    out_dir: str | Path,
    name: str,
    urdf: str | Path | None,
    kwargs: Mapping[str, Any],
) -> R:
    """``study(nominal, **kwargs)`` on the built-in IIS-head (or the URDF ``urdf``), written
    by :func:`write_study` as ``<name>.png`` and ``<name>.json`` into ``out_dir``."""
    nominal = load_robot(builtin_head_urdf() if urdf is None else urdf)
    result = study(nominal, **kwargs)
    write_study(result, out_dir, name, plot)
    return result


# -- command line --------------------------------------------------------------------------


def study_parser(
    prog: str,
    description: str,
    *,
    trials_help: str,
    trials_default: int | None = None,
    studies: Sequence[str] = (),
) -> argparse.ArgumentParser:
    """The arguments every study's ``main`` takes: the study (when ``studies`` names a
    choice), ``--out DIR`` (required), ``--trials N``, ``--seed S`` (default 0) and
    where the trials run, ``--jobs N`` or ``--executor dask://HOST:PORT``
    (:func:`kinfw.executors.add_executor_options`; :func:`run_and_print` opens it)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    if studies:
        parser.add_argument("study", choices=tuple(studies))
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--trials", type=int, default=trials_default, help=trials_help)
    parser.add_argument("--seed", type=int, default=0)
    add_executor_options(parser, tasks="the trials")
    return parser


def run_and_print(
    label: str,
    run: Callable[..., str],
    kwargs: Mapping[str, Any],
    written: Sequence[Path],
    args: argparse.Namespace,
) -> int:
    """Call ``run(**kwargs)`` (a study that writes ``written`` and returns its table) with
    its trials where ``args.jobs`` / ``args.executor`` say (:func:`study_parser`; passed
    as ``executor=`` unless they run in this process, shut down after; the trials are
    told to :mod:`kinfw.progress`); print the table, then one line with
    ``label``, the wall time and the files written. Returns 0, the exit status."""
    start = time.perf_counter()
    with open_executor(args.jobs, args.executor) as executor:
        if executor is not None:
            kwargs["executor"] = executor
        text = run(**kwargs)
    print(text)
    print(
        f"\n{label}: {time.perf_counter() - start:.1f} s; wrote "
        + " and ".join(str(path) for path in written)
    )
    return 0


def choice_main(
    argv: Sequence[str] | None,
    *,
    prog: str,
    description: str,
    trials_help: str,
    studies: Mapping[str, tuple[Callable[..., R], Callable[[R], str]]],
) -> int:
    """``main`` of a module with several studies: ``prog STUDY --out DIR [--trials N]
    [--seed S]`` runs ``run(out, seed=S[, trials=N])`` of ``studies[STUDY] = (run,
    format)``, which writes ``STUDY.png`` and ``STUDY.json``, and prints ``format(result)``
    (:func:`run_and_print`)."""
    args = study_parser(
        prog, description, trials_help=trials_help, studies=tuple(studies)
    ).parse_args(argv)
    kwargs: dict[str, Any] = {"seed": args.seed}
    if args.trials is not None:
        kwargs["trials"] = args.trials
    run, format_table = studies[args.study]
    return run_and_print(
        args.study,
        lambda **kw: format_table(run(args.out, **kw)),
        kwargs,
        (args.out / f"{args.study}.png", args.out / f"{args.study}.json"),
        args,
    )
