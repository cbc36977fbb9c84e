# SPDX-License-Identifier: LGPL-2.1-or-later
"""Headless FreeCAD tests: skipped cleanly when FreeCAD cannot be imported.

FreeCAD must be imported before ``Part`` or ``Mesh`` (the other order segfaults in
FreeCAD 0.20.2), which ``importorskip`` below does for every test in this folder.
"""
import os
import sys

import pytest

_FREECAD_LIB = "/usr/lib/freecad-python3/lib"
_REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_HERE = os.path.dirname(os.path.abspath(__file__))

for _path in (_REPO, _HERE):
    if _path not in sys.path:
        sys.path.insert(0, _path)
if os.path.isdir(_FREECAD_LIB) and _FREECAD_LIB not in sys.path:
    sys.path.append(_FREECAD_LIB)

pytest.importorskip("FreeCAD")
