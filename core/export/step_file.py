# SPDX-License-Identifier: LGPL-2.1-or-later
"""A closed patch set and its shared-edge topology as an AP214 STEP file.

ISO 10303-21 text in the AUTOMOTIVE_DESIGN schema (AP214): one product (named by the
caller) whose shape is an ADVANCED_BREP_SHAPE_REPRESENTATION holding one
MANIFOLD_SOLID_BREP; lengths in millimetres, distance uncertainty = the B-rep
tolerance. Each B-rep vertex and edge is one entity (VERTEX_POINT, EDGE_CURVE with a
B_SPLINE_CURVE_WITH_KNOTS) referenced by both faces; each face is an ADVANCED_FACE on
a B_SPLINE_SURFACE_WITH_KNOTS bounded by one EDGE_LOOP. Each edge's geometry is a
SURFACE_CURVE: its 3-D B-spline and, on each of its two faces, its parameter curve (PCURVE),
the straight segment in ``(u, v)`` that the topology gives, as a degree-1 B-spline with the
3-D curve's parameter. A reader that finds no parameter curves projects the 3-D curves onto
the surfaces (OpenCascade's ``ShapeFix_Edge::FixAddPCurve``), which costs more than reading
the whole file; the segments are shared by every use with the same end points.

A *light* file (``step_text(..., light=True)``, the G1 export) writes the points with fewer
decimals wherever that cannot open a gap, move the surface by more than a small fraction of
the model's size or turn a normal along a boundary by more than a small angle
(:func:`light_point_decimals`). Short point literals are most of the text a reader parses;
the rest of its work is per face and edge (building the shape, checking wires, edges and the
solid's orientation), the same in either form.
"""
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

SCHEMA = "AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }"
POINT_DECIMALS = 8
"""Decimals of the points' coordinates (millimetres; parameters in ``(u, v)``): a rounding of
at most 5e-9 mm, a twentieth of the B-rep tolerance :data:`core.tolerances.BREP_MM` (an edge
curve whose poles are not the face's own stays within the tolerance of it), and the points
that vertices, curves and surfaces share are one entity each, so the rounding opens no gap;
short literals are most of what a reader parses (lines are written ``#n=ENTITY(...)``, without
optional spaces, for the same reason)."""
LIGHT_POINT_STEP = 1e-6
"""Largest rounding step of a light file's points (:func:`light_point_decimals`), as a
fraction of the poles' bounding-box diagonal: a displacement far below the G1 export's own
departure from the limit surface."""
LIGHT_NORMAL_TURN = 1e-3
"""Largest turn (radians) of a face's normal along its boundary that the rounding of a light
file's points may cause (:func:`light_point_decimals`): the normal there is the cross
product of the boundary's tangent and a weighted mean of the differences between the boundary
row and the pole row next to it, so moving both rows by at most half the rounding step in each
coordinate turns it by about ``sqrt(3)`` times the step over the length of those differences
at most; the normals of the two faces at an edge turn independently, so the rounding keeps
their jump within about twice this (a 0.1-degree bound for a G1 export held to 1 degree)."""


def step_reals(values):
    """STEP REAL literals of a float array: the shortest text that reads back to the same
    float (round-trip exact, Python's ``repr``), always with a decimal point and an upper-case
    exponent (``0.125``, ``1.0``, ``1.E-07``). Returns a list of str."""
    return [step_real(v) for v in np.asarray(values, dtype=np.float64).reshape(-1).tolist()]


def step_fixed_reals(values, decimals=POINT_DECIMALS):
    """STEP REAL literals of a float array rounded to ``decimals`` decimals, without trailing
    zeros (``-1.25``, ``3.``, ``0.``). Returns a list of str."""
    flat = np.round(np.asarray(values, dtype=np.float64).reshape(-1), decimals) + 0.0
    # a decimal point in every literal: the zeros stripped are decimals only ("30." not "3")
    form = f"%.{decimals}f," if decimals > 0 else "%.0f.,"
    text = ((form * len(flat)) % tuple(flat.tolist())).split(",")[:-1]
    return [t.rstrip("0") for t in text]


def step_real(value):
    """STEP REAL literal of one float (see :func:`step_reals`)."""
    mantissa, exponent, power = repr(float(value)).partition("e")
    if "." not in mantissa:
        mantissa += "."
    return mantissa + ("E" + power if exponent else "")


def step_string(text):
    """STEP string literal: printable ASCII, quotes doubled, backslashes dropped."""
    clean = "".join(ch if 32 <= ord(ch) < 127 and ch != "\\" else "_" for ch in str(text))
    return "'" + clean.replace("'", "''") + "'"


