# SPDX-License-Identifier: LGPL-2.1-or-later
"""The computations of the stage objects, as jobs another thread or process can run.

A :class:`StageJob` is a module-level function and its arguments (plain data: numpy
arrays, ``core.types`` results, parameters), so it can be pickled to the GUI's stage
process (:mod:`polycube_wb.stage_worker`) or run in the calling thread. This module never
imports FreeCAD, so that process starts without it; jobs whose function needs FreeCAD
(OpenCascade shapes) say so and run in FreeCAD's own process.
"""
from dataclasses import dataclass

from core.errors import Cancelled, PolycubeError


class StageFailed(PolycubeError):
    """A core stage did not produce its result; the message is the stage's own reason."""


@dataclass(frozen=True)
class StageJob:
    """``function(*args, progress)``: one stage's computation, detached from the document.

    function : a module-level function (picklable by reference).
    args : tuple of plain data.
    needs_freecad : the function makes or reads FreeCAD objects (``Part`` shapes), so it
        runs in FreeCAD's own process.
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


def read_mesh_file(path, progress):
    """The validated target mesh (``core.types.TriMesh``) of the mesh file ``path``."""
    import os

    from polycube_wb.api import read_target_file

    progress.report("reading and validating the mesh", 0.0, os.path.basename(path))
    return read_target_file(path)
