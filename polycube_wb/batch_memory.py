# SPDX-License-Identifier: LGPL-2.1-or-later
"""The batch's memory cap: a resident-memory limit per mesh process, watched from outside it.

The process that starts a mesh's worker (the batch, or a Dask worker) reads the worker's
resident memory every ``POLL_SECONDS`` and kills it once it passes the cap; the row then says
"memory limit of N MB exceeded at stage S". The cap is on the same quantity as the summary's
peak memory (resident set, MiB). A worker may pass the cap by what it allocates within one
poll before it is stopped.

An address-space limit inside the worker (``RLIMIT_AS``) is not used: the libraries do not
all fail cleanly when an allocation is refused. OpenBLAS's ``blas_memory_alloc`` retries a
refused work buffer forever, and manifold3d's TBB spins in ``sched_yield`` after a refused
``cache_aligned_allocate`` (both seen under gdb), so a capped worker
could hang until its time cap instead of failing.
"""
import os

DEFAULT_SHARE = 0.8
"""Fraction of the machine's RAM the meshes running at once may use together."""
MIN_DEFAULT_MB = 512.0
"""Floor of the default cap (a worker with its libraries loaded is about 200 MiB)."""
POLL_SECONDS = 0.05
"""How often a running worker's resident memory is read."""


def machine_memory_mb():
    """Physical memory of this machine in MiB, or None where the platform does not say."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2.0**20
    except (AttributeError, OSError, ValueError):
        return None


def default_memory_limit_mb(jobs_at_once):
    """The default cap per mesh process in MiB: a share of the RAM per mesh running at once.

    ``DEFAULT_SHARE`` of the machine's RAM divided by ``jobs_at_once``, at least
    ``MIN_DEFAULT_MB``, whole MiB; None (no cap) when the machine's RAM is unknown.
    """
    total = machine_memory_mb()
    if total is None:
        return None
    return float(max(MIN_DEFAULT_MB, int(DEFAULT_SHARE * total / max(1, int(jobs_at_once)))))


def can_watch_memory():
    """Whether this platform lets :func:`resident_memory_mb` read another process (Linux)."""
    return os.path.isfile("/proc/self/status")


def resident_memory_mb(pid):
    """Resident memory of process ``pid`` in MiB (Linux ``VmRSS``), or None once it is gone."""
    try:
        with open(f"/proc/{int(pid)}/status", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def memory_message(limit_mb, stage):
    """The row's message of a mesh stopped by its cap."""
    return f"memory limit of {limit_mb:g} MB exceeded at stage {stage}"
