# SPDX-License-Identifier: LGPL-2.1-or-later
"""Benchmark cases; each runs in its own process, started by ``benchmarks/run.py``.

Usage (internal): ``python benchmarks/cases.py SPEC.json RESULT.json``. ``SPEC.json`` holds
``{"kind": ..., ...}``; the case's figures are written to ``RESULT.json``. Peak memory is
``ru_maxrss`` of this process, so it includes the interpreter and the imported libraries
(about 100 MiB for numpy, scipy and trimesh; more once FreeCAD is loaded).

Kinds
-----
mesh : intake, parts, frames and labeling of one mesh file with ``parts`` = ``single`` or
    ``auto``; HBECVT figures before repair, the pipeline's figures after repair, validity
    judged on the written ``--labels`` PLY file, the nearest-direction baselines, PNGs.
cage : a sample subdivision cage through ``polycube_wb.api.subd_to_solid`` and a STEP
    round trip.
step_speed : ``grid_sphere(n)`` to a valid STEP file, timed.
subdivision_speed : ``build_hierarchy`` plus composite matrix of ``grid_sphere(n)``, timed.
labeling_speed : a mesh refined by midpoint subdivision to about 100,000 triangles, labeled
    with one part, timed.
"""
import json
import os
import resource
import sys
import tempfile
import time
import traceback

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if REPO not in sys.path:
    sys.path.insert(0, REPO)

import numpy as np  # noqa: E402

TALLY_KEYS = ("invalid_charts", "invalid_boundaries", "invalid_corners", "turning_points")


def peak_mb():
    """Peak resident memory of this process so far, MiB."""
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)


class _StageMemory:
    """Progress sink that snapshots peak memory when each stage starts (memory before it)."""

    def __init__(self):
        self.before = {}

    def report(self, stage, fraction, message=""):
        self.before.setdefault(stage, peak_mb())

    def check_cancel(self):
        pass


def _counts(report):
    """Validity counts of a ``check_validity`` report."""
    counts = {"valid": bool(report["valid"]), "charts": int(report["charts"]),
              "corners": int(report["corners"])}
    counts.update({k: int(report[k]["count"]) for k in TALLY_KEYS})
    return counts


def _examples(report):
    """First example of each invalid category that has any (for the "why" list)."""
    return {k: report[k]["examples"][0] for k in TALLY_KEYS[:3]
            if report[k]["count"] and report[k]["examples"]}


def _preload():
    """Import the modules the pipeline stages load lazily, so stage times measure the work."""
    import core.mesh_io  # noqa: F401
    import core.segmentation.labeling  # noqa: F401
    import core.segmentation.parts  # noqa: F401
    import core.segmentation.repair  # noqa: F401
    import core.self_intersection  # noqa: F401
    import core.validate  # noqa: F401
    import trimesh  # noqa: F401


def _error_line(exc):
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def mesh_case(spec):
    """Figures of one mesh and one part mode (see module docstring)."""
    from core.errors import PolycubeInputError
    from core.params import ReconstructionParams
    from core.pipeline import reconstruct
    from core.segmentation.labeling import (face_normals, hbecvt_labeling,
                                            nearest_direction_labels)
    from core.segmentation.labels_file import validity_from_labels_file, write_labels_ply
    from core.segmentation.validity import check_validity

    _preload()
    mode = spec["mode"]
    memory = _StageMemory()
    started = time.perf_counter()
    try:
        params = ReconstructionParams(parts=mode)
        result = reconstruct(spec["path"], params, memory, stop_after="labeling")
    except PolycubeInputError as exc:
        return {"status": "rejected", "error": _error_line(exc),
                "seconds": round(time.perf_counter() - started, 3), "peak_memory_mb": peak_mb()}
    report = result.report
    out = {"status": "ok" if result.failed is None else "failed",
           "stages": report["stages"], "input": report.get("input"),
           "pipeline_seconds": report["total_seconds"],
           "peak_memory_mb": {"intake": memory.before.get("parts"),
                              "parts_frames": memory.before.get("labeling"),
                              "labeling": report["peak_memory_mb"]}}
    if result.failed is not None:
        failed = [k for k, v in report["stages"].items() if v["status"] == "failed"]
        out["error"] = f"stage {failed[0] if failed else '?'}: {_error_line(result.failed)}"
    if "parts" in report:
        out["parts"] = report["parts"]
    if "frames" in report:
        out["frames"] = report["frames"]
    if "labeling" not in report:
        return out
    state = result.state
    mesh, field, face_part = state.intake.surface, state.frames.frame_field, state.parts.face_part
    V, F = mesh.vertices, mesh.faces
    out["labeling"] = {k: v for k, v in report["labeling"].items() if k != "examples"}

    clock = time.perf_counter()
    raw, info = hbecvt_labeling(V, F, face_part, field.face_frame, field.face_interface_axis,
                                lam=params.lam, penalty=params.penalty,
                                max_sweeps=params.max_sweeps)
    hbecvt_seconds = time.perf_counter() - clock
    before = _counts(check_validity(V, F, face_part, raw, field.face_frame).report)
    out["before_repair"] = {**before, "hbecvt_seconds": round(hbecvt_seconds, 3), **info}

    with tempfile.TemporaryDirectory(prefix="polycube-bench-") as tmp:
        ply = os.path.join(tmp, "labels.ply")
        write_labels_ply(ply, V, F, face_part, state.labeling.face_label, field.face_frame)
        judged = validity_from_labels_file(ply)
        out["labels_file"] = {**_counts(judged), "examples": _examples(judged)}
        out["labels_file"]["bytes"] = os.path.getsize(ply)

    normals = face_normals(V, F)
    nearest = nearest_direction_labels(normals, field.face_frame)
    out["nearest_same_frames"] = _counts(check_validity(V, F, face_part, nearest,
                                                        field.face_frame).report)
    if mode == "single":
        identity = np.broadcast_to(np.eye(3), (len(F), 3, 3))
        labels = nearest_direction_labels(normals, identity)
        out["nearest_identity"] = _counts(check_validity(V, F, np.zeros(len(F), np.int64), labels,
                                                         identity).report)
    out["peak_memory_mb"]["total"] = peak_mb()
    if spec.get("images"):
        out["images"] = _render_mesh(spec, V, F, face_part, state.labeling.face_label, out)
    return out


