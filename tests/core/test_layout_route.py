# SPDX-License-Identifier: LGPL-2.1-or-later
"""The route policy of the base-mesh stage on shapes with holes: the polycube layout is kept
within 1.5 times the budget, its inverted faces and a few faces where its limit surface
crosses itself are repaired, a layout whose limit surface still crosses itself gives way to a
clean decimation cage, and the report names both candidates."""
from dataclasses import replace

import numpy as np
import pytest

from core.errors import LabelingError
from core.mesh_topology import polymesh_genus
from core.polymesh_checks import check_polymesh
from core.quadmesh import base_mesh as base_mesh_module
from core.quadmesh import build_base_mesh
from core.quadmesh.base_mesh import FALLBACK_OVER_BUDGET, UNTANGLED_KEY, _repaired_layout
from core.quadmesh.local_repair import MAX_EDITS
from core.quadmesh.orientation import inverted_faces
from core.subdivision.limit_crossings import count_limit_self_intersections
from core.target_surface import TargetSurface
from core.types import TriMesh
from tests.core.test_quadmesh import (FRAME, euler_genus, identity_frames, nearest_labels,
                                      union_of_boxes)

# a plate with two square through-holes (genus 2) built of boxes
TWO_HOLES = [[[0, 0, 0], [5, 1, 1]], [[0, 2, 0], [5, 3, 1]], [[0, 0, 0], [1, 3, 1]],
             [[2, 0, 0], [3, 3, 1]], [[4, 0, 0], [5, 3, 1]]]
# a plate with three square through-holes in a row (genus 3)
THREE_HOLES = [[[0, 0, 0], [7, 1, 1]], [[0, 2, 0], [7, 3, 1]], [[0, 0, 0], [1, 3, 1]],
               [[2, 0, 0], [3, 3, 1]], [[4, 0, 0], [5, 3, 1]], [[6, 0, 0], [7, 3, 1]]]
# an L-shaped plate with one square through-hole in its long leg (genus 1)
L_PLATE_WITH_HOLE = [[[0, 0, 0], [5, 1, 1]], [[0, 2, 0], [5, 3, 1]], [[0, 0, 0], [1, 3, 1]],
                     [[2, 0, 0], [5, 3, 1]], [[0, 3, 0], [1, 5, 1]]]


def auto_base_mesh(boxes, target_faces):
    V, F = union_of_boxes(boxes)
    face_frame, part_frames = identity_frames(len(F))
    base, info = build_base_mesh(TriMesh(V, F), np.zeros(len(F), dtype=np.int64),
                                 nearest_labels(V, F), face_frame, part_frames, target_faces)
    return V, F, base, info


@pytest.mark.parametrize("boxes", [FRAME, TWO_HOLES, THREE_HOLES, L_PLATE_WITH_HOLE],
                         ids=["frame", "two-holes", "three-holes", "l-plate-with-hole"])
def test_a_shape_with_holes_takes_the_polycube_route_with_its_genus(boxes):
    V, F, base, info = auto_base_mesh(boxes, 300)
    assert info["method"] == "polycube" and info["fallback_reason"] is None
    check_polymesh(base)  # closed, 2-manifold, outward, no degenerate face
    assert info["genus"] == polymesh_genus(base) == euler_genus(V, F) >= 1
    assert not inverted_faces(base, V, F).any() and info["inverted_faces"] == 0
    assert count_limit_self_intersections(base, 2) == info["limit_crossings"] == 0
    assert base.n_faces <= FALLBACK_OVER_BUDGET * 300
    assert info["candidates"]["polycube"]["faces"] == base.n_faces
    assert info["candidates"]["paired decimation"] is None  # not needed, not built


def test_a_layout_over_the_rule_gives_way_and_the_report_names_both_candidates():
    # six faces cannot hold a frame's layout (each of its 16 charts needs a quad)
    V, F, base, info = auto_base_mesh(FRAME, 6)
    polycube = info["candidates"]["polycube"]
    assert info["method"] == "paired decimation" and not polycube["built"]
    assert polycube["faces"] > FALLBACK_OVER_BUDGET * 6 and polycube["reason"]
    decimation = info["candidates"]["paired decimation"]
    assert decimation["built"] and decimation["faces"] == base.n_faces
    assert decimation["extraordinary_vertices"] == info["extraordinary_vertices"]
    assert info["genus"] == euler_genus(V, F)


