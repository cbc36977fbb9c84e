# SPDX-License-Identifier: LGPL-2.1-or-later
"""Default parameters of new stage objects: the user's preferences, else the paper's values.

The preferences page (``polycube_wb.gui.preferences``) writes the same keys, under
``User parameter:BaseApp/Preferences/Mod/Polycube``; nothing here needs the GUI. The keys are
the page's fields (``polycube_wb.panel_fields.PAGE_FIELDS``), the paper's values those of
``core.params``.
"""
from dataclasses import fields

import FreeCAD

from polycube_wb.panel_fields import EXPORT_DEPTH_KEY, PAGE_FIELDS

PREFERENCES = "User parameter:BaseApp/Preferences/Mod/Polycube"

PREFERENCE_FIELDS = tuple(field.key for field in PAGE_FIELDS if field.key != EXPORT_DEPTH_KEY)
"""``ReconstructionParams`` fields the preferences page offers."""


def paper_defaults():
    """Dict of every ``ReconstructionParams`` field's default (the paper's values) and of the
    grading depth (``export_depth``: ``core.params.EXPORT_DEPTH``)."""
    from core.params import EXPORT_DEPTH, ReconstructionParams

    defaults = ReconstructionParams()
    values = {f.name: getattr(defaults, f.name) for f in fields(defaults)}
    values[EXPORT_DEPTH_KEY] = EXPORT_DEPTH
    return values


def default(name):
    """The default for a new object's parameter ``name`` (a ``ReconstructionParams`` field,
    or ``export_depth``): the user's preference if set, else the paper's value."""
    fallback = paper_defaults()[name]
    group = FreeCAD.ParamGet(PREFERENCES)
    if isinstance(fallback, bool):
        return bool(group.GetBool(name, fallback))
    if isinstance(fallback, int):
        return int(group.GetInt(name, fallback))
    if isinstance(fallback, float):
        return float(group.GetFloat(name, fallback))
    return group.GetString(name, fallback) or fallback


def set_default(name, value):
    """Store the user's default for ``name`` (type as in ``paper_defaults``).

    The paper's value is stored as no preference at all, so the user follows the code's
    default until choosing another value.
    """
    group = FreeCAD.ParamGet(PREFERENCES)
    if value == paper_defaults()[name]:
        _forget(group, name)
    elif isinstance(value, bool):
        group.SetBool(name, value)
    elif isinstance(value, int):
        group.SetInt(name, value)
    elif isinstance(value, float):
        group.SetFloat(name, value)
    else:
        group.SetString(name, str(value))


def reset_defaults():
    """Forget the user's defaults (back to the paper's values)."""
    group = FreeCAD.ParamGet(PREFERENCES)
    for name in PREFERENCE_FIELDS + (EXPORT_DEPTH_KEY,):
        _forget(group, name)


def _forget(group, name):
    for remove in (group.RemBool, group.RemInt, group.RemFloat, group.RemString):
        remove(name)
