# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit stage: move the cage so its limit surface fits the target (paper Sect. 2.4-2.5,
Eqs. 4-11), refining quad strips until a tolerance is met when one is asked for."""
from dataclasses import replace

import numpy as np

from core.subdivision.limit_crossings import (count_limit_self_intersections, fit_levels,
                                              limit_self_intersections)
from core.types import FitResult


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

    checked = []  # (cage, its crossing base faces) of every cage checked, the same object

    def crossing_faces(cage):
        # each cage is checked once: a refinement round checks the cage it refines, which
        # the round before checked as its refinement
        for known, faces in checked:
            if known is cage:
                return faces
        faces = limit_self_intersections(cage, levels_of(cage))[1]
        checked.append((cage, faces))
        return faces

    def fit_once(cage, warm=None):
        return fit_base_mesh(cage, target, levels=levels_of(cage),
                             iterations=params.fit_iterations, mode=params.fit_mode,
                             t_min=params.fit_t_min, tol=params.fit_convergence,
                             progress=progress, warm=warm)

    def fit(cage):
        if params.fit_mode != "inside" or not params.outside_refinement:
            return fit_once(cage)
        from core.fitting.outside_refinement import fit_with_outside_refinement
        from core.fitting.records import OutsideRefinementSummary

        refined = fit_with_outside_refinement(cage, target, fit_once, params.outside_refinement,
                                              params.max_base_faces, crossing_faces,
                                              progress=progress)
        record = refined.info
        if refined.reason:  # the first fit left more than the goal outside
            record = replace(record, outside_refinement=OutsideRefinementSummary(
                params.outside_refinement, refined.reason, refined.rounds,
                int(refined.mesh.n_faces)))
        return refined.mesh, record

    diagonal_mm = float(np.linalg.norm(np.ptp(target.vertices, axis=0)))
    tolerance = params.tolerance or params.tolerance_mm / diagonal_mm
    refinement = None
    if tolerance > 0:
        from core.fitting.refine import fit_to_tolerance

        refinement = fit_to_tolerance(base, target, tolerance, params.max_base_faces, fit,
                                      crossing_faces=crossing_faces)
        fitted, record = refinement.mesh, refinement.info
    else:
        fitted, record = fit(base)
    levels = record.levels
    report = {"mode": params.fit_mode, "levels": levels, **fit_section(record)}
    report["self_intersections"] = (record.self_intersections
                                    if record.self_intersections is not None
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
                     cage_self_intersections=record.cage_self_intersections)


def fit_section(record):
    """The fit's figures in the report (docs/REFERENCE.md, "The report"), from its records.

    Parameters
    ----------
    record : core.fitting.records.FitRecord

    Returns
    -------
    dict: ``start`` (when the fit started from more than the cage), ``rounds``,
    ``iterations``, ``stopped``, the distances and volume fractions of the result and the
    ``initial_`` distances of the cage, ``t_min`` (inside mode), ``seconds``,
    ``measure_seconds``, then what the phases that ran did (:func:`_phase_section`).
    """
    section = {} if record.start is None else {"start": record.start}
    section.update(rounds=record.rounds, iterations=record.iterations, stopped=record.stopped)
    figures = record.figures
    section.update(vars(figures.distances))
    section.update(outside_volume_fraction=figures.outside_volume_fraction,
                   uncovered_volume_fraction=figures.uncovered_volume_fraction)
    section.update({"initial_" + key: value for key, value in vars(figures.initial).items()})
    if record.inside is not None:
        section["t_min"] = record.inside.t_min
    section.update(seconds=record.seconds, measure_seconds=figures.seconds)
    section.update(_phase_section(record))
    return section


def _phase_section(record):
    """What the phases of a fit did: the least-squares fit's refits (``refits``,
    ``refit_crossings``, ``cold_refit_crossings``, ``stiffened``), the base vertices
    ``held_back`` at the start, the RGP's (``rgp_held_back``, ``rgp_retried``, ``rgp_polish``,
    ``rgp_passes``, ``nudged``), the inside start's ``pull_crossings``, the cage's
    ``cage_self_intersections``, the ``crease_curves`` and the ``outside_refinement``;
    each only when that phase ran or that happened."""
    section = {}
    untangled = None if record.least_squares is None else record.least_squares.untangled
    if untangled is not None:
        section.update(refits=untangled.refits, refit_crossings=untangled.refit_crossings)
        if untangled.cold_refit_crossings is not None:
            section["cold_refit_crossings"] = untangled.cold_refit_crossings
        section["stiffened"] = untangled.stiffened
    if record.held_back is not None:
        section["held_back"] = record.held_back
    section.update(_inside_section(record.inside))
    if record.inside_start is not None:
        section["pull_crossings"] = record.inside_start.pull_crossings
    if record.cage_self_intersections is not None:
        section["cage_self_intersections"] = record.cage_self_intersections
    if record.crease_curves is not None:
        creased = record.crease_curves
        section["crease_curves"] = {"matched": creased.matched, "creases": creased.creases,
                                    "held_back": creased.held}
    if record.outside_refinement is not None:
        section["outside_refinement"] = dict(vars(record.outside_refinement))
    return section


def _inside_section(inside):
    """The RGP's hold-backs, retry, shorter-step runs, passes and nudges (none without an
    inside fit)."""
    if inside is None:
        return {}
    section = {"rgp_held_back": inside.held_back}
    if inside.retried:
        section["rgp_retried"] = True
    if inside.passes is not None:
        section["rgp_passes"] = inside.passes
    if inside.nudged is not None:
        section["nudged"] = inside.nudged
    if inside.polish:
        section["rgp_polish"] = inside.polish
    return section
