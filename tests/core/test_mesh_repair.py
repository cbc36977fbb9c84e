# SPDX-License-Identifier: LGPL-2.1-or-later
"""Intake repairs (``core.mesh_repair``) on closed meshes damaged here the way TO exports are.

Each repaired mesh must pass the strict intake (``repair=False``: closed, 2-manifold, no
zero-area or duplicate face, outward, no intersecting pair by the project's own check), keep
the genus and stay within a small margin of the undamaged mesh's volume; the summary must
list the repair with its count and a box holding the damage.
"""
import json

import numpy as np
import pytest
import trimesh

from core.errors import InvalidMeshError
from core.geometry import triangle_mesh_volume
from core.mesh_repair import REPAIRABLE_INTERSECTING_FRACTION
from core.self_intersection import find_self_intersections
from core.validate import validate_target
from test_cli import run


def torus():
    """A genus-1 torus, major radius 1, minor radius 0.35: (V (1536, 3), F (3072, 3))."""
    mesh = trimesh.creation.torus(1.0, 0.35, major_sections=64, minor_sections=24)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def icosphere():
    mesh = trimesh.creation.icosphere(subdivisions=4)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


SPREAD_FACES = (0, 700, 1500, 2300)
"""Faces of the torus far apart from each other, damaged independently."""


def repaired(V, F, genus, volume, volume_margin=2e-3):
    """Validate with repairs and check the result against the strict intake; returns
    ``(mesh, summary)``."""
    mesh, summary = validate_target(V, F)
    again, strict = validate_target(mesh.vertices, mesh.faces, repair=False)
    assert strict["repairs"] == [] and strict["triangles"] == len(mesh.faces)
    assert strict["genus"] == genus == summary["genus"]
    assert len(find_self_intersections(mesh.vertices, mesh.faces)) == 0
    surface = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert surface.is_watertight and surface.is_winding_consistent
    assert triangle_mesh_volume(mesh.vertices, mesh.faces) == pytest.approx(volume, rel=volume_margin)
    return mesh, summary


def the_repair(summary, kind):
    found = [entry for entry in summary["repairs"] if entry["kind"] == kind]
    assert len(found) == 1, summary["repairs"]
    return found[0]


def assert_within(entry, points, margin=1e-9):
    """The repair's box holds ``points`` ((k, 3)) and its places."""
    for inside in (np.asarray(points).reshape(-1, 3), np.asarray(entry["places"])):
        assert (inside >= np.asarray(entry["bbox_min"]) - margin).all()
        assert (inside <= np.asarray(entry["bbox_max"]) + margin).all()


def test_caps_are_flipped_away_and_the_surface_stays_in_place():
    """A corner moved onto the middle of its opposite edge: a zero-area cap (the strict
    intake refuses it); the flip of that edge keeps every vertex where it is."""
    V, F = torus()
    volume = triangle_mesh_volume(V, F)
    damaged = V.copy()
    for face in SPREAD_FACES:
        a, b, c = F[face]
        damaged[c] = (damaged[a] + damaged[b]) / 2
    with pytest.raises(InvalidMeshError) as info:
        validate_target(damaged, F, repair=False)
    assert info.value.reason == "degenerate_faces"
    mesh, summary = repaired(damaged, F, genus=1, volume=volume)
    entry = the_repair(summary, "zero_area_faces")
    assert entry["count"] == len(SPREAD_FACES) and entry["largest_move"] == 0.0
    assert len(mesh.faces) == len(F)
    assert_within(entry, damaged[F[list(SPREAD_FACES)]])
    centres = damaged[F[list(SPREAD_FACES)]].mean(axis=1)
    places = np.asarray(entry["places"])
    assert len(places) == len(SPREAD_FACES)
    assert np.abs(places[:, None] - centres[None]).max(axis=2).min(axis=1).max() < 1e-12
    assert any("zero-area faces" in line for line in summary["warnings"])