def _render_mesh(spec, V, F, face_part, face_label, out):
    from render import render_labels, render_parts

    folder, stem, mode = spec["images"], spec["stem"], spec["mode"]
    os.makedirs(folder, exist_ok=True)
    lab = out["labels_file"]
    verdict = "valid" if lab["valid"] else (
        f"invalid: {lab['invalid_charts']} charts, {lab['invalid_boundaries']} boundaries, "
        f"{lab['invalid_corners']} corners")
    parts = int(face_part.max()) + 1
    images = {}
    clock = time.perf_counter()
    if mode == "single" or parts > 1:
        name = f"{stem}_labels_{mode}.png"
        render_labels(os.path.join(folder, name), V, F, face_label,
                      f"{stem}: labels, {mode} part{'s' if parts > 1 else ''} "
                      f"({parts} part{'s' if parts > 1 else ''}, {lab['charts']} charts, {verdict})")
        images["labels"] = name
    if mode == "auto":
        name = f"{stem}_parts_auto.png"
        render_parts(os.path.join(folder, name), V, F, face_part,
                     f"{stem}: automatic parts ({parts})")
        images["parts"] = name
    images["seconds"] = round(time.perf_counter() - clock, 2)
    return images


def _write_cage(name, folder):
    from core.polymesh_io import write_polymesh
    from core.subdivision import sample_cages

    builders = {"cube": sample_cages.cube, "torus": sample_cages.torus,
                "mixed_prism": sample_cages.mixed_prism,
                "genus3_block": sample_cages.genus3_block}
    if name.startswith("grid_sphere_"):
        mesh = sample_cages.grid_sphere(int(name.rsplit("_", 1)[1]))
    else:
        mesh = builders[name]()
    path = os.path.join(folder, f"{name}.obj")
    write_polymesh(path, mesh)
    return path


def cage_case(spec):
    """A sample cage to a STEP solid through ``subd_to_solid``, then a STEP round trip."""
    from polycube_wb.api import subd_to_solid
    from polycube_wb.step_io import step_round_trip

    measure = spec.get("measure", True)
    with tempfile.TemporaryDirectory(prefix="polycube-bench-") as tmp:
        obj = _write_cage(spec["cage"], tmp)
        step = os.path.join(tmp, f"{spec['cage']}.step")
        clock = time.perf_counter()
        solid, report = subd_to_solid(obj, step, measure=measure)
        api_wall = time.perf_counter() - clock
        clock = time.perf_counter()
        round_trip = step_round_trip(solid, step)
        round_trip["seconds"] = round(time.perf_counter() - clock, 3)
        round_trip["step_bytes"] = os.path.getsize(step)
    report["brep"].pop("step_path", None)
    return {"status": "ok", "measure": measure, "base_mesh": report["base_mesh"],
            "patches": report["patches"], "brep": report["brep"], "stages": report["stages"],
            "total_seconds": report["total_seconds"], "api_wall_seconds": round(api_wall, 3),
            "round_trip": round_trip, "peak_memory_mb": peak_mb()}


