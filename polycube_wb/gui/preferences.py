# SPDX-License-Identifier: LGPL-2.1-or-later
"""Preferences page (Edit > Preferences > Polycube): defaults of new stage objects.

Values are stored by ``polycube_wb.preferences`` (the same keys the factories read); a
field left at the paper's value stores nothing, so a later change of the paper default
in the code reaches the user.
"""
from PySide import QtGui

from polycube_wb.gui.task_panels import make_widget, set_widget_value, widget_value
from polycube_wb.panel_fields import PAGE_FIELDS


class PreferencesPage:
    """A FreeCAD preference page (``form``, ``loadSettings``, ``saveSettings``)."""

    def __init__(self, parent=None):
        self.form = QtGui.QWidget(parent)
        self.form.setWindowTitle("Polycube")
        layout = QtGui.QFormLayout(self.form)
        self.widgets = {}
        for field in PAGE_FIELDS:
            widget = make_widget(field.kind, field.limits)
            layout.addRow(field.label, widget)
            self.widgets[field.key] = (widget, field.kind)
        reset = QtGui.QPushButton("Paper defaults")
        reset.clicked.connect(self.paper_defaults)
        layout.addRow(reset)

    def loadSettings(self):
        from polycube_wb.preferences import default

        for key, (widget, kind) in self.widgets.items():
            set_widget_value(widget, kind, default(key))

    def saveSettings(self):
        from polycube_wb.preferences import set_default

        for key, (widget, kind) in self.widgets.items():
            set_default(key, widget_value(widget, kind))

    def paper_defaults(self):
        from polycube_wb.preferences import paper_defaults

        defaults = paper_defaults()
        for key, (widget, kind) in self.widgets.items():
            set_widget_value(widget, kind, defaults[key])
