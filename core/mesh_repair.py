# SPDX-License-Identifier: LGPL-2.1-or-later
"""Intake repairs of the local defects that topology-optimisation exports often carry.

A marching-cubes or smoothed TO surface is usually a clean closed 2-manifold with a few
defects: faces whose corners coincide or lie on one line (the iso-surface passing through
a grid point), the same triangle written twice, a few triangles folded through their
neighbours. Each is repaired here where the repair is unambiguous, and each repair is
returned as a :class:`Repair` (what, how many, where) for the report:

- faces whose corners coincide after merging are removed: the merge has already
  collapsed their short edge (:func:`drop_collapsed_faces`);
- duplicate faces are removed, one copy kept, or both copies of a face written with
  both windings (a two-sided sheet of no thickness) (:func:`remove_duplicate_faces`);
- zero-area faces of a closed oriented surface are collapsed (a needle: its shortest
  edge, to its midpoint) or flipped away (a cap: a corner on the opposite edge; the
  flip keeps the surface exactly where it is) (:func:`collapse_zero_area_faces`);
- a few intersecting faces are smoothed out: the vertices around them move to the
  fair (discrete thin-plate) surface spanned by the fixed vertices around, one more
  ring at a time until no pair intersects (:func:`resolve_self_intersections`).

The connectivity changes only by edge collapses and flips that keep the surface closed
and 2-manifold (link condition), so genus and components are kept. What is not
repairable this way (an open or non-manifold mesh, a mostly self-intersecting one)
raises ``InvalidMeshError``; :mod:`core.validate` decides which checks run.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.errors import InvalidMeshError
from core.geometry import face_cross, triangle_signed_volumes
from core.mesh_topology import unique_edges
from core.self_intersection import find_self_intersections
from core.tolerances import ZERO_AREA

REPAIRABLE_DEGENERATE_FRACTION = 0.1
"""Zero-area faces are repaired when they are at most this fraction of the faces; more is a
surface that mostly has no area, not a few defects."""
REPAIRABLE_INTERSECTING_FRACTION = 0.01
"""Self-intersections are repaired when the faces of the intersecting pairs are at most
this fraction of the faces; more is not a local defect but a surface that crosses itself."""
REPAIR_RINGS = 4
"""Most rings of vertices grown around the intersecting faces to smooth them out."""
REPAIRABLE_REGION_FRACTION = 0.05
"""The vertices a self-intersection repair may move, as a fraction of all vertices."""
REPAIR_VOLUME_CHANGE = 0.01
"""A self-intersection repair may change the enclosed volume by at most this fraction."""
MAX_PLACES = 10
"""A repair's report lists the places of at most this many of its items."""
NEEDLE_RATIO = 0.1
"""A zero-area face whose shortest edge is at most this fraction of its longest is a needle
(its shortest edge is collapsed); otherwise it is a cap (its longest edge is flipped)."""


@dataclass(frozen=True)
class Repair:
    """One kind of repair made at intake (an entry of the report's ``input.repairs``).

    kind : ``near_duplicate_vertices``, ``coincident_corners``, ``duplicate_faces``,
        ``reoriented_faces``, ``zero_area_faces`` or ``self_intersections``.
    count : how many items were found (vertices, faces or intersecting face pairs).
    action : what was done, one sentence.
    bbox_min, bbox_max : (3,) tuple of float, corners of the box holding the repaired
        items, in the file's units.
    places : tuple of (3,) tuples, the centres of the first :data:`MAX_PLACES` items.
    largest_move : the farthest any kept vertex moved, in the file's units.
    """

    kind: str
    count: int
    action: str
    bbox_min: tuple
    bbox_max: tuple
    places: tuple
    largest_move: float = 0.0

    @classmethod
    def around(cls, kind, count, action, items, places=None, largest_move=0.0):
        """A repair of the ``items`` ((k, c, 3) float64: the c points of each vertex, face
        or pair; (k, 3) for single points); ``places`` ((p, 3)) default to their centres."""
        items = np.asarray(items, dtype=np.float64)
        items = items.reshape(len(items), -1, 3)
        places = items.mean(axis=1) if places is None else np.asarray(places).reshape(-1, 3)
        flat = items.reshape(-1, 3)
        return cls(kind, int(count), action, tuple(map(float, flat.min(axis=0))),
                   tuple(map(float, flat.max(axis=0))),
                   tuple(tuple(map(float, p)) for p in places[:MAX_PLACES]), float(largest_move))

    def message(self):
        """One line for the warnings: the action and where."""
        moved = f", vertices moved by at most {self.largest_move:.3g}" if self.largest_move else ""
        return (f"{self.action} between {format_point(self.bbox_min)} and "
                f"{format_point(self.bbox_max)}{moved}")

    def to_report(self):
        return {"kind": self.kind, "count": self.count, "action": self.action,
                "bbox_min": list(self.bbox_min), "bbox_max": list(self.bbox_max),
                "places": [list(p) for p in self.places], "largest_move": self.largest_move}


