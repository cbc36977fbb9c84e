# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh benchmark: every dev mesh, one part and automatic parts.

Usage::

    .venv/bin/python benchmarks/basemesh_bench.py [--meshes DIR] [--only NAME ...]
                                                  [--solid NAME ...] [--timeout SECONDS]
                                                  [--modes single auto]
                                                  [--base-mesh-method auto|polycube|decimation]
                                                  [--update]

Writes ``benchmarks/BASEMESH_RESULTS.md``, ``benchmarks/basemesh_results.json`` and a PNG of
each cage over its target (``benchmarks/images/basemesh_*.png``). Every case runs in its own
process with a timeout. Per case: the stage reached, base faces against the budget, quads,
extraordinary vertices, valence range, genus against the target's, inverted faces (limit
normal more than 90 degrees from the target's, :mod:`core.quadmesh.orientation`), crossing
triangle pairs of the level-2 limit surface, and the labeling and base-mesh seconds (the base
mesh also in CPU seconds, which the load of other processes does not add). For the
meshes named after ``--solid`` the whole pipeline then writes a STEP file, judged by the
independent ``../shared/tools/evaluate.py``. Rows are kept per mesh, parts mode and requested
``--base-mesh-method`` route, so the routes can be compared side by side (``--update``).
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
from core.params import BASE_MESH_METHODS  # noqa: E402
DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
EVALUATE = os.path.join(REPO, "..", "shared", "tools", "evaluate.py")
MODES = ("single", "auto")

RENDER_FACES = 30000
"""Target triangles drawn under the cage (a random subset of larger targets)."""


def run_case(path, mode, method, out_json, image, solid):
    """One mesh in one parts mode and base-mesh route; writes a JSON dict to ``out_json``."""
    import numpy as np

    from core.pipeline import reconstruct
    from core.subdivision.limit_crossings import count_limit_self_intersections
    from core.quadmesh.orientation import inverted_faces

    started = time.perf_counter()
    result = reconstruct(path, {"parts": mode, "base_mesh_method": method}, stop_after="basemesh")
    report = result.report
    row = {"stages": {k: v["status"] for k, v in report["stages"].items()},
           "messages": {k: v["message"] for k, v in report["stages"].items() if v["message"]},
           "labeling_valid": report.get("labeling", {}).get("valid"),
           "labeling_seconds": report["stages"].get("labeling", {}).get("seconds"),
           "basemesh_seconds": report["stages"].get("basemesh", {}).get("seconds"),
           "basemesh_cpu_seconds": report["stages"].get("basemesh", {}).get("cpu_seconds"),
           "input_genus": report["input"]["genus"], "triangles": report["input"]["triangles"]}
    base = result.state.cage
    if base is not None:
        info = report["base_mesh"]
        target = result.state.intake.target
        row["base_mesh"] = {key: info.get(key) for key in (
            "method", "fallback_reason", "faces", "quads", "triangles",
            "extraordinary_vertices", "min_valence", "max_valence", "genus", "target_faces",
            "within_budget", "minimum_reason", "scale", "solver_status", "collapsed_sides",
            "side_directions_flipped", "rectangles", "relabelled_area", "crossing_reason",
            "candidates", "segmentation",
            "layout_inverted_faces")}
        row["inverted_faces"] = int(inverted_faces(base, target.vertices, target.faces).sum())
        row["limit_self_intersections"] = count_limit_self_intersections(base, 2)
        render_cage(image, target.vertices, target.faces, base,
                    f"{os.path.basename(path)} ({mode}): {base.n_faces} faces")
        if solid:
            row["solid"] = run_solid(path, mode, method)
    row["seconds"] = round(time.perf_counter() - started, 2)
    with open(out_json, "w", encoding="utf-8") as handle:
        json.dump(row, handle)


