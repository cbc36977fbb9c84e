# SPDX-License-Identifier: LGPL-2.1-or-later
# FreeCAD runs this file (exec, so __file__ is undefined) at start-up in the GUI and in
# freecadcmd, before any addon's InitGui.py. Importing polycube_wb installs the finder
# that keeps `from core.x import y` on our own core package even after another addon
# (CfdOF) replaces sys.modules['core']. It imports nothing heavy.
import polycube_wb  # noqa: F401
