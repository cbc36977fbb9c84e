# SPDX-License-Identifier: LGPL-2.1-or-later
"""The base-mesh stage with several parts: where the parts' labeling gives no polycube layout,
the one-part labeling's layout is tried and kept when it is a polycube layout."""
import dataclasses

import numpy as np
import pytest
import trimesh

from core.params import ReconstructionParams
from core.progress import NO_PROGRESS
from core.segmentation.validity import check_validity
from core.stages.basemesh import one_part_segmentation, run_basemesh
from core.stages.frames import run_frames
from core.stages.intake import run_intake
from core.stages.labeling import run_labeling
from core.types import LabelingResult, MeshSource, PartsResult, PipelineState

pytestmark = pytest.mark.unit

PARAMS = ReconstructionParams(target_faces=24, fit_mode="none")


def _box_intake():
    """A 4 x 2 x 1 box, each side in many triangles."""
    box = trimesh.creation.box(extents=(4.0, 2.0, 1.0)).subdivide().subdivide()
    source = MeshSource("box", (np.asarray(box.vertices, np.float64),
                                np.asarray(box.faces, np.int64)))
    return run_intake(source, PARAMS, NO_PROGRESS)


def _two_parts_with_an_island(intake):
    """The box cut in two parts across its long axis, labelled, then one face of the big +Z
    side given the opposite label: a chart of one triangle inside another, which no polycube
    has (an invalid labeling, so its base mesh is the paired decimation)."""
    mesh = intake.surface
    centres = mesh.vertices[mesh.faces].mean(axis=1)
    parts = PartsResult((centres[:, 0] > 0.0).astype(np.int32), {"mode": "file", "parts": 2})
    frames = run_frames(intake, parts, PARAMS, NO_PROGRESS)
    labeling = run_labeling(intake, parts, frames, PARAMS, NO_PROGRESS)
    labels = labeling.face_label.copy()
    top = np.flatnonzero(labels == 4)
    island = top[np.argmin(np.linalg.norm(centres[top] - [1.0, 0.0, 0.5], axis=1))]
    labels[island] = 5
    field = frames.frame_field
    validity = check_validity(mesh.vertices, mesh.faces, parts.face_part, labels,
                              field.face_frame)
    assert not validity.is_valid
    return parts, frames, LabelingResult(labels, validity, {**labeling.report, "valid": False})


@pytest.mark.slow
def test_parts_without_a_polycube_layout_give_way_to_the_one_part_layout():
    intake = _box_intake()
    parts, frames, labeling = _two_parts_with_an_island(intake)
    result = run_basemesh(intake, parts, frames, labeling, PARAMS, NO_PROGRESS)
    assert result.report["method"] == "polycube"
    assert result.report["genus"] == 0 and result.cage.n_faces >= 6
    assert result.report["segmentation"].startswith("one part (the 2 parts' layout failed")
    used = result.segmentation
    assert used is not None and int(used.parts.face_part.max()) == 0
    assert used.labeling.report["valid"]
    # the cage a one-part run builds, and the labeling it is built on
    one = one_part_segmentation(intake, PARAMS, NO_PROGRESS)
    single = run_basemesh(intake, one.parts, one.frames, one.labeling, PARAMS, NO_PROGRESS)
    assert single.segmentation is None  # one part already: nothing else to try
    assert single.cage.n_faces == result.cage.n_faces
    assert np.allclose(single.cage.vertices, result.cage.vertices, atol=1e-9)
    assert np.array_equal(one.labeling.face_label, used.labeling.face_label)
    state = PipelineState(intake=intake, parts=parts, frames=frames, labeling=labeling,
                          basemesh=result)
    assert state.segmentation is used  # what --labels writes


def test_the_decimation_asked_for_tries_no_other_labeling():
    intake = _box_intake()
    parts, frames, labeling = _two_parts_with_an_island(intake)
    params = dataclasses.replace(PARAMS, base_mesh_method="decimation")
    result = run_basemesh(intake, parts, frames, labeling, params, NO_PROGRESS)
    assert result.report["method"] == "paired decimation"
    assert result.segmentation is None and "one_part_labeling" not in result.report
