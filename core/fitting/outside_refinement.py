# SPDX-License-Identifier: LGPL-2.1-or-later
"""Refine the cage where an inside fit leaves volume outside the target.

The inside fit (:func:`core.fitting.fit.fit_base_mesh`) holds its moves back where the limit
surface would cross itself. On a thin plate that a coarse cage spans with wide stencils (a
plate many times thinner than the cage's edges) the relaxed gradient projection pulls the
plate's two walls through each other, the hold-back returns those base vertices towards the
start, and the start lies partly outside, so a visible share of the target's volume stays
outside, varying with the last bits of the cage. A finer cage there has narrower stencils
and fills the plate from inside.

:func:`fit_with_outside_refinement` fits, and while more than ``goal`` of the target's volume
lies outside, splits the quad strips of the **unfitted** cage through the base faces whose
fine limit points lie outside (:func:`core.fitting.refine.refined_without_crossings`, the
refined cage on the same limit surface) and fits that again. The fitted cage is not
refined: its limit surface nearly touches itself where the walls were held back, and its
refinements cross themselves. The fit of the refined cage starts from the least-squares fit
of the cage it refines, split the same way, and its pull inside from that fit's smoothness
weights (``WARM_START`` of :mod:`core.fitting.fit`): that fit has made the large moves
already, and its pull found where the walls cross. The fit that leaves the least volume
outside is kept. A refined cage's fit is refined again only where it leaves more than
``OUTSIDE.again`` times the goal outside.

The default goal (``outside_refinement`` of :class:`core.params.ReconstructionParams`, 0.003)
is three fifths of the 0.5 % containment goal: the fit's figure is measured on its level-``i``
limit mesh, and an independent check on the exported solid samples the exact surface. Most
fits at defaults leave less and are not refined.
"""
from dataclasses import dataclass, field

import numpy as np

from core.fitting.deviation import fine_limit_points
from core.fitting.records import FitRecord, WarmStart
from core.fitting.refine import refined_without_crossings, split_positions, split_values
from core.target_surface import TargetSurface
from core.types import PolyMesh


@dataclass(frozen=True)
class OutsideRefinementSettings:
    """Tuned constants of :func:`fit_with_outside_refinement`."""

    depth: float = 1e-3
    """Depth outside the target, a fraction of its bounding-box diagonal, beyond which a fine
    limit point has its base face refined."""
    rounds: int = 2
    """Most refinements."""
    again: float = 5.0 / 3.0
    """Volume outside, times the goal, above which a refined cage's fit is refined again (the
    0.5 % containment goal at the default goal). A second refinement splits a few strips of
    a fit already near the goal, as often leaves more outside than less (the fit leaving
    least is kept either way) and costs a whole fit; where the first refinement left
    several times the goal, it takes off a good part of that."""


OUTSIDE = OutsideRefinementSettings()
"""The settings this module runs with."""


@dataclass
class OutsideRefinement:
    """Outcome of :func:`fit_with_outside_refinement`.

    mesh : PolyMesh, the fitted cage leaving the least volume outside.
    info : core.fitting.records.FitRecord, its fit's record.
    rounds : list of dict, per fit: ``faces``, ``outside_volume_fraction``,
        ``refined_faces`` (base faces with outside points, whose strips the next cage
        splits; 0 for the last fit).
    reason : str, why the refinement stopped ('' when the first fit met the goal).
    """

    mesh: PolyMesh
    info: FitRecord
    rounds: list = field(default_factory=list)
    reason: str = ""


