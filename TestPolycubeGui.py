# SPDX-License-Identifier: LGPL-2.1-or-later
"""GUI test entry point, run inside the real FreeCAD GUI::

    xvfb-run -a -s "-screen 0 1280x1024x24" freecad -t TestPolycubeGui -M <repo>

(``-t`` before ``-M``: FreeCAD 0.20.2 rejects the other order). FreeCAD loads the
module by name, so this root-level file has a unique name and loads the cases from
``tests/gui/gui_cases*.py`` by path; a ``tests``
package of another addon cannot shadow them. Screenshots go to ``$POLYCUBE_GUI_OUTPUT`` or
``tests/gui/output/``.
"""
import importlib.util
import os
import sys

_CASES_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests", "gui")
_CASES = (("polycube_gui_cases", "gui_cases.py"),
          ("polycube_gui_cases_batch", "gui_cases_batch.py"),
          ("polycube_gui_cases_responsive", "gui_cases_responsive.py"))
"""(module name, file in tests/gui) of every group of GUI cases."""


def _cases_module(name, file_name):
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, os.path.join(_CASES_DIR, file_name))
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return module


def load_tests(loader, standard_tests, pattern):
    """unittest's load_tests protocol: the cases of every file in ``_CASES`` (of the classes
    ``$POLYCUBE_GUI_CASES`` names, when set)."""
    import unittest

    wanted = {name for name in os.environ.get("POLYCUBE_GUI_CASES", "").split(",") if name}
    for name, file_name in _CASES:
        module = _cases_module(name, file_name)
        for _, case in sorted(vars(module).items()):  # name order, as unittest loads
            if isinstance(case, type) and issubclass(case, unittest.TestCase) and \
                    case.__module__ == module.__name__ and (not wanted or case.__name__ in wanted):
                standard_tests.addTests(loader.loadTestsFromTestCase(case))
    return standard_tests
