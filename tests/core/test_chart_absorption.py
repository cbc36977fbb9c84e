# SPDX-License-Identifier: LGPL-2.1-or-later
"""Chart absorption on hand-labelled cubes and plates: a noise chart is taken into its
neighbours and the labeling stays valid; a small chart that the polycube needs is left alone."""
import numpy as np
import pytest

from core.errors import ParameterError
from core.segmentation.chart_absorption import (SMALL_AREA, THIN_WIDTH, absorb_charts,
                                               chart_measures, dissolved_labels)
from core.segmentation.charts import build_topology, extract_layout
from core.segmentation.labeling import face_normals, label_cost, nearest_direction_labels
from core.segmentation.repair import CandidateJudge
from core.segmentation.validity import check_validity
from tests.core.dev_meshes import load_dev_mesh
from tests.core.test_repair_operators import labelled_cube


def cube(levels=4):
    """(V, F, parts, frames, nearest-direction labels) of a subdivided unit cube [0, 1]^3."""
    return labelled_cube(levels)


def absorb(V, F, parts, frames, labels, unit_area, **kw):
    judge = CandidateJudge.of_mesh(V, F, parts, frames, build_topology(F, len(V)))
    return absorb_charts(V, F, parts, labels, judge, unit_area, **kw)


def strip_across_top(V, F, labels, half_width=0.07):
    """A +X strip across the top from the -Y to the +Y side, splitting the +Z top in two:
    a valid chart (four boundaries: two +Z charts, +Y, -Y) that fits its faces at 90 degrees."""
    c = V[F].mean(axis=1)
    strip = (c[:, 2] > 0.99) & (np.abs(c[:, 0] - 0.5) < half_width)
    out = labels.copy()
    out[strip] = 0
    return out, strip


def test_noise_strip_is_absorbed_and_the_labeling_stays_valid():
    V, F, parts, frames, labels = cube()
    noisy, strip = strip_across_top(V, F, labels)
    before = check_validity(V, F, parts, noisy, frames)
    assert before.is_valid and before.layout.n_charts == 8
    given = noisy.copy()
    done = absorb(V, F, parts, frames, noisy, unit_area=0.2)
    assert np.array_equal(noisy, given), "the input labels are not modified"
    assert (done.labels[strip] == 4).all(), "the strip's faces take the +Z of their normals"
    assert np.array_equal(done.labels[~strip], noisy[~strip])
    after = check_validity(V, F, parts, done.labels, frames)
    assert after.is_valid and after.layout.n_charts == 6
    assert done.validity.is_valid and len(done.validity.turning_points) == 0
    assert done.report["charts_before"] == 8 and done.report["charts_after"] == 6
    assert done.report["angle_after"] < done.report["angle_before"]


def test_charts_larger_than_the_quads_are_kept():
    V, F, parts, frames, labels = cube()
    noisy, _ = strip_across_top(V, F, labels, half_width=0.2)
    done = absorb(V, F, parts, frames, noisy, unit_area=0.01)
    assert np.array_equal(done.labels, noisy)
    assert sum(done.report["absorbed"].values()) == 0


def test_small_chart_the_polycube_needs_is_refused():
    """Top quadrants +X, +Y, -X, -Y around a small +Z square: each merge or split of the square
    makes +X meet -X (or a corner of four Z boundaries), so the square stays."""
    V, F, parts, frames, labels = cube()
    c = V[F].mean(axis=1)
    top = c[:, 2] > 0.99
    d = c[:, :2] - 0.5
    quad = top & (np.abs(d).max(axis=1) < 0.2)
    east, north = d[:, 0] > 0, d[:, 1] > 0
    labels[quad] = np.where(east, np.where(north, 0, 3), np.where(north, 2, 1))[quad]
    centre = top & (np.abs(d).max(axis=1) < 0.05)
    labels[centre] = 4
    val = check_validity(V, F, parts, labels, frames)
    assert val.is_valid
    assert val.layout.chart_size[val.layout.face_chart[np.flatnonzero(centre)[0]]] == centre.sum()
    done = absorb(V, F, parts, frames, labels, unit_area=0.02)
    assert np.array_equal(done.labels, labels)
    assert done.report["refused"] >= 1 and sum(done.report["absorbed"].values()) == 0
    assert done.validity.is_valid


def plate_with_holes(centres, size=0.2, edge=0.08):
    """(V, F, parts, frames, nearest-direction labels) of the plate [0, 2] x [0, 1] x [0, 0.5]
    with square through-holes of side ``size`` at ``centres`` ((x, y) pairs), triangles of at
    most ``edge``."""
    import trimesh

    plate = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    plate.apply_translation((1.0, 0.5, 0.25))
    holes = []
    for x, y in centres:
        hole = trimesh.creation.box(extents=(size, size, 1.0))
        hole.apply_translation((x, y, 0.25))
        holes.append(hole)
    mesh = trimesh.boolean.difference([plate] + holes, engine="manifold")
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, edge)
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    frames = np.broadcast_to(np.eye(3), (len(F), 3, 3)).copy()
    labels = nearest_direction_labels(face_normals(V, F), frames).astype(np.int64)
    return V, F, np.zeros(len(F), dtype=np.int64), frames, labels


