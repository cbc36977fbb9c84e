# SPDX-License-Identifier: LGPL-2.1-or-later
"""The workbench's GUI layer: workbench class, commands and the progress adapter.

Only ``InitGui.py`` and the workbench's ``Initialize()`` import this package's
modules; nothing outside ``polycube_wb.gui`` imports it, so the rest of
``polycube_wb`` works in ``freecadcmd`` and plain Python.
"""
import os

from polycube_wb import ADDON_DIR

ICON_DIR = os.path.join(ADDON_DIR, "polycube_wb", "resources", "icons")


def icon_path(name):
    """Absolute path of the SVG icon ``name`` (without the ``.svg`` suffix)."""
    return os.path.join(ICON_DIR, name + ".svg")
