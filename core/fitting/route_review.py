# SPDX-License-Identifier: LGPL-2.1-or-later
"""Route review: a polycube layout whose least-squares fit crosses itself gives way to the
paired decimation when the decimation fits much closer.

The polycube layout is the preferred base mesh (few extraordinary vertices, quads that follow
the design's directions). Where its embedding leaves stretched quads that pass the layout's
checks (no inverted face, a limit surface that does not cross itself), the least-squares fit
that starts the inside fit can still cross itself; the fit then holds those base vertices back
towards the cage (:func:`core.fitting.crossings.hold_back_crossings`) and the CAD model stays
far from the target there, whatever the later phases do. So when the polycube layout's
least-squares fit had to be held back, the paired decimation is built too, both cages'
least-squares fits are measured (:func:`core.fitting.fit.least_squares_preview`), and the
decimation is kept only when the layout's largest distance is more than
:data:`ROUTE_DISTANCE_RATIO` times the decimation's. A layout whose least-squares fit does not
cross itself is kept without building the decimation.
"""
from dataclasses import dataclass

from core.fitting.fit import least_squares_preview
from core.subdivision.limit_crossings import fit_levels
from core.types import PolyMesh

ROUTE_DISTANCE_RATIO = 2.0
"""The polycube layout gives way when its least-squares fit's largest distance to the target is
more than this many times the paired decimation's (and it had to be held back)."""


@dataclass(frozen=True)
class CagePreview:
    """How close a cage's least-squares fit comes to the target (report ``route_review``).

    held_back : int, base vertices held back where the fit crossed itself.
    largest_distance : float, the larger one-sided maximum distance between its limit surface
        and the target, fraction of the target's bounding-box diagonal.
    mean_distance : float, mean distance of the target's samples to it, same unit.
    """

    held_back: int
    largest_distance: float
    mean_distance: float

    def section(self):
        """The preview in the report (JSON-serialisable dict)."""
        return {"held_back": self.held_back, "largest_distance": self.largest_distance,
                "mean_distance": self.mean_distance}


@dataclass(frozen=True)
class ReviewedRoute:
    """The cage kept by :func:`review_route` and its base-mesh report (with a
    ``route_review`` section: each route's :class:`CagePreview` and the route kept)."""

    cage: PolyMesh
    info: dict


def preview_cage(cage, target, subdivision_levels, fit_mode="inside"):
    """:class:`CagePreview` of ``cage`` (PolyMesh) against ``target`` (TriMesh) at the level
    the fit uses (:func:`core.subdivision.limit_crossings.fit_levels`), its least-squares fit
    made as ``fit_mode`` (``'inside'`` or ``'best-fit'``) makes it."""
    least_squares, distances = least_squares_preview(
        cage, target, levels=fit_levels(cage.n_faces, subdivision_levels), mode=fit_mode)
    return CagePreview(int(least_squares.untangled.held_back),
                       max(distances.max_distance, distances.target_max_distance),
                       distances.target_mean_distance)


def decimation_wins(layout, decimation):
    """True when the polycube layout's least-squares fit was held back (``layout``, a
    :class:`CagePreview`) and its largest distance is more than :data:`ROUTE_DISTANCE_RATIO`
    times the paired decimation's (``decimation``, a :class:`CagePreview`)."""
    return (layout.held_back > 0
            and layout.largest_distance > ROUTE_DISTANCE_RATIO * decimation.largest_distance)


def review_route(cage, info, target, subdivision_levels, build_decimation, fit_mode="inside",
                 decimation_preview=None):
    """Keep the polycube layout ``cage`` unless its least-squares fit is held back and the
    paired decimation's fits much closer (this module's docstring).

    Parameters
    ----------
    cage : PolyMesh, the polycube layout; info : dict, its base-mesh report
        (:func:`core.quadmesh.base_mesh.build_base_mesh`).
    target : TriMesh, the surface the base mesh was built on.
    subdivision_levels : int, the fit's subdivision levels (``params.subdivision_levels``).
    build_decimation : callable ``() -> (PolyMesh, dict)``, the paired decimation's cage and
        report (``build_base_mesh(..., method="decimation")``).
    fit_mode : ``'inside'`` or ``'best-fit'``, the fit that will follow (``params.fit_mode``).
    decimation_preview : CagePreview of the cage ``build_decimation`` gives, where already
        measured (another layout of the same target was reviewed against it), or None.

    Returns
    -------
    ReviewedRoute; when the decimation is kept, its report's ``fallback_reason`` says why and
    its ``candidates`` keep the polycube layout's entry.
    """
    layout = preview_cage(cage, target, subdivision_levels, fit_mode)
    review = {"polycube": layout.section(), "paired decimation": None, "kept": "polycube"}
    if layout.held_back == 0:
        return ReviewedRoute(cage, {**info, "route_review": review})
    other_cage, other_info = build_decimation()
    other = (preview_cage(other_cage, target, subdivision_levels, fit_mode)
             if decimation_preview is None else decimation_preview)
    review["paired decimation"] = other.section()
    if not decimation_wins(layout, other):
        return ReviewedRoute(cage, {**info, "route_review": review})
    review["kept"] = "paired decimation"
    reason = (f"the polycube layout's least-squares fit crossed itself and was held back at "
              f"{layout.held_back} base vertices, leaving a largest distance of "
              f"{layout.largest_distance:.2%} of the diagonal, more than "
              f"{ROUTE_DISTANCE_RATIO:g} times the paired decimation's "
              f"({other.largest_distance:.2%})")
    candidates = dict(other_info.get("candidates") or {})
    candidates["polycube"] = (info.get("candidates") or {}).get("polycube")
    return ReviewedRoute(other_cage, {**other_info, "fallback_reason": reason,
                                      "candidates": candidates, "route_review": review})
