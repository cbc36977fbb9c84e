# SPDX-License-Identifier: LGPL-2.1-or-later
"""GUI test entry point, run inside the real FreeCAD GUI::

    xvfb-run -a -s "-screen 0 1280x1024x24" freecad -t TestPolycubeGui -M <repo>

(``-t`` before ``-M``: FreeCAD 0.20.2 rejects the other order). FreeCAD loads the
module by name, so this root-level file has a unique name and loads the cases from
``tests/gui/gui_cases.py`` by path; a ``tests`` package of another addon cannot shadow
them. Screenshots go to ``$POLYCUBE_GUI_OUTPUT`` or ``tests/gui/output/``.
"""
import importlib.util
import os
import sys

_CASES_NAME = "polycube_gui_cases"
_CASES_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests", "gui",
                           "gui_cases.py")


def _cases_module():
    module = sys.modules.get(_CASES_NAME)
    if module is None:
        spec = importlib.util.spec_from_file_location(_CASES_NAME, _CASES_PATH)
        module = importlib.util.module_from_spec(spec)
        sys.modules[_CASES_NAME] = module
        spec.loader.exec_module(module)
    return module


def load_tests(loader, standard_tests, pattern):
    """unittest's load_tests protocol: the cases of tests/gui/gui_cases.py."""
    standard_tests.addTests(loader.loadTestsFromModule(_cases_module()))
    return standard_tests
