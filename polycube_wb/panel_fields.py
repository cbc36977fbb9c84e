# SPDX-License-Identifier: LGPL-2.1-or-later
"""The parameter fields of the task panels and of the preferences page (no GUI needed).

A field that sets a pipeline parameter takes its kind, range or choices from that parameter's
declaration in ``core.params`` (:func:`parameter_field`), and its default from the same place
(``polycube_wb.preferences``), so the GUI, the command line and the range checks agree; the
grading depth of the solid takes its range and default from ``core.params`` too. The Qt widgets
are made from these fields by ``polycube_wb.gui.task_panels``.
"""
from dataclasses import dataclass

from core.params import BASE_MESH_METHODS, MAX_EXPORT_DEPTH, parameter_option

EXPORT_DEPTH_KEY = "export_depth"
"""Preference key of the solid's grading depth (default ``core.params.EXPORT_DEPTH``), which is
not a ``ReconstructionParams`` field."""
KIND_OF_TYPE = {bool: "bool", int: "int", float: "float"}
"""Field kind of a ``ReconstructionParams`` number or flag, by the field's type."""


@dataclass(frozen=True)
class PanelField:
    """One field of a task panel or of the preferences page.

    prop : the stage object's property it edits.
    label : its label in the form.
    kind : ``"int"``, ``"float"``, ``"choice"`` or ``"bool"``.
    limits : (minimum, maximum) of a number, the tuple of choices of a ``"choice"``, None for a
        ``"bool"``.
    key : the ``ReconstructionParams`` field (or :data:`EXPORT_DEPTH_KEY`) whose default and
        preference the field shows, or None (a property of the object only).
    words : the texts the form shows for the ``"choice"`` values ``limits``, in their order, or
        None (the values themselves).
    needs : (prop, value): the field is enabled only while the field of ``prop`` holds
        ``value`` (a disabled ``"choice"`` field holds its first choice); or None (always).
    """

    prop: str
    label: str
    kind: str
    limits: tuple = None
    key: str = None
    words: tuple = None
    needs: tuple = None


def parameter_field(prop, label, name, choices=None, words=None, needs=None):
    """The field of the ``ReconstructionParams`` parameter ``name``: kind, range or choices
    from ``core.params``.

    Parameters
    ----------
    prop, label, words, needs : see :class:`PanelField`; ``words`` maps each offered choice
        to its text (dict), for a parameter with choices.
    name : str, the parameter (a ``ReconstructionParams`` field).
    choices : tuple of str, optional: the subset of the parameter's choices the panel offers
        (the segmentation object has no ``file`` part mode: its parts come from its target).

    Returns
    -------
    PanelField with ``key == name``.

    Raises
    ------
    core.errors.ParameterError
        ``name`` is not a parameter, ``choices`` are not among the parameter's, or ``words``
        does not name every offered choice.
    """
    from core.errors import ParameterError

    item, option = parameter_option(name)
    if option.choices is not None:
        offered = option.choices if choices is None else tuple(choices)
        if not set(offered) <= set(option.choices):
            raise ParameterError(f"{name}: the panel offers {offered}, the parameter allows only "
                                 f"{option.choices}")
        if words is not None and set(words) != set(offered):
            raise ParameterError(f"{name}: the panel's words are for {tuple(words)}, it offers "
                                 f"{offered}")
        texts = None if words is None else tuple(words[choice] for choice in offered)
        return PanelField(prop, label, "choice", offered, name, texts, needs)
    kind = KIND_OF_TYPE[item.type]
    return PanelField(prop, label, kind, None if kind == "bool" else parameter_range(name), name)


def parameter_range(name):
    """(minimum, maximum) of the ``ReconstructionParams`` number ``name`` (``core.params``)."""
    option = parameter_option(name)[1]
    return (option.low, option.high)


