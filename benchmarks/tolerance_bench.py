# SPDX-License-Identifier: LGPL-2.1-or-later
"""``--tolerance`` on the dev meshes: each run meets the tolerance it was given or says why.

Usage::

    .venv/bin/python benchmarks/tolerance_bench.py [--meshes DIR] [--only NAME ...]
                                                   [--tolerances 0.01 0.005] [--timeout SECONDS]

Each case runs exactly as a user would, in its own process with a timeout::

    .venv/bin/python -m polycube_wb reconstruct MESH -o OUT.step --report OUT.json
        --tolerance T

(``T`` a fraction of the target's bounding-box diagonal; default parameters otherwise, so the
inside fit). From the report: the refinement rounds (faces, largest and mean deviation as the
fit measures them), whether the tolerance was met and why the refinement stopped, the fit and
total seconds. The STEP file is then judged by the independent ``../shared/tools/evaluate.py``:
B-rep validity, the largest two-sided distance (a sampled Hausdorff estimate, fraction of the
diagonal) against ``T``, and the volume outside the target. Writes
``benchmarks/TOLERANCE_RESULTS.md`` and ``benchmarks/tolerance_results.json``.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
from unseen_bench import SHARED_TOOLS, _evaluation_cells, _fmt, _json_tool  # noqa: E402

DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
MESHES = ("to_simp_cantilever.stl", "to_simp_lbracket.stl", "to_simp_mbb.stl",
          "to_simp_pylon.stl", "idler_riser.stl", "gripper_domain.stl", "polycube_bone.obj",
          "tray_bottom.stl")
"""Dev meshes that reach a solid, SIMP results first (``--only`` picks a few)."""
TOLERANCES = (0.01, 0.005)
RESULTS_JSON = os.path.join(HERE, "tolerance_results.json")
RESULTS_MD = os.path.join(HERE, "TOLERANCE_RESULTS.md")


def run_case(mesh, tolerance, timeout):
    """One mesh at one tolerance: CLI run and independent evaluation (dict row)."""
    row = {"mesh": os.path.basename(mesh), "tolerance": tolerance}
    with tempfile.TemporaryDirectory(prefix="tolerance-bench-") as tmp:
        step, report_path = os.path.join(tmp, "result.step"), os.path.join(tmp, "report.json")
        cmd = [sys.executable, "-m", "polycube_wb", "reconstruct", mesh, "-o", step,
               "--report", report_path, "--tolerance", repr(tolerance)]
        started = time.perf_counter()
        try:
            done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=timeout)
            row["exit_code"] = done.returncode
            row["stderr"] = done.stderr.strip()[-300:]
        except subprocess.TimeoutExpired:
            row["exit_code"], row["stderr"] = None, f"timed out after {timeout} s"
        row["seconds"] = round(time.perf_counter() - started, 1)
        if os.path.exists(report_path):
            with open(report_path, encoding="utf-8") as handle:
                report = json.load(handle)
            fit = report.get("fit", {})
            row["refinement"] = fit.get("tolerance")
            row["fit_seconds"] = report.get("stages", {}).get("fit", {}).get("seconds")
            row["fit_cpu_seconds"] = report.get("stages", {}).get("fit", {}).get("cpu_seconds")
            row["base_faces"] = report.get("base_mesh", {}).get("faces")
        if os.path.exists(step):
            row["evaluation"], err = _json_tool([os.path.join(SHARED_TOOLS, "evaluate.py"),
                                                 "--target", mesh, "--result", step], timeout)
            if err:
                row["evaluation_error"] = err
    return row


def markdown(rows, meta):
    """The results page (str)."""
    lines = ["# Tolerance-driven refinement (`benchmarks/tolerance_bench.py`)", "",
             "Written by `benchmarks/tolerance_bench.py`; do not edit by hand.", "",
             f"- Date: {meta['date']}; commit {meta['commit']}; load (1 min) at start "
             f"{meta['load']}; every case in its own process (timeout {meta['timeout']} s).",
             "- `T`: `--tolerance`, a fraction of the target's bounding-box diagonal; default "
             "parameters otherwise (inside fit). Rounds: faces / largest deviation / mean "
             "deviation of each fit, as the refinement measures them (fractions of the "
             "diagonal). Judged independently: `evaluate.py` on the STEP file (valid closed "
             "single solid; symmetric mean and max distance, the max a sampled Hausdorff "
             "estimate; fraction of the result's volume outside the target).", "",
             "| mesh | T | base faces | rounds (faces / max / mean) | met | why it stopped | "
             "fit s (CPU s) | total s | STEP valid | evaluate mean | evaluate max | "
             "evaluate max <= T | outside |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        refinement = row.get("refinement") or {}
        rounds = "; ".join(f"{r['faces']} / {r['max_deviation']:.4f} / {r['mean_deviation']:.4f}"
                           for r in refinement.get("rounds", []))
        valid, mean, largest, outside = _evaluation_cells(row)
        measured = ((row.get("evaluation") or {}).get("distance") or {}).get(
            "symmetric", {}).get("max_frac")
        within = "-" if measured is None else ("yes" if measured <= row["tolerance"] else "no")
        met = refinement.get("met")
        lines.append(
            f"| `{row['mesh']}` | {row['tolerance']:g} | {_fmt(row.get('base_faces'))} | "
            f"{rounds or '-'} | {'-' if met is None else ('yes' if met else 'no')} | "
            f"{refinement.get('reason') or row.get('stderr') or '-'} | "
            f"{_fmt(row.get('fit_seconds'), 3)} ({_fmt(row.get('fit_cpu_seconds'), 3)}) | "
            f"{row['seconds']} | {valid} | {mean} | {largest} | {within} | {outside} |")
    met = sum(1 for row in rows if (row.get("refinement") or {}).get("met"))
    lines += ["", f"Tolerance met (by the fit's own measure) on {met} of {len(rows)} cases; "
              "where it was not, the reason column says why (the report's `fit.tolerance.reason`)."]
    return "\n".join(lines) + "\n"


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--tolerances", nargs="*", type=float, default=list(TOLERANCES))
    parser.add_argument("--timeout", type=float, default=900.0)
    args = parser.parse_args(argv)
    names = [m for m in MESHES if not args.only or os.path.splitext(m)[0] in args.only]
    meta = {"date": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                     capture_output=True, text=True).stdout.strip(),
            "load": round(os.getloadavg()[0], 2), "timeout": args.timeout}
    rows = []
    for name in names:
        for tolerance in args.tolerances:
            rows.append(run_case(os.path.join(args.meshes, name), tolerance, args.timeout))
            print(json.dumps({k: rows[-1].get(k) for k in ("mesh", "tolerance", "seconds",
                                                            "exit_code")}), flush=True)
    with open(RESULTS_JSON, "w", encoding="utf-8") as handle:
        json.dump({"meta": meta, "rows": rows}, handle, indent=1)
    with open(RESULTS_MD, "w", encoding="utf-8") as handle:
        handle.write(markdown(rows, meta))


if __name__ == "__main__":
    main(sys.argv[1:])
