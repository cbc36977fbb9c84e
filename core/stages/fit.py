# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit stage: move the cage so its limit surface fits the target (paper Sect. 2.4-2.5,
Eqs. 4-11), refining quad strips until a tolerance is met when one is asked for."""
from dataclasses import dataclass

import numpy as np

from core.types import FitResult

FIT_FACE_BUDGET = 40_000
"""Most faces of the subdivided mesh the fit works on: above it, fewer levels are used
(the closest-point queries and thickness rays of every iteration scale with it)."""

EXPORT_CHECK_LEVELS = 2
"""Subdivision level at which the export checks that a limit surface does not cross itself
(:func:`export_limit_crossings`): the fit's default (paper: 2), at which the fit holds
crossings back, fewer only where the fit also takes fewer (:data:`FIT_FACE_BUDGET`). A coarser
check would refuse fitted cages the fit found clean: coarse level-1 triangles can cross where
the level-2 surface does not."""

FIT_REPORT_KEYS = ("start", "rounds", "iterations", "stopped", "mean_distance", "max_distance",
                   "target_mean_distance", "target_max_distance",
                   "outside_volume_fraction", "uncovered_volume_fraction", "initial_mean_distance",
                   "initial_max_distance", "initial_target_mean_distance",
                   "initial_target_max_distance", "t_min", "seconds", "measure_seconds", "refits",
                   "refit_crossings", "cold_refit_crossings", "stiffened", "held_back",
                   "rgp_held_back", "rgp_retried", "rgp_passes", "nudged", "pull_crossings",
                   "cage_self_intersections", "crease_curves", "outside_refinement")
"""Figures of ``core.fitting.fit_base_mesh``'s info copied into the report, when present."""


def fit_levels(n_base_faces, wanted):
    """Subdivision levels for the fit: ``wanted``, fewer if the fine mesh would exceed the budget."""
    affordable = int(np.floor(np.log(FIT_FACE_BUDGET / max(n_base_faces, 1)) / np.log(4.0)))
    return int(max(1, min(wanted, affordable)))


def run_fit(intake, basemesh, params, progress):
    """Fit the base mesh's cage to the target (``params.fit_mode``), to a tolerance if asked.

    Parameters
    ----------
    intake : core.types.IntakeResult; basemesh : core.types.BaseMeshResult (its ``cage``
        may be one the user edited).
    params : core.params.ReconstructionParams (``fit_mode``, ``fit_iterations``,
        ``fit_convergence``, ``subdivision_levels``, ``fit_t_min``, ``tolerance`` or
        ``tolerance_mm``, ``max_base_faces``, ``outside_refinement``).
    progress : core.progress.Progress; the fit reports its iterations and cancels inside.

    Returns
    -------
    core.types.FitResult (its ``levels`` and ``cage_self_intersections`` also in the report);
    the report has the fit's figures, ``self_intersections`` of the
    fitted limit surface (triangle pairs at the fit's level, the fit's own count when it
    made one), with a tolerance a ``tolerance`` section per refinement round and, when an
    inside fit left more than ``outside_refinement`` of the volume outside, an
    ``outside_refinement`` section (:mod:`core.fitting.outside_refinement`: ``goal``,
    ``reason``, ``faces`` of the cage kept and ``rounds``). The message warns about
    crossings, a tolerance not met and volume still outside above the goal.
    """
    from core.fitting import fit_base_mesh

    base, target = basemesh.cage, intake.target

    def levels_of(cage):
        return fit_levels(cage.n_faces, params.subdivision_levels)

    def crossing_faces(cage):
        return limit_self_intersections(cage, levels_of(cage))[1]

    def fit_once(cage):
        return fit_base_mesh(cage, target, levels=levels_of(cage),
                             iterations=params.fit_iterations, mode=params.fit_mode,
                             t_min=params.fit_t_min, tol=params.fit_convergence,
                             progress=progress)

    def fit(cage):
        if params.fit_mode != "inside" or not params.outside_refinement:
            return fit_once(cage)
        from core.fitting.outside_refinement import fit_with_outside_refinement

        refined = fit_with_outside_refinement(cage, target, fit_once, params.outside_refinement,
                                              params.max_base_faces, crossing_faces,
                                              progress=progress)
        info = dict(refined.info)
        if refined.reason:  # the first fit left more than the goal outside
            info["outside_refinement"] = {"goal": params.outside_refinement,
                                          "reason": refined.reason, "rounds": refined.rounds,
                                          "faces": int(refined.mesh.n_faces)}
        return refined.mesh, info

    diagonal_mm = float(np.linalg.norm(np.ptp(target.vertices, axis=0)))
    tolerance = params.tolerance or params.tolerance_mm / diagonal_mm
    refinement = None
    if tolerance > 0:
        from core.fitting.refine import fit_to_tolerance

        refinement = fit_to_tolerance(base, target, tolerance, params.max_base_faces, fit,
                                      crossing_faces=crossing_faces)
        fitted, info = refinement.mesh, refinement.info
    else:
        fitted, info = fit(base)
    levels = info["levels"]
    report = {"mode": params.fit_mode, "levels": levels,
              **{key: info[key] for key in FIT_REPORT_KEYS if key in info}}
    report["self_intersections"] = (info["self_intersections"] if "self_intersections" in info
                                    else count_limit_self_intersections(fitted, levels))
    warnings = [] if report["self_intersections"] == 0 else [
        f"warning: the fitted limit surface intersects itself "
        f"({report['self_intersections']} triangle pairs at level {levels})"]
    outside = report.get("outside_refinement")
    if outside and report["outside_volume_fraction"] > outside["goal"]:
        warnings.append(f"warning: {outside['reason']} (goal {outside['goal']:.2%})")
    if refinement is not None:
        report["tolerance"] = {"value": tolerance, "value_mm": tolerance * diagonal_mm,
                               "met": refinement.met, "reason": refinement.reason,
                               "faces": int(fitted.n_faces), "rounds": refinement.rounds}
        if not refinement.met:
            warnings.append(f"warning: {refinement.reason}")
    return FitResult(fitted, report, "; ".join(warnings), levels=levels,
                     cage_self_intersections=info.get("cage_self_intersections"))


