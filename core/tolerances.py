# SPDX-License-Identifier: LGPL-2.1-or-later
"""Geometric tolerances shared by the stages, as fractions of the bounding-box diagonal.

Every test that decides whether two points coincide or a face has no area uses one of
these, scaled by the diagonal of the mesh it looks at (so the decisions do not depend on
the model's units). Tolerances that belong to one algorithm (a solver's stall test, the
quantization's face budget) stay with it. The one absolute tolerance is the B-rep's
(:data:`BREP_MM`), which OpenCascade fixes in model units.
"""

MERGE = 1e-8
"""Intake merges vertices closer than ``MERGE * diagonal`` (per coordinate, after rounding
to that grid): STL stores every triangle's corners separately, often printed with a few
digits of noise."""

ZERO_AREA = 1e-14
"""A face whose ``|(b - a) x (c - a)|`` (twice its area; a polygon's Newell vector) is at
most ``ZERO_AREA * diagonal^2`` has no area: intake rejects it, the labeling refuses to
take its normal, the cage check rejects it."""

CONTACT = 1e-9
"""Points closer than ``CONTACT * diagonal`` touch, the slack for the rounding of computed
positions: triangles meeting only that closely are not self-intersecting, a patch corner
that near an extraordinary vertex is at it, samples of neighbouring patches that close are
welded into one vertex of the tessellation, a cage vertex that near a target vertex sits on
it, a closest point that near an edge or corner of the target takes its pseudo-normal, a
fine point that near the target is on it (not outside it), a fine point that shallow below the target is queried again when its inside bound does
not prove it inside, a ray's exit that near its start (times the ray's length) does not
count, and the fit's box and distance bounds are widened by it (relative to the largest
coordinate where no diagonal is at hand)."""

BREP_MM = 1e-7
"""Tolerance of the B-rep's vertices, edges and faces, in millimetres (absolute: OpenCascade's
``Precision::Confusion``); the exported cages' coordinate range is checked against it."""
