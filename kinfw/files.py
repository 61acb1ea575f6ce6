"""Output files: check them before the work, write them atomically.

Every file kinfw writes goes through :func:`write_text_atomic` or :func:`atomic_path`:
the content goes to a temporary file in the destination's directory, which then
replaces the destination (``os.replace``, atomic on POSIX and Windows). A failure midway
leaves the previous file, if any, untouched and no temporary file behind.

Commands call :func:`check_outputs` before any computation, so that a missing directory,
a directory where a file is expected, or an output that is one of the inputs is reported
at once, not after a minute-long solve that has already overwritten some of the files.

This module uses the standard library only at import (the command line imports it at
start-up); :func:`check_figure_path` imports matplotlib when it is called.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path

__all__ = [
    "OutputPathError",
    "atomic_path",
    "check_figure_path",
    "check_output_dir",
    "check_outputs",
    "check_writable",
    "json_text",
    "sidecar_path",
    "write_text_atomic",
]

PathLike = str | os.PathLike[str]


class OutputPathError(ValueError):
    """An output path that cannot or must not be written (the message names it)."""


def _label(path: PathLike, label: str | None) -> str:
    """``--out c.urdf``; a label ending in ``=`` is joined without a space
    (``--camera left=left.yaml``)."""
    if not label:
        return os.fspath(path)
    return f"{label}{os.fspath(path)}" if label.endswith("=") else f"{label} {os.fspath(path)}"


def _same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` name one file: equal resolved paths (symlinks followed),
    or, when both exist, the same inode (hard links, case-insensitive file systems)."""
    if a.resolve() == b.resolve():
        return True
    try:
        return a.exists() and b.exists() and a.samefile(b)
    except OSError:
        return False


def check_writable(
    path: PathLike, *, label: str | None = None, inputs: Mapping[str, PathLike | None] | None = None
) -> Path:
    """Check that ``path`` can be written as a file and is none of ``inputs``.

    Nothing is created or changed.

    Parameters
    ----------
    path : str or PathLike
        The output file.
    label : str, optional
        How the user gave it (``"--out"``), for the message.
    inputs : mapping of str to path, optional
        Files the command reads, keyed by how the user gave them (``{"--urdf": ...}``);
        None values are skipped. Paths are compared after resolving symlinks.

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputPathError
        Naming the output (and the input it would overwrite): its directory is missing
        or not a directory or not writable, it is a directory, it exists but is not
        writable, or it is one of the inputs.
    """
    path = Path(path)
    name = _label(path, label)
    for key, source in (inputs or {}).items():
        if (
            source is not None
            and not str(source).lstrip().startswith("<")
            and _same_file(path, Path(source))
        ):
            raise OutputPathError(
                f"{name} is the same file as {_label(source, key)}: "
                "refusing to overwrite an input; choose another output"
            )
    parent = path.parent
    if not parent.exists():
        raise OutputPathError(f"{name}: directory {os.fspath(parent)!r} does not exist")
    if not parent.is_dir():
        raise OutputPathError(f"{name}: {os.fspath(parent)!r} is not a directory")
    if path.is_dir():
        raise OutputPathError(f"{name}: is a directory, expected a file name")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"{name}: directory {os.fspath(parent)!r} is not writable")
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputPathError(f"{name}: the existing file is not writable")
    return path


def check_output_dir(
    path: PathLike, *, label: str | None = None, files: tuple[str, ...] = ()
) -> Path:
    """Check that ``path`` is, or can be created as, a writable directory, and that the
    ``files`` in it can be written (see :func:`check_writable`). Nothing is created.

    Raises
    ------
    OutputPathError
        Naming the directory: a file stands where it or one of its parents should be,
        or the nearest existing parent is not writable.
    """
    path = Path(path)
    name = _label(path, label)
    if path.exists():
        if not path.is_dir():
            raise OutputPathError(f"{name}: exists and is not a directory")
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputPathError(f"{name}: directory is not writable")
        for file in files:
            check_writable(path / file, label=label and f"{label} .../{file}")
        return path
    ancestor = path.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputPathError(f"{name}: cannot create it, {os.fspath(ancestor)!r} is a file")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise OutputPathError(f"{name}: cannot create it, {os.fspath(ancestor)!r} is not writable")
    return path


