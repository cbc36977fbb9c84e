# SPDX-License-Identifier: LGPL-2.1-or-later
"""Typed records of the fit's phases (:func:`core.fitting.fit.fit_base_mesh`).

The fit is a sequence of phases, each returning one record:

1. :class:`FitSetup`: the subdivision hierarchy, the limit map and the target, built once;
2. the crease curves placed on the target's feature lines
   (:class:`core.fitting.crease_curves.CreaseFit`, creased cages only);
3. :class:`LeastSquaresFit`: the two-sided least-squares fit, untangled where it crosses
   itself (:class:`Untangling`);
4. :class:`InsideStart`: that fit (or the creased cage) pulled just inside the target;
5. :class:`InsideFit`: the relaxed gradient projection (paper Sect. 2.5) from there;
6. :class:`FitFigures`: distances and containment of the result and of the cage.

:class:`FitRecord` holds them all; the fit stage builds its report section from it
(:func:`core.stages.fit.fit_section`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only: the records import nothing of the fit
    import numpy as np
    from scipy import sparse

    from core.fitting.crease_curves import CreaseFit
    from core.target_surface import TargetSurface


@dataclass(frozen=True)
class FitSetup:
    """What every phase of one fit works on.

    target : TargetSurface of the target, its long triangles split (the fit's many
        closest-point queries search pieces of them).
    target_volume : float > 0, volume the target encloses (model units cubed).
    hierarchy : core.subdivision.catmull_clark hierarchy of the base mesh to ``levels``.
    limit_map : (f, n) sparse CSR, base vertices to the level-``levels`` limit points.
    mapping : (f, n) sparse, the fine positions the responses use: ``limit_map``, or the
        level-``levels`` control points (``surface='control'``, paper Eq. 10).
    triangles : (t, 3) int64 triangles of the level-``levels`` mesh.
    surface : ``'limit'`` or ``'control'``.
    """

    target: TargetSurface
    target_volume: float
    hierarchy: object
    limit_map: sparse.csr_matrix
    mapping: sparse.spmatrix
    triangles: np.ndarray
    surface: str

    @property
    def levels(self):
        """int, the subdivision level of the fine points."""
        return len(self.hierarchy.meshes) - 1


@dataclass(frozen=True)
class Untangling:
    """The least-squares fit made not to cross itself (:func:`core.fitting.fit._untangled`).

    vertices : (n, 3) float64 base vertices.
    crossings : int, crossing triangle pairs of their limit surface.
    stiffness : (n,) float64 smoothness weights of the fit (ones: no refit).
    refits : int, refits with a stiffer smoothness term run.
    refit_crossings : list of int, crossing pairs after the first fit and each refit.
    cold_refit_crossings : list of int or None, the same of the refits made the long way
        (None: not made).
    stiffened : int, base vertices with a stiffer smoothness term.
    held_back : int, base vertices held back towards the cage where the fit still crossed.
    cage_self_intersections : int or None, crossing pairs of the cage's limit surface,
        counted when the refitted fit still crossed (None: not counted).
    """

    vertices: np.ndarray
    crossings: int
    stiffness: np.ndarray
    refits: int
    refit_crossings: list
    cold_refit_crossings: list | None
    stiffened: int
    held_back: int
    cage_self_intersections: int | None


@dataclass(frozen=True)
class LeastSquaresFit:
    """The two-sided least-squares fit (:func:`core.fitting.best_fit.best_fit`), untangled.

    rounds : int, Gauss-Newton rounds of both levels.
    rms : list of float, two-sided RMS distances of the fine-level rounds (model units).
    coarse_rms : list of float, the same of the level-1 rounds (empty: none ran).
    stopped : ``'converged'`` or ``'rounds'``, why the fine-level rounds stopped.
    untangled : Untangling, the fit made not to cross itself.
    """

    rounds: int
    rms: list
    coarse_rms: list
    stopped: str
    untangled: Untangling

    @property
    def vertices(self):
        """(n, 3) float64 base vertices of the untangled fit."""
        return self.untangled.vertices

    @property
    def crossings(self):
        """int, crossing triangle pairs of their limit surface."""
        return self.untangled.crossings


@dataclass(frozen=True)
class InsideStart:
    """Start of the inside fit: pulled just inside the target, held back where it crossed.

    vertices : (n, 3) float64 base vertices.
    crossings : int, crossing triangle pairs of their limit surface.
    label : str, what it started from (``'best-fit'``, or the creased cage's
        ``core.fitting.fit.CREASED_START``), and how many base vertices were held back.
    margin : float, the depth pulled to (model units).
    pull_crossings : list of int, crossing pairs of the pull and of each stiffer pull.
    held_back : int, base vertices held back, of the least-squares fit and of the pull.
    stiffness : (n,) float64 or None, the smoothness weights of the pull kept (None: the
        plain smoothness term of a creased cage's start).
    """

    vertices: np.ndarray
    crossings: int
    label: str
    margin: float
    pull_crossings: list
    held_back: int
    stiffness: np.ndarray | None = None


@dataclass(frozen=True)
class WarmStart:
    """Where the inside fit of a refined cage starts, carried from the fit of the cage it
    refines (:mod:`core.fitting.outside_refinement`, ``WARM_START`` of
    :mod:`core.fitting.fit`).

    vertices : (n, 3) float64 that fit's least-squares fit, placed on the refined cage
        (:func:`core.fitting.refine.split_positions`).
    pull_stiffness : (n,) float64 or None, the smoothness weights of that fit's pull inside,
        on the refined cage's vertices (:func:`core.fitting.refine.split_values` of their
        logarithms); None: the pull starts with the plain term.
    """

    vertices: np.ndarray
    pull_stiffness: np.ndarray | None = None


@dataclass(frozen=True)
class InsideFit:
    """The relaxed gradient projection (:func:`core.fitting.rgp.run_rgp`) and what followed.

    vertices : (n, 3) float64 base vertices.
    crossings : int or None, crossing triangle pairs of their fine mesh (None: not known).
    iterations : int, RGP iterations of all runs and passes.
    stopped : str, why the (last) RGP run stopped.
    best_iteration : int, iteration of the RGP's best design.
    objective, volume : list of float, per iteration of the RGP run returned.
    t_min : float, minimal wall thickness (model units; 0: not constrained).
    step : float, largest base-vertex move per iteration of the first run (model units).
    held_back : int, base vertices whose RGP move was cut back where the surface crossed.
    retried : bool, the RGP ran again from its start (without the default thickness
        constraint, or with a shorter step).
    passes : list of [iterations, held back] or None, the further passes around the
        crossings (None: none ran).
    nudged : list of int or None, base vertices moved in each round of
        :func:`core.fitting.contain.nudge_inside` (None: not nudged).
    polish : list of int, iterations of each RGP run with a shorter step after the first
        (:func:`core.fitting.fit._polished`).
    """

    vertices: np.ndarray
    crossings: int | None
    iterations: int
    stopped: str
    best_iteration: int
    objective: list
    volume: list
    t_min: float
    step: float
    held_back: int
    retried: bool
    passes: list | None
    nudged: list | None
    polish: list = field(default_factory=list)


@dataclass(frozen=True)
class Distances:
    """Both one-sided distances between a fine limit surface and the target, as fractions
    of the target's bounding-box diagonal.

    mean_distance, max_distance : the fine limit points to the target.
    target_mean_distance, target_max_distance : area-weighted target samples (the maximum
        also over the target's vertices) to the triangulated limit surface.
    """

    mean_distance: float
    max_distance: float
    target_mean_distance: float
    target_max_distance: float


@dataclass(frozen=True)
class FitFigures:
    """How well the result fits, and how well the cage did.

    distances : Distances of the result; initial : Distances of the cage as given.
    outside_volume_fraction, uncovered_volume_fraction : float, the triangulated fine limit
        mesh minus the target and the target minus it, over the target's volume.
    seconds : float, wall-clock seconds of these measurements.
    """

    distances: Distances
    initial: Distances
    outside_volume_fraction: float
    uncovered_volume_fraction: float
    seconds: float


@dataclass(frozen=True)
class OutsideRefinementSummary:
    """The cage refined where the inside fit left volume outside
    (:func:`core.fitting.outside_refinement.fit_with_outside_refinement`).

    goal : float, fraction of the target's volume allowed outside.
    reason : str, why the refinement stopped.
    rounds : list of dict, per fit (``faces``, ``outside_volume_fraction``,
        ``refined_faces``).
    faces : int, faces of the cage kept.
    """

    goal: float
    reason: str
    rounds: list
    faces: int


@dataclass(frozen=True)
class FitRecord:
    """Everything one fit did (:func:`core.fitting.fit.fit_base_mesh`).

    mode, levels, surface : the fit's mode, subdivision level and fitted surface.
    start : str or None, what the fit started from (None: the cage, no least-squares fit).
    figures : FitFigures.
    seconds : float, wall-clock seconds of the whole fit.
    crease_curves : CreaseFit or None (a cage without creases, or mode ``'none'``).
    least_squares : LeastSquaresFit or None (inside mode from the cage or a creased cage).
    inside_start : InsideStart or None (inside mode from ``start='best-fit'`` only).
    inside : InsideFit or None (inside mode only).
    self_intersections : int or None, crossing triangle pairs of the result's limit
        surface when the fit counted them (``surface='limit'``).
    cage_self_intersections : int or None, the same of the cage, counted when the result
        (or the least-squares fit) still crosses.
    outside_refinement : OutsideRefinementSummary or None, set by the fit stage when the
        cage was refined where the fit left volume outside.
    """

    mode: str
    levels: int
    surface: str
    start: str | None
    figures: FitFigures
    seconds: float
    crease_curves: CreaseFit | None = None
    least_squares: LeastSquaresFit | None = None
    inside_start: InsideStart | None = None
    inside: InsideFit | None = None
    self_intersections: int | None = None
    cage_self_intersections: int | None = None
    outside_refinement: OutsideRefinementSummary | None = None

    @property
    def rounds(self):
        """int, least-squares rounds run (0: none)."""
        return 0 if self.least_squares is None else self.least_squares.rounds

    @property
    def iterations(self):
        """int, RGP iterations run (0: none)."""
        return 0 if self.inside is None else self.inside.iterations

    @property
    def stopped(self):
        """str, why the last optimisation stopped (``'none'``: none ran)."""
        if self.inside is not None:
            return self.inside.stopped
        return "none" if self.least_squares is None else self.least_squares.stopped

    @property
    def held_back(self):
        """int or None, base vertices held back where a start crossed itself (None: no
        least-squares fit and no inside start)."""
        if self.inside_start is not None:
            return self.inside_start.held_back
        return None if self.least_squares is None else self.least_squares.untangled.held_back
