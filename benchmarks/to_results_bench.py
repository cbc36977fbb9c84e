# SPDX-License-Identifier: LGPL-2.1-or-later
"""Topology-optimisation results published by others: per-stage seconds end to end.

Usage::

    .venv/bin/python benchmarks/to_results_bench.py --label after [--repo PATH]
                                                    [--meshes DIR] [--only NAME ...]

``--repo`` is the checkout whose CLI is run (default: this one; for a "before" column, an
export of the commit to compare with, e.g. ``git archive COMMIT | tar -x -C DIR``). Each mesh
runs the command a user runs, ``python -m polycube_wb reconstruct MESH -o OUT.step --report
OUT.json`` with default parameters, in its own process with this checkout's interpreter. Per
mesh: the wall seconds of every stage (from the report), the total, the exit code, the
CPU seconds of every stage (the report's ``cpu_seconds``), the
base-mesh method, faces and limit-surface crossings of the cage kept, the fit's crossings and
volume outside, and the first line of the error of a failed run; with ``--evaluate``, the
verdict of ``../shared/tools/evaluate.py`` on the STEP written (valid, closed, volume outside,
symmetric mean and maximum distance). Rows are kept per label in
``benchmarks/to_results.json``; ``benchmarks/TO_RESULTS.md`` shows the labels side by side.
The machine has 2 cores shared with other jobs: compare labels measured in one run.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
MESHES = ("simjeb76_ge_bracket_to.stl", "toplib_michell3d_density_mc.stl")
"""The public TO results among the dev meshes (genus 52 and 48; see SOURCES.md there)."""
EVALUATE = os.path.join(REPO, "..", "shared", "tools", "evaluate.py")
STAGES = ("intake", "parts", "frames", "labeling", "basemesh", "fit", "patches", "solid")
RESULTS_JSON = os.path.join(HERE, "to_results.json")
RESULTS_MD = os.path.join(HERE, "TO_RESULTS.md")


def run_mesh(repo, path, evaluate=False):
    """One reconstruction of ``path`` by the CLI of ``repo``; a JSON-serialisable row."""
    with tempfile.TemporaryDirectory() as work:
        step, report_path = os.path.join(work, "out.step"), os.path.join(work, "out.json")
        started = time.perf_counter()
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run([sys.executable, "-m", "polycube_wb", "reconstruct", path, "-o",
                               step, "--report", report_path], cwd=repo, capture_output=True,
                              text=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        row = {"mesh": os.path.basename(path), "exit": done.returncode,
               "wall": round(time.perf_counter() - started, 1),
               "cpu": round(after.ru_utime + after.ru_stime - before.ru_utime
                            - before.ru_stime, 1),
               "load": round(os.getloadavg()[0], 1)}
        errors = [line for line in done.stderr.splitlines() + done.stdout.splitlines()
                  if line.startswith(("failed", "error"))]
        row["error"] = errors[0][:300] if errors else ""
        if os.path.exists(report_path):
            with open(report_path) as handle:
                report = json.load(handle)
            row["stages"] = {name: report["stages"][name].get("seconds")
                             for name in STAGES if name in report.get("stages", {})}
            row["stage_cpu"] = {name: report["stages"][name].get("cpu_seconds")
                                for name in STAGES if name in report.get("stages", {})}
            row["total"] = report.get("total_seconds")
            base = report.get("base_mesh", {})
            row["base_mesh"] = {key: base.get(key) for key in ("method", "faces", "genus",
                                                               "limit_crossings")}
            fit = report.get("fit", {})
            row["fit"] = {key: fit.get(key) for key in ("self_intersections",
                                                        "outside_volume_fraction")}
        if evaluate and done.returncode == 0 and os.path.exists(EVALUATE):
            checked = subprocess.run([sys.executable, EVALUATE, "--target", path, "--result",
                                      step], capture_output=True, text=True)
            try:
                verdict = json.loads(checked.stdout)
                brep = verdict["brep"]
                distance = verdict["distance"]["symmetric"]
                row["evaluate"] = (f"evaluate.py: valid {brep['is_valid']}, closed "
                                   f"{brep['all_shells_closed']}, {brep['solids']} solid(s), "
                                   f"outside {verdict['containment']['outside_fraction']:.2%}, "
                                   f"mean / max distance {distance['mean_frac']:.2%} / "
                                   f"{distance['max_frac']:.2%} of the diagonal")
            except (ValueError, KeyError, TypeError):
                row["evaluate"] = (checked.stdout.strip().splitlines() or [""])[-1][:200]
    return row


def write_markdown(results):
    """``RESULTS_MD`` from all labels' rows."""
    lines = ["# Topology-optimisation results of others: seconds per stage", "",
             "Written by `benchmarks/to_results_bench.py`: the CLI with default parameters, "
             "one process per mesh, wall seconds of each stage from its report (`-`: not "
             "reached). `cage` is the base-mesh faces and the crossing triangle pairs of their "
             "level-2 limit surface, `fit x` the fitted limit surface's crossing pairs, "
             "`outside` the share of the target's volume outside it. The machine has 2 cores "
             "shared with other jobs: labels measured in one run compare; figures across runs "
             "vary by a factor up to 2; `total` is the report's (the core stages, without the "
             "solid), `wall` the process's end to end (start-up and the solid included), `cpu` "
             "the CPU seconds of the whole process and of the work it forks (user and "
             "system), which the other jobs change less, `load` the machine's 1-minute load "
             "average when the run ended.", ""]
    header = ["label", "mesh", *STAGES, "total", "wall", "cpu", "load", "exit", "cage",
              "fit x", "outside", "error"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, rows in results.items():
        for row in rows:
            stages = row.get("stages", {})
            base, fit = row.get("base_mesh", {}), row.get("fit", {})
            outside = fit.get("outside_volume_fraction")
            cells = [label, row["mesh"],
                     *[("-" if stages.get(name) is None else f"{stages[name]:.1f}")
                       for name in STAGES],
                     f"{row.get('total') or row['wall']:.1f}", f"{row['wall']:.1f}",
                     "-" if row.get("cpu") is None else f"{row['cpu']:.1f}",
                     "-" if row.get("load") is None else f"{row['load']:.1f}", str(row["exit"]),
                     f"{base.get('faces')} / {base.get('limit_crossings')}",
                     str(fit.get("self_intersections", "-")),
                     "-" if outside is None else f"{outside:.2%}",
                     row.get("evaluate") or row["error"].replace("|", "/")[:160]]
            lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "CPU seconds of each stage (its report's `cpu_seconds`: the process's user and "
              "system time in the stage, which other jobs on the machine change less than "
              "the wall seconds above; work a stage forks to another core, such as the paired "
              "decimation built ahead, is in `cpu` above, not here; `-`: not reached or not "
              "recorded).", "",
              "| " + " | ".join(["label", "mesh", *STAGES, "sum"]) + " |",
              "|" + "---|" * (len(STAGES) + 3)]
    for label, rows in results.items():
        for row in rows:
            cpu = row.get("stage_cpu") or {}
            known = [cpu[name] for name in STAGES if cpu.get(name) is not None]
            lines.append("| " + " | ".join(
                [label, row["mesh"], *[("-" if cpu.get(name) is None else f"{cpu[name]:.1f}")
                                       for name in STAGES],
                 f"{sum(known):.1f}" if known else "-"]) + " |")
    with open(RESULTS_MD, "w") as handle:
        handle.write("\n".join(lines) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--label", required=True)
    parser.add_argument("--repo", default=REPO)
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--evaluate", action="store_true")
    args = parser.parse_args()
    names = args.only or MESHES
    results = {}
    if os.path.exists(RESULTS_JSON):
        with open(RESULTS_JSON) as handle:
            results = json.load(handle)
    rows = []
    for name in names:
        row = run_mesh(os.path.abspath(args.repo), os.path.join(args.meshes, name),
                       args.evaluate)
        print(json.dumps(row), flush=True)
        rows.append(row)
    results[args.label] = rows
    with open(RESULTS_JSON, "w") as handle:
        json.dump(results, handle, indent=1)
    write_markdown(results)


if __name__ == "__main__":
    main()
