# SPDX-License-Identifier: LGPL-2.1-or-later
"""Triangulate a result shape for the 3D view a few faces at a time, the event loop running.

FreeCAD's Part view provider triangulates a shape (OpenCascade's ``BRepMesh``, in the GUI
thread, in one call) when the shape is set on a shown object, unless its faces already carry
a triangulation it made itself with the deflection it asks for; on a solid of several hundred
B-spline faces that call holds the event loop for most of a second. Only the view provider's
own triangulation passes its check (one made by ``Shape.tessellate`` or
``MeshPart.meshFromShape`` does not), so :func:`triangulate_for_display` lets a view provider
of the same kind do it: that of a helper ``Part::Feature`` in a hidden document of its own, a
chunk of faces at a time with the event loop answering between chunks. Each chunk is a
compound of its faces and two vertices at the corners of the whole shape's bounding box: the
view provider's deflection is a fraction of the box it is given, so every chunk gets the
deflection the whole shape will get. The triangulations stay on the faces, which the shape
shares, and the view provider of the object the shape is then set on keeps them. The helper
document keeps no undo, so the command's undo step stays the user's document's alone.
"""
import time

import FreeCAD

CHUNK_SECONDS = 0.04
"""Wall-clock time one chunk of faces should take to triangulate; the next chunk's size is
scaled from the last one's time (a loaded machine gets smaller chunks)."""
FIRST_CHUNK = 8
"""Faces in the first chunk."""
MIN_FACES = 24
"""Shapes with fewer faces are left to the object's own view provider (a short call)."""
HELPER_DOCUMENT = "PolycubeDisplayTessellation"


def triangulate_for_display(shape, progress):
    """Give the faces of ``shape`` the triangulation FreeCAD's Part view provider will show
    them with, a chunk at a time with the event loop answering between chunks. The shape
    itself is not changed otherwise.

    The triangulation is that of a new Part object's view provider (the deviation and angular
    deflection of FreeCAD's preferences); a view provider set otherwise may triangulate the
    shape again, in one call, as without this function.

    Parameters
    ----------
    shape : Part.Shape, not yet on a document object.
    progress : core.progress.Progress; its ``check_cancel`` is called between chunks.

    Raises
    ------
    core.errors.Cancelled
        The user cancelled (the faces triangulated so far keep their triangulation).
    """
    import Part
    from PySide import QtCore

    faces = shape.Faces
    if len(faces) < MIN_FACES:
        return
    box = shape.BoundBox
    corners = [Part.Vertex(box.XMin, box.YMin, box.ZMin), Part.Vertex(box.XMax, box.YMax, box.ZMax)]
    active = FreeCAD.ActiveDocument
    helper_document = FreeCAD.newDocument(HELPER_DOCUMENT, hidden=True)
    try:
        # no undo: its changes must not join the command's transaction (FreeCAD's transactions
        # span every document changed while one is open, and Undo would reach this one)
        helper_document.UndoMode = 0
        _restore_active(active)
        helper = helper_document.addObject("Part::Feature", "Tessellation")
        start, size = 0, FIRST_CHUNK
        while start < len(faces):
            progress.check_cancel()
            began = time.monotonic()
            helper.Shape = Part.Compound(faces[start:start + size] + corners)
            spent = max(time.monotonic() - began, 1e-3)
            start += size
            size = max(1, min(4 * size, int(size * CHUNK_SECONDS / spent)))
            QtCore.QCoreApplication.processEvents(QtCore.QEventLoop.AllEvents)
    finally:
        FreeCAD.closeDocument(helper_document.Name)
        _restore_active(active)


def _restore_active(document):
    """Make ``document`` FreeCAD's active document again (if it is still open)."""
    try:
        if document is not None and document.Name in FreeCAD.listDocuments():
            FreeCAD.setActiveDocument(document.Name)
    except ReferenceError:  # closed meanwhile
        pass
