# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polycube workbench: the FreeCAD layer over the pure-Python ``core`` package.

Importing this package never needs FreeCAD (the CLI imports it from plain Python);
modules that talk to FreeCAD (``brep``, ``step_io``, ``convert``, ``api``, ``gui``)
import it themselves.
"""
import os
import re

from polycube_wb._core_guard import install_core_guard

ADDON_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _read_version():
    """The ``<version>`` of package.xml (FreeCAD's addon manifest), or ``unknown``."""
    try:
        with open(os.path.join(ADDON_DIR, "package.xml"), encoding="utf-8") as handle:
            match = re.search(r"<version>\s*([^<\s]+)\s*</version>", handle.read())
    except OSError:
        return "unknown"
    return match.group(1) if match else "unknown"


__version__ = _read_version()
install_core_guard(os.path.join(ADDON_DIR, "core"))
