# SPDX-License-Identifier: LGPL-2.1-or-later
"""Crossings benchmark: does the fitted limit surface of every dev mesh cross itself?

Usage::

    .venv/bin/python benchmarks/crossings_bench.py [--only NAME ...] [--before OLD_TREE]
                                                   [--jobs 2] [--out benchmarks]

Every dev mesh (``../shared/data/meshes``) runs the whole pipeline with default parameters and
one part (``python -m polycube_wb reconstruct MESH -o X.step --report X.json``, one process
per mesh). Recorded per mesh: the exit code, the fit's figures from the report (crossing
triangle pairs of the fitted limit surface at the fit's level, those of the unfitted cage
when the fit still crosses, the refits and their crossing counts, base vertices held back,
fit seconds), whether the STEP was written or refused, and, for a written STEP, the
independent ``../shared/tools/evaluate.py`` figures (symmetric mean and max distance as
fractions of the bounding-box diagonal, volume outside the target). ``--before DIR`` runs
the pipeline up to the fit on an older checkout (``git archive COMMIT | tar -x -C DIR``) in
the same run, for its crossing count and fit seconds; the older STEP figures are taken from
``basemesh_results.json`` (the base-mesh benchmark's single-part rows, its commit recorded),
which ran the same evaluation.

Writes ``CROSSINGS_RESULTS.md`` and ``crossings_results.json`` into ``--out``. Run from an
exported tree (``git archive``), ``BENCH_COMMIT`` names the commit it was exported from and
``BENCH_SHARED`` the shared folder (default ``../shared`` of the checkout).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SHARED = os.environ.get("BENCH_SHARED") or os.path.join(REPO, "..", "shared")
MESHES = os.path.join(SHARED, "data", "meshes")
EVALUATE = os.path.join(SHARED, "tools", "evaluate.py")
NAMES = ("to_simp_cantilever.stl", "to_simp_lbracket.stl", "to_simp_mbb.stl", "to_simp_pylon.stl",
         "to_simp_torsion_arm.stl", "to_simp_torsion_arm_fine3.stl", "fandisk.obj",
         "featuretype.stl", "ge_bracket_domain.stl", "gripper_domain.stl", "idler_riser.stl",
         "octagonal_pocket.stl", "polycube_bone.obj", "polycube_mambo_b0.obj",
         "to_levelset_cantilever_tiny.stl", "tray_bottom.stl")
FIT_KEYS = ("self_intersections", "cage_self_intersections", "refit_crossings", "stiffened",
            "held_back", "rgp_held_back", "seconds", "mean_distance", "max_distance")


def run_one(tree, name):
    """Pipeline + evaluation of one mesh with the checkout ``tree``; a dict."""
    path = os.path.join(MESHES, name)
    with tempfile.TemporaryDirectory(prefix="crossings-bench-") as tmp:
        step, report_path = os.path.join(tmp, "x.step"), os.path.join(tmp, "x.json")
        started = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "polycube_wb", "reconstruct", path, "-o", step,
                               "--report", report_path], cwd=tree, capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": tree})
        row = {"exit": done.returncode, "seconds": round(time.perf_counter() - started, 1),
               "error": done.stderr.strip().splitlines()[-1][:400] if done.returncode else ""}
        if os.path.exists(report_path):
            with open(report_path, encoding="utf-8") as handle:
                report = json.load(handle)
            fit = report.get("fit", {})
            row["fit"] = {key: fit.get(key) for key in FIT_KEYS}
            row["base_method"] = report.get("base_mesh", {}).get("method")
            row["stages"] = {k: v["status"] for k, v in report["stages"].items()}
        row["step_written"] = os.path.exists(step)
        if row["step_written"]:
            evaluated = subprocess.run([sys.executable, EVALUATE, "--target", path, "--result", step],
                                       capture_output=True, text=True)
            try:
                row["evaluation"] = _figures(json.loads(evaluated.stdout))
            except ValueError:
                row["evaluation_error"] = evaluated.stderr[-300:]
    return row


BEFORE_FIT = """
import json, sys
from core.pipeline import reconstruct
report = reconstruct(sys.argv[1], stop_after="fit").report
fit = report.get("fit", {})
print(json.dumps({"fit": {key: fit.get(key) for key in %r},
                  "stages": {k: v["status"] for k, v in report["stages"].items()}}))
