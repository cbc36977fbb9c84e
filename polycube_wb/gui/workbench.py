# SPDX-License-Identifier: LGPL-2.1-or-later
"""The Polycube workbench: icon, menu and toolbar.

Importing this module is cheap (no numpy, no core); the commands and everything they
need are imported in ``Initialize()``, the first time the user opens the workbench.
"""
import FreeCADGui

from polycube_wb.gui import ICON_DIR, icon_path

MENU_AND_TOOLBAR = "Polycube"


class PolycubeWorkbench(FreeCADGui.Workbench):
    """Mesh from topology optimisation -> polycube -> Catmull-Clark -> B-spline solid -> STEP."""

    MenuText = "Polycube"
    ToolTip = ("Turn a watertight triangle mesh (e.g. a topology-optimisation result) into a "
               "CAD solid through polycube labeling and Catmull-Clark subdivision")
    Icon = icon_path("PolycubeWorkbench")

    def Initialize(self):
        """Register the commands and the preferences page, build the menu and toolbar."""
        from polycube_wb.gui import commands
        from polycube_wb.gui.preferences import PreferencesPage

        commands.register()
        # the preferences dialog shows the icon "preferences-<group>" of the icon paths
        FreeCADGui.addIconPath(ICON_DIR)
        FreeCADGui.addPreferencePage(PreferencesPage, "Polycube")
        self.appendToolbar(MENU_AND_TOOLBAR, list(commands.TOOLBAR))
        self.appendMenu(MENU_AND_TOOLBAR, list(commands.MENU))
        _warm_up()

    def Activated(self):
        """Nothing to set up when the workbench is switched to."""

    def Deactivated(self):
        """Nothing to tear down when another workbench is switched to."""

    def GetClassName(self):
        return "Gui::PythonWorkbench"


def _warm_up():
    """Load now what the first command would load while the user waits: the stage objects'
    modules (FreeCAD's Mesh and MeshPart among them), the target's validation (scipy,
    numba), the mesh view providers (MeshGui, loaded with the first mesh shown) and the
    stage process (``polycube_wb.gui.worker``), which starts in the background."""
    import importlib

    from polycube_wb.gui.worker import stage_process

    for module in ("polycube_wb.api", "polycube_wb.convert", "polycube_wb.objects.target",
                   "polycube_wb.objects.segmentation", "polycube_wb.objects.fit",
                   "polycube_wb.objects.solid", "polycube_wb.objects.deviation",
                   "core.validate", "MeshGui"):
        importlib.import_module(module)
    try:
        stage_process()
    except RuntimeError as exc:  # no interpreter for it: the first stage command says so
        import FreeCAD

        FreeCAD.Console.PrintWarning(f"Polycube: {exc}\n")
