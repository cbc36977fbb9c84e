# SPDX-License-Identifier: LGPL-2.1-or-later
"""Tolerance-driven refinement of an all-quad cage (``--tolerance``).

After a fit, every base quad gets the largest deviation between its part of the limit
surface and the target, both ways: the distance of its fine limit points to the target,
and the distance of the target samples whose closest point on the limit surface lies in
it. Each quad deviating more than the tolerance has the quad strip through its two
longer opposite edges split: every quad of the strip (the ring of quads joined through
opposite edges, closed on a closed quad mesh) is cut in two through the midpoints of its
two crossed edges, so the mesh stays all-quad and conforming (a quad lying on two split
strips is cut in four). The refined cage (midpoints of the fitted cage) is fitted again,
until the largest deviation is at most the tolerance or the next refinement would exceed
the face budget.
"""
from dataclasses import dataclass, field

import numpy as np

from core.errors import ParameterError
from core.geometry import sample_surface, triangulate
from core.subdivision.catmull_clark import build_hierarchy, face_grids
from core.subdivision.limit import limit_matrices
from core.target_surface import TargetSurface
from core.types import PolyMesh

DEVIATION_SAMPLES = 20000


@dataclass
class RefinementResult:
    """Outcome of :func:`fit_to_tolerance`.

    mesh : PolyMesh, the last fitted cage.
    info : dict, the last fit's info.
    rounds : list of dict, per fit: ``faces``, ``max_deviation`` and ``mean_deviation``
        (fractions of the target's bounding-box diagonal), ``offending_faces``.
    met : bool, the last fit's largest deviation is at most the tolerance.
    reason : str, why the refinement stopped.
    """

    mesh: PolyMesh
    info: dict
    rounds: list = field(default_factory=list)
    met: bool = False
    reason: str = ""


def fit_to_tolerance(base, target, tolerance, max_faces, fit, max_rounds=8):
    """Fit, then split the deviating quad strips and refit until within ``tolerance``.

    Parameters
    ----------
    base : PolyMesh, closed, all quads.
    target : TriMesh
    tolerance : float > 0, fraction of the target's bounding-box diagonal.
    max_faces : int, no refinement beyond this many faces.
    fit : callable ``fit(cage) -> (fitted PolyMesh, info dict)`` (the configured fit;
        its ``info["levels"]`` says the subdivision level of the fine limit points).
    max_rounds : int >= 1, most fits.

    Returns
    -------
    RefinementResult

    Raises
    ------
    ParameterError
        ``tolerance`` is not positive, or the base mesh has a face that is not a quad.
    """
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise ParameterError(f"tolerance must be a positive fraction of the bounding-box "
                             f"diagonal, got {tolerance!r}")
    sizes = base.face_sizes
    if (sizes != 4).any():
        bad = np.flatnonzero(sizes != 4)
        raise ParameterError(f"tolerance refinement needs an all-quad base mesh; "
                             f"{len(bad)} faces are not quads, e.g. faces {bad[:5].tolist()}")
    surface = TargetSurface(target.vertices, target.faces)
    rng = np.random.default_rng(0)
    samples = np.vstack([sample_surface(surface.vertices, surface.faces, DEVIATION_SAMPLES, rng),
                         surface.vertices])
    cage = base
    result = RefinementResult(base, {})
    for done in range(max_rounds):
        fitted, info = fit(cage)
        per_face = face_deviation(fitted, info["levels"], surface, samples)
        offending = np.flatnonzero(per_face > tolerance)
        result.mesh, result.info = fitted, info
        result.rounds.append({"faces": int(fitted.n_faces),
                              "max_deviation": float(per_face.max()),
                              "mean_deviation": float(info["mean_distance"]),
                              "offending_faces": int(len(offending))})
        if not len(offending):
            result.met, result.reason = True, "tolerance met"
            return result
        refined = split_quad_strips(fitted, _seed_directions(fitted, offending))
        if refined.n_faces > max_faces:
            result.reason = (f"tolerance not met: the next refinement would have "
                             f"{refined.n_faces} faces, more than max_base_faces={max_faces}")
            return result
        if done == max_rounds - 1:
            result.reason = f"tolerance not met after {max_rounds} fits"
            return result
        cage = refined
    return result


def face_deviation(cage, levels, surface, samples):
    """(m,) float64 largest two-sided deviation of each base quad's limit-surface part.

    Parameters
    ----------
    cage : PolyMesh, all quads.
    levels : int >= 1, level of the fine limit points.
    surface : TargetSurface of the target.
    samples : (s, 3) float64 points on the target.

    Returns
    -------
    (m,) float64, fractions of ``surface.diagonal``.
    """
    hierarchy = build_hierarchy(cage, levels)
    fine = hierarchy.meshes[levels]
    X = limit_matrices(fine)[0] @ hierarchy.composite(levels - 1) @ cage.vertices
    grid = face_grids(hierarchy, levels).reshape(cage.n_faces, -1)
    forward = surface.nearest(X).distance[grid].max(axis=1)
    T = triangulate(fine.face_vertices, fine.face_offsets)
    back = TargetSurface(X, T, "fitted surface").nearest(samples)
    # fan triangulation: 2 triangles per fine quad, 4**levels fine quads per base quad
    owner = back.face // (2 * 4 ** levels)
    backward = np.zeros(cage.n_faces)
    np.maximum.at(backward, owner, back.distance)
    return np.maximum(forward, backward) / surface.diagonal


