# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit benchmark: modes, speed against the query floor, and the remesh-and-fit peer.

Usage::

    .venv/bin/python benchmarks/fit_bench.py [--only NAME ...] [--baseline OLD_TREE]
                                             [--out benchmarks]

For every dev mesh whose pipeline reaches the base mesh (the base mesh is built in this run),
each fit mode (``none``, ``best-fit``, ``inside``) is timed and measured: rounds and
iterations, two-sided distances between the triangulated level-3 limit mesh and the target
(``core.quality.surface_distances``, fractions of the bounding-box diagonal), and the volume
outside / not covered (``core.quality.containment``). The floor is 100k closest-point
queries on the same compiled target, in the same run; the ratio says how many such query
sets one fit iteration costs.

The peer, in the same run and at the same face count: QuadriFlow (PyPI ``pyquadriflow``, a
benchmark-only dependency) remeshes the target into quads, Catmull-Clark level 3, and a linear
least-squares fit of the cage to the closest target points of the level-3 vertices, five
rounds. ``--baseline DIR`` also runs the best-fit and inside fits of an older checkout's
``core`` (for example ``git archive 9ea2d9c core | tar -x -C DIR``) on the same base mesh, in a
subprocess, with each sampling seed of ``SEEDS`` (ours too), and compares the medians over the
seeds. The other dev meshes that reach the fit (``RULE_ONLY``) get only the inside fit, ours and
the baseline's, for the 0.5 % volume-outside rule. The medians of the CPU seconds over the seeds
are set against the issue's speed rule, and the inside fits of ``PROFILED`` are profiled once
(where the time goes).

Writes ``FIT_RESULTS.md`` and ``fit_results.json`` into ``--out``. Timings are wall-clock
seconds on a shared 2-core machine; the load average at the start is recorded.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)

from core.fitting import fit_base_mesh  # noqa: E402
from core.stages.fit import fit_section  # noqa: E402
from core.geometry import triangulate  # noqa: E402
from core.pipeline import reconstruct  # noqa: E402
from core.subdivision.limit_crossings import count_limit_self_intersections, fit_levels  # noqa: E402
from core.quality import containment, sample_surface, surface_distances  # noqa: E402
from core.subdivision.catmull_clark import build_hierarchy  # noqa: E402
from core.subdivision.limit import limit_matrices  # noqa: E402
from core.target_surface import TargetSurface  # noqa: E402
from core.types import PolyMesh  # noqa: E402

MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
CASES = {
    "to_simp_cantilever": os.path.join(REPO, "examples", "to_simp_cantilever.stl"),
    "polycube_bone": os.path.join(MESHES, "polycube_bone.obj"),
    "polycube_mambo_b0": os.path.join(MESHES, "polycube_mambo_b0.obj"),
    "to_levelset_cantilever_tiny": os.path.join(MESHES, "to_levelset_cantilever_tiny.stl"),
    "idler_riser": os.path.join(MESHES, "idler_riser.stl"),
    "to_simp_mbb": os.path.join(MESHES, "to_simp_mbb.stl"),
    "ge_bracket_domain": os.path.join(MESHES, "ge_bracket_domain.stl"),
    "to_simp_torsion_arm_fine3": os.path.join(MESHES, "to_simp_torsion_arm_fine3.stl"),
    "featuretype": os.path.join(MESHES, "featuretype.stl"),
    "octagonal_pocket": os.path.join(MESHES, "octagonal_pocket.stl"),
}
RULE_ONLY = {name: os.path.join(MESHES, name + ext) for name, ext in (
    ("gripper_domain", ".stl"), ("fandisk", ".obj"), ("to_simp_lbracket", ".stl"),
    ("to_simp_pylon", ".stl"), ("to_simp_torsion_arm", ".stl"), ("tray_bottom", ".stl"))}
