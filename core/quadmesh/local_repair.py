# SPDX-License-Identifier: LGPL-2.1-or-later
"""Local edits of a cage at the faces still inverted after unshrinking, and where its limit
surface crosses itself.

:mod:`core.quadmesh.limit_interpolation` repairs faces whose limit surface is pulled past a
thin feature. Two other causes of inverted faces were found on paired-decimation cages:

- a quad paired across a sharp fold: its two triangles lie on two sheets of a thin wall or on
  both sides of a strut's ridge (the matching takes such a pair where an augmenting path
  needs it). Two triangles over the edge of a thin wall can be nearly opposite; the quad's
  limit surface then runs across the wall, not round it;
- a quad folded over its neighbours: QSlim can leave long sliver triangles facing away from a
  nearly flat top (:mod:`core.quadmesh.decimation.even_triangulation` untangles only planar
  regions), so a quad there is clockwise seen from outside.

Two edits act on such a face: moving one of its corners to the target point nearest the mean
of the corner's neighbours (which unfolds a folded quad and evens out a pair over a fold), and
splitting the quad into two triangles along either diagonal (each sheet of a fold then has its
own face). Most such faces go with one corner moved; a few need several edits, some of them
splits.

The same folds make the limit surfaces of neighbouring faces cross each other (a polycube
layout whose quads fold over a strongly curved chart), so the faces holding a crossing of the
level-2 limit surface are edited the same way.

For each flawed face (inverted ones first, then those holding a crossing) the edits are tried
in this order: each corner moved (the faces stay quads), then the split along each diagonal
(while the triangles stay within :data:`MAX_TRIANGLE_SHARE` of the faces). An edit is kept
when it lowers the cage's inverted faces or the self-crossings of its limit surface and raises
neither; the search then starts again on the edited cage, until no face is flawed or no edit
helps.

A polycube layout folds where its integer chart polygons differ from the charts' shapes: a
side measured nearly zero long but given a unit or two leaves quads with two corners almost
at one point, and the quads beside it fold over. A corner moved onto the target point nearest
its neighbours' mean can jump to another wall of a thin member; moving it towards that mean
in the tangent plane of the target at the corner (off the target, as the unshrinking moves
vertices) untangles such a fold without leaving the corner's wall. With ``untangle``, where
no edit above helps, the corners of each flawed face, then also their neighbours, get
:data:`UNTANGLE_ROUNDS` rounds of such tangent-plane smoothing (kept by the same rule).
"""
from dataclasses import replace
from itertools import chain

import numpy as np

from core.errors import InvalidMeshError
from core.mesh_topology import neighbour_mean
from core.polymesh_checks import check_polymesh
from core.quadmesh.crossing_count import LEVELS
from core.quadmesh.orientation import inverted_faces
from core.subdivision.limit_crossings import limit_self_intersections
from core.types import PolyMesh

MAX_TRIANGLE_SHARE = 0.1
"""Splits keep at least 90% of the faces quads (the base mesh's quad-dominance rule)."""
MAX_EDITS = 12
"""Edits kept at most (each one lowers the inverted faces or the crossings; this bounds the
time on cages with many flawed faces)."""
PATCH_FACES = 3
"""Flawed faces one edit is counted on to mend with ``untangle`` (a patch smoothed in the
tangent planes unfolds a face and its neighbours at once; without it, one face per edit)."""
UNTANGLE_ROUNDS = (1, 2, 4)
"""Rounds of tangent-plane smoothing tried per patch (``untangle`` of :func:`repair_inverted`);
more rounds spread a fold over more of the patch."""


