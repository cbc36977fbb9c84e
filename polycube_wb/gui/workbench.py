# SPDX-License-Identifier: LGPL-2.1-or-later
"""The Polycube workbench: icon, menu and toolbar.

Importing this module is cheap (no numpy, no core); the commands and everything they
need are imported in ``Initialize()``, the first time the user opens the workbench.
"""
import FreeCADGui

from polycube_wb.gui import icon_path

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
        FreeCADGui.addPreferencePage(PreferencesPage, "Polycube")
        self.appendToolbar(MENU_AND_TOOLBAR, list(commands.TOOLBAR))
        self.appendMenu(MENU_AND_TOOLBAR, list(commands.MENU))

    def Activated(self):
        """Nothing to set up when the workbench is switched to."""

    def Deactivated(self):
        """Nothing to tear down when another workbench is switched to."""

    def GetClassName(self):
        return "Gui::PythonWorkbench"
