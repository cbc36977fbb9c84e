# SPDX-License-Identifier: LGPL-2.1-or-later
"""Intake stage: read and validate the target, scale it to millimetres (paper Sect. 2: the
watertight surface mesh the method starts from)."""
from core.params import UNIT_TO_MM
from core.proxy import working_surface
from core.types import IntakeResult, TriMesh


def run_intake(source, params, progress):
    """Read and validate the target; scale it from ``params.units`` to millimetres; reduce
    a fine target to the working surface of the later stages (``core.proxy``).

    Every later stage, the solid and the STEP file are in millimetres; the report's
    ``bbox_diagonal`` stays in the file's units, ``unit_to_mm`` is the factor applied.

    Parameters
    ----------
    source : core.types.MeshSource, the file, or arrays in memory.
    params : core.params.ReconstructionParams (``units``, ``components``,
        ``check_self_intersections``, ``repair_mesh``, ``proxy_triangles``, ``parts``).
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
    target, genus = TriMesh(mesh.vertices * factor, mesh.faces), int(summary["genus"])
    progress.check_cancel()
    components = summary["components"] if params.components == "all" else 1
    working = working_surface(target, genus, components, params.proxy_triangles,
                              "the parts file numbers the target's own faces"
                              if params.parts == "file" else "")
    report = {"file": str(source.path), "units": params.units, "unit_to_mm": factor, **summary,
              "proxy": working.report}
    return IntakeResult(target=target, genus=genus, report=report,
                        message="; ".join(summary["warnings"]),
                        working=working.mesh if working.reduced else None)
