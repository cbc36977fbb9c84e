# SPDX-License-Identifier: LGPL-2.1-or-later
# FreeCAD runs this file (exec, so __file__ is undefined) when the GUI starts. The
# workbench class imports its commands (and numpy, core...) only in Initialize(), the
# first time the user opens the workbench.
import FreeCAD
import FreeCADGui

from polycube_wb.gui.workbench import PolycubeWorkbench

FreeCADGui.addWorkbench(PolycubeWorkbench())
FreeCAD.__unit_test__ += ["TestPolycubeGui"]
