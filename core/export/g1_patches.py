# SPDX-License-Identifier: LGPL-2.1-or-later
"""Tangent-continuous (G1) bicubic B-spline patches of a Catmull-Clark cage, few poles each.

The light alternative to the graded export (:mod:`core.export.bspline`): one B-spline face
per quad of the cage, with two double interior knots per direction at most. A cage with
other faces is built on its first Catmull-Clark refinement (the same limit surface, all
quads), and the four patches of each base quad are joined back into one face
(:func:`core.export.quad_blocks.base_face_blocks`, :func:`core.export.chart_faces.chart_patches`:
knot insertion, then every knot the surface does not need removed within
:data:`core.export.chart_faces.MERGE_TOLERANCE`; the four patches are made to join C2, so
this leaves at most a single knot line at 1/2 per direction besides the corner knots,
:func:`_base_join_system`, unless those joins contradict the G1 conditions, when the patches
join C1 and a double knot line may stay); a face with ``n != 4`` corners keeps its ``n``
patches.

Method
------
* A *regular* quad (its four corners have valence 4) is exactly its limit surface: the
  bicubic Bezier patch of its 4 x 4 B-spline stencil (C2 with its regular neighbours).
* A quad with an extraordinary corner (EV, valence ``n != 4``) or a crease vertex in its
  stencil becomes a *free* patch: a bicubic B-spline with double knots at ``h`` and ``1 - h``
  in each direction (``h`` = :data:`EV_SPAN`; 8 x 8 poles, C1 inside), of which it keeps
  only those at the ends of a direction with a *special* corner (an EV, a dart, a corner of
  three or more creases, or a crease vertex with a sector whose connection is not C1,
  :func:`_special_vertices`; a corner in a two-face sector of a crease vertex counts only
  when the direction's other end has a special corner too, :func:`_kept_knots`): elsewhere
  it is one cubic across the knot (linear conditions below), and the knot is removed from
  the result (6 x 6 poles at one such corner, 4 x 4 without, as next to a valence-4 crease
  vertex with two faces on each side). Its poles are the solution of one
  sparse least-squares problem over all free patches: they fit exact limit points (the
  squared distance integrated by 4 x 4 Gauss points per pair of knot spans) subject to

  - C0: neighbouring patches share their boundary poles (one unknown per shared pole; a
    free patch's side next to a regular quad takes the quad's side, its knot-inserted
    Bezier row);
  - G1 along every edge next to a free patch, with the symmetric connection of
    Peters' G1 constructions: for the edge ``b(t)`` from vertex ``A`` to ``B`` and the
    inward cross-boundary derivatives ``L(t)``, ``R(t)`` of its two patches,
    ``L(t) + R(t) = alpha(t) b'(t)`` with
    ``alpha(t) = 2 cos(2 pi / n_A) phi(t) - 2 cos(2 pi / n_B) phi(1 - t)``,
    ``phi(t) = (1 - t / h)^2`` on ``[0, h]`` and 0 beyond (:func:`connection_alpha`):
    C1 (``alpha = 0``) at valence 4 and on the middle span, where the limit surface is C2
    across the edge like a regular B-spline, so the departure from the limit stays in the
    corner spans. Both sides are cubic on each knot span (the edge curve is quadratic on
    a corner span at an EV), so the condition holds identically once it holds at four
    parameters per span. At an EV it forces the spoke tangents into one plane (the
    relation ``x_{k-1} + x_{k+1} = 2 cos(2 pi / n) x_k`` of an affine image of a regular
    ``n``-gon), so the patches share a normal there.
  - none across sharp crease edges (the patches share the edge only, C0); at a vertex with
    crease edges each sector of faces between two of them has its own cosines in place of
    ``cos(2 pi / n)`` (:func:`_corner_cosines`: a half fan at a crease vertex, the exact
    limit's tangent relation at a corner).

  The constrained fit is one sparse KKT system, factored once in a regularised
  (quasi-definite) form, the conditions as a penalty of weight :data:`G1_PENALTY` relative
  to the fit, and refined to the conditions met up to rounding (:func:`_solve`).
  Everything is linear in the cage with fixed coefficients: every pole is a fixed affine
  combination of cage vertices (weights summing to 1), so translating or scaling the cage
  translates or scales the patches.

The patches meet along whole sides; the shared vertices and edges are returned as a
:class:`core.export.brep_topology.BRepTopology` (an edge next to a regular quad takes the
quad's Bezier row, an edge between two free patches their shared row on the knots that
patch keeps).
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.linalg import null_space
from scipy.sparse.linalg import splu

from core.errors import ExportError
from core.optional_imports import optional_module
from core.export.brep_topology import CORNER_UV, BRepTopology, EdgeCurve
from core.export.chart_faces import chart_patches
from core.export.corner_warp import corner_growth, spoke_growth, warped_params
from core.export.quad_blocks import base_face_blocks
from core.export.bspline_basis import basis_matrix
from core.export.bspline_measure import normal_jumps, patch_deviation
from core.export.spline_knots import insertion_matrix
from core.export.patch_context import PatchContext
from core.subdivision.catmull_clark import crease_edge_mask, mesh_topology, vertex_crease_counts
from core.subdivision.limit import quad_mesh_of, quad_stencils
from core.params import check_face_form
from core.types import BSplinePatch, PatchSet

mumps = optional_module("mumps", package="python-mumps")

EV_SPAN = 0.125
"""Length ``h`` of a free patch's corner knot spans: the part of an edge next to an
extraordinary vertex on which the G1 connection departs from C1."""
SPLIT_KNOTS = np.array([0.0, EV_SPAN, 1.0 - EV_SPAN, 1.0])
SPLIT_MULTS = np.array([4, 2, 2, 4], dtype=np.int64)
BEZIER_KNOTS = np.array([0.0, 1.0])
BEZIER_MULTS = np.array([4, 4], dtype=np.int64)
N_SPLIT = int(SPLIT_MULTS.sum()) - 4
"""Poles per direction of a free patch (cubic, double knots at h and 1 - h)."""
G1_PENALTY = 1.0e4
"""Weight of the G1 and C1 conditions against the fit to limit points in the regularised KKT
system that is factored (:func:`_solve`; refinement then meets them up to rounding)."""
REFINE_STEPS = 20
"""Most steps of iterative refinement of the G1 fit's KKT system after its regularised
factorisation (:func:`_solve_quasi_definite`)."""
G1_RESIDUAL_MAX = 1.0e-6
"""Largest residual of the G1 conditions accepted, as a fraction of the bounding-box diagonal
(per unit parameter; solved conditions leave rounding, about 1e-11)."""

BSPLINE_TO_BEZIER = np.array([[1.0, 4.0, 1.0, 0.0], [0.0, 4.0, 2.0, 0.0],
                              [0.0, 2.0, 4.0, 0.0], [0.0, 1.0, 4.0, 1.0]]) / 6.0
"""(4, 4) Bezier points of the middle span of a uniform cubic B-spline from its 4 poles."""


def _bernstein(s):
    """(len(s), 4) cubic Bernstein polynomials at ``s`` in [0, 1]."""
    s = np.asarray(s, dtype=np.float64)[:, None]
    k = np.arange(4)
    return np.array([1.0, 3.0, 3.0, 1.0]) * s ** k * (1.0 - s) ** (3 - k)


def _span_bezier(a, b):
    """(4, N_SPLIT) Bezier points of the span [a, b] of a free curve from its poles."""
    s = np.linspace(0.0, 1.0, 4)
    return np.linalg.solve(_bernstein(s), basis_matrix(SPLIT_KNOTS, SPLIT_MULTS, a + (b - a) * s))


def _bezier_to_split():
    """(N_SPLIT, 4) poles on :data:`SPLIT_KNOTS` of a cubic Bezier curve (knot insertion,
    exact: the Bezier space lies in the spline space)."""
    s = np.linspace(0.0, 1.0, 2 * N_SPLIT)
    return np.linalg.lstsq(basis_matrix(SPLIT_KNOTS, SPLIT_MULTS, s), _bernstein(s), rcond=None)[0]


BEZIER_TO_SPLIT = _bezier_to_split()
"""(N_SPLIT, 4) poles on the knots :data:`SPLIT_KNOTS` of a cubic Bezier curve."""
THIRD_DIFFERENCE = np.array([[-1.0, 3.0, -3.0, 1.0]])
"""(1, 4) third difference of 4 Bezier points: zero iff the span is quadratic."""


def _reduced_knots(keep_start, keep_end):
    """Knots and multiplicities of :data:`SPLIT_KNOTS` without the double knot at ``h``
    (``keep_start`` False) and/or at ``1 - h`` (``keep_end`` False)."""
    keep = np.array([True, keep_start, keep_end, True])
    return SPLIT_KNOTS[keep], SPLIT_MULTS[keep]


def _knot_free_rows(end):
    """(2, N_SPLIT) weights whose products with a pole row of :data:`SPLIT_KNOTS` vanish iff
    the curve is one cubic across the double knot at ``h`` (``end`` 0) or ``1 - h``
    (``end`` 1): the left null space of the insertion from the knot vector without it."""
    knots, mults = _reduced_knots(end == 1, end == 0)
    return null_space(insertion_matrix(knots, mults, SPLIT_KNOTS, SPLIT_MULTS).T).T


KNOT_FREE_ROWS = (_knot_free_rows(0), _knot_free_rows(1))
"""Rows of :func:`_knot_free_rows` for the knot at ``h`` and at ``1 - h``."""
END_CORNERS = ((np.array([0, 3]), np.array([1, 2])), (np.array([0, 1]), np.array([3, 2])))
"""Patch corners at the start (``h``) and the end (``1 - h``) of the ``u`` and the ``v``
direction (corner ``k`` at :data:`core.export.brep_topology.CORNER_UV` ``[k]``)."""


def _gauss_params(per_span=4):
    """(spans per_span,) Gauss-Legendre parameters in each knot span of :data:`SPLIT_KNOTS` and
    their quadrature weights (summing to 1)."""
    x, w = np.polynomial.legendre.leggauss(per_span)
    a, b = SPLIT_KNOTS[:-1], SPLIT_KNOTS[1:]
    return ((a[:, None] + (b - a)[:, None] * 0.5 * (x[None, :] + 1.0)).reshape(-1),
            (0.5 * (b - a)[:, None] * w[None, :]).reshape(-1))


def _side_slots(n):
    """(4, n) int64 slots ``i * n + j`` of an (n, n) pole grid along each side, in loop
    order: side ``k`` runs from patch corner ``k`` to ``k + 1``."""
    r = np.arange(n)
    return np.stack([r * n, (n - 1) * n + r, (n - 1 - r) * n + (n - 1), (n - 1) - r])


def _side_uv(side, s):
    """Patch parameters (u, v) at position ``s`` along ``side`` (arrays, broadcast)."""
    u = np.select([side == 0, side == 1, side == 2], [s, np.ones_like(s), 1.0 - s],
                  np.zeros_like(s))
    v = np.select([side == 0, side == 1, side == 2], [np.zeros_like(s), s, np.ones_like(s)],
                  1.0 - s)
    return u, v


def _tensor_rows(u, v, du, dv):
    """(p, N_SPLIT^2) weights of a free patch's poles for the point or derivative at (u, v)."""
    bu = basis_matrix(SPLIT_KNOTS, SPLIT_MULTS, u, du)
    bv = basis_matrix(SPLIT_KNOTS, SPLIT_MULTS, v, dv)
    return (bu[:, :, None] * bv[:, None, :]).reshape(len(u), -1)


