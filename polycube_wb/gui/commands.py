# SPDX-License-Identifier: LGPL-2.1-or-later
"""The workbench's commands and the document operations behind them.

Each command's ``Activated`` only gathers input (file dialogs, the selection) and calls
one of the module-level operations below (``import_target_mesh``, ``label_polycube``,
``import_subd_cage``, ...). The operations do the work inside a document transaction
(one undo step) and take no dialogs, so scripts and tests call them directly.

Errors reach the user twice: as a line in the Report view (``FreeCAD.Console``) and as
a message box. Bad input (``PolycubeInputError``) is a warning box, a stage that is not
built yet (``StageNotAvailableError``) an information box naming the stage, anything
else an error box plus the traceback in the Report view.

Importing this module needs the FreeCAD GUI only for ``register()`` and the commands'
``Activated``; numpy and ``core`` are imported when a command runs.
"""
import contextlib
import os
import traceback

import FreeCAD
import FreeCADGui

from polycube_wb.gui import icon_path

SOURCE_PROPERTY = "PolycubeSource"
"""Property on an imported target ``Mesh::Feature``: the mesh file it was read from."""
PARTS_PROPERTY = "PolycubeParts"
"""Property on a target: how the pipeline splits it into parts (``single`` or ``auto``)."""
RESULT_KIND_PROPERTY = "PolycubeResult"
"""Property on a result group (``parts`` or ``labels``)."""
RESULT_TARGET_PROPERTY = "PolycubeTarget"
"""Link from a result group to its target mesh object."""

MESH_FILTER = "Triangle meshes (*.stl *.obj *.ply *.off);;All files (*)"
CAGE_FILTER = "Polygon meshes (*.obj);;All files (*)"
STEP_FILTER = "STEP files (*.step *.stp)"
PREFERENCES = "User parameter:BaseApp/Preferences/Mod/Polycube"

LABEL_NAMES = ("PlusX", "MinusX", "PlusY", "MinusY", "PlusZ", "MinusZ")
"""Object names of the six polycube labels (directions in the part's own frame)."""
LABEL_COLOURS = ((0.90, 0.16, 0.16), (0.55, 0.05, 0.05), (0.20, 0.75, 0.20),
                 (0.05, 0.40, 0.05), (0.20, 0.45, 0.95), (0.05, 0.15, 0.55))
PART_COLOURS = ((0.12, 0.47, 0.71), (1.00, 0.50, 0.05), (0.17, 0.63, 0.17),
                (0.84, 0.15, 0.16), (0.58, 0.40, 0.74), (0.55, 0.34, 0.29),
                (0.89, 0.47, 0.76), (0.50, 0.50, 0.50), (0.74, 0.74, 0.13),
                (0.09, 0.75, 0.81))

NOT_AVAILABLE = "not available yet"


# ----------------------------------------------------------------------------------------
# Document operations (no dialogs; usable from scripts and tests)
# ----------------------------------------------------------------------------------------

@contextlib.contextmanager
def transaction(doc, name):
    """One undo step for everything done inside the block.

    The transaction is aborted (changes rolled back) when the block raises, except for
    ``StageNotAvailableError``: what was added before the missing stage (e.g. the target
    mesh of *Reconstruct all*) is kept and can be undone.
    """
    from core.errors import StageNotAvailableError

    doc.openTransaction(name)
    try:
        yield
    except StageNotAvailableError:
        doc.commitTransaction()
        raise
    except BaseException:
        doc.abortTransaction()
        raise
    doc.commitTransaction()


