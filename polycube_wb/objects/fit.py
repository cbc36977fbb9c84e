# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit: shape optimisation of a cage so its limit surface fills the target from inside.

A ``Part::FeaturePython`` holding the fitted cage (``polycube_wb.objects.cage``). Its input
is any cage object (a BaseMesh, or another Fit to refine further). Editing the fitted
``CageVertices`` does not rerun the fit; the Solid after it follows the edit.
"""
from core.params import FIT_MODES
from polycube_wb.stage_jobs import StageJob, core_stages
from polycube_wb.objects.base import FINE_FLOAT, add_property, stage_params
from polycube_wb.objects.base_mesh import CageProxy
from polycube_wb.objects.cage import add_cage_properties, store_cage

FIGURES = (("MeanDistance", "mean_distance", "Mean distance of the limit surface to the target "
            "(fraction of the bounding-box diagonal)"),
           ("MaxDistance", "max_distance", "Largest distance to the target (fraction of the "
            "diagonal)"),
           ("TargetMaxDistance", "target_max_distance", "Largest distance of the target to the "
            "limit surface: what the surface misses, such as a thin tip (fraction of the "
            "diagonal)"),
           ("OutsideVolume", "outside_volume_fraction", "Volume outside the target (fraction "
            "of the target volume)"),
           ("UncoveredVolume", "uncovered_volume_fraction", "Target volume not covered "
            "(fraction of the target volume)"))


STOPPED_WORDS = {"stalled": "converged"}
"""The fit report's reason to stop -> the word the GUI shows."""


class FitProxy(CageProxy):
    TYPE = "Polycube::Fit"
    INPUTS = ("BaseMesh",)
    RESULT = "fit"

    def init_properties(self, obj):
        from polycube_wb.preferences import default

        super().init_properties(obj)
        add_property(obj, "App::PropertyLink", "BaseMesh", "Fit",
                     "The cage to fit (a base mesh, possibly edited)")
        add_property(obj, "App::PropertyInteger", "Iterations", "Fit",
                     "Shape-optimisation iterations (paper: 100)", default("fit_iterations"))
        add_property(obj, FINE_FLOAT, "Convergence", "Fit",
                     "The inside fit stops when its best objective improved by less than this "
                     "fraction over five iterations (0: run every iteration)",
                     default("fit_convergence"))
        add_property(obj, "App::PropertyInteger", "SubdivisionLevels", "Fit",
                     "Catmull-Clark levels the fit works on (paper: 2; fewer on large cages)",
                     default("subdivision_levels"))
        add_property(obj, "App::PropertyEnumeration", "Mode", "Fit",
                     "'inside': the limit surface fills the target from inside (paper); "
                     "'best-fit': two-sided least squares; 'none': the unfitted surface",
                     list(FIT_MODES), choice=default("fit_mode"))
        add_property(obj, "App::PropertyBool", "AutoMinThickness", "Fit",
                     "Pick the minimal wall thickness from the cage and the target", True)
        add_property(obj, "App::PropertyFloat", "MinThickness", "Fit",
                     "Minimal wall thickness when not automatic, mm (0: no thickness "
                     "constraint)", 0.0)
        add_property(obj, "App::PropertyFloat", "Tolerance", "Fit",
                     "Largest deviation wanted between the fitted surface and the target, mm "
                     "(0: none). Where the surface deviates more, the quad strips there are "
                     "split and the cage fitted again (at most the base mesh's 'Most faces' "
                     "default)", 0.0)
        add_property(obj, FINE_FLOAT, "OutsideRefinement", "Fit",
                     "Inside mode: where the fit leaves more than this fraction of the target's "
                     "volume outside, the quad strips there are split and the cage fitted again "
                     "(0: off)", default("outside_refinement"))
        add_cage_properties(obj)
        for name, _, tooltip in FIGURES:
            add_property(obj, "App::PropertyFloat", name, "Result", tooltip, 0.0,
                         read_only=True, output=True)
        add_property(obj, "App::PropertyString", "Stopped", "Result",
                     "Why the fit stopped: 'iterations' (all of them ran) or 'converged' "
                     "(its objective stopped improving)", "", read_only=True,
                     output=True)
        add_property(obj, "App::PropertyString", "Refinement", "Result",
                     "With a tolerance or volume left outside: whether the goal was met, why the "
                     "refinement stopped and the faces of every fitted cage", "",
                     read_only=True, output=True)
        add_property(obj, "App::PropertyString", "CreaseCurves", "Result",
                     "A cage with sharp creases: how many of its crease edges were fitted to "
                     "the target's feature lines before the fit", "", read_only=True,
                     output=True)

    def parameters(self, obj):
        return {"fit_iterations": int(obj.Iterations),
                "fit_convergence": float(obj.Convergence),
                "subdivision_levels": int(obj.SubdivisionLevels), "fit_mode": obj.Mode,
                "fit_t_min": None if obj.AutoMinThickness else float(obj.MinThickness),
                "tolerance_mm": float(obj.Tolerance),
                "outside_refinement": float(obj.OutsideRefinement)}

    def prepare(self, obj):
        from core.types import BaseMeshResult

        state, params = self.upstream_state(obj), stage_params(**self.parameters(obj))
        # the cage to fit is the linked object's, possibly edited: a base mesh or an earlier fit
        state.basemesh = BaseMeshResult(state.cage)
        return StageJob(core_stages, (state, ("fit",), params))

    def store(self, obj, state):
        fit = state.fit.report
        for name, key, _ in FIGURES:
            setattr(obj, name, float(fit[key]))
        stopped = str(fit.get("stopped", ""))
        obj.Stopped = STOPPED_WORDS.get(stopped, stopped)
        obj.Refinement = "; ".join(filter(None, (
            refinement_summary(fit.get("tolerance")),
            outside_refinement_summary(fit.get("outside_refinement")))))
        obj.CreaseCurves = crease_curves_summary(fit.get("crease_curves"))
        store_cage(obj, state.fit.cage)


def refinement_summary(tolerance):
    """One line on a fit's tolerance refinement (its report's ``tolerance`` section or None)."""
    if not tolerance:
        return ""
    faces = _faces_of_fits(tolerance["rounds"])
    return (f"{tolerance['reason']} ({tolerance['value_mm']:.4g} mm; faces {faces}; largest "
            f"deviation {tolerance['rounds'][-1]['max_deviation']:.3g} of the diagonal)")


def outside_refinement_summary(outside):
    """One line on a fit's refinement where it left volume outside (its report's
    ``outside_refinement`` section or None)."""
    if not outside:
        return ""
    faces = _faces_of_fits(outside["rounds"])
    return (f"volume outside above {outside['goal']:.2%}: {outside['reason']} (faces {faces}; "
            f"kept {outside['faces']})")


def _faces_of_fits(rounds):
    """``'320 -> 523'``: the faces of each fitted cage of a refinement's ``rounds``."""
    return " -> ".join(str(round_["faces"]) for round_ in rounds)


def crease_curves_summary(crease_curves):
    """One line on the crease-curve fit (the fit report's ``crease_curves`` or None)."""
    if not crease_curves:
        return ""
    return (f"{crease_curves['matched']} of {crease_curves['creases']} crease edges fitted to "
            f"the target's feature lines, {crease_curves['held_back']} vertices held back "
            "where the surface would cross itself")
