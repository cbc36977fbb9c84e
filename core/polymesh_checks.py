# SPDX-License-Identifier: LGPL-2.1-or-later
"""Validation of closed polygon base meshes (subdivision cages).

:func:`check_polymesh` raises :class:`core.errors.InvalidMeshError` naming the first
problem found, how many items have it and a few examples; it returns nothing.
"""
import numpy as np
from scipy.sparse.csgraph import connected_components
import scipy.sparse as sp

from core.errors import InvalidMeshError
from core.geometry import polymesh_volume
from core.mesh_topology import next_corners, previous_corners
from core.tolerances import BREP_MM, ZERO_AREA

MAX_EXPORT_COORDINATE = 1e7
"""Largest |coordinate| (mm) of a cage exported to a B-rep: there a float64 still resolves
steps of 2e-9, well below the B-rep tolerance (``core.tolerances.BREP_MM``, 1e-7)."""
MIN_EXPORT_DIAGONAL = 1e-3
"""Smallest bounding-box diagonal (mm) of an exported cage: 10,000 times the B-rep tolerance."""


def _fail(what, reason, bad, examples):
    bad = np.asarray(bad)
    count = int(bad.sum()) if bad.dtype == bool else int(len(bad))
    ex = [e.tolist() if hasattr(e, "tolist") else e for e in list(examples)[:5]]
    raise InvalidMeshError(f"base mesh {what}: {count} found, e.g. {ex}", reason=reason,
                           count=count, examples=ex)


