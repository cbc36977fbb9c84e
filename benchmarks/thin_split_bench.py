# SPDX-License-Identifier: LGPL-2.1-or-later
"""Thickness-aware splits of the paired decimation's triangles: limit-surface crossings.

Usage::

    .venv/bin/python benchmarks/thin_split_bench.py [--meshes DIR] [--only NAME ...]

QSlim sizes its triangles by the quadric error, so thin plates and struts of a TO result get
triangles many times longer than the wall is thick. This measures one remedy that the paired
decimation (:mod:`core.quadmesh.decimation.paired_decimation`) does not use: before pairing, split
the edges of the evened-out decimation longer than ``ratio`` times the local wall thickness (the
inward ray from the target point to where it leaves the solid,
:meth:`core.target_surface.TargetSurface.first_exit`), optionally only those across which the
decimation folds (the two triangles' normals at a cosine below ``fold``), longest first, no two in
one triangle per pass, each new vertex at the closest target point among the target triangles facing
the edge's way (so it does not snap to the far wall of a thin plate). Per mesh, budget and variant:
the cage's faces, the self-crossing triangle pairs of its level-2 limit surface and its inverted
faces (after the ladder's unshrinking and edits, ``paired_decimation._repaired``), against the cage
without splits. Writes ``benchmarks/THIN_SPLIT_RESULTS.md``.

The crossing faces of these cages are faces folded over themselves around thin members (the
normals at their corners disagree), not faces long against the wall: nearly every face of a
thin-membered TO result is several times longer than the wall is thick. The splits change
the crossings both ways, from budget to budget, and leave none of the cages clean, so the
paired decimation does not use them.
"""
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
DEFAULT_MESHES = os.path.join(REPO, "..", "shared", "data", "meshes")
MESHES = ("toplib_michell3d_density_mc.stl", "simjeb76_ge_bracket_to.stl",
          "to_simp_torsion_arm.stl", "tray_bottom.stl")
BUDGETS = (300, 900, 1800)
VARIANTS = (("none", None, None, 0), ("ratio 1.5, all edges", 1.5, None, 2),
            ("ratio 1.5, folds", 1.5, 0.0, 1), ("ratio 3, folds", 3.0, 0.0, 1))
"""(label, ratio, fold cosine, passes)."""
SIDE_COSINE = 0.3
"""A target triangle is on an edge's side when its normal and the edge's make a cosine above
this."""
RESULTS_MD = os.path.join(HERE, "THIN_SPLIT_RESULTS.md")

from core.box_tree import closest_on_triangles  # noqa: E402
from core.geometry import face_cross  # noqa: E402
from core.mesh_topology import unique_edges  # noqa: E402


def wall_thickness(surface, points, normals):
    """(k,) float64 length of the inward ray from each point to where it leaves the solid.

    Parameters
    ----------
    surface : TargetSurface; points : (k, 3) float64 on it; normals : (k, 3) float64 unit
        outward normals there. ``inf`` where the ray leaves within no diagonal's length.
    """
    if not len(points):
        return np.zeros(0)
    return surface.first_exit(points, -normals, surface.diagonal).t


def side_closest(surface, points, normals, radius):
    """Closest target points among the triangles facing like ``normals``.

    Parameters
    ----------
    surface : TargetSurface.
    points : (k, 3) float64; normals : (k, 3) float64 unit vectors, the side wanted.
    radius : (k,) float64, model units: triangles whose centroid is farther than this from
        the point (plus the longest target edge) are not searched.

    Returns
    -------
    (k, 3) float64 the closest points, or the unconstrained closest point
    (:meth:`TargetSurface.nearest`) where no triangle facing that way is near.
    """
    from scipy.spatial import cKDTree

    result = surface.nearest(points).point
    if not len(points):
        return result
    triangles = surface.vertices[surface.faces]
    centroid = triangles.mean(axis=1)
    reach = float(np.linalg.norm(triangles - centroid[:, None], axis=2).max())
    near = cKDTree(centroid).query_ball_point(points, radius + reach)
    query = np.repeat(np.arange(len(points)), [len(found) for found in near])
    face = np.fromiter((f for found in near for f in found), dtype=np.int64, count=len(query))
    facing = np.einsum("ij,ij->i", surface.face_normals[face], normals[query]) > SIDE_COSINE
    query, face = query[facing], face[facing]
    if not len(query):
        return result
    closest, _, _ = closest_on_triangles(triangles[face], points[query])
    distance = np.linalg.norm(closest - points[query], axis=1)
    order = np.lexsort((distance, query))
    first = order[np.r_[True, query[order][1:] != query[order][:-1]]]
    result[query[first]] = closest[first]
    return result


def split_thin_walls(vertices, faces, surface, max_faces, ratio, fold_cosine, passes):
    """Split the edges longer than ``ratio`` times the wall thickness.

    Parameters
    ----------
    vertices : (n, 3) float64 near the target; faces : (m, 3) int64 closed, outward
        2-manifold triangles.
    surface : TargetSurface of the target.
    max_faces : int, no split is made that would leave more triangles than this.
    ratio : float, edges longer than this times the smallest wall thickness at their ends
        and midpoint are split; fold_cosine : float or None, only edges whose two
        triangles' unit normals make a cosine below this (None: all); passes : int, rounds.

    Returns
    -------
    vertices : (n', 3) float64; faces : (m', 3) int64, the same topology, ``m <= m' <=
    max(m, max_faces)``; the new vertices on the target (:func:`side_closest`).
    """
    vertices = np.array(vertices, dtype=np.float64)
    faces = np.array(faces, dtype=np.int64)
    near = surface.closest(vertices)
    thickness = wall_thickness(surface, near.point, near.normal)
    for _ in range(passes):
        room = (int(max_faces) - len(faces)) // 2
        if room <= 0:
            break
        vertices, faces, thickness, split = _split_pass(vertices, faces, thickness, surface,
                                                        room, ratio, fold_cosine)
        if not split:
            break
    return vertices, faces