def subdivision_speed_case(spec):
    """Median of ``repeats`` timings of ``build_hierarchy(grid_sphere(n), levels)`` plus composite."""
    from core.subdivision.catmull_clark import build_hierarchy
    from core.subdivision.sample_cages import grid_sphere

    mesh = grid_sphere(spec["n"])
    levels = spec["levels"]
    times = []
    for _ in range(spec.get("repeats", 3)):
        clock = time.perf_counter()
        hierarchy = build_hierarchy(mesh, levels)
        composite = hierarchy.composite(levels - 1)
        times.append(time.perf_counter() - clock)
    fine = hierarchy.meshes[-1]
    return {"status": "ok", "base_faces": int(mesh.n_faces), "levels": levels,
            "fine_faces": int(fine.n_faces), "fine_vertices": int(len(fine.vertices)),
            "composite_shape": list(composite.shape), "composite_nnz": int(composite.nnz),
            "seconds_all": [round(t, 4) for t in times], "seconds_first": round(times[0], 4),
            "seconds_median": round(float(np.median(times)), 4), "peak_memory_mb": peak_mb()}


def labeling_speed_case(spec):
    """Label a midpoint-refined copy of a mesh (single part) and time the labeling stage."""
    import trimesh

    from core.mesh_io import read_triangle_soup
    from core.pipeline import reconstruct
    from core.validate import merge_identical_vertices

    _preload()
    V, F = read_triangle_soup(spec["path"])
    V, F, _ = merge_identical_vertices(np.asarray(V, np.float64), np.asarray(F, np.int64))
    while len(F) < spec["triangles"]:
        V, F = trimesh.remesh.subdivide(V, F)
    with tempfile.TemporaryDirectory(prefix="polycube-bench-") as tmp:
        path = os.path.join(tmp, "refined.ply")
        trimesh.Trimesh(V, F, process=False).export(path)
        result = reconstruct(path, {"parts": "single", "check_self_intersections": False},
                             stop_after="labeling")
    lab = result.report.get("labeling", {})
    stages = result.report["stages"]
    return {"status": "ok" if result.failed is None else "failed",
            "source": os.path.basename(spec["path"]), "triangles": int(len(F)),
            "labeling_seconds": stages["labeling"]["seconds"],
            "frames_seconds": stages["frames"]["seconds"],
            "valid": lab.get("valid"), "charts": lab.get("charts"),
            "peak_memory_mb": peak_mb()}


def reconstruction_case(spec):
    """The whole pipeline (one part) to STEP, then the check against the target."""
    from core.errors import PolycubeError, PolycubeInputError
    from polycube_wb.api import check, reconstruct_to_step

    _preload()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="polycube-bench-") as tmp:
        step = os.path.join(tmp, "result.step")
        try:
            report = reconstruct_to_step(spec["path"], step, parts="single")
            status, error = "ok", ""
        except PolycubeInputError as exc:
            return {"status": "rejected", "error": _error_line(exc), "peak_memory_mb": peak_mb()}
        except PolycubeError as exc:
            report = getattr(exc, "report", None) or {}
            status, error = "incomplete", _error_line(exc)
        seconds = round(time.perf_counter() - started, 3)
        out = {"status": status, "error": error, "seconds": seconds,
               "stages": report.get("stages", {}), "peak_memory_mb": peak_mb()}
        for key in ("polycube", "base_mesh", "fit", "brep"):
            if key in report:
                out[key] = report[key]
        if os.path.exists(step):
            clock = time.perf_counter()
            out["check"] = check(spec["path"], step)
            out["check_seconds"] = round(time.perf_counter() - clock, 3)
    return out


CASES = {"reconstruction": reconstruction_case, "mesh": mesh_case, "cage": cage_case, "step_speed": cage_case,
         "subdivision_speed": subdivision_speed_case, "labeling_speed": labeling_speed_case}


def main(argv):
    spec_path, result_path = argv
    with open(spec_path, encoding="utf-8") as fh:
        spec = json.load(fh)
    started = time.perf_counter()
    try:
        result = CASES[spec["kind"]](spec)
    except Exception as exc:  # recorded in the results, the benchmark goes on
        result = {"status": "failed", "error": _error_line(exc),
                  "traceback": traceback.format_exc(limit=6), "peak_memory_mb": peak_mb()}
    result["case_wall_seconds"] = round(time.perf_counter() - started, 3)
    with open(result_path, "w", encoding="utf-8") as fh:
        json.dump(result, fh, indent=1, default=_plain)
    return 0


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
