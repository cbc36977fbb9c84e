# SPDX-License-Identifier: LGPL-2.1-or-later
"""Operations on a document of stage objects: which stage an object is, the chain it is built
from, the object to work on, the chain up to a stage, cage edits, recompute as one undo step,
a line describing a result."""
import numpy as np

from core.progress import NO_PROGRESS
from polycube_wb.api.factories import make_base_mesh, make_fit, make_segmentation, make_solid


STAGE_ORDER = ("Target", "Segmentation", "BaseMesh", "Fit", "Solid")
"""The stage kinds of a chain, in the order each is built from the one before."""


def stage_kind(obj):
    """``Target``, ``Segmentation``, ... for a stage object, else None."""
    from polycube_wb.objects.base import stage_kind as kind_of

    return kind_of(obj)


def upstream_objects(obj):
    """Dict kind -> object of ``obj`` and the stage objects it is built from."""
    found = {}
    stack = [obj]
    while stack:
        current = stack.pop()
        kind = stage_kind(current)
        if kind is None or kind in found:
            continue
        found[kind] = current
        stack.extend(getattr(current, link) for link in current.Proxy.INPUTS)
    return found


def find_stage(doc, kind, start=None):
    """The stage object of ``kind`` to work on, or None.

    With ``start`` (e.g. the selection): the one ``start`` is built from, else the last
    one built from ``start``; otherwise (or when there is none) the last one in ``doc``.
    """
    if start is not None:
        upstream = upstream_objects(start).get(kind)
        if upstream is not None:
            return upstream
        built = {obj.Name for obj in start.InListRecursive}
        for obj in reversed(doc.Objects):
            if obj.Name in built and stage_kind(obj) == kind:
                return obj
    for obj in reversed(doc.Objects):
        if stage_kind(obj) == kind:
            return obj
    return None


def make_chain(doc, start, last="Solid", **properties):
    """Add the stage objects after ``start`` up to ``last`` (reusing existing ones).

    Parameters
    ----------
    start : a stage object (typically the Target).
    last : kind of the last stage to have (``Segmentation`` ... ``Solid``).
    properties : ``{kind: {property: value}}`` for the objects that are created.

    Returns
    -------
    dict kind -> object, for every kind from the Target to ``last``.
    """
    factories = {"Segmentation": make_segmentation, "BaseMesh": make_base_mesh,
                 "Fit": make_fit, "Solid": make_solid}
    chain = upstream_objects(start)
    previous = start
    for kind in STAGE_ORDER[STAGE_ORDER.index(stage_kind(start)) + 1:
                            STAGE_ORDER.index(last) + 1]:
        existing = next((obj for obj in previous.InList
                         if stage_kind(obj) == kind and is_reusable(obj)), None)
        chain[kind] = existing or factories[kind](doc, previous, **properties.get(kind, {}))
        previous = chain[kind]
    return chain


def move_cage_vertices(obj, moves):
    """Move vertices of a cage object (BaseMesh or Fit); the next recompute follows.

    Parameters
    ----------
    obj : a BaseMesh or Fit object.
    moves : dict vertex index -> new position (x, y, z) in model units (mm).

    Raises
    ------
    ParameterError
        ``obj`` holds no cage, an index is not a cage vertex, or a position is not 3
        finite numbers.
    """
    import FreeCAD

    from core.errors import ParameterError

    if stage_kind(obj) not in ("BaseMesh", "Fit"):
        raise ParameterError(f"{obj.Label} is not a BaseMesh or Fit object (it has no cage)")
    points = list(obj.CageVertices)
    for index, position in moves.items():
        if not isinstance(index, (int, np.integer)) or not 0 <= index < len(points):
            raise ParameterError(f"{obj.Label}: {index!r} is not a cage vertex index "
                                 f"(0..{len(points) - 1})")
        position = np.asarray(position, dtype=np.float64)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ParameterError(f"{obj.Label}: vertex {index} position must be 3 finite "
                                 f"numbers, got {position.tolist()}")
        points[index] = FreeCAD.Vector(*position.tolist())
    obj.CageVertices = points


def is_reusable(obj):
    """Whether later stages may be built on ``obj`` by default.

    A Segmentation with automatic parts is not: assembling the part base meshes at their
    interfaces is not built yet, so *Segment parts* shows the parts without changing what
    the base mesh is built from (select it explicitly to try).
    """
    return not (stage_kind(obj) == "Segmentation" and obj.PartMode == "auto")


class RecomputeOutcome:
    """What a :func:`recompute` did.

    failures : dict object name -> one-line reason its stage failed (empty when all ran).
    cancelled : bool, the user cancelled (the document was rolled back).
    """

    def __init__(self, failures, cancelled):
        self.failures = failures
        self.cancelled = cancelled

    @property
    def ok(self):
        return not self.failures and not self.cancelled


