# SPDX-License-Identifier: LGPL-2.1-or-later
"""The only bridge between numpy arrays and FreeCAD objects.

Arrays are validated here before they reach FreeCAD's C++ code, because bad input
there can crash the process instead of raising (``Mesh.Mesh`` given tuples of points
segfaults in FreeCAD 0.20.2; it is safe with ``FreeCAD.Vector`` points).

Large meshes cross the bridge as FreeCAD's own binary mesh file (``.bms``, the kernel's
points and facets with their neighbours) written and parsed with numpy
(``polycube_wb.mesh_binary``): building a
``Mesh.Mesh`` from Python lists, or reading its ``Topology``, holds the GUI thread for about a
second on a mesh of 150,000 triangles, reading or writing the binary file a few hundredths.
"""
from itertools import chain

import numpy as np

import FreeCAD
import Mesh
import MeshPart

from core.errors import InvalidMeshError, ParameterError
from core.geometry import validate_triangles
from polycube_wb.file_bytes import bytes_written_by, read_from_bytes
from polycube_wb.mesh_binary import binary_mesh, binary_mesh_arrays


def arrays_to_vectors(points):
    """List of ``FreeCAD.Vector`` from (n, 3) finite float coordinates."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise ParameterError(f"points must be a finite (n, 3) array, got shape {points.shape}")
    return [FreeCAD.Vector(*p) for p in points.tolist()]


def vectors_to_array(vectors):
    """(n, 3) float64 array from a sequence of ``FreeCAD.Vector`` (or 3-sequences)."""
    count = 3 * len(vectors)
    return np.fromiter(chain.from_iterable(vectors), np.float64, count).reshape(-1, 3)


def arrays_to_mesh(V, F, binary=None):
    """``Mesh.Mesh`` with exactly the given vertices and triangles.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    binary : bytes, optional: ``polycube_wb.mesh_binary.binary_mesh(V, F)``, made beforehand
        (by the GUI's stage process, which reads the mesh file); made here when None.

    Returns
    -------
    Mesh.Mesh
        ``CountPoints == n`` and ``CountFacets == m``, same vertex order and indices.

    Raises
    ------
    InvalidMeshError
        Bad arrays (see ``core.geometry.validate_triangles``), or triangles repeating a vertex index
        (``degenerate_faces``), which FreeCAD would drop silently.
    """
    V, F = validate_triangles(V, F)
    repeated = np.flatnonzero((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2]))
    if len(repeated):
        raise InvalidMeshError(f"mesh: {len(repeated)} triangles repeat a vertex index, "
                               f"e.g. faces {repeated[:5].tolist()}", "degenerate_faces",
                               len(repeated), repeated[:5])
    data = binary_mesh(V, F) if binary is None else binary
    if data is not None:
        mesh = _read_binary_mesh(data)
    else:
        mesh = Mesh.Mesh((arrays_to_vectors(V), [tuple(f) for f in F.tolist()]))
    if mesh.CountPoints != len(V) or mesh.CountFacets != len(F):
        raise InvalidMeshError(f"FreeCAD changed the mesh: {len(V)} -> {mesh.CountPoints} "
                               f"points, {len(F)} -> {mesh.CountFacets} facets", "format")
    return mesh


def mesh_to_arrays(mesh):
    """(V (n, 3) float64, F (m, 3) int64) from a ``Mesh.Mesh`` (its placement applied), the
    same arrays as its ``Topology`` gives."""
    if not mesh.Placement.isIdentity():
        points, facets = mesh.Topology
        return vectors_to_array(points), _triangle_array(facets)
    return binary_mesh_arrays(bytes_written_by(mesh.write, "mesh.bms"))


def _read_binary_mesh(data):
    """``Mesh.Mesh`` read from the bytes of a binary mesh file."""
    mesh = Mesh.Mesh()
    read_from_bytes(data, "mesh.bms", mesh.read)
    return mesh


def shape_to_arrays(shape, tolerance, angular_deflection=0.5):
    """Triangulate a Part shape's faces.

    Uses ``MeshPart.meshFromShape`` (OpenCascade's BRepMesh with an absolute linear
    deflection): in FreeCAD 0.20.2 ``Shape.tessellate`` produces about ten times more
    triangles for the same tolerance and is far slower.

    Parameters
    ----------
    shape : Part.Shape
    tolerance : float
        Maximum linear deviation from the surfaces, model units, > 0.
    angular_deflection : float
        Maximum angle between neighbouring triangles' normals along a face, radians.

    Returns
    -------
    V : (n, 3) float64
        Vertices; faces sharing a B-rep edge share its vertices.
    F : (m, 3) int64
        Triangles, oriented with the B-rep faces (outward for an outward solid).
    """
    tolerance = float(tolerance)
    if not np.isfinite(tolerance) or tolerance <= 0:
        raise ParameterError(f"tessellation tolerance must be a positive number, got {tolerance}")
    if not 0 < angular_deflection <= np.pi:
        raise ParameterError(f"angular deflection must be in (0, pi], got {angular_deflection}")
    if shape.isNull():
        raise ParameterError("cannot tessellate a null shape")
    mesh = MeshPart.meshFromShape(Shape=shape, LinearDeflection=tolerance,
                                  AngularDeflection=float(angular_deflection), Relative=False)
    return mesh_to_arrays(mesh)


def _triangle_array(facets):
    """(m, 3) int64 array from a sequence of index triples."""
    count = 3 * len(facets)
    return np.fromiter(chain.from_iterable(facets), np.int64, count).reshape(-1, 3)