def _split_pass(vertices, faces, thickness, surface, most, ratio, fold_cosine):
    """One round of :func:`split_thin_walls`: up to ``most`` disjoint edges, longest first.

    Returns ``(vertices, faces, thickness, split_any)``, ``thickness`` (n',) of every vertex.
    """
    edges, halfedge_edge = unique_edges(faces)
    halfedges = np.argsort(halfedge_edge, kind="stable").reshape(-1, 2)
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    long = length > ratio * thickness[edges].min(axis=1)
    cross = face_cross(vertices, faces)
    unit = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
    if fold_cosine is not None:
        long &= np.einsum("ij,ij->i", unit[halfedges[:, 0] // 3],
                          unit[halfedges[:, 1] // 3]) < fold_cosine
    if not long.any():
        return vertices, faces, thickness, False
    side = unit[halfedges[:, 0] // 3] + unit[halfedges[:, 1] // 3]
    side /= np.maximum(np.linalg.norm(side, axis=1), 1e-300)[:, None]
    candidates = np.flatnonzero(long)
    midpoint = side_closest(surface, 0.5 * (vertices[edges[candidates, 0]]
                                            + vertices[edges[candidates, 1]]),
                            side[candidates], 0.5 * length[candidates])
    near = surface.closest(midpoint)
    middle_thickness = wall_thickness(surface, near.point, near.normal)
    too_long = length[candidates] > ratio * middle_thickness
    too_long |= long[candidates]
    order = np.argsort(-length[candidates], kind="stable")
    taken = np.zeros(len(faces), dtype=bool)
    chosen = []
    for k in order.tolist():
        touched = halfedges[candidates[k]] // 3
        if too_long[k] and not taken[touched].any():
            taken[touched] = True
            chosen.append(k)
            if len(chosen) == most:
                break
    chosen = np.array(sorted(chosen), dtype=np.int64)
    h1, h2 = halfedges[candidates[chosen], 0], halfedges[candidates[chosen], 1]
    f1, c1 = np.divmod(h1, 3)
    f2, c2 = np.divmod(h2, 3)
    a, b, c = faces[f1, c1], faces[f1, (c1 + 1) % 3], faces[f1, (c1 + 2) % 3]
    d = faces[f2, (c2 + 2) % 3]
    m = len(vertices) + np.arange(len(chosen))
    faces = faces.copy()
    faces[f1] = np.stack([a, m, c], axis=1)
    faces[f2] = np.stack([b, m, d], axis=1)
    added = np.concatenate([np.stack([m, b, c], axis=1), np.stack([m, a, d], axis=1)])
    return (np.vstack([vertices, midpoint[chosen]]), np.vstack([faces, added]),
            np.concatenate([thickness, middle_thickness[chosen]]), True)


def measure(path, budgets):
    """Rows ``(mesh, budget, variant, faces, crossings, inverted, seconds)`` of one mesh."""
    import trimesh

    import core.quadmesh.decimation.paired_decimation as paired
    from core.quadmesh.decimation.decimation import Decimation
    from core.quadmesh.decimation.even_triangulation import even_triangulation
    from core.target_surface import TargetSurface

    mesh = trimesh.load(path, process=True)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    surface = TargetSurface(vertices, faces)
    decimation = Decimation(vertices, faces, coarse_triangles=750)
    rows = []
    for budget in budgets:
        for label, ratio, fold, passes in VARIANTS:
            def evened(v, f, s, ratio=ratio, fold=fold, passes=passes):
                v, f = even_triangulation(v, f, s)
                if ratio is None:
                    return v, f
                return split_thin_walls(v, f, s, int(1.5 * len(f)), ratio, fold, passes)
            paired.even_triangulation = evened
            started = time.perf_counter()
            try:
                result, crossings, inverted, _, _ = paired._repaired(
                    paired._paired_mesh(decimation, 2 * budget, surface), surface)
            finally:
                paired.even_triangulation = even_triangulation
            rows.append((os.path.basename(path), budget, label, result.mesh.n_faces, crossings,
                         inverted, time.perf_counter() - started))
            print("| %s | %d | %s | %d | %d | %d | %.1f |" % rows[-1], flush=True)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default=DEFAULT_MESHES, help="folder of the dev meshes")
    parser.add_argument("--only", nargs="*", default=MESHES, help="mesh file names")
    args = parser.parse_args(argv)
    lines = ["# Thickness-aware splits before pairing: limit-surface crossings", "",
             "Written by `benchmarks/thin_split_bench.py` (its docstring describes the splits). "
             "`budget`: faces asked of the paired decimation (twice as many triangles decimated); "
             "`faces`: of the cage; `crossings`: self-crossing triangle pairs of its level-2 limit "
             "surface; `inverted`: faces facing away from the target; `s`: wall seconds.", "",
             "| mesh | budget | splits | faces | crossings | inverted | s |",
             "|---|---|---|---|---|---|---|"]
    for name in args.only:
        for row in measure(os.path.join(args.meshes, name), BUDGETS):
            lines.append("| %s | %d | %s | %d | %d | %d | %.1f |" % row)
    with open(RESULTS_MD, "w") as handle:
        handle.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
