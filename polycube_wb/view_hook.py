# SPDX-License-Identifier: LGPL-2.1-or-later
"""The one place the GUI hands the document layer its view providers.

``polycube_wb.api`` makes stage objects from scripts, the GUI's commands and ``freecadcmd``
alike; only when the GUI is up does a new object need a view provider. The GUI registers the
function that attaches one when FreeCAD starts it (``InitGui.py``), so the document layer
never imports the GUI package.
"""
_attach = None


def register_view_provider(attach):
    """Set the function ``attach(obj, kind)`` that gives a new stage object its view provider."""
    global _attach
    _attach = attach


def attach_view_provider(obj, kind):
    """Attach the registered view provider to ``obj`` (a new stage object of ``kind``) when
    the GUI is up and registered one; otherwise do nothing (headless, ``freecadcmd``)."""
    import FreeCAD

    if _attach is not None and FreeCAD.GuiUp and obj.ViewObject is not None:
        _attach(obj, kind)
