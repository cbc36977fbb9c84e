# SPDX-License-Identifier: LGPL-2.1-or-later
"""Watertightness, containment and surface-distance checks on analytic shapes."""
import sys

import numpy as np
import pytest
import trimesh
from scipy.integrate import dblquad
from trimesh.triangles import closest_point

from core.errors import InvalidMeshError
from core.quality import (containment, is_watertight_manifold, manifold_report,
                          point_surface_distance, sample_surface, surface_distances)


def box(extents, center=(0.0, 0.0, 0.0)):
    mesh = trimesh.creation.box(extents)
    return mesh.vertices + np.asarray(center), mesh.faces.astype(np.int64)


def test_closed_box_is_watertight_manifold():
    V, F = box((1.0, 2.0, 3.0))
    assert is_watertight_manifold(V, F)
    report = manifold_report(V, F)
    assert report["manifold_status"] == "NoError" and report["genus"] == 0
    assert report["volume"] == pytest.approx(6.0, rel=1e-12)


def test_open_or_misoriented_box_is_not_watertight_manifold():
    V, F = box((1.0, 1.0, 1.0))
    assert not is_watertight_manifold(V, F[:-2])
    report = manifold_report(V, F[:-2])
    assert not report["edges_watertight"] and report["manifold_status"] == "NotManifold"
    flipped = F.copy()
    flipped[0] = flipped[0, ::-1]
    assert not is_watertight_manifold(V, flipped)


@pytest.mark.parametrize("module", ["manifold3d", "trimesh"])
def test_missing_dependency_gives_install_hint(monkeypatch, module):
    monkeypatch.setitem(sys.modules, module, None)
    V, F = box((1.0, 1.0, 1.0))
    with pytest.raises(ImportError, match=f"pip install {module}"):
        is_watertight_manifold(V, F)


def test_bad_arrays_raise_invalid_mesh_error():
    V, F = box((1.0, 1.0, 1.0))
    with pytest.raises(InvalidMeshError, match="outside") as info:
        is_watertight_manifold(V, F + 3)
    assert info.value.reason == "format"
    bad = V.copy()
    bad[V[:, 0] > 0, 1] = np.nan
    with pytest.raises(InvalidMeshError) as info:
        is_watertight_manifold(bad, F)
    assert info.value.reason == "non_finite" and info.value.count == 4


def test_small_box_inside_large_box_is_contained():
    small, small_f = box((1.0, 1.0, 1.0))
    large, large_f = box((2.0, 2.0, 2.0))
    result = containment(small, small_f, large, large_f)
    assert abs(result["outside_volume_fraction"]) <= 1e-12
    assert result["uncovered_volume_fraction"] == pytest.approx(7.0 / 8.0, abs=1e-9)


@pytest.mark.parametrize("extents, center, outside, uncovered", [
    ((1.0, 1.0, 1.0), (0.3, 0.2, 0.1), 1 - 0.7 * 0.8 * 0.9, 1 - 0.7 * 0.8 * 0.9),
    ((0.5, 0.5, 0.5), (0.5, 0.0, 0.0), 0.5 * 0.5 * 0.25, 1 - 0.5 * 0.5 * 0.25),
])
def test_shifted_box_gives_analytic_fractions(extents, center, outside, uncovered):
    target, target_f = box((1.0, 1.0, 1.0))
    result, result_f = box(extents, center)
    figures = containment(result, result_f, target, target_f)
    assert figures["outside_volume_fraction"] == pytest.approx(outside, abs=1e-6)
    assert figures["uncovered_volume_fraction"] == pytest.approx(uncovered, abs=1e-6)


def test_containment_rejects_open_or_inverted_meshes():
    V, F = box((1.0, 1.0, 1.0))
    with pytest.raises(InvalidMeshError, match="result: not a closed") as info:
        containment(V, F[:-1], V, F)
    assert info.value.reason == "non_manifold"
    with pytest.raises(InvalidMeshError, match="target: encloses volume") as info:
        containment(V, F, V, F[:, ::-1])
    assert info.value.reason == "orientation"


@pytest.mark.slow
def test_point_distance_equals_brute_force_on_mixed_triangle_sizes():
    sphere = trimesh.creation.icosphere(4)
    big, big_f = box((2.0, 2.0, 2.0))
    V = np.vstack([big, sphere.vertices * 0.3])
    F = np.vstack([big_f, sphere.faces + len(big)])
    points = np.random.default_rng(3).normal(size=(150, 3))
    tri = V[F]
    brute = np.array([np.linalg.norm(closest_point(tri, np.repeat(p[None], len(F), 0)) - p,
                                     axis=1).min() for p in points])
    assert np.max(np.abs(point_surface_distance(points, V, F) - brute)) <= 1e-12


def test_samples_lie_on_the_surface_and_are_deterministic():
    V, F = box((1.0, 2.0, 3.0))
    a = sample_surface(V, F, 1000, np.random.default_rng(7))
    b = sample_surface(V, F, 1000, np.random.default_rng(7))
    assert np.array_equal(a, b)
    assert point_surface_distance(a, V, F).max() <= 1e-12
    # area weighting: the two 2 x 3 faces hold 12 / 22 of the area
    assert np.mean(np.isclose(np.abs(a[:, 0]), 0.5)) == pytest.approx(12 / 22, abs=0.05)


def test_identical_surfaces_have_zero_distance():
    V, F = box((1.0, 2.0, 3.0))
    report = surface_distances(V, F, V, F, samples=2000)
    assert report["hausdorff"] <= 1e-12


def test_concentric_boxes_give_analytic_distances():
    inner, inner_f = box((2.0, 2.0, 2.0))
    outer, outer_f = box((2.2, 2.2, 2.2))
    report = surface_distances(outer, outer_f, inner, inner_f, samples=20000, seed=1)
    diagonal = 2.0 * np.sqrt(3.0)
    assert report["bbox_diagonal"] == pytest.approx(diagonal, rel=1e-12)
    # every point of the inner box is exactly 0.1 from the outer box
    assert report["target_to_result_mean"] == pytest.approx(0.1 / diagonal, rel=1e-9)
    assert report["target_to_result_max"] == pytest.approx(0.1 / diagonal, rel=1e-9)
    # outer -> inner: 0.1 over the face centres, up to 0.1 * sqrt(3) at the corners
    assert report["result_to_target_max"] == pytest.approx(0.1 * np.sqrt(3) / diagonal, rel=1e-9)
    # the bounds of the search over every triangle: within its resolution of the maxima
    for side in ("result_to_target", "target_to_result"):
        assert (report[f"{side}_max"] - 1e-12 <= report[f"{side}_max_bound"]
                <= report[f"{side}_max"] + report["resolution"])
    h, b, a = 0.1, 1.0, 1.1
    strip = 0.5 * h * h * (np.sqrt(2.0) + np.arcsinh(1.0))
    corner, _ = dblquad(lambda s, t: np.sqrt(h * h + s * s + t * t), 0, h, 0, h)
    mean = ((2 * b) ** 2 * h + 4 * 2 * b * strip + 4 * corner) / (2 * a) ** 2
    assert report["result_to_target_mean"] == pytest.approx(mean / diagonal, rel=2e-3)
