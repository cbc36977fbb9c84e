# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reading target meshes from STL (ASCII/binary), OBJ, PLY and OFF files.

Reading only parses the file; ``core.validate`` decides whether the mesh is usable.
The input file is opened read-only and never modified. OBJ and ASCII STL are parsed
here, strictly (a malformed record is an error naming its line, never skipped); binary
STL, PLY and OFF by trimesh, after the binary STL's size is checked against its count.
"""
import os

import numpy as np

from core.errors import InvalidMeshError

SUPPORTED_EXTENSIONS = ("stl", "obj", "ply", "off")
ASCII_STL_KEYWORDS = ("solid", "facet", "outer", "vertex", "endloop", "endfacet", "endsolid", "end")
"""The first words of the lines of an ASCII STL file (some writers spell ``end loop``)."""


def read_triangle_soup(path):
    """Read a triangle mesh file without any repair or vertex merging.

    Parameters
    ----------
    path : str or os.PathLike
        ``.stl``, ``.obj``, ``.ply`` or ``.off`` file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64, polygons of OBJ/PLY/OFF files are fan-triangulated.

    Raises
    ------
    InvalidMeshError
        ``reason='unreadable'`` (missing, unreadable or corrupt file),
        ``reason='format'`` (unsupported extension or a malformed OBJ/ASCII STL record)
        or ``reason='empty'``.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if ext not in SUPPORTED_EXTENSIONS:
        raise InvalidMeshError(
            f"{path}: unsupported file type '.{ext}'; expected one of "
            + ", ".join("." + e for e in SUPPORTED_EXTENSIONS), reason="format")
    if os.path.isdir(path):
        raise InvalidMeshError(f"{path}: is a folder, not a mesh file", reason="unreadable")
    if not os.path.isfile(path):
        raise InvalidMeshError(f"{path}: no such file", reason="unreadable")
    if os.path.getsize(path) == 0:
        raise InvalidMeshError(f"{path}: the file is empty (0 bytes)", reason="empty")
    if ext == "obj":
        vertices, faces = _read_obj(path)
    elif ext == "stl" and _is_ascii_stl(path):
        vertices, faces = _read_ascii_stl(path)
    else:
        vertices, faces = _read_with_trimesh(path, ext)
    if len(faces) == 0 or len(vertices) == 0:
        raise InvalidMeshError(f"{path}: the file contains no triangles", reason="empty")
    bad = (faces < 0) | (faces >= len(vertices))
    if bad.any():
        f = int(np.flatnonzero(bad.any(axis=1))[0])
        raise InvalidMeshError(
            f"{path}: face {f} refers to a vertex index outside 0..{len(vertices) - 1}",
            reason="unreadable", count=int(bad.any(axis=1).sum()), examples=[f])
    return vertices, faces


def _read_with_trimesh(path, ext):
    import trimesh

    if ext == "stl":
        _check_binary_stl_length(path)
    try:
        loaded = trimesh.load(path, file_type=ext, process=False, force="mesh")
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InvalidMeshError(f"{path}: cannot parse as {ext.upper()}: {exc}",
                               reason="unreadable") from exc
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    return vertices.reshape(-1, 3), faces.reshape(-1, 3)


def _read_text(path, encoding):
    try:
        with open(path, "rb") as handle:
            return handle.read().decode(encoding)
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidMeshError(f"{path}: cannot read as text: {exc}", reason="unreadable") from None


def _read_obj(path):
    """Vertices and fan-triangulated faces of an OBJ file (``core.polymesh_io.parse_obj``)."""
    from core.geometry import triangulate
    from core.polymesh_io import parse_obj

    text = _read_text(path, "utf-8")
    if "\x00" in text:
        raise InvalidMeshError(f"{path}: binary data, not an OBJ text file", reason="unreadable")
    mesh = parse_obj(text, name=path)
    return mesh.vertices, triangulate(mesh.face_vertices, mesh.face_offsets)


def _is_ascii_stl(path):
    """True if the file starts with ``solid`` and its first kilobyte has no NUL byte (a
    binary STL's triangle count and coordinates practically always have one; its 80-byte
    header may start with ``solid`` too)."""
    with open(path, "rb") as handle:
        chunk = handle.read(1024)
    return chunk.lstrip()[:5].lower() == b"solid" and b"\0" not in chunk


def _read_ascii_stl(path):
    """Vertices (three per facet, unmerged) and faces of an ASCII STL file.

    Every line must start with one of :data:`ASCII_STL_KEYWORDS`, every ``vertex`` line
    hold three numbers and every facet exactly three vertices; the error names the line.
    """
    lines = _read_text(path, "latin-1").splitlines()
    words = [line.split() for line in lines]
    first = np.array([w[0].lower() if w else "" for w in words])
    lengths = np.array([len(w) for w in words], dtype=np.int64)
    unknown = np.flatnonzero(~np.isin(first, ("",) + ASCII_STL_KEYWORDS))
    if len(unknown):
        _stl_line_error(path, lines, unknown[0], "not an ASCII STL record")
    vertex_lines = np.flatnonzero(first == "vertex")
    facet_lines = np.flatnonzero(first == "facet")
    short = vertex_lines[lengths[vertex_lines] != 4]
    if len(short):
        _stl_line_error(path, lines, short[0], "a vertex needs exactly 3 coordinates")
    try:
        vertices = np.array([words[i][1:] for i in vertex_lines.tolist()], dtype=np.float64)
    except ValueError:
        bad = next(i for i in vertex_lines.tolist() if not _are_numbers(words[i][1:]))
        _stl_line_error(path, lines, bad, "a vertex coordinate is not a number")
    owner = np.searchsorted(facet_lines, vertex_lines, side="right") - 1
    if (owner < 0).any():
        _stl_line_error(path, lines, vertex_lines[np.argmax(owner < 0)], "a vertex outside any facet")
    if len(facet_lines) == 0:
        raise InvalidMeshError(f"{path}: the file contains no triangles", reason="empty")
    per_facet = np.bincount(owner, minlength=len(facet_lines))
    wrong = np.flatnonzero(per_facet != 3)
    if len(wrong):
        k = int(wrong[0])
        _stl_line_error(path, lines, facet_lines[k],
                        f"facet {k} has {per_facet[k]} vertices, a triangle needs 3")
    return vertices.reshape(-1, 3), np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)


def _are_numbers(tokens):
    try:
        [float(t) for t in tokens]
    except ValueError:
        return False
    return True


def _stl_line_error(path, lines, index, what):
    index = int(index)
    raise InvalidMeshError(f"{path} line {index + 1}: {what}: {lines[index].strip()[:80]!r}",
                           reason="format", count=1, examples=[index + 1])


def _check_binary_stl_length(path):
    """Reject a binary STL whose size disagrees with its triangle count (truncated or
    corrupt file: trimesh would fall back to reading it as text)."""
    size = os.path.getsize(path)
    with open(path, "rb") as handle:
        head = handle.read(84)
    if len(head) < 84:
        raise InvalidMeshError(f"{path}: binary STL shorter than its 84-byte header "
                               f"({size} bytes): the file is truncated", reason="unreadable")
    count = int(np.frombuffer(head[80:84], dtype="<u4")[0])
    expected = 84 + 50 * count
    if size != expected:
        state = "truncated" if size < expected else "corrupt (the count or the size is wrong)"
        raise InvalidMeshError(
            f"{path}: binary STL declares {count} triangles ({expected} bytes) but has "
            f"{size} bytes: the file is {state}", reason="unreadable")
