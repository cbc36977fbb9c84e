# SPDX-License-Identifier: LGPL-2.1-or-later
"""Measure the parametric document objects on a target mesh; writes ``workbench_RESULTS.md``.

Usage::

    .venv/bin/python benchmarks/workbench_bench.py [MESH] [--iterations N] [--out FILE]

Headless (plain FreeCAD in the .venv), on one document: the whole chain (Target ->
Segmentation -> BaseMesh -> Fit -> Solid -> Deviation) from scratch; a recompute after
changing the fit's iterations (only the fit and what follows rerun); a cage edit of the
fitted cage (only the solid and the map rerun); a recompute with nothing changed; the
document's size on disk with the target embedded; save -> close -> reopen -> recompute
after a parameter change with the source file deleted; and how long a cancel takes to
land inside the fit (from the request, 8 s into a long refit, to the document with the Fit
marked cancelled: at most one fit iteration). Every figure is
measured here, in this run; seconds are wall-clock on this machine.
"""
import argparse
import os
import platform
import shutil
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
if "/usr/lib/freecad-python3/lib" not in sys.path:
    sys.path.append("/usr/lib/freecad-python3/lib")

import FreeCAD  # noqa: E402

from core.errors import Cancelled  # noqa: E402
from core.progress import Progress  # noqa: E402
from polycube_wb import api  # noqa: E402


class RunLog:
    """Names of the stage objects whose stage ran (not only redisplayed)."""

    def __init__(self, doc):
        self.ran = []
        for obj in doc.Objects:
            if api.stage_kind(obj):
                original = obj.Proxy.run

                def run(o, progress, original=original):
                    self.ran.append(api.stage_kind(o))
                    return original(o, progress)

                obj.Proxy.run = run


class CancelAt(Progress):
    """Asks to cancel ``seconds`` after ``arm()``, as a user pressing Esc at that moment
    would: the request is seen at the next progress report or cancel check."""

    def __init__(self, seconds):
        self.seconds = seconds
        self.requested_at = None

    def arm(self):
        self.requested_at = time.perf_counter() + self.seconds

    def report(self, stage, fraction, message=""):
        self.check_cancel()

    def check_cancel(self):
        if self.requested_at is not None and time.perf_counter() >= self.requested_at:
            raise Cancelled("benchmark cancel")


def timed(function):
    started = time.perf_counter()
    value = function()
    return time.perf_counter() - started, value


