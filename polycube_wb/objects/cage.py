# SPDX-License-Identifier: LGPL-2.1-or-later
"""A polygon cage (``core.types.PolyMesh``) stored in a document object's properties.

The base mesh and the fitted base mesh are kept as three list properties
(``CageVertices``: one ``FreeCAD.Vector`` per vertex; ``CageFaceVertices`` and
``CageFaceOffsets``: the faces in CSR form; ``CageCreases``: the vertex pairs of the edges
tagged as sharp creases, flattened, empty for none), so they are saved in the ``.FCStd`` and the
user can edit the vertex coordinates. The object's ``Shape`` shows the cage: first one
``Part.Vertex`` per cage vertex (so ``VertexK`` of the shape is cage vertex ``K - 1``),
then one edge per cage edge.
"""
import numpy as np

import FreeCAD
import Part

from polycube_wb.objects.base import StageFailed, add_property

GROUP = "Cage"


def add_cage_properties(obj):
    """Add the cage properties (idempotent)."""
    add_property(obj, "App::PropertyVectorList", "CageVertices", GROUP,
                 "Cage vertex coordinates (editable: the stages after this one follow)")
    for name, tooltip in (("CageFaceVertices", "Corners of all cage faces, concatenated"),
                          ("CageFaceOffsets", "Face f is CageFaceVertices[o[f]:o[f + 1]]"),
                          ("CageCreases", "Vertex pairs of the sharp crease edges, flattened")):
        add_property(obj, "App::PropertyIntegerList", name, GROUP, tooltip, hidden=True,
                     output=True)
    for name, tooltip in (("Faces", "Cage faces"), ("Vertices", "Cage vertices"),
                          ("ExtraordinaryVertices", "Cage vertices of valence other than 4"),
                          ("Genus", "Genus of the cage")):
        add_property(obj, "App::PropertyInteger", name, "Result", tooltip, 0, read_only=True,
                     output=True)


def store_cage(obj, mesh):
    """Write a PolyMesh into the cage properties (the vertices last: they are watched)."""
    from core.mesh_topology import polymesh_summary
    from polycube_wb.convert import arrays_to_vectors

    obj.CageFaceVertices = np.asarray(mesh.face_vertices, dtype=int).tolist()
    obj.CageFaceOffsets = np.asarray(mesh.face_offsets, dtype=int).tolist()
    obj.CageCreases = (np.asarray(mesh.creases, dtype=int).reshape(-1).tolist()
                       if mesh.n_creases else [])
    summary = polymesh_summary(mesh)
    obj.Faces, obj.Vertices = summary["faces"], summary["vertices"]
    obj.ExtraordinaryVertices, obj.Genus = summary["extraordinary_vertices"], summary["genus"]
    obj.CageVertices = arrays_to_vectors(mesh.vertices)


def read_cage(obj):
    """The PolyMesh stored on ``obj``.

    Documents saved before ``CageCreases`` existed get it empty on restore (no creases, as
    their cages had).

    Raises
    ------
    StageFailed
        No cage is stored, or its lists do not fit together.
    """
    from core.types import PolyMesh
    from polycube_wb.convert import vectors_to_array

    vertices = vectors_to_array(obj.CageVertices)
    face_vertices = np.asarray(obj.CageFaceVertices, dtype=np.int64)
    offsets = np.asarray(obj.CageFaceOffsets, dtype=np.int64)
    if (len(vertices) == 0 or len(offsets) < 2 or offsets[0] != 0
            or offsets[-1] != len(face_vertices) or np.any(np.diff(offsets) < 3)
            or face_vertices.min() < 0 or face_vertices.max() >= len(vertices)):
        raise StageFailed(f"{obj.Label}: no valid cage is stored ({len(vertices)} vertices, "
                          f"{max(len(offsets) - 1, 0)} faces); recompute it")
    creases = np.asarray(obj.CageCreases, dtype=np.int64)
    if len(creases) % 2 or (len(creases) and (creases.min() < 0
                                              or creases.max() >= len(vertices))):
        raise StageFailed(f"{obj.Label}: its stored crease tags ({len(creases)} numbers) do "
                          f"not name vertex pairs of its cage; recompute it")
    return PolyMesh(vertices, face_vertices, offsets,
                    creases.reshape(-1, 2) if len(creases) else None)


def cage_edges(mesh):
    """(e, 2) int64 vertex pairs of the cage's edges, each edge once."""
    from core.subdivision.catmull_clark import mesh_topology

    return mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices)).edges


def cage_shape(mesh):
    """``Part.Compound``: the cage's vertices (in order), then its edges."""
    points = [FreeCAD.Vector(*p) for p in np.asarray(mesh.vertices, dtype=float).tolist()]
    vertices = [Part.Vertex(p) for p in points]
    edges = [Part.LineSegment(points[a], points[b]).toShape()
             for a, b in cage_edges(mesh).tolist()]
    return Part.Compound(vertices + edges)


def vertex_indices(sub_names):
    """Cage vertex indices from selected sub-element names (``Vertex1`` -> 0, ...).

    Sub-elements that are not among the first ``Vertexes`` (edge ends) are ignored by
    the caller, which knows the cage size.
    """
    return sorted({int(name[6:]) - 1 for name in sub_names
                   if name.startswith("Vertex") and name[6:].isdigit()})
