# SPDX-License-Identifier: LGPL-2.1-or-later
"""Labeling benchmark: validity judged independently, frames per part, mean angles, seconds.

Usage::

    .venv/bin/python benchmarks/labeling_bench.py [--meshes DIR] [--only NAME ...] [--out FILE]
        [--before CHECKOUT]

For every dev mesh and part mode (``single``, ``auto``) this runs, in a fresh process,
``python -m polycube_wb reconstruct MESH --labels x.ply --report x.json
--stop-after labeling --parts MODE``, judges the ``--labels`` file with the independent
``../shared/tools/labelcheck.py`` (run as its own process, never imported into the project) and
compares its verdict with the project's report. From the labels file it measures, per part, the
area-weighted mean angle between face normals and label directions, and the same for the
nearest-of-six-directions labels in the world axes and in the part's PCA frame. For the SIMP
dev meshes with one part it also runs ``--stop-after basemesh`` and records whether the base mesh
is reached (against :data:`BASEMESH_BEFORE`, measured the same way before the turning-point work).
The labeling stage of the largest mesh (:data:`SPEED_MESH`, one part) is timed again on its own:
in a fresh process the stages up to the frames run once, then the labeling stage
:data:`SPEED_RUNS` times, and the least CPU time counts (the other jobs on the shared machine only
ever add to it); with ``--before CHECKOUT`` the same is measured on another checkout of the
project (e.g. the commit before the speed work, a checkout or a ``git archive`` export in a
directory named after the commit), run by the same interpreter.
Writes ``benchmarks/LABELING_RESULTS.md`` (or ``--out``).
"""
import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)

import numpy as np  # noqa: E402

DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
LABELCHECK = os.path.join(REPO, "..", "shared", "tools", "labelcheck.py")
MODES = ("single", "auto")
TIMEOUT = 600.0
TINY_CHART = 20
"""Charts of at most this many faces count as tiny."""
BASEMESH_BEFORE = {
    "commit": "038d80c",
    "turning_points": {"to_simp_cantilever": 8, "to_simp_lbracket": 3, "to_simp_mbb": 0,
                       "to_simp_pylon": 2, "to_simp_torsion_arm": 5,
                       "to_simp_torsion_arm_fine3": 38},
    "reached": {"to_simp_cantilever": "yes", "to_simp_lbracket": "yes",
                "to_simp_mbb": "no: 1 integer chart polygon overlaps itself",
                "to_simp_pylon": "no: 4 charts do not turn by four",
                "to_simp_torsion_arm": "no: 18 charts do not turn by four",
                "to_simp_torsion_arm_fine3": "no: 2553 quads > max_base_faces 2500"},
}
"""Turning points and base-mesh outcome of the SIMP dev meshes (one part) on main at ``commit``,
before the turning-point pass (same command as :func:`basemesh_case`)."""


SPEED_MESH = "to_simp_torsion_arm_fine3.stl"
SPEED_RUNS = 3
SPEED_SCRIPT = """
import json, os, sys, time
sys.path.insert(0, os.getcwd())
from core.params import ReconstructionParams
from core.pipeline import run_stages
from core.progress import NO_PROGRESS
from core.stages.labeling import run_labeling
from core.types import MeshSource, PipelineState
params = ReconstructionParams()
state = PipelineState(source=MeshSource(sys.argv[1]))
state = run_stages(state, ["intake", "parts", "frames"], params)[0]
cpu, wall = [], []
for _ in range(int(sys.argv[2])):
    c, w = time.process_time(), time.perf_counter()
    result = run_labeling(state.intake, state.parts, state.frames, params, NO_PROGRESS)
    cpu.append(time.process_time() - c)
    wall.append(time.perf_counter() - w)
r = result.report
print(json.dumps({"cpu": cpu, "wall": wall, "valid": r["valid"], "charts": r["charts"],
                  "turning_points": r["turning_points"], "load": os.getloadavg()[0]}))
"""
"""Times the labeling stage of one mesh (one part) in the checkout it runs in (its working
directory): prints the CPU and wall seconds of each run and the last run's figures as JSON."""


