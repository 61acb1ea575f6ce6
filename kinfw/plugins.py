"""Plugins: observation kinds, robot blocks, commands and hand-eye starts from another
installed package, through one entry-point group, ``kinfw.plugins``.

A package declares its plugin in its ``pyproject.toml``::

    [project.entry-points."kinfw.plugins"]
    ball = "my_package.kinfw_ball"                # a module: importing it registers
    scale = "my_package.kinfw_scale:register"     # a callable: called once, no arguments

and the module (or the function) registers its pieces itself, with kinfw's public
register functions: :func:`kinfw.observations.register_kind`,
:func:`kinfw.model.register_block` (a robot block of ``--model``),
:func:`kinfw.cli.register_command`, :func:`kinfw.identification.handeye.register_start`.
kinfw only
imports the modules the entry points name, once per process, when a registry is first
consulted:
:func:`load_plugins` is called by the ``kinfw`` command before it builds its parser (so
a plugin's command is listed by ``kinfw --help`` and runs), by the look-ups of the kinds
(:func:`kinfw.observations.kinds`, ``kind_named``, ``kind_of``), of the robot blocks
(:func:`kinfw.model.block_from_spec`, :func:`kinfw.model.block_names`) and by the hand-eye
closed forms (:func:`kinfw.identification.handeye.candidate_starts`, the ``--method``
of ``kinfw handeye``). A registry of kinfw that lists or looks up what plugins may add
calls :func:`load_plugins` first; nothing else is needed for its plugins to reach it.

A plugin that fails (its import or its function raises) is reported by one
:class:`PluginWarning` naming the distribution, the entry point and the exception's first
line, and skipped: the rest of kinfw, the other plugins and ``kinfw --help`` still work.
``import kinfw`` loads no plugin; this module imports only the standard library.
"""

from __future__ import annotations

import threading
import warnings
from dataclasses import dataclass

__all__ = ["GROUP", "LoadedPlugin", "PluginWarning", "load_plugins"]

#: The entry-point group kinfw reads its plugins from.
GROUP = "kinfw.plugins"


class PluginWarning(UserWarning):
    """A plugin of :data:`GROUP` failed to load and was skipped."""


@dataclass(frozen=True, slots=True)
class LoadedPlugin:
    """One entry point of :data:`GROUP`, as :func:`load_plugins` found it.

    Attributes
    ----------
    distribution : str
        The installed distribution that declares it (``"?"`` when unknown).
    name : str
        The entry point's name.
    value : str
        What it points at: ``"module"`` or ``"module:function"``.
    error : str or None
        The first line of the exception it raised (``"ImportError: ..."``), or None when
        it loaded.
    """

    distribution: str
    name: str
    value: str
    error: str | None = None


_LOCK = threading.RLock()
#: What the first call found, once it has finished; the records so far while it runs.
_LOADED: tuple[LoadedPlugin, ...] | None = None
_LOADING: list[LoadedPlugin] | None = None


def load_plugins() -> tuple[LoadedPlugin, ...]:
    """Import every entry point of :data:`GROUP` once per process; return what was found.

    The first call reads the entry points (:func:`importlib.metadata.entry_points`) and
    loads each in turn: a module is imported (its import registers its pieces); a
    ``module:function`` is imported and the function called with no arguments. Later
    calls return the same records at once. Other threads wait for the first call to
    finish; a call made by a plugin while it loads (a registry consulted as it registers)
    returns the records so far instead of loading again.

    Returns
    -------
    tuple of LoadedPlugin
        Every entry point of the group, in the order loaded, with its error, if any.

    Warns
    -----
    PluginWarning
        Once per failed plugin: ``plugin 'NAME' of DIST (VALUE) failed to load and was
        skipped: ERROR``.
    """
    global _LOADED, _LOADING
    if _LOADED is not None:  # the look-ups call this often: no lock once loaded
        return _LOADED
    with _LOCK:
        if _LOADED is not None:  # loaded by another thread while this one waited
            return _LOADED
        if _LOADING is not None:  # this thread, inside a plugin that is loading
            return tuple(_LOADING)
        _LOADING = []
        try:
            from importlib.metadata import entry_points

            for entry in entry_points(group=GROUP):
                _LOADING.append(_load(entry))
        finally:  # interrupted: what loaded stays loaded, nothing is imported twice
            _LOADED, _LOADING = tuple(_LOADING), None
        return _LOADED


def _load(entry) -> LoadedPlugin:
    """Load one entry point, warning (and returning its error) when it raises."""
    dist = getattr(entry.dist, "name", None) or "?"
    try:
        loaded = entry.load()
        if callable(loaded):
            loaded()
    except Exception as exc:
        lines = str(exc).strip().splitlines()
        error = type(exc).__name__ + (f": {lines[0]}" if lines else "")
        warnings.warn(
            f"plugin {entry.name!r} of {dist} ({entry.value}) failed to load and was "
            f"skipped: {error}",
            PluginWarning,
            stacklevel=4,
        )
        return LoadedPlugin(dist, entry.name, entry.value, error)
    return LoadedPlugin(dist, entry.name, entry.value)