"""The other dev meshes that reach the fit: only the inside fit, ours and the baseline's, for
the 0.5 % outside rule."""
SEEDS = (0, 1, 2)
"""Sampling seeds of the before / after comparison: changing only the seed moves the inside
mean by 20-40 %, so before and after are compared by the median over these seeds."""
LARGE = "to_simp_torsion_arm_fine3"
"""The issue's large case (151k triangles): its fit within 6 s, the others' within 2 s."""
PROFILED = (LARGE, "to_simp_mbb", "polycube_mambo_b0")
"""Meshes whose inside fit is also run under cProfile (:func:`profile_fit`)."""
PARTS = (("closest points (TargetSurface.nearest)", "target_surface.py", "nearest"),
         ("crossing checks (find_self_intersections)", "self_intersection.py",
          "find_self_intersections"),
         ("normal equations (NormalEquations.solve)", "best_fit.py", "solve"),
         ("thickness rays (responses.thickness)", "responses.py", "thickness"),
         ("report figures (containment boolean)", "quality.py", "containment"))
"""The parts of the fit whose cumulative CPU time :func:`profile_fit` reports."""
MODES = ("none", "best-fit", "inside")
EVAL_LEVEL = 3
FLOOR_QUERIES = 100_000
PEER_ROUNDS = 5


def limit_mesh(base, level=EVAL_LEVEL):
    """(vertices, triangles) of the triangulated level-``level`` limit mesh of a cage."""
    hierarchy = build_hierarchy(base, level)
    fine = hierarchy.meshes[level]
    L, _, _ = limit_matrices(fine)
    return L @ fine.vertices, triangulate(fine.face_vertices, fine.face_offsets)


MAX_MEASURES = {
    "samples": "Hausdorff lower bound from 20k samples and vertices (runs before commit 1c0ca58)",
    "search": "Hausdorff distance searched over every triangle to 1e-4 of the diagonal "
              "(`core.quality.surface_distances`, from commit 1c0ca58 on)"}
"""What a run's ``max`` is, by its ``info["max_measure"]``."""


def surface_figures(V, F, target):
    """Two-sided distances and containment of a triangle mesh against the target."""
    d = surface_distances(V, F, target.vertices, target.faces, samples=20000)
    figures = {"mean_distance": 0.5 * (d["result_to_target_mean"] + d["target_to_result_mean"]),
               "max_distance": d["hausdorff"],
               "result_to_target_mean": d["result_to_target_mean"],
               "target_to_result_mean": d["target_to_result_mean"]}
    try:
        c = containment(V, F, target.vertices, target.faces)
        figures.update(outside=c["outside_volume_fraction"], uncovered=c["uncovered_volume_fraction"])
    except Exception as exc:  # a self-intersecting result has no boolean; say so
        figures.update(outside=None, uncovered=None, containment_error=str(exc))
    return figures


def floor_seconds(target):
    """Seconds for 100k closest-point queries on the compiled target (built once, not timed)."""
    surface = TargetSurface(target.vertices, target.faces)
    points = sample_surface(target.vertices, target.faces, FLOOR_QUERIES, np.random.default_rng(0))
    points += 0.01 * surface.diagonal * np.random.default_rng(1).normal(size=points.shape)
    start = time.perf_counter()
    surface.closest(points)
    return time.perf_counter() - start


def our_fit(base, target, mode, seed=0):
    levels = fit_levels(base.n_faces, 2)
    start, cpu = time.perf_counter(), time.process_time()
    fitted, record = fit_base_mesh(base, target, levels=levels, iterations=100, mode=mode,
                                   seed=seed)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    info = fit_section(record)
    V, F = limit_mesh(fitted)
    row = {"mode": mode, "seconds": seconds, "cpu_seconds": cpu,
           "measure_seconds": info["measure_seconds"],
           "rounds": info["rounds"], "refit_crossings": info.get("refit_crossings"),
           "iterations": info["iterations"], "stopped": info["stopped"],
           "self_intersections": count_limit_self_intersections(fitted, levels),
           "fine_points": int(limit_matrices(build_hierarchy(base, levels).meshes[levels])[0]
                              .shape[0])}
    if seed:
        row["seed"] = seed
    row.update(surface_figures(V, F, target))
    return row


