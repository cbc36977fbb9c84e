# SPDX-License-Identifier: LGPL-2.1-or-later
"""The workbench's commands: thin wrappers over ``polycube_wb.api``.

A command gathers its input (a file dialog, the selection), then runs the API calls as
one undo step with the progress bar (``run_stage_command``): the calls that create or
change objects go through ``FreeCADGui.doCommand``, so the Python console shows a script
that replays them, and the recompute that follows runs the stages (Esc cancels: the
stages that finished keep their results, the one that was running is marked cancelled and
runs again at the next recompute; Undo removes the whole step). Success is reported in the Report view and the status bar;
failures also in a message box: bad input (``PolycubeInputError``) a warning, anything
else an error box plus the traceback in the Report view.

Each stage command works on the selected object's chain (or the last target): it reuses
the stage objects that exist, creates the missing ones, and hides the displays the new
result supersedes.
"""
import os
import traceback

import FreeCAD
import FreeCADGui

from polycube_wb.gui import dialogs, icon_path
from polycube_wb.gui.batch_command import ReconstructFolderCommand

MESH_FILTER = "Triangle meshes (*.stl *.obj *.ply *.off);;All files (*)"
CAGE_FILTER = "Polygon meshes (*.obj);;All files (*)"
STEP_FILTER = "STEP files (*.step *.stp)"
SUPERSEDES = {"Segmentation": ("Target",), "BaseMesh": ("Segmentation",),
              "Fit": ("BaseMesh",), "Solid": ("Fit", "BaseMesh"),
              "Deviation": ("Solid", "Fit", "BaseMesh", "Segmentation", "Target")}
"""Displays hidden when a stage's result is shown (the deviation map is the solid, coloured:
it is shown alone)."""


# ----------------------------------------------------------------------------------------
# Feedback (the dialogs are in polycube_wb.gui.dialogs, which tests replace)
# ----------------------------------------------------------------------------------------

def report_success(text):
    """A success line in the Report view and the status bar."""
    FreeCAD.Console.PrintMessage(f"Polycube: {text}\n")
    FreeCADGui.getMainWindow().statusBar().showMessage(f"Polycube: {text}", 15000)


def run_guarded(title, work, with_progress=False):
    """Run ``work(progress)`` with a busy cursor and report any failure.

    With ``with_progress``, ``progress`` is a :class:`polycube_wb.gui.worker.GuiProgress`
    (bar, *Cancel*, Esc) for ``work`` to run its computations with
    (:func:`polycube_wb.gui.worker.run_job`); otherwise None.

    Returns
    -------
    What ``work`` returns, or None after a failure or a cancel. The bar is stopped and
    the cursor restored before a message is shown.
    """
    from PySide import QtCore, QtGui

    from polycube_wb.gui.worker import GuiProgress

    progress = GuiProgress(title) if with_progress else None
    if progress is not None:
        progress.start()
    else:
        QtGui.QApplication.setOverrideCursor(QtCore.Qt.WaitCursor)
    try:
        return work(progress)
    except Exception as exc:
        failure = exc
    finally:
        if progress is not None:
            progress.stop()
        else:
            QtGui.QApplication.restoreOverrideCursor()
    box = _report_failure(title, failure)
    if box is not None:
        dialogs.message_box(*box)
    return None


def _report_failure(title, exc):
    """Write a failure of ``title`` to the Report view (a cancel also to the status bar);
    returns the message box to show, ``(kind, title, text)``, or None."""
    from core.errors import Cancelled, PolycubeInputError
    from polycube_wb.panel_fields import in_gui_words

    if isinstance(exc, Cancelled):
        FreeCAD.Console.PrintWarning(f"Polycube: {exc}\n")
        FreeCADGui.getMainWindow().statusBar().showMessage(f"Polycube: {exc}", 15000)
        return None
    if isinstance(exc, PolycubeInputError):
        text = in_gui_words(str(exc))
        FreeCAD.Console.PrintError(f"Polycube: {title}: {text}\n")
        return ("warning", title, text)
    if isinstance(exc, ImportError):
        FreeCAD.Console.PrintError(f"Polycube: {title}: missing Python package: {exc}\n")
        return ("critical", title, f"A Python package is missing:\n\n{exc}\n\n"
                "See the README, \"Install as a FreeCAD addon\", step 2.")
    # last resort: show the user the traceback of an internal error
    trace = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    FreeCAD.Console.PrintError(f"Polycube: {title} failed:\n{trace}")
    return ("critical", title, f"Internal error: {type(exc).__name__}: {exc}\n\n"
            "The Report view shows the traceback.")


