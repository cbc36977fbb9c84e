# SPDX-License-Identifier: LGPL-2.1-or-later
"""View providers of the stage objects: icons, tree nesting, colours, double-click edit.

A double-click opens the object's task panel (``polycube_wb.gui.task_panels``). The
Segmentation and Deviation meshes are shown with per-face / per-vertex colours (the mesh
view provider's ``Coloring`` uses the object's colour list of matching length). While shown,
the Deviation draws its colour legend in the 3D view, and a Segmentation coloured by label the
six label colours (``polycube_wb.gui.legend``).
"""
import FreeCADGui

from polycube_wb.gui import icon_path

ICONS = {"Target": "PolyCube_ImportTarget", "Segmentation": "PolyCube_LabelPolycube",
         "BaseMesh": "PolyCube_BuildBaseMesh", "Fit": "PolyCube_FitTarget",
         "Solid": "PolyCube_MakeSolid", "Deviation": "PolyCube_CheckResult"}
NESTED = ("Segmentation", "BaseMesh", "Fit", "Solid")
"""Kinds that show their input under them in the tree (a chain, as PartDesign does)."""


class StageViewProvider:
    """View provider of one stage object (persisted as nothing: it keeps no state)."""

    def __init__(self, vobj, kind):
        vobj.Proxy = self
        self.kind = kind
        self.Object = vobj.Object

    def attach(self, vobj):
        self.Object = vobj.Object
        self.kind = _kind(vobj.Object)
        if self.kind in ("Deviation", "Segmentation"):
            # A reopened map: colour it and draw its legend once the document and its view
            # are loaded (the mesh view restores Coloring before the colour list is read).
            from PySide import QtCore

            QtCore.QTimer.singleShot(0, lambda: _legend_after_restore(vobj.Object))

    def getIcon(self):
        return icon_path(ICONS.get(self.kind or "", "PolycubeWorkbench"))

    def claimChildren(self):
        obj = getattr(self, "Object", None)
        if obj is None or _kind(obj) not in NESTED:
            return []
        return [getattr(obj, link) for link in obj.Proxy.INPUTS if getattr(obj, link)]

    def doubleClicked(self, vobj):
        FreeCADGui.ActiveDocument.setEdit(vobj.Object.Name, 0)
        return True

    def setEdit(self, vobj, mode=0):
        if mode != 0:
            return False
        from polycube_wb.gui.task_panels import panel_for

        FreeCADGui.Control.showDialog(panel_for(vobj.Object))
        return True

    def unsetEdit(self, vobj, mode=0):
        FreeCADGui.Control.closeDialog()
        return True

    def updateData(self, obj, prop):
        if prop in ("FaceColors", "VertexColors") and hasattr(obj.ViewObject, "Coloring"):
            obj.ViewObject.Coloring = False
            obj.ViewObject.Coloring = True
        if (prop in ("ScaleUsed", "MaxDeviationAt") and _kind(obj) == "Deviation") or \
                (prop == "FaceColors" and _kind(obj) == "Segmentation"):
            _update_legend(obj)

    def onChanged(self, vobj, prop):
        if prop == "Visibility" and _kind(vobj.Object) in ("Deviation", "Segmentation"):
            _update_legend(vobj.Object)

    def onDelete(self, vobj, subelements):
        if _kind(vobj.Object) in ("Deviation", "Segmentation"):
            from polycube_wb.gui.legend import remove_legend

            remove_legend(vobj.Object)
        return True

    def __getstate__(self):
        return None

    def __setstate__(self, state):
        self.kind = None


def _legend_after_restore(obj):
    from polycube_wb.gui.legend import has_legend

    try:
        vobj = obj.ViewObject
        if vobj is not None and getattr(vobj, "Coloring", False):
            vobj.Coloring = False
            vobj.Coloring = True
        if not has_legend(obj):
            _update_legend(obj)
    except ReferenceError:  # the document was closed before the event loop ran
        return


def _update_legend(obj):
    """Draw the legend of a shown Deviation map, or of a shown Segmentation coloured by
    label; remove it otherwise."""
    from polycube_wb.gui import legend

    vobj = obj.ViewObject
    if vobj is None or not vobj.Visibility:
        legend.remove_legend(obj)
    elif _kind(obj) == "Deviation":
        legend.update_legend(obj)
    elif getattr(obj, "ColourBy", "") == "Labels" and len(obj.FaceColors) > 0:
        legend.update_label_legend(obj)
    else:
        legend.remove_legend(obj)


def _kind(obj):
    from polycube_wb.objects.base import stage_kind

    return stage_kind(obj)


def attach_view_provider(obj, kind):
    """Give a new stage object its view provider and display defaults."""
    vobj = obj.ViewObject
    StageViewProvider(vobj, kind)
    if kind in ("BaseMesh", "Fit"):
        vobj.LineColor = (0.1, 0.1, 0.1) if kind == "BaseMesh" else (0.0, 0.35, 0.7)
        vobj.PointColor = vobj.LineColor
        vobj.LineWidth = 2.0
        vobj.PointSize = 5.0
    if kind == "Solid":
        vobj.ShapeColor = (0.72, 0.74, 0.78)
    if kind in ("Segmentation", "Deviation") and hasattr(vobj, "Coloring"):
        vobj.Coloring = True
        vobj.Lighting = "Two side"
