# SPDX-License-Identifier: LGPL-2.1-or-later
"""B-spline patches -> FreeCAD B-rep solid, built from shared edges.

The solid is assembled topologically: every B-rep vertex and edge is made once and
used by both faces that meet there (``core.export.brep_topology``), written as
OpenCascade BREP text (``core.export.occ_brep``) and read with
``Part.Shape.importBrepFromString``, which rebuilds exactly that topology. Nothing is
sewn and no curve is projected, so this is fast and the result does not depend on a
sewing tolerance. OpenCascade's validity check (``isValid``) still judges the result.

Only when that path fails (a PatchSet whose sides do not pair up, or a solid the
check rejects) are the faces sewn the old way (``Part.Shell`` merges coincident
boundaries; FreeCAD 0.20.2 cannot sew with a chosen tolerance), and the figures say
``construction: "sewn"`` with the reason. When the shell does not close either way,
the patches' boundary pole rows are matched in numpy to name the patches whose sides
have no identical partner and the size of the gap to the nearest candidate.
"""
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

import FreeCAD
import Part

from core.errors import ExportError
from core.export.brep_topology import check_topology, topology_from_sides
from core.export.bspline_tessellation import enclosed_volume
from core.export.occ_brep import brep_text
from core.tolerances import BREP_MM
from core.progress import NO_PROGRESS
from polycube_wb.convert import shape_to_arrays

_MAX_DEGREE = 25  # OpenCascade's Geom_BSplineSurface::MaxDegree()
_SIDE_NAMES = ("u=min", "u=max", "v=min", "v=max")
_MAX_EXAMPLES = 5


def patches_to_solid(patchset, progress=NO_PROGRESS):
    """Build a closed, valid, outward-oriented ``Part.Solid`` from a PatchSet.

    Same as ``build_solid(patchset, progress)[0]``; see :func:`build_solid`.
    """
    return build_solid(patchset, progress)[0]


@dataclass
class BuiltSolid:
    """A solid and what it was built from.

    solid : Part.Solid; figures : dict (see :func:`build_solid`);
    topology : core.export.brep_topology.BRepTopology of the shared edges, or None when
        the faces had to be sewn; reverse : bool, faces are reversed against the patches'
        ``d/du x d/dv``.
    """

    solid: object
    figures: dict
    topology: object
    reverse: bool


def build_solid(patchset, progress=NO_PROGRESS):
    """Build a closed, valid, outward-oriented ``Part.Solid`` and the figures checked on it.

    Same as ``make_solid(patchset, progress)`` without the topology; see :func:`make_solid`.
    """
    built = make_solid(patchset, progress)
    return built.solid, built.figures


