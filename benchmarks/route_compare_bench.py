# SPDX-License-Identifier: LGPL-2.1-or-later
"""The polycube layout against the paired decimation at the same face count, as solids.

Usage::

    .venv/bin/python benchmarks/route_compare_bench.py [--meshes DIR ...] [--only NAME ...]
                                                       [--modes single auto] [--timeout S]

For every mesh (default: the dev meshes and the generated SIMP designs in
``benchmarks/simp_unseen``) and parts mode, ``reconstruct`` runs at default parameters to a STEP
file; where it takes the polycube route, it runs again with ``--base-mesh-method decimation
--target-faces N`` (N: the layout's face count), and the independent
``../shared/tools/evaluate.py`` measures both STEP files (symmetric mean and maximum distance
as fractions of the target's diagonal, volume outside the target, validity). Each run is a
process of its own. Writes ``benchmarks/ROUTE_COMPARE_RESULTS.md`` and
``benchmarks/route_compare_results.json``; rows of meshes and modes not run are kept from the
last run.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEV_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
SIMP_MESHES = os.path.join(HERE, "simp_unseen")
EVALUATE = os.path.join(REPO, "..", "shared", "tools", "evaluate.py")
RESULTS_JSON = os.path.join(HERE, "route_compare_results.json")
RESULTS_MD = os.path.join(HERE, "ROUTE_COMPARE_RESULTS.md")
MESH_EXTENSIONS = (".stl", ".obj", ".ply", ".off")


def run_route(path, mode, extra, timeout):
    """``reconstruct`` to STEP and evaluate.py on it: dict with ``route``, ``faces``,
    ``extraordinary_vertices``, ``seconds`` and, when a STEP was written, ``valid``,
    ``mean``, ``max``, ``outside`` (fractions), or ``error``."""
    with tempfile.TemporaryDirectory(prefix="route-compare-") as tmp:
        step, report = os.path.join(tmp, "result.step"), os.path.join(tmp, "report.json")
        started = time.perf_counter()
        try:
            done = subprocess.run([sys.executable, "-m", "polycube_wb", "reconstruct", path,
                                   "-o", step, "--report", report, "--parts", mode, *extra],
                                  cwd=REPO, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"error": f"timeout after {timeout} s"}
        row = {"seconds": round(time.perf_counter() - started, 1)}
        if os.path.exists(report):
            with open(report, encoding="utf-8") as handle:
                base = json.load(handle).get("base_mesh") or {}
            row.update(route=base.get("method"), faces=base.get("faces"),
                       extraordinary_vertices=base.get("extraordinary_vertices"))
        if done.returncode != 0:
            row["error"] = done.stderr.strip()[-300:]
            return row
        evaluated = subprocess.run([sys.executable, EVALUATE, "--target", path, "--result", step],
                                   capture_output=True, text=True)
        try:
            metrics = json.loads(evaluated.stdout)
        except ValueError:
            row["error"] = evaluated.stderr.strip()[-300:]
            return row
        symmetric = metrics["distance"]["symmetric"]
        row.update(valid=bool(metrics["brep"]["is_valid"]), mean=symmetric["mean_frac"],
                   max=symmetric["max_frac"],
                   outside=metrics["containment"]["outside_fraction"])
        return row


def compare(path, mode, timeout):
    """One mesh and parts mode: the default run and, on the polycube route, the decimation
    at the same face count."""
    layout = run_route(path, mode, [], timeout)
    row = {"mesh": os.path.basename(path), "mode": mode, "default": layout, "decimation": None}
    if layout.get("route") == "polycube" and layout.get("faces"):
        row["decimation"] = run_route(path, mode, ["--base-mesh-method", "decimation",
                                                   "--target-faces", str(layout["faces"])],
                                      timeout)
    return row


def _ratio(row, key):
    """The layout's figure over the decimation's (None where either is missing)."""
    a, b = row["default"].get(key), (row["decimation"] or {}).get(key)
    return None if a is None or not b else a / b


def _pct(value, digits=2):
    return "–" if value is None else f"{100 * value:.{digits}f}"


def _route_cells(run):
    if run is None:
        return ["–"] * 6
    return [str(run.get("faces", "–")), str(run.get("extraordinary_vertices", "–")),
            _pct(run.get("mean"), 3), _pct(run.get("max")), _pct(run.get("outside"), 3),
            {True: "yes", False: "NO"}.get(run.get("valid"), run.get("error", "–")[:60])]


def markdown(rows, meta):
    """The results table (str)."""
    lines = ["# Polycube layout against paired decimation at the same face count", "",
             "Written by `benchmarks/route_compare_bench.py`; do not edit by hand.", "",
             f"- Last run: {meta['date']}, commit {meta['commit']}, load (1 min) {meta['load']} "
             "at start (rows of meshes not in it are kept from earlier runs); every run a process "
             "of its own at default parameters (`exact` export).",
             "- `default`: the route `reconstruct` takes; where that is the polycube layout, "
             "`decimation` is the paired decimation with `--target-faces` set to the layout's "
             "face count. Distances: `../shared/tools/evaluate.py`'s symmetric mean and maximum, "
             "% of the target's diagonal; `outside`: % of the target's volume outside the solid.",
             "- `ratio`: the layout's figure over the decimation's (below 1: the layout is "
             "closer).", "",
             "| mesh | parts | route | faces | EVs | mean % | max % | outside % | valid "
             "| dec. faces | dec. EVs | dec. mean % | dec. max % | dec. outside % | dec. valid "
             "| ratio mean | ratio max |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in sorted(rows, key=lambda r: (r["mesh"], r["mode"])):
        mean, top = _ratio(row, "mean"), _ratio(row, "max")
        lines.append("| " + " | ".join(
            [f"`{row['mesh']}`", row["mode"], str(row["default"].get("route", "–"))]
            + _route_cells(row["default"]) + _route_cells(row["decimation"])
            + ["–" if mean is None else f"{mean:.2f}", "–" if top is None else f"{top:.2f}"])
            + " |")
    compared = [r for r in rows if _ratio(r, "mean") is not None and _ratio(r, "max")]
    if compared:
        lines += ["", f"Median over the {len(compared)} polycube rows: ratio of the mean "
                  f"{statistics.median(_ratio(r, 'mean') for r in compared):.2f}, of the "
                  f"maximum {statistics.median(_ratio(r, 'max') for r in compared):.2f}."]
    return "\n".join(lines) + "\n"


def _meta():
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()
    return {"date": time.strftime("%Y-%m-%d"), "commit": commit,
            "load": round(os.getloadavg()[0], 2)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", nargs="+", default=[DEV_MESHES, SIMP_MESHES])
    parser.add_argument("--only", nargs="*", default=None,
                        help="mesh file names, with or without extension")
    parser.add_argument("--modes", nargs="+", default=["single"], choices=["single", "auto"])
    parser.add_argument("--timeout", type=float, default=900)
    args = parser.parse_args(argv)
    paths = sorted(os.path.join(folder, name) for folder in args.meshes
                   for name in os.listdir(folder) if name.endswith(MESH_EXTENSIONS))
    if args.only is not None:
        wanted = set(args.only)
        paths = [p for p in paths if os.path.basename(p) in wanted
                 or os.path.splitext(os.path.basename(p))[0] in wanted]
    kept = []
    if os.path.exists(RESULTS_JSON):
        with open(RESULTS_JSON, encoding="utf-8") as handle:
            kept = json.load(handle)["rows"]
    meta = _meta()
    rows = {(r["mesh"], r["mode"]): r for r in kept}
    for path in paths:
        for mode in args.modes:
            row = compare(path, mode, args.timeout)
            rows[(row["mesh"], mode)] = row
            print(row["mesh"], mode, row["default"].get("route"), row["default"].get("faces"),
                  flush=True)
            with open(RESULTS_JSON, "w", encoding="utf-8") as handle:
                json.dump({"meta": meta, "rows": list(rows.values())}, handle, indent=1)
            with open(RESULTS_MD, "w", encoding="utf-8") as handle:
                handle.write(markdown(list(rows.values()), meta))


if __name__ == "__main__":
    main()
