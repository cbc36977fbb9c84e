# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh stage speed and determinism: CPU seconds per dev mesh, before and after.

Usage::

    .venv/bin/python benchmarks/basemesh_speed_bench.py --label after [--repo PATH]
                                                        [--meshes DIR] [--only NAME ...]
                                                        [--target-faces N] [--parts auto]
                                                        [--profile NAME ...]

``--repo`` is the checkout whose ``core`` is measured (default: this one; for the "before"
column, an export of the commit to compare with). Every mesh runs in its own process: the
labeling once, then the base-mesh stage (``core.stages.basemesh.run_basemesh``, default
parameters but ``--target-faces`` and ``--parts``) twice. Per mesh: CPU seconds of the parts
stage and a hash of its ``face_part`` (with ``--parts auto``), of the base-mesh stage (the
first run), of its polycube attempt (``_polycube_base_mesh``), the mixed-integer programs
(count, the slowest one's CPU seconds, the most branch-and-bound nodes), the method, faces and
a hash of the base mesh, and whether the second run gave the same base mesh; ``--profile``
meshes get a third, profiled run. Rows are kept per label in
``benchmarks/basemesh_speed_results.json``; ``benchmarks/BASEMESH_SPEED_RESULTS.md`` shows the
labels of one face budget and parts mode side by side.
"""
import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
RESULTS_JSON = os.path.join(HERE, "basemesh_speed_results.json")
RESULTS_MD = os.path.join(HERE, "BASEMESH_SPEED_RESULTS.md")
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off")
PROFILE_ROWS = 14
"""Functions listed per profiled mesh."""


def run_case(path, target_faces, parts="single", profile=False):
    """One mesh with the ``core`` on ``sys.path``; returns a JSON-serialisable dict (with a
    third, profiled run of the stage when ``profile``)."""
    import hashlib
    import time

    import numpy as np
    import scipy.optimize

    programs = []
    solver = scipy.optimize.milp

    def timed_milp(*args, **kwargs):
        started = time.process_time()
        result = solver(*args, **kwargs)
        programs.append({"cpu": time.process_time() - started,
                         "nodes": result.get("mip_node_count") or 0})
        return result

    scipy.optimize.milp = timed_milp  # before core imports it
    import core.quadmesh.base_mesh as base_mesh
    from core.params import ReconstructionParams
    from core.pipeline import reconstruct
    from core.progress import NO_PROGRESS
    from core.stages.basemesh import run_basemesh

    attempt = {"cpu": 0.0}
    polycube = base_mesh._polycube_base_mesh

    def timed_polycube(*args, **kwargs):
        started = time.process_time()
        try:
            return polycube(*args, **kwargs)
        finally:
            attempt["cpu"] += time.process_time() - started

    base_mesh._polycube_base_mesh = timed_polycube
    directions = []
    repair = base_mesh.make_loops_rectilinear

    def timed_repair(*args, **kwargs):
        started = time.process_time()
        outcome = "solved"
        try:
            return repair(*args, **kwargs)
        except Exception:
            outcome = "infeasible"
            raise
        finally:
            directions.append([outcome, round(time.process_time() - started, 2)])

    base_mesh.make_loops_rectilinear = timed_repair
    import core.segmentation.skeleton_parts as skeleton_parts

    parts_cpu = {"cpu": 0.0}
    segmentation = skeleton_parts.skeleton_segmentation

    def timed_segmentation(*args, **kwargs):
        started = time.process_time()
        try:
            return segmentation(*args, **kwargs)
        finally:
            parts_cpu["cpu"] += time.process_time() - started

    skeleton_parts.skeleton_segmentation = timed_segmentation  # imported by run_parts per call
    params = ReconstructionParams(target_faces=target_faces, parts=parts)
    state = reconstruct(path, params, stop_after="labeling").state
    hashes, row = [], {}
    for run in range(2):
        programs.clear()
        directions.clear()
        attempt["cpu"] = 0.0
        started = time.process_time()
        result = run_basemesh(state.intake, state.parts, state.frames, state.labeling,
                              params, NO_PROGRESS)
        seconds = time.process_time() - started
        cage = result.cage
        digest = hashlib.sha1(np.ascontiguousarray(cage.vertices).tobytes()
                              + np.ascontiguousarray(cage.face_vertices).tobytes())
        hashes.append(digest.hexdigest()[:12])
        if run == 0:
            info = result.report
            row = {"triangles": int(len(state.intake.target.faces)),
                   "stage_cpu": round(seconds, 2), "polycube_cpu": round(attempt["cpu"], 2),
                   "programs": len(programs),
                   "slowest_program_cpu": round(max((p["cpu"] for p in programs), default=0), 2),
                   "most_nodes": int(max((p["nodes"] for p in programs), default=0)),
                   "method": info["method"], "faces": int(info["faces"]),
                   "target_faces": int(target_faces), "parts": parts,
                   "parts_cpu": round(parts_cpu["cpu"], 2),
                   "face_part_hash": hashlib.sha1(np.ascontiguousarray(
                       state.parts.face_part, dtype=np.int64).tobytes()).hexdigest()[:12],
                   "fallback_reason": info.get("fallback_reason"),
                   "side_directions": [list(d) for d in directions]}
    row["hash"] = hashes[0]
    row["same_twice"] = hashes[0] == hashes[1]
    if profile:
        row["profile"] = profile_stage(state, params)
    return row


def profile_stage(state, params):
    """Cumulative CPU seconds of the stage's main functions (cProfile, CPU clock), top first."""
    import cProfile
    import pstats
    import time

    from core.progress import NO_PROGRESS
    from core.stages.basemesh import run_basemesh

    profiler = cProfile.Profile(time.process_time)
    profiler.enable()
    run_basemesh(state.intake, state.parts, state.frames, state.labeling, params, NO_PROGRESS)
    profiler.disable()
    totals = {}
    for (filename, _, function), (_, calls, _, cumulative, _) in \
            pstats.Stats(profiler).stats.items():
        if os.sep + "core" + os.sep in filename or function == "milp":
            name = f"{os.path.basename(filename)}:{function}"
            seconds, count = totals.get(name, (0.0, 0))
            totals[name] = (seconds + cumulative, count + calls)
    top = sorted(totals.items(), key=lambda item: -item[1][0])[:PROFILE_ROWS]
    return [[name, round(seconds, 2), calls] for name, (seconds, calls) in top]


def write_markdown(results):
    """BASEMESH_SPEED_RESULTS.md from every label in ``results`` (label -> mesh -> row): one
    table per face budget, its labels side by side, and its last two labels compared."""
    lines = ["# Base-mesh stage: CPU seconds and determinism", "",
             "Written by `benchmarks/basemesh_speed_bench.py` (one process per mesh; default "
             "parameters, the face budget and parts mode of the table; the labeling is not in "
             "`stage`). "
             "`stage` is the CPU seconds of `run_basemesh` (polycube attempt + paired "
             "decimation where it falls back), `poly` of its polycube attempt, `MILPs` the "
             "mixed-integer programs solved (`slowest` CPU s, `nodes` the most branch-and-bound "
             "nodes of one), `same` whether a second run in the same process gave the same base "
             "mesh (vertices and faces bit for bit), `hash` a digest of the base mesh. The "
             "machine has 2 cores shared with other jobs, so CPU seconds vary by about 10%."]
    budgets = {}
    for label, rows in results.items():
        budget = next((row["target_faces"] for row in rows.values() if "target_faces" in row),
                      300)
        parts = next((row["parts"] for row in rows.values() if "parts" in row), "single")
        budgets.setdefault((budget, parts), []).append(label)
    for (budget, parts), labels in budgets.items():
        meshes = sorted({m for label in labels for m in results[label]})
        auto = parts != "single"
        header, rule = "| mesh | triangles |", "|---|---:|"
        for label in labels:
            header += ((f" {label}: parts s | face_part |" if auto else f" {label}:")
                       + " stage | poly | MILPs | slowest | nodes | method | faces | hash | same |")
            rule += ("---:|---|" if auto else "") + "---:|---:|---:|---:|---:|---|---:|---|---|"
        lines += ["", f"## Face budget {budget}" + (f", --parts {parts}" if auto else ""), "",
                  header, rule]
        for mesh in meshes:
            triangles = next((results[label][mesh].get("triangles", "") for label in labels
                              if mesh in results[label]), "")
            line = f"| {mesh} | {triangles} |"
            for label in labels:
                row = results[label].get(mesh)
                if row is None or "error" in row:
                    line += " " + ("failed" if row else "-") + " |" * (10 if auto else 8)
                    continue
                method = "polycube" if row["method"] == "polycube" else "decimation"
                if auto:
                    line += f" {row['parts_cpu']:.2f} | `{row['face_part_hash']}` |"
                line += (f" {row['stage_cpu']:.2f} | {row['polycube_cpu']:.2f} | "
                         f"{row['programs']} | {row['slowest_program_cpu']:.2f} | "
                         f"{row['most_nodes']} | {method} | {row['faces']} | `{row['hash']}` | "
                         f"{'yes' if row['same_twice'] else 'NO'} |")
            lines.append(line)
        if len(labels) >= 2:
            first, last = results[labels[-2]], results[labels[-1]]  # the latest pair
            both = [m for m in meshes if "hash" in first.get(m, {}) and "hash" in last.get(m, {})]
            same = [m for m in both if first[m]["hash"] == last[m]["hash"]
                    and first[m]["method"] == last[m]["method"]]
            total = [sum(rows[m]["stage_cpu"] for m in both) for rows in (first, last)]
            lines += ["", f"Same method and bit-identical base mesh in `{labels[-2]}` and "
                          f"`{labels[-1]}`: {len(same)} of {len(both)} meshes; stage CPU "
                          f"seconds summed over them {total[0]:.1f} and {total[1]:.1f}."]
            if auto:
                same_parts = [m for m in both
                              if first[m]["face_part_hash"] == last[m]["face_part_hash"]]
                seconds = [sum(rows[m]["parts_cpu"] for m in both) for rows in (first, last)]
                lines[-1] += (f" Same face_part: {len(same_parts)} of {len(both)}; parts-stage "
                              f"CPU seconds summed {seconds[0]:.1f} and {seconds[1]:.1f}.")
        lines += ["", f"Why the polycube attempt fails where it does (`{labels[-1]}`):", ""]
        for mesh in meshes:
            row = results[labels[-1]].get(mesh, {})
            if row.get("fallback_reason"):
                calls = row.get("side_directions")
                lines.append(f"- {mesh}: {row['fallback_reason']}" + (
                    "" if not calls else " [side-direction programs: "
                    + ", ".join(f"{outcome} in {cpu:.2f} s" for outcome, cpu in calls) + "]"))
        for label in labels:
            for mesh in meshes:
                profile = results[label].get(mesh, {}).get("profile")
                if profile:
                    lines += ["", f"Profile of the stage on {mesh} (`{label}`; cumulative CPU "
                                  "seconds of a third run under cProfile, which adds its own "
                                  "overhead):", "", "| function | CPU s | calls |",
                              "|---|---:|---:|"]
                    lines += [f"| `{name}` | {seconds:.2f} | {calls} |"
                              for name, seconds, calls in profile]
    with open(RESULTS_MD + ".tmp", "w") as handle:
        handle.write("\n".join(lines) + "\n")
    os.replace(RESULTS_MD + ".tmp", RESULTS_MD)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", required=True, help="column name, e.g. before or after")
    parser.add_argument("--repo", default=REPO, help="checkout whose core is measured")
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--target-faces", type=int, default=300,
                        help="face budget (a label measures one budget)")
    parser.add_argument("--parts", default="single", choices=("single", "auto"),
                        help="parts mode (a label measures one mode)")
    parser.add_argument("--profile", nargs="*", default=[],
                        help="meshes whose stage is also profiled")
    parser.add_argument("--case", help=argparse.SUPPRESS)
    parser.add_argument("--profile-case", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        sys.path.insert(0, os.path.abspath(args.repo))
        print(json.dumps(run_case(args.case, args.target_faces, args.parts,
                                  profile=args.profile_case)))
        return
    names = sorted(n for n in os.listdir(args.meshes) if n.lower().endswith(MESH_SUFFIXES))
    if args.only:
        names = [n for n in names if n in args.only or os.path.splitext(n)[0] in args.only]
    rows = {}
    if os.path.exists(RESULTS_JSON):
        with open(RESULTS_JSON) as handle:
            rows = json.load(handle).get(args.label, {})
    for name in names:
        profiled = name in args.profile or os.path.splitext(name)[0] in args.profile
        done = subprocess.run([sys.executable, os.path.abspath(__file__), "--label", args.label,
                               "--repo", args.repo, "--target-faces", str(args.target_faces),
                               "--parts", args.parts,
                               "--case", os.path.join(args.meshes, name)]
                              + (["--profile-case"] if profiled else []),
                              capture_output=True, text=True, cwd=args.repo)
        if done.returncode == 0:
            rows[name] = json.loads(done.stdout.strip().splitlines()[-1])
        else:
            rows[name] = {"error": done.stderr.strip().splitlines()[-1:]}
        print(name, rows[name].get("stage_cpu"), rows[name].get("method"),
              rows[name].get("same_twice"), flush=True)
        _save(args.label, rows)
    with open(RESULTS_JSON) as handle:
        write_markdown(json.load(handle))


def _save(label, rows):
    """Write ``rows`` as ``label`` into RESULTS_JSON, keeping the other labels in it."""
    results = {}
    if os.path.exists(RESULTS_JSON):
        with open(RESULTS_JSON) as handle:
            results = json.load(handle)
    results[label] = rows
    with open(RESULTS_JSON + ".tmp", "w") as handle:
        json.dump(results, handle, indent=1)
    os.replace(RESULTS_JSON + ".tmp", RESULTS_JSON)


if __name__ == "__main__":
    main()