def format_point(point):
    """``(x, y, z)`` with six significant digits."""
    return "(" + ", ".join(f"{c:.6g}" for c in point) + ")"


def diagonal(vertices):
    """Bounding-box diagonal of (n, 3) points (1.0 for a single point)."""
    return float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0


def degenerate_face_mask(vertices, faces, diag=None):
    """(m,) bool: faces with a repeated corner or twice their area at most
    ``ZERO_AREA * diag**2`` (``diag``: the bounding-box diagonal unless given)."""
    diag = diagonal(vertices) if diag is None else diag
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    double_area = np.linalg.norm(face_cross(vertices, faces), axis=1)
    return repeated | (double_area <= ZERO_AREA * diag * diag)


def drop_collapsed_faces(vertices, faces):
    """Remove the faces with a repeated corner (two corners merged into one vertex).

    In a closed mesh whose short edge ``(a, b)`` was merged, its two faces become
    ``(a, a, c)`` and ``(a, a, d)`` and each remaining edge ``(a, c)`` has two faces again:
    removing them is the edge collapse. Whether the result is closed and 2-manifold is
    checked afterwards by the caller.

    Returns ``(faces (m', 3) int64, Repair or None)``.
    """
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    if not repeated.any():
        return faces, None
    count = int(repeated.sum())
    return faces[~repeated], Repair.around(
        "coincident_corners", count,
        f"removed {count} faces whose corners coincide (their zero-length edges collapsed)",
        vertices[faces[repeated]])