def import_target_mesh(doc, path, components="largest", check_self_intersections=True):
    """Read and validate a target mesh file and add it as a ``Mesh::Feature``.

    Parameters
    ----------
    doc : App.Document
    path : str, STL / OBJ / PLY / OFF file.
    components, check_self_intersections : as in ``core.validate.validate_target``.

    Returns
    -------
    (Mesh::Feature, dict)
        The new object (with the ``PolycubeSource`` and ``PolycubeParts`` properties) and
        the intake summary (triangles, vertices, genus, components, bbox_diagonal, ...).

    Raises
    ------
    InvalidMeshError
        The file cannot be read or the mesh is not a valid closed solid; the document
        is not changed.
    """
    from core.mesh_io import read_triangle_soup
    from core.validate import validate_target
    from polycube_wb.document import add_target_mesh

    path = os.path.abspath(os.fspath(path))
    mesh, summary = validate_target(*read_triangle_soup(path), components=components,
                                    check_self_intersections=check_self_intersections,
                                    name=path)
    with transaction(doc, "Import target mesh"):
        obj = add_target_mesh(doc, mesh, _base_name(path))
        mark_target(obj, path)
    FreeCAD.Console.PrintMessage(
        f"Polycube: imported {path}: {summary['triangles']} triangles, "
        f"{summary['vertices']} vertices, genus {summary['genus']}, "
        f"{summary['components']} component(s), bounding-box diagonal "
        f"{summary['bbox_diagonal']:.6g}, volume {summary['volume']:.6g}\n")
    for warning in summary["warnings"]:
        FreeCAD.Console.PrintWarning(f"Polycube: {path}: {warning}\n")
    return obj, summary


def mark_target(obj, path, parts="single"):
    """Record on ``obj`` that it is the target mesh read from ``path`` (idempotent)."""
    from core.params import PART_MODES

    if SOURCE_PROPERTY not in obj.PropertiesList:
        obj.addProperty("App::PropertyFile", SOURCE_PROPERTY, "Polycube",
                        "Mesh file this target was read from")
        obj.setEditorMode(SOURCE_PROPERTY, 1)
    if PARTS_PROPERTY not in obj.PropertiesList:
        obj.addProperty("App::PropertyEnumeration", PARTS_PROPERTY, "Polycube",
                        "Parts for labeling: 'single' (whole mesh) or 'auto' (curve skeleton)")
        setattr(obj, PARTS_PROPERTY, list(PART_MODES))
        setattr(obj, PARTS_PROPERTY, parts)
    setattr(obj, SOURCE_PROPERTY, os.fspath(path))


def is_target(obj):
    """True if ``obj`` is a target mesh added by this workbench."""
    return obj.isDerivedFrom("Mesh::Feature") and SOURCE_PROPERTY in obj.PropertiesList


def find_target(doc, selection=()):
    """The target mesh to work on: the selected one, else the last one added to ``doc``.

    Returns None when ``doc`` holds no target.
    """
    for obj in selection:
        if is_target(obj):
            return obj
    for obj in reversed(doc.Objects):
        if is_target(obj):
            return obj
    return None


def segment_parts(doc, target, progress=None):
    """Split the target into parts (curve-skeleton segmentation) and show them.

    Sets the target's ``PolycubeParts`` to ``auto`` (so *Label polycube* uses these
    parts) and adds a group with one coloured mesh per part, replacing an earlier one.

    Returns
    -------
    (App::DocumentObjectGroup, dict) the group and the report's ``parts`` section.
    """
    result = _run_to(target, "parts", progress, parts="auto")
    state = result.state
    with transaction(doc, "Segment parts"):
        setattr(target, PARTS_PROPERTY, "auto")
        n_parts = int(state["face_part"].max()) + 1
        names = [f"Part{k:03d}" for k in range(n_parts)]
        colours = [PART_COLOURS[k % len(PART_COLOURS)] for k in range(n_parts)]
        group = _show_face_groups(doc, target, state["target"], state["face_part"], names,
                                  colours, "parts")
    section = result.report.get("parts", {})
    FreeCAD.Console.PrintMessage(
        f"Polycube: {target.Label}: {n_parts} part(s) "
        f"({section.get('pieces', 'n/a')} skeleton pieces, "
        f"{section.get('junctions', 'n/a')} junctions)\n")
    return group, section