def test_a_folded_layout_vertex_is_repaired():
    V, F, base, info = auto_base_mesh(FRAME, 300)
    surface = TargetSurface(V, F)
    # fold the layout: one vertex of the frame's top face pushed across its neighbours
    top = np.flatnonzero((np.abs(base.vertices[:, 2] - 1.0) < 1e-9)
                         & (base.vertices[:, 0] > 0.05) & (base.vertices[:, 0] < 0.95)
                         & (base.vertices[:, 1] > 1.05) & (base.vertices[:, 1] < 1.95))
    assert len(top)
    vertex = top[0]
    neighbours = [f for f in base.faces() if vertex in f]
    ring = np.unique(np.concatenate([np.asarray(f) for f in neighbours]))
    spread = base.vertices[ring] - base.vertices[vertex]
    folded = base.vertices.copy()
    folded[vertex] += 2.0 * spread[np.argmax(np.linalg.norm(spread, axis=1))]
    folded_base = replace(base, vertices=folded)
    before = int(inverted_faces(folded_base, V, F, surface).sum())
    assert before > 0
    repaired, repaired_info = _repaired_layout(folded_base, info, surface)
    check_polymesh(repaired)
    assert repaired_info["layout_inverted_faces"] == before
    assert repaired_info["inverted_faces"] == int(inverted_faces(repaired, V, F, surface).sum())
    assert repaired_info["inverted_faces"] == 0  # one corner moved back unfolds it
    assert polymesh_genus(repaired) == euler_genus(V, F)


def test_a_layout_pierced_at_one_vertex_is_mended():
    V, F, base, info = auto_base_mesh(FRAME, 300)
    surface = TargetSurface(V, F)
    top = np.flatnonzero((np.abs(base.vertices[:, 2] - 1.0) < 1e-9)
                         & (np.abs(base.vertices[:, 0] - 0.5) < 0.3)
                         & (base.vertices[:, 1] > 1.2) & (base.vertices[:, 1] < 1.8))
    pierced = base.vertices.copy()
    pierced[top[0], 2] = -3.0
    pierced_base = replace(base, vertices=pierced)
    assert count_limit_self_intersections(pierced_base, 2) > 0
    repaired, repaired_info = _repaired_layout(pierced_base, info, surface)
    check_polymesh(repaired)
    assert count_limit_self_intersections(repaired, 2) == repaired_info["limit_crossings"] == 0
    assert not inverted_faces(repaired, V, F, surface).any()
    assert polymesh_genus(repaired) == euler_genus(V, F)


def test_a_layout_whose_limit_surface_crosses_itself_gives_way_to_a_clean_cage(monkeypatch):
    layout = base_mesh_module._polycube_base_mesh

    def pierced_layout(*args, **kwargs):
        # a whole strip of the top face pierced: more flawed faces than local edits can mend
        mesh, info = layout(*args, **kwargs)
        top = np.flatnonzero((np.abs(mesh.vertices[:, 2] - 1.0) < 1e-9)
                             & (mesh.vertices[:, 1] > 0.9) & (mesh.vertices[:, 1] < 2.1))
        assert len(top) > MAX_EDITS
        pierced = mesh.vertices.copy()
        pierced[top, 2] = -3.0
        # the untangled copy is of the layout before the piercing: none of the pierced one
        return replace(mesh, vertices=pierced), {**info, UNTANGLED_KEY: None}

    monkeypatch.setattr(base_mesh_module, "_polycube_base_mesh", pierced_layout)
    V, F, base, info = auto_base_mesh(FRAME, 300)
    polycube = info["candidates"]["polycube"]
    decimation = info["candidates"]["paired decimation"]
    assert polycube["built"] and polycube["limit_crossings"] > 0
    assert decimation["built"]  # built to compare, since the layout's limit crosses itself
    kept = count_limit_self_intersections(base, 2)
    assert kept == info["limit_crossings"]
    # the cage kept has the fewer flaws: no crossing first, then fewer inverted faces
    assert (kept > 0, info["inverted_faces"]) == min(
        (c["limit_crossings"] > 0, c["inverted_faces"]) for c in (polycube, decimation))
    if kept == 0:
        assert info["method"] == "paired decimation" and "self-crossing" in info["fallback_reason"]


