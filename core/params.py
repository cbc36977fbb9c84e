# SPDX-License-Identifier: LGPL-2.1-or-later
"""Pipeline parameters with the paper's defaults and range checks."""
from dataclasses import asdict, dataclass, fields
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
MAX_EXPORT_DEPTH = 12
"""Deeper grading adds (2 depth + 3)^2 poles per patch at an extraordinary vertex for no
visible gain (the error is already ~1e-6 of the diagonal at depth 8)."""


def check_export_depth(depth, name="depth"):
    """Raise ParameterError unless ``depth`` is an integer in ``1..MAX_EXPORT_DEPTH``.

    ``name`` is what the message calls it (``depth`` on the command line, ``Depth`` for the
    document property).
    """
    if isinstance(depth, bool) or not isinstance(depth, Integral):
        raise ParameterError(f"{name} must be an integer, got {depth!r}")
    _range(name, depth, 1, MAX_EXPORT_DEPTH)


@dataclass(frozen=True)
class ReconstructionParams:
    """Every user-settable parameter of :func:`core.pipeline.reconstruct`.

    units : length unit of the target file's coordinates (``mm``, ``cm``, ``m``, ``in``);
        intake scales the target to millimetres (``UNIT_TO_MM``), so the solid and the STEP
        file are in millimetres, FreeCAD's and STEP's usual unit.
    components : what to do with several connected components (``largest``, ``all``, ``error``).
    check_self_intersections : run the triangle-triangle test at intake.
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
        than twice the budget or has inverted faces, the paired decimation of the target),
        ``polycube`` (never falls back) or ``decimation`` (the paired decimation only).
    subdivision_levels : Catmull-Clark levels used by the fit (paper: 2).
    fit_iterations : most shape-optimisation iterations (paper: 100); the fit stops earlier
        when it has converged.
    fit_mode : ``inside`` (the paper's: the surface fills the target from inside),
        ``best-fit`` (two-sided least squares) or ``none`` (the unfitted limit surface).
    tolerance : largest deviation wanted, as a fraction of the target's bounding-box
        diagonal; 0 = no refinement. Quad strips deviating more are split and refitted
        until it is met or ``max_base_faces`` would be exceeded.
    tolerance_mm : the same in millimetres (after ``units``); at most one of the two.
    fit_t_min : minimal wall thickness of the fit in model units; None picks it from the
        base mesh and the target (see ``core.fitting.fit_base_mesh``), 0 disables it.
    """

    units: str = "mm"
    components: str = "largest"
    check_self_intersections: bool = True
    parts: str = "single"
    parts_file: str = ""
    blend_factor: float = 4.0
    lam: float = 0.5
    penalty: float = 1e5
    max_sweeps: int = 200
    repair: bool = True
    target_faces: int = 300
    max_base_faces: int = 2500
    base_mesh_method: str = "auto"
    subdivision_levels: int = 2
    fit_iterations: int = 100
    fit_mode: str = "inside"
    fit_t_min: float = None
    tolerance: float = 0.0
    tolerance_mm: float = 0.0

    def __post_init__(self):
        _choice("units", self.units, tuple(UNIT_TO_MM))
        _choice("components", self.components, COMPONENT_POLICIES)
        _choice("parts", self.parts, PART_MODES)
        if (self.parts == "file") != bool(self.parts_file):
            raise ParameterError("parts='file' and parts_file go together: give the JSON file "
                                 "of user parts with parts='file'")
        _range("blend_factor", self.blend_factor, 1e-3, 1000.0)
        _range("lam", self.lam, 0.0, 1e3)
        _range("penalty", self.penalty, 0.0, 1e12)
        _range("max_sweeps", self.max_sweeps, 1, 100_000)
        _range("target_faces", self.target_faces, 6, 200_000)
        _range("max_base_faces", self.max_base_faces, 6, 1_000_000)
        _choice("base_mesh_method", self.base_mesh_method, BASE_MESH_METHODS)
        _range("subdivision_levels", self.subdivision_levels, 1, 5)
        _range("fit_iterations", self.fit_iterations, 0, 100_000)
        _choice("fit_mode", self.fit_mode, FIT_MODES)
        if self.fit_t_min is not None:
            _range("fit_t_min", self.fit_t_min, 0.0, 1e9)
        _range("tolerance", self.tolerance, 0.0, 1.0)
        _range("tolerance_mm", self.tolerance_mm, 0.0, 1e9)
        if self.tolerance > 0 and self.tolerance_mm > 0:
            raise ParameterError("give the tolerance once: as a fraction of the bounding-box "
                                 "diagonal (tolerance) or in millimetres (tolerance_mm)")
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
