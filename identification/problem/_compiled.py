"""Compiled residual functions: CasADi's generated C, built once per machine when that pays.

CasADi evaluates an SX function in its virtual machine at a few nanoseconds per
instruction; the residual and Jacobian of a 6-joint arm's point are ~1,300 and ~6,000
instructions per sample, so 10,000 samples cost ~40 and ~150 ms per evaluation. The same
function generated as C (:class:`casadi.CodeGenerator`) and compiled by the system's C
compiler runs 5-8 times faster with the same operations in the same order: the results
are the same to the last bit (``-ffp-contract=off``: no fused multiply-add; the same
``libm``), so whether a function was compiled never changes an estimate.

Compiling costs about as much as evaluating the function 25,000-40,000 times for one
sample in the virtual machine (TIAGo's residual and Jacobian, 8,900 instructions: 2-5 s),
whatever its size. A calibration evaluates its main functions 100-200 times (noise rounds
of Levenberg-Marquardt iterations), about 1,000 times with a model choice (TIAGo's 21
samples: 20,349 and 22,239 sample evaluations of its two main functions, a few dozen of
the others), and the model choice runs on small data only: compiling pays for a group of
:data:`COMPILE_SAMPLES` samples or more. :func:`compiled` returns the
compiled twin of a function when it is already in the cache (loaded in milliseconds) or
its group is that large, and otherwise the function itself: TIAGo's 21 Vicon samples
calibrate in 3.8 s in the virtual machine, against 18.6 s when its 13 functions are
first compiled (2.6 s once they are). It says so before it compiles (a
:func:`kinfw.progress.notice`, shown even inside a loop). It returns the function itself
too when there is no C compiler
(``$CC``, else ``cc``, ``gcc`` or ``clang`` on the ``PATH``), compiling fails (logged
once), or ``KINFW_COMPILE=0`` is set; ``KINFW_COMPILE=1`` compiles whatever the size.
Shared libraries are kept in ``$KINFW_CACHE_DIR`` (default ``$XDG_CACHE_HOME/kinfw/casadi``
or ``~/.cache/kinfw/casadi``) under a hash of their C source, compiler command and the
processor they were built for (:data:`NATIVE_FLAGS`), so a function is compiled once per
machine and then loaded in milliseconds; concurrent processes each write to a temporary
name and rename it into place.

Compiled functions have no derivatives: they serve the numeric evaluations of
:meth:`kinfw.identification.problem.ResidualGroup.evaluate` only.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Any

from kinfw import progress

log = logging.getLogger("kinfw.identification.problem")

#: Compiler flags: optimised (-O1 compiles the large Jacobians 3-4 times faster than
#: -O2 for the same speed) and without contracting a * b + c into a fused multiply-add,
#: which would round differently from CasADi's virtual machine.
FLAGS = ("-O1", "-ffp-contract=off", "-fPIC", "-shared")

#: Tried first: the instructions of this processor (vector units), ~30 % faster
#: evaluations with the same results (no fused multiply-add, no fast math: the same
#: operations in the same order); a library built so is kept under a name that includes
#: the processor's identity (:func:`_processor`), and a compiler that refuses the flag
#: gets :data:`FLAGS` alone.
NATIVE_FLAGS = ("-march=native",)

#: A function not yet in the cache is compiled for a group of this many samples or more
#: (see the module notes): compiling costs 25,000-40,000 one-sample evaluations in the
#: virtual machine, a calibration of plentiful data evaluates it 100-200 times.
COMPILE_SAMPLES = 200

_LOCK = threading.Lock()
_LOADED: dict[str, Any] = {}
_FAILED: list[str] = []  # the first failure's message: compiling is not retried
_NATIVE_REFUSED: list[str] = []  # not empty once compiling with NATIVE_FLAGS failed


def compiler() -> str | None:
    """The C compiler to use (``$CC``, else ``cc``, ``gcc`` or ``clang``), or None when
    there is none or ``KINFW_COMPILE=0``."""
    if os.environ.get("KINFW_COMPILE", "").strip() == "0":
        return None
    names = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in names:
        path = shutil.which(name)
        if path is not None:
            return path
    return None


def cache_dir() -> Path:
    """Where compiled functions are kept: ``$KINFW_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/kinfw/casadi``, else ``~/.cache/kinfw/casadi``."""
    if os.environ.get("KINFW_CACHE_DIR"):
        return Path(os.environ["KINFW_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "kinfw" / "casadi"


def compiled(f: Any, samples: int) -> Any:
    """The compiled twin of the CasADi function ``f`` (same inputs, outputs and results,
    bit for bit), or ``f`` itself when it cannot be compiled or compiling it would not
    pay (see the module notes).

    Parameters
    ----------
    f : casadi.Function
        An SX function.
    samples : int
        The samples of the group it is evaluated over: a function not in the cache is
        compiled only for :data:`COMPILE_SAMPLES` or more (any with ``KINFW_COMPILE=1``).
    """
    import casadi as ca

    cc = compiler()
    if cc is None or _FAILED:
        return f
    build = samples >= COMPILE_SAMPLES or os.environ.get("KINFW_COMPILE", "").strip() == "1"
    generator = ca.CodeGenerator("kinfw_fn.c", {"with_header": False})
    generator.add(_renamed(f, "kinfw_fn"))
    source = generator.dump()
    with _LOCK:
        try:
            loaded = None
            if not _NATIVE_REFUSED:
                try:
                    loaded = _load(source, (cc, *FLAGS, *NATIVE_FLAGS), _processor(), build)
                except subprocess.CalledProcessError:  # e.g. a compiler without the flag
                    _NATIVE_REFUSED.append(cc)
            if loaded is None and _NATIVE_REFUSED:
                loaded = _load(source, (cc, *FLAGS), "", build)
        except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
            detail = getattr(exc, "stderr", None) or str(exc) or type(exc).__name__
            _FAILED.append(detail)
            log.warning(
                "compiling the residual functions failed (%s); evaluating them in "
                "CasADi's virtual machine (slower, same results)",
                detail.strip().splitlines()[-1] if detail.strip() else type(exc).__name__,
            )
            return f
        return f if loaded is None else loaded


def _load(source: str, command: tuple[str, ...], processor: str, build: bool) -> Any:
    """The compiled ``source`` (function ``kinfw_fn``), loaded once per process and
    compiled once per cache (see :func:`_build`; not compiled unless ``build``: None
    then when it is not in the cache), named by a hash of the source, the command,
    CasADi's version and the ``processor`` it was built for."""
    import casadi as ca

    key = "\0".join([*command, ca.__version__, processor, source])
    name = f"kinfw_{hashlib.sha256(key.encode()).hexdigest()[:24]}"
    if name not in _LOADED:
        library = cache_dir() / f"{name}.so"
        if not library.exists():
            if not build:
                return None
            _build(library, source.replace("kinfw_fn", name), command)
        _LOADED[name] = ca.external(name, str(library))
    return _LOADED[name]


