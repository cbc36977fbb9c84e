# SPDX-License-Identifier: LGPL-2.1-or-later
"""Adding pipeline results to a FreeCAD document (works headless and in the GUI)."""
import FreeCAD  # noqa: F401  (FreeCAD before Mesh/Part: the reverse order segfaults in 0.20.2)
import Mesh  # noqa: F401
import Part

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


def base_mesh_cage(base):
    """``Part.Compound`` of the edges of a ``core.types.PolyMesh`` (each edge once)."""
    from core.subdivision.catmull_clark import mesh_topology

    edges = mesh_topology(base.face_vertices, base.face_offsets, len(base.vertices)).edges
    points = [FreeCAD.Vector(*map(float, p)) for p in base.vertices]
    return Part.Compound([Part.LineSegment(points[a], points[b]).toShape() for a, b in edges])


def add_base_mesh(doc, base, name="BaseMesh"):
    """Add a base mesh's cage (its edges) as a ``Part::Feature``; returns the object."""
    obj = doc.addObject("Part::Feature", name)
    obj.Shape = base_mesh_cage(base)
    obj.Label = name
    if obj.ViewObject is not None:
        obj.ViewObject.LineColor = (0.1, 0.1, 0.1)
        obj.ViewObject.LineWidth = 2.0
        obj.ViewObject.PointSize = 4.0
    doc.recompute()
    return obj
