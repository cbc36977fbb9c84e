# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reading target meshes from STL (ASCII/binary), OBJ, PLY and OFF files.

Reading only parses the file; ``core.validate`` decides whether the mesh is usable.
The input file is opened read-only and never modified.
"""
import os

import numpy as np

from core.errors import InvalidMeshError

SUPPORTED_EXTENSIONS = ("stl", "obj", "ply", "off")


def read_triangle_soup(path):
    """Read a triangle mesh file without any repair or vertex merging.

    Parameters
    ----------
    path : str or os.PathLike
        ``.stl``, ``.obj``, ``.ply`` or ``.off`` file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64, polygons of OBJ/PLY/OFF files are fan-triangulated by trimesh.

    Raises
    ------
    InvalidMeshError
        ``reason='unreadable'`` (missing, unreadable or corrupt file),
        ``reason='format'`` (unsupported extension) or ``reason='empty'``.
    """
    import trimesh

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if ext not in SUPPORTED_EXTENSIONS:
        raise InvalidMeshError(
            f"{path}: unsupported file type '.{ext}'; expected one of "
            + ", ".join("." + e for e in SUPPORTED_EXTENSIONS), reason="format")
    if not os.path.isfile(path):
        raise InvalidMeshError(f"{path}: no such file", reason="unreadable")
    if os.path.getsize(path) == 0:
        raise InvalidMeshError(f"{path}: the file is empty (0 bytes)", reason="empty")
    _check_binary_stl_length(path, ext)
    try:
        loaded = trimesh.load(path, file_type=ext, process=False, force="mesh")
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InvalidMeshError(f"{path}: cannot parse as {ext.upper()}: {exc}",
                               reason="unreadable") from exc
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(faces) == 0 or len(vertices) == 0:
        raise InvalidMeshError(f"{path}: the file contains no triangles", reason="empty")
    faces = faces.reshape(-1, 3)
    bad = (faces < 0) | (faces >= len(vertices))
    if bad.any():
        f = int(np.flatnonzero(bad.any(axis=1))[0])
        raise InvalidMeshError(
            f"{path}: face {f} refers to a vertex index outside 0..{len(vertices) - 1}",
            reason="unreadable", count=int(bad.any(axis=1).sum()), examples=[f])
    return vertices, faces


def _check_binary_stl_length(path, ext):
    """Reject a binary STL whose size disagrees with its triangle count (truncated file)."""
    if ext != "stl":
        return
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(84)
    if head[:5].lower() == b"solid" and _looks_like_ascii(path):
        return
    if len(head) < 84:
        raise InvalidMeshError(f"{path}: binary STL shorter than its 84-byte header "
                               f"({size} bytes): the file is truncated", reason="unreadable")
    count = int(np.frombuffer(head[80:84], dtype="<u4")[0])
    expected = 84 + 50 * count
    if size < expected:
        raise InvalidMeshError(
            f"{path}: binary STL declares {count} triangles ({expected} bytes) but has only "
            f"{size} bytes: the file is truncated", reason="unreadable")


def _looks_like_ascii(path):
    """True if the first kilobyte of the file is printable text with a 'facet' keyword."""
    with open(path, "rb") as handle:
        chunk = handle.read(1024)
    try:
        text = chunk.decode("ascii")
    except UnicodeDecodeError:
        return False
    return "facet" in text or len(chunk) < 1024