""" % (FIT_KEYS,)


def run_before(tree, name):
    """The older checkout's pipeline up to the fit on one mesh; a dict."""
    done = subprocess.run([sys.executable, "-c", BEFORE_FIT, os.path.join(MESHES, name)], cwd=tree,
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": tree})
    try:
        return json.loads(done.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return {"error": done.stderr[-300:]}


def basemesh_before(path):
    """name -> {"evaluation", "step_written"} of the base-mesh benchmark's single-part rows."""
    if not os.path.exists(path):
        return {}, None
    with open(path, encoding="utf-8") as handle:
        data = json.load(handle)
    rows = {}
    for row in data["rows"]:
        solid = row.get("solid") or {}
        if row.get("mode") != "single" or "evaluation" not in solid:
            continue
        rows[row["mesh"]] = {"step_written": solid.get("reached"),
                             "evaluation": _figures(solid["evaluation"])}
    return rows, data["meta"].get("commit")


def _figures(metrics):
    distance = metrics["distance"]
    there, back = distance["result_to_target"], distance["target_to_result"]
    return {"mean": 0.5 * (there["mean_frac"] + back["mean_frac"]),
            "max": max(there["max_frac"], back["max_frac"]),
            "outside": metrics["containment"]["outside_fraction"],
            "valid": metrics["brep"]["is_valid"] if "brep" in metrics else None}


def markdown(rows, meta, older):
    lines = ["# Crossings benchmark (`benchmarks/crossings_bench.py`)", "",
             f"Run {meta['date']} on 2 cores (load average at start {meta['load']:.2f}), commit "
             f"{meta['commit']}; before: crossings and fit seconds of {meta['before'] or 'not run'} "
             f"in the same run, STEP figures from `basemesh_results.json` (commit {meta['older']}, "
             "same evaluation). Every dev mesh, one part, "
             "default parameters, `reconstruct MESH -o X.step --report X.json`. Crossings: "
             "intersecting triangle pairs of the fitted limit surface at the fit's level (the "
             "report's `fit.self_intersections`); cage: those of the unfitted cage (reported when "
             "the fit still crosses). Distances by `../shared/tools/evaluate.py` on the STEP, "
             "fractions of the target's bounding-box diagonal (mean: both directions' means "
             "averaged; max: the larger); outside: volume fraction of the solid outside the target.",
             "", "| mesh | base mesh | crossings before | crossings after | cage crossings | refits "
             "(crossings after each fit) | STEP after | mean before | mean after | max before | "
             "max after | outside before | outside after | fit s before | fit s after |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in NAMES:
        if name not in rows:
            continue
        if "after" not in rows[name]:
            continue
        after, before = rows[name]["after"], rows[name].get("before") or {}
        fa, fb = after.get("fit", {}), before.get("fit", {})
        ea = after.get("evaluation", {})
        eb = older.get(name.rsplit(".", 1)[0], {}).get("evaluation", {})
        step = "written" if after.get("step_written") else f"refused (exit {after['exit']})"
        lines.append("| " + " | ".join([
            name.rsplit(".", 1)[0], str(after.get("base_method")), _n(fb.get("self_intersections")),
            _n(fa.get("self_intersections")), _n(fa.get("cage_self_intersections")),
            str(fa.get("refit_crossings")), step, _e(eb.get("mean")), _e(ea.get("mean")),
            _e(eb.get("max")), _e(ea.get("max")), _p(eb.get("outside")), _p(ea.get("outside")),
            _s(fb.get("seconds")), _s(fa.get("seconds"))]) + " |")
    refused = [n for n in NAMES if "after" in rows.get(n, {})
               and not rows[n]["after"].get("step_written")]
    lines += ["", "Refused (the fitted limit surface still crosses itself; exit 1, the report "
              "written):", ""]
    lines += [f"- {n}: `{rows[n]['after']['error']}`" for n in refused] or ["- none"]
    return "\n".join(lines) + "\n"


def _n(value):
    return "" if value is None else str(value)


def _e(value):
    return "" if value is None else f"{value:.2e}"


def _p(value):
    return "" if value is None else f"{100 * value:.2f}%"


def _s(value):
    return "" if value is None else f"{value:.1f}"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", choices=NAMES, default=None)
    parser.add_argument("--before", help="folder holding an older checkout (whole tree)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", default=HERE)
    args = parser.parse_args(argv)
    names = args.only or list(NAMES)
    commit = os.environ.get("BENCH_COMMIT") or subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip()
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load": os.getloadavg()[0],
            "commit": commit, "before": args.before}
    older, meta["older"] = basemesh_before(os.path.join(HERE, "basemesh_results.json"))
    jobs = []
    for name in names:
        jobs.append((name, "after", lambda name=name: run_one(REPO, name)))
        if args.before:
            tree = os.path.abspath(args.before)
            jobs.append((name, "before", lambda name=name: run_before(tree, name)))
    rows = {}
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for (name, which, _), row in zip(jobs, pool.map(lambda job: job[2](), jobs)):
            rows.setdefault(name, {})[which] = row
            print(name, which, row.get("fit", {}).get("self_intersections"), row.get("exit"),
                  flush=True)
            _write(args.out, rows, meta, older)


def _write(folder, rows, meta, older):
    """Both result files, rewritten after every finished run (a stopped run keeps its rows)."""
    with open(os.path.join(folder, "crossings_results.json"), "w", encoding="utf-8") as handle:
        json.dump({"meta": meta, "rows": rows}, handle, indent=1)
    with open(os.path.join(folder, "CROSSINGS_RESULTS.md"), "w", encoding="utf-8") as handle:
        handle.write(markdown(rows, meta, older))


if __name__ == "__main__":
    main()
