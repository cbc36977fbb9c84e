# SPDX-License-Identifier: LGPL-2.1-or-later
"""Scale benchmark: the same two designs at 15 thousand to 2.4 million triangles, time and
peak memory per stage, and whether the cage and the fit stay the same.

Usage::

    .venv/bin/python benchmarks/scale_bench.py [--cases NAME ...] [--out benchmarks]

Each case is a dev mesh refined by uniform midpoint subdivision (every triangle into four,
``levels`` times: the surface is unchanged, only finer), written once as a binary STL under
``benchmarks/tmp/scale/`` and run through the command line (``reconstruct -o STEP --report``)
with default parameters, in a process of its own. Per stage the report gives wall and CPU
seconds and the process's peak resident memory so far; the run's own wall time and the
report's ``brep`` (valid, closed) and ``fit`` figures say whether the solid and its deviation
match the coarsest version of the same design. ``../shared/tools/evaluate.py`` then measures each
STEP against the design's unrefined mesh (the same surface, so every case is measured by the same
samples of it), the resolution-independent comparison of the deviation. Writes ``SCALE_RESULTS.md``,
``scale_results.json`` and ``images/scale_time.png`` (log-log: seconds against triangles)
into ``--out``, keeping the cases of an earlier run that ``--cases`` leaves out.
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
sys.path.insert(0, REPO)
MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
CACHE = os.path.join(HERE, "tmp", "scale")

DESIGNS = {
    # design: (mesh file, midpoint subdivision levels of each case)
    "cantilever": (os.path.join(MESHES, "to_simp_cantilever.stl"), (0, 1, 2, 3)),
    "torsion_arm": (os.path.join(MESHES, "to_simp_torsion_arm_fine3.stl"), (0, 1, 2)),
}
STAGES = ("intake", "parts", "frames", "labeling", "basemesh", "fit", "patches")
EVALUATE = os.path.join(REPO, "..", "shared", "tools", "evaluate.py")
TIMEOUT = 1800.0


def case_names():
    """``design_xN`` for every design and refinement (N = 4**levels times the triangles)."""
    return [f"{design}_x{4 ** levels}" for design, (_, all_levels) in DESIGNS.items()
            for levels in all_levels]


def refined_stl(design, levels):
    """Path of the design's mesh refined ``levels`` times (written once into ``CACHE``)."""
    import numpy as np
    import trimesh
    from trimesh.remesh import subdivide

    from core.mesh_io import read_triangle_soup
    from core.validate import merge_identical_vertices

    source = DESIGNS[design][0]
    if levels == 0:
        return source
    path = os.path.join(CACHE, f"{design}_x{4 ** levels}.stl")
    if not os.path.exists(path):
        os.makedirs(CACHE, exist_ok=True)
        vertices, faces = read_triangle_soup(source)
        vertices, faces, _ = merge_identical_vertices(vertices, faces)
        for _ in range(levels):
            vertices, faces = subdivide(vertices, faces)
        trimesh.Trimesh(np.asarray(vertices), np.asarray(faces), process=False).export(path)
    return path


def run_case(name):
    """Run one case through the CLI; returns its JSON-able figures."""
    design, factor = name.rsplit("_x", 1)
    levels = {4 ** k: k for k in DESIGNS[design][1]}[int(factor)]
    path = refined_stl(design, levels)
    row = {"case": name, "design": design, "levels": levels,
           "load_before": round(os.getloadavg()[0], 2)}
    with tempfile.TemporaryDirectory(prefix="scale_") as folder:
        step, report_path = os.path.join(folder, "out.step"), os.path.join(folder, "r.json")
        started = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "polycube_wb", "reconstruct", path, "-o", step,
                               "--report", report_path], cwd=REPO, capture_output=True,
                              text=True, timeout=TIMEOUT)
        row["wall_seconds"] = round(time.perf_counter() - started, 1)
        row["exit"] = done.returncode
        if done.returncode != 0:
            row["error"] = done.stderr.strip().splitlines()[-1][:200] if done.stderr else ""
        if os.path.exists(report_path):
            with open(report_path, encoding="utf-8") as handle:
                row.update(_figures(json.load(handle)))
        if done.returncode == 0 and os.path.exists(EVALUATE):
            row.update(_evaluated(DESIGNS[design][0], step))
    return row


