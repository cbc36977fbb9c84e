# SPDX-License-Identifier: LGPL-2.1-or-later
# FreeCAD runs this file (exec, so __file__ is undefined) when the GUI starts. The
# workbench class imports its commands (and numpy, core...) only in Initialize(), the
# first time the user opens the workbench.
import FreeCAD
import FreeCADGui

from polycube_wb.gui.view_providers import attach_view_provider
from polycube_wb.gui.workbench import PolycubeWorkbench
from polycube_wb.view_hook import register_view_provider

FreeCADGui.addWorkbench(PolycubeWorkbench())
register_view_provider(attach_view_provider)  # new stage objects made by polycube_wb.api
FreeCAD.__unit_test__ += ["TestPolycubeGui"]
