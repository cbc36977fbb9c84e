# SPDX-License-Identifier: LGPL-2.1-or-later
"""Batch reconstruction: many meshes, the same pipeline as ``reconstruct``, one row per mesh.

Each mesh runs in its own process (:mod:`polycube_wb.batch_worker`) with a time cap and a
memory cap (:mod:`polycube_wb.batch_memory`), either on this machine (``jobs`` at once) or on
the workers of a Dask distributed scheduler, which run the same process on a path they
share. A mesh whose report says it was done with the same parameters, and whose outputs are
all there and newer than the input, is skipped unless ``force``. One failing mesh never
stops the others.
"""
import dataclasses
import fnmatch
import glob
import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass, field

from core.errors import ParameterError
from core.output_files import write_json_atomic
from core.params import ReconstructionParams
from core.threads import CORES_VARIABLE, usable_cores

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off")
OUTPUT_SUFFIXES = {"step": ".step", "base_mesh": ".base.obj", "labels": ".labels.ply",
                   "report": ".json", "thumbnail": ".png"}
"""Per-mesh output file names: ``OUT_DIR/<name><suffix>``."""
RESULT_OUTPUTS = ("step", "base_mesh", "labels", "thumbnail")
"""Outputs checked for freshness when the report lists them."""
RERUN_STATUSES = ("timeout", "crashed")
"""Batch statuses of a mesh that say nothing about the mesh itself: always run again (so
does a mesh stopped by its memory cap, ``batch.memory_limit_exceeded`` in its report)."""
ROW_PREFIX = "ROW "
"""A worker's last stdout line: this, then its row as JSON (``polycube_wb.batch_worker``)."""
CANCELLED_EXIT = 130
"""Exit code of a worker stopped by Ctrl-C (SIGINT): no row, no output, no report."""
AUTO_MEMORY = "auto"
REDRAW_SECONDS = 1.0
"""The progress line is redrawn at least this often while meshes run locally."""


@dataclass
class MeshJob:
    """One mesh of a batch and where its outputs go.

    source : absolute path of the target mesh.
    name : output stem (the file name without its suffix, made unique in the batch).
    out_dir : absolute output folder.
    params : keyword arguments of ``reconstruct_to_step`` (ReconstructionParams fields).
    timeout : seconds the mesh may take, or None.
    memory_mb : resident-memory cap of the mesh's process in MiB, None for none, or
        ``AUTO_MEMORY``: the default share of the machine that runs it with one mesh per
        core (:func:`polycube_wb.batch_memory.default_memory_limit_mb`; Dask workers).
    cores : cores the mesh's process may use (``core.threads.CORES_VARIABLE``), or None for
        all it is given: its share where several meshes run at once.
    """

    source: str
    name: str
    out_dir: str
    params: dict
    timeout: float = None
    memory_mb: float | str | None = None
    cores: int | None = None

    def paths(self):
        """dict of output kind -> absolute path (see ``OUTPUT_SUFFIXES``)."""
        return {kind: os.path.join(self.out_dir, self.name + suffix)
                for kind, suffix in OUTPUT_SUFFIXES.items()}

    def batch_section(self, seconds, status=None, message=""):
        """The report's ``batch`` section: parameters, status and wall time of this mesh."""
        return {"params": self.params, "seconds": round(seconds, 3),
                **({"status": status, "message": message} if status else {})}

    def to_dict(self):
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data):
        return cls(**data)


@dataclass
class MeshRow:
    """One row of the summary (``summary.csv`` / ``summary.html``).

    status : ``ok`` (a STEP solid), ``failed`` (a stage stopped; ``failed_stage`` and
        ``message`` say which and why), ``timeout``, ``crashed`` (the process) or
        ``cancelled`` (its process got Ctrl-C; no report written).
    stage_reached : last stage whose status is ``ok``.
    mean_deviation : fitted surface to target; max_deviation : the larger of the fitted
        surface to the target and the target to it (a missed tip counts); fractions of the
        bbox diagonal.
    outside_volume : fraction of the target volume the fitted surface leaves outside it.
    seconds : wall time of the mesh; peak_memory_mb : peak resident memory of its process in
        MiB (its own ``VmHWM`` at its end; for a process the batch stopped or that died, the
        largest of the batch's readings every ``batch_memory.POLL_SECONDS``).
    skipped : the outputs were up to date and the mesh was not run again.
    """

    name: str
    source: str
    status: str
    triangles: int = None
    genus: int = None
    stage_reached: str = ""
    failed_stage: str = ""
    faces: int = None
    mean_deviation: float = None
    max_deviation: float = None
    outside_volume: float = None
    seconds: float = None
    peak_memory_mb: float = None
    message: str = ""
    thumbnail: str = ""
    skipped: bool = False

    def to_dict(self):
        return dataclasses.asdict(self)


