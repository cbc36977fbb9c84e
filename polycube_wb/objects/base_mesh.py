# SPDX-License-Identifier: LGPL-2.1-or-later
"""BaseMesh: the coarse quad base mesh (the cage) built from the polycube labeling (or, as
fallback, from a paired decimation of the target; ``Method``).

A ``Part::FeaturePython`` whose shape is the cage's vertices and edges, stored in the
document (``polycube_wb.objects.cage``). It runs the core stages between the labeling and
the fit (read from ``core.pipeline.CORE_STAGES``: the quantized base mesh).
Editing ``CageVertices`` reruns only the stages after it (the fit starts from the edited
cage).
"""
import numpy as np

from core.params import BASE_MESH_METHODS
from polycube_wb.stage_jobs import StageJob, core_stages
from polycube_wb.objects.base import StageProxy, add_property, fingerprint, stage_params
from polycube_wb.objects.cage import add_cage_properties, cage_shape, read_cage, store_cage


def base_mesh_stages():
    """Core stage names after ``labeling`` and before ``fit``."""
    from core.pipeline import CORE_STAGES

    return CORE_STAGES[CORE_STAGES.index("labeling") + 1:CORE_STAGES.index("fit")]


class CageProxy(StageProxy):
    """A stage whose result is a cage (base mesh or fitted base mesh).

    ``RESULT`` is the ``core.types.PipelineState`` field the stored cage fills.
    """

    RESULT = "basemesh"

    def show(self, obj):
        mesh = read_cage(obj)
        obj.Shape = cage_shape(mesh)
        creases = ((np.asarray(mesh.creases, dtype=np.int64),) if mesh.n_creases else ())
        return fingerprint(mesh.vertices, mesh.face_vertices, mesh.face_offsets, *creases)

    def load_outputs(self, obj):
        from core.types import BaseMeshResult, FitResult

        result_type = {"basemesh": BaseMeshResult, "fit": FitResult}[self.RESULT]
        return {self.RESULT: result_type(read_cage(obj))}


class BaseMeshProxy(CageProxy):
    TYPE = "Polycube::BaseMesh"
    INPUTS = ("Segmentation",)

    def init_properties(self, obj):
        from polycube_wb.preferences import default

        super().init_properties(obj)
        add_property(obj, "App::PropertyLink", "Segmentation", "Base mesh",
                     "The segmentation (a valid polycube labeling)")
        add_property(obj, "App::PropertyInteger", "TargetFaces", "Base mesh",
                     "Face budget of the base mesh (met within 25% when the labeling allows; "
                     "otherwise the smallest layout found)", default("target_faces"))
        add_property(obj, "App::PropertyInteger", "MaxBaseFaces", "Base mesh",
                     "A base mesh with more faces stops the stage with a message",
                     default("max_base_faces"))
        add_property(obj, "App::PropertyEnumeration", "Method", "Base mesh",
                     "'auto': the polycube layout, or a paired decimation of the target where "
                     "the layout fails, needs more than 1.5 times the budget or has more "
                     "inverted faces after its repair; 'polycube': never fall back; 'decimation': the paired "
                     "decimation only", list(BASE_MESH_METHODS), choice=default("base_mesh_method"))
        add_cage_properties(obj)
        add_property(obj, "App::PropertyString", "LabelingUsed", "Result",
                     "The labeling the cage was built on: the segmentation's, or the one-part "
                     "labeling where the segmentation's parts gave no polycube layout",
                     "", read_only=True, output=True)

    def parameters(self, obj):
        return {"target_faces": int(obj.TargetFaces), "max_base_faces": int(obj.MaxBaseFaces),
                "base_mesh_method": str(obj.Method)}

    def prepare(self, obj):
        # the segmentation's parameters too: the one-part labeling, built where its parts'
        # layout fails, is labelled as it would be
        segmentation = obj.Segmentation
        upstream = segmentation.Proxy.parameters(segmentation) if segmentation else {}
        state = self.upstream_state(obj)
        params = stage_params(**{**upstream, **self.parameters(obj)})
        return StageJob(core_stages, (state, tuple(base_mesh_stages()), params))

    def store(self, obj, state):
        store_cage(obj, state.basemesh.cage)
        obj.LabelingUsed = str(state.basemesh.report.get("segmentation", ""))