def test_needles_are_collapsed():
    """A corner moved onto its opposite edge 3% from one end: a needle, whose short edge
    is collapsed (two faces fewer each)."""
    V, F = torus()
    damaged = V.copy()
    for face in SPREAD_FACES:
        a, b, c = F[face]
        damaged[c] = damaged[a] + 0.03 * (damaged[b] - damaged[a])
    mesh, summary = repaired(damaged, F, genus=1, volume=triangle_mesh_volume(V, F))
    entry = the_repair(summary, "zero_area_faces")
    assert entry["count"] == len(SPREAD_FACES)
    assert len(mesh.faces) == len(F) - 2 * len(SPREAD_FACES)
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).max()
    assert 0 < entry["largest_move"] < 0.05 * edge


def test_collapsed_triangles_are_removed():
    """All three corners of two triangles moved onto their centroid: after merging, the
    triangle and its three neighbours have coincident corners."""
    V, F = torus()
    damaged = V.copy()
    for face in SPREAD_FACES[:2]:
        damaged[F[face]] = damaged[F[face]].mean(axis=0)
    mesh, summary = repaired(damaged, F, genus=1, volume=triangle_mesh_volume(V, F))
    entry = the_repair(summary, "coincident_corners")
    assert entry["count"] == 8 and len(mesh.faces) == len(F) - 8
    assert_within(entry, damaged[F[list(SPREAD_FACES[:2])]])


def test_duplicate_faces_are_removed():
    """Three faces written twice, one three times, one with both windings once more (a
    sheet of no thickness): the closed torus is left."""
    V, F = torus()
    extra = np.vstack([F[[5, 6, 900, 5]], F[[1800]], F[[1800]][:, ::-1]])
    mesh, summary = repaired(V, np.vstack([F, extra]), genus=1, volume=triangle_mesh_volume(V, F))
    assert the_repair(summary, "duplicate_faces")["count"] == len(extra)
    assert len(mesh.faces) == len(F)


def test_two_copies_of_a_lone_sheet_are_refused():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    with pytest.raises(InvalidMeshError) as info:
        validate_target(V, np.vstack([F, F[:, ::-1]]))
    assert info.value.reason == "duplicate_faces" and "closed surface" in str(info.value)


def pierced_torus():
    """The torus with one vertex pushed across the tube through the middle of a face of
    the opposite wall (a dent made too deep): its six faces cross that face, in general
    position (no edge passes near another's edge or corner)."""
    V, F = torus()
    vertex = 777
    axis = np.array([*V[vertex, :2] / np.linalg.norm(V[vertex, :2]), 0.0])
    centres = V[F].mean(axis=1)
    across = centres[np.argmin(np.linalg.norm(centres - (2 * axis - V[vertex]), axis=1))]
    damaged = V.copy()
    damaged[vertex] = axis + 1.1 * 0.35 * (across - axis) / np.linalg.norm(across - axis)
    return V, F, damaged, vertex


def test_a_dent_through_the_wall_is_smoothed_out():
    V, F, damaged, vertex = pierced_torus()
    pairs = find_self_intersections(damaged, F)
    assert 2 <= len(pairs) <= 8
    with pytest.raises(InvalidMeshError) as info:
        validate_target(damaged, F, repair=False)
    assert info.value.reason == "self_intersecting"
    mesh, summary = repaired(damaged, F, genus=1, volume=triangle_mesh_volume(V, F))
    entry = the_repair(summary, "self_intersections")
    assert entry["count"] == len(pairs)
    assert_within(entry, damaged[np.unique(F[pairs.reshape(-1)])])
    assert (len(mesh.vertices), len(mesh.faces)) == (len(V), len(F))  # nothing removed


