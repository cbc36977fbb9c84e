# SPDX-License-Identifier: LGPL-2.1-or-later
"""Base-mesh stage: the coarse quad cage from the labeling (paper Sect. 2.3; a quantized
polycube embedded on the target instead of a deformed mesh, or a paired decimation of the
target as fallback: ``core.quadmesh``, docs/DESIGN.md)."""
import dataclasses

import numpy as np

from core.types import BaseMeshResult, Segmentation


def start_basemesh_ahead(intake, params):
    """The base mesh's work that needs the target only, started on another core.

    In ``auto`` the paired decimation of the target is built ahead
    (``core.quadmesh.base_mesh.DecimationCache.start``): it needs no labeling, and where the
    polycube layout fails (quickly, on a labeling that is no polycube) the stage would
    otherwise wait for it. Started when the intake is done, it is built while the parts,
    frames and labeling are; the same decimation as the stage builds itself, bit for bit.

    Parameters
    ----------
    intake : core.types.IntakeResult; params : core.params.ReconstructionParams
        (``base_mesh_method``, ``target_faces``, ``max_base_faces``).

    Returns
    -------
    core.quadmesh.base_mesh.DecimationCache for :func:`run_basemesh`'s ``ahead`` (started only
    in ``auto``); its ``close`` ends the work when the stage did not ask for it.
    """
    from core.quadmesh.base_mesh import DecimationCache

    decimation = DecimationCache()
    if params.base_mesh_method == "auto":
        decimation.start(intake.surface.vertices, intake.surface.faces, params.target_faces,
                         params.max_base_faces)
    return decimation


def run_basemesh(intake, parts, frames, labeling, params, progress, ahead=None):
    """Quantize the labeling's polycube and lay its unit quads on the target, or decimate.

    With ``base_mesh_method="auto"`` an invalid labeling, or a layout that fails, needs
    more than 1.5 times the budget or has more inverted faces after its repair, falls back to
    the paired decimation of the target (``core.quadmesh.build_base_mesh``); so does a layout
    whose least-squares fit crosses itself and stays much farther from the target than the
    decimation's (:mod:`core.fitting.route_review`; not with ``fit_mode="none"``), unless the
    layout quantized again with the corners of its drifting charts kept near their measured
    places (``core.quadmesh.base_mesh.CORNER_COST``) passes that review.

    Parts make the layout easier where each is a simple polycube, but their interfaces add
    charts and corners, and a layout of several parts can fail where the one-part labeling's
    succeeds. So in ``auto``, when the labeling has more parts than one part per connected
    component and its layout does not give the polycube route, the one-part segmentation is
    built as ``parts="single"`` builds it (:func:`one_part_segmentation`) and its layout tried
    the same way; it is kept when it gives the polycube route, and the result then carries it
    (``BaseMeshResult.segmentation``). Both attempts share one paired decimation.

    Parameters
    ----------
    intake : core.types.IntakeResult; parts : core.types.PartsResult;
    frames : core.types.FramesResult; labeling : core.types.LabelingResult.
    params : core.params.ReconstructionParams (``target_faces``, ``max_base_faces``,
        ``base_mesh_method``, ``fit_mode``, ``subdivision_levels``; for the one-part labeling
        also those of the frames and labeling stages).
    progress : core.progress.Progress; cancellable before the layout starts.
    ahead : the :func:`start_basemesh_ahead` of ``intake`` and ``params`` (the caller closes
        it), or None: the stage starts the decimation itself and ends it when done.

    Returns
    -------
    core.types.BaseMeshResult; its report is ``build_base_mesh``'s info (with
    ``fallback_reason`` when the labeling was invalid, and the ``route_review`` of a polycube
    layout in ``auto``) and ``segmentation``, which labeling the cage was built on and why
    (with ``one_part_labeling``, the one-part labeling's validity figures, where it was tried);
    its message names a fallback or the one-part labeling and says when the face budget
    could not be met or the limit surface of every cage tried crosses itself.

    Raises
    ------
    LabelingError when ``base_mesh_method="polycube"`` and the labeling is invalid, the base
    mesh cannot be built, or the cage's genus differs from the target's; FaceLimitError
    (a user error) when ``base_mesh_method="polycube"`` and the layout needs more faces than
    ``max_base_faces``.
    """
    if ahead is not None:
        return _basemesh(intake, parts, frames, labeling, params, progress, ahead)
    decimation = start_basemesh_ahead(intake, params)
    try:
        return _basemesh(intake, parts, frames, labeling, params, progress, decimation)
    finally:
        decimation.close()


