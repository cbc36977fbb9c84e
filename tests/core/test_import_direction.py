# SPDX-License-Identifier: LGPL-2.1-or-later
"""Import direction: ``core`` never imports the FreeCAD layer; inside ``core`` no import runs
up the layers (kernel, algorithms, stages, runner: ``CORE_LAYERS``); the document objects
never import the API; only the GUI imports the GUI; no two modules of ``core``, nor of
``polycube_wb``, import each other, directly or around a cycle.

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


KERNEL = "core"
"""The layer of ``core``'s top-level modules (types, errors, tolerances, geometry, meshes,
target surface, I/O): the kernel every algorithm uses."""
QUADMESH_ROUTE = "core.quadmesh.base_mesh"
"""The base mesh's choice of route (and the package ``core.quadmesh``, which re-exports it):
above both routes and the modules they share."""
CORE_LAYERS = {
    KERNEL: set(),
    "core.subdivision": {KERNEL},
    "core.segmentation": {KERNEL},
    "core.quadmesh": {KERNEL, "core.subdivision"},
    "core.quadmesh.polycube": {KERNEL, "core.segmentation", "core.subdivision", "core.quadmesh"},
    "core.quadmesh.decimation": {KERNEL, "core.subdivision", "core.quadmesh"},
    QUADMESH_ROUTE: {KERNEL, "core.segmentation", "core.subdivision", "core.quadmesh",
                     "core.quadmesh.polycube", "core.quadmesh.decimation"},
    "core.fitting": {KERNEL, "core.quadmesh", "core.subdivision"},
    "core.export": {KERNEL, "core.subdivision"},
    "core.stages": {KERNEL, "core.subdivision", "core.segmentation", "core.quadmesh",
                    QUADMESH_ROUTE, "core.fitting", "core.export"},
    "core.pipeline": {KERNEL, "core.stages"},
    "core.precompile": {KERNEL, "core.subdivision", "core.segmentation", "core.quadmesh",
                        "core.quadmesh.polycube", "core.quadmesh.decimation", QUADMESH_ROUTE,
                        "core.fitting", "core.export"},
}
"""Which layers of ``core`` each layer may import (besides itself): a package of ``core``
is a layer of its own, the runner ``core.pipeline`` one above the stages, the set-up's
``core.precompile`` (which compiles the algorithms' compiled functions) one above the
algorithms, every other top-level module of ``core`` belongs to the kernel. The kernel imports no algorithm, an
algorithm package only those below it, only the stages and the runner import the stages.
Inside ``core.quadmesh`` the two routes (``polycube``, ``decimation``) are layers that never
import each other, both above the modules they share and below the route choice."""
SUBLAYERS = ("core.pipeline", "core.precompile", "core.quadmesh.polycube",
             "core.quadmesh.decimation", QUADMESH_ROUTE)
"""Layers that are a module or a subpackage rather than a package of ``core``."""


def core_layer(module):
    """The layer (a key of ``CORE_LAYERS``) of a dotted ``core`` module name."""
    if module == "core.quadmesh":
        return QUADMESH_ROUTE
    for top in SUBLAYERS:
        if _is_within(module, top):
            return top
    parts = module.split(".")
    if len(parts) > 1 and os.path.isdir(os.path.join(REPO, "core", parts[1])):
        return "core." + parts[1]
    return KERNEL


def _core_module(name):
    """The ``core`` module an imported name lives in (``core.a.b.name`` -> ``core.a.b``),
    or None for an import from outside ``core`` or of the package ``core`` itself."""
    parts = name.split(".")
    if parts[0] != "core":
        return None
    for n in range(len(parts), 1, -1):
        path = os.path.join(REPO, *parts[:n])
        if os.path.isfile(path + ".py") or os.path.isdir(path):
            return ".".join(parts[:n])
    return None


def layer_violations(files):
    """``(path, imported layer)`` pairs of ``files`` (``core`` sources) that import a layer
    of ``core`` their own layer may not (``CORE_LAYERS``); a layer missing from
    ``CORE_LAYERS`` is reported as ``(path, 'undeclared layer ...')``."""
    offending = []
    for path in files:
        layer = core_layer(_module_of(path))
        if layer not in CORE_LAYERS:
            offending.append((path, f"undeclared layer {layer}"))
            continue
        for name in imported_modules(path):
            module = _core_module(name)
            if module is None or core_layer(module) == layer:
                continue
            if core_layer(module) not in CORE_LAYERS[layer]:
                offending.append((path, core_layer(module)))
    return sorted(set(offending))


def test_no_import_runs_up_the_layers_of_core():
    assert layer_violations(_python_files("core")) == []


def test_the_layer_check_sees_an_import_up_the_layers(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "REPO", str(tmp_path))
    for package in ("fitting", "quadmesh", "stages"):
        (tmp_path / "core" / package).mkdir(parents=True)
    (tmp_path / "core" / "geometry.py").write_text("def f():\n    from core.fitting import x\n")
    (tmp_path / "core" / "quadmesh" / "a.py").write_text("from core.stages.fit import run_fit\n")
    (tmp_path / "core" / "fitting" / "x.py").write_text("from core.quadmesh.b import y\n")
    (tmp_path / "core" / "stages" / "fit.py").write_text("from core.fitting.x import y\n")
    for route in ("polycube", "decimation"):
        (tmp_path / "core" / "quadmesh" / route).mkdir()
    (tmp_path / "core" / "quadmesh" / "polycube" / "p.py").write_text(
        "from core.quadmesh.decimation.d import z\nfrom core.quadmesh.b import y\n")
    (tmp_path / "core" / "quadmesh" / "decimation" / "d.py").write_text(
        "import core.quadmesh.b\n")
    (tmp_path / "core" / "quadmesh" / "b.py").write_text(
        "import core.geometry\nfrom core.quadmesh.decimation import d\n")
    (tmp_path / "core" / "newpkg").mkdir()
    (tmp_path / "core" / "newpkg" / "c.py").write_text("")
    assert layer_violations(_python_files("core")) == [
        (os.path.join("core", "geometry.py"), "core.fitting"),
        (os.path.join("core", "newpkg", "c.py"), "undeclared layer core.newpkg"),
        (os.path.join("core", "quadmesh", "a.py"), "core.stages"),
        (os.path.join("core", "quadmesh", "b.py"), "core.quadmesh.decimation"),
        (os.path.join("core", "quadmesh", "polycube", "p.py"), "core.quadmesh.decimation")]


def test_the_document_objects_never_import_the_api():
    """``polycube_wb.api`` builds documents from the objects; the objects use ``core`` and
    the FreeCAD layer's converters, never the API above them."""
    offending = sorted((path, name) for path in _python_files(os.path.join("polycube_wb",
                                                                           "objects"))
                       for name in imported_modules(path)
                       if _is_within(name, "polycube_wb.api"))
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
