# SPDX-License-Identifier: LGPL-2.1-or-later
"""Solid: the limit surface of a cage as bicubic B-spline faces, a valid closed solid.

A ``Part::FeaturePython`` (its ``Shape`` is saved in the document). Its input is any cage
object: a Fit, or a BaseMesh to see the unfitted limit surface. A cage whose limit surface
crosses itself is refused, as on the command line (no solid of it would be one).
"""
from polycube_wb.objects.base import StageProxy, add_property

FIGURES = (("BrepFaces", "faces", "App::PropertyInteger", "B-spline faces of the solid"),
           ("BrepValid", "valid", "App::PropertyBool", "OpenCascade finds the solid valid"),
           ("BrepVolume", "volume", "App::PropertyFloat", "Volume of the solid, mm³"),
           ("MaxNormalJump", "max_normal_jump_deg", "App::PropertyFloat",
            "Largest normal jump across patch boundaries, degrees"))


class SolidProxy(StageProxy):
    TYPE = "Polycube::Solid"
    INPUTS = ("Cage",)

    def init_properties(self, obj):
        from core.params import MAX_EXPORT_DEPTH
        from polycube_wb.panel_fields import EXPORT_DEPTH_KEY
        from polycube_wb.preferences import default

        super().init_properties(obj)
        add_property(obj, "App::PropertyLink", "Cage", "Solid",
                     "The cage whose limit surface becomes the solid (a Fit or a BaseMesh)")
        add_property(obj, "App::PropertyInteger", "Depth", "Solid",
                     "Patch refinement at irregular (extraordinary) vertices: the grading "
                     f"depth, 1..{MAX_EXPORT_DEPTH}; the solid is the exact limit surface "
                     "except in a cell of size 2^-depth around them",
                     default(EXPORT_DEPTH_KEY))
        from core.params import DEFAULT_EXPORT_FORM, DEFAULT_FACE_FORM, EXPORT_FORMS, FACE_FORMS

        add_property(obj, "App::PropertyEnumeration", "Export", "Solid",
                     "Surface form: exact (graded patches, the Catmull-Clark limit; large) or "
                     "g1 (one light tangent-continuous patch per quad, close to the limit; "
                     "sharp creases stay C0)", list(EXPORT_FORMS), choice=DEFAULT_EXPORT_FORM)
        add_property(obj, "App::PropertyEnumeration", "Faces", "Solid",
                     "B-rep faces of the g1 form: quad (one per quad of the cage) or chart "
                     "(one multi-span face per rectangular block of quads)",
                     list(FACE_FORMS), choice=DEFAULT_FACE_FORM)
        for name, _, kind, tooltip in FIGURES:
            add_property(obj, kind, name, "Result", tooltip, read_only=True, output=True)

    def parameters(self, obj):
        """The depth, and the surface form and faces where they are not the defaults (so a
        solid of a document saved before they existed keeps its parameter id)."""
        from core.params import DEFAULT_EXPORT_FORM, DEFAULT_FACE_FORM

        params = {"depth": int(obj.Depth)}
        if (str(obj.Export), str(obj.Faces)) != (DEFAULT_EXPORT_FORM, DEFAULT_FACE_FORM):
            params.update(export=str(obj.Export), faces=str(obj.Faces))
        return params

    def prepare(self, obj):
        from core.params import check_export_depth, check_export_form, check_face_form
        from polycube_wb.stage_jobs import StageJob

        check_export_depth(obj.Depth, "Depth")
        check_export_form(obj.Export, "Export")
        check_face_form(obj.Faces, obj.Export, "Faces")
        base, depth = self.upstream_state(obj).cage, int(obj.Depth)
        what = f"{obj.Label}: the cage of {obj.Cage.Label}"
        return StageJob(_limit_solid, (base, depth, what, str(obj.Export), str(obj.Faces)))

    def store(self, obj, result):
        solid, brep = result
        obj.Shape = solid
        for name, key, _, _ in FIGURES:
            setattr(obj, name, brep[key])

    def show(self, obj):
        """The solid is a function of the cage and the depth: its id is theirs (hashing the
        B-rep of hundreds of B-spline faces would cost about a second)."""
        from polycube_wb.objects.base import StageFailed, fingerprint

        if obj.Shape.isNull():
            raise StageFailed(f"{obj.Label}: no solid is stored; recompute it")
        return fingerprint(obj.InputId, obj.ParamsId)

    def load_outputs(self, obj):
        return {}


def _limit_solid(base, depth, what, export, faces, progress):
    """(Part.Solid, its figures) of the limit surface of the cage ``base`` (B-spline faces:
    ``export`` "exact" graded to ``depth``, or "g1" with one face per quad or per block of
    quads, ``faces``); ``what`` names the cage in the error when the surface crosses itself.

    Raises
    ------
    core.errors.ExportError
        The limit surface crosses itself (the check of subd-to-step and the pipeline).
    """
    from core.errors import ExportError
    from core.export.bspline import limit_surface_patches
    from core.export.g1_patches import g1_surface_patches
    from core.progress import SubProgress
    from core.subdivision.limit_crossings import export_limit_crossings
    from polycube_wb.brep import build_solid

    progress.report("patches", 0.05)
    crossings = export_limit_crossings(base)
    if crossings.count:
        raise ExportError(f"{what}: {crossings.message()}")
    if export == "g1":
        patches = g1_surface_patches(base, measure=False, faces=faces)
    else:
        patches = limit_surface_patches(base, depth=depth, measure=False)
    progress.check_cancel()
    solid, brep = build_solid(patches, SubProgress(progress, 0.5, 1.0))
    jump = patches.info.get("normal_jump_max_deg")
    brep["max_normal_jump_deg"] = -1.0 if jump is None else float(jump)
    return solid, brep
