# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit stage: move the cage so its limit surface fits the target (paper Sect. 2.4-2.5,
Eqs. 4-11), refining quad strips until a tolerance is met when one is asked for."""
import numpy as np

from core.subdivision.limit_crossings import (count_limit_self_intersections, fit_levels,
                                              limit_self_intersections)
from core.types import FitResult

FIT_REPORT_KEYS = ("start", "rounds", "iterations", "stopped", "mean_distance", "max_distance",
                   "target_mean_distance", "target_max_distance",
                   "outside_volume_fraction", "uncovered_volume_fraction", "initial_mean_distance",
                   "initial_max_distance", "initial_target_mean_distance",
                   "initial_target_max_distance", "t_min", "seconds", "measure_seconds", "refits",
                   "refit_crossings", "cold_refit_crossings", "stiffened", "held_back",
                   "rgp_held_back", "rgp_retried", "rgp_passes", "nudged", "pull_crossings",
                   "cage_self_intersections", "crease_curves", "outside_refinement")
"""Figures of ``core.fitting.fit_base_mesh``'s info copied into the report, when present."""


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
