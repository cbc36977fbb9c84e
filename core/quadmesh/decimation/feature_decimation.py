# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quadric-error decimation that keeps the target's sharp feature lines as chains of edges.

QSlim (:mod:`core.quadmesh.decimation.decimation`) places its edges wherever the quadric error is
least, so on a machined part many cage edges cross a sharp step diagonally and cannot be tagged as
creases. This decimation (Garland & Heckbert, "Surface simplification using quadric error metrics",
SIGGRAPH 1997: edge collapses in the order of their quadric error, each collapsed pair placed where
the sum of its quadrics is least) keeps the whole feature network (target edges whose dihedral angle
exceeds :data:`core.quadmesh.creases.CREASE_ANGLE`, :func:`core.quadmesh.creases.feature_edges`,
without the chains that end inside a face region, :func:`core.quadmesh.creases.closed_network`: the
isolated sharp edges of a SIMP result's iso-surface are no feature lines) as edges of the result:

* every vertex is *free* (no feature edge), on a *line* (two feature edges turning by at most
  :data:`TURN_ANGLE`) or a *corner* (three or more feature edges, or a sharp turn of the
  line: the junctions and kinks of the network);
* a corner never moves and is never removed; a line vertex is removed only by a collapse
  along its line into a line neighbour or a corner, which stays where it is (so every
  feature vertex stays a vertex of the target on its line); a free vertex collapses into any
  neighbour (into a feature vertex at that vertex's position, between two free vertices at
  the quadric optimum);
* no collapse joins two feature vertices over an edge that is not a feature edge, and a line
  vertex is removed only where the line's new edge passes within :data:`MAX_CHORD_SAG` of
  its length of it (a round hole keeps 6 edges);
* every feature edge adds the quadrics of the two planes through it perpendicular to its
  triangles, weighted by :data:`BOUNDARY_WEIGHT` times its squared length (the paper's
  boundary constraint planes), so a curved line loses its vertices last;
* the link condition (the two ends share exactly the two opposite vertices) keeps the
  topology; collapses that turn a triangle's normal by more than ``arccos``
  :data:`MIN_NORMAL_COSINE`, leave it thinner than :data:`MIN_QUALITY` (or, when it was
  already, than :data:`QUALITY_KEPT` of that), or make one whose normal is that far from the
  target's (pseudo-)normal at the point closest to its centroid, or whose centroid is
  farther from the target than :data:`MAX_DEVIATION` times its longest edge, are refused; a
  refused edge is tried again when its neighbourhood changes. The last two rules keep a
  triangle from capping a slot or a notch: quadrics do not see a triangle in the plane of a
  wall that spans a slot's mouth, nor one in the plane of a notch's rim once its floor's
  vertices, free where its edges are rounded, have been collapsed into the rim.

Each feature edge of the result is the union of a chain of feature edges of the target, so
pairing triangles into quads never across them keeps them cage edges, which become the
cage's crease edges (:mod:`core.quadmesh.decimation.paired_decimation`).
"""
import heapq

import numpy as np

from core.errors import InvalidMeshError
from core.mesh_topology import connected_face_components, edge_faces, genus_of
from core.quadmesh.creases import CREASE_ANGLE, closed_network, feature_edges
from core.quadmesh.decimation.decimation import SOURCE_TRIANGLES
from core.target_surface import TargetSurface

TURN_ANGLE = 40.0
"""Degrees: a vertex with two feature edges whose directions turn by more than this is a
corner of the network (a kink of a line is kept where it is). A regular octagon's rim turns
by 45 degrees at each corner; a tessellated circle by much less per segment."""
BOUNDARY_WEIGHT = 10.0
"""Weight of the planes through a feature edge perpendicular to its triangles, per squared
edge length (the triangle quadrics are weighted by area, the same units)."""
MAX_CHORD_SAG = 0.25
"""A line vertex is removed only if it lies within this share of the new edge's length of
it (the chord that replaces its two edges): the crease rules make a closed line's limit the
uniform cubic B-spline of its polygon, which lies at 1/2 of a triangle's circumradius at its
vertices, 2/3 of a square's and 5/6 of a hexagon's, and the walls of a hole of three edges
crossed the faces around it. A regular polygon's vertex lies 0.24 of the
chord from it for 7 edges and 0.29 for 6, so a round hole keeps 6 edges; a half circle
between two corners keeps 2 (with one, a notch's U-shaped rim becomes a single edge across
the notch's mouth, and the notch is capped)."""
MIN_NORMAL_COSINE = 0.2
"""A collapse is refused when it turns a triangle's normal by more than about 78 degrees."""
MAX_DEVIATION = 0.25
"""A collapse is refused when it makes a triangle whose centroid lies farther from the target
than this times its longest edge. A hexagonal hole's wall triangles lie at most 0.13 times
their longest edge inside its cylinder; a triangle capping a notch whose floor and walls have
rounded edges (no feature lines to keep them) lies in the plane of the rim, and its normal
agrees with the floor's, far above it."""
MIN_QUALITY = 0.05
"""A collapse is refused when it leaves a triangle of a lower quality ``4 sqrt(3) area / (sum
of squared edge lengths)`` (1 for an equilateral triangle) than this and than
:data:`QUALITY_KEPT` times the quality it had."""
QUALITY_KEPT = 0.9
"""Share of its quality a triangle already thinner than :data:`MIN_QUALITY` may lose in one
collapse: the long thin triangles along a straight feature line change by a little whenever
a line vertex next to them moves along its line, and refusing every such change would stop
the decimation of a machined part well above its budget."""


class FeatureDecimation:
    """Feature-preserving decimations of one closed, outward 2-manifold target (module
    docstring) to any triangle count.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 the target.
    surface : TargetSurface of the target already built, or None (built here).
    angle : float, degrees: the smallest dihedral angle of a feature edge.

    Targets of more than :data:`core.quadmesh.decimation.decimation.SOURCE_TRIANGLES` triangles are
    decimated to that many once, on first use, and every count starts from that (pure
    Python, so its time grows with the triangles collapsed: about a second for a few
    thousand, a minute for 150k). The collapses run in one order whatever the count (quadric
    error, ties by the order they were queued; only where they stop depends on it), so one
    decimation of the source serves every count: a lower count continues it, a higher one
    replays the first of its collapses (:meth:`_CollapseState.replay`) without judging them
    again.

    Raises
    ------
    InvalidMeshError (from :meth:`triangles`) when a decimation changed the genus: collapses
    that would are refused, so this means a defect in the input the intake did not catch.
    """

    def __init__(self, vertices, faces, surface=None, angle=CREASE_ANGLE):
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        self._surface = TargetSurface(vertices, faces) if surface is None else surface
        features = closed_network(feature_edges(vertices, faces, angle), len(vertices))
        features = np.zeros((0, 2), dtype=np.int64) if features is None else features
        self._target = (vertices, faces, features, corner_vertices(vertices, features))
        self._components = int(connected_face_components(faces).max()) + 1
        self._genus = genus_of(len(vertices), faces, self._components)
        self._source = None
        self._state = None
        self._results = {}

    @property
    def target_features(self):
        """(k, 2) int64 the target's feature network kept as edges (sorted vertex pairs; the
        closed network of its feature edges, module docstring)."""
        return self._target[2]

    def triangles(self, count):
        """The decimation to ``count`` triangles (more where every collapse left is refused;
        the source itself when it has no more than ``count``).

        Returns
        -------
        vertices : (n', 3) float64; faces : (m', 3) int64 closed, outward, the target's genus;
        features : (k', 2) int64 sorted vertex pairs, its feature edges. The same count gives
        the same (cached) arrays, and so does every count below the triangles of a
        decimation that stopped short of its count (:meth:`_floor`).
        """
        count = int(count)
        if self._source is None:
            self._source = (self._decimated(self._target, SOURCE_TRIANGLES)
                            if len(self._target[1]) > SOURCE_TRIANGLES else self._target)
        if count >= len(self._source[1]):
            return self._source[:3]
        if count not in self._results:
            floor = self._floor()
            self._results[count] = (floor if floor is not None and count < len(floor[1]) else
                                    self._checked(self._from_source(count)))
        return self._results[count][:3]

    def _from_source(self, count):
        """``(vertices, faces, features, corner)`` of the source's decimation to ``count``
        triangles: the live decimation continued when it has not reached ``count`` yet, else
        its first collapses replayed."""
        if self._state is None:
            self._state = _CollapseState(*self._source, self._surface)
        if self._state.n_faces > count:
            self._state.run(count)
            return self._state.result()
        replay = _CollapseState(*self._source, self._surface, queued=False)
        replay.replay(self._state.log, count)
        return replay.result()

    def _floor(self):
        """The cached decimation that stopped short of its count because every collapse left
        was refused, or None.

        The collapses run in a fixed order (quadric error, ties by the order they were
        queued), so a decimation to any count below that result's triangles makes the same
        collapses and ends at the same refusals: the same result, not worth computing again
        (the budget ladder asks for up to 12 such counts on a target whose feature network
        stops the decimation early).
        """
        short = [result for count, result in self._results.items() if len(result[1]) > count]
        return min(short, key=lambda result: len(result[1]), default=None)

    def _decimated(self, source, count):
        return self._checked(collapse_edges(*source, count, self._surface))

    def _checked(self, decimated):
        """``decimated`` ``(vertices, faces, features, corner)``, checked to keep the genus."""
        vertices, faces, features, corner = decimated
        if genus_of(len(vertices), faces, self._components) != self._genus:
            raise InvalidMeshError("the decimated target changed its genus; the input surface "
                                   "is not a clean 2-manifold")
        return vertices, faces, features, corner


def corner_vertices(vertices, features):
    """(n,) bool: the corners of a feature network (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64; features : (k, 2) int64 feature edges.
    """
    n = len(vertices)
    degree = np.bincount(features.reshape(-1), minlength=n)
    corner = (degree != 0) & (degree != 2)
    ends = np.concatenate([features, features[:, ::-1]])
    ends = ends[np.argsort(ends[:, 0], kind="stable")]
    ends = ends[degree[ends[:, 0]] == 2].reshape(-1, 2, 2)  # both edges of each line vertex
    centre = vertices[ends[:, 0, 0]]
    incoming = centre - vertices[ends[:, 0, 1]]
    outgoing = vertices[ends[:, 1, 1]] - centre
    cosine = np.einsum("ij,ij->i", incoming, outgoing) / np.maximum(
        np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1), 1e-300)
    corner[ends[:, 0, 0]] = cosine < np.cos(np.radians(TURN_ANGLE))
    return corner


def vertex_quadrics(vertices, faces, features):
    """(n, 4, 4) float64 quadric of every vertex: the area-weighted planes of its triangles
    plus the boundary planes of its feature edges (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 closed, outward;
    features : (k, 2) int64 sorted vertex pairs, edges of ``faces``.
    """
    from core.geometry import face_cross

    cross = face_cross(vertices, faces)
    twice_area = np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(twice_area, 1e-300)[:, None]
    plane = np.concatenate([normal, -np.einsum("ij,ij->i", normal, vertices[faces[:, 0]])[:, None]],
                           axis=1)
    quadrics = np.zeros((len(vertices), 4, 4))
    face_quadric = 0.5 * twice_area[:, None, None] * plane[:, :, None] * plane[:, None, :]
    for k in range(3):
        np.add.at(quadrics, faces[:, k], face_quadric)
    if len(features):
        edges, pairs = edge_faces(faces)
        n = len(vertices)
        index = np.searchsorted(edges[:, 0] * n + edges[:, 1], features[:, 0] * n + features[:, 1])
        a, b = vertices[features[:, 0]], vertices[features[:, 1]]
        along = b - a
        for side in (0, 1):
            across = np.cross(along, normal[pairs[index, side]])
            across /= np.maximum(np.linalg.norm(across, axis=1), 1e-300)[:, None]
            side_plane = np.concatenate([across, -np.einsum("ij,ij->i", across, a)[:, None]],
                                        axis=1)
            weight = BOUNDARY_WEIGHT * np.einsum("ij,ij->i", along, along)
            side_quadric = weight[:, None, None] * side_plane[:, :, None] * side_plane[:, None, :]
            np.add.at(quadrics, features[:, 0], side_quadric)
            np.add.at(quadrics, features[:, 1], side_quadric)
    return quadrics


def collapse_edges(vertices, faces, features, corner, count, surface):
    """Feature-preserving quadric-error edge collapses down to ``count`` triangles.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 closed, outward 2-manifold;
    features : (k, 2) int64 sorted vertex pairs, edges of ``faces``: the feature network;
    corner : (n,) bool its corners (:func:`corner_vertices`);
    count : int, triangles wanted;
    surface : TargetSurface of the target whose decimation this is (the mesh itself or a
        decimation of it), for the normals under new triangles.

    Returns
    -------
    vertices : (n', 3) float64; faces : (m', 3) int64, ``m' <= max(count, m)`` unless every
    collapse left is refused; features : (k', 2) int64 sorted pairs; corner : (n',) bool.
    """
    state = _CollapseState(vertices, faces, features, corner, surface)
    state.run(int(count))
    return state.result()


class _CollapseState:
    """The mesh being decimated by :func:`collapse_edges`: faces as vertex lists, per-vertex
    face and feature-neighbour sets, quadrics, the heap of candidate collapses (none when not
    ``queued``: a state that only replays) and ``log``, the collapses made, each
    ``(keep, remove, position)``."""

    def __init__(self, vertices, faces, features, corner, surface, queued=True):
        self.surface = surface
        self.V = np.array(vertices, dtype=np.float64)
        self.Q = vertex_quadrics(self.V, faces, features)
        self.faces = faces.tolist()
        n = len(self.V)
        self.vertex_faces = [set() for _ in range(n)]
        for index, face in enumerate(self.faces):
            for v in face:
                self.vertex_faces[v].add(index)
        self.feature_nb = [set() for _ in range(n)]
        for a, b in features.tolist():
            self.feature_nb[a].add(b)
            self.feature_nb[b].add(a)
        self.corner = corner.tolist()
        self.stamp = [0] * n
        self.blocked = {}
        self.heap = []
        self.pushed = 0
        self.n_faces = len(self.faces)
        self.log = []
        if queued:
            edges, _ = edge_faces(faces)
            for a, b in edges.tolist():
                self._push(a, b)

    def neighbours(self, v):
        """Set of the vertices sharing a face with ``v``."""
        around = {w for f in self.vertex_faces[v] for w in self.faces[f]}
        around.discard(v)
        return around

    def run(self, count):
        """Collapse the cheapest allowed edge until ``count`` triangles are left."""
        while self.n_faces > count and self.heap:
            _, _, a, b, stamp_a, stamp_b, keep, remove, position = heapq.heappop(self.heap)
            if self.stamp[a] != stamp_a or self.stamp[b] != stamp_b:
                continue
            if not self._allowed(keep, remove, position):
                self.blocked.setdefault(a, set()).add(b)
                self.blocked.setdefault(b, set()).add(a)
                continue
            self._collapse(keep, remove, position)
            self.log.append((keep, remove, position))
            ring = self.neighbours(keep)
            for w in ring:
                self._push(keep, w)
            for w in ring:
                for x in self.blocked.pop(w, ()):
                    if self.stamp[x] >= 0 and x in self.neighbours(w) and x != keep:
                        self._push(w, x)

    def replay(self, log, count):
        """Make the collapses of ``log`` (another state's, from the same mesh) in order until
        ``count`` triangles are left: the mesh :meth:`run` leaves, since its collapses do not
        depend on where it stops."""
        for keep, remove, position in log:
            if self.n_faces <= count:
                break
            self._collapse(keep, remove, position)
            self.log.append((keep, remove, position))

    def _plan(self, a, b):
        """``(keep, remove, position)`` of collapsing edge ``(a, b)``, or None if the feature
        rules (module docstring) forbid it."""
        on_a, on_b = bool(self.feature_nb[a]), bool(self.feature_nb[b])
        if self.corner[a] and self.corner[b]:
            return None
        if not on_a and not on_b:
            return a, b, self._optimum(a, b)
        if on_a != on_b:
            keep, remove = (a, b) if on_a else (b, a)
            return keep, remove, self.V[keep].copy()
        if b not in self.feature_nb[a]:
            return None
        if self.corner[a] or self.corner[b]:
            keep, remove = (a, b) if self.corner[a] else (b, a)
            return keep, remove, self.V[keep].copy()
        q = self.Q[a] + self.Q[b]
        keep, remove = (a, b) if _error(q, self.V[a]) <= _error(q, self.V[b]) else (b, a)
        return keep, remove, self.V[keep].copy()

    def _optimum(self, a, b):
        """(3,) the point least in the quadric of ``a`` and ``b``; the best of both ends and
        the midpoint where that quadric is singular."""
        q = self.Q[a] + self.Q[b]
        A = q[:3, :3]
        if abs(np.linalg.det(A)) > 1e-9 * max(np.abs(A).max() ** 3, 1e-300):
            return np.linalg.solve(A, -q[:3, 3])
        points = (self.V[a], self.V[b], 0.5 * (self.V[a] + self.V[b]))
        return min(points, key=lambda p: _error(q, p))

    def _push(self, a, b):
        """Queue the collapse of edge ``(a, b)`` at its quadric error, if the rules allow it."""
        plan = self._plan(a, b)
        if plan is None:
            return
        keep, remove, position = plan
        cost = _error(self.Q[a] + self.Q[b], position)
        self.pushed += 1
        heapq.heappush(self.heap, (cost, self.pushed, a, b, self.stamp[a], self.stamp[b],
                                   keep, remove, position))

    def _allowed(self, keep, remove, position):
        """Whether the collapse keeps the topology (link condition) and no triangle flips or
        degenerates (module docstring)."""
        shared = self.vertex_faces[keep] & self.vertex_faces[remove]
        if len(shared) != 2 or len(self.neighbours(keep) & self.neighbours(remove)) != 2:
            return False
        if self.feature_nb[remove] and not self._is_flat_chord(keep, remove):
            return False
        moved = [self.faces[f] for f in (self.vertex_faces[keep] | self.vertex_faces[remove])
                 if f not in shared]
        index = np.array(moved, dtype=np.int64)
        old = self.V[index]
        new = np.where(((index == keep) | (index == remove))[:, :, None], position, old)
        normal, quality = _normals_and_qualities(np.concatenate([old, new]))
        normal_old, normal_new = normal[:len(old)], normal[len(old):]
        quality_old, quality_new = quality[:len(old)], quality[len(old):]
        if not ((np.einsum("ij,ij->i", normal_old, normal_new) >= MIN_NORMAL_COSINE).all()
                and (quality_new >= np.minimum(MIN_QUALITY, QUALITY_KEPT * quality_old)).all()):
            return False
        near = self.surface.closest(new.mean(axis=1))
        longest = np.sqrt(((new - new[:, [2, 0, 1]]) ** 2).sum(axis=2).max(axis=1))
        return bool((np.einsum("ij,ij->i", normal_new, near.normal) >= MIN_NORMAL_COSINE).all()
                    and (near.distance <= MAX_DEVIATION * longest).all())

    def _is_flat_chord(self, keep, remove):
        """Whether removing line vertex ``remove`` (collapsed into its line neighbour
        ``keep``) leaves its line's new edge within :data:`MAX_CHORD_SAG` of its length of
        it, without closing the line into a loop of two edges."""
        (other,) = self.feature_nb[remove] - {keep}
        if other in self.feature_nb[keep]:
            return False
        start, end, point = self.V[other], self.V[keep], self.V[remove]
        along = end - start
        length2 = float(along @ along)
        t = min(max(float((point - start) @ along) / length2, 0.0), 1.0)
        return float(np.linalg.norm(point - start - t * along)) <= MAX_CHORD_SAG * np.sqrt(length2)

    def _collapse(self, keep, remove, position):
        """Merge ``remove`` into ``keep`` at ``position``: its two shared triangles go, its
        other triangles, feature edges and quadric pass to ``keep``."""
        for f in self.vertex_faces[keep] & self.vertex_faces[remove]:
            for w in self.faces[f]:
                if w != keep and w != remove:
                    self.vertex_faces[w].discard(f)
            self.faces[f] = None
            self.n_faces -= 1
        self.vertex_faces[keep] -= self.vertex_faces[remove]
        for f in self.vertex_faces[remove]:
            if self.faces[f] is not None:
                self.faces[f] = [keep if v == remove else v for v in self.faces[f]]
                self.vertex_faces[keep].add(f)
        self.vertex_faces[remove] = set()
        for w in self.feature_nb[remove]:
            self.feature_nb[w].discard(remove)
            if w != keep:
                self.feature_nb[w].add(keep)
                self.feature_nb[keep].add(w)
        self.feature_nb[keep].discard(remove)
        self.feature_nb[remove] = set()
        self.V[keep] = position
        self.Q[keep] += self.Q[remove]
        self.stamp[keep] += 1
        self.stamp[remove] = -1

    def result(self):
        """``(vertices, faces, features, corner)`` renumbered over the vertices left."""
        faces = np.array([f for f in self.faces if f is not None], dtype=np.int64).reshape(-1, 3)
        used = np.unique(faces)
        renumber = np.full(len(self.V), -1, dtype=np.int64)
        renumber[used] = np.arange(len(used))
        pairs = [(a, b) for a in used.tolist() for b in self.feature_nb[a] if a < b]
        features = np.sort(renumber[np.array(pairs, dtype=np.int64).reshape(-1, 2)], axis=1)
        features = features[np.lexsort((features[:, 1], features[:, 0]))]
        return (self.V[used], renumber[faces], features,
                np.asarray(self.corner, dtype=bool)[used])


def _error(q, point):
    """Quadric error ``[p, 1] q [p, 1]^T`` of a (3,) point."""
    h = np.append(point, 1.0)
    return float(h @ q @ h)


def _normals_and_qualities(triangles):
    """(t, 3) unit normals (zero rows where degenerate) and (t,) qualities (module docstring)
    of (t, 3, 3) triangles."""
    u = triangles[:, 1] - triangles[:, 0]
    w = triangles[:, 2] - triangles[:, 0]
    cross = u[:, [1, 2, 0]] * w[:, [2, 0, 1]] - u[:, [2, 0, 1]] * w[:, [1, 2, 0]]
    twice_area = np.sqrt((cross * cross).sum(axis=1))
    squares = ((triangles - triangles[:, [2, 0, 1]]) ** 2).sum(axis=(1, 2))
    quality = 2.0 * np.sqrt(3.0) * twice_area / np.maximum(squares, 1e-300)
    return cross / np.maximum(twice_area, 1e-300)[:, None], quality