def make_solid(patchset, progress=NO_PROGRESS):
    """Build a closed, valid, outward-oriented ``Part.Solid`` and the figures checked on it.

    Parameters
    ----------
    patchset : core.types.PatchSet
        ``patches`` is a list of BSplinePatch (poles (nu, nv, 3) float64, OpenCascade-style
        distinct knots + multiplicities); ``topology`` gives the shared edges, or None
        when neighbouring patches share whole sides with bit-identical poles.
        ``d/du x d/dv`` should point outward (every face is reversed if the enclosed
        volume comes out negative).
    progress : core.progress.Progress
        Receives ``report("brep", fraction)``; ``check_cancel()`` is called between steps.

    Returns
    -------
    BuiltSolid
        ``solid``: one B-rep face per patch, one closed shell, ``isValid()`` true,
        volume > 0; ``topology`` (None if sewn) and ``reverse`` for the STEP writer;
        ``figures``: dict
        ``faces``, ``edges``, ``shells``, ``valid``, ``closed``, ``volume`` (model units
        cubed, by exact quadrature of the patches), ``construction`` (``"shared_edges"``
        or ``"sewn"``) and ``construction_note`` (why sewing was needed, else "").

    Raises
    ------
    ExportError
        A patch is malformed (the message names the patch and the field), the faces
        do not form one closed shell (the message gives the number of free edges and
        examples of patch sides without a partner, with the gap size), or OpenCascade
        reports the solid invalid.
    """
    patches = list(patchset.patches)
    if not patches:
        raise ExportError("cannot build a solid: the PatchSet has no patches")
    checked_layouts = set()
    for index, patch in enumerate(patches):
        _check_patch(index, patch, checked_layouts)
    progress.report("brep", 0.1, "building the shell from shared edges")
    progress.check_cancel()
    volume = enclosed_volume(patches)
    reverse = bool(volume < 0)
    topology = patchset.topology
    try:
        if topology is None:
            topology = topology_from_sides(patches)
        solid = _shared_edge_solid(patches, topology, reverse)
        construction, note = "shared_edges", ""
    except ExportError as exc:
        progress.report("brep", 0.4, "sewing faces into a shell")
        progress.check_cancel()
        solid = _sewn_solid(patches, str(exc))
        construction, note, topology = "sewn", f"shared-edge construction failed: {exc}", None
    volume = abs(volume)
    progress.report("brep", 0.8, "checking the solid")
    progress.check_cancel()
    if len(solid.Faces) != len(patches):
        raise ExportError(f"the solid has {len(solid.Faces)} B-rep faces for {len(patches)} "
                          "patches; expected one face per patch")
    if len(solid.Shells) != 1 or not solid.Shells[0].isClosed():
        raise ExportError(f"the solid has {len(solid.Shells)} shells; expected one closed shell")
    if not volume > 0:
        raise ExportError(f"the solid encloses no volume ({volume:.6g})")
    if construction == "sewn" and not solid.isValid():
        raise ExportError("OpenCascade reports the solid as invalid (BRepCheck_Analyzer); "
                          f"{len(patches)} patches, volume {volume:.6g}")
    progress.report("brep", 1.0)
    figures = {"faces": len(solid.Faces), "edges": len(solid.Edges), "shells": len(solid.Shells),
               "valid": True, "closed": True, "volume": float(volume),
               "construction": construction, "construction_note": note}
    return BuiltSolid(solid, figures, topology, reverse)


def _shared_edge_solid(patches, topology, reverse):
    """The solid read from BREP text of the shared-edge topology; ExportError if invalid."""
    check_topology(topology, patches, BREP_MM)
    shape = Part.Shape()
    try:
        shape.importBrepFromString(brep_text(patches, topology, BREP_MM, reverse), False)
    except (Part.OCCError, RuntimeError) as exc:
        raise ExportError(f"OpenCascade could not read the shared-edge B-rep ({exc})") from exc
    if shape.isNull() or shape.ShapeType != "Solid":
        raise ExportError("the shared-edge B-rep did not give a solid")
    if not shape.isValid():
        raise ExportError("OpenCascade reports the shared-edge solid as invalid (BRepCheck_Analyzer)")
    return shape


def _sewn_solid(patches, why):
    """Faces sewn by ``Part.Shell`` into a solid, outward; ExportError if it does not close."""
    faces = [Part.Face(_surface(patch)) for patch in patches]
    try:
        shell = Part.Shell(faces)
    except Part.OCCError as exc:
        raise ExportError(_open_shell_message(patches, None, f"Part.Shell failed ({exc})")
                          + f" (shared-edge construction: {why})") from exc
    if not shell.isClosed():
        raise ExportError(_open_shell_message(patches, _free_edge_count(shell),
                                              "the shell is not closed")
                          + f" (shared-edge construction: {why})")
    solid = Part.Solid(shell)
    if solid.Volume < 0:
        solid.reverse()
    return solid


def solid_report(solid):
    """Plain-Python figures about a solid (JSON-serialisable).

    Returns
    -------
    dict
        ``faces`` (int), ``edges`` (int), ``shells`` (int), ``valid`` (bool, from
        ``isValid()``), ``closed`` (bool, every shell closed), ``volume`` and ``area``
        (float, model units cubed / squared).
    """
    shells = solid.Shells
    return {
        "faces": len(solid.Faces),
        "edges": len(solid.Edges),
        "shells": len(shells),
        "valid": bool(solid.isValid()),
        "closed": bool(shells) and all(shell.isClosed() for shell in shells),
        "volume": float(solid.Volume),
        "area": float(solid.Area),
    }