def _evaluated(target, step):
    """``../shared/tools/evaluate.py``'s symmetric distances and volume outside of ``step``
    against ``target`` (percent of the diagonal and of the volume), or its error line."""
    checked = subprocess.run([sys.executable, EVALUATE, "--target", target, "--result", step],
                             cwd=REPO, capture_output=True, text=True, timeout=TIMEOUT)
    try:
        verdict = json.loads(checked.stdout)
        distance = verdict["distance"]["symmetric"]
        return {"evaluate_mean_pct": _percent(distance["mean_frac"]),
                "evaluate_max_pct": _percent(distance["max_frac"]),
                "evaluate_outside_pct": _percent(verdict["containment"]["outside_fraction"]),
                "evaluate_valid": bool(verdict["brep"]["is_valid"]
                                       and verdict["brep"]["all_shells_closed"])}
    except (ValueError, KeyError, TypeError):
        return {"evaluate_error": (checked.stdout.strip().splitlines() or [""])[-1][:200]}


def _figures(report):
    """The figures of a run report this benchmark tabulates."""
    stages = report.get("stages", {})
    figures = {"triangles": report["input"]["triangles"],
               "proxy_triangles": report["input"].get("proxy", {}).get("triangles"),
               "peak_mb": report.get("peak_memory_mb"),
               "stages": {name: {key: stages[name].get(key) for key in
                                 ("status", "seconds", "cpu_seconds", "peak_memory_mb")}
                          for name in STAGES if name in stages}}
    base, fit, brep = report.get("base_mesh", {}), report.get("fit", {}), report.get("brep", {})
    largest = [fit[key] for key in ("max_distance", "target_max_distance") if key in fit]
    figures.update({"route": base.get("method"), "faces": base.get("faces"),
                    "genus": base.get("genus"), "valid": brep.get("valid"),
                    "closed": brep.get("closed"),
                    "mean_pct": _percent(fit.get("mean_distance")),
                    "max_pct": _percent(max(largest) if largest else None),
                    "outside_pct": _percent(fit.get("outside_volume_fraction"))})
    return figures


def _percent(fraction):
    return None if fraction is None else round(100.0 * fraction, 3)


def markdown(rows):
    """SCALE_RESULTS.md: conditions, the per-stage table and the comparison with the coarsest
    version of each design."""
    lines = ["# Scale: the same designs from 15 thousand to 2.4 million triangles", "",
             "Written by `benchmarks/scale_bench.py`; do not edit by hand.", "",
             f"- Machine: {os.cpu_count()} cores; load average (1 min) before each case in the "
             "table. Each case is the design's dev mesh refined by midpoint subdivision (the same "
             "surface), run with `reconstruct -o STEP --report` at default parameters in a "
             "process of its own.",
             "- Stage columns: CPU seconds (what load does not add); `wall s`: the whole "
             "command, FreeCAD's solid and STEP included; `peak MiB`: the process's peak "
             "resident memory; `proxy`: triangles of the working surface the segmentation "
             "and base mesh ran on.",
             "- `faces`, `mean %`, `max %`: the cage and the fit's distances (% of the "
             "bounding-box diagonal; mean from the surface, max both ways, over samples and "
             "every target vertex, so a finer target is searched more finely); `vs x1`: faces "
             "and distances against the design's coarsest case (1.00 = the same).",
             "- `evaluate.py`: `../shared/tools/evaluate.py` on the STEP against the design's "
             "unrefined mesh (the same surface for every case): symmetric mean and maximum "
             "distance (% of the diagonal), volume outside (%), and both distances against the "
             "coarsest case.", "",
             "![seconds against triangles](images/scale_time.png)", "",
             "| case | triangles | proxy | load | " + " | ".join(STAGES)
             + " | wall s | peak MiB | route | faces | genus | valid closed | mean % | max % "
             "| outside % | vs x1: faces, mean, max | evaluate.py mean %, max %, outside % "
             "| evaluate.py vs x1: mean, max | exit |",
             "|" + "---|" * (len(STAGES) + 17)]
    first = {}
    for row in rows:
        if row.get("levels") == 0:
            first[row["design"]] = row
    for row in rows:
        stages = row.get("stages", {})
        cpu = [f"{stages[name]['cpu_seconds']:.1f}" if name in stages
               and stages[name].get("cpu_seconds") is not None else "–" for name in STAGES]
        lines.append("| " + " | ".join(
            [f"`{row['case']}`", str(row.get("triangles", "–")), str(row.get("proxy_triangles", "–")),
             str(row.get("load_before", "–"))] + cpu
            + [str(row.get("wall_seconds", "–")), str(row.get("peak_mb", "–")),
               str(row.get("route", "–")), str(row.get("faces", "–")), str(row.get("genus", "–")),
               "yes" if row.get("valid") and row.get("closed") else "no",
               str(row.get("mean_pct", "–")), str(row.get("max_pct", "–")),
               str(row.get("outside_pct", "–")), _versus(row, first.get(row["design"])),
               _evaluation(row), _versus_evaluated(row, first.get(row["design"])),
               str(row.get("exit", "–")) + (f" {row['error']}" if row.get("error") else "")])
            + " |")
    return "\n".join(lines) + "\n"


