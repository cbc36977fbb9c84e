# SPDX-License-Identifier: LGPL-2.1-or-later
"""The working surface: a fine target is reduced to a proxy of bounded size that keeps its
shape (closed, genus, components); the later stages run on it and the fit on the target."""
import numpy as np
import pytest
import trimesh

from core.geometry import face_areas
from core.params import ReconstructionParams
from core.pipeline import run_stages
from core.proxy import working_surface
from core.types import MeshSource, PipelineState, TriMesh


def fine_torus(sections=160):
    """A torus of major radius 10 and minor radius 3 (mm), 2 * sections**2 triangles."""
    mesh = trimesh.creation.torus(major_radius=10.0, minor_radius=3.0,
                                  major_sections=sections, minor_sections=sections)
    return TriMesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces))


def graded_torus(sections=120, grading=0.8):
    """The torus of :func:`fine_torus` with its rings crowded towards one side: triangles
    there are many times smaller than on the other side (2 * sections**2 triangles)."""
    k = np.arange(sections) * 2.0 * np.pi / sections
    major = k + grading * np.sin(k)  # strictly increasing for grading < 1
    minor = k[:, None]
    ring = np.stack([(10.0 + 3.0 * np.cos(minor)) * np.cos(major),
                     (10.0 + 3.0 * np.cos(minor)) * np.sin(major),
                     3.0 * np.sin(minor) * np.ones_like(major)], axis=-1)  # (minor, major, 3)
    i, j = np.meshgrid(np.arange(sections), np.arange(sections), indexing="ij")
    a, b = i * sections + j, i * sections + (j + 1) % sections
    c, d = ((i + 1) % sections) * sections + j, ((i + 1) % sections) * sections + (j + 1) % sections
    faces = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                            np.stack([b, c, d], -1).reshape(-1, 3)])
    mesh = trimesh.Trimesh(ring.reshape(-1, 3), faces, process=False)
    if mesh.volume < 0:
        mesh.invert()
    return TriMesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces))


def tube_distance(points):
    """(k,) distance of points to the torus of :func:`fine_torus` (mm)."""
    return np.abs(np.hypot(np.hypot(points[:, 0], points[:, 1]) - 10.0, points[:, 2]) - 3.0)


def end_ratio(mesh):
    """Mean triangle area at the torus's coarse end (x > 7 mm) over that at its fine end
    (x < -7 mm)."""
    area = face_areas(mesh.vertices, mesh.faces)
    x = mesh.vertices[mesh.faces].mean(axis=1)[:, 0]
    return float(area[x > 7.0].mean() / area[x < -7.0].mean())


def test_a_fine_torus_becomes_a_closed_genus_one_proxy_near_it():
    torus = fine_torus(100)
    working = working_surface(torus, genus=1, components=1, proxy_triangles=3000)
    assert working.reduced
    assert working.report["reduced"] and working.report["reason"] == ""
    assert len(working.mesh.faces) <= 2 * 3000 < len(torus.faces)
    mesh = trimesh.Trimesh(working.mesh.vertices, working.mesh.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    assert mesh.euler_number == 0  # genus 1
    # the proxy's vertices lie on the target (its facets are within 0.01 mm of the torus),
    # moved there from the collapses' midpoints by well under the tube's radius
    assert tube_distance(working.mesh.vertices).max() < 0.01
    assert 0 < working.report["largest_move_mm"] < 0.3


def test_a_graded_target_gives_a_proxy_of_about_even_triangles():
    # the same shape triangulated finely on one side and coarsely on the other: the proxy's
    # triangles are of about one size, so the labeling sees the shape, not its triangulation
    torus = graded_torus()
    assert end_ratio(torus) > 3.0
    working = working_surface(torus, genus=1, components=1, proxy_triangles=4000)
    assert working.reduced and len(working.mesh.faces) < len(torus.faces)
    assert end_ratio(working.mesh) < 2.0
    assert tube_distance(working.mesh.vertices).max() < 0.02


def test_the_proxy_does_not_depend_on_the_order_of_the_vertices():
    # a midpoint-subdivided torus: its edges come in families of exactly one length, whose
    # collapse order the tie-break decides; listing the vertices in another order gives the
    # same proxy (the same vertex positions and the same triangles)
    torus = fine_torus(30)
    vertices, faces = trimesh.remesh.subdivide(torus.vertices, torus.faces)
    order = np.random.default_rng(1).permutation(len(vertices))
    shuffled = TriMesh(vertices[order], np.argsort(order)[faces])
    proxies = [working_surface(mesh, genus=1, components=1, proxy_triangles=1500).mesh
               for mesh in (TriMesh(vertices, faces), shuffled)]
    assert all(len(p.faces) < len(faces) for p in proxies)
    for points in (lambda p: p.vertices, lambda p: p.vertices[p.faces].mean(axis=1)):
        first, second = (np.array(sorted(map(tuple, np.round(points(p), 6)))) for p in proxies)
        assert first.shape == second.shape
        assert np.abs(first - second).max() < 1e-6


def test_a_target_at_or_under_the_size_is_its_own_working_surface():
    torus = fine_torus(40)
    working = working_surface(torus, genus=1, components=1, proxy_triangles=len(torus.faces))
    assert working.mesh is torus and not working.reduced
    assert working_surface(torus, 1, 1, proxy_triangles=0).mesh is torus


def test_user_parts_keep_the_target_and_say_why():
    torus = fine_torus(40)
    working = working_surface(torus, 1, 1, proxy_triangles=100, reason_to_keep="parts file")
    assert working.mesh is torus and working.report["reason"] == "parts file"


def test_a_reduction_that_does_not_keep_the_shape_is_refused():
    # told the target has two components, no reduction of the one torus matches: every
    # attempt is refused and the target itself is the working surface, with the reasons
    torus = fine_torus(60)
    working = working_surface(torus, genus=1, components=2, proxy_triangles=1000)
    assert working.mesh is torus and not working.reduced
    assert "no reduction kept the shape" in working.report["reason"]
    assert "target has genus 1 and 2" in working.report["reason"]


@pytest.mark.slow
def test_the_segmentation_and_base_mesh_run_on_the_proxy_and_keep_the_genus():
    torus = fine_torus(120)
    params = ReconstructionParams(proxy_triangles=4000, target_faces=64)
    state = PipelineState(source=MeshSource(path="torus", arrays=(torus.vertices, torus.faces)))
    state, report, failed = run_stages(state, ["intake", "parts", "frames", "labeling",
                                               "basemesh"], params)
    assert failed is None, report["stages"]
    proxy = state.intake.surface
    assert state.intake.working is not None and len(proxy.faces) < len(torus.faces)
    assert len(state.intake.target.faces) == len(torus.faces)
    assert len(state.labeling.face_label) == len(proxy.faces)
    assert report["input"]["proxy"]["triangles"] == len(proxy.faces)
    assert report["base_mesh"]["genus"] == 1
