# SPDX-License-Identifier: LGPL-2.1-or-later
"""One mesh of a batch, in its own process: ``python -m polycube_wb.batch_worker < JOB.json``.

Reads the job (a :class:`polycube_wb.batch.MeshJob` as JSON) from stdin, runs the same
pipeline as ``reconstruct`` (:func:`polycube_wb.api.reconstruct_to_step`) with every output,
renders the thumbnail, writes the per-mesh JSON report with its ``batch`` section, and prints
the summary row as one JSON line on stdout. Whatever happens to the mesh, the exit code is 0
and the row says which stage failed and why; only a crash of the process itself (killed,
out of memory) leaves no row, which the batch reports as ``crashed``.

Each stage's start is announced on stderr as a line ``STAGE <name>``, so that the batch can
name the stage of a process it stops (time or memory cap) or that dies without a row. The
report's ``peak_memory_mb`` is the process's resident peak at its very end (thumbnail
included).
"""
import json
import os
import sys
import time
import traceback

import polycube_wb  # noqa: F401  (installs the guard that makes ``core`` ours)
from core.progress import NO_PROGRESS
from polycube_wb.stage_lines import StageLines


def run_job(job, stages=None):
    """Run one mesh and write its outputs; returns the report (dict) with its ``batch`` section.

    Parameters
    ----------
    job : polycube_wb.batch.MeshJob
    stages : StageLines announcing the stages, or None for none.
    """
    from core.errors import PolycubeInputError
    from core.output_files import write_json_atomic
    from core.pipeline import peak_memory_mb
    from polycube_wb.api import reconstruct_to_step

    paths = job.paths()
    started = time.perf_counter()
    started_wall = time.time()
    report = None
    try:
        report = reconstruct_to_step(job.source, paths["step"], paths["base_mesh"],
                                     paths["report"], paths["labels"], "solid",
                                     progress=stages or NO_PROGRESS, **job.params)
    except PolycubeInputError as exc:
        report = {"input": {"file": job.source},
                  "stages": {"intake": {"status": "failed", "seconds": 0.0, "message": str(exc)}}}
    except Exception as exc:  # a stage failed unexpectedly: the pipeline wrote its report first
        report = _read_report(paths["report"], started_wall) or \
            {"input": {"file": job.source}, "stages": {}}
        stage = _first_failed(report) or "solid"
        entry = report["stages"].setdefault(stage, {"status": "failed", "seconds": 0.0})
        entry["status"] = "failed"
        entry["message"] = entry.get("message") or f"{type(exc).__name__}: {exc}"
        report["traceback"] = traceback.format_exc(limit=8)
    report.setdefault("outputs", {})
    if "step" in report["outputs"]:
        if stages is not None:
            stages.announce("thumbnail")
        try:
            from polycube_wb.batch_thumbnail import render_solid_thumbnail

            report["outputs"]["thumbnail"] = render_solid_thumbnail(
                paths["thumbnail"], job.source, paths["step"], job.params.get("units", "mm"))
        except Exception as exc:  # a picture must not fail the mesh; the row says why it is missing
            report["thumbnail_error"] = f"{type(exc).__name__}: {exc}"
    report["peak_memory_mb"] = round(peak_memory_mb(), 1)
    report["batch"] = job.batch_section(time.perf_counter() - started)
    write_json_atomic(paths["report"], report, (job.source,))
    report["outputs"]["report"] = os.path.abspath(paths["report"])
    return report


def _read_report(path, not_before):
    """The report at ``path`` if it was written at or after ``not_before`` (epoch s), else None."""
    try:
        if os.path.getmtime(path) < not_before - 1e-3:
            return None
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except (OSError, ValueError):
        return None


def _first_failed(report):
    return next((name for name, entry in report.get("stages", {}).items()
                 if entry.get("status") == "failed"), None)


def main():
    """Entry point of the worker process (see the module docstring)."""
    from polycube_wb.batch import CANCELLED_EXIT, ROW_PREFIX, MeshJob, row_from_report

    job = MeshJob.from_dict(json.load(sys.stdin))
    stages = StageLines()
    try:
        with stages.ctrl_c_remembered():
            report = run_job(job, stages)
    except KeyboardInterrupt:  # Ctrl-C reaches the whole batch: this mesh leaves no output
        sys.stderr.write(f"cancelled at stage {stages.stage}\n")
        return CANCELLED_EXIT
    row = row_from_report(job, report).to_dict()
    sys.stdout.write("\n" + ROW_PREFIX + json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