def label_polycube(doc, target, progress=None):
    """Run the pipeline up to the polycube labeling and show the six labels.

    Uses the target's ``PolycubeParts`` mode. Adds a group with one coloured mesh per
    label (``PlusX`` ... ``MinusZ``, directions in each part's own frame), replacing an
    earlier one, hides the target, and prints the validity figures.

    Returns
    -------
    (App::DocumentObjectGroup, dict) the group and the report's ``labeling`` section.
    """
    result = _run_to(target, "labeling", progress, parts=getattr(target, PARTS_PROPERTY))
    state, report = result.state, result.report["labeling"]
    with transaction(doc, "Label polycube"):
        group = _show_face_groups(doc, target, state["target"], state["face_label"],
                                  list(LABEL_NAMES), list(LABEL_COLOURS), "labels")
        if target.ViewObject is not None:
            target.ViewObject.Visibility = False
    print_labeling_report(target.Label, report)
    return group, report


def build_base_mesh(doc, target, progress=None):
    """Run the pipeline to the coarse quad base mesh (one part) and show its cage.

    Returns
    -------
    (Part::Feature, dict) the cage object and the report's ``base_mesh`` section.

    Raises
    ------
    StageNotAvailableError when the base mesh cannot be built yet (e.g. several parts).
    """
    obj, report = _run_and_show_cage(doc, target, "basemesh", "BaseMesh", "base mesh", progress)
    section = report["base_mesh"]
    FreeCAD.Console.PrintMessage(
        f"Polycube: {target.Label}: base mesh {section['faces']} faces ({section['quads']} quads), "
        f"{section['vertices']} vertices, {section['extraordinary_vertices']} extraordinary "
        f"vertices, genus {section['genus']}\n")
    return obj, section


def fit_to_target(doc, target, progress=None, **params):
    """Run the pipeline through the shape optimisation and show the fitted base mesh's cage.

    ``params`` are pipeline parameters (e.g. ``fit_iterations``).

    Returns
    -------
    (Part::Feature, dict) the cage object and the report's ``fit`` section.
    """
    obj, report = _run_and_show_cage(doc, target, "fit", "FittedBaseMesh", "fitted base mesh",
                                     progress, **params)
    fit = report["fit"]
    FreeCAD.Console.PrintMessage(
        f"Polycube: {target.Label}: fit {fit['iterations']} iterations ({fit['stopped']}); mean "
        f"distance {fit['mean_distance']:.2e}, max {fit['max_distance']:.2e} of the bounding-box "
        f"diagonal; outside volume {fit['outside_volume_fraction']:.2e} of the target\n")
    return obj, fit


def _run_and_show_cage(doc, target, stop_after, suffix, what, progress, **params):
    """Run to ``stop_after`` and show ``state['base_mesh']`` as ``<target>_<suffix>``."""
    from core.errors import StageNotAvailableError
    from polycube_wb.document import add_base_mesh

    params.setdefault("parts", getattr(target, PARTS_PROPERTY))
    result = _run_to(target, stop_after, progress, **params)
    stages = result.report["stages"]
    if any(entry["status"] != "ok" for entry in stages.values()):
        stage, entry = next((name, entry) for name, entry in stages.items()
                            if entry["status"] != "ok")
        raise StageNotAvailableError(f"the '{stage}' stage did not run: {entry['message']}")
    name = f"{target.Name}_{suffix}"
    with transaction(doc, f"Build {what}"):
        old = doc.getObject(name)
        if old is not None:
            doc.removeObject(old.Name)
        obj = add_base_mesh(doc, result.state["base_mesh"], name)
        obj.Label = f"{target.Label} {what}"
    return obj, result.report