def run_stage_command(title, doc, build, read_ahead=None):
    """Run ``build()`` and the recompute it needs as one undo step, with progress.

    The stages' computations run in a worker thread while FreeCAD stays live
    (:mod:`polycube_wb.gui.worker`); their results are stored in the document in this
    thread.

    Parameters
    ----------
    title : str, the undo step's and the progress bar's name.
    doc : App.Document
    build : callable creating or changing objects (through ``FreeCADGui.doCommand``);
        may return a stage object to report on and show.
    read_ahead : path of a mesh file ``build`` makes a target of, or None: the file is read
        and validated in the worker first (:func:`polycube_wb.api.read_ahead_target`); a bad
        file is reported before the undo step opens.

    Returns
    -------
    api.RecomputeOutcome, or None when it failed before recomputing (the document is then
    as before) or was cancelled (see ``api.run_in_transaction``: one undo step). Success and stage failures are reported after the
    progress bar has stopped (stopping it clears the status bar).
    """
    from polycube_wb import api

    from core.progress import SubProgress
    from polycube_wb.gui.worker import run_job
    from polycube_wb.stage_jobs import StageJob, read_mesh_file

    def work(progress):
        if read_ahead is not None:
            read = run_job(StageJob(read_mesh_file, (read_ahead,)),
                           SubProgress(progress, 0.0, 0.0))
            api.read_ahead_target(read_ahead, mesh=read.mesh, binary=read.binary)
        return api.run_in_transaction(doc, title, lambda: _built_then_drawn(build), progress,
                                      lambda job, share: _latest_shown(doc, run_job, job, share),
                                      _event_loop_turn)

    first = not _has_results(doc)
    done = run_guarded(title, work, with_progress=True)
    _hide_superseded(doc)
    if first and _has_results(doc):  # the document's first result: show all of it
        _view_fit()
    if done is None:
        return None
    shown, outcome = done
    if outcome.failures:
        lines = [f"{doc.getObject(name).Label}: {reason}"
                 for name, reason in outcome.failures.items()]
        FreeCAD.Console.PrintWarning(f"Polycube: {title}: " + "; ".join(lines) + "\n")
        dialogs.message_box("warning", title, "A stage did not finish:\n\n" + "\n".join(lines))
    if shown is not None:
        _supersede(shown)
        if not outcome.failures:
            report_success(api.describe(shown))
    elif not outcome.failures:
        report_success(f"{title}: done")
    return outcome


def _built_then_drawn(build):
    """``build()``, then the new objects drawn in turns of the event loop of their own: the
    3D view's scene is updated in one, painted in the next (a large mesh takes a tenth of a
    second each), so that making the objects, drawing them and reading the first stage's
    inputs do not hold the GUI in one stretch."""
    built = build()
    _event_loop_turn()
    _repaint_view()
    _event_loop_turn()
    return built


def _repaint_view():
    """Ask the active 3D view for a repaint, which the next turn of the event loop paints."""
    document = FreeCADGui.ActiveDocument
    view = None if document is None else document.ActiveView
    if view is not None and hasattr(view, "redraw"):  # not a 3D view: nothing to paint
        view.redraw()


def _event_loop_turn():
    """One turn of FreeCAD's event loop (pending redraws, timers and input)."""
    from PySide import QtCore

    QtCore.QCoreApplication.processEvents()


def _latest_shown(doc, run_job, job, progress):
    """``run_job(job, progress)`` after hiding the displays that the results stored so far
    supersede: while a stage runs, the 3D view draws the last result alone (drawing the
    target mesh under its labeling doubles the cost of each redraw of a large mesh)."""
    _hide_superseded(doc)
    return run_job(job, progress)


def _supersede(obj):
    """Show ``obj`` and hide the upstream displays its result replaces."""
    from polycube_wb import api

    if obj.ViewObject is None:
        return
    obj.ViewObject.Visibility = True
    chain = api.upstream_objects(obj)
    for kind in SUPERSEDES.get(api.stage_kind(obj), ()):
        if kind in chain and chain[kind] is not obj and chain[kind].ViewObject is not None:
            chain[kind].ViewObject.Visibility = False


def _has_results(doc):
    """Whether a stage object of ``doc`` holds a result."""
    from polycube_wb import api

    return _is_open(doc) and any(
        api.stage_kind(obj) is not None and obj.ResultId for obj in doc.Objects)


def _is_open(doc):
    """Whether ``doc`` is still open in FreeCAD."""
    try:
        return doc.Name in FreeCAD.listDocuments()
    except ReferenceError:
        return False


