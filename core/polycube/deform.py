# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polycube deformation of a labelled triangle mesh (paper Sect. 2.3, first step).

Each part is deformed in the coordinates of its own frame (``u = V @ R.T`` with ``R`` the
part frame, rows x, y, z), so a face labelled ``+X`` must end up with normal ``+u_x``.

``method="fast"`` (fastbndpolycube, Protais et al.): for every axis ``k`` one sparse
least-squares problem for the ``k``-th coordinate of all vertices,

    min  sum over half-edges (a -> b) of faces  w_ab (u_k[b] - u_k[a] - t_k[a, b])^2,

where the target ``t`` is the original edge vector, ``w`` a weight (see ``weighting``), and all vertices of faces whose label axis
is ``k`` are merged into one unknown per connected group (so each chart is exactly planar and
edges inside it have zero ``k``-component). The three scalar problems are independent; each
normal matrix is factorised once (``splu``). One unknown per connected component of the
unknown graph is eliminated (pinned) and the solution is shifted afterwards so the mean
coordinate of the component's vertices equals the mean of the targets' source coordinates.

``method="iterative"`` (Gregson et al. 2011 style, surface version, 20 iterations in the
paper): each iteration rotates every face of the current shape so its normal points along its
label direction (minimal rotation about the face centroid) and solves the same least-squares
problem without chart constraints for all three coordinates (one vertex Laplacian, factorised
once, only the right-hand side changes). The last iterate's edge vectors are then the targets
of the ``fast`` solve, which makes the charts exactly planar. This keeps edge lengths better than
projecting the original edges.

Parts are solved independently: a vertex shared by several parts (on an interface) gets one
position per part (:attr:`PartPolycube.vertices`); :attr:`PolycubeDeformation.vertices` takes,
for such vertices, the position from the lowest-numbered part.
"""
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu

from core.errors import ParameterError
from core.segmentation.charts import build_topology, extract_layout

METHODS = ("fast", "iterative")
WEIGHTINGS = ("relative", "uniform")
DEFAULT_ITERATIONS = 20
DEGENERATE_REL_AREA = 1e-10
"""A deformed face counts as degenerate below this fraction of the part's mean original area."""


@dataclass
class PartPolycube:
    """Polycube deformation of one part.

    part : int part index.
    frame : (3, 3) float64 part frame used (rows x, y, z in world coordinates).
    vertex_ids : (k,) int64 global indices of the part's vertices, ascending.
    faces : (f,) int64 global indices of the part's faces, ascending.
    local : (k, 3) float64 deformed positions in frame coordinates (``u = world @ frame.T``).
    world : (k, 3) float64 deformed positions in world coordinates (``local @ frame``).
    flipped : (f,) bool faces whose deformed normal points away from their label direction.
    degenerate : (f,) bool faces whose deformed area is (near) zero.
    """

    part: int
    frame: np.ndarray
    vertex_ids: np.ndarray
    faces: np.ndarray
    local: np.ndarray
    world: np.ndarray
    flipped: np.ndarray
    degenerate: np.ndarray


@dataclass
class PolycubeDeformation:
    """Result of :func:`polycube_deformation`.

    vertices : (n, 3) float64 deformed world positions (interface vertices: lowest part).
    local : (n, 3) float64 deformed positions in the frame of that same part.
    parts : list of PartPolycube, one per part.
    face_chart : (m,) int64 chart of each face (``charts.extract_layout`` numbering).
    chart_label : (c,) int64 label 0..5 of each chart.
    chart_part : (c,) int64 part of each chart.
    chart_plane : (c,) float64 coordinate of each chart's plane along its label axis, in its
        part's frame (mesh units).
    chart_planarity : (c,) float64 max |coordinate - plane| over the chart's vertices.
    flipped : (m,) bool, degenerate : (m,) bool per face (see PartPolycube).
    normal_deviation_deg : (m,) float64 angle between deformed normal and label direction
        (NaN for degenerate faces).
    history : list of dict per solve (``flipped``, ``degenerate``, ``max_normal_deviation_deg``).
    info : dict of summary figures and timings (seconds).
    """

    vertices: np.ndarray
    local: np.ndarray
    parts: list
    face_chart: np.ndarray
    chart_label: np.ndarray
    chart_part: np.ndarray
    chart_plane: np.ndarray
    chart_planarity: np.ndarray
    flipped: np.ndarray
    degenerate: np.ndarray
    normal_deviation_deg: np.ndarray
    history: list = field(default_factory=list)
    info: dict = field(default_factory=dict)


