# SPDX-License-Identifier: LGPL-2.1-or-later
"""The reconstruction pipeline: chains the core stages (``core.stages``) and builds the report.

``STAGES`` declares, per stage, its function, the results it reads (fields of
``core.types.PipelineState``) and its report key. The runner calls each stage with those
results, the parameters and the stage's share of the progress, stores the typed result it
returns under the stage's name, and puts the result's report section in the run report.
User errors (``PolycubeInputError``) propagate unchanged; any other exception is recorded as
``failed``, the later stages are marked ``skipped`` and the run stops there.
"""
import resource
import sys
import time
from dataclasses import dataclass

import numpy as np

from core.errors import ParameterError, PolycubeInputError
from core.params import ReconstructionParams
from core.progress import NO_PROGRESS, SubProgress
from core.stages.basemesh import run_basemesh, start_basemesh_ahead
from core.stages.fit import run_fit
from core.stages.frames import run_frames
from core.stages.intake import run_intake
from core.stages.labeling import run_labeling
from core.stages.parts import run_parts
from core.stages.patches import run_patches
from core.threads import single_threaded
from core.types import MeshSource, PipelineState


@dataclass(frozen=True)
class Stage:
    """One pipeline stage.

    name : its name in ``report["stages"]``, ``--stop-after`` and ``PipelineState``.
    run : ``run(*inputs, params, progress) -> result`` (a ``core.types`` stage result).
    inputs : names of the ``PipelineState`` fields passed to ``run``, in order.
    report_key : key of the stage's section in the run report.
    ahead : ``(inputs, start)`` or None: ``start(*inputs, params)`` begins work of the stage
        that needs only the results ``inputs`` (a subset of its own) and returns an object
        with ``close()``, passed to ``run`` as ``ahead=`` and closed once the stage is done.
    """

    name: str
    run: object
    inputs: tuple
    report_key: str
    ahead: tuple = None


STAGES = (
    Stage("intake", run_intake, ("source",), "input"),
    Stage("parts", run_parts, ("intake",), "parts"),
    Stage("frames", run_frames, ("intake", "parts"), "frames"),
    Stage("labeling", run_labeling, ("intake", "parts", "frames"), "labeling"),
    Stage("basemesh", run_basemesh, ("intake", "parts", "frames", "labeling"), "base_mesh",
          (("intake",), start_basemesh_ahead)),
    Stage("fit", run_fit, ("intake", "basemesh"), "fit"),
    Stage("patches", run_patches, ("fit",), "patches"),
)
STAGE_BY_NAME = {stage.name: stage for stage in STAGES}
CORE_STAGES = tuple(stage.name for stage in STAGES)
STOP_AFTER_CHOICES = ("intake", "parts", "labeling", "basemesh", "fit", "solid")

# The last core stage that each --stop-after choice runs ("solid" is built by polycube_wb).
LAST_CORE_STAGE = {"intake": "intake", "parts": "frames", "labeling": "labeling",
                   "basemesh": "basemesh", "fit": "fit", "solid": "patches"}


@dataclass
class PipelineResult:
    """Everything a run produced.

    state : core.types.PipelineState, the typed result of every stage that ran.
    report : dict, the JSON report (see docs/REFERENCE.md, "The report").
    failed : the exception of a stage that failed unexpectedly, else None.
    """

    state: PipelineState
    report: dict
    failed: Exception = None


