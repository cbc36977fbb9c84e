# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh stage: the coarse quad cage from a valid labeling (paper Sect. 2.3; a quantized
polycube embedded on the target instead of a deformed mesh: ``core.quadmesh``, docs/DESIGN.md)."""
from core.types import BaseMeshResult


def run_basemesh(intake, parts, frames, labeling, params, progress):
    """Quantize the labeling's polycube and lay its unit quads on the target.

    Parameters
    ----------
    intake : core.types.IntakeResult; parts : core.types.PartsResult;
    frames : core.types.FramesResult; labeling : core.types.LabelingResult (valid).
    params : core.params.ReconstructionParams (``target_faces``, ``max_base_faces``).
    progress : core.progress.Progress; cancellable before the layout starts.

    Returns
    -------
    core.types.BaseMeshResult; its report is ``build_base_mesh``'s info, its message says
    when the face budget could not be met.

    Raises
    ------
    LabelingError when the labeling is invalid, cannot be quantized or laid out, or the
    cage's genus differs from the target's.
    """
    from core.errors import LabelingError
    from core.quadmesh.base_mesh import build_base_mesh

    validity = labeling.validity.report
    if not validity["valid"]:
        raise LabelingError(
            "the base mesh needs a valid labeling; it still has "
            f"{validity['invalid_charts']['count']} invalid charts, "
            f"{validity['invalid_boundaries']['count']} invalid boundaries and "
            f"{validity['invalid_corners']['count']} invalid corners (see the labeling section)")
    progress.check_cancel()
    field = frames.frame_field
    interface_axis = field.face_interface_axis if len(field.interfaces) else None
    cage, info = build_base_mesh(intake.target, parts.face_part, labeling.face_label,
                                 field.face_frame, field.part_frames,
                                 target_faces=params.target_faces,
                                 max_base_faces=params.max_base_faces,
                                 face_interface_axis=interface_axis)
    if info["genus"] != intake.genus:
        raise LabelingError(
            f"the base mesh has genus {info['genus']} but the target has genus {intake.genus}")
    message = ("" if info["within_budget"] else
               f"{info['faces']} faces for a budget of {info['target_faces']}: "
               f"{info['minimum_reason'] or 'the closest layout found'}")
    return BaseMeshResult(cage, info, message)
