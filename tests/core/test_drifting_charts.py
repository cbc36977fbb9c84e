# SPDX-License-Identifier: LGPL-2.1-or-later
"""Corner terms of the quantization: a chart whose boundary runs at a slant keeps its measured
shape, which its side lengths alone do not say."""
import os
from types import SimpleNamespace

import numpy as np
import pytest

from core.quadmesh.polycube.quantize import (LoopTables, drifting_charts, quantize,
                                             rectangular_refinement)

pytestmark = pytest.mark.unit


def _chart(corners, axis, sign):
    """One chart walked counter-clockwise through ``corners`` ((n, 2) measured start corner
    of each side); side ``i`` runs along ``axis[i]`` in direction ``sign[i]``."""
    corners = np.asarray(corners, dtype=np.float64)
    n = len(corners)
    along = np.abs(np.roll(corners, -1, axis=0) - corners)[np.arange(n), axis]
    tables = LoopTables(np.zeros(n, dtype=np.int64), np.arange(n), np.asarray(axis),
                        np.asarray(sign), (np.arange(n) + 1) % n, np.array([1]), corners)
    complex_ = SimpleNamespace(n_sides=n, n_charts=1, slit_walks=list,
                               side_extent=np.stack([along, along], axis=1))
    return complex_, tables


def slanted_steps():
    # two steps whose long sides rise by two units each: measured heights 1, 3 to 4, and 6
    return _chart([[0, 0], [8, 0], [8, 1], [4, 3], [4, 4], [0, 6]],
                  [0, 1, 0, 1, 0, 1], [1, 1, -1, 1, -1, -1])


def rectangle():
    return _chart([[0, 0], [8, 0], [8, 3], [0, 3]], [0, 1, 0, 1], [1, 1, -1, -1])


def test_only_a_chart_whose_sides_drift_is_flagged():
    complex_, tables = slanted_steps()
    assert drifting_charts(complex_, tables, 1.0).tolist() == [0]
    complex_, tables = rectangle()
    assert len(drifting_charts(complex_, tables, 1.0)) == 0


def test_corner_terms_keep_a_slanted_chart_as_tall_as_it_is_measured():
    complex_, tables = slanted_steps()
    refinement = rectangular_refinement(complex_, tables)
    sides_only = quantize(complex_, tables, refinement, 1.0)
    with_corners = quantize(complex_, tables, refinement, 1.0, corner_cost=2.0)
    height = {name: int(result.side_length[5]) for name, result in
              (("sides", sides_only), ("corners", with_corners))}
    # the side lengths alone are as close at any height from 2 to 6 and take the least;
    # the corners, measured at heights 0 to 6 along the chart, want it well above that
    assert height["sides"] <= 2 < 3 <= height["corners"] <= 6
    for result in (sides_only, with_corners):
        assert (result.side_length >= 1).all() and result.faces > 0


def tapered_plate():
    """A plate 1 thick whose outline tapers from 6 wide to 2 wide over 12 (slanted sides
    about 10 degrees off the x axis), small triangles."""
    import trimesh

    outline = np.array([[0, 0], [12, 2], [12, 4], [0, 6]], dtype=np.float64)
    corners = np.concatenate([np.column_stack([outline, np.full(4, z)]) for z in (0.0, 1.0)])
    mesh = trimesh.convex.convex_hull(corners)
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=0.3)
    mesh = trimesh.Trimesh(V, F, process=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


@pytest.mark.slow
def test_a_tapered_plate_laid_out_with_its_corners_is_a_closed_quad_cage():
    from core.polymesh_checks import check_polymesh
    from core.quadmesh.base_mesh import build_base_mesh
    from core.types import TriMesh
    from tests.core.test_quadmesh import identity_frames, nearest_labels

    V, F = tapered_plate()
    frames, part_frames = identity_frames(len(F))
    labels = nearest_labels(V, F)
    for cost in (0.0, 2.0):
        base, info = build_base_mesh(TriMesh(V, F), np.zeros(len(F), dtype=np.int64), labels,
                                     frames, part_frames, 120, method="polycube",
                                     corner_cost=cost)
        check_polymesh(base)
        assert info["method"] == "polycube" and info["genus"] == 0
        assert info["corner_cost"] == cost
        assert 0.5 * 120 <= info["faces"] <= 1.5 * 120


SPACE_FRAME = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "simp_unseen",
                           "simp_space_frame.stl")


@pytest.mark.slow
def test_a_space_frame_of_slanted_struts_keeps_the_layout_with_its_corners():
    """The struts of the frame run at a slant to its axes: the layout quantized from its side
    lengths alone stretches quads whose least-squares fit crosses itself, and the layout with
    the corner terms draws a chart polygon running along itself unless its segments are kept
    apart. The layout kept is a clean cage whose fit comes as close as the decimation's."""
    from core.fitting.route_review import ROUTE_DISTANCE_RATIO, preview_cage
    from core.mesh_topology import polymesh_genus
    from core.params import ReconstructionParams
    from core.pipeline import reconstruct
    from core.polymesh_checks import check_polymesh
    from core.quadmesh.base_mesh import FALLBACK_OVER_BUDGET
    from core.quadmesh.orientation import inverted_faces
    from core.subdivision.limit_crossings import count_limit_self_intersections

    params = ReconstructionParams.from_dict({"parts": "single"})
    result = reconstruct(SPACE_FRAME, params, stop_after="basemesh")
    info = result.report["base_mesh"]
    base, target = result.state.basemesh.cage, result.state.intake.target
    assert info["method"] == "polycube"
    check_polymesh(base)
    assert (base.face_sizes == 4).all()
    assert polymesh_genus(base) == result.report["input"]["genus"]
    assert not inverted_faces(base, target.vertices, target.faces).any()
    assert count_limit_self_intersections(base, 2) == 0
    assert base.n_faces <= FALLBACK_OVER_BUDGET * params.target_faces
    if not info["within_budget"]:
        # its size comes of the corner terms, and the report says so
        assert "corners of its drifting charts" in info["minimum_reason"]
    preview = preview_cage(base, target, params.subdivision_levels, params.fit_mode)
    decimation = info["route_review"]["paired decimation"]["largest_distance"]
    assert preview.largest_distance <= ROUTE_DISTANCE_RATIO * decimation