def test_charts_no_trial_takes_do_not_use_up_the_rounds():
    """The walls of four square through-holes are charts smaller and thinner than the quads
    that no merge can take (each would label a wall across its normals, or leave a hole without
    corners); a noise strip across the top shares the top with them. Two rounds take the strip:
    the walls are refused without holding it up."""
    V, F, parts, frames, labels = plate_with_holes([(0.3, 0.3), (0.3, 0.7), (1.7, 0.3),
                                                    (1.7, 0.7)])
    c = V[F].mean(axis=1)
    strip = (np.abs(c[:, 2] - 0.5) < 1e-6) & (np.abs(c[:, 0] - 1.0) < 0.07)
    noisy = labels.copy()
    noisy[strip] = 0  # +X across the +Z top, from the -Y side to the +Y side
    before = check_validity(V, F, parts, noisy, frames)
    assert before.is_valid
    done = absorb(V, F, parts, frames, noisy, unit_area=0.2, max_rounds=2)
    assert (done.labels[strip] == 4).all()
    assert np.array_equal(done.labels[~strip], noisy[~strip]), "the hole walls stay"
    assert done.report["refused"] >= 16
    after = check_validity(V, F, parts, done.labels, frames)
    assert after.is_valid and after.layout.n_charts == before.layout.n_charts - 2


def test_invalid_input_gets_no_more_invalid_items():
    V, F, parts, frames, labels = cube()
    noisy, _ = strip_across_top(V, F, labels)
    c = V[F].mean(axis=1)
    noisy[(c[:, 0] > 0.99) & (c[:, 2] < 0.2) & (np.abs(c[:, 1] - 0.5) < 0.1)] = 1  # -X on +X
    before = check_validity(V, F, parts, noisy, frames)
    assert not before.is_valid
    done = absorb(V, F, parts, frames, noisy, unit_area=0.2)
    assert check_validity(V, F, parts, done.labels, frames).n_invalid <= before.n_invalid


def test_dissolve_gives_every_face_a_neighbouring_label():
    V, F, parts, frames, labels = cube()
    noisy, strip = strip_across_top(V, F, labels)
    topology = build_topology(F, len(V))
    lay = extract_layout(topology, parts, noisy)
    chart = int(lay.face_chart[np.flatnonzero(strip)[0]])
    out = dissolved_labels(topology, parts, noisy, lay.face_chart, chart,
                           label_cost(face_normals(V, F), frames))
    assert np.array_equal(out[~strip], noisy[~strip])
    neighbour_labels = set(lay.chart_label[lay.chart_neighbours[chart].indices].tolist())
    assert set(out[strip].tolist()) <= neighbour_labels and 0 not in set(out[strip].tolist())


def test_bad_unit_area_is_refused():
    V, F, parts, frames, labels = cube(2)
    with pytest.raises(ParameterError):
        absorb(V, F, parts, frames, labels, unit_area=0.0)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["idler_riser.stl", "to_simp_mbb.stl", "tray_bottom.stl"])
def test_dev_mesh_loses_noise_charts_and_stays_valid(name):
    """On a real design the pass keeps a valid labeling valid, adds no turning point and never
    adds a chart; what it takes are charts below one quad of the budget."""
    from core.geometry import face_areas
    from core.segmentation.frames import compute_frames
    from core.segmentation.labeling import hbecvt_labeling
    from core.segmentation.repair import repair_labeling

    mesh = load_dev_mesh(name)
    V, F = mesh.vertices, mesh.faces
    parts = np.zeros(len(F), dtype=np.int64)
    field = compute_frames(mesh, parts)
    labels, _ = hbecvt_labeling(V, F, parts, field.face_frame, field.face_interface_axis)
    labels, _ = repair_labeling(V, F, parts, labels, field.face_frame)
    labels = labels.astype(np.int64)
    before = check_validity(V, F, parts, labels, field.face_frame)
    assert before.is_valid
    unit_area = face_areas(V, F).sum() / 300
    done = absorb(V, F, parts, field.face_frame, labels, unit_area)
    after = check_validity(V, F, parts, done.labels, field.face_frame)
    assert after.is_valid
    assert len(after.turning_points) <= len(before.turning_points)
    assert after.layout.n_charts <= before.layout.n_charts
    changed = np.unique(before.layout.face_chart[done.labels != labels])
    area, width = chart_measures(V, build_topology(F, len(V)), before.layout, face_areas(V, F))
    small = (area < SMALL_AREA * unit_area) | (width < THIN_WIDTH * np.sqrt(unit_area))
    assert small[changed].all(), "only charts below a quad in area or width are touched"
