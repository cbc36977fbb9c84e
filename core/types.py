# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plain data passed between pipeline stages (numpy arrays in small dataclasses)."""
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class TriMesh:
    """A closed triangle mesh.

    vertices : (n, 3) float64, coordinates in the file's units.
    faces : (m, 3) int64, counter-clockwise seen from outside (outward normals).
    """

    vertices: np.ndarray
    faces: np.ndarray


@dataclass(frozen=True)
class PolyMesh:
    """A polygon mesh with faces of any size, stored CSR-style.

    vertices : (n, 3) float64.
    face_vertices : (k,) int64, the corners of all faces concatenated,
        each face counter-clockwise seen from outside.
    face_offsets : (m + 1,) int64, face ``f`` is
        ``face_vertices[face_offsets[f]:face_offsets[f + 1]]``.
    """

    vertices: np.ndarray
    face_vertices: np.ndarray
    face_offsets: np.ndarray

    @classmethod
    def from_faces(cls, vertices, faces):
        """Build from (n, 3) vertices and a sequence of per-face vertex-index sequences."""
        sizes = np.fromiter((len(f) for f in faces), dtype=np.int64, count=len(faces))
        offsets = np.zeros(len(faces) + 1, dtype=np.int64)
        np.cumsum(sizes, out=offsets[1:])
        flat = (np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
                if len(faces) else np.zeros(0, dtype=np.int64))
        return cls(np.asarray(vertices, dtype=np.float64), flat, offsets)

    @property
    def face_sizes(self):
        """(m,) int64 number of corners of each face."""
        return np.diff(self.face_offsets)

    @property
    def n_faces(self):
        return len(self.face_offsets) - 1

    def faces(self):
        """List of (size_f,) int64 arrays, one per face (a Python list: use for small meshes)."""
        return [self.face_vertices[a:b] for a, b in zip(self.face_offsets[:-1], self.face_offsets[1:])]


@dataclass
class Segmentation:
    """Parts and polycube labels of a target mesh's faces.

    face_part : (m,) int32, part index of each face (0 .. n_parts-1).
    face_label : (m,) int32, 0..5 = +X, -X, +Y, -Y, +Z, -Z of the face's frame.
    face_frame : (m, 3, 3) float64, rows are the face's (blended) local x, y, z axes
        in world coordinates, right-handed.
    part_frames : (n_parts, 3, 3) float64, PCA frame of each part (rows x, y, z).
    """

    face_part: np.ndarray
    face_label: np.ndarray
    face_frame: np.ndarray
    part_frames: np.ndarray
    info: dict = field(default_factory=dict)

    def label_directions(self):
        """(m, 3) float64 unit vector of each face's label in world coordinates."""
        axis = self.face_label // 2
        sign = np.where(self.face_label % 2 == 0, 1.0, -1.0)
        rows = self.face_frame[np.arange(len(axis)), axis]
        return rows * sign[:, None]


@dataclass
class BSplinePatch:
    """One B-spline surface patch in OpenCascade's form (distinct knots + multiplicities).

    poles : (nu, nv, 3) float64; ``d/du x d/dv`` points out of the solid.
    u_knots, v_knots : (ku,), (kv,) float64 strictly increasing distinct knots.
    u_mults, v_mults : (ku,), (kv,) int64 multiplicities; clamped ends have degree + 1,
        so ``sum(u_mults) == nu + degree_u + 1``.
    """

    poles: np.ndarray
    u_knots: np.ndarray
    u_mults: np.ndarray
    v_knots: np.ndarray
    v_mults: np.ndarray
    degree_u: int = 3
    degree_v: int = 3


@dataclass
class PatchSet:
    """The limit surface of a base mesh as B-spline patches.

    patches : list of BSplinePatch; neighbouring patches agree along their shared
        boundary so the B-rep shell closes without sewing.
    face_of_patch : (k,) int64 base-mesh face each patch comes from.
    info : figures about the approximation (EV error, continuity), JSON-serialisable.
    topology : core.export.brep_topology.BRepTopology or None, the shared vertices
        and edges of the patches; None means whole sides with bit-identical poles
        (``topology_from_sides``).
    """

    patches: list
    face_of_patch: np.ndarray
    info: dict = field(default_factory=dict)
    topology: object = None