@dataclass
class BatchResult:
    """rows : list of MeshRow in input order; summary_csv, summary_html : paths written."""

    rows: list
    summary_csv: str
    summary_html: str
    seconds: float
    failures: int = field(init=False)

    def __post_init__(self):
        self.failures = sum(row.status != "ok" for row in self.rows)


def collect_inputs(items):
    """Mesh files named by ``items`` (files, folders, glob patterns), sorted, duplicates removed.

    Raises ParameterError naming the item that matches no mesh file.
    """
    found = []
    for item in items:
        if os.path.isdir(item):
            matches = [os.path.join(item, n) for n in sorted(os.listdir(item))
                       if n.lower().endswith(MESH_SUFFIXES)
                       and os.path.isfile(os.path.join(item, n))]
        elif os.path.isfile(item):
            matches = [item]
        else:
            matches = [p for p in sorted(glob.glob(item)) if os.path.isfile(p)
                       and p.lower().endswith(MESH_SUFFIXES)]
        if not matches:
            raise ParameterError(f"batch input {item!r} is not a mesh file, a folder with mesh "
                                 f"files ({', '.join(MESH_SUFFIXES)}) or a pattern matching one")
        found.extend(os.path.abspath(p) for p in matches)
    return list(dict.fromkeys(found))


def load_overrides(path):
    """Per-mesh parameter overrides: JSON ``{"file name or glob": {"param": value, ...}, ...}``.

    Keys are matched against the mesh file's name (``fnmatch``); later keys win. Values are
    ``ReconstructionParams`` fields. Raises ParameterError on unreadable JSON or unknown fields.
    """
    try:
        with open(path, encoding="utf-8") as handle:
            data = json.load(handle)
    except (OSError, ValueError) as exc:
        raise ParameterError(f"cannot read the override file {path}: {exc}") from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise ParameterError(f"override file {path}: expected an object of "
                             f"{{\"pattern\": {{\"parameter\": value}}}}")
    known = {f.name for f in dataclasses.fields(ReconstructionParams)}
    for pattern, values in data.items():
        unknown = sorted(set(values) - known)
        if unknown:
            raise ParameterError(f"override file {path}: pattern {pattern!r} sets unknown "
                                 f"parameter(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    return data


def plan_jobs(sources, out_dir, params, overrides=None, timeout=None, memory_mb=None):
    """One MeshJob per source; output names are the file stems, made unique with ``-2``, ``-3``.

    Raises ParameterError naming the first mesh whose parameters (``params`` with its
    overrides) are out of range, so a bad value stops the batch before any mesh runs.
    """
    out_dir = os.path.abspath(out_dir)
    jobs, used = [], set()
    for source in sources:
        stem = os.path.splitext(os.path.basename(source))[0]
        name, k = stem, 1
        while name in used:
            k += 1
            name = f"{stem}-{k}"
        used.add(name)
        merged = dict(params)
        for pattern, values in (overrides or {}).items():
            if fnmatch.fnmatch(os.path.basename(source), pattern):
                merged.update(values)
        try:
            ReconstructionParams(**merged)
        except ParameterError as exc:
            raise ParameterError(f"parameters of {source}: {exc}") from None
        jobs.append(MeshJob(source, name, out_dir, merged, timeout, memory_mb))
    return jobs


def up_to_date_report(job):
    """The mesh's existing report when its outputs are complete and current, else None.

    Current means: the report was written with the same parameters, after the input was last
    changed, the run was not cut short (timeout, crash, memory cap), and every result file it lists exists
    and is newer than the input.
    """
    paths = job.paths()
    try:
        with open(paths["report"], encoding="utf-8") as handle:
            report = json.load(handle)
        source_time = os.path.getmtime(job.source)
        if os.path.getmtime(paths["report"]) < source_time:
            return None
    except (OSError, ValueError):
        return None
    batch = report.get("batch", {})
    if batch.get("params") != json.loads(json.dumps(job.params)) or \
            batch.get("status") in RERUN_STATUSES or batch.get("memory_limit_exceeded"):
        return None
    for kind in RESULT_OUTPUTS:
        listed = report.get("outputs", {}).get(kind)
        if listed and not (os.path.isfile(listed) and os.path.getmtime(listed) >= source_time):
            return None
    return report


def row_from_report(job, report, skipped=False):
    """The summary row of a mesh from its report (see :class:`MeshRow`)."""
    stages = report.get("stages", {})
    source = report.get("input", {})
    ok = [name for name, entry in stages.items() if entry.get("status") == "ok"]
    failed = _first_failed(stages)
    batch = report.get("batch", {})
    fit, brep = report.get("fit", {}), report.get("brep", {})
    has_step = bool(report.get("outputs", {}).get("step"))
    status = batch.get("status") or ("ok" if has_step and failed is None else "failed")
    message = batch.get("message") or (failed[1].get("message", "") if failed else "")
    if status == "ok" and report.get("thumbnail_error"):
        message = f"no thumbnail: {report['thumbnail_error']}"
    thumbnail = report.get("outputs", {}).get("thumbnail") or ""
    return MeshRow(name=job.name, source=job.source, status=status,
                   triangles=source.get("triangles"), genus=source.get("genus"),
                   stage_reached=ok[-1] if ok else "", failed_stage=failed[0] if failed else "",
                   faces=brep.get("faces"), mean_deviation=fit.get("mean_distance"),
                   max_deviation=_larger(fit.get("max_distance"), fit.get("target_max_distance")),
                   outside_volume=fit.get("outside_volume_fraction"),
                   seconds=batch.get("seconds"), peak_memory_mb=report.get("peak_memory_mb"),
                   message=message, thumbnail=os.path.basename(thumbnail) if thumbnail else "",
                   skipped=skipped)


def _first_failed(stages):
    """``(name, entry)`` of the first failed stage of a report's ``stages``, or None."""
    return next(((name, entry) for name, entry in stages.items()
                 if entry.get("status") == "failed"), None)


def _larger(a, b):
    """The larger of two optional figures (None where neither is known)."""
    known = [x for x in (a, b) if x is not None]
    return max(known) if known else None


def run_isolated(job):
    """Run one mesh in a fresh worker process with the job's time and memory caps; its MeshRow.

    Used locally and, unchanged, as the task a Dask worker runs. A process that runs over
    ``job.timeout`` is killed (status ``timeout``); one whose resident memory passes
    ``job.memory_mb`` is killed too (status ``failed``, "memory limit of N MB exceeded at
    stage S"); one that dies without a row is ``crashed``, with the end of its stderr as the
    message. Each gets a report naming the stage it was in, with the largest of the resident
    memory readings as its peak memory.
    """
    from polycube_wb.batch_memory import default_memory_limit_mb, memory_message
    from polycube_wb.stage_lines import STAGE_PREFIX

    if job.memory_mb == AUTO_MEMORY:
        job = dataclasses.replace(job, memory_mb=default_memory_limit_mb(os.cpu_count() or 1))
    package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [package_root, os.environ.get("PYTHONPATH")])))
    if job.cores:
        env[CORES_VARIABLE] = str(job.cores)
    started = time.perf_counter()
    process = subprocess.Popen([_python(), "-m", "polycube_wb.batch_worker"],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=env, cwd=package_root)
    stdout, stderr, stop, peak = _watch(process, job, started)
    stage = _last_stage(stderr, STAGE_PREFIX)
    if stop == "timeout":
        return _cut_short(job, started, "timeout",
                          f"stopped after the {job.timeout:g} s time cap at stage {stage}", stage,
                          peak_mb=peak)
    if stop == "memory":
        return _cut_short(job, started, "failed", memory_message(job.memory_mb, stage), stage,
                          {"memory_limit_exceeded": True}, peak)
    if process.returncode in (CANCELLED_EXIT, -signal.SIGINT):
        return _cancelled(job, started, stage)
    rows = [line for line in stdout.splitlines() if line.startswith(ROW_PREFIX)]
    if process.returncode != 0 or not rows:
        lines = [line for line in stderr.strip().splitlines() if not line.startswith(STAGE_PREFIX)]
        tail = " ".join(lines[-3:]) or "no output"
        return _cut_short(job, started, "crashed", f"worker process exited with code "
                                                   f"{process.returncode} at stage {stage}: {tail}",
                          stage, peak_mb=peak)
    return MeshRow(**json.loads(rows[-1][len(ROW_PREFIX):]))