@functools.cache
def _processor() -> str:
    """This processor's model and instruction-set flags (``/proc/cpuinfo``; else what
    :mod:`platform` says): a library built with ``-march=native`` runs only where they
    are the same."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    keys = ("model name", "flags", "Features", "CPU implementer", "CPU part")
    found = {}
    for line in lines:
        key, _, value = line.partition(":")
        if key.strip() in keys:
            found.setdefault(key.strip(), value.strip())
    return repr(sorted(found.items())) if found else f"{platform.machine()} {platform.processor()}"


def _renamed(f: Any, name: str) -> Any:
    """The SX function ``f`` under another name (the C symbol the generated code
    defines)."""
    import casadi as ca

    args = f.sx_in()
    return ca.Function(name, args, f.call(args))


def _build(library: Path, source: str, command: tuple[str, ...]) -> None:
    """Compile ``source`` into ``library`` (in the cache), saying so first."""
    directory = library.parent
    progress.notice(
        f"compiling a residual function into C for this machine, once (kept in {directory})"
    )
    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=directory, prefix=".build-") as tmp:
        c_file = Path(tmp) / f"{library.stem}.c"
        c_file.write_text(source)
        built = Path(tmp) / library.name
        subprocess.run(
            [*command, str(c_file), "-o", str(built), "-lm"],
            check=True,
            capture_output=True,
            text=True,
        )
        built.replace(library)  # atomic: a concurrent process sees all of it or nothing
    log.info("compiled residual function %s in %s", library.stem, directory)
