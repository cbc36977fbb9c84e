# SPDX-License-Identifier: LGPL-2.1-or-later
"""The ``--labels`` PLY file: mesh plus per-face part, label, label direction and colour.

Format (binary little-endian PLY 1.0)::

    element vertex n      property double x, y, z
    element face m        property list uchar int vertex_indices
                          property int part
                          property int label          (0..5 = +X, -X, +Y, -Y, +Z, -Z of the face's frame)
                          property float ax, ay, az   (unit label direction, world coordinates)
                          property uchar red, green, blue   (fixed colour per label)

Vertices are written as float64 (``double``) so coordinates round-trip exactly; faces keep the
order they are given in. MeshLab, CloudCompare and trimesh read it as is.
"""
import os

import numpy as np

from core.errors import ExportError, InvalidMeshError, ParameterError
from core.output_files import atomic_output
from core.segmentation.validity import check_validity

LABEL_COLOURS = np.array([[230, 25, 75],    # +X red
                          [245, 130, 48],   # -X orange
                          [60, 180, 75],    # +Y green
                          [210, 245, 60],   # -Y lime
                          [0, 130, 200],    # +Z blue
                          [145, 30, 180]],  # -Z purple
                         dtype=np.uint8)
"""(6, 3) uint8 face colour of each label."""

_FACE_DTYPE = np.dtype([("n", "u1"), ("v", "<i4", (3,)), ("part", "<i4"), ("label", "<i4"),
                        ("ax", "<f4"), ("ay", "<f4"), ("az", "<f4"),
                        ("red", "u1"), ("green", "u1"), ("blue", "u1")])

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2",
              "int16": "<i2", "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4",
              "uint": "<u4", "uint32": "<u4", "float": "<f4", "float32": "<f4",
              "double": "<f8", "float64": "<f8"}


