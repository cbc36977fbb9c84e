# SPDX-License-Identifier: LGPL-2.1-or-later
"""The working surface: a proxy of bounded size on which parts, frames, labeling and the
base mesh run.

A fine target (a topology-optimisation export of a million triangles) and a coarse one of
the same shape should give the same labeling and the same cage, and the cost of those
stages should follow the size of the answer (a few hundred cage faces), not the size of the
input. Above ``params.proxy_triangles`` triangles the target is therefore reduced to about
that many by shortest-edge collapses (libigl's ``decimate``: the shortest edge left becomes
its midpoint; collapses that would change the topology are refused), and the proxy's
vertices are then moved to their closest points on the target (a midpoint of a curved
surface's edge lies off it). Collapsing the shortest edges first leaves triangles of about
one size wherever the target's are smaller, so proxies of one shape triangulated at
different resolutions are alike, and alike to a target of about the proxy's size from the
same design. A quadric reduction (Garland & Heckbert) would keep the shape closer with the
same count, but it keeps small triangles where the surface curves and a few large ones on
flat regions, in a pattern that differs from one triangulation of the shape to another: the
boundaries between charts then follow different triangle edges, and the labeling and the
cage differ with the resolution of the input.

The proxy is accepted only when it is what the later stages need: a closed, consistently
oriented 2-manifold without self-intersections and with the target's genus and components
(the intake's own checks and unambiguous repairs). Otherwise the reduction is tried again
with more triangles, and the full target is used when no reduction keeps the shape; the
report says which and why. The fit and every distance and containment figure still use the
full target.
"""
from dataclasses import dataclass, field

import numpy as np

from core.errors import InvalidMeshError
from core.types import TriMesh

ATTEMPT_SIZES = (1.0, 1.1, 1.25, 2.0, 4.0)
"""Sizes of the reductions tried, in multiples of ``proxy_triangles``: a reduction whose one
sliver the repairs cannot remove usually succeeds a little larger; one that loses a handle,
only with more triangles."""
TIE_BREAK = 1e-4
"""Vertices are moved by about this many mean edge lengths before the reduction: a subdivided
mesh has whole families of edges of exactly one length, and the order that breaks those ties
leaves slivers the repairs cannot remove; a move far below any tolerance of the later stages
breaks them (and the projection onto the target undoes it). The move is a fixed function of
the vertex's position (:func:`tie_break`), so the proxy does not depend on the order in
which the file lists the vertices."""
TIE_BREAK_WAVES = 8
"""Plane waves summed by :func:`tie_break` along every axis."""


@dataclass(frozen=True)
class WorkingSurface:
    """The surface the segmentation and the base mesh run on.

    mesh : TriMesh, the proxy, or the target itself when it is small enough or no reduction
        kept its shape.
    reduced : bool, ``mesh`` is a reduction of the target.
    report : dict, JSON-serialisable: triangles, reduced, largest_move_mm (the largest
        distance by which a vertex of the reduction was moved onto the target, 0 when not
        reduced), reason (why the target itself is used), refused (the smaller reductions
        tried first and why each was refused).
    """

    mesh: TriMesh
    reduced: bool
    report: dict = field(default_factory=dict)


def working_surface(target, genus, components, proxy_triangles, reason_to_keep=""):
    """The proxy of ``target`` the segmentation and the base mesh run on.

    Parameters
    ----------
    target : TriMesh, the validated target (closed, outward, 2-manifold), in mm.
    genus, components : int, its genus and connected components; the proxy must keep them.
    proxy_triangles : int, triangles above which the target is reduced, and about the size
        of the proxy; 0 keeps the target.
    reason_to_keep : str, non-empty when the caller needs the target's own faces (user parts
        given per face); the target is then kept and this is the report's reason.

    Returns
    -------
    WorkingSurface
    """
    n_faces = len(target.faces)
    if reason_to_keep or not proxy_triangles or n_faces <= proxy_triangles:
        reason = reason_to_keep or ("" if n_faces <= proxy_triangles or not proxy_triangles
                                    else "proxy off")
        return _kept(target, reason)
    from core.target_surface import TargetSurface

    surface = TargetSurface(target.vertices, target.faces)
    failures = []
    for size in ATTEMPT_SIZES:
        wanted = int(round(size * proxy_triangles))
        if wanted >= n_faces:
            break
        reduced = reduce_triangles(target, wanted)
        onto = surface.nearest(reduced.vertices)
        proxy, problem = _checked(TriMesh(onto.point, reduced.faces), genus, components)
        if problem is None:
            return WorkingSurface(proxy, True, {
                "triangles": int(len(proxy.faces)), "reduced": True,
                "largest_move_mm": round(float(onto.distance.max()), 6),
                "reason": "", "refused": failures})
        failures.append(f"{wanted} triangles: {problem}")
    return _kept(target, "no reduction kept the shape (" + "; ".join(failures) + ")")


