# SPDX-License-Identifier: LGPL-2.1-or-later
"""Adding plain (non-parametric) results to a FreeCAD document (headless and in the GUI).

Used by ``api.reconstruct`` and ``api.import_subd_cage``; the parametric stage objects
are in ``polycube_wb.objects``.
"""
import FreeCAD  # noqa: F401  (FreeCAD before Mesh/Part: the reverse order segfaults in 0.20.2)
import Mesh  # noqa: F401

from polycube_wb.convert import arrays_to_mesh


def add_target_mesh(doc, target, name="Target"):
    """Add a validated ``core.types.TriMesh`` as a ``Mesh::Feature``; returns the object."""
    obj = doc.addObject("Mesh::Feature", name)
    obj.Mesh = arrays_to_mesh(target.vertices, target.faces)
    obj.Label = name
    doc.recompute()
    return obj


def add_solid(doc, solid, name="Solid"):
    """Add a ``Part.Solid`` as a ``Part::Feature``; returns the object."""
    obj = doc.addObject("Part::Feature", name)
    obj.Shape = solid
    obj.Label = name
    doc.recompute()
    return obj
