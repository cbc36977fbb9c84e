# SPDX-License-Identifier: LGPL-2.1-or-later
"""What every stage object shares: properties, persistence, fingerprints, the run session.

A stage object keeps its parameters in properties and its result in the document (mesh,
shape and list properties), never in the proxy: the proxy's saved state is only its
``Type`` string (FreeCAD 0.20.2 stores proxies as JSON through ``__getstate__``, and
numpy arrays there are silently lost).

Recompute reruns only what changed. Each object stores ``ResultId`` (a hash of its result),
``InputId`` (the ``ResultId`` of its inputs when it ran) and ``ParamsId`` (a hash of its
parameters). ``execute`` reruns the stage only when one of those differs; otherwise it just
rebuilds its display from the stored result (and keeps its cached outputs unless the stored
result changed). So editing a stored result (the cage's vertex
coordinates) changes the ``ResultId`` and reruns the stages after it, not the stage itself.

The objects' ``execute`` is called by ``doc.recompute()``, which cannot pass arguments;
``recompute_session`` hands them the progress object of the command that recomputes and
collects their failures (an exception in ``execute`` does not propagate from recompute).

A stage's run is split in three: ``prepare`` reads what it needs from the document and
returns the computation as a ``polycube_wb.stage_jobs.StageJob`` (a function and plain data
that touch no document object); ``store`` writes the job's result back. ``run`` chains them
in the calling thread (``doc.recompute()`` in scripts and ``freecadcmd``).
:func:`run_pending_stages` instead hands each job to a job runner (the GUI runs it in its
stage process or a worker thread while FreeCAD's event loop keeps going) and stores its
result in the calling thread; the ``doc.recompute()`` that follows then finds every stage up
to date.
"""
import contextlib
import hashlib
import json

import numpy as np

import FreeCAD

from core.errors import Cancelled, PolycubeError
from core.progress import NO_PROGRESS, SubProgress
from polycube_wb.stage_jobs import StageFailed  # noqa: F401  (raised by the stage objects)

STATUS_GROUP = "Status"
STAGE_WEIGHTS = {"Target": 1.0, "Segmentation": 1.0, "BaseMesh": 2.0, "Fit": 12.0,
                 "Solid": 1.5, "Deviation": 1.5}
"""Share of the progress bar each object gets when several recompute together (about
their run times on the bundled sample: the fit dominates)."""


CANCELLED_STATUS = "cancelled by the user"
"""``Status`` of a stage object whose run the user cancelled (Esc)."""


class _Session:
    """The progress and failures of one ``recompute_session``."""

    def __init__(self, progress, weights):
        self.progress = progress
        self.weights = weights
        self.total = sum(weights.values()) or 1.0
        self.done = 0.0
        self.failures = {}
        self.cancelled = False
        self.skipped = []
        self.spans = {}
        self.stored = set()
        self.errors = {}

    def span(self, obj):
        """The ``SubProgress`` of ``obj``'s run: its share of the bar, in run order (the same
        one when asked again for ``obj``)."""
        if obj.Name not in self.spans:
            weight = self.weights.get(obj.Name, 0.0)
            start = self.done / self.total
            self.done = min(self.total, self.done + weight)
            self.spans[obj.Name] = SubProgress(self.progress, start, self.done / self.total)
        return self.spans[obj.Name]


_SESSIONS = []


def _current():
    return _SESSIONS[-1] if _SESSIONS else None


@contextlib.contextmanager
def recompute_session(doc, progress=NO_PROGRESS):
    """Give the stage objects recomputed inside the block ``progress`` and collect failures.

    The bar spans every stage object that the recompute will run (the touched ones and
    everything after them), each weighted by ``STAGE_WEIGHTS``.

    Yields
    ------
    _Session
        ``failures`` maps object names to the one-line reason their stage failed;
        ``cancelled`` is True when the user cancelled; ``skipped`` names the objects
        that did not run after the cancel; ``stored`` names the objects whose result
        :func:`run_pending_stages` stored, ``errors`` the exception of those whose stage
        failed there (their ``execute`` raises it again, so FreeCAD marks them invalid).
    """
    weights = {}
    for obj in pending_objects(doc):
        kind = stage_kind(obj)
        if kind is not None:
            weights[obj.Name] = STAGE_WEIGHTS.get(kind, 1.0)
    session = _Session(progress, weights)
    _SESSIONS.append(session)
    try:
        yield session
    finally:
        _SESSIONS.pop()


