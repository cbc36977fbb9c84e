# SPDX-License-Identifier: LGPL-2.1-or-later
"""Pipeline parameters: the one place for their names, types, defaults, help and valid values.

``ReconstructionParams`` declares every user-settable parameter as a dataclass field whose
``metadata["option"]`` (an :class:`Option`) holds its help line, its range or choices and its
command-line flag; the range checks, ``polycube_wb.cli``'s options and their ``--help`` are
built from these fields (:func:`parameter_options`).
"""
from dataclasses import asdict, dataclass, field, fields
from numbers import Integral

from core.errors import ParameterError

PART_MODES = ("single", "auto", "file")
COMPONENT_POLICIES = ("largest", "all", "error")
FIT_MODES = ("inside", "best-fit", "none")
"""The modes of ``core.fitting.fit_base_mesh`` (checked here so a bad mode is reported before
any stage runs)."""
BASE_MESH_METHODS = ("auto", "polycube", "decimation")
"""The base-mesh routes of ``core.quadmesh.build_base_mesh``: the polycube layout with the
paired decimation as fallback (``auto``), either one alone."""
UNIT_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
EXPORT_DEPTH = 8
"""Grading depth of the B-spline patches at extraordinary vertices (``core.export.bspline``):
a patch is exact except in a corner cell of size 2^-depth."""
EXPORT_FORMS = ("exact", "g1")
"""The surface forms of ``subd-to-step``: ``exact``, the graded patches of
``core.export.bspline`` (the Catmull-Clark limit except in corner cells of size 2^-depth);
``g1``, the light tangent-continuous patches of ``core.export.g1_patches`` (one face per quad,
at most 64 poles, close to the limit near extraordinary vertices)."""
DEFAULT_EXPORT_FORM = "exact"
FACE_FORMS = ("quad", "chart")
"""The B-rep faces of the G1 export: ``quad``, one face per quad of the cage; ``chart``, one
multi-span face per rectangular block of quads (``core.export.chart_faces``)."""
DEFAULT_FACE_FORM = "quad"
MAX_EXPORT_DEPTH = 12
"""Deeper grading adds (2 depth + 3)^2 poles per patch at an extraordinary vertex for no
visible gain (the error is already ~1e-6 of the diagonal at depth 8)."""


@dataclass(frozen=True)
class Option:
    """How one parameter is given and checked.

    help : one line for ``--help`` (``%(default)s`` is replaced by the default); a bool's
        describes its flag.
    low, high : inclusive range of a number, or None.
    choices : the allowed values of a text parameter (tuple of str), or None.
    flag : the command-line option (``--lam``), or None when it has none; a bool's flag sets
        it to the opposite of its default (``--no-repair``).
    metavar : the value's name in ``--help``, or None for argparse's (the flag in capitals).
    """

    help: str
    low: float = None
    high: float = None
    choices: tuple = None
    flag: str = None
    metavar: str = None


def _param(default, help, flag=None, **option):
    """A dataclass field with its :class:`Option` (``flag`` defaults to none)."""
    return field(default=default, metadata={"option": Option(help, flag=flag, **option)})


def _flag(name):
    """``--name-with-dashes`` of a parameter name."""
    return "--" + name.replace("_", "-")


def check_export_depth(depth, name="depth"):
    """Raise ParameterError unless ``depth`` is an integer in ``1..MAX_EXPORT_DEPTH``.

    ``name`` is what the message calls it (``depth`` on the command line, ``Depth`` for the
    document property).
    """
    if isinstance(depth, bool) or not isinstance(depth, Integral):
        raise ParameterError(f"{name} must be an integer, got {depth!r}")
    _range(name, depth, 1, MAX_EXPORT_DEPTH)


def check_export_form(form, name="export"):
    """Raise ParameterError unless ``form`` is one of :data:`EXPORT_FORMS`."""
    if form not in EXPORT_FORMS:
        raise ParameterError(f"{name} must be one of {', '.join(EXPORT_FORMS)}, got {form!r}")