def recompute(doc, progress=NO_PROGRESS, run_job=None, between_stages=None):
    """``doc.recompute()`` with ``progress`` reaching the stage objects; returns the outcome.

    With ``run_job`` (``run_job(job, progress) -> result``, e.g. the GUI's stage process,
    :mod:`polycube_wb.gui.worker`), the stale stage objects' computations are run by it and
    their results stored before the recompute (:func:`polycube_wb.objects.base.run_pending_stages`,
    which calls ``between_stages()``, if given, between storing one result and reading the
    next stage's inputs); the outcome is the same as without it.

    FreeCAD does not propagate errors from ``execute``; the outcome lists them. An object
    whose stage failed is marked invalid (``obj.isValid()`` is False) with the reason in its
    ``Status`` property; the objects after it are not recomputed. When the user cancels
    (``progress`` raises ``Cancelled``), the object that was running gets ``Status``
    "cancelled by the user" and keeps its last result; it and the objects that did not run
    after it stay touched (the next recompute runs them).
    """
    from polycube_wb.objects.base import recompute_session, run_pending_stages

    with recompute_session(doc, progress) as session:
        if run_job is not None:
            run_pending_stages(doc, session, run_job, between_stages)
        doc.recompute()
    if session.cancelled:
        for name in list(session.failures) + session.skipped:
            doc.getObject(name).touch()
    return RecomputeOutcome(dict(session.failures), session.cancelled)


def run_in_transaction(doc, title, build, progress=NO_PROGRESS, run_job=None,
                       between_stages=None):
    """Run ``build()`` (adds or changes objects), then recompute, as one undo step.

    ``run_job`` runs the stages' computations, ``between_stages`` runs between one stage's
    stored result and the next stage's inputs (see :func:`recompute`).

    When ``build`` raises, the document is rolled back to what it was before. When the user
    cancels during the recompute, the stages that finished keep their results, the stage
    object that was running keeps the result it had (none if it is new) and is marked:
    ``Status`` "cancelled by the user", touched, so the next recompute runs it again; the
    objects after it are not run. The step is committed, so Undo restores the document as
    it was before ``build`` (needs ``doc.UndoMode``, which the GUI turns on).

    Returns
    -------
    (what ``build`` returned, RecomputeOutcome)

    Raises
    ------
    core.errors.Cancelled
        The user cancelled; the message names the stage object that was running.
    """
    from core.errors import Cancelled
    from polycube_wb.objects.base import CANCELLED_STATUS

    doc.openTransaction(title)
    try:
        built = build()
        outcome = recompute(doc, progress, run_job, between_stages)
    except BaseException:
        doc.abortTransaction()
        raise
    doc.commitTransaction()
    if outcome.cancelled:
        stopped = [doc.getObject(name) for name, reason in outcome.failures.items()
                   if reason == CANCELLED_STATUS]
        where = " at " + ", ".join(obj.Label for obj in stopped) if stopped else ""
        raise Cancelled(f"{title}: cancelled by the user{where}; the stages before it keep "
                        f"their results (Undo restores the document as it was)")
    return built, outcome


def describe(obj):
    """One line about a stage object's result (for the Report view and messages)."""
    from polycube_wb.objects.base import CANCELLED_STATUS

    kind = stage_kind(obj)
    if obj.Status == CANCELLED_STATUS:
        return f"{obj.Label}: {CANCELLED_STATUS}; it runs again at the next recompute"
    if not obj.isValid() or obj.Status not in ("ok", ""):
        return f"{obj.Label}: failed: {obj.Status}"
    if kind == "Target":
        return f"{obj.Label}: {obj.Triangles} triangles, genus {obj.Genus}"
    if kind == "Segmentation":
        return (f"{obj.Label}: labeling {'valid' if obj.Valid else 'INVALID'}: {obj.Parts} "
                f"part(s), {obj.Charts} charts, {obj.Corners} corners; invalid charts "
                f"{obj.InvalidCharts}, boundaries {obj.InvalidBoundaries}, corners "
                f"{obj.InvalidCorners}")
    if kind in ("BaseMesh", "Fit"):
        line = (f"{obj.Label}: cage of {obj.Faces} faces, {obj.Vertices} vertices, "
                f"{obj.ExtraordinaryVertices} extraordinary, genus {obj.Genus}")
        if kind == "Fit":
            size = _target_diagonal(obj)
            line += (f"; distance to the target mean {_mm(obj.MeanDistance, size)}, max "
                     f"{_mm(obj.MaxDistance, size)}; volume outside the target "
                     f"{100 * obj.OutsideVolume:.2f} % ({obj.Stopped})")
        return line
    if kind == "Solid":
        return (f"{obj.Label}: solid of {obj.BrepFaces} B-spline faces, valid "
                f"{obj.BrepValid}, volume {obj.BrepVolume:.6g} mm³")
    if kind == "Deviation":
        return (f"{obj.Label}: distance to the target mean {obj.MeanDeviation:.3g} mm "
                f"({obj.MeanDeviationPercent:.3f} % of the size), max {obj.MaxDeviation:.3g} mm "
                f"({obj.MaxDeviationPercent:.3f} %); volume outside the target "
                f"{obj.OutsideVolume:.3f} %, not covered {obj.UncoveredVolume:.3f} %; watertight "
                f"{obj.Watertight}")
    return obj.Label


def _target_diagonal(obj):
    """Bounding-box diagonal of the target ``obj`` is built from, mm (None without one)."""
    target = upstream_objects(obj).get("Target")
    return target.Mesh.BoundBox.DiagonalLength if target is not None else None


def _mm(fraction, diagonal):
    """A distance given as a fraction of the diagonal, in mm and in % of the size."""
    if not diagonal:
        return f"{100 * fraction:.3g} % of the size"
    return f"{fraction * diagonal:.3g} mm ({100 * fraction:.3g} % of the size)"
