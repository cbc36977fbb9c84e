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
    creases : None, or (c, 2) int64 vertex pairs of the edges tagged as infinitely sharp
        creases (any order within a pair; ``core.subdivision.catmull_clark`` applies the crease
        rules to them and carries them to the refined meshes). None or an empty array: no
        creases. Build meshes with new vertex positions by ``dataclasses.replace(mesh,
        vertices=...)`` so the tags stay.
    """

    vertices: np.ndarray
    face_vertices: np.ndarray
    face_offsets: np.ndarray
    creases: np.ndarray = None

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

    @property
    def n_creases(self):
        """Number of crease edges (0 without creases)."""
        return 0 if self.creases is None else len(self.creases)

    def faces(self):
        """List of (size_f,) int64 arrays, one per face (a Python list: use for small meshes)."""
        return [self.face_vertices[a:b] for a, b in zip(self.face_offsets[:-1], self.face_offsets[1:])]


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


# -- stage results ------------------------------------------------------------------------
# One dataclass per pipeline stage (``core.stages``). Each holds the stage's data for later
# stages, ``report`` (its JSON section of the run report, built by the stage) and
# ``message`` (one line for the run's stage table: warnings, or "" when there is nothing
# to say). Arrays are never copied between stages; treat them as read-only.


@dataclass(frozen=True)
class MeshSource:
    """What the intake reads: a mesh file, or arrays already in memory.

    path : str, the file (STL, OBJ, PLY, OFF), or the name to report for ``arrays``.
    arrays : None, or ``(vertices (n, 3) float64, faces (m, 3) int64)`` to validate
        instead of reading ``path`` (a FreeCAD document's mesh).
    """

    path: str
    arrays: tuple = None


@dataclass(frozen=True)
class IntakeResult:
    """The validated target, in millimetres (report key ``input``).

    target : TriMesh, watertight, 2-manifold, outward, scaled by ``report["unit_to_mm"]``.
    genus : int, genus of the target (every later stage keeps it).
    working : TriMesh, the surface parts, frames, labeling and base mesh run on: a reduction
        of ``target`` of bounded size with its genus (``core.proxy``), or ``target`` itself;
        None stands for ``target``.
    """

    target: TriMesh
    genus: int
    report: dict = field(default_factory=dict)
    message: str = ""
    working: TriMesh = None

    @property
    def surface(self):
        """The TriMesh the segmentation and the base mesh run on (``working`` or ``target``)."""
        return self.target if self.working is None else self.working


@dataclass(frozen=True)
class PartsResult:
    """The part of every target face (report key ``parts``).

    face_part : (m,) int32, part 0 .. P-1 of each face of ``IntakeResult.surface``.
    """

    face_part: np.ndarray
    report: dict = field(default_factory=dict)
    message: str = ""


@dataclass(frozen=True)
class FramesResult:
    """Part, interface and blended face frames (report key ``frames``).

    frame_field : core.segmentation.frames.FrameField.
    """

    frame_field: object
    report: dict = field(default_factory=dict)
    message: str = ""


@dataclass(frozen=True)
class LabelingResult:
    """The polycube labeling and its validity (report key ``labeling``).

    face_label : (m,) int, 0..5 = +X, -X, +Y, -Y, +Z, -Z of each face's frame.
    validity : core.segmentation.validity.Validity of ``face_label``.
    """

    face_label: np.ndarray
    validity: object
    report: dict = field(default_factory=dict)
    message: str = ""


@dataclass(frozen=True)
class Segmentation:
    """The parts, frames and labeling one base mesh was built on.

    parts : PartsResult; frames : FramesResult; labeling : LabelingResult (of the same faces).
    """

    parts: PartsResult
    frames: FramesResult
    labeling: LabelingResult


@dataclass(frozen=True)
class BaseMeshResult:
    """The coarse quad base mesh (cage) on the target (report key ``base_mesh``).

    cage : PolyMesh, closed, 2-manifold, outward, the target's genus; its ``creases`` are
        the edges on the target's sharp feature lines (``core.quadmesh.creases``; the paired
        decimation only), None when there are none.
    segmentation : Segmentation the cage was built on when it is not the labeling stage's
        (the one-part labeling, tried where the parts' polycube layout failed and kept where
        its layout did not), else None.
    """

    cage: PolyMesh
    report: dict = field(default_factory=dict)
    message: str = ""
    segmentation: Segmentation = None


@dataclass(frozen=True)
class FitResult:
    """The fitted cage (report key ``fit``).

    cage : PolyMesh whose Catmull-Clark limit surface approximates the target (possibly
        refined: more faces than the base mesh when ``tolerance`` split quad strips).
    levels : int or None, the subdivision level the fit worked on (None: not known, a
        cage read back from a document).
    cage_self_intersections : int or None, crossing triangle pairs of the unfitted cage's
        limit surface at ``levels``, counted only when the fitted one still crosses itself
        (None: not counted).
    """

    cage: PolyMesh
    report: dict = field(default_factory=dict)
    message: str = ""
    levels: int | None = None
    cage_self_intersections: int | None = None


@dataclass(frozen=True)
class PatchesResult:
    """The fitted cage's limit surface as B-spline patches (report key ``patches``).

    patches : PatchSet.
    """

    patches: PatchSet
    report: dict = field(default_factory=dict)
    message: str = ""


@dataclass
class PipelineState:
    """What the stages of one run have produced so far: one field per stage, None until it ran.

    ``source`` is the intake's input; every other field is the result of the stage of the
    same name (``core.pipeline.STAGES``), which reads only the fields it declares.
    """

    source: MeshSource = None
    intake: IntakeResult = None
    parts: PartsResult = None
    frames: FramesResult = None
    labeling: LabelingResult = None
    basemesh: BaseMeshResult = None
    fit: FitResult = None
    patches: PatchesResult = None

    @property
    def segmentation(self):
        """The parts, frames and labeling of the base mesh (a ``Segmentation``): the base-mesh
        stage's own where it built the cage on another labeling than the labeling stage's
        (``BaseMeshResult.segmentation``), else the labeling stage's; None before the labeling."""
        if self.basemesh is not None and self.basemesh.segmentation is not None:
            return self.basemesh.segmentation
        if self.labeling is None:
            return None
        return Segmentation(self.parts, self.frames, self.labeling)

    @property
    def cage(self):
        """The latest cage: the fitted one when the fit ran, else the base mesh, else None."""
        for result in (self.fit, self.basemesh):
            if result is not None:
                return result.cage
        return None
