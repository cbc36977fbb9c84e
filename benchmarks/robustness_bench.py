# SPDX-License-Identifier: LGPL-2.1-or-later
"""Scale benchmark: the pipeline on targets of about a million triangles, time and peak
memory per stage.

Usage::

    .venv/bin/python benchmarks/robustness_bench.py [--cases NAME ...] [--fit-iterations N]
                                                    [--out benchmarks]

Each case is a dev mesh refined by uniform midpoint subdivision (every triangle into four,
``levels`` times: the surface is unchanged, only finer), written as a binary STL and run
through every stage in a process of its own: intake (read + validate), parts, frames,
labeling, base mesh, fit, patches and the FreeCAD solid with its STEP file, as far as the
stages go. Per stage the wall time and the peak resident memory of the process while the
stage ran (sampled every 20 ms from ``/proc/self/status``) are recorded. Writes
``ROBUSTNESS_RESULTS.md`` and ``robustness_results.json`` into ``--out``, keeping the
cases of an earlier run that ``--cases`` leaves out. The machine is a shared 2-core box:
the load average before each case is recorded with it.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")

CASES = {
    # name: (mesh file, midpoint subdivision levels)
    "cantilever_x4": (os.path.join(REPO, "examples", "to_simp_cantilever.stl"), 1),
    "cantilever_x64": (os.path.join(REPO, "examples", "to_simp_cantilever.stl"), 3),
    "torsion_arm_fine3_x4": (os.path.join(MESHES, "to_simp_torsion_arm_fine3.stl"), 1),
    "torsion_arm_fine3_x16": (os.path.join(MESHES, "to_simp_torsion_arm_fine3.stl"), 2),
}
MEMORY_LIMIT_MB = 8192
"""The issue's budget for a million-triangle target."""
SAMPLE_SECONDS = 0.02


