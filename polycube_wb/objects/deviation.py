# SPDX-License-Identifier: LGPL-2.1-or-later
"""Deviation: a colour map of the solid's distance to the target, with the check figures.

A ``Mesh::FeaturePython`` holding a tessellation of the solid whose vertices are coloured
by their signed distance to the target (blue inside, white on it, red outside), clipped
at ``Scale`` (model units; 0 picks the largest distance, so the scale covers it). The colour
grows with the square root of the distance, so distances well below the largest still show.
``MaxDeviationAt`` is a point of the tessellation where the largest distance is, which the
legend marks on the model. It also holds the figures of
``Check result``: the mean distance of its vertices, the largest distance both ways
(:func:`core.quality.largest_distances`: the target's thin tips the solid stops short of count
too), volume outside the target and target volume not covered, and watertightness of the
tessellation.
"""
from dataclasses import dataclass

import numpy as np

from polycube_wb.objects.base import FINE_FLOAT, StageFailed, StageProxy, add_property, \
    fingerprint

FIGURES = (("MeanDeviation", "Mean unsigned distance of the solid's tessellation vertices "
            "to the target, model units"),
           ("MaxDeviation", "Largest distance between the solid's tessellation and the "
            "target, both ways, searched over every triangle (to 1e-4 of the diagonal), model "
            "units"),
           ("MaxDeviationPercent", "MaxDeviation in % of the target's bounding-box diagonal"),
           ("MeanDeviationPercent", "MeanDeviation in % of the diagonal"),
           ("OutsideVolume", "Solid volume outside the target, % of the target volume"),
           ("UncoveredVolume", "Target volume the solid does not cover, % of the target "
            "volume"),
           ("ScaleUsed", "Distance shown at the ends of the colour scale, model units (with "
            "Scale 0, the largest of MaxDeviation and the vertices' distances)"))
MAX_RESOLUTION = 1e-4
"""``MaxDeviation`` is found to within this fraction of the target's diagonal."""
INSIDE, ON, OUTSIDE = (0.13, 0.31, 0.85), (0.95, 0.95, 0.95), (0.85, 0.13, 0.13)


class DeviationProxy(StageProxy):
    TYPE = "Polycube::Deviation"
    INPUTS = ("Solid", "Target")

    def init_properties(self, obj):
        super().init_properties(obj)
        add_property(obj, "App::PropertyLink", "Solid", "Deviation", "The result solid")
        add_property(obj, "App::PropertyLink", "Target", "Deviation", "The target mesh")
        add_property(obj, FINE_FLOAT, "Tolerance", "Deviation",
                     "Tessellation tolerance, fraction of the target's diagonal", 1e-3)
        add_property(obj, "App::PropertyFloat", "Scale", "Deviation",
                     "Distance at the ends of the colour scale, model units (0: the largest)",
                     0.0)
        for name, tooltip in FIGURES:
            add_property(obj, "App::PropertyFloat", name, "Result", tooltip, 0.0,
                         read_only=True, output=True)
        add_property(obj, "App::PropertyVector", "MaxDeviationAt", "Result",
                     "Point of the tessellation where the largest distance is (model units)",
                     read_only=True, output=True)
        add_property(obj, "App::PropertyBool", "Watertight", "Result",
                     "The tessellation of the solid is closed and 2-manifold", False,
                     read_only=True, output=True)
        add_property(obj, "App::PropertyFloatList", "SignedDistance", "Result",
                     "Signed distance of every vertex (positive outside the target)",
                     hidden=True, output=True)
        add_property(obj, "App::PropertyColorList", "VertexColors", "Display",
                     "Colour of every vertex (shown by the view provider)", hidden=True,
                     output=True)

    def parameters(self, obj):
        return {"tolerance": float(obj.Tolerance)}

    def inputs(self, obj):
        """The solid and the target: stage objects, or plain ones (a ``Part::Feature``
        solid and a ``Mesh::Feature``, e.g. from ``api.reconstruct`` or an older version)."""
        found = []
        for name, kind in (("Solid", "Part::Feature"), ("Target", "Mesh::Feature")):
            upstream = getattr(obj, name)
            if upstream is None or not upstream.isDerivedFrom(kind):
                raise StageFailed(f"{obj.Label}: its '{name}' link must point to a {kind} "
                                  "object")
            found.append(upstream)
        return found

    def input_id(self, obj):
        """Result ids of stage objects; for plain objects, a hash of their geometry."""
        ids = []
        for upstream in self.inputs(obj):
            if getattr(upstream, "ResultId", ""):
                ids.append(upstream.ResultId)
            elif upstream.isDerivedFrom("Mesh::Feature"):
                ids.append(fingerprint(*_mesh_arrays(upstream)))
            else:
                shape = upstream.Shape
                ids.append(fingerprint(len(shape.Faces), shape.Volume, shape.Area))
        return fingerprint(ids)

    def prepare(self, obj):
        from core.errors import ParameterError
        from polycube_wb.stage_jobs import StageJob

        if not 0 < obj.Tolerance <= 0.1:
            raise ParameterError(f"{obj.Label}: its Tessellation tolerance must be in (0, 0.1] "
                                 f"of the diagonal, got {obj.Tolerance:g}")
        solids = obj.Solid.Shape.Solids
        if len(solids) != 1:
            raise StageFailed(f"{obj.Solid.Label}: expected one solid, found {len(solids)}")
        # a copy: the worker tessellates it while the 3D view may draw the original
        solid, tolerance = solids[0].copy(), float(obj.Tolerance)
        target_V, target_F = _mesh_arrays(obj.Target)
        return StageJob(_deviation, (solid, target_V, target_F, tolerance))

    def store(self, obj, result):
        from polycube_wb.convert import arrays_to_mesh

        for name, value in result.figures.items():
            setattr(obj, name, value)
        obj.Watertight = result.watertight
        obj.MaxDeviationAt = tuple(float(x) for x in result.largest_at)
        obj.SignedDistance = result.signed.tolist()
        obj.Mesh = arrays_to_mesh(result.vertices, result.faces)

    def show(self, obj):
        signed = np.asarray(obj.SignedDistance, dtype=np.float64)
        if len(signed) != obj.Mesh.CountPoints:
            raise StageFailed(f"{obj.Label}: no distances are stored; recompute it")
        scale = obj.Scale if obj.Scale > 0 else max(float(np.abs(signed).max()),
                                                     float(obj.MaxDeviation))
        obj.ScaleUsed = scale
        obj.VertexColors = deviation_colours(signed, scale)
        return fingerprint(signed, scale)

    def load_outputs(self, obj):
        return {}