def _example(mask):
    return np.flatnonzero(mask)[:5].tolist()


def check_inputs(V, F, face_label, face_frame, face_part):
    """Validated float64/int64 copies of the inputs; raises ``ParameterError``.

    ``face_frame`` may be (3, 3) (one frame for every face) or (m, 3, 3).
    Returns ``V (n, 3), F (m, 3), face_label (m,), face_frame (m, 3, 3), face_part (m,)``.
    """
    V = np.asarray(V, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise ParameterError(f"vertices must be a non-empty (n, 3) array, got shape {V.shape}")
    bad = ~np.isfinite(V).all(axis=1)
    if bad.any():
        raise ParameterError(f"{int(bad.sum())} vertices are not finite, e.g. {_example(bad)}")
    F = np.asarray(F)
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0 or not np.issubdtype(F.dtype, np.integer):
        raise ParameterError(f"faces must be a non-empty (m, 3) integer array, got shape {F.shape} "
                             f"dtype {F.dtype}")
    F = F.astype(np.int64)
    bad = ((F < 0) | (F >= len(V))).any(axis=1)
    if bad.any():
        raise ParameterError(f"{int(bad.sum())} faces use vertex indices outside 0..{len(V) - 1}, "
                             f"e.g. faces {_example(bad)}")
    m = len(F)
    face_label = np.asarray(face_label)
    if face_label.shape != (m,) or not np.issubdtype(face_label.dtype, np.integer):
        raise ParameterError(f"face_label must be an ({m},) integer array, got shape "
                             f"{face_label.shape} dtype {face_label.dtype}")
    face_label = face_label.astype(np.int64)
    bad = (face_label < 0) | (face_label > 5)
    if bad.any():
        raise ParameterError(f"{int(bad.sum())} face labels are outside 0..5, e.g. faces "
                             f"{_example(bad)} with labels {face_label[bad][:5].tolist()}")
    face_frame = np.asarray(face_frame, dtype=np.float64)
    if face_frame.shape == (3, 3):
        face_frame = np.broadcast_to(face_frame, (m, 3, 3))
    if face_frame.shape != (m, 3, 3):
        raise ParameterError(f"face_frame must be (3, 3) or ({m}, 3, 3), got {face_frame.shape}")
    err = np.abs(np.einsum("fij,fkj->fik", face_frame, face_frame) - np.eye(3)).max(axis=(1, 2))
    bad = ~(err <= 1e-6)
    if bad.any():
        raise ParameterError(f"{int(bad.sum())} face frames are not orthonormal (tolerance 1e-6), "
                             f"e.g. faces {_example(bad)}")
    if face_part is None:
        face_part = np.zeros(m, dtype=np.int64)
    face_part = np.asarray(face_part)
    if face_part.shape != (m,) or not np.issubdtype(face_part.dtype, np.integer):
        raise ParameterError(f"face_part must be an ({m},) integer array, got shape "
                             f"{face_part.shape} dtype {face_part.dtype}")
    face_part = face_part.astype(np.int64)
    bad = face_part < 0
    if bad.any():
        raise ParameterError(f"{int(bad.sum())} faces have a negative part, e.g. {_example(bad)}")
    return V, F, face_label, face_frame, face_part


def mean_frame(frames):
    """(3, 3) float64 rotation closest (Frobenius) to the mean of (k, 3, 3) rotations."""
    u, _, vt = np.linalg.svd(frames.mean(axis=0))
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    return r


def _face_normals_raw(P, F):
    """(f, 3) float64 cross products (twice the area times unit normal) of faces ``F`` on ``P``."""
    return np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])


