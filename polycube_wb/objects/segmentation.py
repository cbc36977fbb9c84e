# SPDX-License-Identifier: LGPL-2.1-or-later
"""Segmentation: parts, PCA frames and the HBECVT polycube labeling of the target.

A ``Mesh::FeaturePython`` showing the target's triangles coloured by label (or by part).
The per-face part and label are stored in the document (integer lists); the frames and the
validity, which later stages need too, are rebuilt from them when the document is reopened
(both are deterministic functions of the mesh and the parts).
"""
import numpy as np

from polycube_wb.stage_jobs import StageJob, core_stages
from polycube_wb.objects.base import StageFailed, StageProxy, add_property, fingerprint, \
    stage_params

STAGES = ("parts", "frames", "labeling")
PART_MODES = ["single", "auto"]
COLOUR_MODES = ["Labels", "Parts"]
LABEL_COLOURS = ((0.90, 0.16, 0.16), (0.55, 0.05, 0.05), (0.20, 0.75, 0.20),
                 (0.05, 0.40, 0.05), (0.20, 0.45, 0.95), (0.05, 0.15, 0.55))
"""RGB of the labels +X, -X, +Y, -Y, +Z, -Z (of each part's own frame)."""
PART_COLOURS = ((0.12, 0.47, 0.71), (1.00, 0.50, 0.05), (0.17, 0.63, 0.17),
                (0.84, 0.15, 0.16), (0.58, 0.40, 0.74), (0.55, 0.34, 0.29),
                (0.89, 0.47, 0.76), (0.50, 0.50, 0.50), (0.74, 0.74, 0.13),
                (0.09, 0.75, 0.81))
FIGURES = ("Parts", "Charts", "Corners", "InvalidCharts", "InvalidBoundaries",
           "InvalidCorners", "TurningPoints")


class SegmentationProxy(StageProxy):
    TYPE = "Polycube::Segmentation"
    INPUTS = ("Target",)

    def init_properties(self, obj):
        from polycube_wb.preferences import default

        super().init_properties(obj)
        add_property(obj, "App::PropertyLink", "Target", "Segmentation", "The target mesh")
        add_property(obj, "App::PropertyEnumeration", "PartMode", "Parts",
                     "'single': the whole mesh is one part; 'auto': parts along the curve "
                     "skeleton", list(PART_MODES), choice=default("parts"))
        add_property(obj, "App::PropertyFloat", "BlendFactor", "Frames",
                     "Frame blending distance near part interfaces, in mean edge lengths "
                     "(paper: 4)", default("blend_factor"))
        add_property(obj, "App::PropertyFloat", "Lambda", "Labeling",
                     "Compactness weight (λ, Eq. 3): weight of neighbours with another label "
                     "(paper: 0.5)",
                     default("lam"))
        add_property(obj, "App::PropertyFloat", "Penalty", "Labeling",
                     "Opposite-label penalty (p, Eq. 3): weight of opposite and "
                     "interface-parallel labels (paper: 1e5)",
                     default("penalty"))
        add_property(obj, "App::PropertyInteger", "MaxSweeps", "Labeling",
                     "Most sweeps of the labeling's optimisation (HBECVT)",
                     default("max_sweeps"))
        add_property(obj, "App::PropertyBool", "Repair", "Labeling",
                     "Repair invalid charts, boundaries and corners after HBECVT",
                     default("repair"))
        add_property(obj, "App::PropertyEnumeration", "ColourBy", "Display",
                     "Colour the faces by polycube label or by part", list(COLOUR_MODES),
                     output=True)
        add_property(obj, "App::PropertyBool", "Valid", "Result",
                     "The labeling passes the polycube validity rules", False, read_only=True,
                     output=True)
        for name in FIGURES:
            add_property(obj, "App::PropertyInteger", name, "Result", f"{name} of the labeling",
                         0, read_only=True, output=True)
        for name in ("FacePart", "FaceLabel"):
            add_property(obj, "App::PropertyIntegerList", name, "Result",
                         f"{name[4:]} of every target face", hidden=True, output=True)
        add_property(obj, "App::PropertyColorList", "FaceColors", "Display",
                     "Colour of every face (shown by the view provider)", hidden=True,
                     output=True)

    def parameters(self, obj):
        return {"parts": obj.PartMode, "blend_factor": float(obj.BlendFactor),
                "lam": float(obj.Lambda), "penalty": float(obj.Penalty),
                "max_sweeps": int(obj.MaxSweeps), "repair": bool(obj.Repair)}

    def prepare(self, obj):
        state, params = self.upstream_state(obj), stage_params(**self.parameters(obj))
        return StageJob(core_stages, (state, tuple(STAGES), params))

    def store(self, obj, state):
        labeling = state.labeling.report
        obj.FacePart = state.parts.face_part.astype(int).tolist()
        obj.FaceLabel = state.labeling.face_label.astype(int).tolist()
        obj.Valid = bool(labeling["valid"])
        for name, key in zip(FIGURES, ("parts", "charts", "corners", "invalid_charts",
                                       "invalid_boundaries", "invalid_corners",
                                       "turning_points")):
            setattr(obj, name, int(labeling[key]))
        self._cache = {key: getattr(state, key) for key in STAGES}

    def show(self, obj):
        target = self.upstream_state(obj).intake.surface  # the labeling's own faces
        face_part, face_label = stored_arrays(obj, len(target.faces))
        obj.Mesh = _same_or_new_mesh(obj.Target, target.vertices, target.faces)
        obj.FaceColors = face_colours(face_part, face_label, obj.ColourBy)
        return fingerprint(face_part, face_label)

    def onChanged(self, obj, prop):
        if prop == "ColourBy" and "FaceLabel" in obj.PropertiesList and obj.FaceLabel:
            face_part, face_label = stored_arrays(obj)
            obj.FaceColors = face_colours(face_part, face_label, obj.ColourBy)

    def load_outputs(self, obj):
        from core.segmentation.validity import check_validity
        from core.types import LabelingResult, PartsResult

        state = self.upstream_state(obj)
        mesh = state.intake.surface
        face_part, face_label = stored_arrays(obj, len(mesh.faces))
        state.parts = PartsResult(face_part)
        state = core_stages(state, ["frames"], stage_params(**self.parameters(obj)),
                                _no_progress())
        validity = check_validity(mesh.vertices, mesh.faces, face_part, face_label,
                                  state.frames.frame_field.face_frame)
        # results rebuilt from the document carry no report section (the run that made
        # them wrote it)
        return {"parts": state.parts, "frames": state.frames,
                "labeling": LabelingResult(face_label, validity)}