def reduce_triangles(mesh, triangles):
    """``mesh`` reduced to about ``triangles`` triangles by shortest-edge collapses.

    Parameters
    ----------
    mesh : TriMesh (n vertices, m > ``triangles`` faces), a closed 2-manifold.
    triangles : int, wanted triangle count.

    Returns
    -------
    TriMesh, its vertices the midpoints of collapsed edges (off a curved target by a
    fraction of an edge length) or the target's own; faces with a repeated corner and unused
    vertices dropped; not checked further (see :func:`working_surface`).
    """
    import igl

    faces = np.asfortranarray(mesh.faces, dtype=np.int32)
    edge = float(np.linalg.norm(mesh.vertices[faces[:, 0]] - mesh.vertices[faces[:, 1]],
                                axis=1).mean())
    vertices = np.asfortranarray(mesh.vertices + TIE_BREAK * edge * tie_break(mesh.vertices, edge),
                                 dtype=np.float64)
    points, triangles_out = igl.decimate(vertices, faces, int(triangles))[:2]
    points = np.asarray(points, dtype=np.float64)
    triangles_out = np.asarray(triangles_out, dtype=np.int64)
    collapsed = ((triangles_out[:, 0] == triangles_out[:, 1])
                 | (triangles_out[:, 1] == triangles_out[:, 2])
                 | (triangles_out[:, 2] == triangles_out[:, 0]))
    triangles_out = triangles_out[~collapsed]
    used, compact = np.unique(triangles_out, return_inverse=True)
    return TriMesh(points[used], compact.reshape(-1, 3))


def tie_break(points, wavelength):
    """(n, 3) float64 in about [-1, 1]: a fixed function of each point's position.

    Every coordinate is a sum of ``TIE_BREAK_WAVES`` plane waves of about ``wavelength``
    (model units) in seeded random directions and phases, so neighbouring vertices move
    differently and a point moves the same whatever its index.
    """
    rng = np.random.default_rng(0)
    directions = rng.standard_normal((3, TIE_BREAK_WAVES, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    frequency = 2.0 * np.pi / (wavelength * rng.uniform(0.5, 1.5, (3, TIE_BREAK_WAVES, 1)))
    phase = rng.uniform(0.0, 2.0 * np.pi, (3, TIE_BREAK_WAVES))
    wave_vectors = directions * frequency
    move = np.empty((len(points), 3))
    for axis in range(3):  # one axis at a time: n x waves values, not n x 3 x waves
        move[:, axis] = np.sin(np.asarray(points) @ wave_vectors[axis].T + phase[axis]).sum(axis=1)
    return move / np.sqrt(0.5 * TIE_BREAK_WAVES)


def _checked(proxy, genus, components):
    """``(mesh, problem)``: the proxy after the intake's validation and its unambiguous
    repairs (a reduction can leave coincident vertices and the zero-area faces between them),
    and None; or ``(None, why)`` when it fails them or lacks the target's ``genus`` and
    ``components``."""
    from core.validate import validate_target

    try:
        mesh, summary = validate_target(proxy.vertices, proxy.faces, components="all",
                                        name="the proxy")
    except InvalidMeshError as exc:
        return None, str(exc)
    if int(summary["genus"]) != genus or summary["components"] != components:
        return None, (f"genus {summary['genus']} and {summary['components']} component(s) "
                      f"where the target has genus {genus} and {components}")
    return mesh, None


def _kept(target, reason):
    return WorkingSurface(target, False, {"triangles": int(len(target.faces)), "reduced": False,
                                          "largest_move_mm": 0.0, "reason": reason,
                                          "refused": []})