_POINT_KEY = np.dtype((np.void, 24))


def _point_keys(xyz):
    """(n,) keys of the rows of ``xyz`` (n, 3) float64, equal iff the points are equal bit for
    bit (``-0.0`` taken as ``0.0``)."""
    return np.ascontiguousarray(np.asarray(xyz, dtype=np.float64) + 0.0).view(
        _POINT_KEY).reshape(-1)


@dataclass
class PointDecimals:
    """Decimals of a light file's points (:func:`light_point_decimals`).

    keys : (k,) sorted keys of points (:func:`_point_keys`); places : (k,) int64 decimals of
    each; points not listed take :data:`POINT_DECIMALS`.
    """

    keys: np.ndarray
    places: np.ndarray

    def of(self, xyz):
        """(n,) int64 decimals of the rows of ``xyz`` (n, 3)."""
        keys = _point_keys(xyz)
        at = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        return np.where(self.keys[at] == keys, self.places[at], POINT_DECIMALS)


class _Entities:
    """Numbered DATA section lines."""

    def __init__(self, decimals=None):
        self.lines = []
        self.point_ids = {}
        self.decimals = decimals

    def add(self, text):
        self.lines.append(text)
        return len(self.lines)

    def points(self, xyz):
        """The CARTESIAN_POINT ids of the rows of ``xyz`` (n, d), d = 3 (model space) or 2
        (parameter space): one entity per distinct point, shared by every vertex, curve and
        surface that has a pole there (the poles along a shared patch side are equal bit for
        bit), so each is written and read once. Model-space points take the decimals of
        ``decimals`` (a :class:`PointDecimals`, or None: :data:`POINT_DECIMALS`).
        """
        xyz = np.asarray(xyz, dtype=np.float64) + 0.0  # no -0.0
        d = xyz.shape[1]
        reals = np.array(step_fixed_reals(xyz), dtype=object).reshape(-1, d)
        if d == 3 and self.decimals is not None:
            places = self.decimals.of(xyz)
            for decimals in np.unique(places[places < POINT_DECIMALS]).tolist():
                rows = np.flatnonzero(places == decimals)
                reals[rows] = np.array(step_fixed_reals(xyz[rows], decimals),
                                       dtype=object).reshape(-1, d)
        # every line in one formatting pass over the flat literals (a list per row costs more)
        line = "CARTESIAN_POINT('',(" + ",".join(["%s"] * d) + "))\n"
        ids = []
        for text in ((line * len(reals)) % tuple(reals.reshape(-1).tolist())).split("\n")[:-1]:
            known = self.point_ids.get(text)
            if known is None:
                known = self.point_ids[text] = self.add(text)
            ids.append(known)
        return ids


def _boundary_row(poles, uv):
    """The pole row (n, 3) of the patch side that the ``(u, v)`` segment ``uv`` (2, 2) lies on
    (patches are parametrised on the unit square), from ``u`` or ``v`` = 0 to 1."""
    (u0, v0), (u1, v1) = np.asarray(uv, dtype=np.float64)
    if v0 == v1:
        return poles[:, 0] if v0 == 0.0 else poles[:, -1]
    return poles[0, :] if u0 == 0.0 else poles[-1, :]


def _exact_points(patches, topology):
    """(k, 3) points that a light file keeps at :data:`POINT_DECIMALS`: the vertices (not
    always a pole of the curves they end), the poles of every edge curve that is not, pole for
    pole, the boundary row of a face it bounds (a knot-inserted form of it, or a part of a
    longer side), and that boundary row. Elsewhere a curve and its faces share their point
    entities, so rounding them moves them together; these only agree within
    :data:`POINT_DECIMALS`."""
    t = topology
    curves = [np.asarray(t.edge_curves[e].poles, dtype=np.float64) for e in t.use_edge.tolist()]
    rows = [_boundary_row(np.asarray(patches[f].poles, dtype=np.float64), uv)
            for f, uv in zip(t.use_face.tolist(), t.use_uv)]
    lengths = np.array([(len(c), len(r)) for c, r in zip(curves, rows)])
    exact = [np.asarray(t.vertices, dtype=np.float64)]
    for n_curve, n_row in np.unique(lengths, axis=0).tolist():
        which = np.flatnonzero((lengths == (n_curve, n_row)).all(axis=1))
        C = np.stack([curves[i] for i in which])
        R = np.stack([rows[i] for i in which])
        if n_curve == n_row:
            same = (C == R).all(axis=(1, 2)) | (C == R[:, ::-1]).all(axis=(1, 2))
            C, R = C[~same], R[~same]
        exact += [C.reshape(-1, 3), R.reshape(-1, 3)]
    return np.concatenate(exact)