def fit_with_outside_refinement(base, target, fit, goal, max_faces, crossing_faces=None,
                                rounds=OUTSIDE.rounds, progress=None):
    """Fit ``base``; while too much volume is outside, refine the cage there and fit again.

    Parameters
    ----------
    base : PolyMesh, the cage to fit (closed, quad-dominant, unfitted).
    target : TriMesh, closed, outward oriented.
    fit : callable ``fit(cage, warm) -> (fitted PolyMesh, FitRecord)``, the configured inside
        fit (``warm``: None, or the core.fitting.records.WarmStart of a refined cage, the
        ``warm`` of :func:`core.fitting.fit.fit_base_mesh`).
    goal : float >= 0, fraction of the target's volume allowed outside; 0: no refinement.
    max_faces : int, no cage with more faces is fitted.
    crossing_faces : None or callable ``crossing_faces(cage) -> (k, 2) int``, the base faces
        where a cage's limit surface crosses itself (a refinement crossing more than the
        unfitted cage is not fitted, :func:`core.fitting.refine.refined_without_crossings`).
    rounds : int >= 0, most refinements; after the first, only while the last fit leaves
        more than ``OUTSIDE.again * goal`` outside.
    progress : core.progress.Progress or None, told when a refined cage is fitted.

    Returns
    -------
    OutsideRefinement
    """
    fitted, info = fit(base, None)
    result = OutsideRefinement(fitted, info)
    cage, surface = base, None
    for done in range(rounds + 1):
        outside = float(info.figures.outside_volume_fraction)
        result.rounds.append({"faces": int(fitted.n_faces), "outside_volume_fraction": outside,
                              "refined_faces": 0})
        if outside < result.info.figures.outside_volume_fraction:
            result.mesh, result.info = fitted, info
        if not goal or outside <= goal:
            result.reason = "" if done == 0 else (f"{outside:.3%} of the volume outside after "
                                                  f"{done} refinement{'s' * (done > 1)}")
            return result
        if done == rounds or (done and outside <= OUTSIDE.again * goal):
            further = "" if done == rounds else (f" (refined again only above "
                                                 f"{OUTSIDE.again * goal:.3%})")
            result.reason = _kept(result, f"still {outside:.3%} outside after {done} "
                                          f"refinement{'s' * (done > 1)}{further}")
            return result
        if surface is None:
            surface = TargetSurface(target.vertices, target.faces)
        marked = faces_outside(fitted, info.levels, surface, OUTSIDE.depth)
        result.rounds[-1]["refined_faces"] = int(marked.sum())
        refined, why_not, split = (None, "no point lies deeper outside than "
                                   f"{OUTSIDE.depth:g} of the diagonal", None) \
            if not marked.any() else refined_without_crossings(cage, marked, crossing_faces,
                                                               with_split=True)
        if refined is not None and refined.n_faces > max_faces:
            why_not = (f"the refined cage would have {refined.n_faces} faces, more than "
                       f"max_base_faces={max_faces}")
            refined = None
        if refined is None:
            result.reason = _kept(result, f"{outside:.3%} outside, not refined: {why_not}")
            return result
        if progress is not None:
            progress.report("fit", 0.0, f"{outside:.2%} of the volume outside: fitting a "
                                        f"cage refined there ({refined.n_faces} faces)")
        warm = _warm_start(cage, split, info)
        cage = refined
        fitted, info = fit(cage, warm)


def _warm_start(cage, split, info):
    """The WarmStart of the fit of ``cage`` split by ``split``
    (core.fitting.refine.StripSplit), carried from ``info`` (the FitRecord of the fit of
    ``cage``): its least-squares fit placed on the refined cage, its pull's smoothness
    weights spread to the new vertices as geometric means; None without a least-squares
    fit."""
    if info.least_squares is None:
        return None
    vertices = split_positions(cage, split, info.least_squares.vertices)
    weights = None if info.inside_start is None else info.inside_start.stiffness
    if weights is not None:
        weights = np.exp(split_values(cage, split, np.log(weights)))
    return WarmStart(vertices, weights)


def _kept(result, reason):
    """``reason``, and which fit is kept when it is not the last one."""
    if result.mesh.n_faces == result.rounds[-1]["faces"]:
        return reason
    return (f"{reason}; the fit of the {result.mesh.n_faces}-face cage is kept "
            f"({result.info.figures.outside_volume_fraction:.3%} outside)")


def faces_outside(cage, levels, surface, depth):
    """(m,) bool base faces with a level-``levels`` limit point outside the target deeper
    than ``depth`` (fraction of ``surface.diagonal``).

    cage : PolyMesh, closed; surface : TargetSurface of the target.
    """
    X, fine, owner = fine_limit_points(cage, levels)
    outside = surface.closest(X).signed > depth * surface.diagonal
    quads = fine.face_vertices.reshape(-1, 4)
    marked = np.zeros(cage.n_faces, dtype=bool)
    marked[owner[outside[quads].any(axis=1)]] = True
    return marked
