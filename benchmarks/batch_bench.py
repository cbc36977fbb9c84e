# SPDX-License-Identifier: LGPL-2.1-or-later
"""Batch benchmark: ``batch --jobs 1`` against ``--jobs 2`` on the same folder, in one run.

Usage::

    .venv/bin/python benchmarks/batch_bench.py [--meshes DIR] [--out benchmarks]
                                               [-- BATCH OPTIONS ...]

Runs ``python -m polycube_wb batch DIR -o benchmarks/tmp/batch-jobsN --jobs N --force`` for
N = 1 and then N = 2 with the same options (default ``--fit-iterations 10 --timeout 30``),
times each whole command (wall clock), and writes ``BATCH_RESULTS.md`` into ``--out``: both
wall times, the speed-up, whether both runs gave every mesh the same status, stage and face
count, and the per-mesh rows of the ``--jobs 2`` run. Timings are on a shared 2-core
machine; the load average before each run is recorded.
"""
import argparse
import csv
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
DEFAULT_OPTIONS = ("--fit-iterations", "10", "--timeout", "30")


def run(meshes, jobs, options):
    """Run the batch once; returns (wall seconds, load average before, rows by name)."""
    out = os.path.join(HERE, "tmp", f"batch-jobs{jobs}")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    load = os.getloadavg()[0]
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "polycube_wb", "batch", meshes, "-o", out,
                           "--jobs", str(jobs), "--force", "--quiet", *options],
                          cwd=REPO, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"batch --jobs {jobs} failed ({done.returncode}): {done.stderr}")
    with open(os.path.join(out, "summary.csv"), newline="") as handle:
        rows = {row["name"]: row for row in csv.DictReader(handle)}
    return seconds, load, rows


def _number(text, digits=3):
    return f"{float(text):.{digits}g}" if text else ""


def write_results(path, options, runs):
    (t1, load1, rows1), (t2, load2, rows2) = runs
    same = [name for name in rows1 if name in rows2 and all(
        rows1[name][k] == rows2[name][k] for k in ("status", "stage_reached", "faces"))]
    solids = sum(row["status"] == "ok" for row in rows2.values())
    lines = [
        "# Batch benchmark (`benchmarks/batch_bench.py`)",
        "",
        f"`python -m polycube_wb batch ../shared/data/meshes -o ... --force {' '.join(options)}`,"
        " each mesh in its own process; wall clock of the whole command, both runs in the same"
        " invocation of this script, on the shared 2-core machine.",
        "",
        "| run | wall s | load average before | meshes | solids | failed |",
        "|---|---|---|---|---|---|",
    ]
    for jobs, (seconds, load, rows) in zip((1, 2), runs):
        ok = sum(row["status"] == "ok" for row in rows.values())
        lines.append(f"| `--jobs {jobs}` | {seconds:.1f} | {load:.2f} | {len(rows)} | {ok} | "
                     f"{len(rows) - ok} |")
    lines += ["", f"Speed-up of `--jobs 2` over `--jobs 1`: **{t1 / t2:.2f}x**. "
              f"Same status, stage reached and face count in both runs: {len(same)} of "
              f"{len(rows1)} meshes.", "",
              f"Per mesh (`--jobs 2` run; {solids} solids):", "",
              "| mesh | triangles | status | stage reached | failed stage | faces | mean dev. | "
              "max dev. | outside vol. | s (jobs 1) | s (jobs 2) | peak MiB | message |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, row in rows2.items():
        message = row["message"].replace("|", "/").replace("\n", " ")
        if len(message) > 160:
            message = message[:157] + "..."
        lines.append(f"| {name} | {row['triangles']} | {row['status']} | {row['stage_reached']} | "
                     f"{row['failed_stage']} | {row['faces']} | {_number(row['mean_deviation'])} | "
                     f"{_number(row['max_deviation'])} | {_number(row['outside_volume'])} | "
                     f"{_number(rows1.get(name, {}).get('seconds', ''), 4)} | "
                     f"{_number(row['seconds'], 4)} | {_number(row['peak_memory_mb'], 4)} | "
                     f"{message} |")
    lines += ["", "Deviations are fractions of the bounding-box diagonal (fitted surface to "
              "target), the volume outside a fraction of the target volume (the pipeline's own "
              "report, not the independent `../shared/tools/evaluate.py`).", ""]
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default=MESHES, help="folder of meshes")
    parser.add_argument("--out", default=HERE, help="folder for BATCH_RESULTS.md")
    parser.add_argument("options", nargs="*", help="batch options (after --)")
    args = parser.parse_args(argv)
    options = tuple(args.options) or DEFAULT_OPTIONS
    runs = [run(args.meshes, jobs, options) for jobs in (1, 2)]
    write_results(os.path.join(args.out, "BATCH_RESULTS.md"), options, runs)
    print(f"jobs 1: {runs[0][0]:.1f} s, jobs 2: {runs[1][0]:.1f} s, "
          f"speed-up {runs[0][0] / runs[1][0]:.2f}x")


if __name__ == "__main__":
    main()