def count_limit_self_intersections(base, levels):
    """Intersecting triangle pairs of the level-``levels`` limit mesh of ``base`` (0 = clean)."""
    return int(len(limit_self_intersections(base, levels)[0]))


def limit_self_intersections(base, levels):
    """Where the level-``levels`` limit mesh of ``base`` intersects itself.

    The base mesh is subdivided ``levels >= 1`` times, its vertices moved to their
    limit positions and its quads split into two triangles each.

    Returns
    -------
    pairs : (k, 2) int64 intersecting triangle pairs (``core.self_intersection``).
    base_faces : (k, 2) int64 the base faces the two triangles of each pair lie on.
    points : (k, 3) float64 the centroid of the first triangle of each pair.
    """
    from core.geometry import triangulate
    from core.self_intersection import find_self_intersections
    from core.subdivision.catmull_clark import build_hierarchy, fine_face_owner
    from core.subdivision.limit import limit_matrices

    fine = build_hierarchy(base, levels).meshes[levels]
    limit, _, _ = limit_matrices(fine)
    points = limit @ fine.vertices
    triangles = triangulate(fine.face_vertices, fine.face_offsets)
    pairs = find_self_intersections(points, triangles)
    base_faces = fine_face_owner(base, levels)[pairs // 2]
    return pairs, base_faces, points[triangles[pairs[:, 0]]].mean(axis=1)


@dataclass(frozen=True)
class LimitCrossings:
    """Where a cage's limit surface crosses itself (:func:`export_limit_crossings`).

    levels : int, the subdivision level checked.
    pairs, base_faces, points : as returned by :func:`limit_self_intersections`.
    """

    levels: int
    pairs: np.ndarray
    base_faces: np.ndarray
    points: np.ndarray

    @property
    def count(self):
        """Crossing triangle pairs (0 = the surface does not cross itself)."""
        return int(len(self.pairs))

    def message(self):
        """What crosses and where, for an error message (the surface must cross)."""
        x, y, z = self.points[0]
        return (f"the limit surface intersects itself ({self.count} crossing triangle pairs "
                f"of its level-{self.levels} limit mesh), e.g. between base faces "
                f"{self.base_faces[0, 0]} and {self.base_faces[0, 1]} near "
                f"({x:.6g}, {y:.6g}, {z:.6g}); a STEP solid of it would not be a solid")


def export_limit_crossings(base):
    """The export's check that the limit surface of ``base`` does not cross itself.

    Tested on the limit mesh at :data:`EXPORT_CHECK_LEVELS` (fewer for cages so large that
    the fit takes fewer, :func:`fit_levels`); ``subd-to-step`` refuses a cage that fails it, and
    the pipeline refuses to build a solid of a fitted cage that fails it
    (``core.stages.patches``).

    Returns
    -------
    LimitCrossings
    """
    levels = fit_levels(base.n_faces, EXPORT_CHECK_LEVELS)
    return LimitCrossings(levels, *limit_self_intersections(base, levels))
