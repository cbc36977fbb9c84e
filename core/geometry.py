# SPDX-License-Identifier: LGPL-2.1-or-later
"""Triangle-mesh geometry shared by every stage: the checked arrays of a triangle mesh, face
cross products and areas, volumes, and the radius classes of k-d tree searches (topology
tables are in ``core.mesh_topology``)."""
import numpy as np

from core.errors import InvalidMeshError


def validate_triangles(V, F, name="mesh"):
    """Check and coerce a triangle mesh's arrays.

    Parameters
    ----------
    V : array_like, (n, 3)
        Vertex coordinates, finite.
    F : array_like, (m, 3)
        Triangle corner indices into ``V``, integers in ``[0, n)``.
    name : str
        What to call the mesh in error messages.

    Returns
    -------
    V : (n, 3) float64, C-contiguous
    F : (m, 3) int64, C-contiguous

    Raises
    ------
    InvalidMeshError
        ``reason`` is ``format`` (wrong shape, dtype or index range), ``empty`` or
        ``non_finite``; the message gives the count and examples.
    """
    V = np.asarray(V)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or not np.issubdtype(V.dtype, np.number):
        raise InvalidMeshError(f"{name}: vertices must be a numeric (n, 3) array, got shape "
                               f"{V.shape} dtype {V.dtype}", "format")
    if F.ndim != 2 or F.shape[1] != 3:
        raise InvalidMeshError(f"{name}: faces must be an (m, 3) array, got shape {F.shape}",
                               "format")
    if len(V) == 0 or len(F) == 0:
        raise InvalidMeshError(f"{name}: mesh is empty ({len(V)} vertices, {len(F)} faces)",
                               "empty")
    integral = np.issubdtype(F.dtype, np.integer) or (
        np.issubdtype(F.dtype, np.floating) and np.all(F == np.round(F)))
    if not integral:
        raise InvalidMeshError(f"{name}: face indices must be integers, got dtype {F.dtype}",
                               "format")
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    bad_v = np.flatnonzero(~np.isfinite(V).all(axis=1))
    if len(bad_v):
        raise InvalidMeshError(f"{name}: {len(bad_v)} vertices have non-finite coordinates, "
                               f"e.g. {bad_v[:5].tolist()}", "non_finite", len(bad_v), bad_v[:5])
    bad_f = np.flatnonzero(((F < 0) | (F >= len(V))).any(axis=1))
    if len(bad_f):
        raise InvalidMeshError(f"{name}: {len(bad_f)} faces index vertices outside [0, {len(V)}), "
                               f"e.g. faces {bad_f[:5].tolist()}", "format", len(bad_f),
                               bad_f[:5])
    return V, F


def scatter_add(index, values, n):
    """(n, 3) float64 sums of the rows of ``values`` ((p, 3)) by ``index`` ((p,) int64).

    The unbuffered ``np.add.at`` of numpy 1.24 is several times slower than one
    ``np.bincount`` per coordinate.
    """
    return np.stack([np.bincount(index, weights=values[:, k], minlength=n)
                     for k in range(values.shape[1])], axis=1)


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


def sample_surface(V, F, count, rng):
    """Uniform area-weighted random points on a triangle mesh.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
    count : int
    rng : numpy.random.Generator

    Returns
    -------
    (count, 3) float64
    """
    tri = V[F]
    area = face_areas(V, F)
    total = area.sum()
    if not total > 0:
        raise InvalidMeshError("mesh has zero surface area", "degenerate_faces", len(F))
    face = rng.choice(len(F), size=count, p=area / total)
    a, b = rng.random((2, count))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    t = tri[face]
    return t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])


def shortest_edges_at(vertices, edges):
    """(n,) float64 length of the shortest of ``edges`` ((e, 2) int vertex pairs) at every
    vertex of ``vertices`` ((n, 3), model units); inf at a vertex on none of them."""
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    shortest = np.full(len(vertices), np.inf)
    np.minimum.at(shortest, edges[:, 0], length)
    np.minimum.at(shortest, edges[:, 1], length)
    return shortest


def bisect_long_triangles(vertices, faces, longest, most):
    """Long triangles cut, by halving their longest edge again and again, into pieces whose
    edges are at most ``longest`` long.

    The pieces cover each triangle exactly (a midpoint is not shared with the neighbour
    across the halved edge: the pieces are a soup, for a search tree, not a mesh).

    Parameters
    ----------
    vertices : (n, 3) float64, model units.
    faces : (m, 3) int64
    longest : float > 0, model units.
    most : int, largest number of pieces.

    Returns
    -------
    (vertices, pieces, owner) : (n', 3) float64 the vertices followed by the midpoints,
        (p, 3) int64 the pieces (each oriented as its triangle), (p,) int64 the triangle
        each piece lies in; None when the pieces would be more than ``most``.
    """
    points, count = [vertices], len(vertices)
    done, done_owner = [], []
    active, owner = faces, np.arange(len(faces))
    total = len(faces)
    while len(active):
        P = np.concatenate(points) if len(points) > 1 else vertices
        corner = P[active]
        edge = np.linalg.norm(np.roll(corner, -1, axis=1) - corner, axis=2)
        cut = edge.max(axis=1) > longest
        done.append(active[~cut])
        done_owner.append(owner[~cut])
        active, owner, first = active[cut], owner[cut], edge[cut].argmax(axis=1)
        total += len(active)
        if total > most:
            return None
        a, b, c = (active[np.arange(len(active)), (first + k) % 3] for k in range(3))
        middle = count + np.arange(len(active))
        points.append(0.5 * (P[a] + P[b]))
        count += len(active)
        active = np.concatenate([np.stack([a, middle, c], axis=1),
                                 np.stack([middle, b, c], axis=1)])
        owner = np.concatenate([owner, owner])
    return np.concatenate(points), np.concatenate(done), np.concatenate(done_owner)


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


def morton_codes(points):
    """(n,) int64 Z-order codes of points quantised to 2^10 cells per axis (bit ``b`` of
    axis ``a``'s cell at bit ``3 b + a``)."""
    low = points.min(axis=0)
    span = np.maximum(points.max(axis=0) - low, 1e-300)
    cells = np.minimum(((points - low) / span * 1024).astype(np.int64), 1023)
    code = np.zeros(len(points), dtype=np.int64)
    for axis in range(3):
        code |= _spread_bits(cells[:, axis]) << axis
    return code


def _spread_bits(values):
    """(n,) int64 the ten low bits of ``values`` ((n,) int64) moved from bit ``b`` to bit
    ``3 b`` (two zero bits between each)."""
    values = values & 0x3FF
    for shift, mask in ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249)):
        values = (values | (values << shift)) & mask
    return values
