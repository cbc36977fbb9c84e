# SPDX-License-Identifier: LGPL-2.1-or-later
"""Checks and atomic writes for output files: never half-written, never over an input."""
import contextlib
import contextvars
import json
import os
import signal
import tempfile
import threading

from core.errors import ParameterError


def check_output_path(path, inputs=(), what="output"):
    """Raise ``ParameterError`` unless ``path`` can be written without touching an input.

    Parameters
    ----------
    path : str or os.PathLike, the file to be written.
    inputs : iterable of paths that must never be overwritten.
    what : str, used in the message ("STEP file", "report", ...).

    Returns
    -------
    str, the absolute path.
    """
    target = os.path.abspath(os.fspath(path))
    folder = os.path.dirname(target)
    if not os.path.isdir(folder):
        raise ParameterError(f"cannot write the {what} {target}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ParameterError(f"cannot write the {what} {target}: folder {folder} is not writable")
    if os.path.isdir(target):
        raise ParameterError(f"cannot write the {what} {target}: it is a folder")
    for source in inputs:
        if source is not None and same_file(target, source):
            raise ParameterError(f"refusing to overwrite the input file {os.fspath(source)} "
                                 f"with the {what} {target}")
    return target


def same_file(a, b):
    """True if paths ``a`` and ``b`` name one file (the same path, a link to it, or a hard link)."""
    a, b = os.path.realpath(os.fspath(a)), os.path.realpath(os.fspath(b))
    if a == b:
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def new_file_mode(target):
    """Permission bits for an output: those of the file it replaces, else 0o666 minus umask."""
    if os.path.exists(target):
        return os.stat(target).st_mode & 0o777
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_output(path, inputs=(), what="output"):
    """Write an output file through a temporary file in its folder and one rename.

    The path is checked first (:func:`check_output_path`: never over one of ``inputs``).
    The block writes the temporary file, whose path it is given; when the block ends
    normally the file is flushed to disk, gets the permissions of the file it replaces
    (else the umask's) and is renamed over ``path``; on any exception (also Ctrl-C) it is
    removed and an existing ``path`` is left untouched. Inside an
    :func:`output_transaction` the rename waits for the end of the transaction.

    Parameters
    ----------
    path : str or os.PathLike, the output file.
    inputs : iterable of paths that must never be overwritten.
    what : str, names the file in messages ("STEP file", "report", ...).

    Yields
    ------
    str, the temporary file (next to ``path``, ending in ``.tmp`` plus ``path``'s suffix,
    so writers that choose the format by suffix see the right one); it exists and is empty.

    Raises
    ------
    ParameterError from :func:`check_output_path`.
    """
    target = check_output_path(path, inputs, what)
    with output_transaction():
        pending = _PENDING.get()
        with interrupts_held():
            temporary = _new_temporary(target)
            pending.append((temporary, target))
        try:
            yield temporary
        except BaseException:
            with interrupts_held():
                pending.remove((temporary, target))
                _remove_quietly(temporary)
            raise


@contextlib.contextmanager
def output_transaction():
    """Make the outputs written in the block (:func:`atomic_output`) appear together or not at all.

    Each file is written to its temporary file as usual; when the block ends normally all of
    them are flushed to disk and renamed over their targets, with Ctrl-C held back during the
    renames (a Ctrl-C then arrives too late to stop the run and is dropped: the outputs are
    complete). When the block ends with an exception (an error, Ctrl-C) every temporary file
    is removed and no target is touched. A transaction inside another joins the outer one.
    A file written in the block exists at its path only after the block: read it back after.

    Raises
    ------
    OSError when flushing or renaming fails; the temporary files not yet renamed are removed.
    """
    if _PENDING.get() is not None:
        yield
        return
    pending = []
    token = _PENDING.set(pending)
    try:
        yield
        for temporary, target in pending:
            with open(temporary, "rb+") as stream:
                os.fsync(stream.fileno())
            os.chmod(temporary, new_file_mode(target))
        with interrupts_held(redeliver=False):
            while pending:
                temporary, target = pending[0]
                os.replace(temporary, target)
                _COMMITTED.append(os.path.abspath(target))
                pending.pop(0)
    finally:
        _PENDING.reset(token)
        with interrupts_held():
            for temporary, _ in pending:
                _remove_quietly(temporary)


@contextlib.contextmanager
def interrupts_held(redeliver=True):
    """Hold Ctrl-C (SIGINT) back during the block, for bookkeeping that must not stop halfway.

    Only in the main thread while a Python SIGINT handler is installed (elsewhere none runs).
    A Ctrl-C during the block is handed to that handler when the block ends if ``redeliver``
    (Python's own raises ``KeyboardInterrupt`` then), else it is dropped.
    """
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield
        return
    caught = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(frame))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught and redeliver:
        previous(signal.SIGINT, caught[0])


_COMMITTED = []
"""Targets renamed into place by the transactions of this process, in order."""


def committed_count():
    """How many outputs the transactions of this process have put in place so far: a
    Ctrl-C that stops a command after its transaction must not say that nothing was
    written (compare the count before and after)."""
    return len(_COMMITTED)


_PENDING = contextvars.ContextVar("polycube_pending_outputs", default=None)
"""``[(temporary, target), ...]`` of the innermost :func:`output_transaction`, else None."""


def _new_temporary(target):
    """Create an empty temporary file next to ``target``; its path."""
    suffix = ".tmp" + os.path.splitext(target)[1]
    handle, temporary = tempfile.mkstemp(prefix="." + os.path.basename(target) + ".",
                                         suffix=suffix, dir=os.path.dirname(target))
    os.close(handle)
    return temporary


def _remove_quietly(path):
    with contextlib.suppress(FileNotFoundError):
        os.remove(path)


def write_text_atomic(path, text, inputs=(), what="output"):
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_output`).

    Returns
    -------
    str, the absolute path written.
    """
    with atomic_output(path, inputs, what) as temporary:
        with open(temporary, "w", encoding="utf-8") as stream:
            stream.write(text)
    return os.path.abspath(os.fspath(path))


def write_json_atomic(path, data, inputs=(), what="report"):
    """Write ``data`` as indented JSON, atomically (see :func:`write_text_atomic`)."""
    return write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False) + "\n", inputs, what)