def _watch(process, job, started):
    """Feed the job to the worker and wait, killing it at the time or memory cap.

    Returns ``(stdout, stderr, stop, peak_mb)``: ``stop`` is None (it ended by itself),
    ``"timeout"`` or ``"memory"``; ``peak_mb`` is the largest of its resident memory readings
    (every ``POLL_SECONDS`` where the platform allows, else None).
    """
    from polycube_wb.batch_memory import POLL_SECONDS, can_watch_memory, resident_memory_mb

    watch_memory = can_watch_memory()
    feed = json.dumps(job.to_dict())
    peak, stop = None, None
    while True:
        try:
            stdout, stderr = process.communicate(feed, timeout=POLL_SECONDS)
            return stdout, stderr, stop, peak
        except subprocess.TimeoutExpired:
            feed = None
        if stop is None and watch_memory:
            resident = resident_memory_mb(process.pid)
            peak = max(peak or 0.0, resident or 0.0) or None
            if job.memory_mb and resident is not None and resident > job.memory_mb:
                stop = "memory"
        if stop is None and job.timeout and time.perf_counter() - started > job.timeout:
            stop = "timeout"
        if stop is not None:
            process.kill()


def _last_stage(stderr, prefix):
    """The stage a worker last announced on its stderr text; "startup" if none."""
    stages = [line[len(prefix):].strip() for line in stderr.splitlines()
              if line.startswith(prefix)]
    return stages[-1] if stages else "startup"


