"""Setup shared by the tests: Hypothesis runs reproducibly, and the built-in head.

Hypothesis is derandomized (the same examples every run, on every machine), so a run of
the suite is reproducible and CI cannot turn red on a draw no one can replay; a property
that fails is found by running with ``--hypothesis-seed`` or a new test, not by chance.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import settings

from kinfw.model import Robot, load_robot
from tests.paths import HEAD_URDF

settings.register_profile("kinfw", derandomize=True, deadline=None)
settings.load_profile("kinfw")


@pytest.fixture(scope="session")
def head_urdf() -> Path:
    """Path of the built-in IIS-head URDF."""
    return HEAD_URDF


@pytest.fixture(scope="session")
def head() -> Robot:
    """The built-in IIS-head (a Robot is immutable, so one instance serves every test)."""
    return load_robot(HEAD_URDF)
