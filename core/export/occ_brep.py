# SPDX-License-Identifier: LGPL-2.1-or-later
"""A closed patch set and its shared-edge topology as OpenCascade BREP text.

The BREP format (``BRepTools::Write``, "CASCADE Topology V1") stores the topology
explicitly: each vertex and edge once, each edge with its 3-D curve and one parameter
curve (pcurve) per face that uses it, each face with its surface and its loop of
oriented edges, then the shell and the solid. Reading it back
(``Part.Shape.importBrepFromString``) rebuilds the solid as written, with every edge
shared by its two faces: no sewing, no projection, no tolerance search.

Layout written here: no locations; one pcurve per edge use, the straight ``(u, v)``
segment of :attr:`BRepTopology.use_uv` (a unit-speed line for whole patch sides, which
OpenCascade checks faster, else a degree-1 B-spline); one clamped B-spline
3-D curve per edge and one B-spline surface per patch; all shapes with the same
tolerance. Shapes are numbered in writing order and referenced back from the end
(the last shape written, the solid, is number 1).
"""
from functools import lru_cache

import numpy as np

HEADER = "CASCADE Topology V1, (c) Matra-Datavision"
VERTEX_FLAGS, EDGE_FLAGS, WIRE_FLAGS = "0101101", "0101000", "0101100"
FACE_FLAGS, SHELL_FLAGS, SOLID_FLAGS = "0111000", "0101100", "1100000"


def _numbers(values):
    """Space-separated 17-significant-digit (round-trip exact) form of a float array."""
    flat = np.asarray(values, dtype=np.float64).reshape(-1).tolist()
    return ("%.17g " * len(flat)) % tuple(flat)


def _knot_lines(knots, mults):
    """``knot mult`` lines of a knot vector (formatted once per distinct vector)."""
    return _knot_text(np.asarray(knots, dtype=np.float64).tobytes(),
                      np.asarray(mults, dtype=np.int64).tobytes())


@lru_cache(maxsize=256)
def _knot_text(knot_bytes, mult_bytes):
    knots = np.frombuffer(knot_bytes, dtype=np.float64).tolist()
    mults = np.frombuffer(mult_bytes, dtype=np.int64).tolist()
    return "\n".join(f"{k:.17g} {m}" for k, m in zip(knots, mults))


def _pcurve(uv):
    """A use's parameter line: a unit-speed Geom2d line when the segment has length 1,
    else a degree-1 B-spline between its ends (both on parameter 0..1)."""
    start, end = uv
    direction = end - start
    if abs(float(np.hypot(*direction)) - 1.0) == 0.0:
        return f"1 {_numbers(start)}{_numbers(direction)}"
    return f"7 0 0 1 2 2 {_numbers(uv)}\n0 2\n1 2"


def _curve_3d(curve):
    head = f"7 0 0 {int(curve.degree)} {len(curve.poles)} {len(curve.knots)} "
    return head + _numbers(curve.poles) + "\n" + _knot_lines(curve.knots, curve.mults)


def _surface(patch):
    poles = np.asarray(patch.poles)
    head = (f"9 0 0 0 0 {int(patch.degree_u)} {int(patch.degree_v)} {poles.shape[0]} "
            f"{poles.shape[1]} {len(patch.u_knots)} {len(patch.v_knots)} ")
    return (head + _numbers(poles) + "\n" + _knot_lines(patch.u_knots, patch.u_mults) + "\n"
            + _knot_lines(patch.v_knots, patch.v_mults))


def brep_text(patches, topology, tolerance, reverse=False):
    """OpenCascade BREP text of one solid bounded by ``patches``.

    Parameters
    ----------
    patches : list of core.types.BSplinePatch, face ``i`` of the topology.
    topology : core.export.brep_topology.BRepTopology, checked
        (:func:`core.export.brep_topology.check_topology`).
    tolerance : float, tolerance of every vertex, edge and face (model units).
    reverse : bool, write every face reversed in the shell (for patches whose
        ``d/du x d/dv`` points into the solid).

    Returns
    -------
    str
    """
    t = topology
    n_vertices, n_edges, n_faces = len(t.vertices), len(t.edge_curves), len(patches)
    n_shapes = n_vertices + n_edges + 2 * n_faces + 2
    tol = f"{float(tolerance):.17g}"
    vertex_ref = n_shapes - np.arange(n_vertices)
    edge_ref = n_shapes - n_vertices - np.arange(n_edges)
    wire_ref = n_shapes - n_vertices - n_edges - 2 * np.arange(n_faces)
    face_ref = wire_ref - 1

    out = ["", HEADER, "Locations 0", f"Curve2ds {len(t.use_edge)}"]
    out += [_pcurve(uv) for uv in t.use_uv]
    out.append(f"Curves {n_edges}")
    out += [_curve_3d(curve) for curve in t.edge_curves]
    out += ["Polygon3D 0", "PolygonOnTriangulations 0", f"Surfaces {n_faces}"]
    out += [_surface(patch) for patch in patches]
    out += ["Triangulations 0", "", f"TShapes {n_shapes}"]
    for point in t.vertices:
        out += ["Ve", tol, _numbers(point), "0 0", "", VERTEX_FLAGS, "*"]
    uses_of_edge = np.argsort(t.use_edge, kind="stable").reshape(n_edges, 2)
    for e in range(n_edges):
        start, end = t.edge_vertices[e]
        out += ["Ed", f" {tol} 1 1 0", f"1  {e + 1} 0 0 1"]
        out += [f"2  {u + 1} {t.use_face[u] + 1} 0 0 1" for u in uses_of_edge[e].tolist()]
        out += ["0", "", EDGE_FLAGS, f"+{vertex_ref[start]} 0 -{vertex_ref[end]} 0 *"]
    offsets = t.loop_offsets()
    sign = np.where(t.use_reversed, "-", "+")
    for f in range(n_faces):
        uses = range(offsets[f], offsets[f + 1])
        loop = " ".join(f"{sign[u]}{edge_ref[t.use_edge[u]]} 0" for u in uses)
        out += ["Wi", "", WIRE_FLAGS, loop + " *"]
        out += ["Fa", f"0  {tol} {f + 1} 0", "", FACE_FLAGS, f"+{wire_ref[f]} 0 *"]
    face_sign = "-" if reverse else "+"
    out += ["Sh", "", SHELL_FLAGS, " ".join(f"{face_sign}{r} 0" for r in face_ref.tolist()) + " *"]
    out += ["So", "", SOLID_FLAGS, "+2 0 *", "", "+1 0 ", ""]
    return "\n".join(out)