def remove_duplicate_faces(vertices, faces, name="mesh"):
    """Remove repeated faces (the same three vertices), keeping the surface closed.

    A face written several times with one winding keeps one copy; a face written as often
    with one winding as with the other is a two-sided sheet of no thickness and all its
    copies go. The repair stands only when every edge of those faces then has exactly
    two faces; otherwise ``InvalidMeshError`` ``duplicate_faces``.

    Returns ``(faces (m', 3) int64, Repair or None)``.
    """
    ordered = np.sort(faces, axis=1)
    _, group, copies = np.unique(ordered, axis=0, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    duplicated = copies[group] > 1
    if not duplicated.any():
        return faces, None
    # a face is "even" when it is a rotation of its sorted corners (one winding)
    even = np.zeros(len(faces), dtype=bool)
    for shift in range(3):
        even |= (np.roll(faces, shift, axis=1) == ordered).all(axis=1)
    n_even = np.bincount(group, weights=even, minlength=len(copies))
    n_odd = copies - n_even
    one_winding = n_even != n_odd  # else a two-sided sheet: every copy goes
    candidate = np.flatnonzero(duplicated & one_winding[group] & (even == (n_even >= n_odd)[group]))
    _, first = np.unique(group[candidate], return_index=True)
    keep = ~duplicated
    keep[candidate[first]] = True
    repaired = faces[keep]
    n_duplicates = int(duplicated.sum() - (copies > 1).sum())
    if not _every_edge_on_two_faces(repaired, faces[duplicated]):
        f = int(np.flatnonzero(~keep)[0])
        raise InvalidMeshError(
            f"{name}: {n_duplicates} duplicate faces, e.g. face {f} repeats vertices "
            f"{faces[f].tolist()} at {format_point(vertices[faces[f]].mean(axis=0))}; removing "
            "them does not leave a closed surface",
            reason="duplicate_faces", count=n_duplicates,
            examples=np.flatnonzero(~keep)[:5].tolist())
    removed = len(faces) - len(repaired)
    return repaired, Repair.around(
        "duplicate_faces", removed,
        f"removed {removed} duplicate faces ({int((copies > 1).sum())} faces were written "
        "more than once)", vertices[faces[~keep]])


def _every_edge_on_two_faces(faces, where):
    """Whether every edge of the faces ``where`` ((k, 3) int64) is an edge of exactly two
    of ``faces`` ((m, 3) int64)."""
    if len(faces) == 0:
        return False
    edges, he_edge = unique_edges(faces)
    count = np.bincount(he_edge, minlength=len(edges))
    wanted = np.sort(np.stack([where, np.roll(where, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    base = int(max(edges.max(), wanted.max())) + 1
    position = np.searchsorted(edges[:, 0] * base + edges[:, 1], wanted[:, 0] * base + wanted[:, 1])
    position = np.minimum(position, len(edges) - 1)
    return bool(((edges[position] == wanted).all(axis=1) & (count[position] == 2)).all())


def collapse_zero_area_faces(vertices, faces, name="mesh"):
    """Collapse or flip away the zero-area faces of a closed, oriented 2-manifold mesh.

    A needle (shortest edge at most :data:`NEEDLE_RATIO` of the longest) has its shortest
    edge collapsed to the midpoint; a cap (a corner on the opposite edge) has that edge
    flipped, which replaces it and its neighbour by two faces covering the same place.
    Each operation keeps the mesh closed and 2-manifold (the link condition, no edge made
    twice, no valence below 3) and turns no face over; when one is refused the other is
    tried. Faces that neither can remove, or more than
    :data:`REPAIRABLE_DEGENERATE_FRACTION` of the faces, raise ``InvalidMeshError``
    ``degenerate_faces``.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64, every edge on two faces, consistently
        oriented, no repeated corner.

    Returns
    -------
    vertices : (n', 3) float64, the collapsed vertices dropped.
    faces : (m', 3) int64.
    repair : Repair or None.
    """
    diag = diagonal(vertices)
    bad = degenerate_face_mask(vertices, faces, diag)
    if not bad.any():
        return vertices, faces, None
    found, where = int(bad.sum()), vertices[faces[bad]]
    if found > REPAIRABLE_DEGENERATE_FRACTION * len(faces):
        f = int(np.flatnonzero(bad)[0])
        raise InvalidMeshError(
            f"{name}: {found} of {len(faces)} faces are degenerate (zero-area), more than the "
            f"{REPAIRABLE_DEGENERATE_FRACTION:.0%} a repair may collapse, e.g. face {f} at "
            f"{format_point(where[0].mean(axis=0))}",
            reason="degenerate_faces", count=found, examples=np.flatnonzero(bad)[:5].tolist())
    editor = _FaceEditor(vertices, faces, ZERO_AREA * diag * diag)
    for _ in range(8):
        progressed = False
        for face in np.flatnonzero(editor.alive & editor.degenerate()):
            if editor.alive[face] and editor.is_degenerate(face):
                progressed |= editor.remove_degenerate(face)
        if not progressed:
            break
    left = np.flatnonzero(editor.alive & editor.degenerate())
    if len(left):
        f = int(left[0])
        raise InvalidMeshError(
            f"{name}: {len(left)} degenerate (zero-area) faces that no edge collapse or flip "
            f"removes without tearing the surface, e.g. face {f} at "
            f"{format_point(editor.vertices[editor.faces[f]].mean(axis=0))}",
            reason="degenerate_faces", count=len(left), examples=left[:5].tolist())
    used = np.unique(editor.faces[editor.alive])
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    moved = float(np.linalg.norm(editor.vertices[used] - vertices[used], axis=1).max())
    return editor.vertices[used], remap[editor.faces[editor.alive]], Repair.around(
        "zero_area_faces", found,
        f"collapsed or flipped {found} zero-area faces ({editor.collapses} edge collapses, "
        f"{editor.flips} edge flips)", where, largest_move=moved)


class _FaceEditor:
    """Edge collapses and flips on a closed oriented triangle mesh held as arrays.

    vertices : (n, 3) float64 and faces : (m, 3) int64 (copies, edited in place); alive :
    (m,) bool, False for removed faces; zero_double_area : twice the area at or below
    which a face has none. Neighbourhoods are found by scanning the face array (one
    vectorised pass per query), which suits the few operations a repair needs.
    """

    def __init__(self, vertices, faces, zero_double_area):
        self.vertices = np.array(vertices, dtype=np.float64)
        self.faces = np.array(faces, dtype=np.int64)
        self.alive = np.ones(len(faces), dtype=bool)
        self.zero = zero_double_area
        self.collapses = self.flips = 0

    def cross(self, faces):
        return face_cross(self.vertices, self.faces[faces])

    def degenerate(self):
        return np.linalg.norm(face_cross(self.vertices, self.faces), axis=1) <= self.zero

    def is_degenerate(self, face):
        return float(np.linalg.norm(self.cross([face])[0])) <= self.zero

    def faces_at(self, vertex):
        return np.flatnonzero(self.alive & (self.faces == vertex).any(axis=1))

    def remove_degenerate(self, face):
        corners = self.faces[face]
        length = np.linalg.norm(self.vertices[np.roll(corners, -1)] - self.vertices[corners], axis=1)
        longest, shortest = int(np.argmax(length)), int(np.argmin(length))
        edge = (corners[shortest], corners[(shortest + 1) % 3])
        if length[shortest] <= NEEDLE_RATIO * length[longest]:
            return self.collapse(*edge) or self.flip(face, longest)
        return self.flip(face, longest) or self.collapse(*edge)

    def flip(self, face, edge):
        """Flip edge ``edge`` (corner ``edge`` to ``edge + 1``) of ``face``; False if refused."""
        a, b, c = np.roll(self.faces[face], -edge)
        across = [f for f in self.faces_at(a) if f != face and b in self.faces[f]]
        if len(across) != 1:
            return False
        other = across[0]
        d = int(next(v for v in self.faces[other] if v != a and v != b))
        if d == c or len(np.intersect1d(self.faces_at(c), self.faces_at(d))):
            return False  # the new edge (c, d) exists already
        old_normal = self.cross([other])[0]
        saved = self.faces[[face, other]].copy()
        self.faces[face], self.faces[other] = (a, d, c), (d, b, c)
        new = self.cross([face, other])
        if (np.linalg.norm(new, axis=1) <= self.zero).any() or (new @ old_normal <= 0).any():
            self.faces[[face, other]] = saved
            return False
        self.flips += 1
        return True

    def collapse(self, u, v):
        """Collapse edge ``(u, v)`` into ``u`` at its midpoint (or at an end); False if refused."""
        at_u, at_v = self.faces_at(u), self.faces_at(v)
        on_edge = np.intersect1d(at_u, at_v)
        if len(on_edge) != 2:
            return False
        opposite = set(self.faces[on_edge].reshape(-1).tolist()) - {u, v}
        ring_u = set(self.faces[at_u].reshape(-1).tolist()) - {u}
        ring_v = set(self.faces[at_v].reshape(-1).tolist()) - {v}
        if (ring_u & ring_v) != opposite or len(ring_u | ring_v) - 2 < 3:
            return False  # the link condition: else the collapse pinches the surface
        if any(len(self.faces_at(o)) <= 3 for o in opposite):
            return False
        around = np.setdiff1d(np.union1d(at_u, at_v), on_edge)
        old = self.cross(around)
        old_faces, old_u = self.faces[around].copy(), self.vertices[u].copy()
        self.faces[around] = np.where(self.faces[around] == v, u, self.faces[around])
        sound = np.linalg.norm(old, axis=1) > self.zero
        for point in ((old_u + self.vertices[v]) / 2, old_u, self.vertices[v].copy()):
            self.vertices[u] = point
            new = self.cross(around)
            if (np.einsum("ij,ij->i", new[sound], old[sound]) > 0).all():
                self.alive[on_edge] = False
                self.collapses += 1
                return True
        self.faces[around], self.vertices[u] = old_faces, old_u
        return False


def resolve_self_intersections(vertices, faces, pairs, name="mesh"):
    """Smooth out a few intersecting faces of a closed oriented mesh.

    The vertices of the intersecting faces and one ring around them are moved to the fair
    surface spanned by the others: the minimiser of the discrete thin-plate energy
    ``sum_i d_i |L x_i|^2`` (``L`` the uniform Laplacian, ``d_i`` the valence) with every
    other vertex fixed. The uniform weights also unfold folded faces. When some pair still
    intersects (or a face loses its area), one more ring is freed, up to
    :data:`REPAIR_RINGS`. The connectivity is not changed.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64.
    pairs : (k, 2) int64 intersecting faces (:func:`find_self_intersections`).

    Returns
    -------
    vertices : (n, 3) float64 with no intersecting pair.
    repair : Repair.

    Raises
    ------
    InvalidMeshError ``self_intersecting`` when the intersecting faces are more than
    :data:`REPAIRABLE_INTERSECTING_FRACTION` of the faces, or no fair patch within
    :data:`REPAIR_RINGS` rings, :data:`REPAIRABLE_REGION_FRACTION` of the vertices and
    :data:`REPAIR_VOLUME_CHANGE` of the volume removes every intersection.
    """
    involved = np.unique(pairs)
    a, b = pairs[0]
    what = (f"{name}: {len(pairs)} pairs of intersecting faces, e.g. faces {a} and {b} near "
            f"{format_point(vertices[faces[a]].mean(axis=0))}")
    if len(involved) > REPAIRABLE_INTERSECTING_FRACTION * len(faces):
        raise InvalidMeshError(
            f"{what}; {len(involved)} of {len(faces)} faces intersect, more than the "
            f"{REPAIRABLE_INTERSECTING_FRACTION:.0%} a local repair may change",
            reason="self_intersecting", count=len(pairs), examples=[tuple(map(int, p)) for p in pairs[:5]])
    n = len(vertices)
    edges, _ = unique_edges(faces)
    ends = (edges.reshape(-1), edges[:, ::-1].reshape(-1))
    adjacency = sp.coo_matrix((np.ones(2 * len(edges)), ends), shape=(n, n)).tocsr()
    valence = np.asarray(adjacency.sum(axis=1)).reshape(-1)
    laplacian = (sp.diags(valence) - adjacency).tocsr()
    _, component = connected_components(adjacency, directed=False)
    volume = float(triangle_signed_volumes(vertices, faces).sum())
    diag = diagonal(vertices)
    free = np.zeros(n, dtype=bool)
    free[faces[involved]] = True
    why = f"smoothing {REPAIR_RINGS} rings of vertices around them does not separate them"
    for _ in range(REPAIR_RINGS):
        free |= adjacency @ free.astype(np.float64) > 0
        if free.sum() > REPAIRABLE_REGION_FRACTION * n:
            why = (f"separating them would move more than {REPAIRABLE_REGION_FRACTION:.0%} of "
                   "the vertices")
            break
        if np.isin(component, component[~free], invert=True).any():
            why = "separating them would move a whole component"
            break
        faired = _fair(vertices, laplacian, valence, free)
        moved_faces = free[faces].any(axis=1)
        if degenerate_face_mask(faired, faces[moved_faces], diag).any() or \
                len(find_self_intersections(faired, faces, among=moved_faces)):
            continue
        change = abs(float(triangle_signed_volumes(faired, faces).sum()) - volume)
        if change > REPAIR_VOLUME_CHANGE * abs(volume):
            why = (f"separating them would change the volume by more than "
                   f"{REPAIR_VOLUME_CHANGE:.0%}")
            break
        move = float(np.linalg.norm(faired[free] - vertices[free], axis=1).max())
        return faired, Repair.around(
            "self_intersections", len(pairs),
            f"smoothed out {len(pairs)} pairs of intersecting faces by moving "
            f"{int(free.sum())} vertices (volume changed by {change / abs(volume):.2%})",
            vertices[free], vertices[faces[pairs]].reshape(-1, 6, 3).mean(axis=1), move)
    raise InvalidMeshError(f"{what}; {why}", reason="self_intersecting", count=len(pairs),
                           examples=[tuple(map(int, p)) for p in pairs[:5]])


def _fair(vertices, laplacian, valence, free):
    """(n, 3) float64 vertices with the ``free`` ((n,) bool) ones at the minimum of
    ``x^T K D^-1 K x`` (``K`` the graph Laplacian (n, n), ``D`` the valences (n,)) and
    the others where they are."""
    from scipy.sparse.linalg import splu

    fixed_only = np.where(free[:, None], 0.0, vertices)
    rows = laplacian[free]
    inverse_valence = sp.diags(1.0 / valence)
    system = (rows @ inverse_valence @ rows.T).tocsc()
    rhs = -(rows @ (inverse_valence @ (laplacian @ fixed_only)))
    faired = vertices.copy()
    faired[free] = splu(system).solve(np.asarray(rhs))
    return faired