def profile_fit(base, target):
    """CPU seconds of the default inside fit and of its parts (``PARTS``), under cProfile.

    The parts can nest (a crossing check inside a hold-back inside a pull), so they do not
    add up to the total; the profiler itself adds some time to every call.
    """
    import cProfile
    import pstats

    profiler = cProfile.Profile(time.process_time)
    profiler.enable()
    fit_base_mesh(base, target, levels=fit_levels(base.n_faces, 2), iterations=100,
                  mode="inside")
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    parts = {}
    for label, filename, function in PARTS:
        found = [(calls, cumulative) for (path, _, name), (_, calls, _, cumulative, _)
                 in stats.items() if path.endswith(filename) and name == function]
        parts[label] = [sum(c for c, _ in found), sum(t for _, t in found)]
    total = max(cumulative for (path, _, name), (_, _, _, cumulative, _) in stats.items()
                if name == "fit_base_mesh")
    return {"total": total, "parts": parts}


def peer_fit(target, faces):
    """QuadriFlow remesh to about ``faces`` quads, Catmull-Clark level 3, 5 linear LSQ rounds."""
    from pyQuadriFlow.pyQuadriFlow import pyquadriflow

    start = time.perf_counter()
    out = pyquadriflow(int(faces), 0, target.vertices.tolist(), target.faces.tolist(),
                       False, False, False, False, False)
    remesh_seconds = time.perf_counter() - start
    quad_V = np.asarray(out["vertices"], dtype=np.float64)
    quad_F = np.asarray(out["faces"], dtype=np.int64)
    cage = PolyMesh(quad_V, quad_F.reshape(-1), np.arange(0, quad_F.size + 1, 4))
    start = time.perf_counter()
    hierarchy = build_hierarchy(cage, EVAL_LEVEL)
    S = hierarchy.composite(EVAL_LEVEL - 1).tocsr()
    surface = TargetSurface(target.vertices, target.faces)
    normal = (S.T @ S).tocsc() + 1e-9 * sp.identity(S.shape[1], format="csc")
    solver = splu(normal)
    V = quad_V
    for _ in range(PEER_ROUNDS):
        closest = surface.nearest(S @ V).point
        V = solver.solve(np.asarray(S.T @ closest))
    fit_seconds = time.perf_counter() - start
    fine = hierarchy.meshes[EVAL_LEVEL]
    row = {"mode": "peer", "faces": int(len(quad_F)), "remesh_seconds": remesh_seconds,
           "seconds": fit_seconds}
    row.update(surface_figures(S @ V, triangulate(fine.face_vertices, fine.face_offsets), target))
    return row


BASELINE_CODE = """
import sys, time, json
from types import SimpleNamespace
import numpy as np
sys.path.insert(0, sys.argv[1])
from core.fitting import fit_base_mesh
from core.types import PolyMesh
data = np.load(sys.argv[2])
creases = data["creases"]
base = PolyMesh(data["vertices"], data["face_vertices"], data["face_offsets"],
                creases if len(creases) else None)
target = SimpleNamespace(vertices=data["target_vertices"], faces=data["target_faces"])
rows, fitted = [], {}
for run in sys.argv[4:]:
    mode, seed = run.rsplit(":", 1)
    start, cpu = time.perf_counter(), time.process_time()
    result, info = fit_base_mesh(base, target, levels=int(data["levels"]), iterations=100,
                                 mode=mode, seed=int(seed))
    if not isinstance(info, dict):  # a tree whose fit returns its phase records
        from core.stages.fit import fit_section
        info = fit_section(info)
    rows.append({"mode": mode, "seed": int(seed), "seconds": time.perf_counter() - start,
                 "cpu_seconds": time.process_time() - cpu, "rounds": info["rounds"],
                 "iterations": info["iterations"], "measure_seconds": info["measure_seconds"],
                 "refit_crossings": info.get("refit_crossings")})
    fitted[run] = result.vertices
np.savez(sys.argv[3], **fitted)
print(json.dumps(rows))
"""
"""The older tree's fits, run in a subprocess on the same base mesh and target (npz)."""
BASELINE_MODES = ("best-fit", "inside")