def test_a_fold_is_smoothed_out():
    """A vertex moved across a neighbour: its faces fold over the neighbour's."""
    V, F = torus()
    vertex = 100
    neighbour = next(v for v in F[(F == vertex).any(axis=1)][0] if v != vertex)
    damaged = V.copy()
    damaged[vertex] = V[neighbour] + 0.7 * (V[neighbour] - V[vertex])
    assert 2 <= len(find_self_intersections(damaged, F)) <= 8
    mesh, summary = repaired(damaged, F, genus=1, volume=triangle_mesh_volume(V, F))
    assert the_repair(summary, "self_intersections")["largest_move"] > 0


def test_an_inward_sphere_is_turned_outwards():
    V, F = icosphere()
    mesh, summary = repaired(V, F[:, ::-1], genus=0, volume=triangle_mesh_volume(V, F),
                             volume_margin=1e-12)
    assert the_repair(summary, "reoriented_faces")["count"] == len(F)


def test_a_mostly_self_intersecting_mesh_is_refused():
    """Every vertex jittered by about an edge length: far more intersecting faces than a
    local repair may change."""
    V, F = icosphere()
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    jittered = V + np.random.default_rng(5).normal(scale=edge, size=V.shape)
    pairs = find_self_intersections(jittered, F)
    assert len(np.unique(pairs)) > 3 * REPAIRABLE_INTERSECTING_FRACTION * len(F)
    with pytest.raises(InvalidMeshError) as info:
        validate_target(jittered, F)
    assert info.value.reason == "self_intersecting" and "of 5120 faces intersect" in str(info.value)


def write_obj(path, V, F):
    with open(path, "w") as handle:
        handle.writelines("v %r %r %r\n" % tuple(p) for p in V)
        handle.writelines("f %d %d %d\n" % tuple(f + 1) for f in F)
    return path


@pytest.mark.slow
def test_the_command_line_repairs_lists_and_refuses(tmp_path):
    """The pierced torus is repaired and the report's ``input.repairs`` says where; with
    ``--no-mesh-repair``, and for an open or a mostly self-intersecting mesh, exit 2 with
    one ``error:`` line and no report."""
    V, F, damaged, _ = pierced_torus()
    a, b, c = F[SPREAD_FACES[0]]
    damaged[c] = (damaged[a] + damaged[b]) / 2
    path = write_obj(tmp_path / "damaged.obj", damaged, F)
    result = run("reconstruct", path, "--stop-after", "intake", "--report", tmp_path / "r.json")
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    kinds = {entry["kind"]: entry for entry in report["input"]["repairs"]}
    assert set(kinds) == {"zero_area_faces", "self_intersections"}
    assert kinds["zero_area_faces"]["count"] == 1
    assert report["input"]["genus"] == 1 and report["input"]["triangles"] == len(F)
    assert "smoothed out" in report["stages"]["intake"]["message"]
    ico_V, ico_F = icosphere()
    refused = {
        "strict": (path, ("--no-mesh-repair",), "degenerate (zero-area) faces"),
        "open": (write_obj(tmp_path / "open.obj", V, F[:-2]), (), "boundary edges"),
        "jittered": (write_obj(tmp_path / "jittered.obj", ico_V + np.random.default_rng(5).normal(
            scale=0.05, size=ico_V.shape), ico_F), (), "of 5120 faces intersect"),
    }
    for name, (mesh_path, extra, words) in refused.items():
        out = tmp_path / f"{name}.json"
        result = run("reconstruct", mesh_path, "--stop-after", "intake", "--report", out, *extra)
        lines = result.stderr.splitlines()
        assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), name
        assert words in lines[0], (name, lines[0])
        assert not out.exists()


def test_a_mostly_degenerate_mesh_is_refused():
    """The torus's vertices spread along a line: a closed 2-manifold whose faces have no
    area, no surface to repair."""
    V, F = torus()
    line = np.zeros_like(V)
    line[:, 0] = np.arange(len(V)) / len(V)
    with pytest.raises(InvalidMeshError) as info:
        validate_target(line, F)
    assert info.value.reason == "degenerate_faces" and "of 3072 faces are degenerate" in str(info.value)
