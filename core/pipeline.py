# SPDX-License-Identifier: LGPL-2.1-or-later
"""The reconstruction pipeline: runs the core stages in order and builds the report.

Each stage is a function ``stage(state, params) -> dict`` that reads earlier results
from ``state`` (a dict) and returns its own results (merged into ``state``) plus a
``"report"`` entry. A stage that is not built yet raises ``StageNotAvailableError``;
the runner records it as ``not_available`` and marks the later stages ``skipped``.
User errors (``PolycubeInputError``) propagate unchanged; any other exception
is recorded as ``failed`` and the run stops there.
"""
import resource
import time
from dataclasses import dataclass, field

import numpy as np

from core.errors import PolycubeInputError, StageNotAvailableError
from core.params import ReconstructionParams
from core.progress import NO_PROGRESS, SubProgress

CORE_STAGES = ("intake", "parts", "frames", "labeling", "basemesh", "fit", "patches")
STOP_AFTER_CHOICES = ("intake", "parts", "labeling", "basemesh", "fit", "solid")


@dataclass
class PipelineResult:
    """Everything a run produced.

    state : dict of stage outputs (``target``, ``face_part``, ``frames``, ``face_label``,
        ``validity``, ``base_mesh``, ``patches``, ...), present for the stages that ran.
    report : dict, the JSON report (see README, "Report").
    failed : the exception of a stage that failed unexpectedly, else None.
    """

    state: dict
    report: dict
    failed: Exception = None
    timings: dict = field(default_factory=dict)


