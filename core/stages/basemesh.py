# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh stage: the coarse quad cage from the labeling (paper Sect. 2.3; a quantized
polycube embedded on the target instead of a deformed mesh, or a paired decimation of the
target as fallback: ``core.quadmesh``, docs/DESIGN.md)."""
from core.types import BaseMeshResult


def run_basemesh(intake, parts, frames, labeling, params, progress):
    """Quantize the labeling's polycube and lay its unit quads on the target, or decimate.

    With ``base_mesh_method="auto"`` an invalid labeling, or a layout that fails, needs
    more than 1.5 times the budget or has more inverted faces after its repair, falls back to
    the paired decimation of the target (``core.quadmesh.build_base_mesh``); so does a layout
    whose least-squares fit crosses itself and stays much farther from the target than the
    decimation's (:mod:`core.fitting.route_review`; not with ``fit_mode="none"``), unless the
    layout quantized again with the corners of its drifting charts kept near their measured
    places (``core.quadmesh.base_mesh.CORNER_COST``) passes that review.

    Parameters
    ----------
    intake : core.types.IntakeResult; parts : core.types.PartsResult;
    frames : core.types.FramesResult; labeling : core.types.LabelingResult.
    params : core.params.ReconstructionParams (``target_faces``, ``max_base_faces``,
        ``base_mesh_method``, ``fit_mode``, ``subdivision_levels``).
    progress : core.progress.Progress; cancellable before the layout starts.

    Returns
    -------
    core.types.BaseMeshResult; its report is ``build_base_mesh``'s info (with
    ``fallback_reason`` when the labeling was invalid, and the ``route_review`` of a polycube
    layout in ``auto``), its message names a fallback and
    says when the face budget could not be met or the limit surface of every cage tried
    crosses itself.

    Raises
    ------
    LabelingError when ``base_mesh_method="polycube"`` and the labeling is invalid, the base
    mesh cannot be built, or the cage's genus differs from the target's; FaceLimitError
    (a user error) when ``base_mesh_method="polycube"`` and the layout needs more faces than
    ``max_base_faces``.
    """
    from core.errors import FaceLimitError, LabelingError
    from core.fitting.route_review import CagePreview, review_route
    from core.quadmesh.base_mesh import CORNER_COST, LayoutTooLargeError, build_base_mesh

    validity = labeling.validity.report
    method = params.base_mesh_method
    invalid = None
    if not validity["valid"]:
        invalid = (f"{validity['invalid_charts']['count']} invalid charts, "
                   f"{validity['invalid_boundaries']['count']} invalid boundaries and "
                   f"{validity['invalid_corners']['count']} invalid corners")
        if method == "polycube":
            raise LabelingError(f"the polycube base mesh needs a valid labeling; it still has "
                                f"{invalid} (see the labeling section)")
        method = "decimation"
    progress.check_cancel()
    field = frames.frame_field
    interface_axis = field.face_interface_axis if len(field.interfaces) else None

    def build(route, corner_cost=0.0):
        return build_base_mesh(intake.surface, parts.face_part, labeling.face_label,
                               field.face_frame, field.part_frames,
                               target_faces=params.target_faces,
                               max_base_faces=params.max_base_faces,
                               face_interface_axis=interface_axis, method=route,
                               corner_cost=corner_cost)

    try:
        cage, info = build(method)
    except LayoutTooLargeError as exc:
        # only the polycube route lets it through, and only over the user's max_base_faces
        raise FaceLimitError(str(exc)) from exc
    if method == "auto" and info["method"] == "polycube" and params.fit_mode != "none":
        progress.check_cancel()
        polycube_info = info
        reviewed = review_route(cage, info, intake.surface, params.subdivision_levels,
                                lambda: build("decimation"), params.fit_mode)
        cage, info = reviewed.cage, reviewed.info
        if info["method"] != "polycube" and polycube_info["corner_cost"] == 0:
            # the layout lost the review: quantized again with the corners of its drifting
            # charts kept near their places, it is reviewed against the same decimation
            progress.check_cancel()
            other_cage, other_info = build("auto", CORNER_COST)
            review, retry = info["route_review"], None
            if (other_info["method"] == "polycube" and not other_info["inverted_faces"]
                    and not other_info["limit_crossings"]):
                again = review_route(other_cage, other_info, intake.surface,
                                     params.subdivision_levels, lambda: (cage, info),
                                     params.fit_mode,
                                     CagePreview(**review["paired decimation"]))
                retry = again.info["route_review"]["polycube"]
                if again.info["method"] == "polycube":
                    cage, info = again.cage, again.info
            info["route_review"] = {**review, "corner_retry": retry,
                                    "kept": ("polycube with corners"
                                             if info["method"] == "polycube" else
                                             review["kept"])}
    if invalid is not None and params.base_mesh_method == "auto":
        info["fallback_reason"] = f"the labeling is not a valid polycube labeling ({invalid})"
    if info["genus"] != intake.genus:
        raise LabelingError(
            f"the base mesh has genus {info['genus']} but the target has genus {intake.genus}")
    message = ("" if info["within_budget"] else
               f"{info['faces']} faces for a budget of {info['target_faces']}: "
               f"{info['minimum_reason'] or 'the closest layout found'}")
    if info["method"] != "polycube":
        message = "; ".join(filter(None, [f"{info['method']} ({info['fallback_reason']})",
                                          message, info["crossing_reason"]]))
    return BaseMeshResult(cage, info, message)
