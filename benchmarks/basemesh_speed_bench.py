# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh stage speed and determinism (issue 8): CPU seconds per dev mesh, before and after.

Usage::

    .venv/bin/python benchmarks/basemesh_speed_bench.py --label after [--repo PATH]
                                                        [--meshes DIR] [--only NAME ...]

``--repo`` is the checkout whose ``core`` is measured (default: this one; for the "before"
column, an export of the commit to compare with). Every mesh runs in its own process: the
labeling once, then the base-mesh stage (``core.stages.basemesh.run_basemesh``, default
parameters, one part) twice. Per mesh: CPU seconds of the stage (the first run), of its
polycube attempt (``_polycube_base_mesh``), the mixed-integer programs (count, the slowest one's
CPU seconds, the most branch-and-bound nodes), the method, faces and a hash of the base mesh,
and whether the second run gave the same base mesh. Rows are kept per label in
``benchmarks/basemesh_speed_results.json``; ``benchmarks/BASEMESH_SPEED_RESULTS.md`` shows
every label side by side.
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


def run_case(path):
    """One mesh with the ``core`` on ``sys.path``; returns a JSON-serialisable dict."""
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
    state = reconstruct(path, stop_after="labeling").state
    hashes, row = [], {}
    for run in range(2):
        programs.clear()
        attempt["cpu"] = 0.0
        started = time.process_time()
        result = run_basemesh(state.intake, state.parts, state.frames, state.labeling,
                              ReconstructionParams(), NO_PROGRESS)
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
                   "fallback_reason": info.get("fallback_reason")}
    row["hash"] = hashes[0]
    row["same_twice"] = hashes[0] == hashes[1]
    return row


def write_markdown(results):
    """BASEMESH_SPEED_RESULTS.md from every label in ``results`` (label -> mesh -> row)."""
    labels = list(results)
    meshes = sorted({m for rows in results.values() for m in rows})
    lines = ["# Base-mesh stage: CPU seconds and determinism (issue 8)", "",
             "Written by `benchmarks/basemesh_speed_bench.py` (one process per mesh; default "
             "parameters, one part; the labeling is not timed). `stage` is the CPU seconds of "
             "`run_basemesh` (polycube attempt + paired decimation where it falls back), `poly` "
             "of its polycube attempt, `MILPs` the mixed-integer programs solved (`slowest` "
             "CPU s, `nodes` the most branch-and-bound nodes of one), `same` whether a second "
             "run in the same process gave the same base mesh (vertices and faces bit for "
             "bit), `hash` a digest of the base mesh. The machine has 2 cores shared with "
             "other jobs, so CPU seconds vary by about 10%.", ""]
    header = "| mesh | triangles |"
    rule = "|---|---:|"
    for label in labels:
        header += (f" {label} stage | poly | MILPs | slowest | nodes | method | faces | hash "
                   "| same |")
        rule += "---:|---:|---:|---:|---:|---|---:|---|---|"
    lines += [header, rule]
    for mesh in meshes:
        line = f"| {mesh} |"
        triangles = next((rows[mesh]["triangles"] for rows in results.values() if mesh in rows),
                         "")
        line += f" {triangles} |"
        for label in labels:
            row = results[label].get(mesh)
            if row is None or "error" in row:
                line += " " + ("failed" if row else "-") + " |" * 9
                continue
            method = "polycube" if row["method"] == "polycube" else "decimation"
            line += (f" {row['stage_cpu']:.2f} | {row['polycube_cpu']:.2f} | {row['programs']} "
                     f"| {row['slowest_program_cpu']:.2f} | {row['most_nodes']} | {method} | "
                     f"{row['faces']} | `{row['hash']}` | {'yes' if row['same_twice'] else 'NO'} |")
        lines.append(line)
    if len(labels) >= 2:
        first, last = labels[0], labels[-1]
        same = [m for m in meshes if m in results[first] and m in results[last]
                and results[first][m].get("hash") == results[last][m].get("hash")
                and results[first][m].get("method") == results[last][m].get("method")]
        lines += ["", f"Same method and bit-identical base mesh in `{first}` and `{last}`: "
                      f"{len(same)} of {len(meshes)} meshes."]
    lines += ["", "Why the polycube attempt fails where it does (last label):", ""]
    for mesh in meshes:
        row = results[labels[-1]].get(mesh, {})
        if row.get("fallback_reason"):
            lines.append(f"- {mesh}: {row['fallback_reason']}")
    with open(RESULTS_MD + ".tmp", "w") as handle:
        handle.write("\n".join(lines) + "\n")
    os.replace(RESULTS_MD + ".tmp", RESULTS_MD)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", required=True, help="column name, e.g. before or after")
    parser.add_argument("--repo", default=REPO, help="checkout whose core is measured")
    parser.add_argument("--meshes", default=DEFAULT_MESHES)
    parser.add_argument("--only", nargs="*", default=None)
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        sys.path.insert(0, os.path.abspath(args.repo))
        print(json.dumps(run_case(args.case)))
        return
    names = sorted(n for n in os.listdir(args.meshes) if n.lower().endswith(MESH_SUFFIXES))
    if args.only:
        names = [n for n in names if n in args.only or os.path.splitext(n)[0] in args.only]
    results = {}
    if os.path.exists(RESULTS_JSON):
        with open(RESULTS_JSON) as handle:
            results = json.load(handle)
    rows = results.setdefault(args.label, {})
    for name in names:
        done = subprocess.run([sys.executable, os.path.abspath(__file__), "--label", args.label,
                               "--repo", args.repo, "--case", os.path.join(args.meshes, name)],
                              capture_output=True, text=True, cwd=args.repo)
        if done.returncode == 0:
            rows[name] = json.loads(done.stdout.strip().splitlines()[-1])
        else:
            rows[name] = {"error": done.stderr.strip().splitlines()[-1:]}
        print(name, rows[name].get("stage_cpu"), rows[name].get("method"),
              rows[name].get("same_twice"), flush=True)
        with open(RESULTS_JSON + ".tmp", "w") as handle:
            json.dump(results, handle, indent=1)
        os.replace(RESULTS_JSON + ".tmp", RESULTS_JSON)
    write_markdown(results)


if __name__ == "__main__":
    main()