def print_labeling_report(name, report):
    """Write the labeling validity figures to the Report view."""
    line = (f"Polycube: {name}: labeling {'valid' if report['valid'] else 'INVALID'}: "
            f"{report['parts']} part(s), {report['charts']} charts, {report['corners']} "
            f"corners; invalid charts {report['invalid_charts']}, invalid boundaries "
            f"{report['invalid_boundaries']}, invalid corners {report['invalid_corners']}, "
            f"turning points {report['turning_points']}; mean normal-to-label angle "
            f"{report['mean_angle_deg']:.2f} deg\n")
    if report["valid"]:
        FreeCAD.Console.PrintMessage(line)
    else:
        FreeCAD.Console.PrintWarning(line)


def reconstruct_all(doc, path, progress=None, **params):
    """``polycube_wb.api.reconstruct`` inside one transaction; returns the solid's object.

    The target mesh the API adds is marked as a target (``PolycubeSource``) so the
    stage commands can use it.

    Raises
    ------
    StageNotAvailableError
        A stage the solid needs is not built yet; the target mesh stays in ``doc``.
    """
    from core.progress import NO_PROGRESS
    from polycube_wb import api

    path = os.path.abspath(os.fspath(path))
    before = {obj.Name for obj in doc.Objects}
    with transaction(doc, "Reconstruct all"):
        try:
            solid = api.reconstruct(doc, path, progress=progress or NO_PROGRESS, **params)
        finally:
            for obj in doc.Objects:
                if obj.Name not in before and obj.isDerivedFrom("Mesh::Feature"):
                    mark_target(obj, path, params.get("parts", "single"))
    return solid


def import_subd_cage(doc, path, progress=None, depth=None):
    """Turn a SubD cage (closed polygon OBJ) into a B-spline solid in ``doc``.

    Returns
    -------
    (Part::Feature, dict) the new object and the report of
    ``polycube_wb.api.subd_to_solid`` (``brep``: faces, valid, closed, volume,
    volume_error_rel, ...).
    """
    from core.progress import NO_PROGRESS
    from polycube_wb import api
    from polycube_wb.document import add_solid

    path = os.path.abspath(os.fspath(path))
    depth = api.DEFAULT_EXPORT_DEPTH if depth is None else depth
    solid, report = api.subd_to_solid(path, depth=depth, measure=True,
                                      progress=progress or NO_PROGRESS)
    with transaction(doc, "Import SubD cage as solid"):
        obj = add_solid(doc, solid, _base_name(path) + "_solid")
    brep = report["brep"]
    jump = brep.get("max_normal_jump_deg")
    FreeCAD.Console.PrintMessage(
        f"Polycube: {path} -> {obj.Label}: {brep['faces']} B-spline faces, "
        f"valid {brep['valid']}, closed {brep['closed']}, volume {brep['volume']:.6g} "
        f"(limit surface {brep['limit_volume']:.6g}, relative error "
        f"{brep['volume_error_rel']:.2e}), max normal jump "
        f"{'n/a' if jump is None else f'{jump:.3g} deg'}\n")
    return obj, report


def export_step(obj, path):
    """Write the shape of ``obj`` (a Part object) to a STEP file; returns the path."""
    from polycube_wb.step_io import write_step

    written = write_step(obj.Shape, path)
    FreeCAD.Console.PrintMessage(f"Polycube: wrote {obj.Label} to {written}\n")
    return written


