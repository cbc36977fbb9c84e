# SPDX-License-Identifier: LGPL-2.1-or-later
"""FreeCAD's binary mesh file (``.bms``) written and read with numpy, without FreeCAD.

The file is the mesh kernel's own data (``MeshCore::MeshKernel::Write``): points, facets with
their neighbours and the bounding box, so FreeCAD reads it without building the neighbours
itself. This module imports no FreeCAD, so the GUI's stage process can write the file of a
mesh it read (``polycube_wb.stage_jobs.read_mesh_file``) and hand the bytes to FreeCAD's
process, which only reads them (``polycube_wb.convert.arrays_to_mesh``).
"""
from dataclasses import dataclass

import numpy as np

_HEADER = np.array([0xA0B0C0D0, 0x00010000], np.uint32).tobytes() + b"MESH-" * 51 + b"\n"
"""Start of the file: magic number, version and a 256-byte comment; the point and facet
counts follow."""
_COUNTS = len(_HEADER)
_NO_NEIGHBOUR = 0xFFFFFFFF


@dataclass(frozen=True)
class MeshWithBinary:
    """A mesh and its binary mesh file, made together where FreeCAD is not running.

    mesh : core.types.TriMesh
    binary : bytes of :func:`binary_mesh` of its vertices and faces, or None (a mesh whose
        neighbours FreeCAD builds itself).
    """

    mesh: object
    binary: bytes = None


def binary_mesh(V, F):
    """The binary mesh file (bytes) of a mesh whose every edge joins two triangles, or None
    for any other mesh (its neighbours are left to FreeCAD's own builder).

    Parameters
    ----------
    V : (n, 3) float, vertex coordinates (stored as float32, as FreeCAD keeps them).
    F : (m, 3) int, triangles as vertex indices (validated by the caller).

    Returns
    -------
    bytes or None
        Each facet's vertex indices and its neighbours across the edges (i, i + 1) (uint32).
    """
    n, m = len(V), len(F)
    if m == 0 or n >= _NO_NEIGHBOUR or m >= _NO_NEIGHBOUR:
        return None
    start = F.reshape(-1)
    end = np.roll(F, -1, axis=1).reshape(-1)
    key = np.minimum(start, end).astype(np.int64) * n + np.maximum(start, end)
    order = np.argsort(key, kind="stable")
    ordered = key[order]
    first, second = order[0::2], order[1::2]
    if len(first) != len(second) or np.any(ordered[0::2] != ordered[1::2]) or \
            np.any(ordered[2::2] == ordered[1:-1:2]):
        return None  # an open or a non-manifold edge
    neighbours = np.empty(3 * m, np.uint32)
    neighbours[first] = second // 3
    neighbours[second] = first // 3
    points = np.asarray(V, np.float32)
    low, high = points.min(axis=0), points.max(axis=0)
    box = np.array([low[0], high[0], low[1], high[1], low[2], high[2]], np.float32)
    facets = np.hstack([F.astype(np.uint32), neighbours.reshape(-1, 3)])
    return b"".join((_HEADER, np.array([n, m], np.uint32).tobytes(), points.tobytes(),
                     facets.tobytes(), box.tobytes()))


def binary_mesh_arrays(data):
    """(V (n, 3) float64, F (m, 3) int64) of the bytes ``data`` of a binary mesh file."""
    n, m = np.frombuffer(data, np.uint32, 2, _COUNTS)
    points = np.frombuffer(data, np.float32, 3 * n, _COUNTS + 8).reshape(-1, 3)
    facets = np.frombuffer(data, np.uint32, 6 * m, _COUNTS + 8 + 12 * int(n))
    # + 0.0: FreeCAD's Topology gives +0.0 for a -0.0 coordinate
    V = points.astype(np.float64) + 0.0
    return V, facets.reshape(-1, 6)[:, :3].astype(np.int64)
