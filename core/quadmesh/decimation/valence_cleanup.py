# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fewer extraordinary vertices on a paired cage: local quad operators that lower the valence
energy, each kept only where the cage's faces stay well shaped on the target.

Pairing the triangles of a decimation (:mod:`core.quadmesh.decimation.paired_decimation`)
gives quads, but its vertices keep the valences of the triangle mesh halved at random: about
half of them have a valence other than 4 (extraordinary vertices, where Catmull-Clark's limit
surface is only C1 and where a CAD user sees fans and long thin faces). Following Tarini et
al., "Practical quad mesh simplification" (Eurographics 2010) and Daniels et al.,
"Quadrilateral mesh simplification" (SIGGRAPH Asia 2008), three local operators change the
connectivity of the quads (triangles left over by the pairing are left as they are):

- edge rotation: the two quads on an edge make a hexagon, re-split along one of its two other
  diagonals (the edge's ends lose one valence each, the new edge's ends gain one);
- diagonal collapse: a quad's two opposite corners merged into one vertex (one face fewer;
  the merged vertex has the two valences less two, the other two corners lose one each);
- vertex split, its inverse: a vertex's fan of faces cut into two by two of its edges, the
  vertex made two joined by a new quad (one face more).

Each is applied only where it keeps a closed 2-manifold of the same genus: the hexagon's six
corners distinct and its new edge not already an edge; the collapsed corners sharing no face
but the quad and no neighbour but its other two corners (the link condition); no vertex left
with fewer than three faces. Crease vertices (``PolyMesh.creases``) keep their position and
valence and crease edges are never rotated, so a feature cage keeps its crease chains.

