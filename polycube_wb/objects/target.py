# SPDX-License-Identifier: LGPL-2.1-or-later
"""The target: the triangle mesh to reconstruct, embedded in the document.

A ``Mesh::FeaturePython`` whose ``Mesh`` is the validated target (saved in the
``.FCStd``), so the document needs no file on disk. Its placement is honoured: the stages
after it see the mesh where it is shown. ``execute`` validates the mesh again (intake)
when its points or placement changed.
"""
import numpy as np

from polycube_wb.objects.base import StageProxy, add_property, fingerprint, stage_params

GROUP = "Target"


class TargetProxy(StageProxy):
    TYPE = "Polycube::Target"

    def init_properties(self, obj):
        super().init_properties(obj)
        add_property(obj, "App::PropertyString", "SourceFile", GROUP,
                     "Mesh file the target was read from (for information; not read again)",
                     "", read_only=True)
        add_property(obj, "App::PropertyBool", "CheckSelfIntersections", GROUP,
                     "Test the mesh for self-intersections when it is validated", True)
        for name, tooltip in (("Genus", "Genus of the validated mesh"),
                              ("Triangles", "Triangles of the validated mesh")):
            add_property(obj, "App::PropertyInteger", name, GROUP, tooltip, 0, read_only=True,
                         output=True)

    def parameters(self, obj):
        return {"check_self_intersections": bool(obj.CheckSelfIntersections)}

    def inputs(self, obj):
        return []

    def input_id(self, obj):
        V, F = _mesh_arrays(obj)
        return fingerprint(V, F)

    def prepare(self, obj):
        from polycube_wb.stage_jobs import StageJob, intake

        V, F = _mesh_arrays(obj)
        params = stage_params(check_self_intersections=bool(obj.CheckSelfIntersections))
        return StageJob(intake, (obj.Label, V, F, params))

    def store(self, obj, result):
        self._cache = result
        intake = result["intake"]
        obj.Genus = intake.genus
        obj.Triangles = int(len(intake.target.faces))

    def show(self, obj):
        V, F = _mesh_arrays(obj)
        return fingerprint(V, F)

    def load_outputs(self, obj):
        from core.progress import NO_PROGRESS

        return self.prepare(obj)(NO_PROGRESS)


def _mesh_arrays(obj):
    """(V (n, 3) float64 with the placement applied, F (m, 3) int64) of the object's mesh."""
    from polycube_wb.convert import mesh_to_arrays

    V, F = mesh_to_arrays(obj.Mesh)
    return np.ascontiguousarray(V), np.ascontiguousarray(F)