def _hide_superseded(doc):
    """Hide every stage result that a shown, up-to-date later result replaces (also after
    a cancel, a resume or a recompute, which show each object whose display they rebuild)."""
    from polycube_wb import api

    if not _is_open(doc):
        return
    for later in doc.Objects:
        kind = api.stage_kind(later)
        if kind not in SUPERSEDES or later.ViewObject is None or \
                not later.ViewObject.Visibility or later.Status != "ok" or not later.ResultId:
            continue
        for name in later.Proxy.INPUTS:
            earlier = getattr(later, name, None)
            while earlier is not None and api.stage_kind(earlier) in SUPERSEDES[kind]:
                if earlier.ViewObject is not None:
                    earlier.ViewObject.Visibility = False
                links = earlier.Proxy.INPUTS if hasattr(earlier, "Proxy") else ()
                earlier = getattr(earlier, links[0], None) if links else None


def _selection():
    return FreeCADGui.Selection.getSelection()


def _view_fit():
    if FreeCADGui.ActiveDocument is not None:
        FreeCADGui.SendMsgToActiveView("ViewFit")


def _ref(obj):
    return f"App.getDocument({obj.Document.Name!r}).getObject({obj.Name!r})"


def _do(line):
    """Run a console line (echoed in the Python console) and return ``_polycube_result``."""
    FreeCADGui.doCommand("from polycube_wb import api")
    FreeCADGui.doCommand(f"_polycube_result = {line}")
    import __main__

    return getattr(__main__, "_polycube_result", None)


def selected_or_last(kind):
    """The stage object of ``kind`` for the selection (its chain), else the last one."""
    from polycube_wb import api

    doc = FreeCAD.ActiveDocument
    for obj in _selection():
        if api.stage_kind(obj) is not None:
            found = api.find_stage(doc, kind, obj)
            if found is not None:
                return found
    return api.find_stage(doc, kind)


def target_for_selection():
    """The Target to work on: the selection's, else the last one; converts an old plain
    target mesh (``Mesh::Feature`` of an older version) into a Target when selected."""
    from polycube_wb import api

    for obj in _selection():
        if api.stage_kind(obj) is None and obj.isDerivedFrom("Mesh::Feature"):
            return _do(f"api.make_target(App.ActiveDocument, {_ref(obj)}, "
                       f"name={obj.Name + '_target'!r})")
    return selected_or_last("Target")


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
               "to the document (embedded) as the reconstruction target")

    def IsActive(self):
        return True

    def Activated(self):
        path = dialogs.ask_open_file(self.MENU_TEXT.rstrip("."), MESH_FILTER)
        if path is None:
            return
        doc = FreeCAD.ActiveDocument or FreeCAD.newDocument()
        name = os.path.splitext(os.path.basename(path))[0]
        run_stage_command("Import target mesh", doc, lambda: _do(
            f"api.make_target(App.ActiveDocument, {path!r}, name={name!r})"), read_ahead=path)
        _view_fit()


class _StageCommand(_Command):
    """Creates the stage ``KIND`` after the selection's chain (reusing what exists)."""

    KIND = ""
    PROPERTIES = {}

    def Activated(self):
        doc = FreeCAD.ActiveDocument
        from polycube_wb import api

        existing = selected_or_last(self.KIND)
        if existing is not None and api.is_reusable(existing) and \
                _is_on_selected_chain(existing):
            run_stage_command(self.MENU_TEXT, doc, lambda: _recompute_existing(existing))
            return
        target = target_for_selection()
        if target is None:
            _no_target(self.MENU_TEXT)
            return
        run_stage_command(self.MENU_TEXT, doc, lambda: self.create(target))

    def create(self, target):
        """Make the chain from ``target`` to this stage; returns the new stage object."""
        chain_start = _chain_start(target, self.KIND)
        properties = {self.KIND: self.PROPERTIES} if self.PROPERTIES else {}
        _do(f"api.make_chain(App.ActiveDocument, {_ref(chain_start)}, {self.KIND!r}, "
            f"**{properties!r})")
        from polycube_wb import api

        return api.find_stage(FreeCAD.ActiveDocument, self.KIND, chain_start)


def _chain_start(target, kind):
    """Where to extend the chain: the selected stage object if it comes before ``kind``."""
    from polycube_wb import api

    order = api.STAGE_ORDER
    for obj in _selection():
        selected = api.stage_kind(obj)
        if selected in order and kind in order and order.index(selected) < order.index(kind):
            return obj
    return target


def _is_on_selected_chain(obj):
    """True when ``obj`` is selected or built from the selection (or nothing is selected)."""
    from polycube_wb import api

    selection = [o for o in _selection() if api.stage_kind(o) is not None]
    if not selection:
        return True
    chain = api.upstream_objects(obj).values()
    return any(o is obj or o in chain for o in selection)


