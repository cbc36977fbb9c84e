# SPDX-License-Identifier: LGPL-2.1-or-later
"""Tolerance-driven refinement of a quad-dominant cage (``--tolerance``).

After a fit, every base face gets the largest deviation between its part of the limit
surface and the target, both ways: the distance of its fine limit points to the target, and
the distance of every part of the target whose closest point on the limit surface lies in it
(:func:`core.fitting.deviation.face_deviation`). Each face deviating more than the tolerance
has the quad strip through it split (for a quad, the strip through its two longer opposite
edges; for another face, the strip across its longest edge). The strip runs through quads
across opposite edges, both ways from its seed, **only through the deviating faces**: every
quad of it is cut in two through the midpoints of its two crossed edges, and it ends in the
first face that deviates less or is not a quad. There the mesh is closed conformingly,
without T-junctions:

- a quad entered on one edge keeps its four corners and the midpoint as a fifth (a pentagon,
  which Catmull-Clark subdivides like any face; it is not split, so a strip adds faces only
  where the surface deviates);
- a quad entered on two neighbouring edges is cut into three quads around its centre, on two
  opposite edges in two, on more around its centre, one face per entry;
- another face entered once is cut from the midpoint to the corner ``(n + 1) // 2`` further
  on (a triangle into two triangles, a pentagon into two quads), entered more often around
  its centre.

Strips that ran round the whole part would triple the cage in every round, most of the new
faces where the surface is already within the tolerance, so strips end where they can. The
refined cage is placed so that its limit surface passes through the fitted one at every
vertex (a sparse linear system of the limit masks), then fitted again, until the largest
deviation is at most the tolerance or the next refinement would exceed the face budget.
Where every split of the fitted cage crosses itself (an inside fit held a thin wall back, so
its walls nearly touch), the cage the fit started from is split instead.
"""
from dataclasses import dataclass, field, replace

import numpy as np

from core.errors import ParameterError
from core.fitting.deviation import face_deviation
from core.fitting.records import FitRecord
from core.subdivision.catmull_clark import mesh_topology
from core.target_surface import TargetSurface
from core.types import PolyMesh


@dataclass(frozen=True)
class RefineSettings:
    """Tuned constants of :func:`fit_to_tolerance`."""

    crossing_rings: int = 3
    """Rings of faces around a crossing in which the deviating faces to turn or leave whole
    are looked for: the refined cage is placed on the limit surface as a whole, so a split
    can move the surface a ring or two beyond the faces it changed, and a crossing need not
    lie in or next to a deviating face."""
    uncross_tries: int = 20
    """Most refinements tried per round with the deviating faces under new crossings cut the
    other way, then left whole (each try costs a crossing search of the refined limit
    surface; a tight tolerance can need more than a few)."""


REFINE = RefineSettings()
"""The settings this module runs with."""


@dataclass
class RefinementResult:
    """Outcome of :func:`fit_to_tolerance`.

    mesh : PolyMesh, the fitted cage that met the tolerance, else the closest one (the
        smallest largest deviation of all fits).
    info : core.fitting.records.FitRecord or None, its fit's record (None: no fit yet).
    rounds : list of dict, per fit: ``faces``, ``max_deviation`` and ``mean_deviation``
        (fractions of the target's bounding-box diagonal), ``offending_faces`` and, when a
        refinement was tried after it, ``split``: which cage's strips were split (``'fitted
        cage'``, or ``'unfitted cage'`` when every split of the fitted one crossed).
    met : bool, the last fit's largest deviation is at most the tolerance.
    reason : str, why the refinement stopped.
    """

    mesh: PolyMesh
    info: FitRecord | None
    rounds: list = field(default_factory=list)
    met: bool = False
    reason: str = ""