class PeakMemory:
    """Peak resident memory (MiB) of this process between :meth:`start` and :meth:`stop`,
    sampled by a thread."""

    def __init__(self):
        self._peak = 0.0
        self._running = False
        self._thread = None

    @staticmethod
    def resident_mb():
        with open("/proc/self/status", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
        return 0.0

    def _sample(self):
        while self._running:
            self._peak = max(self._peak, self.resident_mb())
            time.sleep(SAMPLE_SECONDS)

    def start(self):
        self._peak = self.resident_mb()
        self._running = True
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()

    def stop(self):
        self._running = False
        self._thread.join()
        return max(self._peak, self.resident_mb())


def refined_stl(source, levels, folder):
    """Write ``source`` refined ``levels`` times by midpoint subdivision as a binary STL in
    ``folder``; returns ``(path, triangles)``."""
    import numpy as np
    import trimesh
    from trimesh.remesh import subdivide

    from core.mesh_io import read_triangle_soup
    from core.validate import merge_identical_vertices

    vertices, faces = read_triangle_soup(source)
    vertices, faces, _ = merge_identical_vertices(vertices, faces)
    for _ in range(levels):
        vertices, faces = subdivide(vertices, faces)
    path = os.path.join(folder, "target.stl")
    trimesh.Trimesh(np.asarray(vertices), np.asarray(faces), process=False).export(path)
    return path, int(len(faces))


def run_case(name, fit_iterations):
    """Run one case in this process; returns its JSON-able figures."""
    from core.params import ReconstructionParams
    from core.pipeline import CORE_STAGES, run_stages

    source, levels = CASES[name]
    memory = PeakMemory()
    figures = {"case": name, "source": os.path.basename(source), "levels": levels,
               "load_before": round(os.getloadavg()[0], 2), "stages": []}
    with tempfile.TemporaryDirectory(prefix="robustness_") as folder:
        memory.start()
        started = time.perf_counter()
        path, triangles = refined_stl(source, levels, folder)
        figures["refine"] = {"seconds": round(time.perf_counter() - started, 2),
                             "peak_mb": round(memory.stop(), 1)}
        figures["triangles"] = triangles
        figures["file_mb"] = round(os.path.getsize(path) / 2 ** 20, 1)
        params = ReconstructionParams(fit_iterations=fit_iterations)
        state = {"input_path": path, "params": params}
        report = {"stages": {}}
        for stage in CORE_STAGES:
            memory.start()
            started = time.perf_counter()
            state, report, failed = run_stages(state, [stage], params, report=report)
            entry = dict(report["stages"][stage], stage=stage,
                         wall_seconds=round(time.perf_counter() - started, 2),
                         peak_mb=round(memory.stop(), 1))
            figures["stages"].append(entry)
            print(json.dumps(entry), file=sys.stderr, flush=True)
            if entry["status"] != "ok":
                break
        if "patches" in state:
            figures["stages"].append(_solid_stage(state["patches"], folder, memory))
    figures["process_peak_mb"] = round(_process_peak_mb(), 1)
    return figures


def _solid_stage(patches, folder, memory):
    """The FreeCAD solid and its STEP file, timed like a core stage."""
    import FreeCAD  # noqa: F401  (before Part, see docs/CONTRIBUTING.md)

    from polycube_wb.brep import make_solid
    from polycube_wb.step_io import write_solid_step

    memory.start()
    started = time.perf_counter()
    try:
        built = make_solid(patches)
        write_solid_step(built, patches, os.path.join(folder, "result.step"), input_paths=(),
                         name="robustness")
        status, message = "ok", f"valid={built.figures['valid']} faces={built.figures['faces']}"
    except Exception as exc:  # recorded in the results like a failed core stage
        status, message = "failed", f"{type(exc).__name__}: {exc}"
    return {"stage": "solid", "status": status, "message": message,
            "wall_seconds": round(time.perf_counter() - started, 2), "peak_mb": round(memory.stop(), 1)}


def _process_peak_mb():
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _run_child(name, fit_iterations, timeout):
    """Figures of one case run in a child process; on a timeout or a crash, the stages it
    finished (from its stderr) and why it stopped."""
    command = [sys.executable, os.path.abspath(__file__), "--one", name,
               "--fit-iterations", str(fit_iterations)]
    try:
        done = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        stderr = exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return {"case": name, "error": f"stopped after {timeout:.0f} s",
                "finished": _finished_stages(stderr)}
    if done.returncode != 0:
        return {"case": name, "error": f"exit {done.returncode}: {done.stderr.strip()[-400:]}",
                "finished": _finished_stages(done.stderr)}
    return json.loads(done.stdout.strip().splitlines()[-1])


def _merged(path, results):
    """``results`` plus the cases of an earlier run (``path``) not run this time, in the
    order of :data:`CASES`."""
    by_name = {}
    if os.path.isfile(path):
        with open(path, encoding="utf-8") as handle:
            by_name = {case["case"]: case for case in json.load(handle) if case["case"] in CASES}
    by_name.update({case["case"]: case for case in results})
    return [by_name[name] for name in CASES if name in by_name]


def _finished_stages(stderr):
    entries = []
    for line in stderr.splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if isinstance(entry, dict) and "stage" in entry:
            entries.append(entry)
    return entries


def markdown(results, fit_iterations):
    lines = ["# Robustness benchmark: targets of about a million triangles",
             "",
             "Written by `benchmarks/robustness_bench.py` (do not edit by hand). Each case is a "
             "mesh refined by uniform midpoint subdivision (the surface is unchanged, every "
             "triangle becomes 4 per level), run stage by stage in its own process with the "
             f"default parameters and `fit_iterations={fit_iterations}`. Peak memory is the "
             "resident set of the process while the stage ran (sampled every 20 ms); the "
             f"issue's budget is {MEMORY_LIMIT_MB} MiB. Shared 2-core machine: wall times "
             "include other jobs' load (load average before each case given).",
             ""]
    for case in results:
        if "error" in case:
            lines += [f"## {case['case']}", "", f"did not finish: {case['error']}; stages done "
                      "before: " + (", ".join(f"{e['stage']} {e['status']} {e['wall_seconds']:.1f} s "
                                              f"{e['peak_mb']:,.0f} MiB" for e in case["finished"])
                                    or "none"), ""]
            continue
        within = "within" if case["process_peak_mb"] <= MEMORY_LIMIT_MB else "OVER"
        lines += [f"## {case['case']}: {case['triangles']:,} triangles",
                  "",
                  f"`{case['source']}` refined {case['levels']} times ({case['file_mb']} MiB binary "
                  f"STL, written in {case['refine']['seconds']} s); load average before: "
                  f"{case['load_before']}; process peak {case['process_peak_mb']:,.0f} MiB "
                  f"({within} {MEMORY_LIMIT_MB} MiB).",
                  "",
                  "| stage | status | wall s | peak MiB | message |",
                  "|---|---|---:|---:|---|"]
        for entry in case["stages"]:
            message = (entry.get("message") or "").replace("|", "/").replace("\n", " ")
            if len(message) > 160:
                message = message[:157] + "..."
            lines.append(f"| {entry['stage']} | {entry['status']} | {entry['wall_seconds']:.1f} | "
                         f"{entry['peak_mb']:,.0f} | {message} |")
        total = sum(entry["wall_seconds"] for entry in case["stages"])
        lines += ["", f"Total over the stages that ran: {total:.1f} s.", ""]
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", choices=tuple(CASES), default=tuple(CASES))
    parser.add_argument("--fit-iterations", type=int, default=20)
    parser.add_argument("--timeout", type=float, default=3600.0,
                        help="seconds a case may take before it is stopped (default 3600)")
    parser.add_argument("--out", default=HERE)
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(run_case(args.one, args.fit_iterations)))
        return 0
    results = []
    for name in args.cases:
        print(f"robustness: {name} ...", flush=True)
        results.append(_run_child(name, args.fit_iterations, args.timeout))
        print(json.dumps(results[-1])[:600], flush=True)
    from core.output_files import write_json_atomic, write_text_atomic

    results = _merged(os.path.join(args.out, "robustness_results.json"), results)
    write_json_atomic(os.path.join(args.out, "robustness_results.json"), results)
    write_text_atomic(os.path.join(args.out, "ROBUSTNESS_RESULTS.md"),
                      markdown(results, args.fit_iterations), what="results")
    return 0


if __name__ == "__main__":
    sys.exit(main())
