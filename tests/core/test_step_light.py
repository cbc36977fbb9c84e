# SPDX-License-Identifier: LGPL-2.1-or-later
"""The light STEP points of the G1 export (core.export.step_file.light_point_decimals) on
cages built here: no gap can open, and the rounding keeps each patch within its bounds."""
import dataclasses

import numpy as np
import pytest

from core.export.g1_patches import g1_surface_patches
from core.export.step_file import (LIGHT_NORMAL_TURN, LIGHT_POINT_STEP, POINT_DECIMALS,
                                   light_point_decimals, step_fixed_reals, step_text)
from core.subdivision import sample_cages
from core.tolerances import BREP_MM


@pytest.fixture(scope="module", params=[("mixed_prism", "quad"), ("mixed_prism", "chart"),
                                        ("genus3_block", "quad")])
def light(request):
    name, faces = request.param
    cage = getattr(sample_cages, name)()
    cage = dataclasses.replace(cage, vertices=100.0 * cage.vertices)
    patches = g1_surface_patches(cage, measure=False, faces=faces)
    return patches, light_point_decimals(patches.patches, patches.topology)


def test_vertices_and_edge_curves_that_are_no_face_row_keep_every_decimal(light):
    """Every vertex, and every pole of an edge curve that is not a pole of a face (a part of
    a longer side or another representation of it), keeps :data:`POINT_DECIMALS`."""
    patches, decimals = light
    t = patches.topology
    assert (decimals.of(t.vertices) == POINT_DECIMALS).all()
    poles = np.concatenate([p.poles.reshape(-1, 3) for p in patches.patches])
    keys = {p.tobytes() for p in poles + 0.0}
    for curve in t.edge_curves:
        own = np.array([p.tobytes() not in keys for p in curve.poles + 0.0])
        assert (decimals.of(curve.poles)[own] == POINT_DECIMALS).all()


def test_each_patch_moves_and_turns_within_its_bounds(light):
    """Rounding each patch's poles to their decimals moves none by more than half
    :data:`LIGHT_POINT_STEP` of the diagonal per coordinate, and changes the differences
    between boundary rows and the rows next to them by at most :data:`LIGHT_NORMAL_TURN`
    of their length; the rounding is coarse enough to shorten the text."""
    patches, decimals = light
    poles = [p.poles for p in patches.patches]
    diagonal = np.linalg.norm(np.ptp(np.concatenate([P.reshape(-1, 3) for P in poles]), axis=0))
    assert decimals.places.min() < POINT_DECIMALS and 10.0 ** -decimals.places.min() > BREP_MM
    for P in poles:
        places = decimals.of(P.reshape(-1, 3))
        R = np.stack([np.round(p, k) for p, k in zip(P.reshape(-1, 3), places)]).reshape(P.shape)
        assert np.abs(R - P).max() <= 0.5 * LIGHT_POINT_STEP * diagonal + 1e-12
        for axis in (0, 1):
            for near, next_ in ((0, 1), (-1, -2)):
                d = np.take(P, next_, axis) - np.take(P, near, axis)
                e = np.take(R, next_, axis) - np.take(R, near, axis)
                length = np.linalg.norm(d, axis=-1)
                assert (np.linalg.norm(e - d, axis=-1) <= LIGHT_NORMAL_TURN * length + 1e-12).all()


def test_light_text_is_shorter_with_the_same_entities(light):
    patches, _ = light
    t = patches.topology
    texts = [step_text(patches.patches, t, "cage", BREP_MM, light=flag) for flag in (False, True)]
    assert len(texts[1]) < 0.97 * len(texts[0])
    for entity in ("ADVANCED_FACE(", "EDGE_CURVE(", "VERTEX_POINT(", "PCURVE("):
        assert texts[0].count(entity) == texts[1].count(entity)


def test_whole_millimetre_literals_keep_their_digits():
    # a point rounded to no decimals (a very large model) still reads back as itself
    literals = step_fixed_reals([30.0, -120.4, 0.0, 1e6], 0)
    assert literals == ["30.", "-120.", "0.", "1000000."]
    assert [float(text) for text in literals] == [30.0, -120.0, 0.0, 1e6]
    assert step_fixed_reals([30.0, 0.25], 2) == ["30.", "0.25"]