def measure(mesh_path, iterations):
    rows = []
    folder = tempfile.mkdtemp(prefix="polycube_wb_bench_")
    try:
        source = os.path.join(folder, os.path.basename(mesh_path))
        shutil.copy(mesh_path, source)
        doc = FreeCAD.newDocument("Bench")
        doc.UndoMode = 1
        seconds, target = timed(lambda: api.make_target(doc, source))
        rows.append(("import and validate the target (with self-intersection test)", seconds, ""))
        chain = api.make_chain(doc, target, "Solid", Fit={"Iterations": iterations})
        chain["Deviation"] = api.make_deviation(doc, chain["Solid"], target)
        seconds, outcome = timed(lambda: api.recompute(doc))
        assert outcome.ok, outcome.failures
        rows.append(("whole chain from scratch", seconds,
                     f"fit {iterations} iterations; {chain['Solid'].BrepFaces} B-spline faces"))
        deviation = chain["Deviation"]
        map_line = (f"mean {deviation.MeanDeviation:.3g} mm ({deviation.MeanDeviationPercent:.3f} %), "
                    f"max {deviation.MaxDeviation:.3g} mm ({deviation.MaxDeviationPercent:.3f} %), "
                    f"outside {deviation.OutsideVolume:.3f} %, uncovered "
                    f"{deviation.UncoveredVolume:.3f} %")

        log = RunLog(doc)
        chain["Fit"].Iterations = max(iterations // 2, 1)
        seconds, outcome = timed(lambda: api.recompute(doc))
        rows.append(("Fit.Iterations changed", seconds, "reran: " + ", ".join(log.ran)))

        log.ran.clear()
        fit = chain["Fit"]
        top = max(range(len(fit.CageVertices)), key=lambda k: fit.CageVertices[k].z)
        point = fit.CageVertices[top]
        api.move_cage_vertices(fit, {top: (point.x, point.y, point.z + 2.0)})
        seconds, outcome = timed(lambda: api.recompute(doc))
        rows.append(("one fitted cage vertex moved 2 mm", seconds, "reran: " + ", ".join(log.ran)))

        log.ran.clear()
        for obj in chain.values():
            obj.touch()
        seconds, outcome = timed(lambda: api.recompute(doc))
        rows.append(("every object touched, nothing changed", seconds,
                     "reran: " + (", ".join(log.ran) or "none")))

        progress = CancelAt(8.0)
        before = chain["Fit"].Iterations

        def cancelled_run():
            try:
                api.run_in_transaction(doc, "bench",
                                       lambda: setattr(chain["Fit"], "Iterations", 400), progress)
            except Cancelled:
                return time.perf_counter()
            raise AssertionError("the run was not cancelled")

        progress.arm()
        _, landed = timed(cancelled_run)
        rows.append(("cancel requested 8 s into a 400-iteration refit -> Fit marked cancelled",
                     landed - progress.requested_at,
                     f"seconds from the request; Fit.Iterations {before} -> "
                     f"{chain['Fit'].Iterations}, Status '{chain['Fit'].Status}' (its last "
                     f"result kept; Undo restores {before})"))

        path = os.path.join(folder, "bench.FCStd")
        os.remove(source)
        doc.saveAs(path)
        size_mb = os.path.getsize(path) / 2 ** 20
        FreeCAD.closeDocument(doc.Name)
        seconds, doc = timed(lambda: FreeCAD.openDocument(path))
        rows.append(("reopen the document (source file deleted)", seconds,
                     f"file size {size_mb:.1f} MiB"))
        fit = next(obj for obj in doc.Objects if api.stage_kind(obj) == "Fit")
        fit.Iterations = iterations
        seconds, outcome = timed(lambda: api.recompute(doc))
        assert outcome.ok, outcome.failures
        rows.append(("after reopening: Fit.Iterations changed", seconds, "ok, no file on disk"))
        FreeCAD.closeDocument(doc.Name)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return rows, map_line


def write_markdown(path, mesh_path, iterations, rows, map_line):
    lines = [
        "# Workbench objects: recompute, edit, cancel, reopen",
        "",
        f"Written by `benchmarks/workbench_bench.py` on {time.strftime('%Y-%m-%d')} "
        f"({platform.machine()}, {os.cpu_count()} CPUs, other jobs running: figures are "
        "indicative); target `" + os.path.relpath(mesh_path, REPO) + f"`, {iterations} fit "
        "iterations.",
        "",
        "| step | seconds | notes |",
        "|---|---:|---|",
    ]
    lines += [f"| {step} | {seconds:.2f} | {notes} |" for step, seconds, notes in rows]
    lines += ["", f"Deviation map of the solid against the target: {map_line}.", ""]
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines))
    os.replace(tmp, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", nargs="?",
                        default=os.path.join(REPO, "examples", "to_simp_cantilever.stl"))
    parser.add_argument("--iterations", type=int, default=100)
    parser.add_argument("--out", default=os.path.join(HERE, "workbench_RESULTS.md"))
    args = parser.parse_args()
    rows, map_line = measure(os.path.abspath(args.mesh), args.iterations)
    write_markdown(args.out, os.path.abspath(args.mesh), args.iterations, rows, map_line)
    for step, seconds, notes in rows:
        print(f"{seconds:8.2f} s  {step}  {notes}")


if __name__ == "__main__":
    main()
