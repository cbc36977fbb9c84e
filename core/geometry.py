# SPDX-License-Identifier: LGPL-2.1-or-later
"""Triangle-mesh geometry shared by every stage: face cross products and areas, volumes,
and the radius classes of k-d tree searches (topology tables are in ``core.mesh_topology``)."""
import numpy as np


def radius_classes(radius, max_classes=12):
    """Group triangles by bounding radius in halving classes for k-d tree searches.

    Class ``k`` holds radii in ``(r_max / 2^(k+1), r_max / 2^k]``; the last class takes
    everything smaller. Searching each class with its own largest radius keeps a few large
    triangles from widening the search for all.

    Parameters
    ----------
    radius : (t,) float64 bounding radius of each triangle (model units).
    max_classes : int, at most this many classes.

    Returns
    -------
    list of (k_i,) int64 index arrays, together a partition of ``range(t)``.
    """
    r_max = radius.max()
    if not r_max > 0:
        return [np.arange(len(radius))]
    level = np.floor(-np.log2(np.maximum(radius, np.finfo(float).tiny) / r_max))
    level = np.minimum(level, max_classes - 1).astype(np.int64)
    return [np.flatnonzero(level == value) for value in np.unique(level)]


def face_cross(vertices, faces):
    """(m, 3) float64 ``(b - a) x (c - a)`` of each triangle: its normal times twice its area.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 (counter-clockwise seen from outside).
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def face_areas(vertices, faces):
    """(m,) float64 triangle areas (model units squared)."""
    return 0.5 * np.linalg.norm(face_cross(vertices, faces), axis=1)


def triangle_signed_volumes(vertices, faces):
    """(m,) float64 signed volume of the tetrahedron (origin, a, b, c) of each triangle.

    Their sum over a closed, outward-oriented mesh is its enclosed volume (divergence
    theorem); summed per component they give each component's volume.
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    return np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])) / 6.0


def triangle_mesh_volume(vertices, faces):
    """Enclosed volume of a closed, outward-oriented triangle mesh (float, units cubed).

    The tetrahedra are taken from the vertex centroid, which keeps the sum accurate far
    from the origin (:func:`triangle_signed_volumes` of the centred mesh).
    """
    V = np.asarray(vertices, dtype=np.float64)
    return float(triangle_signed_volumes(V - V.mean(axis=0), faces).sum())


def triangulate(face_vertices, face_offsets):
    """Fan triangulation of a CSR polygon mesh (``core.types.PolyMesh`` layout).

    Parameters
    ----------
    face_vertices : (k,) int64
    face_offsets : (m + 1,) int64

    Returns
    -------
    (t, 3) int64 triangles ``(c0, c_j, c_{j+1})`` of every face, same orientation; quads
    give ``(0, 1, 2), (0, 2, 3)``; faces of size n give n - 2 triangles, in face order.
    """
    fv = np.asarray(face_vertices, dtype=np.int64)
    fo = np.asarray(face_offsets, dtype=np.int64)
    sizes = np.diff(fo)
    count = np.maximum(sizes - 2, 0)
    face = np.repeat(np.arange(len(sizes)), count)
    j = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + 1
    start = fo[face]
    return np.stack([fv[start], fv[start + j], fv[start + j + 1]], axis=1)


def polymesh_volume(vertices, face_vertices, face_offsets):
    """Enclosed volume of a closed, outward polygon mesh, faces fan-triangulated (float).

    Parameters
    ----------
    vertices : (n, 3) float64; face_vertices, face_offsets : CSR faces (``PolyMesh``).
    """
    return triangle_mesh_volume(vertices, triangulate(face_vertices, face_offsets))


def unit_face_normals(vertices, faces):
    """(m, 3) float64 unit normals of the triangles, zero rows for zero-area triangles.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 (counter-clockwise seen from outside).
    """
    cross = face_cross(vertices, faces)
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    return np.divide(cross, length, out=np.zeros_like(cross), where=length > 0)