def speed_case(checkout, path, runs=SPEED_RUNS):
    """CPU and wall seconds of the labeling stage on ``path`` (one part), ``runs`` times, in the
    project checkout ``checkout`` (a fresh process running :data:`SPEED_SCRIPT`)."""
    proc = subprocess.run([sys.executable, "-c", SPEED_SCRIPT, os.path.abspath(path), str(runs)],
                          cwd=checkout, capture_output=True, text=True, timeout=TIMEOUT)
    if proc.returncode != 0:
        return {"error": (proc.stderr.strip().splitlines() or ["failed"])[-1]}
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    # an exported tree (``git archive``) is named after its commit
    out["commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=checkout,
                                   capture_output=True, text=True).stdout.strip() or (
        os.path.basename(os.path.normpath(checkout)))
    return out


def speed_markdown(now, before=None):
    """The speed section: least CPU (and its run's wall) seconds of the labeling stage."""
    lines = ["", f"## Labeling speed ({os.path.splitext(SPEED_MESH)[0]}, one part)", "",
             f"The labeling stage alone (HBECVT, repair, monotonicity pass, validity), run "
             f"{SPEED_RUNS} times in one process after the earlier stages; least CPU seconds "
             "(the other jobs on the 2-core machine only add to it), the wall seconds of that "
             "run, and the machine's load when it ended.", "",
             "| checkout | commit | CPU s (least) | CPU s (all runs) | wall s | load | valid "
             "| charts | turning points |", "|---|---|---|---|---|---|---|---|---|"]
    for name, r in (("before", before), ("now", now)):
        if r is None:
            continue
        if "error" in r:
            lines.append(f"| {name} | | error: {r['error']} | | | | | | |")
            continue
        k = int(np.argmin(r["cpu"]))
        lines.append(f"| {name} | `{r['commit']}` | {min(r['cpu']):.2f} | "
                     f"{' '.join(f'{c:.2f}' for c in r['cpu'])} | {r['wall'][k]:.2f} | "
                     f"{r['load']:.1f} | {'yes' if r['valid'] else 'no'} | {r['charts']} | "
                     f"{r['turning_points']} |")
    return lines


def _read_labels(path):
    """Vertices, faces, per-face part, label and label direction of a ``--labels`` PLY."""
    import trimesh

    mesh = trimesh.load(path, process=False, force="mesh")
    raw = mesh.metadata["_ply_raw"]["face"]["data"]
    axis = np.stack([np.asarray(raw[k], dtype=np.float64).ravel() for k in ("ax", "ay", "az")],
                    axis=1)
    return (np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64),
            np.asarray(raw["part"]).astype(np.int64).ravel(),
            np.asarray(raw["label"]).astype(np.int64).ravel(), axis)


def _angles(normals, directions):
    return np.degrees(np.arccos(np.clip((normals * directions).sum(axis=1), -1.0, 1.0)))


def part_angles(V, F, part, axis):
    """Per part: area-weighted mean angle (degrees) of the labels, of the nearest world axis and
    of the nearest axis of the part's PCA frame."""
    from core.segmentation.frames import face_geometry, part_frames

    area, normal, _ = face_geometry(V, F)
    pca = part_frames(V, F, part)
    world_best = np.degrees(np.arccos(np.clip(np.abs(normal).max(axis=1), -1.0, 1.0)))
    local = np.abs(np.einsum("fij,fj->fi", pca[part], normal)).max(axis=1)
    pca_best = np.degrees(np.arccos(np.clip(local, -1.0, 1.0)))
    label = _angles(normal, axis / np.linalg.norm(axis, axis=1, keepdims=True))
    rows = []
    for p in range(int(part.max()) + 1):
        sel = part == p
        w = area[sel]
        rows.append({"label": float(np.average(label[sel], weights=w)),
                     "world": float(np.average(world_best[sel], weights=w)),
                     "pca": float(np.average(pca_best[sel], weights=w)),
                     "area_fraction": float(w.sum() / area.sum())})
    return rows