def _versus(row, base):
    if base is None or not row.get("faces") or not base.get("faces"):
        return "–"
    ratios = [row["faces"] / base["faces"]]
    for key in ("mean_pct", "max_pct"):
        ratios.append(row[key] / base[key] if row.get(key) and base.get(key) else float("nan"))
    return ", ".join(f"{value:.2f}" for value in ratios)


def _evaluation(row):
    if row.get("evaluate_error"):
        return row["evaluate_error"].replace("|", "/")
    if row.get("evaluate_max_pct") is None:
        return "–"
    return (f"{row['evaluate_mean_pct']}, {row['evaluate_max_pct']}, "
            f"{row['evaluate_outside_pct']}" + ("" if row.get("evaluate_valid") else " (invalid)"))


def _versus_evaluated(row, base):
    keys = ("evaluate_mean_pct", "evaluate_max_pct")
    if base is None or any(not row.get(key) or not base.get(key) for key in keys):
        return "–"
    return ", ".join(f"{row[key] / base[key]:.2f}" for key in keys)


def plot(rows, path):
    """Log-log plot of wall and summed CPU seconds against triangles, one line per design."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(6.4, 4.4), dpi=100)
    for design in DESIGNS:
        done = sorted((row for row in rows if row["design"] == design and row.get("triangles")),
                      key=lambda row: row["triangles"])
        if not done:
            continue
        x = [row["triangles"] for row in done]
        axes.loglog(x, [row["wall_seconds"] for row in done], "o-", label=f"{design}: wall")
        axes.loglog(x, [sum(s["cpu_seconds"] or 0 for s in row["stages"].values())
                        for row in done], "s--", label=f"{design}: CPU of the stages")
    axes.set_xlabel("target triangles")
    axes.set_ylabel("seconds")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path)
    plt.close(figure)


def main(argv=None):
    from core.output_files import write_json_atomic, write_text_atomic

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", choices=case_names(), default=case_names())
    parser.add_argument("--out", default=HERE)
    args = parser.parse_args(argv)
    os.makedirs(os.path.join(args.out, "images"), exist_ok=True)
    json_path = os.path.join(args.out, "scale_results.json")
    previous = {}
    if os.path.exists(json_path):
        with open(json_path, encoding="utf-8") as handle:
            previous = {row["case"]: row for row in json.load(handle)}
    for name in args.cases:
        print(f"scale: {name} ...", file=sys.stderr, flush=True)
        previous[name] = run_case(name)
        print(json.dumps(previous[name]), file=sys.stderr, flush=True)
    rows = [previous[name] for name in case_names() if name in previous]
    write_json_atomic(json_path, rows)
    plot(rows, os.path.join(args.out, "images", "scale_time.png"))
    write_text_atomic(os.path.join(args.out, "SCALE_RESULTS.md"), markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
