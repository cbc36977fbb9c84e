# SPDX-License-Identifier: LGPL-2.1-or-later
"""Task panels of the stage objects: their parameters, OK / Cancel and Apply.

One panel class serves every stage: its fields are ``polycube_wb.panel_fields.FIELDS``
(property, label, kind, range or choices from ``core.params``). OK and Apply write the fields
to the object and recompute (one undo step, with the progress bar; Esc cancels: the object is
marked cancelled with its last result, Undo restores it); Cancel changes nothing. "Paper
defaults" puts the paper's values in the fields. The cage stages (BaseMesh, Fit) also offer
moving selected cage vertices: the stages after them follow
(a Fit reruns from an edited base mesh; a Solid follows an edited fitted cage directly).

Panels hold no geometry code, so tests build them, set their widgets and call
``accept()``.
"""
import FreeCAD
import FreeCADGui
from PySide import QtGui

from polycube_wb.gui import icon_path
from polycube_wb.panel_fields import FIELDS

CAGE_KINDS = ("BaseMesh", "Fit")
ACTIVE = {}
"""Object name -> its open task panel (for scripts and tests)."""


def panel_for(obj):
    """The task panel of a stage object."""
    return StagePanel(obj)


class StagePanel:
    """Task panel of one stage object (``form``, ``accept``, ``reject``, ``clicked``)."""

    def __init__(self, obj):
        from polycube_wb.objects.base import stage_kind

        self.obj = obj
        self.kind = stage_kind(obj)
        ACTIVE[obj.Name] = self
        self.widgets = {}
        self.outcome = None
        self.form = QtGui.QWidget()
        self.form.setWindowTitle(_panel_title(f"{self.kind}: {obj.Label}"))
        self.form.setWindowIcon(QtGui.QIcon(icon_path("PolycubeWorkbench")))
        layout = QtGui.QVBoxLayout(self.form)
        # the task box has margins of its own: the form's would push the panel past the
        # Combo View's default width
        layout.setContentsMargins(0, 0, 0, 0)
        box = QtGui.QGroupBox("Parameters")
        form = QtGui.QFormLayout(box)
        # the Combo View is narrow: each label goes above its field, which keeps its width
        # (side by side, the number fields were squeezed out of sight by the long labels)
        form.setRowWrapPolicy(QtGui.QFormLayout.WrapAllRows)
        for field in FIELDS.get(self.kind, ()):
            widget = make_widget(field.kind, field.limits, field.words)
            set_widget_value(widget, field.kind, getattr(obj, field.prop))
            widget.setToolTip(obj.getDocumentationOfProperty(field.prop))
            widget.setMinimumWidth(FIELD_WIDTH)  # not as wide as its largest number
            form.addRow(_wrapping_label(field.label), widget)
            self.widgets[field.prop] = (widget, field.kind)
        for field in FIELDS.get(self.kind, ()):
            if field.needs is not None:
                self._follow(field)
        defaults = QtGui.QPushButton("Paper defaults")
        defaults.clicked.connect(self.paper_defaults)
        # Apply sits here, not beside OK and Cancel: three buttons there are wider than
        # FreeCAD's default Combo View
        apply = QtGui.QPushButton("Apply")
        apply.setToolTip("Write the fields to the object and recompute; the panel stays open")
        apply.clicked.connect(lambda: self.apply())
        buttons = QtGui.QHBoxLayout()
        buttons.addWidget(defaults)
        buttons.addWidget(apply)
        form.addRow(buttons)
        layout.addWidget(box)
        self.hidden_for_edit = {}
        if self.kind in CAGE_KINDS:
            layout.addWidget(self._cage_box())
            self.hidden_for_edit = _show_cage_alone(obj)
        self.status = QtGui.QLabel()
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        layout.addStretch(1)
        self.show_status()

    def _follow(self, field):
        """Enable ``field`` only while the field it needs holds the value it needs; a choice
        field disabled goes back to its first choice (the only one the stage then accepts)."""
        widget, kind = self.widgets[field.prop]
        other, wanted = field.needs
        source, source_kind = self.widgets[other]

        def update(*_):
            enabled = widget_value(source, source_kind) == wanted
            widget.setEnabled(enabled)
            if not enabled and kind == "choice":
                widget.setCurrentIndex(0)

        source.currentIndexChanged.connect(update)
        update()

    # -- task dialog protocol ---------------------------------------------------------------

    def getStandardButtons(self):
        buttons = QtGui.QDialogButtonBox
        return int(buttons.Ok | buttons.Cancel)

    def accept(self):
        """Write the fields and recompute; the panel stays open when the user cancelled
        (the object is marked cancelled) or the change could not be made (the document is
        then as before)."""
        self.apply()
        if self.outcome is None:
            return False
        self._close()
        return True

    def reject(self):
        self._close()
        return True

    def _close(self):
        _restore_visibility(self.hidden_for_edit)
        self.hidden_for_edit = {}
        _close(self.obj)

    # -- actions ----------------------------------------------------------------------------

    def values(self):
        """Dict property -> value of the fields."""
        return {prop: widget_value(widget, kind) for prop, (widget, kind) in self.widgets.items()}

    def paper_defaults(self):
        from polycube_wb.preferences import paper_defaults

        defaults = paper_defaults()
        for field in FIELDS.get(self.kind, ()):
            if field.key is not None:
                set_widget_value(self.widgets[field.prop][0], field.kind, defaults[field.key])

    def apply(self, vertex_moves=None):
        """Write the fields (and ``vertex_moves``: index -> new position) and recompute."""
        from polycube_wb import api
        from polycube_wb.gui.commands import run_stage_command

        obj, values = self.obj, self.values()
        changed = {prop: value for prop, value in values.items()
                   if getattr(obj, prop) != value}
        if not changed and not vertex_moves and obj.isValid() and obj.Status == "ok":
            self.outcome = api.RecomputeOutcome({}, False)  # nothing to do
            return

        def build():
            for line in _replay_lines(obj, changed):
                FreeCADGui.doCommand(line)
            if vertex_moves:
                moves = {index: tuple(point) for index, point in vertex_moves.items()}
                FreeCADGui.doCommand("from polycube_wb import api")
                FreeCADGui.doCommand(f"api.move_cage_vertices({_reference(obj)}, {moves!r})")
            obj.touch()
            return obj

        self.outcome = run_stage_command(f"Edit {obj.Label}", obj.Document, build)
        self.show_status()

    def show_status(self):
        from polycube_wb import api

        self.status.setText(api.describe(self.obj))

    # -- cage editing -----------------------------------------------------------------------

    def _cage_box(self):
        box = QtGui.QGroupBox("Move cage vertices")
        form = QtGui.QFormLayout(box)
        self.vertex_field = QtGui.QLineEdit()
        self.vertex_field.setToolTip("Cage vertex indices (from 0), separated by commas; "
                                     "'Use selection' takes the vertices selected in the view")
        form.addRow("Vertices", self.vertex_field)
        use = QtGui.QPushButton("Use selection")
        use.clicked.connect(self.use_selection)
        form.addRow(use)
        self.move_fields = []
        for axis in "XYZ":
            field = QtGui.QDoubleSpinBox()
            field.setRange(-1e6, 1e6)
            field.setDecimals(4)
            field.setSuffix(" mm")
            field.setMinimumWidth(FIELD_WIDTH)
            form.addRow(_wrapping_label(f"Move by {axis}"), field)
            self.move_fields.append(field)
        move = QtGui.QPushButton("Move")
        move.clicked.connect(self.move_vertices)
        form.addRow(move)
        return box

    def selected_vertices(self):
        """Cage vertex indices in the field; raises ValueError naming a bad entry."""
        count = len(self.obj.CageVertices)
        indices = []
        for entry in self.vertex_field.text().replace(" ", "").split(","):
            if not entry:
                continue
            if not entry.isdigit() or int(entry) >= count:
                raise ValueError(f"'{entry}' is not a cage vertex index (0..{count - 1})")
            indices.append(int(entry))
        return sorted(set(indices))

    def use_selection(self):
        from polycube_wb.objects.cage import vertex_indices

        count = len(self.obj.CageVertices)
        names = []
        for selection in FreeCADGui.Selection.getSelectionEx():
            if selection.Object is self.obj:
                names += selection.SubElementNames
        picked = [index for index in vertex_indices(names) if index < count]
        self.vertex_field.setText(", ".join(str(index) for index in picked))

    def move_vertices(self):
        """Move the listed cage vertices by the offset and recompute what follows."""
        try:
            indices = self.selected_vertices()
        except ValueError as exc:
            self.status.setText(str(exc))
            return
        offset = FreeCAD.Vector(*(field.value() for field in self.move_fields))
        points = self.obj.CageVertices
        self.apply({index: points[index] + offset for index in indices})