def _across_distances(poles):
    """(p,) shortest distance, per patch of ``poles`` (a list of (n_u, n_v, 3) grids), between
    a boundary pole and the pole next to it across that boundary."""
    across = np.empty(len(poles))
    shapes = np.array([P.shape[:2] for P in poles])
    for shape in np.unique(shapes, axis=0):
        which = np.flatnonzero((shapes == shape).all(axis=1))
        G = np.stack([poles[i] for i in which])
        steps = (G[:, 1] - G[:, 0], G[:, -2] - G[:, -1], G[:, :, 1] - G[:, :, 0],
                 G[:, :, -2] - G[:, :, -1])
        across[which] = np.min([np.linalg.norm(d, axis=-1).min(axis=-1) for d in steps], axis=0)
    return across


def light_point_decimals(patches, topology):
    """The decimals of every point of a light file (:class:`PointDecimals`).

    A patch's poles take the fewest decimals whose rounding step is at most
    :data:`LIGHT_POINT_STEP` of the poles' bounding-box diagonal and at most
    :data:`LIGHT_NORMAL_TURN` times the patch's shortest distance between a boundary pole and
    the pole next to it across that boundary over ``sqrt(3)`` (at most
    :data:`POINT_DECIMALS`); a pole shared by several patches takes the most of theirs, so
    each patch's normals keep their bound. The points of :func:`_exact_points` keep
    :data:`POINT_DECIMALS`.
    """
    poles = [np.asarray(p.poles, dtype=np.float64) for p in patches]
    every = np.concatenate([P.reshape(-1, 3) for P in poles])
    diagonal = float(np.linalg.norm(np.ptp(every, axis=0)))
    step = np.minimum(LIGHT_POINT_STEP * diagonal,
                      LIGHT_NORMAL_TURN * _across_distances(poles) / np.sqrt(3.0))
    with np.errstate(divide="ignore"):
        places = np.clip(np.ceil(-np.log10(step)), 0, POINT_DECIMALS).astype(np.int64)
    exact = _exact_points(patches, topology)
    wanted = np.concatenate([np.repeat(places, [P.shape[0] * P.shape[1] for P in poles]),
                             np.full(len(exact), POINT_DECIMALS)])
    keys, inverse = np.unique(np.concatenate([_point_keys(every), _point_keys(exact)]),
                              return_inverse=True)
    most = np.zeros(len(keys), dtype=np.int64)
    np.maximum.at(most, inverse.reshape(-1), wanted)
    return PointDecimals(keys, most)


def _outermost_first(face_ids, patches):
    """``face_ids`` with the face that reaches farthest along +x first (the rest in order).

    OpenCascade's STEP reader orients a closed shell by classifying a point at infinity
    (``ShapeFix_Solid``, ``BRepClass3d_SolidClassifier::PerformInfinitePoint``) along a ray
    from a point of the shell's first usable face. From a face next to a crease vertex, where
    the limit surface has no tangent plane (``docs/DESIGN.md``), that ray can give the wrong
    side, and an outward solid reads back with a negative volume. From an outermost face the
    ray leaves the solid through that face alone, so the shell reads back outward. Face order
    means nothing else in STEP.
    """
    reach = [float(np.asarray(patch.poles)[..., 0].max()) for patch in patches]
    first = int(np.argmax(reach))
    return [face_ids[first]] + face_ids[:first] + face_ids[first + 1:]


def _knot_args(knots, mults):
    """``(mults),(knots)`` arguments of a B-spline entity (formatted once per vector)."""
    return _knot_arg_text(np.asarray(knots, dtype=np.float64).tobytes(),
                          np.asarray(mults, dtype=np.int64).tobytes())


@lru_cache(maxsize=256)
def _knot_arg_text(knot_bytes, mult_bytes):
    knots = np.frombuffer(knot_bytes, dtype=np.float64)
    mults = np.frombuffer(mult_bytes, dtype=np.int64)
    return _ints(mults), _reals(knots)


def _refs(ids):
    return "(" + ",".join(f"#{i}" for i in ids) + ")"


def _ints(values):
    return "(" + ",".join(str(int(v)) for v in np.asarray(values).tolist()) + ")"


def _reals(values):
    return "(" + ",".join(step_reals(values)) + ")"