def peak_memory_mb():
    """Peak resident memory of this process so far, in MiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def stage_intake(state, params):
    """Read and validate the target; scale it from ``params.units`` to millimetres.

    Every later stage, the solid and the STEP file are in millimetres; the report's
    ``bbox_diagonal`` stays in the file's units, ``unit_to_mm`` is the factor applied.
    """
    from core.mesh_io import read_triangle_soup
    from core.params import UNIT_TO_MM
    from core.types import TriMesh
    from core.validate import validate_target

    if "input_mesh" in state:  # (vertices, faces) arrays given in memory, e.g. by a document
        path = state.get("input_path", "mesh")
        vertices, faces = state["input_mesh"]
    else:
        path = state["input_path"]
        vertices, faces = read_triangle_soup(path)
    factor = UNIT_TO_MM[params.units]
    mesh, summary = validate_target(vertices, faces, components=params.components,
                                    check_self_intersections=params.check_self_intersections,
                                    name=str(path), unit_to_mm=factor)
    mesh = TriMesh(mesh.vertices * factor, mesh.faces)
    report = {"file": str(path), "units": params.units, "unit_to_mm": factor, **summary}
    message = "; ".join(summary["warnings"])
    return {"target": mesh, "input_genus": summary["genus"], "report": report, "message": message}


def stage_parts(state, params):
    from core.segmentation.parts import single_part, skeleton_segmentation

    mesh = state["target"]
    if params.parts == "single":
        from core.mesh_topology import connected_face_components

        # with components="all", every connected component is its own (single) part
        face_part = connected_face_components(mesh.faces).astype(np.int32)
        if face_part.max() == 0:
            face_part = single_part(mesh)
        return {"face_part": face_part,
                "report": {"mode": "single", "parts": int(face_part.max()) + 1}}
    if params.parts == "file":
        face_part = parts_from_file(mesh, params.parts_file)
        return {"face_part": face_part,
                "report": {"mode": "file", "file": params.parts_file,
                           "parts": int(face_part.max()) + 1}}
    result = skeleton_segmentation(mesh)
    return {"face_part": result.face_part, "report": {"mode": "auto", **result.info}}


def read_parts_file(path):
    """The user's part specification from a JSON file (see ``ReconstructionParams.parts_file``).

    Returns ``(kind, value)``: ``kind`` is the file's one key, ``face_part``, ``groups`` or
    ``planes``; ``value`` its (m,) array or list.
    """
    import json

    from core.errors import ParameterError

    try:
        with open(path, encoding="utf-8") as handle:
            data = json.load(handle)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"cannot read the parts file {path}: {exc}") from exc
    kinds = [key for key in ("face_part", "groups", "planes") if isinstance(data, dict) and key in data]
    if len(kinds) != 1:
        raise ParameterError(f"the parts file {path} must hold exactly one of the keys "
                             "'face_part', 'groups' or 'planes'")
    value = data[kinds[0]]
    if kinds[0] != "face_part" and not isinstance(value, list):
        raise ParameterError(f"the parts file {path}: '{kinds[0]}' must be a list, got {value!r}")
    return kinds[0], np.asarray(value) if kinds[0] == "face_part" else value


def parts_from_file(mesh, path):
    """(m,) int32 face_part of ``mesh`` from the parts file ``path``; a ParameterError names
    the file."""
    from core.errors import ParameterError
    from core.segmentation.parts import parts_from_face_groups, parts_from_planes, validate_face_part

    kind, value = read_parts_file(path)
    build = {"face_part": validate_face_part, "groups": parts_from_face_groups,
             "planes": parts_from_planes}[kind]
    try:
        return build(mesh, value)
    except ParameterError as exc:
        raise ParameterError(f"the parts file {path}: {exc}") from None


def stage_frames(state, params):
    from core.segmentation.frames import compute_frames, mean_edge_length

    mesh = state["target"]
    blend = params.blend_factor * mean_edge_length(mesh.vertices, mesh.faces)
    field = compute_frames(mesh, state["face_part"], blend_distance=blend, lam=params.lam)
    report = {"parts": int(len(field.part_frames)), "interfaces": len(field.interfaces),
              "blend_distance": float(field.blend_distance),
              "part_frame_source": list(field.part_frame_source)}
    return {"frames": field, "report": report}


def stage_labeling(state, params):
    from core.segmentation.labeling import (face_normals, hbecvt_labeling, mean_label_angle,
                                            nearest_direction_labels)
    from core.segmentation.monotone import straighten_boundaries
    from core.segmentation.repair import repair_labeling
    from core.segmentation.validity import check_validity

    mesh, field = state["target"], state["frames"]
    face_part = state["face_part"]
    labels, info = hbecvt_labeling(mesh.vertices, mesh.faces, face_part, field.face_frame,
                                   field.face_interface_axis, lam=params.lam,
                                   penalty=params.penalty, max_sweeps=params.max_sweeps)
    repair_report = None
    if params.repair:
        labels, repair_report = repair_labeling(mesh.vertices, mesh.faces, face_part, labels,
                                                field.face_frame, field.face_interface_axis,
                                                lam=params.lam, penalty=params.penalty)
        labels, straighten_report, validity = straighten_boundaries(
            mesh.vertices, mesh.faces, face_part, labels, field.face_frame)
    else:
        straighten_report = None
        validity = check_validity(mesh.vertices, mesh.faces, face_part, labels, field.face_frame)
    normals = face_normals(mesh.vertices, mesh.faces)
    nearest = nearest_direction_labels(normals, field.face_frame)
    v = validity.report
    report = {
        "valid": bool(v["valid"]),
        "parts": int(face_part.max()) + 1,
        "charts": int(v["charts"]),
        "corners": int(v["corners"]),
        "invalid_charts": int(v["invalid_charts"]["count"]),
        "invalid_boundaries": int(v["invalid_boundaries"]["count"]),
        "invalid_corners": int(v["invalid_corners"]["count"]),
        "invalid_at_interfaces": {k: int(v[f"invalid_{k}"]["at_interfaces"])
                                  for k in ("boundaries", "corners")},
        "turning_points": int(v["turning_points"]["count"]),
        "mean_angle_deg": float(mean_label_angle(normals, labels, field.face_frame)),
        "nearest_direction_mean_angle_deg": float(mean_label_angle(normals, nearest, field.face_frame)),
        "hbecvt": info,
        "unfixed": repair_report["unfixed"] if repair_report else None,
        "straightened": straighten_report,
        "examples": {k: v[k]["examples"] for k in
                     ("invalid_charts", "invalid_boundaries", "invalid_corners", "turning_points")},
    }
    message = "valid polycube labeling" if report["valid"] else (
        f"labeling still has {report['invalid_charts']} invalid charts, "
        f"{report['invalid_boundaries']} invalid boundaries, {report['invalid_corners']} invalid corners")
    return {"face_label": labels, "validity": validity, "report": report, "message": message}


def stage_basemesh(state, params):
    from core.errors import LabelingError
    from core.quadmesh import build_base_mesh

    labeling = state["validity"].report
    if not labeling["valid"]:
        raise LabelingError(
            "the base mesh needs a valid labeling; it still has "
            f"{labeling['invalid_charts']['count']} invalid charts, "
            f"{labeling['invalid_boundaries']['count']} invalid boundaries and "
            f"{labeling['invalid_corners']['count']} invalid corners (see the labeling section)")
    field = state["frames"]
    interface_axis = field.face_interface_axis if len(field.interfaces) else None
    base, info = build_base_mesh(state["target"], state["face_part"], state["face_label"],
                                 field.face_frame, field.part_frames,
                                 target_faces=params.target_faces,
                                 max_base_faces=params.max_base_faces,
                                 face_interface_axis=interface_axis)
    target_genus = state["input_genus"]
    if info["genus"] != target_genus:
        raise LabelingError(
            f"the base mesh has genus {info['genus']} but the target has genus {target_genus}")
    message = ("" if info["within_budget"] else
               f"{info['faces']} faces for a budget of {info['target_faces']}: "
               f"{info['minimum_reason'] or 'the closest layout found'}")
    return {"base_mesh": base, "report": info, "message": message}


FIT_FACE_BUDGET = 40_000
"""Most faces of the subdivided mesh the fit works on: above it, fewer levels are used
(the closest-point queries and thickness rays of every iteration scale with it)."""


def fit_levels(n_base_faces, wanted):
    """Subdivision levels for the fit: ``wanted``, fewer if the fine mesh would exceed the budget."""
    affordable = int(np.floor(np.log(FIT_FACE_BUDGET / max(n_base_faces, 1)) / np.log(4.0)))
    return int(max(1, min(wanted, affordable)))


def stage_fit(state, params):
    from core.fitting import fit_base_mesh

    base, target = state["base_mesh"], state["target"]

    def fit(cage):
        return fit_base_mesh(cage, target, levels=fit_levels(cage.n_faces, params.subdivision_levels),
                             iterations=params.fit_iterations, mode=params.fit_mode,
                             t_min=params.fit_t_min, progress=state.get("progress"))

    diagonal_mm = float(np.linalg.norm(np.ptp(target.vertices, axis=0)))
    tolerance = params.tolerance or params.tolerance_mm / diagonal_mm
    refinement = None
    if tolerance > 0:
        from core.fitting.refine import fit_to_tolerance

        refinement = fit_to_tolerance(base, target, tolerance, params.max_base_faces, fit)
        fitted, info = refinement.mesh, refinement.info
    else:
        fitted, info = fit(base)
    levels = info["levels"]
    report = {"mode": params.fit_mode, "levels": levels, **{key: info[key] for key in (
        "start", "rounds", "iterations", "stopped", "mean_distance", "max_distance", "outside_volume_fraction",
        "uncovered_volume_fraction", "initial_mean_distance", "initial_max_distance", "initial_outside_volume_fraction",
        "t_min", "seconds", "measure_seconds") if key in info}}
    report["self_intersections"] = count_limit_self_intersections(fitted, levels)
    warnings = [] if report["self_intersections"] == 0 else [
        f"warning: the fitted limit surface intersects itself "
        f"({report['self_intersections']} triangle pairs at level {levels})"]
    if refinement is not None:
        report["tolerance"] = {"value": tolerance, "value_mm": tolerance * diagonal_mm,
                               "met": refinement.met, "reason": refinement.reason,
                               "faces": int(fitted.n_faces), "rounds": refinement.rounds}
        if not refinement.met:
            warnings.append(f"warning: {refinement.reason}")
    message = "; ".join(warnings)
    return {"base_mesh": fitted, "report": report, "message": message}


def count_limit_self_intersections(base, levels):
    """Intersecting triangle pairs of the level-``levels`` limit mesh of ``base`` (0 = clean)."""
    return int(len(limit_self_intersections(base, levels)[0]))


def limit_self_intersections(base, levels):
    """Where the level-``levels`` limit mesh of ``base`` intersects itself.

    The base mesh is subdivided ``levels >= 1`` times, its vertices moved to their
    limit positions and its quads split into two triangles each.

    Returns
    -------
    pairs : (k, 2) int64 intersecting triangle pairs (``core.self_intersection``).
    base_faces : (k, 2) int64 the base faces the two triangles of each pair lie on.
    points : (k, 3) float64 the centroid of the first triangle of each pair.
    """
    from core.fitting.responses import triangulate
    from core.self_intersection import find_self_intersections
    from core.subdivision.catmull_clark import build_hierarchy
    from core.subdivision.limit import limit_matrices

    fine = build_hierarchy(base, levels).meshes[levels]
    limit, _, _ = limit_matrices(fine)
    points = limit @ fine.vertices
    triangles = triangulate(fine.face_vertices, fine.face_offsets)
    pairs = find_self_intersections(points, triangles)
    level_one_face = pairs // 2 // 4 ** (levels - 1)
    base_faces = np.repeat(np.arange(base.n_faces), base.face_sizes)[level_one_face]
    return pairs, base_faces, points[triangles[pairs[:, 0]]].mean(axis=1)


def stage_patches(state, params):
    from core.export.bspline import limit_surface_patches

    patches = limit_surface_patches(state["base_mesh"])
    return {"patches": patches, "report": dict(patches.info)}


STAGE_FUNCTIONS = {
    "intake": stage_intake, "parts": stage_parts, "frames": stage_frames,
    "labeling": stage_labeling, "basemesh": stage_basemesh,
    "fit": stage_fit, "patches": stage_patches,
}

# The last core stage that each --stop-after choice runs ("solid" is built by polycube_wb).
LAST_CORE_STAGE = {"intake": "intake", "parts": "frames", "labeling": "labeling",
                    "basemesh": "basemesh", "fit": "fit", "solid": "patches"}


def run_stages(state, stages, params, progress=NO_PROGRESS, report=None):
    """Run ``stages`` in order on ``state``; returns ``(state, report, failed_exception)``.

    While a stage runs, ``state["progress"]`` is its share of ``progress`` (a
    ``SubProgress`` the stage reports its own fraction to, and that cancels); it is
    removed when the run ends. ``state["input_mesh"] = (vertices, faces)`` makes the
    intake validate those arrays instead of reading ``state["input_path"]``.
    """
    report = report if report is not None else {"stages": {}}
    report.setdefault("stages", {})
    blocked_by = None
    failed = None
    for index, name in enumerate(stages):
        if blocked_by is not None:
            report["stages"][name] = {"status": "skipped", "seconds": 0.0,
                                      "message": f"needs the '{blocked_by}' stage"}
            continue
        progress.check_cancel()
        progress.report(name, index / len(stages))
        state["progress"] = SubProgress(progress, index / len(stages), (index + 1) / len(stages))
        start = time.perf_counter()
        try:
            output = STAGE_FUNCTIONS[name](state, params)
        except StageNotAvailableError as exc:
            entry = {"status": "not_available", "message": str(exc)}
            blocked_by = name
        except PolycubeInputError:
            raise
        except Exception as exc:  # recorded, then reported as an internal failure
            entry = {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
            blocked_by, failed = name, exc
        else:
            entry = {"status": "ok", "message": output.pop("message", "")}
            stage_report = output.pop("report", {})
            state.update(output)
            report[name] = stage_report
        entry["seconds"] = round(time.perf_counter() - start, 4)
        report["stages"][name] = entry
    state.pop("progress", None)
    progress.report("done", 1.0)
    return state, report, failed


def reconstruct(input_path, params=None, progress=NO_PROGRESS, stop_after="solid"):
    """Run the core stages on a target mesh file.

    Parameters
    ----------
    input_path : str or path of the target mesh (STL, OBJ, PLY, OFF).
    params : ReconstructionParams or dict, defaults are the paper's values.
    progress : core.progress.Progress for feedback and cancelling.
    stop_after : one of ``STOP_AFTER_CHOICES``; core stages after it are not run.

    Returns
    -------
    PipelineResult; ``report`` has ``input`` and per-stage sections and ``stages``.

    Raises
    ------
    PolycubeInputError (InvalidMeshError, ParameterError) for bad input.
    """
    from core.errors import ParameterError

    if params is None:
        params = ReconstructionParams()
    elif isinstance(params, dict):
        params = ReconstructionParams.from_dict(params)
    if stop_after not in STOP_AFTER_CHOICES:
        raise ParameterError(f"stop_after must be one of {', '.join(STOP_AFTER_CHOICES)}, "
                             f"got {stop_after!r}")
    last = CORE_STAGES.index(LAST_CORE_STAGE[stop_after])
    started = time.perf_counter()
    state = {"input_path": str(input_path), "params": params}
    report = {"parameters": params.to_dict(), "stages": {}}
    state, report, failed = run_stages(state, CORE_STAGES[:last + 1], params, progress, report)
    report["input"] = report.pop("intake", {"file": str(input_path)})
    if "basemesh" in report:
        report["base_mesh"] = report.pop("basemesh")
    report["total_seconds"] = round(time.perf_counter() - started, 4)
    report["peak_memory_mb"] = round(peak_memory_mb(), 1)
    return PipelineResult(state, _json_safe(report), failed)


def _json_safe(value):
    """Convert numpy scalars/arrays inside a report to plain Python types."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and value != value:
        return None
    return value