def _no_progress():
    from core.progress import NO_PROGRESS

    return NO_PROGRESS


def _same_or_new_mesh(target, V, F):
    """A copy of the Target object's mesh when it is exactly ``(V, F)`` (no placement), which
    costs a fraction of building a mesh; else a mesh built from the arrays."""
    from polycube_wb.convert import arrays_to_mesh, mesh_to_arrays

    mesh = getattr(target, "Mesh", None)
    if mesh is not None and mesh.Placement.isIdentity() and mesh.CountPoints == len(V) and \
            mesh.CountFacets == len(F):
        own_V, own_F = mesh_to_arrays(mesh)
        if np.array_equal(own_V, V) and np.array_equal(own_F, F):
            return mesh.copy()
    return arrays_to_mesh(V, F)


def stored_arrays(obj, n_faces=None):
    """(face_part, face_label) int32 arrays stored on a Segmentation object.

    Raises
    ------
    StageFailed
        Nothing is stored, or not one entry per target face (``n_faces``).
    """
    face_part = np.asarray(obj.FacePart, dtype=np.int32)
    face_label = np.asarray(obj.FaceLabel, dtype=np.int32)
    expected = len(face_part) if n_faces is None else n_faces
    if len(face_part) == 0 or len(face_part) != expected or len(face_label) != expected:
        raise StageFailed(f"{obj.Label}: the stored labeling has {len(face_label)} faces, the "
                          f"target {expected}; recompute the segmentation")
    return face_part, face_label


def face_colours(face_part, face_label, colour_by="Labels"):
    """List of RGB tuples, one per face: its label's or its part's colour."""
    if colour_by == "Parts":
        table, index = PART_COLOURS, np.asarray(face_part) % len(PART_COLOURS)
    else:
        table, index = LABEL_COLOURS, np.asarray(face_label)
    return [table[k] for k in index.tolist()]  # shares the table's tuples: fast on big meshes
