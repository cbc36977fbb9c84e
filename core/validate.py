# SPDX-License-Identifier: LGPL-2.1-or-later
"""Intake validation of target meshes: every check the pipeline relies on, once, up front.

Each failed check raises ``InvalidMeshError`` naming what is wrong, how many items,
and an example (index and coordinates). Repairs are made only where they are
unambiguous and are listed, with their counts and places, in the returned summary:
always merging coincident vertices and orienting an orientable surface outwards; unless
``repair=False``, also removing faces with coincident corners, duplicate faces and
zero-area faces and smoothing out a few intersecting faces (:mod:`core.mesh_repair`).
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.errors import InvalidMeshError, ParameterError
from core.geometry import triangle_signed_volumes
from core.mesh_repair import (Repair, collapse_zero_area_faces, degenerate_face_mask,
                              drop_collapsed_faces, format_point, remove_duplicate_faces,
                              resolve_self_intersections)
from core.mesh_topology import directed_edges, genus_of, unique_edges
from core.polymesh_checks import check_coordinate_range
from core.self_intersection import find_self_intersections
from core.tolerances import MERGE
from core.types import TriMesh

COMPONENT_POLICIES = ("largest", "all", "error")


def check_finite(vertices, name="mesh"):
    """Raise ``non_finite`` if any coordinate is NaN or infinite."""
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        idx = np.flatnonzero(bad)
        raise InvalidMeshError(
            f"{name}: {len(idx)} vertices have NaN or infinite coordinates, "
            f"e.g. vertex {idx[0]} = {format_point(vertices[idx[0]])}",
            reason="non_finite", count=len(idx), examples=idx[:5].tolist())


def _unique_rows(rows):
    """First occurrence of each distinct row and the row -> distinct-row map.

    rows : (n, k) int64. Returns ``first (u,) int64`` (index of each distinct row's first
    occurrence, in lexicographic order of the rows) and ``inverse (n,) int64``. Faster than
    ``np.unique(axis=0)``, which sorts a structured view.
    """
    order = np.lexsort(rows.T[::-1])
    ordered = rows[order]
    new = np.ones(len(rows), dtype=bool)
    new[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    group = np.cumsum(new) - 1
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = group
    first = np.full(int(group[-1]) + 1 if len(rows) else 0, len(rows), dtype=np.int64)
    np.minimum.at(first, group, order)
    return first, inverse


def merge_identical_vertices(vertices, faces):
    """Merge vertices that coincide up to ``core.tolerances.MERGE`` and drop unreferenced ones.

    Returns
    -------
    vertices : (n', 3) float64, in order of first use by the faces.
    faces : (m, 3) int64 re-indexed.
    n_merged : int, how many input vertices were merged away or dropped.
    """
    first_of_key, inverse = _unique_rows(_merge_grid(vertices))
    unique = vertices[first_of_key]
    faces = inverse.reshape(-1)[faces]
    used, first = np.unique(faces.reshape(-1), return_index=True)
    order = used[np.argsort(first, kind="stable")]
    remap = np.full(len(unique), -1, dtype=np.int64)
    remap[order] = np.arange(len(order))
    return unique[order], remap[faces], len(vertices) - len(order)


def _merge_grid(vertices):
    """(n, 3) int64 cells of the ``MERGE * diagonal`` grid: vertices in one cell are merged."""
    diag = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0
    return np.round(vertices / (MERGE * diag)).astype(np.int64)


def near_duplicate_vertices(vertices):
    """(k, 3) float64 distinct coordinates that :func:`merge_identical_vertices` merges with
    other coordinates (vertices within ``MERGE`` of the diagonal, not bit-identical)."""
    distinct = vertices[_unique_rows(np.ascontiguousarray(vertices).view(np.int64))[0]]
    _, cell = _unique_rows(_merge_grid(distinct))
    return distinct[np.bincount(cell)[cell] > 1]


def _drop_unused_vertices(vertices, faces):
    used, faces = np.unique(faces, return_inverse=True)
    return vertices[used], faces.reshape(-1, 3)


def check_degenerate_faces(vertices, faces, name="mesh"):
    """Raise ``degenerate_faces`` for faces with a repeated vertex or (near) zero area."""
    tri = vertices[faces]
    bad = degenerate_face_mask(vertices, faces)
    if bad.any():
        idx = np.flatnonzero(bad)
        f = idx[0]
        raise InvalidMeshError(
            f"{name}: {len(idx)} degenerate (zero-area) faces, e.g. face {f} with corners "
            f"{faces[f].tolist()} at {format_point(tri[f].mean(axis=0))}",
            reason="degenerate_faces", count=len(idx), examples=idx[:5].tolist())


def check_duplicate_faces(vertices, faces, name="mesh"):
    """Raise ``duplicate_faces`` for faces using the same three vertices as another face."""
    first, _ = _unique_rows(np.sort(faces, axis=1))
    keep = np.zeros(len(faces), dtype=bool)
    keep[first] = True
    idx = np.flatnonzero(~keep)
    if len(idx):
        f = idx[0]
        raise InvalidMeshError(
            f"{name}: {len(idx)} duplicate faces, e.g. face {f} repeats vertices "
            f"{faces[f].tolist()} at {format_point(vertices[faces[f]].mean(axis=0))}",
            reason="duplicate_faces", count=len(idx), examples=idx[:5].tolist())


def check_edges(vertices, faces, name="mesh"):
    """Raise ``open`` for boundary edges and ``non_manifold`` for edges with > 2 faces."""
    edges, he_edge = unique_edges(faces)
    count = np.bincount(he_edge, minlength=len(edges))
    for wanted, reason, what in ((count == 1, "open", "boundary edges (the mesh is not closed)"),
                                 (count > 2, "non_manifold", "non-manifold edges (shared by more than two faces)")):
        if wanted.any():
            idx = np.flatnonzero(wanted)
            a, b = edges[idx[0]]
            face = int(np.flatnonzero(he_edge == idx[0])[0] // 3)
            raise InvalidMeshError(
                f"{name}: {len(idx)} {what}, e.g. edge ({a}, {b}) of face {face} at "
                f"{format_point((vertices[a] + vertices[b]) / 2)}",
                reason=reason, count=len(idx), examples=[tuple(map(int, edges[i])) for i in idx[:5]])


def _paired_halfedges(faces):
    """Half-edges (see ``directed_edges``) and, per edge, its two half-edge indices.

    Assumes every edge has exactly two faces. Returns ``(half (3m, 2), h1 (e,), h2 (e,))``;
    half-edge ``h`` belongs to face ``h // 3``.
    """
    _, he_edge = unique_edges(faces)
    order = np.argsort(he_edge, kind="stable")
    return directed_edges(faces), order[0::2], order[1::2]


def check_manifold_vertices(vertices, faces, name="mesh"):
    """Raise ``non_manifold`` for vertices whose faces form more than one fan.

    Assumes every edge has exactly two faces (run :func:`check_edges` first).
    """
    m = len(faces)
    half, h1, h2 = _paired_halfedges(faces)
    f1, f2 = h1 // 3, h2 // 3
    corner_of = np.full((m, 3), -1, dtype=np.int64)
    corner_of[:] = np.arange(3 * m).reshape(m, 3)

    def corner(face, vertex):
        position = np.argmax(faces[face] == vertex[:, None], axis=1)
        return corner_of[face, position]

    links = []
    for end in (0, 1):
        v = half[h1, end]
        links.append((corner(f1, v), corner(f2, v)))
    rows = np.concatenate([a for a, _ in links])
    cols = np.concatenate([b for _, b in links])
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
    _, fan = connected_components(graph, directed=False)
    corner_vertex = faces.reshape(-1)
    first, _ = _unique_rows(np.stack([corner_vertex, fan], axis=1))
    fans_per_vertex = np.bincount(corner_vertex[first], minlength=len(vertices))
    bad = np.flatnonzero(fans_per_vertex > 1)
    if len(bad):
        v = bad[0]
        raise InvalidMeshError(
            f"{name}: {len(bad)} non-manifold vertices (two surface sheets touch at a point), "
            f"e.g. vertex {v} at {format_point(vertices[v])}",
            reason="non_manifold", count=len(bad), examples=bad[:5].tolist())


def orient_consistently(vertices, faces, name="mesh"):
    """Make the winding consistent and the normals point outwards.

    Every edge must have two faces. Returns ``(faces (m, 3) int64, flipped (m,) bool)``,
    the faces whose winding was reversed. Raises
    ``orientation`` if the surface is not orientable (no consistent winding exists).
    """
    m = len(faces)
    half, h1, h2 = _paired_halfedges(faces)
    f1, f2 = h1 // 3, h2 // 3
    same_direction = (half[h1, 0] == half[h2, 0]).astype(np.int8)
    flip = np.zeros(m, dtype=np.int8)
    if same_direction.any():
        flip = _solve_flip_parity(m, f1, f2, same_direction)
        if ((flip[f1] ^ flip[f2]) != same_direction).any():
            raise InvalidMeshError(
                f"{name}: the surface is not orientable (no consistent face winding exists)",
                reason="orientation", count=int(same_direction.sum()))
    faces = np.where(flip[:, None].astype(bool), faces[:, ::-1], faces)
    _, component = connected_components(_face_graph(m, f1, f2), directed=False)
    volume = np.bincount(component, weights=triangle_signed_volumes(vertices, faces))
    inward = volume[component] < 0
    faces = np.where(inward[:, None], faces[:, ::-1], faces)
    return faces, flip.astype(bool) ^ inward


def _face_graph(m, f1, f2):
    return sp.coo_matrix((np.ones(len(f1)), (f1, f2)), shape=(m, m)).tocsr()


def _solve_flip_parity(m, f1, f2, same_direction):
    """Per-face flip bit so that adjacent faces agree, from a spanning forest (vectorised).

    Walks each face to its tree root by pointer doubling, accumulating the xor of the
    ``same_direction`` bits along the tree edges.
    """
    from scipy.sparse.csgraph import breadth_first_order

    weights = sp.coo_matrix((same_direction.astype(np.float64) + 1.0, (f1, f2)), shape=(m, m)).tocsr()
    weights = weights.maximum(weights.T)
    _, component = connected_components(weights, directed=False)
    _, roots = np.unique(component, return_index=True)
    parent = np.arange(m)
    bit = np.zeros(m, dtype=np.int8)
    for root in roots:
        nodes, pred = breadth_first_order(weights, root, directed=False, return_predecessors=True)
        child = nodes[1:]
        parent[child] = pred[child]
        bit[child] = (np.asarray(weights[child, pred[child]]).reshape(-1) - 1.0).astype(np.int8)
    while True:
        grand = parent[parent]
        if np.array_equal(grand, parent):
            return bit
        bit = bit ^ bit[parent]
        parent = grand


def select_components(vertices, faces, policy, name="mesh"):
    """Apply the multiple-components policy.

    Returns ``(vertices, faces, n_components_in_input, warnings)``.
    """
    if policy not in COMPONENT_POLICIES:
        raise ParameterError(f"components must be one of {', '.join(COMPONENT_POLICIES)}, got {policy!r}")
    from core.mesh_topology import connected_face_components

    component = connected_face_components(faces)
    n = int(component.max()) + 1
    if n == 1 or policy == "all":
        return vertices, faces, n, []
    volume = np.abs(np.bincount(component, weights=triangle_signed_volumes(vertices, faces)))
    largest = int(np.argmax(volume))
    if policy == "error":
        others = [c for c in range(n) if c != largest]
        f = int(np.flatnonzero(component == others[0])[0])
        raise InvalidMeshError(
            f"{name}: {n} separate components (expected one solid), e.g. face {f} at "
            f"{format_point(vertices[faces[f]].mean(axis=0))} is not connected to the largest one; "
            "use components='largest' to keep only the largest",
            reason="multiple_components", count=n, examples=[f])
    keep = component == largest
    dropped = int((~keep).sum())
    vertices, faces, _ = merge_identical_vertices(vertices, faces[keep])
    return vertices, faces, n, [f"kept the largest of {n} components by volume; "
                                f"dropped {dropped} faces of the other {n - 1}"]


def validate_target(vertices, faces, components="largest", check_self_intersections=True,
                    name="mesh", unit_to_mm=1.0, repair=True):
    """Validate raw triangle data and return a clean closed mesh plus a summary.

    Parameters
    ----------
    vertices : (n, 3) array_like of float
    faces : (m, 3) array_like of int
    components : {'largest', 'all', 'error'}
        What to do when the mesh has several connected components.
    check_self_intersections : bool
        Run the triangle-triangle intersection test (on by default).
    name : str
        Used in error messages (usually the file name).
    unit_to_mm : float
        Millimetres per unit of ``vertices``: the coordinates in millimetres must suit a
        B-rep (``core.polymesh_checks.check_coordinate_range``).
    repair : bool
        Repair faces with coincident corners, duplicate and zero-area faces and a few
        intersecting faces (:mod:`core.mesh_repair`); False refuses them.

    Returns
    -------
    mesh : TriMesh, watertight, 2-manifold, outward oriented.
    summary : dict, JSON-serialisable: triangles, vertices, genus, components,
        bbox_diagonal, volume, merged_vertices, reoriented_faces, repairs (one entry per
        kind of repair: kind, count, action, bbox_min, bbox_max and places in the file's
        units, largest_move; see ``core.mesh_repair.Repair``), warnings (list of str).

    Raises
    ------
    InvalidMeshError
        See ``InvalidMeshError.reason`` for the kinds.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise InvalidMeshError(f"{name}: the mesh has no faces", reason="empty")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InvalidMeshError(f"{name}: face indices outside 0..{len(vertices) - 1}", reason="unreadable")
    n_input_vertices = len(vertices)
    vertices, faces = _drop_unused_vertices(vertices, faces)
    check_finite(vertices, name)
    check_coordinate_range(vertices, f"{name}:", "scale the mesh or give its --units",
                           unit_to_mm)
    repairs = []
    near = near_duplicate_vertices(vertices)
    if len(near):
        repairs.append(Repair.around(
            "near_duplicate_vertices", len(near),
            f"merged {len(near)} vertices lying within {MERGE:g} of the diagonal of another",
            near))
    vertices, faces, _ = merge_identical_vertices(vertices, faces)
    merged = n_input_vertices - len(vertices)
    if repair:
        faces, done = drop_collapsed_faces(vertices, faces)
        repairs.append(done)
        if len(faces):
            faces, done = remove_duplicate_faces(vertices, faces, name)
            repairs.append(done)
        if len(faces) == 0:
            raise InvalidMeshError(f"{name}: every face has coincident corners", reason="degenerate_faces",
                                   count=merged)
        vertices, faces = _drop_unused_vertices(vertices, faces)
    else:
        check_degenerate_faces(vertices, faces, name)
        check_duplicate_faces(vertices, faces, name)
    check_edges(vertices, faces, name)
    check_manifold_vertices(vertices, faces, name)
    faces, flipped = orient_consistently(vertices, faces, name)
    if flipped.any():
        repairs.append(Repair.around(
            "reoriented_faces", int(flipped.sum()),
            f"re-oriented {int(flipped.sum())} faces so that all normals point outwards "
            "(the fix is unambiguous for a closed orientable surface)", vertices[faces[flipped]]))
    if repair:
        vertices, faces, done = collapse_zero_area_faces(vertices, faces, name)
        repairs.append(done)
    vertices, faces, n_components, component_warnings = select_components(
        vertices, faces, components, name)
    if check_self_intersections:
        pairs = find_self_intersections(vertices, faces)
        if len(pairs) and repair:
            vertices, done = resolve_self_intersections(vertices, faces, pairs, name)
            repairs.append(done)
            pairs = find_self_intersections(vertices, faces)
        if len(pairs):
            a, b = pairs[0]
            raise InvalidMeshError(
                f"{name}: {len(pairs)} pairs of intersecting faces, e.g. faces {a} and {b} near "
                f"{format_point(vertices[faces[a]].mean(axis=0))}",
                reason="self_intersecting", count=len(pairs), examples=[tuple(map(int, p)) for p in pairs[:5]])
    repairs = [done for done in repairs if done is not None]
    kept_components = n_components if components == "all" else 1
    summary = {
        "triangles": int(len(faces)),
        "vertices": int(len(vertices)),
        "genus": genus_of(len(vertices), faces, kept_components),
        "components": int(n_components),
        "bbox_diagonal": float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))),
        "volume": float(triangle_signed_volumes(vertices, faces).sum()),
        "merged_vertices": int(merged),
        "reoriented_faces": int(flipped.sum()),
        "repairs": [done.to_report() for done in repairs],
        "warnings": [done.message() for done in repairs if done.kind != "near_duplicate_vertices"]
        + component_warnings,
    }
    return TriMesh(vertices, faces), summary
