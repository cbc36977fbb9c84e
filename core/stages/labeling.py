# SPDX-License-Identifier: LGPL-2.1-or-later
"""Labeling stage: HBECVT polycube labeling (paper Sect. 2.2, Eqs. 2-3), repair, validity."""
import numpy as np

from core.types import LabelingResult

VALIDITY_COUNTS = ("invalid_charts", "invalid_boundaries", "invalid_corners", "turning_points")
"""Sections of ``Validity.report`` with a ``count`` and ``examples``, in report order."""

REPAIR_PASSES = 3
"""Passes of repair, chart absorption and straightening at most: a pass after the first runs
only while the labeling is still invalid and the pass before changed it."""

REPAIR_ESCAPES = 4
"""Uphill restarts (:func:`core.segmentation.repair.repair_labeling`'s ``escapes``) the repair
of a pass after the first may try."""


def run_labeling(intake, parts, frames, params, progress):
    """Label every face with one of six directions of its frame, repair, check validity.

    HBECVT (Eqs. 2-3), then, with ``params.repair``, passes (:func:`_repair_pass`) of the
    repair loop, the absorption of charts smaller or thinner than a quad of the face budget
    (``params.target_faces``) into their neighbours where validity allows
    (:mod:`core.segmentation.chart_absorption`) and the straightening of boundary hooks (which
    returns the validity it ends with), again while the labeling is invalid, up to
    :data:`REPAIR_PASSES`; otherwise the validity of the HBECVT labels (the corner rules are the
    independent check).

    A repair stops where no candidate lowers the invalid count within its angle budget and
    trial caps, but the absorption and the straightening move boundaries and merge charts, so
    the next pass starts from other charts and corners, with a fresh budget and fresh caps
    measured from its own input, and the repair may then leave a stuck state uphill
    (:data:`REPAIR_ESCAPES`): validity comes first, since the base mesh refuses an invalid
    labeling whatever its angle. A labeling valid after the first pass is never changed again.

    Parameters
    ----------
    intake : core.types.IntakeResult; parts : core.types.PartsResult;
    frames : core.types.FramesResult.
    params : core.params.ReconstructionParams (``lam``, ``penalty``, ``max_sweeps``,
        ``repair``, ``target_faces``).
    progress : core.progress.Progress; reported after each step, cancellable between them.

    Returns
    -------
    core.types.LabelingResult; an invalid labeling is a result too (its report says what
    is invalid), the base-mesh stage refuses it.
    """
    from core.geometry import face_areas
    from core.progress import SubProgress
    from core.segmentation.charts import build_topology
    from core.segmentation.labeling import (face_colouring, face_normals, hbecvt_labeling,
                                            mean_label_angle, nearest_direction_labels,
                                            part_neighbours)
    from core.segmentation.repair import CandidateJudge
    from core.segmentation.validity import check_validity

    mesh, face_part, field = intake.surface, parts.face_part, frames.frame_field
    # one edge table, one colouring, one set of normals and one judge serve the sweeps, the
    # repair and the monotonicity pass
    topology = build_topology(mesh.faces, len(mesh.vertices))
    colour = face_colouring(part_neighbours(topology, face_part))
    normals = face_normals(mesh.vertices, mesh.faces)
    labels, info = hbecvt_labeling(mesh.vertices, mesh.faces, face_part, field.face_frame,
                                   field.face_interface_axis, lam=params.lam,
                                   penalty=params.penalty, max_sweeps=params.max_sweeps,
                                   topology=topology, colour=colour, normals=normals)
    progress.report("labeling", 0.5)
    progress.check_cancel()
    repair_report = straighten_report = absorb_report = None
    passes = 0
    if params.repair:
        judge = CandidateJudge.of_mesh(mesh.vertices, mesh.faces, face_part, field.face_frame,
                                       topology, normals)
        # charts smaller or thinner than the base mesh's quads are noise for its layout
        unit_area = float(face_areas(mesh.vertices, mesh.faces).sum()) / params.target_faces
        for passes in range(1, REPAIR_PASSES + 1):
            start = labels
            share = SubProgress(progress, 0.5 + 0.45 * (passes - 1) / REPAIR_PASSES,
                                0.5 + 0.45 * passes / REPAIR_PASSES)
            labels, validity, repair_report, absorb_report, straighten_report = _repair_pass(
                mesh, face_part, field, labels, params, topology, colour, judge, unit_area,
                REPAIR_ESCAPES if passes > 1 else 0, share)
            if validity.is_valid or np.array_equal(labels, start):
                break
    else:
        validity = check_validity(mesh.vertices, mesh.faces, face_part, labels, field.face_frame,
                                  topology)
    nearest = nearest_direction_labels(normals, field.face_frame)
    v = validity.report
    report = {
        "valid": bool(v["valid"]),
        "parts": int(face_part.max()) + 1,
        "charts": int(v["charts"]),
        "corners": int(v["corners"]),
        "invalid_charts": int(v["invalid_charts"]["count"]),
        "invalid_boundaries": int(v["invalid_boundaries"]["count"]),
        "invalid_corners": int(v["invalid_corners"]["count"]),
        "invalid_at_interfaces": {k: int(v[f"invalid_{k}"]["at_interfaces"])
                                  for k in ("boundaries", "corners")},
        "turning_points": int(v["turning_points"]["count"]),
        "mean_angle_deg": float(mean_label_angle(normals, labels, field.face_frame)),
        "nearest_direction_mean_angle_deg": float(mean_label_angle(normals, nearest, field.face_frame)),
        "hbecvt": info,
        "repair_passes": passes,
        "unfixed": _unfixed(v) if repair_report else None,
        "absorbed": absorb_report,
        "straightened": straighten_report,
        "examples": {k: v[k]["examples"] for k in VALIDITY_COUNTS},
    }
    message = "valid polycube labeling" if report["valid"] else (
        f"labeling still has {report['invalid_charts']} invalid charts, "
        f"{report['invalid_boundaries']} invalid boundaries, {report['invalid_corners']} invalid corners")
    return LabelingResult(labels, validity, report, message)


def _repair_pass(mesh, face_part, field, labels, params, topology, colour, judge, unit_area,
                 escapes, progress):
    """One pass of repair (with ``escapes`` uphill restarts), chart absorption and straightening
    on ``labels`` ((m,) int); ``progress`` is the pass's share of the stage's.

    Returns
    -------
    labels : (m,) int32; validity : Validity of them (turning points included);
    the reports of the repair, the absorption and the straightening (dicts).
    """
    from core.segmentation.chart_absorption import absorb_charts
    from core.segmentation.monotone import straighten_boundaries
    from core.segmentation.repair import repair_labeling

    labels, repair_report = repair_labeling(mesh.vertices, mesh.faces, face_part, labels,
                                            field.face_frame, field.face_interface_axis,
                                            lam=params.lam, penalty=params.penalty,
                                            topology=topology, colour=colour, judge=judge,
                                            escapes=escapes)
    progress.report("labeling", 0.5)
    progress.check_cancel()
    absorption = absorb_charts(mesh.vertices, mesh.faces, face_part, labels, judge, unit_area)
    progress.report("labeling", 0.8)
    progress.check_cancel()
    labels, straighten_report, validity = straighten_boundaries(
        mesh.vertices, mesh.faces, face_part, absorption.labels, field.face_frame,
        topology=topology, judge=judge)
    return labels, validity, repair_report, absorption.report, straighten_report


def _unfixed(report):
    """The invalid items of a validity ``report`` (sections with their examples), empty when
    valid."""
    return {k: report[k] for k in VALIDITY_COUNTS[:3] if report[k]["count"]}