def pending_objects(doc):
    """Objects of ``doc`` a recompute will run: the touched ones and all depending on them."""
    pending = {}
    for obj in doc.Objects:
        if "Touched" in obj.State or obj.MustExecute:
            pending[obj.Name] = obj
            for dependent in obj.InListRecursive:
                pending[dependent.Name] = dependent
    return list(pending.values())


def run_pending_stages(doc, session, run_job, between_stages=None):
    """Bring the stale stage objects of ``doc`` up to date, each computation run by
    ``run_job``, before the ``doc.recompute()`` of ``session`` (which then only marks them).

    The stage objects a recompute would run are taken in dependency order. For each stale
    one, :meth:`StageProxy.prepare` reads its inputs in this thread, ``run_job`` runs the
    computation, and its result is stored here (one object at a time, so the next stage
    reads the stored result exactly as ``doc.recompute()`` would). A stage that fails is
    marked as ``execute`` marks it, and nothing that depends on it runs; a cancel marks the
    object that was running and stops.

    Parameters
    ----------
    doc : App.Document
    session : the ``recompute_session`` of ``doc`` that the recompute after this call uses.
    run_job : callable ``run_job(job, progress) -> result`` running the ``StageJob``
        ``job(progress)`` (in the GUI: in another process or thread while FreeCAD stays
        live); ``progress`` is the object's share of the session's bar.
    between_stages : callable ``between_stages()``, optional, called after a stage's result
        is stored and before the next stage's inputs are read (in the GUI: one turn of the
        event loop, so that storing one result and reading the next inputs do not hold it in
        one stretch).
    """
    blocked, stored_one = set(), False
    for obj in _dependency_order(pending_objects(doc)):
        kind = stage_kind(obj)
        if kind is None or getattr(obj, "Proxy", None) is None:
            continue
        if stored_one and between_stages is not None:
            between_stages()
            stored_one = False
        if session.cancelled:
            return
        if blocked & {upstream.Name for upstream in obj.OutListRecursive}:
            blocked.add(obj.Name)
            continue
        proxy = obj.Proxy
        progress = session.span(obj)
        try:
            proxy.bring_up_to_date(
                obj, lambda: proxy.store(obj, run_job(proxy.prepare(obj), progress)))
        except Cancelled:
            proxy._fail(obj, session, CANCELLED_STATUS, cancelled=True)
            return
        except Exception as exc:  # raised again by its execute, where FreeCAD reports it
            if isinstance(exc, (PolycubeError, ImportError)):
                proxy._fail(obj, session, _one_line(exc))
            session.errors[obj.Name] = exc
            blocked.add(obj.Name)
            continue
        progress.report(kind, 1.0)
        obj.Status = "ok"
        session.stored.add(obj.Name)
        stored_one = True


def _dependency_order(objects):
    """``objects`` ordered so that each comes after the ones of them it depends on."""
    names = {obj.Name for obj in objects}
    placed, ordered = set(), []
    remaining = list(objects)
    while remaining:
        ready = [obj for obj in remaining
                 if not ({o.Name for o in obj.OutListRecursive} & names) - placed]
        if not ready:  # a dependency cycle: FreeCAD's recompute reports it
            ready = remaining[:1]
        for obj in ready:
            placed.add(obj.Name)
            ordered.append(obj)
            remaining.remove(obj)
    return ordered


def stage_kind(obj):
    """``Type`` of a stage object's proxy without the ``Polycube::`` prefix, else None."""
    proxy = getattr(obj, "Proxy", None)
    kind = getattr(proxy, "Type", "")
    return kind.split("::", 1)[1] if kind.startswith("Polycube::") else None


FINE_FLOAT = "App::PropertyPrecision"
"""Property type of a small fraction (e.g. 0.002): the property editor shows a plain
``App::PropertyFloat`` with the user's unit decimals (2 by default: "0.00"), this one in full.
Older documents keep the type their objects were made with."""


def add_property(obj, kind, name, group, tooltip, default=None, read_only=False, hidden=False,
                 output=False, choice=None):
    """Add a property if ``obj`` lacks it (idempotent: new objects and old documents).

    Parameters
    ----------
    kind : FreeCAD property type (``App::PropertyInteger``, ...).
    default : value set only when the property is added (a list for an enumeration: its
        choices, the first being the default unless ``choice`` names another).
    read_only, hidden : editor modes; ``output`` marks a result that does not touch the
        object when set (so storing a result does not schedule another recompute).
    """
    if name in obj.PropertiesList:
        return False
    obj.addProperty(kind, name, group, tooltip)
    if default is not None:
        setattr(obj, name, default)
        if isinstance(default, list) and kind == "App::PropertyEnumeration":
            setattr(obj, name, choice if choice in default else default[0])
    if hidden:
        obj.setEditorMode(name, 2)
    elif read_only:
        obj.setEditorMode(name, 1)
    if output:
        obj.setPropertyStatus(name, "Output")
    return True