def run_solid(path, mode, method):
    """The whole pipeline to STEP, then the independent evaluation (dict)."""
    with tempfile.TemporaryDirectory(prefix="basemesh-bench-") as tmp:
        step = os.path.join(tmp, "result.step")
        started = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "polycube_wb", "reconstruct", path, "-o", step,
                               "--parts", mode, "--base-mesh-method", method], cwd=REPO, capture_output=True, text=True)
        seconds = round(time.perf_counter() - started, 2)
        if done.returncode != 0:
            return {"reached": False, "seconds": seconds, "error": done.stderr.strip()[-300:]}
        evaluated = subprocess.run([sys.executable, EVALUATE, "--target", path, "--result", step],
                                   capture_output=True, text=True)
        try:
            metrics = json.loads(evaluated.stdout)
        except ValueError:
            return {"reached": True, "seconds": seconds, "error": evaluated.stderr[-300:]}
        return {"reached": True, "seconds": seconds, "evaluation": metrics}


def render_cage(path, V, F, base, title):
    """PNG of the cage (blue quads, black edges) over the target (light grey), two views."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    rng = np.random.default_rng(0)
    shown = F if len(F) <= RENDER_FACES else F[rng.choice(len(F), RENDER_FACES, replace=False)]
    quads = [base.vertices[base.face_vertices[a:b]]
             for a, b in zip(base.face_offsets[:-1], base.face_offsets[1:])]
    fig = plt.figure(figsize=(12, 6))
    centre = V.mean(axis=0)
    radius = float(np.ptp(V, axis=0).max()) / 2
    for k, (elev, azim) in enumerate(((25, 35), (-25, 215))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        polys = list(V[shown]) + list(quads)
        colours = ([(0.8, 0.8, 0.8, 0.12)] * len(shown)) + ([(0.25, 0.45, 0.85, 0.55)] * len(quads))
        edges = ([(0, 0, 0, 0)] * len(shown)) + ([(0, 0, 0, 0.8)] * len(quads))
        ax.add_collection3d(Poly3DCollection(polys, facecolors=colours, edgecolors=edges,
                                             linewidths=0.3))
        ax.set_xlim(centre[0] - radius, centre[0] + radius)
        ax.set_ylim(centre[1] - radius, centre[1] + radius)
        ax.set_zlim(centre[2] - radius, centre[2] + radius)
        ax.view_init(elev, azim)
        ax.set_axis_off()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def markdown(rows, meta):
    lines = ["# Base-mesh benchmark", "",
             "Written by `benchmarks/basemesh_bench.py`; do not edit by hand.", "",
             f"- Date: {meta['date']}; commit {meta['commit']}; load (1 min) at start "
             f"{meta['load']}; every case in its own process (timeout {meta['timeout']} s)."
             + _other_runs(rows, meta)
             + (f" {meta['note']}." if "note" in meta else ""),
             "- Budget: `--target-faces 300` (met when within 25%); genus is the base mesh's "
             "against the target's; inverted: base faces whose limit normal points more than 90 "
             "degrees from the target's at the closest point; crossings: intersecting triangle "
             "pairs of the level-2 limit surface of the unfitted cage.", ""]
    reached = [r for r in rows if r.get("base_mesh")]
    lines.append(f"Base mesh reached on **{len(reached)} of {len(rows)}** cases.")
    lines.append("")
    header = ["mesh", "parts", "asked", "labeling", "base mesh", "route", "faces", "budget met", "quads %", "EVs",
              "valence", "genus (target)", "inverted", "crossings", "labeling s", "base mesh s",
              "base mesh CPU s"]
    with_solid = any("solid" in r for r in rows)
    if with_solid:
        header += ["STEP valid", "mean dist %", "max dist %"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        b = r.get("base_mesh")
        status = r.get("stages", {}).get("basemesh", r.get("error", "?"))
        cells = [f"`{r['mesh']}`", r["mode"], r.get("method", "auto"),
                 "valid" if r.get("labeling_valid") else "invalid", status]
        if b:
            cells += [b.get("method") or "polycube", str(b["faces"]), "yes" if b["within_budget"] else "no (minimum)",
                      f"{100.0 * b['quads'] / b['faces']:.0f}", str(b["extraordinary_vertices"]),
                      f"{b['min_valence']}-{b['max_valence']}",
                      f"{b['genus']} ({r['input_genus']})", str(r["inverted_faces"]),
                      str(r["limit_self_intersections"])]
        else:
            cells += ["–"] * 9
        cells += [str(r.get("labeling_seconds", "–")), str(r.get("basemesh_seconds", "–")),
                  str(r.get("basemesh_cpu_seconds", "–"))]
        if with_solid:
            metrics = (r.get("solid") or {}).get("evaluation", {})
            symmetric = metrics.get("distance", {}).get("symmetric", {})
            valid = metrics.get("brep", {}).get("is_valid")
            cells += ["–" if valid is None else ("yes" if valid else "no"),
                      _percent(symmetric.get("mean_frac")), _percent(symmetric.get("max_frac"))]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "## Both routes", "",
              "The candidates of `base_mesh.candidates`: the polycube layout (faces and "
              "extraordinary vertices where built, else the size of its smallest layout found "
              "or bounded) and the paired decimation (where it was built). The layout is kept "
              "within 1.5 times the budget unless the decimation's cage has fewer flaws: no "
              "self-crossing of its limit surface where the layout's crosses itself, else fewer "
              "inverted faces after the repair. Crossings: self-crossing triangle pairs of the "
              "level-2 limit surface of the cage.", "",
              "| mesh | parts | genus | polycube faces | polycube EVs | polycube inverted "
              "after repair | polycube crossings | decimation faces | decimation EVs | "
              "decimation crossings | route |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in reached:
        b = r["base_mesh"]
        candidates = b.get("candidates") or {}
        poly = candidates.get("polycube") or {}
        deci = candidates.get("paired decimation") or {}
        poly_faces = (str(poly.get("faces")) if poly.get("built")
                      else (f"> rule ({poly['faces']})" if poly.get("faces") else
                            ("failed" if poly else "–")))
        lines.append("| " + " | ".join([
            f"`{r['mesh']}`", r["mode"], str(r["input_genus"]), poly_faces,
            str(poly.get("extraordinary_vertices", "–")),
            str(poly.get("inverted_faces", "–")), str(poly.get("limit_crossings", "–")),
            str(deci.get("faces", "–")), str(deci.get("extraordinary_vertices", "–")),
            str(deci.get("limit_crossings", "–")), b.get("method") or "polycube"]) + " |")
    lines += ["", "Where the base mesh was not reached, the stage's message; where the route "
              "fell back from the polycube layout, why; where the cage was built on the one-part "
              "labeling instead of the parts' (`base_mesh.segmentation`), why; where no cage "
              "tried had a limit surface that does not cross itself, the stage's reason:", ""]
    for r in rows:
        reason = (r.get("base_mesh") or {}).get("fallback_reason")
        segmentation = (r.get("base_mesh") or {}).get("segmentation") or ""
        if segmentation.startswith("one part"):
            lines.append(f"- `{r['mesh']}` ({r['mode']}): built on {segmentation[:300]}")
        if not r.get("base_mesh"):
            message = r.get("messages", {}).get("basemesh") or r.get("error") or ""
            lines.append(f"- `{r['mesh']}` ({r['mode']}, {r.get('method', 'auto')}): "
                         f"not reached: {message[:300]}")
        elif reason and r.get("method", "auto") == "auto":
            lines.append(f"- `{r['mesh']}` ({r['mode']}): {reason[:300]}")
        crossing = (r.get("base_mesh") or {}).get("crossing_reason")
        if crossing:
            lines.append(f"- `{r['mesh']}` ({r['mode']}, {r.get('method', 'auto')}): "
                         f"{crossing}")
    lines += ["", "## Cages over their targets", ""]
    for r in reached:
        lines.append(f"![{r['mesh']} {r['mode']} {r.get('method', 'auto')}]"
                     f"(images/{_image_name(r['mesh'], r['mode'], r.get('method', 'auto'))})")
    return "\n".join(lines) + "\n"


def _order(row):
    """SIMP topology-optimisation results first, then the other meshes; one part first."""
    return (not row["mesh"].startswith("to_simp"), row["mesh"], MODES.index(row["mode"]),
            BASE_MESH_METHODS.index(row.get("method", "auto")))


def _image_name(stem, mode, method):
    return f"basemesh_{stem}_{mode}" + ("" if method == "auto" else f"_{method}") + ".png"


def _percent(value):
    return "–" if value is None else f"{100.0 * value:.2f}"


def _other_runs(rows, meta):
    """Sentence naming the runs (date, commit, rows) of the ``rows`` that ``meta``'s run
    did not make (``--update`` keeps them); rows without a ``run`` are from a run before
    rows recorded theirs."""
    this = (meta["date"], meta["commit"])
    counts = {}
    for row in rows:
        run = row.get("run")
        key = (run["date"], run["commit"]) if run else None
        if key != this:
            counts[key] = counts.get(key, 0) + 1
    if not counts:
        return ""
    parts = [(f"{n} from {key[0]}, commit {key[1]}" if key else f"{n} from an earlier run")
             for key, n in sorted(counts.items(), key=lambda item: item[0] or ("", ""))]
    return " Rows not re-run: " + "; ".join(parts) + "."


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*")
    parser.add_argument("--solid", nargs="*", default=[],
                        help="meshes whose whole pipeline to STEP is run and evaluated")
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--update", action="store_true",
                        help="keep the other rows of basemesh_results.json, replace these")
    parser.add_argument("--modes", nargs="*", choices=MODES, default=list(MODES))
    parser.add_argument("--base-mesh-method", choices=BASE_MESH_METHODS, default="auto")
    parser.add_argument("--case", nargs=5, metavar=("PATH", "MODE", "METHOD", "JSON", "PNG"))
    args = parser.parse_args(argv)
    if args.case:
        run_case(*args.case, solid=bool(args.solid))
        return 0
    names = sorted(f for f in os.listdir(args.meshes) if f.endswith((".stl", ".obj")))
    if args.only:
        names = [n for n in names if os.path.splitext(n)[0] in args.only]
    os.makedirs(os.path.join(HERE, "images"), exist_ok=True)
    meta = {"date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "load": round(os.getloadavg()[0], 2),
            "timeout": args.timeout,
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                     capture_output=True, text=True).stdout.strip()}
    results_json = os.path.join(HERE, "basemesh_results.json")
    kept = []
    if args.update and os.path.exists(results_json):
        with open(results_json, encoding="utf-8") as handle:
            previous = json.load(handle)
        ran = {(os.path.splitext(n)[0], mode, args.base_mesh_method) for n in names
               for mode in args.modes}
        kept = [r for r in previous["rows"]
                if (r["mesh"], r["mode"], r.get("method", "auto")) not in ran]
    rows = []
    for name in names:
        stem = os.path.splitext(name)[0]
        for mode in args.modes:
            with tempfile.TemporaryDirectory(prefix="basemesh-case-") as tmp:
                out = os.path.join(tmp, "row.json")
                image = os.path.join(HERE, "images", _image_name(stem, mode, args.base_mesh_method))
                command = [sys.executable, os.path.abspath(__file__), "--case",
                           os.path.join(args.meshes, name), mode, args.base_mesh_method, out, image]
                if stem in args.solid:
                    command += ["--solid", stem]
                try:
                    done = subprocess.run(command, capture_output=True, text=True,
                                          timeout=args.timeout, cwd=REPO)
                    row = (json.load(open(out, encoding="utf-8")) if os.path.exists(out)
                           else {"error": done.stderr.strip().splitlines()[-1:]})
                except subprocess.TimeoutExpired:
                    row = {"error": f"timed out after {args.timeout} s"}
            if isinstance(row.get("error"), list):
                row["error"] = " ".join(row["error"])
            row.update({"mesh": stem, "mode": mode, "method": args.base_mesh_method,
                        "run": {"date": meta["date"], "commit": meta["commit"]}})
            rows.append(row)
            print(stem, mode, row.get("stages", {}).get("basemesh", row.get("error")),
                  row.get("base_mesh", {}).get("faces"), flush=True)
    rows = sorted(kept + rows, key=_order)
    with open(results_json, "w", encoding="utf-8") as handle:
        json.dump({"meta": meta, "rows": rows}, handle, indent=1)
    with open(os.path.join(HERE, "BASEMESH_RESULTS.md"), "w", encoding="utf-8") as handle:
        handle.write(markdown(rows, meta))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