def check_result(solid_obj, target_obj, samples=20000):
    """Compare a result solid with a target mesh, as ``polycube_wb.api.check`` does.

    Parameters
    ----------
    solid_obj : Part object whose shape holds exactly one solid.
    target_obj : ``Mesh::Feature`` with a closed, outward-oriented mesh.
    samples : random surface points per surface for the distances.

    Returns
    -------
    dict
        ``valid``, ``closed``, ``faces``, ``watertight`` (tessellation of the solid,
        manifold3d and trimesh), ``outside_volume_fraction``,
        ``uncovered_volume_fraction`` (fractions of the target volume) and
        ``distances`` (``core.quality.surface_distances``, fractions of the target's
        bounding-box diagonal).

    Raises
    ------
    PolycubeInputError
        The object does not hold exactly one solid.
    """
    import numpy as np

    from core.errors import PolycubeInputError
    from core.quality import containment, is_watertight_manifold, surface_distances
    from polycube_wb.brep import tessellate
    from polycube_wb.convert import mesh_to_arrays

    solids = solid_obj.Shape.Solids
    if len(solids) != 1:
        raise PolycubeInputError(f"{solid_obj.Label}: expected one solid, found {len(solids)}")
    solid = solids[0]
    target_V, target_F = mesh_to_arrays(target_obj.Mesh)
    diagonal = float(np.linalg.norm(target_V.max(axis=0) - target_V.min(axis=0)))
    V, F = tessellate(solid, 1e-4 * diagonal)
    inside = containment(V, F, target_V, target_F)
    distances = surface_distances(V, F, target_V, target_F, samples=samples)
    shells = solid.Shells
    figures = {
        "result": solid_obj.Label,
        "target": target_obj.Label,
        "valid": bool(solid.isValid()),
        "closed": bool(shells) and all(shell.isClosed() for shell in shells),
        "faces": len(solid.Faces),
        "watertight": bool(is_watertight_manifold(V, F)),
        "outside_volume_fraction": inside["outside_volume_fraction"],
        "uncovered_volume_fraction": inside["uncovered_volume_fraction"],
        "distances": distances,
    }
    FreeCAD.Console.PrintMessage(
        f"Polycube: check {figures['result']} against {figures['target']}: "
        f"valid {figures['valid']}, closed {figures['closed']}, watertight "
        f"{figures['watertight']}, {figures['faces']} faces; outside volume "
        f"{100 * figures['outside_volume_fraction']:.3f} %, uncovered volume "
        f"{100 * figures['uncovered_volume_fraction']:.3f} % of the target; distance to "
        f"target mean {distances['result_to_target_mean']:.2e}, Hausdorff "
        f"{distances['hausdorff']:.2e} (fractions of the bounding-box diagonal)\n")
    return figures


def _run_to(target, stop_after, progress, **params):
    """Run the core pipeline on a target object's file up to ``stop_after``."""
    from core.pipeline import reconstruct
    from core.progress import NO_PROGRESS

    result = reconstruct(getattr(target, SOURCE_PROPERTY), params, progress or NO_PROGRESS,
                         stop_after)
    if result.failed is not None:
        raise result.failed
    return result


def _show_face_groups(doc, target, mesh, face_group, names, colours, kind):
    """Add a group holding one coloured mesh per face group; replaces an older one.

    Parameters
    ----------
    mesh : core.types.TriMesh, the validated target (vertices (n, 3) float64,
        faces (m, 3) int64).
    face_group : (m,) int, group index of every face (index into ``names``).
    names, colours : per group index, object name and RGB in [0, 1].
    kind : ``parts`` or ``labels``.
    """
    import numpy as np

    from polycube_wb.convert import arrays_to_mesh

    _remove_result_groups(doc, target, kind)
    group = doc.addObject("App::DocumentObjectGroup", f"{target.Name}_{kind}")
    group.Label = f"{target.Label} {kind}"
    group.addProperty("App::PropertyString", RESULT_KIND_PROPERTY, "Polycube", "Result kind")
    group.addProperty("App::PropertyLink", RESULT_TARGET_PROPERTY, "Polycube", "Target mesh")
    setattr(group, RESULT_KIND_PROPERTY, kind)
    setattr(group, RESULT_TARGET_PROPERTY, target)
    vertices = np.asarray(mesh.vertices)
    faces = np.asarray(mesh.faces)
    face_group = np.asarray(face_group)
    for index in np.unique(face_group):
        sub = faces[face_group == index]
        used, local = np.unique(sub, return_inverse=True)
        obj = doc.addObject("Mesh::Feature", f"{target.Name}_{names[index]}")
        obj.Label = f"{target.Label} {names[index]}"
        obj.Mesh = arrays_to_mesh(vertices[used], local.reshape(-1, 3))
        group.addObject(obj)
        if obj.ViewObject is not None:
            obj.ViewObject.ShapeColor = tuple(colours[index])
    doc.recompute()
    return group


