# SPDX-License-Identifier: LGPL-2.1-or-later
"""Checks and atomic writes for output files: never half-written, never over an input."""
import json
import os
import tempfile

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


def write_text_atomic(path, text, inputs=(), what="output"):
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    target = check_output_path(path, inputs, what)
    handle, temporary = tempfile.mkstemp(prefix="." + os.path.basename(target) + ".",
                                         suffix=".tmp", dir=os.path.dirname(target))
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.chmod(temporary, 0o644)
        os.replace(temporary, target)
    except BaseException:
        if os.path.exists(temporary):
            os.remove(temporary)
        raise
    return target


def write_json_atomic(path, data, inputs=(), what="report"):
    """Write ``data`` as indented JSON, atomically (see :func:`write_text_atomic`)."""
    return write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False) + "\n", inputs, what)