def _recompute_existing(obj):
    FreeCADGui.doCommand(f"{_ref(obj)}.touch()")
    return obj


class SegmentPartsCommand(_StageCommand):
    ID = "PolyCube_SegmentParts"
    MENU_TEXT = "Segment parts"
    TOOLTIP = ("Split the target into parts along its curve skeleton and show each part in "
               "its own colour (a Segmentation with automatic parts; the base mesh stage "
               "keeps using the single-part labeling unless you select this one)")
    KIND = "Segmentation"

    def Activated(self):
        target = target_for_selection()
        if target is None:
            _no_target(self.MENU_TEXT)
            return
        run_stage_command(self.MENU_TEXT, FreeCAD.ActiveDocument, lambda: _do(
            f"api.make_segmentation(App.ActiveDocument, {_ref(target)}, "
            f"name={target.Name + '_parts'!r}, PartMode='auto', ColourBy='Parts')"))


class LabelPolycubeCommand(_StageCommand):
    ID = "PolyCube_LabelPolycube"
    MENU_TEXT = "Label polycube"
    TOOLTIP = ("Compute the polycube labeling (HBECVT) of the selected (or last) target, "
               "show the six labels in colour and report its validity")
    KIND = "Segmentation"


class BuildBaseMeshCommand(_StageCommand):
    ID = "PolyCube_BuildBaseMesh"
    MENU_TEXT = "Build polycube + base mesh"
    TOOLTIP = ("Deform the labeled target into a polycube and build the coarse quad base mesh "
               "(one part); shows its cage")
    KIND = "BaseMesh"


class FitTargetCommand(_StageCommand):
    ID = "PolyCube_FitTarget"
    MENU_TEXT = "Fit to target"
    TOOLTIP = ("Optimise the base mesh so its Catmull-Clark limit surface fits the target "
               "from inside (volume, packaging and thickness; Esc cancels)")
    KIND = "Fit"


class MakeSolidCommand(_StageCommand):
    ID = "PolyCube_MakeSolid"
    MENU_TEXT = "Make solid"
    TOOLTIP = ("Turn the fitted cage (or the selected cage) into a solid of bicubic B-spline "
               "faces: its Catmull-Clark limit surface")
    KIND = "Solid"


class ReconstructAllCommand(_Command):
    ID = "PolyCube_ReconstructAll"
    MENU_TEXT = "Reconstruct all"
    TOOLTIP = ("Run every stage on the selected (or last) target, from the labeling to the "
               "B-spline solid; asks for a mesh file when the document has no target")

    def IsActive(self):
        return True

    def Activated(self):
        doc = FreeCAD.ActiveDocument
        target = target_for_selection() if doc is not None else None
        if target is None:
            path = dialogs.ask_open_file("Reconstruct all: target mesh", MESH_FILTER)
            if path is None:
                return
            doc = doc or FreeCAD.newDocument()
            name = os.path.splitext(os.path.basename(path))[0]

            def build():
                made = _do(f"api.make_target(App.ActiveDocument, {path!r}, name={name!r})")
                return _make_chain_to_solid(made)
        else:
            path = None

            def build():
                return _make_chain_to_solid(target)
        run_stage_command("Reconstruct all", doc, build, read_ahead=path)
        _view_fit()


def _make_chain_to_solid(target):
    from polycube_wb import api

    _do(f"api.make_chain(App.ActiveDocument, {_ref(target)}, 'Solid')")
    return api.find_stage(FreeCAD.ActiveDocument, "Solid", target)


class CheckResultCommand(_Command):
    ID = "PolyCube_CheckResult"
    MENU_TEXT = "Check result (deviation map)"
    TOOLTIP = ("Colour the selected (or last) solid by its distance to the target (its own, "
               "or the selected mesh), with a legend, and report mean and max distance, "
               "volume outside and uncovered")

    def IsActive(self):
        return FreeCAD.ActiveDocument is not None and _solid_to_check() is not None

    def Activated(self):
        from polycube_wb import api

        solid = _solid_to_check()
        target = api.upstream_objects(solid).get("Target") or next(
            (obj for obj in _selection() if obj.isDerivedFrom("Mesh::Feature")),
            None) or api.find_stage(FreeCAD.ActiveDocument, "Target")
        if target is None:
            _no_target(self.MENU_TEXT)
            return
        run_stage_command(self.MENU_TEXT, FreeCAD.ActiveDocument, lambda: _do(
            f"api.make_deviation(App.ActiveDocument, {_ref(solid)}, {_ref(target)}, "
            f"name={solid.Name + '_deviation'!r})"))