def _remove_result_groups(doc, target, kind):
    for obj in list(doc.Objects):
        if RESULT_KIND_PROPERTY not in obj.PropertiesList:
            continue
        link = getattr(obj, RESULT_TARGET_PROPERTY)
        if getattr(obj, RESULT_KIND_PROPERTY) == kind and link is not None \
                and link.Name == target.Name:
            for child in list(obj.Group):
                doc.removeObject(child.Name)
            doc.removeObject(obj.Name)


def _base_name(path):
    return os.path.splitext(os.path.basename(path))[0]


# ----------------------------------------------------------------------------------------
# GUI helpers (dialogs and feedback); tests replace ask_* and message_box
# ----------------------------------------------------------------------------------------

def _last_directory():
    return FreeCAD.ParamGet(PREFERENCES).GetString("LastDirectory", os.path.expanduser("~"))


def _remember_directory(path):
    FreeCAD.ParamGet(PREFERENCES).SetString("LastDirectory", os.path.dirname(path))


def ask_open_file(title, file_filter, start=None):
    """File-open dialog; returns the chosen path or None."""
    from PySide import QtGui

    path, _ = QtGui.QFileDialog.getOpenFileName(FreeCADGui.getMainWindow(), title,
                                                start or _last_directory(), file_filter)
    if not path:
        return None
    _remember_directory(path)
    return path


def ask_save_file(title, file_filter, start):
    """File-save dialog; returns the chosen path (``.step`` added if no suffix) or None."""
    from PySide import QtGui

    path, _ = QtGui.QFileDialog.getSaveFileName(FreeCADGui.getMainWindow(), title, start,
                                                file_filter)
    if not path:
        return None
    if not os.path.splitext(path)[1]:
        path += ".step"
    _remember_directory(path)
    return path


def message_box(kind, title, text):
    """Modal message box; ``kind`` is ``information``, ``warning`` or ``critical``."""
    from PySide import QtGui

    getattr(QtGui.QMessageBox, kind)(FreeCADGui.getMainWindow(), title, text)


def run_guarded(title, work, with_progress=False):
    """Run ``work(progress)`` with a wait cursor and report any failure.

    Parameters
    ----------
    title : str, names the operation in the Report view, the progress bar and boxes.
    work : callable taking a ``FreeCADProgress`` (``with_progress``) or None.
    with_progress : show FreeCAD's progress bar (Esc cancels).

    Returns
    -------
    What ``work`` returns, or None after a failure. The bar is stopped and the cursor
    restored before a message box opens, so the box is never blocked by the bar.
    """
    from PySide import QtCore, QtGui

    from core.errors import Cancelled, PolycubeInputError, StageNotAvailableError
    from polycube_wb.gui.fc_progress import FreeCADProgress

    progress = FreeCADProgress(title) if with_progress else None
    box = None
    QtGui.QApplication.setOverrideCursor(QtCore.Qt.WaitCursor)
    try:
        return work(progress)
    except Cancelled as exc:
        FreeCAD.Console.PrintWarning(f"Polycube: {title}: {exc}\n")
    except StageNotAvailableError as exc:
        FreeCAD.Console.PrintWarning(f"Polycube: {title}: {NOT_AVAILABLE}: {exc}\n")
        box = ("information", f"Stage {NOT_AVAILABLE}:\n\n{exc}")
    except PolycubeInputError as exc:
        FreeCAD.Console.PrintError(f"Polycube: {title}: {exc}\n")
        box = ("warning", str(exc))
    except ImportError as exc:
        FreeCAD.Console.PrintError(f"Polycube: {title}: missing Python package: {exc}\n")
        box = ("critical", f"A Python package is missing:\n\n{exc}\n\n"
               "See the README, section on installing the dependencies.")
    except Exception as exc:  # last resort: show the user the traceback of an internal error
        FreeCAD.Console.PrintError(f"Polycube: {title} failed:\n{traceback.format_exc()}")
        box = ("critical", f"Internal error: {type(exc).__name__}: {exc}\n\n"
               "The Report view shows the traceback.")
    finally:
        if progress is not None:
            progress.stop()
        QtGui.QApplication.restoreOverrideCursor()
    if box is not None:
        message_box(box[0], title, box[1])
    return None