def _python():
    """This process's Python interpreter, which runs the per-mesh processes.

    Inside FreeCAD (GUI or freecadcmd) ``sys.executable`` is FreeCAD itself, which cannot run
    ``-m`` modules; the batch then needs the project's ``.venv`` interpreter.
    """
    if not os.path.basename(sys.executable).lower().startswith("python"):
        raise RuntimeError(f"the batch runs each mesh with a Python interpreter, but this "
                           f"process runs {sys.executable}; start it from the project's "
                           f".venv: .venv/bin/python -m polycube_wb batch ...")
    return sys.executable


def _cut_short(job, started, status, message, stage, batch_extra=None, peak_mb=None):
    stages = {stage: {"status": "failed", "seconds": 0.0, "message": message}}
    report = {"input": {"file": job.source}, "stages": stages, "outputs": {},
              "batch": {**job.batch_section(time.perf_counter() - started, status, message),
                        **(batch_extra or {})}}
    if peak_mb is not None:
        report["peak_memory_mb"] = round(peak_mb, 1)
    write_json_atomic(job.paths()["report"], report, (job.source,))
    return row_from_report(job, report)


def _cancelled(job, started, stage):
    """The row of a mesh whose process a Ctrl-C (SIGINT) stopped; no report is written, so an
    earlier report and outputs of the mesh stay as they were."""
    message = f"cancelled at stage {stage}"
    report = {"input": {"file": job.source}, "outputs": {},
              "stages": {stage: {"status": "failed", "seconds": 0.0, "message": message}},
              "batch": job.batch_section(time.perf_counter() - started, "cancelled", message)}
    return row_from_report(job, report)


