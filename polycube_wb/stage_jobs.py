# SPDX-License-Identifier: LGPL-2.1-or-later
"""The computations of the stage objects, as jobs another thread or process can run.

A :class:`StageJob` is a module-level function and its arguments (plain data: numpy
arrays, ``core.types`` results, parameters), so it can be pickled to the GUI's stage
process (:mod:`polycube_wb.stage_worker`) or run in the calling thread. This module never
imports FreeCAD, so that process starts without it. A job that makes or reads OpenCascade
shapes imports FreeCAD's ``Part`` there when it runs; its shapes cross the pipe in OpenCascade's
binary shape format (:func:`register_shape_pickling`), so the B-rep work holds no lock FreeCAD's
GUI waits for.
"""
import os
from dataclasses import dataclass

from core.errors import Cancelled, PolycubeError
from polycube_wb.file_bytes import bytes_written_by, read_from_bytes


class StageFailed(PolycubeError):
    """A core stage did not produce its result; the message is the stage's own reason."""


@dataclass(frozen=True)
class StageJob:
    """``function(*args, progress)``: one stage's computation, detached from the document.

    function : a module-level function (picklable by reference).
    args : tuple of plain data.
    needs_freecad : the function reads FreeCAD's document or GUI objects, so it runs in
        FreeCAD's own process (``Part`` shapes alone do not need it: they pickle, see
        :func:`register_shape_pickling`).
    """

    function: object
    args: tuple = ()
    needs_freecad: bool = False

    def __call__(self, progress):
        return self.function(*self.args, progress)


def core_stages(state, stages, params, progress):
    """Run core pipeline stages on ``state`` (a ``core.types.PipelineState``); returns it.

    Raises
    ------
    Cancelled, PolycubeInputError
        As raised by the stages.
    StageFailed
        A stage did not run to the end; the message names it and its reason.
    """
    from core.pipeline import run_stages

    state, report, failed = run_stages(state, list(stages), params, progress)
    if isinstance(failed, (Cancelled, PolycubeError)):
        raise failed
    for name in stages:
        entry = report["stages"].get(name, {})
        if entry.get("status") != "ok":
            raise StageFailed(f"the '{name}' stage {entry.get('status', 'did not run')}: "
                              f"{entry.get('message', '')}".rstrip(": "))
    return state


def intake(label, vertices, faces, params, progress):
    """``{"intake": IntakeResult}`` of the mesh ``(vertices, faces)`` named ``label``."""
    from core.types import MeshSource, PipelineState

    state = PipelineState(source=MeshSource(label, (vertices, faces)))
    return {"intake": core_stages(state, ["intake"], params, progress).intake}


def read_target_file(path, components="largest", check_self_intersections=True, repair=True):
    """The validated target mesh (``core.types.TriMesh``) of a mesh file.

    Raises
    ------
    InvalidMeshError
        The file cannot be read or the mesh is not a valid closed solid.
    """
    from core.mesh_io import read_triangle_soup
    from core.validate import validate_target

    path = os.path.abspath(os.fspath(path))
    vertices, faces = read_triangle_soup(path)
    mesh, _ = validate_target(vertices, faces, components=components,
                              check_self_intersections=check_self_intersections, name=path,
                              repair=repair)
    return mesh


def read_mesh_file(path, progress):
    """The validated target mesh of the mesh file ``path`` with FreeCAD's binary mesh file of
    it (``polycube_wb.mesh_binary.MeshWithBinary``), which FreeCAD then only reads."""
    from polycube_wb.mesh_binary import MeshWithBinary, binary_mesh

    progress.report("reading and validating the mesh", 0.0, os.path.basename(path))
    mesh = read_target_file(path)
    return MeshWithBinary(mesh, binary_mesh(mesh.vertices, mesh.faces))


def shape_from_binary(data):
    """The ``Part.Shape`` of OpenCascade's binary shape format ``data`` (bytes; how shapes
    unpickle)."""
    import Part

    shape = Part.Shape()
    read_from_bytes(data, "shape.bin", shape.importBinary)
    return shape


def _reduce_shape(shape):
    return shape_from_binary, (bytes_written_by(shape.exportBinary, "shape.bin"),)


def register_shape_pickling():
    """Let ``Part`` shapes pickle in OpenCascade's binary shape format (call where ``Part`` is
    imported: in FreeCAD, and in the stage process once a job has imported it).

    The binary format is exact, as BREP text is, and reading it takes a fraction of the time:
    the GUI's thread that reads a stage's result holds Python's lock meanwhile, so the event
    loop waits for it."""
    import copyreg

    import Part

    for kind in (Part.Shape, Part.Solid, Part.Shell, Part.Face, Part.Compound):
        copyreg.pickle(kind, _reduce_shape)


def portable_error(exc):
    """``exc`` if it survives pickling, else an exception of the same class with its message
    (an exception whose constructor takes more than the message does not unpickle)."""
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        return RebuiltError(type(exc).__module__, type(exc).__qualname__, str(exc))


class RebuiltError:
    """An exception's class (module, name) and message, for :meth:`rebuild` in the GUI."""

    def __init__(self, module, name, message):
        self.module, self.name, self.message = module, name, message

    def rebuild(self):
        """The exception: of its own class when it can be imported, else a RuntimeError."""
        import importlib

        try:
            cls = getattr(importlib.import_module(self.module), self.name)
            exc = cls.__new__(cls)
            Exception.__init__(exc, self.message)
            return exc
        except Exception:
            return RuntimeError(f"{self.name}: {self.message}")
