# SPDX-License-Identifier: LGPL-2.1-or-later
"""The non-parametric way to fill a document: the pipeline's target mesh and result solid, or a
SubD cage's solid, added as plain objects that do not recompute (the parametric chain of stage
objects is :mod:`polycube_wb.api.factories`)."""
import os

from core.params import EXPORT_DEPTH
from core.pipeline import reconstruct as run_pipeline
from core.progress import NO_PROGRESS
from polycube_wb.api.headless import subd_to_solid


def reconstruct(doc, mesh_path, progress=NO_PROGRESS, **params):
    """Run the pipeline into document ``doc``; returns the result solid's object.

    The validated target is added as a mesh object first, so the user sees what was
    read; when the pipeline can build the solid it is added as a ``Part::Feature``.

    Raises
    ------
    PolycubeInputError for bad input (nothing is added); the exception of a stage that
    failed (the target mesh is added first).
    """
    from polycube_wb.document import add_solid, add_target_mesh

    result = run_pipeline(mesh_path, params, progress, "solid")
    name = os.path.splitext(os.path.basename(mesh_path))[0]
    add_target_mesh(doc, result.state.intake.target, name + "_target")
    if result.failed is not None:
        raise result.failed
    from polycube_wb.brep import patches_to_solid

    return add_solid(doc, patches_to_solid(result.state.patches.patches), name + "_solid")


def import_subd_cage(doc, path, progress=NO_PROGRESS, depth=EXPORT_DEPTH):
    """Turn a SubD cage (closed polygon OBJ) into a B-spline solid ``Part::Feature`` in ``doc``.

    Returns
    -------
    (Part::Feature, dict) the new object and the report of :func:`subd_to_solid`.
    """
    from polycube_wb.document import add_solid

    path = os.path.abspath(os.fspath(path))
    solid, report = subd_to_solid(path, depth=depth, measure=True, progress=progress)
    name = os.path.splitext(os.path.basename(path))[0] + "_solid"
    return add_solid(doc, solid, name), report


def export_step(obj, path):
    """Write the shape of ``obj`` (a Part object) to a STEP file; returns the path."""
    from polycube_wb.step_io import write_step

    return write_step(obj.Shape, path)