def _mesh_arrays(obj):
    from polycube_wb.convert import mesh_to_arrays

    return mesh_to_arrays(obj.Mesh)


@dataclass
class DeviationResult:
    """The deviation map's computation.

    vertices : (n, 3) float64, faces : (m, 3) int64, the tessellation of the solid (mm).
    signed : (n,) float64 signed distance of every vertex to the target (mm, + outside).
    figures : dict ``FIGURES`` property name -> value (without ``ScaleUsed``).
    watertight : bool, the tessellation is closed and 2-manifold.
    largest_at : (3,) float64, a point of the tessellation at the largest distance (mm): the
        vertex farthest from the target, or the centroid of the triangle nearest the target's
        point farthest from the solid, whichever distance is larger.
    """

    vertices: np.ndarray
    faces: np.ndarray
    signed: np.ndarray
    figures: dict
    watertight: bool
    largest_at: np.ndarray


def _deviation(solid, target_V, target_F, tolerance, progress):
    """:class:`DeviationResult` of ``solid`` (Part.Solid) against the target mesh
    ``(target_V, target_F)``; ``tolerance`` is the tessellation's, a fraction of the target's
    bounding-box diagonal."""
    from core.quality import containment, is_watertight_manifold, largest_distances
    from core.target_surface import TargetSurface
    from polycube_wb.brep import tessellate

    surface = TargetSurface(target_V, target_F)
    progress.report("tessellate", 0.1)
    V, F = tessellate(solid, tolerance * surface.diagonal)
    progress.report("distances", 0.4)
    signed = surface.closest(V).signed
    progress.check_cancel()
    progress.report("largest distances", 0.55)
    distance = np.abs(signed)
    searched = largest_distances(TargetSurface(V, F, "solid"), surface,
                                 MAX_RESOLUTION * surface.diagonal)
    progress.check_cancel()
    progress.report("containment", 0.7)
    inside = containment(V, F, target_V, target_F)
    mean = float(distance.mean())
    forward, backward = searched
    largest = max(float(distance.max()), float(forward.distance.max()))
    largest_at = V[int(np.argmax(distance))]
    if float(backward.distance.max()) > largest:
        largest = float(backward.distance.max())
        largest_at = V[F[int(backward.face[int(np.argmax(backward.distance))])]].mean(axis=0)
    figures = {"MeanDeviation": mean, "MaxDeviation": largest,
               "MeanDeviationPercent": 100.0 * mean / surface.diagonal,
               "MaxDeviationPercent": 100.0 * largest / surface.diagonal,
               "OutsideVolume": 100.0 * inside["outside_volume_fraction"],
               "UncoveredVolume": 100.0 * inside["uncovered_volume_fraction"]}
    return DeviationResult(V, F, signed, figures, bool(is_watertight_manifold(V, F)),
                           np.asarray(largest_at, dtype=np.float64))


def deviation_colours(signed, scale):
    """RGB per value: blue (-scale) -> white (0) -> red (+scale), clipped beyond; the colour
    moves from white with the square root of ``|signed| / scale`` (a quarter of the scale is
    half-way), so distances well below the largest are not left white.

    Parameters
    ----------
    signed : (n,) float64 signed distances (positive outside).
    scale : float > 0 (0 gives all white).

    Returns
    -------
    list of n (r, g, b) tuples in [0, 1].
    """
    t = np.sqrt(np.clip(np.abs(signed) / scale, 0.0, 1.0)) * np.sign(signed) if scale > 0 \
        else np.zeros_like(signed)
    ends = np.where((t < 0)[:, None], np.asarray(INSIDE), np.asarray(OUTSIDE))
    colours = np.asarray(ON) + np.abs(t)[:, None] * (ends - np.asarray(ON))
    return [tuple(row) for row in colours.tolist()]