def write_labels_ply(path, V, F, face_part, face_label, face_frame, protect=()):
    """Write the labels file atomically (``core.output_files.atomic_output``).

    Parameters
    ----------
    path : str, output file.
    V : (n, 3) float vertices (written as float64).
    F : (m, 3) int faces (written as int32, order kept).
    face_part : (m,) int part of each face.
    face_label : (m,) int label 0..5 of each face.
    face_frame : (m, 3, 3) float rows x, y, z of each face's frame (world coordinates).
    protect : str or sequence of str, paths that must not be overwritten (e.g. the input mesh).

    Raises
    ------
    ParameterError if ``path`` is a protected path, its folder is missing or not writable,
    or the arrays do not match;
    ExportError if the file cannot be written.
    """
    if isinstance(protect, (str, os.PathLike)):
        protect = (protect,)
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    face_part = np.asarray(face_part)
    face_label = np.asarray(face_label)
    face_frame = np.asarray(face_frame, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise ParameterError(f"V must be (n, 3) and F (m, 3); got {V.shape} and {F.shape}")
    if face_part.shape != (m,) or face_label.shape != (m,) or face_frame.shape != (m, 3, 3):
        raise ParameterError(f"face_part, face_label must be ({m},) and face_frame ({m}, 3, 3); "
                             f"got {face_part.shape}, {face_label.shape}, {face_frame.shape}")
    bad = np.flatnonzero((face_label < 0) | (face_label > 5))
    if len(bad):
        raise ParameterError(f"face_label has {len(bad)} values outside 0..5 "
                             f"(e.g. face {int(bad[0])}: {int(face_label[bad[0]])})")
    if m and (F.min() < 0 or F.max() >= len(V)):
        raise ParameterError(f"F indexes vertices outside 0..{len(V) - 1}")
    lab = face_label.astype(np.int64)
    sign = np.where(lab % 2 == 0, 1.0, -1.0)
    d = face_frame[np.arange(m), lab // 2] * sign[:, None]
    d /= np.linalg.norm(d, axis=1)[:, None]
    rec = np.zeros(m, dtype=_FACE_DTYPE)
    rec["n"] = 3
    rec["v"] = F
    rec["part"] = face_part
    rec["label"] = lab
    rec["ax"], rec["ay"], rec["az"] = d[:, 0], d[:, 1], d[:, 2]
    col = LABEL_COLOURS[lab]
    rec["red"], rec["green"], rec["blue"] = col[:, 0], col[:, 1], col[:, 2]
    header = ("ply\nformat binary_little_endian 1.0\ncomment polycube labels: label 0..5 = "
              "+X -X +Y -Y +Z -Z of the face frame\n"
              f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {m}\nproperty list uchar int vertex_indices\nproperty int part\n"
              "property int label\nproperty float ax\nproperty float ay\nproperty float az\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    try:
        with atomic_output(path, protect, "labels file") as temporary:
            with open(temporary, "wb") as fh:
                fh.write(header.encode("ascii"))
                fh.write(np.ascontiguousarray(V, dtype="<f8").tobytes())
                fh.write(rec.tobytes())
    except OSError as exc:
        raise ExportError(f"cannot write labels file {path!r}: {exc}") from exc


def _parse_header(fh, path):
    if fh.readline().strip() != b"ply":
        raise InvalidMeshError(f"{path!r} is not a PLY file", "format")
    elements = []
    fmt = None
    while True:
        line = fh.readline()
        if not line:
            raise InvalidMeshError(f"{path!r}: PLY header has no end_header", "format")
        words = line.decode("ascii", "replace").split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "end_header":
            return fmt, elements
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            elements[-1][2].append(words[1:])


def read_labels_ply(path):
    """Read a labels file written by :func:`write_labels_ply` (or any binary little-endian PLY
    with triangle faces and the same per-face properties).

    Returns
    -------
    dict with ``V`` (n, 3) float64, ``F`` (m, 3) int64, ``part`` (m,) int32, ``label`` (m,)
    int32, ``direction`` (m, 3) float64 and ``colour`` (m, 3) uint8.

    Raises
    ------
    InvalidMeshError for files that are not such a PLY (reason ``format``).
    """
    with open(path, "rb") as fh:
        fmt, elements = _parse_header(fh, path)
        if fmt != "binary_little_endian":
            raise InvalidMeshError(f"{path!r}: need binary_little_endian PLY, got {fmt}", "format")
        data = {}
        for name, count, props in elements:
            fields = []
            for p in props:
                if p[0] == "list":
                    if name != "face":
                        raise InvalidMeshError(f"{path!r}: list property on {name}", "format")
                    fields.append(("n", _PLY_TYPES[p[1]]))
                    fields.append(("v", _PLY_TYPES[p[2]], (3,)))
                else:
                    fields.append((p[1], _PLY_TYPES[p[0]]))
            dt = np.dtype(fields)
            buf = fh.read(dt.itemsize * count)
            if len(buf) != dt.itemsize * count:
                raise InvalidMeshError(f"{path!r}: file ends inside element {name}", "format")
            data[name] = np.frombuffer(buf, dtype=dt, count=count)
    if "vertex" not in data or "face" not in data:
        raise InvalidMeshError(f"{path!r}: PLY needs vertex and face elements", "format")
    fc = data["face"]
    if fc.dtype.names is None or "n" not in fc.dtype.names or (fc["n"] != 3).any():
        raise InvalidMeshError(f"{path!r}: faces must all be triangles", "format")
    missing = [k for k in ("part", "label", "ax", "ay", "az") if k not in fc.dtype.names]
    if missing:
        raise InvalidMeshError(f"{path!r}: face properties missing: {', '.join(missing)}", "format")
    vx = data["vertex"]
    V = np.stack([vx["x"], vx["y"], vx["z"]], axis=1).astype(np.float64)
    out = {"V": V, "F": fc["v"].astype(np.int64), "part": fc["part"].astype(np.int32),
           "label": fc["label"].astype(np.int32),
           "direction": np.stack([fc["ax"], fc["ay"], fc["az"]], axis=1).astype(np.float64)}
    if all(k in fc.dtype.names for k in ("red", "green", "blue")):
        out["colour"] = np.stack([fc["red"], fc["green"], fc["blue"]], axis=1).astype(np.uint8)
    return out


def frames_from_label_directions(face_part, face_label, direction):
    """Per-face frames consistent with the stored label directions.

    Row ``label // 2`` of each face's frame is its (sign-corrected) label direction exactly; the
    other two rows come from the part's mean frame (mean sign-corrected direction of each axis's
    faces, orthonormalised; missing axes completed by cross products), made orthogonal to that
    row, right-handed.

    Returns
    -------
    (m, 3, 3) float64
    """
    face_part = np.asarray(face_part, dtype=np.int64)
    lab = np.asarray(face_label, dtype=np.int64)
    m = len(lab)
    sign = np.where(lab % 2 == 0, 1.0, -1.0)
    axis_dir = np.asarray(direction, dtype=np.float64) * sign[:, None]
    axis_dir /= np.linalg.norm(axis_dir, axis=1)[:, None]
    n_parts = int(face_part.max()) + 1 if m else 0
    sums = np.zeros((n_parts, 3, 3))
    np.add.at(sums, (face_part, lab // 2), axis_dir)
    part_frames = np.zeros((n_parts, 3, 3))
    for p in range(n_parts):
        norms = np.linalg.norm(sums[p], axis=1)
        order = np.argsort(-norms, kind="stable")
        rows = {}
        for k in order:
            if norms[k] < 1e-12 and len(rows) < 2:
                continue
            v = sums[p, k].copy()
            for r in rows.values():
                v -= (v @ r) * r
            if np.linalg.norm(v) > 1e-9 and len(rows) < 2:
                rows[int(k)] = v / np.linalg.norm(v)
        if not rows:
            rows[0] = np.array([1.0, 0.0, 0.0])
        if len(rows) == 1:
            (k, r), = rows.items()
            helper = np.eye(3)[np.argmin(np.abs(r))]
            rows[(k + 1) % 3] = np.cross(r, helper) / np.linalg.norm(np.cross(r, helper))
        a, b = sorted(rows)
        c = 3 - a - b
        # right-handed: e_{k+2} = e_k x e_{k+1}
        rows[c] = np.cross(rows[(c + 1) % 3], rows[(c + 2) % 3])
        part_frames[p] = np.stack([rows[0], rows[1], rows[2]])
    frames = np.zeros((m, 3, 3))
    k = lab // 2
    k1, k2 = (k + 1) % 3, (k + 2) % 3
    ar = np.arange(m)
    pf = part_frames[face_part]
    r1 = pf[ar, k1] - (pf[ar, k1] * axis_dir).sum(axis=1)[:, None] * axis_dir
    bad = np.linalg.norm(r1, axis=1) < 1e-9
    r1[bad] = np.cross(axis_dir[bad], pf[np.flatnonzero(bad), k2[bad]])
    r1 /= np.linalg.norm(r1, axis=1)[:, None]
    frames[ar, k] = axis_dir
    frames[ar, k1] = r1
    frames[ar, k2] = np.cross(axis_dir, r1)
    return frames


def validity_from_labels_file(path, max_examples=5):
    """Validity report (see :func:`core.segmentation.validity.check_validity`) of a labels file.

    Frames are rebuilt from the stored label directions with
    :func:`frames_from_label_directions`; interface axes come from the interface loops (PCA).
    """
    d = read_labels_ply(path)
    frames = frames_from_label_directions(d["part"], d["label"], d["direction"])
    return check_validity(d["V"], d["F"], d["part"], d["label"], frames,
                          max_examples=max_examples).report