def fit_to_tolerance(base, target, tolerance, max_faces, fit, crossing_faces=None,
                     max_rounds=8):
    """Fit, then split the deviating quad strips and refit until within ``tolerance``.

    Parameters
    ----------
    base : PolyMesh, closed 2-manifold, quad-dominant.
    target : TriMesh
    tolerance : float > 0, fraction of the target's bounding-box diagonal.
    max_faces : int, no refinement beyond this many faces.
    fit : callable ``fit(cage) -> (fitted PolyMesh, FitRecord)`` (the configured fit;
        the record's ``levels`` is the subdivision level of the fine limit points).
    crossing_faces : None, or callable ``crossing_faces(cage) -> (k, 2) int`` the base faces
        of the triangle pairs where the cage's limit surface crosses itself (at the fit's
        level). Given, a refined cage that crosses itself more than the fitted one is not
        fitted: the deviating faces under its crossings are cut the other way, then left
        whole, and the split tried again (at most ``REFINE.uncross_tries`` times,
        :func:`refined_without_crossings`), since the fit keeps the crossings it starts from.
        When no split of the fitted cage is left, the same faces of the cage it was fitted
        from are split instead (when the fit kept its faces): where an inside fit held a
        thin wall back, the fitted walls nearly touch, while the cage before the fit lies on
        the last clean surface, so the refinement can go on where splitting the fitted cage
        would stop it.
    max_rounds : int >= 1, most fits.

    Returns
    -------
    RefinementResult

    Raises
    ------
    ParameterError
        ``tolerance`` is not positive.
    """
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise ParameterError(f"tolerance must be a positive fraction of the bounding-box "
                             f"diagonal, got {tolerance!r}")
    surface = TargetSurface(target.vertices, target.faces)
    cage = base
    result = RefinementResult(base, None)
    closest = None  # (largest deviation, fitted cage, info) of the closest fit so far
    for done in range(max_rounds):
        fitted, info = fit(cage)
        deviation = face_deviation(fitted, surface, tolerance)
        per_face = deviation.per_face
        offending = np.flatnonzero(per_face > tolerance)
        result.rounds.append({"faces": int(fitted.n_faces),
                              "max_deviation": float(per_face.max()),
                              "mean_deviation": float(info.figures.distances.mean_distance),
                              "offending_faces": int(len(offending)),
                              "unproven_area": deviation.unproven_area})
        if closest is None or per_face.max() < closest[0]:
            closest = (per_face.max(), fitted, info)
        if not len(offending):
            result.mesh, result.info = fitted, info
            result.met = deviation.unproven_area == 0
            result.reason = ("tolerance met" if result.met else
                             f"tolerance not proven: {deviation.unproven_area:.1%} of the "
                             f"target's area lies in pieces too many to look at closely")
            return result
        deviating = per_face > tolerance
        refined, why_not = refined_without_crossings(fitted, deviating, crossing_faces)
        split = "fitted cage"
        if refined is None and fitted.n_faces == cage.n_faces:
            refined, _ = refined_without_crossings(cage, deviating, crossing_faces)
            split = "unfitted cage"
        if refined is not None:
            result.rounds[-1]["split"] = split
        if refined is None:
            why_not = f"tolerance not met: {why_not}"
        elif refined.n_faces > max_faces:
            why_not = (f"tolerance not met: the next refinement would have {refined.n_faces} "
                       f"faces, more than max_base_faces={max_faces}")
        elif done == max_rounds - 1:
            why_not = f"tolerance not met after {max_rounds} fits"
        else:
            cage = refined
            continue
        _, result.mesh, result.info = closest
        result.reason = why_not + (
            "" if result.mesh is fitted else
            f"; the closest fit is kept ({result.mesh.n_faces} faces, largest deviation "
            f"{closest[0]:.3g} of the diagonal)")
        return result


@dataclass(frozen=True)
class StripSplit:
    """Which quad strips :func:`split_quad_strips` split: its ``seeds`` ((s, 2) int64) and
    ``within`` ((m,) bool), so that other positions of the same cage can be split the same
    way (:func:`split_positions`, :func:`split_values`)."""

    seeds: np.ndarray
    within: np.ndarray


def refined_without_crossings(fitted, deviating, crossing_faces, with_split=False):
    """The cage ``fitted`` with the strips of its ``deviating`` (m,) bool faces split, placed
    on its limit surface (``keep_limit``), and faces left whole where that made the limit
    surface cross itself more than the cage's (see :func:`fit_to_tolerance`; the cage need
    not be fitted, :mod:`core.fitting.outside_refinement` refines the unfitted one).

    The deviating faces under the crossings (or, where every crossing lies in faces that
    do not deviate, such as those where strips ended, the deviating faces nearest to them,
    up to ``REFINE.crossing_rings`` rings of faces away) are cut the other way next time (a
    quad across its shorter edges, another face across its second-longest edge); those
    already turned are left whole: a strip that crosses itself cut one way often does not
    cut the other.

    Returns ``(refined PolyMesh, None)``, or ``(None, reason str)`` when no deviating face
    could be split without a crossing; with ``with_split``, a third element, the
    :class:`StripSplit` that made the refined cage (None when there is none).
    """
    refined, seeds, within, why_not = _split_without_crossings(fitted, deviating,
                                                               crossing_faces)
    if not with_split:
        return refined, why_not
    return refined, why_not, None if refined is None else StripSplit(seeds, within)