def peak_memory_mb():
    """Peak resident memory of this process so far, in MiB.

    Linux's ``VmHWM`` (the high-water mark of this process's own address space); the
    ``ru_maxrss`` of ``getrusage`` is not used there because a process started by
    ``fork``/``vfork`` + ``exec`` inherits its parent's peak in it. Elsewhere ``ru_maxrss``
    (bytes on macOS, KiB on other systems).
    """
    try:
        with open("/proc/self/status", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2.0**20 if sys.platform == "darwin" else peak / 1024.0


def _check_inputs(state, stages):
    """Raise ParameterError (a caller's mistake) when a stage's input is neither in ``state``
    nor made by an earlier stage of ``stages``."""
    available = {name for name in ("source",) + CORE_STAGES if getattr(state, name) is not None}
    for name in stages:
        if name not in STAGE_BY_NAME:
            raise ParameterError(f"unknown stage {name!r}; the stages are {', '.join(CORE_STAGES)}")
        missing = [field for field in STAGE_BY_NAME[name].inputs if field not in available]
        if missing:
            raise ParameterError(f"the '{name}' stage needs the {', '.join(missing)} result, "
                                 "which neither the state nor an earlier stage of this run "
                                 "provides")
        available.add(name)


@single_threaded()
def run_stages(state, stages, params, progress=NO_PROGRESS, report=None):
    """Run ``stages`` (names, in order) on ``state``; returns ``(state, report, failed)``.

    The stages run with one BLAS / OpenMP thread (:func:`core.threads.single_threaded`), so
    a run's results do not depend on the machine's core count. The ``Stage.ahead`` work of a
    stage of ``stages`` starts as soon as the results it needs are in ``state`` (the base
    mesh's paired decimation once the intake is done, so it is built on another core while the
    labeling runs) and ends once that stage is done or the run stops.

    Parameters
    ----------
    state : core.types.PipelineState holding at least the inputs the first stages need
        (``source`` for the intake); each stage's result is stored in its field.
    stages : sequence of stage names (``CORE_STAGES``).
    params : core.params.ReconstructionParams.
    progress : core.progress.Progress; each stage gets its share as a ``SubProgress``.
    report : dict to extend (``stages`` and the stages' sections), or None for a new one.

    Returns
    -------
    state : the same PipelineState, with the results of the stages that ran.
    report : dict with ``stages`` (status, message, seconds, CPU seconds and the process's
        peak memory so far in MiB, per stage) and
        each finished stage's section under its ``report_key``.
    failed : the unexpected exception a stage raised (also a ``Cancelled``), else None.

    Raises
    ------
    PolycubeInputError from a stage (bad input); ParameterError when a stage is unknown or
    its inputs are missing.
    """
    _check_inputs(state, stages)
    report = report if report is not None else {"stages": {}}
    report.setdefault("stages", {})
    blocked_by = None
    failed = None
    ahead = {}  # stage name -> its work started ahead (Stage.ahead), until the stage is done
    try:
        for index, name in enumerate(stages):
            _start_ahead(state, stages[index:], params, ahead)
            if blocked_by is not None:
                report["stages"][name] = {"status": "skipped", "seconds": 0.0,
                                          "message": f"needs the '{blocked_by}' stage"}
                continue
            stage = STAGE_BY_NAME[name]
            progress.check_cancel()
            progress.report(name, index / len(stages))
            share = SubProgress(progress, index / len(stages), (index + 1) / len(stages))
            extra = {"ahead": ahead[name]} if name in ahead else {}
            start, cpu_start = time.perf_counter(), time.process_time()
            try:
                result = stage.run(*(getattr(state, field) for field in stage.inputs), params,
                                   share, **extra)
            except PolycubeInputError:
                raise
            except Exception as exc:  # recorded, then reported as an internal failure
                entry = {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
                blocked_by, failed = name, exc
            else:
                entry = {"status": "ok", "message": result.message}
                setattr(state, name, result)
                report[stage.report_key] = result.report
            finally:
                if name in ahead:
                    ahead.pop(name).close()
            entry["seconds"] = round(time.perf_counter() - start, 4)
            # what load does not add
            entry["cpu_seconds"] = round(time.process_time() - cpu_start, 4)
            entry["peak_memory_mb"] = round(peak_memory_mb(), 1)  # of the process, so far
            report["stages"][name] = entry
    finally:
        for work in ahead.values():  # the run stopped before their stages
            work.close()
    progress.report("done", 1.0)
    return state, report, failed


def _start_ahead(state, stages, params, ahead):
    """Start the ``Stage.ahead`` work of those of ``stages`` (names, the rest of the run) whose
    results it needs are in ``state`` now, adding it to ``ahead`` (name -> work)."""
    for name in stages:
        stage = STAGE_BY_NAME[name]
        if stage.ahead is None or name in ahead:
            continue
        inputs, start = stage.ahead
        results = [getattr(state, field) for field in inputs]
        if all(result is not None for result in results):
            ahead[name] = start(*results, params)


def reconstruct(input_path, params=None, progress=NO_PROGRESS, stop_after="solid"):
    """Run the core stages on a target mesh file.

    Parameters
    ----------
    input_path : str or path of the target mesh (STL, OBJ, PLY, OFF).
    params : ReconstructionParams or dict, defaults are the paper's values.
    progress : core.progress.Progress for feedback and cancelling.
    stop_after : one of ``STOP_AFTER_CHOICES``; core stages after it are not run.

    Returns
    -------
    PipelineResult; ``report`` has ``parameters``, ``stages``, the sections of the stages
    that ran (``input``, ``parts``, ``frames``, ``labeling``, ``base_mesh``, ``fit``,
    ``patches``), ``total_seconds`` and ``peak_memory_mb``.

    Raises
    ------
    PolycubeInputError (InvalidMeshError, ParameterError) for bad input.
    """
    if params is None:
        params = ReconstructionParams()
    elif isinstance(params, dict):
        params = ReconstructionParams.from_dict(params)
    if stop_after not in STOP_AFTER_CHOICES:
        raise ParameterError(f"stop_after must be one of {', '.join(STOP_AFTER_CHOICES)}, "
                             f"got {stop_after!r}")
    last = CORE_STAGES.index(LAST_CORE_STAGE[stop_after])
    started = time.perf_counter()
    state = PipelineState(source=MeshSource(str(input_path)))
    report = {"parameters": params.to_dict(), "stages": {}}
    state, report, failed = run_stages(state, CORE_STAGES[:last + 1], params, progress, report)
    report.setdefault("input", {"file": str(input_path)})  # the intake failed or was cancelled
    report["total_seconds"] = round(time.perf_counter() - started, 4)
    report["peak_memory_mb"] = round(peak_memory_mb(), 1)
    return PipelineResult(state, _json_safe(report), failed)


def _json_safe(value):
    """Convert numpy scalars/arrays inside a report to plain Python types."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and value != value:
        return None
    return value
