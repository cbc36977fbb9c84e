# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polygon OBJ reading and writing that keeps n-gons (trimesh would triangulate).

Only ``v``, ``f`` and ``t crease`` records are used; texture coordinates, normals, groups
and materials are ignored. Face corners may be written ``a``, ``a/b``, ``a//c`` or
``a/b/c``; negative indices count back from the last vertex read so far.

Sharp creases (``PolyMesh.creases``) are written as OpenSubdiv's OBJ tags (its regression
shapes and ``osd_obj`` reader): ``t crease 2/1 a b 10``, one per crease edge, with
**0-based** vertex indices ``a b`` (OpenSubdiv's convention, unlike the 1-based ``f``
records) and sharpness 10, OpenSubdiv's ``SHARPNESS_INFINITE``. Read back, a sharpness of 10
or more is an infinitely sharp crease and 0 no crease; semi-sharp creases (between) and
other tags (``t corner``, ``t hole``, ...) are refused, since this workbench's subdivision
has no rules for them and ignoring them would change the surface silently.
"""
import os

import numpy as np

from core.errors import InvalidMeshError
from core.output_files import write_text_atomic
from core.types import PolyMesh

INFINITE_SHARPNESS = 10.0
"""OpenSubdiv's ``Sdc::Crease::SHARPNESS_INFINITE``: the sharpness written for crease edges."""


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
    creases = []
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
            elif tag == "t":
                pairs, problem = _crease_pairs(parts)
                if problem:
                    raise ValueError(problem)
                creases.extend(pairs)
        except ValueError as exc:
            raise InvalidMeshError(f"{name} line {lineno}: {exc}: {raw.strip()!r}",
                                   reason="format", count=1, examples=[lineno]) from None
    if not verts or not faces:
        raise InvalidMeshError(f"{name} has {len(verts)} vertices and {len(faces)} faces; "
                               "a mesh needs both", reason="empty")
    mesh = PolyMesh.from_faces(np.array(verts, dtype=np.float64), faces)
    if not creases:
        return mesh
    pairs = np.array(creases, dtype=np.int64)
    outside = np.flatnonzero((pairs < 0).any(axis=1) | (pairs >= len(verts)).any(axis=1))
    if len(outside):
        raise InvalidMeshError(
            f"{name}: {len(outside)} crease tags name vertices outside 0..{len(verts) - 1} "
            f"(crease tags count from 0), e.g. {pairs[outside[:5]].tolist()}",
            reason="format", count=len(outside), examples=pairs[outside[:5]].tolist())
    return PolyMesh(mesh.vertices, mesh.face_vertices, mesh.face_offsets, pairs)


def _crease_pairs(parts):
    """The vertex pairs of one ``t crease 2/1 a b sharpness`` record.

    Returns ``(pairs, problem)``: a list of 0 or 1 pairs and None, or ``([], what is wrong)``
    for other tags, other argument counts and semi-sharp creases (the caller names the line).
    """
    if len(parts) < 2 or parts[1] != "crease":
        return [], f"tag {' '.join(parts[:2])!r} is not supported (only 't crease')"
    if len(parts) != 6 or parts[2] != "2/1":
        return [], ("a crease tag is 't crease 2/1 a b sharpness' (two 0-based vertex indices, "
                    "one sharpness)")
    a, b, sharpness = int(parts[3]), int(parts[4]), float(parts[5])
    if sharpness == 0:
        return [], None
    if not sharpness >= INFINITE_SHARPNESS:
        return [], (f"semi-sharp creases are not supported (sharpness {sharpness:g}; use "
                    f"{INFINITE_SHARPNESS:g}, infinitely sharp, or 0)")
    return [(a, b)], None


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
    read-back is bit-identical; crease edges as ``t crease`` tags, module docstring), atomically and never over one of ``inputs``
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
    if mesh.n_creases:
        lines += ["t crease 2/1 %d %d %g" % (a, b, INFINITE_SHARPNESS)
                  for a, b in np.asarray(mesh.creases, dtype=np.int64).reshape(-1, 2)]
    return write_text_atomic(path, "\n".join(lines) + "\n", inputs, "base mesh")
