"""Run the ``kinfw`` command line in the test's process and capture what it prints."""

import re

from kinfw.cli._main import main


def run_cli(argv, capsys) -> tuple[int, str, str]:
    """``(exit code, stdout, stderr)`` of ``kinfw ARGV`` (each argument through ``str``)."""
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def without_dirs(line: str) -> str:
    """``line`` without the directories of its paths (pytest's temporary folders are
    long): a message's first line is judged as a user with short paths reads it."""
    return re.sub(r"/\S*/", "", line)