def _points_of(ent, arrays):
    """CARTESIAN_POINT ids (:meth:`_Entities.points`) of the poles of every array in
    ``arrays`` (each (..., 3)), formatted in one pass: a list of int64 arrays of the arrays'
    shapes without the last axis."""
    if not arrays:
        return []
    flat = np.concatenate([a.reshape(-1, 3) for a in arrays])
    ids = np.asarray(ent.points(flat), dtype=np.int64)
    ends = np.cumsum([a.size // 3 for a in arrays])[:-1]
    return [part.reshape(a.shape[:-1]) for part, a in zip(np.split(ids, ends), arrays)]


def _segment(ent, segments, uv, context_2d):
    """The DEFINITIONAL_REPRESENTATION of the ``(u, v)`` segment ``uv`` (2, 2) from its
    start to its end point, linear in the parameter on [0, 1] (a degree-1 B-spline), made
    once per distinct segment (``segments`` maps its end points to the entity id)."""
    key = tuple(np.asarray(uv, dtype=np.float64).reshape(-1).tolist())
    known = segments.get(key)
    if known is None:
        ends = ent.points(np.asarray(uv, dtype=np.float64).reshape(2, 2))
        line = ent.add(f"B_SPLINE_CURVE_WITH_KNOTS('',1,{_refs(ends)},.POLYLINE_FORM.,.F.,.F.,"
                       "(2,2),(0.,1.),.UNSPECIFIED.)")
        known = segments[key] = ent.add(f"DEFINITIONAL_REPRESENTATION('',(#{line}),#{context_2d})")
    return known


def step_text(patches, topology, name, tolerance, reverse=False, timestamp="1970-01-01T00:00:00",
              light=False):
    """AP214 STEP text of one solid bounded by ``patches``.

    Parameters
    ----------
    patches : list of core.types.BSplinePatch, face ``i`` of the topology; coordinates
        in millimetres.
    topology : core.export.brep_topology.BRepTopology, checked.
    name : str, the product name (also the file name in the header).
    tolerance : float, distance uncertainty written into the context (mm).
    reverse : bool, the patches' ``d/du x d/dv`` points into the solid.
    timestamp : str, ISO 8601 time for the header (fixed by default so equal inputs
        give byte-identical files).
    light : bool, write the points with the decimals of :func:`light_point_decimals` (the G1
        export, which departs from the limit surface far more than that rounding); else every
        point with :data:`POINT_DECIMALS`.

    Returns
    -------
    str
    """
    t = topology
    ent = _Entities(light_point_decimals(patches, t) if light else None)
    app = ent.add("APPLICATION_CONTEXT('core data for automotive mechanical design processes')")
    ent.add(f"APPLICATION_PROTOCOL_DEFINITION('international standard','automotive_design',2000,#{app})")
    product_context = ent.add(f"PRODUCT_CONTEXT('',#{app},'mechanical')")
    product = ent.add(f"PRODUCT({step_string(name)},{step_string(name)},'',(#{product_context}))")
    ent.add(f"PRODUCT_RELATED_PRODUCT_CATEGORY('part',$,(#{product}))")
    formation = ent.add(f"PRODUCT_DEFINITION_FORMATION('','',#{product})")
    definition_context = ent.add(f"PRODUCT_DEFINITION_CONTEXT('part definition',#{app},'design')")
    definition = ent.add(f"PRODUCT_DEFINITION('design','',#{formation},#{definition_context})")
    shape_def = ent.add(f"PRODUCT_DEFINITION_SHAPE('','',#{definition})")
    mm = ent.add("( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) )")
    rad = ent.add("( NAMED_UNIT(*) PLANE_ANGLE_UNIT() SI_UNIT($,.RADIAN.) )")
    sr = ent.add("( NAMED_UNIT(*) SI_UNIT($,.STERADIAN.) SOLID_ANGLE_UNIT() )")
    uncertainty = ent.add(f"UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE({step_real(tolerance)}),"
                          f"#{mm},'distance_accuracy_value','confusion accuracy')")
    context = ent.add(f"( GEOMETRIC_REPRESENTATION_CONTEXT(3) GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT("
                      f"(#{uncertainty})) GLOBAL_UNIT_ASSIGNED_CONTEXT((#{mm},#{rad},#{sr})) "
                      "REPRESENTATION_CONTEXT('Context #1','3D Context with UNIT and UNCERTAINTY') )")

    context_2d = ent.add("( GEOMETRIC_REPRESENTATION_CONTEXT(2) "
                         "PARAMETRIC_REPRESENTATION_CONTEXT() REPRESENTATION_CONTEXT('2D SPACE','') )")
    segments = {}
    surface_ids = []
    pole_ids = _points_of(ent, [np.asarray(patch.poles) for patch in patches])
    for patch, ids in zip(patches, pole_ids):
        grid = "(" + ",".join(_refs(row) for row in ids.tolist()) + ")"
        u_mults, u_knots = _knot_args(patch.u_knots, patch.u_mults)
        v_mults, v_knots = _knot_args(patch.v_knots, patch.v_mults)
        surface_ids.append(ent.add(f"B_SPLINE_SURFACE_WITH_KNOTS('',{int(patch.degree_u)},"
                                   f"{int(patch.degree_v)},{grid},.UNSPECIFIED.,.F.,.F.,.F.,"
                                   f"{u_mults},{v_mults},{u_knots},{v_knots},.UNSPECIFIED.)"))
    edge_pcurves = [[] for _ in t.edge_curves]
    for u in range(len(t.use_edge)):
        segment = _segment(ent, segments, t.use_uv[u], context_2d)
        edge_pcurves[t.use_edge[u]].append(
            ent.add(f"PCURVE('',#{surface_ids[t.use_face[u]]},#{segment})"))
    vertex_ids = [ent.add(f"VERTEX_POINT('',#{p})") for p in ent.points(t.vertices)]
    edge_ids = []
    curve_pole_ids = _points_of(ent, [np.asarray(curve.poles) for curve in t.edge_curves])
    for e, curve in enumerate(t.edge_curves):
        poles = curve_pole_ids[e].tolist()
        mults, knots = _knot_args(curve.knots, curve.mults)
        bspline = ent.add(f"B_SPLINE_CURVE_WITH_KNOTS('',{int(curve.degree)},{_refs(poles)},"
                          f".UNSPECIFIED.,.F.,.F.,{mults},{knots},.UNSPECIFIED.)")
        on_surfaces = ent.add(f"SURFACE_CURVE('',#{bspline},{_refs(edge_pcurves[e])},.CURVE_3D.)")
        start, end = t.edge_vertices[e]
        edge_ids.append(ent.add(f"EDGE_CURVE('',#{vertex_ids[start]},#{vertex_ids[end]},"
                                f"#{on_surfaces},.T.)"))
    offsets = t.loop_offsets()
    sense = ".F." if reverse else ".T."
    face_ids = []
    for f, surface in enumerate(surface_ids):
        oriented = [ent.add(f"ORIENTED_EDGE('',*,*,#{edge_ids[t.use_edge[u]]},"
                            f"{'.F.' if t.use_reversed[u] else '.T.'})")
                    for u in range(offsets[f], offsets[f + 1])]
        loop = ent.add(f"EDGE_LOOP('',{_refs(oriented)})")
        bound = ent.add(f"FACE_OUTER_BOUND('',#{loop},{sense})")
        face_ids.append(ent.add(f"ADVANCED_FACE('',(#{bound}),#{surface},{sense})"))
    shell = ent.add(f"CLOSED_SHELL('',{_refs(_outermost_first(face_ids, patches))})")
    solid = ent.add(f"MANIFOLD_SOLID_BREP({step_string(name)},#{shell})")
    origin = ent.points(np.zeros((1, 3)))[0]
    z_axis = ent.add("DIRECTION('',(0.,0.,1.))")
    x_axis = ent.add("DIRECTION('',(1.,0.,0.))")
    placement = ent.add(f"AXIS2_PLACEMENT_3D('',#{origin},#{z_axis},#{x_axis})")
    representation = ent.add(f"ADVANCED_BREP_SHAPE_REPRESENTATION({step_string(name)},"
                             f"(#{placement},#{solid}),#{context})")
    ent.add(f"SHAPE_DEFINITION_REPRESENTATION(#{shape_def},#{representation})")
    header = ["ISO-10303-21;", "HEADER;",
              "FILE_DESCRIPTION(('B-spline solid of a Catmull-Clark limit surface'),'2;1');",
              f"FILE_NAME({step_string(name)},{step_string(timestamp)},(''),(''),"
              "'polycube_wb','polycube_wb','');",
              f"FILE_SCHEMA(('{SCHEMA}'));", "ENDSEC;", "DATA;"]
    body = [f"#{i}={line};" for i, line in enumerate(ent.lines, start=1)]
    return "\n".join(header + body + ["ENDSEC;", "END-ISO-10303-21;", ""])
