# SPDX-License-Identifier: LGPL-2.1-or-later
"""Bytes in and out of FreeCAD readers and writers that only take a file path.

``Mesh.Mesh.read``/``write`` and ``Part.Shape.importBinary``/``exportBinary`` work on paths;
the stage process and FreeCAD's process exchange the bytes. Each call goes through a file in
a temporary folder of its own, removed afterwards. This module imports no FreeCAD.
"""
import os
import tempfile


def bytes_written_by(write, filename):
    """bytes: what ``write(path)`` writes to a temporary file called ``filename`` (its suffix
    may choose the format)."""
    with tempfile.TemporaryDirectory(prefix="polycube-") as folder:
        path = os.path.join(folder, filename)
        write(path)
        with open(path, "rb") as handle:
            return handle.read()


def read_from_bytes(data, filename, read):
    """``read(path)`` of a temporary file called ``filename`` holding ``data`` (bytes)."""
    with tempfile.TemporaryDirectory(prefix="polycube-") as folder:
        path = os.path.join(folder, filename)
        with open(path, "wb") as handle:
            handle.write(data)
        return read(path)
