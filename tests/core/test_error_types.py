# SPDX-License-Identifier: LGPL-2.1-or-later
"""Every failure a user can cause is a project error (``core.errors``), so the command line
turns it into exit 2 and one ``error:`` line instead of exit 1 and a traceback.

The sources are read with ``ast``: a ``raise`` of a built-in exception class is allowed only
inside a ``try`` of the same function that catches it (and turns it into a project error),
or where listed below with the reason. The errors of the subdivision, the limit surface and
the B-spline export are then raised on real bad input and checked for their type and message.
"""
import ast
import os

import numpy as np
import pytest

from core.errors import (FaceLimitError, InternalError, InvalidMeshError, LabelingError,
                         ParameterError, PolycubeInputError, StepPathError)
from core.types import PolyMesh

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BUILTIN = {"ValueError", "TypeError", "RuntimeError", "KeyError", "IndexError", "Exception",
           "AssertionError", "OSError", "IOError", "ArithmeticError", "ZeroDivisionError"}
ALLOWED = {
    ("core/fitting/responses.py", "ValueError"):
        "unknown packaging mode: an internal argument (fit_mode is checked by core.params)",
    ("polycube_wb/gui/task_panels.py", "ValueError"):
        "the cage-vertex field's caller catches it and shows the message in the panel",
    ("polycube_wb/batch.py", "RuntimeError"):
        "the batch started from FreeCAD's interpreter: an installation problem, exit 1",
    ("polycube_wb/gui/batch_command.py", "RuntimeError"):
        "no Python interpreter for the batch on the PATH: an installation problem",
}
"""(file, built-in class) raised outside a converting ``try``, with why that is right."""


def _sources():
    for folder in ("core", "polycube_wb"):
        for root, _, names in os.walk(os.path.join(REPO, folder)):
            for name in sorted(names):
                if name.endswith(".py"):
                    path = os.path.join(root, name)
                    yield os.path.relpath(path, REPO).replace(os.sep, "/"), path


def _caught(handler, name):
    """Whether the ``except`` clause ``handler`` catches the built-in class ``name``."""
    kinds = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return handler.type is None or any(isinstance(k, ast.Name) and k.id in (name, "Exception")
                                       for k in kinds)


def builtin_raises(tree):
    """(line, class name) of every ``raise BuiltinError(...)`` not converted by an enclosing
    ``try`` of the same function."""
    found = []

    def visit(node, handlers):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            handlers = ()
        if isinstance(node, ast.Raise) and node.exc is not None:
            call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(call, ast.Name) and call.id in BUILTIN \
                    and not any(_caught(h, call.id) for h in handlers):
                found.append((node.lineno, call.id))
        if isinstance(node, ast.Try):
            for child in node.body:
                visit(child, handlers + tuple(node.handlers))
            for child in node.handlers + node.orelse + node.finalbody:
                visit(child, handlers)
            return
        for child in ast.iter_child_nodes(node):
            visit(child, handlers)

    visit(tree, ())
    return found


def test_the_checker_finds_a_plain_raise_and_accepts_a_converted_one():
    tree = ast.parse("def f(x):\n"
                     "    try:\n"
                     "        raise ValueError('converted below')\n"
                     "    except ValueError:\n"
                     "        raise ParameterError('x')\n"
                     "    raise TypeError('leaks')\n"
                     "def g():\n"
                     "    try:\n"
                     "        h(lambda: 0)\n"
                     "    except KeyError:\n"
                     "        raise ValueError('leaks from the handler')\n")
    assert builtin_raises(tree) == [(6, "TypeError"), (11, "ValueError")]


def test_no_plain_builtin_error_reaches_a_user():
    leaks = []
    for name, path in _sources():
        with open(path, encoding="utf-8") as handle:
            tree = ast.parse(handle.read(), filename=name)
        leaks += [f"{name}:{line} raises {kind}" for line, kind in builtin_raises(tree)
                  if (name, kind) not in ALLOWED]
    assert leaks == [], "raise a core.errors class instead:\n" + "\n".join(leaks)


def _tetra_triangles():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    return PolyMesh.from_faces(V, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def _cube(drop=0):
    """The unit cube as six quads, outward, without its last ``drop`` faces."""
    V = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=np.float64)
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return PolyMesh.from_faces(V, quads[:len(quads) - drop])


def test_limit_masks_name_the_faces_that_are_not_quads():
    from core.subdivision.limit import LimitEvaluator, limit_matrices

    for call in (limit_matrices, LimitEvaluator):
        with pytest.raises(InvalidMeshError, match=r"4 of 4 faces are not quads, e\.g\. "
                                                   r"faces \[0, 1, 2, 3\]") as info:
            call(_tetra_triangles())
        assert info.value.reason == "not_quads" and info.value.count == 4


def test_limit_masks_name_the_open_edges():
    from core.subdivision.limit import limit_matrices

    with pytest.raises(InvalidMeshError, match=r"4 edges have one face") as info:
        limit_matrices(_cube(drop=1))
    assert info.value.reason == "open" and info.value.count == 4
    assert all(len(edge) == 2 for edge in info.value.examples)
    limit_matrices(_cube())  # the closed cube is accepted


def test_subdivision_and_grid_arguments_are_parameter_errors():
    from core.subdivision.catmull_clark import build_hierarchy, face_grids
    from core.subdivision.limit import limit_volume

    with pytest.raises(ParameterError, match="subdivision levels must be >= 0, got -1"):
        build_hierarchy(_cube(), -1)
    with pytest.raises(ParameterError, match="limit_volume needs level >= 2, got 1"):
        limit_volume(_cube(), level=1)
    with pytest.raises(ParameterError, match=r"composite index 3 outside -1\.\.1"):
        build_hierarchy(_cube(), 2).composite(3)
    with pytest.raises(InvalidMeshError, match=r"4 faces are not quads") as info:
        face_grids(build_hierarchy(_tetra_triangles(), 1), 1)
    assert info.value.reason == "not_quads"
    assert abs(limit_volume(_cube(), level=3) - limit_volume(_cube(), level=2)) < 1e-2


@pytest.mark.parametrize("depth, message", [
    (0, "depth must be between 1 and 12, got 0"), (13, "depth must be between 1 and 12, got 13"),
    (2.5, "depth must be an integer, got 2.5"), (True, "depth must be an integer, got True")])
def test_a_bad_export_depth_is_a_parameter_error(depth, message):
    from core.export.bspline import limit_surface_patches

    with pytest.raises(ParameterError, match=message):
        limit_surface_patches(_cube(), depth=depth, measure=False)


def test_error_classes_map_to_the_exit_codes_the_readme_gives():
    """User errors are ``PolycubeInputError`` (exit 2); the others are not (exit 1)."""
    assert issubclass(FaceLimitError, ParameterError) and not issubclass(FaceLimitError,
                                                                          LabelingError)
    assert issubclass(StepPathError, PolycubeInputError)
    assert not issubclass(InternalError, PolycubeInputError)
    assert not issubclass(LabelingError, PolycubeInputError)
