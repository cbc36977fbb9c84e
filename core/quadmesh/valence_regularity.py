# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fewer extraordinary vertices on a quad-dominant cage by local connectivity edits.

Pairing the triangles of a decimated target (:mod:`core.quadmesh.decimation.paired_decimation`)
leaves about half of the cage's vertices extraordinary (valence other than 4): a triangle mesh
has valence 6 on average, and which pairs a matching takes does not look at the valences it
leaves. Every extraordinary vertex is a corner where the limit surface is only G1 and where
the exported patches need extra knots, and a CAD user sees it as a fan of faces.

Two edits of quad-mesh simplification (Tarini, Pietroni, Cignoni, Panozzo & Puppo,
"Practical quad mesh simplification", Eurographics 2010) lower the valence energy
``E = sum_v (valence(v) - 4)^2`` without touching the cage's topology:

- **edge rotation**: the edge between two quads is turned to the other diagonal of their
  hexagon (either way round), so its two ends lose a face each and two hexagon corners gain
  one; a valence-5 pair next to a valence-3 pair becomes four regular vertices;
- **diagonal collapse**: a quad is collapsed along a diagonal, its two ends merged at the
  one of them that leaves the better-shaped faces, so it stays on the target (valence
  ``v_a + v_c - 2``, two valence-3 corners become one regular vertex) and
  the other two corners lose a face. The cage loses one face per collapse.