def _selection():
    return FreeCADGui.Selection.getSelection()


def _view_fit():
    if FreeCADGui.ActiveDocument is not None:
        FreeCADGui.SendMsgToActiveView("ViewFit")


# ----------------------------------------------------------------------------------------
# Commands
# ----------------------------------------------------------------------------------------

class _Command:
    """Common parts: resources from class attributes; active when a document is open."""

    ID = ""
    MENU_TEXT = ""
    TOOLTIP = ""

    def GetResources(self):
        return {"Pixmap": icon_path(self.ID), "MenuText": self.MENU_TEXT,
                "ToolTip": self.TOOLTIP}

    def IsActive(self):
        return FreeCAD.ActiveDocument is not None


class ImportTargetCommand(_Command):
    ID = "PolyCube_ImportTarget"
    MENU_TEXT = "Import target mesh..."
    TOOLTIP = ("Read a watertight triangle mesh (STL, OBJ, PLY, OFF), validate it and add it "
               "to the document as the reconstruction target")

    def IsActive(self):
        return True

    def Activated(self):
        path = ask_open_file(self.MENU_TEXT.rstrip("."), MESH_FILTER)
        if path is None:
            return
        doc = FreeCAD.ActiveDocument or FreeCAD.newDocument()
        if run_guarded("Import target mesh", lambda _: import_target_mesh(doc, path)):
            _view_fit()


class _TargetStageCommand(_Command):
    """Runs ``STAGE(doc, target, progress)`` on the selected (or last imported) target."""

    STAGE = None

    def Activated(self):
        doc = FreeCAD.ActiveDocument
        target = find_target(doc, _selection())
        if target is None:
            _no_target(self.MENU_TEXT)
            return
        stage = type(self).STAGE
        run_guarded(self.MENU_TEXT, lambda progress: stage(doc, target, progress),
                    with_progress=True)


class SegmentPartsCommand(_TargetStageCommand):
    ID = "PolyCube_SegmentParts"
    MENU_TEXT = "Segment parts"
    TOOLTIP = ("Split the selected (or last imported) target into parts along its curve "
               "skeleton and show each part in its own colour")
    STAGE = segment_parts


class LabelPolycubeCommand(_TargetStageCommand):
    ID = "PolyCube_LabelPolycube"
    MENU_TEXT = "Label polycube"
    TOOLTIP = ("Compute the polycube labeling (HBECVT) of the selected (or last imported) "
               "target, show the six labels in colour and report its validity")
    STAGE = label_polycube


class BuildBaseMeshCommand(_TargetStageCommand):
    ID = "PolyCube_BuildBaseMesh"
    MENU_TEXT = "Build polycube + base mesh"
    TOOLTIP = ("Deform the labeled target into a polycube and build the coarse quad base mesh "
               "(one part); shows its cage")
    STAGE = build_base_mesh


class FitTargetCommand(_TargetStageCommand):
    ID = "PolyCube_FitTarget"
    MENU_TEXT = "Fit to target"
    TOOLTIP = ("Optimise the base mesh so its Catmull-Clark limit surface fits the target "
               "from inside (volume, packaging and thickness; relaxed gradient projection)")
    STAGE = fit_to_target