def chart_shapes(V, F, part, label, tiny=TINY_CHART):
    """Counts of charts that are not topological disks (Euler characteristic != 1), that have
    fewer than four corners on their boundary, and that have at most ``tiny`` faces."""
    from core.segmentation.charts import build_topology, extract_layout

    topo = build_topology(F, len(V))
    lay = extract_layout(topo, part, label)
    c, n = lay.face_chart, lay.n_charts
    vc = np.unique(F * n + c[:, None])
    ef = topo.edge_faces
    ec = np.unique(np.concatenate([np.arange(len(ef)) * n + c[ef[:, 0]],
                                   np.arange(len(ef)) * n + c[ef[:, 1]]]))
    euler = (np.bincount(vc % n, minlength=n) - np.bincount(ec % n, minlength=n)
             + lay.chart_size)
    corner = np.zeros(topo.n_vertices, dtype=bool)
    corner[lay.corners] = True
    cc = vc[corner[vc // n]]
    corners = np.bincount(cc % n, minlength=n)
    return {"non_disk": int((euler != 1).sum()), "under_4_corners": int((corners < 4).sum()),
            "tiny": int((lay.chart_size <= tiny).sum())}


def run_case(path, mode, tmp):
    stem = os.path.splitext(os.path.basename(path))[0]
    ply = os.path.join(tmp, f"{stem}_{mode}.ply")
    rep = os.path.join(tmp, f"{stem}_{mode}.json")
    cmd = [sys.executable, "-m", "polycube_wb", "reconstruct", path, "--labels", ply,
           "--report", rep, "--stop-after", "labeling", "--parts", mode]
    started = time.perf_counter()
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=TIMEOUT)
    wall = time.perf_counter() - started
    out = {"mesh": stem, "mode": mode, "exit": proc.returncode, "wall_seconds": wall}
    if not os.path.exists(rep):
        out["error"] = (proc.stderr.strip().splitlines() or ["no report"])[-1]
        return out
    with open(rep, encoding="utf-8") as fh:
        report = json.load(fh)
    out["stages"] = {k: v.get("seconds") for k, v in report["stages"].items()}
    out["cpu"] = {k: v.get("cpu_seconds") for k, v in report["stages"].items()}
    out["faces"] = report["input"]["triangles"]
    if "labeling" not in report or not os.path.exists(ply):
        out["error"] = (proc.stderr.strip().splitlines() or ["no labeling"])[-1]
        return out
    out["report"] = {k: report["labeling"][k] for k in
                     ("valid", "parts", "charts", "invalid_charts", "invalid_boundaries",
                      "invalid_corners", "turning_points")}
    out["report"]["at_interfaces"] = report["labeling"].get("invalid_at_interfaces",
                                                            {"boundaries": 0, "corners": 0})
    out["frames"] = report.get("frames", {}).get("part_frame_source", [])
    check = subprocess.run([sys.executable, LABELCHECK, ply], capture_output=True, text=True,
                           timeout=TIMEOUT)
    out["labelcheck"] = json.loads(check.stdout)
    V, F, part, label, axis = _read_labels(ply)
    out["parts"] = part_angles(V, F, part, axis)
    out["shapes"] = chart_shapes(V, F, part, label)
    return out


def basemesh_case(path, tmp):
    """Whether ``reconstruct --stop-after basemesh`` (one part) reaches a base mesh: a dict with
    ``reached``, ``faces`` (when reached), ``turning_points`` and the failure ``message``."""
    stem = os.path.splitext(os.path.basename(path))[0]
    rep = os.path.join(tmp, f"{stem}_basemesh.json")
    cmd = [sys.executable, "-m", "polycube_wb", "reconstruct", path, "--report", rep,
           "--stop-after", "basemesh"]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=TIMEOUT)
    out = {"mesh": stem, "exit": proc.returncode, "reached": False}
    if not os.path.exists(rep):
        out["message"] = (proc.stderr.strip().splitlines() or ["no report"])[-1]
        return out
    with open(rep, encoding="utf-8") as fh:
        report = json.load(fh)
    out["turning_points"] = report.get("labeling", {}).get("turning_points")
    stage = report["stages"].get("basemesh", {})
    out["reached"] = stage.get("status") == "ok"
    out["faces"] = report.get("base_mesh", {}).get("faces")
    out["message"] = stage.get("message", "")
    return out


def _fmt_parts(rows, frames):
    cells = []
    for p, r in enumerate(rows):
        src = frames[p] if p < len(frames) else "?"
        over = r["label"] - min(r["world"], r["pca"])
        cells.append(f"{p}:{src} {r['label']:.1f} ({r['world']:.1f}/{r['pca']:.1f}, "
                     f"{over:+.1f})")
    return "; ".join(cells)