def _basemesh(intake, parts, frames, labeling, params, progress, decimation):
    """The work of :func:`run_basemesh`, with the target's ``DecimationCache`` (in ``auto``
    started ahead on another core, :func:`start_basemesh_ahead`, since most designs the layout
    fails on need it)."""
    from core.errors import LabelingError
    from core.progress import SubProgress

    n_parts = int(parts.face_part.max()) + 1 if len(parts.face_part) else 0
    cage, info = _layout(intake, parts, frames, labeling, params, decimation,
                         SubProgress(progress, 0.0, 0.5))
    used = None
    segmentation = f"the labeling stage's ({_parts_words(n_parts)})"
    if params.base_mesh_method == "auto" and info["method"] != "polycube":
        one_part = one_part_segmentation(intake, params, SubProgress(progress, 0.5, 0.75),
                                         parts)
        if one_part is not None:
            failed = info["fallback_reason"]
            other_cage, other_info = _layout(intake, one_part.parts, one_part.frames,
                                             one_part.labeling, params, decimation,
                                             SubProgress(progress, 0.75, 1.0))
            if other_info["method"] == "polycube":
                cage, info, used = other_cage, other_info, one_part
                segmentation = f"one part (the {_parts_words(n_parts)}' layout failed: {failed})"
            else:
                segmentation += (f"; the one-part labeling's layout failed too: "
                                 f"{other_info['fallback_reason']}")
            info["one_part_labeling"] = {key: one_part.labeling.report[key] for key in
                                         ("valid", "parts", "charts", "corners")}
    info["segmentation"] = segmentation
    if info["genus"] != intake.genus:
        raise LabelingError(
            f"the base mesh has genus {info['genus']} but the target has genus {intake.genus}")
    message = ("" if info["within_budget"] else
               f"{info['faces']} faces for a budget of {info['target_faces']}: "
               f"{info['minimum_reason'] or 'the closest layout found'}")
    if info["method"] != "polycube":
        message = "; ".join(filter(None, [f"{info['method']} ({info['fallback_reason']})",
                                          message, info["crossing_reason"]]))
    elif used is not None:
        message = "; ".join(filter(None, [f"polycube layout of one part (the {_parts_words(n_parts)}' "
                                          f"layout failed: base_mesh.segmentation says why)",
                                          message]))
    return BaseMeshResult(cage, info, message, used)


def one_part_segmentation(intake, params, progress, parts=None):
    """The segmentation of a ``parts="single"`` run: its parts, frames and labeling stages
    with ``params`` otherwise unchanged.

    Parameters
    ----------
    intake : core.types.IntakeResult.
    params : core.params.ReconstructionParams.
    progress : core.progress.Progress for the labeling.
    parts : core.types.PartsResult to compare with, or None.

    Returns
    -------
    core.types.Segmentation, or None when ``parts`` is already one part per connected
    component (the same partition of the faces).
    """
    from core.stages.frames import run_frames
    from core.stages.labeling import run_labeling
    from core.stages.parts import run_parts

    single = dataclasses.replace(params, parts="single", parts_file="")
    one = run_parts(intake, single, progress)
    if parts is not None and _same_partition(parts.face_part, one.face_part):
        return None
    frames = run_frames(intake, one, single, progress)
    progress.check_cancel()
    labeling = run_labeling(intake, one, frames, single, progress)
    return Segmentation(one, frames, labeling)


def _layout(intake, parts, frames, labeling, params, decimation, progress):
    """The base mesh of one segmentation: ``(cage, info)`` as :func:`run_basemesh` describes
    (the route review included), without the genus check; ``decimation`` is the
    ``DecimationCache`` of the target."""
    from core.errors import FaceLimitError, LabelingError
    from core.fitting.route_review import review_route
    from core.quadmesh.base_mesh import LayoutTooLargeError, build_base_mesh

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
                               decimation=decimation, corner_cost=corner_cost)

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
            progress.check_cancel()
            cage, info = _corner_retry(cage, info, build, intake.surface, params)
    if invalid is not None and params.base_mesh_method == "auto":
        info["fallback_reason"] = f"the labeling is not a valid polycube labeling ({invalid})"
    return cage, info


def _corner_retry(cage, info, build, surface, params):
    """The layout that lost the route review, quantized again with the corners of its
    drifting charts kept near their measured places, reviewed against the same decimation.

    Parameters
    ----------
    cage : core.types.PolyMesh, info : dict, the decimation cage the review kept and its
        report (with ``route_review``).
    build : callable ``build(route, corner_cost)`` returning ``(cage, info)``
        (:func:`core.quadmesh.base_mesh.build_base_mesh` on this segmentation).
    surface : core.types.TriMesh, the target; params : core.params.ReconstructionParams.

    Returns
    -------
    (cage, info): the corner-term layout where it is flawless and wins the review (its
    ``route_review.kept`` is ``"polycube with corners"``), else the given ones; either way
    ``route_review.corner_retry`` holds the retry's preview, None where it was not reviewed.
    """
    from core.fitting.route_review import CagePreview, review_route
    from core.quadmesh.base_mesh import CORNER_COST

    review, retry = info["route_review"], None
    other_cage, other_info = build("auto", CORNER_COST)
    if (other_info["method"] == "polycube" and not other_info["inverted_faces"]
            and not other_info["limit_crossings"]):
        again = review_route(other_cage, other_info, surface, params.subdivision_levels,
                             lambda: (cage, info), params.fit_mode,
                             CagePreview(**review["paired decimation"]))
        retry = again.info["route_review"]["polycube"]
        if again.info["method"] == "polycube":
            cage, info = again.cage, again.info
    info["route_review"] = {**review, "corner_retry": retry,
                            "kept": ("polycube with corners" if info["method"] == "polycube"
                                     else review["kept"])}
    return cage, info


def _same_partition(a, b):
    """True when the (m,) int part arrays ``a`` and ``b`` split the faces alike (up to the
    parts' numbering)."""
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


def _parts_words(n):
    """``"1 part"``, ``"3 parts"``."""
    return f"{n} part" if n == 1 else f"{n} parts"
