# SPDX-License-Identifier: LGPL-2.1-or-later
"""Cancel (Esc) during the recompute of each stage object leaves a consistent document.

The whole chain (Target to Deviation) on the tiny level-set cantilever is built in one
undo step and cancelled inside each stage object's run in turn, by a progress object
that raises ``Cancelled`` from its ``report`` as FreeCAD's progress bar does after Esc.
Every time: the stages before keep their results and are up to date, the cancelled one is
marked (``Status``, touched) with no result, the ones after are touched and not
run; Undo removes the whole step; the document saves, reopens and, recomputed, runs only
what the cancel left (the stages before are not run again) to a valid solid.
"""
import os

import pytest

import FreeCAD

from core.errors import Cancelled
from core.progress import Progress
from tiny_chain import KINDS, TINY, record_runs

STAGES_OF = {"Target": ("intake",), "Segmentation": ("parts", "frames", "labeling"),
             "BaseMesh": ("basemesh",), "Fit": ("fit",), "Solid": ("patches",),
             "Deviation": ("tessellate",)}
"""Progress stage names each stage object reports while it runs."""


class EscIn(Progress):
    """Raises ``Cancelled`` at the first progress report from inside one object's stages,
    and from every report after it (FreeCAD's bar stays cancelled)."""

    def __init__(self, kind):
        self.stages = STAGES_OF[kind]
        self.pressed = False

    def report(self, stage, fraction, message=""):
        self.pressed = self.pressed or stage in self.stages
        self.check_cancel()

    def check_cancel(self):
        if self.pressed:
            raise Cancelled("test: Esc")


def _kinds(doc):
    from polycube_wb import api

    return {api.stage_kind(obj): obj for obj in doc.Objects}


def _build(doc):
    from polycube_wb import api

    target = api.make_target(doc, TINY, check_self_intersections=False)
    chain = api.make_chain(doc, target, "Solid", Fit={"Iterations": 2})
    api.make_deviation(doc, chain["Solid"], target)


def _has_result(obj):
    return bool(obj.ResultId)


@pytest.fixture(scope="module", autouse=True)
def _needs_the_mesh():
    if not os.path.exists(TINY):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")


@pytest.mark.parametrize("kind", KINDS)
def test_cancel_in_a_stage_keeps_the_earlier_ones_marks_it_and_resumes_after_reopening(
        tmp_path, kind):
    from polycube_wb import api

    doc = FreeCAD.newDocument(f"PolycubeCancel{kind}")
    doc.UndoMode = 1
    try:
        with pytest.raises(Cancelled, match=f"cancelled by the user at {kind}; the stages "
                                            "before it keep their results"):
            api.run_in_transaction(doc, "Make the chain", lambda: _build(doc), EscIn(kind))
        objects = _kinds(doc)
        assert sorted(objects) == sorted(KINDS), "nothing half-made is removed or added"
        index = KINDS.index(kind)
        for before in KINDS[:index]:
            obj = objects[before]
            assert obj.Status == "ok" and obj.isValid() and obj.State == ["Up-to-date"], before
            assert _has_result(obj), before
        cancelled = objects[kind]
        assert cancelled.Status == "cancelled by the user"
        assert "Touched" in cancelled.State
        assert not _has_result(cancelled), "no half result"
        for after in KINDS[index + 1:]:
            obj = objects[after]
            assert obj.Status == "" and "Touched" in obj.State and not _has_result(obj), after
        assert doc.UndoCount == 1 and doc.UndoNames == ["Make the chain"]

        path = str(tmp_path / "cancelled.FCStd")
        doc.saveAs(path)
        FreeCAD.closeDocument(doc.Name)
        doc = FreeCAD.openDocument(path)
        objects = _kinds(doc)
        assert objects[kind].Status == "cancelled by the user"
        ran = record_runs(objects.values())
        for obj in objects.values():
            obj.touch()  # a user's "recompute all": only stale stages run
        outcome = api.recompute(doc)
        assert outcome.ok, outcome.failures
        assert ran == [objects[k].Name for k in KINDS[index:]]
        assert all(obj.Status == "ok" and obj.isValid() for obj in objects.values())
        assert objects["Solid"].Shape.isValid() and len(objects["Solid"].Shape.Solids) == 1
    finally:
        FreeCAD.closeDocument(doc.Name)


def test_undo_after_a_cancel_removes_the_whole_step():
    from polycube_wb import api

    doc = FreeCAD.newDocument("PolycubeCancelUndo")
    doc.UndoMode = 1
    try:
        with pytest.raises(Cancelled):
            api.run_in_transaction(doc, "Make the chain", lambda: _build(doc), EscIn("Fit"))
        assert len(doc.Objects) == len(KINDS)
        doc.undo()
        assert doc.Objects == [] and doc.UndoCount == 0 and doc.RedoCount == 1
    finally:
        FreeCAD.closeDocument(doc.Name)
