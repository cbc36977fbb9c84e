# SPDX-License-Identifier: LGPL-2.1-or-later
"""The GUI's parameter fields come from ``core.params``: one source of ranges and defaults.

The task panels and the preferences page are built from ``polycube_wb.panel_fields``; here
every field that sets a pipeline parameter is held to that parameter's declaration (kind,
range or choices, and the range check of ``ReconstructionParams`` accepts the ends and rejects
just beyond them), and every field to the stage object's property it edits (it exists, a new
object's value is the field's default, an enumeration offers exactly the field's choices).
"""
import math

import FreeCAD
import pytest

from core.errors import ParameterError
from core.params import (EXPORT_DEPTH, MAX_EXPORT_DEPTH, ReconstructionParams,
                         check_export_depth, check_face_form, parameter_option)
from polycube_wb.panel_fields import (EXPORT_DEPTH_KEY, FIELDS, OBJECT_ONLY_KEYS, PAGE_FIELDS,
                                      PanelField, in_gui_words, parameter_field)

PARAMETER_FIELDS = [field for fields in FIELDS.values() for field in fields
                    if field.key not in (None, EXPORT_DEPTH_KEY)]


def test_every_pipeline_parameter_a_panel_offers_has_its_declared_range_or_choices():
    assert len(PARAMETER_FIELDS) == 16
    for field in PARAMETER_FIELDS:
        item, option = parameter_option(field.key)
        if option.choices is not None:
            assert field.kind == "choice" and set(field.limits) <= set(option.choices), field
            assert field.words is None or len(field.words) == len(field.limits), field
        elif item.type is bool:
            assert field.kind == "bool" and field.limits is None, field
        else:
            assert field.kind == {int: "int", float: "float"}[item.type], field
            assert field.limits == (option.low, option.high), field


@pytest.mark.parametrize("field", [f for f in PARAMETER_FIELDS if f.kind in ("int", "float")],
                         ids=lambda f: f.key)
def test_a_panel_range_is_exactly_what_the_parameters_accept(field):
    low, high = field.limits
    step = 1 if field.kind == "int" else 1e-9 * max(1.0, abs(high))
    for value in (low, high):
        ReconstructionParams(**{field.key: value})
    for value in (low - step, high + step):
        with pytest.raises(ParameterError, match=field.key):
            ReconstructionParams(**{field.key: value})


def test_the_depth_field_is_the_exporters_range():
    (depth,) = [field for field in FIELDS["Solid"] if field.prop == "Depth"]
    assert depth.key == EXPORT_DEPTH_KEY and depth.limits == (1, MAX_EXPORT_DEPTH)
    for value in depth.limits:
        check_export_depth(value)
    for value in (depth.limits[0] - 1, depth.limits[1] + 1):
        with pytest.raises(ParameterError):
            check_export_depth(value)


def test_the_preferences_page_offers_every_parameter_field_once():
    from polycube_wb.preferences import PREFERENCE_FIELDS, paper_defaults

    keys = [field.key for field in PAGE_FIELDS]
    assert len(keys) == len(set(keys)) == 15
    offered = {f.key for f in PARAMETER_FIELDS} - set(OBJECT_ONLY_KEYS)
    assert set(keys) == offered | {EXPORT_DEPTH_KEY}
    assert set(PREFERENCE_FIELDS) == offered
    defaults = paper_defaults()
    assert defaults[EXPORT_DEPTH_KEY] == EXPORT_DEPTH
    assert all(defaults[key] == getattr(ReconstructionParams(), key) for key in PREFERENCE_FIELDS)


def test_the_solid_panel_offers_only_surface_forms_and_faces_the_exporter_accepts():
    fields = {field.prop: field for field in FIELDS["Solid"]}
    export, faces = fields["Export"], fields["Faces"]
    assert export.words and faces.words and "one per quad" in faces.words
    other, wanted = faces.needs
    assert fields[other] is export
    for form in export.limits:  # a disabled choice field holds its first choice
        offered = faces.limits if form == wanted else faces.limits[:1]
        for choice in offered:
            check_face_form(choice, form)
    with pytest.raises(ParameterError):
        check_face_form("chart", "exact")
    assert "'CAD faces' (Faces)" in in_gui_words("--faces chart needs --export g1")


def test_a_field_refuses_a_parameter_or_choice_that_does_not_exist():
    with pytest.raises(ParameterError, match="unknown parameter 'lambda'"):
        parameter_field("Lambda", "λ", "lambda")
    with pytest.raises(ParameterError, match="fit_mode"):
        parameter_field("Mode", "Mode", "fit_mode", choices=("inside", "outside"))
    with pytest.raises(ParameterError, match="faces"):
        parameter_field("Faces", "Faces", "faces", words={"quad": "one per quad"})
    assert parameter_field("Lambda", "λ", "lam") == PanelField("Lambda", "λ", "float",
                                                               (0.0, 1e3), "lam")


def test_new_stage_objects_have_every_field_with_its_default_and_choices():
    from polycube_wb import api
    from polycube_wb.preferences import default

    doc = FreeCAD.newDocument("PolycubePanelFields")
    try:
        segmentation = api.make_segmentation(doc, None)
        base = api.make_base_mesh(doc, segmentation)
        fit = api.make_fit(doc, base)
        solid = api.make_solid(doc, fit)
        objects = {"Segmentation": segmentation, "BaseMesh": base, "Fit": fit, "Solid": solid}
        for kind, obj in objects.items():
            for field in FIELDS[kind]:
                assert field.prop in obj.PropertiesList, (kind, field.prop)
                value = getattr(obj, field.prop)
                if field.kind == "choice":
                    assert tuple(obj.getEnumerationsOfProperty(field.prop)) == field.limits
                elif field.kind in ("int", "float"):
                    assert field.limits[0] <= value <= field.limits[1], (kind, field.prop)
                if field.key is not None:
                    expected = default(field.key)
                    assert (value == expected or (isinstance(value, float)
                                                  and math.isclose(value, expected))), field
    finally:
        FreeCAD.closeDocument(doc.Name)