FIELDS = {
    "Target": (PanelField("CheckSelfIntersections", "Check self-intersections", "bool"),),
    "Segmentation": (
        parameter_field("PartMode", "Parts", "parts", choices=("single", "auto")),
        parameter_field("BlendFactor", "Frame blending (mean edge lengths)", "blend_factor"),
        parameter_field("Lambda", "Compactness weight", "lam"),
        parameter_field("Penalty", "Opposite-label penalty", "penalty"),
        parameter_field("MaxSweeps", "Most labeling sweeps", "max_sweeps"),
        parameter_field("Repair", "Repair the labeling", "repair"),
        PanelField("ColourBy", "Colour by", "choice", ("Labels", "Parts"))),
    "BaseMesh": (
        parameter_field("TargetFaces", "Target faces", "target_faces"),
        parameter_field("MaxBaseFaces", "Most faces", "max_base_faces"),
        parameter_field("Method", "Route", "base_mesh_method", choices=BASE_MESH_METHODS)),
    "Fit": (
        parameter_field("Iterations", "Iterations", "fit_iterations"),
        parameter_field("Convergence", "Convergence (0: off)", "fit_convergence"),
        parameter_field("SubdivisionLevels", "Subdivision levels", "subdivision_levels"),
        parameter_field("Mode", "Mode", "fit_mode"),
        PanelField("AutoMinThickness", "Automatic minimal thickness", "bool"),
        PanelField("MinThickness", "Minimal thickness, mm (0: none)", "float",
                   parameter_range("fit_t_min")),
        PanelField("Tolerance", "Tolerance, mm (0: no refinement)", "float",
                   parameter_range("tolerance_mm")),
        parameter_field("OutsideRefinement", "Most volume outside, fraction (0: off)",
                        "outside_refinement")),
    "Solid": (
        parameter_field("Export", "Surface form", "export",
                        words={"exact": "exact limit surface", "g1": "light G1 patches"}),
        # the G1 patches have no grading
        PanelField("Depth", "Patch refinement at irregular vertices", "int",
                   (1, MAX_EXPORT_DEPTH), EXPORT_DEPTH_KEY, needs=("Export", "exact")),
        # one face per block is made of the G1 patches only (core.params.check_face_form)
        parameter_field("Faces", "CAD faces", "faces",
                        words={"quad": "one per quad", "chart": "one per rectangular block"},
                        needs=("Export", "g1"))),
    "Deviation": (
        PanelField("Tolerance", "Tessellation tolerance, fraction of the size", "float",
                   (1e-6, 0.1)),
        PanelField("Scale", "Colour scale, mm (0: largest deviation)", "float", (0.0, 1e9))),
}
"""Stage kind -> its task panel's fields, in form order."""
PREFERENCE_KINDS = ("Segmentation", "BaseMesh", "Fit", "Solid")
"""Stage kinds whose parameter fields the preferences page offers."""
OBJECT_ONLY_KEYS = ("export", "faces")
"""Parameters a panel offers that the preferences page does not: a new Solid takes the paper's
surface form and faces, a choice made per solid."""
PAGE_FIELDS = tuple(field for kind in PREFERENCE_KINDS for field in FIELDS[kind]
                    if field.key is not None and field.key not in OBJECT_ONLY_KEYS)
"""The preferences page's fields: every panel field with a default (``key``) but those of
:data:`OBJECT_ONLY_KEYS`."""


_OBJECT_OF_KIND = {"Segmentation": "the Segmentation's", "BaseMesh": "the BaseMesh's",
                   "Fit": "the Fit's", "Solid": "the Solid's"}
_GUI_PHRASES = (
    ("other parts (--parts auto, or your own with --parts file)",
     "other parts (a Segmentation with 'Parts' set to 'auto')"),
    ("scale the mesh or give its --units", "scale the mesh"),
    ("--parts file", "parts of your own (command line only)"),
)


def in_gui_words(text):
    """``text`` (a stage's message) with its command-line options named as the GUI names them.

    ``--target-faces`` becomes "the BaseMesh's 'Target faces' (TargetFaces)": the panel field
    and the property to change. Options the GUI does not have are reworded
    (:data:`_GUI_PHRASES`).
    """
    import re

    for phrase, words in _GUI_PHRASES:
        text = text.replace(phrase, words)

    def field_words(match):
        key = match.group(1).replace("-", "_")
        for kind in PREFERENCE_KINDS:
            for field in FIELDS[kind]:
                if field.key == key:
                    return f"{_OBJECT_OF_KIND[kind]} '{field.label}' ({field.prop})"
        return match.group(0)

    return re.sub(r"--([a-z][a-z0-9-]*)", field_words, text)