def repair_inverted(mesh, surface, crossings, inverted, count_crossings, untangle=False):
    """The cage with its inverted faces, and the faces where its limit surface crosses
    itself, relaxed or split where that helps (module docstring).

    An edit is kept when it lowers the inverted faces or the crossing pairs and raises
    neither. A limit surface that crosses itself gives no solid, so the edits are tried on a
    crossing cage only while its flawed faces (inverted, or holding a crossing) are no more
    than the edits left (:data:`PATCH_FACES` times that with ``untangle``): each edit mends
    about one face (with ``untangle``, a patch of faces), and a cage left crossing is
    outranked by any cage that does not (the time would be lost).

    Parameters
    ----------
    mesh : PolyMesh closed 2-manifold cage (vertices on the target or moved off it).
    surface : TargetSurface of the target.
    crossings, inverted : int, the limit flaws of ``mesh`` (self-crossing triangle pairs of
        its level-2 limit surface, inverted faces).
    count_crossings : callable PolyMesh -> int, the self-crossing pairs of a cage's limit
        surface (as ``crossings`` was counted).
    untangle : bool, also try tangent-plane smoothing of the flawed faces' patches once no
        corner move or split helps (module docstring).

    Returns
    -------
    mesh : PolyMesh, ``mesh`` itself when no edit helped.
    crossings, inverted : int, its limit flaws.
    edits : int, edits kept.
    """
    edits = 0
    while (inverted or crossings) and edits < MAX_EDITS:
        flawed = np.flatnonzero(inverted_faces(mesh, surface.vertices, surface.faces, surface))
        if crossings:
            _, base_faces, _ = limit_self_intersections(mesh, LEVELS)
            crossing = np.unique(base_faces)
            flawed = np.concatenate([flawed, crossing[~np.isin(crossing, flawed)]])
            if len(flawed) > (PATCH_FACES if untangle else 1) * (MAX_EDITS - edits):
                break  # more faces than edits mend: the limit surface would still cross
        candidates = _candidates(mesh, flawed, surface)
        if untangle:
            candidates = chain(candidates, _untangled(mesh, flawed, surface))
        for candidate in candidates:
            count = int(inverted_faces(candidate, surface.vertices, surface.faces,
                                       surface).sum())
            if count > inverted or (count == inverted and not crossings):
                continue
            candidate_crossings = count_crossings(candidate)
            if candidate_crossings <= crossings and (count, candidate_crossings) != (
                    inverted, crossings):
                mesh, crossings, inverted = candidate, candidate_crossings, count
                edits += 1
                break
        else:
            break
    return mesh, crossings, inverted, edits


def _candidates(mesh, faces, surface):
    """Edited cages, lazily, in the order of the module docstring, for each of ``faces``
    ((k,) int64 face indices); edits that give an invalid cage are skipped."""
    face_list = [list(f) for f in mesh.faces()]
    centres = neighbour_mean(mesh.vertices, mesh.face_vertices, mesh.face_offsets)
    # a split makes one quad two triangles
    can_split = (mesh.face_sizes == 3).sum() + 2 <= MAX_TRIANGLE_SHARE * (mesh.n_faces + 1)
    for face in faces.tolist():
        corners = face_list[face]
        for vertex in corners:
            vertices = mesh.vertices.copy()
            vertices[vertex] = surface.nearest(centres[vertex][None]).point[0]
            yield from _valid(replace(mesh, vertices=vertices))
        if len(corners) == 4 and can_split:
            for start in (0, 1):
                a, b, c, d = np.roll(corners, -start).tolist()
                split = face_list[:face] + [[a, b, c], [c, d, a]] + face_list[face + 1:]
                # the diagonal is a new edge: every crease edge stays an edge
                yield from _valid(replace(PolyMesh.from_faces(mesh.vertices, split),
                                          creases=mesh.creases))


def _untangled(mesh, faces, surface):
    """Cages with the patch of each of ``faces`` ((k,) int64) smoothed in the target's tangent
    planes, lazily: its corners, then its corners and their neighbours, each for every number
    of :data:`UNTANGLE_ROUNDS`; invalid cages are skipped."""
    corners = mesh.face_vertices
    face_of_corner = np.repeat(np.arange(mesh.n_faces), mesh.face_sizes)
    for face in faces.tolist():
        own = corners[mesh.face_offsets[face]:mesh.face_offsets[face + 1]]
        ring = np.unique(corners[np.isin(face_of_corner,
                                         face_of_corner[np.isin(corners, own)])])
        for patch in (own, ring):
            for rounds in UNTANGLE_ROUNDS:
                yield from _valid(_tangent_smoothed(mesh, patch, surface, rounds))


def _tangent_smoothed(mesh, patch, surface, rounds):
    """``mesh`` with the vertices ``patch`` ((p,) int64) moved ``rounds`` times to the mean of
    their neighbours, each move projected onto the tangent plane of the target at the vertex
    (the plane normal to the target's normal at its closest target point)."""
    vertices = mesh.vertices.copy()
    for _ in range(rounds):
        centres = neighbour_mean(vertices, mesh.face_vertices, mesh.face_offsets)[patch]
        normal = surface.closest(vertices[patch]).normal
        step = centres - vertices[patch]
        step -= np.einsum("pk,pk->p", step, normal)[:, None] * normal
        vertices[patch] += step
    return replace(mesh, vertices=vertices)


def _valid(mesh):
    """``[mesh]`` if it is a closed 2-manifold without degenerate faces, else ``[]``."""
    try:
        check_polymesh(mesh)
    except InvalidMeshError:
        return []
    return [mesh]