def fingerprint(*parts):
    """Short hex digest of arrays, numbers and strings (stable across runs and machines)."""
    digest = hashlib.sha1()
    for part in parts:
        if isinstance(part, np.ndarray):
            array = np.ascontiguousarray(part)
            digest.update(str(array.dtype).encode() + str(array.shape).encode())
            digest.update(array.tobytes())
        else:
            digest.update(json.dumps(part, sort_keys=True, default=str).encode())
    return digest.hexdigest()[:16]


class StageProxy:
    """Base of the stage proxies.

    Subclasses set ``TYPE`` and ``INPUTS`` (names of link properties to upstream stage
    objects), and implement ``init_properties``, ``parameters(obj)`` (a JSON-able dict),
    ``run(obj, progress)`` (run the stage and store its result, may raise) and
    ``show(obj)`` (rebuild the display from the stored result; returns its ``ResultId``).
    ``outputs(obj)`` returns the typed core results later stages need (a dict from
    ``core.types.PipelineState`` field to stage result), cached in memory and rebuilt from
    the document when missing (after reopening).
    """

    TYPE = "Polycube::Stage"
    INPUTS = ()

    def __init__(self, obj):
        obj.Proxy = self
        self.Type = self.TYPE
        self._cache = None
        self.init_properties(obj)

    # -- persistence (JSON only; FreeCAD 0.20.2 uses __getstate__, 0.21+ dumps) -----------

    def __getstate__(self):
        return {"Type": self.TYPE}

    def __setstate__(self, state):
        self.Type = self.TYPE
        self._cache = None

    def dumps(self):
        return self.__getstate__()

    def loads(self, state):
        self.__setstate__(state)

    def onDocumentRestored(self, obj):
        self._cache = None
        self.init_properties(obj)

    # -- properties ------------------------------------------------------------------------

    def init_properties(self, obj):
        """Add the properties this object needs that it lacks (idempotent)."""
        add_property(obj, "App::PropertyString", "Status", STATUS_GROUP,
                     "Outcome of the last run: 'ok', or why the stage failed", "",
                     read_only=True, output=True)
        for name, tooltip in (("ResultId", "Hash of the stored result"),
                              ("InputId", "ResultId of the inputs when the stage last ran"),
                              ("ParamsId", "Hash of the parameters when the stage last ran")):
            add_property(obj, "App::PropertyString", name, STATUS_GROUP, tooltip, "",
                         hidden=True, output=True)

    # -- running ---------------------------------------------------------------------------

    def inputs(self, obj):
        """The upstream stage objects, in ``INPUTS`` order; raises when a link is empty."""
        found = []
        for name in self.INPUTS:
            upstream = getattr(obj, name)
            if upstream is None or stage_kind(upstream) is None:
                raise StageFailed(f"{obj.Label}: its '{name}' link must point to a Polycube "
                                  "stage object")
            found.append(upstream)
        return found

    def input_id(self, obj):
        return fingerprint([upstream.ResultId for upstream in self.inputs(obj)])

    def is_stale(self, obj):
        """True when the stage must rerun: inputs or parameters changed, or no result yet."""
        return (not obj.ResultId or obj.InputId != self.input_id(obj)
                or obj.ParamsId != fingerprint(self.parameters(obj)))

    def prepare(self, obj):
        """Read what the stage needs from the document (the thread that owns it).

        Returns
        -------
        polycube_wb.stage_jobs.StageJob, callable as ``job(progress) -> result``; it touches
        no document object, so it may run in a worker thread or process (``progress`` is a
        ``core.progress.Progress``).
        """
        raise NotImplementedError(f"{type(self).__name__} must implement prepare")

    def store(self, obj, result):
        """Write ``result`` (what the computation of :meth:`prepare` returned) to ``obj`` and
        keep the typed core results later stages need in the cache."""
        raise NotImplementedError(f"{type(self).__name__} must implement store")

    def run(self, obj, progress):
        """Run the stage in this thread and store its result (may raise)."""
        self.store(obj, self.prepare(obj)(progress))

    def execute(self, obj):
        session = _current()
        if session is not None and session.cancelled:  # after Esc nothing else runs
            session.skipped.append(obj.Name)
            return
        if session is not None and obj.Name in session.errors:  # failed in run_pending_stages
            raise session.errors[obj.Name]
        if session is not None and obj.Name in session.stored:  # up to date already
            obj.Status = "ok"
            return
        progress = session.span(obj) if session is not None else NO_PROGRESS
        try:
            self.bring_up_to_date(obj, lambda: self.run(obj, progress))
        except Cancelled:  # not raised on: FreeCAD would print a traceback for it
            self._fail(obj, session, CANCELLED_STATUS, cancelled=True)
            return
        except (PolycubeError, ImportError) as exc:
            self._fail(obj, session, _one_line(exc))
            raise
        progress.report(self.TYPE.split("::")[1], 1.0)
        obj.Status = "ok"

    def bring_up_to_date(self, obj, run):
        """Call ``run()`` (runs the stage and stores its result) when the stage is stale, then
        rebuild the display and the ids.

        The cache ``run`` fills holds the typed results of the run itself, so the stages after
        it start from them; a result that changed without a run (an edited cage) empties the
        cache, and the typed results are rebuilt from the document when asked for.
        """
        ran = self.is_stale(obj)
        if ran:
            self._cache = None
            run()
            obj.InputId = self.input_id(obj)
            obj.ParamsId = fingerprint(self.parameters(obj))
        result_id = self.show(obj)
        if result_id != obj.ResultId:
            if not ran:
                self._cache = None
            obj.ResultId = result_id

    def _fail(self, obj, session, reason, cancelled=False):
        from polycube_wb.panel_fields import in_gui_words

        reason = in_gui_words(reason)
        obj.Status = reason
        FreeCAD.Console.PrintError(f"Polycube: {obj.Label}: {reason}\n")
        if session is not None:
            session.failures[obj.Name] = reason
            session.cancelled = session.cancelled or cancelled

    def outputs(self, obj):
        """``{PipelineState field: core stage result}`` of this stage (cached; rebuilt after
        reopening)."""
        if self._cache is None:
            self._cache = self.load_outputs(obj)
        return self._cache

    def load_outputs(self, obj):
        raise NotImplementedError(f"{type(self).__name__} must implement load_outputs")

    def upstream_results(self, obj):
        """The merged ``outputs`` of all stages before this one (a new dict)."""
        results = {}
        for upstream in self.inputs(obj):
            results.update(upstream.Proxy.upstream_results(upstream))
            results.update(upstream.Proxy.outputs(upstream))
        return results

    def upstream_state(self, obj):
        """A new ``core.types.PipelineState`` with the results of all stages before this one."""
        from core.types import PipelineState

        return PipelineState(**self.upstream_results(obj))