def _agree_without_interfaces(lc, rp):
    """Whether the report matches labelcheck once the items only the interface rules judge
    (labels parallel to an interface axis, corners on interfaces) are taken out."""
    itf = rp["at_interfaces"]
    return (lc["invalid_charts"] == rp["invalid_charts"]
            and lc["invalid_boundaries"] == rp["invalid_boundaries"] - itf["boundaries"]
            and lc["invalid_corners"] == rp["invalid_corners"] - itf["corners"])


def basemesh_markdown(rows):
    """The base-mesh section: per SIMP mesh, turning points and outcome before and now."""
    before = BASEMESH_BEFORE
    lines = ["", "## Base mesh reached (SIMP dev meshes, one part)", "",
             "`reconstruct MESH --stop-after basemesh` with default options. *Before*: main at "
             f"`{before['commit']}` (the monotonicity pass then moved boundary hooks only).", "",
             "| mesh | turning points before | turning points now | base mesh before "
             "| base mesh now |", "|---|---|---|---|---|"]
    for r in rows:
        now = (f"yes ({r['faces']} faces)" if r["reached"] else
               f"no: {r.get('message', '')[:160]}")
        lines.append(f"| {r['mesh']} | {before['turning_points'].get(r['mesh'], '?')} | "
                     f"{r.get('turning_points', '?')} | {before['reached'].get(r['mesh'], '?')} "
                     f"| {now} |")
    n_before = sum(v == "yes" for v in before["reached"].values())
    lines += ["", f"Reached: {n_before} of {len(before['reached'])} before, "
              f"{sum(r['reached'] for r in rows)} of {len(rows)} now; turning points "
              f"{sum(before['turning_points'].values())} before, "
              f"{sum(r.get('turning_points') or 0 for r in rows)} now."]
    return lines


def over_rule(results, mode, limit=3.0):
    """Parts of ``mode`` runs whose labeling angle exceeds the better nearest-direction labeling
    by more than ``limit`` degrees: list of (mesh, part, frame, excess)."""
    out = []
    for r in results:
        if r["mode"] != mode or "parts" not in r:
            continue
        for p, row in enumerate(r["parts"]):
            over = row["label"] - min(row["world"], row["pca"])
            if over > limit:
                src = r["frames"][p] if p < len(r["frames"]) else "?"
                out.append((r["mesh"], p, src, over))
    return out


