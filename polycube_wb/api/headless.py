# SPDX-License-Identifier: LGPL-2.1-or-later
"""Headless pipeline functions of the scripting API: files in, files and a report out (the
command line's ``reconstruct``, ``subd-to-step`` and ``check``).

Functions that build solids import FreeCAD themselves, so this module imports in any Python;
call them where ``import FreeCAD`` works (freecadcmd, the GUI, or the project's .venv).
"""
import os
import time

import numpy as np

from core.mesh_topology import polymesh_summary
from core.output_files import check_output_path, output_transaction, write_json_atomic
from core.params import (DEFAULT_EXPORT_FORM, DEFAULT_FACE_FORM, EXPORT_DEPTH,
                         check_export_depth, check_export_form, check_face_form)
from core.pipeline import STOP_AFTER_CHOICES, peak_memory_mb, reconstruct as run_pipeline
from core.progress import NO_PROGRESS


def reconstruct_to_step(mesh_path, step_path=None, base_mesh_path=None, report_path=None,
                        labels_path=None, stop_after="solid", progress=NO_PROGRESS, **params):
    """Run the whole pipeline on a target mesh file and write the requested outputs.

    Parameters
    ----------
    mesh_path : path of the target mesh (STL, OBJ, PLY, OFF).
    step_path : path of the STEP file to write (needed when ``stop_after='solid'``).
    base_mesh_path, report_path, labels_path : optional paths for the base-mesh OBJ, the
        JSON report and the per-face labeling PLY (the labeling the base mesh was built on,
        ``PipelineState.segmentation``).
    stop_after : one of ``intake, parts, labeling, basemesh, fit, solid``.
    progress : core.progress.Progress.
    **params : fields of ``core.params.ReconstructionParams``.

    Returns
    -------
    dict, the report (also written to ``report_path``); ``report['outputs']`` lists the
    files written.

    Raises
    ------
    PolycubeInputError for bad input (nothing is written): a bad file or parameter, an
    output over an input (the mesh or the parts file), two outputs on one path, or an
    output that no stage up to ``stop_after`` makes;
    the exception of a stage that failed (the report is written first).
    """
    inputs = (mesh_path,) + ((params["parts_file"],) if params.get("parts_file") else ())
    _check_outputs(((step_path, "STEP file", "solid"), (base_mesh_path, "base mesh", "basemesh"),
                    (report_path, "report", "intake"), (labels_path, "labels file", "labeling")),
                   inputs, stop_after)
    result = run_pipeline(mesh_path, params, progress, stop_after)
    report, state = result.report, result.state
    outputs = {}
    with output_transaction():  # every output or none (an error, Ctrl-C)
        progress.report("writing", 1.0)
        if labels_path is not None:
            segmentation = state.segmentation  # the one the base mesh was built on
            if segmentation is not None:
                from core.segmentation.labels_file import write_labels_ply

                mesh = state.intake.surface  # the labeling's own faces
                write_labels_ply(labels_path, mesh.vertices, mesh.faces,
                                 segmentation.parts.face_part, segmentation.labeling.face_label,
                                 segmentation.frames.frame_field.face_frame, protect=inputs)
                outputs["labels"] = os.path.abspath(labels_path)
        if base_mesh_path is not None:
            if state.cage is not None:
                from core.polymesh_io import write_polymesh

                write_polymesh(base_mesh_path, state.cage, inputs)
                outputs["base_mesh"] = os.path.abspath(base_mesh_path)
        if stop_after == "solid":
            if state.patches is not None:
                progress.report("solid", 1.0)
                started, cpu_started = time.perf_counter(), time.process_time()
                solid_section = _solid_and_step(state.patches.patches, step_path, inputs)
                report["stages"]["solid"] = {
                    "status": "ok", "message": "",
                    "seconds": round(time.perf_counter() - started, 4),
                    "cpu_seconds": round(time.process_time() - cpu_started, 4)}
                report["brep"] = solid_section
                if step_path is not None:
                    outputs["step"] = solid_section["step_path"]
            else:
                report["stages"]["solid"] = {"status": "skipped", "seconds": 0.0, "message":
                                             "needs B-spline patches of the fitted base mesh"}
        progress.report("writing", 1.0)
        report["outputs"] = outputs
        report["peak_memory_mb"] = round(peak_memory_mb(), 1)
        if report_path is not None:
            write_json_atomic(report_path, report, inputs)
            outputs["report"] = os.path.abspath(report_path)
    if result.failed is not None:
        raise result.failed
    return report