class ReconstructAllCommand(_Command):
    ID = "PolyCube_ReconstructAll"
    MENU_TEXT = "Reconstruct all..."
    TOOLTIP = ("Run every stage on a target mesh file, from validation to the B-spline solid; "
               "reports the stage that stops it, if any")

    def IsActive(self):
        return True

    def Activated(self):
        doc = FreeCAD.ActiveDocument
        target = find_target(doc, _selection()) if doc is not None else None
        start = getattr(target, SOURCE_PROPERTY) if target is not None else None
        path = ask_open_file("Reconstruct all", MESH_FILTER, start)
        if path is None:
            return
        doc = doc or FreeCAD.newDocument()
        same_file = target is not None and os.path.abspath(path) == start
        parts = getattr(target, PARTS_PROPERTY) if same_file else "single"
        run_guarded("Reconstruct all",
                    lambda progress: reconstruct_all(doc, path, progress, parts=parts),
                    with_progress=True)
        _view_fit()


class ImportSubDCommand(_Command):
    ID = "PolyCube_ImportSubD"
    MENU_TEXT = "Import SubD cage as solid..."
    TOOLTIP = ("Read a closed polygon mesh (OBJ) as a Catmull-Clark control cage and add its "
               "limit surface as a solid of bicubic B-spline faces")

    def IsActive(self):
        return True

    def Activated(self):
        path = ask_open_file("Import SubD cage as solid", CAGE_FILTER)
        if path is None:
            return
        doc = FreeCAD.ActiveDocument or FreeCAD.newDocument()
        done = run_guarded("Import SubD cage as solid",
                           lambda progress: import_subd_cage(doc, path, progress),
                           with_progress=True)
        if done:
            _view_fit()


class ExportStepCommand(_Command):
    ID = "PolyCube_ExportStep"
    MENU_TEXT = "Export STEP..."
    TOOLTIP = "Write the selected solid to a STEP file"

    def IsActive(self):
        selection = _selection()
        return len(selection) == 1 and selection[0].isDerivedFrom("Part::Feature")

    def Activated(self):
        obj = _selection()[0]
        start = os.path.join(_last_directory(), obj.Label + ".step")
        path = ask_save_file("Export STEP", STEP_FILTER, start)
        if path is not None:
            run_guarded("Export STEP", lambda _: export_step(obj, path))


class CheckResultCommand(_Command):
    ID = "PolyCube_CheckResult"
    MENU_TEXT = "Check result"
    TOOLTIP = ("Compare the selected solid with the target mesh (the selected mesh, else the "
               "last imported target): validity, watertightness, volume outside/uncovered "
               "and surface distances in the Report view")

    def IsActive(self):
        return any(obj.isDerivedFrom("Part::Feature") for obj in _selection())

    def Activated(self):
        selection = _selection()
        solid = next(obj for obj in selection if obj.isDerivedFrom("Part::Feature"))
        target = next((obj for obj in selection if obj.isDerivedFrom("Mesh::Feature")), None)
        target = target or find_target(FreeCAD.ActiveDocument)
        if target is None:
            _no_target(self.MENU_TEXT)
            return
        run_guarded(self.MENU_TEXT, lambda _: check_result(solid, target))


def _no_target(title):
    text = "No target mesh: import one with 'Import target mesh' first (or select it)."
    FreeCAD.Console.PrintWarning(f"Polycube: {title}: {text}\n")
    message_box("warning", title, text)


COMMANDS = (ImportTargetCommand, SegmentPartsCommand, LabelPolycubeCommand,
            BuildBaseMeshCommand, FitTargetCommand, ReconstructAllCommand, ImportSubDCommand,
            ExportStepCommand, CheckResultCommand)
TOOLBAR = tuple(command.ID for command in COMMANDS)
MENU = (ImportTargetCommand.ID, "Separator", SegmentPartsCommand.ID, LabelPolycubeCommand.ID,
        BuildBaseMeshCommand.ID, FitTargetCommand.ID, "Separator", ReconstructAllCommand.ID,
        "Separator", ImportSubDCommand.ID, ExportStepCommand.ID, CheckResultCommand.ID)


def register():
    """Add every command to FreeCAD's command manager (idempotent)."""
    known = set(FreeCADGui.listCommands())
    for command in COMMANDS:
        if command.ID not in known:
            FreeCADGui.addCommand(command.ID, command())