def baseline_fits(tree, base, target, work, name, modes=BASELINE_MODES, seeds=SEEDS):
    """The older ``core`` tree's fits of the same base mesh, each mode with each seed.

    Run in a subprocess (``BASELINE_CODE``); the fitted cages come back and are measured
    here as :func:`our_fit` measures ours.

    Returns
    -------
    list of dict, one per mode and seed, with :func:`our_fit`'s keys.
    """
    levels = fit_levels(base.n_faces, 2)
    given, back = os.path.join(work, f"{name}_in.npz"), os.path.join(work, f"{name}_out.npz")
    creases = np.zeros((0, 2), dtype=np.int64) if base.creases is None else base.creases
    np.savez(given, vertices=base.vertices, face_vertices=base.face_vertices,
             face_offsets=base.face_offsets, creases=creases, target_vertices=target.vertices,
             target_faces=target.faces, levels=levels)
    runs = [f"{mode}:{seed}" for mode in modes for seed in seeds]
    done = subprocess.run([sys.executable, "-c", BASELINE_CODE, tree, given, back, *runs],
                          capture_output=True, text=True, timeout=3600, check=True)
    rows = json.loads(done.stdout.strip().splitlines()[-1])
    fitted = np.load(back)
    for row, run in zip(rows, runs):
        cage = PolyMesh(fitted[run], base.face_vertices, base.face_offsets, base.creases)
        row["self_intersections"] = count_limit_self_intersections(cage, levels)
        row.update(surface_figures(*limit_mesh(cage), target))
    return rows


def run_case(name, path, baseline, work):
    result = reconstruct(path, stop_after="basemesh")
    if result.state.basemesh is None:
        stage = [k for k, v in result.report["stages"].items() if v["status"] != "ok"]
        return {"name": name, "error": f"no base mesh ({', '.join(stage)})"}
    base, target = result.state.basemesh.cage, result.state.intake.target
    row = {"name": name, "triangles": int(len(target.faces)), "base_faces": int(base.n_faces),
           "rule_only": name in RULE_ONLY}
    if name in RULE_ONLY:
        row["modes"] = [our_fit(base, target, "inside")]
        if baseline:
            row["baseline"] = baseline_fits(baseline, base, target, work, name, ("inside",),
                                            (0,))
        return row
    row["floor_seconds"] = floor_seconds(target)
    row["modes"] = ([our_fit(base, target, mode) for mode in MODES]
                    + [our_fit(base, target, mode, seed=seed) for mode in BASELINE_MODES
                       for seed in SEEDS if seed])
    try:
        row["peer"] = peer_fit(target, base.n_faces)
    except Exception as exc:  # recorded: the peer failing on a mesh is a result too
        row["peer"] = {"error": f"{type(exc).__name__}: {exc}"}
    if baseline:
        row["baseline"] = baseline_fits(baseline, base, target, work, name)
    if name in PROFILED:
        row["profile"] = profile_fit(base, target)
    return row