def test_least_lengths_lengthen_the_sides_and_the_polygons_still_close():
    from core.quadmesh.polycube.lattice import build_lattice
    from core.quadmesh.polycube.quantize import quantize, rectangular_refinement
    from tests.core.test_quadmesh import layout_problem

    complex_, tables = layout_problem(FRAME)
    # every chart split into rectangles: any lengths that close them draw simple polygons
    refinement = rectangular_refinement(complex_, tables, range(complex_.n_charts))
    coarse = quantize(complex_, tables, refinement, 1e-3)
    least = np.zeros(complex_.n_sides, dtype=np.int64)
    least[::3] = 3
    finer = quantize(complex_, tables, refinement, 1e-3, least=least)
    assert (finer.side_length >= np.maximum(least, 1)).all()
    assert finer.faces > coarse.faces
    lattice = build_lattice(complex_, tables, finer)  # every chart still a closed polygon
    assert len(lattice.quads) == finer.faces


@pytest.mark.slow
def test_a_dev_mesh_with_thin_walls_takes_the_polycube_route_with_no_inverted_face():
    import os

    from core.pipeline import reconstruct
    from tests.core.dev_meshes import MESHES

    path = os.path.join(MESHES, "idler_riser.stl")
    if not os.path.exists(path):
        pytest.skip("dev mesh idler_riser.stl not available")
    result = reconstruct(path, stop_after="basemesh")
    info = result.report["base_mesh"]
    base, target = result.state.basemesh.cage, result.state.intake.target
    assert info["method"] == "polycube"
    check_polymesh(base)
    assert (base.face_sizes == 4).all()
    assert polymesh_genus(base) == result.report["input"]["genus"] >= 1
    assert not inverted_faces(base, target.vertices, target.faces).any()
    assert count_limit_self_intersections(base, 2) == 0
    assert base.n_faces <= FALLBACK_OVER_BUDGET * 300


# a frame whose right bar is a fifth as wide as the others (genus 1)
THIN_BAR_FRAME = [[[0, 0, 0], [4, 1, 1]], [[0, 2, 0], [4, 3, 1]], [[0, 0, 0], [1, 3, 1]],
                  [[3.8, 0, 0], [4, 3, 1]]]


@pytest.mark.slow
def test_a_thin_bar_gets_quads_that_face_the_target_before_any_repair():
    V, F, base, info = auto_base_mesh(THIN_BAR_FRAME, 100)
    assert info["method"] == "polycube"
    check_polymesh(base)
    assert (base.face_sizes == 4).all()
    assert polymesh_genus(base) == euler_genus(V, F) == 1
    # the quantized layout itself, not only its repair, has every limit normal facing out
    assert info["layout_inverted_faces"] == 0 and info["edits"] == 0
    assert not inverted_faces(base, V, F).any()
    assert count_limit_self_intersections(base, 2) == 0
    assert base.n_faces <= FALLBACK_OVER_BUDGET * 100


def test_a_layout_too_large_with_every_side_kept_says_why_collapsing_slivers_failed(
        monkeypatch):
    # the bound of the layout that keeps every side hides what the smaller layouts that let
    # slivers collapse ran into: the report names both
    def every_side(complex_, target_faces):
        return np.ones(complex_.n_sides, dtype=bool)

    def layout(V, F, complex_, tables, target_faces, max_base_faces, collapsible, *args,
               **kwargs):
        if collapsible.any():
            raise LabelingError("2 integer chart polygons overlap")
        raise base_mesh_module.LayoutTooLargeError("at least 999 quads", 999)

    monkeypatch.setattr(base_mesh_module, "collapsible_sides", every_side)
    monkeypatch.setattr(base_mesh_module, "_layout_on_target", layout)
    V, F, base, info = auto_base_mesh(TWO_HOLES, 300)
    polycube = info["candidates"]["polycube"]
    assert info["method"] == "paired decimation" and not polycube["built"]
    assert polycube["faces"] == 999
    assert "at least 999 quads" in polycube["reason"]
    assert "2 integer chart polygons overlap" in polycube["reason"]
