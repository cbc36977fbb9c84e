# SPDX-License-Identifier: LGPL-2.1-or-later
"""The route review keeps a polycube layout that fits, and gives way only to a much closer
paired decimation when the layout's least-squares fit had to be held back."""
import os

import numpy as np
import pytest
import trimesh

from core.errors import ParameterError
from core.fitting.fit import least_squares_preview

from core.fitting.route_review import (ROUTE_DISTANCE_RATIO, CagePreview, decimation_wins,
                                       preview_cage, review_route)
from core.subdivision.sample_cages import grid_sphere
from core.types import TriMesh

pytestmark = pytest.mark.unit
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _sphere_target(radius):
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    return TriMesh(np.asarray(sphere.vertices, dtype=np.float64),
                   np.asarray(sphere.faces, dtype=np.int64))


def test_only_a_held_back_layout_much_farther_than_the_decimation_gives_way():
    near = CagePreview(held_back=0, largest_distance=0.01, mean_distance=0.001)
    held_far = CagePreview(held_back=3, largest_distance=0.01 * ROUTE_DISTANCE_RATIO * 1.5,
                           mean_distance=0.002)
    held_close = CagePreview(held_back=3, largest_distance=0.01 * ROUTE_DISTANCE_RATIO * 0.9,
                             mean_distance=0.002)
    free_far = CagePreview(held_back=0, largest_distance=held_far.largest_distance,
                           mean_distance=0.002)
    assert decimation_wins(held_far, near)
    assert not decimation_wins(held_close, near)
    assert not decimation_wins(free_far, near)


def test_a_layout_whose_fit_does_not_cross_is_kept_without_building_the_decimation():
    cage = grid_sphere()
    radius = float(np.linalg.norm(cage.vertices, axis=1).mean())
    target = _sphere_target(radius)

    def build_decimation():
        raise AssertionError("the decimation is built only for a held-back layout")

    info = {"method": "polycube", "fallback_reason": None, "candidates": {}}
    reviewed = review_route(cage, info, target, 2, build_decimation)
    assert reviewed.cage is cage
    review = reviewed.info["route_review"]
    assert review["kept"] == "polycube" and review["paired decimation"] is None
    assert review["polycube"]["held_back"] == 0
    # a 96-quad sphere fits a sphere closely: well under a hundredth of the diagonal
    assert 0 <= review["polycube"]["largest_distance"] < 0.01
    assert reviewed.info["method"] == "polycube" and reviewed.info["fallback_reason"] is None


def test_the_preview_measures_the_fitted_cage_not_the_cage_as_given():
    cage = grid_sphere()
    radius = float(np.linalg.norm(cage.vertices, axis=1).mean())
    near = preview_cage(cage, _sphere_target(radius), 2)
    # the cage as given is a seventh of the diagonal off a sphere twice its size; its
    # least-squares fit is on it
    resized = preview_cage(cage, _sphere_target(2.0 * radius), 2)
    assert near.largest_distance < 0.01 and resized.largest_distance < 0.01
    assert near.held_back == 0 and resized.held_back == 0


def test_the_preview_is_of_the_inside_or_the_best_fit_mode_only():
    cage = grid_sphere()
    radius = float(np.linalg.norm(cage.vertices, axis=1).mean())
    best = preview_cage(cage, _sphere_target(radius), 2, fit_mode="best-fit")
    assert best.held_back == 0 and best.largest_distance < 0.01
    with pytest.raises(ParameterError, match="inside or best-fit"):
        least_squares_preview(cage, _sphere_target(radius), mode="none")


@pytest.mark.slow
def test_the_base_mesh_stage_reviews_a_layout_only_when_a_fit_follows():
    from core.pipeline import reconstruct

    sample = os.path.join(REPO, "examples", "to_simp_cantilever.stl")
    fitted = reconstruct(sample, {}, stop_after="basemesh").report["base_mesh"]
    unfitted = reconstruct(sample, {"fit_mode": "none"},
                           stop_after="basemesh").report["base_mesh"]
    assert fitted["method"] == "polycube" and fitted["route_review"]["kept"] == "polycube"
    assert fitted["route_review"]["polycube"]["largest_distance"] < 0.05
    assert "route_review" not in unfitted and unfitted["method"] == "polycube"
