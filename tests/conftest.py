# SPDX-License-Identifier: LGPL-2.1-or-later
"""Test tiers, and every test run gets a FreeCAD of its own (a temporary user-data folder) and
Ctrl-C.

Tiers: each test is marked by its folder, ``unit`` (``tests/core``, ``tests/fuzz``), ``freecad``
(``tests/freecad``, headless FreeCAD) or ``gui`` (``tests/gui``, the GUI under Xvfb); tests
that take more than about a second on an idle machine are marked ``slow`` where they are
defined. ``make test-fast`` runs the unit tests that are not slow; ``make test`` runs all.

Ctrl-C: the cancel tests send SIGINT to this process and to the command-line runs they
start. A shell without job control starts its background jobs with SIGINT ignored, and a
process inherits that (a CI runner may start ``make test`` so); the workbench respects an
ignored SIGINT, as it should. So the test process makes SIGINT Python's usual
KeyboardInterrupt, whatever started it; its children then start with the default action.

FreeCAD:

FreeCAD 0.20.2 takes its user data and settings folder (``user.cfg``, ``Mod``,
``AdditionalPythonPackages``, macros) from ``$FREECAD_USER_HOME`` when it is set, for
``import FreeCAD`` in this process and for the ``freecadcmd`` and ``freecad``
subprocesses, which inherit the environment. A workbench the user installed in their
own ``Mod`` folder (another copy of this one, say) is therefore not loaded, and the
preferences the tests set never touch the user's. The runtime packages that
``scripts/setup.sh`` installs into the user's ``AdditionalPythonPackages`` stay
visible through a link of that name in the temporary folder.
"""
import os
import shutil
import signal
import sys
import tempfile

USER_HOME_VARIABLE = "FREECAD_USER_HOME"
PACKAGES_FOLDER = "AdditionalPythonPackages"


def runtime_packages_folder():
    """The user's ``AdditionalPythonPackages`` folder on ``sys.path`` (the ``.venv``'s
    ``.pth`` file puts it there), or None."""
    for entry in sys.path:
        if os.path.basename(os.path.normpath(entry)) == PACKAGES_FOLDER and os.path.isdir(entry):
            return os.path.realpath(entry)
    return None


def _make_user_home():
    """Create the temporary user folder, link the runtime packages into it, point
    ``$FREECAD_USER_HOME`` at it; returns (folder, the variable's previous value)."""
    home = tempfile.mkdtemp(prefix="polycube_freecad_home_")
    packages = runtime_packages_folder()
    if packages is not None:
        os.symlink(packages, os.path.join(home, PACKAGES_FOLDER))
    previous = os.environ.get(USER_HOME_VARIABLE)
    os.environ[USER_HOME_VARIABLE] = home
    return home, previous


signal.signal(signal.SIGINT, signal.default_int_handler)

# At import, not in pytest_configure: pytest imports tests/freecad/conftest.py (which
# imports FreeCAD) before calling any hook, and always after this parent conftest.
_USER_HOME = _make_user_home()


TIER_OF_FOLDER = {"core": "unit", "fuzz": "unit", "freecad": "freecad", "gui": "gui"}
MARKERS = {"unit": "pure-Python tests of core and the command line",
           "freecad": "tests that need FreeCAD (headless)",
           "gui": "tests that drive the FreeCAD GUI under Xvfb",
           "slow": "tests that take more than about a second; left out by make test-fast"}


def pytest_configure(config):
    for name, meaning in MARKERS.items():
        config.addinivalue_line("markers", f"{name}: {meaning}")


def pytest_collection_modifyitems(config, items):
    import pytest

    tests_folder = os.path.dirname(os.path.abspath(__file__))
    for item in items:
        relative = os.path.relpath(str(item.path), tests_folder)
        tier = TIER_OF_FOLDER.get(relative.split(os.sep)[0])
        if tier is not None:
            item.add_marker(getattr(pytest.mark, tier))


def pytest_unconfigure(config):
    home, previous = _USER_HOME
    if previous is None:
        os.environ.pop(USER_HOME_VARIABLE, None)
    else:
        os.environ[USER_HOME_VARIABLE] = previous
    shutil.rmtree(home, ignore_errors=True)
