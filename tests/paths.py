"""Where the tests find the repository's files: the repository itself and the test data
(``tests/data/``, each set with its source and licence in ``tests/data/README.md``)."""

from pathlib import Path

__all__ = ["DATA", "HEAD_URDF", "REPO"]

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"
HEAD_URDF = REPO / "robots" / "iis_head.urdf"
