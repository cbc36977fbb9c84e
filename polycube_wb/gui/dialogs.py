# SPDX-License-Identifier: LGPL-2.1-or-later
"""The workbench's dialogs: file choosers, message boxes and the last directory used.

Every command opens its dialogs through this module's functions (``dialogs.message_box``),
so the GUI tests replace them here, once, for all commands.
"""
import os

import FreeCAD
import FreeCADGui


def last_directory():
    """The folder of the last file chosen (the preference ``LastDirectory``; home at first)."""
    from polycube_wb.preferences import PREFERENCES

    return FreeCAD.ParamGet(PREFERENCES).GetString("LastDirectory", os.path.expanduser("~"))


def remember_directory(path):
    """Remember the folder of ``path`` for the next dialog."""
    from polycube_wb.preferences import PREFERENCES

    FreeCAD.ParamGet(PREFERENCES).SetString("LastDirectory", os.path.dirname(path))


def ask_open_file(title, file_filter, start=None):
    """File-open dialog; returns the chosen path or None."""
    from PySide import QtGui

    path, _ = QtGui.QFileDialog.getOpenFileName(FreeCADGui.getMainWindow(), title,
                                                start or last_directory(), file_filter)
    if not path:
        return None
    remember_directory(path)
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
    remember_directory(path)
    return path


def message_box(kind, title, text):
    """Modal message box; ``kind`` is ``information``, ``warning`` or ``critical``."""
    from PySide import QtGui

    getattr(QtGui.QMessageBox, kind)(FreeCADGui.getMainWindow(), title, text)