def settle_states(doc):
    """Make the stage objects' FreeCAD flags match their restored properties (after Undo/Redo).

    Undo and Redo restore the properties but leave each object's ``Touched``/``Invalid``
    flags as they were: an object whose run was cancelled and then undone would show an
    error with ``Status`` "ok". An object whose ``Status`` is "ok" and whose stored result
    matches its inputs and parameters is marked up to date (an invalid one is recomputed,
    which only redisplays its result); one whose ``Status`` says it was cancelled is touched.
    """
    for obj in doc.Objects:
        if stage_kind(obj) is None or getattr(obj, "Proxy", None) is None:
            continue
        if obj.Status == CANCELLED_STATUS:
            obj.touch()
            continue
        try:
            current = obj.Status == "ok" and not obj.Proxy.is_stale(obj)
        except PolycubeError:  # a link the undo emptied: leave the object as it is
            continue
        if current:
            if not obj.isValid():
                obj.recompute()
            obj.purgeTouched()


class _UndoObserver:
    """Calls :func:`settle_states` after every Undo and Redo (a FreeCAD document observer)."""

    def slotUndoDocument(self, doc):
        settle_states(doc)

    def slotRedoDocument(self, doc):
        settle_states(doc)


_UNDO_OBSERVER = _UndoObserver()
FreeCAD.addDocumentObserver(_UNDO_OBSERVER)


def _one_line(exc):
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def stage_params(**values):
    """``ReconstructionParams`` from the paper's defaults and the given fields."""
    from core.params import ReconstructionParams

    return ReconstructionParams.from_dict(values)