def tessellate(solid, tolerance, angular_deflection=0.5):
    """Triangulate a solid's faces (see ``polycube_wb.convert.shape_to_arrays``).

    Parameters
    ----------
    solid : Part.Shape
    tolerance : float
        Maximum linear deviation of the triangles from the surface, model units.
    angular_deflection : float
        Maximum angle between neighbouring triangles' normals along a face, radians.

    Returns
    -------
    V : (n, 3) float64
        Vertices, shared between faces along B-rep edges.
    F : (m, 3) int64
        Triangles, counter-clockwise seen from outside for an outward solid.
    """
    return shape_to_arrays(solid, tolerance, angular_deflection)


def _surface(patch):
    """``Part.BSplineSurface`` of one (already checked) patch."""
    surface = Part.BSplineSurface()
    poles = [[FreeCAD.Vector(*p) for p in row] for row in np.asarray(patch.poles).tolist()]
    surface.buildFromPolesMultsKnots(
        poles,
        [int(m) for m in patch.u_mults], [int(m) for m in patch.v_mults],
        [float(k) for k in patch.u_knots], [float(k) for k in patch.v_knots],
        False, False, int(patch.degree_u), int(patch.degree_v))
    return surface


def _check_patch(index, patch, checked_layouts):
    """Raise ExportError naming the patch if its arrays cannot define a B-spline surface.

    ``checked_layouts`` (set) collects the knot layouts already found valid, so patches
    sharing one are not checked again.
    """
    poles = np.asarray(patch.poles)
    if poles.ndim != 3 or poles.shape[2] != 3 or poles.shape[0] < 2 or poles.shape[1] < 2:
        raise ExportError(f"patch {index}: poles must have shape (nu, nv, 3) with nu, nv >= 2, "
                          f"got {poles.shape}")
    if not np.issubdtype(poles.dtype, np.number) or not np.all(np.isfinite(poles)):
        bad = int(np.count_nonzero(~np.isfinite(poles.astype(np.float64)).all(axis=2)))
        raise ExportError(f"patch {index}: {bad} poles are not finite")
    directions = (("u", poles.shape[0], np.asarray(patch.u_knots), np.asarray(patch.u_mults),
                   patch.degree_u),
                  ("v", poles.shape[1], np.asarray(patch.v_knots), np.asarray(patch.v_mults),
                   patch.degree_v))
    layout = tuple((count, knots.dtype.str, knots.shape, knots.tobytes(), mults.dtype.str,
                    mults.shape, mults.tobytes(), degree)
                   for _, count, knots, mults, degree in directions)
    if layout in checked_layouts:
        return
    for direction, count, knots, mults, degree in directions:
        _check_direction(index, direction, count, knots, mults, degree)
    checked_layouts.add(layout)


def _check_direction(index, direction, count, knots, mults, degree):
    """Validate the knots, multiplicities and degree of one parameter direction."""
    where = f"patch {index}, {direction} direction"
    if int(degree) != degree or not 1 <= degree <= _MAX_DEGREE:
        raise ExportError(f"{where}: degree must be an integer in 1..{_MAX_DEGREE}, got {degree}")
    degree = int(degree)
    if knots.ndim != 1 or mults.shape != knots.shape or len(knots) < 2:
        raise ExportError(f"{where}: knots and mults must be 1-D of equal length >= 2, got "
                          f"shapes {knots.shape} and {mults.shape}")
    if not np.all(np.isfinite(knots)) or not np.all(np.diff(knots) > 0):
        raise ExportError(f"{where}: knots must be finite and strictly increasing, got "
                          f"{knots.tolist()}")
    if np.any(mults != np.round(mults)) or np.any(mults < 1) or np.any(mults > degree + 1) \
            or np.any(mults[1:-1] > degree):
        raise ExportError(f"{where}: multiplicities must be integers in 1..{degree + 1} "
                          f"(interior 1..{degree}), got {mults.tolist()}")
    if int(mults.sum()) != count + degree + 1:
        raise ExportError(f"{where}: sum of multiplicities {int(mults.sum())} must equal "
                          f"number of poles + degree + 1 = {count + degree + 1}")
    if mults[0] != degree + 1 or mults[-1] != degree + 1:
        raise ExportError(f"{where}: end multiplicities must be degree + 1 = {degree + 1} "
                          f"(clamped), got {mults[0]} and {mults[-1]}")