def split_positions(cage, split, vertices):
    """(n', 3) float64 vertices of ``cage`` split by ``split`` (:class:`StripSplit`) and placed
    on the limit surface of ``vertices`` ((n, 3) other positions of the cage's vertices, such
    as a fit of it) instead of the cage's own (:func:`split_quad_strips` with
    ``keep_limit``)."""
    moved = replace(cage, vertices=np.asarray(vertices, dtype=np.float64))
    return split_quad_strips(moved, split.seeds, within=split.within, keep_limit=True).vertices


def split_values(cage, split, values):
    """(n',) float64 ``values`` ((n,) float, one per vertex of ``cage``) on the vertices of the
    cage split by ``split`` (:class:`StripSplit`): the same at the cage's vertices, the mean
    of the ends at a new edge midpoint and of the corners at a new face centre."""
    padded = np.zeros((len(values), 3))
    padded[:, 0] = values
    return split_quad_strips(replace(cage, vertices=padded), split.seeds,
                             within=split.within).vertices[:, 0]


def _split_without_crossings(fitted, deviating, crossing_faces):
    """:func:`refined_without_crossings`: ``(refined PolyMesh, seeds, within, None)`` (the
    ``seeds`` and ``within`` of :func:`split_quad_strips` that made it), or
    ``(None, None, None, reason str)``."""
    within = deviating.copy()
    turned = np.zeros(len(within), dtype=bool)
    topology = mesh_topology(fitted.face_vertices, fitted.face_offsets, len(fitted.vertices))
    allowed = None
    for tries in range(REFINE.uncross_tries + 1):
        if not within.any():
            return None, None, None, (
                "splitting the deviating faces makes the refined limit surface cross itself "
                "(thin or sharp features under them need other faces)")
        seeds = _seed_directions(fitted, np.flatnonzero(within), turned)
        refined, parent = split_quad_strips(fitted, seeds, within=within, keep_limit=True,
                                            with_parent=True)
        if crossing_faces is None:
            return refined, seeds, within, None
        if allowed is None:
            allowed = len(crossing_faces(fitted))
        crossing = crossing_faces(refined)
        if len(crossing) <= allowed:
            return refined, seeds, within, None
        under = np.zeros(len(within), dtype=bool)
        under[parent[np.unique(crossing)]] = True
        hit = under & within
        for _ in range(REFINE.crossing_rings):  # crossings where strips ended, or a ring further
            if hit.any():
                break
            under[topology.face_of_corner[topology.twin[np.flatnonzero(
                under[topology.face_of_corner])]]] = True
            hit = under & within
        if not hit.any():
            break
        within[hit & turned] = False  # crossed both ways: left whole
        turned[hit] = True
    return None, None, None, (
        f"splitting the deviating faces makes the refined limit surface cross itself "
        f"({len(crossing)} triangle pairs after {tries + 1} tries turning faces or leaving "
        f"them whole)")


