"""Where the URDFs of ``example-robot-data`` are (real robots for the tests; plain helpers).

The PyPI wheel ``example-robot-data`` (6.x, the ``test`` extra) installs no importable
Python module: only a ROS-style share directory, ``cmeel.prefix/share/example-robot-data/
robots/<robot>_description/...`` under site-packages. Older wheels, robotpkg and conda put
the same tree at ``<prefix>/share/example-robot-data/robots``, three levels above a
``sys.path`` entry (the rule of the package's own ``getModelPath``). The URDFs refer to
their meshes as ``package://...``, which the tests never resolve.
"""

from __future__ import annotations

import sys
from importlib import metadata
from pathlib import Path

__all__ = ["robots_dir", "urdf_path"]

_SHARE = Path("share", "example-robot-data", "robots")


def robots_dir() -> Path | None:
    """The ``robots`` directory of an installed example-robot-data, or None."""
    candidates = []
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        pass
    else:
        candidates.append(Path(str(dist.locate_file(Path("cmeel.prefix") / _SHARE))))
    candidates += [
        Path(p).resolve().parents[2] / _SHARE
        for p in sys.path
        if p and len(Path(p).resolve().parents) > 2
    ]
    return next((c for c in candidates if c.is_dir()), None)


def urdf_path(relative: str) -> Path:
    """Path of ``relative`` (e.g. ``"ur_description/urdf/ur10_robot.urdf"``) in the
    installed robots directory; raises FileNotFoundError naming the fix when absent."""
    root = robots_dir()
    if root is None:
        raise FileNotFoundError(
            "example-robot-data is not installed: "
            "pip install example-robot-data (it is in the test extra)"
        )
    path = root / relative
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not in this example-robot-data installation")
    return path