def _reference(obj):
    return f"App.getDocument({obj.Document.Name!r}).getObject({obj.Name!r})"


def _replay_lines(obj, changed):
    """Console lines that set ``changed`` (property -> value) on ``obj``."""
    return [f"{_reference(obj)}.{prop} = {value!r}" for prop, value in changed.items()]


def _show_cage_alone(obj):
    """Show the cage ``obj`` (its vertices are picked in the view) and hide the document's
    other stage displays but the Solid: the other cage and the meshes, which would hide it or
    be confused with it (the solid stays, to show the edit's effect under the cage's lines);
    returns ``{object: visibility}`` of the objects changed, for :func:`_restore_visibility`."""
    from polycube_wb.objects.base import stage_kind

    changed = {}
    for other in obj.Document.Objects:
        vobj, kind = other.ViewObject, stage_kind(other)
        if vobj is None or kind is None or kind == "Solid":
            continue
        wanted = other is obj
        if bool(vobj.Visibility) != wanted:
            changed[other] = bool(vobj.Visibility)
            vobj.Visibility = wanted
    return changed


def _restore_visibility(changed):
    """Set back the visibilities :func:`_show_cage_alone` changed (of objects still there)."""
    for obj, visible in changed.items():
        try:
            if obj.ViewObject is not None:
                obj.ViewObject.Visibility = visible
        except ReferenceError:  # deleted meanwhile
            continue