def split_quad_strips(cage, seeds, within=None, keep_limit=False, with_parent=False):
    """Split the quad strips through ``seeds`` conformingly.

    A strip runs through quads across opposite edges, both ways from its seed, until it
    closes, enters a face that is not a quad or leaves ``within``, where it ends; the face it
    ends in is closed as the module docstring says.

    Parameters
    ----------
    cage : PolyMesh, closed 2-manifold; faces of any size.
    seeds : (s, 2) int64 rows ``(face, edge)``. A quad is crossed through its local edges
        ``edge`` and ``edge + 2`` (edge ``k`` joins corners ``k`` and ``k + 1``; 0 and 1 are
        its two directions); a strip seeded in another face starts across its edge ``edge``.
    within : None, or (m,) bool faces the strips may run through (the seeds' faces should
        be among them); None: strips run until they close or meet a face that is not a quad.
    keep_limit : bool, place the vertices so the refined limit surface passes through the
        cage's at every refined vertex (:func:`_on_the_limit_of`) instead of keeping the
        cage's vertices and adding edge midpoints and face centres.
    with_parent : bool, also return ``parent`` (m',) int64, the cage face each refined face
        lies in.

    Returns
    -------
    PolyMesh, the new vertices (after the cage's) at the midpoints of the split edges, then
    the centres of the faces cut in four or around their centre (with ``keep_limit``, all
    of them moved); both halves of a split crease edge are crease edges.
    """
    sizes = cage.face_sizes
    offsets = cage.face_offsets
    topology = mesh_topology(cage.face_vertices, offsets, len(cage.vertices))
    quad = sizes == 4
    split = np.zeros((cage.n_faces, 2), dtype=bool)  # quads: crossed through edges (k, k + 2)
    entered = np.zeros(len(cage.face_vertices), dtype=bool)  # other faces: cut edges (corners)

    def walk(corner):
        """Follow a strip out of its face across the edge starting at ``corner``."""
        while True:
            across = int(topology.twin[corner])
            face = int(topology.face_of_corner[across])
            if not quad[face] or (within is not None and not within[face]):
                entered[across] = True
                return
            edge = across - int(offsets[face])
            if split[face, edge % 2]:
                return
            split[face, edge % 2] = True
            corner = int(offsets[face]) + (edge + 2) % 4

    for face, edge in np.asarray(seeds, dtype=np.int64).reshape(-1, 2):
        first = int(offsets[face])
        if quad[face]:
            if split[face, edge % 2]:
                continue
            split[face, edge % 2] = True
            walk(first + edge % 2)
            walk(first + edge % 2 + 2)
        elif not entered[first + edge]:
            entered[first + edge] = True
            walk(first + edge)
    corner_cut = entered.copy()
    quad_corners = offsets[:-1][quad][:, None] + np.arange(4)
    corner_cut[quad_corners] |= np.concatenate([split[quad], split[quad]], axis=1)
    refined, origin, parent = _cut_faces(cage, topology, corner_cut)
    if keep_limit:
        refined = _on_the_limit_of(cage, refined, origin)
    return (refined, parent) if with_parent else refined