Both are applied greedily, largest energy decrease first, in passes until no edit lowers the
energy. An edit is kept only if the faces it makes are not worse-shaped than
:attr:`RegularitySettings.quality_floor` (or than the faces they replace, if those were
worse already) and do not turn away from them, so the cage keeps following the target; it is
refused where it would change the topology (the link condition), merge a crease vertex or
turn a crease edge (crease edges stay edges).
"""
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RegularitySettings:
    """Tuned constants of :func:`regularise_valences`."""

    quality_floor: float = 0.15
    """Least scaled Jacobian (sine of the worst corner angle, measured about the quad's
    diagonal normal) an edit's quads may have unless the replaced quads were worse: lower
    floors remove more extraordinary vertices but make sharper quads, whose limit surface
    the fit folds more easily."""
    min_normal_agreement: float = 0.5
    """Least cosine between an edited face's normal and the normal of the faces it replaces
    (60 degrees): an edit may not tilt the surface across a ridge."""
    passes: int = 12
    """Most rounds of rotations followed by collapses (each round that changes nothing ends
    the edits; the energy falls in every round that does, so this only bounds the time)."""


REGULARITY = RegularitySettings()
"""The settings this module runs with."""


@dataclass(frozen=True)
class RegularisedCage:
    """A cage after :func:`regularise_valences`.

    Attributes
    ----------
    vertices : (n, 3) float64, the input's vertices with each collapse's kept end moved to
        where the merged vertex goes (one of the two ends' positions; the merged-away end is
        unused and left in place).
    faces : list of lists of int, the faces (outward, indices into ``vertices``).
    rotations, collapses : int, the edits made.
    """

    vertices: np.ndarray
    faces: list
    rotations: int
    collapses: int


def regularise_valences(vertices, faces, fixed_vertices=(), settings=REGULARITY):
    """Lower the valence energy of a closed quad-dominant cage (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64 cage vertices (model units).
    faces : sequence of int sequences, outward quads and triangles of a closed 2-manifold.
    fixed_vertices : collection of int, vertices that are never merged and whose edges
        between two of them are never turned (the ends of crease edges).
    settings : RegularitySettings

    Returns
    -------
    RegularisedCage, with the same genus and at most as many faces.
    """
    V = np.array(vertices, dtype=np.float64)
    faces = [list(map(int, face)) for face in faces]
    fixed = frozenset(int(v) for v in fixed_vertices)
    rotations = collapses = 0
    for _ in range(settings.passes):
        turned = _rotate_edges(V, faces, fixed, settings)
        merged = _collapse_diagonals(V, faces, fixed, settings)
        rotations, collapses = rotations + turned, collapses + merged
        if not turned and not merged:
            break
    faces = [face for face in faces if face]
    return RegularisedCage(V, faces, rotations, collapses)


def _rotate_edges(V, faces, fixed, settings):
    """One pass of edge rotations on ``faces`` (edited in place); returns how many."""
    valence = _valences(faces, len(V))
    half_edges = _half_edges(faces)
    candidates = []
    for (u, v), first in half_edges.items():
        second = half_edges.get((v, u))
        if u > v or second is None or len(faces[first]) != 4 or len(faces[second]) != 4:
            continue
        if (u in fixed and v in fixed) or valence[u] < 4 or valence[v] < 4:
            continue
        hexagon = _hexagon(faces[first], faces[second], u, v)
        if hexagon is None:
            continue
        for turn in (1, 2):
            gain = _rotation_gain(valence, hexagon, turn)
            if gain < 0:
                candidates.append((gain, u, v, turn, first, second))
    candidates.sort()
    edited, done = set(), 0
    for _, u, v, turn, first, second in candidates:
        if first in edited or second in edited:
            continue
        if valence[u] < 4 or valence[v] < 4:
            continue
        hexagon = _hexagon(faces[first], faces[second], u, v)
        if hexagon is None or _rotation_gain(valence, hexagon, turn) >= 0:
            continue
        x, y = hexagon[turn], hexagon[turn + 3]
        if (x, y) in half_edges or (y, x) in half_edges:
            continue  # the new diagonal is an edge already: two edges between x and y
        one = [hexagon[(turn + k) % 6] for k in range(4)]
        two = [hexagon[(turn + 3 + k) % 6] for k in range(4)]
        if not _acceptable(V, [faces[first], faces[second]], [one, two], settings):
            continue
        for index in (first, second):
            face = faces[index]
            for k in range(4):
                del half_edges[(face[k], face[(k + 1) % 4])]
        faces[first], faces[second] = one, two
        half_edges.update(_half_edges([one, two], (first, second)))
        for w, step in ((u, -1), (v, -1), (x, 1), (y, 1)):
            valence[w] += step
        edited.update((first, second))
        done += 1
    return done


def _collapse_diagonals(V, faces, fixed, settings):
    """One pass of diagonal collapses on ``faces`` (edited in place: a collapsed quad becomes
    an empty list) and ``V`` (the kept end moved); returns how many."""
    valence = _valences(faces, len(V))
    around = _faces_around(faces, len(V))
    neighbours = _neighbours(faces, len(V))
    candidates = []
    for index, face in enumerate(faces):
        if len(face) != 4:
            continue
        for start in (0, 1):
            a, b, c, d = (face[(start + k) % 4] for k in range(4))
            gain = _collapse_gain(valence, a, b, c, d)
            if gain < 0 and a not in fixed and c not in fixed:
                candidates.append((gain, index, start))
    candidates.sort()
    touched, done = set(), 0
    for _, index, start in candidates:
        face = faces[index]
        if len(face) != 4:
            continue
        a, b, c, d = (face[(start + k) % 4] for k in range(4))
        if touched.intersection((a, b, c, d)) or valence[b] < 4 or valence[d] < 4:
            continue
        # link condition: a and c share only this quad and its two other corners
        if neighbours[a] & neighbours[c] != {b, d} or len(around[a] & around[c]) != 1:
            continue
        changed = sorted((around[a] | around[c]) - {index})
        before = [faces[i] for i in changed]
        after = [[a if w == c else w for w in faces[i]] for i in changed]
        place = _merged_position(V, before, after, a, c, settings)
        if place is None:
            continue
        V[a] = place
        for i, new in zip(changed, after):
            faces[i] = new
        faces[index] = []
        touched.update(neighbours[a] | neighbours[c] | {a, b, c, d})
        valence[a] += valence[c] - 2
        valence[b] -= 1
        valence[d] -= 1
        done += 1
    faces[:] = [face for face in faces if face]
    return done


def _merged_position(V, before, after, a, c, settings):
    """(3,) float64 where the merged vertex of a collapse of ``c`` onto ``a`` goes: the end
    of the two (both lie on the target) whose faces ``after`` are better shaped, among those
    :func:`_acceptable` allows; None when neither is."""
    best, place = None, None
    for end in (a, c):
        if not _acceptable(V, before, after, settings, moved=(a, V[end])):
            continue
        W = V.copy()
        W[a] = V[end]
        worst = min((_quality(W[face]) for face in after if len(face) == 4), default=1.0)
        if best is None or worst > best:
            best, place = worst, V[end].copy()
    return place


def _rotation_gain(valence, hexagon, turn):
    """Change of the valence energy when the diagonal ``hexagon[0]-hexagon[3]`` turns to
    ``hexagon[turn]-hexagon[turn + 3]``."""
    return (_step(valence[hexagon[0]], -1) + _step(valence[hexagon[3]], -1)
            + _step(valence[hexagon[turn]], 1) + _step(valence[hexagon[turn + 3]], 1))


def _collapse_gain(valence, a, b, c, d):
    """Change of the valence energy when the quad ``(a, b, c, d)`` collapses ``c`` onto
    ``a``."""
    merged = valence[a] + valence[c] - 2
    return ((merged - 4) ** 2 - (valence[a] - 4) ** 2 - (valence[c] - 4) ** 2
            + _step(valence[b], -1) + _step(valence[d], -1))


def _step(valence, change):
    """Change of ``(valence - 4)^2`` when ``valence`` changes by ``change``."""
    return (valence + change - 4) ** 2 - (valence - 4) ** 2


def _hexagon(first, second, u, v):
    """The six corners of two quads sharing the edge ``u -> v`` (in ``first``; ``v -> u`` in
    ``second``), in their order round the union, ``u`` first and ``v`` fourth; None when
    they share more than that edge."""
    one = _starting_at(first, u)
    two = _starting_at(second, v)
    if one[1] != v or two[1] != u:
        return None
    hexagon = [u, two[2], two[3], v, one[2], one[3]]
    return hexagon if len(set(hexagon)) == 6 else None


def _starting_at(face, vertex):
    """``face`` rotated to start at ``vertex``."""
    k = face.index(vertex)
    return face[k:] + face[:k]


def _acceptable(V, before, after, settings, moved=None):
    """Whether the faces ``after`` may replace ``before`` (the same count, in step): every
    quad of ``after`` at least as well shaped as the floor or its predecessor, and every face
    within :attr:`RegularitySettings.min_normal_agreement` of the mean normal of ``before``
    (``moved``: a vertex and its new position for ``after``)."""
    W = V
    if moved is not None:
        W = V.copy()
        W[moved[0]] = moved[1]
    reference = sum(_normal(V[face]) for face in before)
    reference = reference / max(np.linalg.norm(reference), np.finfo(float).tiny)
    worst_before = min((_quality(V[face]) for face in before if len(face) == 4), default=1.0)
    floor = min(settings.quality_floor, worst_before)
    for face in after:
        P = W[face]
        if float(np.dot(_normal(P), reference)) < settings.min_normal_agreement:
            return False
        if len(face) == 4 and _quality(P) < floor:
            return False
    return True


def _normal(P):
    """(3,) unit normal of a face's corners ``P`` ((k, 3), k = 3 or 4): across a quad's
    diagonals, of a triangle's plane."""
    normal = np.cross(P[2] - P[0], P[-1] - P[1]) if len(P) == 4 else np.cross(P[1] - P[0],
                                                                              P[2] - P[0])
    return normal / max(np.linalg.norm(normal), np.finfo(float).tiny)


def _quality(P):
    """Scaled Jacobian of a quad's corners ``P`` ((4, 3)): the least sine of its corner angles
    about its diagonal normal (1 for a rectangle, <= 0 where a corner is reflex)."""
    normal = _normal(P)
    ahead = np.roll(P, -1, axis=0) - P
    behind = np.roll(P, 1, axis=0) - P
    sines = np.cross(ahead, behind) @ normal
    lengths = np.linalg.norm(ahead, axis=1) * np.linalg.norm(behind, axis=1)
    return float(np.min(sines / np.maximum(lengths, np.finfo(float).tiny)))


def _valences(faces, n):
    """(n,) int64 faces round each vertex."""
    return np.bincount(np.concatenate([face for face in faces if face]), minlength=n)


def _half_edges(faces, indices=None):
    """dict ``(u, v) -> face index`` of the directed edges of ``faces`` (their indices
    ``indices``, default their positions)."""
    indices = range(len(faces)) if indices is None else indices
    return {(face[k], face[(k + 1) % len(face)]): index
            for index, face in zip(indices, faces) for k in range(len(face))}


def _faces_around(faces, n):
    """list of sets: the faces round each vertex."""
    around = [set() for _ in range(n)]
    for index, face in enumerate(faces):
        for w in face:
            around[w].add(index)
    return around


def _neighbours(faces, n):
    """list of sets: the vertices joined to each vertex by an edge."""
    joined = [set() for _ in range(n)]
    for face in faces:
        for k, w in enumerate(face):
            following = face[(k + 1) % len(face)]
            joined[w].add(following)
            joined[following].add(w)
    return joined
