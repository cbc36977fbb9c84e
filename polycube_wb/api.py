# SPDX-License-Identifier: LGPL-2.1-or-later
"""Scripting API: the same operations as the CLI, as functions for FreeCADCmd scripts.

Functions that build solids import FreeCAD themselves, so ``import polycube_wb.api``
works in any Python; call them where ``import FreeCAD`` works (freecadcmd, the GUI,
or the project's .venv).
"""
import os
import time

import numpy as np

from core.mesh_topology import polymesh_summary
from core.output_files import check_output_path, output_transaction, write_json_atomic
from core.params import (DEFAULT_EXPORT_FORM, EXPORT_DEPTH, check_export_depth,
                         check_export_form)
from core.pipeline import STOP_AFTER_CHOICES, peak_memory_mb, reconstruct as run_pipeline
from core.progress import NO_PROGRESS
from polycube_wb.stage_jobs import read_target_file
from polycube_wb.view_hook import attach_view_provider


def reconstruct_to_step(mesh_path, step_path=None, base_mesh_path=None, report_path=None,
                        labels_path=None, stop_after="solid", progress=NO_PROGRESS, **params):
    """Run the whole pipeline on a target mesh file and write the requested outputs.

    Parameters
    ----------
    mesh_path : path of the target mesh (STL, OBJ, PLY, OFF).
    step_path : path of the STEP file to write (needed when ``stop_after='solid'``).
    base_mesh_path, report_path, labels_path : optional paths for the base-mesh OBJ, the
        JSON report and the per-face labeling PLY.
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
            if state.labeling is not None:
                from core.segmentation.labels_file import write_labels_ply

                mesh = state.intake.surface  # the labeling's own faces
                write_labels_ply(labels_path, mesh.vertices, mesh.faces, state.parts.face_part,
                                 state.labeling.face_label, state.frames.frame_field.face_frame,
                                 protect=inputs)
                outputs["labels"] = os.path.abspath(labels_path)
        if base_mesh_path is not None:
            if state.cage is not None:
                from core.polymesh_io import write_polymesh

                write_polymesh(base_mesh_path, state.cage, inputs)
                outputs["base_mesh"] = os.path.abspath(base_mesh_path)
        if stop_after == "solid":
            if state.patches is not None:
                progress.report("solid", 1.0)
                started = time.perf_counter()
                solid_section = _solid_and_step(state.patches.patches, step_path, inputs)
                report["stages"]["solid"] = {"status": "ok", "message": "",
                                             "seconds": round(time.perf_counter() - started, 4)}
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
    from polycube_wb.step_io import write_solid_step

    built = make_solid(patches)
    section = built.figures
    section["max_normal_jump_deg"] = patches.info.get("normal_jump_max_deg")
    section["step_path"] = None
    if step_path is not None:
        section["step_path"] = write_solid_step(built, patches, step_path, input_paths=inputs,
                                                name=_input_name(inputs[0]))
    return section


def _input_name(path):
    """The STEP product name for an input file: its name without the suffix."""
    return os.path.splitext(os.path.basename(os.fspath(path)))[0]


def subd_to_solid(base_mesh_path, step_path=None, report_path=None, depth=EXPORT_DEPTH,
                  measure=True, progress=NO_PROGRESS, export=DEFAULT_EXPORT_FORM):
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
        tangent-continuous patch per quad, :mod:`core.export.g1_patches`; cages without
        creases).

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
        patches = g1_surface_patches(base, measure=measure)
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


def reconstruct(doc, mesh_path, progress=NO_PROGRESS, **params):
    """Run the pipeline into document ``doc``; returns the result solid's object.

    The validated target is added as a mesh object first, so the user sees what was
    read; when the pipeline can build the solid it is added as a ``Part::Feature``.

    Raises
    ------
    PolycubeInputError for bad input (nothing is added); the exception of a stage that
    failed (the target mesh is added first).
    """
    from polycube_wb.document import add_solid, add_target_mesh

    result = run_pipeline(mesh_path, params, progress, "solid")
    name = os.path.splitext(os.path.basename(mesh_path))[0]
    add_target_mesh(doc, result.state.intake.target, name + "_target")
    if result.failed is not None:
        raise result.failed
    from polycube_wb.brep import patches_to_solid

    return add_solid(doc, patches_to_solid(result.state.patches.patches), name + "_solid")


# ----------------------------------------------------------------------------------------
# Parametric document objects (one per stage): factories, recompute, document operations
# ----------------------------------------------------------------------------------------

_STAGE_OBJECTS = {
    # kind: (FreeCAD type, proxy module, proxy class)
    "Target": ("Mesh::FeaturePython", "polycube_wb.objects.target", "TargetProxy"),
    "Segmentation": ("Mesh::FeaturePython", "polycube_wb.objects.segmentation",
                     "SegmentationProxy"),
    "BaseMesh": ("Part::FeaturePython", "polycube_wb.objects.base_mesh", "BaseMeshProxy"),
    "Fit": ("Part::FeaturePython", "polycube_wb.objects.fit", "FitProxy"),
    "Solid": ("Part::FeaturePython", "polycube_wb.objects.solid", "SolidProxy"),
    "Deviation": ("Mesh::FeaturePython", "polycube_wb.objects.deviation", "DeviationProxy"),
}


def _make(doc, kind, name, links, properties):
    """Add a stage object of ``kind`` with its links and properties set; returns it."""
    import importlib

    from core.errors import ParameterError

    type_name, module, cls = _STAGE_OBJECTS[kind]
    obj = doc.addObject(type_name, name)
    getattr(importlib.import_module(module), cls)(obj)
    for prop, value in links.items():
        setattr(obj, prop, value)
    for prop, value in properties.items():
        if prop not in obj.PropertiesList:
            known = ", ".join(sorted(obj.PropertiesList))
            doc.removeObject(obj.Name)
            raise ParameterError(f"{kind} has no property {prop!r}; its properties: {known}")
        setattr(obj, prop, value)
    attach_view_provider(obj, kind)
    return obj


def stage_kind(obj):
    """``Target``, ``Segmentation``, ... for a stage object, else None."""
    from polycube_wb.objects.base import stage_kind as kind_of

    return kind_of(obj)


def make_target(doc, source, name="Target", components="largest",
                check_self_intersections=True, repair=True):
    """Add a Target object holding a validated mesh (embedded in the document).

    Parameters
    ----------
    doc : App.Document
    source : path of a mesh file (STL, OBJ, PLY, OFF), a ``core.types.TriMesh``, or a
        ``Mesh::Feature`` (e.g. the plain target of a document made by an older version;
        its placement is applied).
    components, check_self_intersections, repair : as in ``core.validate.validate_target``
        (the command line's intake: the target holds the repaired mesh).

    Returns
    -------
    Mesh::FeaturePython, not yet recomputed (``doc.recompute()`` or :func:`recompute`).

    Raises
    ------
    InvalidMeshError
        The file cannot be read or the mesh is not a valid closed solid; nothing is added.
    """
    from core.types import TriMesh
    from core.validate import validate_target
    from polycube_wb.convert import arrays_to_mesh, mesh_to_arrays

    options = {"components": components, "check_self_intersections": check_self_intersections,
               "repair": repair}
    source_file = ""
    if isinstance(source, TriMesh):
        mesh, _ = validate_target(source.vertices, source.faces, name=name, **options)
    elif hasattr(source, "Mesh"):
        source_file = getattr(source, "PolycubeSource", "") or getattr(source, "SourceFile", "")
        mesh, _ = validate_target(*mesh_to_arrays(source.Mesh), name=source_file or name,
                                  **options)
    else:
        source_file = os.path.abspath(os.fspath(source))
        mesh = _READ_AHEAD.pop(_read_ahead_key(source_file, **options), None) \
            or read_target_file(source_file, **options)
    obj = _make(doc, "Target", name, {}, {"CheckSelfIntersections": check_self_intersections})
    obj.Mesh = arrays_to_mesh(mesh.vertices, mesh.faces)
    obj.SourceFile = source_file
    return obj


_READ_AHEAD = {}
"""At most one mesh read by :func:`read_ahead_target`, by :func:`_read_ahead_key`."""


def read_ahead_target(path, components="largest", check_self_intersections=True, repair=True,
                      mesh=None):
    """Read and validate a mesh file for the next :func:`make_target` of the same file.

    The GUI reads a file in its stage process (:func:`read_target_file`) and hands the mesh
    here as ``mesh``, then calls ``make_target`` (through the Python console, which shows
    the line to replay), which takes this mesh instead of reading the file again. A file
    changed since is read again.

    Raises
    ------
    InvalidMeshError
        As :func:`read_target_file` (when ``mesh`` is None).
    """
    path = os.path.abspath(os.fspath(path))
    if mesh is None:
        mesh = read_target_file(path, components, check_self_intersections, repair)
    _READ_AHEAD.clear()
    _READ_AHEAD[_read_ahead_key(path, components, check_self_intersections, repair)] = mesh


def _read_ahead_key(path, components, check_self_intersections, repair):
    """What identifies a read: the file (its size and change time, None when it cannot be
    looked at) and the options."""
    try:
        info = os.stat(path)
    except OSError:
        return (path, None, components, bool(check_self_intersections), bool(repair))
    return (path, (info.st_size, info.st_mtime_ns), components, bool(check_self_intersections),
            bool(repair))


def make_segmentation(doc, target, name="Segmentation", **properties):
    """Add a Segmentation (parts, frames, HBECVT labeling) of ``target``.

    ``properties``: ``PartMode`` (``single``/``auto``), ``BlendFactor``, ``Lambda``,
    ``Penalty``, ``MaxSweeps``, ``Repair``, ``ColourBy``; defaults are the preferences,
    else the paper's values.
    """
    return _make(doc, "Segmentation", name, {"Target": target}, properties)


def make_base_mesh(doc, segmentation, name="BaseMesh", **properties):
    """Add a BaseMesh (polycube and coarse quad cage) built from ``segmentation``.

    ``properties``: ``TargetFaces``, ``MaxBaseFaces``.
    """
    return _make(doc, "BaseMesh", name, {"Segmentation": segmentation}, properties)


def make_fit(doc, cage, name="Fit", **properties):
    """Add a Fit of the cage object ``cage`` (a BaseMesh or a Fit) to its target.

    ``properties``: ``Iterations``, ``SubdivisionLevels``, ``Mode`` (``inside`` /
    ``nearest``), ``AutoMinThickness``, ``MinThickness`` (mm).
    """
    return _make(doc, "Fit", name, {"BaseMesh": cage}, properties)


def make_solid(doc, cage, name="Solid", **properties):
    """Add a Solid: the limit surface of the cage object ``cage`` as B-spline faces.

    ``properties``: ``Depth`` (grading at extraordinary vertices).
    """
    return _make(doc, "Solid", name, {"Cage": cage}, properties)


def make_deviation(doc, solid, target, name="Deviation", **properties):
    """Add a Deviation colour map (and check figures) of ``solid`` against ``target``.

    ``properties``: ``Tolerance`` (tessellation, fraction of the diagonal), ``Scale``.
    """
    return _make(doc, "Deviation", name, {"Solid": solid, "Target": target}, properties)


STAGE_ORDER = ("Target", "Segmentation", "BaseMesh", "Fit", "Solid")


def upstream_objects(obj):
    """Dict kind -> object of ``obj`` and the stage objects it is built from."""
    found = {}
    stack = [obj]
    while stack:
        current = stack.pop()
        kind = stage_kind(current)
        if kind is None or kind in found:
            continue
        found[kind] = current
        stack.extend(getattr(current, link) for link in current.Proxy.INPUTS)
    return found


def find_stage(doc, kind, start=None):
    """The stage object of ``kind`` to work on, or None.

    With ``start`` (e.g. the selection): the one ``start`` is built from, else the last
    one built from ``start``; otherwise (or when there is none) the last one in ``doc``.
    """
    if start is not None:
        upstream = upstream_objects(start).get(kind)
        if upstream is not None:
            return upstream
        built = {obj.Name for obj in start.InListRecursive}
        for obj in reversed(doc.Objects):
            if obj.Name in built and stage_kind(obj) == kind:
                return obj
    for obj in reversed(doc.Objects):
        if stage_kind(obj) == kind:
            return obj
    return None


def make_chain(doc, start, last="Solid", **properties):
    """Add the stage objects after ``start`` up to ``last`` (reusing existing ones).

    Parameters
    ----------
    start : a stage object (typically the Target).
    last : kind of the last stage to have (``Segmentation`` ... ``Solid``).
    properties : ``{kind: {property: value}}`` for the objects that are created.

    Returns
    -------
    dict kind -> object, for every kind from the Target to ``last``.
    """
    factories = {"Segmentation": make_segmentation, "BaseMesh": make_base_mesh,
                 "Fit": make_fit, "Solid": make_solid}
    chain = upstream_objects(start)
    previous = start
    for kind in STAGE_ORDER[STAGE_ORDER.index(stage_kind(start)) + 1:
                            STAGE_ORDER.index(last) + 1]:
        existing = next((obj for obj in previous.InList
                         if stage_kind(obj) == kind and is_reusable(obj)), None)
        chain[kind] = existing or factories[kind](doc, previous, **properties.get(kind, {}))
        previous = chain[kind]
    return chain


def move_cage_vertices(obj, moves):
    """Move vertices of a cage object (BaseMesh or Fit); the next recompute follows.

    Parameters
    ----------
    obj : a BaseMesh or Fit object.
    moves : dict vertex index -> new position (x, y, z) in model units (mm).

    Raises
    ------
    ParameterError
        ``obj`` holds no cage, an index is not a cage vertex, or a position is not 3
        finite numbers.
    """
    import FreeCAD

    from core.errors import ParameterError

    if stage_kind(obj) not in ("BaseMesh", "Fit"):
        raise ParameterError(f"{obj.Label} is not a BaseMesh or Fit object (it has no cage)")
    points = list(obj.CageVertices)
    for index, position in moves.items():
        if not isinstance(index, (int, np.integer)) or not 0 <= index < len(points):
            raise ParameterError(f"{obj.Label}: {index!r} is not a cage vertex index "
                                 f"(0..{len(points) - 1})")
        position = np.asarray(position, dtype=np.float64)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ParameterError(f"{obj.Label}: vertex {index} position must be 3 finite "
                                 f"numbers, got {position.tolist()}")
        points[index] = FreeCAD.Vector(*position.tolist())
    obj.CageVertices = points


def is_reusable(obj):
    """Whether later stages may be built on ``obj`` by default.

    A Segmentation with automatic parts is not: assembling the part base meshes at their
    interfaces is not built yet, so *Segment parts* shows the parts without changing what
    the base mesh is built from (select it explicitly to try).
    """
    return not (stage_kind(obj) == "Segmentation" and obj.PartMode == "auto")


class RecomputeOutcome:
    """What a :func:`recompute` did.

    failures : dict object name -> one-line reason its stage failed (empty when all ran).
    cancelled : bool, the user cancelled (the document was rolled back).
    """

    def __init__(self, failures, cancelled):
        self.failures = failures
        self.cancelled = cancelled

    @property
    def ok(self):
        return not self.failures and not self.cancelled


def recompute(doc, progress=NO_PROGRESS, run_job=None):
    """``doc.recompute()`` with ``progress`` reaching the stage objects; returns the outcome.

    With ``run_job`` (``run_job(job, progress) -> result``, e.g. the GUI's stage process,
    :mod:`polycube_wb.gui.worker`), the stale stage objects' computations are run by it and
    their results stored before the recompute (:func:`polycube_wb.objects.base.run_pending_stages`);
    the outcome is the same as without it.

    FreeCAD does not propagate errors from ``execute``; the outcome lists them. An object
    whose stage failed is marked invalid (``obj.isValid()`` is False) with the reason in its
    ``Status`` property; the objects after it are not recomputed. When the user cancels
    (``progress`` raises ``Cancelled``), the object that was running gets ``Status``
    "cancelled by the user" and keeps its last result; it and the objects that did not run
    after it stay touched (the next recompute runs them).
    """
    from polycube_wb.objects.base import recompute_session, run_pending_stages

    with recompute_session(doc, progress) as session:
        if run_job is not None:
            run_pending_stages(doc, session, run_job)
        doc.recompute()
    if session.cancelled:
        for name in list(session.failures) + session.skipped:
            doc.getObject(name).touch()
    return RecomputeOutcome(dict(session.failures), session.cancelled)


def run_in_transaction(doc, title, build, progress=NO_PROGRESS, run_job=None):
    """Run ``build()`` (adds or changes objects), then recompute, as one undo step.

    ``run_job`` runs the stages' computations (see :func:`recompute`).

    When ``build`` raises, the document is rolled back to what it was before. When the user
    cancels during the recompute, the stages that finished keep their results, the stage
    object that was running keeps the result it had (none if it is new) and is marked:
    ``Status`` "cancelled by the user", touched, so the next recompute runs it again; the
    objects after it are not run. The step is committed, so Undo restores the document as
    it was before ``build`` (needs ``doc.UndoMode``, which the GUI turns on).

    Returns
    -------
    (what ``build`` returned, RecomputeOutcome)

    Raises
    ------
    core.errors.Cancelled
        The user cancelled; the message names the stage object that was running.
    """
    from core.errors import Cancelled
    from polycube_wb.objects.base import CANCELLED_STATUS

    doc.openTransaction(title)
    try:
        built = build()
        outcome = recompute(doc, progress, run_job)
    except BaseException:
        doc.abortTransaction()
        raise
    doc.commitTransaction()
    if outcome.cancelled:
        stopped = [doc.getObject(name) for name, reason in outcome.failures.items()
                   if reason == CANCELLED_STATUS]
        where = " at " + ", ".join(obj.Label for obj in stopped) if stopped else ""
        raise Cancelled(f"{title}: cancelled by the user{where}; the stages before it keep "
                        f"their results (Undo restores the document as it was)")
    return built, outcome


def describe(obj):
    """One line about a stage object's result (for the Report view and messages)."""
    from polycube_wb.objects.base import CANCELLED_STATUS

    kind = stage_kind(obj)
    if obj.Status == CANCELLED_STATUS:
        return f"{obj.Label}: {CANCELLED_STATUS}; it runs again at the next recompute"
    if not obj.isValid() or obj.Status not in ("ok", ""):
        return f"{obj.Label}: failed: {obj.Status}"
    if kind == "Target":
        return f"{obj.Label}: {obj.Triangles} triangles, genus {obj.Genus}"
    if kind == "Segmentation":
        return (f"{obj.Label}: labeling {'valid' if obj.Valid else 'INVALID'}: {obj.Parts} "
                f"part(s), {obj.Charts} charts, {obj.Corners} corners; invalid charts "
                f"{obj.InvalidCharts}, boundaries {obj.InvalidBoundaries}, corners "
                f"{obj.InvalidCorners}")
    if kind in ("BaseMesh", "Fit"):
        line = (f"{obj.Label}: cage of {obj.Faces} faces, {obj.Vertices} vertices, "
                f"{obj.ExtraordinaryVertices} extraordinary, genus {obj.Genus}")
        if kind == "Fit":
            size = _target_diagonal(obj)
            line += (f"; distance to the target mean {_mm(obj.MeanDistance, size)}, max "
                     f"{_mm(obj.MaxDistance, size)}; volume outside the target "
                     f"{100 * obj.OutsideVolume:.2f} % ({obj.Stopped})")
        return line
    if kind == "Solid":
        return (f"{obj.Label}: solid of {obj.BrepFaces} B-spline faces, valid "
                f"{obj.BrepValid}, volume {obj.BrepVolume:.6g} mm³")
    if kind == "Deviation":
        return (f"{obj.Label}: distance to the target mean {obj.MeanDeviation:.3g} mm "
                f"({obj.MeanDeviationPercent:.3f} % of the size), max {obj.MaxDeviation:.3g} mm "
                f"({obj.MaxDeviationPercent:.3f} %); volume outside the target "
                f"{obj.OutsideVolume:.3f} %, not covered {obj.UncoveredVolume:.3f} %; watertight "
                f"{obj.Watertight}")
    return obj.Label


def _target_diagonal(obj):
    """Bounding-box diagonal of the target ``obj`` is built from, mm (None without one)."""
    target = upstream_objects(obj).get("Target")
    return target.Mesh.BoundBox.DiagonalLength if target is not None else None


def _mm(fraction, diagonal):
    """A distance given as a fraction of the diagonal, in mm and in % of the size."""
    if not diagonal:
        return f"{100 * fraction:.3g} % of the size"
    return f"{fraction * diagonal:.3g} mm ({100 * fraction:.3g} % of the size)"


def import_subd_cage(doc, path, progress=NO_PROGRESS, depth=EXPORT_DEPTH):
    """Turn a SubD cage (closed polygon OBJ) into a B-spline solid ``Part::Feature`` in ``doc``.

    Returns
    -------
    (Part::Feature, dict) the new object and the report of :func:`subd_to_solid`.
    """
    from polycube_wb.document import add_solid

    path = os.path.abspath(os.fspath(path))
    solid, report = subd_to_solid(path, depth=depth, measure=True, progress=progress)
    name = os.path.splitext(os.path.basename(path))[0] + "_solid"
    return add_solid(doc, solid, name), report


def export_step(obj, path):
    """Write the shape of ``obj`` (a Part object) to a STEP file; returns the path."""
    from polycube_wb.step_io import write_step

    return write_step(obj.Shape, path)
