# SPDX-License-Identifier: LGPL-2.1-or-later
"""Frames stage: a frame per part, per interface, blended per face (paper Sect. 2.2, Eq. 1)."""
from core.types import FramesResult


def run_frames(intake, parts, params, progress):
    """Each part's frame of least labeling energy, interface frames, blended face frames.

    Parameters
    ----------
    intake : core.types.IntakeResult; parts : core.types.PartsResult.
    params : core.params.ReconstructionParams (``blend_factor`` in mean edge lengths,
        ``lam`` of Eq. 3 for the candidates' energy).
    progress : core.progress.Progress.

    Returns
    -------
    core.types.FramesResult
    """
    from core.segmentation.frames import compute_frames, mean_edge_length

    mesh = intake.surface
    blend = params.blend_factor * mean_edge_length(mesh.vertices, mesh.faces)
    frame_field = compute_frames(mesh, parts.face_part, blend_distance=blend, lam=params.lam)
    report = {"parts": int(len(frame_field.part_frames)), "interfaces": len(frame_field.interfaces),
              "blend_distance": float(frame_field.blend_distance),
              "part_frame_source": list(frame_field.part_frame_source)}
    return FramesResult(frame_field, report)