def _check_outputs(outputs, inputs, stop_after):
    """ParameterError unless every requested output can be written and is made by a stage
    up to ``stop_after``.

    outputs : ``(path or None, what, first --stop-after choice that makes it)`` triples.
    """
    from core.errors import ParameterError
    from core.output_files import same_file

    wanted = [(path, what, stage) for path, what, stage in outputs if path is not None]
    for index, (path, what, stage) in enumerate(wanted):
        check_output_path(path, inputs, what)
        if stop_after in STOP_AFTER_CHOICES and \
                STOP_AFTER_CHOICES.index(stop_after) < STOP_AFTER_CHOICES.index(stage):
            raise ParameterError(f"cannot write the {what} {os.fspath(path)}: the run stops after "
                                 f"'{stop_after}' (--stop-after), before the '{stage}' stage "
                                 f"that makes it")
        for other, other_what, _ in wanted[:index]:
            if same_file(path, other):
                raise ParameterError(f"the {other_what} and the {what} are the same file "
                                     f"{os.fspath(path)}; give each output its own path")


def _solid_and_step(patches, step_path, inputs):
    """Build the solid from patches, write STEP if asked; returns the report's ``brep`` section."""
    from polycube_wb.brep import make_solid
    from polycube_wb.step_io import step_text_ahead, write_solid_step

    name = _input_name(inputs[0])
    # the STEP text is made on another core while the solid is built and checked
    ahead = (step_text_ahead(patches, name)
             if step_path is not None and patches.topology is not None and name else None)
    try:
        built = make_solid(patches)
        section = built.figures
        section["max_normal_jump_deg"] = patches.info.get("normal_jump_max_deg")
        section["step_path"] = None
        if step_path is not None:
            section["step_path"] = write_solid_step(built, patches, step_path,
                                                    input_paths=inputs, name=name, ahead=ahead)
    finally:
        if ahead is not None:
            ahead.cancel()
    return section


def _input_name(path):
    """The STEP product name for an input file: its name without the suffix."""
    return os.path.splitext(os.path.basename(os.fspath(path)))[0]


def subd_to_solid(base_mesh_path, step_path=None, report_path=None, depth=EXPORT_DEPTH,
                  measure=True, progress=NO_PROGRESS, export=DEFAULT_EXPORT_FORM,
                  faces=DEFAULT_FACE_FORM):
    """Turn a closed polygon base mesh (a SubD cage, OBJ) into a FreeCAD solid.

    The solid's faces are bicubic B-spline patches of the Catmull-Clark limit surface.

    Parameters
    ----------
    base_mesh_path : path of a closed, 2-manifold, consistently oriented polygon OBJ.
    step_path, report_path : optional outputs (STEP written atomically, JSON report).
    depth : grading depth of patches at extraordinary vertices (accuracy vs pole count).
    measure : compute the approximation error, continuity figures and the limit-surface
        volume the solid is compared with (costs about as much as the export).
    progress : core.progress.Progress.
    export : ``"exact"`` (graded patches, ``depth`` applies) or ``"g1"`` (one light
        tangent-continuous patch per quad, :mod:`core.export.g1_patches`; sharp creases
        stay C0).
    faces : ``"quad"`` (one B-rep face per quad) or ``"chart"`` (one multi-span face per
        rectangular block of quads, :mod:`core.export.chart_faces`; ``g1`` export only).

    Returns
    -------
    (Part.Solid, dict report)
    """
    from core.export.bspline import limit_surface_patches
    from core.export.g1_patches import g1_surface_patches
    from core.polymesh_checks import check_export_range, check_polymesh, check_single_shell
    from core.polymesh_io import read_polymesh
    from core.subdivision.limit import limit_volume
    from polycube_wb.brep import make_solid
    from polycube_wb.step_io import write_solid_step

    check_export_depth(depth)
    check_export_form(export)
    check_face_form(faces, export)
    inputs = (base_mesh_path,)
    for path, what in ((step_path, "STEP file"), (report_path, "report")):
        if path is not None:
            check_output_path(path, inputs, what)
    started = time.perf_counter()
    stages = {}
    clock = time.perf_counter()
    base = read_polymesh(base_mesh_path)
    check_polymesh(base)
    check_single_shell(base)
    check_export_range(base)
    _refuse_self_intersections(base, base_mesh_path)
    stages["intake"] = _ok(clock)
    progress.report("patches", 0.1)
    clock = time.perf_counter()
    if export == "g1":
        patches = g1_surface_patches(base, measure=measure, faces=faces)
    else:
        patches = limit_surface_patches(base, depth=depth, measure=measure)
    stages["patches"] = _ok(clock)
    progress.check_cancel()
    progress.report("solid", 0.5)
    clock = time.perf_counter()
    built = make_solid(patches, progress)
    solid, brep = built.solid, built.figures
    stages["solid"] = _ok(clock)
    progress.report("writing", 0.8)
    with output_transaction():  # the STEP file and the report together, or neither
        brep["step_path"] = None
        if step_path is not None:
            clock = time.perf_counter()
            brep["step_path"] = write_solid_step(built, patches, step_path, input_paths=inputs,
                                                 name=_input_name(base_mesh_path))
            stages["step"] = _ok(clock)
        brep["limit_volume"] = brep["volume_error_rel"] = None
        if measure:
            clock = time.perf_counter()
            reference = limit_volume(base, level=_reference_level(base.n_faces))
            stages["limit_volume"] = _ok(clock)
            brep["limit_volume"] = float(reference)
            brep["volume_error_rel"] = float(abs(brep["volume"] - reference) / abs(reference))
        brep["max_normal_jump_deg"] = patches.info.get("normal_jump_max_deg")
        report = {
            "input": {"file": os.path.abspath(base_mesh_path)},
            "base_mesh": polymesh_summary(base),
            "patches": _plain(patches.info),
            "brep": brep,
            "stages": stages,
            "total_seconds": round(time.perf_counter() - started, 4),
            "peak_memory_mb": round(peak_memory_mb(), 1),
        }
        if report_path is not None:
            write_json_atomic(report_path, report, inputs)
    progress.report("done", 1.0)
    return solid, report