def _side_derivatives(side, s):
    """Pole weights (p, N_SPLIT^2) of the derivative along ``side`` (towards corner side + 1)
    and of the inward cross-boundary derivative, at positions ``s`` (p,) along it."""
    u, v = _side_uv(side, s)
    d_u = _tensor_rows(u, v, 1, 0)
    d_v = _tensor_rows(u, v, 0, 1)
    across_v = (side % 2 == 0)[:, None]
    along = np.where(across_v, d_u, d_v) * np.array([1.0, 1.0, -1.0, -1.0])[side, None]
    inward = np.where(across_v, d_v, d_u) * np.array([1.0, -1.0, -1.0, 1.0])[side, None]
    return along, inward


def _inward_derivative(side, s, order):
    """(p, N_SPLIT^2) pole weights of the ``order``-th derivative across ``side`` into the
    patch (its parameter increasing inwards) at positions ``s`` (p,) along it."""
    u, v = _side_uv(side, s)
    d_u = _tensor_rows(u, v, order, 0)
    d_v = _tensor_rows(u, v, 0, order)
    sign = np.array([1.0, (-1.0) ** order, (-1.0) ** order, 1.0])[side, None]
    return np.where((side % 2 == 0)[:, None], d_v, d_u) * sign


def _base_join_system(layout, topo, free, base_face, base_sizes):
    """Rows making the refined patches of one base quad join C2 across the edges between
    them (as the limit surface does there): equal second derivatives into both patches at
    4 Gauss points per knot span (both sides are cubic there; value and first derivative
    already agree by the shared poles and the C1 connection), so the face joined from them
    keeps a single knot line at 1/2 instead of a double one. One polynomial across (C3)
    would ask the corner knots' kinks to end at the edge, which the G1 conditions next to
    an extraordinary corner do not allow. ``base_face`` (m,) is the base face of every
    quad, ``base_sizes`` the base faces' corner counts."""
    corner = np.arange(len(topo.twin))
    twin = topo.twin
    rep = corner[(corner < twin) & (base_face[corner // 4] == base_face[twin // 4])]
    rep = rep[(base_sizes[base_face[rep // 4]] == 4) & (free[rep // 4] | free[twin[rep] // 4])]
    if not len(rep):
        return None, None
    t = _gauss_params()[0]
    p = len(t)
    c_near = np.repeat(rep, p)
    c_far = np.repeat(twin[rep], p)
    tt = np.tile(t, len(rep))
    A_near, c_n = layout.split_columns(_inward_derivative(c_near % 4, tt, 2), c_near // 4)
    A_far, c_f = layout.split_columns(_inward_derivative(c_far % 4, 1.0 - tt, 2), c_far // 4)
    return (A_near - A_far).tocsr(), c_f - c_n


def connection_alpha(t, valence_start, valence_end):
    """The G1 connection function ``alpha(t)`` along edges (module docstring).

    ``alpha(t) = 2 c_start phi(t) - 2 c_end phi(1 - t)`` with ``c = cos(2 pi / n)`` of each
    end (0 at valence 4) and ``phi(t) = (1 - t / h)^2`` on ``[0, h]``, 0 beyond
    (``h`` = :data:`EV_SPAN`). At an extraordinary vertex ``alpha = 2 c`` puts the spoke
    tangents into one plane; ``phi`` reaches 0 at the double knot ``h`` with value and
    slope, so ``alpha`` is C1 where the patches are, and the edge joins C1 beyond, like the
    limit surface (``alpha`` reaches a valence-4 vertex identically 0, so the four C1
    conditions there are compatible). ``alpha b'`` stays cubic on the corner span because
    the edge curve is quadratic there (:func:`_g1_system`).

    Parameters
    ----------
    t : (p,) float64 edge parameters, 0 at the start vertex.
    valence_start, valence_end : (p,) int64 valences of the edge's end vertices.

    Returns
    -------
    (p,) float64
    """
    c_start = np.where(valence_start != 4, np.cos(2.0 * np.pi / valence_start), 0.0)
    c_end = np.where(valence_end != 4, np.cos(2.0 * np.pi / valence_end), 0.0)
    return _alpha(t, c_start, c_end)


def _alpha(t, c_start, c_end):
    """``alpha(t)`` of :func:`connection_alpha` from the cosines ``c`` (p,) of both ends."""

    def phi(s):
        return np.clip(1.0 - s / EV_SPAN, 0.0, None) ** 2

    return 2.0 * c_start * phi(t) - 2.0 * c_end * phi(1.0 - t)


class _Layout:
    """Pole slots of every quad (N_SPLIT^2 each), merged where patches share poles.

    ``label[slot]`` is the shared pole of a slot; ``fixed_value`` holds the poles of regular
    quads (NaN for unknown ones) and ``unknown[label]`` the unknown index (-1 if fixed).
    """

    def __init__(self, quads, topo, free, bezier):
        m = quads.n_faces
        n2 = N_SPLIT * N_SPLIT
        sides = _side_slots(N_SPLIT)
        corner = np.arange(len(quads.face_vertices))
        face, local = corner // 4, corner % 4
        twin = topo.twin
        a = (face[:, None] * n2 + sides[local]).reshape(-1)
        b = (face[twin][:, None] * n2 + sides[local[twin]][:, ::-1]).reshape(-1)
        n_slots = m * n2
        graph = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n_slots, n_slots))
        _, self.label = connected_components(graph, directed=False)
        n_labels = int(self.label.max()) + 1
        split = np.einsum("ia,fabk,jb->fijk", BEZIER_TO_SPLIT, bezier, BEZIER_TO_SPLIT,
                          optimize=True)
        fixed_slots = (np.flatnonzero(~free)[:, None] * n2 + np.arange(n2)).reshape(-1)
        self.fixed_value = np.full((n_labels, 3), np.nan)
        self.fixed_value[self.label[fixed_slots]] = split[~free].reshape(-1, 3)
        is_unknown = np.isnan(self.fixed_value[:, 0])
        self.unknown = np.full(n_labels, -1, dtype=np.int64)
        self.unknown[is_unknown] = np.arange(int(is_unknown.sum()))
        self.n_unknowns = int(is_unknown.sum())

    def split_columns(self, w, f):
        """Sparse matrix over unknowns and the constant part for rows of pole weights.

        Parameters
        ----------
        w : (p, N_SPLIT^2) pole weights of free-patch points or derivatives; f : (p,) int64 quads.

        Returns
        -------
        A : (p, n_unknowns) csr_matrix; c : (p, 3) the fixed poles' contribution.
        """
        n2 = N_SPLIT * N_SPLIT
        row, slot = np.nonzero(w)
        weight = w[row, slot]
        lab = self.label[f[row] * n2 + slot]
        unk = self.unknown[lab]
        known = unk < 0
        A = sp.csr_matrix((weight[~known], (row[~known], unk[~known])),
                          shape=(len(w), self.n_unknowns))
        fixed = self.fixed_value[lab[known]] * weight[known, None]
        c = np.stack([np.bincount(row[known], weights=fixed[:, k], minlength=len(w))
                      for k in range(3)], axis=1)
        return A, c


def _regular_bezier(quads, topo, st):
    """(m, 4, 4, 3) Bezier poles of every quad's bicubic B-spline stencil ``st`` (m, 4, 4)
    (exact limit of the quads whose corners have valence 4 and whose stencil has no crease
    vertex)."""
    P = quads.vertices[st]
    return np.einsum("ia,fabk,jb->fijk", BSPLINE_TO_BEZIER, P, BSPLINE_TO_BEZIER, optimize=True)


def _fit_system(layout, evaluator, free_faces, growth):
    """Normal equations of the least-squares fit of free patches to exact limit points: the
    squared distance integrated over each patch's parameter square (4 x 4 Gauss points per
    pair of spans), each patch point matched with the limit point at its warped parameters
    (:func:`core.export.corner_warp.warped_params` with the corners' exponents ``growth``
    (n_free, 4, 2)). Every free patch has the same basis, so its Gram matrix ``G`` (64 x 64
    over its slots) is formed once and scattered onto the unknowns.

    Returns
    -------
    H : (n_unknowns, n_unknowns) csc_matrix; rhs : (n_unknowns, 3); centre : (3,) the mean
    target point (the solve is centred on it).
    """
    s, q = _gauss_params()
    U, V = (a.reshape(-1) for a in np.meshgrid(s, s, indexing="ij"))
    root = np.sqrt(np.outer(q, q).reshape(-1))
    W = _tensor_rows(U, V, 0, 0) * root[:, None]
    G = W.T @ W
    n_free, p = len(free_faces), len(U)
    Uw, Vw = warped_params(np.broadcast_to(U, (n_free, p)), np.broadcast_to(V, (n_free, p)),
                           growth)
    target = evaluator.evaluate(np.repeat(free_faces, p), Uw.reshape(-1),
                                Vw.reshape(-1)).reshape(n_free, p, 3)
    n2 = N_SPLIT * N_SPLIT
    lab = layout.label[free_faces[:, None] * n2 + np.arange(n2)]
    unk = layout.unknown[lab]
    known = unk < 0
    b = np.matmul((W * root[:, None]).T, target)
    fixed = layout.fixed_value[lab]
    fixed[~known] = 0.0
    b -= np.matmul(G, fixed)
    pair = ~known[:, :, None] & ~known[:, None, :] & (G != 0.0)[None]
    rows = np.broadcast_to(unk[:, :, None], pair.shape)[pair]
    cols = np.broadcast_to(unk[:, None, :], pair.shape)[pair]
    values = np.broadcast_to(G, pair.shape)[pair]
    m = layout.n_unknowns
    H = sp.csc_matrix((values, (rows, cols)), shape=(m, m))
    rhs = np.stack([np.bincount(unk[~known], weights=b[..., c][~known], minlength=m)
                    for c in range(3)], axis=1)
    return H, rhs, target.reshape(-1, 3).mean(axis=0)


def _corner_cosines(quads, topo, crease, evaluator):
    """(4 m,) float64 ``c = cos(theta)`` of the G1 connection at the start vertex of every
    corner's edge (half-edge), for the sector of faces around that vertex the edge lies in.

    Without crease edges at the vertex, or with one (a dart: the limit surface has a tangent
    plane there), ``theta = 2 pi / n`` (``n`` the valence; ``c`` = 0 at valence 4). With two
    crease edges (a crease vertex, where the crease curve is smooth) a sector of ``k`` faces
    spans a half plane, ``theta = pi / k``: the spokes of a sector are then an affine image
    of a regular fan of angle ``theta`` (``x_{i-1} + x_{i+1} = 2 c x_i``) between its two
    crease spokes. With three or more (a corner) the limit surface's sectors are no such
    fans, so each spoke inside a sector takes the ``c`` that the exact limit's own spoke
    tangents satisfy best (:func:`_limit_spoke_cosines`). Either way the relations chain
    every spoke of a sector to its two crease spokes, so the sector's patches share a
    tangent plane at the vertex.
    """
    fv = quads.face_vertices
    n = len(quads.vertices)
    valence = np.bincount(fv, minlength=n)
    corner = np.arange(len(fv))
    cosine = np.where(valence[fv] != 4, np.cos(2.0 * np.pi / valence[fv]), 0.0)
    spoke_crease = crease[topo.corner_edge]
    n_crease = vertex_crease_counts(topo, crease, n)
    walk = np.flatnonzero((n_crease[fv] >= 2) & ~spoke_crease)
    if not len(walk):
        return cosine
    prev = corner - corner % 4 + (corner + 3) % 4
    turn = (topo.twin[prev], topo.next_corner[topo.twin])
    k = np.zeros(len(walk))
    for direction, step in enumerate(turn):
        s = walk.copy()
        active = np.ones(len(walk), dtype=bool)
        for _ in range(int(valence.max())):
            if direction == 1:
                s[active] = step[s[active]]
            k += active
            if direction == 0:
                s[active] = step[s[active]]
            active &= ~spoke_crease[s]
            if not active.any():
                break
    cosine[walk] = np.where(k == 2, 0.0, np.cos(np.pi / k))  # exactly C1 in a half plane of two faces
    at_corner = walk[n_crease[fv[walk]] >= 3]
    limit = _limit_spoke_cosines(topo, evaluator, at_corner)
    cosine[at_corner] = np.where(np.isfinite(limit), limit, cosine[at_corner])
    return cosine


def _limit_spoke_cosines(topo, evaluator, spokes):
    """(s,) float64 ``c`` of the relation ``x_- + x_+ = 2 c x`` that the exact limit surface's
    tangents satisfy best (least squares) at the start vertex of each half-edge in ``spokes``
    (s,): ``x`` the tangent along it, ``x_-``, ``x_+`` those along the neighbouring spokes
    of its two faces, as differences of limit points at distance ``h / 2`` along the patch
    sides (``h`` = :data:`EV_SPAN`, the scale on which the patches depart from the limit);
    NaN where the limit's tangent vanishes."""
    step = 0.5 * EV_SPAN
    face, k = spokes // 4, spokes % 4
    start = CORNER_UV[k]
    other = topo.next_corner[topo.twin[spokes]]
    points = evaluator.evaluate(
        np.concatenate([face, face, face, other // 4]),
        *np.concatenate([start, start + step * (CORNER_UV[(k + 1) % 4] - start),
                         start + step * (CORNER_UV[(k + 3) % 4] - start),
                         CORNER_UV[other % 4] + step * (CORNER_UV[(other + 1) % 4]
                                                        - CORNER_UV[other % 4])]).T)
    at, along, before, after = points.reshape(4, len(spokes), 3)
    x = along - at
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.einsum("ij,ij->i", before + after - 2.0 * at, x)
                / (2.0 * np.einsum("ij,ij->i", x, x)))


def _g1_system(layout, quads, topo, free, cosine, crease):
    """Rows of the G1 conditions on every edge next to a free patch but crease edges.

    ``L + R - alpha b' = 0`` at 4 Gauss points per knot span (both sides are cubic there),
    and, on the half of an edge from an EV to a valence-4 vertex, a quadratic edge curve
    (zero third difference of its Bezier points) so that ``alpha b'`` stays cubic.
    ``cosine`` (4 m,) are the connection's ``c`` per corner (:func:`_corner_cosines`),
    ``crease`` (n_edges,) the crease edges (C0: the patches there share the edge only).
    """
    fv = quads.face_vertices
    corner = np.arange(len(fv))
    rep = corner[(corner < topo.twin) & ~crease[topo.corner_edge]]
    face, twin_face = rep // 4, topo.twin[rep] // 4
    rep = rep[free[face] | free[twin_face]]
    if not len(rep):
        return None, None
    t = _gauss_params()[0]
    p = len(t)
    c_near = np.repeat(rep, p)
    c_far = np.repeat(topo.twin[rep], p)
    tt = np.tile(t, len(rep))
    along, inward_near = _side_derivatives(c_near % 4, tt)
    _, inward_far = _side_derivatives(c_far % 4, 1.0 - tt)
    alpha = _alpha(tt, cosine[c_near], cosine[topo.twin[c_near]])
    A_near, c_near_fixed = layout.split_columns(inward_near - alpha[:, None] * along, c_near // 4)
    A_far, c_far_fixed = layout.split_columns(inward_far, c_far // 4)
    A = [A_near + A_far]
    y = [-(c_near_fixed + c_far_fixed)]
    ev_start = cosine[rep] != 0.0
    ev_end = cosine[topo.twin[rep]] != 0.0
    sides = _side_slots(N_SPLIT)
    first = THIRD_DIFFERENCE @ _span_bezier(SPLIT_KNOTS[0], SPLIT_KNOTS[1])
    last = THIRD_DIFFERENCE @ _span_bezier(SPLIT_KNOTS[-2], SPLIT_KNOTS[-1])
    for mask, weights in ((ev_start, first), (ev_end, last)):
        c = rep[mask]
        for row in weights:
            w = np.zeros((len(c), N_SPLIT * N_SPLIT))
            w[np.arange(len(c))[:, None], sides[c % 4]] = row
            A_q, c_q = layout.split_columns(w, c // 4)
            A.append(A_q)
            y.append(-c_q)
    return sp.vstack(A).tocsr(), np.concatenate(y)


def _special_vertices(quads, topo, crease, cosine):
    """(n_vertices,) bool: vertices at which the G1 connection departs from C1, so the patches
    there keep their corner knots (:func:`_kept_knots`): extraordinary vertices, darts (one
    crease edge), corners (three or more) and crease vertices with a sector whose connection
    cosine ``cosine`` (4 m,) is not 0 (:func:`_corner_cosines`). A valence-4 crease vertex
    with two faces on each side of its crease is none of these: on each side its limit
    surface is the bicubic B-spline of the grid reflected linearly across the crease (the
    crease rule keeps that reflection), so the patches there join C1 off the crease like
    regular ones, with no knot."""
    fv = quads.face_vertices
    n = len(quads.vertices)
    n_crease = vertex_crease_counts(topo, crease, n)
    special = (np.bincount(fv, minlength=n) != 4) | (n_crease == 1) | (n_crease >= 3)
    bent = (cosine != 0.0) & ~crease[topo.corner_edge]
    special[fv[bent]] = True
    return special


def _two_face_sectors(quads, topo, crease, cosine):
    """(m, 4) bool: patch corners in a sector of two faces between the two crease edges of a
    crease vertex (one spoke a crease edge, the other one with connection ``cosine`` (4 m,)
    0, :func:`_corner_cosines`). Such a sector's refinement involves only its own vertices
    and the crease's, by the rules of a regular grid reflected across the crease, whatever
    the vertex's other sector holds: the limit surface is a bicubic B-spline there and the
    patches join C1 along the spoke between the sector's two faces."""
    fv = quads.face_vertices
    n_crease = vertex_crease_counts(topo, crease, len(quads.vertices))
    corner = np.arange(len(fv))
    other = topo.twin[topo.prev_corner[corner]]  # the patch's other spoke out of its corner
    spoke_crease = crease[topo.corner_edge]
    inner_cosine = np.where(spoke_crease, cosine[other], cosine[corner])
    return ((n_crease[fv] == 2) & (spoke_crease != spoke_crease[other])
            & (inner_cosine == 0.0)).reshape(-1, 4)


def _end_corners(corners):
    """(m, 2, 2) bool: whether any of ``corners`` (m, 4) bool lies at end ``e`` of direction
    ``d`` of each patch (:data:`END_CORNERS`)."""
    ends = np.array([[corners[:, pair].any(axis=1) for pair in pairs] for pairs in END_CORNERS])
    return ends.transpose(2, 0, 1)


def _kept_knots(quads, free, special, two_face):
    """(m, 2, 2) bool: free patch ``f`` keeps its double knot in direction ``d`` (0: ``u``,
    1: ``v``) at end ``e`` (0: ``h``, 1: ``1 - h``) iff a corner at that end of that direction
    is ``special`` (n_vertices,) bool: an extraordinary vertex or one with crease edges;
    elsewhere the G1 connection is C1 and the patch need not depart from one cubic there.
    A direction whose only special corners lie in two-face sectors of crease vertices
    (``two_face`` (m, 4) bool, :func:`_two_face_sectors`) at one end and none at the other keeps
    no knot: the connection is C1 and the limit surface bicubic at both ends, as across a
    regular quad. With a special corner at the other end, the knot stays: it lets the patch
    bend between its two ends where the limit surface is no single cubic."""
    at_vertex = special[quads.face_vertices].reshape(-1, 4)
    at_end = _end_corners(at_vertex)
    departing = _end_corners(at_vertex & ~two_face)
    keep = np.where(at_end[:, :, ::-1], at_end, departing)
    return keep & free[:, None, None]


def _knot_free_system(layout, free, keep):
    """Rows making every free patch one cubic across each double knot it does not keep
    (:func:`_kept_knots`): :data:`KNOT_FREE_ROWS` on every pole row across that knot, so the
    knot can be removed exactly from the solved patch (:func:`_reduced_patch`)."""
    n = N_SPLIT
    weights, faces = [], []
    for d in (0, 1):
        for e in (0, 1):
            f = np.flatnonzero(free & ~keep[:, d, e])
            for row in KNOT_FREE_ROWS[e]:
                for j in range(n):
                    w = np.zeros((n, n))
                    if d == 0:
                        w[:, j] = row
                    else:
                        w[j, :] = row
                    weights.append(np.broadcast_to(w.reshape(-1), (len(f), n * n)))
                    faces.append(f)
    A, c = layout.split_columns(np.vstack(weights), np.concatenate(faces))
    return A, -c


def _reduced_patch(poles, keep):
    """The free patch of ``poles`` (N_SPLIT, N_SPLIT, 3) on its kept knots only (``keep``
    (2, 2) bool of :func:`_kept_knots`): the least-squares poles on the coarser knot vectors,
    the same surface up to rounding once :func:`_knot_free_system` holds."""
    u_knots, u_mults = _reduced_knots(*keep[0])
    v_knots, v_mults = _reduced_knots(*keep[1])
    Tu, Tv = REMOVAL[tuple(keep[0])], REMOVAL[tuple(keep[1])]
    P = np.einsum("ia,abk,jb->ijk", Tu, poles, Tv)
    return BSplinePatch(P, u_knots, u_mults, v_knots, v_mults)


def _removal(keep_start, keep_end):
    """(n, N_SPLIT) least-squares inverse of the knot insertion from the knots that
    :func:`_reduced_knots` keeps to :data:`SPLIT_KNOTS`."""
    knots, mults = _reduced_knots(keep_start, keep_end)
    return np.linalg.pinv(insertion_matrix(knots, mults, SPLIT_KNOTS, SPLIT_MULTS))


REMOVAL = {(a, b): _removal(a, b) for a in (False, True) for b in (False, True)}
"""Matrices of :func:`_removal` for every pair of kept corner knots."""


def _solve(H, rhs, centre, A_g1, y_g1):
    """(n_unknowns, 3) least-squares fit (normal equations ``H x = rhs``) subject to
    ``A_g1 x = y_g1``.

    The solution of the KKT system ``[[H, C^T], [C, 0]]``, with the condition rows ``C``
    scaled to the norm ``sqrt(s)`` (``s`` the mean diagonal of ``H``, the fit's scale; rows
    without unknowns are left out: they hold or fail whatever the poles). The G1 conditions
    are redundant where several meet (at every vertex), so that system is singular in the
    multipliers; its regularised form ``[[H, C^T], [C, -delta I]]`` (``delta = s /
    G1_PENALTY^2``, the fit plus ``G1_PENALTY^2`` times the conditions' squared residuals)
    is quasi-definite, as ``H`` is positive definite, and is factored once
    (:func:`_solve_quasi_definite`); steps of iterative refinement against the
    unregularised system then move the poles to the constrained fit (the method of
    multipliers: each step shifts the multipliers by the conditions' residual over
    ``delta``). The unknowns are centred on ``centre`` first, so a translation of the cage
    moves the poles by exactly that vector up to rounding.
    """
    rhs = rhs - H @ np.broadcast_to(centre, (H.shape[1], 3))
    if A_g1 is None:
        return splu(H.tocsc()).solve(np.ascontiguousarray(rhs)) + centre
    scale = H.diagonal().mean()
    A_g1 = A_g1.tocsr()
    norm = np.sqrt(np.asarray(A_g1.multiply(A_g1).sum(axis=1)).reshape(-1))
    live = np.flatnonzero(norm > 0.0)
    row_scale = sp.diags(np.sqrt(scale) / norm[live])
    C = (row_scale @ A_g1[live]).tocsr()
    y_c = row_scale @ (y_g1[live] - A_g1[live] @ np.broadcast_to(centre, (A_g1.shape[1], 3)))
    x = _solve_quasi_definite(H, C, scale / G1_PENALTY ** 2, np.vstack([rhs, y_c]))
    return x[:H.shape[0]] + centre


def _solve_quasi_definite(H, C, delta, b):
    """``K z = b`` for the KKT matrix ``K = [[H, C^T], [C, 0]]`` (``H`` (n, n) positive
    definite, ``C`` (k, n)), ``b`` (n + k, d): ``L D L^T`` of the quasi-definite
    ``[[H, C^T], [C, -delta I]]`` by MUMPS in an approximate minimum degree order without
    pivoting (quasi-definite matrices need none), then up to :data:`REFINE_STEPS` steps of
    iterative refinement against ``K`` itself, while the residual shrinks. Returns (n + k, d)
    float64."""
    n, k = H.shape[0], C.shape[0]
    H_upper = sp.triu(H, format="coo")
    C_coo = C.tocoo()
    diagonal = n + np.arange(k)
    upper = sp.coo_matrix((np.concatenate([H_upper.data, C_coo.data, np.full(k, -delta)]),
                           (np.concatenate([H_upper.row, C_coo.col, diagonal]),
                            np.concatenate([H_upper.col, n + C_coo.row, diagonal]))),
                          shape=(n + k, n + k))
    context = mumps.Context()
    context.set_matrix(upper, symmetric=True)
    context.factor(ordering="amd", pivot_tol=0.0)
    H, C = H.tocsr(), C.tocsr()
    C_t = C.T.tocsr()

    def residual(z):
        return b - np.vstack([H @ z[:n] + C_t @ z[n:], C @ z[:n]])

    z = np.zeros_like(b)
    r = np.array(b, dtype=np.float64)
    best = np.abs(r).max()
    for _ in range(REFINE_STEPS + 1):
        step = z + np.asarray(context.solve(r), dtype=np.float64)
        r_step = residual(step)
        size = np.abs(r_step).max()
        if not size < best:
            break
        z, r, best = step, r_step, size
    return z


def _side_row(poles, side):
    """Boundary pole row (n, 3) of a patch's (n, n, 3) poles from corner ``side`` to ``side + 1``."""
    return (poles[:, 0], poles[-1, :], poles[::-1, -1], poles[0, ::-1])[side]


def _side_knots(patch, side):
    """Knots and multiplicities of a patch's boundary row from corner ``side`` to ``side + 1``."""
    knots, mults = ((patch.u_knots, patch.u_mults) if side % 2 == 0
                    else (patch.v_knots, patch.v_mults))
    knots, mults = np.asarray(knots, dtype=np.float64), np.asarray(mults, dtype=np.int64)
    if side >= 2:
        return 1.0 - knots[::-1], mults[::-1]
    return knots, mults


def _topology(quads, topo, patches, free):
    """The BRepTopology of quad patches that meet along whole sides: one vertex per used cage
    vertex, one edge per cage edge (a regular patch's Bezier row where it has one)."""
    fv = quads.face_vertices
    used = np.unique(fv)
    index = np.full(len(quads.vertices), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    n_edges = len(topo.edges)
    corner = np.arange(len(fv), dtype=np.int64)
    rep = np.full(n_edges, -1, dtype=np.int64)
    rep[topo.corner_edge[::-1]] = corner[::-1]
    twin = topo.twin[rep]
    curves = []
    for c, t in zip(rep.tolist(), twin.tolist()):
        if not free[c // 4] or free[t // 4]:
            row = _side_row(patches[c // 4].poles, c % 4)
        else:
            row = _side_row(patches[t // 4].poles, t % 4)[::-1]
        if not free[c // 4] or free[t // 4]:
            knots, mults = _side_knots(patches[c // 4], c % 4)
        else:
            knots, mults = _side_knots(patches[t // 4], t % 4)
            knots, mults = 1.0 - knots[::-1], mults[::-1]
        curves.append(EdgeCurve(np.ascontiguousarray(row), knots, mults))
    vertices = np.empty((len(used), 3))
    vertices[index[fv]] = np.stack([patches[c // 4].poles[(0, -1, -1, 0)[c % 4], (0, 0, -1, -1)[c % 4]]
                                    for c in corner.tolist()])
    edge_vertices = np.stack([index[fv[rep]], index[fv[topo.next_corner[rep]]]], axis=1)
    reversed_use = rep[topo.corner_edge] != corner
    uv = np.stack([CORNER_UV[corner % 4], CORNER_UV[(corner + 1) % 4]], axis=1)
    uv[reversed_use] = uv[reversed_use][:, ::-1]
    return BRepTopology(vertices, edge_vertices, curves, corner // 4,
                        topo.corner_edge.astype(np.int64), reversed_use, uv)


def g1_surface_patches(base, measure=True, faces="quad"):
    """G1 bicubic B-spline patches close to the Catmull-Clark limit surface of ``base``.

    Parameters
    ----------
    base : PolyMesh, closed 2-manifold polygon mesh, possibly with sharp crease edges
        (validated by the caller).
    measure : bool, if True fill ``info`` with the deviation from the exact limit surface
        and the normal jumps across edges (of the per-quad patches).
    faces : ``"quad"`` (one face per quad) or ``"chart"`` (the quads' patches merged into
        one multi-span face per rectangular block of quads,
        :func:`core.export.chart_faces.chart_patches`, within
        :data:`core.export.chart_faces.MERGE_TOLERANCE` of them).

    Returns
    -------
    PatchSet
        One patch per quad of ``base`` if it is all quads, else one per base quad and one
        per quad of the first Catmull-Clark refinement (``patch_level`` 1) of every other
        face; or per block of quads with ``faces`` ``"chart"`` (see
        :func:`core.export.chart_faces.chart_patches` for what it adds to ``info``, in both
        merged forms); ``face_of_patch`` is the base face (of a block's first quad);
        ``topology`` the shared vertices and edges; ``d/du x d/dv`` points outward.
        ``info`` holds ``export`` ("g1"), ``faces``, ``n_faces``, ``patch_level``, ``n_patches``,
        ``patches_per_base_face``, ``n_extraordinary_vertices``, ``n_g1_patches`` (free
        patches), ``n_poles``, ``g1_residual`` (largest residual of the G1 conditions,
        model units per unit parameter), ``bbox_diagonal`` and, if ``measure``, the figures
        of :func:`core.export.bspline_measure.patch_deviation` (distances to the limit
        surface from the fit's warped parameters, :mod:`core.export.corner_warp`) and
        :func:`core.export.bspline_measure.normal_jumps`.

    Raises
    ------
    ExportError when the solved poles miss the G1
        conditions by more than :data:`G1_RESIDUAL_MAX` of the cage's bounding-box diagonal
        (conditions that contradict each other), rather than writing a surface with kinks.
    """
    check_face_form(faces, "g1")
    result, quads = g1_quad_patches(base, measure)
    if faces == "chart":
        return chart_patches(result, quads)
    if result.info["patch_level"] == 1:
        merged = chart_patches(result, quads, partition=base_face_blocks(base, quads))
        merged.info["faces"] = "quad"
        return merged
    return result


def _conditioned_solve(H, rhs, centre, systems):
    """The constrained least-squares poles of :func:`_solve` under the stacked condition rows
    of ``systems`` (pairs ``(A, y)``; ``A`` None or without rows adds none).

    Returns
    -------
    (x, A, y): the solution and the stacked conditions (None, None without any).
    """
    kept = [(A, y) for A, y in systems if A is not None and A.shape[0]]
    if not kept:
        return _solve(H, rhs, centre, None, None), None, None
    A = sp.vstack([A for A, _ in kept]).tocsr()
    y = np.concatenate([y for _, y in kept])
    return _solve(H, rhs, centre, A, y), A, y


def _residual(A, y, x):
    """Largest residual of the conditions ``A x = y`` (0 without conditions)."""
    return float(np.abs(A @ x - y).max()) if A is not None else 0.0


def g1_quad_patches(base, measure=True):
    """The G1 patches of :func:`g1_surface_patches` on the quad mesh of ``base`` (``base``
    itself, or its first Catmull-Clark refinement when it has other faces), one per quad,
    before any merge.

    Returns
    -------
    (PatchSet, PolyMesh): the patches (``face_of_patch`` the base face of each quad;
    ``info`` as :func:`g1_surface_patches` describes, with ``faces`` "quad") and the quad
    mesh.
    """
    quads = quad_mesh_of(base)
    level = 0 if quads is base else 1
    fv = quads.face_vertices
    topo = mesh_topology(fv, quads.face_offsets, len(quads.vertices))
    valence = np.bincount(fv, minlength=len(quads.vertices))
    crease = crease_edge_mask(topo, quads.creases)
    creased = vertex_crease_counts(topo, crease, len(quads.vertices)) > 0
    st = quad_stencils(quads, topo)
    free = ((valence != 4) | creased)[fv].reshape(-1, 4).any(axis=1) | creased[st].any(axis=(1, 2))
    keep = np.zeros((quads.n_faces, 2, 2), dtype=bool)
    if level == 0:
        base_face_of_quad = np.arange(base.n_faces, dtype=np.int64)
    else:
        base_face_of_quad = mesh_topology(base.face_vertices, base.face_offsets,
                                          len(base.vertices)).face_of_corner.astype(np.int64)
    growth = np.ones((quads.n_faces, 4, 2))
    ctx = PatchContext(quads, 1)
    bezier = _regular_bezier(quads, topo, st)
    layout = _Layout(quads, topo, free, bezier)
    free_faces = np.flatnonzero(free)
    slots = np.nan_to_num(layout.fixed_value)
    residual = 0.0
    if len(free_faces):
        evaluator = ctx.evaluator  # the limit of ``quads`` itself: it is all quads
        cosine = _corner_cosines(quads, topo, crease, evaluator)
        special = _special_vertices(quads, topo, crease, cosine)
        keep = _kept_knots(quads, free, special, _two_face_sectors(quads, topo, crease, cosine))
        growth = corner_growth(topo, spoke_growth(quads, topo, crease, special))
        H, rhs, centre = _fit_system(layout, evaluator, free_faces, growth[free_faces])
        A_g1, y_g1 = _g1_system(layout, quads, topo, free, cosine, crease)
        A_k, y_k = _knot_free_system(layout, free, keep)
        A_j, y_j = (_base_join_system(layout, topo, free, base_face_of_quad, base.face_sizes)
                    if level == 1 else (None, None))
        diagonal = float(np.linalg.norm(np.ptp(quads.vertices[np.unique(fv)], axis=0)))
        x, A, y = _conditioned_solve(H, rhs, centre, [(A_g1, y_g1), (A_k, y_k), (A_j, y_j)])
        residual = _residual(A, y, x)
        if residual > G1_RESIDUAL_MAX * diagonal and A_j is not None:
            # the C2 joins inside base quads only save poles; where they contradict the G1
            # conditions, the quads join C1 (a knot line at 1/2 stays in the merged face)
            x, A, y = _conditioned_solve(H, rhs, centre, [(A_g1, y_g1), (A_k, y_k)])
            residual = _residual(A, y, x)
        slots[layout.unknown >= 0] = x[layout.unknown[layout.unknown >= 0]]
        if residual > G1_RESIDUAL_MAX * diagonal:
            raise ExportError(f"the G1 conditions of this cage could not be met (residual "
                              f"{residual / diagonal:.1e} of the bounding-box diagonal); use "
                              "the exact (graded) export")
    n2 = N_SPLIT * N_SPLIT
    patches = []
    for f in range(quads.n_faces):
        if free[f]:
            P = slots[layout.label[f * n2:(f + 1) * n2]].reshape(N_SPLIT, N_SPLIT, 3)
            patches.append(_reduced_patch(P, keep[f]))
        else:
            patches.append(BSplinePatch(np.ascontiguousarray(bezier[f]), BEZIER_KNOTS,
                                        BEZIER_MULTS, BEZIER_KNOTS, BEZIER_MULTS))
    topology = _topology(quads, topo, patches, free)
    face_of_patch = base_face_of_quad
    sizes = base.face_sizes
    per_face = np.bincount(face_of_patch, minlength=base.n_faces)
    info = {
        "export": "g1",
        "faces": "quad",
        "n_faces": len(patches),
        "patch_level": level,
        "n_patches": len(patches),
        "patches_per_base_face": {str(n): float(per_face[sizes == n].mean())
                                  for n in np.unique(sizes).tolist()},
        "n_extraordinary_vertices": int((valence[np.unique(fv)] != 4).sum()),
        "n_g1_patches": int(free.sum()),
        "n_poles": int(sum(p.poles.shape[0] * p.poles.shape[1] for p in patches)),
        "g1_residual": residual,
        "bbox_diagonal": ctx.bbox_diagonal,
    }
    result = PatchSet(patches, face_of_patch, info, topology)
    if measure:
        info.update(patch_deviation(result, quads, context=ctx, target_params=(
            lambda f, u, v: warped_params(u[:, None], v[:, None], growth[f]))))
        used = np.unique(fv)
        info.update(normal_jumps(result, quads, context=ctx, ev_vertex=valence[used] != 4))
    return result, quads
