# SPDX-License-Identifier: LGPL-2.1-or-later
"""The fuzz corpus (``fuzz_cases``) through the command line.

Every case must end in success (exit 0) or in exactly one ``error:`` line with exit 2
naming what is wrong; never a traceback, a warning on stderr, a hang (``CASE_SECONDS``
per case) or exit 1. Whatever the ending, the input files keep their bytes; after a
failure the output folder holds exactly what it held before (no partial or temporary
file, an existing output unchanged); after a success no temporary file is left.
"""
import contextlib
import hashlib
import io
import os
import signal
import subprocess
import sys
import warnings

import pytest

import fuzz_cases
from fuzz_cases import DIR

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASE_SECONDS = 60
"""Upper bound on one case: far above the slowest case (a full run on a 12-triangle box
takes a few seconds), so only a hang trips it."""
SENTINEL = b"an output file that existed before the run\n"
CASES = fuzz_cases.all_cases()


class CaseTimeout(BaseException):
    """Raised by the alarm in an in-process case (not an Exception: the CLI must not catch it)."""


def _on_alarm(signum, frame):
    raise CaseTimeout(f"no result after {CASE_SECONDS} s")


def run_in_process(argv):
    """``(exit code, stdout, stderr)`` of ``polycube_wb.cli.main(argv)``; a Python warning
    counts as a stderr line (a user running the command would see it)."""
    from polycube_wb.cli import main

    out, err = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.alarm(CASE_SECONDS)
    try:
        with warnings.catch_warnings(record=True) as caught, \
                contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            warnings.simplefilter("always")
            try:
                code = main(list(argv))
            except SystemExit as exc:
                code = exc.code
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    lines = [f"warning: {w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught]
    return code, out.getvalue(), err.getvalue() + "".join(line + "\n" for line in lines)


def run_subprocess(argv):
    done = subprocess.run([sys.executable, "-m", "polycube_wb", *argv], cwd=REPO,
                          capture_output=True, text=True, timeout=CASE_SECONDS)
    return done.returncode, done.stdout, done.stderr


def snapshot(folder):
    """``{relative path: sha256 or 'folder'}`` of everything under ``folder``."""
    found = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs:
            found[os.path.relpath(os.path.join(root, name), folder)] = "folder"
        for name in files:
            path = os.path.join(root, name)
            with open(path, "rb") as handle:
                found[os.path.relpath(path, folder)] = hashlib.sha256(handle.read()).hexdigest()
    return found


def prepare(case, tmp_path):
    """Create the case's inputs and existing outputs; returns ``(argv, in_dir, out_dir)``."""
    folders = {key: tmp_path / key for key in ("in", "out")}
    for folder in folders.values():
        folder.mkdir()
    for name, data in case.files.items():
        path = folders["in"] / name
        if data is DIR:
            path.mkdir()
        else:
            path.write_bytes(data)
    argv = []
    for arg in case.argv:
        if arg.startswith("{old}/"):
            path = folders["out"] / arg[len("{old}/"):]
            path.write_bytes(SENTINEL)
            arg = str(path)
        argv.append(arg.replace("{in}", str(folders["in"])).replace("{out}", str(folders["out"])))
    return argv, folders["in"], folders["out"]


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_fuzz_case(case, tmp_path):
    argv, in_dir, out_dir = prepare(case, tmp_path)
    inputs, outputs = snapshot(in_dir), snapshot(out_dir)
    code, stdout, stderr = (run_subprocess if case.subprocess else run_in_process)(argv)
    assert "Traceback" not in stderr + stdout, stderr
    assert code in case.codes, f"exit {code}, expected {case.codes}:\n{stderr}"
    assert snapshot(in_dir) == inputs, "an input file changed"
    if code == 0:
        assert stderr == "", stderr
        leftovers = [name for name in snapshot(out_dir) if name.endswith(".tmp")]
        assert leftovers == [], leftovers
        return
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    for word in case.words:
        assert word in lines[0], f"{word!r} not in {lines[0]!r}"
    assert snapshot(out_dir) == outputs, "a failed run changed the output folder"


def test_the_corpus_is_large_and_mostly_fast():
    """At least 200 cases; most fail at intake or parameter validation, a handful run the
    pipeline past intake, a few run as real processes."""
    assert len(CASES) >= 200
    past_intake = [case for case in CASES if case.name.startswith("run-")]
    assert 1 <= len(past_intake) <= 6
    assert 3 <= sum(case.subprocess for case in CASES) <= 10