def _close(obj):
    ACTIVE.pop(obj.Name, None)
    FreeCADGui.Control.closeDialog()
    gui_document = FreeCADGui.getDocument(obj.Document.Name)
    if gui_document is not None and gui_document.getInEdit() is not None:
        gui_document.resetEdit()


FIELD_WIDTH = 100
"""Least width of a number field, pixels: a spin box asks for the width of its largest
number (``1e9`` with six decimals), which made the panel wider than the Combo View."""


COMBO_CHARACTERS = 8
"""Characters a choice field is sized for: it widens to what the panel gives, but never
widens the panel."""


TITLE_WIDTH = 170
"""Widest panel title, pixels: FreeCAD's task box does not shorten its title, whose width
then widens the panel past the Combo View."""


def _panel_title(text):
    """``text`` shortened with an ellipsis to :data:`TITLE_WIDTH` in the task box's bold font."""
    from PySide import QtCore

    font = QtGui.QApplication.font()
    font.setBold(True)
    return QtGui.QFontMetrics(font).elidedText(text, QtCore.Qt.ElideRight, TITLE_WIDTH)


def _wrapping_label(text):
    """A form label that wraps rather than widen the panel past the Combo View."""
    label = QtGui.QLabel(text)
    label.setWordWrap(True)
    return label


def make_widget(kind, limits, words=None):
    """The widget of a field of ``kind`` with ``limits`` (range or choices) and ``words``
    (the texts of the choices, else the choices themselves); see ``PanelField``."""
    if kind == "int":
        widget = QtGui.QSpinBox()
        widget.setRange(*limits)
    elif kind == "float":
        widget = QtGui.QDoubleSpinBox()
        widget.setRange(*limits)
        widget.setDecimals(6)
    elif kind == "choice":
        widget = QtGui.QComboBox()
        for value, text in zip(limits, words or limits):
            widget.addItem(text, value)
        # as wide as the panel gives, not as its longest text (the list shows it whole)
        widget.setSizeAdjustPolicy(QtGui.QComboBox.AdjustToMinimumContentsLengthWithIcon)
        widget.setMinimumContentsLength(COMBO_CHARACTERS)
    else:
        widget = QtGui.QCheckBox()
    return widget


def set_widget_value(widget, kind, value):
    if kind in ("int", "float"):
        widget.setValue(value)
    elif kind == "choice":
        widget.setCurrentIndex(max(widget.findData(str(value)), 0))
    else:
        widget.setChecked(bool(value))


def widget_value(widget, kind):
    if kind == "int":
        return int(widget.value())
    if kind == "float":
        return float(widget.value())
    if kind == "choice":
        return widget.itemData(widget.currentIndex())
    return bool(widget.isChecked())