def run_batch(jobs, jobs_at_once=1, scheduler=None, force=False, progress=None, on_row=None):
    """Run every job not up to date; returns the MeshRows in job order.

    Parameters
    ----------
    jobs : list of MeshJob.
    jobs_at_once : int >= 1, meshes run at the same time on this machine.
    scheduler : address of a Dask distributed scheduler (``tcp://host:8786``) or a
        ``distributed.Client``; the work goes to its workers instead, ``jobs_at_once`` unused.
    force : run meshes whose outputs are up to date too.
    progress : callable(done, failed, running, total) or None, called as meshes finish.
    on_row : callable(MeshRow) or None, called with each mesh's row when it is known
        (skipped ones first).
    """
    rows = [None] * len(jobs)
    todo = []
    for k, job in enumerate(jobs):
        report = None if force else up_to_date_report(job)
        if report is None:
            todo.append(k)
        else:
            rows[k] = row_from_report(job, report, skipped=True)
            if on_row:
                on_row(rows[k])
    counts = {"done": len(jobs) - len(todo), "failed": sum(r.status != "ok" for r in rows if r)}

    def redraw():
        if progress:
            running = min(len(jobs) - counts["done"], width)
            progress(counts["done"], counts["failed"], running, len(jobs))

    def finished(k, row):
        rows[k] = row
        if on_row:
            on_row(row)
        counts["done"] += 1
        counts["failed"] += row.status != "ok"
        redraw()

    if scheduler is not None:
        width = len(todo)
        _run_on_dask(scheduler, _sharing_cores(jobs, 1), todo, finished)
    else:
        width = max(1, int(jobs_at_once))
        jobs = _sharing_cores(jobs, max(1, usable_cores() // width) if width > 1 else None)
        redraw()
        with ThreadPoolExecutor(max_workers=width) as pool:
            futures = {pool.submit(run_isolated, jobs[k]): k for k in todo}
            pending = set(futures)
            while pending:
                ready, pending = wait(pending, timeout=REDRAW_SECONDS, return_when=FIRST_COMPLETED)
                for future in sorted(ready, key=futures.get):
                    finished(futures[future], future.result())
                if not ready:
                    redraw()
    return rows


def _sharing_cores(jobs, cores):
    """The ``jobs`` with ``cores`` each, unless a job sets its own: a Dask worker runs one
    mesh per core, a local batch of ``jobs_at_once`` meshes gives each its share of the cores."""
    return [job if job.cores else dataclasses.replace(job, cores=cores) for job in jobs]


def _run_on_dask(scheduler, jobs, todo, finished):
    try:
        from distributed import Client, as_completed as dask_completed
    except ImportError:
        raise ParameterError("--scheduler needs the Dask distributed package "
                             "(pip install 'dask[distributed]' into the .venv)") from None
    client = scheduler if isinstance(scheduler, Client) else Client(scheduler, timeout="30s")
    try:
        futures = {client.submit(run_isolated, jobs[k], key=f"polycube-{k}-{jobs[k].name}",
                                 pure=False): k for k in todo}
        for future in dask_completed(futures):
            finished(futures[future], future.result())
    finally:
        if client is not scheduler:
            client.close()


def run_batch_command(inputs, out_dir, params, overrides_path=None, jobs=1, timeout=None,
                      memory_mb=None, scheduler=None, force=False, progress=None):
    """The ``batch`` command: collect, plan, run, and write both summaries into ``out_dir``.

    Parameters
    ----------
    inputs : list of mesh files, folders or glob patterns.
    out_dir : output folder (created when missing; its parent must exist).
    params : keyword arguments of ``reconstruct_to_step`` for every mesh.
    overrides_path : optional JSON of per-mesh parameters (see :func:`load_overrides`).
    jobs, scheduler, force : see :func:`run_batch`; timeout : see :class:`MeshJob`.
    memory_mb : cap per mesh process in MiB; 0 for none; None for the default share of the
        RAM per mesh at once (:func:`polycube_wb.batch_memory.default_memory_limit_mb`),
        on a Dask worker that of its own machine with one mesh per core.
    progress : None, or a reporter with ``update(done, failed, running, total)``, ``row(row)``
        and ``close()``: ``polycube_wb.batch_progress.ProgressBar`` or ``ProgressLines``.

    Returns
    -------
    BatchResult
    """
    from polycube_wb.batch_memory import default_memory_limit_mb
    from polycube_wb.batch_summary import write_summary_csv, write_summary_html

    started = time.perf_counter()
    sources = collect_inputs(inputs)
    overrides = load_overrides(overrides_path) if overrides_path else None
    out_dir = os.path.abspath(out_dir)
    if not os.path.isdir(out_dir) and not os.path.isdir(os.path.dirname(out_dir)):
        raise ParameterError(f"cannot create the output folder {out_dir}: its parent "
                             f"does not exist")
    for source in sources:
        if os.path.dirname(source) == out_dir and \
                source.endswith(tuple(OUTPUT_SUFFIXES.values())):
            raise ParameterError(f"input {source} is in the output folder and could be "
                                 f"overwritten; choose another output folder")
    if memory_mb is None:
        memory_mb = AUTO_MEMORY if scheduler is not None else default_memory_limit_mb(jobs)
    jobs_list = plan_jobs(sources, out_dir, params, overrides, timeout, memory_mb or None)
    if not os.path.isdir(out_dir):
        os.mkdir(out_dir)
    rows = run_batch(jobs_list, jobs, scheduler, force, progress.update if progress else None,
                     progress.row if progress else None)
    if progress:
        progress.close()
    csv_path = write_summary_csv(os.path.join(out_dir, "summary.csv"), rows, sources)
    html_path = write_summary_html(os.path.join(out_dir, "summary.html"), rows, sources)
    return BatchResult(rows, csv_path, html_path, time.perf_counter() - started)
