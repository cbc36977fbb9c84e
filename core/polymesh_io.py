# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polygon OBJ reading and writing that keeps n-gons (trimesh would triangulate).

Only ``v`` and ``f`` records are used; texture coordinates, normals, groups and
materials are ignored. Face corners may be written ``a``, ``a/b``, ``a//c`` or
``a/b/c``; negative indices count back from the last vertex read so far.
"""
import os

import numpy as np

from core.errors import InvalidMeshError
from core.output_files import write_text_atomic
from core.types import PolyMesh


def parse_obj(text, name="OBJ"):
    """Parse polygon OBJ text into a PolyMesh (no topological validation).

    Raises
    ------
    InvalidMeshError
        ``format`` on a malformed record or out-of-range index, ``empty`` when there
        are no vertices or no faces.
    """
    verts = []
    faces = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        parts = raw.split("#", 1)[0].split()
        if not parts:
            continue
        tag = parts[0]
        try:
            if tag == "v":
                if len(parts) < 4:
                    raise ValueError("a vertex needs 3 coordinates")
                verts.append([float(x) for x in parts[1:4]])
            elif tag == "f":
                if len(parts) < 4:
                    raise ValueError("a face needs at least 3 corners")
                idx = []
                for tok in parts[1:]:
                    i = int(tok.split("/", 1)[0])
                    if i == 0:
                        raise ValueError("OBJ indices start at 1")
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                if min(idx) < 0 or max(idx) >= len(verts):
                    raise ValueError("vertex index out of range")
                faces.append(idx)
        except ValueError as exc:
            raise InvalidMeshError(f"{name} line {lineno}: {exc}: {raw.strip()!r}",
                                   reason="format", count=1, examples=[lineno]) from None
    if not verts or not faces:
        raise InvalidMeshError(f"{name} has {len(verts)} vertices and {len(faces)} faces; "
                               "a mesh needs both", reason="empty")
    return PolyMesh.from_faces(np.array(verts, dtype=np.float64), faces)


def read_polymesh(path):
    """Read a polygon OBJ file (n-gons kept).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    PolyMesh

    Raises
    ------
    InvalidMeshError
        ``unreadable`` if the file cannot be opened or decoded as text, else as
        :func:`parse_obj`.
    """
    try:
        with open(path, "rb") as fh:
            data = fh.read()
        text = data.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidMeshError(f"cannot read {os.fspath(path)!r}: {exc}",
                               reason="unreadable") from None
    if "\x00" in text:
        raise InvalidMeshError(f"{os.fspath(path)!r} is binary, not an OBJ text file",
                               reason="unreadable")
    return parse_obj(text, name=os.path.basename(os.fspath(path)))


def write_polymesh(path, mesh, inputs=()):
    """Write ``mesh`` as a polygon OBJ (coordinates with 17 significant digits, so a
    read-back is bit-identical), atomically and never over one of ``inputs``
    (:func:`core.output_files.write_text_atomic`).

    Returns
    -------
    str, the absolute path written.

    Raises
    ------
    ParameterError
        The folder is missing or not writable, ``path`` is a folder or one of ``inputs``.
    """
    lines = ["# polygon mesh written by polycube_wb"]
    lines += ["v %.17g %.17g %.17g" % tuple(p) for p in np.asarray(mesh.vertices)]
    fv = np.asarray(mesh.face_vertices) + 1
    fo = np.asarray(mesh.face_offsets)
    lines += ["f " + " ".join(map(str, fv[a:b])) for a, b in zip(fo[:-1], fo[1:])]
    return write_text_atomic(path, "\n".join(lines) + "\n", inputs, "base mesh")