The operators lower the energy ``sum_v E(valence(v))`` (:data:`ENERGY`: every extraordinary
vertex costs alike and a valence above 5 little more, so that two vertices of valence 5 may
merge into one of valence 6), greedily: the move that lowers it most is applied first (ties by
kind and by vertex and face indices, so the same cage always gives the same result). An edge
rotation that leaves the energy as it is is taken too where it lowers
``sum over edges (u, w) of (valence(u) - 4) (valence(w) - 4)``: it brings vertices of valence
below 4 next to ones above 4, which later moves can cancel (the pair of energies falls at every
move, so the moves end). A move is kept only where the faces it makes are well shaped: the
smallest of their corners' signed sines about the target's normal at the corner and of the
cosines between their normals and the target's at their corners (:func:`_face_quality`;
negative where a corner folds over or a face spans a thin strut with its corners on opposite
walls) is at least :data:`MIN_CORNER_SINE` or at least that of the faces it replaces, and
where they stay near the target: their centres and edge midpoints, and the places of the
vertices the move removed or moved, lie within :data:`MAX_DEVIATION` of the mean edge length of
the target (or of the new faces), or no farther than the old faces' centres and midpoints (a
collapse must not cut off a tip or a ridge that a vertex held). A vertex made by a collapse or a
split is placed on the target (the point nearest the mean of the vertices it comes from, or
halfway to the centre of its side of the fan); the other vertices stay where they are (on the
target, where the decimation's quadrics put them: a tangential relaxation towards the
neighbours' mean takes them off ridges and tips, and the fitted surface moves farther from the
target). Within ``min_faces`` and ``max_faces`` collapses and splits keep the face count near
the budget.
"""
import heapq
import math
from dataclasses import dataclass, replace

import numpy as np

from core.box_tree import closest_on_triangles
from core.mesh_topology import polymesh_summary
from core.polymesh_checks import check_polymesh
from core.types import PolyMesh

REGULAR_VALENCE = 4
"""Valence of a regular vertex of a closed quad mesh."""
ENERGY = {3: 2, 4: 0, 5: 2, 6: 3, 7: 4, 8: 6}
"""Energy of a vertex by its valence (integers, so that sums compare exactly). Every
extraordinary vertex costs 2 and a valence beyond 5 little more: two vertices of valence 5
become one of valence 6 where the faces stay well shaped (fewer extraordinary vertices, each a
little more irregular), where the squared deviation from 4 would keep them apart."""
MIN_CORNER_SINE = 0.5
"""Faces made by a move are kept when their :func:`_face_quality` is at least this (corner
angles between 30 and 150 degrees, normals within 60 degrees of the target's at the corners),
or at least the smallest one of the faces they replace."""
MAX_DEVIATION = 0.1
"""Faces made by a move are kept when their centres and edge midpoints, and the places of the
vertices the move removed or moved, lie at most this share of the mean edge length from the
target (or from the new faces), or no farther than the old faces' centres and midpoints."""
MAX_MOVES_PER_FACE = 2
"""Moves applied at most, per face of the cage (each lowers the integer energies, so the moves
end anyway; this bounds the time on large cages)."""


@dataclass(frozen=True)
class ValenceCleanup:
    """Result of :func:`clean_valences`.

    mesh : PolyMesh, the cleaned cage (closed 2-manifold, the input's genus and creases).
    rotations, collapses, splits : int, moves applied.
    extraordinary_before, extraordinary_after : int, vertices of valence other than 4.
    origin : (k,) int64, for each vertex of ``mesh`` the input vertex it comes from (the
        vertex split, for the second vertex of a split; the first corner, for a collapse).
    """

    mesh: PolyMesh
    rotations: int
    collapses: int
    splits: int
    extraordinary_before: int
    extraordinary_after: int
    origin: np.ndarray


def clean_valences(mesh, surface, min_faces=None, max_faces=None, fixed=()):
    """``mesh`` with fewer extraordinary vertices (module docstring).

    Parameters
    ----------
    mesh : PolyMesh closed, 2-manifold, outward cage of quads and triangles, its vertices on
        (or near) the target.
    surface : TargetSurface of the target.
    min_faces, max_faces : int or None, the face counts collapses and splits keep within
        (None: the cage's own count, so they only come in pairs).
    fixed : iterable of int, vertices of ``mesh`` kept as they are (valence and position),
        as crease vertices are.

    Returns
    -------
    ValenceCleanup
    """
    before = polymesh_summary(mesh)["extraordinary_vertices"]
    cage = _Cage(mesh, surface)
    for v in fixed:
        cage.frozen[int(v)] = True
    n_faces = mesh.n_faces
    cage.min_faces = n_faces if min_faces is None else min(int(min_faces), n_faces)
    cage.max_faces = n_faces if max_faces is None else max(int(max_faces), n_faces)
    counts = cage.optimise(MAX_MOVES_PER_FACE * n_faces)
    cleaned, origin = cage.mesh(mesh)
    check_polymesh(cleaned)
    return ValenceCleanup(cleaned, *counts, before,
                          polymesh_summary(cleaned)["extraordinary_vertices"], origin)


def _energy(valence):
    """Energy of one vertex of ``valence`` faces (:data:`ENERGY`; beyond its table, two more
    per face; below valence 3, which no move makes, 16)."""
    if valence in ENERGY:
        return ENERGY[valence]
    return ENERGY[max(ENERGY)] + 2 * (valence - max(ENERGY)) if valence > 4 else 16


class _Cage:
    """A cage under edit: faces as vertex lists (None where removed), half-edges to faces,
    faces around each vertex, positions and target normals as Python lists."""

    def __init__(self, mesh, surface):
        self.surface = surface
        self.faces = [list(map(int, f)) for f in mesh.faces()]
        self.points = [list(p) for p in np.asarray(mesh.vertices, dtype=np.float64).tolist()]
        self.normals = surface.closest(mesh.vertices).normal.tolist()
        self.half = {}
        self.around = [[] for _ in self.points]
        for index, face in enumerate(self.faces):
            self._add(index, face)
        self.frozen = [False] * len(self.points)
        self.origin = list(range(len(self.points)))
        self.creases = set()
        if mesh.creases is not None and len(mesh.creases):
            for a, b in np.asarray(mesh.creases).tolist():
                self.frozen[a] = self.frozen[b] = True
                self.creases.add((min(a, b), max(a, b)))
        self.n_faces = len(self.faces)
        self.touched = set()
        self.refused = False
        self.min_faces = self.max_faces = self.n_faces

    # --- bookkeeping -------------------------------------------------------------------

    def _add(self, index, face):
        for k, v in enumerate(face):
            self.half[(v, face[k - len(face) + 1])] = index
            self.around[v].append(index)

    def _remove(self, index):
        face = self.faces[index]
        for k, v in enumerate(face):
            del self.half[(v, face[k - len(face) + 1])]
            self.around[v].remove(index)

    def _replace(self, removed, new_faces):
        """Faces ``removed`` (indices) replaced by ``new_faces`` (vertex lists): their slots
        are reused in order, extra faces appended, slots left over emptied."""
        for index in removed:
            self._remove(index)
        slots = list(removed)
        for face in new_faces:
            if slots:
                index = slots.pop(0)
                self.faces[index] = face
            else:
                index = len(self.faces)
                self.faces.append(face)
            self._add(index, face)
            self.touched.update(face)
        for index in slots:
            self.faces[index] = None
        self.n_faces += len(new_faces) - len(removed)

    def valence(self, v):
        return len(self.around[v])

    def fan(self, v):
        """Faces around ``v`` counter-clockwise seen from outside, the first the smallest
        index, and the neighbours ``u`` with ``u[k]`` the corner after ``v`` in face ``k``
        (the edge between faces ``k - 1`` and ``k``)."""
        start = min(self.around[v])
        faces, ring = [], []
        index = start
        while True:
            face = self.faces[index]
            k = face.index(v)
            ring.append(face[(k + 1) % len(face)])
            faces.append(index)
            index = self.half[(v, face[k - 1])]
            if index == start:
                return faces, ring

    def face_ring(self, v):
        """Set of the vertices other than ``v`` of the faces around ``v``."""
        ring = set()
        for index in self.around[v]:
            ring.update(self.faces[index])
        ring.discard(v)
        return ring

    # --- geometry ----------------------------------------------------------------------

    def quality(self, faces, moved=None):
        """Smallest :func:`_face_quality` of ``faces`` (vertex lists), with the vertices of
        ``moved`` (dict vertex -> (point, normal)) at those places."""
        worst = math.inf
        for face in faces:
            points, normals = [], []
            for v in face:
                if moved is not None and v in moved:
                    point, normal = moved[v]
                else:
                    point, normal = self.points[v], self.normals[v]
                points.append(point)
                normals.append(normal)
            worst = min(worst, _face_quality(points, normals))
        return worst

    def on_target(self, *points):
        """``(point, normal)`` of the target nearest each of ``points`` (3 floats each), in a
        list."""
        found = self.surface.closest(np.asarray(points, dtype=np.float64))
        return list(zip(found.point.tolist(), found.normal.tolist()))

    def acceptable(self, old_faces, new_faces, moved=None, lost=()):
        """Whether the faces ``new_faces`` (with the vertices of ``moved`` there) may replace
        ``old_faces``: well shaped (:func:`_face_quality` at least :data:`MIN_CORNER_SINE` or
        at least the old faces'), and as near the target
        (:meth:`deviation` at most :data:`MAX_DEVIATION` or at most the old faces'), the
        points ``lost`` (positions of vertices removed or moved) included."""
        new = self.quality(new_faces, moved)
        if new < MIN_CORNER_SINE and new < self.quality(old_faces):
            self.refused = True
            return False
        new, old = self.deviation(new_faces, old_faces, moved, lost)
        if new <= MAX_DEVIATION or new <= old:
            return True
        self.refused = True
        return False

    def deviation(self, new_faces, old_faces, moved, lost):
        """Largest distance to the target of the centres and edge midpoints of ``new_faces``
        and of ``old_faces``, the first with the distance of the points ``lost`` to the new
        faces, each over the mean edge length of the old faces: two floats."""
        new = [self._corners(face, moved) for face in new_faces]
        old = [self._corners(face, None) for face in old_faces]
        samples = [_samples(corners) for corners in new + old]
        count = sum(len(sample) for sample in samples[:len(new)])
        distance = self.surface.nearest(
            np.asarray([p for sample in samples for p in sample], dtype=np.float64)).distance
        edges = [math.dist(corners[k], corners[k - 1]) for corners in old
                 for k in range(len(corners))]
        scale = sum(edges) / len(edges)
        worst_new = float(distance[:count].max())
        if lost:
            triangles = np.asarray([[corners[0], corners[k], corners[k + 1]] for corners in new
                                    for k in range(1, len(corners) - 1)], dtype=np.float64)
            points = np.repeat(np.asarray(lost, dtype=np.float64), len(triangles), axis=0)
            closest, _, _ = closest_on_triangles(np.tile(triangles, (len(lost), 1, 1)), points)
            gap = np.linalg.norm(closest - points, axis=1).reshape(len(lost), -1).min(axis=1)
            worst_new = max(worst_new, float(gap.max()))
        return worst_new / scale, float(distance[count:].max()) / scale

    def _corners(self, face, moved):
        return [moved[v][0] if moved is not None and v in moved else self.points[v]
                for v in face]

    # --- moves -------------------------------------------------------------------------

    def rotation(self, a, b, check=True):
        """Best edge rotation of edge ``(a, b)``: ``(delta, removed, new_faces, moved)`` or
        None (module docstring); with ``check`` False, the energy only."""
        first, second = self.half.get((a, b)), self.half.get((b, a))
        if first is None or second is None or (min(a, b), max(a, b)) in self.creases:
            return None
        f, g = self.faces[first], self.faces[second]
        if len(f) != 4 or len(g) != 4 or self.frozen[a] or self.frozen[b]:
            return None
        va, vb = self.valence(a), self.valence(b)
        if va <= 3 or vb <= 3:
            return None
        k, j = f.index(b), g.index(a)
        # the hexagon counter-clockwise from b: b, c, d, a (first quad), e, f (second)
        hexagon = [f[k], f[(k + 1) % 4], f[(k + 2) % 4], f[(k + 3) % 4],
                   g[(j + 1) % 4], g[(j + 2) % 4]]
        if len(set(hexagon)) != 6:
            return None
        base = _energy(va - 1) + _energy(vb - 1) - _energy(va) - _energy(vb)
        options = []
        for start in (1, 2):
            x, y = hexagon[start], hexagon[start + 3]
            if self.frozen[x] or self.frozen[y]:
                continue
            vx, vy = self.valence(x), self.valence(y)
            delta = base + (_energy(vx + 1) + _energy(vy + 1) - _energy(vx) - _energy(vy))
            if delta > 0:
                continue
            delta = (delta, self._pair_delta(a, b, x, y))
            if delta >= (0, 0):
                continue
            options.append((delta, start))
        best = None
        for delta, start in sorted(options):
            if best is not None and delta > best[0]:
                break
            x, y = hexagon[start], hexagon[start + 3]
            if (x, y) in self.half or not self.face_ring(x).isdisjoint((y,)):
                continue
            new = [[hexagon[(start + i) % 6] for i in range(4)],
                   [hexagon[(start + 3 + i) % 6] for i in range(4)]]
            if not check:
                return delta, None, None, None
            if not self.acceptable([f, g], new):
                continue
            quality = self.quality(new)
            if best is None or quality > best[4]:
                best = (delta, [first, second], new, None, quality)
        return None if best is None else best[:4]

    def neighbours(self, v):
        """The vertices joined to ``v`` by an edge."""
        found = []
        for index in self.around[v]:
            face = self.faces[index]
            found.append(face[(face.index(v) + 1) % len(face)])
        return found

    def _pair_delta(self, a, b, x, y):
        """Change of ``sum over edges (u, w) of (valence(u) - 4) (valence(w) - 4)`` by the
        rotation of edge ``(a, b)`` to ``(x, y)``: negative where it brings vertices of
        valence below 4 next to ones above 4 (which later moves can cancel)."""
        change = {a: -1, b: -1, x: 1, y: 1}
        old = {}
        for u in change:
            for w in self.neighbours(u):
                old[(min(u, w), max(u, w))] = True
        new = dict(old)
        del new[(min(a, b), max(a, b))]
        new[(min(x, y), max(x, y))] = True

        before = {v: len(self.around[v]) - REGULAR_VALENCE for edge in old for v in edge}
        after = {v: excess + change.get(v, 0) for v, excess in before.items()}
        return (sum(after[u] * after[w] for u, w in new)
                - sum(before[u] * before[w] for u, w in old))

    def collapse(self, index, k, check=True):
        """The collapse of face ``index``'s corners ``k`` and ``k + 2``:
        ``(delta, removed, new_faces, moved)`` or None."""
        face = self.faces[index]
        if face is None or len(face) != 4 or self.n_faces - 1 < self.min_faces:
            return None
        a, b, c, d = face[k], face[k + 1], face[(k + 2) % 4], face[(k + 3) % 4]
        if self.frozen[a] or self.frozen[c] or self.frozen[b] or self.frozen[d]:
            return None
        va, vb, vc, vd = (self.valence(v) for v in (a, b, c, d))
        if vb <= 3 or vd <= 3:
            return None
        delta = (_energy(va + vc - 2) + _energy(vb - 1) + _energy(vd - 1)
                 - _energy(va) - _energy(vb) - _energy(vc) - _energy(vd))
        if delta >= 0:
            return None
        if self.face_ring(a) & self.face_ring(c) != {b, d}:
            return None
        if not check:
            return delta, None, None, None
        removed = sorted(set(self.around[a]) | set(self.around[c]))
        new = []
        for other in removed:
            if other != index:
                new.append([a if v == c else v for v in self.faces[other]])
        middle = [(p + q) / 2.0 for p, q in zip(self.points[a], self.points[c])]
        moved = {a: self.on_target(middle)[0]}
        if not self.acceptable([self.faces[i] for i in removed], new, moved,
                               (self.points[a], self.points[c])):
            return None
        return delta, removed, new, moved

    def split(self, v, check=True):
        """Best vertex split of ``v``: ``(delta, removed, new_faces, moved)`` or None; the
        new vertex is numbered ``len(self.points)``."""
        if self.frozen[v] or self.n_faces + 1 > self.max_faces:
            return None
        n = self.valence(v)
        if n < 5:
            return None
        faces, ring = self.fan(v)
        options = []
        for i in range(n):
            for j in range(i + 2, n - 1 if i == 0 else n):
                x, y = ring[i], ring[j]
                if self.frozen[x] or self.frozen[y]:
                    continue
                vx, vy = self.valence(x), self.valence(y)
                delta = (_energy(j - i + 1) + _energy(n - (j - i) + 1) - _energy(n)
                         + _energy(vx + 1) + _energy(vy + 1) - _energy(vx) - _energy(vy))
                if delta < 0:
                    options.append((delta, i, j))
        if not options:
            return None
        if not check:
            return min(options)[0], None, None, None
        w = len(self.points)
        best = None
        for delta, i, j in sorted(options):
            if best is not None and delta > best[0]:
                break
            x, y = ring[i], ring[j]
            near = [f for k, f in enumerate(faces) if i <= k < j]
            far = [f for k, f in enumerate(faces) if not i <= k < j]
            placed = self.on_target(self._towards(v, near), self._towards(v, far))
            moved = {v: placed[0], w: placed[1]}
            new = [list(self.faces[f]) for f in near]
            new += [[w if u == v else u for u in self.faces[f]] for f in far]
            new.append([v, y, w, x])
            if not self.acceptable([self.faces[f] for f in faces], new, moved,
                                   (self.points[v],)):
                continue
            quality = self.quality(new, moved)
            if best is None or quality > best[4]:
                best = (delta, faces, new, moved, quality)
        return None if best is None else best[:4]

    def _towards(self, v, faces):
        """Halfway from ``v`` to the mean centre of ``faces``."""
        centre = [0.0, 0.0, 0.0]
        for index in faces:
            face = self.faces[index]
            for u in face:
                for axis in range(3):
                    centre[axis] += self.points[u][axis] / (len(face) * len(faces))
        return [(p + q) / 2.0 for p, q in zip(self.points[v], centre)]

    def _apply(self, move):
        _, removed, new, moved = move
        if moved is not None:
            for v, (point, normal) in moved.items():
                if v == len(self.points):
                    self.points.append(point)
                    self.normals.append(normal)
                    self.around.append([])
                    self.frozen.append(False)
                    self.origin.append(self.origin[min(moved)])
                else:
                    self.points[v], self.normals[v] = point, normal
        self._replace(removed, new)

    # --- the greedy search -------------------------------------------------------------

    def _candidates(self, vertices, heap):
        """Push the moves around ``vertices`` that lower the energy (cheap test)."""
        edges, faces = set(), set()
        for v in sorted(vertices):
            if v >= len(self.around) or not self.around[v]:
                continue
            faces.update(self.around[v])
            split = self.split(v, check=False)
            if split is not None:
                heapq.heappush(heap, (split[0], 0, 2, v, 0))
        for index in sorted(faces):
            face = self.faces[index]
            for k, u in enumerate(face):
                w = face[k - len(face) + 1]
                edges.add((min(u, w), max(u, w)))
            for k in (0, 1):
                found = self.collapse(index, k, check=False)
                if found is not None:
                    heapq.heappush(heap, (found[0], 0, 1, index, k))
        for a, b in sorted(edges):
            found = self.rotation(a, b, check=False)
            if found is not None:
                heapq.heappush(heap, (*found[0], 0, a, b))

    def optimise(self, max_moves):
        """Apply the best move while one lowers the energy; returns the numbers of
        rotations, collapses and splits applied."""
        heap = []
        self._candidates(range(len(self.points)), heap)
        counts = [0, 0, 0]
        # moves refused for their faces' shape or distance, by the number of moves applied
        # then; one is tried again only once a vertex near it has changed since
        refused = {}
        stamp = [0] * len(self.points)
        while heap and sum(counts) < max_moves:
            entry = heapq.heappop(heap)
            delta, kind, p, q = entry[:2], *entry[2:]
            key = (kind, p, q)
            if key in refused and all(stamp[u] <= refused[key]
                                      for u in self._region(kind, p, q)):
                continue
            self.refused = False
            if kind == 0:
                move = self.rotation(p, q)
            elif kind == 1:
                move = self.collapse(p, q)
            else:
                move = self.split(p)
            if move is None:
                if self.refused:
                    refused[key] = sum(counts)
                continue
            found = move[0] if kind == 0 else (move[0], 0)
            if found > delta:
                heapq.heappush(heap, (*found, kind, p, q))
                continue
            self.touched = set()
            self._apply(move)
            counts[kind] += 1
            stamp += [0] * (len(self.points) - len(stamp))
            for u in self.touched:
                stamp[u] = sum(counts)
            region = set(self.touched)
            for u in list(self.touched):
                region.update(self.face_ring(u))
            self._candidates(region, heap)
        return counts

    def _region(self, kind, p, q):
        """The vertices whose valences, places and faces decide the move ``(kind, p, q)``
        of :meth:`optimise` (a rotation of edge ``(p, q)``, a collapse in face ``p``, a split
        of vertex ``p``)."""
        if kind == 0:
            ends = (p, q)
        elif kind == 1:
            ends = [] if self.faces[p] is None else self.faces[p]
        else:
            ends = (p,)
        region = set(ends)
        for v in ends:
            if self.around[v]:
                region.update(self.face_ring(v))
        return region

    def mesh(self, original):
        """The edited cage as a PolyMesh (unused vertices dropped, creases renumbered) and
        the (k,) int64 input vertex each of its vertices comes from."""
        faces = [f for f in self.faces if f is not None]
        used = sorted({v for f in faces for v in f})
        renumber = {v: i for i, v in enumerate(used)}
        vertices = np.asarray([self.points[v] for v in used], dtype=np.float64)
        mesh = PolyMesh.from_faces(vertices, [[renumber[v] for v in f] for f in faces])
        if original.creases is not None:
            creases = np.asarray([[renumber[a], renumber[b]] for a, b in
                                  np.asarray(original.creases).tolist()], dtype=np.int64)
            mesh = replace(mesh, creases=creases.reshape(-1, 2))
        return mesh, np.asarray([self.origin[v] for v in used], dtype=np.int64)


def _samples(corners):
    """The centre and the edge midpoints of a face (its corners, lists of 3 floats)."""
    size = len(corners)
    centre = [sum(p[axis] for p in corners) / size for axis in range(3)]
    return [centre] + [[(p[axis] + q[axis]) / 2.0 for axis in range(3)]
                       for p, q in zip(corners, corners[1:] + corners[:1])]


def _face_quality(points, normals):
    """Shape of a face on the target: the smallest of its corners' signed sines about the
    target's normals there and of the cosines between its normal and those normals.

    points, normals : lists of (3,) float sequences, the face's corners counter-clockwise
    seen from outside and the target's unit normals at them. The sine at a corner is
    ``((p_next - p) x (p_prev - p)) . n / (|p_next - p| |p_prev - p|)``: 1 at a right angle
    turning counter-clockwise about ``n``, near 0 at a degenerate or flat corner, negative
    where the corner folds over (a reflex corner, a face facing away from the target). The
    face's normal (Newell's) against the target's normals at its corners is negative where
    the face spans a thin strut or plate (its corners on opposite walls). Returns a float in
    [-1, 1] (-1 for a face of zero area).
    """
    size = len(points)
    # the face's normal (Newell's): its cosine with the target's normal at each corner
    fx = fy = fz = 0.0
    for k in range(size):
        p, q = points[k], points[(k + 1) % size]
        fx += (p[1] - q[1]) * (p[2] + q[2])
        fy += (p[2] - q[2]) * (p[0] + q[0])
        fz += (p[0] - q[0]) * (p[1] + q[1])
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if norm == 0.0:
        return -1.0
    worst = math.inf
    for n in normals:
        worst = min(worst, (fx * n[0] + fy * n[1] + fz * n[2]) / norm)
    for k in range(size):
        p, q, r = points[k], points[(k + 1) % size], points[k - 1]
        ux, uy, uz = q[0] - p[0], q[1] - p[1], q[2] - p[2]
        vx, vy, vz = r[0] - p[0], r[1] - p[1], r[2] - p[2]
        n = normals[k]
        cross = ((uy * vz - uz * vy) * n[0] + (uz * vx - ux * vz) * n[1]
                 + (ux * vy - uy * vx) * n[2])
        length = math.sqrt((ux * ux + uy * uy + uz * uz) * (vx * vx + vy * vy + vz * vz))
        worst = min(worst, cross / length if length > 0.0 else -1.0)
    return worst