def rotations_to(a, b):
    """(f, 3, 3) float64 minimal rotations taking unit vectors ``a`` (f, 3) to ``b`` (f, 3).

    Antiparallel pairs rotate by 180 degrees about an axis perpendicular to ``a``.
    """
    c = np.einsum("ij,ij->i", a, b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1)
    anti = s < 1e-12
    if anti.any():
        helper = np.eye(3)[np.argmin(np.abs(a[anti]), axis=1)]
        perp = np.cross(a[anti], helper)
        axis[anti] = perp
        s[anti] = np.linalg.norm(perp, axis=1)
        c = c.copy()
        c[anti] = np.where(c[anti] < 0, -1.0, 1.0)
    k = axis / np.maximum(s, 1e-300)[:, None]
    sin = np.where(anti, 0.0, s)
    K = np.zeros((len(a), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    return np.eye(3) + sin[:, None, None] * K + (1.0 - c)[:, None, None] * (K @ K)


class _ScalarSystem:
    """Least-squares edge-difference system over merged unknowns, factorised once.

    Rows are the half-edges ``(a, b)`` of the faces; unknown of vertex ``v`` is ``group[v]``.
    Rows whose two ends share an unknown are dropped. One unknown per connected component
    of the unknown graph is pinned to zero; :meth:`solve` shifts each component afterwards so
    its vertices' mean coordinate equals ``mean_ref`` over the same vertices.
    """

    def __init__(self, half_a, half_b, group, n_groups, weight):
        self.group = group
        keep = group[half_a] != group[half_b]
        self.keep = keep
        ga, gb = group[half_a[keep]], group[half_b[keep]]
        r = len(ga)
        self.sqrt_w = np.sqrt(weight[keep])
        rows = np.repeat(np.arange(r), 2)
        cols = np.stack([ga, gb], axis=1).reshape(-1)
        vals = (self.sqrt_w[:, None] * np.array([-1.0, 1.0])).reshape(-1)
        self.A = sp.csr_matrix((vals, (rows, cols)), shape=(r, n_groups))
        adj = sp.csr_matrix((np.ones(r), (ga, gb)), shape=(n_groups, n_groups))
        n_comp, comp = connected_components(adj, directed=False)
        self.vertex_comp = comp[group]
        self.n_comp = n_comp
        pinned = np.zeros(n_groups, dtype=bool)
        first = np.full(n_comp, n_groups, dtype=np.int64)
        np.minimum.at(first, comp, np.arange(n_groups))
        pinned[first] = True
        self.free = np.flatnonzero(~pinned)
        self.n_groups = n_groups
        normal = (self.A.T @ self.A).tocsc()[self.free][:, self.free]
        self.lu = splu(normal.tocsc(), permc_spec="MMD_AT_PLUS_A") if len(self.free) else None

    def solve(self, target, mean_ref):
        """(k,) float64 least-squares vertex values.

        target : (h,) float64 desired difference ``u[b] - u[a]`` of every half-edge.
        mean_ref : (k,) float64 reference coordinate of every vertex (only component means used).
        """
        x = np.zeros(self.n_groups)
        if self.lu is not None:
            rhs = self.A.T @ (self.sqrt_w * target[self.keep])
            x[self.free] = self.lu.solve(rhs[self.free])
        u = x[self.group]
        counts = np.bincount(self.vertex_comp, minlength=self.n_comp)
        shift = (np.bincount(self.vertex_comp, weights=mean_ref - u, minlength=self.n_comp)
                 / np.maximum(counts, 1))
        return u + shift[self.vertex_comp]


def _merge_groups(n, faces_k):
    """(n,) int64 unknown of each vertex: vertices joined by faces ``faces_k`` (j, 3) share one."""
    if len(faces_k):
        a = faces_k.reshape(-1)
        b = np.roll(faces_k, -1, axis=1).reshape(-1)
        adj = sp.csr_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    else:
        adj = sp.csr_matrix((n, n))
    _, comp = connected_components(adj, directed=False)
    # number unknowns by lowest vertex index so results do not depend on scipy's numbering
    first = np.full(comp.max() + 1, n, dtype=np.int64)
    np.minimum.at(first, comp, np.arange(n))
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[comp]


def _face_quality(P, F, label, ref_area):
    """Flipped, degenerate masks and normal deviation (deg) of faces ``F`` on positions ``P``."""
    nrm = _face_normals_raw(P, F)
    area2 = np.linalg.norm(nrm, axis=1)
    axis = label // 2
    sign = np.where(label % 2 == 0, 1.0, -1.0)
    along = sign * nrm[np.arange(len(F)), axis]
    degenerate = area2 <= 2.0 * DEGENERATE_REL_AREA * ref_area
    flipped = (along <= 0) & ~degenerate
    cosang = np.clip(along / np.maximum(area2, 1e-300), -1.0, 1.0)
    dev = np.where(degenerate, np.nan, np.degrees(np.arccos(cosang)))
    return flipped, degenerate, dev


def _quality_entry(stage, flipped, degenerate, dev):
    finite = dev[np.isfinite(dev)]
    return {"stage": stage, "flipped": int(flipped.sum()), "degenerate": int(degenerate.sum()),
            "max_normal_deviation_deg": float(finite.max()) if len(finite) else 0.0}


def _deform_part(U, F, label, method, iterations, history, part, weighting):
    """Deformed local coordinates (k, 3) of one part (U: local vertex coords, F: local faces)."""
    n = len(U)
    half_a = F.reshape(-1)
    half_b = np.roll(F, -1, axis=1).reshape(-1)
    length = np.linalg.norm(U[half_b] - U[half_a], axis=1)
    if weighting == "uniform":
        weight = np.ones(len(length))
    else:  # "relative": each edge's error relative to its length
        weight = (length.mean() / np.maximum(length, 1e-12 * length.mean())) ** 2
    ref_area = 0.5 * np.linalg.norm(_face_normals_raw(U, F), axis=1).mean()
    axis = label // 2
    timings = {}
    targets = U
    if method == "iterative" and iterations > 0:
        t0 = time.perf_counter()
        soft = _ScalarSystem(half_a, half_b, np.arange(n), n, weight)
        timings["factor_soft"] = time.perf_counter() - t0
        direction = np.zeros((len(F), 3))
        direction[np.arange(len(F)), axis] = np.where(label % 2 == 0, 1.0, -1.0)
        P = U.copy()
        t0 = time.perf_counter()
        for it in range(iterations):
            nrm = _face_normals_raw(P, F)
            nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)[:, None]
            R = rotations_to(nrm, direction)
            corners = P[F]
            centred = corners - corners.mean(axis=1, keepdims=True)
            rotated = np.einsum("fij,fcj->fci", R, centred)
            diff = (np.roll(rotated, -1, axis=1) - rotated).reshape(-1, 3)
            P = np.stack([soft.solve(diff[:, k], P[:, k]) for k in range(3)], axis=1)
            history.append({"part": part, "iteration": it + 1,
                            **_quality_entry("soft", *_face_quality(P, F, label, ref_area))})
        timings["soft_iterations"] = time.perf_counter() - t0
        targets = P
    t0 = time.perf_counter()
    systems = [_ScalarSystem(half_a, half_b, g, int(g.max()) + 1, weight)
               for g in (_merge_groups(n, F[axis == k]) for k in range(3))]
    timings["factor_hard"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    diff = targets[half_b] - targets[half_a]
    out = np.stack([systems[k].solve(diff[:, k], targets[:, k]) for k in range(3)], axis=1)
    timings["solve_hard"] = time.perf_counter() - t0
    flipped, degenerate, dev = _face_quality(out, F, label, ref_area)
    history.append({"part": part, "iteration": iterations if method == "iterative" else 0,
                    **_quality_entry("planar", flipped, degenerate, dev)})
    return out, flipped, degenerate, dev, timings


def polycube_deformation(V, F, face_label, face_frame, face_part=None, part_frames=None,
                         method="fast", iterations=DEFAULT_ITERATIONS, weighting="relative"):
    """Deform each part of a labelled mesh into a polycube with exactly planar charts.

    Parameters
    ----------
    V : (n, 3) float vertex positions (world, mesh units).
    F : (m, 3) int faces, outward orientation.
    face_label : (m,) int labels 0..5 = +X, -X, +Y, -Y, +Z, -Z of the face's part frame.
    face_frame : (3, 3) or (m, 3, 3) float frames (rows x, y, z). Without ``part_frames`` each
        part uses the rotation closest to the mean of its faces' frames.
    face_part : (m,) int parts (default: one part).
    part_frames : optional (P, 3, 3) float frame of each part (rows x, y, z).
    method : ``"fast"`` (one solve per axis) or ``"iterative"`` (Gregson-style rotations, then
        the planar solve); see the module docstring.
    iterations : int >= 0, rotation iterations of ``"iterative"`` (paper: 20).
    weighting : ``"relative"`` (default: half-edge rows weighted by ``(mean length / length)^2``,
        so every edge keeps its vector up to a relative error; far fewer folds on meshes with
        long thin triangles) or ``"uniform"`` (absolute errors, long edges dominate).

    Returns
    -------
    PolycubeDeformation

    Raises
    ------
    ParameterError for malformed arrays, labels outside 0..5 or unknown options.
    """
    started = time.perf_counter()
    if method not in METHODS:
        raise ParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if weighting not in WEIGHTINGS:
        raise ParameterError(f"weighting must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 0:
        raise ParameterError(f"iterations must be an integer >= 0, got {iterations!r}")
    V, F, face_label, face_frame, face_part = check_inputs(V, F, face_label, face_frame, face_part)
    n_parts = int(face_part.max()) + 1
    if part_frames is not None:
        part_frames = np.asarray(part_frames, dtype=np.float64)
        if part_frames.ndim != 3 or part_frames.shape[1:] != (3, 3) or len(part_frames) < n_parts:
            raise ParameterError(f"part_frames must be ({n_parts}, 3, 3), got {part_frames.shape}")
    m = len(F)
    t0 = time.perf_counter()
    topology = build_topology(F, len(V))
    layout = extract_layout(topology, face_part, face_label)
    t_layout = time.perf_counter() - t0

    vertices = V.copy()
    local = V.copy()
    assigned = np.zeros(len(V), dtype=bool)
    flipped = np.zeros(m, dtype=bool)
    degenerate = np.zeros(m, dtype=bool)
    deviation = np.full(m, np.nan)
    parts, history, timings = [], [], {"layout": t_layout}
    chart_plane = np.full(layout.n_charts, np.nan)
    chart_planarity = np.full(layout.n_charts, np.nan)
    for p in range(n_parts):
        faces_p = np.flatnonzero(face_part == p)
        if not len(faces_p):
            continue
        frame = part_frames[p] if part_frames is not None else mean_frame(face_frame[faces_p])
        vids, local_f = np.unique(F[faces_p], return_inverse=True)
        local_f = local_f.reshape(-1, 3)
        U = V[vids] @ frame.T
        out, fl, dg, dev, tm = _deform_part(U, local_f, face_label[faces_p], method,
                                            int(iterations), history, p, weighting)
        for key, value in tm.items():
            timings[key] = timings.get(key, 0.0) + value
        world = out @ frame
        parts.append(PartPolycube(p, frame, vids, faces_p, out, world, fl, dg))
        new = ~assigned[vids]
        vertices[vids[new]] = world[new]
        local[vids[new]] = out[new]
        assigned[vids] = True
        flipped[faces_p], degenerate[faces_p], deviation[faces_p] = fl, dg, dev
        # chart planes: coordinate along the label axis of every corner of every face
        chart = layout.face_chart[faces_p]
        ax = face_label[faces_p] // 2
        coord = out[local_f, ax[:, None]]
        lo = np.full(layout.n_charts, np.inf)
        hi = np.full(layout.n_charts, -np.inf)
        np.minimum.at(lo, np.repeat(chart, 3), coord.reshape(-1))
        np.maximum.at(hi, np.repeat(chart, 3), coord.reshape(-1))
        used = np.unique(chart)
        chart_plane[used] = 0.5 * (lo[used] + hi[used])
        chart_planarity[used] = 0.5 * (hi[used] - lo[used])
    finite = deviation[np.isfinite(deviation)]
    info = {
        "method": method,
        "weighting": weighting,
        "iterations": int(iterations) if method == "iterative" else 0,
        "parts": len(parts),
        "charts": int(layout.n_charts),
        "flipped": int(flipped.sum()),
        "degenerate": int(degenerate.sum()),
        "flipped_examples": _example(flipped),
        "max_normal_deviation_deg": float(finite.max()) if len(finite) else 0.0,
        "max_chart_planarity": float(np.nanmax(chart_planarity)) if layout.n_charts else 0.0,
        "interface_vertices": int(sum(len(pp.vertex_ids) for pp in parts) - assigned.sum()),
        "seconds": {k: round(v, 4) for k, v in timings.items()},
    }
    info["seconds"]["total"] = round(time.perf_counter() - started, 4)
    return PolycubeDeformation(vertices, local, parts, layout.face_chart, layout.chart_label,
                               layout.chart_part, chart_plane, chart_planarity, flipped,
                               degenerate, deviation, history, info)
