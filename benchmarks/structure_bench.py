# SPDX-License-Identifier: LGPL-2.1-or-later
"""Structure benchmark: the restructured pipeline gives the same reports.

Usage::

    .venv/bin/python benchmarks/structure_bench.py [--base REV] [--meshes DIR]
                                                   [--timeout SECONDS] [--repeat N]

The tree of commit ``REV`` (default: where this branch left ``main``) is extracted with ``git archive`` into a
temporary folder; every case then runs ``core.pipeline.reconstruct`` once in that tree and
once in this one, each in its own process (the same ``.venv`` interpreter), and the two
reports are compared with every timing and memory figure removed (``seconds``,
``cpu_seconds``, ``total_seconds``, ``measure_seconds``, ``peak_memory_mb``). The import time of
``core.pipeline`` (what the command line and FreeCAD's start-up pay) is the median of
``--repeat`` fresh processes per tree. Writes ``benchmarks/STRUCTURE_RESULTS.md``.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
RESULTS = os.path.join(HERE, "STRUCTURE_RESULTS.md")
CASES = (
    ("to_levelset_cantilever_tiny.stl", "solid", {}),
    ("to_levelset_cantilever_tiny.stl", "fit", {"fit_mode": "best-fit", "tolerance_mm": 0.1}),
    ("to_simp_cantilever.stl", "fit", {}),
    ("to_simp_cantilever.stl", "basemesh", {"parts": "auto"}),
    ("fandisk.obj", "basemesh", {}),
    ("idler_riser.stl", "basemesh", {}),
    ("polycube_bone.obj", "basemesh", {"parts": "auto"}),
    ("to_simp_pylon.stl", "basemesh", {}),
)
"""(mesh, --stop-after, parameters): every stage, the tolerance refinement, automatic parts,
genus 3, and a mesh whose polycube layout fails (the base-mesh fallback's report)."""
VOLATILE = {"seconds", "cpu_seconds", "total_seconds", "measure_seconds", "peak_memory_mb"}

RUN_CASE = """
import json, sys
from core.pipeline import reconstruct
result = reconstruct(sys.argv[1], json.loads(sys.argv[2]), stop_after=sys.argv[3])
print(json.dumps(result.report))
"""


def stable(value):
    """``value`` (a report) without its timing and memory figures."""
    if isinstance(value, dict):
        return {key: stable(item) for key, item in value.items() if key not in VOLATILE}
    if isinstance(value, list):
        return [stable(item) for item in value]
    return value


def differences(a, b, where=""):
    """Paths (``section.key``) at which two reports differ, at most 10."""
    if isinstance(a, dict) and isinstance(b, dict):
        found = [f"{where}{key} (only in one)" for key in sorted(set(a) ^ set(b))]
        for key in a.keys() & b.keys():
            found += differences(a[key], b[key], f"{where}{key}.")
        return found[:10]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{where}{i}.")][:10]
    return [] if a == b else [where.rstrip(".") or "(root)"]


def run_in(tree, path, stop_after, params, timeout):
    """The stable report of one case run in ``tree``, or ``{"error": ...}``."""
    started = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-c", RUN_CASE, path, json.dumps(params), stop_after],
                              cwd=tree, capture_output=True, text=True, timeout=timeout,
                              env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout} s"}, time.perf_counter() - started
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1]}, time.perf_counter() - started
    return stable(json.loads(done.stdout.strip().splitlines()[-1])), time.perf_counter() - started


def import_seconds(tree, repeat):
    """Median wall time of ``import core.pipeline`` in a fresh process (s)."""
    times = []
    for _ in range(repeat):
        done = subprocess.run([sys.executable, "-c", "import time; t = time.perf_counter(); "
                               "import core.pipeline; print(time.perf_counter() - t)"],
                              cwd=tree, capture_output=True, text=True, check=True,
                              env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
        times.append(float(done.stdout))
    return statistics.median(times)


def extract(rev, folder):
    """Extract commit ``rev`` of this repository into ``folder``; returns its short hash."""
    commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=REPO, capture_output=True,
                            text=True, check=True).stdout.strip()
    archive = os.path.join(folder, "base.tar")
    subprocess.run(["git", "archive", "-o", archive, commit], cwd=REPO, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(os.path.join(folder, "tree"))
    return commit


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default=None,
                        help="commit to compare with (default: the merge base with main)")
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                          text=True, check=True).stdout.strip()
    meta = {"date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "load": round(os.getloadavg()[0], 2)}
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        rev = args.base or subprocess.run(["git", "merge-base", "HEAD", "main"], cwd=REPO,
                                          capture_output=True, text=True,
                                          check=True).stdout.strip()
        base = extract(rev, folder)
        base_tree = os.path.join(folder, "tree")
        imports = {"base": import_seconds(base_tree, args.repeat),
                   "head": import_seconds(REPO, args.repeat)}
        for name, stop_after, params in CASES:
            path = os.path.abspath(os.path.join(args.meshes, name))
            old, old_s = run_in(base_tree, path, stop_after, params, args.timeout)
            new, new_s = run_in(REPO, path, stop_after, params, args.timeout)
            stages = new.get("stages", {})
            reached = [stage for stage, entry in stages.items() if entry["status"] == "ok"]
            rows.append({"mesh": name, "stop_after": stop_after, "params": params,
                         "reached": reached[-1] if reached else "-",
                         "error": old.get("error") or new.get("error"),
                         "differences": differences(old, new), "seconds": (old_s, new_s)})
            print(f"{name} {stop_after} {params}: {len(rows[-1]['differences'])} differences",
                  flush=True)
    write_results(rows, imports, meta, base, head)


def write_results(rows, imports, meta, base, head):
    same = sum(1 for row in rows if not row["differences"] and not row["error"])
    lines = ["# Structure benchmark", "",
             "Written by `benchmarks/structure_bench.py`; do not edit by hand.", "",
             f"- Date: {meta['date']}; load (1 min) at start {meta['load']}; base commit "
             f"{base}, this branch at {head}; every run in its own process.",
             "- Reports compared without their timing and memory figures "
             f"({', '.join(sorted(VOLATILE))}).", "",
             f"Identical reports on **{same} of {len(rows)}** cases.", "",
             "| mesh | --stop-after | parameters | last stage ok | differences | run s (base / branch) |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        params = ", ".join(f"{k}={v}" for k, v in row["params"].items()) or "defaults"
        verdict = (f"error: {row['error']}" if row["error"] else
                   "none" if not row["differences"] else ", ".join(row["differences"]))
        lines.append(f"| `{row['mesh']}` | {row['stop_after']} | {params} | {row['reached']} | "
                     f"{verdict} | {row['seconds'][0]:.1f} / {row['seconds'][1]:.1f} |")
    lines += ["", f"`import core.pipeline` in a fresh process (median of runs): base "
              f"{imports['base'] * 1000:.0f} ms, branch {imports['head'] * 1000:.0f} ms.", ""]
    with open(RESULTS, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
