# SPDX-License-Identifier: LGPL-2.1-or-later
"""Chart faces (core.export.quad_blocks, chart_faces, spline_knots) on cages built here: the
blocks tile the quad mesh as rectangles, the merged faces form one closed shell, and they are
the per-quad G1 surface (same points, same volume) with far fewer faces."""
import numpy as np
import pytest

from core.errors import ParameterError
from core.export.brep_topology import check_topology
from core.export.bspline_basis import evaluate_patch_points
from core.export.bspline_tessellation import enclosed_volume
from core.export.chart_faces import MERGE_TOLERANCE
from core.export.g1_patches import g1_quad_patches, g1_surface_patches
from core.export.quad_blocks import quad_blocks
from core.export.spline_knots import join, refine, remove_knots
from core.params import ReconstructionParams
from core.subdivision import sample_cages
from core.subdivision.catmull_clark import build_hierarchy


def _cube_once():
    return build_hierarchy(sample_cages.cube(), 1).meshes[1]


CAGES = {"cube_once": _cube_once, "torus": sample_cages.torus,
         "genus3_block": sample_cages.genus3_block, "mixed_prism": sample_cages.mixed_prism}


@pytest.fixture(scope="module", params=sorted(CAGES))
def merged(request):
    cage = CAGES[request.param]()
    per_quad, quads = g1_quad_patches(cage, measure=False)
    return (request.param, quads, per_quad, g1_surface_patches(cage, measure=False, faces="chart"))


def test_blocks_tile_the_quads_as_rectangles(merged):
    """Every quad is in one block, and each block's grid vertices are its quads' corners in
    the block's orientation, all distinct."""
    _, quads, _, _ = merged
    fv = quads.face_vertices.reshape(-1, 4)
    seen = np.zeros(quads.n_faces, dtype=int)
    for block in quad_blocks(quads).blocks:
        W, H = block.quads.shape
        seen[block.quads.reshape(-1)] += 1
        assert len(np.unique(block.vertices)) == (W + 1) * (H + 1)
        for (di, dj), k in (((0, 0), 0), ((1, 0), 1), ((1, 1), 2), ((0, 1), 3)):
            corner = fv[block.quads, (block.rotation + k) % 4]
            assert np.array_equal(corner, block.vertices[di:di + W, dj:dj + H])
    assert (seen == 1).all()


def test_faces_form_one_closed_shell(merged):
    name, quads, per_quad, chart = merged
    diag = per_quad.info["bbox_diagonal"]
    assert check_topology(chart.topology, chart.patches, 1e-9 * diag) <= 1e-9 * diag
    assert chart.info["faces"] == "chart" and chart.info["n_faces"] == len(chart.patches)
    assert chart.info["merge_error"] <= MERGE_TOLERANCE
    if name == "cube_once":
        assert len(chart.patches) == 6
    else:
        assert len(chart.patches) <= 0.5 * len(per_quad.patches)


def test_merged_faces_are_the_per_quad_surface(merged):
    """Points of each block face equal the quad patch under them (the parameter map of the
    block, the quad's rotation), within the merge tolerance."""
    _, quads, per_quad, chart = merged
    rng = np.random.default_rng(3)
    for f, block in enumerate(quad_blocks(quads).blocks):
        W, H = block.quads.shape
        uv = rng.random((40, 2))
        i, j = np.minimum((uv * [W, H]).astype(int).T, [[W - 1], [H - 1]])
        a, b = uv[:, 0] * W - i, uv[:, 1] * H - j
        r = block.rotation[i, j]
        u = np.select([r == 0, r == 1, r == 2], [a, 1 - b, 1 - a], b)
        v = np.select([r == 0, r == 1, r == 2], [b, a, 1 - b], 1 - a)
        ours = evaluate_patch_points(chart.patches, np.full(40, f), uv[:, 0], uv[:, 1])
        theirs = evaluate_patch_points(per_quad.patches, block.quads[i, j], u, v)
        assert np.linalg.norm(ours - theirs, axis=1).max() <= MERGE_TOLERANCE


def test_volume_is_the_per_quad_volume(merged):
    _, _, per_quad, chart = merged
    v_quad, v_chart = enclosed_volume(per_quad.patches), enclosed_volume(chart.patches)
    assert v_chart > 0 and abs(v_chart - v_quad) <= 1e-6 * v_quad


def test_regular_grid_merges_to_few_poles():
    """On the torus (all valence 4, the exact bicubic limit) the joins are C2 and every inner
    knot goes: each block is one B-spline with single knots."""
    chart = g1_surface_patches(sample_cages.torus(), measure=False, faces="chart")
    for patch in chart.patches:
        assert (patch.u_mults[1:-1] == 1).all() and (patch.v_mults[1:-1] == 1).all()
    assert chart.info["n_seeds"] >= 1


def test_knot_tools_keep_the_curve():
    """Refining, joining at C0 and removing knots leave a cubic spline where it was; a C2 join
    of two pieces of one cubic goes entirely, a kink stays."""
    poles = np.array([[0.0, 0.0], [1.0, 2.0], [2.0, -1.0], [3.0, 0.5]])
    knots, mults = np.array([0.0, 1.0]), np.array([4, 4])
    fine = refine(poles, knots, mults, np.array([0.0, 0.5, 1.0]), np.array([4, 3, 4]))
    halves = [(fine[:4], knots, mults), (fine[3:], knots, mults)]
    joined, jk, jm = join(halves)
    back, bk, bm, err = remove_knots(joined, jk, jm, 1e-12)
    assert err <= 1e-12 and np.array_equal(bm, [4, 4])
    assert np.allclose(back, poles, atol=1e-12)
    kinked = join([(poles, knots, mults), (poles[::-1] + [3.0, 0.5], knots, mults)])
    _, _, km, _ = remove_knots(*kinked, 1e-9)
    assert km[1] == 3


def test_chart_faces_need_the_g1_export():
    with pytest.raises(ParameterError, match="g1"):
        ReconstructionParams(faces="chart")
    assert ReconstructionParams(faces="chart", export="g1").faces == "chart"
    with pytest.raises(ParameterError, match="faces"):
        g1_surface_patches(sample_cages.cube(), faces="blocks")
