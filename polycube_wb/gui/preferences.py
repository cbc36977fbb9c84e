# SPDX-License-Identifier: LGPL-2.1-or-later
"""Preferences page (Edit > Preferences > Polycube): defaults of new stage objects.

Values are stored by ``polycube_wb.preferences`` (the same keys the factories read); a
field left at the paper's value stores nothing, so a later change of the paper default
in the code reaches the user.
"""
from PySide import QtGui

from polycube_wb.gui.task_panels import FIELDS, make_widget, set_widget_value, widget_value

PAGE_FIELDS = tuple(
    (prop, label, kind, limits, field)
    for kind_fields in (FIELDS["Segmentation"], FIELDS["BaseMesh"], FIELDS["Fit"])
    for prop, label, kind, limits, field in kind_fields if field is not None
) + (("Depth", "Grading depth at extraordinary vertices", "int", (1, 12), "export_depth"),)
"""(property, label, kind, limits, preference key) of the page's fields."""


class PreferencesPage:
    """A FreeCAD preference page (``form``, ``loadSettings``, ``saveSettings``)."""

    def __init__(self, parent=None):
        self.form = QtGui.QWidget(parent)
        self.form.setWindowTitle("Polycube")
        layout = QtGui.QFormLayout(self.form)
        self.widgets = {}
        for _, label, kind, limits, key in PAGE_FIELDS:
            widget = make_widget(kind, limits)
            layout.addRow(label, widget)
            self.widgets[key] = (widget, kind)
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
        from core.params import EXPORT_DEPTH
        from polycube_wb.preferences import paper_defaults

        defaults = dict(paper_defaults(), export_depth=EXPORT_DEPTH)
        for key, (widget, kind) in self.widgets.items():
            set_widget_value(widget, kind, defaults[key])