def markdown(results, started, basemesh_rows=(), speed=None, speed_before=None):
    lines = ["# Labeling benchmark", "",
             f"Written by `benchmarks/labeling_bench.py` on {started} "
             f"(machine: {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f} at the end).", "",
             "Validity is judged by the independent `../shared/tools/labelcheck.py` on the "
             "`--labels` PLY; *agree* says whether the project's report gives the same verdict "
             "and counts (*interface rules*: it does once the items only the project's interface "
             "rules judge are taken out: labels parallel to an interface's x-axis, Eq. 3 term 4, "
             "and corners on part interfaces, which labelcheck skips). Angles are area-weighted means in degrees between face normals and "
             "label directions; per part `p:frame label (world/pca, over)` gives the frame the "
             "part got, the labeling's angle, the nearest-of-six-directions angle in the world "
             "axes and in the part's PCA frame, and the labeling's excess over the better of "
             "those two. Seconds are the pipeline's own stage times (frames, labeling = "
             "HBECVT + repair + monotonicity pass + validity) in a process of their own, wall "
             "clock and, in brackets, the process's CPU time (what the stage costs without the "
             "other jobs on the machine).", "",
             "Chart shapes (what the base mesh needs): *non-disk* charts, charts with *<4 "
             f"corners* on their boundary, *tiny* charts of at most {TINY_CHART} faces.", "",
             "| mesh | parts | faces | valid (labelcheck) | agree | charts "
             "| inv. charts/bnd/corners | turning points | non-disk / <4 corners / tiny "
             "| frames s | labeling s (CPU s) | per part |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        if "labelcheck" not in r:
            lines.append(f"| {r['mesh']} | {r['mode']} | {r.get('faces', '')} | error: "
                         f"{r.get('error', '?')} | | | | | | | | |")
            continue
        lc, rp = r["labelcheck"], r["report"]
        keys = ("invalid_charts", "invalid_boundaries", "invalid_corners")
        agree = "yes" if lc["valid"] == rp["valid"] and all(lc[k] == rp[k] for k in keys) else (
            "interface rules" if _agree_without_interfaces(lc, rp) else "NO")
        st, sh = r["stages"], r["shapes"]
        lines.append(
            f"| {r['mesh']} | {r['mode']} ({rp['parts']}) | {r['faces']} | "
            f"{'yes' if lc['valid'] else 'no'} | {agree} | {lc['charts']} | "
            f"{lc['invalid_charts']}/{lc['invalid_boundaries']}/{lc['invalid_corners']} | "
            f"{rp['turning_points']} | "
            f"{sh['non_disk']} / {sh['under_4_corners']} / {sh['tiny']} | "
            f"{st.get('frames') or 0:.2f} | "
            f"{st.get('labeling') or 0:.2f} ({r['cpu'].get('labeling') or 0:.2f}) | "
            f"{_fmt_parts(r['parts'], r['frames'])} |")
    ok = [r for r in results if "labelcheck" in r]
    lines += ["", "## Summary", ""]
    for mode in MODES:
        rows = [r for r in ok if r["mode"] == mode]
        valid = sum(r["labelcheck"]["valid"] for r in rows)
        worst = max((p["label"] - min(p["world"], p["pca"]) for r in rows for p in r["parts"]),
                    default=float("nan"))
        tp = sum(r["report"]["turning_points"] for r in rows if r["mesh"].startswith("to_simp"))
        over = over_rule(results, mode)
        listed = "; ".join(f"{m} part {p} ({src}, {e:+.1f})" for m, p, src, e in over) or "none"
        lines.append(f"- `--parts {mode}`: valid by labelcheck on {valid} of {len(rows)} meshes; "
                     f"largest per-part excess over the better nearest-direction labeling "
                     f"{worst:+.1f} deg; turning points on the SIMP meshes {tp}; parts more than "
                     f"3 deg over it: {listed}.")
    big = [r for r in ok if r["mode"] == "single"]
    if big:
        r = max(big, key=lambda r: r["faces"])
        lines.append(f"- Largest mesh {r['mesh']} ({r['faces']} triangles): frames "
                     f"{r['stages']['frames']:.2f} s, labeling {r['stages']['labeling']:.2f} s "
                     f"wall ({r['cpu']['labeling']:.2f} s of CPU: the wall time on the shared "
                     "machine includes waiting for the other jobs' cores).")
    if speed is not None:
        lines += speed_markdown(speed, speed_before)
    if basemesh_rows:
        lines += basemesh_markdown(basemesh_rows)
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--out", default=os.path.join(HERE, "LABELING_RESULTS.md"))
    parser.add_argument("--before", default=None,
                        help="another checkout of the project whose labeling speed to measure too")
    args = parser.parse_args(argv)
    started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    names = sorted(n for n in os.listdir(args.meshes)
                   if os.path.splitext(n)[1].lower() in (".stl", ".obj", ".ply", ".off"))
    if args.only:
        names = [n for n in names if os.path.splitext(n)[0] in args.only]
    results = []
    with tempfile.TemporaryDirectory(prefix="labeling-bench-") as tmp:
        for name in names:
            for mode in MODES:
                r = run_case(os.path.join(args.meshes, name), mode, tmp)
                print(json.dumps({k: r.get(k) for k in ("mesh", "mode", "labelcheck", "frames")}),
                      flush=True)
                results.append(r)
        basemesh_rows = []
        for name in names:
            if name.startswith("to_simp"):
                b = basemesh_case(os.path.join(args.meshes, name), tmp)
                print(json.dumps(b), flush=True)
                basemesh_rows.append(b)
    speed = speed_before = None
    if SPEED_MESH in names:
        speed_path = os.path.join(args.meshes, SPEED_MESH)
        if args.before:
            speed_before = speed_case(args.before, speed_path)
            print(json.dumps({"speed_before": speed_before}), flush=True)
        speed = speed_case(REPO, speed_path)
        print(json.dumps({"speed": speed}), flush=True)
    text = markdown(results, started, basemesh_rows, speed, speed_before)
    tmp_out = args.out + ".tmp"
    with open(tmp_out, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp_out, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
