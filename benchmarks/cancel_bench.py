# SPDX-License-Identifier: LGPL-2.1-or-later
"""How fast Ctrl-C stops ``reconstruct`` in each stage; writes ``benchmarks/CANCEL_RESULTS.md``.

Usage::

    .venv/bin/python benchmarks/cancel_bench.py [MESH] [--delay S] [--out FILE]

For every stage announced by ``reconstruct --progress`` (intake ... writing) one run of the
command line on MESH (default: the bundled SIMP cantilever, 15,388 triangles) with every
output requested over older files; SIGINT is sent ``--delay`` seconds after the stage's line
appears. Each row: the stage the process names in its ``cancelled at stage`` line, the exit
code, the seconds from SIGINT to the process's end (wall clock, this machine, under whatever
load it has), and whether the output folder kept its bytes (no new file, no temporary file,
the older STEP file and report unchanged). Calls into compiled code (HiGHS, libigl,
OpenCascade) finish before Python sees the signal, and a Ctrl-C during an import waits for
the next progress report: those are what the latency measures.
"""
import argparse
import hashlib
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)

from polycube_wb.stage_lines import ANNOUNCED, STAGE_PREFIX  # noqa: E402

DEFAULT_MESH = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
GUARD_SECONDS = 600
OLDER = {"result.step": b"ISO-10303-21; an older result\n", "report.json": b'{"older": 1}\n'}


def digest(folder):
    found = {}
    for name in sorted(os.listdir(folder)):
        with open(os.path.join(folder, name), "rb") as handle:
            found[name] = hashlib.sha256(handle.read()).hexdigest()
    return found


def one_run(mesh, stage, delay, folder):
    """``(named stage, exit code, seconds from SIGINT to exit, folder unchanged)``; the
    stage is None when the run ended before the stage's line appeared."""
    for name, data in OLDER.items():
        with open(os.path.join(folder, name), "wb") as handle:
            handle.write(data)
    before = digest(folder)
    command = [sys.executable, "-m", "polycube_wb", "reconstruct", mesh, "--progress",
               "-o", os.path.join(folder, "result.step"),
               "--report", os.path.join(folder, "report.json"),
               "--base-mesh", os.path.join(folder, "base.obj"),
               "--labels", os.path.join(folder, "labels.ply")]
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    sent = None
    for line in process.stderr:
        if line.strip() == STAGE_PREFIX + stage:
            time.sleep(delay)
            process.send_signal(signal.SIGINT)
            sent = time.perf_counter()
            break
    _, rest = process.communicate(timeout=GUARD_SECONDS)
    ended = time.perf_counter()
    last = (rest.strip().splitlines() or [""])[-1]
    named = last.split("cancelled at stage ", 1)[1].split(";")[0] if "cancelled at" in last else "-"
    unchanged = digest(folder) == before
    return named, process.returncode, None if sent is None else ended - sent, unchanged


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mesh", nargs="?", default=DEFAULT_MESH)
    parser.add_argument("--delay", type=float, default=0.3,
                        help="seconds between the stage's line and SIGINT (default 0.3)")
    parser.add_argument("--out", default=os.path.join(HERE, "CANCEL_RESULTS.md"))
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="polycube_cancel_") as folder:
        for stage in ANNOUNCED:
            named, code, seconds, unchanged = one_run(args.mesh, stage, args.delay, folder)
            rows.append((stage, named, code, seconds, unchanged))
            print(stage, named, code, seconds, unchanged, flush=True)
            for name in os.listdir(folder):
                os.remove(os.path.join(folder, name))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()
    lines = ["# Ctrl-C on the command line: how fast each stage stops, and what it leaves", "",
             f"`benchmarks/cancel_bench.py` at {commit} on `{os.path.relpath(args.mesh, REPO)}` "
             f"(Python {platform.python_version()}, {os.cpu_count()} cores, shared with other "
             f"jobs): `reconstruct --progress` with `-o`, `--report`, `--base-mesh` and "
             f"`--labels` over an older STEP file and report; SIGINT {args.delay:g} s after "
             f"the stage's `STAGE` line.", "",
             "| stage signalled | stage named | exit | s from SIGINT to exit | folder unchanged |",
             "|---|---|---|---|---|"]
    for stage, named, code, seconds, unchanged in rows:
        shown = "-" if seconds is None else f"{seconds:.2f}"
        lines.append(f"| {stage} | {named} | {code} | {shown} | {'yes' if unchanged else 'NO'} |")
    lines += ["", "A run whose stage named is later than the one signalled had left that stage "
              "before Python handled the signal (a compiled call finishing, or an import: the "
              "Ctrl-C is then raised at the next progress report).", ""]
    with open(args.out, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