def markdown(rows, info):
    lines = ["# Fit benchmark (`benchmarks/fit_bench.py`)", "",
             f"Run {info['date']} on {info['cpu_count']} cores, load average at start "
             f"{info['load']:.2f} (the machine is shared: wall-clock times are noisy), "
             f"{info.get('label', '')}. "
             "Distances are fractions of the target's bounding-box diagonal, two-sided "
             f"(mean of both directions' means; max = {MAX_MEASURES[info.get('max_measure', 'samples')]}), "
             f"on the triangulated level-{EVAL_LEVEL} limit mesh (peer: its "
             f"level-{EVAL_LEVEL} mesh). Volumes are fractions of the target volume.", "",
             "## Per mode", "",
             "Seconds: the whole `fit_base_mesh` call (wall clock); in brackets the part of "
             "it spent on its report figures (one manifold3d boolean and the distances). CPU "
             "seconds: the fit process's own time, less noisy than the wall clock on a loaded "
             "machine (every thread counts, so a BLAS call waiting for a core counts too). "
             "Refits: crossing triangle pairs of the least-squares fit and after each refit. "
             "`MODE, seed k`: the fit with the least-squares fit's target samples "
             "drawn with another seed, a measure of how much the figures move for reasons "
             "that have nothing to do with the code. Peer: the least-squares rounds only "
             "(its remesh time is in the last table).", "",
             "| mesh | triangles | cage faces | mode | seconds (figures) | CPU seconds | rounds | "
             "RGP iterations | refits | mean | max | outside | uncovered | "
             "self-intersecting pairs (level 2) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        if "error" in row:
            lines.append(f"| {row['name']} | | | {row['error']} | | | | | | | | | | |")
            continue
        if row.get("rule_only"):
            continue
        for m in row["modes"] + ([row["peer"]] if "seconds" in row.get("peer", {}) else []):
            lines.append(
                f"| {row['name']} | {row['triangles']} | {row['base_faces']} | {_label(m)} | "
                f"{m['seconds']:.2f}{_figure_time(m)} | {_cpu(m)} | "
                f"{m.get('rounds', PEER_ROUNDS)} | {m.get('iterations', '')} | "
                f"{_refits(m)} | {m['mean_distance']:.2e} | {m['max_distance']:.2e} | "
                f"{_pct(m['outside'])} | {_pct(m['uncovered'])} | "
                f"{m.get('self_intersections', '')} |")
        if "error" in row.get("peer", {}):
            lines.append(f"| {row['name']} | | | peer failed: {row['peer']['error']} |"
                         + " |" * 10)
    lines += _speed(rows)
    lines += _speed_rule(rows)
    lines += _profiles(rows)
    lines += _before_after(rows, info)
    lines += _outside_rule(rows)
    lines += ["", "## Against the peer (best-fit, same face count)", "",
              "| mesh | our mean / peer mean | our max / peer max | our seconds | peer seconds "
              "(remesh + fit) |", "|---|---|---|---|---|"]
    ratios = []
    for row in rows:
        peer = row.get("peer", {})
        if "error" in row or row.get("rule_only") or "seconds" not in peer:
            continue
        ours = _mode(row, "best-fit")
        ratio = ours["mean_distance"] / peer["mean_distance"]
        ratios.append((ratio, ours["max_distance"] <= peer["max_distance"]))
        lines.append(f"| {row['name']} | {ratio:.2f} | "
                     f"{ours['max_distance'] / peer['max_distance']:.2f} | {ours['seconds']:.2f} | "
                     f"{peer['remesh_seconds'] + peer['seconds']:.2f} |")
    lines += ["", "## Done-when checks", ""]
    for row in rows:
        if "error" in row or row.get("rule_only"):
            continue
        inside, fitted, unfitted = _mode(row, "inside"), _mode(row, "best-fit"), _mode(row, "none")
        limit = _time_limit(row)
        verdict = ("no limit set (more than 30k triangles)" if limit is None else
                   f"limit {limit:.0f} s: "
                   f"{'met' if max(_seconds(inside), _seconds(fitted)) <= limit else 'not met'}"
                   " by CPU seconds")
        lines.append(
            f"- {row['name']}: inside outside {_pct(inside['outside'])} "
            f"({'<=' if _within(inside['outside'], 0.005) else 'not <='} 0.5%); best-fit mean "
            f"{fitted['mean_distance'] / unfitted['mean_distance']:.2f} of the unfitted; "
            f"inside fit {inside['seconds']:.2f} s wall, {_cpu(inside)} s CPU, best-fit "
            f"{fitted['seconds']:.2f} s wall, {_cpu(fitted)} s CPU ({verdict}).")
    if ratios:
        lines += ["", f"Median mean-distance ratio {np.median([r for r, _ in ratios]):.2f}; our "
                  f"maximum no worse than the peer's on {sum(ok for _, ok in ratios)} of "
                  f"{len(ratios)} meshes."]
    return "\n".join(lines) + "\n"


def _speed(rows):
    """Markdown lines: the inside fit per iteration against 100k closest-point queries."""
    lines = ["", "## Speed against the query floor", "",
             "One iteration = one least-squares round or one RGP iteration (figures "
             "excluded, wall clock).", "",
             "| mesh | 100k closest points (s) | inside fit (s) | rounds + RGP iterations | "
             "fit per iteration / 100k queries |", "|---|---|---|---|---|"]
    for row in rows:
        if "error" in row or row.get("rule_only"):
            continue
        inside = _mode(row, "inside")
        steps = inside["iterations"] + inside["rounds"]
        per = (inside["seconds"] - inside["measure_seconds"]) / max(steps, 1)
        lines.append(f"| {row['name']} | {row['floor_seconds']:.3f} | {inside['seconds']:.2f} | "
                     f"{steps} | {per / row['floor_seconds']:.2f} |")
    return lines


def _speed_rule(rows):
    """Markdown lines: median CPU seconds over the seeds, before and after, against the
    issue's limits (2 s for a target of up to 30k triangles, 6 s for ``LARGE``)."""
    lines = ["", "## CPU seconds against the speed rule", "",
             "Median over the sampling seeds of `SEEDS` of the fit process's CPU seconds "
             "(report figures included); before: the `--baseline` tree in the same run.", "",
             "| mesh | triangles | cage faces | mode | CPU s before | CPU s after | after / before "
             "| limit | met after |", "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        if "error" in row or row.get("rule_only"):
            continue
        limit = _time_limit(row)
        for mode in BASELINE_MODES:
            after = [m["cpu_seconds"] for m in row["modes"] if m["mode"] == mode]
            before = [b["cpu_seconds"] for b in row.get("baseline", []) if b["mode"] == mode]
            a = float(np.median(after))
            b = float(np.median(before)) if before else None
            lines.append(
                f"| {row['name']} | {row['triangles']} | {row['base_faces']} | {mode} | "
                f"{'' if b is None else format(b, '.2f')} | {a:.2f} | "
                f"{'' if b is None else format(a / b, '.2f')} | "
                f"{'none' if limit is None else format(limit, '.0f') + ' s'} | "
                f"{'' if limit is None else ('yes' if a <= limit else 'no')} |")
    return lines


def _profiles(rows):
    """Markdown lines: where the inside fit's CPU time goes (:func:`profile_fit`)."""
    profiled = [row for row in rows if "profile" in row]
    if not profiled:
        return []
    lines = ["", "## Where the inside fit's CPU time goes", "",
             "cProfile of one default inside fit (seed 0) after the comparison runs; "
             "cumulative CPU seconds and calls of each part (parts can nest, the profiler "
             "adds overhead).", "",
             "| mesh | total CPU s | " + " | ".join(label for label, _, _ in PARTS) + " |",
             "|---|---|" + "---|" * len(PARTS)]
    for row in profiled:
        parts = row["profile"]["parts"]
        lines.append(f"| {row['name']} | {row['profile']['total']:.2f} | " + " | ".join(
            f"{parts[label][1]:.2f} ({parts[label][0]})" for label, _, _ in PARTS) + " |")
    return lines


def _before_after(rows, info):
    """Markdown lines: the ``--baseline`` tree's fits against ours, same base meshes, same run,
    each seed of ``SEEDS``, and per mesh the medians over the seeds."""
    pairs = [(row, before, _mode(row, before["mode"], before.get("seed", 0))) for row in rows
             if not row.get("rule_only") for before in row.get("baseline", [])]
    if not pairs:
        return []
    lines = ["", "## Before / after (same run, same base meshes)", "",
             f"Before: `--baseline` tree {info.get('baseline_label', '')}, run in a subprocess "
             "of this run on the same base mesh and target, with the same sampling seeds; its "
             "fitted cages measured here like ours.", "",
             "| mesh | mode | seed | CPU s before | CPU s after | wall s before | wall s after | "
             "refits before | refits after | mean before | mean after | max before | max after "
             "| outside before | outside after | self-int. before | self-int. after |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row, b, m in pairs:
        lines.append(
            f"| {row['name']} | {m['mode']} | {b.get('seed', 0)} | {_cpu(b)} | {_cpu(m)} | "
            f"{b['seconds']:.2f} | {m['seconds']:.2f} | {_refits(b)} | {_refits(m)} | "
            f"{b['mean_distance']:.2e} | {m['mean_distance']:.2e} | {b['max_distance']:.2e} | "
            f"{m['max_distance']:.2e} | {_pct(b['outside'])} | {_pct(m['outside'])} | "
            f"{b['self_intersections']} | {m['self_intersections']} |")
    cpu = [(b["cpu_seconds"], m["cpu_seconds"]) for _, b, m in pairs]
    lines += ["", f"CPU seconds summed over these fits: {sum(c for c, _ in cpu):.1f} before, "
              f"{sum(c for _, c in cpu):.1f} after.", "",
              "Medians over the seeds, per mesh and mode (after / before of the medians; below 1: "
              "after is closer or faster; outside: the largest over the seeds):", "",
              "| mesh | mode | mean after / before | max after / before | CPU after / before | "
              "seed spread of the mean after (max - min) / median | outside before (largest) | "
              "outside after (largest) |", "|---|---|---|---|---|---|---|---|"]
    medians = {}
    for row in rows:
        for mode in BASELINE_MODES:
            got = [(b, m) for r, b, m in pairs if r is row and m["mode"] == mode]
            if not got:
                continue
            ratio = {key: float(np.median([m[key] for _, m in got])
                                / np.median([b[key] for b, _ in got]))
                     for key in ("mean_distance", "max_distance", "cpu_seconds")}
            after = [m["mean_distance"] for _, m in got]
            spread = (max(after) - min(after)) / float(np.median(after))
            medians.setdefault(mode, []).append(ratio)
            lines.append(
                f"| {row['name']} | {mode} | {ratio['mean_distance']:.2f} | "
                f"{ratio['max_distance']:.2f} | {ratio['cpu_seconds']:.2f} | {spread:.2f} | "
                f"{_pct(_largest(b['outside'] for b, _ in got))} | "
                f"{_pct(_largest(m['outside'] for _, m in got))} |")
    lines.append("")
    for mode, ratios in medians.items():
        lines.append(
            f"- {mode}: median over the meshes of the mean ratio "
            f"{np.median([r['mean_distance'] for r in ratios]):.2f}, of the max ratio "
            f"{np.median([r['max_distance'] for r in ratios]):.2f}, of the CPU ratio "
            f"{np.median([r['cpu_seconds'] for r in ratios]):.2f} ({len(ratios)} meshes).")
    return lines


def _outside_rule(rows):
    """Markdown lines: the inside fit's volume outside on every dev mesh that reaches the fit."""
    lines = ["", "## Inside mode: volume outside on every dev mesh that reaches the fit", "",
             "One part, default parameters, seed 0; the rule is at most 0.5 % of the target's "
             "volume outside. Before: the `--baseline` tree on the same base mesh.", "",
             "| mesh | triangles | cage faces | outside before | outside after | mean before | "
             "mean after | uncovered after | CPU s after | within 0.5 % |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    within = []
    for row in rows:
        if "error" in row:
            lines.append(f"| {row['name']} | | | {row['error']} | | | | | | |")
            continue
        m = _mode(row, "inside")
        b = next((b for b in row.get("baseline", []) if b["mode"] == "inside"
                  and b.get("seed", 0) == 0), None)
        ok = _within(m["outside"], 0.005)
        within.append(ok)
        lines.append(
            f"| {row['name']} | {row['triangles']} | {row['base_faces']} | "
            f"{_pct(b['outside']) if b else ''} | {_pct(m['outside'])} | "
            f"{'' if b is None else format(b['mean_distance'], '.2e')} | "
            f"{m['mean_distance']:.2e} | {_pct(m['uncovered'])} | {_cpu(m)} | "
            f"{'yes' if ok else 'no'} |")
    lines += ["", f"Within 0.5 %: {sum(within)} of {len(within)}."]
    return lines


def _largest(values):
    values = [v for v in values if v is not None]
    return max(values) if values else None


def _mode(row, mode, seed=0):
    return next(m for m in row["modes"] if m["mode"] == mode and m.get("seed", 0) == seed)


def _label(m):
    if m["mode"] == "peer":
        return f"peer ({m['faces']} quads)"
    return m["mode"] if "seed" not in m else f"{m['mode']}, seed {m['seed']}"


def _refits(m):
    return "" if m.get("refit_crossings") is None else str(m["refit_crossings"])


def _time_limit(row):
    """The issue's time limit for a fit of this row's target (s), None above 30k triangles."""
    if row["name"] == LARGE:
        return 6.0
    return 2.0 if row["triangles"] <= 30_000 else None


def _seconds(m):
    return m.get("cpu_seconds", m["seconds"])


def comparison(rows, before):
    """Markdown lines: every mode's figures in an older run (``before``) and in this one."""
    old = {(r["name"], m["mode"]): m for r in before["rows"] if "modes" in r for m in r["modes"]}
    lines = ["", "## Before / after", "",
             f"Before: the same benchmark on the previous fit ({before['info'].get('label', '')}), "
             f"run {before['info']['date']} on the same base meshes (built by the same "
             "base-mesh stage). CPU seconds are the fit process's own (less noisy than wall "
             "clock on the shared machine).", "",
             "| mesh | mode | CPU s before | CPU s after | wall s before | wall s after | "
             "mean before | mean after | max before | max after | outside before | "
             "outside after | self-int. before | self-int. after |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        for m in row.get("modes", []):
            b = old.get((row["name"], m["mode"]))
            if b is None:
                continue
            lines.append(
                f"| {row['name']} | {m['mode']} | {_cpu(b)} | {_cpu(m)} | {b['seconds']:.2f} | "
                f"{m['seconds']:.2f} | {b['mean_distance']:.2e} | {m['mean_distance']:.2e} | "
                f"{b['max_distance']:.2e} | {m['max_distance']:.2e} | {_pct(b['outside'])} | "
                f"{_pct(m['outside'])} | {b['self_intersections']} | {m['self_intersections']} |")
    return lines


def _cpu(row):
    return f"{row['cpu_seconds']:.2f}" if "cpu_seconds" in row else ""


def _within(value, limit):
    return value is not None and value <= limit


def _figure_time(row):
    return f" ({row['measure_seconds']:.2f})" if "measure_seconds" in row else ""


def _pct(value):
    return "n/a" if value is None else f"{100 * value:.2f}%"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", choices=sorted({**CASES, **RULE_ONLY}),
                        default=None)
    parser.add_argument("--baseline", help="folder holding an older checkout's core/")
    parser.add_argument("--out", default=HERE)
    parser.add_argument("--compare", help="fit_results.json of an earlier run: adds a "
                        "before / after table")
    parser.add_argument("--label", default="", help="what this run measures (recorded)")
    parser.add_argument("--baseline-label", default="", help="what the --baseline tree is "
                        "(recorded)")
    parser.add_argument("--render", help="fit_results.json of a finished run: write its "
                        "FIT_RESULTS.md again without measuring")
    args = parser.parse_args(argv)
    if args.render:
        with open(args.render, encoding="utf-8") as handle:
            done = json.load(handle)
        _write(args.out, "FIT_RESULTS.md", markdown(done["rows"], done["info"])
               + _compared(done["rows"], args.compare))
        return
    info = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu_count": os.cpu_count(),
            "load": os.getloadavg()[0], "label": args.label,
            "baseline_label": args.baseline_label, "max_measure": "search"}
    cases = {**CASES, **RULE_ONLY}
    names = args.only or list(cases)
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for name in names:
            print(f"fit_bench: {name}", flush=True)
            rows.append(run_case(name, cases[name], args.baseline, work))
    for filename, text in (("fit_results.json", json.dumps({"info": info, "rows": rows}, indent=1)),
                           ("FIT_RESULTS.md", markdown(rows, info) + _compared(rows, args.compare))):
        _write(args.out, filename, text)


def _write(folder, filename, text):
    """Write ``text`` to ``folder/filename`` atomically."""
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, filename)
    with open(path + ".tmp", "w", encoding="utf-8") as handle:
        handle.write(text)
    os.replace(path + ".tmp", path)
    print(f"fit_bench: wrote {path}")


def _compared(rows, path):
    if not path:
        return ""
    with open(path, encoding="utf-8") as handle:
        return "\n".join(comparison(rows, json.load(handle))) + "\n"


if __name__ == "__main__":
    main()