def _refuse_self_intersections(base, path):
    """InvalidMeshError if the limit surface of ``base`` intersects itself
    (``core.subdivision.limit_crossings.export_limit_crossings``, the check the pipeline's solid uses too)."""
    from core.errors import InvalidMeshError
    from core.subdivision.limit_crossings import export_limit_crossings

    crossings = export_limit_crossings(base)
    if crossings.count:
        raise InvalidMeshError(f"{os.fspath(path)}: {crossings.message()}",
                               reason="self_intersecting", count=crossings.count,
                               examples=crossings.base_faces[:5].tolist())


def _reference_level(n_faces, budget=40_000):
    """Subdivision level for the reference limit volume: at most ``budget`` faces, 2..5.

    With Richardson extrapolation the reference is within about 2e-7 of the limit volume
    at level 2 on a 2,000-face cage and 2e-7 at level 3 on a 300-face one, far below
    the 1e-3 the export is held to.
    """
    level = int(np.floor(np.log(budget / max(n_faces, 1)) / np.log(4.0)))
    return min(5, max(2, level))


def _ok(clock):
    return {"status": "ok", "seconds": round(time.perf_counter() - clock, 4), "message": ""}


def _plain(info):
    return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in info.items()}


def check(target_path, result_path, components="largest"):
    """Compare a result solid (STEP) with a target mesh.

    Returns a dict: ``watertight`` (manifold3d and trimesh on a tessellation of the solid),
    ``outside_volume_fraction`` and ``uncovered_volume_fraction`` (fractions of the target
    volume), ``mean_distance`` / ``max_distance`` (fractions of the target's bounding-box
    diagonal, result samples to target), solid validity and face count.
    """
    from core.mesh_io import read_triangle_soup
    from core.quality import containment, is_watertight_manifold, surface_distances
    from core.validate import validate_target
    from polycube_wb.brep import tessellate
    from polycube_wb.step_io import read_step

    target, summary = validate_target(*read_triangle_soup(target_path), components=components,
                                      check_self_intersections=False, name=str(target_path))
    shape = read_step(result_path)
    if len(shape.Solids) != 1:
        from core.errors import InvalidMeshError

        raise InvalidMeshError(f"{result_path}: expected one solid, found {len(shape.Solids)}",
                               reason="format", count=len(shape.Solids))
    solid = shape.Solids[0]
    V, F = tessellate(solid, 1e-4 * summary["bbox_diagonal"])
    inside = containment(V, F, target.vertices, target.faces)
    distances = surface_distances(V, F, target.vertices, target.faces)
    return {
        "target": os.path.abspath(target_path),
        "result": os.path.abspath(result_path),
        "valid": bool(solid.isValid()),
        "faces": len(solid.Faces),
        "watertight": bool(is_watertight_manifold(V, F)),
        "outside_volume_fraction": inside["outside_volume_fraction"],
        "uncovered_volume_fraction": inside["uncovered_volume_fraction"],
        "distances": distances,
    }
