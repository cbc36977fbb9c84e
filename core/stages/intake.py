# SPDX-License-Identifier: LGPL-2.1-or-later
"""Intake stage: read and validate the target, scale it to millimetres (paper Sect. 2: the
watertight surface mesh the method starts from)."""
from core.params import UNIT_TO_MM
from core.types import IntakeResult, TriMesh


def run_intake(source, params, progress):
    """Read and validate the target; scale it from ``params.units`` to millimetres.

    Every later stage, the solid and the STEP file are in millimetres; the report's
    ``bbox_diagonal`` stays in the file's units, ``unit_to_mm`` is the factor applied.

    Parameters
    ----------
    source : core.types.MeshSource, the file, or arrays in memory.
    params : core.params.ReconstructionParams (``units``, ``components``,
        ``check_self_intersections``, ``repair_mesh``).
    progress : core.progress.Progress.

    Returns
    -------
    core.types.IntakeResult

    Raises
    ------
    InvalidMeshError when the mesh is not a closed, consistently oriented 2-manifold after
    the repairs ``params.repair_mesh`` allows.
    """
    from core.mesh_io import read_triangle_soup
    from core.validate import validate_target

    if source.arrays is not None:
        vertices, faces = source.arrays
    else:
        vertices, faces = read_triangle_soup(source.path)
    progress.check_cancel()
    factor = UNIT_TO_MM[params.units]
    mesh, summary = validate_target(vertices, faces, components=params.components,
                                    check_self_intersections=params.check_self_intersections,
                                    name=str(source.path), unit_to_mm=factor,
                                    repair=params.repair_mesh)
    report = {"file": str(source.path), "units": params.units, "unit_to_mm": factor, **summary}
    return IntakeResult(target=TriMesh(mesh.vertices * factor, mesh.faces),
                        genus=int(summary["genus"]), report=report,
                        message="; ".join(summary["warnings"]))