def check_figure_path(path: PathLike, *, label: str | None = None) -> Path:
    """Check that matplotlib can write a figure in the format of ``path``'s suffix
    (``savefig`` infers it from there); nothing is written.

    Raises
    ------
    OutputPathError
        Naming the path and the formats matplotlib can write, when the suffix is missing
        or not one of them.
    """
    from matplotlib.backend_bases import FigureCanvasBase

    path = Path(path)
    formats = sorted(FigureCanvasBase.get_supported_filetypes())
    suffix = path.suffix.lstrip(".").lower()
    if suffix not in formats:
        what = (
            f"matplotlib cannot write a .{suffix} figure" if suffix else "no suffix names a format"
        )
        raise OutputPathError(
            f"{_label(path, label)}: {what}; give a suffix matplotlib can write: "
            + ", ".join(f".{f}" for f in formats)
        )
    return path


def check_outputs(
    outputs: Mapping[str, PathLike | None],
    *,
    inputs: Mapping[str, PathLike | None] | None = None,
    figures: tuple[str, ...] = (),
) -> None:
    """:func:`check_writable` for each output, and check that no two outputs are one file.

    ``outputs`` and ``inputs`` map how the user gave a path (``"--out"``) to the path;
    None values are skipped. The outputs keyed by ``figures`` are matplotlib figures:
    their suffix must name a format it can write (:func:`check_figure_path`).
    """
    given = {k: Path(v) for k, v in outputs.items() if v is not None}
    for key, path in given.items():
        check_writable(path, label=key, inputs=inputs)
        if key in figures:
            check_figure_path(path, label=key)
    keys = list(given)
    for i, a in enumerate(keys):
        for b in keys[i + 1 :]:
            if _same_file(given[a], given[b]):
                raise OutputPathError(
                    f"{_label(given[b], b)} is the same file as "
                    f"{_label(given[a], a)}: give two different outputs"
                )


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``.

    For writers that take a file name (``Figure.savefig``): write to the yielded path.
    The temporary name keeps ``path``'s suffix (so a writer that infers the format from
    it still does) and starts with a dot. When the body raises, the temporary file is
    removed and ``path`` is left as it was. The file gets the permissions of a newly
    created file (``0o666`` less the umask). When the temporary file cannot be created
    (a missing directory, no permission) the error names ``path``.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.urandom(4).hex()}.tmp{path.suffix}")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:  # the user's path in the message, not the temporary one
        raise type(exc)(exc.errno, exc.strerror, str(path)) from None
    os.close(fd)
    try:
        yield tmp
        tmp.replace(path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_text_atomic(
    path: PathLike, text: str, *, encoding: str = "utf-8", newline: str | None = None
) -> Path:
    """Write ``text`` to ``path`` atomically (see the module docstring).

    ``newline`` is as for :func:`open` (``""``: no translation). Returns ``path``.
    """
    path = Path(path)
    with atomic_path(path) as tmp, tmp.open("w", encoding=encoding, newline=newline) as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    return path


def _finite_or_null(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_null(v) for v in value]
    return value


def json_text(value, *, indent: int | None = 2) -> str:
    """``value`` as strict JSON (RFC 8259): a NaN or infinite float (an undefined
    number: a point's rotation, an image point's position) is written ``null``, never
    the ``NaN`` token most JSON parsers refuse."""
    return json.dumps(_finite_or_null(value), indent=indent, allow_nan=False)


def sidecar_path(urdf_path: str | Path) -> Path:
    """Where the calibration sidecar of the calibrated URDF ``urdf_path`` goes:
    ``<stem>.kinfw.json`` beside it."""
    return Path(urdf_path).with_suffix(".kinfw.json")