def _cut_faces(cage, topology, corner_cut):
    """The faces of ``cage`` cut at the midpoints of the edges of ``corner_cut`` (k,) bool.

    As the module docstring says: a quad cut on one edge becomes a pentagon, on two
    neighbouring edges three quads around its centre, on opposite edges two quads; a face
    cut on one edge (other than a quad) is cut from the midpoint to the corner
    ``(n + 1) // 2`` further on; every other cut face around its centre, one face per cut
    (a quad cut on all four edges: four quads).

    Returns
    -------
    refined : PolyMesh, the cage's vertices, then the midpoints of the cut edges, then the
        centres of the faces cut around them.
    origin : (n',) int64 the vertex of the cage's first Catmull-Clark refinement (old
        vertices ``0..n-1``, face points ``n + face``, edge points ``n + m + edge``, as
        :func:`core.subdivision.catmull_clark.subdivision_operator` numbers them) at the
        same place of the surface's parameter domain as each vertex of ``refined``.
    parent : (m',) int64 the cage face each face of ``refined`` lies in.
    """
    edge_cut = np.zeros(len(topology.edges), dtype=bool)
    edge_cut[topology.corner_edge[corner_cut]] = True
    V = np.asarray(cage.vertices, dtype=np.float64)
    n = len(V)
    cut_edges = np.flatnonzero(edge_cut)
    midpoint = np.full(len(topology.edges), -1, dtype=np.int64)
    midpoint[cut_edges] = n + np.arange(len(cut_edges))
    new_points = [V[topology.edges[cut_edges]].mean(axis=1)]
    origin = [np.arange(n), n + cage.n_faces + cut_edges]
    next_index = n + len(cut_edges)
    faces, parent = [], []
    for face in range(cage.n_faces):
        first = len(faces)
        corners = np.arange(cage.face_offsets[face], cage.face_offsets[face + 1])
        ring = cage.face_vertices[corners]
        mids = midpoint[topology.corner_edge[corners]]
        cuts = np.flatnonzero(mids >= 0)
        size = len(ring)
        if len(cuts) == 0:
            faces.append(ring)
        elif size == 4 and len(cuts) == 1:
            i = cuts[0]
            faces.append(np.concatenate([ring[:i + 1], [mids[i]], ring[i + 1:]]))
        elif size == 4 and len(cuts) == 2 and (cuts[1] - cuts[0]) % 2:
            i = cuts[0] if cuts[1] == cuts[0] + 1 else cuts[1]  # the first of the two
            j, centre = (i + 1) % 4, next_index
            next_index += 1
            new_points.append(V[ring].mean(axis=0)[None])
            origin.append([n + face])
            faces += [np.array([centre, mids[i], ring[j], mids[j]]),
                      np.array([centre, mids[j], ring[(j + 1) % 4], ring[(j + 2) % 4]]),
                      np.array([centre, ring[(j + 2) % 4], ring[i], mids[i]])]
        elif len(cuts) == 1 or (size == 4 and len(cuts) == 2 and cuts[1] - cuts[0] == 2):
            i = cuts[0]
            j = (i + (size + 1) // 2) % size if len(cuts) == 1 else cuts[1]
            # corners i+1 .. j on one side of the cut, j(+1) .. i on the other
            one = [mids[i]] + [ring[(i + 1 + t) % size] for t in range((j - i) % size)]
            other = [ring[(j + 1 + t) % size] for t in range((i - j) % size)] + [mids[i]]
            if len(cuts) == 2:
                one, other = one + [mids[j]], [mids[j]] + other
            else:
                other = [ring[j]] + other
            faces += [np.array(one), np.array(other)]
        else:
            centre = next_index
            next_index += 1
            new_points.append(V[ring].mean(axis=0)[None])
            origin.append([n + face])
            for a, b in zip(cuts, np.roll(cuts, -1)):
                between = [ring[(a + 1 + t) % size] for t in range((b - a) % size)]
                faces.append(np.array([centre, mids[a]] + between + [mids[b]]))
        parent += [face] * (len(faces) - first)
    vertices = np.vstack([V] + new_points)
    face_vertices = np.concatenate(faces).astype(np.int64)
    face_offsets = np.concatenate([[0], np.cumsum([len(f) for f in faces])]).astype(np.int64)
    creases = None
    if cage.n_creases:
        pairs = np.asarray(cage.creases, dtype=np.int64)
        crease_mid = midpoint[topology.edge_index(pairs[:, 0], pairs[:, 1])]
        cut = crease_mid >= 0
        creases = np.concatenate([pairs[~cut], np.stack([pairs[cut, 0], crease_mid[cut]], axis=1),
                                  np.stack([crease_mid[cut], pairs[cut, 1]], axis=1)])
    return (PolyMesh(vertices, face_vertices, face_offsets, creases),
            np.concatenate(origin).astype(np.int64), np.asarray(parent, dtype=np.int64))


def _on_the_limit_of(cage, refined, origin):
    """``refined`` with vertices whose limit positions lie on the limit surface of ``cage``.

    Each vertex of ``refined`` is asked to have its limit position where the limit surface of
    ``cage`` has the same parameter (``origin``: the limit positions of the cage's first
    refinement, where Catmull-Clark subdivision leaves the surface unchanged), a sparse
    square system ``L' V' = P`` (``L'``: the refined cage's vertex limit masks). So the refined
    surface interpolates the fitted one at all its vertices and stays close between them;
    with the edge midpoints of the fitted cage as vertices instead, the refined limit
    surface can cross itself where the fitted one does not, and the refit keeps what it
    started from. Where the system is
    singular, the midpoint cage is returned unchanged.
    """
    import scipy.sparse.linalg as sla

    from core.subdivision.catmull_clark import subdivide
    from core.subdivision.limit import limit_matrices, vertex_limit_matrix

    fine, _ = subdivide(cage)  # all quads: its limit masks apply directly
    on_surface = (limit_matrices(fine)[0] @ fine.vertices)[origin]
    with np.errstate(all="ignore"):
        vertices = sla.splu(vertex_limit_matrix(refined).tocsc()).solve(on_surface)
    if not np.isfinite(vertices).all():
        return refined
    return PolyMesh(vertices, refined.face_vertices, refined.face_offsets, refined.creases)


def _seed_directions(cage, faces, turned=None):
    """(s, 2) rows ``(face, edge)``: cut each face across its longest edge (a quad across its
    two longer opposite edges), or, where ``turned`` ((m,) bool) says so, across its
    second-longest edge (a quad across its shorter ones)."""
    rows = []
    V = cage.vertices
    for face in faces:
        ring = cage.face_vertices[cage.face_offsets[face]:cage.face_offsets[face + 1]]
        length = np.linalg.norm(V[np.roll(ring, -1)] - V[ring], axis=1)
        if len(ring) == 4:
            length = length[:2] + length[2:]  # the two directions
        rank = 1 if turned is not None and turned[face] else 0
        rows.append((face, int(np.argsort(-length, kind="stable")[rank])))
    return np.asarray(rows, dtype=np.int64).reshape(-1, 2)
