# SPDX-License-Identifier: LGPL-2.1-or-later
"""Batch memory benchmark: is the summary's peak memory right, and does the cap stop a mesh?

Usage::

    .venv/bin/python benchmarks/memory_bench.py [--meshes DIR] [--out benchmarks]
                                                [--seconds 60] [--share 0.6]

1. Peak memory, checked independently: every mesh of ``--meshes`` runs as one batch worker
   (``python -m polycube_wb.batch_worker``, the process the batch starts per mesh, no cap)
   under GNU ``/usr/bin/time -f %M`` (the maximum resident set the kernel reports for the
   finished process) and ``timeout -s KILL SECONDS``. The worker's own figure (its report's
   ``peak_memory_mb``, Linux ``VmHWM`` at its end) is compared with ``time``'s.
2. The cap: every mesh that gave a solid runs through ``batch --memory-limit`` at
   ``--share`` of its measured peak. Recorded: the row's status and message, the resident
   memory when it was stopped (how far a 50 ms poll lets it pass the cap) and its seconds
   against the uncapped run's (it must stop, not hang).

Writes ``MEMORY_RESULTS.md`` into ``--out``. Options of every run: ``--fit-iterations 10``.
"""
import argparse
import csv
import glob
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
PARAMS = {"fit_iterations": 10}
SUFFIXES = (".stl", ".obj", ".ply", ".off")


def measure_worker(source, out_dir, seconds):
    """One uncapped worker under ``/usr/bin/time``; (report or None, time's MiB, wall s)."""
    name = os.path.splitext(os.path.basename(source))[0]
    job = {"source": os.path.abspath(source), "name": name, "out_dir": out_dir,
           "params": PARAMS, "timeout": None, "memory_mb": None}
    env = dict(os.environ, PYTHONPATH=REPO)
    started = time.perf_counter()
    done = subprocess.run(["/usr/bin/time", "-f", "MAXRSS %M", "timeout", "-s", "KILL",
                           str(seconds), sys.executable, "-m", "polycube_wb.batch_worker"],
                          input=json.dumps(job), capture_output=True, text=True, cwd=REPO,
                          env=env)
    wall = time.perf_counter() - started
    kib = [line.split()[1] for line in done.stderr.splitlines() if line.startswith("MAXRSS ")]
    time_mb = int(kib[-1]) / 1024.0 if kib else None
    rows = [line for line in done.stdout.splitlines() if line.startswith("ROW ")]
    report = None
    if rows:
        with open(os.path.join(out_dir, name + ".json"), encoding="utf-8") as handle:
            report = json.load(handle)
    return report, time_mb, wall


def capped_batch(source, out_dir, cap_mb):
    """``batch --memory-limit cap_mb`` on one mesh; (summary row, wall s)."""
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "polycube_wb", "batch", source, "-o", out_dir,
                           "--memory-limit", f"{cap_mb:g}", "--force", "--quiet",
                           "--fit-iterations", str(PARAMS["fit_iterations"])],
                          cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"batch failed ({done.returncode}): {done.stderr}")
    with open(os.path.join(out_dir, "summary.csv"), newline="") as handle:
        return next(csv.DictReader(handle)), wall


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default=MESHES)
    parser.add_argument("--out", default=HERE)
    parser.add_argument("--seconds", type=float, default=60.0, help="time cap per worker")
    parser.add_argument("--share", type=float, default=0.6, help="cap as a share of the peak")
    args = parser.parse_args(argv)
    sources = sorted(p for p in glob.glob(os.path.join(args.meshes, "*"))
                     if p.lower().endswith(SUFFIXES))
    work = tempfile.mkdtemp(prefix="memory-bench-", dir=os.path.join(HERE, "tmp")
                            if os.path.isdir(os.path.join(HERE, "tmp")) else None)
    peaks = []
    for source in sources:
        report, time_mb, wall = measure_worker(source, work, args.seconds)
        peaks.append((source, report, time_mb, wall))
        print(f"{os.path.basename(source)}: time {time_mb} MiB, report "
              f"{report and report.get('peak_memory_mb')} MiB, {wall:.1f} s", flush=True)
    caps = []
    for source, report, time_mb, wall in peaks:
        if report and report.get("outputs", {}).get("step"):
            cap = round(args.share * report["peak_memory_mb"])
            row, capped_wall = capped_batch(source, os.path.join(work, "capped"), cap)
            caps.append((source, report["peak_memory_mb"], wall, cap, row, capped_wall))
            print(f"{os.path.basename(source)}: cap {cap} -> {row['status']} "
                  f"{row['message']} ({capped_wall:.1f} s)", flush=True)
    write_results(os.path.join(args.out, "MEMORY_RESULTS.md"), args, peaks, caps)


def _stage(report):
    stages = report.get("stages", {})
    failed = [n for n, e in stages.items() if e.get("status") == "failed"]
    ok = [n for n, e in stages.items() if e.get("status") == "ok"]
    return f"failed at {failed[0]}" if failed else (ok[-1] if ok else "")


def write_results(path, args, peaks, caps):
    lines = ["# Batch memory benchmark (`benchmarks/memory_bench.py`)", "",
             f"Every mesh of `../shared/data/meshes/` as one batch worker (no cap, "
             f"`--fit-iterations {PARAMS['fit_iterations']}`, killed after {args.seconds:g} s), "
             "run one at a time on the shared 2-core machine. *reported* is the worker's own "
             "`peak_memory_mb` (Linux `VmHWM` at its very end, thumbnail included; the summary's "
             "column); *GNU time* is `/usr/bin/time -f %M` around it (the kernel's maximum "
             "resident set of the finished process tree).", "",
             "| mesh | outcome | reported MiB | GNU time MiB | reported / time | wall s |",
             "|---|---|---|---|---|---|"]
    ratios = []
    for source, report, time_mb, wall in peaks:
        name = os.path.splitext(os.path.basename(source))[0]
        if report is None:  # no report; time's figure is then that of `timeout` alone
            lines.append(f"| {name} | killed at {args.seconds:g} s | | | | {wall:.1f} |")
            continue
        reported = report["peak_memory_mb"]
        ratios.append(reported / time_mb)
        lines.append(f"| {name} | {_stage(report)} | {reported:.1f} | {time_mb:.1f} | "
                     f"{reported / time_mb:.3f} | {wall:.1f} |")
    if ratios:
        lines += ["", f"Reported / GNU time over the {len(ratios)} meshes that finished: "
                  f"{min(ratios):.3f} to {max(ratios):.3f}."]
    lines += ["", f"## The cap at {args.share:g} of each solid's peak", "",
              "`batch MESH --memory-limit CAP --fit-iterations 10`: the row, the resident memory "
              "when the batch stopped the worker (its summary peak) and the time to the stop "
              "against the uncapped run.", "",
              "| mesh | uncapped peak MiB | cap MiB | status | message | peak at stop MiB | "
              "over the cap MiB | s capped | s uncapped |",
              "|---|---|---|---|---|---|---|---|---|"]
    for source, peak, wall, cap, row, capped_wall in caps:
        name = os.path.splitext(os.path.basename(source))[0]
        stop = float(row["peak_memory_mb"]) if row["peak_memory_mb"] else None
        lines.append(f"| {name} | {peak:.1f} | {cap} | {row['status']} | {row['message']} | "
                     f"{'' if stop is None else f'{stop:.1f}'} | "
                     f"{'' if stop is None else f'{stop - cap:.1f}'} | {capped_wall:.1f} | "
                     f"{wall:.1f} |")
    lines.append("")
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines))


if __name__ == "__main__":
    main()