def _free_edge_count(shell):
    """Number of non-degenerate edges of ``shell`` bounding only one face."""
    buckets = {}
    for face in shell.Faces:
        for edge in face.Edges:
            if edge.Degenerated:
                continue
            bucket = buckets.setdefault(edge.hashCode(), [])
            for entry in bucket:
                if entry[0].isSame(edge):
                    entry[1] += 1
                    break
            else:
                bucket.append([edge, 1])
    return sum(1 for bucket in buckets.values() for _, uses in bucket if uses == 1)


def _open_shell_message(patches, free_edges, what):
    """Explain an open shell from the patches' boundary pole rows."""
    matching = _side_matching(patches)
    parts = [f"cannot build a closed solid from {len(patches)} patches: {what}"]
    if free_edges is not None:
        parts.append(f"{free_edges} free (open) B-rep edges")
    parts.append(f"{matching['unmatched']} patch sides have no partner side with bit-identical "
                 "poles")
    if matching["examples"]:
        texts = []
        for patch, side, other, other_side, gap in matching["examples"]:
            text = f"patch {patch} side {_SIDE_NAMES[side]}"
            if other is not None:
                text += (f" (nearest: patch {other} side {_SIDE_NAMES[other_side]}, "
                         f"max pole distance {gap:.3g})")
            texts.append(text)
        parts.append("e.g. " + "; ".join(texts))
    if matching["overmatched"]:
        parts.append(f"{matching['overmatched']} boundary curves are shared by more than two "
                     "patch sides (non-manifold)")
    if matching["components"] > 1:
        parts.append(f"the patches form {matching['components']} separate pieces")
    parts.append("neighbouring patches must share bit-identical boundary poles "
                 "(FreeCAD 0.20 cannot sew gaps)")
    return "; ".join(parts)


def _side_poles(patch):
    """The four boundary pole rows of a patch, order of ``_SIDE_NAMES``."""
    poles = np.asarray(patch.poles, dtype=np.float64)
    return (poles[0, :], poles[-1, :], poles[:, 0], poles[:, -1])


def _side_matching(patches):
    """Match patch sides by bit-identical boundary poles (in either direction).

    Returns
    -------
    dict
        ``unmatched`` (int): sides whose pole row equals no other side's row;
        ``examples``: the first few as (patch, side, nearest_patch, nearest_side,
        max_pole_distance), nearest among other patches' sides with as many poles
        (None and NaN when there is none); ``overmatched`` (int): rows shared by more
        than two sides; ``components`` (int): connected pieces of patches joined
        through matched sides.
    """
    sides = [(p, s, row) for p, patch in enumerate(patches)
             for s, row in enumerate(_side_poles(patch))]
    groups = {}
    for index, (_, _, row) in enumerate(sides):
        key = (len(row), min(row.tobytes(), row[::-1].tobytes()))
        groups.setdefault(key, []).append(index)
    lonely = [members[0] for members in groups.values() if len(members) == 1]
    lonely.sort()
    pairs = np.array([(sides[members[0]][0], sides[other][0])
                      for members in groups.values() for other in members[1:]],
                     dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(patches), len(patches)))
    components = connected_components(graph, directed=False)[0]
    examples = []
    for i in lonely[:_MAX_EXAMPLES]:
        patch, side, row = sides[i]
        others = [j for j, (p, _, r) in enumerate(sides) if p != patch and len(r) == len(row)]
        if not others:
            examples.append((patch, side, None, None, float("nan")))
            continue
        rows = np.stack([sides[j][2] for j in others])
        gaps = np.minimum(np.linalg.norm(rows - row, axis=2).max(axis=1),
                          np.linalg.norm(rows - row[::-1], axis=2).max(axis=1))
        best = others[int(np.argmin(gaps))]
        examples.append((patch, side, sides[best][0], sides[best][1], float(gaps.min())))
    return {
        "unmatched": len(lonely),
        "examples": examples,
        "overmatched": sum(1 for members in groups.values() if len(members) > 2),
        "components": int(components),
    }