def _solid_to_check():
    """The selected Part object holding a solid, else the last Solid stage object."""
    for obj in _selection():
        if obj.isDerivedFrom("Part::Feature") and len(obj.Shape.Solids) == 1:
            return obj
    return selected_or_last("Solid")


class EditCageCommand(_Command):
    ID = "PolyCube_EditCage"
    MENU_TEXT = "Edit cage"
    TOOLTIP = ("Move vertices of the selected base mesh or fitted cage; the fit (from an "
               "edited base mesh) or the solid (from an edited fitted cage) follows")

    def IsActive(self):
        return FreeCAD.ActiveDocument is not None and _selected_cage() is not None

    def Activated(self):
        cage = _selected_cage()
        FreeCADGui.ActiveDocument.setEdit(cage.Name, 0)


def _selected_cage():
    from polycube_wb import api

    for obj in _selection():
        if api.stage_kind(obj) in ("BaseMesh", "Fit"):
            return obj
    return None


class RecomputeCommand(_Command):
    ID = "PolyCube_Recompute"
    MENU_TEXT = "Recompute with progress"
    TOOLTIP = ("Recompute the document's changed stages (e.g. after editing properties) as "
               "one undo step with the progress bar; Esc cancels (finished stages keep their "
               "results; Undo restores the document)")

    def IsActive(self):
        return FreeCAD.ActiveDocument is not None

    def Activated(self):
        doc = FreeCAD.ActiveDocument
        run_stage_command("Recompute", doc, lambda: None)


class ImportSubDCommand(_Command):
    ID = "PolyCube_ImportSubD"
    MENU_TEXT = "Import SubD cage as solid..."
    TOOLTIP = ("Read a closed polygon mesh (OBJ) as a Catmull-Clark control cage and add its "
               "limit surface as a solid of bicubic B-spline faces")

    def IsActive(self):
        return True

    def Activated(self):
        path = dialogs.ask_open_file("Import SubD cage as solid", CAGE_FILTER)
        if path is None:
            return
        doc = FreeCAD.ActiveDocument or FreeCAD.newDocument()

        def work(_):
            doc.openTransaction("Import SubD cage as solid")
            try:
                obj, report = _do(f"api.import_subd_cage(App.ActiveDocument, {path!r})")
            except BaseException:
                doc.abortTransaction()
                raise
            doc.commitTransaction()
            return obj, report

        done = run_guarded("Import SubD cage as solid", work)
        if done:
            obj, report = done
            brep = report["brep"]
            report_success(f"{path} -> {obj.Label}: {brep['faces']} B-spline faces, valid "
                           f"{brep['valid']}, volume {brep['volume']:.6g} (limit surface "
                           f"{brep['limit_volume']:.6g})")
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
        start = os.path.join(dialogs.last_directory(), obj.Label + ".step")
        path = dialogs.ask_save_file("Export STEP", STEP_FILTER, start)
        if path is not None:
            run_guarded("Export STEP", lambda _: report_success(
                f"wrote {obj.Label} to {_do(f'api.export_step({_ref(obj)}, {path!r})')}"))


def _no_target(title):
    text = "No target mesh: import one with 'Import target mesh' first (or select it)."
    FreeCAD.Console.PrintWarning(f"Polycube: {title}: {text}\n")
    dialogs.message_box("warning", title, text)


COMMANDS = (ImportTargetCommand, SegmentPartsCommand, LabelPolycubeCommand,
            BuildBaseMeshCommand, FitTargetCommand, MakeSolidCommand, ReconstructAllCommand,
            ReconstructFolderCommand, RecomputeCommand, CheckResultCommand, EditCageCommand, ImportSubDCommand,
            ExportStepCommand)
TOOLBAR = tuple(command.ID for command in COMMANDS)
MENU = (ImportTargetCommand.ID, "Separator", SegmentPartsCommand.ID, LabelPolycubeCommand.ID,
        BuildBaseMeshCommand.ID, FitTargetCommand.ID, MakeSolidCommand.ID, "Separator",
        ReconstructAllCommand.ID, ReconstructFolderCommand.ID, RecomputeCommand.ID, "Separator",
        CheckResultCommand.ID, EditCageCommand.ID, "Separator", ImportSubDCommand.ID, ExportStepCommand.ID)


def register():
    """Add every command to FreeCAD's command manager (idempotent)."""
    known = set(FreeCADGui.listCommands())
    for command in COMMANDS:
        if command.ID not in known:
            FreeCADGui.addCommand(command.ID, command())