def check_face_form(faces, export, name="faces"):
    """Raise ParameterError unless ``faces`` is one of :data:`FACE_FORMS` and fits ``export``
    (merged faces are made of the G1 export's patches only)."""
    if faces not in FACE_FORMS:
        raise ParameterError(f"{name} must be one of {', '.join(FACE_FORMS)}, got {faces!r}")
    if faces != "quad" and export != "g1":
        raise ParameterError(f"{name} '{faces}' needs the g1 export (got export {export!r})")


@dataclass(frozen=True)
class ReconstructionParams:
    """Every user-settable parameter of :func:`core.pipeline.reconstruct`.

    units : length unit of the target file's coordinates (``mm``, ``cm``, ``m``, ``in``);
        intake scales the target to millimetres (``UNIT_TO_MM``), so the solid and the STEP
        file are in millimetres, FreeCAD's and STEP's usual unit.
    components : what to do with several connected components (``largest``, ``all``, ``error``).
    check_self_intersections : run the triangle-triangle test at intake.
    repair_mesh : repair, at intake, faces with coincident corners, duplicate and zero-area
        faces and a few intersecting faces (``core.mesh_repair``; each repair is listed in
        the report's ``input.repairs``); False refuses such a mesh.
    proxy_triangles : a target with more triangles is reduced to about this many for the
        parts, frames, labeling and base mesh (``core.proxy``), so that the cage does not
        depend on how finely the shape is triangulated; the fit and every figure use the
        whole target. 0 never reduces.
    parts : ``single`` (whole mesh one part), ``auto`` (curve-skeleton based) or ``file``
        (chosen by the user, read from ``parts_file``).
    parts_file : JSON file with one of ``{"face_part": [p_0, ..., p_m-1]}``, ``{"groups":
        [[face, ...], ...]}`` or ``{"planes": [[[px, py, pz], [nx, ny, nz]], ...]}``; face
        indices are in the order of the mesh after intake (the ``--labels`` file's order,
        which is the file's own order for a single-component mesh).
    blend_factor : frame blending distance in mean edge lengths (paper: 4).
    lam : Eq. 3 lambda, weight of neighbours with a different label (paper: 0.5).
    penalty : Eq. 3 p, weight of opposite labels and interface-parallel labels (paper: 1e5).
    max_sweeps : cap on HBECVT sweeps.
    repair : run the validity repair loop after HBECVT.
    target_faces : base-mesh face budget: the integer polycube's scale is searched so the quad
        count is within 25% of it; when the labeling needs more, the smallest layout found is
        used and the report says why.
    max_base_faces : a base mesh with more faces stops the run with a message (its fit would
        take many minutes, and such a model is not the few-patch result the tool is for).
    base_mesh_method : ``auto`` (the quantized polycube layout; where it cannot be built, needs more
        than 1.5 times the budget or has more inverted faces after its repair, the paired
        decimation of the target),
        ``polycube`` (never falls back) or ``decimation`` (the paired decimation only).
    subdivision_levels : Catmull-Clark levels used by the fit (paper: 2).
    fit_iterations : most shape-optimisation iterations (paper: 100); the fit stops earlier
        when it has converged.
    fit_convergence : the inside fit has converged when its best objective improved by less
        than this fraction over its last five iterations (default 0.002); 0 runs every one of
        ``fit_iterations``.
    fit_mode : ``inside`` (the paper's: the surface fills the target from inside),
        ``best-fit`` (two-sided least squares) or ``none`` (the unfitted limit surface).
    tolerance : largest deviation wanted, as a fraction of the target's bounding-box
        diagonal; 0 = no refinement. Quad strips deviating more are split and refitted
        until it is met or ``max_base_faces`` would be exceeded.
    tolerance_mm : the same in millimetres (after ``units``); at most one of the two.
    outside_refinement : inside mode: where the fit leaves more than this fraction of the
        target's volume outside, the cage's quad strips under the outside points are split
        and the cage fitted again (``core.fitting.outside_refinement``; default 0.003,
        0 = off).
    fit_t_min : minimal wall thickness of the fit in model units; None picks it from the
        base mesh and the target (see ``core.fitting.fit_base_mesh``), 0 disables it.
    export : surface form of the solid's patches, one of :data:`EXPORT_FORMS` (``exact``:
        graded, the Catmull-Clark limit; ``g1``: one light tangent-continuous patch per quad,
        cages without creases).
    faces : B-rep faces of the ``g1`` export, one of :data:`FACE_FORMS` (``quad``: one per
        quad; ``chart``: one multi-span face per rectangular block of quads).
    """

    units: str = _param("mm", "length unit of the target's coordinates (default: mm); the "
                        "result is written in millimetres", _flag("units"),
                        choices=tuple(UNIT_TO_MM))
    components: str = _param("largest", "several connected components: keep the largest (with a "
                             "warning), keep all, or reject (default: largest)",
                             _flag("components"), choices=COMPONENT_POLICIES)
    check_self_intersections: bool = _param(
        True, "do not run the triangle-triangle intersection test at intake",
        "--skip-self-intersection-check")
    repair_mesh: bool = _param(
        True, "refuse a mesh with duplicate or zero-area faces or a few intersecting faces "
        "instead of repairing it", "--no-mesh-repair")
    proxy_triangles: int = _param(
        60_000, "targets with more triangles are reduced to about this many for the parts, "
        "frames, labeling and base mesh (the fit uses the whole target; default %(default)s; "
        "0: never)", _flag("proxy_triangles"), low=0, high=100_000_000)
    parts: str = _param("single", "part segmentation: whole mesh one part, or curve-skeleton "
                        "based", _flag("parts"), choices=PART_MODES)
    parts_file: str = _param("", "user parts: JSON with 'face_part' (per-face part ids), 'groups' "
                             "(face-index lists) or 'planes' ([point, normal] pairs); implies "
                             "--parts file", _flag("parts_file"), metavar="JSON")
    blend_factor: float = _param(4.0, "frame blending distance in mean edge lengths (paper: 4)",
                                 _flag("blend_factor"), low=1e-3, high=1000.0)
    lam: float = _param(0.5, "HBECVT neighbour weight lambda (paper: 0.5)", _flag("lam"),
                        low=0.0, high=1e3)
    penalty: float = _param(1e5, "HBECVT penalty p (paper: 1e5)", _flag("penalty"),
                            low=0.0, high=1e12)
    max_sweeps: int = _param(200, "most HBECVT sweeps (default %(default)s)", _flag("max_sweeps"),
                             low=1, high=100_000)
    repair: bool = _param(True, "skip the labeling repair loop", "--no-repair")
    target_faces: int = _param(300, "approximate number of base-mesh faces (default %(default)s)",
                               _flag("target_faces"), low=6, high=200_000)
    max_base_faces: int = _param(2500, "stop when the base mesh has more faces than this "
                                 "(default %(default)s)", _flag("max_base_faces"),
                                 low=6, high=1_000_000)
    base_mesh_method: str = _param(
        "auto", "auto: the polycube layout, falling back to a paired decimation of the target "
        "where the layout fails, needs more than 1.5 times --target-faces or has more inverted "
        "faces after its repair; "
        "polycube: never fall back; decimation: the paired decimation only (default auto)",
        _flag("base_mesh_method"), choices=BASE_MESH_METHODS)
    subdivision_levels: int = _param(2, "Catmull-Clark levels of the fit (paper: %(default)s)",
                                     _flag("subdivision_levels"), low=1, high=5)
    fit_iterations: int = _param(100, "most shape-optimisation iterations (paper: 100; the fit "
                                 "stops earlier when converged)", _flag("fit_iterations"),
                                 low=0, high=100_000)
    fit_convergence: float = _param(2e-3, "the inside fit stops when its best objective "
                                    "improved by less than this fraction over five iterations "
                                    "(default %(default)s; 0: run every iteration)",
                                    _flag("fit_convergence"), low=0.0, high=1.0)
    fit_mode: str = _param("inside", "inside: fill the target from inside (paper, default); "
                           "best-fit: two-sided least squares; none: the unfitted limit surface",
                           _flag("fit_mode"), choices=FIT_MODES)
    fit_t_min: float = _param(None, "minimal wall thickness of the fit (model units; none: "
                              "from the base mesh, 0: off)", low=0.0, high=1e9)
    tolerance: float = _param(0.0, "largest deviation wanted: a fraction of the bounding-box "
                              "diagonal (0.002) or a length with its unit (0.5mm, 0.05cm, "
                              "0.02in); quad strips deviating more are split and refitted "
                              "(default 0: off)", _flag("tolerance"), low=0.0, high=1.0,
                              metavar="T")
    tolerance_mm: float = _param(0.0, "largest deviation wanted in millimetres (given as "
                                 "--tolerance with a unit)", low=0.0, high=1e9)
    export: str = _param(DEFAULT_EXPORT_FORM, "surface form of the solid: exact: graded patches, "
                         "the Catmull-Clark limit (large STEP); g1: one light tangent-continuous "
                         "patch per quad, close to the limit (cages without creases) (default "
                         "%(default)s)", _flag("export"), choices=EXPORT_FORMS)
    faces: str = _param(DEFAULT_FACE_FORM, "B-rep faces of the g1 export: quad: one face per "
                        "quad of the cage; chart: one multi-span face per rectangular block of "
                        "quads (fewer faces, faster to read) (default %(default)s)",
                        _flag("faces"), choices=FACE_FORMS)
    outside_refinement: float = _param(
        0.003, "inside mode: where the fit leaves more than this fraction of the target's "
        "volume outside, split the cage's quad strips there and fit again (default "
        "%(default)s; 0: off)", _flag("outside_refinement"), low=0.0, high=1.0)

    def __post_init__(self):
        for item in fields(self):
            option, value = item.metadata["option"], getattr(self, item.name)
            if option.choices is not None:
                _choice(item.name, value, option.choices)
            elif option.low is not None and not (value is None and item.default is None):
                _range(item.name, value, option.low, option.high)
        if (self.parts == "file") != bool(self.parts_file):
            raise ParameterError("parts='file' and parts_file go together: give the JSON file "
                                 "of user parts with parts='file'")
        if self.tolerance > 0 and self.tolerance_mm > 0:
            raise ParameterError("give the tolerance once: as a fraction of the bounding-box "
                                 "diagonal (tolerance) or in millimetres (tolerance_mm)")
        check_face_form(self.faces, self.export)
        if (self.tolerance > 0 or self.tolerance_mm > 0) and self.fit_mode == "none":
            raise ParameterError("a tolerance needs a fit: fit_mode 'none' cannot refine")

    @classmethod
    def from_dict(cls, values):
        """Build from a dict, rejecting unknown keys with a clear message."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ParameterError(f"unknown parameter(s): {', '.join(unknown)}; "
                                 f"known: {', '.join(sorted(known))}")
        return cls(**values)

    def to_dict(self):
        return asdict(self)


def parameter_options():
    """``(field, Option)`` of every ``ReconstructionParams`` field, in declaration order
    (``field.name``, ``field.type``, ``field.default``)."""
    return [(item, item.metadata["option"]) for item in fields(ReconstructionParams)]


def parameter_option(name):
    """``(field, Option)`` of the ``ReconstructionParams`` field ``name``; ParameterError
    naming the parameters when there is no such field."""
    found = [(item, option) for item, option in parameter_options() if item.name == name]
    if not found:
        raise ParameterError(f"unknown parameter {name!r}; known: "
                             f"{', '.join(item.name for item, _ in parameter_options())}")
    return found[0]


def _choice(name, value, allowed):
    if value not in allowed:
        raise ParameterError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")


def _range(name, value, low, high):
    try:
        ok = low <= value <= high
    except TypeError:
        ok = False
    if not ok or value != value:
        raise ParameterError(f"{name} must be between {low} and {high}, got {value!r}")