def check_polymesh(mesh):
    """Check that ``mesh`` is a closed, 2-manifold, consistently outward-oriented polygon mesh.

    Parameters
    ----------
    mesh : core.types.PolyMesh

    Raises
    ------
    InvalidMeshError
        with ``reason`` one of ``empty`` (no faces or vertices), ``format`` (bad
        offsets or vertex indices out of range), ``unused_vertices`` (a vertex in no
        face), ``non_finite`` (NaN/inf
        coordinates), ``degenerate_faces`` (fewer than 3 corners, a repeated corner or
        zero area), ``open`` (an edge with one face), ``non_manifold`` (an edge with
        more than two faces, or a vertex whose faces form several fans),
        ``orientation`` (neighbouring faces disagree, or all faces point inward),
        ``crease_not_edge`` (a pair of ``mesh.creases`` that is not an edge).
    """
    V = np.asarray(mesh.vertices, dtype=np.float64)
    fv = np.asarray(mesh.face_vertices, dtype=np.int64)
    fo = np.asarray(mesh.face_offsets, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0 or len(fo) < 2 or len(fv) == 0:
        raise InvalidMeshError("base mesh is empty: it needs vertices (n, 3) and faces",
                               reason="empty")
    if fo[0] != 0 or fo[-1] != len(fv) or (np.diff(fo) < 0).any():
        raise InvalidMeshError("base mesh face offsets do not describe face_vertices",
                               reason="format")
    out_of_range = (fv < 0) | (fv >= len(V))
    if out_of_range.any():
        _fail("has corner indices outside 0..n_vertices-1", "format",
              out_of_range, np.flatnonzero(out_of_range))
    finite = np.isfinite(V).all(axis=1)
    if not finite.all():
        _fail("has vertices with NaN or infinite coordinates", "non_finite", ~finite,
              np.flatnonzero(~finite))
    sizes = np.diff(fo)
    small = sizes < 3
    if small.any():
        _fail("has faces with fewer than 3 corners", "degenerate_faces", small,
              np.flatnonzero(small))
    m = len(sizes)
    face = np.repeat(np.arange(m), sizes)
    key = face * len(V) + fv
    order = np.argsort(key, kind="stable")
    dup = np.zeros(len(fv), dtype=bool)
    dup[order[1:]] = key[order[1:]] == key[order[:-1]]
    if dup.any():
        faces_dup = np.unique(face[dup])
        _fail("has faces that repeat a corner vertex", "degenerate_faces", faces_dup, faces_dup)
    nxt = next_corners(fo)
    newell = np.zeros((m, 3))
    np.add.at(newell, face, np.cross(V[fv], V[fv[nxt]]))
    diag2 = float(np.sum((V.max(axis=0) - V.min(axis=0)) ** 2))
    zero = np.linalg.norm(newell, axis=1) <= ZERO_AREA * max(diag2, 1e-300)
    if zero.any():
        _fail("has faces of zero area", "degenerate_faces", zero, np.flatnonzero(zero))

    a, b = fv, fv[nxt]
    n = np.int64(len(V))
    und = np.minimum(a, b) * n + np.maximum(a, b)
    uniq, counts = np.unique(und, return_counts=True)
    edges = np.stack([uniq // n, uniq % n], axis=1)
    if (counts == 1).any():
        bad = counts == 1
        _fail("is open (edges with a single face)", "open", bad, edges[bad])
    if (counts > 2).any():
        bad = counts > 2
        _fail("has non-manifold edges (more than two faces)", "non_manifold", bad, edges[bad])
    if mesh.n_creases:
        pairs = np.asarray(mesh.creases, dtype=np.int64).reshape(-1, 2)
        outside = (pairs < 0).any(axis=1) | (pairs >= n).any(axis=1)
        keys = np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1])
        bad = outside | ~np.isin(keys, uniq)
        if bad.any():
            _fail("has crease tags on vertex pairs that are not edges", "crease_not_edge", bad,
                  pairs[bad])
    directed = a * n + b
    d_sorted = np.sort(directed)
    same_dir = d_sorted[1:] == d_sorted[:-1]
    if same_dir.any():
        dups = d_sorted[1:][same_dir]
        _fail("has inconsistently oriented neighbouring faces (edges used twice in the "
              "same direction)", "orientation", dups,
              np.stack([dups // n, dups % n], axis=1))
    # vertex fans: rotate half-edges around their start vertex, count cycles per vertex
    order = np.argsort(directed)
    twin_key = b * n + a
    twin = order[np.searchsorted(directed[order], twin_key)]
    rot = twin[previous_corners(fo)]
    graph = sp.coo_matrix((np.ones(len(fv)), (np.arange(len(fv)), rot)),
                          shape=(len(fv), len(fv)))
    _, comp = connected_components(graph, directed=False)
    fans = np.unique(np.stack([fv, comp], axis=1), axis=0)
    fan_count = np.bincount(fans[:, 0], minlength=len(V))
    if (fan_count > 1).any():
        bad = fan_count > 1
        _fail("has non-manifold vertices (faces meet only at the vertex)", "non_manifold",
              bad, np.flatnonzero(bad))
    unused = fan_count == 0
    if unused.any():
        _fail("has vertices used by no face (a vertex of the limit surface needs its faces)",
              "unused_vertices", unused, np.flatnonzero(unused))
    volume = polymesh_volume(V, fv, fo)
    if volume < 0:
        raise InvalidMeshError(
            f"base mesh faces point inward: all {m} faces are clockwise seen from outside "
            f"(enclosed volume {volume:.6g} < 0); reverse the corner order of every face",
            reason="orientation", count=m, examples=[0])


def check_export_range(mesh):
    """Check that a cage's coordinates suit a B-rep with the ``BREP_MM`` tolerance.

    Parameters
    ----------
    mesh : core.types.PolyMesh, finite coordinates in millimetres.

    Raises
    ------
    InvalidMeshError
        ``coordinate_range``, see :func:`check_coordinate_range`.
    """
    check_coordinate_range(mesh.vertices, "base mesh", "scale or move the cage closer to the origin")


def check_coordinate_range(vertices, what, hint, unit_to_mm=1.0):
    """Check that coordinates suit a B-rep with the ``BREP_MM`` tolerance (1e-7 mm).

    Parameters
    ----------
    vertices : (n, 3) float64, finite, in the file's units.
    what : str, what the coordinates belong to, starts the message (``"base mesh"``).
    hint : str, what to do about it, ends the message.
    unit_to_mm : float, millimetres per unit of ``vertices``.

    Raises
    ------
    InvalidMeshError
        ``coordinate_range`` when a coordinate exceeds :data:`MAX_EXPORT_COORDINATE` mm in
        magnitude (the message gives the largest and a vertex having it) or the
        bounding-box diagonal is below :data:`MIN_EXPORT_DIAGONAL` mm.
    """
    V = np.asarray(vertices, dtype=np.float64)
    raw = np.abs(V).max(axis=1)
    with np.errstate(over="ignore"):
        size = raw * unit_to_mm
    if size.max() > MAX_EXPORT_COORDINATE:
        far = np.flatnonzero(size > MAX_EXPORT_COORDINATE)
        scale = " mm" if unit_to_mm == 1.0 else f" x {unit_to_mm:g} = {size.max():.3g} mm"
        raise InvalidMeshError(
            f"{what} coordinates reach {raw.max():.3g}{scale} ({len(far)} vertices beyond "
            f"+-{MAX_EXPORT_COORDINATE:.0e} mm, e.g. vertex {int(np.argmax(size))}): a B-rep with "
            f"tolerance {BREP_MM:g} mm cannot resolve them; {hint}",
            reason="coordinate_range", count=len(far), examples=far[:5].tolist())
    diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) * unit_to_mm
    if diagonal < MIN_EXPORT_DIAGONAL:
        raise InvalidMeshError(
            f"{what} is {diagonal:.3g} mm across (bounding-box diagonal), less than "
            f"{MIN_EXPORT_DIAGONAL:g} mm: too small for a B-rep with tolerance {BREP_MM:g} mm; "
            f"{hint}",
            reason="coordinate_range", count=1, examples=[0])


def check_single_shell(mesh):
    """Check that a closed cage is one connected surface (a solid needs one shell).

    Parameters
    ----------
    mesh : core.types.PolyMesh that passed :func:`check_polymesh`.

    Raises
    ------
    InvalidMeshError
        ``multiple_components`` naming how many pieces and a face of the second one.
    """
    fv = np.asarray(mesh.face_vertices, dtype=np.int64)
    face = np.repeat(np.arange(mesh.n_faces), np.diff(np.asarray(mesh.face_offsets)))
    n = len(mesh.vertices)
    graph = sp.coo_matrix((np.ones(len(fv)), (face, fv)), shape=(mesh.n_faces, n)).tocsr()
    count, piece = connected_components(graph @ graph.T, directed=False)
    if count > 1:
        f = int(np.flatnonzero(piece != piece[0])[0])
        raise InvalidMeshError(
            f"base mesh has {count} separate components (faces sharing no vertex), e.g. face "
            f"{f} is not connected to face 0; a STEP solid needs one closed shell",
            reason="multiple_components", count=count, examples=[f])