def split_quad_strips(cage, seeds):
    """Split the quad strips through ``seeds`` conformingly.

    Parameters
    ----------
    cage : PolyMesh, closed, all quads.
    seeds : (s, 2) int64 rows ``(face, direction)``; direction 0 crosses the face's edges
        0 (corners 0-1) and 2 (corners 2-3), direction 1 its edges 1 and 3.

    Returns
    -------
    PolyMesh, all quads, the new vertices at the midpoints of the split edges; both halves of
    a split crease edge are crease edges.
    """
    quads = cage.face_vertices.reshape(-1, 4)
    m = len(quads)
    a, b = quads, np.roll(quads, -1, axis=1)
    keys = np.minimum(a, b) * len(cage.vertices) + np.maximum(a, b)
    _, edge_id = np.unique(keys.reshape(-1), return_inverse=True)
    edge_id = edge_id.reshape(m, 4)
    twin = _twins(edge_id)
    split = np.zeros((m, 2), dtype=bool)
    for face, direction in np.asarray(seeds, dtype=np.int64).reshape(-1, 2):
        f, k = int(face), int(direction)
        leave = k + 2
        while not split[f, k]:
            split[f, k] = True
            f, entry = divmod(int(twin[f * 4 + leave]), 4)
            k, leave = entry % 2, (entry + 2) % 4
    cut_edges = np.unique(np.concatenate([edge_id[split[:, 0]][:, [0, 2]].reshape(-1),
                                          edge_id[split[:, 1]][:, [1, 3]].reshape(-1)]))
    V = np.asarray(cage.vertices, dtype=np.float64)
    n = len(V)
    mid_index = np.full(edge_id.max() + 1, -1, dtype=np.int64)
    mid_index[cut_edges] = n + np.arange(len(cut_edges))
    first = np.zeros(edge_id.max() + 1, dtype=np.int64)
    first[edge_id.reshape(-1)] = np.arange(4 * m)
    ends = np.stack([a.reshape(-1)[first[cut_edges]], b.reshape(-1)[first[cut_edges]]], axis=1)
    both = split.all(axis=1)
    centres = np.flatnonzero(both)
    centre_index = np.full(m, -1, dtype=np.int64)
    centre_index[centres] = n + len(cut_edges) + np.arange(len(centres))
    vertices = np.vstack([V, V[ends].mean(axis=1), V[quads[centres]].mean(axis=1)])
    mid = mid_index[edge_id]
    v0, v1, v2, v3 = quads.T
    m0, m1, m2, m3 = mid.T
    e = centre_index
    pieces = [quads[~split.any(axis=1)]]
    only0 = split[:, 0] & ~split[:, 1]
    only1 = split[:, 1] & ~split[:, 0]
    pieces.append(np.stack([v0, m0, m2, v3], axis=1)[only0])
    pieces.append(np.stack([m0, v1, v2, m2], axis=1)[only0])
    pieces.append(np.stack([v0, v1, m1, m3], axis=1)[only1])
    pieces.append(np.stack([m3, m1, v2, v3], axis=1)[only1])
    pieces.append(np.stack([v0, m0, e, m3], axis=1)[both])
    pieces.append(np.stack([m0, v1, m1, e], axis=1)[both])
    pieces.append(np.stack([e, m1, v2, m2], axis=1)[both])
    pieces.append(np.stack([m3, e, m2, v3], axis=1)[both])
    faces = np.concatenate(pieces).astype(np.int64)
    creases = None
    if cage.n_creases:
        pairs = np.asarray(cage.creases, dtype=np.int64)
        crease_keys = pairs.min(axis=1) * n + pairs.max(axis=1)
        crease_mid = mid_index[np.searchsorted(np.unique(keys), crease_keys)]
        cut = crease_mid >= 0
        creases = np.concatenate([pairs[~cut], np.stack([pairs[cut, 0], crease_mid[cut]], axis=1),
                                  np.stack([crease_mid[cut], pairs[cut, 1]], axis=1)])
    return PolyMesh(vertices, faces.reshape(-1), np.arange(0, faces.size + 1, 4, dtype=np.int64),
                    creases)


def _twins(edge_id):
    """(4 m,) int64: for corner-edge ``4 f + i`` the corner-edge on the other side."""
    flat = edge_id.reshape(-1)
    order = np.argsort(flat, kind="stable")
    pairs = order.reshape(-1, 2)
    twin = np.empty_like(flat)
    twin[pairs[:, 0]], twin[pairs[:, 1]] = pairs[:, 1], pairs[:, 0]
    return twin


def _seed_directions(cage, faces):
    """(s, 2) rows ``(face, direction)``: cut each face across its two longer edges."""
    quads = cage.face_vertices.reshape(-1, 4)[faces]
    V = cage.vertices
    length = np.linalg.norm(V[np.roll(quads, -1, axis=1)] - V[quads], axis=2)
    direction = np.where(length[:, 0] + length[:, 2] >= length[:, 1] + length[:, 3], 0, 1)
    return np.stack([faces, direction], axis=1)
