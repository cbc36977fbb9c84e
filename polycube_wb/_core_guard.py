# SPDX-License-Identifier: LGPL-2.1-or-later
"""Keep ``from core.x import y`` working when another addon owns ``sys.modules['core']``.

``core`` is a common name: CfdOF's InitGui sets ``sys.modules['core']`` to its own
package, after which Python would look for ``core.x`` inside CfdOF. This finder,
placed first on ``sys.meta_path``, resolves ``core.<name>`` to our own files whenever
``sys.modules['core']`` is not our package, and otherwise stays out of the way.
"""
import importlib.abc
import importlib.util
import os
import sys


class _OwnCoreFinder(importlib.abc.MetaPathFinder):
    """Finds ``core.*`` submodules in our ``core`` folder when ``core`` is foreign."""

    def __init__(self, core_dir):
        self.core_dir = os.path.realpath(core_dir)

    def _core_is_ours(self):
        module = sys.modules.get("core")
        location = getattr(module, "__file__", None) if module is not None else None
        return module is None or (location is not None
                                  and os.path.realpath(os.path.dirname(location)) == self.core_dir)

    def find_spec(self, fullname, path=None, target=None):
        if not fullname.startswith("core.") or self._core_is_ours():
            return None
        base = os.path.join(self.core_dir, *fullname.split(".")[1:])
        package_init = os.path.join(base, "__init__.py")
        if os.path.isfile(package_init):
            return importlib.util.spec_from_file_location(
                fullname, package_init, submodule_search_locations=[base])
        if os.path.isfile(base + ".py"):
            return importlib.util.spec_from_file_location(fullname, base + ".py")
        return None


def install_core_guard(core_dir):
    """Put the finder for ``core_dir`` first on ``sys.meta_path`` (idempotent)."""
    for finder in sys.meta_path:
        if isinstance(finder, _OwnCoreFinder) or type(finder).__name__ == "_OwnCoreFinder":
            return
    sys.meta_path.insert(0, _OwnCoreFinder(core_dir))
