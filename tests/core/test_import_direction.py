# SPDX-License-Identifier: LGPL-2.1-or-later
"""Import direction: ``core`` never imports the FreeCAD layer; only the GUI imports the GUI;
no two modules of ``core``, nor of ``polycube_wb``, import each other, directly or around a
cycle.

Every ``import`` statement of the sources (also those inside functions) is read with
``ast``, relative imports resolved to their absolute module; a subprocess that imports
every ``core`` module checks the same at run time (no module imported indirectly).
"""
import ast
import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FREECAD_LAYER = ("FreeCAD", "FreeCADGui", "Part", "Mesh", "MeshPart", "PySide", "PySide2",
                 "polycube_wb")
"""Top-level modules that ``core`` must not import (FreeCAD, its Qt binding, our layer)."""
GUI = "polycube_wb.gui"
GUI_ENTRY_POINTS = {"InitGui.py", "TestPolycubeGui.py"}
"""Files FreeCAD itself loads only in the GUI: they may import the GUI package."""


def _python_files(*folders):
    """Repository-relative paths of the ``.py`` files below ``folders`` (sorted)."""
    found = []
    for folder in folders:
        for root, _, names in os.walk(os.path.join(REPO, folder)):
            found += [os.path.relpath(os.path.join(root, name), REPO)
                      for name in names if name.endswith(".py")]
    return sorted(found)


def _module_of(path):
    """Dotted module name of a repository-relative ``.py`` path."""
    parts = path[:-3].split(os.sep)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path):
    """Absolute names of every module the file at ``path`` imports (set of str)."""
    with open(os.path.join(REPO, path), encoding="utf-8") as handle:
        tree = ast.parse(handle.read(), filename=path)
    package = _module_of(path).split(".")
    if not path.endswith("__init__.py"):
        package = package[:-1]
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            names.add(module)
            names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def _is_within(name, top):
    return name == top or name.startswith(top + ".")


def test_relative_imports_are_resolved():
    names = imported_modules(os.path.join("polycube_wb", "gui", "__init__.py"))
    assert all(not name.startswith(".") for name in names)


def test_core_never_imports_freecad_or_the_workbench():
    files = _python_files("core")
    assert len(files) > 40, "the walk found the core package"
    offending = sorted((path, name) for path in files for name in imported_modules(path)
                       if any(_is_within(name, top) for top in FREECAD_LAYER))
    assert offending == []


def test_only_the_gui_imports_the_gui():
    files = _python_files("core", "polycube_wb", "examples", "benchmarks", "scripts")
    files += [name for name in os.listdir(REPO) if name.endswith(".py")]
    outside = [path for path in files if not path.startswith(os.path.join("polycube_wb", "gui"))
               and path not in GUI_ENTRY_POINTS]
    offending = {path.replace(os.sep, "/") for path in outside
                 if any(_is_within(name, GUI) for name in imported_modules(path))}
    assert offending == set()


def test_the_check_sees_an_offending_import(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "REPO", str(tmp_path))
    (tmp_path / "core").mkdir()
    (tmp_path / "core" / "bad.py").write_text("def f():\n    from FreeCADGui import x\n")
    assert "FreeCADGui.x" in imported_modules(os.path.join("core", "bad.py"))


def import_cycles(files):
    """Sets of modules (dotted names, sorted lists) that import each other around a cycle:
    the strongly connected components of more than one module of the import graph of
    ``files`` (an import of ``a.b.name`` counts as one of module ``a.b``)."""
    import numpy as np
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    modules = sorted({_module_of(path) for path in files})
    index = {name: k for k, name in enumerate(modules)}
    edges = set()
    for path in files:
        for name in imported_modules(path):
            parts = name.split(".")
            target = next((".".join(parts[:n]) for n in range(len(parts), 0, -1)
                           if ".".join(parts[:n]) in index), None)
            if target is not None and target != _module_of(path):
                edges.add((index[_module_of(path)], index[target]))
    rows, cols = (np.array(side, dtype=np.int64) for side in zip(*edges)) if edges else ([], [])
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(modules), len(modules)))
    _, component = connected_components(graph, directed=True, connection="strong")
    sizes = np.bincount(component)
    return sorted([modules[k] for k in np.flatnonzero(component == c)]
                  for c in np.flatnonzero(sizes > 1))


CORE_LAYERS = (("core.stages", "core.pipeline"),)
"""Packages of ``core`` above the algorithms: the stages and their runner call the algorithm
packages (``core.quadmesh``, ``core.fitting``, ``core.subdivision``, ``core.export``, ...),
never the other way round."""


def test_the_algorithms_never_import_the_stages_or_the_runner():
    upper = CORE_LAYERS[0]
    offending = sorted(
        (path, name) for path in _python_files("core")
        if not _module_of(path).startswith(upper)
        for name in imported_modules(path) if any(_is_within(name, top) for top in upper))
    assert offending == []


def test_core_has_no_import_cycle():
    assert import_cycles(_python_files("core")) == []


def test_the_workbench_has_no_import_cycle():
    assert import_cycles(_python_files("polycube_wb")) == []


def test_the_cycle_check_sees_a_cycle_through_a_function_level_import(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "REPO", str(tmp_path))
    (tmp_path / "core" / "pkg").mkdir(parents=True)
    (tmp_path / "core" / "pkg" / "a.py").write_text("from core.pkg.b import g\n")
    (tmp_path / "core" / "pkg" / "b.py").write_text("def g():\n    from core.pkg import c\n")
    (tmp_path / "core" / "pkg" / "c.py").write_text("import core.pkg.a\n")
    (tmp_path / "core" / "pkg" / "d.py").write_text("from core.pkg.a import x\n")
    assert import_cycles(_python_files("core")) == [["core.pkg.a", "core.pkg.b", "core.pkg.c"]]


@pytest.mark.slow
def test_importing_all_of_core_loads_no_freecad_module():
    modules = [_module_of(path) for path in _python_files("core")]
    code = ("import importlib, sys\n"
            f"for name in {modules!r}:\n    importlib.import_module(name)\n"
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {FREECAD_LAYER!r}))")
    completed = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                               text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr[-3000:]
    assert completed.stdout.strip().splitlines()[-1] == "[]"


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))
